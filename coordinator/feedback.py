"""Which feedback of the running primitive actions the journal keeps (paper section 5).

A primitive action may send feedback as fast as it works (a tracker at the camera's frame rate, a
ROS 2 action server at 500 Hz): the operator's console shows each one, but the journal must not grow
with the rate of a stream. :class:`FeedbackSampler` keeps, per running call, at most
:data:`FEEDBACK_PER_S` feedback messages a second (the first one at once, then one each
``1 / FEEDBACK_PER_S`` s) and always the last one the call sent before its result, which is written
just before the result. A call of ``d`` seconds thus journals at most ``FEEDBACK_PER_S * d + 2``
feedback rows, whatever its rate. Pure: the caller gives the times and writes what it is told to.
"""

from __future__ import annotations

from typing import Generic, TypeVar

__all__ = ["FEEDBACK_PER_S", "FeedbackSampler"]

FEEDBACK_PER_S = 10.0
"""Feedback messages journaled per second and running call, at most (plus the last before the result)."""

T = TypeVar("T")


class FeedbackSampler(Generic[T]):
    """Per running call, the feedback to journal now and the latest one held back.

    Args:
        per_s: feedback kept per second and call, > 0 (:data:`FEEDBACK_PER_S`).

    Raises:
        ValueError: ``per_s`` is not positive.
    """

    __slots__ = ("_held", "_interval", "_last")

    def __init__(self, per_s: float = FEEDBACK_PER_S) -> None:
        if not per_s > 0:
            raise ValueError(f"feedback per second must be positive, not {per_s}")
        self._interval = 1.0 / per_s
        self._last: dict[str, float] = {}
        self._held: dict[str, T] = {}

    def offer(self, call: str, t: float, item: T) -> T | None:
        """A feedback ``item`` of ``call`` arrived at time ``t`` (monotonic seconds): returns it if it
        is to be journaled now, else ``None`` (it is held as the call's latest, replacing the one
        held before)."""
        last = self._last.get(call)
        if last is None or t - last >= self._interval:
            self._last[call] = t
            self._held.pop(call, None)
            return item
        self._held[call] = item
        return None

    def finish(self, call: str) -> T | None:
        """``call`` ended (result, forced outcome, given up on): its held-back latest feedback, to
        journal before the result, or ``None``; the call is forgotten."""
        self._last.pop(call, None)
        return self._held.pop(call, None)

    def __len__(self) -> int:
        """Calls with a feedback state (started sending, not finished)."""
        return len(self._last)
