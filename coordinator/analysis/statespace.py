"""Explicit state space (reachability graph) of a Petri net: a compiled breadth-first search.

Pure: no I/O. :func:`explore` runs the search of :mod:`.reach_kernel` (compiled by numba): the state
array is the queue, so states are numbered breadth-first and edges come out sorted by source, then
transition; transitions are tested through sparse arc lists, only when their first input place is
marked; markings are found again through a hash table of 64-bit keys that pack the marking exactly
while the places' bit widths fit (random linear keys, confirmed against the stored marking, once
they do not). The result is the reachability graph of the ordinary net: states in breadth-first
discovery order (row 0 is M0, so state indices sort by distance from M0) and one edge per
(marking, enabled transition) pair, sorted by source state then transition — the "edges" count of
the Model Checking Contest. Why this technique and what it costs is in docs/analysis.md, section 2.

:func:`enabled_mask` is the vectorised enabling test for many markings at once (numpy), used by the
structural analyses.
"""

from __future__ import annotations

import functools
import os
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from coordinator.analysis.budget import default_max_bytes
from coordinator.analysis.matrices import DENSE_LIMIT, dense_is_cheap, sparse_net
from coordinator.errors import AnalysisError
from coordinator.net import Arc, Marking, PetriNet, Place, Transition

__all__ = ["StateSpace", "arc_table", "default_max_bytes", "enabled_mask", "explore", "implicit_pass_bytes",
           "load_search", "packed_layout", "search_is_compiled", "set_compile_notice"]

#: largest n·|P|·|T| for which enabling is computed by matrix products (see _enabled)
_MAX_PRODUCT = 500_000
#: markings expanded between two progress reports (and checks of a stop event), by default
PROGRESS_STATES = 1 << 16


