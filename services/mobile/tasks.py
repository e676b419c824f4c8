"""The mobile robot's primitive tasks as pure, steppable controllers (paper section 6, Fig. 3).

Each primitive action of the course is a controller stepped once per camera frame with the frame's
time, the odometry pose at that time and the image (and, for the beacon tasks, the beacon scans):
it returns a :class:`Step` — the steering set point to stream to the drives and, when the task
has ended, its outcome. The perception node's actions (:mod:`services.mobile.perception_node`) run them
on frames from the camera server and odometry from the drive node; ``bench/mobile.py`` runs the
same controllers in process in lock-step. What one task leaves for the next (the last track
estimate, where the track ended, the beacon sightings of the last second, the T bar's position,
the numbered set-point stream) lives in one :class:`Course` memory shared by the tasks.

Tasks and outcomes (the names the net ``nets/mobile.toml`` links to):

* :class:`FollowTrack` (detector ``centroid``, ``ransac`` or ``scanline``: the learner's three
  alternatives) — ``interruption`` (the track vanished for ``gap`` m of travel while it was
  last seen straight ahead: a blank square), ``end`` (the T bar seen on ``end_frames`` consecutive
  frames), or ``lost`` (never seen, or last seen sliding out of the view sideways; :data:`LOST_OFFSET`);
* :class:`FindBeacon` — ``found`` (a reflector stands at one of the blank square's three possible
  exits) or ``not_found`` (none within ``find_window`` s; the robot is stopped);
* :class:`GotoBeacon` — ``ok`` within ``reacquire_window`` m of the resume point;
* :class:`ReacquireTrack` — ``ok`` (the track seen again where expected) or ``lost`` (passed the
  resume point by ``max_overshoot`` m without it);
* :class:`StopAtT` — ``ok`` once stopped on the T bar (odometry).

Units SI (m, s, rad, rad/s). Pure: numpy/OpenCV only, no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .beacon import BeaconApproach, BeaconModel, BeaconObservation, Reacquire
from .camera import GroundCamera
from .lines import LineEstimate, make_detector
from .marks import EndMarkDetector, GapMonitor
from .odometry import DriveGeometry, Pose2D
from .steering import PurePursuit, SteeringSetPoint, SpeedLimits, SteeringController

__all__ = [
    "DETECTORS",
    "CourseMemory",
    "FindBeacon",
    "FollowTrack",
    "GotoBeacon",
    "ReacquireTrack",
    "Step",
    "StopAtT",
    "TaskParams",
]

DETECTORS = ("centroid", "ransac", "scanline")
"""Track detectors, one per alternative primitive action of *follow track*."""

LOST_OFFSET = 0.06
"""When the track vanishes, it was an interruption if the robot last saw it ahead (within this
lateral distance of the robot's axis at the look-ahead, or at the nearest end of the stretch of
track last seen, m): a painted track ends at a blank square's
edge straight ahead of a robot that follows it; a track last seen further off slid out of the view
sideways: the robot is off the track (outcome ``lost``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class TaskParams:
    """Tuning of the tasks (SI units; the phase-1 mission's values, ``docs/mobile.md``)."""

    cruise: float = 0.8
    approach_speed: float = 0.6
    look_ahead: float = 0.26
    gap: float = 0.06
    min_confidence: float = 0.3
    max_offset: float = 0.12
    end_frames: int = 3
    stop_decel: float = 1.0
    reacquire_window: float = 0.6
    max_overshoot: float = 0.6
    find_window: float = 0.5
    square: float = 2.0
    track_width: float = 0.05

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> TaskParams:
        """Override the defaults from an action's params (unknown keys ignored).

        Raises:
            ValueError: a value is not a finite positive number (``end_frames``: a positive int).
        """
        kw: dict[str, Any] = {}
        for name in cls.__dataclass_fields__:
            if name in params:
                v = params[name]
                if name == "end_frames":
                    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                        raise ValueError(f"end_frames must be a positive integer, got {v!r}")
                elif not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
                    raise ValueError(f"{name} must be a positive number, got {v!r}")
                kw[name] = v
        return cls(**kw)


@dataclass(frozen=True, slots=True)
class Step:
    """What a task gives for one frame.

    Attributes:
        setpoint: the steering set point to stream.
        outcome: None while the task runs; its outcome name once it has ended.
        success: whether that outcome is a success (meaningless while running).
        note: why it ended, in words.
    """

    setpoint: SteeringSetPoint
    outcome: str | None = None
    success: bool = True
    note: str = ""


@dataclass
class CourseMemory:
    """What the tasks of one course share (built once per run by the perception side).

    Args (fields):
        camera: the downward camera model.
        geometry: the drive geometry the wheel speeds are computed with.
        beacon: the beacon sensor model.
        params: the tuning.
        seq0: first sequence number of the set-point stream (the perception node starts it from
            its wall clock in microseconds so that a restarted node's stream is still increasing).
    """

    camera: GroundCamera
    geometry: DriveGeometry
    beacon: BeaconModel
    params: TaskParams = field(default_factory=TaskParams)
    seq0: int = 0
    steering: SteeringController = field(init=False)
    pursuit: PurePursuit = field(init=False)
    end_detector: EndMarkDetector = field(init=False)
    approach: BeaconApproach = field(init=False)
    reacquire: Reacquire = field(init=False)
    sightings: deque[tuple[Pose2D, list[BeaconObservation]]] = field(init=False)
    detectors: dict[str, Any] = field(init=False)
    last_line: tuple[Pose2D, LineEstimate] | None = None
    heading: float | None = None
    curvature: float = 0.0
    stops: list[float] = field(default_factory=list)
    interruptions: int = 0

    def __post_init__(self) -> None:
        p = self.params
        self.steering = SteeringController(self.geometry, SpeedLimits(cruise=p.cruise))
        self.steering.seq = int(self.seq0)
        self.pursuit = PurePursuit(look_ahead=p.look_ahead)
        self.end_detector = EndMarkDetector(camera=self.camera, bar_width=p.track_width)
        self.approach = BeaconApproach(self.beacon, square=p.square)
        self.reacquire = Reacquire(at_x=p.look_ahead)
        self.sightings = deque()
        self.detectors = {}

    def detector(self, name: str) -> Any:
        """The track detector ``name`` (one of :data:`DETECTORS`), made once.

        Raises:
            ValueError: unknown name.
        """
        if name not in DETECTORS:
            raise ValueError(f"unknown track detector {name!r} (one of {', '.join(DETECTORS)})")
        if name not in self.detectors:
            self.detectors[name] = make_detector(name, self.camera, track_width=self.params.track_width)
        return self.detectors[name]

    def observe_beacons(self, pose: Pose2D, observations: list[BeaconObservation]) -> None:
        """Keep a beacon scan taken at ``pose`` (the sightings of the last second are kept)."""
        self.sightings.append((pose, list(observations)))
        while self.sightings and pose.t - self.sightings[0][0].t > 1.0:
            self.sightings.popleft()

    def track(self, line: LineEstimate | None, *, gate: bool = True) -> LineEstimate | None:
        """The line if it counts as the track (confidence, and within ``max_offset`` at the
        look-ahead unless ``gate`` is False), else None."""
        p = self.params
        if line is None or line.confidence < p.min_confidence:
            return None
        if gate and abs(line.lateral_at(p.look_ahead)) > p.max_offset:
            return None
        return line

    def stop(self, t: float) -> SteeringSetPoint:
        """A zero-speed set point at ``t``."""
        return self.steering.stop(t)


class FollowTrack:
    """Follow the track with one detector until an interruption, the T, or the track is lost.

    Args:
        memory: the course memory.
        detector: ``centroid``, ``ransac`` or ``scanline``.

    Attributes:
        frames, seen: frames processed, frames on which the track was seen.
        distance: odometry distance driven since :meth:`start`, m.
    """

    def __init__(self, memory: CourseMemory, detector: str) -> None:
        self.m = memory
        self.name = detector
        self.detector = memory.detector(detector)
        self.gap = GapMonitor(memory.params.gap)
        self.frames = 0
        self.seen = 0
        self.dropouts = 0
        self.distance = 0.0
        self._s0: float | None = None
        self._end_hits = 0
        self._missing = False

    def start(self, pose: Pose2D) -> None:
        """Start at ``pose`` (the gap counts from here)."""
        self._s0 = pose.s
        self.gap.reset(pose.s)
        self._end_hits = 0

    def step(self, t: float, pose: Pose2D, image: np.ndarray) -> Step:
        """One frame (see the module docstring for the outcomes)."""
        m, p = self.m, self.m.params
        if self._s0 is None:
            self.start(pose)
        assert self._s0 is not None
        self.frames += 1
        self.distance = pose.s - self._s0
        mark = m.end_detector.detect(image)
        self._end_hits = self._end_hits + 1 if mark is not None else 0
        if mark is not None:
            m.stops.append(pose.s + mark.x)
            if self._end_hits >= p.end_frames:
                return Step(m.steering.command(t, p.cruise, m.curvature), "end", True, f"T bar {mark.x:.3f} m ahead")
        line = m.track(self.detector.detect(image))
        if line is not None:
            self.seen += 1
            if self._missing:
                self.dropouts += 1  # the track was there all along: the detector lost it for a while
                self._missing = False
            self.gap.update(True, pose.s)
            m.last_line = (pose, line)
            if line.confidence >= 0.5:
                m.heading = pose.theta + line.heading
            m.curvature = m.pursuit.curvature(line)
            return Step(m.steering.command(t, p.cruise, m.curvature))
        self._missing = self.seen > 0
        if self.gap.update(False, pose.s):
            if m.last_line is None:
                return Step(m.stop(t), "lost", False, "no track seen")
            ln = m.last_line[1]
            off = ln.lateral_at(min(max(p.look_ahead, ln.x_min), ln.x_max))
            if abs(off) > LOST_OFFSET:
                return Step(m.stop(t), "lost", False,
                            f"track slid out of view ({off * 1000:+.0f} mm off the robot's axis when last seen)")
            m.interruptions += 1
            return Step(m.steering.command(t, p.approach_speed, m.curvature), "interruption", True,
                        f"no track for {self.gap.missing(pose.s):.3f} m")
        return Step(m.steering.command(t, p.cruise, m.curvature))


    def judge(self, outcome: str, max_dropouts: int = 0) -> tuple[bool, str]:
        """The follow segment against its specification: it ended with ``interruption`` or ``end``
        and the detector lost the track at most ``max_dropouts`` times on the way (a loss shorter
        than the gap, after which the track was seen again: it was there all along).

        Returns:
            (within specification, why not in words or "").
        """
        if outcome not in ("interruption", "end"):
            return False, f"ended {outcome}"
        if self.dropouts > max_dropouts:
            return False, f"the detector lost the track {self.dropouts} times (at most {max_dropouts} allowed)"
        return True, ""


class FindBeacon:
    """Pick the reflector at one of the blank square's possible exits from the recent sightings.

    Drives on along the last curvature at the approach speed while it waits for sightings, at most
    ``find_window`` s.
    """

    def __init__(self, memory: CourseMemory) -> None:
        self.m = memory
        self._t0: float | None = None

    def step(self, t: float, pose: Pose2D, beacons: list[BeaconObservation] | None = None) -> Step:
        """One frame; ``beacons``: a scan taken at this frame, if any."""
        m, p = self.m, self.m.params
        if beacons is not None:
            m.observe_beacons(pose, beacons)
        if self._t0 is None:
            self._t0 = t
        if m.last_line is None:
            return Step(m.stop(t), "not_found", False, "no track seen before the interruption")
        lp, ln = m.last_line
        ex, ey = lp.to_world(ln.x_max, ln.lateral_at(ln.x_max))
        heading = m.heading if m.heading is not None else lp.theta
        if m.approach.start((ex, ey, heading), list(m.sightings)):
            m.reacquire.reset()
            exit_name = ("straight", "left", "right")[m.approach.exit_index]
            return Step(m.steering.command(t, p.approach_speed, m.curvature), "found", True, f"exit {exit_name}")
        if t - self._t0 >= p.find_window:
            return Step(m.stop(t), "not_found", False, "no beacon at an expected exit")
        return Step(m.steering.command(t, p.approach_speed, m.curvature))


class GotoBeacon:
    """Pure pursuit across the blank square to the resume point under the beacon."""

    def __init__(self, memory: CourseMemory) -> None:
        self.m = memory

    def step(self, t: float, pose: Pose2D, beacons: list[BeaconObservation] | None = None) -> Step:
        """One frame; ``ok`` once within ``reacquire_window`` of the resume point."""
        m, p = self.m, self.m.params
        if beacons:
            m.approach.observe(pose, beacons)
        m.curvature = m.approach.curvature(pose)
        sp = m.steering.command(t, p.approach_speed, m.curvature)
        if m.approach.remaining(pose) < p.reacquire_window:
            return Step(sp, "ok", True, f"{m.approach.remaining(pose):.2f} m from the resume point")
        return Step(sp)


class ReacquireTrack:
    """Near the resume point: keep on the pursuit until the track is seen again where expected."""

    def __init__(self, memory: CourseMemory, detector: str = "ransac") -> None:
        self.m = memory
        self.detector = memory.detector(detector)

    def step(self, t: float, pose: Pose2D, image: np.ndarray,
             beacons: list[BeaconObservation] | None = None) -> Step:
        """One frame; ``ok`` on the track again, ``lost`` past the resume point without it."""
        m, p = self.m, self.m.params
        if beacons:
            m.approach.observe(pose, beacons)
        line = m.track(self.detector.detect(image), gate=False)
        if m.reacquire.update(line):
            assert line is not None
            m.last_line = (pose, line)
            m.heading = None
            m.curvature = m.pursuit.curvature(line)
            return Step(m.steering.command(t, p.approach_speed, m.curvature), "ok", True, "track reacquired")
        assert m.approach.target is not None
        gx, _ = pose.to_local(*m.approach.target[:2])
        if gx < -p.max_overshoot:
            return Step(m.stop(t), "lost", False, "track not found again after the beacon")
        m.curvature = m.approach.curvature(pose)
        return Step(m.steering.command(t, p.approach_speed, m.curvature))


class StopAtT:
    """Brake to a stop on the T bar: the stop point is the median of the bar's positions seen."""

    def __init__(self, memory: CourseMemory, detector: str = "ransac") -> None:
        self.m = memory
        self.detector = memory.detector(detector)
        self.remaining = math.nan

    def step(self, t: float, pose: Pose2D, image: np.ndarray) -> Step:
        """One frame; ``ok`` once stopped (within 5 mm of the stop point or below 3 cm/s)."""
        m, p = self.m, self.m.params
        mark = m.end_detector.detect(image)
        if mark is not None:
            m.stops.append(pose.s + mark.x)
        if not m.stops:
            return Step(m.stop(t), "ok", True, "no T bar position known: stopped where it is")
        target = float(np.median(m.stops[-8:]))
        self.remaining = remaining = target - pose.s
        line = m.track(self.detector.detect(image))
        if line is not None and line.x_min < remaining:
            m.curvature = m.pursuit.curvature(line)
        else:
            m.curvature = 0.0
        v = min(p.cruise, math.sqrt(2.0 * p.stop_decel * max(0.0, remaining)))
        if remaining <= 0.005 or v < 0.03:
            return Step(m.stop(t), "ok", True, f"stopped {remaining:+.3f} m from the T bar (odometry)")
        return Step(m.steering.command(t, v, m.curvature))
