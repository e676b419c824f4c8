"""Track detectors: where the painted track lies in a downward camera frame.

Paper section 6 ("Mobile Robot Task"): the track has the colour *opposite* to the square it
crosses, so its colour flips at every square boundary; the detectors therefore look for contrast —
a thin band differing from its surroundings in either direction — never for a colour. Section 2's
notion of several primitive actions of different cost and reliability for one primitive task is
served by three detectors of the same interface (``detect(image) -> LineEstimate | None``):

* :class:`CentroidDetector` — thin-structure map of the whole frame (morphological white top-hat
  plus black top-hat, Soille, *Morphological Image Analysis*, 2nd ed., §4.4), then per row the
  centroid of the thin pixels, rows gated by the band's width and contiguity, and a weighted
  least-squares fit of a quadratic y(x). Area-based: robust to pixel noise, pulled by scuffs
  next to the track; ~0.3 ms at 80×60.
* :class:`RansacDetector` — horizontal Sobel gradient; per row the strongest rising and falling
  edges, kept when they are a track width apart (either polarity), then a RANSAC line (Fischler &
  Bolles, CACM 24(6), 1981) over the row centres and a least-squares refit on the inliers.
  Rejects outlier rows (marks, scuffs, noise edges); ~0.3 ms.
* :class:`ScanLineDetector` — the same edge pairing on five scan lines only (each the mean of three
  image rows) and a straight-line least-squares fit; no curvature, no outlier rejection; the
  cheapest (~0.2 ms; image work grows with the width only) and the least reliable (a scuff on one
  of its lines moves or loses the line).

A :class:`LineEstimate` gives, in the robot frame, the lateral position of the track's centre line
at a reference distance ahead, its direction and (when measurable) its curvature, plus a
confidence in [0, 1]. Images are (H, W) uint8 grey (or (H, W, 3) BGR, converted) laid out as
:class:`services.mobile.camera.GroundCamera` says. Pure module (no I/O).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from .camera import GroundCamera

__all__ = [
    "DETECTORS",
    "CentroidDetector",
    "LineDetector",
    "LineEstimate",
    "RansacDetector",
    "ScanLineDetector",
    "make_detector",
    "thin_structures",
    "to_grey",
]


@dataclass(frozen=True, slots=True)
class LineEstimate:
    """The track's centre line seen in one frame, in the robot frame.

    The line is the model y(x) = offset + tan(heading)·(x - x_ref) + ½·c·(x - x_ref)², c the
    second derivative (curvature·(1 + tan²)^{3/2}; 0 when the detector fits no curvature).

    Attributes:
        offset: lateral position y of the centre line at x = x_ref, m (+ left of the robot).
        heading: direction of the track relative to the robot's x axis, rad (+ CCW).
        curvature: signed curvature of the track at x_ref, 1/m (+ turning left), or None when the
            detector does not measure it.
        x_ref: forward distance at which offset and heading are given, m.
        x_min, x_max: forward extent of the rows that contributed, m.
        confidence: 0 (nothing usable) … 1 (every row found, fit residual within a pixel).
        rows: number of image rows (or scan lines) that contributed.
    """

    offset: float
    heading: float
    curvature: float | None
    x_ref: float
    x_min: float
    x_max: float
    confidence: float
    rows: int

    def lateral_at(self, x: float) -> float:
        """Lateral position y (m) of the fitted centre line at forward distance x (m)."""
        dx = x - self.x_ref
        c = 0.0
        if self.curvature is not None:
            c = self.curvature * (1.0 + math.tan(self.heading) ** 2) ** 1.5
        return self.offset + math.tan(self.heading) * dx + 0.5 * c * dx * dx


class LineDetector(Protocol):
    """Interface of a track detector."""

    name: str
    camera: GroundCamera

    def detect(self, image: np.ndarray) -> LineEstimate | None:
        """The track in ``image`` ((H, W) uint8 grey or (H, W, 3) BGR), or None if not found."""
        ...


def to_grey(image: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grey view of an (H, W) grey or (H, W, 3) BGR uint8 image.

    Raises:
        ValueError: on another shape or dtype.
    """
    if image.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise ValueError(f"expected an (H, W) or (H, W, 3) image, got shape {image.shape}")


