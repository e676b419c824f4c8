"""Set points from the vision node to the motion node (paper section 6).

"The image processing PC sends set points periodically to the motion control PC using TCP/IP
sockets. The set points represent the predicted catching points." Here the set points travel inside
the node protocol (docs/protocol.md), which is already authenticated (HMAC handshake with the shared
key), framed, size-capped and validated: the vision node publishes each set point as an event on
topic :data:`SETPOINT_TOPIC` (``ctx.publish``), and the motion node subscribes to that topic on the
node that publishes it through the node's own authenticated link (``ctx.node.link(node)``). A
process without the key cannot connect, let alone steer the arm; a connection that opens and closes
cannot end a catch; a set point whose fields are not what :meth:`CatchSetPoint.from_dict` expects is
dropped and counted, never used.

Layers, sans-IO style: :class:`CatchSetPoint` (validation), :class:`LatestSetPoint` (latest wins,
staleness judged with a time passed in, malformed set points counted); :class:`SetPointSubscription`
is the thin shell that feeds a holder from a node link's events.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, fields
from typing import TYPE_CHECKING, Any

from services.errors import ActionError, MalformedSetPoint
from services.sequence import DEFAULT_MAX_STEP, SequenceGate, Verdict

from services.node.logs import LogLimiter

if TYPE_CHECKING:
    from services.client import NodeLink
    from services.protocol import Event

__all__ = [
    "MAX_SEQ",
    "SETPOINT_TOPIC",
    "CatchSetPoint",
    "LatestSetPoint",
    "MalformedSetPoint",
    "SetPointSubscription",
    "StreamLostError",
    "received_map",
    "received_number",
    "received_seq",
]

log = logging.getLogger(__name__)
_limited = LogLimiter(log)

SETPOINT_TOPIC = "setpoints"
"""The event topic on which the node hosting ``predict`` publishes set points."""

MAX_SEQ = 2**63
"""Sequence numbers are integers in ``0 .. MAX_SEQ - 1`` (an int64 on the wire)."""

MAX_FIELDS = 32
"""A set-point map with more keys than this is refused before any field is read."""

#: Largest magnitude accepted per field: metres, seconds (sim or Unix time), m/s.
_BOUNDS: Mapping[str, float] = {
    "t_frame": 1e10, "t_capture": 1e10, "t_sent": 1e10, "t": 1e10,
    "x": 100.0, "y": 100.0, "vx": 100.0, "vy": 100.0, "sigma_y": 100.0, "sigma_t": 1e4,
}
_OPTIONAL = frozenset({"sigma_y", "sigma_t"})


class StreamLostError(ActionError):
    """No fresh set point: the stream never started, went stale, or the link to its node is down."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CatchSetPoint:
    """A predicted catching point, as the vision side sends it to the motion side (the mobile
    robot's set points are :class:`services.mobile.steering.SteeringSetPoint`).

    Coordinates are in the table frame of :mod:`sim.catching.world` (x towards the robot, catch line at
    x = 0); times ``t_frame`` and ``t`` are on the camera's clock (simulated time in the sim),
    ``t_capture`` and ``t_sent`` on the host's wall clock (:func:`time.time`, for latency).

    Attributes:
        seq: sequence number, increasing by one per set point of a ``predict`` call, 0 .. 2**63 - 1.
        t_frame: timestamp of the camera frame the prediction used, s.
        t_capture: wall-clock time the frame was captured, s.
        t_sent: wall-clock time the set point was sent, s.
        x, y: predicted point where the ball crosses the catch line, m.
        t: predicted time of the crossing, s (camera clock).
        vx, vy: predicted ball velocity at the crossing, m/s.
        sigma_y: 1-σ uncertainty of y, m (≥ 0).
        sigma_t: 1-σ uncertainty of t, s (≥ 0).
    """

    seq: int
    t_frame: float
    t_capture: float
    t_sent: float
    x: float
    y: float
    t: float
    vx: float
    vy: float
    sigma_y: float = 0.0
    sigma_t: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """The set point as a plain dict (msgpack-able)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: object) -> CatchSetPoint:
        """Build from a received map, checking every field.

        ``seq`` must be an ``int`` (not a bool) in ``0 .. 2**63 - 1``; every other field a finite
        int or float within a physical bound (|x|, |y| ≤ 100 m, |vx|, |vy| ≤ 100 m/s, times
        ≤ 1e10 s, sigmas ≥ 0); ``sigma_y``/``sigma_t`` may be left out (0); unknown keys are
        ignored; a map of more than :data:`MAX_FIELDS` keys is refused.

        Raises:
            MalformedSetPoint: naming the first field that is missing or wrong.
        """
        m = received_map(d)
        kw: dict[str, Any] = {}
        for f in fields(cls):
            name = f.name
            if name not in m and name in _OPTIONAL:
                continue
            if name == "seq":
                kw[name] = received_seq(m)
            else:
                kw[name] = received_number(m, name, _BOUNDS[name], non_negative=name in _OPTIONAL)
        return cls(**kw)


def received_map(d: object) -> dict[Any, Any]:
    """A received set point's map, refused before any field is read when it is not a map or has
    more than :data:`MAX_FIELDS` keys.

    Raises:
        MalformedSetPoint: saying which.
    """
    if not isinstance(d, dict):
        raise MalformedSetPoint(f"a set point must be a map, not {type(d).__name__}")
    if len(d) > MAX_FIELDS:
        raise MalformedSetPoint(f"a set point has at most {MAX_FIELDS} fields, got {len(d)}")
    return d


def received_seq(d: Mapping[Any, Any], name: str = "seq") -> int:
    """Field ``name`` of a received map as a sequence number: an ``int`` (not a bool) in
    ``0 .. MAX_SEQ - 1``.

    Raises:
        MalformedSetPoint: naming the field.
    """
    if name not in d:
        raise MalformedSetPoint(f"set point without {name!r}")
    v = d[name]
    if type(v) is not int or not 0 <= v < MAX_SEQ:
        raise MalformedSetPoint(f"set point {name} must be an integer in 0..2**63-1, got {v!r:.40}")
    return v


def received_number(d: Mapping[Any, Any], name: str, bound: float, *, non_negative: bool = False) -> float:
    """Field ``name`` of a received map as a finite number within ±``bound`` (and ≥ 0 when
    ``non_negative``); an ``int`` or ``float``, never a bool.

    Raises:
        MalformedSetPoint: naming the field: missing, not a number, not finite, out of range or
            negative.
    """
    if name not in d:
        raise MalformedSetPoint(f"set point without {name!r}")
    v = d[name]
    if type(v) not in (int, float):
        raise MalformedSetPoint(f"set point {name} must be a number, got {type(v).__name__}")
    x = float(v)
    if not math.isfinite(x) or abs(x) > bound:
        raise MalformedSetPoint(f"set point {name} = {x!r} is not finite within ±{bound:g}")
    if non_negative and x < 0:
        raise MalformedSetPoint(f"set point {name} = {x!r} is negative")
    return x


class LatestSetPoint:
    """Holds the latest set point of a stream (latest wins) and judges its freshness (sans-IO).

    Freshness is judged on two clocks: the receiver's wall clock (time since the latest set point
    arrived) and, when the caller passes it, the camera's clock the set points are stamped with
    (the bus time on the motion node; simulated time in the sim). The latest set point is stale
    when it is older than ``max_age`` on both: a simulation that runs slower than real time on a
    loaded machine delivers frames, hence set points, further apart in wall time without anything
    being lost, while a vision side that stopped lets both ages grow.

    Sequence numbers go through a :class:`services.sequence.SequenceGate`: a set point not newer than
    the latest is dropped, one more than ``max_step`` ahead of it while the stream is live is refused
    (a forged or buggy number must not make every later set point look old), and after ``max_age``
    without a set point taken one out of step restarts the stream (:attr:`note` says so).

    Args:
        max_age: a set point older than this (s) is stale.
        max_step: largest step of sequence numbers accepted while the stream is live.

    Attributes:
        latest: the latest accepted set point (``None`` before the first).
        received_at: receive time of :attr:`latest`, s.
        received: set points offered (well-formed or not).
        dropped: well-formed set points not newer than the latest (by ``seq``).
        jumps: well-formed set points refused for a sequence number too far ahead.
        restarts: times the stream restarted after a silence with a number out of step.
        malformed: set points refused by :meth:`CatchSetPoint.from_dict`.
        last_malformed: why the latest malformed one was refused.
        note: after an offer, a line for the log when the set point jumped or restarted the stream.
    """

    def __init__(self, max_age: float = 0.2, max_step: int = DEFAULT_MAX_STEP) -> None:
        self.max_age = max_age
        self.latest: CatchSetPoint | None = None
        self.received_at: float | None = None
        self.received = 0
        self.dropped = 0
        self.jumps = 0
        self.restarts = 0
        self.malformed = 0
        self.last_malformed: str | None = None
        self.closed_reason: str | None = None
        self.note: str | None = None
        self._gate = SequenceGate(max_age, max_step)

    def offer(self, sp: CatchSetPoint, now: float) -> bool:
        """Offer a received set point at time ``now`` (s); True if it became the latest.

        A set point whose seq is not newer than the latest one's is dropped (counted in
        :attr:`dropped`), one too far ahead refused (:attr:`jumps`).
        """
        self.received += 1
        self.note = None
        before = self._gate.latest
        silent = now - self._gate.taken_at
        verdict = self._gate.judge(sp.seq, now)
        if verdict is Verdict.OLD:
            self.dropped += 1
            return False
        if verdict is Verdict.JUMP:
            self.jumps += 1
            self.note = (f"set point refused: seq {sp.seq} is {sp.seq - (before or 0)} ahead of {before} (at most "
                         f"{self._gate.max_step} while the stream is live)")
            return False
        if verdict is Verdict.RESTART:
            self.restarts += 1
            self.note = f"set-point stream restarted at seq {sp.seq} (latest was {before}, none for {silent:.2f} s)"
        self.latest = sp
        self.received_at = now
        return True

    def offer_data(self, data: object, now: float) -> CatchSetPoint | None:
        """Offer a received map; returns the set point if it became the latest, else ``None``.

        A malformed map is counted (:attr:`malformed`, :attr:`last_malformed`) and dropped; it never
        raises and never changes the latest set point.
        """
        try:
            sp = CatchSetPoint.from_dict(data)
        except MalformedSetPoint as exc:
            self.received += 1
            self.note = None
            self.malformed += 1
            self.last_malformed = str(exc)
            return None
        return sp if self.offer(sp, now) else None

    def close(self, reason: str) -> None:
        """Mark the stream as lost for good (no later set point is fresh)."""
        if self.closed_reason is None:
            self.closed_reason = reason

    def age(self, now: float) -> float:
        """Seconds since the latest set point was received (infinite before the first)."""
        return math.inf if self.received_at is None else now - self.received_at

    def get(self, now: float, camera_now: float | None = None) -> CatchSetPoint:
        """The latest set point, if fresh at time ``now`` (s, same clock as :meth:`offer`).

        Args:
            now: the receiver's wall clock, s.
            camera_now: the present time on the set points' camera clock (``t_frame``), s, if
                known; then the set point is stale only if its frame is older than ``max_age`` too.

        Raises:
            StreamLostError: if the stream is closed, never delivered, or the latest set point is
                older than ``max_age`` (on both clocks when ``camera_now`` is given).
        """
        if self.closed_reason is not None:
            raise StreamLostError(f"set-point stream lost: {self.closed_reason}")
        if self.latest is None or self.received_at is None:
            raise StreamLostError("no set point received yet")
        age = now - self.received_at
        if age > self.max_age:
            if camera_now is None or not math.isfinite(camera_now):
                raise StreamLostError(f"set-point stream stale: last set point {age:.3f} s old")
            frame_age = camera_now - self.latest.t_frame
            if frame_age > self.max_age:
                raise StreamLostError(f"set-point stream stale: last set point {age:.3f} s old "
                                      f"({frame_age:.3f} s on the camera clock)")
        return self.latest


class SetPointSubscription:
    """Set points received as events of one node, through an authenticated node link.

    :meth:`start` subscribes ``topic`` on the link (the link reconnects and resubscribes by
    itself); each event's data is offered to :attr:`state`; :meth:`restart` gives a fresh holder
    (a new catch only takes set points that arrive after it started).

    Args:
        link: the link to the node that publishes the set points (``ctx.node.link(name)``).
        topic: the event topic.
        max_age: staleness limit, s (see :class:`LatestSetPoint`).
        clock: wall clock used for receive times (default :func:`time.time`).
        on_set_point: optional callback for each set point that becomes the latest, with the set
            point and its receive time.
    """

    def __init__(
        self,
        link: NodeLink,
        topic: str = SETPOINT_TOPIC,
        *,
        max_age: float = 0.2,
        clock: Callable[[], float] = time.time,
        on_set_point: Callable[[CatchSetPoint, float], None] | None = None,
    ) -> None:
        self.link = link
        self.topic = topic
        self.clock = clock
        self.on_set_point = on_set_point
        self.state = LatestSetPoint(max_age)
        self.events = 0
        """Events received on the topic since :meth:`start`."""
        self._started = False

    @property
    def node(self) -> str:
        """Name of the publishing node."""
        return self.link.node

    def start(self) -> None:
        """Subscribe (idempotent); must run in the event loop of the link."""
        if not self._started:
            self._started = True
            self.link.subscribe(self.topic, self._on_event)

    def restart(self) -> LatestSetPoint:
        """A fresh holder (same ``max_age``); returns it."""
        self.state = LatestSetPoint(self.state.max_age)
        return self.state

    def latest(self, camera_now: float | None = None) -> CatchSetPoint:
        """The latest fresh set point (``camera_now``: see :meth:`LatestSetPoint.get`).

        Raises:
            StreamLostError: stale or none yet; the message says whether the link is down.
        """
        try:
            return self.state.get(self.clock(), camera_now)
        except StreamLostError as exc:
            if not self.link.connected:
                raise StreamLostError(f"{exc} (link to node {self.node} is down)") from None
            raise

    def close(self) -> None:
        """Unsubscribe."""
        if self._started:
            self._started = False
            self.link.unsubscribe(self.topic, self._on_event)

    def _on_event(self, event: Event) -> None:
        self.events += 1
        now = self.clock()
        state = self.state
        sp = state.offer_data(event.data, now)
        if state.note is not None:
            _limited.log(logging.WARNING if sp is None else logging.INFO, ("setpoints", sp is None), "node %s: %s",
                         self.node, state.note)
        if sp is not None and self.on_set_point is not None:
            self.on_set_point(sp, now)
