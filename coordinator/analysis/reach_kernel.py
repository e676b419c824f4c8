"""Compiled breadth-first search of the reachability graph (internal to :mod:`.statespace`).

Pure: no I/O. The functions here are compiled to machine code by numba (``cache=True``: compiled
once per machine and kept beside this file, or in the user's cache directory when that is not
writable) and driven by :func:`coordinator.analysis.statespace.explore`, which documents the
result. What they implement (the reasons and the measurements are in docs/analysis.md, section 2):

* Sparse arc lists per transition (CSR: ``ptr`` of shape (|T|+1,), then place indices and values)
  for the input arcs, the inhibitor arcs and the non-zero entries of the incidence matrix C. Each
  transition with input places is listed under its first input place (its *trigger*), so a marking
  only tests the transitions whose trigger place is marked (enabling rule: Murata 1989, section II).
* A queue that is the state array itself: states are numbered in order of discovery and expanded in
  that order, so the search is breadth-first, a level (the markings at one distance from M0) is a
  contiguous index range, and edges come out sorted by source, then transition.
* A key per marking that is linear in it, ``key(M) = sum_p M(p) * R[p] mod 2**64``, so a
  successor's key is ``key(M) + key(C[:, t])``: one addition per edge. While the bit widths given
  to the places fit in 64 bits together, ``R[p] = 2**offset[p]`` packs the marking into its key
  exactly, so a key hit is a marking hit; a count that outgrows its width repacks every key. When
  the widths no longer fit, ``R`` becomes random odd multipliers and a key hit is confirmed by
  comparing the stored marking. Either way the result is exact.
* An open-addressing hash table (linear probing, load at most 1/2) of (key, index + 1) pairs side
  by side, so a lookup usually touches one cache line.

One call of :func:`run` does the whole search, buffers and growth included, and hands back the
finished arrays: on small nets the cost of crossing from Python into compiled code, not the search,
is what a caller waits for, so it is paid once. Progress reports go through a hook that :func:`run`
calls back in the interpreter (numba's object mode), which is also where Ctrl-C is noticed.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
from numba import njit, objmode

#: status codes: graph complete, or the state limit reached and its level finished; ``budget``
#: markings expanded; a buffer is full; a token count would exceed 2**31 - 1, the largest the int32
#: state store holds.
DONE, BUDGET, ROOM, OVERFLOW = 0, 1, 2, 3
#: layout of the cursor, the first CURSOR_SIZE entries of the int64 scratch array
N, E, NEXT, LEVEL_END, STOPPING, N_TRUNC, MAX_COUNT, EXACT, STARTED = range(9)
CURSOR_SIZE = 9
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_INT32_MAX = 2**31 - 1
_SEED = np.uint64(0x5EED0F9E7B)


_hook = threading.local()


def set_progress(callback: Callable[[int, int], None] | None) -> None:
    """Install (or, with None, remove) the progress callback of this thread's :func:`run` calls."""
    _hook.callback = callback


def _report(n_states: int, n_edges: int) -> None:
    callback = getattr(_hook, "callback", None)
    if callback is not None:
        callback(int(n_states), int(n_edges))


