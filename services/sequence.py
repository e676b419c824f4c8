"""Which sequence numbers a set-point stream takes: newer ones, within a bounded step (sans-IO).

Both testbeds stream set points as numbered events (the catching testbed's predicted catching
points, :mod:`services.catching.setpoints`; the mobile robot's steering, :mod:`services.mobile.setpoints`).
The receiver keeps the latest set point and drops older ones by sequence number. Taken alone, "newer
wins" lets one set point with a huge number (a forged one, or a publisher's bug) poison the stream:
every later legitimate set point is "older" and dropped, and the robot waits for a stream it no
longer hears (issue 22: a sequence number of 2**62 held a mission for 40 s). :class:`SequenceGate`
bounds the step instead:

* the first sequence number of a stream starts it (:attr:`Verdict.START`);
* a number above the latest accepted one by at most ``max_step`` is taken (:attr:`Verdict.NEXT`);
* a number not above the latest is dropped (:attr:`Verdict.OLD`): a late or repeated set point;
* a number further ahead than ``max_step`` is refused (:attr:`Verdict.JUMP`) while the stream is
  live: a publisher steps by one per set point, and loses at most a bounded backlog;
* once nothing was accepted for ``restart_after_s`` — the stream went silent: the receiver's own
  watchdog has stopped the robot by then — a number that would be dropped or refused restarts the
  stream explicitly instead (:attr:`Verdict.RESTART`), up or down: a publisher that restarted (with a new first number) is
  followed again, and a forged number holds the stream for at most that long.

The caller logs :attr:`Verdict.JUMP` and :attr:`Verdict.RESTART` (the gate does no I/O and reads no
clock: times are passed in, in seconds of the caller's clock).
"""

from __future__ import annotations

import enum
from typing import Final

__all__ = ["DEFAULT_MAX_STEP", "SequenceGate", "Verdict"]

DEFAULT_MAX_STEP: Final = 1000
"""Largest step between two accepted sequence numbers of a live stream (a publisher steps by one
per set point; 1,000 is 20 s of set points at 50 Hz, far more than any backlog drops)."""


class Verdict(enum.Enum):
    """What :meth:`SequenceGate.judge` decided about one sequence number."""

    START = "start"
    """The first number of the stream: taken."""
    NEXT = "next"
    """Above the latest accepted one, within the step: taken."""
    RESTART = "restart"
    """The stream was silent for ``restart_after_s``: taken whatever it is, the stream restarts."""
    OLD = "old"
    """Not above the latest accepted one: dropped."""
    JUMP = "jump"
    """Further ahead than ``max_step`` while the stream is live: refused."""

    @property
    def taken(self) -> bool:
        """Whether the set point carrying the number is used."""
        return self in (Verdict.START, Verdict.NEXT, Verdict.RESTART)


class SequenceGate:
    """The sequence numbers of one stream (see the module docstring).

    Args:
        restart_after_s: silence (no number taken), seconds, after which any number restarts the
            stream; the receiver's staleness limit, so that the robot is already stopped.
        max_step: largest step accepted between two numbers of a live stream.

    Attributes:
        latest: the latest number taken, or ``None`` before the first.
        taken_at: when it was taken, s.

    Raises:
        ValueError: ``restart_after_s`` is not positive or ``max_step`` < 1.
    """

    __slots__ = ("latest", "max_step", "restart_after_s", "taken_at")

    def __init__(self, restart_after_s: float, max_step: int = DEFAULT_MAX_STEP) -> None:
        if not restart_after_s > 0 or max_step < 1:
            raise ValueError(f"restart_after_s must be positive and max_step >= 1, got {restart_after_s}, {max_step}")
        self.restart_after_s = float(restart_after_s)
        self.max_step = int(max_step)
        self.latest: int | None = None
        self.taken_at = 0.0

    def judge(self, seq: int, now: float) -> Verdict:
        """Judge number ``seq`` received at ``now`` (s); a number taken becomes :attr:`latest`."""
        latest = self.latest
        if latest is None:
            verdict = Verdict.START
        elif latest < seq <= latest + self.max_step:
            verdict = Verdict.NEXT
        elif now - self.taken_at >= self.restart_after_s and seq != latest:
            verdict = Verdict.RESTART
        else:
            return Verdict.OLD if seq <= latest else Verdict.JUMP
        self.latest = seq
        self.taken_at = now
        return verdict

    def reset(self) -> None:
        """Forget the stream: the next number starts it again."""
        self.latest = None
