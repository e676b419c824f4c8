"""Minimal semi-positive P- and T-invariants (semiflows) of a Petri net, exact integer arithmetic.

Pure: no I/O. A P-invariant is a vector y ≥ 0, y ≠ 0, with yᵀC = 0 (the weighted token count
y·M is the same in every reachable marking); a T-invariant is x ≥ 0, x ≠ 0, with Cx = 0 (firing
every transition t x[t] times returns to the same marking). Both are computed with the Farkas
(Fourier–Motzkin) algorithm of Martinez and Silva (1982), "A simple and fast algorithm to obtain
all invariants of a generalised Petri net", keeping only rows of minimal support at each step
(Colom and Silva 1991), so the result is the set of minimal-support semiflows, each divided by
the gcd of its entries. Arithmetic is on Python integers, so no entry can overflow.

The number of intermediate rows can grow exponentially. Budgets of rows, memory and time are
checked before the run starts (an estimate from the matrix's shape and sign pattern) and before
every step, and the result then says ``complete=False`` with the reason instead of running for
hours; questions that only need the union of the supports (conservative, consistent) are answered
by linear programming in :mod:`.lp` without enumerating anything.

Inhibitor arcs do not change the incidence matrix, so P-invariants stay valid on nets with them;
they only make some T-invariants unrealisable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from math import gcd

import numpy as np
import scipy.sparse as sp

from coordinator.analysis.matrices import sparse_net
from coordinator.net import PetriNet

__all__ = ["FarkasEstimate", "Invariants", "farkas_estimate", "p_invariants", "semiflows", "structural_bounds",
           "t_invariants"]

DEFAULT_MAX_ROWS = 20_000
#: default memory budget of one Farkas run (its tables and their temporaries), bytes
DEFAULT_MAX_BYTES = 512 << 20
#: default time budget of one Farkas run, seconds
DEFAULT_SECONDS = 5.0
#: table entries the elimination touches per second, for the up-front estimate (measured ~1e9 on
#: one core of the development machine with numpy; the estimate is taken 5x more pessimistic)
_ENTRIES_PER_SECOND = 2e8
#: bytes held per table entry while a step builds its combinations (table, combinations, products)
_BYTES_PER_ENTRY = 8 * 4
#: support comparisons (row pairs × support width) per second in the minimality test, for the
#: estimate of a step's cost before it is made (float32 products; measured ~5e9 on the development
#: machine, taken 5x more pessimistic)
_PAIRS_PER_SECOND = 1e9


class _OutOfTime(Exception):
    """The time budget ran out inside a Farkas step."""


@dataclass(frozen=True)
class Invariants:
    """Minimal semi-positive invariants of one kind.

    Attributes:
        vectors: one row per minimal invariant, shape (k, n), int64 (n = |P| for P-invariants,
            |T| for T-invariants); rows sorted by support then entries.
        ids: the place or transition ids naming the columns, length n.
        complete: False if a budget stopped (or prevented) the computation (then ``vectors`` is
            empty: a partial Fourier–Motzkin table is not a set of invariants).
        reason: why the computation is incomplete ("" when complete).
    """

    vectors: np.ndarray
    ids: tuple[str, ...]
    complete: bool
    reason: str = ""

    @property
    def covered(self) -> bool:
        """Whether the invariants' supports cover every column (False when incomplete)."""
        if not self.complete or self.vectors.shape[0] == 0:
            return False
        return bool(np.all(self.vectors.sum(axis=0) > 0))

    def as_dicts(self) -> list[dict[str, int]]:
        """Return each invariant as {id: weight} over its support."""
        return [{self.ids[j]: int(v[j]) for j in np.flatnonzero(v)} for v in self.vectors]


