"""Ball vision for the catching testbed: locate the ball, map pixels to the table, predict the catch.

Paper section 6 ("Visual Servoing and Catching"): the vision subsystem tracks the rolling ball and
the prediction subsystem iteratively estimates its trajectory and the point where it will leave the
table at the manipulator's end. One module per concept, all pure (no I/O, no clocks):

* :mod:`~services.catching.vision.locate` — the three locators of the *locate* primitive task
  (threshold, background difference, k-frame average), :class:`Detection`, :class:`ThresholdParams`,
  :data:`Roi`;
* :mod:`~services.catching.vision.calibration` — the pixel → table homography and its fit, the table's
  region in the image, calibration points, the table → robot base transform;
* :mod:`~services.catching.vision.rolling` — the rolling-ball deceleration model and the catch-line predictor;
* :mod:`~services.catching.vision.tracker` — :class:`BallTracker`, the per-frame pipeline after the locator.

The node's actions that use them live in :mod:`services.catching.vision_node`.
"""

from services.catching.vision.calibration import (
    Homography,
    PlanarTransform,
    calibration_points,
    fit_homography,
    table_roi,
)
from services.catching.vision.locate import (
    Detection,
    Roi,
    ThresholdParams,
    locate_average,
    locate_bgdiff,
    locate_threshold,
)
from services.catching.vision.rolling import Prediction, RollingModel, RollingPredictor
from services.catching.vision.tracker import BallTracker

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
