"""The overhead CCD camera of the catching testbed: two renderers and a TCP frame server.

Paper section 6: a CCD camera above the table feeds the image-processing PC through a frame-grabber
card. Here the camera is a pinhole model shared by two back ends:

* :class:`TinyRenderer` — pybullet's software renderer (``ER_TINY_RENDERER``, no shadows), 320×240 or
  more, for the real demo;
* :class:`AnalyticRenderer` — the ball's centre projected with the same camera model and drawn with
  OpenCV (anti-aliased, sub-pixel) over a pre-rendered background: ~0.1 ms a frame, for Monte-Carlo
  benches.

Both add pixel noise: Gaussian grey-level noise (``intensity_sigma``, drawn from a pre-computed bank
so that a frame costs no random-number generation) and, for the analytic renderer, a Gaussian jitter
of the drawn ball's position (``position_sigma_px``), the "0.5 px noise" of the benchmarks.

The frames are served by :class:`sim.frameserver.FrameServer`; :func:`camera_info` is the info map
the vision node reads from it (data sheet and calibration).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from services.catching.vision import Homography, Roi, fit_homography, locate_threshold

__all__ = [
    "AnalyticRenderer",
    "CameraModel",
        "TinyRenderer",
    "calibrate",
    "camera_info",
    "overhead_camera",
]

BALL_BGR = (0, 140, 255)
"""Colour of the (orange) ball in the analytic renderer, BGR."""
TABLE_BGR = (46, 77, 26)
"""Colour of the table top (dark green), BGR."""
FLOOR_BGR = (60, 60, 60)
"""Colour of the floor around the table, BGR."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraModel:
    """A pinhole camera (OpenGL-style, as pybullet renders).

    Attributes:
        width, height: image size, pixels.
        fov_y: vertical field of view, degrees.
        eye: (3,) camera centre, m (table frame).
        target: (3,) point the optical axis goes through, m.
        up: (3,) up direction of the image.
        near, far: clipping distances, m.
    """

    width: int = 640
    height: int = 480
    fov_y: float = 48.0
    eye: tuple[float, float, float] = (-0.75, 0.0, 2.18)
    target: tuple[float, float, float] = (-0.75, 0.0, 0.76)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    near: float = 0.1
    far: float = 5.0

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (vertical)."""
        return self.height / 2.0 / math.tan(math.radians(self.fov_y) / 2.0)

    def view_matrix(self) -> np.ndarray:
        """(4, 4) world → camera matrix (OpenGL convention: camera looks along -z)."""
        eye, tgt, up = (np.asarray(a, dtype=float) for a in (self.eye, self.target, self.up))
        f = tgt - eye
        f /= np.linalg.norm(f)
        s = np.cross(f, up)
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection_matrix(self) -> np.ndarray:
        """(4, 4) OpenGL perspective projection matrix."""
        aspect = self.width / self.height
        ft = 1.0 / math.tan(math.radians(self.fov_y) / 2.0)
        n, fa = self.near, self.far
        return np.array(
            [
                [ft / aspect, 0, 0, 0],
                [0, ft, 0, 0],
                [0, 0, (fa + n) / (n - fa), 2 * fa * n / (n - fa)],
                [0, 0, -1, 0],
            ]
        )

    def project(self, points: np.ndarray | Sequence[float]) -> np.ndarray:
        """Project table-frame points to pixels.

        Args:
            points: (3,) or (N, 3) points, m.

        Returns:
            (2,) or (N, 2) pixel coordinates (u right, v down, pixel centres at integers).
        """
        a = np.asarray(points, dtype=float)
        p = np.atleast_2d(a)
        cam = (self.view_matrix() @ np.hstack([p, np.ones((len(p), 1))]).T).T
        clip = (self.projection_matrix() @ cam.T).T
        ndc = clip[:, :3] / clip[:, 3:4]
        u = (ndc[:, 0] + 1.0) * 0.5 * self.width - 0.5
        v = (1.0 - ndc[:, 1]) * 0.5 * self.height - 0.5
        out = np.column_stack([u, v])
        return out[0] if a.ndim == 1 else out

    def table_roi(
        self, length: float, width: float, z: float, *, catch_x: float = 0.0, margin_px: int = 3
    ) -> Roi:
        """Pixel box (u0, v0, u1, v1) of the table top's region at height z (m), from the model.

        Stops at the catch line's column (columns grow along +x) so the cup beyond is not searched.
        """
        corners = np.array(
            [[-length, -width / 2, z], [catch_x, -width / 2, z], [catch_x, width / 2, z],
             [-length, width / 2, z]]
        )
        px = self.project(corners)
        u0, v0 = np.floor(px.min(axis=0)).astype(int) - margin_px
        v1 = int(np.ceil(px[:, 1].max())) + margin_px
        u1 = int(np.floor(px[1:3, 0].min()))
        return (max(0, int(u0)), max(0, int(v0)), min(u1, self.width), min(v1, self.height))

    def depth(self, point: Sequence[float] | np.ndarray) -> float:
        """Distance (m) of a point along the optical axis."""
        cam = self.view_matrix() @ np.append(np.asarray(point, dtype=float), 1.0)
        return float(-cam[2])


def overhead_camera(
    table_length: float = 1.5, table_height: float = 0.76, *, width: int = 640, height: int = 480,
    distance: float = 1.42, fov_y: float = 48.0,
) -> CameraModel:
    """The camera above the middle of the table, image columns along the table's x axis."""
    cx = -table_length / 2.0
    return CameraModel(
        width=width, height=height, fov_y=fov_y, eye=(cx, 0.0, table_height + distance),
        target=(cx, 0.0, table_height), up=(0.0, 1.0, 0.0),
    )


