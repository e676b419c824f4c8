"""Breakpoints on a running task net (paper section 5): pause the run where the operator asked.

An operator debugging a task sets breakpoints on the drawing (web console) or types them (terminal),
like the breakpoints of a behaviour-tree monitor: the run pauses

* ``enabled T`` — when transition ``T`` *becomes* ready to fire: enabled by the marking with its
  internal events latched (its external event, if any, is not required: the run pauses while it
  waits for it). The run pauses before ``T`` fires;
* ``fires T`` — right after ``T`` fired (its firing is journaled and shown, nothing fires after it);
* ``count P N`` — when place ``P`` *reaches* ``N`` tokens or more (from fewer);
* ``error TASK`` — when an instance of primitive task ``TASK`` ends with status error (its error
  token is latched: the error branch is ready, and waits).

Breakpoints are edge-triggered: one that already holds when it is set (``T`` already enabled,
``P`` already at ``N``) pauses the run the next time it becomes true. Setting, clearing and every
pause a breakpoint causes are operator commands, journaled like any other (``break``, ``clear``,
and ``pause`` with the breakpoint as its detail), so a replay shows them.

:class:`BreakpointWatch` holds the breakpoints of one run and is asked after every firing, token
insertion or removal and primitive-action result; without breakpoints it costs the run one
attribute test per firing. Pure: the engine is read through :meth:`~coordinator.engine.Engine.ready`
and :attr:`~coordinator.engine.Engine.marking`, nothing else.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

from coordinator.net import PetriNet

__all__ = ["BreakKind", "Breakpoint", "BreakpointWatch", "Hit", "breakpoint_problem", "parse_breakpoint"]

#: Most breakpoints one run holds.
MAX_BREAKPOINTS = 256


class BreakKind(enum.StrEnum):
    """What a breakpoint watches."""

    ENABLED = "enabled"
    """A transition becomes ready to fire."""
    FIRES = "fires"
    """A transition fired."""
    COUNT = "count"
    """A place reaches a token count."""
    ERROR = "error"
    """A primitive task ends with status error."""


@dataclass(frozen=True, slots=True)
class Breakpoint:
    """One breakpoint.

    Attributes:
        kind: what it watches.
        target: the transition (``enabled``, ``fires``), place (``count``) or primitive task (``error``).
        count: the token count of a ``count`` breakpoint (≥ 0), else ``None``.
    """

    kind: BreakKind
    target: str
    count: int | None = None

    def __str__(self) -> str:
        return f"{self.kind.value} {self.target}" + (f" {self.count}" if self.kind is BreakKind.COUNT else "")

    def to_json(self) -> dict[str, object]:
        """``{"kind", "target", "count"}`` (the console's and the journal's form)."""
        return {"kind": self.kind.value, "target": self.target, "count": self.count}

    @classmethod
    def from_json(cls, data: object) -> Breakpoint:
        """The breakpoint of :meth:`to_json`'s form (as a journal's ``operator.detail`` holds it).

        Raises:
            ValueError: ``data`` is not that form, saying what is wrong.
        """
        if not isinstance(data, dict) or not {"kind", "target"} <= set(data) <= {"kind", "target", "count"}:
            raise ValueError("a breakpoint is {kind, target, count}")
        kind, target, count = data["kind"], data["target"], data.get("count")
        if kind not in tuple(k.value for k in BreakKind) or not isinstance(target, str) or not target:
            raise ValueError(f"not a breakpoint: kind {str(kind)[:20]!r}, target {str(target)[:40]!r}")
        if BreakKind(kind) is BreakKind.COUNT:
            if type(count) is not int or count < 0:
                raise ValueError(f"a count breakpoint needs a token count >= 0, not {str(count)[:20]}")
        elif count is not None:
            raise ValueError(f"a {kind} breakpoint takes no count")
        return cls(BreakKind(kind), target, count)


@dataclass(frozen=True, slots=True)
class Hit:
    """A breakpoint that has just become true, and what made it so (in words)."""

    breakpoint: Breakpoint
    why: str


def parse_breakpoint(text: str) -> Breakpoint:
    """Parse ``enabled T``, ``fires T``, ``count P N`` or ``error TASK``.

    Raises:
        ValueError: with the syntax, on anything else.
    """
    words = text.split()
    usage = "breakpoints: enabled TRANSITION | fires TRANSITION | count PLACE N | error TASK"
    if not words:
        raise ValueError(usage)
    try:
        kind = BreakKind(words[0])
    except ValueError:
        raise ValueError(usage) from None
    if kind is BreakKind.COUNT:
        if len(words) != 3:
            raise ValueError("usage: count PLACE N")
        try:
            count = int(words[2])
        except ValueError:
            raise ValueError(f"count must be an integer, got {words[2]!r}") from None
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        return Breakpoint(kind, words[1], count)
    if len(words) != 2:
        raise ValueError(f"usage: {kind.value} {'TASK' if kind is BreakKind.ERROR else 'TRANSITION'}")
    return Breakpoint(kind, words[1])


def breakpoint_problem(net: PetriNet, bp: Breakpoint) -> str | None:
    """Why ``bp`` cannot be set on ``net`` (an unknown element), or ``None``."""
    if bp.kind in (BreakKind.ENABLED, BreakKind.FIRES):
        if bp.target not in net.transition_index:
            return f"no transition {bp.target!r} in net {net.name!r}"
    elif bp.kind is BreakKind.COUNT:
        if bp.target not in net.place_index:
            return f"no place {bp.target!r} in net {net.name!r}"
        if bp.count is None or bp.count < 0:
            return "a count breakpoint needs a token count >= 0"
    elif bp.target not in net.tasks:
        return f"no primitive task {bp.target!r} in net {net.name!r}"
    return None


class _Engine(Protocol):
    def ready(self, transition: str) -> bool: ...

    @property
    def marking(self) -> Mapping[str, int]: ...


class BreakpointWatch:
    """The breakpoints of one run, and whether one has just become true.

    Args:
        net: the net being run (breakpoints are checked against it).
    """

    def __init__(self, net: PetriNet) -> None:
        self.net = net
        self._points: dict[Breakpoint, bool] = {}  # breakpoint -> held at the last look (edge detection)

    def __bool__(self) -> bool:
        return bool(self._points)

    @property
    def breakpoints(self) -> tuple[Breakpoint, ...]:
        """The breakpoints set, in the order they were set."""
        return tuple(self._points)

    def add(self, bp: Breakpoint, engine: _Engine) -> None:
        """Set ``bp`` (once; setting it again changes nothing).

        Raises:
            ValueError: ``bp`` names an element the net does not have, or too many are set.
        """
        problem = breakpoint_problem(self.net, bp)
        if problem is not None:
            raise ValueError(problem)
        if bp not in self._points and len(self._points) >= MAX_BREAKPOINTS:
            raise ValueError(f"at most {MAX_BREAKPOINTS} breakpoints")
        self._points.setdefault(bp, self._holds(bp, engine, engine.marking))

    def remove(self, bp: Breakpoint) -> None:
        """Clear ``bp``.

        Raises:
            ValueError: it was not set.
        """
        if bp not in self._points:
            raise ValueError(f"no breakpoint {bp} is set")
        del self._points[bp]

    def _holds(self, bp: Breakpoint, engine: _Engine, counts: Mapping[str, int]) -> bool:
        if bp.kind is BreakKind.ENABLED:
            return engine.ready(bp.target)
        if bp.kind is BreakKind.COUNT:
            return counts.get(bp.target, 0) >= (bp.count or 0)
        return False

    def _edges(self, engine: _Engine) -> Hit | None:
        """Look at the level breakpoints (enabled, count); the first that became true."""
        hit = None
        counts: Mapping[str, int] | None = None
        for bp, held in self._points.items():
            if bp.kind is BreakKind.ENABLED or bp.kind is BreakKind.COUNT:
                if counts is None:
                    counts = engine.marking
                now = self._holds(bp, engine, counts)
                self._points[bp] = now
                if now and not held and hit is None:
                    why = (f"{bp.target} is ready to fire" if bp.kind is BreakKind.ENABLED else
                           f"{bp.target} holds {counts.get(bp.target, 0)} tokens")
                    hit = Hit(bp, why)
        return hit

    def after_firing(self, transition: str, engine: _Engine) -> Hit | None:
        """After ``transition`` fired: the breakpoint that has just become true, or ``None``."""
        fired = Breakpoint(BreakKind.FIRES, transition)
        edge = self._edges(engine)
        if fired in self._points:
            return Hit(fired, f"{transition} fired")
        return edge

    def after_change(self, engine: _Engine) -> Hit | None:
        """After the marking or the latched events changed otherwise (an operator's tokens, a result)."""
        return self._edges(engine)

    def after_result(self, task: str, status: str, engine: _Engine) -> Hit | None:
        """After an instance of ``task`` ended with ``status`` (its events latched)."""
        edge = self._edges(engine)
        errored = Breakpoint(BreakKind.ERROR, task)
        if status == "error" and errored in self._points:
            return Hit(errored, f"{task} ended with an error")
        return edge
