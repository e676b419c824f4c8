"""Compiled breadth-first search of the reachability graph (internal to :mod:`.statespace`).

Pure: no I/O. The functions here are compiled to machine code by numba (``cache=True``: compiled
once per machine and kept in numba's cache directory, which :mod:`.jit` points at the user's cache
directory) and driven by :func:`coordinator.analysis.statespace.explore`, which documents the
result. What they implement (the reasons and the measurements are in docs/analysis.md, section 2):

* Sparse arc lists per transition (CSR: ``ptr`` of shape (|T|+1,), then place indices and values)
  for the input arcs, the inhibitor arcs, the non-zero entries of the incidence matrix C and the
  reset arcs, packed in one int64 array (:func:`tables`, or built by the caller from sparse
  matrices; always by the caller for a net with reset arcs). A reset arc r → t lists r with the
  count it holds after t fires, ``Post[r, t]``, and r is left out of t's incidence list: the
  successor is ``M + C[:, t]`` off the reset places and ``Post[r, t]`` on them. A net without reset
  arcs has empty reset lists, and its search is a specialisation compiled without their code (an
  argument that is ``None`` for such nets, pruned by numba when it compiles). Each transition
  with input places is listed under its first input place (its *trigger*), so a marking only tests
  the transitions whose trigger place is marked (enabling rule: Murata 1989, section II); the
  caller's lists put first a place that no marking marks, if a transition has one
  (:func:`coordinator.analysis.statespace.arc_table`), so a transition that never fires is never
  tested.
* A queue that is the state array itself: states are numbered in order of discovery and expanded in
  that order, so the search is breadth-first, a level (the markings at one distance from M0) is a
  contiguous index range, and edges come out sorted by source, then transition.
* Markings stored packed: each place a field of a few bits (its width comes from the place's
  proven bound, given by the caller: :func:`coordinator.analysis.statespace.packed_layout`), the
  fields first-fit in 64-bit words, so a marking of a 1-safe net of |P| places takes about |P| / 8
  bytes. A successor is the parent's words with the fields of the changed places rewritten, each
  new count checked against its field: a count that does not fit stops the expansion of its
  parent (status ``WIDEN``, the parent's successors found so far dropped), the field is widened,
  every marking found is repacked, and the parent is expanded again, so a field never wraps. The hash
  table's key is a hash of the packed words; a key hit is confirmed by comparing the words. Keys
  are not stored with the markings: the table is rebuilt from the markings when it grows.
* An open-addressing hash table (linear probing, load at most 3/4) of one uint64 a slot: the high
  32 bits of the marking's hash beside its index + 1, so a probe compares words only when those
  bits agree, a lookup usually touches one cache line, and a marking costs 11–21 bytes of table.
* Edges kept (``keep_edges``: int32 target and transition, sorted by source) or only counted
  per state, for questions that need the markings and the out-degrees alone; with
  ``shed_edges``, kept while they fit the budget and then dropped, the search going on counting
  them (a graph whose edges fill the budget is not searched twice); the breadth-first
  tree is the state each marking was first reached from (int32), whose edge the caller finds
  again when it needs it.
* The edges need not be kept to be used: :func:`components` finds the strongly connected
  components and liveness levels of a complete graph from its packed markings alone, firing each
  marking's enabled transitions again and finding the successors through a hash table rebuilt
  over the markings (the search's own :func:`_enabled_list`, :func:`_fire` and :func:`_find`);
  when the edges were kept, :func:`edge_components` runs the same pass over them, no copy made.
* A byte budget: every buffer is counted, a buffer grows only if the bytes held during the copy
  (its arrays grow one at a time: every other array at its new size, the one being copied old and
  new) stay within ``max_bytes``, and growth near the budget takes only what fits. When nothing
  fits the search stops (status ``MEMORY``) with the states found so far; states not expanded are
  flagged, as with the state limit.

Code shape: flat 1-D buffers, plain loops and few numpy calls, because numba's compile time grows
with the amount of typed code (the first use on a machine compiles this module; docs/analysis.md,
section 2, gives the times). The helpers the search and :func:`components` share are inlined
into them by numba (``inline="always"``) and hand back scalars: as calls returning tuples they made
the search 1.5–2× slower (numba's optimisation level 1, :mod:`.jit`).

One call of :func:`run` does the whole search, buffers and growth included, and hands back the
finished arrays: on small nets the cost of crossing from Python into compiled code, not the search,
is what a caller waits for, so it is paid once. Progress reports go through a hook that :func:`run`
calls back in the interpreter (numba's object mode), which is also where Ctrl-C is noticed and a
stop event set by another thread is read. Between reports :func:`run` holds no GIL, so a search
in one thread and the symbolic engine's saturation in others run at once.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from coordinator.analysis import jit

jit.configure()  # numba's cache in the user's cache directory: before numba is imported

from numba import njit, objmode, types  # noqa: E402

__all__ = ["CURSOR_SIZE", "HEAD", "RESET_SIGNATURE", "RUN_SIGNATURE", "cached", "components", "edge_components", "extremes",
           "load",
           "load_resets", "run", "set_progress", "tables", "unpack"]

#: status codes: graph complete, or the state limit reached and its level finished; ``budget``
#: markings expanded; a buffer is full; a token count would exceed 2**31 - 1, the largest a field
#: holds; the byte budget stopped the search; a count outgrew its place's field; the caller's stop
#: event was set (:func:`set_progress`).
DONE, BUDGET, ROOM, OVERFLOW, MEMORY, WIDEN, STOPPED = 0, 1, 2, 3, 4, 5, 6
#: layout of the cursor array
N, E, NEXT, LEVEL_END, STOPPING, N_TRUNC, MAX_COUNT, NEED, NEED_S = range(9)
CURSOR_SIZE = 9
#: header of the packed arc lists: offsets of in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, d_ptr, d_p,
#: d_v, r_ptr, r_p, r_v and the end
HEAD = 13
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_LOW32 = np.uint64(0xFFFF_FFFF)
_THIRTY_TWO = np.uint64(32)
_INT32_MAX = 2**31 - 1
_SEED = np.uint64(0x5EED0F9E7B)


_hook = threading.local()


def set_progress(callback: Callable[[int, int], None] | None, stop: threading.Event | None = None) -> None:
    """Install (or, with None, remove) the progress callback of this thread's :func:`run` calls, and
    the event that stops them (status :data:`STOPPED`, checked at each report: another thread's
    decision, e.g. the symbolic engine answered first)."""
    _hook.callback = callback
    _hook.stop = stop


def _report(n_states: int, n_edges: int) -> int:
    """Called from :func:`run` in the interpreter: 1 to stop (the stop event is set), else 0."""
    callback = getattr(_hook, "callback", None)
    if callback is not None:
        callback(int(n_states), int(n_edges))
    stop = getattr(_hook, "stop", None)
    return int(stop is not None and stop.is_set())


@njit(cache=True)
def tables(pre: np.ndarray, inhibitor: np.ndarray, incidence: np.ndarray) -> np.ndarray:
    """Packed arc lists of a net without reset arcs from its dense matrices (a net with reset arcs
    has its lists built by the caller, :func:`coordinator.analysis.statespace.arc_table`).

    Args:
        pre, inhibitor, incidence: (|P|, |T|) int64 matrices of the net.

    Returns:
        A flat int64 array: :data:`HEAD` offsets, then the input arcs, the inhibitor arcs, the
        non-zero incidence entries and the (empty) reset arcs as CSR lists by transition (ptr
        (|T|+1,) relative to its list, place indices ascending, values; a reset arc's value is the
        count its place holds after the firing).
    """
    n_p, n_t = pre.shape
    # entries per transition of each matrix (row-major pass: the matrices are C-ordered)
    cnt = np.zeros(3 * (n_t + 1), np.int64)
    for p in range(n_p):
        for t in range(n_t):
            if pre[p, t] != 0:
                cnt[t + 1] += 1
            if inhibitor[p, t] != 0:
                cnt[n_t + 2 + t] += 1
            if incidence[p, t] != 0:
                cnt[2 * n_t + 3 + t] += 1
    for m in range(3):
        for t in range(n_t):
            cnt[m * (n_t + 1) + t + 1] += cnt[m * (n_t + 1) + t]
    c0, c1, c2 = cnt[n_t], cnt[2 * n_t + 1], cnt[3 * n_t + 2]
    out = np.zeros(HEAD + 4 * (n_t + 1) + 2 * (c0 + c1 + c2), np.int64)
    out[0] = HEAD
    out[1] = out[0] + n_t + 1
    out[2] = out[1] + c0
    out[3] = out[2] + c0
    out[4] = out[3] + n_t + 1
    out[5] = out[4] + c1
    out[6] = out[5] + c1
    out[7] = out[6] + n_t + 1
    out[8] = out[7] + c2
    out[9] = out[8] + c2
    out[10] = out[9] + n_t + 1  # reset lists: ptr all zero, no entries
    out[11] = out[10]
    out[12] = out[11]
    for m in range(3):
        for t in range(n_t + 1):
            out[out[3 * m] + t] = cnt[m * (n_t + 1) + t]
    # fill, places ascending within a transition; cnt[m, t] becomes transition t's next free slot
    for p in range(n_p):
        for t in range(n_t):
            w = pre[p, t]
            if w != 0:
                k = cnt[t]
                out[out[1] + k] = p
                out[out[2] + k] = w
                cnt[t] = k + 1
            w = inhibitor[p, t]
            if w != 0:
                k = cnt[n_t + 1 + t]
                out[out[4] + k] = p
                out[out[5] + k] = w
                cnt[n_t + 1 + t] = k + 1
            w = incidence[p, t]
            if w != 0:
                k = cnt[2 * n_t + 2 + t]
                out[out[7] + k] = p
                out[out[8] + k] = w
                cnt[2 * n_t + 2 + t] = k + 1
    return out


@njit(cache=True)
def _bit_length(v: int) -> int:
    bits = 0
    while v >> bits:
        bits += 1
    return bits


@njit(cache=True)
def _slot(key: np.uint64, bits: int) -> np.int64:
    return np.int64((key * _GOLDEN) >> np.uint64(64 - bits))


@njit(cache=True)
def _hash(words: np.ndarray, base: int, n_w: int) -> np.uint64:
    """Hash of the packed marking ``words[base:base + n_w]`` (a multiply-xorshift chain)."""
    h = _SEED
    for k in range(n_w):
        h = (h ^ words[base + k]) * _GOLDEN
        h ^= h >> np.uint64(29)
    return h


@njit(cache=True)
def _table_slots(n: int) -> int:
    """Slots of a hash table for n markings: the smallest power of two (at least 16) at most 3/4
    full."""
    size = 16
    while 3 * size < 4 * n:
        size *= 2
    return size


@njit(cache=True)
def _fill_table(table: np.ndarray, states: np.ndarray, n: int, n_w: int) -> None:
    """(Re)build the hash table, (2**k,) uint64 slots of (tag << 32) | (index + 1), the tag the
    high 32 bits of the marking's hash, from states 0..n-1."""
    size = table.shape[0]
    bits = _bit_length(size) - 1
    for k in range(size):
        table[k] = 0
    for j in range(n):
        key = _hash(states, j * n_w, n_w)
        s = _slot(key, bits)
        while table[s] != 0:
            s = (s + 1) & (size - 1)
        table[s] = ((key >> _THIRTY_TWO) << _THIRTY_TWO) | np.uint64(j + 1)


