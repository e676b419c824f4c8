"""Structural answers by linear programming, each checked in exact integer arithmetic (pure, no I/O).

Enumerating minimal semiflows (:mod:`.invariants`) can take exponential time, and an explicit state
space can be too large; the questions below need neither. Each is a linear program (LP) solved by
HiGHS through :func:`scipy.optimize.linprog` (the bounds of the state equation and the semiflow
cover's, one place after another, through HiGHS's own bindings: :class:`_StateEquation`,
:class:`_Through`), and each answer comes with a certificate, an integer
vector rebuilt from the LP's floating-point solution and checked exactly, so a verdict is either
proved or reported as resting on floating point (``certified`` False).

* **Which places (transitions) lie in the support of some P-semiflow (T-semiflow)?** For a matrix
  A of shape (n, m), the semi-positive y (n,) with yᵀA = 0 have a largest support, the union of all
  minimal supports. The LP ``max Σ z  s.t.  yᵀA = 0, 0 ≤ z ≤ 1, z ≤ y, y ≥ 0`` finds it: y can be
  scaled up freely, so z is 1 exactly on that support. By Tucker's complementarity theorem (the
  strict form of Farkas' lemma; Schrijver 1986, *Theory of Linear and Integer Programming*, §7.8),
  every index outside it carries a witness x with A·x ≥ 0 and (A·x)_i > 0, found by the LP
  ``max Σ w  s.t.  A·x ≥ 0, 0 ≤ w ≤ 1, w ≤ (A·x)_U``, w only on the indices U outside the support
  (on the support, (A·x)_i = 0 for every such x). Both vectors together prove the partition. With
  A = C (incidence, |P| × |T|): the net is *conservative* (a strictly positive P-semiflow exists)
  iff every place is covered; with A = Cᵀ: *consistent* (a strictly positive T-semiflow) iff
  every transition is covered (Murata 1989, section VI; Silva, Teruel, Colom 1998, *Linear algebraic
  and linear programming techniques for the analysis of P/T net systems*).
* **Upper bounds from the state equation.** Every reachable marking is M = M0 + C·σ for some σ ≥ 0
  (the firing count vector), so ``max M(p)  s.t.  M0 + C·σ ≥ 0, σ ≥ 0`` bounds place p (Silva et
  al. 1998, section 4). Its dual gives y ≥ 0 with y_p ≥ 1 and yᵀC ≤ 0, and then M(p) ≤ y·M0 for
  every reachable M: an integer check of yᵀC ≤ 0 certifies the bound. The same LP for Σ_p M(p)
  decides boundedness of every place at once when it is finite (structural boundedness: a y > 0
  with yᵀC ≤ 0; Memmi and Roucairol 1980, Murata 1989 theorem 29). Inhibitor arcs only forbid
  firings, so the bounds hold on nets with them too. An unbounded LP proves nothing (the relaxation
  admits markings that are not reachable).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from math import comb, floor
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from coordinator.analysis.matrices import SparseNet

__all__ = [
    "PlaceBounds",
    "Support",
    "conservative",
    "consistent",
    "place_bounds",
    "semiflow_cover",
    "semiflow_support",
    "total_bound",
    "total_place_bounds",
]

#: default seconds allowed to one LP
LP_SECONDS = 10.0
_TOL = 1e-7


@dataclass(frozen=True)
class Support:
    """The largest support of the semi-positive y with yᵀA = 0, with its certificates.

    Attributes:
        covered: shape (n,), bool: index i lies in the support of some semiflow; None if the LP
            did not finish (time limit, numerical trouble).
        certified: True when both certificates were rebuilt as integer vectors and checked exactly.
        semiflow: an integer semiflow (n,) whose support is ``covered`` (Python ints as int64 when
            they fit, else object), or None.
        witness: integer x (m,) with A·x ≥ 0 and (A·x)_i > 0 for every uncovered i, or None (also
            when every index is covered: nothing to witness).
        message: what the solver said when it did not finish.
    """

    covered: np.ndarray | None
    certified: bool = False
    semiflow: np.ndarray | None = None
    witness: np.ndarray | None = None
    message: str = ""

    @property
    def all_covered(self) -> bool | None:
        """True if every index is covered (conservative / consistent), None if undecided."""
        return None if self.covered is None else bool(self.covered.all())


def _solve(c: np.ndarray, a_ub: sp.spmatrix | None, b_ub: np.ndarray | None, a_eq: sp.spmatrix | None,
           b_eq: np.ndarray | None, bounds: Sequence[tuple[float | None, float | None]] | tuple[float, None],
           seconds: float) -> Any:
    return linprog(c, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq, bounds=bounds, method="highs",
                   options={"time_limit": max(float(seconds), 0.01), "presolve": True})


#: common denominators tried when an LP solution is rebuilt as an integer vector (720720 is the
#: least common multiple of 1..16, so vertex solutions with small denominators come back exactly)
_DENOMINATORS = (1, 2, 6, 12, 60, 840, 27720, 720720)


def _rationalised(values: np.ndarray) -> list[np.ndarray]:
    """Integer vectors proportional to ``values`` (scaled to a largest magnitude of 1, then
    multiplied by each common denominator of :data:`_DENOMINATORS` and rounded), keeping only the
    roundings that moved no entry by more than 1e-6 relative; each divided by the gcd of its
    entries. Vectorised: no per-entry Python work."""
    top = float(np.abs(values).max(initial=0.0))
    if top <= 0:
        return []
    vals = values / top
    out: list[np.ndarray] = []
    for den in _DENOMINATORS:
        scaled = vals * den
        ints = np.rint(scaled)
        if np.abs(scaled - ints).max(initial=0.0) > 1e-6 * den:
            continue
        vec = ints.astype(np.int64)
        g = int(np.gcd.reduce(np.abs(vec))) if vec.size else 0
        if g > 1:
            vec //= g
        if vec.any() and not any(np.array_equal(vec, o) for o in out):
            out.append(vec)
    return out


def _exact_product(mat: sp.csr_matrix, vec: np.ndarray | list[int]) -> np.ndarray:
    """mat @ vec in exact integer arithmetic: an int64 array when it provably fits, an array of
    Python ints (dtype object) otherwise. An integer array is read as it is (no Python int per
    entry: AirplaneLD-PT-2000's semiflow cover checked 357 vectors of 8,017 and 16,008 entries, 1.8 s
    that way, most of it in the bound); an int64 ``mat`` is not copied."""
    arr = np.asarray(vec)
    if arr.dtype.kind not in "iu" or arr.ndim != 1:
        arr = np.array([int(v) for v in vec], dtype=object)
    big = max(int(arr.max(initial=0)), -int(arr.min(initial=0)))
    row_nnz = int(np.diff(mat.indptr).max(initial=0))
    scale = int(np.abs(mat.data).max(initial=0))
    if big < 2**62 and big * scale * max(row_nnz, 1) < 2**62:
        return np.asarray(mat.astype(np.int64, copy=False) @ arr.astype(np.int64), dtype=np.int64).ravel()
    vec = [int(v) for v in arr.tolist()]
    out = np.empty(mat.shape[0], dtype=object)
    data, idx, ptr = mat.data.tolist(), mat.indices.tolist(), mat.indptr.tolist()
    for r in range(mat.shape[0]):
        out[r] = sum(int(data[k]) * vec[idx[k]] for k in range(ptr[r], ptr[r + 1]))
    return out


def semiflow_support(matrix: sp.spmatrix | np.ndarray, *, seconds: float = LP_SECONDS) -> Support:
    """The largest support of the semi-positive y with yᵀ·matrix = 0, by two LPs (module docstring).

    Args:
        matrix: shape (n, m), integer (the incidence matrix C for P-semiflows, Cᵀ for T-semiflows).
        seconds: time limit of each LP.

    Returns:
        A :class:`Support` (``covered`` None if an LP did not finish).
    """
    a = sp.csr_matrix(matrix, dtype=np.float64)
    n, m = a.shape
    if n == 0:
        return Support(covered=np.zeros(0, dtype=bool), certified=True)
    a_int = sp.csr_matrix(matrix).astype(np.int64)
    at_int = sp.csr_matrix(a_int.T)
    # LP 1: max sum z, yᵀA = 0, z <= y, 0 <= z <= 1, y >= 0; variables [y, z]
    eye = sp.identity(n, format="csr")
    a_eq = sp.hstack([a.T, sp.csr_matrix((m, n))], format="csr") if m else None
    a_ub = sp.hstack([-eye, eye], format="csr")
    c = np.concatenate([np.zeros(n), -np.ones(n)])
    bounds = [(0.0, None)] * n + [(0.0, 1.0)] * n
    res = _solve(c, a_ub, np.zeros(n), a_eq, np.zeros(m) if m else None, bounds, seconds)
    if res.status != 0:
        return Support(covered=None, message=str(res.message))
    y = np.asarray(res.x[:n])
    z = np.asarray(res.x[n:])
    covered = z > 0.5
    semiflow: np.ndarray | None = None
    for cand in _rationalised(np.where(covered, np.maximum(y, 0.0), 0.0)):
        if (cand[covered] > 0).all() and (cand >= 0).all() and not _exact_product(at_int, cand).any():
            semiflow = cand
            break
    if covered.all():
        return Support(covered=covered, certified=semiflow is not None, semiflow=semiflow)
    # LP 2: max sum w, A x >= 0, w <= (A x)_U, 0 <= w <= 1, x free; variables [x, w], w only on the
    # indices U outside the support: on an index of a semiflow's support, (A x)_i is 0 for every x
    # with A x >= 0 (yᵀA x = 0), so a w there would always be 0. StigmergyCommit-PT-08b (42,776
    # transitions, 515 outside): 0.7 s, where a w on every transition took 19 s
    out = np.flatnonzero(~covered)
    k = out.size
    pick = sp.csr_matrix((np.ones(k), (np.arange(k), out)), shape=(k, n))
    a_ub2 = sp.vstack([sp.hstack([-a, sp.csr_matrix((n, k))]), sp.hstack([-(pick @ a), sp.identity(k, format="csr")])],
                      format="csr")
    c2 = np.concatenate([np.zeros(m), -np.ones(k)])
    bounds2 = [(None, None)] * m + [(0.0, 1.0)] * k
    res2 = _solve(c2, a_ub2, np.zeros(n + k), None, None, bounds2, seconds)
    witness: np.ndarray | None = None
    if res2.status == 0:
        x = np.asarray(res2.x[:m])
        for cand in _rationalised(x):
            ax = _exact_product(a_int, cand)
            if (ax >= 0).all() and (ax[~covered] > 0).all():
                witness = cand
                break
    certified = witness is not None and (semiflow is not None or not covered.any())
    return Support(covered=covered, certified=certified, semiflow=semiflow, witness=witness)


def conservative(sn: SparseNet, *, seconds: float = LP_SECONDS) -> Support:
    """P-semiflow support of a net (:func:`semiflow_support` of C): conservative iff all covered."""
    return semiflow_support(sn.incidence, seconds=seconds)


def consistent(sn: SparseNet, *, seconds: float = LP_SECONDS) -> Support:
    """T-semiflow support of a net (:func:`semiflow_support` of Cᵀ): consistent iff all covered."""
    return semiflow_support(sn.incidence.T, seconds=seconds)


@dataclass(frozen=True)
class _Bound:
    value: int | None  # None: the LP is unbounded (or did not finish: see ok)
    ok: bool  # the LP finished (optimal or unbounded)
    certified: bool
    dual: np.ndarray | None = None  # the integer certificate y (yᵀC <= 0, y >= 0), if any


def _certified_dual(ct: sp.csr_matrix, weights: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, int] | None:
    """An integer y = d·(weights + u') (u' ≈ u, rounded to a common denominator d) with yᵀC ≤ 0,
    checked exactly (``ct``: Cᵀ, int64, (|T|, |P|)); returned with d, or None."""
    w = np.asarray(weights, dtype=np.float64)
    for den in _DENOMINATORS:
        scaled = u * den
        ints = np.rint(scaled)
        if np.abs(scaled).max(initial=0.0) > 2.0**52 or np.abs(scaled - ints).max(initial=0.0) > 1e-6 * den:
            continue
        y = ints.astype(np.int64) + np.rint(w * den).astype(np.int64)
        if (_exact_product(ct, y) <= 0).all():
            return y, den
    return None


def _highs(cols: sp.csc_matrix, cost: np.ndarray, col_lower: np.ndarray, row_lower: np.ndarray,
           row_upper: np.ndarray) -> Any:
    """A HiGHS instance (HiGHS's own bindings, ``highspy``) holding ``min cost·x  s.t.  row_lower ≤
    cols·x ≤ row_upper, x ≥ col_lower``, its output off. Their ``Highs`` subclass is not used: it
    sets up callbacks on construction, and that writes HiGHS's banner to the process's standard
    output before any option can turn it off (`petrobot analyze --json` prints there)."""
    import highspy

    m, n = cols.shape
    h = highspy._Highs()  # type: ignore[attr-defined]  # exported, not in their stubs
    h.setOptionValue("output_flag", False)
    model = highspy.HighsLp()
    model.num_col_, model.num_row_ = n, m
    model.col_cost_ = cost
    model.col_lower_ = col_lower
    model.col_upper_ = np.full(n, highspy.kHighsInf)
    model.row_lower_ = row_lower
    model.row_upper_ = row_upper
    model.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    model.a_matrix_.num_col_, model.a_matrix_.num_row_ = n, m
    model.a_matrix_.start_ = cols.indptr
    model.a_matrix_.index_ = cols.indices
    model.a_matrix_.value_ = cols.data
    h.passModel(model)
    return h


def _time_limit(h: Any, seconds: float) -> None:
    """Let the next run of HiGHS instance ``h`` take ``seconds`` (at least 0.01). HiGHS compares its
    ``time_limit`` with the instance's run time summed over all its runs, so the limit is that sum
    plus ``seconds``: given as ``seconds`` alone, the LPs of one instance stopped when the runs
    before them had taken what was left of the time, about half of it (NeoElection-PT-3's cover
    from scratch, :func:`semiflow_cover`: at 1.3 s of its 3 s, with 449 to 527 semiflows from one
    run to the next; 664 now)."""
    h.setOptionValue("time_limit", h.getRunTime() + max(float(seconds), 0.01))


class _StateEquation:
    """``max w·M  s.t.  M = M0 + Cσ ≥ 0, σ ≥ 0`` for one weight vector w after another, in one HiGHS
    instance: only the objective changes between two, so the last optimal basis stays feasible and
    each LP after the first goes on from it by the primal simplex. Over EnergyBus-PT-none's 157
    places (4,430 transitions) 0.4 s, against 4.8 s through :func:`scipy.optimize.linprog`, which
    builds the model for each; ARMCacheCoherence-PT-none's 87 places (33,676 transitions) 1.2 s
    against 9.8 s. The bound is the LP's optimum whatever vertex attains it; its certificate is
    the vertex's dual.

    Args:
        sn: the net's sparse matrices (at least one transition).
    """

    def __init__(self, sn: SparseNet) -> None:
        import highspy

        self.sn = sn
        self.c_mat = sp.csr_matrix(sn.incidence, dtype=np.float64)
        self.m0 = np.asarray(sn.m0, dtype=np.float64)
        n_p, n_t = self.c_mat.shape
        inf = np.full(n_p, highspy.kHighsInf)
        self.h = _highs(sp.csc_matrix(self.c_mat), np.zeros(n_t), np.zeros(n_t), -self.m0, inf)
        self.status = highspy.HighsModelStatus
        self.ct = sp.csr_matrix(sn.incidence.T).astype(np.int64)
        self.cost = np.zeros(n_t)  # the objective the instance holds
        self.solved = 0

    def bound(self, weights: np.ndarray, seconds: float) -> _Bound:
        """The LP for ``weights`` ((|P|,), ≥ 0) within ``seconds``."""
        h, st = self.h, self.status
        cost = -(self.c_mat.T @ weights)
        # only the columns whose cost changes: passing all of them makes HiGHS sort the set each time
        # (AirplaneLD-PT-1000, 8,008 transitions: 14% of the time of its per-place LPs)
        cols = np.flatnonzero(cost != self.cost).astype(np.int32)
        if cols.size:
            h.changeColsCost(cols.size, cols, cost[cols])
            self.cost = cost
        _time_limit(h, seconds)
        if self.solved == 1:  # from the first optimal basis on, the objective alone changes
            h.setOptionValue("simplex_strategy", 4)  # primal
        h.run()
        self.solved += 1
        status = h.getModelStatus()
        if status in (st.kUnbounded, st.kUnboundedOrInfeasible):  # σ = 0 is feasible: unbounded
            return _Bound(value=None, ok=True, certified=False)
        if status != st.kOptimal:
            return _Bound(value=None, ok=False, certified=False)
        base = float(weights @ self.m0)
        value = base - float(h.getInfo().objective_function_value)
        # dual certificate: y = weights + u, u ≥ 0 the rows' duals (Cσ ≥ -M0), with yᵀC ≤ 0; then
        # w·M ≤ y·M ≤ y·M0
        u = np.maximum(np.asarray(h.getSolution().row_dual, dtype=np.float64), 0.0)
        y = _certified_dual(self.ct, weights, u)
        if y is not None:
            vec, den = y
            num = int(np.dot(vec.astype(object), self.sn.m0.astype(object)))
            return _Bound(value=num // den, ok=True, certified=True, dual=vec)
        return _Bound(value=floor(value + _TOL * max(1.0, abs(value))), ok=True, certified=False)


def _bound(sn: SparseNet, weights: np.ndarray, seconds: float, lps: _StateEquation | None = None) -> _Bound:
    """max weights·M over the state equation: M = M0 + Cσ ≥ 0, σ ≥ 0 (weights ≥ 0, (|P|,)), in
    ``lps`` (a new instance if None)."""
    if not sn.n_transitions:
        return _Bound(value=floor(float(weights @ np.asarray(sn.m0, dtype=np.float64)) + 1e-9), ok=True,
                      certified=True)
    return (lps or _StateEquation(sn)).bound(weights, seconds)


def total_bound(sn: SparseNet, *, seconds: float = LP_SECONDS) -> tuple[int | None, bool, bool]:
    """Bound on the total token count Σ_p M(p) from the state equation.

    Returns:
        ``(bound, finished, certified)``: bound None when the LP is unbounded or did not finish
        (``finished`` False); ``certified`` when a dual vector y ≥ 1, yᵀC ≤ 0 was checked exactly.
    """
    value, ok, certified, _ = total_place_bounds(sn, seconds=seconds)
    return value, ok, certified


def total_place_bounds(sn: SparseNet, *, seconds: float = LP_SECONDS) -> tuple[int | None, bool, bool, np.ndarray]:
    """:func:`total_bound`, and the per-place bounds its certificate gives at no further cost: with
    the checked dual vector y (y ≥ 1, yᵀC ≤ 0), M(p) ≤ ⌊y·M0 / y_p⌋ (else the total bound itself).

    Returns:
        ``(bound, finished, certified, places)``: as :func:`total_bound`, then (|P|,) int64 place
        bounds, -1 where none (the LP unbounded or not finished).
    """
    b = _bound(sn, np.ones(sn.n_places), seconds)
    places = np.full(sn.n_places, -1 if b.value is None else b.value, dtype=np.int64)
    if b.value is not None and b.dual is not None:
        _apply(places, np.zeros(sn.n_places, dtype=bool), b.dual, sn.m0, True)
    return b.value, b.ok, b.certified, places


@dataclass(frozen=True)
class PlaceBounds:
    """Upper bounds of the places of a net from the state equation and semiflows.

    Attributes:
        total: bound on Σ_p M(p), or None (LP unbounded or not finished).
        bounds: per place (|P|,), int64: the best bound known, -1 where none.
        own: (|P|,) bool: the place had its own LP.
        certified: (|P|,) bool: the bound rests on an integer vector checked exactly.
        complete: every place that could still be improved had its own LP within the time allowed.
        notes: what was left out and why.
    """

    total: int | None
    bounds: np.ndarray
    own: np.ndarray
    certified: np.ndarray
    complete: bool
    notes: list[str] = field(default_factory=list)


def _apply(bounds: np.ndarray, cert: np.ndarray, y: np.ndarray, m0: np.ndarray, certified: bool) -> None:
    """Tighten ``bounds`` with y ≥ 0 such that y·M ≤ y·M0 for every reachable M: M(p) ≤ ⌊y·M0 / y_p⌋."""
    total = int(np.dot(np.asarray(y).astype(object), np.asarray(m0).astype(object)))
    for p in np.flatnonzero(y).tolist():
        b = total // int(y[p])
        if bounds[p] < 0 or b < bounds[p] or (b == bounds[p] and certified and not cert[p]):
            bounds[p] = b
            cert[p] = certified


#: places weighed together by one LP of :func:`_blocks`
_BLOCK = 16


def _blocks(sn: SparseNet, lps: _StateEquation, todo: np.ndarray, improvable: Callable[[np.ndarray], np.ndarray],
            bounds: np.ndarray, cert: np.ndarray, until: float) -> None:
    """max Σ M(p) over each run of :data:`_BLOCK` places of ``todo`` (in the net's order) that still
    need an LP (``improvable``), by :func:`place_bounds` when one LP per place would not fit in its
    time. Where the places of a run exclude each other (at most one token among them, as the places
    a choice among many values leads to), the run's certificate bounds them all by one, and they
    need no LP of their own; elsewhere it costs one LP more in :data:`_BLOCK`. AirplaneLD-PT-1000
    (7,019 places, 8,008 transitions, every place 1-safe): 3,044 LPs and 4.8 s instead of 7,014
    LPs and 12.7 s (10 s given: 2,691 places were left at the total's bound, 3,008), the same
    bounds. Stops at ``until`` (``time.monotonic()``)."""
    for s in range(0, todo.size, _BLOCK):
        block = todo[s:s + _BLOCK]
        block = block[improvable(block)]
        left = until - time.monotonic()
        if left <= 0:
            return
        if block.size < 2:
            continue
        w = np.zeros(sn.n_places)
        w[block] = 1.0
        b = lps.bound(w, left)
        if b.dual is not None:
            _apply(bounds, cert, b.dual, sn.m0, True)
        elif b.value is not None:  # M(p) ≤ Σ M(q) over the run, uncertified as the LP's own value
            tighter = block[(bounds[block] < 0) | (bounds[block] > b.value)]
            bounds[tighter] = b.value
            cert[tighter] = False


def place_bounds(sn: SparseNet, *, seconds: float = 5.0, seen: np.ndarray | None = None,
                 semiflows: Sequence[np.ndarray] = (), lp_above: int = 0) -> PlaceBounds:
    """Upper bound of each place from the state equation (module docstring), within a time budget.

    First the LP of the total token count Σ M(p): its dual vector y (y ≥ 1, yᵀC ≤ 0) bounds every
    place at once by ⌊y·M0 / y_p⌋, and so does every semiflow given (yᵀC = 0, e.g. P-invariants).
    Then each place whose bound is not yet reached by an explored marking (``seen``) gets its own
    LP, in order, until ``seconds`` are spent (none after the first when its time says that they
    would take more than twice that). The LPs share one HiGHS instance (:class:`_StateEquation`).
    Each LP's certificate y bounds every place it weighs, by ⌊y·M0 / y_q⌋, too; so a place that an
    earlier LP's certificate has bounded to its reached count, or to at most ``lp_above``, needs no
    LP of its own (CloudReconfiguration-PT-309, no semiflow, ``lp_above`` 1: its 2,585 places are
    all bounded by one token after 10 LPs, 0.07 s, where one LP per place had done about 1,800 of
    them in the 10 s it was given and left the rest at 5 tokens). With ``lp_above`` ≥ 1, once the
    LPs' rate says that the places left would not fit in ``seconds``, runs of them are weighed
    together first (:func:`_blocks`).

    Args:
        sn: the net's sparse matrices.
        seconds: wall-clock budget of all the LPs together.
        seen: (|P|,) largest count of each place among markings known to be reachable; a place
            whose bound equals it needs no LP (the bound is exact).
        semiflows: semi-positive integer vectors y with yᵀC = 0 (their bounds are exact certificates).
        lp_above: a place whose bound from the total's LP and the semiflows is at most this keeps
            it without an LP of its own (1: a place the semiflows already bound by one token, whose
            own LP could only say 0; 0: every place not reached).

    Returns:
        :class:`PlaceBounds`.
    """
    start = time.monotonic()
    n = sn.n_places
    lps = _StateEquation(sn) if sn.n_transitions else None
    tb = _bound(sn, np.ones(n), seconds, lps)
    bounds = np.full(n, -1, dtype=np.int64)
    cert = np.zeros(n, dtype=bool)
    if tb.value is not None:
        bounds[:] = tb.value
        cert[:] = tb.certified
        if tb.dual is not None:
            _apply(bounds, cert, tb.dual, sn.m0, True)
    for y in semiflows:
        _apply(bounds, cert, y, sn.m0, True)
    notes: list[str] = []
    if not tb.ok:
        notes.append("the LP of the total token count did not finish in time")
    reached = np.full(n, -1, dtype=np.int64) if seen is None else np.asarray(seen, dtype=np.int64)

    def improvable(ps: np.ndarray) -> np.ndarray:
        """Those of places ``ps`` whose bound an LP of their own could still lower where it matters."""
        out: np.ndarray = (bounds[ps] < 0) | ((reached[ps] < bounds[ps]) & (bounds[ps] > lp_above))
        return out

    todo = np.flatnonzero(improvable(np.arange(n)))
    own = np.zeros(n, dtype=bool)
    done = passed = 0
    blocked = lp_above < 1 or lps is None  # whether the runs of places were weighed (_blocks)
    lp_start = time.monotonic()
    for i, p in enumerate(todo.tolist()):
        if not improvable(todo[i:i + 1])[0]:
            passed += 1  # an earlier LP's certificate bounded it (see above)
            continue
        left = seconds - (time.monotonic() - start)
        if left <= 0:
            break
        w = np.zeros(n)
        w[p] = 1.0
        t0 = time.monotonic()
        b = _bound(sn, w, left, lps)
        per = time.monotonic() - t0
        if b.ok:
            done += 1
            own[p] = True
            if b.value is not None and (bounds[p] < 0 or b.value < bounds[p] or (b.value == bounds[p] and b.certified)):
                bounds[p] = b.value
                cert[p] = b.certified
            if b.dual is not None:
                _apply(bounds, cert, b.dual, sn.m0, True)
        if done == 1 or (done and not blocked and done % _BLOCK == 0):
            rest = int(improvable(todo[i + 1:]).sum())
            now = time.monotonic()
            if not blocked and rest >= 2 * _BLOCK and (now - lp_start) / done * rest > seconds - (now - start):
                # at this rate the places left would not fit: runs of them first, by one LP each
                blocked = True
                assert lps is not None
                _blocks(sn, lps, todo[i + 1:], improvable, bounds, cert, start + seconds)
                rest = int(improvable(todo[i + 1:]).sum())
        if done == 1:
            took = per * rest
            if took > 2 * (seconds - (time.monotonic() - start)):
                # the first place's LP (from the total's basis) says the others do not nearly fit:
                # they are not begun, and keep the bounds they have
                notes.append(f"state-equation LP bounds: {rest:,} of the places whose bound is not reached by an "
                             f"explored marking keep the bound of the total token count's LP and of the semiflows "
                             f"(their own LPs would take about {took:,.0f} s)")
                return PlaceBounds(total=tb.value, bounds=bounds, own=own, certified=cert, complete=False, notes=notes)
    complete = done + passed == todo.size
    if not complete:
        notes.append(f"state-equation LP bounds: {done + passed} of the {todo.size} places whose bound was not yet "
                     f"reached had their own LP or another's certificate within {seconds:g} s; the others keep "
                     "the bound of the total token count's LP")
    return PlaceBounds(total=tb.value, bounds=bounds, own=own, certified=cert, complete=complete, notes=notes)


#: :func:`semiflow_cover` starts each LP from the last one's basis beyond this many places to cover
_WARM_PLACES = 1000
#: below, the LPs from scratch whose time per place covered decides whether the rest may start from one
_SAMPLE_LPS = 8


class _Through:
    """``min Σ y  s.t.  yᵀC = 0, 0 ≤ y ≤ upper, y_p ≥ 1`` for one place p after another, in one HiGHS
    instance (only p's lower bound changes between two solves). A solve starts from scratch, or,
    ``warm``, from the last one's basis (dual simplex): over RwMutex-PT-r0500w0010's 1,520 places
    about 1 ms warm, 3 ms from scratch, 8 ms through :func:`scipy.optimize.linprog`, which builds the
    model each time. From scratch, the optimal vertex is the one linprog finds, whatever place came
    before; warm, it depends on the order of the solves.

    Args:
        c_t: Cᵀ, shape (|T|, |P|), float.
        upper: each y_q's upper bound (1: only semiflows in which p weighs the most, scaled to
            y_p = 1, are feasible, and the 0/1 ones among them: :func:`semiflow_cover`).
    """

    def __init__(self, c_t: sp.spmatrix, upper: float | None = None) -> None:
        import highspy

        cols = sp.csc_matrix(c_t, dtype=np.float64)
        m, n = cols.shape
        self.h = _highs(cols, np.ones(n), np.zeros(n), np.zeros(m), np.zeros(m))
        self.inf = highspy.kHighsInf
        self.upper = self.inf if upper is None else float(upper)
        if upper is not None:
            self.h.changeColsBounds(n, np.arange(n, dtype=np.int32), np.zeros(n), np.full(n, self.upper))
        self.optimal, self.time_limit = highspy.HighsModelStatus.kOptimal, highspy.HighsModelStatus.kTimeLimit

    def solve(self, p: int, seconds: float, warm: bool) -> np.ndarray | bool:
        """The LP's optimal y (|P|,) float for place ``p``; False when it has none (no semiflow
        through p), True when ``seconds`` ran out first."""
        h = self.h
        if not warm:
            h.clearSolver()
        h.changeColBounds(p, 1.0, self.upper)
        _time_limit(h, seconds)
        try:
            h.run()
            status = h.getModelStatus()
            if status == self.optimal:
                return np.asarray(h.getSolution().col_value, dtype=np.float64)
            return bool(status == self.time_limit)
        finally:
            h.changeColBounds(p, 0.0, self.upper)


def semiflow_cover(sn: SparseNet, *, seconds: float = 3.0, covered: np.ndarray | None = None,
                   warm: bool | None = None, spread: int = 0) -> list[np.ndarray]:
    """Small-support P-semiflows covering the places, one LP per place not yet covered.

    For a place p, ``min Σ y  s.t.  yᵀC = 0, y_p ≥ 1, y ≥ 0`` has a vertex solution of small support
    (a sum of minimal semiflows through p at most); rebuilt as an integer vector and checked exactly
    (yᵀC = 0), it is kept. One LP over all the places first tells when there is no semiflow at all.
    Cheaper than the Farkas enumeration (:mod:`.invariants`) when that one explodes, and enough
    where only some semiflows are needed (groups and order of a decision diagram, :mod:`.mdd_order`).
    The LPs of successive places differ in one bound and are solved in one HiGHS instance
    (:class:`_Through`). Each starts from the last one's basis beyond :data:`_WARM_PLACES` places
    to cover: Philosophers-PT-000500's 1,000 semiflows over 2,500 places in 1.5 s,
    RwMutex-PT-r0500w0010's 1,010 over 1,520 places in 1.0 s (7.2 s and 4.6 s from scratch; 11.8 s
    and 8.4 s with an LP built for each place over the whole net). Below, each starts from scratch
    (its vertex then does not depend on the order of the places), unless the time per place covered
    of the first :data:`_SAMPLE_LPS` LPs says that the places left do not fit in ``seconds``. The
    two give different covers on some nets (AirplaneLD-PT-0200: 605 semiflows from one basis to the
    next, 3 from scratch), so the choice is made on the count of places where it can be: made on the
    first LP's time times the places to cover, as it was, ASLink-PT-02a (626 places, 4.7 ms for the
    first LP, about 3.6 ms for each next one; 102 LPs from scratch take 0.5 s) came out on either
    side of its 3 s from one run to the next, with covers of 100 or 102 semiflows, and reachable
    sets of 4.7 s or 13 s.

    A weighted semiflow can have the smaller Σ y and hide a 0/1 one through the same places
    (SimpleLoadBal-PT-10: Σ_k (10 − k)·load_k plus the requests, against the one-hot Σ_k load_k = 1).
    With ``spread``, a second pass bounds every y_q by 1, for the places no 0/1 semiflow found
    covers: a semiflow is then feasible with y_p = 1 only where p weighs the most in it, and the 0/1
    one comes out. It is added when its tokens can lie on its places in at most ``spread`` ways
    (C(|support| + y·M0 − 1, y·M0)) and none of its places is in such a semiflow of the first pass:
    then it becomes a level of a decision diagram (a group of places, :data:`.mdd_order.MAX_LOCAL`)
    and takes no place from another; the others would only move the order (on
    RingSingleMessageInMbox-PT-d0m160 a one-hot semiflow across the ring, taking places from other
    groups, made saturation 2.5 times slower).

    Args:
        sn: the net's sparse matrices.
        seconds: time for all the LPs together.
        covered: (|P|,) places to skip (already covered by known semiflows, or by none).
        warm: True: each LP from the last one's basis; False: each from scratch; None (default):
            decided by the places to cover, and the first LPs' time, as above.
        spread: 0 (default): no second pass; else the most ways its tokens can lie of a 0/1
            semiflow the second pass adds.

    Returns:
        Integer semiflows (|P|,) int64, each checked exactly; those found in ``seconds`` when the
        time runs out first.
    """
    start = time.monotonic()
    n = sn.n_places
    c_t = sp.csr_matrix(sn.incidence.T, dtype=np.float64)
    c_int = sp.csr_matrix(sn.incidence.T).astype(np.int64)
    done = np.zeros(n, dtype=bool) if covered is None else np.asarray(covered, dtype=bool).copy()
    out: list[np.ndarray] = []
    if done.all():
        return out
    if c_t.shape[0]:
        # one LP first, max Σ y over yᵀC = 0, 0 ≤ y ≤ 1: 0 when the net has no semiflow at all,
        # and the LPs place by place would only be infeasible (CloudReconfiguration-PT-303's 2,584
        # places: 3 s of them, against 0.01 s for this one)
        res = _solve(-np.ones(n), None, None, c_t, np.zeros(c_t.shape[0]), [(0.0, 1.0)] * n, seconds)
        if res.status == 0 and -float(res.fun) < 0.5:
            return out
    else:  # no transition: each place is a semiflow of its own
        for p in np.flatnonzero(~done).tolist():
            y = np.zeros(n, dtype=np.int64)
            y[p] = 1
            out.append(y)
        return out
    through = _Through(c_t)
    tried = done.copy()  # places of no semiflow at all (and then of a small one: the second pass)
    before, lps, spent = int(done.sum()), 0, 0.0  # the LPs from scratch that decide ``warm``
    if warm is None and n - before > _WARM_PLACES:
        warm = True
    for p in range(n):
        left = seconds - (time.monotonic() - start)
        if left <= 0:
            return out
        if done[p]:
            continue
        if warm is None and lps == _SAMPLE_LPS:  # their time per place covered, for the places left
            warm = spent / (int(done.sum()) - before) * int((~done).sum()) > left
        t0 = time.monotonic()
        x = through.solve(p, left, bool(warm) and lps > 0)  # the first from scratch: no basis before it
        lps, spent = lps + 1, spent + time.monotonic() - t0
        if x is True:
            return out
        done[p] = True
        if x is False:
            tried[p] = True
            continue
        for cand in _rationalised(np.maximum(x, 0.0)):
            if cand[p] > 0 and (cand >= 0).all() and not _exact_product(c_int, cand).any():
                out.append(cand)
                done |= cand > 0
                break
    # the second pass (docstring): on SimpleLoadBal-PT-10 a level of 11 local markings for each
    # server's load instead of 11 levels, and the reachable set in 13 s, against none in 100 s
    if spread <= 0:
        return out
    known = {cand.tobytes() for cand in out}

    def few(y: np.ndarray, support: np.ndarray) -> bool:
        """Whether the tokens of semiflow y can lie on its places in at most ``spread`` ways."""
        total = int(np.dot(y[support], sn.m0[support]))
        if (y[support] == 1).all():
            return support.size <= spread and total < spread and comb(support.size + total - 1, total) <= spread
        with np.errstate(over="ignore"):  # inf beyond 1e308: far above spread either way
            return float(np.prod((total // y[support] + 1).astype(np.float64))) <= spread

    grouped = np.zeros(n, dtype=bool)  # places of a semiflow found whose tokens lie in few ways
    for cand in out:
        support = np.flatnonzero(cand)
        if few(cand, support):
            grouped[support] = True
    tried |= grouped
    through = _Through(c_t, upper=1.0)
    for p in np.flatnonzero(~tried).tolist():
        left = seconds - (time.monotonic() - start)
        if left <= 0:
            break
        if tried[p]:
            continue
        x = through.solve(p, left, bool(warm))
        if x is True:
            break
        tried[p] = True
        if x is False:
            continue
        for cand in _rationalised(np.maximum(x, 0.0)):
            if cand[p] > 0 and (cand >= 0).all() and (cand <= 1).all() and not _exact_product(c_int, cand).any():
                support = np.flatnonzero(cand)
                if few(cand, support):
                    tried[support] = True
                    if cand.tobytes() not in known and not grouped[support].any():
                        known.add(cand.tobytes())
                        out.append(cand)
                break
    return out
