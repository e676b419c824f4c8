"""Catching motion control (services/catching/robot/motion_control.py), checked with forward kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.catching.robot import motion_control as M
from services.catching.robot import puma560 as P

GEOM = M.CatchGeometry()


def _rim(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = P.fk(q)
    return t[:3, 3] + P.CUP_RIM_OFFSET * t[:3, 2], t[:3, 2]


def test_the_catch_target_puts_the_rim_where_the_falling_ball_crosses_the_rim_height():
    x, y, vx, vy = GEOM.edge_x, 0.1, -0.9, 0.05
    target = M.catch_target(x, y, 2.0, vx, vy, P.Q_HOME, GEOM)
    rim, axis = _rim(target.q)
    assert np.allclose(rim, target.rim, atol=1e-9)
    drop = GEOM.ball_radius + GEOM.rim_drop
    t_fall = math.sqrt(2 * drop / M.G)
    assert np.allclose(rim, [x + vx * t_fall, y + vy * t_fall, GEOM.table_z - GEOM.rim_drop], atol=1e-9)
    assert target.t_rim == pytest.approx(2.0 + t_fall)
    # cup axis tilted 45 degrees from vertical toward the table (+x)
    assert np.allclose(axis, [math.sin(GEOM.tilt), 0.0, math.cos(GEOM.tilt)], atol=1e-9)


def test_the_whole_catch_line_is_reachable_for_every_throw_speed():
    for y in np.linspace(GEOM.y_min, GEOM.y_max, 15):
        for vx in (-0.3, -0.8, -1.5):
            for vy in (-0.3, 0.0, 0.3):
                target = M.catch_target(GEOM.edge_x, y, 0.0, vx, vy, P.Q_HOME, GEOM)
                assert P.within_limits(target.q)
                assert np.allclose(_rim(target.q)[0], target.rim, atol=1e-9)


def test_a_crossing_beyond_the_covered_span_is_clamped_to_its_end():
    target = M.catch_target(GEOM.edge_x, 0.6, 0.0, -1.0, 0.0, P.Q_HOME, GEOM)
    assert target.rim[1] == pytest.approx(GEOM.y_max)


def test_a_geometry_out_of_reach_raises_unreachable():
    far = M.CatchGeometry(edge_x=1.6)
    with pytest.raises(P.UnreachableError):
        M.catch_target(far.edge_x, 0.0, 0.0, -1.0, 0.0, P.Q_HOME, far)


def test_the_home_pose_holds_the_cup_mid_catch_line():
    q = M.home_pose(GEOM)
    assert P.within_limits(q)
    rim, _ = _rim(q)
    assert rim[1] == pytest.approx(0.0, abs=1e-9)
    assert rim[2] == pytest.approx(GEOM.table_z - GEOM.rim_drop)
    assert np.allclose(q, P.Q_HOME, atol=0.05)


def test_joint_steps_respect_speed_and_acceleration_limits_and_land_on_the_goal():
    q = P.Q_HOME.copy()
    goal = M.catch_target(GEOM.edge_x, GEOM.y_max, 0.0, -1.0, 0.0, q, GEOM).q
    qd = np.zeros(6)
    prev_v = qd
    for _ in range(2000):
        q_next, v = M.step_toward(q, qd, goal)
        assert np.all(np.abs(v) <= P.QD_MAX + 1e-9)
        assert np.all(np.abs(v - prev_v) <= P.QDD_MAX * M.CYCLE_S + 1e-9)
        assert np.allclose(q_next, q + v * M.CYCLE_S)
        q, qd, prev_v = q_next, v, v
    assert np.allclose(q, goal, atol=1e-6)
    assert np.allclose(qd, 0.0, atol=1e-6)


def test_joint_steps_do_not_overshoot_the_goal():
    q = np.zeros(6)
    goal = np.array([0.5, -0.3, 0.2, 1.0, -1.0, 2.0])
    qd = np.zeros(6)
    for _ in range(3000):
        q, qd = M.step_toward(q, qd, goal)
        # every joint stays on the start side of its goal (within one cycle's acceleration step)
        assert np.all((goal - q) * np.sign(goal) >= -P.QDD_MAX * M.CYCLE_S**2)


def test_reach_time_is_a_tight_lower_bound_of_the_stepped_motion():
    servo = M.CatchServo(P.Q_HOME)
    servo.aim(GEOM.edge_x, -0.3, 1.0, -1.0, 0.0)
    bound = servo.time_to_goal()
    steps = 0
    while not servo.at_goal() and steps < 5000:
        servo.step()
        steps += 1
    elapsed = steps * M.CYCLE_S
    assert bound <= elapsed + 1e-9
    assert elapsed <= bound * 1.1 + 0.02


def test_reach_time_accounts_for_moving_away_from_the_goal():
    q, goal = np.zeros(6), np.zeros(6)
    goal[0] = 0.1
    at_rest = M.reach_time(q, np.zeros(6), goal)
    away = np.zeros(6)
    away[0] = -P.QD_MAX[0]
    assert M.reach_time(q, away, goal) > at_rest + P.QD_MAX[0] / P.QDD_MAX[0] - 1e-9


def test_a_new_set_point_retargets_the_moving_servo_latest_wins():
    servo = M.CatchServo(P.Q_HOME)
    first = servo.aim(GEOM.edge_x, 0.3, 1.0, -1.0, 0.0)
    for _ in range(50):
        servo.step()
    second = servo.aim(GEOM.edge_x, -0.2, 1.0, -1.0, 0.0)
    assert servo.target is second and not np.allclose(first.q, second.q)
    for _ in range(1000):
        servo.step()
    assert np.allclose(_rim(servo.q)[0], second.rim, atol=1e-5)


def test_an_unreachable_aim_leaves_the_goal_unchanged():
    servo = M.CatchServo(P.Q_HOME, M.CatchGeometry(edge_x=1.6))
    goal = servo.goal.copy()
    with pytest.raises(P.UnreachableError):
        servo.aim(1.6, 0.0, 1.0, -1.0, 0.0)
    assert np.array_equal(servo.goal, goal)
    with pytest.raises(P.UnreachableError):
        servo.set_goal(P.Q_MAX + 0.1)
