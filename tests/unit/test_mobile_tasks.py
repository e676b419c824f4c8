"""The nodes' primitive actions (services/mobile/tasks.py) driven in process in lock-step, sequenced as
the task net does (sim/mobile/lockstep.py), and their specification."""

from __future__ import annotations

import numpy as np
import pytest

from services.mobile.beacon import BeaconModel
from services.mobile.camera import GroundCamera
from services.mobile.odometry import DriveGeometry, Pose2D
from services.mobile.tasks import CourseMemory, FollowTrack, StopAtT, TaskParams
from sim.mobile.course import course_from_codes
from sim.mobile.harness import run_course
from sim.mobile.lockstep import TaskSequence, run_tasks


def memory() -> CourseMemory:
    return CourseMemory(GroundCamera(), DriveGeometry(), BeaconModel(), TaskParams(), seq0=1000)


@pytest.mark.parametrize("codes", ["S S B S E", "S R S BL S E"], ids=["hidden-straight", "hidden-arc"])
def test_the_nodes_task_code_drives_a_course_with_an_interruption_to_the_t_mark(codes):
    seq: list[TaskSequence] = []

    def factory(*a, **kw):
        seq.append(TaskSequence(*a, **kw))
        return seq[0]

    r = run_course(course_from_codes(codes.split()), seed=3, mission_factory=factory)
    assert r.completed, (r.reason, r.log)
    assert (r.interruptions, r.recovered) == (1, 1)
    assert [(x.task, x.outcome) for x in seq[0].records] == [
        ("follow_track", "interruption"), ("find_beacon", "found"), ("goto_beacon", "ok"),
        ("reacquire_track", "ok"), ("follow_track", "end"), ("stop_at_t", "ok")]
    assert all(x.success for x in seq[0].records)
    assert r.cross_track_rms < 0.010 and r.stop_error < 0.05 and r.mean_speed > 0.5


def test_the_set_point_stream_is_numbered_from_its_first_sequence_number_across_tasks():
    m = memory()
    follow = FollowTrack(m, "ransac")
    blank = np.full((60, 80), 128, np.uint8)
    a = follow.step(0.0, Pose2D(t=0.0), blank).setpoint
    b = StopAtT(m).step(0.02, Pose2D(t=0.02), blank).setpoint
    assert (a.seq, b.seq) == (1000, 1001)


def test_a_follow_that_never_saw_the_track_ends_lost_and_fails_its_specification():
    m = memory()
    follow = FollowTrack(m, "scanline")
    blank = np.full((60, 80), 128, np.uint8)
    step = None
    for k in range(20):
        step = follow.step(k * 0.02, Pose2D(s=k * 0.016, t=k * 0.02), blank)
        if step.outcome:
            break
    assert step is not None and step.outcome == "lost" and not step.success
    assert step.setpoint.v == 0.0
    assert follow.judge("lost") == (False, "ended lost")


def test_a_follow_segment_with_detector_dropouts_fails_its_specification_but_keeps_its_outcome():
    follow = FollowTrack(memory(), "centroid")
    follow.dropouts = 2
    ok, why = follow.judge("interruption")
    assert not ok and "lost the track 2 times" in why
    assert follow.judge("interruption", max_dropouts=2) == (True, "")


def test_task_params_reject_nonsense():
    assert TaskParams.from_params({"cruise": 0.5, "other": 1}).cruise == 0.5
    for bad in ({"cruise": -1.0}, {"gap": float("nan")}, {"end_frames": 0}, {"look_ahead": True}):
        with pytest.raises(ValueError):
            TaskParams.from_params(bad)


def test_an_unknown_detector_is_refused():
    with pytest.raises(ValueError, match="unknown track detector"):
        memory().detector("hough")


def test_run_tasks_is_run_course_with_the_task_sequence():
    r = run_tasks(course_from_codes(["S", "S", "E"]), seed=1)
    assert r.completed, r.reason
