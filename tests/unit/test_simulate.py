"""The GSPN simulator agrees with the CTMC when delays are exponential, and handles other laws."""

from __future__ import annotations

import pytest

from coordinator.analysis.gspn import analyse
from coordinator.analysis.simulate import Delay, simulate_absorption, simulate_steady
from coordinator.errors import AnalysisError
from tests.unit.gspn_nets import fork_join, queue, vanishing_loop


def test_simulated_mmck_queue_agrees_with_the_ctmc_within_its_intervals() -> None:
    net = queue(3.0, 1.5, 6, servers=2)
    exact = analyse(net)
    est = simulate_steady(net, seed=7, batch_time=200.0, batches=20, warmup=50.0, confidence=0.99)
    for place in ("queue", "free"):
        assert est.mean_tokens[place].contains(exact.mean_tokens[place])
        assert est.probability_nonempty[place].contains(exact.probability_nonempty[place])
    assert est.throughput["serve"].contains(exact.throughput["serve"])
    assert est.mean_tokens["queue"].half_width < 0.25


def test_simulated_vanishing_loop_agrees_with_the_ctmc() -> None:
    net = vanishing_loop(2.0, 1.0)
    exact = analyse(net)
    est = simulate_steady(net, seed=3, batch_time=200.0, batches=20, warmup=20.0, confidence=0.99)
    for tid in ("go", "a2b", "b2a", "b2t"):
        assert est.throughput[tid].contains(exact.throughput[tid])


def test_simulated_fork_join_agrees_with_the_absorbing_analysis() -> None:
    net = fork_join(2.0, 0.5, 0.8)
    exact = analyse(net)
    est = simulate_absorption(net, seed=11, replications=3000, confidence=0.99)
    assert est.mean_time_to_absorption.contains(exact.mean_time_to_absorption or 0.0)
    assert est.absorption[(("ok", 1),)].contains(0.8)


def test_deterministic_delays_make_the_fork_join_take_the_longest_branch() -> None:
    net = fork_join(2.0, 0.5, 1.0 - 1e-9)
    est = simulate_absorption(net, {"ta": Delay.deterministic(1.0), "tb": Delay.deterministic(2.5)},
                              seed=1, replications=5)
    assert est.mean_time_to_absorption.mean == pytest.approx(2.5)


def test_empirical_delays_are_resampled_from_the_journal_samples() -> None:
    net = fork_join(2.0, 0.5, 0.5)
    delays = {"ta": Delay.empirical([0.1, 0.2]), "tb": Delay.empirical([0.3])}
    est = simulate_absorption(net, delays, seed=2, replications=50)
    assert est.mean_time_to_absorption.mean == pytest.approx(0.3)


def test_simulation_is_reproducible_with_a_seed() -> None:
    net = queue(1.0, 1.2, 4)
    a = simulate_steady(net, seed=5, batch_time=20.0, batches=5, warmup=5.0)
    b = simulate_steady(net, seed=5, batch_time=20.0, batches=5, warmup=5.0)
    assert a.mean_tokens == b.mean_tokens


def test_simulator_reports_a_timeless_trap() -> None:
    with pytest.raises(AnalysisError, match="timeless trap"):
        simulate_steady(vanishing_loop(1.0, 1.0, trap=True), seed=0, batch_time=10.0, batches=2, warmup=0.0)
