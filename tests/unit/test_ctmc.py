"""Tests of coordinator.analysis.ctmc against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp

from coordinator.analysis import ctmc
from coordinator.errors import AnalysisError


def birth_death(lam: float, mu: float, k: int) -> sp.csr_matrix:
    """Generator of the M/M/1/K queue length (states 0..k)."""
    rows, cols, vals = [], [], []
    for i in range(k):
        rows += [i, i + 1]
        cols += [i + 1, i]
        vals += [lam, mu]
    return ctmc.generator(sp.csr_matrix((vals, (rows, cols)), shape=(k + 1, k + 1)))


def mm1k_pi(lam: float, mu: float, k: int) -> np.ndarray:
    rho = lam / mu
    pi = rho ** np.arange(k + 1)
    return pi / pi.sum()


@pytest.mark.parametrize("method", ["dense", "direct", "bicgstab"])
def test_steady_state_of_a_birth_death_chain_matches_the_closed_form(method: str) -> None:
    q = birth_death(2.0, 3.0, 12)
    sol = ctmc.steady_state(q, method=method, tol=1e-12)
    assert np.allclose(sol.pi, mm1k_pi(2.0, 3.0, 12), atol=1e-10)
    assert sol.residual < 1e-10


def test_iterative_solver_reaches_the_stated_residual_on_a_product_chain() -> None:
    # Two independent queues: Q = Q1 (+) Q2 (Kronecker sum), pi = pi1 (x) pi2.
    q1, q2 = birth_death(0.8, 1.0, 79), birth_death(1.4, 2.0, 79)
    eye = sp.identity(80, format="csr")
    q = sp.csr_matrix(sp.kron(q1, eye) + sp.kron(eye, q2))
    sol = ctmc.steady_state(q, method="bicgstab", tol=1e-11)
    assert sol.residual <= 1e-11
    assert sol.iterations > 0
    assert np.allclose(sol.pi, np.kron(mm1k_pi(0.8, 1.0, 79), mm1k_pi(1.4, 2.0, 79)), atol=1e-9)


def test_transient_distribution_tends_to_the_steady_state() -> None:
    q = birth_death(2.0, 3.0, 8)
    alpha = np.zeros(9)
    alpha[0] = 1.0
    late = ctmc.transient(q, alpha, 200.0)
    assert np.allclose(late, ctmc.steady_state(q).pi, atol=1e-9)


def test_transient_of_a_two_state_chain_matches_the_exponential_formula() -> None:
    a, b, t = 1.5, 0.5, 0.7
    q = ctmc.generator(sp.csr_matrix([[0.0, a], [b, 0.0]]))
    p = ctmc.transient(q, np.array([1.0, 0.0]), t)
    expected = b / (a + b) + a / (a + b) * math.exp(-(a + b) * t)
    assert p[0] == pytest.approx(expected, abs=1e-11)


def test_absorbing_chain_gives_mean_time_and_probabilities() -> None:
    # 0 -> 1 (rate 2) or 0 -> 2 (rate 1); 1 -> 3 (rate 4). 2 and 3 are absorbing.
    rates = sp.csr_matrix(([2.0, 1.0, 4.0], ([0, 0, 1], [1, 2, 3])), shape=(4, 4))
    q = ctmc.generator(rates)
    res = ctmc.absorption(q, np.array([1.0, 0, 0, 0]))
    assert res.mean_time == pytest.approx(1 / 3 + (2 / 3) * 0.25)
    assert res.probabilities == pytest.approx([1 / 3, 2 / 3])


def test_reducible_chain_reports_its_bottom_classes() -> None:
    rates = sp.csr_matrix(([1.0, 1.0, 2.0, 3.0], ([0, 0, 1, 2], [1, 2, 2, 1])), shape=(3, 3))
    q = ctmc.generator(rates)
    classes = ctmc.classify(q)
    assert not classes.irreducible
    assert [c.tolist() for c in classes.bottom] == [[1, 2]]
    lr = ctmc.long_run(q, np.array([1.0, 0.0, 0.0]))
    assert lr.pi == pytest.approx([0.0, 0.6, 0.4])


def test_a_reducible_chain_has_no_plain_steady_state() -> None:
    q = ctmc.generator(sp.csr_matrix(([1.0], ([0], [1])), shape=(3, 3)))
    with pytest.raises(AnalysisError):
        ctmc.steady_state(q, method="dense")