@njit(cache=True)
def tables(pre: np.ndarray, inhibitor: np.ndarray, incidence: np.ndarray) -> np.ndarray:
    """Arc lists of a net for :func:`_search`, packed in one int64 array.

    Args:
        pre, inhibitor, incidence: (|P|, |T|) int64 matrices of the net, read row by row.

    Returns:
        A flat int64 array: a header of 12 offsets, then the input arcs, the inhibitor arcs and the
        non-zero incidence entries as CSR lists (ptr (|T|+1,), places, values), then the
        transitions by trigger place (ptr (|P|+2,): slot |P| lists those without input places;
        transition ids). :func:`_unpack` gives the pieces back.
    """
    n_p, n_t = pre.shape
    head = 12
    # entries per transition (column) of each matrix, counted in one row-major pass
    count = np.zeros((3, n_t + 1), np.int64)
    for p in range(n_p):
        for t in range(n_t):
            if pre[p, t] != 0:
                count[0, t + 1] += 1
            if inhibitor[p, t] != 0:
                count[1, t + 1] += 1
            if incidence[p, t] != 0:
                count[2, t + 1] += 1
    for m in range(3):
        for t in range(n_t):
            count[m, t + 1] += count[m, t]
    nz0, nz1, nz2 = count[0, n_t], count[1, n_t], count[2, n_t]
    sizes = np.array([n_t + 1, nz0, nz0, n_t + 1, nz1, nz1, n_t + 1, nz2, nz2, n_p + 2, n_t])
    out = np.zeros(head + sizes.sum(), np.int64)
    pos = head
    for k in range(11):
        out[k] = pos
        pos += sizes[k]
    out[11] = pos
    # CSR by counting sort: places ascending within a transition, as the row-major pass meets them;
    # once copied into the pointers, count[m, t] serves as transition t's next free slot
    for m in range(3):
        out[out[3 * m]:out[3 * m] + n_t + 1] = count[m]
    for p in range(n_p):
        for t in range(n_t):
            _put(out, count, 0, p, t, pre[p, t])
            _put(out, count, 1, p, t, inhibitor[p, t])
            _put(out, count, 2, p, t, incidence[p, t])
    in_ptr, in_p, _, _, _, _, _, _, _, trig_ptr, trig_t = _unpack(out)
    for t in range(n_t):
        first = in_p[in_ptr[t]] if in_ptr[t + 1] > in_ptr[t] else n_p
        trig_ptr[first + 1] += 1
    for p in range(n_p + 1):
        trig_ptr[p + 1] += trig_ptr[p]
    slot = trig_ptr[:-1].copy()
    for t in range(n_t):  # transition order within each trigger place
        first = in_p[in_ptr[t]] if in_ptr[t + 1] > in_ptr[t] else n_p
        trig_t[slot[first]] = t
        slot[first] += 1
    return out


@njit(cache=True)
def _put(out: np.ndarray, fill: np.ndarray, m: int, p: int, t: int, value: int) -> None:
    """Append entry (p, value) to transition t's list in CSR m; ``fill[m, t]`` is its next slot."""
    if value != 0:
        k = fill[m, t]
        out[out[3 * m + 1] + k] = p
        out[out[3 * m + 2] + k] = value
        fill[m, t] = k + 1


@njit(cache=True)
def _unpack(tab: np.ndarray) -> tuple[np.ndarray, ...]:
    """(in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, d_ptr, d_p, d_v, trig_ptr, trig_t) views of :func:`tables`."""
    return (tab[tab[0]:tab[1]], tab[tab[1]:tab[2]], tab[tab[2]:tab[3]], tab[tab[3]:tab[4]], tab[tab[4]:tab[5]],
            tab[tab[5]:tab[6]], tab[tab[6]:tab[7]], tab[tab[7]:tab[8]], tab[tab[8]:tab[9]], tab[tab[9]:tab[10]],
            tab[tab[10]:tab[11]])


@njit(cache=True)
def _bit_length(v: int) -> int:
    bits = 0
    while v >> bits:
        bits += 1
    return bits


@njit(cache=True)
def _slot(key: np.uint64, bits: int) -> int:
    return np.int64((key * _GOLDEN) >> np.uint64(64 - bits))


