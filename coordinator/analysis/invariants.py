"""Minimal semi-positive P- and T-invariants (semiflows) of a Petri net, exact integer arithmetic.

Pure: no I/O. A P-invariant is a vector y ≥ 0, y ≠ 0, with yᵀC = 0 (the weighted token count
y·M is the same in every reachable marking); a T-invariant is x ≥ 0, x ≠ 0, with Cx = 0 (firing
every transition t x[t] times returns to the same marking). Both are computed with the Farkas
(Fourier–Motzkin) algorithm of Martinez and Silva (1982), "A simple and fast algorithm to obtain
all invariants of a generalised Petri net", keeping only rows of minimal support at each step
(Colom and Silva 1991), so the result is the set of minimal-support semiflows, each divided by
the gcd of its entries. Arithmetic is on Python integers, so no entry can overflow.

The number of intermediate rows can grow exponentially; ``max_rows`` guards it and the result then
says ``complete=False`` instead of running for hours.

Inhibitor arcs do not change the incidence matrix, so P-invariants stay valid on nets with them;
they only make some T-invariants unrealisable.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import gcd

import numpy as np

from coordinator.net import PetriNet

__all__ = ["Invariants", "p_invariants", "semiflows", "structural_bounds", "t_invariants"]

DEFAULT_MAX_ROWS = 20_000
#: Memory guard: entries of one intermediate Farkas table (8 bytes each).
MAX_TABLE_ENTRIES = 25_000_000


@dataclass(frozen=True)
class Invariants:
    """Minimal semi-positive invariants of one kind.

    Attributes:
        vectors: one row per minimal invariant, shape (k, n), int64 (n = |P| for P-invariants,
            |T| for T-invariants); rows sorted by support then entries.
        ids: the place or transition ids naming the columns, length n.
        complete: False if the ``max_rows`` guard stopped the computation (then ``vectors`` is
            empty: a partial Fourier–Motzkin table is not a set of invariants).
        covered: True if every column is in the support of some invariant (for P-invariants:
            the net is conservative, weights allowed; for T-invariants: consistent).
    """

    vectors: np.ndarray
    ids: tuple[str, ...]
    complete: bool

    @property
    def covered(self) -> bool:
        """Whether the invariants' supports cover every column."""
        if not self.complete or self.vectors.shape[0] == 0:
            return False
        return bool(np.all(self.vectors.sum(axis=0) > 0))

    def as_dicts(self) -> list[dict[str, int]]:
        """Return each invariant as {id: weight} over its support."""
        return [{self.ids[j]: int(v[j]) for j in np.flatnonzero(v)} for v in self.vectors]


def semiflows(matrix: np.ndarray, *, max_rows: int = DEFAULT_MAX_ROWS) -> tuple[np.ndarray, bool]:
    """Return the minimal-support semi-positive integer vectors y with yᵀ·matrix = 0.

    Martinez–Silva Farkas algorithm: start from the table [matrix | I]; for each column j of
    ``matrix`` (the one with the fewest positive × negative pairs first), add every positive
    combination of a row with a positive and a row with a negative entry in j that cancels j,
    drop the rows non-zero in j, divide each row by the gcd of its entries, then drop duplicates and
    rows whose support (in the identity part) strictly contains another row's support. The table is
    a numpy int64 array while every combination provably fits in 62 bits, else Python integers.

    Args:
        matrix: shape (n, m), integer; rows are the candidates' coordinates (places for
            P-invariants with the incidence matrix, transitions with its transpose).
        max_rows: give up when the table would hold more rows than this (after pruning; 4× before),
            or more than :data:`MAX_TABLE_ENTRIES` entries.

    Returns:
        ``(vectors, complete)``: vectors of shape (k, n), int64, each with gcd 1, sorted by support;
        complete is False (and vectors empty) if ``max_rows`` was hit.

    Raises:
        OverflowError: if a final invariant entry does not fit in int64.
    """
    mat = np.asarray(matrix, dtype=np.int64)
    n, m = mat.shape
    table: np.ndarray = np.concatenate([mat, np.eye(n, dtype=np.int64)], axis=1)
    remaining = list(range(m))
    while remaining:
        col = table[:, remaining]
        pos_n = (col > 0).sum(axis=0)
        neg_n = (col < 0).sum(axis=0)
        pick = int(np.argmin(pos_n * neg_n - pos_n - neg_n))
        j = remaining.pop(pick)
        cj = table[:, j]
        pos, neg = np.flatnonzero(cj > 0), np.flatnonzero(cj < 0)
        keep = table[cj == 0]
        rows_next = keep.shape[0] + pos.size * neg.size
        if rows_next > 4 * max_rows or rows_next * table.shape[1] > MAX_TABLE_ENTRIES:
            return np.zeros((0, n), dtype=np.int64), False
        if pos.size and neg.size:
            rows_a, rows_b = table[pos], table[neg]
            ka = cj[pos]          # > 0
            kb = -cj[neg]         # > 0
            if table.dtype != object:
                bound = int(np.abs(rows_a).max()) * int(kb.max()) + int(ka.max()) * int(np.abs(rows_b).max())
                if bound >= 2**62:
                    table = table.astype(object)
                    keep = keep.astype(object)
                    rows_a, rows_b, ka, kb = (x.astype(object) for x in (rows_a, rows_b, ka, kb))
            combos = (kb[None, :, None] * rows_a[:, None, :] + ka[:, None, None] * rows_b[None, :, :])
            combos = combos.reshape(pos.size * neg.size, -1)
            table = np.concatenate([keep, combos], axis=0) if keep.shape[0] else combos
        else:
            table = keep
        table = _prune(_divide_gcd(table), m)
        if table.shape[0] > max_rows:
            return np.zeros((0, n), dtype=np.int64), False
    if table.shape[0] == 0:
        return np.zeros((0, n), dtype=np.int64), True
    ident = table[:, m:]
    if ident.dtype == object and max(int(x) for x in ident.ravel()) > np.iinfo(np.int64).max:
        raise OverflowError("an invariant entry does not fit in 64 bits")
    vectors = ident.astype(np.int64)
    order = sorted(range(vectors.shape[0]),
                   key=lambda i: (tuple(np.flatnonzero(vectors[i]).tolist()), tuple(vectors[i].tolist())))
    return vectors[order], True


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


