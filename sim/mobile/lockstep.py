"""The nodes' primitive actions driven in process, in lock-step simulated time (benchmarks, tests).

:class:`TaskSequence` runs the controllers the perception node's actions run
(:mod:`services.mobile.tasks`: follow the track, find the beacon, go to it, reacquire the track,
stop at the T) with the sequencing of the task net ``nets/mobile.toml`` (Fig. 3): follow →
``interruption`` → find beacon → ``found`` → go to the beacon → reacquire → follow ... → ``end`` →
stop at the T; ``lost`` / ``not_found`` end the run as failed (the net's recovery branch stops the
robot). Odometry comes from the wheel encoders as on the drive node (:class:`Odometry`). It has
the interface :func:`sim.mobile.harness.run_course` drives (``start``, ``tick``, ``phase``,
``reason``, ``log``, ``interruptions``), so the world, the scoring (:class:`RunResult`) and the
benchmark's keys are those of phase 1: ``run_tasks(course, ...)`` is ``run_course`` with it.

Per task it also keeps what the journal would hold: outcome, frames, distance, CPU time
(:attr:`TaskSequence.records`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.mobile.beacon import BeaconModel, BeaconObservation
from services.mobile.camera import GroundCamera
from services.mobile.odometry import DriveGeometry, Odometry, Pose2D
from services.mobile.steering import SteeringSetPoint
from services.mobile.tasks import (
    CourseMemory,
    FindBeacon,
    FollowTrack,
    GotoBeacon,
    ReacquireTrack,
    StopAtT,
)

from .course import Course
from .harness import MissionParams, Phase, RunResult, run_course
from .robot import RobotSpec

__all__ = ["TaskRecord", "TaskSequence", "run_tasks"]


@dataclass
class TaskRecord:
    """One primitive-task instance as the journal would record it."""

    task: str
    action: str
    t0: float
    t1: float = 0.0
    outcome: str = ""
    success: bool = True
    note: str = ""
    frames: int = 0
    cpu_s: float = 0.0
    dropouts: int = 0


class TaskSequence:
    """The course's primitive actions sequenced as the net does (see the module docstring).

    Args:
        camera: the downward camera model.
        robot: the robot's parameter table.
        beacon_height: reflector height above the floor, m.
        square, track_width: floor geometry, m.
        params: the mission tuning (``detector`` names the follow action's detector).
    """

    def __init__(self, camera: GroundCamera, robot: RobotSpec, *, beacon_height: float = 1.0,
                 square: float = 2.0, track_width: float = 0.05, params: MissionParams | None = None) -> None:
        p = self.params = params or MissionParams()
        geo = DriveGeometry(wheel_radius=robot.wheel_radius, track_width=robot.track_width)
        self.odometry = Odometry(DriveGeometry(wheel_radius=robot.wheel_radius * p.odometry_scale,
                                               track_width=robot.track_width))
        tp = p.task_params(square=square, track_width=track_width)
        beacon = BeaconModel(height_above_sensor=beacon_height - robot.sensor_height, sensor_x=robot.sensor_x)
        self.memory = CourseMemory(camera, geo, beacon, tp)
        self.phase = Phase.FOLLOW
        self.reason = ""
        self.log: list[tuple[float, str, str]] = []
        self.records: list[TaskRecord] = []
        self._task: Any = None
        self._kind = ""

    @property
    def interruptions(self) -> int:
        """Interruptions declared by the follow actions."""
        return self.memory.interruptions

    def start(self, pose: Pose2D, encoders: tuple[float, float], t: float) -> None:
        """Set the odometry frame and start following."""
        self.odometry.reset(pose)
        self.odometry.update(*encoders, t)
        self.log.append((t, self.phase.value, "start"))
        self._begin("follow_track", f"follow_{self.params.detector}", t)

    def _begin(self, task: str, action: str, t: float) -> None:
        m = self.memory
        self._kind = task
        self._task = {
            "follow_track": lambda: FollowTrack(m, self.params.detector),
            "find_beacon": lambda: FindBeacon(m),
            "goto_beacon": lambda: GotoBeacon(m),
            "reacquire_track": lambda: ReacquireTrack(m),
            "stop_at_t": lambda: StopAtT(m),
        }[task]()
        self.records.append(TaskRecord(task, action, t))

    def tick(self, t: float, image: np.ndarray, encoders: tuple[float, float],
             beacons: list[BeaconObservation] | None = None) -> SteeringSetPoint:
        """One control step (one camera frame): the running task's set point."""
        pose = self.odometry.update(*encoders, t)
        m = self.memory
        if self.phase in (Phase.DONE, Phase.FAILED):
            return m.stop(t)
        if beacons is not None and self._kind not in ("find_beacon",):
            m.observe_beacons(pose, beacons)
        c0 = time.process_time()
        kind, task = self._kind, self._task
        if kind == "follow_track":
            step = task.step(t, pose, image)
        elif kind == "find_beacon" or kind == "goto_beacon":
            step = task.step(t, pose, beacons)
        elif kind == "reacquire_track":
            step = task.step(t, pose, image, beacons)
        else:
            step = task.step(t, pose, image)
        rec = self.records[-1]
        rec.cpu_s += time.process_time() - c0
        rec.frames += 1
        if step.outcome is None:
            return step.setpoint
        rec.t1, rec.outcome, rec.success, rec.note = t, step.outcome, step.success, step.note
        if kind == "follow_track":
            rec.success, why = task.judge(step.outcome)
            rec.note = why or rec.note
            rec.dropouts = task.dropouts
        nxt = {
            ("follow_track", "interruption"): "find_beacon",
            ("follow_track", "end"): "stop_at_t",
            ("find_beacon", "found"): "goto_beacon",
            ("goto_beacon", "ok"): "reacquire_track",
            ("reacquire_track", "ok"): "follow_track",
        }.get((kind, step.outcome))
        if nxt is None and kind == "stop_at_t":
            self.phase = Phase.DONE
            self.log.append((t, self.phase.value, step.note))
            return step.setpoint
        if nxt is None:
            self.reason = f"{kind}: {step.outcome} ({step.note})"
            self.phase = Phase.FAILED
            self.log.append((t, self.phase.value, self.reason))
            return m.stop(t)
        phase = {"follow_track": Phase.FOLLOW, "stop_at_t": Phase.STOPPING}.get(nxt, Phase.APPROACH)
        if phase is not self.phase:
            self.phase = phase
            self.log.append((t, phase.value, step.note))
        action = f"follow_{self.params.detector}" if nxt == "follow_track" else nxt
        self._begin(nxt, action, t)
        return step.setpoint


def run_tasks(course: Course, **kwargs: Any) -> RunResult:
    """:func:`sim.mobile.harness.run_course` with :class:`TaskSequence` (the nodes' action code)."""
    return run_course(course, mission_factory=TaskSequence, **kwargs)