@njit(cache=True)
def _splitmix(x: np.uint64) -> np.uint64:
    x = x + np.uint64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def _rekey(d_ptr: np.ndarray, d_p: np.ndarray, d_v: np.ndarray, width: np.ndarray, mult: np.ndarray,
           dkey: np.ndarray, states: np.ndarray, keys: np.ndarray, n: int, table: np.ndarray,
           cursor: np.ndarray) -> None:
    """Choose the multipliers from the widths (exact packing while it fits, else random, for good),
    then recompute every key, the per-transition key deltas and the hash table, in place."""
    n_p = width.shape[0]
    total = 0
    for p in range(n_p):
        total += width[p]
    if cursor[EXACT] and total <= 64:
        offset = 0
        for p in range(n_p):
            mult[p] = np.uint64(1) << np.uint64(offset)
            offset += width[p]
    else:
        cursor[EXACT] = 0
        for p in range(n_p):
            mult[p] = _splitmix(_SEED + np.uint64(p)) | np.uint64(1)
    for t in range(dkey.shape[0]):
        acc = np.uint64(0)
        for k in range(d_ptr[t], d_ptr[t + 1]):
            acc += np.uint64(d_v[k]) * mult[d_p[k]]  # wraps modulo 2**64 for negative entries
        dkey[t] = acc
    for j in range(n):
        acc = np.uint64(0)
        for p in range(n_p):
            acc += np.uint64(states[j, p]) * mult[p]
        keys[j] = acc
    _fill_table(table, keys, n)


@njit(cache=True)
def _fill_table(table: np.ndarray, keys: np.ndarray, n: int) -> None:
    """(Re)build the hash table, shape (2**k, 2) uint64, from the keys of states 0..n-1."""
    size = table.shape[0]
    bits = _bit_length(size) - 1
    table[:] = 0
    for j in range(n):
        s = _slot(keys[j], bits)
        while table[s, 1] != 0:
            s = (s + 1) & (size - 1)
        table[s, 0] = keys[j]
        table[s, 1] = np.uint64(j + 1)


