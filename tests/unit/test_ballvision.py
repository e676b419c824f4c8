"""Ball locators, pixel → table calibration and the rolling-ball predictor (no sockets)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.catching.vision import (
    BallTracker,
    Homography,
    PlanarTransform,
    RollingModel,
    RollingPredictor,
    calibration_points,
    fit_homography,
    locate_average,
    locate_bgdiff,
    locate_threshold,
    table_roi,
)
from sim.catching.camera import AnalyticRenderer, calibrate, overhead_camera

Z_BALL = 0.78  # centre plane of a 40 mm ball on the 0.76 m table


@pytest.fixture(scope="module")
def camera():
    return overhead_camera()


def _renderer(camera, **kw) -> AnalyticRenderer:
    return AnalyticRenderer(camera, **kw)


@pytest.mark.parametrize("point", [(-0.3, 0.2), (-1.2, -0.3), (-0.75, 0.0), (-0.05, 0.33)])
def test_threshold_and_background_locators_find_the_projected_ball_centre(camera, point):
    r = _renderer(camera, intensity_sigma=0.0)
    pos = (*point, Z_BALL)
    img = r.render(pos)
    truth = camera.project(pos)
    d1 = locate_threshold(img, 1.5)
    d2 = locate_bgdiff(img, r.noiseless_background(), 1.5)
    assert d1 is not None and d2 is not None
    assert d1.t == 1.5
    assert math.hypot(d1.u - truth[0], d1.v - truth[1]) < 0.3
    assert math.hypot(d2.u - truth[0], d2.v - truth[1]) < 0.1


def test_locators_report_no_ball_on_an_empty_table(camera):
    r = _renderer(camera, intensity_sigma=3.0)
    img = r.render(None)
    assert locate_threshold(img, 0.0) is None
    assert locate_bgdiff(img, r.noiseless_background(), 0.0) is None
    assert locate_average([(img, 0.0), (img, 0.1)]) is None


def test_background_difference_rejects_a_background_of_another_size(camera):
    r = _renderer(camera)
    with pytest.raises(ValueError):
        locate_bgdiff(r.render(None), np.zeros((10, 10, 3), np.uint8), 0.0)


def test_averaging_over_k_frames_reduces_the_position_noise(camera):
    r = _renderer(camera, position_sigma_px=1.0, seed=4)
    pos = (-0.6, 0.1, Z_BALL)
    truth = camera.project(pos)
    single = [locate_threshold(r.render(pos), 0.0) for _ in range(60)]
    averaged = [locate_average([(r.render(pos), 0.01 * i) for i in range(8)]) for _ in range(60)]
    err1 = np.std([d.u - truth[0] for d in single if d])
    err8 = np.std([d.u - truth[0] for d in averaged if d])
    assert err8 < 0.6 * err1
    assert averaged[0] is not None and averaged[0].frames == 8
    assert averaged[0].t == pytest.approx(0.035)


def test_average_of_no_frames_is_an_error():
    with pytest.raises(ValueError):
        locate_average([])


def test_homography_fit_recovers_a_known_homography():
    h = np.array([[0.002, 1e-4, -0.8], [2e-5, -0.0021, 0.3], [1e-5, 2e-6, 1.0]])
    truth = Homography(h)
    px = np.array([[10, 20], [600, 30], [620, 470], [15, 460], [300, 240], [100, 400]], float)
    fitted = fit_homography(px, truth.to_table(px))
    assert fitted.rms_m < 1e-9
    np.testing.assert_allclose(fitted.to_table([321.0, 123.0]), truth.to_table([321.0, 123.0]))
    np.testing.assert_allclose(fitted.to_pixels(fitted.to_table([5.0, 7.0])), [5.0, 7.0], atol=1e-6)


def test_homography_fit_refuses_too_few_or_collinear_points():
    with pytest.raises(ValueError):
        fit_homography(np.zeros((3, 2)), np.zeros((3, 2)))
    line = np.array([[i, 2 * i] for i in range(6)], float)
    with pytest.raises(ValueError):
        fit_homography(line, line)


def test_calibrated_camera_maps_the_ball_to_the_table_within_a_millimetre(camera):
    r = _renderer(camera, intensity_sigma=2.0)
    hom = calibrate(lambda x, y: r.render((x, y, Z_BALL)), calibration_points(1.5, 0.76))
    assert hom.rms_m < 0.001
    rng = np.random.default_rng(0)
    for _ in range(10):
        x, y = rng.uniform(-1.4, -0.1), rng.uniform(-0.3, 0.3)
        d = locate_threshold(r.render((x, y, Z_BALL)), 0.0)
        assert d is not None
        assert np.hypot(*(hom.to_table([d.u, d.v]) - [x, y])) < 0.001


def _analytic_track(model: RollingModel, v0: float, heading: float, x0: float, y0: float, ts):
    s = model.distance(v0, np.asarray(ts))
    return x0 + s * math.cos(heading), y0 + s * math.sin(heading)


@pytest.mark.parametrize(
    "alpha, beta",
    [(0.0294, 0.0786), (0.0, 0.0786), (0.0294, 0.0), (0.0, 0.0)],
    ids=["friction+drag", "drag", "friction", "none"],
)
def test_predictor_recovers_an_analytic_trajectory_exactly_without_noise(alpha, beta):
    model = RollingModel(alpha, beta)
    v0, heading, x0, y0 = 1.1, -0.12, -1.45, 0.1
    ts = np.arange(0.0, 0.5, 0.02)
    xs, ys = _analytic_track(model, v0, heading, x0, y0, ts)
    pred = RollingPredictor(model)
    for t, x, y in zip(ts, xs, ys):
        pred.add(float(t), float(x), float(y))
    p = pred.predict()
    assert p is not None
    ds = -x0 / math.cos(heading)
    t_true = model.time_to_travel(v0, ds)
    assert t_true is not None
    assert p.y == pytest.approx(y0 + ds * math.sin(heading), abs=1e-6)
    assert p.t == pytest.approx(t_true, abs=1e-5)
    v_true = model.speed(v0, t_true)
    assert math.hypot(p.vx, p.vy) == pytest.approx(v_true, abs=1e-4)
    assert p.t_obs == pytest.approx(ts[-1])
    assert p.n == len(ts)


def test_predictor_error_with_noisy_positions_is_within_its_uncertainty():
    model = RollingModel(0.0294, 0.0786)
    rng = np.random.default_rng(7)
    errs_y, errs_t, sig_y = [], [], []
    for _ in range(40):
        v0 = rng.uniform(0.6, 1.5)
        heading = rng.uniform(-0.2, 0.2)
        x0, y0 = -1.45, rng.uniform(-0.1, 0.1)
        ts = np.arange(0.0, 0.6, 0.02)
        xs, ys = _analytic_track(model, v0, heading, x0, y0, ts)
        pred = RollingPredictor(model, position_sigma=0.002)
        for t, x, y in zip(ts, xs + rng.normal(0, 0.002, len(ts)), ys + rng.normal(0, 0.002, len(ts))):
            pred.add(float(t), float(x), float(y))
        p = pred.predict()
        assert p is not None
        ds = -x0 / math.cos(heading)
        errs_y.append(p.y - (y0 + ds * math.sin(heading)))
        errs_t.append(p.t - model.time_to_travel(v0, ds))
        sig_y.append(p.sigma_y)
    rms_y = float(np.sqrt(np.mean(np.square(errs_y))))
    assert rms_y < 0.005
    assert 0.4 < rms_y / float(np.mean(sig_y)) < 2.5
    assert float(np.sqrt(np.mean(np.square(errs_t)))) < 0.02


def test_predictor_needs_enough_points_and_a_ball_that_reaches_the_line():
    model = RollingModel(0.3, 0.0)
    pred = RollingPredictor(model, min_points=4)
    for t in (0.0, 0.02, 0.04):
        pred.add(t, -1.4 + 0.3 * t, 0.0)
    assert pred.predict() is None  # three points
    pred.add(0.06, -1.4 + 0.3 * 0.06, 0.0)
    assert pred.predict() is None  # at 0.3 m/s with 0.3 m/s^2 it stops after 0.15 m
    pred.reset()
    assert pred.count == 0


def test_predictor_ignores_points_past_the_catch_line_and_out_of_order():
    pred = RollingPredictor(RollingModel(0.0, 0.0))
    pred.add(0.0, -0.1, 0.0)
    pred.add(0.1, 0.05, 0.0)
    pred.add(-1.0, -0.2, 0.0)
    assert pred.count == 1


def test_time_to_travel_inverts_the_distance_function():
    m = RollingModel(0.03, 0.08)
    for v0 in (0.3, 0.8, 1.5):
        for tau in (0.1, 0.7, 1.3):
            d = float(m.distance(v0, tau))
            assert m.time_to_travel(v0, d) == pytest.approx(tau, abs=1e-9)


def test_planar_transform_turns_the_table_frame_into_the_robot_base_frame():
    tf = PlanarTransform.from_base_pose(0.75, 0.0, 0.46, math.pi)
    x, y, z = tf.point(-0.5, 0.2, 0.76)
    assert (x, y, z) == pytest.approx((1.25, -0.2, 0.30))
    assert tf.vector(-1.0, 0.1) == pytest.approx((1.0, -0.1))


def test_the_table_roi_leaves_out_what_lies_beyond_the_catch_line(camera):
    roi = camera.table_roi(1.5, 0.76, Z_BALL)
    u_edge = camera.project((0.0, 0.0, Z_BALL))[0]
    u_beyond = camera.project((0.03, 0.0, Z_BALL))[0]
    assert roi[2] <= u_edge + 1 and roi[2] < u_beyond
    r = _renderer(camera, intensity_sigma=0.0)
    hom = calibrate(lambda x, y: r.render((x, y, Z_BALL)), calibration_points(1.5, 0.76), roi=roi)
    roi2 = table_roi(hom, 1.5, 0.76, image_size=(camera.width, camera.height))
    assert abs(roi2[2] - roi[2]) <= 2 and abs(roi2[0] - roi[0]) <= 4
    img = r.render((0.05, 0.0, Z_BALL))  # a ball beyond the edge (as the cup would be)
    assert locate_threshold(img, 0.0) is not None
    assert locate_threshold(img, 0.0, roi=roi) is None
    d = locate_threshold(r.render((-0.5, 0.1, Z_BALL)), 0.0, roi=roi)
    assert d is not None and abs(d.u - camera.project((-0.5, 0.1, Z_BALL))[0]) < 0.3


def test_the_tracker_starts_a_new_throw_after_a_gap_or_a_jump_back(camera):
    r = _renderer(camera, intensity_sigma=0.0)
    hom = calibrate(lambda x, y: r.render((x, y, Z_BALL)), calibration_points(1.5, 0.76))
    tracker = BallTracker(hom, RollingPredictor(RollingModel(0.0, 0.0)), gap=0.1)

    def see(t: float, x: float, y: float):
        return tracker.observe(locate_threshold(r.render((x, y, Z_BALL)), t), t)

    preds = [see(0.02 * i, -1.4 + 0.02 * i, 0.0) for i in range(6)]
    assert preds[2] is None and preds[-1] is not None
    assert preds[-1].t == pytest.approx(1.4 / 1.0, abs=0.02)
    assert tracker.throws == 1
    assert see(0.12, -1.42, 0.05) is None  # jumped back: a new throw with one observation
    assert tracker.throws == 2
    assert tracker.observe(None, 0.5) is None and tracker.last_position is None
