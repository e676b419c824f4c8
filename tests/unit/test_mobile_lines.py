"""Track detectors, end-mark detection and the gap monitor on rendered frames; layering."""

from __future__ import annotations

import ast
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from services.mobile.lines import DETECTORS, make_detector
from services.mobile.marks import EndMarkDetector, GapMonitor
from sim.mobile.course import course_from_codes
from sim.mobile.floor import FloorMap
from sim.mobile.sensors import AnalyticCamera, ImageNoise, robot_camera
from sim.mobile.world import DEFAULT_DT, MobileWorld
from sim.world import World

ROOT = Path(__file__).resolve().parents[2]
COURSE = course_from_codes(["S", "S", "L", "S", "B", "S", "R", "S", "E"])  # square (0, 0) black: a white track first
ARC = 4.0  # path length where the left arc starts
CAM = robot_camera()


def _pose(s: float, offset: float = 0.0, dheading: float = 0.0) -> tuple[float, float, float]:
    """Robot pose with the axle ``offset`` m left of the centre line at path length s, turned by
    ``dheading`` rad from the track's direction."""
    x, y, th = COURSE.pose_at(s)
    return x - offset * math.sin(th), y + offset * math.cos(th), th + dheading


def _expected(offset: float, dheading: float, x: float) -> float:
    """Lateral position of a straight track at forward distance x seen from such a pose."""
    return (-offset - math.tan(dheading) * x * math.cos(dheading)) / math.cos(dheading)


@pytest.fixture(scope="module")
def analytic() -> AnalyticCamera:
    return AnalyticCamera(CAM, FloorMap(COURSE), noise=ImageNoise(), seed=3)


@pytest.mark.parametrize("name", sorted(DETECTORS))
@pytest.mark.parametrize(
    "s", [0.6, 2.6, 1.9], ids=["white-track-on-black", "black-track-on-white", "across-a-square-edge"]
)
def test_every_detector_finds_a_straight_track_of_either_colour(name, s, analytic):
    det = make_detector(name, CAM)
    for offset, dh in [(0.02, 0.05), (-0.03, -0.1), (0.0, 0.0)]:
        line = det.detect(analytic.render(_pose(s, offset, dh)))
        assert line is not None and line.confidence > 0.5
        assert line.lateral_at(0.26) == pytest.approx(_expected(offset, dh, 0.26), abs=0.003)
        assert line.heading == pytest.approx(-dh, abs=0.03)


@pytest.mark.parametrize("name", ["centroid", "ransac"])
def test_curving_detectors_see_the_sign_of_a_one_metre_arc(name, analytic):
    det = make_detector(name, CAM)
    line = det.detect(analytic.render(_pose(ARC + 0.5, 0.0, 0.0)))  # on the left arc
    assert line is not None and line.curvature is not None
    assert 0.4 < line.curvature < 2.0
    # pure pursuit's goal lies on the arc: y = R - sqrt(R² - x²) ahead
    assert line.lateral_at(0.26) == pytest.approx(1.0 - math.sqrt(1.0 - 0.26**2), abs=0.004)


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_no_track_is_reported_on_a_blank_square(name, analytic):
    det = make_detector(name, CAM)
    s_blank = ARC + math.pi / 2 + 2.0 + 1.0  # the middle of tile 5 (B)
    for dh in (0.0, 0.4):
        assert det.detect(analytic.render(_pose(s_blank, 0.0, dh))) is None


def test_the_end_mark_is_found_at_its_distance_and_nowhere_else(analytic):
    det = EndMarkDetector(camera=CAM)
    for ahead in (0.15, 0.20, 0.25):
        mark = det.detect(analytic.render(_pose(COURSE.length - ahead)))
        assert mark is not None and mark.x == pytest.approx(ahead, abs=0.006)
    for s in np.arange(0.3, COURSE.length - 1.6, 0.05):
        assert det.detect(analytic.render(_pose(float(s), 0.01, 0.05))) is None


def test_detectors_read_tinyrenderer_frames_like_analytic_ones():
    with World(dt=DEFAULT_DT) as world:
        mw = MobileWorld(world, COURSE, textured=True)
        try:
            tiny = mw.tiny_camera(CAM, seed=1)
            for s, off, dh in [(0.6, 0.02, 0.05), (2.6, -0.01, -0.08), (1.9, 0.0, 0.1)]:
                frame = tiny.grab(_pose(s, off, dh), world.t)
                assert frame.image.shape == (CAM.height, CAM.width) and frame.image.dtype == np.uint8
                for name in DETECTORS:
                    line = make_detector(name, CAM).detect(frame.image)
                    assert line is not None
                    assert line.lateral_at(0.26) == pytest.approx(_expected(off, dh, 0.26), abs=0.004)
            mark = EndMarkDetector(camera=CAM).detect(tiny.render(_pose(COURSE.length - 0.2)))
            assert mark is not None and mark.x == pytest.approx(0.2, abs=0.008)
        finally:
            mw.close()


def test_the_gap_monitor_declares_an_interruption_after_the_gap_distance():
    gap = GapMonitor(0.06)
    assert not gap.update(True, 1.00)
    assert not gap.update(False, 1.03)
    assert gap.missing(1.05) == pytest.approx(0.05)
    assert gap.update(False, 1.061)
    assert not gap.update(True, 1.08)  # seen again: the count restarts
    assert not gap.update(False, 1.10)
    with pytest.raises(ValueError):
        GapMonitor(0.0)


def test_detectors_refuse_images_of_the_wrong_kind():
    det = make_detector("ransac", CAM)
    with pytest.raises(ValueError, match="uint8"):
        det.detect(np.zeros((60, 80), dtype=np.float32))
    with pytest.raises(ValueError, match="unknown line detector"):
        make_detector("hough", CAM)


def test_the_mobile_services_import_only_numpy_opencv_the_standard_library_and_the_exception_tree():
    allowed = {"numpy", "cv2", "__future__"}
    framework = {"services.errors", "services.sequence"}  # pure: the exception tree, the set points' numbering
    for path in sorted((ROOT / "services" / "mobile").glob("*.py")):
        if path.name.endswith("_node.py"):
            continue  # the nodes' shells around these algorithms (drivers, actions)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative: inside services.mobile
                    continue
                names = [node.module or ""]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                assert top in allowed or top in sys.stdlib_module_names or name in framework, \
                    f"{path.name} imports {name}"
