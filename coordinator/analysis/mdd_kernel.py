"""Compiled multi-valued decision diagrams and saturation (internal to :mod:`.symbolic`).

Pure: no I/O. Compiled by numba (``cache=True``, in the user's cache directory, :mod:`.jit`) and
driven by :mod:`coordinator.analysis.symbolic`, which documents the results. What is here:

* **A quasi-reduced MDD store.** Levels 0 (the root's) to K − 1, one per variable (a place, or a
  group of places: :mod:`.symbolic` decides), level K holds the terminal. Node 0 is the empty set,
  node 1 the terminal {ε}; a node at level k has children at level k + 1 for the local values
  0 .. dom[k] − 1, stored up to its last non-empty child (``size``). Nodes are unique (a hash table
  over level and children), so two sets are equal iff their nodes are (Bryant 1986, for MDDs:
  Kam, Villa, Brayton, Sangiovanni-Vincentelli 1998). No node is ever empty but node 0.
* **Saturation** (Ciardo, Lüttgen, Siminiceanu 2001; constrained: Zhao, Ciardo 2009): an event (a
  transition) has a top and a bottom level (the highest and lowest levels it reads or changes) and a
  local function per level in between (``next``: local value → local value, or −1 where the event
  is disabled). A node at level k is saturated when its set is closed under every event whose top
  is at k or below, and its children are saturated: ``SAT`` saturates the children first, then
  fires the events of level k on the node in place until nothing changes (``NODE``); ``FIRE``
  applies one event to a saturated node below its top and saturates the result. A constraint node
  (same level) keeps every intermediate set inside it (backward reachability inside the reachable
  set). With saturation off, ``FIRE`` is a plain image: ``IMAGE`` unites every event's image of a
  set (breadth-first layers for witnesses), or **chains** them (Roig, Cortadella, Pastor 1995):
  each event fires on the set so far, the result added before the next fires, the events of the
  deepest tops first or the root's first, so one call can go many steps deep.
* **Set operations** (``APPLY``: union, intersection, difference) and ``RESTRICT`` (the markings of a
  set in which an event is enabled, or disabled).
* **The dead markings of a set in one pass** (``DEAD``): down each path, the set of the events'
  residual conditions still pending (:func:`dead_tables`), numbered as met; a node's result is
  cached on the node and that set's number.
* **Counts** that build no node: the paths of a set (:func:`count`), and per event the paths on
  which it is enabled (:func:`enabled_counts`), exact modulo primes; the most paths below any node
  of the store (:func:`most_paths`, a float).

numba cannot load a recursive function from its cache (it crashes: checked on numba 0.68), so the
recursion runs on an explicit stack of frames, each with a program counter. The loop over the
frames (``_steps``) never reassigns an array and hands none to a helper in its inner steps (the
helpers it inlines take numbers, or run once per new node): numba counts the references of an
array variable at each such place, with an atomic instruction, and on Peterson-PT-4 that counting
took three quarters of the saturation (39 s; 7.5 s without it). The buffers are grown between two
calls of ``_steps``, in :func:`run`; a frame's node under
construction lives in an arena of child buffers with stack discipline. Results of operations go
to a lossy computed table (a cache of two-entry buckets; an entry's two keys and its value side
by side, so a look-up reads one or two cache lines; a new key goes first in its bucket and moves
the older entry to second, dropping the one that was there), which never changes a result, only
what is recomputed. (A direct-mapped table, as CUDD's, drops an entry at every collision: on
FMS-PT-00200, 239 million steps of saturation instead of 75 million.) Buffers grow inside the one
compiled call, within a byte budget: the computed table stops growing where it would pass it, and
status ``MEMORY`` comes when the nodes' own buffers would. The store is handed back to the caller,
who passes it to the next call; nothing is ever freed (the store lives as long as one analysis).
A grown buffer is made by numpy, in an ``objmode`` block, not by numba: numpy asks Linux for
transparent huge pages for an array of 4 MiB or more (``madvise``, honoured where the system's
setting is ``madvise``, as on the machine measured, or ``always``), numba's allocator does not,
and the unique and computed tables are read at random, so with 4 KiB pages nearly every look-up
misses the TLB (TCPcondis-PT-15, the first order's saturation alone, six alternating pairs: 31
to 54 s with huge pages, 53 to 59 s without, faster in every pair; docs/BENCHMARKS.md).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from coordinator.analysis import jit

jit.configure()  # numba's cache in the user's cache directory: before numba is imported

from numba import njit, objmode  # noqa: E402

__all__ = ["APPLY_DIFF", "APPLY_INTER", "APPLY_UNION", "EMPTY", "Flag", "IMAGE_CHAIN_DEEP", "IMAGE_CHAIN_ROOT",
           "IMAGE_EACH", "MEMORY", "MODE_APPLY", "MODE_DEAD", "MODE_IMAGE", "MODE_RESTRICT", "MODE_SATURATE",
           "NO_CONSTRAINT", "OK", "OVERFLOW", "STOPPED", "TERMINAL", "WIDE", "add_path", "clear_cache", "count",
           "dead_tables", "enabled_counts", "enabling_values", "max_weight", "most_paths", "new_store", "node_of_path",
           "presence", "run", "set_watch", "subset", "suffix_ids", "watch", "wider_dead_tables"]

EMPTY, TERMINAL = 0, 1
NO_CONSTRAINT = -1
#: run statuses: done; a firing left a level's values; the byte budget; the deadline (or the watch);
#: MODE_DEAD's table of pending conditions is full
OK, OVERFLOW, MEMORY, STOPPED, WIDE = 0, 1, 2, 3, 4
#: loop steps between two calls of the watch (in the interpreter)
_WATCH_STEPS = 1 << 20
#: what :func:`run` computes
MODE_SATURATE, MODE_IMAGE, MODE_APPLY, MODE_RESTRICT, MODE_DEAD = 0, 1, 2, 3, 4
APPLY_UNION, APPLY_INTER, APPLY_DIFF = 0, 1, 2
#: what MODE_IMAGE computes: the union of every event's image of the set; the set and its chained
#: images, the events of the deepest tops first, or of the root's first
IMAGE_EACH, IMAGE_CHAIN_DEEP, IMAGE_CHAIN_ROOT = 0, 1, 2
#: why :func:`_steps` returned: a buffer of the store is full; done (or a status is set)
_FULL, _DONE = 0, 1
#: frame kinds
_SAT, _FIRE, _NODE, _APPLY, _RESTRICT, _IMAGE, _DEAD = 0, 1, 2, 3, 4, 5, 6
#: operation tags in the computed table
_OP_SAT, _OP_FIRE, _OP_APPLY, _OP_RESTRICT, _OP_IMAGE, _OP_DEAD = 1, 2, 3, 4, 5, 6
#: meta array layout: nodes used, kid slots used, entries of the unique table, level of an overflow
META_NODES, META_KIDS, META_UNIQUE, META_OVERFLOW_LEVEL, META_CT_USED = 0, 1, 2, 3, 4
META_SIZE = 5
#: largest computed table (entries of 24 bytes)
_CT_MAX = 1 << 24
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLD = np.uint64(0x9E3779B97F4A7C15)


_watch = threading.local()


class Flag(Protocol):
    """What :func:`set_watch` reads to cancel: a :class:`threading.Event`, or any object with its
    ``is_set``."""

    def is_set(self) -> bool: ...


def set_watch(deadline: float | None, progress: Callable[[int], None] | None = None,
              cancel: Flag | None = None) -> None:
    """Stop this thread's :func:`run` calls at ``deadline`` (``time.monotonic()`` seconds; None: no
    deadline) or once ``cancel`` is set (another thread's decision), and report the store's node
    count to ``progress`` every million steps or so."""
    _watch.deadline = deadline
    _watch.progress = progress
    _watch.cancel = cancel


def watch() -> tuple[float | None, Callable[[int], None] | None, Flag | None]:
    """This thread's ``(deadline, progress, cancel)`` as :func:`set_watch` set them (all None when
    never set), for a caller that narrows the deadline for a while and then restores them."""
    return getattr(_watch, "deadline", None), getattr(_watch, "progress", None), getattr(_watch, "cancel", None)


def _tick(nodes: int) -> int:
    """Called from :func:`run` in the interpreter: 1 to stop (past the deadline, or cancelled), else
    0. Ctrl-C raises here (in the main thread)."""
    progress = getattr(_watch, "progress", None)
    if progress is not None:
        progress(int(nodes))
    cancel = getattr(_watch, "cancel", None)
    if cancel is not None and cancel.is_set():
        return 1
    deadline = getattr(_watch, "deadline", None)
    return int(deadline is not None and time.monotonic() > deadline)


def new_store(dom: np.ndarray, path: np.ndarray) -> tuple[tuple[np.ndarray, ...], int]:
    """A fresh store ``(meta, level, offset, size, kids, unique, ct)`` with nodes 0
    (empty), 1 (terminal) and the single path of the level values ``path`` (the initial marking),
    and that path's root node. The computed table (``ct_*``) is part of the store, so that a call
    stopped at its deadline resumes from the results it had (:func:`clear_cache` when the events
    change)."""
    n_levels = dom.shape[0]
    # a power of two: a slot of the unique table is a hash masked by the table's size less one, and
    # every buffer grows by doubling (with 4 * n_levels + 16 nodes, a net of over 1,020 levels had a
    # table whose mask reached 4,096 of its slots, and the search for a free slot never ended)
    nodes = 1 << max(12, (4 * n_levels + 16 - 1).bit_length())
    meta = np.zeros(META_SIZE, np.int64)
    level = np.zeros(nodes, np.int32)
    offset = np.zeros(nodes, np.int64)
    size = np.zeros(nodes, np.int32)
    kids = np.zeros(max(nodes * 2, 4 * int(dom.sum()) + 16), np.int32)
    unique = np.zeros(4 * nodes, np.int32)
    meta[META_NODES] = 2
    node, level, offset, size, kids, unique = add_path(np.asarray(path, dtype=np.int64), np.asarray(dom, np.int64),
                                                       meta, level, offset, size, kids, unique)
    ct = np.zeros((1 << 12, 3), np.int64)
    ct[:, 0] = -1
    return (meta, level, offset, size, kids, unique, ct), int(node)


def clear_cache(store: tuple[np.ndarray, ...]) -> None:
    """Forget the computed table of a store (its results depend on the events of the calls)."""
    store[0][META_CT_USED] = 0
    store[6][:, 0] = -1


def dead_tables(dom: np.ndarray, ev_top: np.ndarray, ev_bot: np.ndarray, ev_slot_ptr: np.ndarray,
                ev_slot: np.ndarray, slot_ptr: np.ndarray, nxt: np.ndarray, max_sets: int = 1 << 19,
                max_items: int = 1 << 22) -> tuple[np.ndarray, ...] | None:
    """The tables of MODE_DEAD for a set of events (arrays as :func:`run` takes them).

    An event is enabled in a marking when each of its *literals* holds: at each level where its
    local function disables some value, the marking's local value is one it maps. Its literals from
    one on, in level order, are a *residual*, numbered once for every event with the same ones (the
    events of one shared place below, on many nets). MODE_DEAD walks a set from the root with the
    set of residuals pending on the path (their events enabled by the levels above); a residual
    whose last literal holds ends the path, the marking enabling its event. The sets met are numbered
    as the call goes, at most ``max_sets`` of ``max_items`` residuals in all (status WIDE beyond).

    Returns:
        ``dz`` for :func:`run`: (residual's level, residual after it (0: none left), offset of its
        mask, masks (1: the value holds), first residual of the events whose first literal is at
        each level (pointers, shape (K + 1,), and residuals), the sets' pointers, items and hash
        table, and ``[sets, items]`` used), all int64; None when an event has no literal (it is
        enabled in every marking: no marking is dead).
    """
    n_levels = dom.shape[0]
    res: dict[tuple[int, int, int], int] = {}
    masks: dict[tuple[int, bytes], int] = {}
    r_level, r_next, r_mask_ptr = [-1], [0], [0]  # residual 0: nothing left to hold
    flat: list[np.ndarray] = []
    used = 0
    starts: list[set[int]] = [set() for _ in range(n_levels)]
    n_ev = ev_top.shape[0]
    # every (event, level) with a local function, at once: a literal where the function maps fewer
    # values than the level's domain (those of one event are consecutive, in level order)
    pos = np.flatnonzero(ev_slot[:int(ev_slot_ptr[n_ev]) if n_ev else 0] >= 0)
    ev_of = np.searchsorted(ev_slot_ptr, pos, side="right") - 1
    lev = ev_top[ev_of] + pos - ev_slot_ptr[ev_of]
    fid = ev_slot[pos]
    mapped = np.zeros(nxt.shape[0] + 1, np.int64)
    np.cumsum(nxt >= 0, out=mapped[1:])
    lit = np.flatnonzero(mapped[slot_ptr[fid] + dom[lev]] - mapped[slot_ptr[fid]] < dom[lev])
    first = np.searchsorted(ev_of[lit], np.arange(n_ev + 1))
    if n_ev and (np.diff(first) == 0).any():  # an event with no literal
        return None
    mask_of: dict[tuple[int, int], int] = {}  # (level, function) → its mask's offset
    for e in range(n_ev):
        r = 0
        for i in lit[first[e]:first[e + 1]][::-1].tolist():
            k, f = int(lev[i]), int(fid[i])
            m = mask_of.get((k, f))
            if m is None:
                holds = nxt[slot_ptr[f]:slot_ptr[f] + dom[k]] >= 0
                m = masks.get((k, holds.tobytes()))
                if m is None:
                    m = masks[(k, holds.tobytes())] = used
                    flat.append(holds.astype(np.int64))
                    used += holds.shape[0]
                mask_of[(k, f)] = m
            rid = res.get((k, m, r))
            if rid is None:
                rid = res[(k, m, r)] = len(r_level)
                r_level.append(k)
                r_next.append(r)
                r_mask_ptr.append(m)
            r = rid
        starts[int(lev[lit[first[e]]])].add(r)
    start_ptr = np.zeros(n_levels + 1, np.int64)
    start_ptr[1:] = np.cumsum([len(x) for x in starts])
    start = np.array([r for x in starts for r in sorted(x)], np.int64)
    return wider_dead_tables((np.array(r_level, np.int64), np.array(r_next, np.int64), np.array(r_mask_ptr, np.int64),
                              np.concatenate(flat) if flat else np.zeros(1, np.int64), start_ptr, start),
                             max_sets, max_items)


def wider_dead_tables(dz: tuple[np.ndarray, ...], max_sets: int, max_items: int) -> tuple[np.ndarray, ...]:
    """MODE_DEAD's tables ``dz`` (:func:`dead_tables`) with its residuals as they are and empty
    tables of sets: at most ``max_sets`` sets of ``max_items`` residuals in all (a call that met
    status WIDE runs again on larger ones without the residuals built again)."""
    s_ptr = np.zeros(max_sets + 1, np.int64)  # set 0: the empty set
    s_hash = np.full(2 * max_sets, -1, np.int64)
    s_meta = np.array([1, 0], np.int64)
    return (*dz[:6], s_ptr, np.zeros(max_items, np.int64), s_hash, s_meta)


@njit(cache=True, inline="always")
def _mix(x: np.uint64) -> np.uint64:
    x = (x ^ (x >> np.uint64(30))) * _M1
    x = (x ^ (x >> np.uint64(27))) * _M2
    return x ^ (x >> np.uint64(31))


@njit(cache=True, inline="always")
def _node_hash(k: int, buf: np.ndarray, off: int, n: int) -> np.uint64:
    h = _mix(np.uint64(k + 1) * _GOLD)
    for i in range(n):
        h = _mix(h ^ (np.uint64(buf[off + i]) + np.uint64(i) * _GOLD))
    return h


@njit(cache=True, inline="always")
def _slot(k0: int, k1: int, mask: int) -> int:
    return np.int64(_mix(_mix(np.uint64(k0) * _GOLD) ^ np.uint64(k1)) & np.uint64(mask))  # type: ignore[return-value]


@njit(cache=True, inline="always")
def _checkin(k: int, arena: np.ndarray, b0: int, n: int, meta: np.ndarray, level: np.ndarray,
             offset: np.ndarray, size: np.ndarray, kids: np.ndarray, unique: np.ndarray) -> int:
    """The unique node at level k with children ``arena[b0:b0 + n]`` (trailing empties trimmed):
    found in the hash table, or added (the caller made room for one node)."""
    while n > 0 and arena[b0 + n - 1] == EMPTY:
        n -= 1
    if n == 0:
        return EMPTY
    mask = unique.shape[0] - 1
    s = np.int64(_node_hash(k, arena, b0, n) & np.uint64(mask))
    while unique[s] != 0:
        nd = unique[s]
        if level[nd] == k and size[nd] == n:
            o = offset[nd]
            same = True
            for i in range(n):
                if kids[o + i] != arena[b0 + i]:
                    same = False
                    break
            if same:
                return nd  # type: ignore[no-any-return]
        s = (s + 1) & mask
    r = meta[META_NODES]
    nk = meta[META_KIDS]
    level[r] = k
    offset[r] = nk
    size[r] = n
    for i in range(n):
        kids[nk + i] = arena[b0 + i]
    meta[META_KIDS] = nk + n
    meta[META_NODES] = r + 1
    meta[META_UNIQUE] += 1
    unique[s] = r
    return r  # type: ignore[no-any-return]


@njit(cache=True, inline="always")
def _copy(dst: np.ndarray, src: np.ndarray, n: int) -> None:
    """``dst[:n] = src[:n]`` element by element: a slice copy compiles numba's text for shape
    errors, seconds of a first compile."""
    for i in range(n):
        dst[i] = src[i]


@njit(cache=True)
def _rehash(unique: np.ndarray, n_nodes: int, level: np.ndarray, offset: np.ndarray, size: np.ndarray,
            kids: np.ndarray) -> None:
    mask = unique.shape[0] - 1
    for nd in range(2, n_nodes):
        s = np.int64(_node_hash(level[nd], kids, offset[nd], size[nd]) & np.uint64(mask))
        while unique[s] != 0:
            s = (s + 1) & mask
        unique[s] = nd


@njit(cache=True)
def add_path(values: np.ndarray, dom: np.ndarray, meta: np.ndarray, level: np.ndarray, offset: np.ndarray,
             size: np.ndarray, kids: np.ndarray, unique: np.ndarray) -> tuple:  # type: ignore[type-arg]
    """The node of the set holding the single path ``values`` ((K,) int64, a value per level: one
    marking), added to the store, its buffers grown as needed (a few nodes: no byte budget).

    Returns:
        ``(node, level, offset, size, kids, unique)``, the buffers possibly new.
    """
    n_levels = values.shape[0]
    if meta[META_NODES] + n_levels + 2 > level.shape[0]:
        gn = max(2 * level.shape[0], meta[META_NODES] + n_levels + 2)
        nl = np.zeros(gn, np.int32)
        no = np.zeros(gn, np.int64)
        ns = np.zeros(gn, np.int32)
        _copy(nl, level, level.shape[0])
        _copy(no, offset, offset.shape[0])
        _copy(ns, size, size.shape[0])
        level, offset, size = nl, no, ns
    need = meta[META_KIDS] + dom.sum()
    if need > kids.shape[0]:
        nk = np.zeros(max(2 * kids.shape[0], need), np.int32)
        _copy(nk, kids, kids.shape[0])
        kids = nk
    gu = unique.shape[0]
    while 2 * (meta[META_UNIQUE] + n_levels + 1) > gu:
        gu *= 2
    if gu != unique.shape[0]:
        unique = np.zeros(gu, np.int32)
        _rehash(unique, meta[META_NODES], level, offset, size, kids)
    width = 1
    for k in range(n_levels):  # the widest level (a net of fixed places alone has none)
        width = max(width, dom[k])
    buf = np.zeros(width, np.int32)
    node = TERMINAL
    for k in range(n_levels - 1, -1, -1):
        for x in range(dom[k]):
            buf[x] = EMPTY
        buf[values[k]] = node
        node = _checkin(k, buf, 0, dom[k], meta, level, offset, size, kids, unique)
    return node, level, offset, size, kids, unique


@njit(cache=True, inline="always")
def _prepare(ty: int, k: int, a: int, b: int, c: int, e: int, saturating: bool, n_levels: int,
             bot: int) -> tuple[int, int, int, int, int]:
    """For a call of kind ``ty``: its result when it is immediate (else -1), its operands in canonical
    order, and its two computed-table key words. ``bot``: event e's bottom level (FIRE, RESTRICT), or
    the number of events whose first literal is at level k or below (DEAD); a number, not the table, so
    that the inlined call keeps no reference count."""
    if ty == _SAT:
        if a == EMPTY or k == n_levels:
            return a, a, b, 0, 0
        return -1, a, b, (_OP_SAT << 40) + a, c
    if ty == _FIRE:
        # below the event's bottom a firing changes nothing, but under a constraint the node is
        # moved to another value, whose constraint it must be cut to (and saturated within): the
        # frame then walks down with the identity; a node that is its constraint stays as it is
        if a == EMPTY or k == n_levels or (k > bot and (c == NO_CONSTRAINT or c == a)):
            return a, a, b, 0, 0
        return -1, a, b, ((_OP_FIRE if saturating else _OP_IMAGE) << 40) + a, (c << 24) + e
    if ty == _APPLY:
        if e == APPLY_UNION:
            if a == EMPTY or a == b:
                return b, a, b, 0, 0
            if b == EMPTY:
                return a, a, b, 0, 0
        elif e == APPLY_INTER:
            if a == EMPTY or b == EMPTY:
                return EMPTY, a, b, 0, 0
            if a == b:
                return a, a, b, 0, 0
        else:
            if a == EMPTY or a == b:
                return EMPTY, a, b, 0, 0
            if b == EMPTY:
                return a, a, b, 0, 0
        if e != APPLY_DIFF and a > b:
            a, b = b, a
        return -1, a, b, (_OP_APPLY << 40) + (e << 36) + a, b
    if ty == _DEAD:
        # b: the set of pending residuals; bot: the events whose first literal is at level k or below
        if a == EMPTY or k == n_levels or (b == 0 and bot == 0):
            return a, a, b, 0, 0
        return -1, a, b, (_OP_DEAD << 40) + a, b
    # _RESTRICT: b is 1 to keep the markings where event e is enabled, 0 where it is disabled
    if a == EMPTY:
        return EMPTY, a, b, 0, 0
    if k > bot:
        return (a if b == 1 else EMPTY), a, b, 0, 0
    return -1, a, b, (_OP_RESTRICT << 40) + a, (e << 2) + b


@njit(cache=True, inline="always")
def _full(n_nodes: int, n_kids: int, n_unique: int, ct_used: int, node_cap: int, kid_cap: int, unique_cap: int,
          ct_cap: int, max_dom: int | np.int64, ct_max: int) -> bool | np.bool_:
    """Whether a buffer of the store must grow before the next step (room for one more node of
    ``max_dom`` children, the unique table at most half full, the computed table at most a quarter
    full below ``ct_max`` entries); numbers only, so that the loop keeps no reference count."""
    return (n_nodes + 2 > node_cap or n_kids + max_dom > kid_cap or 2 * (n_unique + 1) > unique_cap
            or (4 * ct_used > ct_cap and ct_cap < ct_max))


@njit(cache=True, nogil=True)
def _steps(dom: np.ndarray, ev_top: np.ndarray, ev_bot: np.ndarray, ev_slot_ptr: np.ndarray, ev_slot: np.ndarray,
           slot_ptr: np.ndarray, nxt: np.ndarray, evtop: np.ndarray,
           dom_ptr: np.ndarray, byval_ptr: np.ndarray, byval: np.ndarray,
           dz: tuple[np.ndarray, ...], meta: np.ndarray, level: np.ndarray, offset: np.ndarray, size: np.ndarray,
           kids: np.ndarray, unique: np.ndarray, ct: np.ndarray, check_overflow: bool, saturating: bool,
           max_dom: int | np.int64, f_ty: np.ndarray,
           f_pc: np.ndarray, f_k: np.ndarray, f_a: np.ndarray, f_b: np.ndarray, f_c: np.ndarray, f_e: np.ndarray,
           f_i: np.ndarray, f_j: np.ndarray, f_buf: np.ndarray, f_k0: np.ndarray, f_k1: np.ndarray,
           f_s: np.ndarray, arena: np.ndarray, depth: int, atop: int | np.int64, ret: int, ct_used: int,
           steps: int | np.int64, ct_max: int) -> tuple:  # type: ignore[type-arg]
    """The steps of :func:`run` on its stack of frames, until the stack is empty, a status is set,
    or a buffer of the store is full (``_FULL``: :func:`run` grows it and calls again). No array is
    reassigned here: numba then keeps no reference count in the loop (with the buffers grown in
    the loop itself, counting references took three quarters of the time of a saturation).

    Returns:
        ``(why, depth, atop, ret, status, ct_used, steps)``: why is ``_FULL`` or ``_DONE``."""
    n_levels = dom.shape[0]
    status = OK
    ccap = ct.shape[0]
    cmask = ccap - 1
    r_level, r_next, r_mask_ptr, r_mask, st_ptr, st, s_ptr, s_items, s_hash, s_meta = dz
    # a call: the caller sets (cty, ck, ca, cb, cc, ce) and its own continuation pc, then jumps to
    # ``call``; an immediate or cached result comes back in ret at once, else a frame is pushed
    while depth > 0:
        steps += 1
        if steps == _WATCH_STEPS:
            steps = 0
            stop = 0
            with objmode(stop="int64"):
                stop = _tick(meta[META_NODES])
            if stop != 0:
                status = STOPPED
                break
        n_nodes = meta[META_NODES]
        if _full(n_nodes, meta[META_KIDS], meta[META_UNIQUE], ct_used, level.shape[0], kids.shape[0],
                 unique.shape[0], ccap, max_dom, ct_max):
            return _FULL, depth, atop, ret, status, ct_used, steps
        d = depth - 1
        ty = f_ty[d]
        pc = f_pc[d]
        k = f_k[d]
        # what this step calls, if anything (cty >= 0)
        cty = -1
        ck = 0
        ca = 0
        cb = 0
        cc = NO_CONSTRAINT
        ce = 0
        if ty == _NODE:
            # Ciardo's loop: the dirty values of the node (its own flags, after the node's buffer in
            # the arena) are fired by every event of the level enabled on them until none is left;
            # the events of level k enabled on value i: byval[byval_ptr[dom_ptr[k] + i]:...[... + 1]]
            vk = dom_ptr[k]
            b0 = f_buf[d]
            fl = f_j[d]
            if pc == 0:
                f_j[d] = atop
                fl = atop
                for x in range(dom[k]):
                    arena[atop + x] = 1 if arena[b0 + x] != EMPTY else 0
                atop += dom[k]
                f_i[d] = -1
                f_e[d] = 0
                f_s[d] = 0
                pc = 2
            if pc == 3:  # a firing is back
                i = f_i[d]
                e = byval[f_e[d]]
                j = nxt[slot_ptr[ev_slot[ev_slot_ptr[e]]] + i]
                if ret != EMPTY:
                    if j >= dom[k]:
                        status = OVERFLOW
                        meta[META_OVERFLOW_LEVEL] = k
                        break
                    f_b[d] = j
                    cty = _APPLY
                    ck = k + 1
                    ca = arena[b0 + j]
                    cb = ret
                    ce = APPLY_UNION
                    f_pc[d] = 4
                else:
                    f_e[d] += 1
                    pc = 2
            elif pc == 4:  # the union is back
                j = f_b[d]
                if ret != arena[b0 + j]:
                    arena[b0 + j] = ret
                    arena[fl + j] = 1
                    f_s[d] = min(f_s[d], j)
                f_e[d] += 1
                pc = 2
            while pc == 2 and cty < 0:
                ei = f_e[d]
                i = f_i[d]
                if i < 0 or ei == byval_ptr[vk + i + 1]:  # the next dirty value: the lowest, searched
                    i = -1  # from f_s (none below it), so a sweep upwards reads each value once
                    for x in range(f_s[d], dom[k]):
                        if arena[fl + x] != 0:
                            i = x
                            break
                    if i < 0:
                        pc = 5
                        break
                    f_s[d] = i + 1
                    arena[fl + i] = 0
                    f_i[d] = i
                    f_e[d] = byval_ptr[vk + i]
                    continue
                v = arena[b0 + i]
                e = byval[ei]
                j = nxt[slot_ptr[ev_slot[ev_slot_ptr[e]]] + i]  # the top level always has a function
                if v == EMPTY or j < 0 or (j >= dom[k] and not check_overflow):
                    f_e[d] = ei + 1
                    continue
                cons = f_c[d]  # child j of the constraint (no array passed to a helper: module docstring)
                if cons != NO_CONSTRAINT:
                    cons = kids[offset[cons] + j] if j < size[cons] else EMPTY
                    if cons == EMPTY:
                        f_e[d] = ei + 1
                        continue
                cty = _FIRE
                ck = k + 1
                ca = v
                cc = cons
                ce = e
                f_pc[d] = 3
            if pc == 5:
                atop = fl
                depth -= 1
                continue
        elif ty == _IMAGE:
            if pc == 0:
                f_i[d] = 0
                f_j[d] = EMPTY if f_e[d] == IMAGE_EACH else f_a[d]
                pc = 1
            elif pc == 2:  # an event's image is back: add it
                cty = _APPLY
                ck = 0
                ca = f_j[d]
                cb = ret
                ce = APPLY_UNION
                f_pc[d] = 3
            elif pc == 3:
                f_j[d] = ret
                f_i[d] += 1
                pc = 1
            if pc == 1:
                e = f_i[d]
                if e == ev_top.shape[0]:
                    ret = f_j[d]
                    depth -= 1
                    continue
                if f_e[d] == IMAGE_CHAIN_DEEP:  # evtop is sorted by top
                    e = evtop[ev_top.shape[0] - 1 - e]
                elif f_e[d] == IMAGE_CHAIN_ROOT:
                    e = evtop[e]
                cty = _FIRE
                ck = 0
                ca = f_a[d] if f_e[d] == IMAGE_EACH else f_j[d]
                cc = f_c[d]
                ce = e
                f_pc[d] = 2
        else:
            b0 = f_buf[d]
            if pc == 0:
                f_buf[d] = atop
                b0 = atop
                for x in range(dom[k]):
                    arena[atop + x] = EMPTY
                atop += dom[k]
                f_i[d] = 0
                pc = 1
            elif pc == 2:  # a child's result is back
                i = f_i[d]
                if ty == _FIRE:
                    if ret != EMPTY:
                        j = f_j[d]
                        if j >= dom[k]:
                            status = OVERFLOW
                            meta[META_OVERFLOW_LEVEL] = k
                            break
                        cur = arena[b0 + j]
                        if cur == EMPTY:
                            arena[b0 + j] = ret
                        else:  # two values fire to the same one (a reset arc): union
                            cty = _APPLY
                            ck = k + 1
                            ca = cur
                            cb = ret
                            ce = APPLY_UNION
                            f_pc[d] = 3
                else:
                    arena[b0 + i] = ret
                if cty < 0:
                    f_i[d] = i + 1
                    pc = 1
            elif pc == 3:
                arena[b0 + f_j[d]] = ret
                f_i[d] += 1
                pc = 1
            while pc == 1 and cty < 0:
                # the next child to compute, or the node is complete
                i = f_i[d]
                x = f_a[d]
                if ty == _APPLY:
                    op = f_e[d]
                    y = f_b[d]
                    n = max(size[x], size[y]) if op == APPLY_UNION else (
                        min(size[x], size[y]) if op == APPLY_INTER else size[x])
                    if i >= n:
                        pc = 9
                        break
                    cty = _APPLY
                    ck = k + 1
                    ca = kids[offset[x] + i] if i < size[x] else EMPTY
                    cb = kids[offset[y] + i] if i < size[y] else EMPTY
                    ce = op
                    f_pc[d] = 2
                    break
                if i >= size[x]:
                    if ty == _SAT or (ty == _FIRE and saturating):
                        pc = 8  # saturate the node's own events, then check it in
                    else:
                        pc = 9
                    break
                ch = kids[offset[x] + i]
                if ch == EMPTY:
                    f_i[d] = i + 1
                    continue
                if ty == _SAT:
                    cty = _SAT
                    ck = k + 1
                    ca = ch
                    cc = f_c[d]
                    if cc != NO_CONSTRAINT:
                        cc = kids[offset[cc] + i] if i < size[cc] else EMPTY
                    f_pc[d] = 2
                elif ty == _FIRE:
                    e = f_e[d]
                    j = i
                    if ev_top[e] <= k <= ev_bot[e]:
                        sl = ev_slot[ev_slot_ptr[e] + k - ev_top[e]]
                        if sl >= 0:
                            j = nxt[slot_ptr[sl] + i]
                    if j < 0 or (j >= dom[k] and not check_overflow):
                        f_i[d] = i + 1
                        continue
                    cons = f_c[d]
                    if cons != NO_CONSTRAINT:
                        cons = kids[offset[cons] + j] if j < size[cons] else EMPTY
                        if cons == EMPTY:
                            f_i[d] = i + 1
                            continue
                    f_j[d] = j
                    cty = _FIRE
                    ck = k + 1
                    ca = ch
                    cc = cons
                    ce = e
                    f_pc[d] = 2
                elif ty == _RESTRICT:
                    e = f_e[d]
                    if k >= ev_top[e]:
                        sl = ev_slot[ev_slot_ptr[e] + k - ev_top[e]]
                        if sl >= 0 and nxt[slot_ptr[sl] + i] < 0:
                            arena[b0 + i] = EMPTY if f_b[d] == 1 else ch
                            f_i[d] = i + 1
                            continue
                    cty = _RESTRICT
                    ck = k + 1
                    ca = ch
                    cb = f_b[d]
                    ce = e
                    f_pc[d] = 2
                else:  # _DEAD: the residuals pending below value i, sorted and once each, after the free end
                    s = f_b[d]  # of the sets' items; the set is then found, or added, in the sets' hash table
                    base = s_meta[1]
                    n = 0
                    killed = False
                    q = s_ptr[s]
                    qs = st_ptr[k]
                    while True:
                        if q < s_ptr[s + 1]:
                            r = s_items[q]
                            q += 1
                        elif qs < st_ptr[k + 1]:
                            r = st[qs]
                            qs += 1
                        else:
                            break
                        if r_level[r] == k:
                            if r_mask[r_mask_ptr[r] + i] == 0:
                                continue  # its event is disabled in these markings
                            r = r_next[r]
                            if r == 0:  # its event is enabled: no marking below is dead
                                killed = True
                                break
                        if base + n >= s_items.shape[0]:
                            status = WIDE
                            break
                        x = base + n
                        while x > base and s_items[x - 1] > r:
                            x -= 1
                        if x > base and s_items[x - 1] == r:
                            continue
                        for y in range(base + n, x, -1):
                            s_items[y] = s_items[y - 1]
                        s_items[x] = r
                        n += 1
                    if status != OK:
                        break
                    if killed:
                        arena[b0 + i] = EMPTY
                        f_i[d] = i + 1
                        continue
                    sid = 0
                    if n > 0:
                        hm = s_hash.shape[0] - 1
                        hs = np.int64(_node_hash(0, s_items, base, n) & np.uint64(hm))
                        sid = -1
                        while s_hash[hs] >= 0:
                            c2 = s_hash[hs]
                            if s_ptr[c2 + 1] - s_ptr[c2] == n:
                                same = True
                                for y in range(n):
                                    if s_items[s_ptr[c2] + y] != s_items[base + y]:
                                        same = False
                                        break
                                if same:
                                    sid = c2
                                    break
                            hs = (hs + 1) & hm
                        if sid < 0:
                            ns = s_meta[0]
                            if ns + 2 > s_ptr.shape[0] or 2 * (ns + 1) > s_hash.shape[0]:
                                status = WIDE
                                break
                            sid = ns
                            s_ptr[ns + 1] = base + n
                            s_hash[hs] = ns
                            s_meta[0] = ns + 1
                            s_meta[1] = base + n
                    cty = _DEAD
                    ck = k + 1
                    ca = ch
                    cb = sid
                    f_pc[d] = 2
            if status != OK:
                break
            if pc == 8:
                f_pc[d] = 9
                f_ty[depth] = _NODE
                f_pc[depth] = 0
                f_k[depth] = k
                f_buf[depth] = b0
                f_c[depth] = f_c[d]
                depth += 1
                continue
            if pc == 9:
                # check the node in, remember the result, free the buffer
                r = _checkin(k, arena, b0, dom[k], meta, level, offset, size, kids, unique)
                key0 = f_k0[d]
                key1 = f_k1[d]
                for twice in range(2 if ty == _SAT else 1):
                    if twice == 1:  # a saturated node is its own saturation
                        key0 = (_OP_SAT << 40) + r
                    # a bucket of two entries, the newer first: a new key moves the older one out
                    s = _slot(key0, key1, cmask - 1)
                    if ct[s + 1, 0] == key0 and ct[s + 1, 1] == key1:
                        ct[s + 1, 2] = r
                        continue
                    if not (ct[s, 0] == key0 and ct[s, 1] == key1):
                        if ct[s, 0] != -1:
                            if ct[s + 1, 0] == -1:
                                ct_used += 1
                            ct[s + 1, 0] = ct[s, 0]
                            ct[s + 1, 1] = ct[s, 1]
                            ct[s + 1, 2] = ct[s, 2]
                        else:
                            ct_used += 1
                    ct[s, 0] = key0
                    ct[s, 1] = key1
                    ct[s, 2] = r
                atop = b0
                depth -= 1
                ret = r
                continue
        if cty < 0:
            f_pc[d] = pc
            continue
        # the call: immediate, cached, or a new frame
        quick, ca, cb, key0, key1 = _prepare(cty, ck, ca, cb, cc, ce, saturating, n_levels,
                                              ev_bot[ce] if cty == _FIRE or cty == _RESTRICT else (
                                                  st_ptr[n_levels] - st_ptr[ck] if cty == _DEAD else 0))
        if quick < 0:
            s = _slot(key0, key1, cmask - 1)
            if ct[s, 0] == key0 and ct[s, 1] == key1:
                quick = ct[s, 2]
            elif ct[s + 1, 0] == key0 and ct[s + 1, 1] == key1:
                quick = ct[s + 1, 2]
        if quick >= 0:
            ret = quick
            continue
        f_ty[depth] = cty
        f_pc[depth] = 0
        f_k[depth] = ck
        f_a[depth] = ca
        f_b[depth] = cb
        f_c[depth] = cc
        f_e[depth] = ce
        f_k0[depth] = key0
        f_k1[depth] = key1
        depth += 1
    return _DONE, depth, atop, ret, status, ct_used, steps


@njit(cache=True, nogil=True)
def _by_value(dom: np.ndarray, ev_slot_ptr: np.ndarray, ev_slot: np.ndarray, slot_ptr: np.ndarray, nxt: np.ndarray,
              evtop_ptr: np.ndarray, evtop: np.ndarray, saturating: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The events of each level that are enabled on each of its values, for saturation's loop over a
    node's values (``NODE``): ``(dom_ptr, byval_ptr, byval)``, the events of level k enabled on value
    i being ``byval[byval_ptr[dom_ptr[k] + i]:byval_ptr[dom_ptr[k] + i + 1]]``, in the order of
    ``evtop``. Enabled: the event's function at its top level maps i to a value, in
    the level's domain or not (an overflow is the loop's to report). Empty tables but ``dom_ptr``
    when not ``saturating``. On Peterson-PT-4 the loop over every event of the level for each dirty
    value read 210 million (value, event) pairs to fire 12 million."""
    n_levels = dom.shape[0]
    dom_ptr = np.zeros(n_levels + 1, np.int64)
    for k in range(n_levels):
        dom_ptr[k + 1] = dom_ptr[k] + dom[k]
    if not saturating:
        return dom_ptr, np.zeros(1, np.int64), np.zeros(0, np.int64)
    byval_ptr = np.zeros(dom_ptr[n_levels] + 1, np.int64)
    for k in range(n_levels):
        for ei in range(evtop_ptr[k], evtop_ptr[k + 1]):
            f = slot_ptr[ev_slot[ev_slot_ptr[evtop[ei]]]]
            for i in range(dom[k]):
                if nxt[f + i] >= 0:
                    byval_ptr[dom_ptr[k] + i + 1] += 1
    for x in range(dom_ptr[n_levels]):
        byval_ptr[x + 1] += byval_ptr[x]
    byval = np.zeros(byval_ptr[dom_ptr[n_levels]], np.int64)
    fill = byval_ptr[:-1].copy()
    for k in range(n_levels):
        for ei in range(evtop_ptr[k], evtop_ptr[k + 1]):
            f = slot_ptr[ev_slot[ev_slot_ptr[evtop[ei]]]]
            for i in range(dom[k]):
                if nxt[f + i] >= 0:
                    byval[fill[dom_ptr[k] + i]] = evtop[ei]
                    fill[dom_ptr[k] + i] += 1
    return dom_ptr, byval_ptr, byval


