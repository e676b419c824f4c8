"""The vision node's per-frame pipeline after the locator: detections in, catch predictions out.

Pure: no I/O, no clocks (frame times are passed in).
"""

from __future__ import annotations

from services.catching.vision.calibration import Homography
from services.catching.vision.locate import Detection, Roi
from services.catching.vision.rolling import Prediction, RollingPredictor

__all__ = ["BallTracker"]


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
        roi: region of the image to search (see :func:`services.catching.vision.calibration.table_roi`), for
            the locate functions.
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
