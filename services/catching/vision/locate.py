"""Locate the ball in camera frames: three locators of different cost and reliability (paper §2, §6).

Section 2 uses *locate* as the example of a primitive task with several primitive actions of
different cost and reliability; three are offered here:

* :func:`locate_threshold` — HSV colour threshold + centroid of the largest contour (one frame);
* :func:`locate_bgdiff` — difference to a background image + intensity-weighted centroid (one frame,
  cheaper, needs a background);
* :func:`locate_average` — the threshold locator over k frames, averaging positions and timestamps
  (costs k frames, noise falls as 1/√k; the paper's own example of cost rising with reliability).

Pure: no I/O, no clocks; OpenCV is used on arrays only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Detection", "Roi", "ThresholdParams", "locate_average", "locate_bgdiff", "locate_threshold"]


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
        roi: search only this region (e.g. :func:`services.catching.vision.calibration.table_roi`, which
            keeps the robot's orange cup beyond the table edge out of the search).

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