@njit(cache=True)
def _get(states: np.ndarray, base: int, p: int, wd: np.ndarray, sh: np.ndarray, msk: np.ndarray) -> np.int64:
    return np.int64((states[base + wd[p]] >> sh[p]) & msk[p])


@njit(cache=True)
def _set(words: np.ndarray, base: int, p: int, v: np.int64, wd: np.ndarray, sh: np.ndarray, msk: np.ndarray) -> None:
    k = base + wd[p]
    words[k] = (words[k] & ~(msk[p] << sh[p])) | (np.uint64(v) << sh[p])


@njit(cache=True)
def _arcs(tab: np.ndarray) -> tuple[np.ndarray, ...]:
    """The twelve lists of packed arc lists (:func:`tables`): input arcs (ptr, place, weight),
    inhibitor arcs, incidence entries (ptr, place, value) and reset arcs (ptr, place, count after)."""
    return (tab[tab[0]:tab[1]], tab[tab[1]:tab[2]], tab[tab[2]:tab[3]], tab[tab[3]:tab[4]], tab[tab[4]:tab[5]],
            tab[tab[5]:tab[6]], tab[tab[6]:tab[7]], tab[tab[7]:tab[8]], tab[tab[8]:tab[9]], tab[tab[9]:tab[10]],
            tab[tab[10]:tab[11]], tab[tab[11]:tab[12]])


@njit(cache=True)
def _triggers(tab: np.ndarray, n_p: int) -> tuple[np.ndarray, np.ndarray]:
    """Transitions by trigger place (their first input place; slot |P| lists those without input
    places): ``(trig_ptr, trig_t)``, (|P|+2,) and (|T|,) int64, a CSR list."""
    n_t = tab[1] - tab[0] - 1
    in_ptr, in_p = tab[tab[0]:tab[1]], tab[tab[1]:tab[2]]
    trig_ptr = np.zeros(n_p + 2, np.int64)
    trig_t = np.zeros(n_t, np.int64)
    for t in range(n_t):
        first = in_p[in_ptr[t]] if in_ptr[t + 1] > in_ptr[t] else n_p
        trig_ptr[first + 1] += 1
    for p in range(n_p + 1):
        trig_ptr[p + 1] += trig_ptr[p]
    slot = trig_ptr.copy()
    for t in range(n_t):
        first = in_p[in_ptr[t]] if in_ptr[t + 1] > in_ptr[t] else n_p
        trig_t[slot[first]] = t
        slot[first] += 1
    return trig_ptr, trig_t


