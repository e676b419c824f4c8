"""Explicit state space (reachability graph) of a Petri net: a breadth-first search that starts one
marking at a time and hands over to a vectorised frontier search once levels grow.

Pure: no I/O. The search is breadth-first by levels (a level is the set of markings at one distance
from M0), in two stages that produce the same numbering and edge order:

0. Small levels: a plain loop over markings held as tuples, with a ``dict`` of known markings and
   per-transition (place, weight) arc lists; a transition is tested only if its first input place is
   marked. It costs 1–4 µs per firing and nothing per level, so it wins while levels are small.
   Before the first level predicted to have more than ``_SMALL_EDGES`` edges, the states, edges and
   parent edges found so far are handed to the vectorised search, which continues.
1. Enabling: one vectorised comparison per input arc and per inhibitor arc over the whole block
   (or, for small blocks, per distinct arc weight one matrix product that counts the satisfied arcs
   of every transition) gives a (rows, |T|) mask; with a ``priority`` vector only the enabled
   transitions of the highest enabled level survive (GSPN rule, Ajmone Marsan et al. 1995).
2. Keys: every marking has a 64-bit key that is *linear* in the marking,
   ``key(M) = sum_p M(p) * R[p] (mod 2**64)``, so the successor's key is
   ``key(M) + key(C[:, t])``: one addition per edge, no successor vector is built.
   While the bit widths of the largest counts seen so far fit in 64 bits, ``R`` is a mixed-radix
   packing (``R[p] = 2**offset[p]``) and the key is exact (injective); widths grow on demand (the
   exact largest successor count is checked before keys are trusted, and all keys are repacked).
   When they no longer fit, ``R`` becomes random odd multipliers (a universal linear hash) and every
   edge is verified against the stored successor vector; a collision (never seen in practice,
   probability about N**2 / 2**65) restarts the search with other multipliers.
3. Lookup: the keys of known markings are kept sorted with their state indices; the block's keys
   are deduplicated with one sort (``np.unique``) and looked up with ``np.searchsorted``; new keys are
   merged in with one ``np.insert``.

The result is the reachability graph of the ordinary net: states in breadth-first discovery order
(row 0 is M0, so state indices sort by distance from M0) and one edge per (marking, enabled
transition) pair, sorted by source state then transition — the "edges" count of the Model Checking
Contest. Why this technique and what it costs is in docs/analysis.md.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from coordinator.errors import AnalysisError
from coordinator.net import Marking, PetriNet

__all__ = ["StateSpace", "enabled_mask", "explore"]

_BLOCK_ROWS = 1 << 16
_MAX_RESTARTS = 3
#: largest n·|P|·|T| for which enabling is computed by matrix products (see _enabled)
_MAX_PRODUCT = 500_000
#: a level whose predicted number of edges (its size times the mean out-degree so far) is at most
#: this is expanded one marking at a time; the first larger level goes to the vectorised search.
#: Chosen by measurement on the MCC models (docs/analysis.md): one numpy level costs ~0.1–0.3 ms
#: fixed, one edge in pure Python ~1–3 µs.
_SMALL_EDGES = 200


@dataclass(frozen=True, eq=False)
class StateSpace:
    """The reachability graph of a net (possibly truncated at ``max_states``).

    Attributes:
        net: the explored net.
        states: markings, shape (N, |P|), dtype uint8/uint16/uint32/int64 (the smallest that fits),
            columns in ``net.places`` order; row 0 is the initial marking; rows are in breadth-first
            order, so a state's index never precedes that of a state closer to M0.
        src: edge sources (state indices), shape (E,), int64, non-decreasing.
        dst: edge targets, shape (E,), int64.
        transition: transition index (column of the net's matrices) of each edge, shape (E,), int32.
        complete: False if the search stopped at ``max_states``; then the markings whose successors
            were not all computed are those with ``expanded == False`` and edges are missing.
        parent_edge: for each state, the index of an edge from a state one level closer to M0
            (a breadth-first tree, so following it back gives a shortest firing sequence);
            -1 for M0. Shape (N,), int64.
        expanded: which states had all their successors computed, shape (N,), bool.
    """

    net: PetriNet
    states: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    transition: np.ndarray
    complete: bool
    parent_edge: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    expanded: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @property
    def n_states(self) -> int:
        """Number of reachable markings found, N."""
        return int(self.states.shape[0])

    @property
    def n_edges(self) -> int:
        """Number of edges (firings between found markings), E."""
        return int(self.src.shape[0])

    def marking(self, index: int) -> Marking:
        """Return state ``index`` as a :class:`~coordinator.net.Marking`."""
        return self.net.marking(self.states[index])

    def index_of(self, marking: Mapping[str, int] | np.ndarray) -> int:
        """Return the state index of a marking.

        Args:
            marking: a mapping place id → tokens, or a vector of shape (|P|,).

        Raises:
            KeyError: if the marking is not among the states found.
        """
        vec = np.asarray(marking, dtype=np.int64) if isinstance(marking, np.ndarray) else self.net.vector(marking)
        keys, order = self._lookup()
        k = _random_key(vec[None, :])[0]
        lo = int(np.searchsorted(keys, k, side="left"))
        hi = int(np.searchsorted(keys, k, side="right"))
        for pos in range(lo, hi):
            idx = int(order[pos])
            if np.array_equal(self.states[idx].astype(np.int64), vec):
                return idx
        raise KeyError(f"marking {self.net.marking(np.maximum(vec, 0))!r} is not a reachable state found")

    def _lookup(self) -> tuple[np.ndarray, np.ndarray]:
        cached = self.__dict__.get("_lookup_cache")
        if cached is None:
            keys = _random_key(self.states)
            order = np.argsort(keys, kind="stable")
            cached = (keys[order], order)
            object.__setattr__(self, "_lookup_cache", cached)
        return cached

    def successor_matrix(self) -> sp.csr_matrix:
        """Return the graph as a CSR matrix A of shape (N, N): ``A[i, j]`` = number of edges i → j."""
        n = self.n_states
        data = np.ones(self.n_edges, dtype=np.int32)
        mat = sp.csr_matrix((data, (self.src, self.dst)), shape=(n, n))
        mat.sum_duplicates()
        return mat

    def predecessor_matrix(self) -> sp.csr_matrix:
        """Return the reversed graph as CSR, shape (N, N): ``B[j, i]`` = number of edges i → j."""
        return self.successor_matrix().T.tocsr()

    def out_edges(self, index: int) -> np.ndarray:
        """Return the indices of the edges leaving state ``index`` (a slice of the sorted ``src``)."""
        lo, hi = self.out_ptr[index], self.out_ptr[index + 1]
        return np.arange(lo, hi, dtype=np.int64)

    @property
    def out_ptr(self) -> np.ndarray:
        """CSR row pointer over edges: edges of state i are ``out_ptr[i]:out_ptr[i+1]``, shape (N+1,)."""
        cached = self.__dict__.get("_out_ptr")
        if cached is None:
            cached = np.searchsorted(self.src, np.arange(self.n_states + 1), side="left").astype(np.int64)
            object.__setattr__(self, "_out_ptr", cached)
        return cached

    def successors(self, index: int) -> list[tuple[str, int]]:
        """Return ``(transition id, target state)`` for each edge leaving state ``index``."""
        ids = self.net.transitions
        return [(ids[int(self.transition[e])].id, int(self.dst[e])) for e in self.out_edges(index)]

    def predecessors(self, index: int) -> list[tuple[int, str]]:
        """Return ``(source state, transition id)`` for each edge entering state ``index`` (O(E))."""
        ids = self.net.transitions
        edges = np.flatnonzero(self.dst == index)
        return [(int(self.src[e]), ids[int(self.transition[e])].id) for e in edges]

    def deadlocks(self) -> np.ndarray:
        """Return the indices of expanded states with no enabled transition, shape (k,), int64."""
        has_out = np.zeros(self.n_states, dtype=bool)
        has_out[self.src] = True
        return np.flatnonzero(~has_out & self._expanded_mask()).astype(np.int64)

    def _expanded_mask(self) -> np.ndarray:
        if self.expanded.shape[0] == self.n_states:
            return self.expanded
        return np.ones(self.n_states, dtype=bool)

    def firing_sequence(self, index: int) -> list[str]:
        """Return a shortest firing sequence (transition ids) from M0 to state ``index``.

        Raises:
            AnalysisError: if the state space carries no breadth-first tree.
        """
        if self.parent_edge.shape[0] != self.n_states:
            raise AnalysisError("this state space has no breadth-first tree (parent_edge)")
        seq: list[str] = []
        node = int(index)
        for _ in range(self.n_states):
            e = int(self.parent_edge[node])
            if e < 0:
                break
            seq.append(self.net.transitions[int(self.transition[e])].id)
            node = int(self.src[e])
        seq.reverse()
        return seq


# ---------------------------------------------------------------------------------------- helpers
_HASH_SEED = 0x5EED_0F_9E7B


def _multipliers(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 2**63, size=n, dtype=np.uint64) * np.uint64(2) + np.uint64(1)


def _random_key(rows: np.ndarray) -> np.ndarray:
    """Fixed-seed linear hash of rows (N, P) → (N,) uint64 (used for index_of lookups)."""
    mult = _multipliers(rows.shape[1], _HASH_SEED)
    with np.errstate(over="ignore"):
        out: np.ndarray = (rows.astype(np.int64).astype(np.uint64) * mult).sum(axis=1, dtype=np.uint64)
    return out


def _keys(rows: np.ndarray, mult: np.ndarray) -> np.ndarray:
    """Linear keys of rows (n, P) → (n,) uint64, arithmetic modulo 2**64."""
    with np.errstate(over="ignore"):
        out: np.ndarray = rows.astype(np.uint64) @ mult
    return out


def _delta_keys(incidence: np.ndarray, mult: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        out: np.ndarray = (incidence.astype(np.int64).astype(np.uint64) * mult[:, None]).sum(axis=0, dtype=np.uint64)
    return out


def _storage_dtype(max_value: int) -> Any:
    for dt in (np.uint8, np.uint16, np.uint32):
        if max_value <= np.iinfo(dt).max:
            return dt
    return np.int64


def _dedupe(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """np.unique(keys, return_index=True, return_inverse=True) for uint64, without a stable argsort."""
    sk = np.sort(keys)
    head = np.empty(sk.shape[0], dtype=bool)
    head[:1] = True
    np.not_equal(sk[1:], sk[:-1], out=head[1:])
    uniq = sk[head]
    inverse = np.searchsorted(uniq, keys)
    first = np.empty(uniq.shape[0], dtype=np.int64)
    # with repeated indices the last assignment wins: write in reverse so the first occurrence stays
    first[inverse[::-1]] = np.arange(keys.shape[0] - 1, -1, -1, dtype=np.int64)
    return uniq, first, inverse


def _arcs_by_transition(matrix: np.ndarray) -> list[tuple[tuple[int, int], ...]]:
    """Non-zero entries of a (|P|, |T|) matrix as ``(place, value)`` pairs per transition."""
    ts, ps = np.nonzero(matrix.T)
    vals = matrix.T[ts, ps].tolist()
    out: list[list[tuple[int, int]]] = [[] for _ in range(matrix.shape[1])]
    for t, p, v in zip(ts.tolist(), ps.tolist(), vals):
        out[t].append((p, v))
    return [tuple(arcs) for arcs in out]


class _NetTables:
    """Per-net arc lists (plain tuples, built first) and the dense arrays of the vectorised
    enabling test (built on first use, so small searches never pay for them)."""

    def __init__(self, net: PetriNet, priority: np.ndarray | None) -> None:
        self.net = net
        self.n_p, self.n_t = net.pre.shape
        #: per transition: input arcs, inhibitor arcs, non-zero incidence entries, as (place, value)
        self.inputs = _arcs_by_transition(net.pre)
        self.inhib = _arcs_by_transition(net.inhibitor)
        self.deltas = _arcs_by_transition(net.incidence)
        self.priority = None if priority is None else np.asarray(priority, dtype=np.int64)
        if self.priority is not None and self.priority.shape != (self.n_t,):
            raise AnalysisError(f"priority has shape {self.priority.shape}; expected ({self.n_t},)")

    @cached_property
    def n_arcs(self) -> int:
        return sum(len(a) for a in self.inputs) + sum(len(a) for a in self.inhib)

    @cached_property
    def has_inhibitors(self) -> bool:
        return any(self.inhib)

    @cached_property
    def incidence(self) -> np.ndarray:
        return np.asarray(self.net.incidence, dtype=np.int64)

    @cached_property
    def inc_t(self) -> np.ndarray:
        return np.ascontiguousarray(self.incidence.T)

    @cached_property
    def threshold_tables(self) -> tuple[list[tuple[int, np.ndarray | None, np.ndarray | None]], np.ndarray]:
        """Per distinct arc weight w: w, then (|P|, |T|) float32 0/1 matrices of the input arcs and
        of the inhibitor arcs of weight w (None if there are none); and the number of input arcs of
        each transition, (|T|,) float32."""
        pre, inh = self.net.pre, self.net.inhibitor
        tables = []
        for w in sorted(set(np.unique(pre[pre > 0]).tolist()) | set(np.unique(inh[inh > 0]).tolist())):
            tables.append((int(w), (pre == w).astype(np.float32) if (pre == w).any() else None,
                           (inh == w).astype(np.float32) if (inh == w).any() else None))
        return tables, (pre > 0).sum(axis=0).astype(np.float32)

    @cached_property
    def growth_bound(self) -> tuple[np.ndarray, np.ndarray]:
        """The places whose count some transition increases, and the largest increase of each:
        two (k,) int64 arrays."""
        gain = self.incidence.max(axis=1)
        growing = np.flatnonzero(gain > 0)
        return growing, gain[growing]


def enabled_mask(net: PetriNet, rows: np.ndarray, priority: np.ndarray | None = None) -> np.ndarray:
    """Return which transitions are enabled in each of several markings.

    Args:
        net: the net.
        rows: markings, shape (n, |P|), any integer dtype.
        priority: optional (|T|,) priority levels; only the enabled transitions of the highest
            enabled level are kept in each row (GSPN rule).

    Returns:
        Boolean mask of shape (n, |T|).
    """
    return _enabled(_NetTables(net, priority), np.ascontiguousarray(np.asarray(rows).T))


def _enabled(tab: _NetTables, cols: np.ndarray) -> np.ndarray:
    """cols: (|P|, n) marking columns. Returns (n, |T|) bool.

    Two equivalent ways: one comparison per arc over the n columns (cheap per element, one numpy
    call per arc), or, per distinct arc weight w, one matrix product of the indicator ``M >= w``
    (n, |P|) with the 0/1 matrix of the arcs of weight w, which counts the satisfied input arcs and
    the violated inhibitor arcs of every transition (a few calls, n·|P|·|T| multiply-adds in BLAS;
    float32 counts are exact up to 2**24 arcs); the cheaper is chosen from the sizes.
    """
    n = cols.shape[1]
    per_arc = tab.n_arcs * (3000 + n)
    tables, n_inputs = tab.threshold_tables
    macs = n * tab.n_p * tab.n_t
    counting = len(tables) * (8000 + 2 * n * tab.n_p + macs // 8) + 5000
    # above ~5e5 multiply-adds per product BLAS goes multi-threaded, which on a shared machine was
    # measured 50-200x slower than single-threaded; the per-arc way is cheap there anyway
    if counting < per_arc and macs <= _MAX_PRODUCT:
        rows = cols.T
        met = np.zeros((n, tab.n_t), dtype=np.float32)
        blocked = np.zeros((n, tab.n_t), dtype=np.float32) if tab.has_inhibitors else None
        for w, pre_w, inh_w in tables:
            reached = (rows >= w).astype(np.float32)
            if pre_w is not None:
                met += reached @ pre_w
            if inh_w is not None and blocked is not None:
                blocked += reached @ inh_w
        out = met == n_inputs[None, :]
        if blocked is not None:
            out &= blocked == 0
    else:
        mask = np.ones((tab.n_t, n), dtype=bool)
        for t in range(tab.n_t):
            row = mask[t]
            for p, w in tab.inputs[t]:
                row &= cols[p] >= w
            for p, w in tab.inhib[t]:
                row &= cols[p] < w
        out = mask.T
    if tab.priority is not None and n:
        level = np.where(out, tab.priority[None, :], np.iinfo(np.int64).min)
        top = level.max(axis=1)
        out = out & (tab.priority[None, :] == top[:, None])
    return np.ascontiguousarray(out)


@dataclass
class _Prefix:
    """The part of the breadth-first search done so far (internal).

    States ``0 .. expanded - 1`` have been expanded; states ``expanded .. n - 1`` are the next level.
    """

    states: np.ndarray  #: (n, |P|) int64
    src: np.ndarray  #: (e,) int64
    dst: np.ndarray  #: (e,) int64
    tr: np.ndarray  #: (e,) int32
    parent: np.ndarray  #: (n,) int64
    expanded: int
    stopped: bool = False  #: max_states was hit (the search is over)
    truncated_src: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def finished(self) -> bool:
        return self.stopped or self.expanded == self.states.shape[0]


#: (transition, input arcs, inhibitor arcs, incidence entries); arcs are (place, weight) pairs
_Rule = tuple[int, tuple[tuple[int, int], ...], tuple[tuple[int, int], ...], tuple[tuple[int, int], ...]]


def _small_bfs(tab: _NetTables, m0: np.ndarray, max_states: int, edge_limit: int,
               progress: Callable[[int, int], None] | None) -> _Prefix:
    """Breadth-first search one marking at a time over tuples and a dict, while levels are small.

    Stops before the first level predicted to have more than ``edge_limit`` edges (its size times
    the mean out-degree so far; such a level has at most ``edge_limit`` markings, as every marking
    found has an edge to it), when the graph is complete, or at ``max_states``; the vectorised
    search then takes over from the returned prefix. The
    numbering, edge order, parent edges and truncation are those of the vectorised search: states in
    order of first appearance, edges by source then transition, a level processed as one block.
    Only the transitions whose first input place is marked are tested (those without input places
    always are), so the cost per marking follows its marked places rather than |T|.
    """
    by_place: dict[int, list[_Rule]] = {}
    always: list[_Rule] = []
    for t in range(tab.n_t):
        rule = (t, tab.inputs[t], tab.inhib[t], tab.deltas[t])
        if rule[1]:
            by_place.setdefault(rule[1][0][0], []).append(rule)
        else:
            always.append(rule)
    triggers = sorted(by_place.items())
    prio = None if tab.priority is None else tab.priority.tolist()
    first = tuple(m0.tolist())
    states: list[tuple[int, ...]] = [first]
    seen: dict[tuple[int, ...], int] = {first: 0}
    src: list[int] = []
    dst: list[int] = []
    tr: list[int] = []
    parent: list[int] = [-1]
    truncated: set[int] = set()
    lo, hi = 0, 1
    # the next level's edges, predicted from the mean out-degree so far
    while lo < hi and (hi - lo) * len(src) <= edge_limit * max(lo, 1):
        for i in range(lo, hi):
            m = states[i]
            enabled: list[_Rule] = []
            for p, rules in triggers:
                if m[p]:
                    for rule in rules:
                        for q, w in rule[1]:
                            if m[q] < w:
                                break
                        else:
                            for q, w in rule[2]:
                                if m[q] >= w:
                                    break
                            else:
                                enabled.append(rule)
            for rule in always:
                for q, w in rule[2]:
                    if m[q] >= w:
                        break
                else:
                    enabled.append(rule)
            if len(enabled) > 1:
                enabled.sort()
                if prio is not None:
                    top = max(prio[rule[0]] for rule in enabled)
                    enabled = [rule for rule in enabled if prio[rule[0]] == top]
            for t, _, _, delta in enabled:
                succ = list(m)
                for q, d in delta:
                    succ[q] += d
                key = tuple(succ)
                j = seen.get(key)
                if j is None:
                    j = len(states)
                    if j == max_states:
                        truncated.add(i)
                        continue
                    seen[key] = j
                    states.append(key)
                    parent.append(len(src))
                src.append(i)
                dst.append(j)
                tr.append(t)
        if truncated:
            lo = hi
            break
        if progress is not None:
            progress(len(states), len(src))
        lo, hi = hi, len(states)
    return _Prefix(states=np.array(states, dtype=np.int64).reshape(len(states), tab.n_p),
                   src=np.array(src, dtype=np.int64), dst=np.array(dst, dtype=np.int64),
                   tr=np.array(tr, dtype=np.int32), parent=np.array(parent, dtype=np.int64), expanded=lo,
                   stopped=bool(truncated), truncated_src=np.array(sorted(truncated), dtype=np.int64))


class _Explorer:
    """Mutable state of one vectorised search, continuing from a prefix (internal)."""

    def __init__(self, net: PetriNet, tab: _NetTables, max_states: int, seed: int, prefix: _Prefix) -> None:
        self.net, self.tab, self.max_states = net, tab, max_states
        self.seed = seed
        known = prefix.states
        self.n = known.shape[0]
        top = known.max(axis=0) if self.n else np.zeros(tab.n_p, np.int64)
        self.width = np.array([max(1, int(v).bit_length()) for v in top], dtype=np.int64)
        packing = self._packing()
        self.exact = packing is not None
        self.mult: np.ndarray = packing if packing is not None else _multipliers(tab.n_p, seed)
        self.states = np.zeros((max(1024, 2 * self.n), tab.n_p), dtype=_storage_dtype(int(known.max(initial=0))))
        self.states[: self.n] = known
        self._rekey()  # keys of the known markings, sorted, and the per-transition key deltas
        small = np.int32 if self.max_states < 2**31 else np.int64
        self.parent = [prefix.parent]
        self.src: list[np.ndarray] = [prefix.src.astype(small)]
        self.dst: list[np.ndarray] = [prefix.dst.astype(small)]
        self.tr: list[np.ndarray] = [prefix.tr]
        self.n_edges = int(prefix.src.shape[0])
        self.expanded_upto = prefix.expanded
        self.truncated_src = np.zeros(0, dtype=np.int64)

    def _packing(self) -> np.ndarray | None:
        total = int(self.width.sum())
        if total > 64:
            return None
        offsets = np.concatenate(([0], np.cumsum(self.width)[:-1])).astype(np.uint64)
        return np.left_shift(np.uint64(1), offsets)

    # -- storage
    def _store(self, rows: np.ndarray) -> None:
        need = self.n + rows.shape[0]
        top = int(rows.max(initial=0))
        dt = self.states.dtype
        if top > (np.iinfo(dt).max if dt != np.int64 else 2**62):
            dt = _storage_dtype(top)
        if need > self.states.shape[0] or dt != self.states.dtype:
            cap = max(need, self.states.shape[0] * 2 if need > self.states.shape[0] else self.states.shape[0])
            new = np.zeros((cap, self.tab.n_p), dtype=dt)
            new[: self.n] = self.states[: self.n]
            self.states = new
        self.states[self.n : need] = rows
        self.n = need

    def _rekey(self) -> None:
        """Recompute every known key after a change of multipliers."""
        self.dkey = _delta_keys(self.tab.incidence, self.mult)
        keys = _keys(self.states[: self.n], self.mult)
        order = np.argsort(keys, kind="stable")
        self.known_keys = keys[order]
        self.known_idx = order.astype(np.int64)

    def _widen(self, block: np.ndarray, rows_local: np.ndarray, trans: np.ndarray) -> None:
        """Make sure every successor count of this block fits the current packing widths.

        block: (|P|, n) markings; rows_local, trans: (E,) the block's edges (row, transition).
        """
        growing, most = self.tab.growth_bound
        if not self.exact or not rows_local.shape[0] or not growing.shape[0]:
            return
        # quick bound, one vectorised test: the largest count plus the largest increase fits
        doubtful = growing[block.max(axis=1)[growing] + most >= np.left_shift(1, np.minimum(self.width[growing], 62))]
        if not doubtful.shape[0]:
            return
        # exact largest successor count of each doubtful place, in chunks of about 2**20 values
        counts, inc = block[doubtful], self.tab.incidence[doubtful]
        top = np.zeros(doubtful.shape[0], dtype=np.int64)
        step = max(1, (1 << 20) // doubtful.shape[0])
        for a in range(0, rows_local.shape[0], step):
            r, t = rows_local[a : a + step], trans[a : a + step]
            np.maximum(top, (counts[:, r] + inc[:, t]).max(axis=1), out=top)
        grow = False
        for p, value in zip(doubtful.tolist(), top.tolist()):
            need = int(value).bit_length()
            if need > self.width[p]:
                self.width[p] = need
                grow = True
        if not grow:
            return
        mult = self._packing()
        if mult is None:
            self.exact = False
            self.mult = _multipliers(self.tab.n_p, self.seed)
        else:
            self.mult = mult
        self._rekey()

    # -- one block of the frontier
    def expand(self, lo: int, hi: int) -> bool:
        """Expand states lo..hi-1; return False if max_states stopped the search."""
        block = np.ascontiguousarray(self.states[lo:hi].T.astype(np.int64))
        en = _enabled(self.tab, block)
        rows_local, trans = np.nonzero(en)
        self._widen(block, rows_local, trans)
        src = rows_local.astype(np.int64) + lo
        trans = trans.astype(np.int64)
        frontier_keys = _keys(block.T, self.mult)
        with np.errstate(over="ignore"):
            keys = frontier_keys[rows_local] + self.dkey[trans]
        uniq, first, inverse = _dedupe(keys)
        pos = np.searchsorted(self.known_keys, uniq)
        pos_c = np.minimum(pos, self.known_keys.shape[0] - 1)
        found = self.known_keys[pos_c] == uniq
        target = np.empty(uniq.shape[0], dtype=np.int64)
        target[found] = self.known_idx[pos_c[found]]
        new = np.flatnonzero(~found)
        # new markings get indices in order of first appearance (src-major, breadth-first)
        new = new[np.argsort(first[new], kind="stable")]
        room = self.max_states - self.n
        stopped = False
        if new.shape[0] > room:
            stopped = True
            new = new[:room]
            keep_u = found.copy()
            keep_u[new] = True
        else:
            keep_u = None
        fe = first[new]
        new_rows = block.T[rows_local[fe]] + self.tab.inc_t[trans[fe]]
        target[new] = np.arange(self.n, self.n + new.shape[0], dtype=np.int64)
        dst = target[inverse]
        parent_local = fe.astype(np.int64)
        if keep_u is not None:
            # drop the edges to markings beyond max_states; renumber the parent edges
            keep_e = keep_u[inverse]
            self.truncated_src = np.unique(src[~keep_e])
            parent_local = (np.cumsum(keep_e) - 1)[fe]
            src, dst, trans = src[keep_e], dst[keep_e], trans[keep_e]
            rows_local = rows_local[keep_e]
        self.parent.append(parent_local + self.n_edges)
        if not self.exact:
            self._verify(block, rows_local, trans, dst, new_rows, int(self.n))
        self._store(new_rows)
        by_key = np.sort(new)
        ins = np.searchsorted(self.known_keys, uniq[by_key])
        self.known_keys = np.insert(self.known_keys, ins, uniq[by_key])
        self.known_idx = np.insert(self.known_idx, ins, target[by_key])
        small = np.int32 if self.max_states < 2**31 else np.int64
        self.src.append(src.astype(small))
        self.dst.append(dst.astype(small))
        self.tr.append(trans.astype(np.int32))
        self.n_edges += src.shape[0]
        self.expanded_upto = hi
        return not stopped

    def _verify(self, block: np.ndarray, rows_local: np.ndarray, trans: np.ndarray, dst: np.ndarray,
                new_rows: np.ndarray, first_new: int) -> None:
        succ = block.T[rows_local] + self.tab.inc_t[trans]
        old = dst < first_new
        ok = np.array_equal(self.states[dst[old]].astype(np.int64), succ[old])
        if ok and (~old).any():
            ok = np.array_equal(new_rows[dst[~old] - first_new], succ[~old])
        if not ok:
            raise _Collision()


class _Collision(Exception):
    pass


def explore(net: PetriNet, *, max_states: int = 10_000_000, priority: np.ndarray | None = None,
            progress: Callable[[int, int], None] | None = None) -> StateSpace:
    """Build the reachability graph of ``net`` by breadth-first search (small levels one marking at a
    time, then a vectorised frontier).

    The ordinary firing rule of :mod:`coordinator.net` is used (inhibitor arcs honoured; events,
    weights and rates ignored). Technique and cost: module docstring and docs/analysis.md;
    reachability graphs: Murata 1989, section V-A.

    Args:
        net: the net; its initial marking is the root.
        max_states: stop once this many markings are found (``complete`` is then False).
        priority: optional (|T|,) integer levels; in each marking only the enabled transitions of the
            highest enabled level fire (the GSPN helper passes 0 for timed transitions and
            1 + priority for immediate ones).
        progress: called as ``progress(states_found, edges_found)`` after each small level and each
            block of the vectorised frontier.

    Returns:
        The :class:`StateSpace`.

    Raises:
        AnalysisError: on a bad ``priority`` shape or ``max_states < 1``, or if the linear hash
            collides on several seeds in a row (astronomically unlikely).
    """
    if max_states < 1:
        raise AnalysisError(f"max_states must be >= 1, got {max_states}")
    tab = _NetTables(net, priority)
    prefix = _small_bfs(tab, net.vector(net.initial_marking), max_states, _SMALL_EDGES, progress)
    if prefix.finished:
        return _space(net, prefix.states, prefix.src, prefix.dst, prefix.tr, prefix.parent,
                      not prefix.stopped, prefix.expanded, prefix.truncated_src)
    for attempt in range(_MAX_RESTARTS):
        try:
            return _run(net, tab, max_states, progress, _HASH_SEED + 7919 * attempt, prefix)
        except _Collision:
            continue
    raise AnalysisError("the 64-bit marking hash collided on every seed tried; cannot build the state space")


def _run(net: PetriNet, tab: _NetTables, max_states: int, progress: Callable[[int, int], None] | None,
         seed: int, prefix: _Prefix) -> StateSpace:
    ex = _Explorer(net, tab, max_states, seed, prefix)
    level_lo, level_hi = prefix.expanded, ex.n
    complete = True
    while level_lo < level_hi:
        lo = level_lo
        while lo < level_hi:
            hi = min(level_hi, lo + _BLOCK_ROWS)
            if not ex.expand(lo, hi):
                complete = False
                break
            if progress is not None:
                progress(ex.n, ex.n_edges)
            lo = hi
        if not complete:
            break
        level_lo, level_hi = level_hi, ex.n

    def cat(parts: list[np.ndarray], dtype: Any) -> np.ndarray:
        out = np.concatenate(parts).astype(dtype, copy=False)
        parts.clear()
        return out

    src = cat(ex.src, np.int64)
    dst = cat(ex.dst, np.int64)
    tr = cat(ex.tr, np.int32)
    parent = np.concatenate(ex.parent)[: ex.n]
    return _space(net, ex.states[: ex.n], src, dst, tr, parent, complete, ex.expanded_upto, ex.truncated_src)


def _space(net: PetriNet, states: np.ndarray, src: np.ndarray, dst: np.ndarray, tr: np.ndarray,
           parent: np.ndarray, complete: bool, expanded_upto: int, truncated_src: np.ndarray) -> StateSpace:
    """Assemble the result; states in the smallest dtype that holds the largest count."""
    expanded = np.zeros(states.shape[0], dtype=bool)
    expanded[:expanded_upto] = True
    expanded[truncated_src] = False
    if complete:
        expanded[:] = True
    dtype = _storage_dtype(int(states.max(initial=0)))
    return StateSpace(net=net, states=states.astype(dtype, copy=True), src=src, dst=dst, transition=tr,
                      complete=complete, parent_edge=parent, expanded=expanded)
