"""The result vocabulary: how one run of a primitive action ends (paper sections 2 and 4).

One frozen record, :class:`ActionResult`, travels unchanged from the primitive action on its node,
over the wire (docs/protocol.md, ``result``), through the coordinator's runtime, into the engine
(which latches its internal events on the task's token), the journal and the learner. It is
validated once, when it is built: by the action on the node, and by the protocol decoder when a
``result`` frame arrives.

The status of an ending (:class:`Status`) decides the branch the net takes:

* ``success`` — the specifications were met; raises ``int:<task>.ok`` and ``int:<task>.success``;
* ``failure`` — not met, but the normal branch goes on; raises ``int:<task>.ok`` and
  ``int:<task>.failure``;
* ``error`` — error recovery is needed (timeout, node lost, exception); raises ``int:<task>.error``.

An action may add a named outcome (an identifier such as ``interruption``), raised as
``int:<task>.<outcome>``: that is how a net branches on a result (the paper's Fig. 3 conflicts on
boolean variables set by the preceding primitive task).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any

from services.errors import ActionError

__all__ = ["ActionResult", "Status", "latched_events"]


class Status(enum.StrEnum):
    """How a primitive action ended (section 4). A ``str``: ``Status.SUCCESS == "success"``."""

    SUCCESS = "success"
    """The specifications were fully met."""
    FAILURE = "failure"
    """The specifications were not fully met, but execution goes on along the normal branch."""
    ERROR = "error"
    """The specifications were not met and error recovery is required (timeout, node lost...)."""


_BASE_EVENTS = {
    Status.SUCCESS: frozenset({"ok", "success"}),
    Status.FAILURE: frozenset({"ok", "failure"}),
    Status.ERROR: frozenset({"error"}),
}


def latched_events(status: Status, outcome: str | None = None) -> frozenset[str]:
    """The outcome names latched on a primitive task's token when its instance ends.

    Args:
        status: how the action ended.
        outcome: an optional named outcome (an identifier).

    Returns:
        ``{"ok", "success"}``, ``{"ok", "failure"}`` or ``{"error"}``, plus ``outcome`` if given:
        the ``<outcome>`` parts of the ``int:<task>.<outcome>`` events raised.
    """
    base = _BASE_EVENTS[status]
    return base | {outcome} if outcome else base


def _finite(value: Any) -> bool:
    return type(value) in (int, float) and math.isfinite(value)


@dataclass(frozen=True, slots=True, kw_only=True)
class ActionResult:
    """How one call of a primitive action ended.

    Build it with :meth:`success`, :meth:`failure` or :meth:`error` in an action; the node adds
    the measured durations.

    Attributes:
        status: success, failure or error.
        outcome: optional named outcome, an identifier, raised as ``int:<task>.<outcome>``.
        value: any msgpack-able value the action returns (data for the next primitive task).
        cost: the action's own cost figure C(a) for J = 1 − R + ρC (section 3), or ``None``
            (then the measured duration is used).
        wall_s: wall-clock duration of the call on the node, seconds (0 if it never ran).
        cpu_s: CPU time of the node process during the call, seconds (overcounts when calls
            overlap).
        reason: why an error happened (``"deadline"``, ``"cancelled"``, exception text, node
            trouble seen by the caller), else ``None``.

    Raises:
        ActionError: a field has the wrong type or value (a bad status, an outcome that is not an
            identifier, a negative or non-finite duration or cost).
    """

    status: Status
    outcome: str | None = None
    value: Any = None
    cost: float | None = None
    wall_s: float = 0.0
    cpu_s: float = 0.0
    reason: str | None = None

    def __post_init__(self) -> None:
        if type(self.status) is not Status:
            try:
                object.__setattr__(self, "status", Status(self.status))
            except ValueError:
                raise ActionError(f"status must be one of success, failure, error; got {self.status!r}") from None
        if self.outcome is not None and not (type(self.outcome) is str and self.outcome.isidentifier()):
            raise ActionError(f"outcome must be an identifier or None, got {self.outcome!r}")
        if self.cost is not None and not _finite(self.cost):
            raise ActionError(f"cost must be a finite number or None, got {self.cost!r}")
        if not (_finite(self.wall_s) and self.wall_s >= 0 and _finite(self.cpu_s) and self.cpu_s >= 0):
            raise ActionError(f"durations must be finite and non-negative, got {self.wall_s!r}, {self.cpu_s!r}")
        if self.reason is not None and type(self.reason) is not str:
            raise ActionError(f"reason must be a string or None, got {self.reason!r}")

    @classmethod
    def success(cls, value: Any = None, *, outcome: str | None = None, cost: float | None = None) -> ActionResult:
        """The specifications were met."""
        return cls(status=Status.SUCCESS, outcome=outcome, value=value, cost=cost)

    @classmethod
    def failure(cls, value: Any = None, *, outcome: str | None = None, cost: float | None = None,
                reason: str | None = None) -> ActionResult:
        """Not met; the normal branch goes on."""
        return cls(status=Status.FAILURE, outcome=outcome, value=value, cost=cost, reason=reason)

    @classmethod
    def error(cls, reason: str, *, outcome: str | None = None, value: Any = None,
              cost: float | None = None) -> ActionResult:
        """Error recovery is needed, for ``reason``."""
        return cls(status=Status.ERROR, outcome=outcome, value=value, cost=cost, reason=reason)

    @property
    def ok(self) -> bool:
        """True for success and failure (the normal branch), False for error."""
        return self.status is not Status.ERROR

    @property
    def events(self) -> frozenset[str]:
        """The outcome names this result latches on its token (:func:`latched_events`)."""
        return latched_events(self.status, self.outcome)
