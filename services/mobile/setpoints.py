"""The steering set-point stream from the perception node to the drive node, and the drive's
watchdog (pure: no clocks of its own, no I/O).

Set points travel as authenticated events of the perception node on topic :data:`STEERING_TOPIC`
(``ctx.publish``; the drive node subscribes through its node link, as the catching testbed's
motion node takes its set points). Each event's data is a map
``{seq, t, v, curvature, left, right, t_sent[, t_capture]}``: sequence number (int, 0..2⁶³−1, increasing over the
whole stream), the camera frame's time on the simulation clock (s), speed (m/s), curvature (1/m),
the wheel speeds (rad/s, positive forward), the sender's wall clock and the frame's capture wall
clock (s; latency only, not checked beyond being ignored when unusable).

:class:`SteeringInput` (the drive node's side) checks each field (:func:`parse_setpoint`): a set point
that is malformed (missing or non-numeric field, bool, non-finite, out of range), **stale** (its
frame is more than ``stale_s`` older than the bus clock when it arrives), **not newer** (seq not
above the latest accepted) or a **jump** (seq more than 1,000 ahead of the latest accepted while the
stream is live, :class:`services.sequence.SequenceGate`) is dropped and counted, never used; the
latest accepted wins. After ``stale_s`` without an accepted set point (the watchdog has stopped the
wheels), a set point that would be dropped as not newer or as a jump restarts the stream instead (a
restarted perception node numbers its set points afresh); :attr:`SteeringInput.note` says so, for
the drive node's log.
**Watchdog:** with no accepted set point for ``stale_s`` — on the wall clock *and* on the bus clock,
so that a simulation slowed down by a loaded machine is not taken for a lost stream — the drive
commands zero wheel speed (a controlled stop on the drives' acceleration ramp) and counts a
watchdog stop; the next accepted set point resumes. Stop bound: ``stale_s`` to notice plus v/a on
the ramp (0.25 s + 16 rad/s ÷ 40 rad/s² = 0.65 s from 0.8 m/s), measured in docs/mobile.md.

The drive node publishes its odometry on :data:`ODOMETRY_TOPIC` (``{t, x, y, theta, s, v, w,
seq, stops, state}``: bus time, odometry pose, speeds, the latest set point applied, the watchdog
stops so far, ``"ok"`` / ``"enabling"`` (the wheel drives are being configured and enabled) /
``"watchdog"`` / ``"fault: ..."``); :func:`parse_odometry` checks it on the
perception node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from services.errors import MalformedSetPoint
from services.sequence import DEFAULT_MAX_STEP, SequenceGate, Verdict

from .odometry import Pose2D
from .steering import SteeringSetPoint

__all__ = [
    "MAX_CURVATURE",
    "MAX_SPEED",
    "MAX_WHEEL_SPEED",
    "ODOMETRY_TOPIC",
    "STEERING_TOPIC",
    "MalformedSetPoint",
    "Odometry",
    "SteeringInput",
    "parse_odometry",
    "parse_setpoint",
    "setpoint_to_dict",
]

STEERING_TOPIC = "steering"
ODOMETRY_TOPIC = "odometry"
MAX_SPEED = 5.0
"""|v| bound of a valid set point, m/s."""
MAX_CURVATURE = 100.0
"""|curvature| bound, 1/m."""
MAX_WHEEL_SPEED = 100.0
"""|left|, |right| bound, rad/s (the drives clamp to their own, lower, limit)."""
MAX_TIME = 1e10
MAX_SEQ = 2**63 - 1
MAX_KEYS = 32


def setpoint_to_dict(sp: SteeringSetPoint, t_sent: float, t_capture: float | None = None) -> dict[str, Any]:
    """The event data of set point ``sp`` (``t_sent``: the sender's wall clock, s; ``t_capture``: the
    wall clock at which its frame was captured, s, when known: for latency only)."""
    out = {"seq": sp.seq, "t": sp.t, "v": sp.v, "curvature": sp.curvature, "left": sp.left,
           "right": sp.right, "t_sent": t_sent}
    if t_capture is not None:
        out["t_capture"] = t_capture
    return out


def _number(d: dict[Any, Any], key: str, bound: float, *, non_negative: bool = False) -> float:
    if key not in d:
        raise MalformedSetPoint(f"no field {key!r}")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise MalformedSetPoint(f"field {key!r} is not a number: {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise MalformedSetPoint(f"field {key!r} is not finite: {x}")
    if abs(x) > bound or (non_negative and x < 0):
        raise MalformedSetPoint(f"field {key!r} out of range: {x}")
    return x


def _check_map(d: object) -> dict[Any, Any]:
    if not isinstance(d, dict):
        raise MalformedSetPoint(f"not a map: {type(d).__name__}")
    if len(d) > MAX_KEYS:
        raise MalformedSetPoint(f"{len(d)} keys (at most {MAX_KEYS})")
    return d


def parse_setpoint(data: object) -> SteeringSetPoint:
    """Validate one set point's event data field by field (unknown keys ignored).

    Raises:
        MalformedSetPoint: naming the first bad field.
    """
    d = _check_map(data)
    seq = d.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq <= MAX_SEQ:
        raise MalformedSetPoint(f"field 'seq' is not an integer in 0..2^63-1: {seq!r}")
    return SteeringSetPoint(
        seq=seq,
        t=_number(d, "t", MAX_TIME, non_negative=True),
        v=_number(d, "v", MAX_SPEED),
        curvature=_number(d, "curvature", MAX_CURVATURE),
        left=_number(d, "left", MAX_WHEEL_SPEED),
        right=_number(d, "right", MAX_WHEEL_SPEED),
    )


@dataclass(frozen=True, slots=True)
class Odometry:
    """The drive node's odometry message (see the module docstring)."""

    pose: Pose2D
    v: float
    w: float
    seq: int
    stops: int
    state: str


