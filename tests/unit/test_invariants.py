"""Minimal semi-positive P- and T-invariants (Martinez–Silva) against hand-computed ones."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from analysis_nets import make_net

from coordinator.analysis.invariants import (
    p_invariants,
    semiflows,
    structural_bounds,
    t_invariants,
)
from coordinator.net import PetriNet


def mutex() -> PetriNet:
    return make_net("mutex", {"idle1": 1, "idle2": 1, "free": 1}, {
        "enter1": ({"idle1": 1, "free": 1}, {"crit1": 1}),
        "leave1": ({"crit1": 1}, {"idle1": 1, "free": 1}),
        "enter2": ({"idle2": 1, "free": 1}, {"crit2": 1}),
        "leave2": ({"crit2": 1}, {"idle2": 1, "free": 1}),
    })


def as_sets(dicts: list[dict[str, int]]) -> set[frozenset[tuple[str, int]]]:
    return {frozenset(d.items()) for d in dicts}


def test_mutex_has_the_three_hand_computed_p_invariants_and_is_conservative() -> None:
    inv = p_invariants(mutex())
    assert inv.complete and inv.covered
    assert as_sets(inv.as_dicts()) == as_sets([
        {"idle1": 1, "crit1": 1}, {"idle2": 1, "crit2": 1}, {"free": 1, "crit1": 1, "crit2": 1},
    ])


def test_mutex_has_one_t_invariant_per_process_cycle() -> None:
    inv = t_invariants(mutex())
    assert as_sets(inv.as_dicts()) == as_sets([{"enter1": 1, "leave1": 1}, {"enter2": 1, "leave2": 1}])
    assert inv.covered


def test_arc_weights_appear_in_the_invariant() -> None:
    net = make_net("pairs", {"a": 4}, {"join": ({"a": 2}, {"b": 1}), "split": ({"b": 1}, {"a": 2})})
    assert p_invariants(net).as_dicts() == [{"a": 1, "b": 2}]
    assert t_invariants(net).as_dicts() == [{"join": 1, "split": 1}]
    assert structural_bounds(net, p_invariants(net)).tolist() == [4, 2]


def test_producer_without_consumer_has_no_invariant_on_the_buffer() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    pinv = p_invariants(net)
    assert pinv.as_dicts() == [{"go": 1}]
    assert not pinv.covered
    assert structural_bounds(net, pinv).tolist() == [1, -1]
    tinv = t_invariants(net)
    assert tinv.complete and tinv.vectors.shape == (0, 1) and not tinv.covered


def test_size_guard_stops_the_farkas_table() -> None:
    vecs, complete, why = semiflows(np.array([[1, -1]] * 6 + [[-1, 1]] * 6), max_rows=10)
    assert not complete and vecs.shape[0] == 0 and "rows" in why


def brute_force_semiflows(matrix: np.ndarray, top: int) -> np.ndarray:
    """Every y in {0..top}^n, y != 0, with y·matrix = 0."""
    n = matrix.shape[0]
    grid = np.array(list(itertools.product(range(top + 1), repeat=n)), dtype=np.int64)[1:]
    return grid[~(grid @ matrix).any(axis=1)]


@pytest.mark.parametrize("seed", range(12))
def test_random_matrices_agree_with_brute_force_enumeration(seed: int) -> None:
    rng = np.random.default_rng(seed)
    matrix = rng.integers(-2, 3, size=(6, 2))
    vecs, complete, _ = semiflows(matrix)
    assert complete
    for v in vecs:
        assert (v >= 0).all() and v.any() and not (v @ matrix).any()
    ours = [frozenset(np.flatnonzero(v).tolist()) for v in vecs]
    brute = brute_force_semiflows(matrix, top=5)
    brute_supports = {frozenset(np.flatnonzero(v).tolist()) for v in brute}
    # no semiflow has a support strictly inside one of ours: ours are minimal
    for s in ours:
        assert not any(b < s for b in brute_supports)
    # every semiflow found by enumeration contains the support of one of ours
    for b in brute_supports:
        assert any(s <= b for s in ours)
    # a minimal support carries one semiflow up to scaling: ours is the smallest (gcd 1)
    for v, s in zip(vecs, ours):
        same = [w for w in brute if frozenset(np.flatnonzero(w).tolist()) == s]
        if same:
            assert min(int(w.sum()) for w in same) == int(v.sum())
