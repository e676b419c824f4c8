"""Closed-loop runs of the mobile-robot task in lock-step simulated time (one process, no sockets).

Paper section 6 ("Mobile Robot Task", Fig. 3): follow the track; on an interruption, find the
retroreflector, go to it across the blank square and pick the track up again; stop on the T mark.

:class:`MobileMission` sequences the pure primitive actions of :mod:`services.mobile` — it stands
in for the interpreted Petri net of Fig. 3, which will take over the sequencing when the actions
run on the robot's nodes. Each control tick (50 Hz) it takes the latest camera image, the wheel
encoder angles and, when the beacon sensor scanned, its observations, and returns a drive set
point. Phases:

* ``FOLLOW`` — track detector → pure pursuit at cruise speed; the end-mark detector watches for
  the T; the gap monitor declares an interruption after ``gap`` m without track (the robot keeps
  its last curvature meanwhile);
* ``APPROACH`` — :class:`services.mobile.beacon.BeaconApproach` picks the beacon at one of the
  blank square's expected exits from the sightings of the last second, and pure pursuit drives to
  the fused resume point; near it :class:`services.mobile.beacon.Reacquire` hands back to FOLLOW;
* ``STOPPING`` — the T bar's position (odometry path length + its distance in the image, averaged
  over the frames that see it) gives the stop point; speed follows √(2·a·d) to zero;
* ``DONE`` / ``FAILED`` (with a reason: no beacon, track not found again, ...).

:func:`run_course` builds a :class:`sim.mobile.world.MobileWorld`, runs the mission with the
analytic (or TinyRenderer) camera and scores it against ground truth (:class:`RunResult`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any

import numpy as np

from services.mobile.beacon import (
    BeaconApproach,
    BeaconModel,
    BeaconObservation,
    Reacquire,
)
from services.mobile.camera import GroundCamera
from services.mobile.lines import LineEstimate, make_detector
from services.mobile.marks import EndMarkDetector, GapMonitor
from services.mobile.odometry import DriveGeometry, Odometry, Pose2D
from services.mobile.steering import (
    PurePursuit,
    SteeringSetPoint,
    SpeedLimits,
    SteeringController,
)
from services.mobile.tasks import TaskParams

from ..world import ClockMode, World
from .course import Course
from .robot import RobotSpec
from .sensors import ImageNoise
from .world import DEFAULT_DT, MobileWorld

__all__ = ["MissionParams", "MobileMission", "Phase", "RunResult", "run_course"]


class Phase(Enum):
    """Phase of the mobile mission."""

    FOLLOW = "follow"
    APPROACH = "approach"
    STOPPING = "stopping"
    DONE = "done"
    FAILED = "failed"


_TASKS = TaskParams()


@dataclass(frozen=True, slots=True, kw_only=True)
class MissionParams:
    """Tuning of the mission (units SI).

    Attributes:
        detector: track detector name (``ransac``, ``centroid``, ``scanline``).
        control_rate: control ticks (camera frames) per second.
        beacon_rate: beacon sensor scans per second.
        cruise: speed while following, m/s.
        approach_speed: speed across an interruption, m/s.
        look_ahead: pure-pursuit goal distance on the track, m.
        gap: travel without track before an interruption is declared, m.
        min_confidence: least detector confidence for a frame to count as seeing the track.
        max_offset: while following, a line whose lateral position at the look-ahead is further
            off than this is not the track being followed (a scuff, a mark), m.
        end_frames: consecutive frames that must show the T bar before stopping.
        stop_decel: deceleration of the final stop, m/s².
        reacquire_window: the track detector is consulted for reacquisition within this distance
            of the resume point, m.
        max_overshoot: the approach fails when the robot passes the resume point by this much
            without finding the track, m.
        odometry_scale: ratio of the wheel radius the odometry assumes to the true one (a
            calibration error; 1 = exact).
    """

    detector: str = "ransac"
    control_rate: float = 50.0
    beacon_rate: float = 20.0
    # the nodes' task tuning is the one source of these defaults
    cruise: float = _TASKS.cruise
    approach_speed: float = _TASKS.approach_speed
    look_ahead: float = _TASKS.look_ahead
    gap: float = _TASKS.gap
    min_confidence: float = _TASKS.min_confidence
    max_offset: float = _TASKS.max_offset
    end_frames: int = _TASKS.end_frames
    stop_decel: float = _TASKS.stop_decel
    reacquire_window: float = _TASKS.reacquire_window
    max_overshoot: float = _TASKS.max_overshoot
    odometry_scale: float = 1.0

    def task_params(self, *, square: float, track_width: float) -> TaskParams:
        """The nodes' task tuning (:class:`services.mobile.tasks.TaskParams`) with this mission's
        values for the fields both have, on a floor of ``square`` m squares and a ``track_width`` m
        track."""
        shared = {f.name: getattr(self, f.name) for f in fields(TaskParams) if hasattr(self, f.name)}
        return TaskParams(**{**shared, "square": square, "track_width": track_width})


class MobileMission:
    """The mission's sequencing of primitive actions (see the module docstring).

    Args:
        camera: the downward camera model.
        robot: the robot's parameter table (drive geometry, sensor height).
        beacon_height: height of the reflectors' centres above the floor, m.
        square: side of the floor squares, m.
        track_width: painted track width, m.
        params: tuning.

    Attributes:
        phase: present phase.
        reason: why the mission failed ("" otherwise).
        interruptions: interruptions declared.
        log: (t, phase name, note) of every phase change.
        line: the present frame's track estimate when it counted as the track, else None
            (telemetry).
    """

    def __init__(
        self, camera: GroundCamera, robot: RobotSpec, *, beacon_height: float = 1.0, square: float = 2.0,
        track_width: float = 0.05, params: MissionParams | None = None,
    ) -> None:
        p = self.params = params or MissionParams()
        self.camera = camera
        geo = DriveGeometry(wheel_radius=robot.wheel_radius * p.odometry_scale, track_width=robot.track_width)
        self.odometry = Odometry(geo)
        self.detector = make_detector(p.detector, camera, track_width=track_width)
        self.end_detector = EndMarkDetector(camera=camera, bar_width=track_width)
        self.gap = GapMonitor(p.gap)
        self.pursuit = PurePursuit(look_ahead=p.look_ahead)
        self.steering = SteeringController(
            DriveGeometry(wheel_radius=robot.wheel_radius, track_width=robot.track_width),
            SpeedLimits(cruise=p.cruise),
        )
        self.approach = BeaconApproach(
            BeaconModel(height_above_sensor=beacon_height - robot.sensor_height, sensor_x=robot.sensor_x),
            square=square,
        )
        self.reacquire = Reacquire(at_x=p.look_ahead)
        self.phase = Phase.FOLLOW
        self.reason = ""
        self.interruptions = 0
        self.log: list[tuple[float, str, str]] = []
        self._curvature = 0.0
        self._sightings: deque[tuple[Pose2D, list[BeaconObservation]]] = deque()
        self._last_line: tuple[Pose2D, LineEstimate] | None = None
        self._heading: float | None = None
        self._end_hits = 0
        self._stops: list[float] = []
        self.line: LineEstimate | None = None

    def _enter(self, phase: Phase, t: float, note: str = "") -> None:
        self.phase = phase
        self.log.append((t, phase.value, note))

    def start(self, pose: Pose2D, encoders: tuple[float, float], t: float) -> None:
        """Set the odometry frame (e.g. the start pose) and the encoder reference."""
        self.odometry.reset(pose)
        self.odometry.update(*encoders, t)
        self.gap.reset(pose.s)
        self.log.append((t, self.phase.value, "start"))

    def tick(
        self, t: float, image: np.ndarray, encoders: tuple[float, float],
        beacons: list[BeaconObservation] | None = None,
    ) -> SteeringSetPoint:
        """One control step.

        Args:
            t: time of the frame and encoder reading, s.
            image: (H, W) uint8 grey frame of the downward camera.
            encoders: (left, right) wheel angles, rad.
            beacons: observations of a beacon scan at this tick, or None if no scan.

        Returns:
            The drive set point (zero speed once DONE or FAILED).
        """
        pose = self.odometry.update(*encoders, t)
        if beacons is not None:
            self._sightings.append((pose, beacons))
        while self._sightings and t - self._sightings[0][0].t > 1.0:
            self._sightings.popleft()
        if self.phase in (Phase.DONE, Phase.FAILED):
            return self.steering.stop(t)
        line = self.detector.detect(image)
        seen = line is not None and line.confidence >= self.params.min_confidence
        if seen and self.phase is not Phase.APPROACH:
            assert line is not None
            seen = abs(line.lateral_at(self.params.look_ahead)) <= self.params.max_offset
        self.line = line if seen else None
        if self.phase is Phase.FOLLOW:
            return self._follow(t, pose, image, line if seen else None)
        if self.phase is Phase.APPROACH:
            return self._approach(t, pose, beacons, line if seen else None)
        return self._stopping(t, pose, image, line if seen else None)

    # --- phases -----------------------------------------------------------------------------
    def _follow(self, t: float, pose: Pose2D, image: np.ndarray, line: LineEstimate | None) -> SteeringSetPoint:
        p = self.params
        mark = self.end_detector.detect(image)
        self._end_hits = self._end_hits + 1 if mark is not None else 0
        if mark is not None:
            self._stops.append(pose.s + mark.x)
            if self._end_hits >= p.end_frames:
                self._enter(Phase.STOPPING, t, f"T bar {mark.x:.3f} m ahead")
                return self._stopping(t, pose, image, line)
        if line is not None:
            self.gap.update(True, pose.s)
            self._last_line = (pose, line)
            if line.confidence >= 0.5:
                self._heading = pose.theta + line.heading
            self._curvature = self.pursuit.curvature(line)
            return self.steering.command(t, p.cruise, self._curvature)
        if self.gap.update(False, pose.s):
            return self._interruption(t, pose)
        return self.steering.command(t, p.cruise, self._curvature)

    def _interruption(self, t: float, pose: Pose2D) -> SteeringSetPoint:
        self.interruptions += 1
        if self._last_line is None:
            return self._fail(t, "no track seen before the interruption")
        lp, ln = self._last_line
        ex, ey = lp.to_world(ln.x_max, ln.lateral_at(ln.x_max))
        heading = self._heading if self._heading is not None else lp.theta
        if not self.approach.start((ex, ey, heading), list(self._sightings)):
            return self._fail(t, "interruption: no beacon at an expected exit")
        self.reacquire.reset()
        self._enter(Phase.APPROACH, t, f"exit {('straight', 'left', 'right')[self.approach.exit_index]}")
        return self._approach(t, pose, None, None)

    def _approach(
        self, t: float, pose: Pose2D, beacons: list[BeaconObservation] | None, line: LineEstimate | None
    ) -> SteeringSetPoint:
        p = self.params
        if beacons:
            self.approach.observe(pose, beacons)
        remaining = self.approach.remaining(pose)
        if remaining < p.reacquire_window and self.reacquire.update(line):
            assert line is not None
            self.gap.reset(pose.s)
            self._last_line = (pose, line)
            self._heading = None
            self._end_hits = 0
            self._enter(Phase.FOLLOW, t, "track reacquired")
            self._curvature = self.pursuit.curvature(line)
            return self.steering.command(t, p.approach_speed, self._curvature)
        gx, _ = pose.to_local(*self.approach.target)  # type: ignore[misc]
        if gx < -p.max_overshoot:
            return self._fail(t, "track not found again after the beacon")
        self._curvature = self.approach.curvature(pose)
        return self.steering.command(t, p.approach_speed, self._curvature)

    def _stopping(self, t: float, pose: Pose2D, image: np.ndarray, line: LineEstimate | None) -> SteeringSetPoint:
        p = self.params
        mark = self.end_detector.detect(image)
        if mark is not None:
            self._stops.append(pose.s + mark.x)
        target = float(np.median(self._stops[-8:]))
        remaining = target - pose.s
        if line is not None and line.x_min < target - pose.s:
            self._curvature = self.pursuit.curvature(line)
        else:
            self._curvature = 0.0  # the T's stem is straight; past the bar nothing is painted ahead
        v = min(p.cruise, math.sqrt(2.0 * p.stop_decel * max(0.0, remaining)))
        if remaining <= 0.005 or v < 0.03:
            self._enter(Phase.DONE, t, f"stopped {remaining:+.3f} m from the T bar (odometry)")
            return self.steering.stop(t)
        return self.steering.command(t, v, self._curvature)

    def _fail(self, t: float, reason: str) -> SteeringSetPoint:
        self.reason = reason
        self._enter(Phase.FAILED, t, reason)
        return self.steering.stop(t)


@dataclass(slots=True)
class RunResult:
    """Score of one run against ground truth.

    Attributes:
        course: course name.
        completed: the robot stopped on its own within ``stop_tolerance`` of the T mark, having
            recovered every interruption, without being judged off the track.
        reason: why not (empty when completed).
        t_sim: simulated time from the start to the stop (or the end of the run), s.
        wall: wall-clock time of the closed loop, s.
        cpu: CPU time of this process during the closed loop, s (independent of the machine's
            load, unlike ``wall``).
        length: course length from the start to the T mark, m.
        interruptions: interruptions on the course.
        recovered: interruptions after which the robot was on the next tile's track (|offset| <
            0.1 m half a metre into it).
        cross_track: |cross-track offset| samples of the axle midpoint on painted tiles while
            following, m.
        stop_error: distance from the axle midpoint to the T mark's centre at the stop, m (nan if
            the robot did not stop).
        mean_speed: course length / t_sim, m/s (nan unless completed).
        log: the mission's phase log.
    """

    course: str
    completed: bool = False
    reason: str = ""
    t_sim: float = 0.0
    wall: float = 0.0
    cpu: float = 0.0
    length: float = 0.0
    interruptions: int = 0
    recovered: int = 0
    cross_track: list[float] = field(default_factory=list)
    stop_error: float = math.nan
    mean_speed: float = math.nan
    log: list[tuple[float, str, str]] = field(default_factory=list)

    @property
    def cross_track_rms(self) -> float:
        """RMS cross-track offset, m."""
        return float(np.sqrt(np.mean(np.square(self.cross_track)))) if self.cross_track else math.nan

    @property
    def cross_track_max(self) -> float:
        """Largest |cross-track offset|, m."""
        return float(np.max(np.abs(self.cross_track))) if self.cross_track else math.nan


def run_course(
    course: Course,
    *,
    params: MissionParams | None = None,
    robot: RobotSpec | None = None,
    camera: str = "analytic",
    camera_model: GroundCamera | None = None,
    noise: ImageNoise | None = None,
    seed: int = 0,
    dt: float = DEFAULT_DT,
    max_time: float | None = None,
    stop_tolerance: float = 0.3,
    off_track: float = 0.4,
    realtime: bool = False,
    latency: float = 0.0,
    on_tick: Any = None,
    mission_factory: Any = None,
) -> RunResult:
    """Drive a course end to end in a fresh world and score the run.

    Args:
        course: the course.
        params: mission tuning.
        robot: robot parameter table.
        camera: ``analytic`` (floor-map warp) or ``tiny`` (pybullet TinyRenderer, textured floor).
        camera_model: the camera model (default: :func:`sim.mobile.sensors.robot_camera`).
        noise: image degradations.
        seed: seed of the sensors' noise.
        dt: physics step, s.
        max_time: simulated time limit, s (default: course length / 0.25 m/s + 10 s).
        stop_tolerance: a stop counts as on the T mark within this distance, m.
        off_track: the run is judged lost when the axle is further than this from the track on a
            painted tile, m.
        realtime: pace the world to the wall clock (the demo) instead of lock-step.
        latency: delay from a frame's exposure to its set point reaching the drives, s (applied at
            the first physics step at or after it; 0 = the next step). Stands for image transfer,
            processing and the set-point stream between nodes.
        on_tick: optional ``f(t, mission, world, set_point)`` called after every control tick.
        mission_factory: the class sequencing the primitive actions, called like
            :class:`MobileMission` (default); :class:`sim.mobile.lockstep.TaskSequence` runs the
            nodes' action code instead.

    Returns:
        The run's score.

    Raises:
        ValueError: on an unknown camera kind.
    """
    if camera not in ("analytic", "tiny"):
        raise ValueError(f"unknown camera {camera!r} (analytic or tiny)")
    run = _CourseRun(course, params or MissionParams(), robot or RobotSpec(), dt=dt, realtime=realtime,
                     latency=latency)
    try:
        run.start(camera, camera_model, noise, seed, mission_factory or MobileMission)
        limit = max_time if max_time is not None else course.length / 0.25 + 10.0
        while run.tick(limit, off_track, on_tick):
            pass
        run.finish(stop_tolerance)
        return run.result
    finally:
        run.close()


class _CourseRun:
    """The phases of one :func:`run_course`: build the world and the mission, tick the closed loop
    (scoring each tick against ground truth), score the stop; always close the world."""

    def __init__(self, course: Course, params: MissionParams, spec: RobotSpec, *, dt: float, realtime: bool,
                 latency: float) -> None:
        self.course = course
        self.params = params
        self.spec = spec
        self.latency = latency
        self.world = World(dt=dt, mode=ClockMode.REALTIME if realtime else ClockMode.LOCKSTEP, solver_iterations=10)
        self.result = RunResult(course.name, length=course.length, interruptions=sum(t.blank for t in course.tiles))
        self.mw: MobileWorld | None = None
        self.queue: deque[tuple[float, SteeringSetPoint]] = deque()
        self.pending: set[int] = set()
        self.tick_no = 0

    def start(self, camera: str, camera_model: GroundCamera | None, noise: ImageNoise | None, seed: int,
              mission_factory: Any) -> None:
        """Build the world, the sensors and the mission; let the robot settle; start the mission."""
        course, world = self.course, self.world
        self.mw = mw = MobileWorld(world, course, robot=self.spec, textured=camera == "tiny")
        cam_model = camera_model or mw.camera_model()
        self.cam = (mw.analytic_camera if camera == "analytic" else mw.tiny_camera)(cam_model, noise=noise, seed=seed)
        self.sensor = mw.beacon_sensor(seed=seed + 1)
        self.mission = mission_factory(
            cam_model, self.spec, beacon_height=course.beacon.height, square=course.square,
            track_width=course.track_width, params=self.params,
        )
        x0, y0, th0 = course.start_pose()
        world.step(25)  # let the robot settle on its wheels
        self.mission.start(Pose2D(x0, y0, th0, 0.0, world.t), mw.encoders(), world.t)
        self.period = 1.0 / self.params.control_rate
        self.scan_every = max(1, round(self.params.control_rate / self.params.beacon_rate))
        self.pending = {b.tile for b in mw.beacons}
        world.add_step_hook(self._deliver)
        self.t_start = world.t
        self.wall0 = time.perf_counter()
        self.cpu0 = time.process_time()

    def _deliver(self, t_step: float) -> None:
        """Apply the set points whose latency has passed (a step hook of the world)."""
        assert self.mw is not None
        while self.queue and self.queue[0][0] <= t_step + 1e-9:
            sp_due = self.queue.popleft()[1]
            self.mw.set_wheel_velocities(sp_due.left, sp_due.right)

    def tick(self, limit: float, off_track: float, on_tick: Any) -> bool:
        """One control tick: sense, step the mission, score; False once the run is over."""
        mw, mission, world, result = self.mw, self.mission, self.world, self.result
        assert mw is not None
        t = world.t
        pose = mw.pose()
        frame = self.cam.render(pose)
        obs = self.sensor.observe(pose, t) if self.tick_no % self.scan_every == 0 else None
        sp = mission.tick(t, frame, mw.encoders(), obs)
        self.queue.append((t + self.latency, sp))
        if on_tick is not None:
            on_tick(t, mission, mw, sp)
        if not self._score(pose, off_track):
            return False
        if mission.phase is Phase.DONE:
            return False
        if mission.phase is Phase.FAILED:
            result.reason = mission.reason
            return False
        if t - self.t_start > limit:
            result.reason = f"time limit {limit:.0f} s"
            return False
        world.advance(self.period)
        self.tick_no += 1
        return True

    def _score(self, pose: tuple[float, float, float], off_track: float) -> bool:
        """Score one tick against ground truth: the cross-track offset while following, the
        interruptions recovered; False when the robot left the track."""
        assert self.mw is not None
        here = self.mw.where(pose[0], pose[1])
        if here is None:
            return True
        tile, _, off = here
        if not tile.blank and self.mission.phase in (Phase.FOLLOW, Phase.STOPPING):
            self.result.cross_track.append(abs(off))
            if abs(off) > off_track:
                self.result.reason = f"left the track on tile {tile.index + 1} ({abs(off):.2f} m off)"
                return False
        if tile.index - 1 in self.pending and self.course.project(tile, pose[0], pose[1])[0] >= 0.5:
            self.pending.discard(tile.index - 1)
            if abs(off) < 0.1:
                self.result.recovered += 1
        return True

    def finish(self, stop_tolerance: float) -> None:
        """Time the run and, when the mission is done, score where the robot stopped."""
        result, world, mission = self.result, self.world, self.mission
        assert self.mw is not None
        result.wall = time.perf_counter() - self.wall0
        result.cpu = time.process_time() - self.cpu0
        result.t_sim = world.t - self.t_start
        result.log = mission.log
        if mission.phase is not Phase.DONE:
            return
        world.advance(0.3)  # let it come to rest
        x, y, _ = self.mw.pose()
        ex, ey = self.course.end_point()
        result.stop_error = math.hypot(x - ex, y - ey)
        if result.stop_error > stop_tolerance:
            result.reason = f"stopped {result.stop_error:.2f} m from the T mark"
        elif result.recovered < result.interruptions:
            result.reason = f"recovered {result.recovered} of {result.interruptions} interruptions"
        else:
            result.completed = True
            result.mean_speed = self.course.length / result.t_sim

    def close(self) -> None:
        if self.mw is not None:
            self.mw.close()
        self.world.close()