@njit(cache=True, inline="always")
def _enabled_list(cur: np.ndarray, trig_ptr: np.ndarray, trig_t: np.ndarray, in_ptr: np.ndarray, in_p: np.ndarray,
                  in_w: np.ndarray, ih_ptr: np.ndarray, ih_p: np.ndarray, ih_w: np.ndarray, prio: np.ndarray,
                  use_prio: bool, enabled: np.ndarray) -> int:
    """The transitions enabled in the unpacked marking ``cur`` (|P|,), ascending, in
    ``enabled[:k]``; returns k. Only transitions whose trigger place is marked are tested, then
    those without input places; with ``use_prio``, only those of the highest enabled level are kept."""
    n_p = cur.shape[0]
    k = 0
    for p in range(n_p + 1):
        if p < n_p and cur[p] == 0:
            continue
        for a in range(trig_ptr[p], trig_ptr[p + 1]):
            t = trig_t[a]
            ok = True
            for b in range(in_ptr[t], in_ptr[t + 1]):
                if cur[in_p[b]] < in_w[b]:
                    ok = False
                    break
            if ok:
                for b in range(ih_ptr[t], ih_ptr[t + 1]):
                    if cur[ih_p[b]] >= ih_w[b]:
                        ok = False
                        break
            if ok:
                enabled[k] = t
                k += 1
    for a in range(1, k):  # insertion sort: few enabled transitions, often in order already
        t = enabled[a]
        b = a - 1
        while b >= 0 and enabled[b] > t:
            enabled[b + 1] = enabled[b]
            b -= 1
        enabled[b + 1] = t
    if use_prio and k > 1:
        best = prio[enabled[0]]
        for a in range(1, k):
            best = max(best, prio[enabled[a]])
        kept = 0
        for a in range(k):
            if prio[enabled[a]] == best:
                enabled[kept] = enabled[a]
                kept += 1
        k = kept
    return k


@njit(cache=True, inline="always")
def _fits(q: int, v: int, msk: np.ndarray, cursor: np.ndarray) -> int:
    """Whether the new count v of place q fits: DONE, OVERFLOW (above 2**31 - 1) or WIDEN (above
    q's field; ``cursor[NEED]``, ``cursor[NEED_S]`` = q, v); ``cursor[MAX_COUNT]`` becomes at least v."""
    if v > cursor[MAX_COUNT]:
        cursor[MAX_COUNT] = v
        if v > _INT32_MAX:
            return OVERFLOW
    if np.uint64(v) & ~msk[q]:
        cursor[NEED], cursor[NEED_S] = q, v
        return WIDEN
    return DONE


@njit(cache=True, inline="always")
def _fire(states: np.ndarray, base: int, succ: np.ndarray, t: int, cur: np.ndarray, d_ptr: np.ndarray,
          d_p: np.ndarray, d_v: np.ndarray, r_ptr: np.ndarray, r_p: np.ndarray, r_v: np.ndarray,
          resets: np.ndarray | None, wd: np.ndarray, sh: np.ndarray, msk: np.ndarray, cursor: np.ndarray) -> int:
    """The successor of the packed marking ``states[base:base + W]`` (unpacked: ``cur``) by the
    enabled transition t, packed into ``succ`` (W,); every count written is checked against its
    field, so it never wraps, and ``cursor[MAX_COUNT]`` is raised to the largest count written.

    Returns:
        DONE, OVERFLOW (a count above 2**31 - 1) or WIDEN (``cursor[NEED]``'s new count
        ``cursor[NEED_S]`` outgrew its field; ``succ`` is then incomplete).
    """
    for w in range(succ.shape[0]):
        succ[w] = states[base + w]
    for b in range(d_ptr[t], d_ptr[t + 1]):
        q = d_p[b]
        v = cur[q] + d_v[b]
        if d_v[b] > 0:
            status = _fits(q, v, msk, cursor)
            if status != DONE:
                return status
        # the new count fits its field, so adding the shifted change (modulo 2**64 when it is
        # negative) rewrites that field alone
        succ[wd[q]] += np.uint64(d_v[b]) << sh[q]
    if resets is not None:
        for b in range(r_ptr[t], r_ptr[t + 1]):  # reset places end with r_v tokens
            q = r_p[b]
            v = r_v[b]
            status = _fits(q, v, msk, cursor)
            if status != DONE:
                return status
            _set(succ, 0, q, v, wd, sh, msk)
    return DONE


@njit(cache=True, inline="always")
def _find(states: np.ndarray, table: np.ndarray, succ: np.ndarray, key: np.uint64, bits: int) -> np.int64:
    """Look the packed marking ``succ`` (W,), of hash ``key`` (:func:`_hash`), up in the hash
    table (:func:`_fill_table`) over the packed markings ``states`` (N·W,): its index, or -1 - s
    when it is not there, s the empty slot it would take."""
    n_w = succ.shape[0]
    mask = table.shape[0] - 1
    tag = (key >> _THIRTY_TWO) << _THIRTY_TWO
    s = _slot(key, bits)
    while table[s] != 0:
        if (table[s] & ~_LOW32) == tag:
            cand = np.int64(table[s] & _LOW32) - 1
            same = True
            cb = cand * n_w
            for w in range(n_w):
                if states[cb + w] != succ[w]:
                    same = False
                    break
            if same:
                return cand
        s = (s + 1) & mask
    return -1 - s


