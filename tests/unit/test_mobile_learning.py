"""Learning the follow_track detector per follow segment (bench/mobile_learning.py, issue 13)."""

from __future__ import annotations

import importlib.util
import os
import sys
from types import ModuleType, SimpleNamespace

import pytest

from sim.mobile.course import course_from_codes
from sim.mobile.harness import Phase

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    spec = importlib.util.spec_from_file_location("bench_mobile_learning", os.path.join(ROOT, "bench", "mobile_learning.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_every_follow_segment_of_a_clean_course_is_one_learner_trial(bench: ModuleType) -> None:
    res = bench.run_condition("clean", 2, 5)
    assert res.courses == [True, True]
    assert len(res.curve) == len(res.segments) >= 2
    assert [s.outcome for s in res.segments].count("end") == 2
    assert all(s.success and s.outcome in ("interruption", "end") for s in res.segments)
    assert all(s.frames > 0 and s.cpu_ms_per_frame > 0 for s in res.segments)
    auto = res.automaton
    assert sum(e.trials for e in auto.estimates.values()) == len(res.segments)
    assert list(auto.actions) == ["follow_ransac", "follow_centroid", "follow_scanline"]
    summary = bench.summarise(res)
    assert summary["segments"] == len(res.segments) and summary["completion_rate"] == 1.0


class _Detector:
    def detect(self, image: object) -> None:
        return None


def _judge(bench: ModuleType, pose: tuple[float, float, float], offset: float, then: Phase) -> object:
    """Drive the segment hook through FOLLOW (at ``offset`` from the track) then ``then``."""
    course = course_from_codes(["S", "S", "B", "S", "S", "E"], name="judge")
    out = bench.ConditionResult("clean", automaton=bench.make_automaton(1, "apriori"))
    hook = bench._Segments(course, 0, out.automaton, "apriori", 0.020, out, "follow_ransac")
    mission = SimpleNamespace(phase=Phase.FOLLOW, detector=_Detector(), camera=None)
    tile = course.tile_at(pose[0], pose[1])
    mw = SimpleNamespace(pose=lambda: pose, where=lambda x, y: (tile, 0.0, offset))
    hook(0.0, mission, mw, None)
    mission.phase = then
    hook(0.02, mission, mw, None)
    (seg,) = out.segments
    return seg


def test_an_interruption_declared_far_from_a_blank_square_is_a_failed_segment(bench: ModuleType) -> None:
    # the second straight's start (x = 2 m): the blank square begins at x = 4 m, 2 m ahead
    seg = _judge(bench, (2.1, 1.0, 0.0), 0.002, Phase.APPROACH)
    assert (seg.outcome, seg.success) == ("false_interruption", False)
    seg = _judge(bench, (3.7, 1.0, 0.0), 0.002, Phase.APPROACH)  # 0.3 m before the blank square
    assert (seg.outcome, seg.success) == ("interruption", True)


def test_a_segment_off_the_track_by_more_than_the_specification_fails(bench: ModuleType) -> None:
    seg = _judge(bench, (3.7, 1.0, 0.0), 0.025, Phase.APPROACH)
    assert (seg.outcome, seg.success) == ("off_spec", False)