@dataclass(frozen=True, eq=False)
class StateSpace:
    """The reachability graph of a net (possibly truncated at ``max_states`` or by the byte budget).

    Markings are held packed, as the search stored them (``words``, ``layout``); ``states`` unpacks
    them on first use and keeps the copy.

    Attributes:
        net: the explored net.
        words: packed markings, shape (N, W), uint64: place p's count is the field of
            ``layout[2|P| + p]`` bits at shift ``layout[|P| + p]`` of word ``layout[p]``
            (:func:`packed_layout`); row 0 is the initial marking, rows in breadth-first order.
        layout: (3·|P|,) int64 per place its word, shift and width in bits.
        out_ptr: CSR row pointer over edges, shape (N+1,), int64: the edges of state i are
            ``out_ptr[i]:out_ptr[i+1]`` (given whether the edges were kept or only counted).
        dst: edge targets, shape (E,), int32 (state indices stay below 2**31); empty if the edges
            were not kept.
        transition: transition index (column of the net's matrices) of each edge, shape (E,), int32;
            empty if the edges were not kept.
        complete: False if the search stopped early; then the markings whose successors were not
            all computed are those with ``expanded == False`` and edges are missing.
        parent: for each state, the state one level closer to M0 it was first reached from (a
            breadth-first tree: following it back gives a shortest firing sequence); -1 for M0.
            Shape (N,), int32.
        expanded: which states had all their successors computed, shape (N,), bool.
        stopped_by: why an incomplete search stopped: ``"max_states"`` (the state limit; the level
            in progress was finished), ``"max_memory"`` (the byte budget; stopped at once) or
            ``"stopped"`` (the caller's stop event); None when complete.
        packed_bits: bits of one marking in the search's packed store (the sum of the places'
            field widths, :func:`packed_layout`).
        store_bytes: bytes of the search's marking store and hash table when it ended (capacity,
            not just the markings found).
        max_count: the largest token count of any marking found (sizes ``states``' dtype).
        edges_kept: False if the search only counted the edges (``explore(..., edges=False)``,
            or edges dropped on the way: ``edges_shed_at``): then ``dst``, ``transition``,
            ``src``, ``parent_edge`` and the matrices are not available, while counts, deadlocks,
            markings and firing sequences are.
        priority: the priority levels the search applied, (|T|,) int64, or None.
        edges_shed_at: the number of markings found when the search dropped the edges it kept, to
            go on within its budget counting them only (``explore(..., shed_edges=True)``); None
            if it did not.
        fired: (|T|,) bool, the transitions that label an edge found (kept or only counted): in a
            complete graph, the quasi-live ones (Murata's L1); None if the caller did not say.
        interpreted: True if the search ran in the interpreter (the same code, not compiled: a
            small net while the compiled search is not in numba's cache yet, :func:`explore`).

    ``src`` (edge sources, (E,) int32, non-decreasing) is derived from ``out_ptr`` on first use.
    """

    net: PetriNet
    words: np.ndarray
    layout: np.ndarray
    out_ptr: np.ndarray
    dst: np.ndarray
    transition: np.ndarray
    complete: bool
    parent: np.ndarray
    expanded: np.ndarray
    stopped_by: str | None
    packed_bits: int
    store_bytes: int
    max_count: int
    edges_kept: bool = True
    priority: np.ndarray | None = None
    edges_shed_at: int | None = None
    fired: np.ndarray | None = None
    interpreted: bool = False

    @property
    def states(self) -> np.ndarray:
        """Markings, shape (N, |P|), dtype uint8/uint16/uint32/int64 (the smallest that fits),
        columns in ``net.places`` order, rows as ``words``; unpacked on first use, then kept."""
        cached = self.__dict__.get("_states")
        if cached is None:
            cached = np.empty((self.n_states, len(self.net.places)), _storage_dtype(self.max_count))
            if self.n_states:
                _ready().unpack(self.words, self.layout, cached)
            object.__setattr__(self, "_states", cached)
        return cached

    def extremes(self) -> tuple[np.ndarray, np.ndarray, int]:
        """``(largest, smallest, top)``: each place's largest and smallest count over the markings
        found, (|P|,) int64 each (zeros when there are none), and the largest token count of one
        marking; read from the packed markings without unpacking them (``states`` for 7.5 million
        markings of 160 places is 1.2 GB), computed once."""
        found = self.__dict__.get("_extremes")
        if found is None:
            n_p = len(self.net.places)
            hi, lo, top = np.zeros(n_p, np.int64), np.zeros(n_p, np.int64), 0
            if self.n_states:
                top = int(_ready().extremes(self.words, self.layout, hi, lo))
            for a in (hi, lo):
                a.flags.writeable = False
            found = (hi, lo, top)
            object.__setattr__(self, "_extremes", found)
        return found

    def rows(self, lo: int, hi: int) -> np.ndarray:
        """Markings ``lo:hi``, shape (hi - lo, |P|), int64, unpacked from ``words`` (a block at a
        time, without unpacking the whole state space)."""
        block = self.words[lo:hi]
        out = np.empty((block.shape[0], len(self.net.places)), np.int64)
        if block.shape[0]:
            _ready().unpack(np.ascontiguousarray(block), self.layout, out)
        return out

    def seen_counts(self, max_values: int = 50_000_000) -> np.ndarray:
        """The largest count of each place in the markings found, or in every k-th of them (k as
        small as keeps the unpacked counts within ``max_values``; M0, row 0, always in), shape
        (|P|,), int64: a lower bound of each place's bound, for the symbolic engine's guessed
        levels (:func:`.symbolic.analyse_symbolic`)."""
        n_places = len(self.net.places)
        out = np.zeros(n_places, np.int64)
        step = max(1, -(-self.n_states * n_places // max(1, max_values)))
        rows = self.words[::step]
        block = max(1, (1 << 22) // max(1, n_places))  # 32 MiB of int64 counts at a time
        for lo in range(0, rows.shape[0], block):
            part = np.ascontiguousarray(rows[lo:lo + block])
            counts = np.empty((part.shape[0], n_places), np.int64)
            _ready().unpack(part, self.layout, counts)
            np.maximum(out, counts.max(axis=0, initial=0), out=out)
        return out

    @property
    def memory_per_marking_bytes(self) -> float:
        """Bytes per marking of the search's marking store and hash table (``store_bytes / N``)."""
        return self.store_bytes / max(self.n_states, 1)

    def _need_edges(self) -> None:
        if not self.edges_kept:
            raise AnalysisError("this state space was explored without keeping its edges (explore(..., edges=False)); "
                                "only their number per marking is known")

    @property
    def src(self) -> np.ndarray:
        """Edge sources, shape (E,), int32, non-decreasing (built from ``out_ptr`` once, then kept).

        Raises:
            AnalysisError: if the edges were not kept.
        """
        self._need_edges()
        cached = self.__dict__.get("_src")
        if cached is None:
            counts = np.diff(self.out_ptr)
            cached = np.repeat(np.arange(self.n_states, dtype=np.int32), counts)
            object.__setattr__(self, "_src", cached)
        return cached

    @property
    def parent_edge(self) -> np.ndarray:
        """For each state, the index of its breadth-first tree edge (from ``parent``, the first edge
        of the search to it), -1 for M0; shape (N,), int64. Derived on first use, then kept.

        Raises:
            AnalysisError: if the edges were not kept.
        """
        self._need_edges()
        cached = self.__dict__.get("_parent_edge")
        if cached is None:
            cached = np.full(self.n_states, -1, np.int64)
            hit = np.flatnonzero(self.parent[self.dst] == self.src)
            reached, first = np.unique(self.dst[hit], return_index=True)
            cached[reached] = hit[first]
            object.__setattr__(self, "_parent_edge", cached)
        return cached

    @property
    def nbytes(self) -> int:
        """Bytes held by the graph's arrays (``src``, ``parent_edge`` and ``states`` included once built)."""
        arrays = [self.words, self.out_ptr, self.dst, self.transition, self.parent, self.expanded]
        arrays += [self.__dict__[k] for k in ("_src", "_parent_edge", "_states") if k in self.__dict__]
        return int(sum(a.nbytes for a in arrays))

    @property
    def n_states(self) -> int:
        """Number of reachable markings found, N."""
        return int(self.words.shape[0])

    @property
    def n_edges(self) -> int:
        """Number of edges (firings between found markings), E (counted even when not kept)."""
        return int(self.out_ptr[-1]) if self.out_ptr.shape[0] else 0

    def marking(self, index: int) -> Marking:
        """Return state ``index`` as a :class:`~coordinator.net.Marking` (negative: from the end).

        Raises:
            IndexError: if there is no such state.
        """
        i = range(self.n_states)[int(index)]
        return self.net.marking(self.rows(i, i + 1)[0])

    def index_of(self, marking: Mapping[str, int] | np.ndarray) -> int:
        """Return the state index of a marking.

        Args:
            marking: a mapping place id → tokens, or a vector of shape (|P|,).

        Raises:
            KeyError: if the marking is not among the states found.
        """
        vec = np.asarray(marking, dtype=np.int64) if isinstance(marking, np.ndarray) else self.net.vector(marking)
        n_p = len(self.net.places)
        wd, sh, width = self.layout[:n_p], self.layout[n_p:2 * n_p], self.layout[2 * n_p:]
        if vec.shape == (n_p,) and (vec >= 0).all() and (vec < (np.int64(1) << width)).all():
            packed = np.zeros(self.words.shape[1], np.uint64)
            np.bitwise_or.at(packed, wd, vec.astype(np.uint64) << sh.astype(np.uint64))
            keys, order = self._lookup()
            k = _random_key(packed[None, :])[0]
            lo = int(np.searchsorted(keys, k, side="left"))
            hi = int(np.searchsorted(keys, k, side="right"))
            for pos in range(lo, hi):
                idx = int(order[pos])
                if np.array_equal(self.words[idx], packed):
                    return idx
        raise KeyError(f"marking {self.net.marking(np.maximum(vec, 0))!r} is not a reachable state found")

    def _lookup(self) -> tuple[np.ndarray, np.ndarray]:
        cached = self.__dict__.get("_lookup_cache")
        if cached is None:
            keys = _random_key(self.words)
            order = np.argsort(keys, kind="stable")
            cached = (keys[order], order)
            object.__setattr__(self, "_lookup_cache", cached)
        return cached

    def successor_matrix(self) -> sp.csr_matrix:
        """Return the graph as a CSR matrix A of shape (N, N): ``A[i, j]`` = number of edges i → j.

        Raises:
            AnalysisError: if the edges were not kept.
        """
        self._need_edges()
        n = self.n_states
        data = np.ones(self.n_edges, dtype=np.int32)
        mat = sp.csr_matrix((data, self.dst, self.out_ptr), shape=(n, n))
        mat.sum_duplicates()
        return mat

    def predecessor_matrix(self) -> sp.csr_matrix:
        """Return the reversed graph as CSR, shape (N, N): ``B[j, i]`` = number of edges i → j."""
        return self.successor_matrix().T.tocsr()

    def out_edges(self, index: int) -> np.ndarray:
        """Return the indices of the edges leaving state ``index`` (a slice of the sorted ``src``).

        Raises:
            AnalysisError: if the edges were not kept.
        """
        self._need_edges()
        lo, hi = self.out_ptr[index], self.out_ptr[index + 1]
        return np.arange(lo, hi, dtype=np.int64)

    def successors(self, index: int) -> list[tuple[str, int]]:
        """Return ``(transition id, target state)`` for each edge leaving state ``index``."""
        ids = self.net.transitions
        return [(ids[int(self.transition[e])].id, int(self.dst[e])) for e in self.out_edges(index)]

    def predecessors(self, index: int) -> list[tuple[int, str]]:
        """Return ``(source state, transition id)`` for each edge entering state ``index`` (O(E))."""
        ids = self.net.transitions
        self._need_edges()
        edges = np.flatnonzero(self.dst == index)
        return [(int(self.src[e]), ids[int(self.transition[e])].id) for e in edges]

    def deadlocks(self) -> np.ndarray:
        """Return the indices of expanded states with no enabled transition, shape (k,), int64."""
        has_out = np.diff(self.out_ptr) > 0
        return np.flatnonzero(~has_out & self._expanded_mask()).astype(np.int64)

    def _expanded_mask(self) -> np.ndarray:
        if self.expanded.shape[0] == self.n_states:
            return self.expanded
        return np.ones(self.n_states, dtype=bool)

    def _tree_transition(self, source: int, target: int) -> int:
        """The transition of the first edge of the search from ``source`` to ``target``: with the
        edges kept, read from them; else the lowest transition enabled in ``source`` (under the
        search's priorities) whose firing gives ``target``."""
        if self.edges_kept:
            lo, hi = int(self.out_ptr[source]), int(self.out_ptr[source + 1])
            k = int(np.flatnonzero(self.dst[lo:hi] == target)[0])
            return int(self.transition[lo + k])
        m_from, m_to = self.rows(source, source + 1)[0], self.rows(target, target + 1)[0]
        enabled = enabled_mask(self.net, m_from[None, :], self.priority)[0]
        for t in np.flatnonzero(enabled).tolist():
            if np.array_equal(_fire(self.net, m_from, t), m_to):
                return int(t)
        raise AnalysisError(f"no transition leads from state {source} to state {target}")  # pragma: no cover

    def implicit_liveness(self, stats: dict[str, int] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Liveness levels and strongly connected components of the complete graph by a compiled
        pass (:mod:`.reach_kernel`; Tarjan 1972 in the form of Pearce 2016; compiled on its first
        use on a machine, then loaded from numba's cache) that needs no copy of the edges. When
        the edges were kept, each marking's successors are read from them
        (``edge_components``); else (``explore(..., edges=False)``) they are computed again from
        the packed markings by the search's own enabling and firing rules (under its priorities)
        and found through a hash table over ``words`` (``components``).

        Args:
            stats: if given, receives ``deepest_path`` (the longest depth-first path, markings) and
                ``largest_stack`` (the most markings the component stack held): what the pass's
                shared path and stack array held at most.

        Returns:
            ``(levels, labels, terminal)`` as :func:`coordinator.analysis.structure.liveness_levels`:
            levels (|T|,) int64 in {0, 1, 3, 4}; labels (N,) int32 the component of each state;
            terminal (number of components,) bool.

        Raises:
            AnalysisError: if the graph is not complete.

        Memory: :func:`implicit_pass_bytes` beyond the graph.
        """
        if not self.complete:
            raise AnalysisError("liveness needs the complete reachability graph; this one stopped early "
                                f"({self.stopped_by})")
        rk = _ready()
        if self.edges_kept:
            levels, labels, terminal, deepest, tallest = rk.edge_components(
                self.out_ptr, self.dst, self.transition, len(self.net.transitions))
            status = 0
        else:
            tab = arc_table(self.net)
            prio = _NO_PRIORITY if self.priority is None else self.priority
            resets = tab if self.net.has_resets else None
            status, levels, labels, terminal, deepest, tallest = rk.components(
                tab, self.words, self.layout, prio, self.priority is not None, resets)
        if status:
            raise AnalysisError(f"state {status - 1} has a successor that is not among the {self.n_states} states "
                                "found")  # pragma: no cover - a complete graph holds every successor
        if stats is not None:
            stats.update(deepest_path=int(deepest), largest_stack=int(tallest))
        return levels, labels, terminal

    def firing_sequence(self, index: int) -> list[str]:
        """Return a shortest firing sequence (transition ids) from M0 to state ``index``."""
        seq: list[str] = []
        node = int(index)
        for _ in range(self.n_states):
            source = int(self.parent[node])
            if source < 0:
                break
            seq.append(self.net.transitions[self._tree_transition(source, node)].id)
            node = source
        seq.reverse()
        return seq


def implicit_pass_bytes(n_states: int) -> int:
    """Bytes :meth:`StateSpace.implicit_liveness` needs beyond the graph for ``n_states`` markings
    (at most): without the edges, the hash table (8 bytes a slot, a power of two at least 4/3 of
    the markings) and 10 bytes a marking (its index and flag, the shared depth-first path and
    component stack, a flag a component); with them, 18 bytes a marking (the path's edge positions
    instead of the hash table), which is less."""
    slots = 16
    while 3 * slots < 4 * n_states:
        slots *= 2
    return 8 * slots + 10 * n_states


def _fire(net: PetriNet, marking: np.ndarray, t: int) -> np.ndarray:
    """The marking after transition ``t`` fires in ``marking`` (assumed enabled), (|P|,) int64:
    the search's rule (reset places end with ``Post[r, t]``)."""
    if net.has_resets:
        inc, after = _reset_lists(net)
        reset: np.ndarray = marking + inc.getcol(t).toarray().ravel()
        col = after.getcol(t).tocoo()
        reset[col.row] = col.data - 1
        return reset
    out: np.ndarray = marking + sparse_net(net).incidence.getcol(t).toarray().ravel().astype(np.int64)
    return out


# ---------------------------------------------------------------------------------------- helpers
_HASH_SEED = 0x5EED_0F_9E7B


def _multipliers(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 2**63, size=n, dtype=np.uint64) * np.uint64(2) + np.uint64(1)


def _random_key(rows: np.ndarray, block_bytes: int = 1 << 25) -> np.ndarray:
    """Fixed-seed linear hash of rows (N, P) → (N,) uint64 (used for index_of lookups); rows are
    taken in blocks of about ``block_bytes`` of uint64 temporaries, so a wide net never needs an
    (N, P) uint64 copy."""
    n, n_p = rows.shape
    mult = _multipliers(n_p, _HASH_SEED)
    out = np.empty(n, dtype=np.uint64)
    step = max(1, block_bytes // max(8 * n_p, 1))
    with np.errstate(over="ignore"):
        for lo in range(0, n, step):
            out[lo:lo + step] = (rows[lo:lo + step].astype(np.uint64) * mult).sum(axis=1, dtype=np.uint64)
    return out


def _storage_dtype(max_value: int) -> Any:
    """The smallest unsigned dtype that holds counts up to ``max_value`` (int64 beyond uint32)."""
    for dt, top in ((np.uint8, 0xFF), (np.uint16, 0xFFFF), (np.uint32, 0xFFFF_FFFF)):
        if max_value <= top:
            return dt
    return np.int64


class _NetTables:
    """Per-net arc lists (from the sparse matrices) and, for small nets, the dense 0/1 tables of the
    vectorised enabling test (:func:`enabled_mask`)."""

    def __init__(self, net: PetriNet, priority: np.ndarray | None) -> None:
        self.net = net
        sn = sparse_net(net)
        self.n_p, self.n_t = sn.n_places, sn.n_transitions
        self.pre = sn.pre
        self.inh = sn.inhibitor
        self.priority = None if priority is None else np.asarray(priority, dtype=np.int64)
        if self.priority is not None and self.priority.shape != (self.n_t,):
            raise AnalysisError(f"priority has shape {self.priority.shape}; expected ({self.n_t},)")

    @cached_property
    def n_arcs(self) -> int:
        return int(self.pre.nnz + self.inh.nnz)

    @cached_property
    def has_inhibitors(self) -> bool:
        return bool(self.inh.nnz)

    @cached_property
    def threshold_tables(self) -> tuple[list[tuple[int, np.ndarray | None, np.ndarray | None]], np.ndarray]:
        """Per distinct arc weight w: w, then (|P|, |T|) float32 0/1 matrices of the input arcs and
        of the inhibitor arcs of weight w (None if there are none); and the number of input arcs of
        each transition, (|T|,) float32. Only built for small nets (see :func:`_enabled`)."""
        tables = []
        for w in sorted(set(self.pre.data.tolist()) | set(self.inh.data.tolist())):
            pre_w = (self.pre == w).astype(np.float32).toarray() if (self.pre.data == w).any() else None
            inh_w = (self.inh == w).astype(np.float32).toarray() if (self.inh.data == w).any() else None
            tables.append((int(w), pre_w, inh_w))
        return tables, np.diff(self.pre.indptr).astype(np.float32)


def enabled_mask(net: PetriNet, rows: np.ndarray, priority: np.ndarray | None = None) -> np.ndarray:
    """Return which transitions are enabled in each of several markings.

    Args:
        net: the net.
        rows: markings, shape (n, |P|), any integer dtype.
        priority: optional (|T|,) priority levels; only the enabled transitions of the highest
            enabled level are kept in each row (GSPN rule).

    Returns:
        Boolean mask of shape (n, |T|) (callers with many markings of a wide net pass them in blocks).
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
    macs = n * tab.n_p * tab.n_t
    # above ~5e5 multiply-adds per product BLAS goes multi-threaded, which on a shared machine was
    # measured 50-200x slower than single-threaded; the per-arc way is cheap there anyway
    if macs <= _MAX_PRODUCT and tab.n_p * tab.n_t <= DENSE_LIMIT:
        tables, n_inputs = tab.threshold_tables
        counting = len(tables) * (8000 + 2 * n * tab.n_p + macs // 8) + 5000
    else:
        counting = per_arc + 1
    if counting < per_arc:
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
        for mat, inhibit in ((tab.pre, False), (tab.inh, True)):
            ptr, idx, val = mat.indptr, mat.indices, mat.data
            for t in np.flatnonzero(np.diff(ptr)).tolist():
                row = mask[t]
                for k in range(ptr[t], ptr[t + 1]):
                    if inhibit:
                        row &= cols[idx[k]] < val[k]
                    else:
                        row &= cols[idx[k]] >= val[k]
        out = mask.T
    if tab.priority is not None and n:
        level = np.where(out, tab.priority[None, :], np.iinfo(np.int64).min)
        top = level.max(axis=1)
        out = out & (tab.priority[None, :] == top[:, None])
    return np.ascontiguousarray(out)


def _reset_lists(net: PetriNet) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """For the search: the incidence matrix without the entries of reset pairs, and ``1 + Post[r, t]``
    on every reset pair r → t (CSC, (|P|, |T|), int64); see :mod:`.reach_kernel`."""
    sn = sparse_net(net)
    assert sn.reset is not None
    inc = sp.csc_matrix(sn.incidence - sn.incidence.multiply(sn.reset)).astype(np.int64)
    inc.eliminate_zeros()
    inc.sort_indices()
    after = sp.csc_matrix(sn.reset + sn.post.multiply(sn.reset)).astype(np.int64)
    after.sort_indices()
    return inc, after


def arc_table(net: PetriNet) -> np.ndarray:
    """The packed arc lists of :func:`.reach_kernel.tables` built from the sparse matrices (for nets
    whose dense matrices would be large, and nets with transitions that never fire), shape (k,),
    int64.

    A transition that consumes from the largest siphon unmarked at M0 never fires
    (:meth:`.SparseNet.markable`); its input list starts with a place of that siphon, which is its
    trigger in the search (:mod:`.reach_kernel`): no marking marks it, so the search never tests
    the transition. Medical-PT-08, 5,204 of whose 5,431 transitions are such, is searched about 3×
    faster (its first 500,000 markings, 5.4–5.5 s then 1.6–1.9 s). The other lists are in place order."""
    sn = sparse_net(net)
    inc, after = _reset_lists(net) if net.has_resets else (sn.incidence, None)
    pre_p = sn.pre.indices.astype(np.int64)
    pre_w = sn.pre.data.astype(np.int64)
    markable, fires = sn.markable()
    arc_t = np.repeat(np.arange(sn.n_transitions), np.diff(sn.pre.indptr))
    # each dead transition's first unmarkable input place (one exists) swapped to the front of its list
    dead_t, first = np.unique(arc_t[~markable[pre_p]], return_index=True)
    first = np.flatnonzero(~markable[pre_p])[first[~fires[dead_t]]]
    lo = sn.pre.indptr[arc_t[first]].astype(np.int64)
    pre_p[lo], pre_p[first] = pre_p[first], pre_p[lo].copy()
    pre_w[lo], pre_w[first] = pre_w[first], pre_w[lo].copy()
    parts = [sn.pre.indptr.astype(np.int64), pre_p, pre_w]
    for mat in (sn.inhibitor, inc):
        parts += [mat.indptr.astype(np.int64), mat.indices.astype(np.int64), mat.data.astype(np.int64)]
    if after is not None:
        parts += [after.indptr.astype(np.int64), after.indices.astype(np.int64), after.data.astype(np.int64) - 1]
    else:
        parts += [np.zeros(len(net.transitions) + 1, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)]
    head = np.zeros(13, dtype=np.int64)
    offsets = np.cumsum([13] + [p.shape[0] for p in parts])
    head[:] = offsets[:13]
    return np.concatenate([head, *parts])


#: field width, bits, of a place without a proven bound before it needs more (then doubled)
_UNPROVEN_BITS = 8
#: widest field: a count above 2**31 - 1 is an error of the search, not a wider field
_MAX_BITS = 31


def packed_layout(widths: np.ndarray) -> tuple[np.ndarray, int]:
    """The packed form of a marking: each place a field of ``widths[p]`` bits, the fields laid
    first-fit in 64-bit words, in place order, none straddling two words.

    Args:
        widths: (|P|,) int64 field widths, 1..31 bits.

    Returns:
        ``(layout, words)``: layout (3·|P|,) int64 — per place its word, its shift in the word, its
        width — and the number of words of a marking.
    """
    n_p = widths.shape[0]
    layout = np.zeros(3 * n_p, np.int64)
    word = used = 0
    for p, w in enumerate(widths.tolist()):
        if used + w > 64:
            word, used = word + 1, 0
        layout[p], layout[n_p + p], layout[2 * n_p + p] = word, used, w
        used += w
    return layout, word + 1


def _widths(bounds: np.ndarray | None, m0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starting field widths and the widths the proven bounds need (0: no bound).

    A place with a proven bound b starts with the bits of its initial count (at least one) and
    takes bit_length(b) bits at the first overflow (of any such place: all of them together, one
    repacking); a place without starts with 8 bits and doubles when a count outgrows them."""
    n_p = m0.shape[0]
    b = np.full(n_p, -1, np.int64) if bounds is None else np.asarray(bounds, dtype=np.int64)
    if b.shape != (n_p,):
        raise AnalysisError(f"bounds has shape {b.shape}; expected ({n_p},)")
    need = np.array([max(1, int(v).bit_length()) for v in np.asarray(m0).tolist()], np.int64)
    proven = b >= 0
    target = np.zeros(n_p, np.int64)
    target[proven] = [max(1, int(v).bit_length()) for v in b[proven].tolist()]
    target = np.minimum(np.maximum(target, need), _MAX_BITS) * proven
    start = np.where(proven, need, np.maximum(need, _UNPROVEN_BITS))
    return np.minimum(start, _MAX_BITS), target


def explore(net: PetriNet, *, max_states: int = 10_000_000, priority: np.ndarray | None = None,
            progress: Callable[[int, int], None] | None = None, max_bytes: int | None = None,
            bounds: np.ndarray | None = None, edges: bool = True, finish_level: bool = True,
            stop: threading.Event | None = None, shed_edges: bool = False,
            report_every: int = PROGRESS_STATES) -> StateSpace:
    """Build the reachability graph of ``net`` by a compiled breadth-first search.

    The ordinary firing rule of :mod:`coordinator.net` is used (inhibitor arcs honoured, reset arcs
    empty their places; events, weights and rates ignored). Technique and cost: :mod:`.reach_kernel` and docs/analysis.md;
    reachability graphs: Murata 1989, section V-A. The first call in a process loads the compiled
    search (about 0.5 s). While it is not in numba's cache yet (the first use on a machine), the
    same code runs in the interpreter (:func:`.jit.interpreted`) for up to
    :data:`INTERPRETED_SECONDS`: a small net's graph is done by then, with nothing compiled
    (``interpreted`` True); a larger net's search is compiled (12–15 s on 2 cores, once per machine; the
    notice of :func:`set_compile_notice` is called first) and run from the start.

    Markings are stored packed (:func:`packed_layout`): a place with a proven bound b in the bits
    its count needs so far, bit_length(b) once one such place overflows; one without in 8 bits,
    doubled when they do not suffice. Every count written is checked against its field: one that
    does not fit widens the field and repacks the markings found, so a packed marking never wraps
    (a wrong bound costs a wider field, never a wrong graph).

    Args:
        net: the net; its initial marking is the root.
        max_states: stop once this many markings are found: the level being expanded is finished
            (its edges to known markings kept, those to new ones dropped; with ``finish_level``
            False, only the marking being expanded) and ``complete`` is False. At most 2**31 − 1.
        priority: optional (|T|,) integer levels; in each marking only the enabled transitions of the
            highest enabled level fire (the GSPN helper passes 0 for timed transitions and
            1 + priority for immediate ones).
        progress: called as ``progress(states_found, edges_found)`` every ``report_every``
            expanded markings and at the end.
        max_bytes: byte budget of the search's buffers (markings, edges, hash table, and room for
            the unpacked ``states`` a consumer may ask for); when growing a buffer would exceed it, the search stops at once with
            what it has (``stopped_by == "max_memory"``). Default :func:`default_max_bytes`.
        bounds: optional (|P|,) int64 proven upper bounds of the places (-1 where none), e.g. from
            the P-invariants or the state equation (:mod:`.lp`); they size the packed fields only.
        edges: keep the edges (target and transition, 8 bytes each); False counts them only (per
            state, ``out_ptr``), for questions that need the markings, the edge count, the
            deadlocks and their firing sequences but not the graph itself.
        finish_level: False to stop at once at ``max_states`` (the markings of the level not yet
            expanded stay unexpanded), for a caller that asks only whether the graph fits: a level
            may be most of the graph (Eratosthenes-PT-200's 1,000,000th marking is found in 7 s,
            and its level took 54 s more to finish).
        stop: an event another thread sets to stop the search (checked every ``report_every``
            expanded markings; ``stopped_by == "stopped"``): the automatic engine's search beside the
            symbolic engine, when that one answers first.
        shed_edges: with ``edges``, when the kept edges leave the markings no room within
            ``max_bytes``, drop them and go on counting them only (``edges_kept`` False and
            ``edges_shed_at`` the number of markings found then), instead of stopping: a graph
            whose edges do not fit is searched once, not again without them.
        report_every: expanded markings between two calls of ``progress`` (and checks of
            ``stop``), default 65,536; a caller that waits for the search to pass a count smaller
            than that passes the count.

    Returns:
        The :class:`StateSpace`.

    Raises:
        AnalysisError: on a bad ``priority`` or ``bounds`` shape, ``max_states < 1``, or a token
            count above 2**31 - 1 (the largest field holds 31 bits).
    """
    rk = _ready()
    if max_states < 1:
        raise AnalysisError(f"max_states must be >= 1, got {max_states}")
    max_states = min(int(max_states), 2**31 - 1)
    budget = _DEFAULT_BYTES if max_bytes is None else int(max_bytes)
    n_t = len(net.transitions)
    use_prio = priority is not None
    prio = _NO_PRIORITY
    if priority is not None:
        prio = np.array(priority, dtype=np.int64)  # a copy, made read-only: the compiled signature
        prio.flags.writeable = False
        if prio.shape != (n_t,):
            raise AnalysisError(f"priority has shape {prio.shape}; expected ({n_t},)")
    if dense_is_cheap(net) and not net.has_resets and (n_t <= _FEW_TRANSITIONS or sparse_net(net).markable()[1].all()):
        pre, inh, inc, tab, m0 = net.pre, net.inhibitor, net.incidence, _NO_TABLE, net.initial_vector
    else:
        pre = inh = inc = _NO_MATRIX
        tab, m0 = arc_table(net), sparse_net(net).m0
    start, target = _widths(bounds, np.asarray(m0))
    layout = np.concatenate([packed_layout(start)[0], target])
    report_every = max(1, int(report_every)) if progress is not None or stop is not None else 0
    args = (pre, inh, inc, tab, m0, layout, prio, use_prio, max_states, budget, report_every, bool(edges),
            bool(shed_edges), tab if net.has_resets else None, bool(finish_level))
    found = None
    interpreted = rk is not _RK
    if interpreted:
        found = _interpreted(rk, args, progress, stop)
        interpreted = found is not None
    if found is None:
        rk = _kernel()
        if net.has_resets:
            rk.load_resets()  # the search of nets with reset arcs is a second compiled specialisation
        rk.set_progress(progress, stop)
        try:
            found = rk.run(*args)
        finally:
            rk.set_progress(None)
    status, words, dst, tr, parent, expanded, out_ptr, complete, top, layout, store, shed_at, fired = found
    if status == rk.OVERFLOW:
        raise AnalysisError(f"a token count reached {top}, above 2**31 - 1 (the search stores counts in at most "
                            f"31 bits), after {words.shape[0]} markings; petrobot analyze decides boundedness "
                            "by coverability")
    stopped = None if complete else {rk.MEMORY: "max_memory", rk.STOPPED: "stopped"}.get(status, "max_states")
    n_p = len(net.places)
    return StateSpace(net=net, words=words, layout=layout[:3 * n_p].copy(), out_ptr=out_ptr, dst=dst, transition=tr,
                      complete=bool(complete), parent=parent, expanded=expanded, stopped_by=stopped,
                      packed_bits=int(layout[2 * n_p:3 * n_p].sum()), store_bytes=int(store), max_count=int(top),
                      edges_kept=bool(edges) and shed_at < 0, priority=None if priority is None else prio,
                      edges_shed_at=None if shed_at < 0 else int(shed_at), fired=fired, interpreted=interpreted)


def _interpreted(twin: Any, args: tuple[Any, ...], progress: Callable[[int, int], None] | None,
                 stop: threading.Event | None) -> tuple[Any, ...] | None:
    """Run the search of ``args`` (:func:`.reach_kernel.run`'s) in the interpreter, ``twin``; return
    its result, or None if it was still going after :data:`INTERPRETED_SECONDS` (then the caller
    compiles the search and runs it from the start). ``stop`` is honoured as the compiled search
    does; ``progress`` is called once, with the counts of the result, and not while the search
    runs: a search given up would report counts that the compiled one then reports again from
    zero, and a caller that follows the counts sees one search."""
    caller_every = int(args[10])
    every = min(caller_every or _INTERPRETED_REPORT, _INTERPRETED_REPORT)  # the caller's stop, as often
    deadline = time.monotonic() + INTERPRETED_SECONDS
    halt = threading.Event()
    late = False

    def watch(_n_states: int, _n_edges: int) -> None:
        nonlocal late
        if stop is not None and stop.is_set():
            halt.set()
        elif time.monotonic() > deadline:
            late = True
            halt.set()

    twin.set_progress(watch, halt)
    try:
        found = twin.run(*args[:10], every, *args[11:])
    finally:
        twin.set_progress(None)
    if late and found[0] == twin.STOPPED:
        return None
    if progress is not None and caller_every:
        progress(int(found[1].shape[0]), int(found[6][-1]))
    return tuple(found)


def load_search() -> float:
    """Load the compiled search (numba import and its cache, or a first compile) by exploring a
    one-place net; return the seconds it took. Commands call it before they start timing a search,
    so the rate they report is that of the search. Later calls return almost at once."""
    start = time.perf_counter()
    _kernel()
    explore(_ONE_PLACE)
    return time.perf_counter() - start


_DEFAULT_BYTES = default_max_bytes()
#: most transitions of a net searched on its dense matrices even if some never fire (:func:`arc_table`
#: lists those under a place no marking marks): testing them costs the search little, and the sparse
#: matrices that find them would cost a fresh small net more (0.55 ms for the demo's 6 transitions,
#: whose search takes 0.13 ms)
_FEW_TRANSITIONS = 64
_NO_PRIORITY = np.zeros(0, np.int64)  # not read when use_prio is False
_NO_PRIORITY.flags.writeable = False
_NO_TABLE = np.zeros(0, np.int64)  # run builds the arc lists from the dense matrices
_NO_MATRIX = np.zeros((0, 0), np.int64)  # the dense matrices, unused when the arc lists are given
_NO_MATRIX.flags.writeable = False  # same numba type as a net's read-only matrices: one compilation
_RK: Any = None
_TWIN: Any = None
_LOADING = threading.RLock()
_compile_notice: Callable[[], None] | None = None
#: seconds of interpreted search a net gets, while the compiled search is not in numba's cache, before
#: the search is compiled and run from the start (:func:`explore`)
INTERPRETED_SECONDS = 1.0
#: expanded markings between two looks at the clock of the interpreted search
_INTERPRETED_REPORT = 64


def _kernel() -> Any:
    """The compiled search module, imported on first use (numba takes ~0.3 s to import) with numba's
    cache in the user's cache directory (:mod:`.jit`), its search loaded from there or compiled."""
    global _RK
    with _LOADING:
        if _RK is None:
            from coordinator.analysis import jit

            jit.configure()
            from coordinator.analysis import reach_kernel

            if reach_kernel.cached() is False and _compile_notice is not None:
                _compile_notice()
            reach_kernel.load()
            _RK = reach_kernel
    return _RK


def _ready() -> Any:
    """The compiled search module if its search is loaded or in numba's cache (or numba cannot say),
    else the same module run by the interpreter (:func:`.jit.interpreted`), made once."""
    global _TWIN
    with _LOADING:
        if _RK is not None:
            return _RK
        if _TWIN is None:  # numba's cache is asked once; the copy, once made, serves until a compile
            if search_is_compiled() is not False:
                return _kernel()
            from coordinator.analysis import jit, reach_kernel

            _TWIN = jit.interpreted(reach_kernel)
        return _TWIN


def set_compile_notice(notice: Callable[[], None] | None) -> None:
    """Have ``notice()`` called just before the search is compiled (its first use on a machine with a
    net too large for the interpreted search; once per process at most), or no longer (None)."""
    global _compile_notice
    _compile_notice = notice



def search_is_compiled() -> bool | None:
    """Whether the compiled state-space search is in numba's cache for this source and this
    machine (True: it is loaded now), will be compiled on its first use (False), or cannot be told
    (None). Imports :mod:`.reach_kernel` (and numba, its cache in the user's directory: :mod:`.jit`)
    but compiles nothing."""
    try:
        from coordinator.analysis import reach_kernel
    except ImportError:
        return None
    return reach_kernel.cached()

_ONE_PLACE = PetriNet(name="load", places=(Place(id="p"),), transitions=(Transition(id="t"),),
                      arcs=(Arc(source="p", target="t"), Arc(source="t", target="p")),
                      initial_marking=Marking({"p": 1}))