@dataclass(frozen=True)
class FarkasEstimate:
    """What a Farkas run on a matrix will cost at least, known before it starts.

    Attributes:
        rows, width: rows of the starting table and its width (columns + rows).
        first_bytes: bytes of the starting table and its first step's combinations.
        seconds: lower estimate of the time to eliminate every column if the table never grew.
        max_rows: the row limit the memory budget allows.
    """

    rows: int
    width: int
    first_bytes: int
    seconds: float
    max_rows: int


def farkas_estimate(matrix: np.ndarray | sp.spmatrix, *, max_bytes: int = DEFAULT_MAX_BYTES) -> FarkasEstimate:
    """Estimate a Farkas run on ``matrix`` (shape (n, m)) from its shape and sign pattern: the
    starting table [matrix | I] is n × (m + n); the first eliminated column adds pos × neg rows;
    every one of the m steps touches the whole table at least once."""
    n, m = matrix.shape
    width = n + m
    mat = sp.csc_matrix(matrix)
    pos = np.asarray((mat > 0).sum(axis=0)).ravel() if m else np.zeros(0)
    neg = np.asarray((mat < 0).sum(axis=0)).ravel() if m else np.zeros(0)
    growth = int((pos * neg - pos - neg).min(initial=0)) if m else 0
    first = (n + max(growth, 0)) * width * _BYTES_PER_ENTRY
    seconds = m * n * width / _ENTRIES_PER_SECOND
    max_rows = max(1, max_bytes // max(width * _BYTES_PER_ENTRY, 1))
    return FarkasEstimate(rows=n, width=width, first_bytes=first, seconds=seconds, max_rows=max_rows)


def semiflows(matrix: np.ndarray | sp.spmatrix, *, max_rows: int = DEFAULT_MAX_ROWS,
              max_bytes: int = DEFAULT_MAX_BYTES, seconds: float = DEFAULT_SECONDS,
              rows: np.ndarray | None = None) -> tuple[np.ndarray, bool, str]:
    """Return the minimal-support semi-positive integer vectors y with yᵀ·matrix = 0.

    Martinez–Silva Farkas algorithm: start from the table [matrix | I]; for each column j of
    ``matrix`` (the one with the fewest positive × negative pairs first), add every positive
    combination of a row with a positive and a row with a negative entry in j that cancels j,
    drop the rows non-zero in j, divide each new row by the gcd of its entries, then drop duplicates
    and rows whose support (in the identity part) strictly contains another row's support. Only the
    new rows need that test (against each other and against the rows kept from the step before,
    which were minimal among themselves), so a step costs (new rows) × (all rows), not (all rows)².
    The table is a numpy int64 array while every combination provably fits in 62 bits, else Python
    integers.

    Budgets, checked before the run (from :func:`farkas_estimate`) and before every step: the
    memory the table and its combinations would take (``max_bytes``; it also caps the rows), the
    time (``seconds``), and ``max_rows``.

    Args:
        matrix: shape (n, m), integer; rows are the candidates' coordinates (places for
            P-invariants with the incidence matrix, transitions with its transpose).
        max_rows: give up when the table would hold more rows than this (after pruning; 4× before).
        max_bytes: memory budget of the tables, bytes.
        seconds: time budget, wall clock.
        rows: optional boolean (n,) mask of the rows that can be in a semiflow's support (e.g. the
            LP support of :func:`coordinator.analysis.lp.semiflow_support`); the others are left out
            of the table, which does not change the result.

    Returns:
        ``(vectors, complete, reason)``: vectors of shape (k, n), int64, each with gcd 1, sorted by
        support; complete is False (and vectors empty) if a budget stopped or prevented the run,
        and reason says which.

    Raises:
        OverflowError: if a final invariant entry does not fit in int64.
    """
    start = time.monotonic()
    n_all, _ = matrix.shape
    keep_rows = np.arange(n_all) if rows is None else np.flatnonzero(np.asarray(rows, dtype=bool))
    csr = sp.csr_matrix(matrix)[keep_rows]
    used_cols = np.unique(csr.indices)
    sub = csr[:, used_cols]
    n, m = sub.shape
    est = farkas_estimate(sub, max_bytes=max_bytes)
    limit = min(max_rows, est.max_rows)
    if n > limit or est.first_bytes > max_bytes:
        why = (f"not started: the table would need about {est.first_bytes / 2**20:,.0f} MiB "
               f"({n} rows of {est.width} entries; budget {max_bytes / 2**20:,.0f} MiB)")
        return np.zeros((0, n_all), dtype=np.int64), False, why
    if est.seconds > seconds:
        why = (f"not started: {m} eliminations over {n} rows of {est.width} entries take about "
               f"{est.seconds:,.0f} s (time budget {seconds:g} s)")
        return np.zeros((0, n_all), dtype=np.int64), False, why
    mat = sub.toarray().astype(np.int64)
    table: np.ndarray = np.concatenate([mat, np.eye(n, dtype=np.int64)], axis=1)
    remaining = list(range(m))
    while remaining:
        if time.monotonic() - start > seconds:
            return np.zeros((0, n_all), dtype=np.int64), False, f"stopped after {seconds:g} s (time budget)"
        col = table[:, remaining]
        pos_n = (col > 0).sum(axis=0)
        neg_n = (col < 0).sum(axis=0)
        pick = int(np.argmin(pos_n * neg_n - pos_n - neg_n))
        j = remaining.pop(pick)
        cj = table[:, j]
        pos, neg = np.flatnonzero(cj > 0), np.flatnonzero(cj < 0)
        keep = table[cj == 0]
        n_new = pos.size * neg.size
        rows_next = keep.shape[0] + n_new
        if rows_next > 4 * limit or (keep.shape[0] + 2 * n_new) * table.shape[1] * 8 > max_bytes:
            why = (f"stopped: a step would make {rows_next:,} rows (limit {limit:,}, memory budget "
                   f"{max_bytes / 2**20:,.0f} MiB)")
            return np.zeros((0, n_all), dtype=np.int64), False, why
        if not n_new:
            table = keep
            continue
        left = seconds - (time.monotonic() - start)
        merge_cost = n_new * (n_new + keep.shape[0]) * n / _PAIRS_PER_SECOND
        if merge_cost > left:
            why = (f"stopped: a step would compare {n_new:,} new rows with {n_new + keep.shape[0]:,} rows, "
                   f"about {merge_cost:,.0f} s (time budget {seconds:g} s)")
            return np.zeros((0, n_all), dtype=np.int64), False, why
        rows_a, rows_b = table[pos], table[neg]
        ka = cj[pos]          # > 0
        kb = -cj[neg]         # > 0
        if table.dtype != object:
            bound = int(np.abs(rows_a).max()) * int(kb.max()) + int(ka.max()) * int(np.abs(rows_b).max())
            if bound >= 2**62:
                table = table.astype(object)
                keep = keep.astype(object)
                rows_a, rows_b, ka, kb = (x.astype(object) for x in (rows_a, rows_b, ka, kb))
        combos = np.empty((n_new, table.shape[1]), dtype=table.dtype)
        for a in range(pos.size):  # one block of |neg| rows per positive row: no 3-D temporaries
            block = combos[a * neg.size:(a + 1) * neg.size]
            np.multiply(rows_b, ka[a], out=block)
            block += kb[:, None] * rows_a[a][None, :]
        combos = _divide_gcd(combos)
        try:
            table = _merge(keep, combos, m, deadline=start + seconds)
        except _OutOfTime:
            return np.zeros((0, n_all), dtype=np.int64), False, f"stopped after {seconds:g} s (time budget)"
        if table.shape[0] > limit:
            return (np.zeros((0, n_all), dtype=np.int64), False,
                    f"stopped: the table outgrew {limit:,} rows")
    if table.shape[0] == 0:
        return np.zeros((0, n_all), dtype=np.int64), True, ""
    ident = table[:, m:]
    if ident.dtype == object and max(int(x) for x in ident.ravel()) > np.iinfo(np.int64).max:
        raise OverflowError("an invariant entry does not fit in 64 bits")
    vectors = np.zeros((ident.shape[0], n_all), dtype=np.int64)
    vectors[:, keep_rows] = ident.astype(np.int64)
    order = sorted(range(vectors.shape[0]),
                   key=lambda i: (tuple(np.flatnonzero(vectors[i]).tolist()), tuple(vectors[i].tolist())))
    return vectors[order], True, ""


def _merge(old: np.ndarray, new: np.ndarray, m: int, block: int = 512, deadline: float = float("inf")) -> np.ndarray:
    """Rows of ``old`` (minimal among themselves) and ``new`` after removing duplicates and every row
    whose identity support strictly contains another row's.

    Raises:
        _OutOfTime: past ``deadline`` (time.monotonic()).
    """
    new = _unique_rows(new)
    if old.shape[0] and new.shape[0]:
        new = new[~_rows_in(new, old)]
    if new.shape[0] == 0:
        return old
    s_new = (new[:, m:] != 0)
    size_new = s_new.sum(axis=1)
    # new rows inside new rows
    drop_new = _strictly_contains(s_new, size_new, s_new, size_new, block, deadline)
    if old.shape[0]:
        s_old = (old[:, m:] != 0)
        size_old = s_old.sum(axis=1)
        drop_new |= _strictly_contains(s_new, size_new, s_old, size_old, block, deadline)
        keep_new = ~drop_new
        drop_old = _strictly_contains(s_old, size_old, s_new[keep_new], size_new[keep_new], block, deadline)
        merged: np.ndarray = np.concatenate([old[~drop_old], new[keep_new]], axis=0)
        return merged
    kept: np.ndarray = new[~drop_new]
    return kept


def _strictly_contains(s_a: np.ndarray, size_a: np.ndarray, s_b: np.ndarray, size_b: np.ndarray,
                       block: int, deadline: float = float("inf")) -> np.ndarray:
    """For each row i of ``s_a`` (bool supports), whether some row of ``s_b`` has a support strictly
    inside it. Shapes (ka, n), (ka,), (kb, n), (kb,); returns (ka,) bool."""
    out = np.zeros(s_a.shape[0], dtype=bool)
    if s_b.shape[0] == 0 or s_a.shape[0] == 0:
        return out
    b_f = s_b.astype(np.float32)
    for lo in range(0, s_a.shape[0], block):
        if time.monotonic() > deadline:
            raise _OutOfTime
        hi = min(lo + block, s_a.shape[0])
        outside = (~s_a[lo:hi]).astype(np.float32)
        # missing[k, i] = |supp_b_k minus supp_a_i|; 0 means supp_b_k ⊆ supp_a_i (exact below 2**24)
        missing = b_f @ outside.T
        out[lo:hi] = ((missing == 0) & (size_b[:, None] < size_a[None, lo:hi])).any(axis=0)
    return out


def _row_hash(table: np.ndarray) -> np.ndarray:
    mult = np.random.default_rng(12345).integers(1, 2**63, size=table.shape[1], dtype=np.uint64) | np.uint64(1)
    if table.dtype == object:
        hashed = np.array([hash(tuple(int(x) for x in r)) for r in table], dtype=np.int64)
        viewed: np.ndarray = hashed.view(np.uint64)
        return viewed
    with np.errstate(over="ignore"):
        out: np.ndarray = (table.astype(np.uint64) * mult).sum(axis=1, dtype=np.uint64)
    return out


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """For each row of ``rows``, whether it equals a row of ``table`` (hash, then exact check)."""
    h_t = _row_hash(table)
    h_r = _row_hash(rows)
    cand = np.flatnonzero(np.isin(h_r, h_t))
    out = np.zeros(rows.shape[0], dtype=bool)
    for i in cand.tolist():
        same = np.flatnonzero(h_t == h_r[i])
        out[i] = any(np.array_equal(rows[i], table[k]) for k in same.tolist())
    return out


def _divide_gcd(table: np.ndarray) -> np.ndarray:
    if table.shape[0] == 0:
        return table
    if table.dtype == object:
        rows = []
        for r in table:
            g = 0
            for x in r:
                g = gcd(g, int(x))
            rows.append([int(x) // g for x in r] if g > 1 else [int(x) for x in r])
        return np.array(rows, dtype=object).reshape(table.shape)
    g = np.gcd.reduce(table, axis=1)
    g[g == 0] = 1
    out: np.ndarray = table // g[:, None]
    return out


def _unique_rows(table: np.ndarray) -> np.ndarray:
    """Exact removal of duplicate rows (hash, sort, compare neighbours), order kept."""
    if table.shape[0] <= 1:
        return table
    if table.dtype == object:
        seen: dict[tuple[int, ...], int] = {}
        for i, r in enumerate(table):
            seen.setdefault(tuple(int(x) for x in r), i)
        return table[sorted(seen.values())]
    h = _row_hash(table)
    order = np.argsort(h, kind="stable")
    hs, ts = h[order], table[order]
    same = (hs[1:] == hs[:-1]) & (ts[1:] == ts[:-1]).all(axis=1)
    dup = np.zeros(table.shape[0], dtype=bool)
    dup[order[1:][same]] = True
    return table[~dup]


def p_invariants(net: PetriNet, *, max_rows: int = DEFAULT_MAX_ROWS, max_bytes: int = DEFAULT_MAX_BYTES,
                 seconds: float = DEFAULT_SECONDS, support: np.ndarray | None = None) -> Invariants:
    """Minimal semi-positive P-invariants (y ≥ 0, yᵀC = 0) of ``net``; see :func:`semiflows`
    (``support``: optional (|P|,) bool mask of the places some P-semiflow covers)."""
    vecs, ok, why = semiflows(sparse_net(net).incidence, max_rows=max_rows, max_bytes=max_bytes, seconds=seconds,
                              rows=support)
    return Invariants(vectors=vecs, ids=tuple(p.id for p in net.places), complete=ok, reason=why)


def t_invariants(net: PetriNet, *, max_rows: int = DEFAULT_MAX_ROWS, max_bytes: int = DEFAULT_MAX_BYTES,
                 seconds: float = DEFAULT_SECONDS, support: np.ndarray | None = None) -> Invariants:
    """Minimal semi-positive T-invariants (x ≥ 0, Cx = 0) of ``net``; see :func:`semiflows`
    (``support``: optional (|T|,) bool mask of the transitions some T-semiflow covers)."""
    vecs, ok, why = semiflows(sparse_net(net).incidence.T, max_rows=max_rows, max_bytes=max_bytes,
                              seconds=seconds, rows=support)
    return Invariants(vectors=vecs, ids=tuple(t.id for t in net.transitions), complete=ok, reason=why)


def structural_bounds(net: PetriNet, pinv: Invariants) -> np.ndarray:
    """Upper bounds on each place's token count implied by the P-invariants.

    For an invariant y with y[p] > 0, every reachable M has y[p]·M(p) ≤ y·M = y·M0, so
    M(p) ≤ ⌊y·M0 / y[p]⌋ (Murata 1989, section VI).

    Returns:
        Shape (|P|,), int64: the smallest such bound per place, -1 where no invariant covers the place.
    """
    m0 = sparse_net(net).m0
    bounds = np.full(len(net.places), -1, dtype=np.int64)
    for y in pinv.vectors:
        total = int(np.dot(y, m0))
        for p in np.flatnonzero(y):
            b = total // int(y[p])
            if bounds[p] < 0 or b < bounds[p]:
                bounds[p] = b
    return bounds