@njit(cache=True, nogil=True)  # two variable orders race on two cores (symbolic._race)
def run(mode: int, dom: np.ndarray, ev_top: np.ndarray, ev_bot: np.ndarray, ev_slot_ptr: np.ndarray,
        ev_slot: np.ndarray, slot_ptr: np.ndarray, nxt: np.ndarray, evtop_ptr: np.ndarray, evtop: np.ndarray,
        dz: tuple[np.ndarray, ...], meta: np.ndarray, level: np.ndarray, offset: np.ndarray, size: np.ndarray,
        kids: np.ndarray, unique: np.ndarray, ct: np.ndarray, a_in: int, b_in: int, c_in: int, arg: int,
        check_overflow: bool, max_bytes: int) -> tuple:  # type: ignore[type-arg]
    """One operation on the store (see the module docstring).

    Args:
        mode: MODE_SATURATE (the saturated closure of ``a_in`` under every event, inside ``c_in``),
            MODE_IMAGE (``arg`` IMAGE_EACH: one step of every event from ``a_in``; IMAGE_CHAIN_DEEP or
            _ROOT: ``a_in`` and its chained images, each event fired on the set so far, the events of
            the deepest tops first or of the root's first; inside ``c_in``, not saturated),
            MODE_APPLY (``arg`` in APPLY_UNION/INTER/DIFF of ``a_in`` and ``b_in``), MODE_RESTRICT
            (the markings of ``a_in`` in which event ``arg`` is enabled if ``b_in`` is 1, disabled if 0)
            or MODE_DEAD (the markings of ``a_in`` in which no event of ``dz`` is enabled).
        dom: (K,) int64 local domain sizes, level 0 at the root.
        ev_top, ev_bot: (E,) int64 top and bottom level of each event.
        ev_slot_ptr, ev_slot: for event e and level k in [top, bot], ``ev_slot[ev_slot_ptr[e] + k -
            top]`` is the index of its local function, or -1 where the event leaves the level alone.
        slot_ptr, nxt: local function s maps value i to ``nxt[slot_ptr[s] + i]`` (-1: disabled).
        evtop_ptr, evtop: the events whose top is level k: ``evtop[evtop_ptr[k]:evtop_ptr[k + 1]]``.
        dz: MODE_DEAD's tables (:func:`dead_tables`; for the other modes any, as :func:`dead_tables`
            of no event). Its sets are filled by the call: a computed result of MODE_DEAD names a set by
            its number, so a new ``dz`` needs the computed table cleared (:func:`clear_cache`).
        meta, level, offset, size, kids, unique, ct: the store (:func:`new_store`, or
            a previous result).
        a_in, b_in, c_in: operand nodes (c_in: a constraint node at the root level, or NO_CONSTRAINT).
        arg: the APPLY operation, the IMAGE kind or the RESTRICT event.
        check_overflow: a firing that leaves a level's domain is an error (status OVERFLOW, with the
            level in meta) instead of being dropped.
        max_bytes: byte budget of the store, computed table, frames and buffers (status MEMORY
            beyond it; the store is then still consistent).

    Returns:
        ``(status, result node, meta, level, offset, size, kids, unique, ct)``.
    """
    n_levels = dom.shape[0]
    max_dom = np.int64(1)  # typed, not a literal: a literal argument of _steps compiles it twice
    for k in range(n_levels):
        max_dom = max(max_dom, dom[k])
    saturating = mode == MODE_SATURATE
    dom_ptr, byval_ptr, byval = _by_value(dom, ev_slot_ptr, ev_slot, slot_ptr, nxt, evtop_ptr, evtop, saturating)
    # computed table: buckets of two entries (key words and value), grown (and refilled) as it fills up
    ccap = ct.shape[0]
    ct_used = meta[META_CT_USED]
    ct_max = _CT_MAX  # lowered to the table's size when the budget leaves it no room to grow
    # frames: along the stack the level grows by one per frame, but for NODE frames (at the level of
    # the SAT or FIRE frame below them) and the IMAGE frame, so the depth stays below 2K + 4
    fcap = 2 * n_levels + 8
    f_ty = np.zeros(fcap, np.int64)
    f_pc = np.zeros(fcap, np.int64)
    f_k = np.zeros(fcap, np.int64)
    f_a = np.zeros(fcap, np.int64)
    f_b = np.zeros(fcap, np.int64)
    f_c = np.zeros(fcap, np.int64)
    f_e = np.zeros(fcap, np.int64)
    f_i = np.zeros(fcap, np.int64)
    f_j = np.zeros(fcap, np.int64)
    f_buf = np.zeros(fcap, np.int64)
    f_k0 = np.zeros(fcap, np.int64)
    f_k1 = np.zeros(fcap, np.int64)
    f_s = np.zeros(fcap, np.int64)  # a NODE frame's lowest value that may be dirty
    arena = np.zeros((fcap + 1) * max_dom, np.int32)
    atop = np.int64(0)
    fixed = fcap * 104 + arena.shape[0] * 4
    status = OK
    ret = EMPTY
    depth = 0
    if mode == MODE_IMAGE:
        f_ty[0] = _IMAGE
        f_a[0] = a_in
        f_c[0] = c_in
        f_e[0] = arg
        depth = 1
    else:
        ty0 = _SAT if mode == MODE_SATURATE else (_APPLY if mode == MODE_APPLY else (
            _RESTRICT if mode == MODE_RESTRICT else _DEAD))
        if ty0 == _DEAD:
            b_in = 0  # no residual pending at the root
        quick, a0, b0_, key0, key1 = _prepare(ty0, 0, a_in, b_in, c_in, arg, saturating, n_levels,
                                                ev_bot[arg] if ty0 == _RESTRICT else (
                                                    int(dz[4][n_levels]) if ty0 == _DEAD else 0))
        if quick >= 0:
            ret = quick
        else:
            f_ty[0] = ty0
            f_a[0] = a0
            f_b[0] = b0_
            f_c[0] = c_in
            f_e[0] = arg
            f_k0[0] = key0
            f_k1[0] = key1
            depth = 1
    steps = np.int64(0)
    while depth > 0:
        n_nodes = meta[META_NODES]
        if _full(n_nodes, meta[META_KIDS], meta[META_UNIQUE], ct_used, level.shape[0], kids.shape[0],
                 unique.shape[0], ccap, max_dom, ct_max):
            # grow what is full; the old and the new buffer are both held during the copy
            gn = level.shape[0] * 2 if n_nodes + 2 > level.shape[0] else level.shape[0]
            gk = kids.shape[0]
            if meta[META_KIDS] + max_dom > gk:
                gk = max(2 * gk, meta[META_KIDS] + 2 * max_dom)
            gu = unique.shape[0]
            while 2 * (meta[META_UNIQUE] + 1) > gu:
                gu *= 2
            gc = ccap
            while 4 * ct_used > gc and gc < ct_max:
                gc *= 2
            held = level.shape[0] * 16 + kids.shape[0] * 4 + unique.shape[0] * 4 + ccap * 24 + fixed
            extra = 0
            if gn != level.shape[0]:
                extra += gn * 16
            if gk != kids.shape[0]:
                extra += gk * 4
            if gu != unique.shape[0]:
                extra += gu * 4
            if gc != ccap and held + extra + gc * 24 > max_bytes:
                # the computed table is a cache: past the budget it stops growing, and only the
                # nodes' own buffers run out of memory (a store of 0.5 GiB whose table of 2^23
                # entries doubled would hold 0.6 GiB during the copy, whatever its nodes)
                gc = ccap
                ct_max = ccap
            if held + extra > max_bytes:
                status = MEMORY
                break
            if gn != level.shape[0]:
                with objmode(nl="int32[::1]", no="int64[::1]", ns="int32[::1]"):  # huge pages (module docstring)
                    nl, no, ns = np.zeros(gn, np.int32), np.zeros(gn, np.int64), np.zeros(gn, np.int32)
                _copy(nl, level, n_nodes)
                _copy(no, offset, n_nodes)
                _copy(ns, size, n_nodes)
                level, offset, size = nl, no, ns
            if gk != kids.shape[0]:
                with objmode(nk="int32[::1]"):
                    nk = np.zeros(gk, np.int32)
                _copy(nk, kids, meta[META_KIDS])
                kids = nk
            if gu != unique.shape[0]:
                with objmode(unique="int32[::1]"):
                    unique = np.zeros(gu, np.int32)
                _rehash(unique, n_nodes, level, offset, size, kids)
            if gc != ccap:
                # a larger table, refilled with the entries of the old one
                with objmode(nct="int64[:, ::1]"):
                    nct = np.zeros((gc, 3), np.int64)
                nct[:, 0] = -1
                ct_used = 0
                # the insertion of _steps at a node's check-in, written again here: _steps hands no
                # array to a helper (module docstring), and this runs once per growth
                for x in range(ccap):  # each bucket's older entry first, so its newer stays first
                    x ^= 1
                    if ct[x, 0] != -1:
                        y = _slot(ct[x, 0], ct[x, 1], gc - 2)
                        if nct[y, 0] != -1:
                            if nct[y + 1, 0] == -1:
                                ct_used += 1
                            nct[y + 1, 0] = nct[y, 0]
                            nct[y + 1, 1] = nct[y, 1]
                            nct[y + 1, 2] = nct[y, 2]
                        else:
                            ct_used += 1
                        nct[y, 0] = ct[x, 0]
                        nct[y, 1] = ct[x, 1]
                        nct[y, 2] = ct[x, 2]
                ccap = gc
                ct = nct
        why, depth, atop, ret, status, ct_used, steps = _steps(
            dom, ev_top, ev_bot, ev_slot_ptr, ev_slot, slot_ptr, nxt, evtop, dom_ptr, byval_ptr, byval,
            dz, meta, level, offset,
            size, kids, unique, ct, check_overflow, saturating, max_dom, f_ty, f_pc, f_k, f_a, f_b, f_c, f_e,
            f_i, f_j, f_buf, f_k0, f_k1, f_s, arena, depth, atop, ret, ct_used, steps, ct_max)
        if why != _FULL:
            break
    meta[META_CT_USED] = ct_used
    if status != OK:
        ret = EMPTY
    return status, ret, meta, level, offset, size, kids, unique, ct


