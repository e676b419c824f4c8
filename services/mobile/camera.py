"""The mobile robot's downward camera: pixel ↔ floor mapping in the robot frame.

A pinhole camera mounted ``mount_height`` above the floor looks straight down; its optical axis
meets the floor at (``x_centre``, ``y_centre``) in the robot frame (ahead of the wheels). The image
is oriented so that *up* in the image is the robot's forward direction (+x) and *left* in the image
is the robot's left (+y). With the floor flat and the axis vertical, the pinhole projection of the
floor is a similarity: every pixel covers ``metres_per_px`` of floor in both directions, and

    x = x_centre + ((H - 1)/2 - v) · s,      y = y_centre + ((W - 1)/2 - u) · s,

with (u, v) the pixel column and row (pixel centres at integers, v down) and s = metres_per_px.
This module is pure (no I/O); the simulated renderers and the detectors use the same model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GroundCamera"]


@dataclass(frozen=True, slots=True, kw_only=True)
class GroundCamera:
    """A downward-looking pinhole camera on the robot (see the module docstring).

    Attributes:
        width: image columns W (across the robot), pixels.
        height: image rows H (along the robot), pixels.
        metres_per_px: floor size of one pixel, m (the same along both axes).
        x_centre: forward distance of the view centre from the axle midpoint, m.
        y_centre: lateral position of the view centre, m (+ left).
        mount_height: height of the camera's centre of projection above the floor, m.

    Raises:
        ValueError: on a non-positive size, pixel size or mounting height.
    """

    width: int = 80
    height: int = 60
    metres_per_px: float = 0.004
    x_centre: float = 0.20
    y_centre: float = 0.0
    mount_height: float = 0.20

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError(f"camera image {self.width}x{self.height} is too small (8x8 at least)")
        if not self.metres_per_px > 0 or not self.mount_height > 0:
            raise ValueError("camera metres_per_px and mount_height must be positive")

    @property
    def focal_px(self) -> float:
        """Focal length of the pinhole, pixels: mount_height / metres_per_px."""
        return self.mount_height / self.metres_per_px

    @property
    def fov_y(self) -> float:
        """Field of view along the image's rows (the robot's x axis), degrees."""
        return math.degrees(2.0 * math.atan(self.height / 2.0 / self.focal_px))

    @property
    def footprint(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the floor seen, m (robot frame, pixel edges)."""
        hx = self.height * self.metres_per_px / 2.0
        hy = self.width * self.metres_per_px / 2.0
        return (self.x_centre - hx, self.x_centre + hx, self.y_centre - hy, self.y_centre + hy)

    def row_x(self) -> np.ndarray:
        """(H,) forward distance x of the centre of each image row, m."""
        v = np.arange(self.height, dtype=float)
        return self.x_centre + ((self.height - 1) / 2.0 - v) * self.metres_per_px

    def col_y(self) -> np.ndarray:
        """(W,) lateral position y of the centre of each image column, m."""
        u = np.arange(self.width, dtype=float)
        return self.y_centre + ((self.width - 1) / 2.0 - u) * self.metres_per_px

    def pixel_to_floor(self, u: np.ndarray | float, v: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Floor point (x, y) in the robot frame, m, of pixel coordinates (u, v) (any shape)."""
        s = self.metres_per_px
        x = self.x_centre + ((self.height - 1) / 2.0 - np.asarray(v, dtype=float)) * s
        y = self.y_centre + ((self.width - 1) / 2.0 - np.asarray(u, dtype=float)) * s
        return x, y

    def floor_to_pixel(self, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (u, v) of floor points (x, y) in the robot frame, m (any shape)."""
        s = self.metres_per_px
        u = (self.width - 1) / 2.0 - (np.asarray(y, dtype=float) - self.y_centre) / s
        v = (self.height - 1) / 2.0 - (np.asarray(x, dtype=float) - self.x_centre) / s
        return u, v

    def pixel_to_robot_affine(self) -> np.ndarray:
        """(2, 3) affine map [x, y]ᵀ = A · [u, v, 1]ᵀ from pixel to robot-frame floor point."""
        s = self.metres_per_px
        return np.array(
            [
                [0.0, -s, self.x_centre + (self.height - 1) / 2.0 * s],
                [-s, 0.0, self.y_centre + (self.width - 1) / 2.0 * s],
            ]
        )

    def px(self, metres: float) -> float:
        """A floor length in pixels."""
        return metres / self.metres_per_px
