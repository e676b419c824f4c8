"""Operator commands (paper section 5): what an operator may do to a running task net.

The operator changes a run's path and timing by inserting or removing tokens in *control* places
(e.g. emptying ``runs_remaining`` ends an experiment after the current run), and can pause it,
step it one firing at a time, resume it or abort it, and end a run that waits for them. Commands
come from the terminal (a typed line, :func:`parse_operator_command`) or a program driving the
runtime; the runtime journals each command and applies it through the engine, or journals its
refusal with the reason.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Command", "OperatorCommand", "parse_operator_command", "USAGE"]

USAGE = "+ PLACE [N] | - PLACE [N] | pause | step | resume | abort | end"
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


@dataclass(frozen=True, slots=True)
class OperatorCommand:
    """One operator command.

    Attributes:
        command: what to do.
        place: the control place of ``insert``/``remove``, else ``None``.
        count: number of tokens for ``insert``/``remove`` (≥ 1).
    """

    command: Command
    place: str | None = None
    count: int = 1

    def __str__(self) -> str:
        if self.place is None:
            return self.command.value
        return f"{self.command.value} {self.place} {self.count}"


_ALIASES = {"+": Command.INSERT, "-": Command.REMOVE, "p": Command.PAUSE, "s": Command.STEP,
            "r": Command.RESUME, "q": Command.ABORT}


def parse_operator_command(text: str) -> OperatorCommand:
    """Parse a typed command: ``+ PLACE [N]``, ``- PLACE [N]``, ``insert PLACE [N]``,
    ``remove PLACE [N]``, ``pause`` (``p``), ``step`` (``s``), ``resume`` (``r``), ``abort`` (``q``),
    ``end``.

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
