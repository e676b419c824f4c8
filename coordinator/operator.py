"""Operator commands (paper section 5): what an operator may do to a running task net.

The operator changes a run's path and timing by inserting or removing tokens in *control* places
(e.g. emptying ``runs_remaining`` ends an experiment after the current run), and can pause it,
step it one firing at a time, resume it or abort it, and end a run that waits for them. They may
set and clear breakpoints (:mod:`coordinator.breakpoints`), and, where the net's ``[operator]``
table allows it, raise an external event (``inject``) or force the outcome of a running primitive
action (``force``) for drills. Commands come from the terminal (a typed line,
:func:`parse_operator_command`), the web console or a program driving the runtime; the runtime
journals each command and applies it through the engine, or journals its refusal with the reason.
"""

from __future__ import annotations

import enum
import json
import shlex
from dataclasses import dataclass
from typing import Any

from coordinator.breakpoints import Breakpoint, parse_breakpoint

__all__ = ["Command", "OperatorCommand", "parse_operator_command", "USAGE"]

USAGE = ("+ PLACE [N] | - PLACE [N] | pause | step | resume | abort | end | break BREAKPOINT | clear BREAKPOINT"
         " | inject ext:TOPIC [JSON] | force INSTANCE OUTCOME [REASON]")
"""One-line summary of the typed command syntax."""


class Command(enum.StrEnum):
    """The operator commands."""

    INSERT = "insert"
    """Put tokens in a control place."""
    REMOVE = "remove"
    """Take tokens from a control place."""
    PAUSE = "pause"
    """Stop firing; running primitive actions go on and their results are latched."""
    STEP = "step"
    """Fire exactly one transition (paused or not)."""
    RESUME = "resume"
    """Leave the paused state."""
    ABORT = "abort"
    """Cancel every running primitive action and end the run."""
    END = "end"
    """Stop waiting: end the run as soon as nothing fires and no primitive action runs, instead of
    waiting for the operator or an external event (Ctrl-D on the terminal does the same)."""
    BREAK = "break"
    """Set a breakpoint (:mod:`coordinator.breakpoints`)."""
    CLEAR = "clear"
    """Clear a breakpoint."""
    INJECT = "inject"
    """Raise an external event the net's ``[operator]`` table lets the operator raise."""
    FORCE = "force"
    """End a running primitive action with an outcome the net's ``[operator]`` table lets the
    operator force (a drill; never counted as a measured result)."""


@dataclass(frozen=True, slots=True)
class OperatorCommand:
    """One operator command.

    Attributes:
        command: what to do.
        place: the control place of ``insert``/``remove``, else ``None``.
        count: number of tokens for ``insert``/``remove`` (≥ 1).
        breakpoint: the breakpoint of ``break``/``clear``, else ``None``.
        event: the ``ext:<topic>`` event of ``inject``, else ``None``.
        payload: what the injected event carries (a JSON value, as a publisher's event data), or
            ``None``.
        instance: the running instance (call id) of ``force``, else ``None``.
        outcome: what ``force`` ends it with: ``success``, ``failure``, ``error`` or
            ``status.named`` (``failure.no_ball``), else ``None``.
        reason: the operator's reason given with ``force`` (journaled with the result).
    """

    command: Command
    place: str | None = None
    count: int = 1
    breakpoint: Breakpoint | None = None
    event: str | None = None
    instance: str | None = None
    outcome: str | None = None
    reason: str = ""
    payload: Any = None

    def __str__(self) -> str:
        if self.place is not None:
            return f"{self.command.value} {self.place} {self.count}"
        if self.breakpoint is not None:
            return f"{self.command.value} {self.breakpoint}"
        if self.event is not None:
            payload = "" if self.payload is None else " " + json.dumps(self.payload, separators=(",", ":"))
            return f"{self.command.value} {self.event}{payload}"
        if self.instance is not None:
            reason = f" {shlex.quote(self.reason)}" if self.reason else ""
            return f"{self.command.value} {self.instance} {self.outcome}{reason}"
        return self.command.value

    def detail(self) -> dict[str, Any] | None:
        """What the journal keeps of this command besides its name, place and count (the
        ``detail`` column: docs/journal.md), or ``None``."""
        if self.breakpoint is not None:
            return {"breakpoint": self.breakpoint.to_json()}
        if self.event is not None:
            return {"event": self.event} if self.payload is None else {"event": self.event, "payload": self.payload}
        if self.instance is not None:
            return {"instance": self.instance, "outcome": self.outcome, "reason": self.reason}
        return None


_ALIASES = {"+": Command.INSERT, "-": Command.REMOVE, "p": Command.PAUSE, "s": Command.STEP,
            "r": Command.RESUME, "q": Command.ABORT}


def parse_operator_command(text: str) -> OperatorCommand:
    """Parse a typed command: ``+ PLACE [N]``, ``- PLACE [N]``, ``insert PLACE [N]``,
    ``remove PLACE [N]``, ``pause`` (``p``), ``step`` (``s``), ``resume`` (``r``), ``abort`` (``q``),
    ``end``, ``break BREAKPOINT``, ``clear BREAKPOINT`` (``enabled T``, ``fires T``, ``count P N``,
    ``error TASK``), ``inject ext:TOPIC [JSON]`` (the JSON value is the event's payload), ``force INSTANCE OUTCOME [REASON]``.

    Raises:
        ValueError: with a usage hint, on anything else.
    """
    words = text.split()
    if not words:
        raise ValueError("empty command")
    head = _ALIASES.get(words[0])
    if head is None:
        try:
            head = Command(words[0])
        except ValueError:
            raise ValueError(f"commands: {USAGE}") from None
    if head in (Command.BREAK, Command.CLEAR):
        return OperatorCommand(head, breakpoint=parse_breakpoint(" ".join(words[1:])))
    if head is Command.INJECT:
        parts = text.split(None, 2)
        if len(parts) < 2 or not parts[1].startswith("ext:"):
            raise ValueError("usage: inject ext:TOPIC [JSON]")
        payload = None
        if len(parts) == 3:
            try:
                payload = json.loads(parts[2])
            except ValueError as exc:
                raise ValueError(f"inject: the payload is not JSON ({exc}); usage: inject ext:TOPIC [JSON]") from None
        return OperatorCommand(head, event=parts[1], payload=payload)
    if head is Command.FORCE:
        try:
            parts = shlex.split(text)
        except ValueError as exc:
            raise ValueError(f"force: {exc}") from None
        if len(parts) < 3:
            raise ValueError("usage: force INSTANCE success|failure|error[.OUTCOME] [REASON]")
        return OperatorCommand(head, instance=parts[1], outcome=parts[2], reason=" ".join(parts[3:]))
    if head in (Command.INSERT, Command.REMOVE):
        if len(words) not in (2, 3):
            raise ValueError(f"usage: {head.value} PLACE [COUNT]")
        try:
            count = int(words[2]) if len(words) == 3 else 1
        except ValueError:
            raise ValueError(f"count must be an integer, got {words[2]!r}") from None
        return OperatorCommand(head, words[1], count)
    if len(words) != 1:
        raise ValueError(f"{head.value} takes no argument; commands: {USAGE}")
    return OperatorCommand(head)