def parse_odometry(data: object) -> Odometry:
    """Validate an odometry event's data.

    Raises:
        MalformedSetPoint: naming the first bad field.
    """
    d = _check_map(data)
    t = _number(d, "t", MAX_TIME, non_negative=True)
    pose = Pose2D(_number(d, "x", 1e6), _number(d, "y", 1e6), _number(d, "theta", 1e3),
                  _number(d, "s", 1e9), t)
    seq, stops, state = d.get("seq", -1), d.get("stops", 0), d.get("state", "")
    if isinstance(seq, bool) or not isinstance(seq, int) or isinstance(stops, bool) or not isinstance(stops, int):
        raise MalformedSetPoint("fields 'seq' and 'stops' must be integers")
    if not isinstance(state, str) or len(state) > 500:
        raise MalformedSetPoint("field 'state' must be a short string")
    return Odometry(pose, _number(d, "v", MAX_SPEED * 10), _number(d, "w", 1e3), seq, stops, state)


class SteeringInput:
    """The drive node's holder of the latest set point, with the watchdog (module docstring).

    Args:
        stale_s: the staleness limit, s (wall clock and bus clock); also the silence after which
            the stream may restart with any sequence number.
        max_step: largest step of sequence numbers accepted while the stream is live.

    Attributes:
        accepted, malformed, stale, out_of_order, jumps: set points accepted / dropped by reason.
        restarts: times the stream restarted after a silence with a number out of step.
        watchdog_stops: times the watchdog stopped the wheels.
        stopped: True while the watchdog holds the wheels stopped.
        last_error: why the latest dropped set point was dropped.
        note: after :meth:`offer`, a line for the log when the set point jumped or restarted the
            stream, else ``None``.
    """

    def __init__(self, stale_s: float = 0.25, max_step: int = DEFAULT_MAX_STEP) -> None:
        if not stale_s > 0:
            raise ValueError(f"stale_s must be positive, got {stale_s}")
        self.stale_s = float(stale_s)
        self.latest: SteeringSetPoint | None = None
        self.accepted = self.malformed = self.stale = self.out_of_order = self.jumps = self.restarts = 0
        self.note: str | None = None
        self._gate = SequenceGate(self.stale_s, max_step)
        self.watchdog_stops = 0
        self.stopped = False
        self.last_error = ""
        self._wall = -math.inf
        self._bus = -math.inf

    def offer(self, data: object, wall: float, bus: float) -> SteeringSetPoint | None:
        """Take one event's data received at wall time ``wall`` and bus time ``bus`` (NaN if the bus
        clock is not known yet); returns the set point if accepted."""
        self.note = None
        try:
            sp = parse_setpoint(data)
        except MalformedSetPoint as exc:
            self.malformed += 1
            self.last_error = f"malformed: {exc}"
            return None
        if math.isfinite(bus) and bus - sp.t > self.stale_s:
            self.stale += 1
            self.last_error = f"stale: frame time {sp.t:.3f} s, bus time {bus:.3f} s"
            return None
        before = self._gate.latest
        silent = wall - self._gate.taken_at
        verdict = self._gate.judge(sp.seq, wall)
        if verdict is Verdict.OLD:
            self.out_of_order += 1
            self.last_error = f"seq {sp.seq} not above {before}"
            return None
        if verdict is Verdict.JUMP:
            self.jumps += 1
            self.last_error = (f"seq {sp.seq} is {sp.seq - (before or 0)} ahead of {before} (at most "
                               f"{self._gate.max_step} while the stream is live): refused")
            self.note = f"steering set point refused: {self.last_error}"
            return None
        if verdict is Verdict.RESTART:
            self.restarts += 1
            self.note = (f"steering stream restarted at seq {sp.seq} (latest was {before}, nothing accepted "
                         f"for {silent:.2f} s)")
        self.latest = sp
        self.accepted += 1
        self._wall, self._bus = wall, bus if math.isfinite(bus) else -math.inf
        self.stopped = False
        return sp

    def age(self, wall: float, bus: float) -> tuple[float, float]:
        """(wall, bus) age of the latest accepted set point, s (inf before the first)."""
        bus_age = bus - self._bus if math.isfinite(bus) and math.isfinite(self._bus) else wall - self._wall
        return wall - self._wall, bus_age

    def wheels(self, wall: float, bus: float) -> tuple[float, float]:
        """Wheel speeds (left, right) to command now, rad/s: the latest set point's, or (0, 0)
        once it is stale on both clocks (the watchdog; counted once per stop) or before any."""
        if self.latest is None:
            return 0.0, 0.0
        wall_age, bus_age = self.age(wall, bus)
        if wall_age > self.stale_s and bus_age > self.stale_s:
            if not self.stopped:
                self.stopped = True
                if self.latest.left != 0.0 or self.latest.right != 0.0:
                    self.watchdog_stops += 1
            return 0.0, 0.0
        return self.latest.left, self.latest.right

    def hold(self) -> None:
        """Forget the latest set point's wheel speeds (an explicit stop): zero until a newer one."""
        if self.latest is not None:
            self.latest = SteeringSetPoint(self.latest.seq, self.latest.t, 0.0, 0.0, 0.0, 0.0)
