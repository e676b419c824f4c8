"""Map camera pixels to the table: the calibrated plane homography, and the table → robot base frame.

Pixel → table mapping is a plane homography (Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.,
§4.1, normalised DLT) fitted by :func:`fit_homography` to pixel/table point pairs that a calibration
routine gathers (the simulated camera places the ball at :func:`calibration_points`).
:func:`table_roi` bounds the table top in the image, so that the locators search it only.
:class:`PlanarTransform` takes table-frame points to the manipulator's base frame, where the
paper's set points live (section 6).

Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from services.catching.vision.locate import Roi

__all__ = ["Homography", "PlanarTransform", "calibration_points", "fit_homography", "table_roi"]


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
