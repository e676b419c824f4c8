"""Ball vision for the catching testbed: locate the ball, map pixels to the table, predict the catch.

Paper section 6 ("Visual Servoing and Catching"): the vision subsystem tracks the rolling ball and
the prediction subsystem iteratively estimates its trajectory and the point where it will leave the
table at the manipulator's end. Section 2 uses *locate* as the example of a primitive task with
several primitive actions of different cost and reliability; three are offered here:

* :func:`locate_threshold` — HSV colour threshold + centroid of the largest contour (one frame);
* :func:`locate_bgdiff` — difference to a background image + intensity-weighted centroid (one frame,
  cheaper, needs a background);
* :func:`locate_average` — the threshold locator over k frames, averaging positions and timestamps
  (costs k frames, noise falls as 1/√k; the paper's own example of cost rising with reliability).

Pixel → table mapping is a plane homography (Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.,
§4.1, normalised DLT) fitted by :func:`fit_homography` to pixel/table point pairs that a calibration
routine gathers (:mod:`sim.camera` places the ball at :func:`calibration_points`).

Prediction (:class:`RollingPredictor`): a rolling ball moves on a straight line (every force on it
acts along its velocity) and decelerates as dv/dt = -(α + β v²) (rolling resistance + air drag, see
:mod:`sim.catching`). The line is fitted by least squares y = a + b·x, the along-track motion by
Gauss–Newton on (s₀, v₀) with the closed-form solution

    v(τ) = √(α/β) · tan(φ₀ - cτ),   s(τ) = s₀ + (1/β) · ln(cos(φ₀ - cτ) / cos φ₀),
    φ₀ = atan(v₀ √(β/α)),   c = √(αβ),

which also gives the time of arrival at the catch line in closed form. Uncertainties are propagated
from the least-squares covariances.

This module is pure: no I/O, no clocks; OpenCV is used on arrays only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "BallTracker",
    "Detection",
    "Homography",
    "PlanarTransform",
    "Prediction",
    "Roi",
    "RollingModel",
    "RollingPredictor",
    "ThresholdParams",
    "calibration_points",
    "fit_homography",
    "locate_average",
    "locate_bgdiff",
    "locate_threshold",
    "table_roi",
]


# --------------------------------------------------------------------------------------------------
# Locators
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Detection:
    """A ball found in an image.

    Attributes:
        u, v: centroid in pixels (u along image columns, v along rows; pixel centres at integers).
        area: pixels of the ball's blob (or blobs, summed over frames for :func:`locate_average`).
        t: timestamp of the frame (or mean timestamp of the frames), s.
        frames: how many frames the detection used.
    """

    u: float
    v: float
    area: float
    t: float
    frames: int = 1


@dataclass(frozen=True, slots=True, kw_only=True)
class ThresholdParams:
    """Thresholds of the locators.

    Attributes:
        hsv_low, hsv_high: inclusive HSV bounds (OpenCV ranges: H 0–179, S and V 0–255) of the
            ball's colour (an orange ping-pong ball by default).
        min_area, max_area: accepted blob area, pixels.
        diff_threshold: grey-level difference to the background that marks a ball pixel.
    """

    hsv_low: tuple[int, int, int] = (5, 120, 120)
    hsv_high: tuple[int, int, int] = (30, 255, 255)
    min_area: float = 4.0
    max_area: float = 5000.0
    diff_threshold: int = 40


def _largest_blob(mask: np.ndarray, params: ThresholdParams) -> np.ndarray | None:
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    best = None
    best_area = 0.0
    for c in contours:
        area = cv2.contourArea(c)
        if area > best_area:
            best, best_area = c, area
    if best is None or not (params.min_area <= max(best_area, 1.0) <= params.max_area):
        return None
    return best


Roi = tuple[int, int, int, int]
"""Region of interest (u0, v0, u1, v1) in pixels, end-exclusive: only this part of a frame is searched."""


def _crop(frame: np.ndarray, roi: Roi | None) -> tuple[np.ndarray, int, int]:
    if roi is None:
        return frame, 0, 0
    u0, v0, u1, v1 = roi
    return frame[max(0, v0) : v1, max(0, u0) : u1], max(0, u0), max(0, v0)


def locate_threshold(
    frame: np.ndarray, t: float, params: ThresholdParams | None = None, roi: Roi | None = None
) -> Detection | None:
    """Locate the ball by HSV colour threshold and the centroid of the largest contour.

    Args:
        frame: (H, W, 3) uint8 BGR image.
        t: timestamp of the frame, s.
        params: thresholds.
        roi: search only this region (e.g. :func:`table_roi`, which keeps the robot's orange cup
            beyond the table edge out of the search).

    Returns:
        The detection, or None when no blob of acceptable area has the ball's colour.
    """
    p = params or ThresholdParams()
    frame, du, dv = _crop(frame, roi)
    hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
    mask = cv2.inRange(hsv, np.array(p.hsv_low, np.uint8), np.array(p.hsv_high, np.uint8))
    blob = _largest_blob(mask, p)
    if blob is None:
        return None
    x, y, w, h = cv2.boundingRect(blob)
    blob_mask = mask[y : y + h, x : x + w]
    m = cv2.moments(blob_mask, binaryImage=True)
    if m["m00"] <= 0:
        return None
    return Detection(
        u=du + x + m["m10"] / m["m00"], v=dv + y + m["m01"] / m["m00"], area=m["m00"], t=t
    )


def locate_bgdiff(
    frame: np.ndarray,
    background: np.ndarray,
    t: float,
    params: ThresholdParams | None = None,
    roi: Roi | None = None,
) -> Detection | None:
    """Locate the ball as the largest region differing from a background image.

    The centroid is weighted by the grey-level difference inside the region, which gives
    sub-pixel accuracy from the anti-aliased edge.

    Args:
        frame: (H, W, 3) uint8 BGR image.
        background: (H, W, 3) uint8 BGR image of the scene without the ball.
        t: timestamp of the frame, s.
        params: thresholds.
        roi: search only this region.

    Returns:
        The detection, or None when nothing differs enough from the background.

    Raises:
        ValueError: if frame and background differ in shape.
    """
    if frame.shape != background.shape:
        raise ValueError(f"frame {frame.shape} and background {background.shape} differ in shape")
    p = params or ThresholdParams()
    frame, du, dv = _crop(frame, roi)
    background, _, _ = _crop(background, roi)
    diff = cv2.absdiff(frame, background)
    if diff.ndim == 3:
        b, g, r = cv2.split(diff)
        grey = cv2.max(cv2.max(b, g), r)
    else:
        grey = diff
    _, mask = cv2.threshold(grey, p.diff_threshold, 255, cv2.THRESH_BINARY)
    blob = _largest_blob(mask, p)
    if blob is None:
        return None
    x, y, w, h = cv2.boundingRect(blob)
    x0, y0 = max(0, x - 2), max(0, y - 2)
    x1, y1 = min(grey.shape[1], x + w + 2), min(grey.shape[0], y + h + 2)
    patch = grey[y0:y1, x0:x1].astype(np.float32)
    patch = np.where(patch >= p.diff_threshold / 2, patch, 0.0).astype(np.float32)
    m = cv2.moments(patch)
    if m["m00"] <= 0:
        return None
    area = float(np.count_nonzero(mask[y : y + h, x : x + w]))
    return Detection(
        u=du + x0 + m["m10"] / m["m00"], v=dv + y0 + m["m01"] / m["m00"], area=area, t=t
    )


def locate_average(
    frames: Sequence[tuple[np.ndarray, float]],
    params: ThresholdParams | None = None,
    roi: Roi | None = None,
) -> Detection | None:
    """Locate the ball in k frames with :func:`locate_threshold` and average.

    Positions and timestamps are averaged together: for a ball moving at constant velocity the mean
    position is exactly the position at the mean time, and the noise falls as 1/√k.

    Args:
        frames: k pairs (BGR frame (H, W, 3) uint8, timestamp s), k >= 1.
        params: thresholds.
        roi: search only this region.

    Returns:
        The averaged detection (``frames`` = number of frames the ball was found in), or None when
        the ball was found in fewer than half of the frames.

    Raises:
        ValueError: if ``frames`` is empty.
    """
    if not frames:
        raise ValueError("locate_average needs at least one frame")
    found = [d for f, t in frames if (d := locate_threshold(f, t, params, roi)) is not None]
    if 2 * len(found) < len(frames):
        return None
    return Detection(
        u=float(np.mean([d.u for d in found])),
        v=float(np.mean([d.v for d in found])),
        area=float(np.sum([d.area for d in found])),
        t=float(np.mean([d.t for d in found])),
        frames=len(found),
    )


# --------------------------------------------------------------------------------------------------
# Pixel -> table mapping
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Homography:
    """A plane homography from pixels to table coordinates (of the ball's centre plane).

    Attributes:
        matrix: (3, 3) H with [x, y, 1]ᵀ ∝ H [u, v, 1]ᵀ; x, y in metres (table frame).
        rms_m: root-mean-square residual of the calibration points, m.
    """

    matrix: np.ndarray
    rms_m: float = 0.0

    def to_table(self, uv: np.ndarray | Sequence[float]) -> np.ndarray:
        """Map pixels to table coordinates.

        Args:
            uv: (2,) or (N, 2) pixel coordinates.

        Returns:
            (2,) or (N, 2) table coordinates x, y in metres.
        """
        a = np.asarray(uv, dtype=float)
        pts = np.atleast_2d(a)
        h = np.hstack([pts, np.ones((pts.shape[0], 1))]) @ self.matrix.T
        out = h[:, :2] / h[:, 2:3]
        result: np.ndarray = out[0] if a.ndim == 1 else out
        return result

    def to_pixels(self, xy: np.ndarray | Sequence[float]) -> np.ndarray:
        """Inverse mapping, table (2,)/(N, 2) metres to pixels (2,)/(N, 2)."""
        inv = Homography(np.linalg.inv(self.matrix))
        return inv.to_table(xy)


def _normaliser(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(axis=0)
    d = np.sqrt(((pts - c) ** 2).sum(axis=1)).mean()
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def fit_homography(pixels: np.ndarray, table: np.ndarray) -> Homography:
    """Fit the pixel → table homography by normalised DLT (Hartley & Zisserman, Alg. 4.2).

    Args:
        pixels: (N, 2) pixel coordinates of calibration points, N >= 4.
        table: (N, 2) their table coordinates, m.

    Returns:
        The homography, with the RMS residual of the points in metres.

    Raises:
        ValueError: with fewer than 4 points, mismatched shapes or a degenerate configuration.
    """
    px = np.asarray(pixels, dtype=float)
    tb = np.asarray(table, dtype=float)
    if px.shape != tb.shape or px.ndim != 2 or px.shape[1] != 2 or px.shape[0] < 4:
        raise ValueError("fit_homography needs two (N, 2) arrays with N >= 4")
    tp, tt = _normaliser(px), _normaliser(tb)
    ph = np.hstack([px, np.ones((len(px), 1))]) @ tp.T
    th = np.hstack([tb, np.ones((len(tb), 1))]) @ tt.T
    rows = []
    for (u, v, w), (x, y, z) in zip(ph, th, strict=True):
        rows.append([0, 0, 0, -z * u, -z * v, -z * w, y * u, y * v, y * w])
        rows.append([z * u, z * v, z * w, 0, 0, 0, -x * u, -x * v, -x * w])
    _, sv, vt = np.linalg.svd(np.asarray(rows))
    if sv[-2] < 1e-9 * sv[0]:
        raise ValueError("degenerate calibration points (collinear?)")
    hn = vt[-1].reshape(3, 3)
    h = np.linalg.inv(tt) @ hn @ tp
    h = h / h[2, 2]
    hom = Homography(h)
    res = hom.to_table(px) - tb
    return Homography(h, float(np.sqrt((res**2).sum(axis=1).mean())))


def table_roi(
    homography: Homography, length: float, width: float, *, catch_x: float = 0.0, margin_px: int = 3,
    image_size: tuple[int, int] | None = None,
) -> Roi:
    """Bounding box in pixels of the table top x in [-length, catch_x], |y| <= width/2.

    The right edge stops at the catch line (no margin there), so the robot's cup beyond the edge
    is never searched; the other edges get ``margin_px`` of slack. ``image_size`` = (W, H) clips.
    """
    corners = np.array(
        [[-length, -width / 2], [catch_x, -width / 2], [catch_x, width / 2], [-length, width / 2]]
    )
    px = homography.to_pixels(corners)
    u0, v0 = np.floor(px.min(axis=0)).astype(int) - margin_px
    u1, v1 = np.ceil(px.max(axis=0)).astype(int) + margin_px
    # the catch-line side: the edge of the image nearest to the catch line's projection
    edge = homography.to_pixels(np.array([[catch_x, 0.0], [catch_x - 0.1, 0.0]]))
    if edge[0][0] > edge[1][0]:
        u1 = int(np.floor(px[1:3, 0].min()))
    elif edge[0][0] < edge[1][0]:
        u0 = int(np.ceil(px[1:3, 0].max()))
    u0, v0 = max(0, int(u0)), max(0, int(v0))
    if image_size is not None:
        u1, v1 = min(int(u1), image_size[0]), min(int(v1), image_size[1])
    return (u0, v0, int(u1), int(v1))


def calibration_points(
    length: float, width: float, nx: int = 5, ny: int = 4, margin: float = 0.08
) -> np.ndarray:
    """A grid of nx × ny calibration points on the table top (table frame), (nx*ny, 2) metres."""
    xs = np.linspace(-length + margin, -margin, nx)
    ys = np.linspace(-width / 2 + margin, width / 2 - margin, ny)
    return np.array([[x, y] for x in xs for y in ys])


# --------------------------------------------------------------------------------------------------
# Prediction
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class RollingModel:
    """Deceleration model of a rolling ball, dv/dt = -(α + β v²).

    Attributes:
        alpha: constant part (rolling resistance), m/s², >= 0.
        beta: quadratic part (air drag), 1/m, >= 0.
    """

    alpha: float
    beta: float

    def distance(self, v0: float | np.ndarray, tau: float | np.ndarray) -> np.ndarray:
        """Distance (m) travelled in time τ (s) from speed v0 (m/s); the ball stops at v = 0."""
        a, b = self.alpha, self.beta
        v0 = np.asarray(v0, dtype=float)
        tau = np.asarray(tau, dtype=float)
        out: np.ndarray
        if a <= 0.0 and b <= 0.0:
            out = v0 * tau
        elif b <= 0.0:
            tt = np.minimum(tau, v0 / a)
            out = v0 * tt - 0.5 * a * tt**2
        elif a <= 0.0:
            out = np.log1p(b * v0 * tau) / b
        else:
            c = math.sqrt(a * b)
            phi0 = np.arctan(v0 * math.sqrt(b / a))
            tt = np.minimum(tau, phi0 / c)
            out = np.log(np.cos(phi0 - c * tt) / np.cos(phi0)) / b
        return out

    def speed(self, v0: float, tau: float) -> float:
        """Speed (m/s) after time τ (s) from speed v0 (m/s), never below 0."""
        a, b = self.alpha, self.beta
        if a <= 0.0 and b <= 0.0:
            return v0
        if b <= 0.0:
            return max(0.0, v0 - a * tau)
        if a <= 0.0:
            return v0 / (1.0 + b * v0 * tau)
        c = math.sqrt(a * b)
        phi0 = math.atan(v0 * math.sqrt(b / a))
        return max(0.0, math.sqrt(a / b) * math.tan(phi0 - c * tau))

    def time_to_travel(self, v0: float, ds: float) -> float | None:
        """Time (s) to travel ds >= 0 metres from speed v0, or None if the ball stops first."""
        a, b = self.alpha, self.beta
        if ds <= 0.0:
            return 0.0
        if v0 <= 0.0:
            return None
        if a <= 0.0 and b <= 0.0:
            return ds / v0
        if b <= 0.0:
            disc = v0 * v0 - 2.0 * a * ds
            return None if disc < 0 else (v0 - math.sqrt(disc)) / a
        if a <= 0.0:
            return math.expm1(b * ds) / (b * v0)
        c = math.sqrt(a * b)
        phi0 = math.atan(v0 * math.sqrt(b / a))
        arg = math.cos(phi0) * math.exp(b * ds)
        if arg > 1.0:
            return None
        return (phi0 - math.acos(arg)) / c


@dataclass(frozen=True, slots=True)
class Prediction:
    """Predicted crossing of the catch line x = catch_x (table frame).

    Attributes:
        x: the catch line's x, m.
        y: predicted lateral crossing point, m.
        t: predicted time of the crossing, s (same clock as the observations).
        vx, vy: predicted velocity at the crossing, m/s.
        sigma_y: 1-σ uncertainty of y, m.
        sigma_t: 1-σ uncertainty of t, s.
        t_obs: timestamp of the last observation used, s.
        n: observations used.
    """

    x: float
    y: float
    t: float
    vx: float
    vy: float
    sigma_y: float
    sigma_t: float
    t_obs: float
    n: int


class RollingPredictor:
    """Iterative estimate of a rolling ball's trajectory and of its catch-line crossing.

    Feed it timestamped table positions of one throw with :meth:`add`; :meth:`predict` fits the
    straight path and the decelerating along-track motion to all of them and returns the predicted
    crossing of x = ``catch_x``. Call :meth:`reset` between throws.

    Args:
        model: deceleration model (α, β) of the rolling ball.
        catch_x: x of the catch line, m (the table's near edge).
        min_points: observations needed before a prediction is made.
        position_sigma: assumed 1-σ noise of an observed position, m (floor of the uncertainty).
        max_points: only the last ``max_points`` observations are used.
    """

    def __init__(
        self,
        model: RollingModel,
        *,
        catch_x: float = 0.0,
        min_points: int = 4,
        position_sigma: float = 0.001,
        max_points: int = 400,
    ) -> None:
        if min_points < 3:
            raise ValueError("min_points must be >= 3")
        self.model = model
        self.catch_x = catch_x
        self.min_points = min_points
        self.position_sigma = position_sigma
        self.max_points = max_points
        self._obs: list[tuple[float, float, float]] = []

    def reset(self) -> None:
        """Forget all observations (a new throw)."""
        self._obs.clear()

    @property
    def count(self) -> int:
        """Observations held."""
        return len(self._obs)

    def add(self, t: float, x: float, y: float) -> None:
        """Add an observed ball position (x, y) m at time t s; ignores points past the catch line."""
        if x >= self.catch_x:
            return
        if self._obs and t <= self._obs[-1][0]:
            return
        self._obs.append((float(t), float(x), float(y)))
        if len(self._obs) > self.max_points:
            del self._obs[0]

    def predict(self) -> Prediction | None:
        """Predict the crossing from the observations held.

        Returns:
            The prediction, or None with too few observations, a ball not moving towards the catch
            line, or a ball predicted to stop before reaching it.
        """
        if len(self._obs) < self.min_points:
            return None
        obs = np.asarray(self._obs)
        t, x, y = obs[:, 0], obs[:, 1], obs[:, 2]
        n = len(t)
        # 1. straight path y = a + b (x - xm), least squares, one pass of 3-sigma rejection
        keep = np.ones(n, dtype=bool)
        for _ in range(2):
            xm = x[keep].mean()
            design = np.column_stack([np.ones(keep.sum()), x[keep] - xm])
            coef, *_ = np.linalg.lstsq(design, y[keep], rcond=None)
            res = y - (coef[0] + coef[1] * (x - xm))
            sig = max(float(np.std(res[keep])), self.position_sigma * 0.1)
            new_keep = np.abs(res) <= 3.0 * sig + 1e-12
            if new_keep.sum() < self.min_points or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        a, b = float(coef[0]), float(coef[1])
        dof = max(1, int(keep.sum()) - 2)
        s2 = max(float((res[keep] ** 2).sum()) / dof, self.position_sigma**2)
        cov = s2 * np.linalg.inv(design.T @ design)
        dxc = self.catch_x - xm
        y_cross = a + b * dxc
        var_y = cov[0, 0] + 2 * dxc * cov[0, 1] + dxc * dxc * cov[1, 1]
        # 2. along-track motion s(t) on the path, Gauss-Newton on (s0, v0) at t_ref = last time
        norm = math.hypot(1.0, b)
        ux, uy = 1.0 / norm, b / norm
        s = (x[keep] - xm) * ux + (y[keep] - a) * uy
        tk = t[keep]
        t_ref = float(t[-1])
        tau = tk - t_ref
        # initial guess from a straight-line fit of s(t)
        lin = np.polyfit(tau, s, 1) if len(tau) >= 2 else np.array([0.0, s[-1]])
        v_ref = float(lin[0])
        if v_ref <= 1e-6 or ux <= 0:
            return None
        s_ref = float(lin[1])
        theta = self._fit_along(tau, s, s_ref, v_ref)
        if theta is None:
            return None
        s_ref, v_ref, cov_sv = theta
        s_cross = dxc * ux + (y_cross - a) * uy
        dt = self.model.time_to_travel(v_ref, s_cross - s_ref)
        if dt is None:
            return None
        # uncertainty of the time by finite differences on (s_ref, v_ref)
        eps_s, eps_v = 1e-4, 1e-4 * max(v_ref, 1e-3)
        t1 = self.model.time_to_travel(v_ref, s_cross - s_ref - eps_s)
        t2 = self.model.time_to_travel(v_ref + eps_v, s_cross - s_ref)
        if t1 is None or t2 is None:
            var_t = 0.0
        else:
            g = np.array([(t1 - dt) / eps_s, (t2 - dt) / eps_v])
            var_t = float(g @ cov_sv @ g)
        v_cross = self.model.speed(v_ref, dt)
        return Prediction(
            x=self.catch_x,
            y=float(y_cross),
            t=t_ref + dt,
            vx=v_cross * ux,
            vy=v_cross * uy,
            sigma_y=math.sqrt(max(var_y, 0.0)),
            sigma_t=math.sqrt(max(var_t, 0.0)),
            t_obs=t_ref,
            n=int(keep.sum()),
        )

    def _fit_along(
        self, tau: np.ndarray, s: np.ndarray, s_ref: float, v_ref: float
    ) -> tuple[float, float, np.ndarray] | None:
        """Gauss-Newton for s(τ) = s_ref + D(v_ref, τ) where D is the model's distance function.

        For τ < 0 (the past) the distance is negative; D(v_ref, τ) for τ < 0 is evaluated by
        running the model backwards: the speed at τ is found from the model and the distance
        between then and now subtracted.
        """
        model = self.model

        def back_distance(v: float, taus: np.ndarray) -> np.ndarray:
            # distance from time tau (<= 0) to time 0 is D(v_tau, -tau) where v_tau solves
            # speed(v_tau, -tau) = v; invert with the time-reversed ODE dv/dτ = +(α + β v²).
            a, b = model.alpha, model.beta
            back = -taus
            if a > 0 and b > 0:
                c = math.sqrt(a * b)
                phi = math.atan(v * math.sqrt(b / a))
                phi_tau = np.minimum(phi + c * back, math.pi / 2 - 1e-9)
                dist: np.ndarray = np.log(np.cos(phi) / np.cos(phi_tau)) / b
                return dist
            if b > 0:
                return np.log(1.0 / np.maximum(1e-12, 1.0 - b * v * back)) / b
            return v * back + 0.5 * a * back**2

        theta = np.array([s_ref, v_ref], dtype=float)
        for _ in range(20):
            f = theta[0] - back_distance(theta[1], tau)
            r = s - f
            h = 1e-6 * max(1.0, abs(theta[1]))
            df_dv = (-(back_distance(theta[1] + h, tau)) - (-(back_distance(theta[1], tau)))) / h
            jac = np.column_stack([np.ones_like(tau), df_dv])
            jtj = jac.T @ jac
            try:
                step = np.linalg.solve(jtj + 1e-12 * np.eye(2), jac.T @ r)
            except np.linalg.LinAlgError:
                return None
            theta = theta + step
            if theta[1] <= 0:
                return None
            if abs(step[0]) < 1e-9 and abs(step[1]) < 1e-9:
                break
        f = theta[0] - back_distance(theta[1], tau)
        r = s - f
        dof = max(1, len(tau) - 2)
        s2 = max(float(r @ r) / dof, self.position_sigma**2)
        try:
            cov = s2 * np.linalg.inv(jtj)
        except np.linalg.LinAlgError:
            return None
        return float(theta[0]), float(theta[1]), cov


@dataclass(frozen=True, slots=True)
class PlanarTransform:
    """A rigid transform between the table frame and the robot base frame (rotation about z).

    p_base = Rz(yaw)ᵀ (p_table - origin), where origin (m) and yaw (rad) give the base frame's pose in
    the table frame. The paper's set points are "coordinates, in the manipulator base frame, of the
    point where [the ball] will leave the table" (section 6).

    Attributes:
        ox, oy, oz: origin of the base frame in the table frame, m.
        yaw: rotation of the base frame about z, rad.
    """

    ox: float
    oy: float
    oz: float
    yaw: float

    @classmethod
    def from_base_pose(cls, x: float, y: float, z: float, yaw: float) -> PlanarTransform:
        """From the base frame's position (m) and yaw (rad) in the table frame."""
        return cls(float(x), float(y), float(z), float(yaw))

    def point(self, x: float, y: float, z: float = 0.0) -> tuple[float, float, float]:
        """Table-frame point (m) → base-frame point (m); z defaults to the table frame's floor."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = x - self.ox, y - self.oy
        return c * dx + s * dy, -s * dx + c * dy, z - self.oz

    def vector(self, vx: float, vy: float) -> tuple[float, float]:
        """Table-frame horizontal vector → base-frame vector (same units)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return c * vx + s * vy, -s * vx + c * vy


class BallTracker:
    """Locations in, predictions out: the vision node's per-frame pipeline after the locator.

    Maps each detection to the table with the calibrated homography, feeds the predictor, and
    starts a new throw (resets the predictor) when the ball was not seen for ``gap`` seconds or
    jumped back towards the thrower by more than ``jump`` metres.

    Args:
        homography: calibrated pixel → table map.
        predictor: the rolling-ball predictor (owned by the tracker from now on).
        gap: s without a detection that ends a throw.
        jump: m of backward motion that starts a new throw.
        roi: region of the image to search (see :func:`table_roi`), for the locate functions.
    """

    def __init__(
        self, homography: Homography, predictor: RollingPredictor, *, gap: float = 0.15,
        jump: float = 0.05, roi: Roi | None = None,
    ) -> None:
        self.roi = roi
        self.homography = homography
        self.predictor = predictor
        self.gap = gap
        self.jump = jump
        self._last: tuple[float, float, float] | None = None
        self.throws = 0

    def observe(self, det: Detection | None, t: float) -> Prediction | None:
        """Take one frame's detection (or None) at frame time t (s); return the prediction, if any.

        Returns None when the ball is not seen, when too few observations are held, or when the
        predictor cannot predict a crossing.
        """
        if det is None:
            if self._last is not None and t - self._last[0] > self.gap:
                self.predictor.reset()
                self._last = None
            return None
        x, y = (float(c) for c in self.homography.to_table([det.u, det.v]))
        if self._last is None or det.t - self._last[0] > self.gap or x < self._last[1] - self.jump:
            self.predictor.reset()
            self.throws += 1
        self._last = (det.t, x, y)
        self.predictor.add(det.t, x, y)
        return self.predictor.predict()

    @property
    def last_position(self) -> tuple[float, float, float] | None:
        """(t, x, y) of the last observation, table frame, or None."""
        return self._last