@njit(cache=True)
def _search(tab: np.ndarray, trig_ptr: np.ndarray, trig_t: np.ndarray, prio: np.ndarray, use_prio: bool,
            states: np.ndarray, table: np.ndarray, dst: np.ndarray, tr: np.ndarray, out_ptr: np.ndarray,
            parent: np.ndarray, trunc: np.ndarray, cursor: np.ndarray, wd: np.ndarray, sh: np.ndarray,
            msk: np.ndarray, succ: np.ndarray, cur: np.ndarray, enabled: np.ndarray, fired: np.ndarray,
            max_states: int, finish_level: bool, budget: int, keep_edges: bool, resets: np.ndarray | None) -> int:
    """Expand markings in breadth-first order, at most ``budget`` of them, from ``cursor[NEXT]``,
    in the given buffers (never reallocated here: ``ROOM`` says one is full, and ``cursor[NEED]``
    how many successors the state waiting to be expanded has).

    Args:
        tab: packed arc lists (:func:`tables`); trig_ptr (|P|+2,), trig_t (|T|,): transitions by
            trigger place (slot |P| lists those without input places).
        prio: (|T|,) int64 priority levels, used if ``use_prio``: in each marking only the enabled
            transitions of the highest enabled level fire.
        states: (cap·W,) uint64 packed markings (W words each, layout ``wd``, ``sh``, ``msk``: the
            word, shift and mask of each place's field); table: (2**k,) uint64 hash table; dst:
            (ecap,) int32 edge targets; tr: (ecap,) int32 their transitions (both written only if
            ``keep_edges``); out_ptr: (cap + 1,) int64, the edges of state i are
            ``out_ptr[i]:out_ptr[i+1]`` (counted whether kept or not); parent: (cap,) int32 the
            state each state was first reached from; trunc: int64 sources that lost an edge to the state limit;
            cursor: int64 (:data:`CURSOR_SIZE`,); succ (W,) uint64 successor scratch; cur (|P|,)
            int64 the marking being expanded, unpacked; enabled (|T|,) scratch; fired (|T|,) int64
            set to 1 for each transition fired from an expanded marking.
        max_states: a new successor beyond this many states is dropped (its source goes to
            ``trunc``) and the search stops at the end of the level (``finish_level``), or once the
            marking being expanded is done.
        budget: most markings to expand in this call.
        keep_edges: store each edge's target and transition in ``dst`` and ``tr``; else they are
            only counted (``out_ptr``).

    Returns:
        DONE, BUDGET, ROOM, OVERFLOW, or WIDEN (a count outgrew its place's field: ``cursor[NEED]``
        is the place, ``cursor[NEED_S]`` the count; nothing was stored); the cursor says where the
        search is.
    """
    n_p = wd.shape[0]
    n_w = succ.shape[0]
    in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, d_ptr, d_p, d_v, r_ptr, r_p, r_v = _arcs(tab)
    # ``resets is not None`` is decided when numba compiles: a net without reset arcs passes None
    # and runs a specialisation of this function without their code
    n, e, i = cursor[N], cursor[E], cursor[NEXT]
    level_end, stopping, n_trunc = cursor[LEVEL_END], cursor[STOPPING], cursor[N_TRUNC]
    cap = parent.shape[0]
    size = table.shape[0]
    bits = _bit_length(size) - 1
    status = DONE
    done = 0
    n0, e0, stopping0 = n, e, stopping
    while True:
        if i == level_end:
            if stopping != 0 or i == n:
                break
            level_end = n
        if done == budget:
            status = BUDGET
            break
        base = i * n_w
        n0, e0, stopping0 = n, e, stopping  # restored if a field overflows while i is expanded
        for p in range(n_p):  # the marking, unpacked once
            cur[p] = _get(states, base, p, wd, sh, msk)
        k = _enabled_list(cur, trig_ptr, trig_t, in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, prio, use_prio, enabled)
        # room for k edges and for as many new states as the state limit still allows
        room = min(k, max_states - n)
        if n + room > cap or (keep_edges and e + k > dst.shape[0]) or 4 * (n + room) > 3 * size or \
                n_trunc == trunc.shape[0]:
            cursor[NEED] = k
            cursor[NEED_S] = room
            status = ROOM
            break
        dropped = False
        for a in range(k):
            t = enabled[a]
            status = _fire(states, base, succ, t, cur, d_ptr, d_p, d_v, r_ptr, r_p, r_v, resets, wd, sh, msk, cursor)
            if status != DONE:
                break
            key = _hash(succ, 0, n_w)
            j = _find(states, table, succ, key, bits)
            if j < 0:
                if n == max_states:
                    dropped = True
                    stopping = 1
                    continue
                table[-1 - j] = ((key >> _THIRTY_TWO) << _THIRTY_TWO) | np.uint64(n + 1)  # its empty slot
                j = n
                jb = j * n_w
                for w in range(n_w):
                    states[jb + w] = succ[w]
                parent[j] = i
                n += 1
            if keep_edges:
                dst[e] = j
                tr[e] = t
            fired[t] = 1
            e += 1
        if status != DONE:
            break
        if dropped:
            trunc[n_trunc] = i
            n_trunc += 1
            if not finish_level:  # the search ends with this marking: the rest are not expanded
                level_end = i + 1
        out_ptr[i + 1] = e
        i += 1
        done += 1
    if status == WIDEN:  # the successors of i found so far are dropped: i is expanded again
        n, e, stopping = n0, e0, stopping0
    cursor[N], cursor[E], cursor[NEXT] = n, e, i
    cursor[LEVEL_END], cursor[STOPPING], cursor[N_TRUNC] = level_end, stopping, n_trunc
    return status


@njit(cache=True)
def _fields(lay: np.ndarray, n_p: int, sh: np.ndarray, msk: np.ndarray) -> int:
    """Lay the fields of widths ``lay[2|P|:3|P|]`` first-fit in 64-bit words, none straddling two
    (fills the words ``lay[:|P|]``, shifts ``lay[|P|:2|P|]`` and ``sh``, masks ``msk``); returns W."""
    word = used = 0
    for p in range(n_p):
        w = lay[2 * n_p + p]
        if used + w > 64:
            word += 1
            used = 0
        lay[p] = word
        lay[n_p + p] = used
        sh[p] = np.uint64(used)
        msk[p] = (np.uint64(1) << np.uint64(w)) - np.uint64(1)
        used += w
    return word + 1


