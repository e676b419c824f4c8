"""Beacon sensor (field of view, range, line of sight), beacon approach, reacquisition, steering."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.mobile.beacon import (
    BeaconApproach,
    BeaconModel,
    BeaconObservation,
    Reacquire,
    expected_exits,
)
from services.mobile.lines import LineEstimate
from services.mobile.odometry import DriveGeometry, Pose2D
from services.mobile.steering import SpeedLimits, SteeringController, pursuit_curvature
from sim.mobile.course import BeaconSpec, course_from_codes
from sim.mobile.sensors import BeaconSensorSpec
from sim.mobile.world import DEFAULT_DT, MobileWorld
from sim.world import World

EXACT = BeaconSensorSpec(azimuth_sigma=0.0, elevation_sigma=0.0)


@pytest.fixture
def beacon_world():
    world = World(dt=DEFAULT_DT)
    # one interruption: the track resumes at (4, 1); the reflector hangs 1 m above it
    course = course_from_codes(["S", "B", "S", "S", "E"], beacon=BeaconSpec(post=False))
    mw = MobileWorld(world, course)
    yield world, mw
    world.close()


def test_the_beacon_sensor_sees_the_reflector_ahead_with_its_bearing_and_elevation(beacon_world):
    _, mw = beacon_world
    sensor = mw.beacon_sensor(EXACT)
    (obs,) = sensor.observe((0.0, 1.0, 0.0), 2.5)
    spec = mw.robot.spec
    dx = 4.0 - spec.sensor_x
    assert obs.azimuth == pytest.approx(0.0, abs=1e-9)
    assert obs.elevation == pytest.approx(math.atan2(1.0 - spec.sensor_height, dx))
    assert obs.t == 2.5
    # seen from the side, the bearing says where it is
    (side,) = sensor.observe((4.0 - 2.0, 1.0 - 2.0, math.pi / 2), 0.0)
    assert side.azimuth == pytest.approx(-math.atan2(2.0, 2.0 - spec.sensor_x), abs=1e-3)


def test_the_beacon_sensor_is_blind_outside_its_field_of_view_and_range(beacon_world):
    _, mw = beacon_world
    assert mw.beacon_sensor(EXACT).observe((0.0, 1.0, math.radians(75)), 0.0) == []  # 75° off
    assert mw.beacon_sensor(EXACT).observe((0.0, 1.0, math.radians(65)), 0.0) != []
    assert mw.beacon_sensor(BeaconSensorSpec(max_range=3.0)).observe((0.0, 1.0, 0.0), 0.0) == []
    assert mw.beacon_sensor(EXACT).observe((3.8, 1.0, 0.0), 0.0) == []  # right below: too steep


def test_an_obstacle_in_the_line_of_sight_hides_the_reflector(beacon_world):
    _, mw = beacon_world
    pb = mw.pb
    sensor = mw.beacon_sensor(EXACT)
    # a box halfway between the sensor and the reflector, on the sight line
    col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[0.05, 0.2, 0.05])
    box = pb.createMultiBody(0, col, -1, [2.0, 1.0, 0.65])
    assert sensor.observe((0.0, 1.0, 0.0), 0.0) == []
    pb.removeBody(box)
    assert len(sensor.observe((0.0, 1.0, 0.0), 0.0)) == 1


def test_the_post_stands_beside_the_resume_point_and_carries_the_reflector_over_it():
    with World(dt=DEFAULT_DT) as world:
        mw = MobileWorld(world, course_from_codes(["S", "B", "S", "S", "E"]))
        (b,) = mw.beacons
        assert b.centre == (4.0, 1.0, 1.0) and b.post is not None
        lo, hi = mw.pb.getAABB(b.post, -1)
        assert math.hypot((lo[0] + hi[0]) / 2 - 4.0, (lo[1] + hi[1]) / 2 - 1.0) == pytest.approx(0.5, abs=0.01)
        # a robot drives under the arm: nothing of the post within 0.3 m of the resume point below 1 m
        hits = mw.pb.rayTestBatch([[4.0, 1.0 - 0.3, z] for z in (0.1, 0.5, 0.9)], [[4.0, 1.0 + 0.3, z] for z in (0.1, 0.5, 0.9)])
        assert all(h[0] == -1 for h in hits)
        assert len(mw.beacon_sensor(EXACT).observe((0.0, 1.0, 0.0), 0.0)) == 1


def test_an_observation_places_the_reflectors_foot_in_the_odometry_frame():
    model = BeaconModel(height_above_sensor=0.7, sensor_x=-0.05)
    pose = Pose2D(1.0, 2.0, 0.5)
    foot = (3.0, 3.5)
    lx, ly = pose.to_local(*foot)
    lx -= model.sensor_x
    obs = BeaconObservation(math.atan2(ly, lx), math.atan2(0.7, math.hypot(lx, ly)), 0.0)
    x, y, sigma = model.locate(pose, obs)  # type: ignore[misc]
    assert (x, y) == pytest.approx(foot)
    assert sigma == pytest.approx(math.hypot(0.7 * 0.01 / math.sin(obs.elevation) ** 2, math.dist(foot, pose.to_world(-0.05, 0.0)) * 0.01), rel=1e-6)
    assert model.locate(pose, BeaconObservation(0.0, math.radians(3), 0.0)) is None  # too flat


def _observe(model: BeaconModel, pose: Pose2D, feet, rng, sigma=0.005):
    out = []
    for fx, fy in feet:
        lx, ly = pose.to_local(fx, fy)
        lx -= model.sensor_x
        out.append(BeaconObservation(
            math.atan2(ly, lx) + rng.normal(0, sigma),
            math.atan2(model.height_above_sensor, math.hypot(lx, ly)) + rng.normal(0, sigma), pose.t,
        ))
    return out


@pytest.mark.parametrize(("foot", "exit_index", "curvature"), [((4.0, 1.0), 0, 0.0), ((3.0, 2.0), 1, 1.0), ((3.0, 0.0), 2, -1.0)])
def test_the_approach_takes_the_beacon_at_an_expected_exit_and_retraces_the_hidden_path(foot, exit_index, curvature):
    model = BeaconModel(height_above_sensor=0.7, sensor_x=-0.05)
    rng = np.random.default_rng(1)
    # the track ended at the blank square's entry (2, 1), heading east; a second beacon elsewhere
    poses = [Pose2D(2.0 - 0.05 * k, 1.0, 0.0, t=-0.05 * k) for k in range(10)]
    sightings = [(p, _observe(model, p, [foot, (5.0, 3.0)], rng)) for p in poses]
    assert expected_exits(2.0, 1.0, 0.0) == [(4.0, 1.0), (3.0, 2.0), (3.0, 0.0)]
    app = BeaconApproach(model)
    assert app.start((2.0, 1.0, 0.0), sightings)
    assert app.exit_index == exit_index
    assert app.target == pytest.approx(foot, abs=0.03)
    assert app.curvature(Pose2D(2.0, 1.0, 0.0)) == pytest.approx(curvature, abs=0.05)
    assert app.remaining(Pose2D(2.0, 1.0, 0.0)) == pytest.approx(math.dist((2.0, 1.0), foot), abs=0.03)


def test_the_approach_refuses_a_beacon_that_stands_at_no_expected_exit():
    model = BeaconModel(height_above_sensor=0.7)
    p = Pose2D(2.0, 1.0, 0.0)
    sightings = [(p, _observe(model, p, [(5.0, 3.0)], np.random.default_rng(0)))]
    app = BeaconApproach(model)
    assert not app.start((2.0, 1.0, 0.0), sightings)
    with pytest.raises(RuntimeError):
        app.curvature(p)


def test_reacquisition_needs_consecutive_confident_frames_near_the_centre():
    good = LineEstimate(0.01, 0.0, None, 0.2, 0.08, 0.32, 0.9, 50)
    weak = LineEstimate(0.01, 0.0, None, 0.2, 0.08, 0.12, 0.1, 6)
    aside = LineEstimate(0.3, 0.0, None, 0.2, 0.08, 0.32, 0.9, 50)
    r = Reacquire(frames=2)
    assert not r.update(good)
    assert not r.update(weak)
    assert not r.update(good)
    assert r.update(good)
    r.reset()
    assert not r.update(aside) and not r.update(aside)


def test_pure_pursuit_steers_on_the_circle_through_the_goal_point():
    assert pursuit_curvature(1.0, 1.0) == pytest.approx(1.0)
    assert pursuit_curvature(2.0, 0.0) == 0.0
    assert pursuit_curvature(0.26, -(1 - math.sqrt(1 - 0.26**2))) == pytest.approx(-1.0)
    assert pursuit_curvature(0.0, 0.01) == 4.0  # clamped beside the robot


def test_set_points_are_numbered_stamped_and_within_the_speed_profile():
    ctl = SteeringController(DriveGeometry(wheel_radius=0.05, track_width=0.3), SpeedLimits(cruise=0.8, accel=1.0, lateral=0.5))
    sps = [ctl.command(0.02 * k, 0.8, 0.0) for k in range(60)]
    assert [sp.seq for sp in sps] == list(range(60))
    assert sps[1].v == pytest.approx(0.02) and sps[-1].v == pytest.approx(0.8)
    curve = ctl.command(1.22, 0.8, 1.0)
    assert curve.v == pytest.approx(math.sqrt(0.5))  # lateral acceleration bound on a 1 m arc
    assert (curve.left, curve.right) == pytest.approx(DriveGeometry(wheel_radius=0.05, track_width=0.3).wheel_speeds(curve.v, 1.0))
    assert ctl.stop(1.24).v == 0.0
    with pytest.raises(ValueError, match="backwards"):
        ctl.command(1.0, 0.5, 0.0)
