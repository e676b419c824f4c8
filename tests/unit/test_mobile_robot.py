"""The differential-drive robot: URDF masses and inertias, kinematics, drives, odometry."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from services.mobile.odometry import DriveGeometry, Odometry, Pose2D, wrap_angle
from sim.mobile.course import course_from_codes
from sim.mobile.robot import (
    RobotSpec,
    box_inertia,
    cylinder_inertia,
    sphere_inertia,
    urdf,
)
from sim.mobile.world import DEFAULT_DT, MobileWorld
from sim.world import World


def test_solid_inertia_formulas_give_the_textbook_values():
    assert box_inertia(12.0, 1.0, 2.0, 3.0) == pytest.approx((13.0, 10.0, 5.0))
    assert cylinder_inertia(2.0, 0.5, 1.0) == pytest.approx((0.25, 2.0 * (0.75 + 1.0) / 12.0))
    assert sphere_inertia(5.0, 0.2) == pytest.approx(0.08)


def test_the_urdf_carries_the_parameter_tables_masses_and_inertias():
    spec = RobotSpec()
    root = ET.fromstring(urdf(spec))
    links = {ln.get("name"): ln for ln in root.iter("link")}
    masses = {n: float(ln.find("inertial/mass").get("value")) for n, ln in links.items()}  # type: ignore[union-attr]
    assert sum(masses.values()) == pytest.approx(spec.mass)
    base = links["base_link"].find("inertial/inertia")
    assert base is not None
    assert [float(base.get(k)) for k in ("ixx", "iyy", "izz")] == pytest.approx(  # type: ignore[arg-type]
        box_inertia(spec.chassis_mass, *spec.chassis_size)
    )
    wheel = links["left_wheel"].find("inertial/inertia")
    assert wheel is not None
    axis, dia = cylinder_inertia(spec.wheel_mass, spec.wheel_radius, spec.wheel_width)
    assert float(wheel.get("iyy")) == pytest.approx(axis)  # type: ignore[arg-type]
    assert float(wheel.get("ixx")) == pytest.approx(dia)  # type: ignore[arg-type]
    joints = {j.get("name"): j for j in root.iter("joint")}
    assert joints["left_wheel_joint"].find("axis").get("xyz") == "0 1 0"  # type: ignore[union-attr]


def test_an_impossible_parameter_table_is_refused():
    with pytest.raises(ValueError, match="wider"):
        RobotSpec(chassis_size=(0.3, 0.29, 0.08))
    with pytest.raises(ValueError, match="touches the floor"):
        RobotSpec(chassis_z=0.03)


def test_wheel_speeds_and_twist_are_inverse_kinematics_of_each_other():
    g = DriveGeometry(wheel_radius=0.05, track_width=0.3)
    for v, k in [(0.8, 0.0), (0.6, 1.0), (0.5, -1.0), (0.2, 3.0)]:
        left, right = g.wheel_speeds(v, k)
        assert g.twist(left, right) == pytest.approx((v, v * k))
    assert g.wheel_speeds(0.8, 0.0) == pytest.approx((16.0, 16.0))
    assert g.twist(-10.0, 10.0) == pytest.approx((0.0, 0.05 * 20.0 / 0.3))  # turning on the spot


def test_odometry_integrates_arcs_exactly_for_constant_wheel_speeds():
    g = DriveGeometry(wheel_radius=0.05, track_width=0.3)
    odo = Odometry(g)
    odo.update(0.0, 0.0, 0.0)
    left, right = g.wheel_speeds(0.5, 1.0)  # 1 m radius to the left
    for k in range(1, 11):  # a quarter circle in ten coarse readings
        t = k * (math.pi / 2) / 0.5 / 10
        odo.update(left * t, right * t, t)
    p = odo.pose
    assert (p.x, p.y, p.theta, p.s) == pytest.approx((1.0, 1.0, math.pi / 2, math.pi / 2), abs=1e-9)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)


@pytest.fixture
def world():
    w = World(dt=DEFAULT_DT, solver_iterations=10)
    yield w
    w.close()


def _robot_world(world: World) -> MobileWorld:
    return MobileWorld(world, course_from_codes(["S", "S", "S", "E"]), start=(1.0, 1.0, 0.3))


def test_the_robot_stands_where_it_was_placed_and_drives_the_commanded_twist(world):
    mw = _robot_world(world)
    world.step(25)
    x, y, th = mw.pose()
    assert (x, y, th) == pytest.approx((1.0, 1.0, 0.3), abs=2e-3)
    g = DriveGeometry(wheel_radius=mw.robot.spec.wheel_radius, track_width=mw.robot.spec.track_width)
    mw.set_wheel_velocities(*g.wheel_speeds(0.6, 1.0))
    world.advance(1.5)
    v, w = mw.robot.twist()
    assert v == pytest.approx(0.6, rel=0.03)
    assert w == pytest.approx(0.6, rel=0.03)


def test_the_drives_ramp_and_clamp_the_velocity_set_points(world):
    mw = _robot_world(world)
    spec = mw.robot.spec
    mw.set_wheel_velocities(100.0, 100.0)  # beyond the motors' speed limit
    assert mw.robot.drives.target == [spec.max_wheel_speed, spec.max_wheel_speed]
    world.advance(0.2)
    assert mw.robot.drives.demand[0] == pytest.approx(spec.ramp * 0.2, rel=0.05)
    world.advance(1.0)
    left, _ = mw.robot.drives.velocities()
    assert left == pytest.approx(spec.max_wheel_speed, rel=0.02)
    assert max(abs(t) for t in mw.robot.drives.torques()) <= spec.max_torque + 1e-9


def test_odometry_follows_ground_truth_over_a_known_manoeuvre(world):
    mw = _robot_world(world)
    world.step(25)
    spec = mw.robot.spec
    g = DriveGeometry(wheel_radius=spec.wheel_radius, track_width=spec.track_width)
    odo = Odometry(g, Pose2D(*mw.pose()))
    odo.update(*mw.encoders(), world.t)
    path = 0.0
    # a straight, a left arc of 1 m radius, a right arc of 0.5 m radius, then a stop
    for v, k, seconds in [(0.6, 0.0, 2.0), (0.6, 1.0, 2.0), (0.4, -2.0, 1.5), (0.0, 0.0, 0.5)]:
        mw.set_wheel_velocities(*g.wheel_speeds(v, k))
        for _ in range(round(seconds / 0.02)):
            world.advance(0.02)
            odo.update(*mw.encoders(), world.t)
        path += v * seconds
    x, y, th = mw.pose()
    err = math.hypot(odo.pose.x - x, odo.pose.y - y)
    assert err < 0.01 * path  # within 1 % of the distance run
    assert abs(wrap_angle(odo.pose.theta - th)) < math.radians(1.5)
    assert odo.pose.s == pytest.approx(path, rel=0.03)


def test_encoders_are_quantised_to_their_counts(world):
    mw = _robot_world(world)
    mw.set_wheel_velocities(3.0, 3.0)
    world.advance(0.5)
    q = 2 * math.pi / mw.robot.spec.encoder_counts
    for a in mw.encoders():
        assert a / q == pytest.approx(round(a / q), abs=1e-6)
    assert np.all(np.array(mw.encoders()) > 0)