class _NoiseBank:
    """Pre-drawn Gaussian grey-level noise, applied with saturating adds at a random row offset.

    The noise is stored as its positive and negative parts (uint8) so that a frame costs two
    saturating OpenCV operations and no random-number generation.
    """

    def __init__(self, shape: tuple[int, int, int], sigma: float, rng: np.random.Generator) -> None:
        self.sigma = sigma
        self.rng = rng
        self.rows = shape[0]
        self.bank: list[tuple[np.ndarray, np.ndarray]] = []
        if sigma > 0:
            for _ in range(4):
                n = np.clip(np.rint(rng.normal(0.0, sigma, (shape[0] * 2, *shape[1:]))), -255, 255)
                self.bank.append(
                    (np.maximum(n, 0).astype(np.uint8), np.maximum(-n, 0).astype(np.uint8))
                )

    def apply(self, image: np.ndarray) -> np.ndarray:
        if not self.bank:
            return image
        pos, neg = self.bank[int(self.rng.integers(len(self.bank)))]
        off = int(self.rng.integers(self.rows))
        out = cv2.add(image, pos[off : off + self.rows])
        return cv2.subtract(out, neg[off : off + self.rows])


class AnalyticRenderer:
    """Fast renderer: the projected ball drawn with OpenCV over a pre-rendered background.

    Args:
        camera: the camera model.
        table_length, table_width, table_height: the table (see :class:`sim.catching.TableSpec`), m.
        ball_radius: m.
        intensity_sigma: 1-σ Gaussian grey-level noise added to every pixel (0 = none).
        position_sigma_px: 1-σ Gaussian jitter of the drawn ball centre, pixels (0 = none).
        seed: seed of the noise generator.
    """

    def __init__(
        self,
        camera: CameraModel,
        *,
        table_length: float = 1.5,
        table_width: float = 0.76,
        table_height: float = 0.76,
        ball_radius: float = 0.02,
        intensity_sigma: float = 2.0,
        position_sigma_px: float = 0.0,
        seed: int = 0,
    ) -> None:
        self.camera = camera
        self.ball_radius = ball_radius
        self.position_sigma_px = position_sigma_px
        self.rng = np.random.default_rng(seed)
        bg = np.empty((camera.height, camera.width, 3), np.uint8)
        bg[:] = FLOOR_BGR
        corners = np.array(
            [
                [-table_length, -table_width / 2, table_height],
                [0.0, -table_width / 2, table_height],
                [0.0, table_width / 2, table_height],
                [-table_length, table_width / 2, table_height],
            ]
        )
        px = np.round(camera.project(corners) * 16).astype(np.int32)
        cv2.fillPoly(bg, [px], TABLE_BGR, lineType=cv2.LINE_AA, shift=4)
        self.background = bg
        self._noise = _NoiseBank(bg.shape, intensity_sigma, self.rng)  # type: ignore[arg-type]

    def reseed(self, seed: int | Sequence[int]) -> None:
        """Restart the noise (grey levels and position jitter) from ``seed``: the sim reseeds at
        each throw, so that a throw's frames get the same noise whenever it happens."""
        self.rng = np.random.default_rng(seed)
        self._noise.rng = self.rng

    def noiseless_background(self) -> np.ndarray:
        """(H, W, 3) uint8 BGR background without ball and without noise."""
        return self.background.copy()

    def render(self, ball_position: Sequence[float] | np.ndarray | None) -> np.ndarray:
        """Render one frame.

        Args:
            ball_position: (3,) centre of the ball in the table frame, m, or None for no ball.

        Returns:
            (H, W, 3) uint8 BGR image.
        """
        img = self.background.copy()
        if ball_position is not None:
            c = self.camera.project(ball_position)
            if self.position_sigma_px > 0:
                c = c + self.rng.normal(0.0, self.position_sigma_px, 2)
            depth = self.camera.depth(ball_position)
            if depth > 0:
                r = self.camera.focal_px * self.ball_radius / depth
                # pixel centres are at integer coordinates; OpenCV's shift draws at (x / 16)
                cv2.circle(
                    img, (round(float(c[0]) * 16), round(float(c[1]) * 16)), round(r * 16),
                    BALL_BGR, -1, cv2.LINE_AA, 4,
                )
        return self._noise.apply(img)