@njit(cache=True)
def extremes(words: np.ndarray, layout: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> np.int64:
    """Per place the largest (``hi``) and smallest (``lo``) count, both (|P|,) int64 filled here,
    over the markings ``words`` (N ≥ 1, W) uint64 packed by ``layout`` (see :func:`run`), read
    without unpacking them; returns the largest token count of one marking."""
    n_p = hi.shape[0]
    top = np.int64(0)
    for p in range(n_p):
        hi[p] = 0
        lo[p] = 1 << 62
    for i in range(words.shape[0]):
        total = np.int64(0)
        for p in range(n_p):
            v = np.int64((words[i, layout[p]] >> np.uint64(layout[n_p + p])) & (
                (np.uint64(1) << np.uint64(layout[2 * n_p + p])) - np.uint64(1)))
            total += v
            if v > hi[p]:
                hi[p] = v
            if v < lo[p]:
                lo[p] = v
        if total > top:
            top = total
    return top


@njit(cache=True)
def unpack(words: np.ndarray, layout: np.ndarray, out: np.ndarray) -> None:
    """Unpack markings: ``words`` (N, W) uint64 packed by ``layout`` (see :func:`run`) into ``out``
    (N, |P|), any integer dtype wide enough for the counts."""
    n_p = out.shape[1]
    for i in range(words.shape[0]):
        for p in range(n_p):
            v = (words[i, layout[p]] >> np.uint64(layout[n_p + p])) & (
                (np.uint64(1) << np.uint64(layout[2 * n_p + p])) - np.uint64(1))
            out[i, p] = v


@njit(cache=True)
def _grow(a: np.ndarray, size: int, used: int) -> np.ndarray:
    out = np.empty(size, a.dtype)
    for k in range(used):
        out[k] = a[k]
    return out


@njit(cache=True)
def _target(cap: int, need: int, unit: int | np.int64, held: int | np.int64, max_bytes: int,
            ceiling: int | np.int64, copy_unit: int | np.int64) -> int:
    """New capacity of buffers of ``unit`` bytes per entry in all (grown one array at a time, the
    largest ``copy_unit`` bytes an entry): the usual growth (×2 up to 2**20 entries, then ×1.5),
    cut to ``ceiling`` and to what the byte budget holds at the last copy — every other array at
    its new size, the last one both old and new — beside the other buffers (``held`` less these
    at ``cap``); -1 if not even ``need`` entries fit."""
    want: int | np.int64 = 2 * cap if cap < (1 << 20) else cap + cap // 2
    want = min(max(want, need), max(ceiling, need))
    want = min(want, (max_bytes - (held - cap * unit) - cap * copy_unit) // unit)
    return int(want) if want >= need else -1


#: the signature :func:`run` is compiled for (read-only matrices, marking and priorities, as a
#: net holds them, and ``resets`` None: a net without reset arcs; callers pass exactly these types,
#: so a call never goes through numba's slower type-conversion path and nothing is compiled twice).
#: :func:`load` compiles it, or loads it from the cache, and then forbids further compilations;
#: :func:`load_resets` does the same for :data:`RESET_SIGNATURE`, the search of nets with reset
#: arcs, on the first such net.
_RO2 = types.Array(types.int64, 2, "C", readonly=True)
_RO1 = types.Array(types.int64, 1, "C", readonly=True)
RUN_SIGNATURE = (_RO2, _RO2, _RO2, types.int64[::1], _RO1, types.int64[::1], _RO1, types.boolean, types.int64,
                 types.int64, types.int64, types.boolean, types.boolean, types.none, types.boolean)
RESET_SIGNATURE = (*RUN_SIGNATURE[:-2], types.int64[::1], types.boolean)


def cached() -> bool | None:
    """Load :func:`run` for :data:`RUN_SIGNATURE` from numba's cache if it is there (True), without
    compiling; False if it is not (the next :func:`load` compiles), None if numba cannot say."""
    if run.overloads:
        return True
    try:
        result = run._cache.load_overload(RUN_SIGNATURE, run.targetctx)  # type: ignore[attr-defined]
    except Exception:  # noqa: BLE001 - numba internals: unknown means "cannot say"
        return None
    if result is None:
        return False
    run.add_overload(result)
    return True


def load() -> None:
    """Make :func:`run` ready: loaded from the cache or compiled (and cached) for its signature."""
    if RUN_SIGNATURE not in run.overloads:
        run.compile(RUN_SIGNATURE)
    run.disable_compile()


def load_resets() -> None:
    """Make :func:`run` ready for nets with reset arcs (:data:`RESET_SIGNATURE`): loaded from the
    cache or compiled (and cached) the first time such a net is explored."""
    if RESET_SIGNATURE not in run.overloads:
        run.disable_compile(False)
        try:
            run.compile(RESET_SIGNATURE)
        finally:
            run.disable_compile()


@njit(cache=True, nogil=True)  # threads may search beside other work (the symbolic engine's lanes)
def run(pre: np.ndarray, inhibitor: np.ndarray, incidence: np.ndarray, tab: np.ndarray, m0: np.ndarray,
        layout: np.ndarray, prio: np.ndarray, use_prio: bool, max_states: int, max_bytes: int,
        report_every: int, keep_edges: bool, shed_edges: bool, resets: np.ndarray | None,
        finish_level: bool) -> tuple:  # type: ignore[type-arg]
    """The whole breadth-first search of a net (see the module docstring).

    Args:
        pre, inhibitor, incidence: (|P|, |T|) int64 matrices of a net without reset arcs, read only
            if ``tab`` is empty.
        tab: packed arc lists (layout of :func:`tables`), or an empty array to build them from the
            matrices.
        m0: (|P|,) int64 initial marking.
        layout: (4·|P|,) int64: per place the word of the packed marking that holds its field, the
            field's shift in that word, its width in bits (1..31; a field never straddles two
            words; :func:`coordinator.analysis.statespace.packed_layout`), and the width its proven
            bound needs (0: none), which a field that overflows takes at once.
        prio, use_prio: (|T|,) int64 priority levels and whether to apply them (only the enabled
            transitions of the highest enabled level fire).
        max_states: a new marking beyond this many is dropped with its edge; the search then
            finishes the level and stops, or (``finish_level`` False) stops once the marking being
            expanded is done.
        max_bytes: byte budget of the search's buffers (see the module docstring).
        report_every: call the progress hook (:func:`set_progress`) every this many expanded
            markings and at the end, and stop (status ``STOPPED``) if its stop event is set; 0 for
            never.
        keep_edges: keep the edges (``dst``, ``tr``); else only count them: ``dst`` and ``tr`` come
            back empty, ``out_ptr`` still gives each state's number of edges.
        shed_edges: when kept edges leave no room in ``max_bytes`` for a buffer to grow, drop them
            (freeing their bytes) and go on counting them only, as if ``keep_edges`` were False,
            instead of stopping.
        resets: ``None`` for a net without reset arcs (the search is compiled without their code),
            else any array (``tab``): the reset lists of ``tab`` are applied.
        finish_level: at the state limit, finish the level being expanded (True), or stop at once
            (False: whoever asks only whether the graph fits the limit need not wait for a level
            that may be most of the graph).

    Returns:
        ``(status, states, dst, tr, parent, expanded, out_ptr, complete, max_count, layout,
        store_bytes, shed_at, fired)``: DONE, OVERFLOW, MEMORY or STOPPED; states (N, W) uint64 packed markings in
        breadth-first order, in the final ``layout`` (fields widened during the search; :func:`unpack`);
        edges as CSR: dst (E,) int32 and tr (E,) int32 sorted by source then transition (empty
        unless ``keep_edges``), out_ptr (N+1,) int64; parent (N,) int32 the state of the previous
        level each state was first reached from (-1 for M0); expanded (N,) bool;
        whether the graph is complete; the largest token count seen; the bytes of the marking store
        and the hash table when the search ended; the number of markings found when the edges
        were dropped (``shed_edges``), -1 if they were not; (|T|,) bool, the transitions fired
        from a marking expanded (each labels an edge found, kept or not).
    """
    arcs = tables(pre, inhibitor, incidence) if tab.shape[0] == 0 else tab
    n_p = m0.shape[0]
    n_t = arcs[1] - arcs[0] - 1
    # the packed layout: per place its word, shift and mask; W words a marking
    lay = layout.copy()
    wd = lay[:n_p]
    sh = np.empty(n_p, np.uint64)
    msk = np.empty(n_p, np.uint64)
    n_w = _fields(lay, n_p, sh, msk)
    succ = np.zeros(n_w, np.uint64)
    cur = np.zeros(n_p, np.int64)
    # one scratch allocation: the cursor and per transition an enabled slot and a fired flag
    scratch = np.zeros(CURSOR_SIZE + 2 * n_t, np.int64)
    cursor = scratch[:CURSOR_SIZE]
    enabled = scratch[CURSOR_SIZE:CURSOR_SIZE + n_t]
    fired = scratch[CURSOR_SIZE + n_t:]
    trig_ptr, trig_t = _triggers(arcs, n_p)
    # buffers; bytes per state: its packed marking (W uint64), a consumer's unpacked copy (one
    # byte a place in the common case; made only when asked for), the parent state, the
    # out-edge pointer and the expanded flag; per edge: int32 target and transition
    unit_s = np.int64(8 * n_w + n_p + 13)
    unit_e = np.int64(8)
    no_ceiling = np.int64(1 << 62)
    # first capacity: small (the buffers grow by doubling, so what is held stays within twice what
    # is used), within 1/8 of the budget and 16 MiB (a wide net's markings are large)
    cap = max(1, min(16, max_states, int(min(max_bytes // 8, 1 << 24) // unit_s)))
    ecap = 4 * cap if keep_edges else 0
    size = _table_slots(cap)
    states = np.zeros(cap * n_w, np.uint64)
    parent = np.empty(cap, np.int32)
    out_ptr = np.empty(cap + 1, np.int64)
    table = np.zeros(size, np.uint64)
    dst = np.empty(ecap, np.int32)
    tr = np.empty(ecap, np.int32)
    trunc = np.empty(16, np.int64)
    held = cap * unit_s + ecap * unit_e + 8 * size
    # state 0 = M0, packed (the caller's layout holds it)
    top = 0
    for p in range(n_p):
        top = max(top, m0[p])
    cursor[MAX_COUNT] = top
    for p in range(n_p):
        if np.uint64(m0[p]) & ~msk[p]:
            cursor[NEED], cursor[NEED_S] = p, m0[p]
            return (OVERFLOW, states[:0].reshape((0, n_w)), dst[:0], tr[:0], parent[:0], np.zeros(0, np.bool_),
                    out_ptr[:1], False, top, lay, np.int64(0), np.int64(-1), fired != 0)
        _set(states, 0, p, m0[p], wd, sh, msk)
    cursor[N] = 1
    cursor[LEVEL_END] = 1
    parent[0] = -1
    out_ptr[0] = 0
    _fill_table(table, states, 1, n_w)
    status = OVERFLOW
    shed_at = np.int64(-1)
    next_report = report_every if report_every > 0 else 1 << 62  # in expanded markings
    while top <= _INT32_MAX:
        status = _search(arcs, trig_ptr, trig_t, prio, use_prio, states, table, dst, tr, out_ptr, parent,
                         trunc, cursor, wd, sh, msk, succ, cur, enabled, fired, max_states, finish_level,
                         max(1, next_report - cursor[NEXT]), keep_edges, resets)
        if status == ROOM:
            n, e, k, ks = cursor[N], cursor[E], cursor[NEED], cursor[NEED_S]
            if n + ks > cap:
                new = _target(cap, n + ks, unit_s, held, max_bytes, max_states, 8 * n_w)
                if new < 0:
                    status = MEMORY
                else:  # one buffer at a time: only one old copy is held at once
                    states = _grow(states, new * n_w, n * n_w)
                    parent = _grow(parent, new, n)
                    out_ptr = _grow(out_ptr, new + 1, cursor[NEXT] + 1)
                    held += (new - cap) * unit_s
                    cap = new
            if status == ROOM and keep_edges and e + k > dst.shape[0]:
                new = _target(dst.shape[0], e + k, unit_e, held, max_bytes, no_ceiling, unit_e // 2)
                if new < 0:
                    status = MEMORY
                else:
                    held += (new - dst.shape[0]) * unit_e
                    dst = _grow(dst, new, e)
                    tr = _grow(tr, new, e)
            if status == ROOM and cursor[N_TRUNC] == trunc.shape[0]:
                trunc = _grow(trunc, 2 * trunc.shape[0], cursor[N_TRUNC])
            if status == ROOM and 4 * (n + ks) > 3 * size:
                new = max(size, _table_slots(n + ks))
                if held + 8 * new > max_bytes:
                    status = MEMORY
                else:
                    held += 8 * (new - size)
                    size = new
                    table = np.zeros(1, np.uint64)  # the old table is rebuilt, not copied: freed first
                    table = np.zeros(size, np.uint64)
                    _fill_table(table, states, n, n_w)
            if status == ROOM:
                continue
        if status == WIDEN:
            # a count outgrew its field: widen the field (to the place's proven width, and every
            # place still narrower than its proven width with it, at the first such overflow;
            # else double it) and repack the markings found
            q, v = cursor[NEED], cursor[NEED_S]
            new_lay = lay.copy()
            if new_lay[3 * n_p + q] > new_lay[2 * n_p + q]:
                for p in range(n_p):
                    new_lay[2 * n_p + p] = max(new_lay[2 * n_p + p], new_lay[3 * n_p + p])
            if v >> new_lay[2 * n_p + q]:
                new_lay[2 * n_p + q] = min(31, max(_bit_length(v), 2 * new_lay[2 * n_p + q]))
            new_sh = np.empty(n_p, np.uint64)
            new_msk = np.empty(n_p, np.uint64)
            new_w = _fields(new_lay, n_p, new_sh, new_msk)
            if held + cap * 8 * new_w > max_bytes:
                status = MEMORY
            else:
                packed = np.zeros(cap * new_w, np.uint64)
                for j in range(cursor[N]):
                    for p in range(n_p):
                        c = (states[j * n_w + wd[p]] >> sh[p]) & msk[p]
                        packed[j * new_w + new_lay[p]] |= c << new_sh[p]
                for p in range(4 * n_p):  # plain loops: a slice copy compiles numba's shape-error text
                    lay[p] = new_lay[p]
                for p in range(n_p):
                    sh[p], msk[p] = new_sh[p], new_msk[p]
                held += cap * 8 * (new_w - n_w)
                unit_s += 8 * (new_w - n_w)
                states = packed
                n_w = new_w
                succ = np.zeros(n_w, np.uint64)
                _fill_table(table, states, cursor[N], n_w)
                continue
        if status == OVERFLOW:
            break
        if status == MEMORY and keep_edges and shed_edges:
            # the edges leave no room: drop them and go on counting them (the search asks again)
            held -= dst.shape[0] * unit_e
            dst = np.empty(0, np.int32)
            tr = np.empty(0, np.int32)
            keep_edges = False
            shed_at = cursor[N]
            continue
        if status == MEMORY:
            cursor[STOPPING] = 1
        if report_every > 0:
            stop = 0
            with objmode(stop="int64"):
                stop = _report(cursor[N], cursor[E])
            if stop != 0 and status == BUDGET:
                status = STOPPED
                cursor[STOPPING] = 1
        if status != BUDGET:
            break
        next_report = cursor[NEXT] + report_every
    n, e, done = cursor[N], cursor[E], cursor[NEXT]
    store = np.int64(cap * 8 * n_w + 8 * size)  # markings and hash table at the end of the search
    table = np.zeros(1, np.uint64)  # free the hash table before the result arrays are made
    for i in range(done + 1, n + 1):  # the states not expanded have no edges
        out_ptr[i] = e
    expanded = np.zeros(n, np.bool_)
    if cursor[STOPPING] != 0:
        for i in range(done):
            expanded[i] = True
        for q in range(cursor[N_TRUNC]):
            expanded[trunc[q]] = False
    else:
        for i in range(n):
            expanded[i] = True
    # compact the buffers that are much larger than their contents, when the budget allows the copy
    if 4 * e < 3 * dst.shape[0] and held + e * unit_e <= max_bytes:
        dst = _grow(dst, e, e)
        tr = _grow(tr, e, e)
    if 4 * n < 3 * cap and held + n * unit_s <= max_bytes:
        states = _grow(states, n * n_w, n * n_w)
        parent = _grow(parent, n, n)
        out_ptr = _grow(out_ptr, n + 1, n + 1)
    return (status, states[:n * n_w].reshape((n, n_w)), dst[:e], tr[:e], parent[:n], expanded, out_ptr[:n + 1],
            cursor[STOPPING] == 0, cursor[MAX_COUNT], lay, store, shed_at, fired != 0)


@njit(cache=True, inline="always")
def _component_base(v: int, n_stack: int, dq: np.ndarray, rindex: np.ndarray) -> int:
    """The depth-first search of ``v`` returned and ``v`` is its component's root: the stack
    position from which the stacked markings are ``v``'s component (the stack of
    :func:`components`, from the top of ``dq``: position a is ``dq[n - 1 - a]``)."""
    n = dq.shape[0]
    lo = n_stack
    while lo > 0 and rindex[v] <= rindex[dq[n - lo]]:
        lo -= 1
    return lo


@njit(cache=True, inline="always")
def _component_left(v: int, lo: int, n_stack: int, dq: np.ndarray, leaves: np.ndarray) -> bool:
    """Whether an edge leaves the component of ``v`` and the stacked markings from ``lo``."""
    n = dq.shape[0]
    out = leaves[v]
    for a in range(lo, n_stack):
        out |= leaves[dq[n - 1 - a]]
    return bool(out)


@njit(cache=True, inline="always")
def _component_close(v: int, lo: int, n_stack: int, comp: int, dq: np.ndarray, rindex: np.ndarray) -> None:
    """Number the markings of the finished component ``comp`` (``rindex`` −1 − comp)."""
    n = dq.shape[0]
    for a in range(lo, n_stack):
        rindex[dq[n - 1 - a]] = -1 - comp
    rindex[v] = -1 - comp


@njit(cache=True)
def _component_levels(fired: np.ndarray, inside: np.ndarray, hits: np.ndarray, n_term: int,
                      rindex: np.ndarray) -> np.ndarray:
    """The liveness level of each transition, (|T|,) int64, from what the pass saw; ``rindex``
    turned into each marking's component number, in place."""
    n_t = fired.shape[0]
    levels = np.zeros(n_t, np.int64)
    for t in range(n_t):
        if fired[t]:
            levels[t] = 1
        if inside[t]:
            levels[t] = 4 if hits[t] == n_term else 3
    for v in range(rindex.shape[0]):
        rindex[v] = -1 - rindex[v]
    return levels


@njit(cache=True)
def components(tab: np.ndarray, words: np.ndarray, layout: np.ndarray, prio: np.ndarray, use_prio: bool,
               resets: np.ndarray | None) -> tuple:  # type: ignore[type-arg]
    """Strongly connected components and liveness levels of a complete reachability graph whose
    edges are not stored: each marking's successors are computed again from its packed form (the
    search's enabling and firing rules, :func:`_enabled_list` and :func:`_fire`) and found by a
    hash table over the markings (:func:`_fill_table`). Tarjan's algorithm (Tarjan 1972) in the
    iterative, one-index-a-state form of Pearce 2016, with every edge classified as it is met: an
    edge into a finished component leaves its source's component (which is then not terminal), any
    other joins two markings of the same component. A finished component that no edge leaves is
    terminal, and the transitions enabled in its markings are those fired inside it.

    Args:
        tab: packed arc lists (:func:`tables`; with reset lists when ``resets`` is not None).
        words: (N, W) uint64 packed markings of a complete graph, in ``layout``.
        layout: (3·|P|,) int64 per place its word, shift and width.
        prio, use_prio: the priority levels the search applied.
        resets: None for a net without reset arcs, else any array (``tab``).

    Returns:
        ``(status, levels, labels, terminal, deepest, tallest)``: status 0, or 1 + the index of a marking with a
        successor that is not among ``words`` (the graph is not complete); levels (|T|,) int64 in
        {0, 1, 3, 4} (never fired, fired, fired inside a component, fired inside every terminal
        component); labels (N,) int32 the component of each marking, numbered in the order they
        finish (a component's successors finish before it); terminal (number of components,) bool;
        the longest depth-first path and the most markings the component stack held.
        Memory: the hash table (8 bytes a slot, at most 3/4 full) and at most 9 bytes a marking
        (its index, its flag, and one array shared by the depth-first path and the component
        stack, which never hold the same marking), plus a flag a component.
    """
    n, n_w = words.shape
    flat = words.reshape(n * n_w)
    n_p = layout.shape[0] // 3
    n_t = tab[1] - tab[0] - 1
    in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, d_ptr, d_p, d_v, r_ptr, r_p, r_v = _arcs(tab)
    trig_ptr, trig_t = _triggers(tab, n_p)
    lay = layout.copy()  # laid again from its widths, as the search laid it: the same words and shifts
    sh = np.empty(n_p, np.uint64)
    msk = np.empty(n_p, np.uint64)
    _fields(lay, n_p, sh, msk)
    wd = lay[:n_p]
    table = np.zeros(_table_slots(n), np.uint64)
    _fill_table(table, flat, n, n_w)
    bits = _bit_length(table.shape[0]) - 1
    cur = np.zeros(n_p, np.int64)
    succ = np.zeros(n_w, np.uint64)
    enabled = np.zeros(n_t, np.int64)
    cursor = np.zeros(CURSOR_SIZE, np.int64)
    # rindex: 0 unvisited, then the visit index lowered to the smallest one reached (Pearce's
    # rindex), then -1 - the component's number once it is finished (one array read tells an
    # edge's target apart); leaves: an edge leaves the marking's component
    rindex = np.zeros(n, np.int32)
    leaves = np.zeros(n, np.bool_)
    terminal = np.zeros(n, np.bool_)  # a flag a component, at most one a marking (pages touched as used)
    fired = np.zeros(n_t, np.bool_)
    inside = np.zeros(n_t, np.bool_)
    hits = np.zeros(n_t, np.int64)  # terminal components each transition fires in
    seen = np.full(n_t, -1, np.int64)
    # one array holds the depth-first path from its bottom (a marking, or -1 - the marking once it
    # is known not to be its component's root) and, from its top, the component stack (markings
    # whose search returned, not roots): no marking is on both, so together they hold at most N
    # (np.empty: only the pages they reach are ever touched)
    dq = np.empty(n, np.int32)
    n_stack = 0
    deepest = tallest = 1
    index = 1
    comp = 0
    n_term = 0
    for start in range(n):
        if rindex[start] != 0:
            continue
        dq[0] = start
        rindex[start] = index
        index += 1
        depth = 1
        back = -1  # the marking whose search just returned to the top frame
        while depth > 0:
            v = dq[depth - 1]
            if v < 0:
                v = -1 - v
            base = v * n_w
            for p in range(n_p):
                cur[p] = _get(flat, base, p, wd, sh, msk)
            k = _enabled_list(cur, trig_ptr, trig_t, in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, prio, use_prio, enabled)
            pos = 0
            if back >= 0:
                # the edge that led to ``back`` is the first whose successor is ``back`` (it was
                # unvisited until then): found again by firing and comparing, no lookup
                while pos < k:
                    _fire(flat, base, succ, enabled[pos], cur, d_ptr, d_p, d_v, r_ptr, r_p, r_v, resets, wd, sh, msk,
                          cursor)
                    same = True
                    for w in range(n_w):
                        if succ[w] != flat[back * n_w + w]:
                            same = False
                            break
                    if same:
                        break
                    pos += 1
                if pos == k:  # pragma: no cover - the edge was found once, so it is found again
                    return (1 + v, np.zeros(n_t, np.int64), rindex, terminal[:0].copy(), deepest, tallest)
            descend = False
            while pos < k:
                t = enabled[pos]
                if back >= 0:
                    w = back
                    back = -1
                else:
                    _fire(flat, base, succ, t, cur, d_ptr, d_p, d_v, r_ptr, r_p, r_v, resets, wd, sh, msk, cursor)
                    w = int(_find(flat, table, succ, _hash(succ, 0, n_w), bits))
                    if w < 0:
                        return (1 + v, np.zeros(n_t, np.int64), rindex, terminal[:0].copy(), deepest, tallest)
                    if rindex[w] == 0:
                        dq[depth] = w
                        rindex[w] = index
                        index += 1
                        depth += 1
                        deepest = max(deepest, depth)
                        descend = True
                        break
                fired[t] = True
                r = rindex[w]
                if r < 0:
                    leaves[v] = True
                else:
                    inside[t] = True
                    if r < rindex[v]:
                        rindex[v] = r
                        dq[depth - 1] = -1 - v
                pos += 1
            if descend:
                continue
            depth -= 1
            back = v
            if dq[depth] < 0:
                n_stack += 1
                dq[n - n_stack] = v  # stack position a (0 at the bottom) is dq[n - 1 - a]
                tallest = max(tallest, n_stack)
                continue
            # v is the root of a finished component: v and the stacked markings visited after it
            lo = _component_base(v, n_stack, dq, rindex)
            out = _component_left(v, lo, n_stack, dq, leaves)
            terminal[comp] = not out
            if not out:
                n_term += 1
                for a in range(lo, n_stack + 1):
                    m = v if a == n_stack else dq[n - 1 - a]
                    for p in range(n_p):
                        cur[p] = _get(flat, m * n_w, p, wd, sh, msk)
                    k = _enabled_list(cur, trig_ptr, trig_t, in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, prio, use_prio,
                                      enabled)
                    for b in range(k):
                        if seen[enabled[b]] != comp:
                            seen[enabled[b]] = comp
                            hits[enabled[b]] += 1
            _component_close(v, lo, n_stack, comp, dq, rindex)
            n_stack = lo
            comp += 1
    levels = _component_levels(fired, inside, hits, n_term, rindex)
    return (0, levels, rindex, terminal[:comp].copy(), deepest, tallest)


@njit(cache=True)
def edge_components(out_ptr: np.ndarray, dst: np.ndarray, tr: np.ndarray, n_t: int) -> tuple:  # type: ignore[type-arg]
    """:func:`components` on a complete graph whose edges are kept: each marking's successors are
    read from the edge lists instead of fired again and looked up, so the pass costs no hash
    table and no firing (SafeBus-PT-06, 6,816,756 markings and 29,904,912 edges: 26.3 s through
    :func:`components`, 2.9 s here). The same algorithm (Tarjan 1972 in the form of
    Pearce 2016) and the same classification of every edge; each frame of the depth-first path
    keeps the position of its next edge.

    Args:
        out_ptr: (N+1,) int64 the first edge of each marking (CSR, edges sorted by source).
        dst: (E,) int32 target of each edge; tr: (E,) int32 its transition.
        n_t: number of transitions.

    Returns:
        ``(levels, labels, terminal, deepest, tallest)`` as :func:`components` (without its status:
        every edge's target is a marking of the graph).
        Memory: at most 17 bytes a marking (its index, its flag, one array shared by the path and
        the component stack, and the path's edge positions), plus a flag a component.
    """
    n = out_ptr.shape[0] - 1
    rindex = np.zeros(n, np.int32)
    leaves = np.zeros(n, np.bool_)
    terminal = np.zeros(n, np.bool_)  # a flag a component, at most one a marking (pages touched as used)
    fired = np.zeros(n_t, np.bool_)
    inside = np.zeros(n_t, np.bool_)
    hits = np.zeros(n_t, np.int64)
    seen = np.full(n_t, -1, np.int64)
    dq = np.empty(n, np.int32)  # the path from the bottom, the component stack from the top
    at = np.empty(n, np.int64)  # the next edge of each frame of the path
    n_stack = 0
    deepest = tallest = 1
    index = 1
    comp = 0
    n_term = 0
    for start in range(n):
        if rindex[start] != 0:
            continue
        dq[0] = start
        at[0] = out_ptr[start]
        rindex[start] = index
        index += 1
        depth = 1
        while depth > 0:
            v = dq[depth - 1]
            if v < 0:
                v = -1 - v
            e = at[depth - 1]
            end = out_ptr[v + 1]
            descend = False
            while e < end:
                w = dst[e]
                if rindex[w] == 0:
                    at[depth - 1] = e  # met again when w's search returns, and classified then
                    dq[depth] = w
                    at[depth] = out_ptr[w]
                    rindex[w] = index
                    index += 1
                    depth += 1
                    deepest = max(deepest, depth)
                    descend = True
                    break
                fired[tr[e]] = True
                r = rindex[w]
                if r < 0:
                    leaves[v] = True
                else:
                    inside[tr[e]] = True
                    if r < rindex[v]:
                        rindex[v] = r
                        dq[depth - 1] = -1 - v
                e += 1
            if descend:
                continue
            depth -= 1
            if dq[depth] < 0:
                n_stack += 1
                dq[n - n_stack] = v
                tallest = max(tallest, n_stack)
                continue
            lo = _component_base(v, n_stack, dq, rindex)
            out = _component_left(v, lo, n_stack, dq, leaves)
            terminal[comp] = not out
            if not out:
                n_term += 1
                for a in range(lo, n_stack + 1):
                    m = v if a == n_stack else dq[n - 1 - a]
                    for f in range(out_ptr[m], out_ptr[m + 1]):
                        if seen[tr[f]] != comp:
                            seen[tr[f]] = comp
                            hits[tr[f]] += 1
            _component_close(v, lo, n_stack, comp, dq, rindex)
            n_stack = lo
            comp += 1
    levels = _component_levels(fired, inside, hits, n_term, rindex)
    return (levels, rindex, terminal[:comp].copy(), deepest, tallest)