def _prune(table: np.ndarray, m: int, block: int = 512) -> np.ndarray:
    """Drop duplicate rows and rows whose identity support strictly contains another row's."""
    if table.shape[0] <= 1:
        return table
    if table.dtype == object:
        seen: dict[tuple[int, ...], int] = {}
        for i, r in enumerate(table):
            seen.setdefault(tuple(int(x) for x in r), i)
        table = table[sorted(seen.values())]
    else:
        table = _unique_rows(table)
    supp = table[:, m:] != 0
    size = supp.sum(axis=1)
    order = np.argsort(size, kind="stable")
    table, supp, size = table[order], supp[order], size[order]
    s_f = supp.astype(np.float32)
    out_f = (~supp).astype(np.float32)
    drop = np.zeros(table.shape[0], dtype=bool)
    for lo in range(0, table.shape[0], block):
        hi = min(lo + block, table.shape[0])
        # only rows of smaller support can lie strictly inside; rows are sorted by support size
        top = int(np.searchsorted(size, size[hi - 1], side="left"))
        if top == 0:
            continue
        # missing[i, j] = |supp_i minus supp_j|; 0 means supp_i ⊆ supp_j (exact in float32 below 2**24)
        missing = s_f[:top] @ out_f[lo:hi].T
        drop[lo:hi] = ((missing == 0) & (size[:top, None] < size[None, lo:hi])).any(axis=0)
    return table[~drop]


def _unique_rows(table: np.ndarray) -> np.ndarray:
    """Exact removal of duplicate int64 rows (hash, sort, compare neighbours), order kept."""
    mult = np.random.default_rng(12345).integers(1, 2**63, size=table.shape[1], dtype=np.uint64) | np.uint64(1)
    with np.errstate(over="ignore"):
        h = (table.astype(np.uint64) * mult).sum(axis=1, dtype=np.uint64)
    order = np.argsort(h, kind="stable")
    hs, ts = h[order], table[order]
    same = (hs[1:] == hs[:-1]) & (ts[1:] == ts[:-1]).all(axis=1)
    dup = np.zeros(table.shape[0], dtype=bool)
    dup[order[1:][same]] = True
    return table[~dup]


def p_invariants(net: PetriNet, *, max_rows: int = DEFAULT_MAX_ROWS) -> Invariants:
    """Minimal semi-positive P-invariants (y ≥ 0, yᵀC = 0) of ``net``; see :func:`semiflows`."""
    vecs, ok = semiflows(net.incidence, max_rows=max_rows)
    return Invariants(vectors=vecs, ids=tuple(p.id for p in net.places), complete=ok)


def t_invariants(net: PetriNet, *, max_rows: int = DEFAULT_MAX_ROWS) -> Invariants:
    """Minimal semi-positive T-invariants (x ≥ 0, Cx = 0) of ``net``; see :func:`semiflows`."""
    vecs, ok = semiflows(np.asarray(net.incidence).T, max_rows=max_rows)
    return Invariants(vectors=vecs, ids=tuple(t.id for t in net.transitions), complete=ok)


def structural_bounds(net: PetriNet, pinv: Invariants) -> np.ndarray:
    """Upper bounds on each place's token count implied by the P-invariants.

    For an invariant y with y[p] > 0, every reachable M has y[p]·M(p) ≤ y·M = y·M0, so
    M(p) ≤ ⌊y·M0 / y[p]⌋ (Murata 1989, section VI).

    Returns:
        Shape (|P|,), int64: the smallest such bound per place, -1 where no invariant covers the place.
    """
    m0 = net.initial_vector
    bounds = np.full(len(net.places), -1, dtype=np.int64)
    for y in pinv.vectors:
        total = int(np.dot(y, m0))
        for p in np.flatnonzero(y):
            b = total // int(y[p])
            if bounds[p] < 0 or b < bounds[p]:
                bounds[p] = b
    return bounds