def thin_structures(grey: np.ndarray, kernel_px: int, smooth_px: float = 1.2) -> np.ndarray:
    """Contrast of thin bands of either polarity: white top-hat + black top-hat.

    A band narrower than the square structuring element (bright on dark *or* dark on bright) keeps
    its full contrast; uniform areas and the boundary between two large areas (a square edge) give
    about 0; so does a strip along the image border (the border is replicated outwards). The
    image is smoothed first: a top-hat measures a pixel against the extreme values
    of its neighbourhood, so unsmoothed pixel noise of σ grey levels reads as thin structure of
    several σ everywhere.

    Args:
        grey: (H, W) uint8 image.
        kernel_px: side of the square structuring element, pixels (about twice the track width).
        smooth_px: 1-σ of the Gaussian pre-smoothing, pixels (0 = none).

    Returns:
        (H, W) uint8 contrast map (saturating sum of the two top-hats).
    """
    if smooth_px > 0:
        grey = cv2.GaussianBlur(grey, (0, 0), smooth_px)
    k = max(3, int(kernel_px) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (k, k))
    # the image continues beyond its border as its edge pixels (padded before the morphology: a
    # border mode of the operators would replicate their intermediate results instead), so that a
    # strip of background between a mark and the border is not mistaken for a thin band
    p = k // 2
    padded = cv2.copyMakeBorder(grey, p, p, p, p, cv2.BORDER_REPLICATE)
    white = cv2.morphologyEx(padded, cv2.MORPH_TOPHAT, kernel)
    black = cv2.morphologyEx(padded, cv2.MORPH_BLACKHAT, kernel)
    return cv2.add(white, black)[p:-p, p:-p]


def _fit(
    x: np.ndarray, y: np.ndarray, w: np.ndarray, x_ref: float, quadratic: bool
) -> tuple[np.ndarray, float]:
    """Weighted least squares of y = p0 + p1·dx (+ p2·dx²/2), dx = x - x_ref.

    Returns:
        (coefficients (3,) with p2 = 0 for a straight fit, weighted residual RMS in m).
    """
    dx = x - x_ref
    cols = [np.ones_like(dx), dx] + ([0.5 * dx * dx] if quadratic else [])
    a = np.stack(cols, axis=1)
    aw = a * w[:, None]
    try:  # normal equations: two or three unknowns, well scaled (dx is a fraction of a metre)
        coef = np.linalg.solve(aw.T @ a, aw.T @ y)
    except np.linalg.LinAlgError:
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
    res = y - a @ coef
    rms = float(np.sqrt(np.sum(w * res * res) / max(float(np.sum(w)), 1e-12)))
    out = np.zeros(3)
    out[: len(coef)] = coef
    return out, rms


def _estimate(
    coef: np.ndarray, rms: float, x: np.ndarray, x_ref: float, rows_found: int, rows_total: int,
    px: float, quadratic: bool,
) -> LineEstimate:
    b, c = float(coef[1]), float(coef[2])
    slope = 1.0 + b * b
    quality = 1.0 / (1.0 + (rms / (1.5 * px)) ** 2)
    return LineEstimate(
        offset=float(coef[0]),
        heading=math.atan(b),
        curvature=(c / slope**1.5) if quadratic else None,
        x_ref=x_ref,
        x_min=float(x.min()),
        x_max=float(x.max()),
        confidence=float(min(1.0, rows_found / rows_total) * quality),
        rows=rows_found,
    )


@dataclass(slots=True, kw_only=True)
class _Common:
    camera: GroundCamera
    track_width: float = 0.05
    """Painted track width, m."""
    min_contrast: float = 60.0
    """Smallest grey-level difference between track and square accepted as track."""
    min_rows: int = 4
    """Fewest rows a line is fitted to."""
    curvature_span: float = 0.45
    """A curvature is fitted only if the rows found span this fraction of the view's length."""

    def _width_px(self) -> float:
        return self.camera.px(self.track_width)


