"""The report and top view of a mobile-robot run (sim/mobile/report.py) on synthetic paths."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.mobile.course import Course, course_from_codes
from sim.mobile.report import render_report, score, write_top_view

CODES = ["S", "L", "S", "B", "S", "R", "S", "E"]
STRAIGHT_OFF, ARC_OFF, BLANK_OFF = 0.002, -0.005, 0.06


@pytest.fixture(scope="module")
def course() -> Course:
    return course_from_codes(CODES, name="synthetic")


def _tile_start_s(course: Course, index: int) -> float:
    return float(sum(course.tile_length(t) for t in course.tiles[:index]))


def _path(course: Course, *, speed: float = 0.5, dt: float = 0.02, until: float | None = None) -> np.ndarray:
    """The centre line driven at ``speed``, offset to the left by a constant per segment kind."""
    end = course.length if until is None else until
    rows = []
    for k in range(int(end / (speed * dt)) + 1):
        s = min(k * speed * dt, end)
        x, y, th = course.pose_at(s)
        tile = next(t for t in course.tiles if s <= _tile_start_s(course, t.index) + course.tile_length(t) + 1e-9)
        off = BLANK_OFF if tile.blank else (ARC_OFF if tile.shape in "LR" else STRAIGHT_OFF)
        rows.append((k * dt, x - off * math.sin(th), y + off * math.cos(th), th))
    return np.array(rows)


def _events(course: Course, path: np.ndarray, speed: float = 0.5) -> list[dict]:
    blank = _tile_start_s(course, 3)
    after = _tile_start_s(course, 4)
    return [
        {"t": (blank + 0.06) / speed, "kind": "interruption", "exit": "straight"},
        {"t": (after + 0.3) / speed, "kind": "recovered", "how": "beacon"},
        {"t": (course.length - 0.2) / speed, "kind": "end"},
        {"t": float(path[-1, 0]), "kind": "stop"},
    ]


def test_a_clean_run_is_completed_with_the_cross_track_error_of_each_segment_kind(course: Course) -> None:
    path = _path(course)
    events = _events(course, path)
    r = score(course, path, events, tuple(path[-1, 1:]))
    assert r["completed"] is True and r["reasons"] == []
    assert r["cross_track"]["straight"]["rms_m"] == pytest.approx(STRAIGHT_OFF, abs=2e-4)
    assert r["cross_track"]["arc"]["rms_m"] == pytest.approx(abs(ARC_OFF), abs=2e-4)
    assert r["cross_track"]["arc"]["max_m"] == pytest.approx(abs(ARC_OFF), abs=2e-4)
    # the blank square's 6 cm is left out: it lies between the interruption and the recovery
    assert r["cross_track"]["all"]["max_m"] < 0.01
    assert r["time_s"] == pytest.approx(course.length / 0.5, abs=0.03)
    assert r["mean_speed_mps"] == pytest.approx(0.5, rel=0.01)
    (it,) = r["interruptions"]
    assert it["tile"] == 4 and it["code"] == "B" and it["on_track_after"] is True
    assert it["declared"]["exit"] == "straight" and it["recovered"]["how"] == "beacon"
    stop = r["stop"]
    assert abs(stop["along_m"]) < 0.011 and stop["across_m"] == pytest.approx(STRAIGHT_OFF, abs=1e-4)


def test_the_text_report_gives_completion_time_errors_interruptions_and_the_stop(course: Course) -> None:
    path = _path(course)
    text = render_report(course, path, _events(course, path), tuple(path[-1, 1:]))
    assert text.splitlines()[1] == "completed: yes"
    assert "straight: RMS 2.0 mm, max 2.0 mm" in text and "arc:      RMS 5.0 mm, max 5.0 mm" in text
    assert "interruption on square 4 (B): declared at" in text and "(how beacon)" in text
    assert "0.5 m into the next square on the track" in text
    assert "to the left of the track" in text and "from the mark's centre" in text


def test_a_robot_that_stops_short_of_the_t_mark_has_not_completed(course: Course) -> None:
    path = _path(course, until=course.length - 0.6)
    events = _events(course, path)
    r = score(course, path, events, tuple(path[-1, 1:]))
    assert r["completed"] is False and r["mean_speed_mps"] is None
    assert r["reasons"] == ["stopped 0.60 m from the T mark"]
    assert r["stop"]["along_m"] == pytest.approx(-0.6, abs=0.011)
    assert "short of the T bar" in render_report(course, path, events, tuple(path[-1, 1:]))


def test_a_run_without_a_stop_or_a_recovery_says_why_it_did_not_complete(course: Course) -> None:
    path = _path(course)
    events = [e for e in _events(course, path) if e["kind"] not in ("stop", "recovered")]
    r = score(course, path, events, None)
    assert r["completed"] is False
    assert "the robot did not stop" in r["reasons"]
    assert r["interruptions"][0]["recovered"] is None
    text = render_report(course, path, events, None)
    assert "; not recovered" in text and "stop: the robot did not stop" in text
    # without the recovery event, the blank square's crossing is still left out of the errors
    assert r["cross_track"]["all"]["max_m"] < 0.01


def test_an_interruption_declared_on_a_painted_square_is_reported_as_false(course: Course) -> None:
    path = _path(course)
    events = [{"t": 1.0, "kind": "interruption"}, {"t": 1.5, "kind": "recovered"}] + _events(course, path)
    r = score(course, path, events, tuple(path[-1, 1:]))
    assert [i["tile"] for i in r["interruptions"]] == [4, None]
    assert r["completed"] is True  # the real interruption was recovered
    assert "false interruption (no blank square there)" in render_report(course, path, events, tuple(path[-1, 1:]))


def test_a_lost_track_is_listed(course: Course) -> None:
    path = _path(course, until=6.0)
    events = [{"t": 11.0, "kind": "lost", "detector": "scanline"}, {"t": 12.0, "kind": "stop"}]
    text = render_report(course, path, events, tuple(path[-1, 1:]))
    assert "track lost at 11.00 s (detector scanline)" in text and "completed: no" in text


def test_bad_paths_and_events_are_refused_with_a_clear_error(course: Course) -> None:
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        score(course, np.zeros((5, 3)), [], None)
    with pytest.raises(ValueError, match="non-finite"):
        score(course, np.full((2, 4), np.nan), [], None)
    with pytest.raises(ValueError, match="must not decrease"):
        score(course, np.array([[1.0, 0, 0, 0], [0.0, 0, 0, 0]]), [], None)
    with pytest.raises(ValueError, match="needs 't' and 'kind'"):
        score(course, np.zeros((1, 4)), [{"kind": "stop"}], None)


def test_the_top_view_is_written_as_a_png(course: Course, tmp_path) -> None:
    path = _path(course)
    out = tmp_path / "top.png"
    write_top_view(course, path, str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _ended(task: str, result, t_wall: float, action: str | None = None):
    from types import SimpleNamespace

    return SimpleNamespace(task=task, action=action or task, node="perception", result=result, t_wall=t_wall)


def test_the_runs_primitive_action_ends_are_read_as_events(course: Course) -> None:
    from services.results import ActionResult

    path = _path(course)
    ev = {e["kind"]: e["t"] for e in _events(course, path)}
    t0_wall = 1.7e9
    ends = [
        _ended("follow_track", ActionResult.success({"frames": 400}, outcome="interruption"), t0_wall + ev["interruption"],
               "follow_ransac"),
        _ended("find_beacon", ActionResult.success(outcome="found"), t0_wall + ev["interruption"] + 0.5),
        _ended("goto_beacon", ActionResult.success(), t0_wall + ev["recovered"] - 0.5),
        _ended("reacquire_track", ActionResult.success(), t0_wall + ev["recovered"]),
        _ended("follow_track", ActionResult.success(outcome="end"), t0_wall + ev["end"], "follow_scanline"),
        _ended("stop_at_t", ActionResult.success({"t": ev["stop"]}), 0.0),  # the value's simulated time wins
    ]
    r = score(course, path, ends, tuple(path[-1, 1:]), t0_wall=t0_wall)
    assert r["events_on_path_clock"] is True and r["completed"] is True
    (it,) = r["interruptions"]
    assert it["tile"] == 4 and it["declared"]["action"] == "follow_ransac" and it["recovered"] is not None
    assert r["end_seen_t"] == pytest.approx(ev["end"])


def test_events_on_another_clock_are_matched_in_order_and_said_so(course: Course) -> None:
    from services.results import ActionResult

    path = _path(course)
    ends = [
        _ended("follow_track", ActionResult.success(outcome="interruption"), 1.7e9 + 10.0),
        _ended("reacquire_track", ActionResult.success(), 1.7e9 + 14.0),
        _ended("goto_beacon", ActionResult.error("drive node silent"), 1.7e9 + 15.0),
        _ended("stop_robot", ActionResult.success(), 1.7e9 + 16.0),
    ]
    r = score(course, path, ends, tuple(path[-1, 1:]))
    assert r["events_on_path_clock"] is False
    assert r["interruptions"][0]["tile"] == 4 and r["interruptions"][0]["recovered"] is not None
    assert [e["reason"] for e in r["errors"]] == ["drive node silent"]
    text = render_report(course, path, ends, tuple(path[-1, 1:]))
    assert "not on the path's clock" in text and "error in goto_beacon (goto_beacon)" in text


def test_a_list_of_tuples_is_a_path_and_an_unknown_event_object_is_refused(course: Course) -> None:
    path = [tuple(row) for row in _path(course)]
    assert score(course, path, [], None)["time_s"] > 0
    with pytest.raises(ValueError, match="neither a dict"):
        score(course, path, [object()], None)


def test_the_top_view_numbers_the_squares_as_the_report_shows_the_gaps_and_keeps_the_t_visible(course: Course):
    from matplotlib import pyplot as plt

    from sim.mobile.report import top_view

    path = _path(course)
    fig = top_view(course, path)
    try:
        ax = fig.axes[0]
        labels = {text.get_text() for text in ax.texts}
        # the report's names: "interruption on square 4 (B)"; the other squares by their number
        report = render_report(course, path, _events(course, path), tuple(path[-1, 1:]))
        assert "interruption on square 4 (B)" in report
        assert labels == {"1", "2", "3", "4 (B)", "5", "6", "7", "8"}
        hatched = [p for p in ax.patches if p.get_hatch() == "//" and p.get_width() > 0]
        assert [(p.get_x(), p.get_y()) for p in hatched] == [
            (i * course.square, j * course.square) for i, j in (t.square for t in course.tiles if t.blank)]
        # the robot stops on the T: the stop marker is hollow and the bar is drawn over it
        fig.canvas.draw()
        image = np.asarray(fig.canvas.buffer_rgba())[:, :, :3].astype(int)
        ex, ey = course.end_point()
        x, y = ax.transData.transform((ex, ey))
        row, col = image.shape[0] - int(round(y)), int(round(x))
        bar = np.array([255, 255, 255] if course.is_black(*course.tiles[-1].square) else [0, 0, 0])
        assert np.abs(image[row - 1:row + 2, col - 1:col + 2] - bar).sum(axis=2).min() < 60, "the T is hidden"
    finally:
        plt.close(fig)
