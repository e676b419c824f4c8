"""Marks on the track: the T-shaped end mark and interruptions (gaps).

Paper section 6 ("Mobile Robot Task"): "The end of the track is signaled by a T-shaped pattern";
"there are track interruptions somewhere along the path ... The robot must detect the
interruption". Both are judged from what the downward camera sees:

* the **T mark**'s cross bar, as wide as the whole view and one track width thick, is a band of
  image rows that are almost entirely thin structure (see :func:`services.mobile.lines.
  thin_structures`): a run of such rows whose thickness is that of the bar, fully inside the view,
  gives the bar's forward distance (:class:`EndMarkDetector`). A bar also changes the rows' median
  grey level — toward the track's colour, against the rows just before *and* just after it —
  which scuffs or dirt lined up with the track on one row do not; that is checked too;
* an **interruption** is no track in view over a travelled distance longer than the gaps that noise
  or a track end passing the view's rear edge can cause (:class:`GapMonitor`, fed with odometry's
  path length).

Pure module (no I/O).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import GroundCamera
from .lines import thin_structures, to_grey

__all__ = ["EndMark", "EndMarkDetector", "GapMonitor"]


@dataclass(frozen=True, slots=True)
class EndMark:
    """The T mark's cross bar seen in one frame.

    Attributes:
        x: forward distance of the bar's centre line from the axle midpoint, m (robot frame).
        thickness: measured bar thickness along the robot's x axis, m.
        coverage: mean fraction of the bar rows' pixels that are thin structure, 0…1.
    """

    x: float
    thickness: float
    coverage: float


@dataclass(slots=True, kw_only=True)
class EndMarkDetector:
    """Finds the T mark's cross bar (see the module docstring).

    Attributes:
        camera: the camera model.
        bar_width: thickness of the painted bar, m (the track width).
        min_contrast: grey levels; thin pixels below ``max(min_contrast, ½ · strongest)`` ignored.
        min_coverage: fraction of a row that must be thin structure for the row to be bar.
    """

    camera: GroundCamera
    bar_width: float = 0.05
    min_contrast: float = 60.0
    min_coverage: float = 0.7

    def detect(self, image: np.ndarray) -> EndMark | None:
        """The cross bar in ``image`` ((H, W) grey or (H, W, 3) BGR uint8), or None."""
        grey = to_grey(image)
        cam = self.camera
        bar_px = cam.px(self.bar_width)
        thin = thin_structures(grey, round(2.0 * bar_px))
        peak = float(thin.max())
        if peak < self.min_contrast:
            return None
        thr = max(self.min_contrast, 0.5 * peak)
        cover = (thin >= thr).mean(axis=1)
        rows = cover >= self.min_coverage
        if not rows.any():
            return None
        # runs of bar rows
        edges = np.diff(np.concatenate(([0], rows.astype(np.int8), [0])))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)  # exclusive
        best: EndMark | None = None
        for a, b in zip(starts, ends):
            n = b - a
            if a == 0 or b == len(rows):
                continue  # cut by the image border: not the whole bar
            if not (0.5 * bar_px <= n <= 2.0 * bar_px):
                continue
            if not self._bar_contrast(grey, int(a), int(b), int(n)):
                continue
            v = 0.5 * (a + b - 1)
            x, _ = cam.pixel_to_floor(0.0, v)
            mark = EndMark(float(x), n * cam.metres_per_px, float(cover[a:b].mean()))
            if best is None or mark.x < best.x:
                best = mark
        return best

    def _bar_contrast(self, grey: np.ndarray, a: int, b: int, n: int) -> bool:
        """The band of rows [a, b) differs in median grey from the n rows before and after it, by
        at least ``min_contrast`` and in the same direction."""
        before, after = grey[max(0, a - n) : a], grey[b : b + n]
        if len(before) < max(2, n // 2) or len(after) < max(2, n // 2):
            return False
        m_bar = float(np.median(grey[a:b]))
        d1 = m_bar - float(np.median(before))
        d2 = m_bar - float(np.median(after))
        return d1 * d2 > 0 and min(abs(d1), abs(d2)) >= self.min_contrast


class GapMonitor:
    """Declares an interruption after no track was seen over ``gap`` metres of travel.

    Args:
        gap: distance travelled without a track before an interruption is declared, m.

    Attributes:
        last_seen_s: odometry path length at the last frame with a track, m (None before any).
    """

    def __init__(self, gap: float = 0.06) -> None:
        if not gap > 0:
            raise ValueError(f"gap must be positive, got {gap}")
        self.gap = gap
        self.last_seen_s: float | None = None

    def reset(self, s: float) -> None:
        """Count the gap from path length ``s`` (m), e.g. when following starts."""
        self.last_seen_s = s

    def update(self, seen: bool, s: float) -> bool:
        """Feed one frame's verdict; returns True once the track has been missing for ``gap``.

        Args:
            seen: whether the frame showed the track.
            s: odometry path length at the frame, m.
        """
        if seen or self.last_seen_s is None:
            self.last_seen_s = s
            return False
        return s - self.last_seen_s >= self.gap

    def missing(self, s: float) -> float:
        """Distance (m) travelled since the track was last seen (0 if never started)."""
        return 0.0 if self.last_seen_s is None else max(0.0, s - self.last_seen_s)