class CentroidDetector(_Common):
    """Thin-structure centroid per row + weighted quadratic least squares (see module docstring).

    Args:
        camera: the camera model (gives row distances and pixel size).
        track_width: painted track width, m.
        min_contrast: grey levels; thin pixels below ``max(min_contrast, ½ · strongest)`` are
            ignored.
        min_rows: fewest valid rows for a fit.
        curvature_span: see :class:`LineEstimate`; below it the fit is a straight line.
    """

    name = "centroid"

    def detect(self, image: np.ndarray) -> LineEstimate | None:
        """The track in ``image``, or None (fewer than ``min_rows`` rows with a track-wide band)."""
        grey = to_grey(image)
        cam = self.camera
        wpx = self._width_px()
        thin = thin_structures(grey, round(2.0 * wpx))
        peak = float(thin.max())
        thr = max(self.min_contrast, 0.5 * peak)
        if peak < self.min_contrast:
            return None
        wgt = np.where(thin >= thr, thin.astype(np.float32) - np.float32(thr / 2.0), np.float32(0.0))
        mask = wgt > 0
        count = mask.sum(axis=1)
        first = np.argmax(mask, axis=1)
        last = mask.shape[1] - 1 - np.argmax(mask[:, ::-1], axis=1)
        span = last - first + 1
        ok = (count >= 0.5 * wpx) & (count <= 2.4 * wpx) & (span <= count + 2)
        # bands touching the image border are cut: their centroid is biased
        ok &= (first > 0) & (last < mask.shape[1] - 1)
        if int(ok.sum()) < self.min_rows:
            return None
        sw = wgt.sum(axis=1)
        u = (wgt @ np.arange(mask.shape[1], dtype=np.float32)) / np.maximum(sw, 1e-6)
        xs = cam.row_x()[ok]
        _, ys = cam.pixel_to_floor(u[ok], 0.0)
        quad = (xs.max() - xs.min()) >= self.curvature_span * cam.height * cam.metres_per_px
        coef, rms = _fit(xs, ys, np.ones_like(xs), cam.x_centre, quad)
        return _estimate(coef, rms, xs, cam.x_centre, int(ok.sum()), cam.height, cam.metres_per_px, quad)