class TinyRenderer:
    """pybullet TinyRenderer back end (no shadows), with grey-level noise.

    Args:
        camera: the camera model.
        client: a pybullet client (e.g. :attr:`sim.world.World.client`).
        intensity_sigma: 1-σ Gaussian grey-level noise per pixel.
        seed: seed of the noise generator.
    """

    def __init__(
        self, camera: CameraModel, client: Any, *, intensity_sigma: float = 2.0, seed: int = 0
    ) -> None:
        self.camera = camera
        self.client = client
        self._view = camera.view_matrix().T.flatten().tolist()  # column-major for pybullet
        self._proj = camera.projection_matrix().T.flatten().tolist()
        self._noise = _NoiseBank(
            (camera.height, camera.width, 3), intensity_sigma, np.random.default_rng(seed)
        )

    def reseed(self, seed: int | Sequence[int]) -> None:
        """Restart the grey-level noise from ``seed`` (see :meth:`AnalyticRenderer.reseed`)."""
        self._noise.rng = np.random.default_rng(seed)

    def render(self) -> np.ndarray:
        """Render the present state of the world: (H, W, 3) uint8 BGR."""
        pb = self.client
        _, _, rgba, _, _ = pb.getCameraImage(
            self.camera.width, self.camera.height, self._view, self._proj,
            shadow=0, renderer=pb.ER_TINY_RENDERER, flags=pb.ER_NO_SEGMENTATION_MASK,
        )
        img = np.asarray(rgba, dtype=np.uint8).reshape(self.camera.height, self.camera.width, 4)
        return self._noise.apply(cv2.cvtColor(img, cv2.COLOR_RGBA2BGR))


def calibrate(
    render_at: Callable[[float, float], np.ndarray],
    points: np.ndarray,
    frames_per_point: int = 1,
    roi: Roi | None = None,
) -> Homography:
    """Calibration routine: image the ball at known table points and fit the pixel → table map.

    Args:
        render_at: function placing the ball's centre at table point (x, y) (on the table) and
            returning the frame, (H, W, 3) uint8 BGR.
        points: (N, 2) known table points, m (e.g. :func:`services.catching.vision.calibration_points`).
        frames_per_point: frames taken at each point; their detections are averaged (reduces the
            effect of pixel noise on the calibration).
        roi: search only this region of the frames (e.g. :meth:`CameraModel.table_roi`).

    Returns:
        The fitted homography (its ``rms_m`` tells the calibration quality).

    Raises:
        RuntimeError: if the ball is not found at some calibration point.
        ValueError: from :func:`services.catching.vision.fit_homography` on degenerate points.
    """
    pixels = []
    for x, y in np.asarray(points, dtype=float):
        dets = [
            locate_threshold(render_at(float(x), float(y)), 0.0, roi=roi)
            for _ in range(frames_per_point)
        ]
        if any(d is None for d in dets):
            raise RuntimeError(f"calibration: ball not found at table point ({x:.3f}, {y:.3f})")
        pixels.append(
            (float(np.mean([d.u for d in dets if d])), float(np.mean([d.v for d in dets if d])))
        )
    return fit_homography(np.asarray(pixels), np.asarray(points, dtype=float))


def camera_info(
    camera: CameraModel,
    homography: Homography,
    *,
    robot_base: Sequence[float],
    rolling_model: Sequence[float],
    catch_x: float = 0.0,
    fps: float = 25.0,
    table_size: tuple[float, float] = (1.5, 0.76),
) -> dict[str, Any]:
    """The info map a :class:`FrameServer` serves: data sheet and calibration of the camera.

    Args:
        camera: the camera model.
        homography: the calibrated pixel → table map (ball-centre plane).
        robot_base: (x, y, z, yaw) of the robot base frame in the table frame, m and rad.
        rolling_model: (α, β) of the rolling-ball deceleration model (m/s², 1/m).
        catch_x: x of the catch line in the table frame, m.
        fps: nominal frame rate, frames per second.
        table_size: (length, width) of the table top, m.
    """
    return {
        "table_size": [float(v) for v in table_size],
        "width": camera.width,
        "height": camera.height,
        "fov_y": camera.fov_y,
        "fps": float(fps),
        "homography": [[float(v) for v in row] for row in homography.matrix],
        "calibration_rms_m": float(homography.rms_m),
        "robot_base": [float(v) for v in robot_base],
        "rolling_model": [float(v) for v in rolling_model],
        "catch_x": float(catch_x),
    }
