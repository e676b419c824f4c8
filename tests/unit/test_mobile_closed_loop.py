"""Closed loop in lock-step time: follow, cross an interruption by its beacon, stop on the T."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.mobile.odometry import Pose2D
from sim.mobile.course import course_from_codes
from sim.mobile.coursefile import load_course
from sim.mobile.harness import MobileMission, Phase, run_course
from sim.mobile.robot import RobotSpec
from sim.mobile.sensors import robot_camera

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("codes", ["S S B S E", "S R S BL S E"], ids=["hidden-straight", "hidden-arc"])
def test_a_short_course_with_an_interruption_is_driven_to_the_t_mark(codes):
    course = course_from_codes(codes.split())
    r = run_course(course, seed=3)
    assert r.completed, (r.reason, r.log)
    assert (r.interruptions, r.recovered) == (1, 1)
    assert [phase for _, phase, _ in r.log] == ["follow", "approach", "follow", "stopping", "done"]
    assert r.cross_track_rms < 0.010
    assert r.cross_track_max < 0.025
    assert r.stop_error < 0.05
    assert r.mean_speed > 0.5
    assert r.t_sim > 0 and r.wall > 0


def test_the_fig2_course_is_driven_end_to_end():
    r = run_course(load_course(ROOT / "nets" / "courses" / "fig2.toml"), seed=2)
    assert r.completed, (r.reason, r.log)
    assert (r.interruptions, r.recovered) == (2, 2)
    assert r.cross_track_rms < 0.010 and r.stop_error < 0.10


def test_a_run_is_the_same_for_the_same_seed():
    course = course_from_codes(["S", "L", "S", "B", "S", "E"])
    a, b = run_course(course, seed=5), run_course(course, seed=5)
    assert a.t_sim == b.t_sim and a.cross_track == b.cross_track and a.stop_error == b.stop_error


def test_the_tinyrenderer_camera_drives_the_same_mission():
    r = run_course(course_from_codes(["S", "B", "S", "E"]), camera="tiny", seed=1)
    assert r.completed, (r.reason, r.log)
    assert r.cross_track_rms < 0.010 and r.stop_error < 0.05


def test_an_interruption_without_a_beacon_in_sight_fails_the_mission_with_a_reason():
    spec = RobotSpec()
    cam = robot_camera(spec)
    mission = MobileMission(cam, spec)
    mission.start(Pose2D(), (0.0, 0.0), 0.0)
    blank = np.full((cam.height, cam.width), 30, np.uint8)
    track = blank.copy()
    track[:, 34:46] = 225  # a straight track under the camera
    angle = 0.0
    for k in range(1, 40):
        angle += 0.3  # 15 mm per tick on 50 mm wheels
        sp = mission.tick(0.02 * k, track if k < 10 else blank, (angle, angle), [])
        if mission.phase is Phase.FAILED:
            break
    assert mission.phase is Phase.FAILED
    assert mission.reason == "interruption: no beacon at an expected exit"
    assert sp.v == 0.0 and mission.interruptions == 1