def _edge_pairs(
    grad: np.ndarray, wpx: float, thr: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per row of a horizontal-gradient array (R, W): the strongest rising and falling edges.

    Returns:
        (ok (R,) bool — both edges above ``thr`` and 0.5–2.4 track widths apart, centre (R,) —
        subpixel column midway between them).
    """
    rows = np.arange(grad.shape[0])
    ip = np.argmax(grad, axis=1)
    im = np.argmin(grad, axis=1)
    gp = grad[rows, ip]
    gm = grad[rows, im]
    w = grad.shape[1]

    def refine(i: np.ndarray) -> np.ndarray:
        lo = np.clip(i - 1, 0, w - 1)
        hi = np.clip(i + 1, 0, w - 1)
        a, b, c = grad[rows, lo], grad[rows, i], grad[rows, hi]
        den = a - 2.0 * b + c
        off = np.where(np.abs(den) > 1e-9, 0.5 * (a - c) / np.where(den == 0, 1.0, den), 0.0)
        return i + np.clip(off, -0.5, 0.5)

    sep = np.abs(ip - im)
    ok = (gp >= thr) & (-gm >= thr) & (sep >= 0.5 * wpx) & (sep <= 2.4 * wpx)
    ok &= (ip > 0) & (ip < w - 1) & (im > 0) & (im < w - 1)
    return ok, 0.5 * (refine(ip) + refine(im))


class RansacDetector(_Common):
    """Edge pairs per row + RANSAC line + least-squares refit (see module docstring).

    Args:
        camera, track_width, min_contrast, min_rows, curvature_span: as :class:`CentroidDetector`.
        hypotheses: RANSAC line hypotheses per frame (pairs of rows).
        inlier_px: a row is an inlier if its centre is within this many pixels of the line.
        seed: seed of the hypothesis sampler (the detector is deterministic for a seed).
    """

    name = "ransac"

    def __init__(
        self, camera: GroundCamera, *, hypotheses: int = 24, inlier_px: float = 2.5, seed: int = 0,
        **kw: float,
    ) -> None:
        super().__init__(camera=camera, **kw)  # type: ignore[arg-type]
        self.hypotheses = hypotheses
        self.inlier_px = inlier_px
        self._rng = np.random.default_rng(seed)

    def detect(self, image: np.ndarray) -> LineEstimate | None:
        """The track in ``image``, or None (fewer than ``min_rows`` inlier rows)."""
        grey = to_grey(image)
        cam = self.camera
        wpx = self._width_px()
        grad = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
        peak = float(np.abs(grad).max())
        # a sharp step of contrast C gives a Sobel response of 4·C
        thr = max(4.0 * self.min_contrast, 0.35 * peak)
        ok, centre = _edge_pairs(grad, wpx, thr)
        n = int(ok.sum())
        if n < self.min_rows:
            return None
        xs = cam.row_x()[ok]
        _, ys = cam.pixel_to_floor(centre[ok], 0.0)
        tol = self.inlier_px * cam.metres_per_px
        i = self._rng.integers(0, n, size=(self.hypotheses, 2))
        x1, x2, y1, y2 = xs[i[:, 0]], xs[i[:, 1]], ys[i[:, 0]], ys[i[:, 1]]
        dxh = x2 - x1
        valid = np.abs(dxh) > 0.5 * cam.metres_per_px
        slope = np.where(valid, (y2 - y1) / np.where(valid, dxh, 1.0), 0.0)
        pred = y1[:, None] + slope[:, None] * (xs[None, :] - x1[:, None])
        inl = np.abs(pred - ys[None, :]) < tol
        score = np.where(valid, inl.sum(axis=1), -1)
        best = inl[int(np.argmax(score))]
        if int(best.sum()) < self.min_rows:
            return None
        xi, yi = xs[best], ys[best]
        quad = (xi.max() - xi.min()) >= self.curvature_span * cam.height * cam.metres_per_px
        coef, rms = _fit(xi, yi, np.ones_like(xi), cam.x_centre, quad)
        if quad:  # a second pass with the curved model recovers rows on a bend
            dx = xs - cam.x_centre
            resid = np.abs(coef[0] + coef[1] * dx + 0.5 * coef[2] * dx * dx - ys)
            best = resid < tol
            xi, yi = xs[best], ys[best]
            if len(xi) >= self.min_rows:
                coef, rms = _fit(xi, yi, np.ones_like(xi), cam.x_centre, True)
        return _estimate(coef, rms, xi, cam.x_centre, len(xi), cam.height, cam.metres_per_px, quad)


class ScanLineDetector(_Common):
    """Edge pairs on a few scan lines + a straight least-squares line (see module docstring).

    Args:
        camera, track_width, min_contrast: as :class:`CentroidDetector`.
        lines: number of scan lines, evenly spread over the image's rows.
        min_rows: fewest scan lines with an edge pair for a fit (default 2).
    """

    name = "scanline"

    def __init__(self, camera: GroundCamera, *, lines: int = 5, min_rows: int = 2, **kw: float) -> None:
        super().__init__(camera=camera, min_rows=min_rows, **kw)  # type: ignore[arg-type]
        h = camera.height
        self.rows = np.clip(
            np.round((np.arange(lines) + 0.5) * h / lines).astype(int), 1, h - 2
        )

    def detect(self, image: np.ndarray) -> LineEstimate | None:
        """The track in ``image``, or None (fewer than ``min_rows`` scan lines with an edge pair)."""
        grey = to_grey(image)
        cam = self.camera
        r = self.rows
        band = (
            grey[r - 1].astype(np.float32) + 2.0 * grey[r].astype(np.float32) + grey[r + 1].astype(np.float32)
        ) / 4.0
        sm = band.copy()
        sm[:, 1:-1] = 0.25 * band[:, :-2] + 0.5 * band[:, 1:-1] + 0.25 * band[:, 2:]
        grad = np.zeros_like(sm)
        grad[:, 1:-1] = 0.5 * (sm[:, 2:] - sm[:, :-2])
        peak = float(np.abs(grad).max())
        # a sharp step of contrast C gives about C/2 here after the smoothing
        thr = max(0.4 * self.min_contrast, 0.35 * peak)
        ok, centre = _edge_pairs(grad, self._width_px(), thr)
        n = int(ok.sum())
        if n < self.min_rows:
            return None
        xs = cam.row_x()[r][ok]
        _, ys = cam.pixel_to_floor(centre[ok], 0.0)
        coef, rms = _fit(xs, ys, np.ones_like(xs), cam.x_centre, False)
        return _estimate(coef, rms, xs, cam.x_centre, n, len(r), cam.metres_per_px, False)


DETECTORS = {"centroid": CentroidDetector, "ransac": RansacDetector, "scanline": ScanLineDetector}
"""The track detectors by name."""


def make_detector(name: str, camera: GroundCamera, **kw: float) -> LineDetector:
    """A track detector by name (``centroid``, ``ransac`` or ``scanline``).

    Raises:
        ValueError: on an unknown name.
    """
    try:
        cls = DETECTORS[name]
    except KeyError:
        raise ValueError(f"unknown line detector {name!r} (known: {', '.join(DETECTORS)})") from None
    return cls(camera=camera, **kw)  # type: ignore[no-any-return]
