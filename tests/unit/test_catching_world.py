"""The catching world: ball physics against theory (the facts in docs/catching.md), thrower, cup, clock."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.catching.robot import motion_control
from services.catching.vision import RollingModel
from sim.catching.world import BallSpec, CatchingWorld, TableSpec, Thrower, ThrowSpec
from sim.world import ClockMode, World


@pytest.fixture
def world():
    w = World()
    yield w
    w.close()


def _roll(
    cw: CatchingWorld, spec: ThrowSpec, seconds: float
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    cw.launch(spec)
    out = []
    t0 = cw.world.t
    while cw.world.t - t0 < seconds:
        p, v = cw.ball_state()
        out.append((cw.world.t - t0, p, v))
        cw.world.step()
    return out


def test_rolling_friction_alone_decelerates_at_three_fifths_g_mu_over_r(world):
    cw = CatchingWorld(world, drag=False)
    trace = _roll(cw, ThrowSpec(x0=-1.4, y0=0.0, speed=1.0, heading=0.0), 1.0)
    decel = (trace[0][2][0] - trace[-1][2][0]) / trace[-1][0]
    b = cw.ball
    assert decel == pytest.approx(0.6 * 9.81 * b.rolling_friction / b.radius, rel=0.02)


def test_sliding_launch_turns_to_rolling_at_three_fifths_of_the_launch_speed(world):
    # Slide-to-roll at a 1.5 m/s launch gives 0.90 m/s after ~0.2 s, as theory says.
    # Thin shell: v_roll = v0 / (1 + 2/3) = 0.6 v0 after t = v0 / (2.5 mu g), mu the combined
    # friction coefficient (Bullet multiplies the two bodies' coefficients).
    cw = CatchingWorld(world, drag=False)
    v0 = 1.5
    cw.launch(ThrowSpec(x0=-1.4, y0=0.0, speed=v0, heading=0.0, rolling=False))
    r = cw.ball.radius
    t_rolling = None
    for _ in range(600):
        world.step()
        v, w = cw.pb.getBaseVelocity(cw.ball_id)
        if abs(v[0] - w[1] * r) < 1e-3:
            t_rolling, v_rolling = world.t, v[0]
            break
    mu = cw.ball.lateral_friction * cw.table.lateral_friction
    assert v0 / (2.5 * mu * 9.81) == pytest.approx(0.2, abs=0.01)
    assert t_rolling == pytest.approx(v0 / (2.5 * mu * 9.81), abs=0.005)
    assert v_rolling == pytest.approx(0.6 * v0, abs=0.01)


def test_ball_rolls_as_the_rolling_model_with_drag_predicts(world):
    cw = CatchingWorld(world)
    a, b = cw.ball.rolling_decel_params()
    model = RollingModel(a, b)
    spec = ThrowSpec(x0=-1.45, y0=0.05, speed=1.2, heading=0.08)
    _roll(cw, spec, 1.8)
    cr = cw.crossing
    assert cr is not None
    ds = -spec.x0 / math.cos(spec.heading)
    t_pred = model.time_to_travel(spec.speed, ds)
    assert t_pred is not None
    assert cr.t - cw.t_launch == pytest.approx(t_pred, abs=0.003)
    assert cr.y == pytest.approx(spec.y0 + ds * math.sin(spec.heading), abs=0.001)
    assert math.hypot(cr.vx, cr.vy) == pytest.approx(model.speed(spec.speed, t_pred), abs=0.005)


def test_the_drag_coefficient_matches_the_design_estimate():
    # docs/catching.md, the ball: air drag ~0.14 v^2 m/s^2 on a free ball
    assert BallSpec().drag_k == pytest.approx(0.14, abs=0.015)


def test_thrown_balls_leave_the_table_within_the_aimed_band(world):
    cw = CatchingWorld(world)
    thrower = Thrower(seed=11)
    for _ in range(3):
        spec = thrower.next()
        assert 0.5 <= spec.speed <= 1.5
        cw.launch(spec)
        for _ in range(4000):
            world.step()
            if cw.crossing is not None:
                break
        cr = cw.crossing
        assert cr is not None
        assert abs(cr.y) <= thrower.aim_half_width + 0.002
        assert cr.y == pytest.approx(spec.aim_y, abs=0.002)
        cw.park()


def test_the_thrower_is_reproducible_by_seed():
    a = [Thrower(seed=5).next() for _ in range(1)] + [Thrower(seed=5).next()]
    assert a[0] == a[1]
    assert Thrower(seed=5).next() != Thrower(seed=6).next()


def test_a_ball_resting_in_the_cup_cuts_the_crossfire_beam_and_one_elsewhere_does_not(world):
    cw = CatchingWorld(world, robot=True)
    q = motion_control.home_pose()
    cw.set_joint_positions(q)
    cw.pb.setJointMotorControlArray(
        cw.robot_id, cw.joint_indices, cw.pb.POSITION_CONTROL, targetPositions=list(q), forces=[500] * 6
    )
    world.step()
    assert cw.crossfire() is False
    # drop the ball onto the crossfire link's position (on the cup axis above the bottom)
    state = cw.pb.getLinkState(cw.robot_id, cw.link_index["crossfire"], computeForwardKinematics=True)
    above = np.asarray(state[4]) + np.array([0.0, 0.0, 0.03])
    cw.pb.resetBasePositionAndOrientation(cw.ball_id, above.tolist(), [0, 0, 0, 1])
    cw.pb.resetBaseVelocity(cw.ball_id, [0, 0, 0], [0, 0, 0])
    cw._parked = False
    world.step(500)
    assert cw.crossfire() is True
    cw.park()
    assert cw.crossfire() is False


def test_a_ball_is_caught_by_a_cup_held_at_the_true_catch_point(world):
    cw = CatchingWorld(world, robot=True)
    a, b = cw.ball.rolling_decel_params()
    model = RollingModel(a, b)
    spec = Thrower(seed=3).next()
    ds = -spec.x0 / math.cos(spec.heading)
    t_cross = model.time_to_travel(spec.speed, ds)
    assert t_cross is not None
    v = model.speed(spec.speed, t_cross)
    tf = cw.table_to_base()
    xb, yb, _ = tf.point(0.0, spec.y0 + ds * math.sin(spec.heading))
    vxb, vyb = tf.vector(v * math.cos(spec.heading), v * math.sin(spec.heading))
    target = motion_control.catch_target(xb, yb, t_cross, vxb, vyb, motion_control.home_pose())
    cw.set_joint_positions(target.q)
    cw.pb.setJointMotorControlArray(
        cw.robot_id, cw.joint_indices, cw.pb.POSITION_CONTROL,
        targetPositions=list(target.q), forces=[500] * 6,
    )
    cw.launch(spec)
    fired = False
    for _ in range(int((t_cross + 0.8) / world.dt)):
        world.step()
        fired = fired or cw.crossfire()
    assert fired


def test_the_robot_base_transform_puts_the_catch_line_where_motion_control_expects_it(world):
    cw = CatchingWorld(world)
    geo = motion_control.CatchGeometry()
    x, y, z = cw.table_to_base().point(0.0, 0.1, cw.table.height)
    assert x == pytest.approx(geo.edge_x)
    assert y == pytest.approx(-0.1)
    assert z == pytest.approx(geo.table_z)


def test_real_time_mode_paces_simulated_time_to_the_wall_clock():
    now = [100.0]
    slept: list[float] = []

    def clock() -> float:
        return now[0]

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    w = World(mode=ClockMode.REALTIME, wall_clock=clock, sleep=sleep)
    try:
        w.advance(0.05)
        assert w.t == pytest.approx(0.05)
        assert now[0] - 100.0 == pytest.approx(0.05, abs=1e-9)
        assert len(slept) == 50
    finally:
        w.close()


def test_an_overloaded_real_time_world_slips_instead_of_racing_to_catch_up():
    now = [0.0]

    def clock() -> float:
        return now[0]

    w = World(mode=ClockMode.REALTIME, wall_clock=clock, sleep=lambda s: None, max_lag=0.1)
    try:
        w.add_step_hook(lambda t: now.__setitem__(0, now[0] + 0.002))  # each step costs 2 ms
        w.advance(0.5)
        assert w.t == pytest.approx(0.5)
        assert w.lag <= 0.1 + 0.002
        assert w.slipped > 0.3
    finally:
        w.close()


def test_lock_step_mode_advances_only_when_asked():
    w = World()
    try:
        calls: list[float] = []
        w.add_step_hook(calls.append)
        w.advance(0.01)
        assert w.steps == 10
        assert calls[0] == 0.0 and calls[-1] == pytest.approx(0.009)
    finally:
        w.close()


def test_the_table_is_the_documented_size():
    tb = TableSpec()
    assert (tb.length, tb.width, tb.height) == (1.5, 0.76, 0.76)