@njit(cache=True)
def count(root: int, offset: np.ndarray, size: np.ndarray, kids: np.ndarray, n_levels: int, level: np.ndarray,
          done: np.ndarray, approx: np.ndarray, residue: np.ndarray, primes: np.ndarray) -> None:
    """Number of paths (markings) below every node reachable from ``root``, into the per-node
    tables: ``approx`` (float64) and ``residue`` (int64, modulo each prime of ``primes``, all below
    2**62 so that a sum of two fits); ``done`` (uint8) marks the nodes already counted (kept between
    calls: a node's count never changes). Iterative depth-first post-order (paths have K levels)."""
    n_pr = primes.shape[0]
    if root <= 1:
        return
    stack = np.zeros(n_levels + 2, np.int64)
    child = np.zeros(n_levels + 2, np.int64)
    depth = 0
    if done[root] == 0:
        stack[0] = root
        child[0] = 0
        depth = 1
    while depth > 0:
        n = stack[depth - 1]
        i = child[depth - 1]
        if i < size[n]:
            child[depth - 1] = i + 1
            c = kids[offset[n] + i]
            if c > 1 and done[c] == 0:
                stack[depth] = c
                child[depth] = 0
                depth += 1
            continue
        tot = 0.0
        for r in range(n_pr):
            residue[n, r] = 0
        for i2 in range(size[n]):
            c = kids[offset[n] + i2]
            if c == 0:
                continue
            if c == 1:
                tot += 1.0
                for r in range(n_pr):
                    residue[n, r] = (residue[n, r] + 1) % primes[r]
            else:
                tot += approx[c]
                for r in range(n_pr):
                    residue[n, r] = (residue[n, r] + residue[c, r]) % primes[r]
        approx[n] = tot
        done[n] = 1
        depth -= 1


