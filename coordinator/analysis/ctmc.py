"""Continuous-time Markov chains: steady state, transient and absorbing analysis (pure, no I/O).

A chain is given by its infinitesimal generator ``Q``, a square ``scipy.sparse`` matrix of shape
(n, n) in 1/s: ``Q[i, j] >= 0`` is the rate from state *i* to state *j* (i ≠ j) and every row sums
to zero. Distributions are row vectors of shape (n,).

Algorithms (see W. J. Stewart, *Introduction to the Numerical Solution of Markov Chains*, Princeton
University Press, 1994):

* steady state ``pi Q = 0, sum(pi) = 1`` of an irreducible chain: one balance equation is dropped
  and one component fixed, which leaves a non-singular sparse system (any proper principal
  sub-matrix of an irreducible generator is non-singular); solved directly with SuperLU
  (:func:`scipy.sparse.linalg.spsolve`) or iteratively with Jacobi-preconditioned BiCGSTAB,
  checked on the normalised result. The quality of a solution is its residual
  ``||pi Q||_inf`` (:func:`residual`).
* reducible chains are split by strongly connected components
  (:func:`scipy.sparse.csgraph.connected_components`) into transient states and *bottom*
  (closed) classes; the long-run distribution weighs the steady state of each bottom class by the
  probability of being absorbed in it.
* transient distribution ``pi(t) = alpha exp(Q t)`` by uniformisation (A. Jensen, 1953) with the
  Poisson weights truncated left and right so that the neglected mass is below ``eps``
  (the idea of B. L. Fox and P. W. Glynn, "Computing Poisson probabilities", CACM 31(4), 1988).
* absorbing analysis: with ``Q_TT`` the generator restricted to the transient states,
  the expected time spent in each transient state starting from ``alpha`` is
  ``y = alpha_T (-Q_TT)^-1`` (a row of the fundamental matrix), the mean time to absorption is
  ``sum(y)`` and the probability of ending in bottom class *k* is ``y Q_T,k 1 + alpha_k``
  (Kemeny & Snell, *Finite Markov Chains*, 1960).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components
from scipy.special import gammaln

from coordinator.errors import AnalysisError

__all__ = [
    "DIRECT_LIMIT",
    "Absorption",
    "Classes",
    "SteadyState",
    "absorption",
    "classify",
    "generator",
    "long_run",
    "residual",
    "steady_state",
    "transient",
]

#: Chains up to this many states are solved directly (SuperLU) when ``method="auto"``.
DIRECT_LIMIT = 2_000


@dataclass(frozen=True, slots=True)
class SteadyState:
    """A steady-state solution.

    Attributes:
        pi: probabilities, shape (n,), summing to 1.
        residual: ``||pi Q||_inf`` in 1/s.
        method: ``"direct"``, ``"bicgstab"`` or ``"dense"``.
        iterations: iterations of the iterative solver (0 for direct ones).
    """

    pi: np.ndarray
    residual: float
    method: str
    iterations: int


@dataclass(frozen=True, slots=True)
class Classes:
    """Strongly connected structure of a chain.

    Attributes:
        label: SCC label of each state, shape (n,).
        bottom: the bottom (closed) classes, each an int array of state indices.
        transient: indices of the states in no bottom class, shape (m,).
    """

    label: np.ndarray
    bottom: tuple[np.ndarray, ...]
    transient: np.ndarray

    @property
    def irreducible(self) -> bool:
        """True when the chain has one class and no transient state."""
        return len(self.bottom) == 1 and self.transient.size == 0


@dataclass(frozen=True, slots=True)
class Absorption:
    """Result of an absorbing-chain analysis.

    Attributes:
        mean_time: expected time (s) until a bottom class is entered.
        probabilities: probability of ending in each bottom class, shape (k,).
        sojourn: expected time (s) spent in each state before absorption, shape (n,)
            (zero on the bottom classes).
    """

    mean_time: float
    probabilities: np.ndarray
    sojourn: np.ndarray


def generator(rates: sp.spmatrix | sp.sparray) -> sp.csr_matrix:
    """Return the generator with the off-diagonal rates of ``rates`` and the diagonal set to −row sums.

    Args:
        rates: sparse (n, n) matrix of non-negative rates (1/s); its diagonal is ignored.

    Returns:
        CSR generator (n, n).
    """
    r = sp.csr_matrix(rates, dtype=float)
    r.setdiag(0.0)
    r.eliminate_zeros()
    out = r - sp.diags(np.asarray(r.sum(axis=1)).ravel())
    return sp.csr_matrix(out)


def residual(q: sp.spmatrix | sp.sparray, pi: np.ndarray) -> float:
    """Return ``||pi Q||_inf`` (1/s): how far ``pi`` is from satisfying the balance equations."""
    return float(np.max(np.abs(q.T @ pi))) if pi.size else 0.0


def classify(q: sp.spmatrix | sp.sparray) -> Classes:
    """Split a chain into bottom (closed) strongly connected classes and transient states.

    Args:
        q: generator (n, n).

    Returns:
        :class:`Classes`.
    """
    q = sp.csr_matrix(q)
    n = q.shape[0]
    off = q.copy()
    off.setdiag(0.0)
    off.eliminate_zeros()
    ncomp, label = connected_components(off, directed=True, connection="strong")
    coo = off.tocoo()
    leaves = np.ones(ncomp, dtype=bool)
    cross = label[coo.row] != label[coo.col]
    leaves[np.unique(label[coo.row[cross]])] = False
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(ncomp + 1))
    bottom = tuple(order[bounds[c]:bounds[c + 1]] for c in range(ncomp) if leaves[c])
    # Present bottom classes in the order of their smallest state index (reproducible output).
    bottom = tuple(sorted(bottom, key=lambda a: int(a.min())))
    in_bottom = np.zeros(n, dtype=bool)
    for cls in bottom:
        in_bottom[cls] = True
    return Classes(label=label, bottom=bottom, transient=np.flatnonzero(~in_bottom))


def steady_state(
    q: sp.spmatrix | sp.sparray,
    *,
    method: str = "auto",
    tol: float = 1e-10,
    maxiter: int = 5000,
) -> SteadyState:
    """Solve ``pi Q = 0``, ``sum(pi) = 1`` for an irreducible chain.

    The balance equation of a reference state *r* is dropped and ``pi_r`` fixed to 1, which leaves a
    non-singular system ``A x = b`` (A: ``Q^T`` without row and column *r*). The reference state is
    the most probable one after a few uniformised power steps: fixing an improbable state makes
    ``A`` nearly singular. Iterative solves use BiCGSTAB (H. A. van der Vorst, SIAM J. Sci. Stat.
    Comput. 13(2), 1992) with a Jacobi preconditioner, restarted until the residual target is met.

    Args:
        q: generator (n, n) in 1/s, irreducible.
        method: ``"dense"`` (numpy LU), ``"direct"`` (SuperLU), ``"bicgstab"`` (iterative) or
            ``"auto"`` (direct up to :data:`DIRECT_LIMIT` states, else bicgstab).
        tol: target residual ``||pi Q||_inf`` (1/s) of the iterative solver.
        maxiter: iteration limit of the iterative solver.

    Returns:
        :class:`SteadyState`.

    Raises:
        AnalysisError: if the chain is empty, the system is singular (reducible chain) or the
            iterative solver does not reach ``tol``.
    """
    q = sp.csr_matrix(q, dtype=float)
    n = q.shape[0]
    if n == 0:
        raise AnalysisError("steady state of an empty chain")
    if n == 1:
        return SteadyState(np.ones(1), 0.0, "direct", 0)
    if method == "auto":
        method = "direct" if n <= DIRECT_LIMIT else "bicgstab"
    qt = sp.csr_matrix(q.T)
    guess = _power_steps(qt, -q.diagonal(), 50)
    ref = int(np.argmax(guess))
    keep = np.r_[0:ref, ref + 1:n]
    a = qt[keep][:, keep]
    b = -np.asarray(qt[keep][:, [ref]].todense()).ravel()
    iterations = 0
    with np.errstate(all="ignore"):
        if method == "dense":
            try:
                x = np.linalg.solve(a.toarray(), b)
            except np.linalg.LinAlgError:
                x = np.full(n - 1, np.nan)
        elif method == "direct":
            x = spla.spsolve(sp.csc_matrix(a), b)
        elif method == "bicgstab":
            x, iterations = _bicgstab(qt, a, b, guess[keep] / guess[ref], ref, keep, tol, maxiter)
        else:
            raise AnalysisError(f"unknown steady-state method {method!r}: use auto, dense, direct or bicgstab")
    pi = np.empty(n)
    pi[keep] = x
    pi[ref] = 1.0
    if not np.all(np.isfinite(pi)):
        raise AnalysisError("steady-state solve failed: singular system (is the chain irreducible?)")
    pi = np.clip(pi, 0.0, None)
    pi /= pi.sum()
    return SteadyState(pi, residual(q, pi), method, iterations)


def _power_steps(qt: sp.csr_matrix, exit_rates: np.ndarray, steps: int) -> np.ndarray:
    """A few steps of the uniformised chain from the uniform distribution (a rough pi, shape (n,))."""
    n = qt.shape[0]
    lam = float(exit_rates.max()) * 1.02 or 1.0
    pi = np.full(n, 1.0 / n)
    for _ in range(steps):
        pi = pi + (qt @ pi) / lam
    return pi


def _bicgstab(qt: sp.csr_matrix, a: sp.csr_matrix, b: np.ndarray, x0: np.ndarray, ref: int,
              keep: np.ndarray, tol: float, maxiter: int) -> tuple[np.ndarray, int]:
    """Jacobi-preconditioned BiCGSTAB on ``a x = b``, judged on the residual of the normalised pi."""
    inv = 1.0 / a.diagonal()
    prec = spla.LinearOperator(a.shape, lambda v: inv * v)
    count = [0]

    def tick(_: np.ndarray) -> None:
        count[0] += 1

    n = qt.shape[0]
    x = x0
    res = math.inf
    # The dropped equation's residual is minus the sum of the others: aim at ||r||_2 <= tol/sqrt(n).
    target = 0.5 * tol / math.sqrt(n)
    a = sp.csc_matrix(a)
    while count[0] < maxiter:
        scale = 1.0 + float(np.abs(x).sum())
        x, _ = spla.bicgstab(a, b, x0=x, rtol=0.0, atol=target * scale, maxiter=maxiter - count[0],
                             M=prec, callback=tick)
        pi = np.empty(n)
        pi[keep] = x
        pi[ref] = 1.0
        pi = np.clip(pi, 0.0, None)
        pi /= pi.sum()
        res = float(np.max(np.abs(qt @ pi)))
        if res <= tol:
            return x, count[0]
        target *= 0.1
        count[0] += 1
    raise AnalysisError(
        f"iterative steady-state solver stopped at residual {res:.3g} > {tol:.3g} after {count[0]} "
        "iterations; raise maxiter or try method='direct'"
    )


def long_run(q: sp.spmatrix | sp.sparray, alpha: np.ndarray, *, method: str = "auto") -> SteadyState:
    """Return the long-run distribution of a possibly reducible chain started from ``alpha``.

    The mass ``alpha`` reaches bottom class *k* with the probability given by :func:`absorption`;
    within the class it settles on the class's own steady state.

    Args:
        q: generator (n, n).
        alpha: initial distribution, shape (n,).
        method: steady-state method for each bottom class (see :func:`steady_state`).

    Returns:
        :class:`SteadyState` of the whole chain (residual over all states).
    """
    q = sp.csr_matrix(q, dtype=float)
    classes = classify(q)
    if classes.irreducible:
        return steady_state(q, method=method)
    absorbed = absorption(q, alpha, classes)
    pi = np.zeros(q.shape[0])
    iterations = 0
    used = "direct"
    for cls, weight in zip(classes.bottom, absorbed.probabilities, strict=True):
        if weight <= 0.0:
            continue
        sub = steady_state(q[cls][:, cls], method=method)
        pi[cls] = weight * sub.pi
        iterations += sub.iterations
        used = sub.method
    return SteadyState(pi, residual(q, pi), used, iterations)


def absorption(
    q: sp.spmatrix | sp.sparray, alpha: np.ndarray, classes: Classes | None = None
) -> Absorption:
    """Mean time to absorption and absorption probabilities into the bottom classes.

    Args:
        q: generator (n, n) in 1/s.
        alpha: initial distribution, shape (n,).
        classes: result of :func:`classify`, computed if omitted.

    Returns:
        :class:`Absorption`; ``probabilities[k]`` belongs to ``classes.bottom[k]``.

    Raises:
        AnalysisError: if ``alpha`` is not a distribution over the n states.
    """
    q = sp.csr_matrix(q, dtype=float)
    n = q.shape[0]
    alpha = np.asarray(alpha, dtype=float)
    if alpha.shape != (n,) or abs(alpha.sum() - 1.0) > 1e-9 or alpha.min() < 0:
        raise AnalysisError(f"initial distribution must be {n} non-negative numbers summing to 1")
    classes = classes if classes is not None else classify(q)
    tr = classes.transient
    sojourn = np.zeros(n)
    probs = np.array([alpha[c].sum() for c in classes.bottom])
    if tr.size and alpha[tr].sum() > 0:
        qtt = sp.csc_matrix(q[tr][:, tr])
        # y (-Q_TT) = alpha_T  <=>  (-Q_TT)^T y^T = alpha_T^T
        y = spla.spsolve(sp.csc_matrix(-qtt.T), alpha[tr]) if tr.size > 1 else alpha[tr] / -qtt.toarray()[0]
        y = np.atleast_1d(np.asarray(y, dtype=float))
        if not np.all(np.isfinite(y)):
            raise AnalysisError("absorbing analysis failed: singular transient generator")
        sojourn[tr] = y
        flow = q[tr].T @ y  # expected number of jumps into each state, shape (n,)
        probs = probs + np.array([flow[c].sum() for c in classes.bottom])
    return Absorption(mean_time=float(sojourn.sum()), probabilities=probs, sojourn=sojourn)


def _poisson_window(lam: float, eps: float) -> tuple[int, np.ndarray]:
    """Left truncation point and normalised Poisson(lam) weights covering ``1 - eps`` of the mass."""
    if lam == 0.0:
        return 0, np.ones(1)
    spread = math.sqrt(lam) * (4.0 + math.sqrt(-2.0 * math.log(eps)))
    left = max(0, math.floor(lam - spread))
    right = math.ceil(lam + spread + 10.0)
    k = np.arange(left, right + 1)
    logw = -lam + k * math.log(lam) - gammaln(k + 1.0)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    return left, w


def transient(q: sp.spmatrix | sp.sparray, alpha: np.ndarray, t: float, *, eps: float = 1e-12) -> np.ndarray:
    """Return ``alpha exp(Q t)`` by uniformisation (Jensen) with Fox–Glynn-style truncation.

    Args:
        q: generator (n, n) in 1/s.
        alpha: initial distribution, shape (n,).
        t: time in s, ``t >= 0``.
        eps: bound on the neglected Poisson mass.

    Returns:
        The distribution at time ``t``, shape (n,).

    Raises:
        AnalysisError: on a negative time.
    """
    if t < 0:
        raise AnalysisError(f"transient analysis needs t >= 0, got {t}")
    q = sp.csr_matrix(q, dtype=float)
    v = np.asarray(alpha, dtype=float).copy()
    rate = float(np.max(-q.diagonal())) if q.shape[0] else 0.0
    if rate == 0.0 or t == 0.0:
        return v
    rate *= 1.02
    p = sp.identity(q.shape[0], format="csr") + q / rate
    pt = sp.csr_matrix(p.T)
    left, weights = _poisson_window(rate * t, eps)
    out = np.zeros_like(v)
    for _ in range(left):
        v = pt @ v
    for w in weights:
        out += w * v
        v = pt @ v
    return out
