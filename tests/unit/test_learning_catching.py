"""Learning the locate primitive task in the catching testbed (bench/learning_catching.py, issue 6)."""

from __future__ import annotations

import importlib.util
import math
import os
import sys
from types import ModuleType

import pytest

from services.catching.vision_node import track_residual

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _bench() -> ModuleType:
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    spec = importlib.util.spec_from_file_location(
        "bench_learning_catching", os.path.join(ROOT, "bench", "learning_catching.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return _bench()


@pytest.fixture(scope="module")
def levels(bench: ModuleType) -> dict[str, dict]:
    out = {}
    for level in ("clean", "noisy"):
        res = bench.run_level(level, 20, 3, rate=0.2, warmup=2, catch=False)
        assert len(res.curve) == len(res.attempts)
        out[level] = bench.summarise_level(res)
    return out


def test_track_residual_is_zero_for_a_point_on_a_straight_track() -> None:
    track = [(0.1 * i, -1.0 + 0.5 * 0.1 * i, 0.02 - 0.1 * 0.1 * i) for i in range(1, 8)]
    assert track_residual((0.0, -1.0, 0.02), track) == pytest.approx(0.0, abs=1e-12)


def test_track_residual_measures_the_distance_to_the_fitted_track() -> None:
    track = [(0.02 * i, 0.5 * 0.02 * i, 0.0) for i in range(1, 11)]
    assert track_residual((0.0, 0.003, 0.004), track) == pytest.approx(0.005, abs=1e-9)


def test_track_residual_rejects_a_track_of_two_points() -> None:
    with pytest.raises(ValueError):
        track_residual((0.0, 0.0, 0.0), [(0.1, 0.0, 0.0), (0.2, 0.0, 0.0)])


def test_the_locate_automaton_takes_its_configuration_from_the_catch_net(bench: ModuleType) -> None:
    auto = bench.make_automaton(1, "apriori", None, None)
    assert auto.scheme == "pursuit"
    assert auto.actions == ("locate_threshold", "locate_bgdiff", "locate_average")
    assert auto.rho == pytest.approx(1.0 / 3.0)


def test_every_locator_meets_the_spec_on_a_clean_camera(levels: dict[str, dict]) -> None:
    est = levels["clean"]["estimates"]
    for name, e in est.items():
        if e["trials"]:
            assert e["R_hat"] >= 0.9, name
    assert levels["clean"]["located_rate"] == 1.0


def test_the_clean_camera_learns_a_cheap_single_frame_locator(levels: dict[str, dict]) -> None:
    clean = levels["clean"]
    assert clean["best_estimated_action"] in ("locate_threshold", "locate_bgdiff")
    assert math.isclose(sum(clean["probabilities"].values()), 1.0, abs_tol=1e-9)
    assert max(clean["probabilities"].values()) >= 0.9


def test_camera_noise_makes_the_learner_pick_a_different_locator(levels: dict[str, dict]) -> None:
    clean, noisy = levels["clean"], levels["noisy"]
    assert noisy["best_estimated_action"] != clean["best_estimated_action"]
    assert noisy["best_estimated_action"] != "locate_bgdiff"
    est = noisy["estimates"]
    # grey-level noise breaks the background difference; position jitter pushes single frames out
    assert est["locate_bgdiff"]["R_hat"] is not None and est["locate_bgdiff"]["R_hat"] <= 0.1
    assert est["locate_threshold"]["R_hat"] < clean["estimates"]["locate_threshold"]["R_hat"] or (
        clean["estimates"]["locate_threshold"]["R_hat"] is None)
    assert noisy["locate_attempts_per_run_first_50"] > clean["locate_attempts_per_run_first_50"]


def test_two_throws_with_the_robot_locate_predict_and_catch(bench: ModuleType) -> None:
    res = bench.run_level("clean", 2, 5, rate=0.2, warmup=1, catch=True)
    summary = bench.summarise_level(res)
    assert summary["located_rate"] == 1.0
    assert summary["catch_rate"] is not None and summary["catch_rate"] >= 0.5