@njit(cache=True)
def most_paths(n_nodes: int, offset: np.ndarray, size: np.ndarray, kids: np.ndarray) -> float:
    """The most paths below any node of the store (its first ``n_nodes`` nodes), float64 (inf past a
    float's range). One pass in the order of the node numbers: a node is checked in after its
    children, so theirs are counted first."""
    paths = np.zeros(max(n_nodes, 2), np.float64)
    paths[TERMINAL] = 1.0
    best = 1.0  # the terminal: the one path of no level
    for n in range(2, n_nodes):
        tot = 0.0
        for i in range(size[n]):
            tot += paths[kids[offset[n] + i]]
        paths[n] = tot
        if tot > best:
            best = tot
    return best


@njit(cache=True)
def _nodes_of(root: int, offset: np.ndarray, size: np.ndarray, kids: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """The nodes of the set ``root`` (itself and every node below it but the terminal), each once, in
    no particular order; ``seen`` (uint8, zero, one per node) is scratch, left set on them."""
    stack = np.zeros(1024, np.int64)
    out = np.zeros(1024, np.int64)
    if root <= 1:
        return out[:0]
    stack[0] = root
    top = 1
    seen[root] = 1
    m = 0
    while top > 0:
        top -= 1
        n = stack[top]
        if m == out.shape[0]:
            grown = np.zeros(2 * m, np.int64)
            _copy(grown, out, m)
            out = grown
        out[m] = n
        m += 1
        for i in range(size[n]):
            c = kids[offset[n] + i]
            if c > 1 and seen[c] == 0:
                seen[c] = 1
                if top == stack.shape[0]:
                    grown = np.zeros(2 * stack.shape[0], np.int64)
                    _copy(grown, stack, top)
                    stack = grown
                stack[top] = c
                top += 1
    return out[:m]


@njit(cache=True)
def presence(root: int, offset: np.ndarray, size: np.ndarray, kids: np.ndarray, level: np.ndarray,
             dom_ptr: np.ndarray, seen: np.ndarray, out: np.ndarray) -> int:
    """Mark in ``out[dom_ptr[k] + i]`` every value i of level k that some path below ``root`` takes
    (every stored node leads to the terminal, so a non-empty child is a value some marking has);
    ``seen`` (uint8, zero, one per node) is scratch. Returns the number of nodes visited."""
    nodes = _nodes_of(root, offset, size, kids, seen)
    for n in nodes:
        k = level[n]
        for i in range(size[n]):
            if kids[offset[n] + i] != EMPTY:
                out[dom_ptr[k] + i] = 1
    return int(nodes.shape[0])


@njit(cache=True, nogil=True)  # beside the main thread's closures (symbolic._Home)
def subset(a: int, offset_a: np.ndarray, size_a: np.ndarray, kids_a: np.ndarray, b: int, offset_b: np.ndarray,
           size_b: np.ndarray, kids_b: np.ndarray) -> bool:
    """Whether the set ``a`` of one store is inside the set ``b`` of another on the same levels (the
    same variable order and domains): a walk over the pairs of nodes (one of each) that the same
    values lead to from the roots, each pair once (a set of their keys), building no node. Every
    stored node leads to the terminal, so a pair is inside iff every non-empty child of the first
    has a non-empty child of the second under the same value and that pair is inside."""
    if a == EMPTY:
        return True
    if b == EMPTY:
        return False
    if a == TERMINAL or b == TERMINAL:
        return a == b
    n_b = np.int64(size_b.shape[0])
    seen = {np.int64(a) * n_b + b}
    stack = np.empty(1024, np.int64)
    stack[0] = np.int64(a) * n_b + b
    depth = 1
    while depth > 0:
        depth -= 1
        x, y = stack[depth] // n_b, stack[depth] % n_b
        for i in range(size_a[x]):
            ca = kids_a[offset_a[x] + i]
            if ca == EMPTY:
                continue
            if i >= size_b[y]:
                return False
            cb = kids_b[offset_b[y] + i]
            if cb == EMPTY:
                return False
            if ca == TERMINAL or cb == TERMINAL:
                if ca != cb:
                    return False
                continue
            key = np.int64(ca) * n_b + cb
            if key in seen:
                continue
            seen.add(key)
            if depth == stack.shape[0]:
                grown = np.empty(2 * depth, np.int64)
                grown[:depth] = stack
                stack = grown
            stack[depth] = key
            depth += 1
    return True


@njit(cache=True)
def max_weight(root: int, offset: np.ndarray, size: np.ndarray, kids: np.ndarray, level: np.ndarray,
               n_levels: int, dom_ptr: np.ndarray, weight: np.ndarray, best: np.ndarray,
               done: np.ndarray) -> int:
    """The largest sum of ``weight[dom_ptr[k] + value]`` along a path below ``root`` (-1 for the empty
    set); ``best`` (int64) and ``done`` (uint8) are per-node scratch, zero."""
    if root == 0:
        return -1
    if root == 1:
        return 0
    stack = np.zeros(n_levels + 2, np.int64)
    child = np.zeros(n_levels + 2, np.int64)
    stack[0] = root
    depth = 1
    while depth > 0:
        n = stack[depth - 1]
        i = child[depth - 1]
        if i < size[n]:
            child[depth - 1] = i + 1
            c = kids[offset[n] + i]
            if c > 1 and done[c] == 0:
                stack[depth] = c
                child[depth] = 0
                depth += 1
            continue
        k = level[n]
        top = -1
        for i2 in range(size[n]):
            c = kids[offset[n] + i2]
            if c == 0:
                continue
            below = 0 if c == 1 else best[c]
            top = max(top, weight[dom_ptr[k] + i2] + below)
        best[n] = top
        done[n] = 1
        depth -= 1
    return best[root]  # type: ignore[no-any-return]


@njit(cache=True)
def node_of_path(root: int, values: np.ndarray, offset: np.ndarray, size: np.ndarray, kids: np.ndarray) -> int:
    """The node reached from ``root`` following ``values`` (one per level): 1 if the path is in the
    set, 0 if not."""
    n = root
    for k in range(values.shape[0]):
        if n <= 1:
            return 0
        v = values[k]
        if v < 0 or v >= size[n]:
            return 0
        n = kids[offset[n] + v]
    return n


def enabling_values(slot_ptr: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The values on which each local function is defined, for :func:`enabled_counts`.

    Args:
        slot_ptr, nxt: the local functions, as :func:`run` takes them (S functions).

    Returns:
        ``(on_ptr, on_val)``: (S + 1,) and (n,) int64; function s is defined (``nxt >= 0``) on the
        values ``on_val[on_ptr[s]:on_ptr[s + 1]]``, increasing."""
    slot_ptr = np.asarray(slot_ptr, dtype=np.int64)
    at = np.flatnonzero(np.asarray(nxt) >= 0)
    owner = np.searchsorted(slot_ptr, at, side="right") - 1
    on_ptr = np.searchsorted(owner, np.arange(slot_ptr.shape[0]), side="left").astype(np.int64)
    return on_ptr, (at - slot_ptr[owner]).astype(np.int64)


def suffix_ids(top: np.ndarray, bot: np.ndarray, slot_ptr: np.ndarray, slot: np.ndarray, on_ptr: np.ndarray,
               on_val: np.ndarray, dom: np.ndarray) -> np.ndarray:
    """Numbers of the events' enabling conditions below their top levels, for :func:`enabled_counts`.

    The count below a node of level k, for an event of bottom level b, depends on the event's
    enabling values on levels k .. b alone: events alike there share it. Each (event e, level k in
    ``top[e] + 1 .. bot[e]``) gets the number of the condition "levels k .. b take these values",
    the same for equal conditions (a level without a function, or whose function is defined on its
    whole domain, takes every value). BridgeAndVehicles-PT-V80P20N20: the 80 events of top level 4
    have one condition on levels 6 and 7 (255,441 and 1,267,600 nodes), counted once, not 80 times.

    Args:
        top, bot, slot_ptr, slot: the events, as :func:`run` takes them (E events).
        on_ptr, on_val: the values each local function is defined on (:func:`enabling_values`).
        dom: (L,) values of each level.

    Returns:
        (len(slot),) int64 aligned with ``slot``: at ``slot_ptr[e] + j`` (j ≥ 1) the number of the
        condition on levels ``top[e] + j .. bot[e]``, ≥ 0; -1 at j = 0."""
    by_values: dict[bytes, int] = {}
    kind = np.empty(on_ptr.shape[0] - 1, dtype=np.int64)  # per local function: its set of values, numbered
    for f in range(kind.shape[0]):
        vals = on_val[on_ptr[f]:on_ptr[f + 1]]
        kind[f] = by_values.setdefault(vals.tobytes(), len(by_values))
    return _suffix_numbers(top, bot, slot_ptr, slot, on_ptr, kind, dom)


@njit(cache=True, inline="always")
def _condition_slot(k: int, v: int, below: int, mask: int) -> int:
    """The first slot of condition (level ``k``, values ``v``, condition ``below``) in a table of
    ``mask + 1`` slots (:func:`_suffix_numbers`)."""
    return _slot(k + 1, (v + 1) * 0x100000001 + below + 1, mask)


@njit(cache=True, nogil=True)
def _suffix_numbers(top: np.ndarray, bot: np.ndarray, slot_ptr: np.ndarray, slot: np.ndarray, on_ptr: np.ndarray,
                    kind: np.ndarray, dom: np.ndarray) -> np.ndarray:
    """:func:`suffix_ids` once each local function's set of values is numbered (``kind``): the
    conditions (level, values, condition below) numbered as first met, in an open-addressing hash
    table that grows (AirplaneLD-PT-2000: 27,912,124 (event, level) pairs, 13,661,773 conditions;
    a dictionary of tuples took 15 s and held the interpreter's lock throughout)."""
    out = np.full(slot.shape[0], -1, dtype=np.int64)
    cap = 1 << 12
    table = np.full(cap, -1, np.int64)
    keys = np.empty((cap // 2, 3), np.int64)  # per condition: level, values (-1: any), the condition below
    n = 0
    for e in range(top.shape[0]):
        t, b, at = top[e], bot[e], slot_ptr[e]
        below = -1  # the condition on the levels under the current one (none under b)
        for j in range(b - t, 0, -1):
            k = t + j
            f = slot[at + j]
            # a function is defined on distinct values of its level's domain: on all of them when
            # it has as many as the domain
            v = -1 if f < 0 or on_ptr[f + 1] - on_ptr[f] == dom[k] else kind[f]
            h = _condition_slot(k, v, below, cap - 1)
            while True:
                i = table[h]
                if i < 0:
                    if 2 * (n + 1) > cap:  # grow: twice the slots, every condition placed again
                        cap *= 2
                        grown = np.empty((cap // 2, 3), np.int64)
                        grown[:n] = keys[:n]
                        keys = grown
                        table = np.full(cap, -1, np.int64)
                        for c in range(n):
                            g = _condition_slot(keys[c, 0], keys[c, 1], keys[c, 2], cap - 1)
                            while table[g] >= 0:
                                g = (g + 1) & (cap - 1)
                            table[g] = c
                        h = _condition_slot(k, v, below, cap - 1)
                        while table[h] >= 0:
                            h = (h + 1) & (cap - 1)
                    keys[n, 0], keys[n, 1], keys[n, 2] = k, v, below
                    table[h] = n
                    i = n
                    n += 1
                    break
                if keys[i, 0] == k and keys[i, 1] == v and keys[i, 2] == below:
                    break
                h = (h + 1) & (cap - 1)
            below = i
            out[at + j] = below
    return out


@njit(cache=True, inline="always")
def _mulmod(a: int, b: int, p: int) -> int:
    """a·b mod p for 0 ≤ a, b < p < 2**61 in int64 arithmetic (two bits of b at a time)."""
    r = 0
    for sh in range(60, -2, -2):
        r = (r * 4) % p
        d = (b >> sh) & 3 if sh >= 0 else 0
        if d:
            r = (r + (a * d) % p) % p
    return r


@njit(cache=True, inline="always")
def _enabled_below(y: int, e: int, t: int, b: int, ev_slot_ptr: np.ndarray, ev_slot: np.ndarray, ev_sid: np.ndarray,
                   on_ptr: np.ndarray, on_val: np.ndarray, ids: np.ndarray, comp: np.ndarray, offset: np.ndarray,
                   size: np.ndarray, kids: np.ndarray, level: np.ndarray, residue: np.ndarray, approx: np.ndarray,
                   primes: np.ndarray, stamp: np.ndarray, memo_r: np.ndarray, memo_f: np.ndarray, st: np.ndarray,
                   ch: np.ndarray) -> None:
    """For :func:`enabled_counts`: the paths below compacted node ``y`` (a level in ``t + 1 .. b``)
    on which event ``e`` (top ``t``, bottom ``b``) takes an enabling value on every level, into
    ``memo_r[y]``, ``memo_f[y]``; depth-first, post-order, each node once per condition on the levels
    from its own down to ``b`` (``stamp``: the number :func:`suffix_ids` gives it in ``ev_sid``)."""
    n_pr = primes.shape[0]
    stamp[y] = ev_sid[ev_slot_ptr[e] + level[ids[y]] - t]
    for r in range(n_pr):
        memo_r[y, r] = 0
    memo_f[y] = 0.0
    st[0] = y
    ch[0] = 0
    depth = 1
    while depth > 0:
        x = st[depth - 1]
        nd = ids[x]
        k = level[nd]
        pos = ch[depth - 1]
        sl = ev_slot[ev_slot_ptr[e] + k - t]
        if sl >= 0:  # the next enabling value, or past the node's last child
            i = on_val[on_ptr[sl] + pos] if pos < on_ptr[sl + 1] - on_ptr[sl] else size[nd]
            if i > size[nd]:
                i = size[nd]
        else:
            i = pos
        if i == size[nd]:
            depth -= 1
            if depth > 0:
                p = st[depth - 1]
                for r in range(n_pr):
                    memo_r[p, r] = (memo_r[p, r] + memo_r[x, r]) % primes[r]
                memo_f[p] += memo_f[x]
            continue
        ch[depth - 1] = pos + 1
        c = kids[offset[nd] + i]
        if c == EMPTY:
            continue
        if k == b:
            if c == TERMINAL:
                for r in range(n_pr):
                    memo_r[x, r] = (memo_r[x, r] + 1) % primes[r]
                memo_f[x] += 1.0
            else:
                for r in range(n_pr):
                    memo_r[x, r] = (memo_r[x, r] + residue[c, r]) % primes[r]
                memo_f[x] += approx[c]
            continue
        z = comp[c]
        sid = ev_sid[ev_slot_ptr[e] + level[c] - t]
        if stamp[z] == sid:
            for r in range(n_pr):
                memo_r[x, r] = (memo_r[x, r] + memo_r[z, r]) % primes[r]
            memo_f[x] += memo_f[z]
            continue
        stamp[z] = sid
        for r in range(n_pr):
            memo_r[z, r] = 0
        memo_f[z] = 0.0
        st[depth] = z
        ch[depth] = 0
        depth += 1


@njit(cache=True, nogil=True)  # beside the deadlocks and the witness (symbolic._Counting)
def enabled_counts(root: int, ev_top: np.ndarray, ev_bot: np.ndarray, ev_slot_ptr: np.ndarray,
                   ev_slot: np.ndarray, ev_sid: np.ndarray, on_ptr: np.ndarray, on_val: np.ndarray, offset: np.ndarray,
                   size: np.ndarray, kids: np.ndarray, level: np.ndarray, n_levels: int, n_nodes: int,
                   residue: np.ndarray, approx: np.ndarray, primes: np.ndarray, out_res: np.ndarray,
                   out_approx: np.ndarray) -> None:
    """For every event e, the number of paths (markings) of the set ``root`` in which e is enabled,
    into ``out_res[e]`` (modulo each prime of ``primes``, all below 2**61) and ``out_approx[e]``
    (float64), building no node.

    A count restricted to the levels ``top[e] .. bot[e]``: the paths from the root down to the arcs
    (n, v, c) leaving level ``top[e]`` (node n there, value v, child c), times the paths below c that
    take an enabling value on every level where e has a local function, down to ``bot[e]``, below
    which the plain count of the node (``residue``, ``approx``: :func:`count` of ``root``, done
    before) is used. The paths above an arc are summed per (v, c) once per top level, for all the
    events of that level (``above(n)``: one top-down pass over the set's nodes; nodes are numbered
    children first, so decreasing numbers are a top-down order): an event then costs its enabling
    values' distinct children at its top level and the nodes below them down to its bottom level,
    not every node of its top level. On a level where e has a local function s, only its enabling
    values are walked: ``on_val[on_ptr[s]:on_ptr[s + 1]]``, increasing (:func:`enabling_values`).
    The paths below a node are kept for the next events with the same enabling values on the levels
    from the node's own down to their bottom (``ev_sid``, :func:`suffix_ids`), which come next: the
    events are taken by top level, then by that number one level below the top.
    """
    n_pr = primes.shape[0]
    n_ev = ev_top.shape[0]
    if root <= 1:
        for e in range(n_ev):
            for r in range(n_pr):
                out_res[e, r] = root
            out_approx[e] = float(root)
        return
    # the set's nodes, compacted, top-down
    found = _nodes_of(root, offset, size, kids, np.zeros(n_nodes, np.uint8))
    ids = found[np.argsort(found, kind="mergesort")[::-1]]  # the sort the events take too: one compile
    m = ids.shape[0]
    comp = np.full(n_nodes, -1, np.int64)
    for x in range(m):
        comp[ids[x]] = x
    # paths from the root to each node
    above_r = np.zeros((m, n_pr), np.int64)
    above_f = np.zeros(m, np.float64)
    for r in range(n_pr):
        above_r[0, r] = 1
    above_f[0] = 1.0
    for x in range(m):
        nd = ids[x]
        for i in range(size[nd]):
            c = kids[offset[nd] + i]
            if c > 1:
                y = comp[c]
                for r in range(n_pr):
                    above_r[y, r] = (above_r[y, r] + above_r[x, r]) % primes[r]
                above_f[y] += above_f[x]
    # the nodes of each level
    lp = np.zeros(n_levels + 1, np.int64)
    for x in range(m):
        lp[level[ids[x]] + 1] += 1
    for k in range(n_levels):
        lp[k + 1] += lp[k]
    fill = lp.copy()
    by_level = np.empty(m, np.int64)
    for x in range(m):
        k = level[ids[x]]
        by_level[fill[k]] = x
        fill[k] += 1
    stamp = np.full(m, -1, np.int64)
    memo_r = np.zeros((m, n_pr), np.int64)
    memo_f = np.zeros(m, np.float64)
    st = np.zeros(n_levels + 2, np.int64)
    ch = np.zeros(n_levels + 2, np.int64)
    first = np.full(n_ev, -1, np.int64)  # the condition below each event's top level
    for e in range(n_ev):
        if ev_bot[e] > ev_top[e]:
            first[e] = ev_sid[ev_slot_ptr[e] + 1]
    by_first = np.argsort(first, kind="mergesort")
    order = by_first[np.argsort(ev_top[by_first], kind="mergesort")]
    cur = -1
    mark = np.full(m + 1, -1, np.int64)
    at = np.zeros(m + 1, np.int64)
    tick = -1
    w_ptr = np.zeros(1, np.int64)
    w_kid = np.zeros(0, np.int64)
    w_r = np.zeros((0, n_pr), np.int64)
    w_f = np.zeros(0, np.float64)
    width = 0
    for q in range(n_ev):
        e = order[q]
        t = ev_top[e]
        b = ev_bot[e]
        if t != cur:
            # the arcs leaving level t, summed per (value, child): w_kid[j] is the child (a store
            # node) and w_r[j], w_f[j] the paths above its arcs, for j in w_ptr[v] .. w_ptr[v + 1]
            cur = t
            width = 0
            for z in range(lp[t], lp[t + 1]):
                width = max(width, size[ids[by_level[z]]])
            # the arcs by value (a counting sort, linear in the arcs: level 6 of
            # BridgeAndVehicles-PT-V80P20N20 has 19.9 million), then one entry per (value, child):
            # mark[key] == tick when the child of that key is met under the current value already,
            # at entry at[key] (a child's key: its compacted number, or m for the terminal)
            per_v = np.zeros(width + 1, np.int64)
            for z in range(lp[t], lp[t + 1]):
                nd = ids[by_level[z]]
                for i in range(size[nd]):
                    if kids[offset[nd] + i] != EMPTY:
                        per_v[i + 1] += 1
            for v in range(width):
                per_v[v + 1] += per_v[v]
            fill = per_v.copy()
            src = np.empty(per_v[width], np.int64)
            keys = np.empty(per_v[width], np.int64)
            for z in range(lp[t], lp[t + 1]):
                x = by_level[z]
                nd = ids[x]
                for i in range(size[nd]):
                    c = kids[offset[nd] + i]
                    if c != EMPTY:
                        a = fill[i]
                        fill[i] += 1
                        src[a] = x
                        keys[a] = comp[c] if c > 1 else m
            w_ptr = np.zeros(width + 1, np.int64)
            for v in range(width):
                tick += 1
                for a in range(per_v[v], per_v[v + 1]):
                    if mark[keys[a]] != tick:
                        mark[keys[a]] = tick
                        w_ptr[v + 1] += 1
            for v in range(width):
                w_ptr[v + 1] += w_ptr[v]
            w_kid = np.empty(w_ptr[width], np.int64)
            w_r = np.zeros((w_ptr[width], n_pr), np.int64)
            w_f = np.zeros(w_ptr[width], np.float64)
            j_next = 0
            for v in range(width):
                tick += 1
                for a in range(per_v[v], per_v[v + 1]):
                    kk = keys[a]
                    if mark[kk] != tick:
                        mark[kk] = tick
                        at[kk] = j_next
                        w_kid[j_next] = ids[kk] if kk < m else TERMINAL
                        j_next += 1
                    j = at[kk]
                    x = src[a]
                    for r in range(n_pr):
                        w_r[j, r] = (w_r[j, r] + above_r[x, r]) % primes[r]
                    w_f[j] += above_f[x]
        for r in range(n_pr):
            out_res[e, r] = 0
        out_approx[e] = 0.0
        sl = ev_slot[ev_slot_ptr[e]]
        n_on = width if sl < 0 else on_ptr[sl + 1] - on_ptr[sl]
        for u in range(n_on):
            v = u if sl < 0 else on_val[on_ptr[sl] + u]
            if v >= width:
                break
            for j in range(w_ptr[v], w_ptr[v + 1]):
                c = w_kid[j]
                if t == b:  # the event reads level t alone: every path below the arc counts
                    for r in range(n_pr):
                        below = 1 if c == TERMINAL else residue[c, r]
                        out_res[e, r] = (out_res[e, r] + _mulmod(w_r[j, r], below, primes[r])) % primes[r]
                    out_approx[e] += w_f[j] * (1.0 if c == TERMINAL else approx[c])
                    continue
                y = comp[c]
                if stamp[y] != ev_sid[ev_slot_ptr[e] + level[c] - t]:
                    _enabled_below(y, e, t, b, ev_slot_ptr, ev_slot, ev_sid, on_ptr, on_val, ids, comp, offset, size, kids,
                                   level, residue, approx, primes, stamp, memo_r, memo_f, st, ch)
                for r in range(n_pr):
                    out_res[e, r] = (out_res[e, r] + _mulmod(w_r[j, r], memo_r[y, r], primes[r])) % primes[r]
                out_approx[e] += w_f[j] * memo_f[y]