@njit(cache=True)
def _start(tab: np.ndarray, m0: np.ndarray, states: np.ndarray, keys: np.ndarray, table: np.ndarray,
           out_ptr: np.ndarray, parent: np.ndarray, scratch: np.ndarray) -> None:
    """State 0 = M0; key widths: the 64 bits shared out evenly (spare bits save repacking), at
    least what M0 needs; exact packing if they fit."""
    n_p = m0.shape[0]
    n_t = tab[1] - tab[0] - 1
    cursor = scratch[:CURSOR_SIZE]
    width = scratch[CURSOR_SIZE:CURSOR_SIZE + n_p]
    mult = scratch[CURSOR_SIZE + n_p:CURSOR_SIZE + 2 * n_p].view(np.uint64)
    dkey = scratch[CURSOR_SIZE + 3 * n_p:CURSOR_SIZE + 3 * n_p + n_t].view(np.uint64)
    d_ptr, d_p, d_v = tab[tab[6]:tab[7]], tab[tab[7]:tab[8]], tab[tab[8]:tab[9]]
    even = max(1, 64 // max(n_p, 1))
    top = 0
    total = 0
    for p in range(n_p):
        states[0, p] = min(m0[p], _INT32_MAX)
        width[p] = max(even, _bit_length(m0[p]))
        total += width[p]
        top = max(top, m0[p])
    if total > 64:
        for p in range(n_p):
            width[p] = max(1, _bit_length(m0[p]))
    cursor[:] = 0
    cursor[N] = 1
    cursor[LEVEL_END] = 1
    cursor[MAX_COUNT] = top
    cursor[EXACT] = 1
    cursor[STARTED] = 1
    parent[0] = -1
    out_ptr[0] = 0
    _rekey(d_ptr, d_p, d_v, width, mult, dkey, states, keys, 1, table, cursor)


@njit(cache=True)
def _search(tab: np.ndarray, prio: np.ndarray, use_prio: bool, m0: np.ndarray, states: np.ndarray,
            keys: np.ndarray, table: np.ndarray, dst: np.ndarray, tr: np.ndarray, out_ptr: np.ndarray,
            parent: np.ndarray, trunc: np.ndarray, scratch: np.ndarray, max_states: int, budget: int) -> int:
    """Expand markings in breadth-first order, at most ``budget`` of them, from ``cursor[NEXT]``,
    in the given buffers (never reallocated here: ``ROOM`` says one is full).

    Args:
        tab: the net's :func:`tables`.
        prio: (|T|,) int64 priority levels, used if ``use_prio``: in each marking only the enabled
            transitions of the highest enabled level fire.
        m0: (|P|,) int64 initial marking (read on the first call only), counts below 2**31.
        states: (cap, |P|) int32 store; keys: (cap,) uint64; table: (2**k, 2) uint64, zeroed before
            the first call; dst: (ecap,) int64 edge targets; tr: (ecap,) int32 their
            transitions; out_ptr: (cap + 1,) int64, the edges of state i are
            ``out_ptr[i]:out_ptr[i+1]`` (sources are implicit); parent: (cap,) int64 parent edge of
            each state; trunc: (tcap,) int64 sources that lost an edge to the state limit;
            scratch: int64, zeroed before the first call: the cursor (CURSOR_SIZE entries), then per
            place a key width, a multiplier and a successor count, then per transition a key delta
            and a slot of the list of enabled transitions.
        max_states: a new successor beyond this many states is dropped (its source goes to
            ``trunc``) and the search stops at the end of the level.
        budget: most markings to expand in this call.

    Returns:
        DONE, BUDGET, ROOM or OVERFLOW; the cursor says where the search is.
    """
    n_p = states.shape[1]
    n_t = tab[1] - tab[0] - 1
    if scratch[STARTED] == 0:
        _start(tab, m0, states, keys, table, out_ptr, parent, scratch)
        if scratch[MAX_COUNT] > _INT32_MAX:
            return OVERFLOW
    in_ptr, in_p, in_w, ih_ptr, ih_p, ih_w, d_ptr, d_p, d_v, trig_ptr, trig_t = _unpack(tab)
    cursor = scratch[:CURSOR_SIZE]
    width = scratch[CURSOR_SIZE:CURSOR_SIZE + n_p]
    mult = scratch[CURSOR_SIZE + n_p:CURSOR_SIZE + 2 * n_p].view(np.uint64)
    succ = scratch[CURSOR_SIZE + 2 * n_p:CURSOR_SIZE + 3 * n_p]
    dkey = scratch[CURSOR_SIZE + 3 * n_p:CURSOR_SIZE + 3 * n_p + n_t].view(np.uint64)
    enabled = scratch[CURSOR_SIZE + 3 * n_p + n_t:CURSOR_SIZE + 3 * n_p + 2 * n_t]
    n, e, i = cursor[N], cursor[E], cursor[NEXT]
    level_end, stopping, n_trunc = cursor[LEVEL_END], cursor[STOPPING], cursor[N_TRUNC]
    top = cursor[MAX_COUNT]
    exact = cursor[EXACT] != 0
    size = table.shape[0]
    bits = _bit_length(size) - 1
    mask = size - 1
    status = DONE
    done = 0
    while True:
        if i == level_end:
            if stopping or i == n:
                break
            level_end = n
        if done == budget:
            status = BUDGET
            break
        if n + n_t > states.shape[0] or e + n_t > tr.shape[0] or 2 * (n + n_t) > size \
                or n_trunc == trunc.shape[0]:
            status = ROOM
            break
        # enabled transitions: those whose trigger place is marked, then the source transitions
        k = 0
        for p in range(n_p + 1):
            if p < n_p and states[i, p] == 0:
                continue
            for a in range(trig_ptr[p], trig_ptr[p + 1]):
                t = trig_t[a]
                ok = True
                for b in range(in_ptr[t], in_ptr[t + 1]):
                    if states[i, in_p[b]] < in_w[b]:
                        ok = False
                        break
                if ok:
                    for b in range(ih_ptr[t], ih_ptr[t + 1]):
                        if states[i, ih_p[b]] >= ih_w[b]:
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
        dropped = False
        for a in range(k):
            t = enabled[a]
            # counts of the places t raises: the int32 limit, and the key widths while exact
            repack = False
            for b in range(d_ptr[t], d_ptr[t + 1]):
                if d_v[b] > 0:
                    q = d_p[b]
                    v = np.int64(states[i, q]) + d_v[b]
                    top = max(top, v)
                    if exact and v >> width[q]:
                        width[q] = _bit_length(v)
                        repack = True
            if top > _INT32_MAX:
                status = OVERFLOW
                break
            if repack:
                _rekey(d_ptr, d_p, d_v, width, mult, dkey, states, keys, n, table, cursor)
                exact = cursor[EXACT] != 0
            key = keys[i] + dkey[t]
            if not exact:
                for p in range(n_p):
                    succ[p] = states[i, p]
                for b in range(d_ptr[t], d_ptr[t + 1]):
                    succ[d_p[b]] += d_v[b]
            s = _slot(key, bits)
            j = -1
            while table[s, 1] != 0:
                if table[s, 0] == key:
                    cand = np.int64(table[s, 1]) - 1
                    if exact:
                        j = cand
                        break
                    same = True
                    for p in range(n_p):
                        if states[cand, p] != succ[p]:
                            same = False
                            break
                    if same:
                        j = cand
                        break
                s = (s + 1) & mask
            if j < 0:
                if n == max_states:
                    dropped = True
                    stopping = 1
                    continue
                j = n
                for p in range(n_p):
                    states[j, p] = states[i, p]
                for b in range(d_ptr[t], d_ptr[t + 1]):
                    states[j, d_p[b]] += d_v[b]
                keys[j] = key
                table[s, 0] = key
                table[s, 1] = np.uint64(j + 1)
                parent[j] = e
                n += 1
            dst[e] = j
            tr[e] = t
            e += 1
        if status == OVERFLOW:
            break
        if dropped:
            trunc[n_trunc] = i
            n_trunc += 1
        out_ptr[i + 1] = e
        i += 1
        done += 1
    cursor[N], cursor[E], cursor[NEXT] = n, e, i
    cursor[LEVEL_END], cursor[STOPPING], cursor[N_TRUNC] = level_end, stopping, n_trunc
    cursor[MAX_COUNT] = top
    return status


@njit(cache=True)
def _finish(out_ptr: np.ndarray, trunc: np.ndarray, cursor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge sources, the out-edge pointers and the expanded-state mask of a finished search.

    Returns:
        src (E,) int64, non-decreasing; out_ptr (N+1,) int64 (states the search did not expand
        have no edges); expanded (N,) bool (all True when the graph is complete).
    """
    n, e, done = cursor[N], cursor[E], cursor[NEXT]
    ptr = np.empty(n + 1, np.int64)
    ptr[: done + 1] = out_ptr[: done + 1]
    ptr[done + 1:] = e
    src = np.empty(e, np.int64)
    for i in range(done):
        src[ptr[i]:ptr[i + 1]] = i
    expanded = np.zeros(n, np.bool_)
    if cursor[STOPPING]:
        expanded[:done] = True
        for k in range(cursor[N_TRUNC]):
            expanded[trunc[k]] = False
    else:
        expanded[:] = True
    return src, ptr, expanded


@njit(cache=True)
def _next_size(size: int) -> int:
    return 2 * size if size < (1 << 20) else size + size // 2


@njit(cache=True)
def _fit(a: np.ndarray, used: int) -> np.ndarray:
    """The first ``used`` entries: a view if they fill most of the buffer, else a compact copy."""
    return a[:used] if 4 * used >= 3 * a.shape[0] else a[:used].copy()


@njit(cache=True)
def run(pre: np.ndarray, inhibitor: np.ndarray, incidence: np.ndarray, m0: np.ndarray, prio: np.ndarray,
        use_prio: bool, max_states: int, report_every: int) -> tuple:  # type: ignore[type-arg]
    """The whole breadth-first search of a net (see the module docstring).

    Args:
        pre, inhibitor, incidence: (|P|, |T|) int64 matrices of the net.
        m0: (|P|,) int64 initial marking.
        prio, use_prio: (|T|,) int64 priority levels and whether to apply them (only the enabled
            transitions of the highest enabled level fire).
        max_states: a new marking beyond this many is dropped with its edge; the search then
            finishes the level and stops.
        report_every: call the progress hook (:func:`set_progress`) every this many expanded
            markings and at the end; 0 for never.

    Returns:
        ``(status, states, src, dst, tr, parent, expanded, out_ptr, complete, max_count)``: DONE or
        OVERFLOW; states (N, |P|) int32 in breadth-first order; edges src, dst (E,) int64 and tr
        (E,) int32 sorted by source then transition; parent (N,) int64 edge from the previous level
        (-1 for M0); expanded (N,) bool; out_ptr (N+1,) int64; whether the graph is complete; the
        largest token count seen.
    """
    n_p, n_t = pre.shape
    tab = tables(pre, inhibitor, incidence)
    rows = max(64, 2 * n_t)
    states = np.empty((rows, n_p), np.int32)
    keys = np.empty(rows, np.uint64)
    parent = np.empty(rows, np.int64)
    out_ptr = np.empty(rows + 1, np.int64)
    size = 128
    while size < 2 * rows:
        size *= 2
    table = np.zeros((size, 2), np.uint64)
    dst = np.empty(4 * rows, np.int64)
    tr = np.empty(4 * rows, np.int32)
    trunc = np.empty(16, np.int64)
    scratch = np.zeros(CURSOR_SIZE + 3 * n_p + 2 * n_t, np.int64)
    cursor = scratch[:CURSOR_SIZE]
    next_report = report_every if report_every > 0 else 1 << 62  # in expanded markings
    while True:
        status = _search(tab, prio, use_prio, m0, states, keys, table, dst, tr, out_ptr, parent, trunc, scratch,
                         max_states, max(1, next_report - cursor[NEXT]))
        if status == ROOM:
            n, e = cursor[N], cursor[E]
            if n + n_t > states.shape[0]:
                cap = max(n + n_t, _next_size(states.shape[0]))
                grown = np.empty((cap, n_p), np.int32)
                grown[:n] = states[:n]
                states = grown
                keys = _grow(keys, cap, n)
                parent = _grow(parent, cap, n)
                out_ptr = _grow(out_ptr, cap + 1, cursor[NEXT] + 1)
            if e + n_t > tr.shape[0]:
                cap = max(e + n_t, _next_size(tr.shape[0]))
                dst = _grow(dst, cap, e)
                tr = _grow(tr, cap, e)
            if cursor[N_TRUNC] == trunc.shape[0]:
                trunc = _grow(trunc, 2 * trunc.shape[0], cursor[N_TRUNC])
            if 2 * (n + n_t) > table.shape[0]:
                size = table.shape[0]
                while 2 * (n + n_t) > size:
                    size *= 2
                table = np.zeros((size, 2), np.uint64)
                _fill_table(table, keys, n)
            continue
        if status == OVERFLOW:
            break
        if report_every > 0:
            with objmode():
                _report(cursor[N], cursor[E])
        if status == DONE:
            break
        next_report = cursor[NEXT] + report_every
    n, e = cursor[N], cursor[E]
    table = np.zeros((1, 2), np.uint64)  # free the table and the keys before the edge arrays are built
    keys = np.zeros(1, np.uint64)
    src, ptr, expanded = _finish(out_ptr, trunc, cursor)
    return (status, _fit(states, n), src, _fit(dst, e), _fit(tr, e), _fit(parent, n), expanded, ptr,
            cursor[STOPPING] == 0, cursor[MAX_COUNT])


@njit(cache=True)
def _grow(a: np.ndarray, size: int, used: int) -> np.ndarray:
    out = np.empty(size, a.dtype)
    out[:used] = a[:used]
    return out
