"""Symbolic state space of a bounded net: the reachable markings as a decision diagram (pure, no I/O).

The explicit search (:mod:`.statespace`) stores every marking; a net of twenty robots has 10^15 of
them. Here the reachable set is a multi-valued decision diagram (MDD, :mod:`.mdd_kernel`; Bryant
1986 for the binary case), built by **saturation** (Ciardo, Lüttgen, Siminiceanu 2001): the events
of the lower levels are fired to a fixed point on each node before the node is used above, so no
breadth-first frontier of the whole state space is ever built; or, where saturation's intermediate
sets grow too large, by chained images (Roig, Cortadella, Pastor 1995), raced against it
(:func:`_race`). The encoding (levels, their local markings, their order, the merged events) comes
from the net's structure and its proven place bounds (:mod:`.mdd_order`), or, where those make the
levels too wide or where a place has none, from the counts an explicit search saw, checked on
every firing and raised where one leaves them (:func:`_reachable`; a set no firing leaves is the
reachable set, so a net no proof bounds is shown bounded by it). From
the set, with exact integers of any size:

* the number of markings and of edges (one per reachable marking and transition enabled in it:
  the Model Checking Contest's count), the edges counted per transition on the levels it reads
  only, building no node (:func:`.mdd_kernel.enabled_counts`; on two CPUs in a thread beside the
  deadlocks and the witness, :class:`_Counting`);
* deadlocks: the dead markings (the reachable set restricted, event by event, to the markings
  where the event is disabled), their number, one of them with a firing sequence from M0: a
  best-first search over explicit markings, nearest to one dead marking first, that never leaves
  the markings able to reach a deadlock (backward saturation from the dead markings inside the
  reachable set), so it mostly walks straight to one; breadth-first images (a shortest sequence)
  when that search is too long;
* quasi-liveness (each transition fireable in some reachable marking), the exact bound of every
  place, one-safety, the largest token count of a marking, stable places;
* reversibility (M0 is reachable from every reachable marking: backward saturation from M0 inside
  the reachable set, Zhao & Ciardo 2009) and liveness (L4): a quasi-live reversible net is live;
  otherwise a transition is live iff some marking of every terminal strongly connected component
  of the reachability graph enables it, the components found by saturations forward and backward
  from single markings (:func:`_terminal`); beyond a few components, or where forward saturation
  from one marking is too slow, each transition t left is live iff every reachable marking can
  reach one that enables t, one backward saturation per transition within the time left; what is
  not decided in time stays ``None`` ("undecided"), never a guess.

Counts are exact: every count is computed modulo a few primes below 2**61 and rebuilt by the
Chinese remainder theorem, with as many primes as a float estimate of the count (or a bound of the
counts to come: markings times transitions for the edges) asks for.

Budgets: ``max_bytes`` bounds the store, its tables and stacks, the counts of its sets and the
event tables of each call (:class:`~coordinator.errors.AnalysisError` when it is reached; each
order raced has tables of its own, 169 MB to 490 MB on AirplaneLD-PT-2000), ``seconds`` the whole
computation (the reachable set first; the witness's firing sequence, then reversibility and
liveness, get what is left of ``answer_seconds``, and what is not decided in time is left
undecided).
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from math import ceil, inf, log2
from typing import Any

import numpy as np

from coordinator.analysis import mdd_kernel as mk
from coordinator.analysis.budget import cpus, lower_priority
from coordinator.analysis.matrices import SparseNet, sparse_net
from coordinator.analysis.mdd_order import (
    Encoding,
    EncodingTooLarge,
    Events,
    PlaceGroups,
    concat_ranges,
    encode,
    events,
    touched_places,
)
from coordinator.errors import AnalysisError
from coordinator.net import PetriNet

__all__ = ["ANSWER_SECONDS", "PROBES", "BeyondBounds", "Rival", "SymbolicResult", "analyse_symbolic", "load_kernel",
           "set_kernels_wait"]

_TWO61 = (1 << 61) - 1
#: default time after which reversibility and liveness are left undecided (seconds from the start of
#: the symbolic analysis; ``petrobot analyze`` counts them from its own start, the bounds' LPs and the
#: explicit search included, so that its whole answer comes within a minute)
ANSWER_SECONDS = 50.0
#: markings drawn from the reachable set whose forward sets are searched for a transition that can
#: never fire again and for M0, before the backward saturations (:func:`_probe`)
PROBES = 3
#: most entries of the dense (transitions, places) block of successor or predecessor markings the
#: witness searches build at once (int64: 32 MB)
_DENSE_BLOCK = 4_000_000
#: longest that search may take before breadth-first images take over (seconds), and the walks that
#: stay among the markings that can reach a deadlock before it (:func:`_walk_sequence` with ``inside``)
_GUIDED_SECONDS = 10.0
#: most bytes that search's markings may take (:func:`_guided_sequence`), and fewest when the
#: decision diagram has left less of its budget (:func:`_witness` gives it half of what is left)
_GUIDED_BYTES = 512 << 20
_GUIDED_MIN_BYTES = 32 << 20
#: bytes a marking the search has seen costs besides its counts and level values: the key's bytes
#: object and its slot in the set, the arrays' headers, its entries in the lists and the heap
_SEEN_OVERHEAD = 600
#: longest that search may take inside the reachable set alone, before the markings that can reach a
#: deadlock are computed to guide it (seconds); random walks get as long after it
_QUICK_SECONDS = 2.0
#: most random walks drawn for a firing sequence to a deadlock, and most steps of each (:func:`_walk_sequence`)
_WALKS = 1_000
_WALK_STEPS = 10_000
#: most steps of a walk that stays among the markings that can reach a deadlock
#: (:func:`_walk_sequence` with ``inside``): it can only end in one, so it is given longer
_INSIDE_WALK_STEPS = 1_000_000
#: successors a step of that walk tries one at a time before the rest in blocks (:func:`_step_inside`)
_ONE_BY_ONE = 4


def _is_prime(n: int) -> bool:
    """Deterministic Miller–Rabin for n < 3.3e24."""
    if n < 2:
        return False
    for p in (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41):
        if n % p == 0:
            return n == p
    d, r = n - 1, 0
    while d % 2 == 0:
        d //= 2
        r += 1
    for a in (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41):
        x = pow(a, d, n)
        if x in (1, n - 1):
            continue
        for _ in range(r - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


def _as_float(n: int) -> float:
    """``n`` as a float, infinite past a float's range instead of an OverflowError."""
    return float(n) if n.bit_length() <= 1000 else inf


def _beyond(estimate: float, k: int) -> bool:
    """A count estimated at ``estimate`` (a float, infinite past its range) may not fit below the
    product of ``k`` primes of :func:`_primes` (each above 2^60; 3 bits kept for the estimate's error)."""
    return estimate > 0 and (estimate == inf or log2(estimate) >= 60 * k - 3)


def _primes(k: int) -> list[int]:
    out: list[int] = []
    n = _TWO61
    while len(out) < k:
        if _is_prime(n):
            out.append(n)
        n -= 2
    return out


@dataclass
class SymbolicResult:
    """What :func:`analyse_symbolic` found. ``None`` means not decided.

    Attributes:
        states: number of reachable markings (exact, any size).
        edges: number of (reachable marking, enabled transition) pairs.
        deadlock: some reachable marking enables no transition; n_deadlocks: how many do.
        deadlock_marking: one dead marking (place id → tokens), with deadlock_sequence: a firing
            sequence from M0 to it (None if it was not found within the time).
        fireable: (|T|,) bool: the transition is enabled in some reachable marking.
        place_bounds: (|P|,) int64 exact bound of every place; stable: (|P|,) bool, the count never changes.
        max_token_per_marking: the largest total count of a reachable marking.
        live: every transition is live (L4); live_transitions: (|T|,) object array of True/False/None.
        reversible: M0 is reachable from every reachable marking.
        levels, groups, nodes, order_score: the diagram: levels, levels holding several places,
            nodes of the reachable set, score of the variable order.
        method: how the reachable set was built, ``"saturation"`` or ``"chaining"`` (:func:`_race`);
            the backward and forward closures of the later phases are built the same way.
        seconds: time per phase ("encode", "reach", "properties", "liveness", "witness").
        notes: what was left undecided and why.
    """

    states: int
    edges: int
    deadlock: bool
    n_deadlocks: int
    deadlock_marking: dict[str, int] | None
    deadlock_sequence: list[str] | None
    fireable: np.ndarray
    place_bounds: np.ndarray
    stable: np.ndarray
    max_token_per_marking: int
    live: bool | None
    live_transitions: np.ndarray
    reversible: bool | None
    levels: int
    groups: int
    nodes: int
    order_score: float
    method: str = "saturation"
    seconds: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


class _Store:
    """The MDD store of one analysis and the calls on it (:mod:`.mdd_kernel`)."""

    def __init__(self, enc: Encoding, max_bytes: int) -> None:
        self.enc = enc
        self.dom = enc.dom
        self.max_bytes = max_bytes
        self.arrays, self.m0 = mk.new_store(enc.dom, enc.m0)
        self._events: Events | None = None
        no_dead = mk.dead_tables(enc.dom, *(np.zeros(0, np.int64),) * 6, max_sets=1, max_items=1)
        assert no_dead is not None  # of no event
        self._no_dead = no_dead  # MODE_DEAD's tables in calls of another mode
        self.dom_ptr = np.concatenate([[0], np.cumsum(enc.dom)]).astype(np.int64)
        #: log2 of the product of the level domains: a bound of every set's count
        self.domain_bits = float(np.log2(np.asarray(enc.dom, dtype=np.float64)).sum())
        self._count_cap = 0
        self._primes: list[int] = []
        self._done = np.zeros(0, np.uint8)
        self._approx = np.zeros(0, np.float64)
        self._residue = np.zeros((0, 1), np.int64)
        #: what frees more bytes for this store when a call outgrows ``max_bytes`` (asked once)
        self.borrow: Callable[[], int] | None = None
        #: what gives back bytes lent out of ``max_bytes`` (:class:`_Counting`: waits for the enabled
        #: counts beside to end), asked once before ``borrow``; the bytes given back
        self.reclaim: Callable[[], int] | None = None
        #: closures by chained images instead of saturation (:meth:`closure`)
        self.chain = False
        #: the last closure by chained images: its events, start and constraint, the passes it had
        #: made and the set they built, where a call stopped part-way resumes (:meth:`closure`)
        self._resume: tuple[Events, int, int, int, int] | None = None

    def call(self, mode: int, ev: Events, a: int, b: int = 0, c: int = mk.NO_CONSTRAINT, arg: int = 0,
             check_overflow: bool = False, dz: tuple[np.ndarray, ...] | None = None) -> int:
        """One operation of :func:`.mdd_kernel.run` on the store (arguments as there); its result node.

        The kernel's budget is ``max_bytes`` less what it does not see: the counts of the store's
        sets and the call's event tables (``ev``; MODE_DEAD's tables ``dz`` are bounded by their
        caller, :func:`_dead`).

        Raises:
            _OutOfMemory: the byte budget. _OutOfTime: the deadline, or the watch. BeyondBounds: a
                firing beyond the proven local markings. _TooWide: MODE_DEAD's sets outgrew ``dz``."""
        if ev is not self._events:  # cached results name events by their index in a set of events
            mk.clear_cache(self.arrays)
            self._events = ev
        while True:
            args = (mode, self.dom, *ev.tables(), dz or self._no_dead, *self.arrays, a, b, c, arg, check_overflow,
                    max(0, self.max_bytes - self._count_bytes() - ev.nbytes))
            status, ret, *arrays = mk.run(*args)  # type: ignore[arg-type]
            self.arrays = tuple(arrays)
            if status != mk.MEMORY:
                break
            if self.reclaim is not None:
                reclaim, self.reclaim = self.reclaim, None
                if reclaim() > 0:
                    continue  # the call again, from the results its store kept
            if self.borrow is None:
                break
            borrow, self.borrow = self.borrow, None
            extra = borrow()
            if extra <= 0:
                break
            self.max_bytes += extra  # the call again, from the results its store kept
        if status == mk.MEMORY:
            raise _OutOfMemory(f"the decision diagram outgrew the memory budget of {self.max_bytes / 2**30:.2f} GiB "
                                f"({self.nodes:,} nodes)")
        if status == mk.STOPPED:
            raise _OutOfTime()
        if status == mk.WIDE:
            raise _TooWide()
        if status == mk.OVERFLOW:
            k = int(self.arrays[0][mk.META_OVERFLOW_LEVEL])
            raise BeyondBounds(f"a firing took level {k} beyond its proven local markings: the place bounds "
                               "given to the symbolic engine are wrong", self.enc.levels[k])
        return int(ret)

    def closure(self, ev: Events, a: int, c: int = mk.NO_CONSTRAINT, check_overflow: bool = False,
                passes: int = 0) -> int:
        """The markings reachable from the set ``a`` by the events ``ev`` (inside the constraint
        ``c``): by saturation, or when :attr:`chain` is set by chained images to a fixed point
        (:func:`.mdd_kernel.run`), the events of the deepest tops first and of the root's first by
        turns (the first order is the better one forward on some nets, the second backward: inside
        SharedMemory-PT-000020's reachable set, backward from M0, 2.3 s and 0.6 s, by turns 0.8 s).
        ``passes``: chained images give up, raising _NoFixedPoint, when this many passes have not
        found the fixed point (0: no limit). A call stopped part-way (the deadline, the watch) and
        made again with the same ``ev``, ``a`` and ``c`` resumes from the last set its passes had
        built, with the passes it had made: nodes are never freed, so that set is still in the
        store, and chained images from it reach the same fixed point. Raises as :meth:`call`."""
        if not self.chain:
            return self.call(mk.MODE_SATURATE, ev, a, c=c, check_overflow=check_overflow)
        last = self._resume
        turn, now = (last[3], last[4]) if last is not None and last[0] is ev and last[1:3] == (a, c) else (0, a)
        while True:
            how = mk.IMAGE_CHAIN_ROOT if turn % 2 else mk.IMAGE_CHAIN_DEEP
            more = self.call(mk.MODE_IMAGE, ev, now, c=c, arg=how, check_overflow=check_overflow)
            if more == now:  # each event's image of the set is inside it
                return now
            now, turn = more, turn + 1
            self._resume = (ev, a, c, turn, now)
            if passes and turn >= passes:
                raise _NoFixedPoint()

    @property
    def nodes(self) -> int:
        return int(self.arrays[0][mk.META_NODES])

    def held(self) -> int:
        """The bytes its arrays hold now: the nodes, tables and the counts of its sets (:meth:`count`)."""
        return sum(a.nbytes for a in self.arrays) + self._count_bytes()

    def _count_bytes(self) -> int:
        """The bytes of the counts of its sets (:meth:`count`): about 17 a node with one prime."""
        return self._done.nbytes + self._approx.nbytes + self._residue.nbytes

    def read_bytes(self) -> int:
        """The bytes a count of its sets reads (:meth:`counting`): the nodes' buffers and their counts."""
        return sum(a.nbytes for a in self.arrays[1:5]) + self._count_bytes()

    def contains(self, node: int, values: np.ndarray) -> bool:
        offset, size, kids = self.arrays[2:5]
        return bool(mk.node_of_path(node, values.astype(np.int64), offset, size, kids) == mk.TERMINAL)

    def path(self, values: np.ndarray) -> int:
        """The node of the set of one path (a value per level: one marking)."""
        meta = self.arrays[0]
        node, *grown = mk.add_path(values.astype(np.int64), self.dom, meta, *self.arrays[1:6])
        self.arrays = (meta, *grown, self.arrays[6])
        return int(node)

    def sample(self, node: int, rng: np.random.Generator) -> np.ndarray:
        """A path of a non-empty set drawn about uniformly (each child in proportion to the float
        estimate of its paths, :meth:`count` of ``node`` first): its value per level."""
        self.count(node)
        offset, size, kids = self.arrays[2:5]
        out = np.zeros(self.enc.n_levels, dtype=np.int64)
        for k in range(self.enc.n_levels):
            ch = kids[int(offset[node]):int(offset[node]) + int(size[node])].astype(np.int64)
            w = np.where(ch == mk.TERMINAL, 1.0, self._approx[ch]) * (ch != mk.EMPTY)
            with np.errstate(over="ignore", invalid="ignore"):
                total = float(w.sum())
            if not np.isfinite(total) or total <= 0:  # beyond a float: any non-empty child
                w = (ch != mk.EMPTY).astype(np.float64)
            i = int(rng.choice(ch.size, p=w / w.sum()))
            out[k] = i
            node = int(ch[i])
        return out

    def pick(self, node: int) -> np.ndarray:
        """One path of a non-empty set: its value per level."""
        offset, size, kids = self.arrays[2:5]
        out = np.zeros(self.enc.n_levels, dtype=np.int64)
        for k in range(self.enc.n_levels):
            o, n = int(offset[node]), int(size[node])
            for i in range(n):
                if kids[o + i] != mk.EMPTY:
                    out[k] = i
                    node = int(kids[o + i])
                    break
        return out

    def count(self, node: int, at_most: float = 0.0) -> int:
        """The exact number of paths (markings) of a set (the first count, of the largest set, sets
        how many primes every count uses; ``at_most``: a bound of counts to come, which may ask for
        more)."""
        if node <= mk.TERMINAL:
            return node
        want = ceil((min(log2(max(at_most, 2.0)), self.domain_bits) + 3) / 60)
        if len(self._primes) < want:
            self._primes = _primes(want)
            self._count_cap = 0
        if not self._primes:
            self._primes = _primes(1)
        meta, level, offset, size, kids = self.arrays[:5]
        n = int(meta[mk.META_NODES])
        if n > self._count_cap:
            cap = max(n, 2 * self._count_cap)
            done = np.zeros(cap, np.uint8)
            approx = np.zeros(cap, np.float64)
            residue = np.zeros((cap, len(self._primes)), np.int64)
            if self._count_cap:
                done[:self._count_cap] = self._done
                approx[:self._count_cap] = self._approx
                residue[:self._count_cap] = self._residue
            self._done, self._approx, self._residue, self._count_cap = done, approx, residue, cap
        primes = np.array(self._primes, dtype=np.int64)
        mk.count(node, offset, size, kids, self.enc.n_levels, level, self._done, self._approx, self._residue, primes)
        estimate = float(self._approx[node])
        if _beyond(estimate, len(self._primes)) and not self._primes_cover_domain():
            # more primes than the first estimate asked for; past a float's range (about 2^1024
            # markings) the estimate is infinite and the product of the level domains bounds every count
            bits = log2(estimate) if estimate < inf else self.domain_bits
            self._primes = _primes(ceil((bits + 3) / 60))
            self._count_cap = 0
            return self.count(node)
        return _crt([int(r) for r in self._residue[node]], self._primes)

    def fewest_reachable(self) -> float:
        """A lower bound of the reachable set's size while a forward closure from M0 builds it in
        this store (and no other call has run on it): the most paths below any of its nodes
        (:func:`.mdd_kernel.most_paths`; inf past a float's range). Saturation and chained images
        check in only sets of sub-markings that complete a reachable marking of the levels above
        into reachable markings (they unite images of reachable markings: Ciardo, Lüttgen,
        Siminiceanu 2001), so each node's paths are as many reachable markings. One pass over the
        nodes, |nodes| floats of scratch."""
        meta, _level, offset, size, kids = self.arrays[:5]
        return float(mk.most_paths(int(meta[mk.META_NODES]), offset, size, kids))

    def _primes_cover_domain(self) -> bool:
        """The primes' product exceeds every set's count (:attr:`domain_bits`)."""
        return 60 * len(self._primes) - 3 > self.domain_bits

    def enabled_counts(self, node: int, ev: Events) -> list[int]:
        """Per event of ``ev``: the exact number of markings of the set ``node`` in which it is
        enabled (:func:`.mdd_kernel.enabled_counts`; builds no node). Counts modulo the primes of
        the set's own :meth:`count`, so that count must have been given a bound (``at_most``) of
        the largest of these."""
        return self.counting(node, ev)()

    def counting(self, node: int, ev: Events) -> Callable[[], list[int]]:
        """:meth:`enabled_counts` in two steps: what the count reads is taken now (the set's
        :meth:`count` first, in the calling thread), and the function returned counts. That
        function may run in another thread while this one goes on with the store
        (:class:`_Counting`): it reads the nodes of the set, which the store never changes (it
        only appends nodes, and a grown buffer is a new array, the old one kept alive by the
        function), and their counts, which :meth:`count` writes once each (a new prime starts new
        arrays). Raises AnalysisError (internal) when a count outgrows the set's primes."""
        self.count(node)
        meta, level, offset, size, kids = self.arrays[:5]
        n_nodes = int(meta[mk.META_NODES])
        residue, approx_of, primes_of = self._residue, self._approx, list(self._primes)
        covered = 60 * len(primes_of) - 3 > self.domain_bits
        n_levels = self.enc.n_levels

        def run() -> list[int]:
            primes = np.array(primes_of, dtype=np.int64)
            res = np.zeros((ev.n_events, len(primes_of)), np.int64)
            approx = np.zeros(ev.n_events, np.float64)
            on_ptr, on_val = mk.enabling_values(ev.fn_ptr, ev.fn)
            sid = mk.suffix_ids(ev.top, ev.bot, ev.slot_ptr, ev.slot, on_ptr, on_val, self.dom)
            mk.enabled_counts(node, ev.top, ev.bot, ev.slot_ptr, ev.slot, sid, on_ptr, on_val, offset, size, kids,
                              level, n_levels, n_nodes, residue, approx_of, primes, res, approx)
            if approx.size and _beyond(float(approx.max()), len(primes_of)) and not covered:
                raise AnalysisError("internal: an enabled count beyond the primes of the set's count")
            return [_crt([int(r) for r in row], primes_of) for row in res]

        return run

    def presence(self, node: int) -> np.ndarray:
        """(Σ dom,) uint8: the values each level takes in the set (flat, per level by ``dom_ptr``)."""
        level, offset, size, kids = self.arrays[1:5]
        out = np.zeros(int(self.dom_ptr[-1]), dtype=np.uint8)
        seen = np.zeros(self.nodes, dtype=np.uint8)
        mk.presence(node, offset, size, kids, level, self.dom_ptr, seen, out)
        return out

    def max_weight(self, node: int, weight: np.ndarray) -> int:
        level, offset, size, kids = self.arrays[1:5]
        best = np.zeros(self.nodes, dtype=np.int64)
        done = np.zeros(self.nodes, dtype=np.uint8)
        return int(mk.max_weight(node, offset, size, kids, level, self.enc.n_levels, self.dom_ptr, weight, best, done))


class _OutOfTime(Exception):
    """The deadline of the symbolic analysis passed inside a kernel call."""


class _NoFixedPoint(Exception):
    """Chained images (:meth:`_Store.closure` given ``passes``) still added markings in their last pass."""


class _TooWide(Exception):
    """MODE_DEAD met more sets of pending residuals than its tables hold (:func:`.mdd_kernel.dead_tables`)."""


class BeyondBounds(AnalysisError):
    """A reachable marking fires beyond the values the levels were given: the bounds given to the
    engine were wrong (proven bounds: a fault) or too low (bounds guessed from markings seen).

    Attributes:
        places: (n,) int64 indices of the places of the level the firing left (or of the fixed
            places it would change).
    """

    def __init__(self, message: str, places: np.ndarray) -> None:
        super().__init__(message)
        self.places = places


class _OutOfMemory(AnalysisError):
    """The decision diagram outgrew its byte budget inside a kernel call (the store stays
    consistent): fatal while the reachable set and its deadlocks are built, an undecided answer
    after (liveness, reversibility, the witness's firing sequence)."""


def _crt(residues: list[int], primes: list[int]) -> int:
    value, modulus = 0, 1
    for r, p in zip(residues, primes):
        # value + modulus * x ≡ r (mod p)
        x = ((r - value) * pow(modulus, -1, p)) % p
        value += modulus * x
        modulus *= p
    return value


_kernels_wait: Callable[[], None] | None = None
_KERNELS_WAIT_LOCK = threading.Lock()


def set_kernels_wait(wait: Callable[[], None] | None) -> None:
    """Have ``wait()`` called once, by the next :func:`analyse_symbolic` before it first uses the
    compiled kernels (None: no longer). A command that has another process compile them into
    numba's cache meanwhile waits for it there, so that this process loads them instead of
    compiling them a second time."""
    global _kernels_wait
    with _KERNELS_WAIT_LOCK:
        _kernels_wait = wait


def _await_kernels() -> None:
    global _kernels_wait
    with _KERNELS_WAIT_LOCK:
        wait, _kernels_wait = _kernels_wait, None
    if wait is not None:
        wait()


def load_kernel() -> None:
    """Import the compiled MDD kernel (numba; its cache, or a first compile) with numba's cache in the
    user's cache directory (:mod:`.jit`)."""
    from coordinator.analysis import jit

    jit.configure()


def _marking(enc: Encoding, values: np.ndarray, net: PetriNet) -> np.ndarray:
    out = np.zeros(len(net.places), dtype=np.int64)
    out[enc.fixed] = enc.fixed_values
    for k, ps in enumerate(enc.levels):
        out[ps] = enc.local[k][int(values[k])]
    return out


def _values(enc: Encoding, marking: np.ndarray) -> np.ndarray | None:
    if (marking[enc.fixed] != enc.fixed_values).any():
        return None
    out = np.empty(enc.n_levels, dtype=np.int64)
    for k in range(enc.n_levels):
        v = enc.value_of(k, marking)
        if v < 0:
            return None
        out[k] = v
    return out


class _LevelValues:
    """The level values of many explicit markings at once: each level's local marking read as a
    mixed-radix number (a digit per place, its radix the place's largest local value + 1), offset
    so that the levels' numbers never overlap, and looked up in one sorted table of every level's
    values. Where the numbers would not fit in 62 bits, level by level through the encoding's
    dictionaries instead."""

    def __init__(self, enc: Encoding) -> None:
        self.enc = enc
        # what each transition's levels take in after_one, gathered when first asked (None: never found)
        self._plans: dict[int, tuple[np.ndarray, ...] | None] = {}
        places = np.concatenate(enc.levels)
        self.order = places
        self.starts = np.cumsum([0] + [ps.size for ps in enc.levels[:-1]]).astype(np.int64)
        self.top = np.concatenate([loc.max(axis=0) for loc in enc.local]).astype(np.int64)
        mult: list[np.ndarray] = []
        keys: list[np.ndarray] = []
        vals: list[np.ndarray] = []
        base = np.zeros(enc.n_levels, dtype=np.int64)
        offset = 0
        self.exact = True
        for k, loc in enumerate(enc.local):
            span = 1
            m = []
            for r in loc.max(axis=0):
                m.append(span)
                span *= int(r) + 1
            if offset + span >= 1 << 62:
                self.exact = False
                return
            m_arr = np.array(m, dtype=np.int64)
            mult.append(m_arr)
            keys.append(offset + loc.astype(np.int64) @ m_arr)
            vals.append(np.arange(loc.shape[0], dtype=np.int64))
            base[k] = offset
            offset += span
        self.mult = np.concatenate(mult)
        self.base = base
        self.sizes = np.array([ps.size for ps in enc.levels], dtype=np.int64)
        every = np.concatenate(keys)
        rank = np.argsort(every, kind="stable")
        self.keys = every[rank]
        self.vals = np.concatenate(vals)[rank]

    def of(self, markings: np.ndarray) -> np.ndarray:
        """(n, K) int64 level values of the (n, |P|) markings; a row is all −1 when some level's
        local marking is not one of its values."""
        n = markings.shape[0]
        if not self.exact:
            rows = [_values(self.enc, m) for m in markings]
            return np.array([r if r is not None else np.full(self.enc.n_levels, -1) for r in rows],
                            dtype=np.int64).reshape(n, self.enc.n_levels)
        digits = markings[:, self.order]
        bad = ((digits < 0) | (digits > self.top)).any(axis=1)
        bad |= (markings[:, self.enc.fixed] != self.enc.fixed_values).any(axis=1)
        out = self._found(np.add.reduceat(digits * self.mult, self.starts, axis=1) + self.base)
        out[bad | (out < 0).any(axis=1)] = -1
        return out

    def _found(self, key: np.ndarray) -> np.ndarray:
        """The level value of each level number ``key`` (any shape), −1 where it is none."""
        at = np.minimum(np.searchsorted(self.keys, key), self.keys.size - 1)
        found: np.ndarray = np.where(self.keys[at] == key, self.vals[at], -1)
        return found

    def after_one(self, vals: np.ndarray, marking: np.ndarray, t: int, lev_ptr: np.ndarray,
                  lev: np.ndarray) -> np.ndarray:
        """(K,) int64: the row of :meth:`after` for one marking and one transition, ``marking``
        being the (|P|,) marking whose level values are ``vals`` changed by transition ``t``. What
        its levels take (their places, radices and offsets) is gathered once a transition and
        kept, so that a step of a walk costs a few small array operations, not the dozen
        :meth:`after` makes for any number of rows (about half of a step's time in
        CloudDeployment-PT-6a's walk inside, before)."""
        if not self.exact:
            row: np.ndarray = self.of(marking[None, :])[0]
            return row
        if t not in self._plans:
            levs = lev[lev_ptr[t]:lev_ptr[t + 1]]
            if (levs < 0).any():  # a place on no level would change: never found
                self._plans[t] = None
            else:
                size = self.sizes[levs]
                at = concat_ranges(self.starts[levs], size)
                self._plans[t] = (levs, self.order[at], self.mult[at], self.top[at], np.cumsum(size) - size,
                                  self.base[levs])
        plan = self._plans[t]
        out = vals.astype(np.int64)
        if plan is None:
            out[:] = -1
            return out
        levs, places, mult, top, seg, base = plan
        if levs.size:
            digits = marking[places]
            found = self._found(np.add.reduceat(digits * mult, seg) + base)
            if ((digits < 0) | (digits > top)).any() or (found < 0).any():
                out[:] = -1
                return out
            out[levs] = found
        return out

    def after(self, vals: np.ndarray, markings: np.ndarray, ts: np.ndarray, lev_ptr: np.ndarray,
              lev: np.ndarray) -> np.ndarray:
        """(n, K) int64 level values of the (n, |P|) ``markings``, row i being the marking whose
        level values are ``vals`` ((K,), each found) changed by transition ``ts[i]`` on the levels
        ``lev[lev_ptr[t]:lev_ptr[t + 1]]`` alone (−1 there: a place on no level): only those
        levels are looked up. A row is all −1 as in :meth:`of`."""
        if not self.exact:
            return self.of(markings)
        n = ts.size
        cnt = lev_ptr[ts + 1] - lev_ptr[ts]
        rows = np.repeat(np.arange(n), cnt)
        levs = lev[concat_ranges(lev_ptr[ts], cnt)]
        out = np.repeat(vals[None, :].astype(np.int64), n, axis=0)
        bad = np.zeros(n, dtype=bool)
        bad[rows[levs < 0]] = True  # a place whose count never changes would change
        rows, levs = rows[levs >= 0], levs[levs >= 0]
        if levs.size:
            size = self.sizes[levs]
            pos = concat_ranges(self.starts[levs], size)
            prow = np.repeat(rows, size)
            digits = markings[prow, self.order[pos]]
            bad[prow[(digits < 0) | (digits > self.top[pos])]] = True
            found = self._found(np.add.reduceat(digits * self.mult[pos], np.cumsum(size) - size) + self.base[levs])
            out[rows, levs] = found
            bad[rows[found < 0]] = True
        out[bad] = -1
        return out


def _blocks(ts: np.ndarray, n_places: int) -> list[np.ndarray]:
    """``ts`` in consecutive parts of at most ``_DENSE_BLOCK`` / ``n_places`` transitions (at least
    one), so that a part's markings, dense, stay within ``_DENSE_BLOCK`` entries."""
    step = max(1, _DENSE_BLOCK // max(1, n_places))
    return [ts[i:i + step] for i in range(0, ts.size, step)]


class _Explicit:
    """What the witness's searches over explicit markings share, built once a witness: the net's
    arcs by transition (Pre, Post and inhibitor as sparse columns, the incidence as rows), so that the
    transitions a marking enables, or may have been reached by, cost the arcs and not |P|·|T|;
    and the level values of the encoding's markings (:class:`_LevelValues`, built when first asked:
    an encoding without levels has none, and its only marking needs no search)."""

    def __init__(self, sn: SparseNet, enc: Encoding) -> None:
        self.enc = enc
        self.m0 = np.asarray(sn.m0, dtype=np.int64)
        self.n_places = sn.n_places
        self.n_t = sn.n_transitions
        self.pre = sn.pre.tocsc()
        self.post = sn.post.tocsc()
        self.inh = sn.inhibitor.tocsc()
        # the incidence by transition (rows), for the successors and predecessors of a marking
        inc_t = sn.incidence.T.tocsr()
        self.inc_ptr = inc_t.indptr.astype(np.int64)
        self.inc_places = inc_t.indices.astype(np.int64)
        self.inc_data = inc_t.data.astype(np.int64)
        # the transitions whose firing leaves every count as it was (self-loops, or none at all)
        self.still = np.bincount(np.repeat(np.arange(self.n_t), np.diff(self.inc_ptr))[self.inc_data != 0],
                                 minlength=self.n_t) == 0
        self.pre.sort_indices()
        self.inh.sort_indices()
        self.pre_t = np.repeat(np.arange(self.n_t), np.diff(self.pre.indptr))
        self.post_t = np.repeat(np.arange(self.n_t), np.diff(self.post.indptr))
        self.inh_t = np.repeat(np.arange(self.n_t), np.diff(self.inh.indptr))
        # the incidence on the inhibitor arcs: a predecessor's count there is the marking's minus it
        self.inh_c = (np.asarray(sn.incidence.tocsc()[self.inh.indices, self.inh_t]).ravel() if self.inh.nnz
                      else np.zeros(0, np.int64))

    @functools.cached_property
    def lookup(self) -> _LevelValues:
        return _LevelValues(self.enc)

    @functools.cached_property
    def narrow(self) -> tuple[np.dtype, np.dtype]:
        """The narrowest signed integer types of a marking of the encoding (every count at most
        the largest of its levels' local markings or of its fixed places: int8 on a 1-safe net)
        and of its level values (below the widest level's number of values): the witness's
        search keeps its markings in them."""
        enc = self.enc
        top = max([0, int(enc.fixed_values.max(initial=0))] + [int(loc.max(initial=0)) for loc in enc.local])
        return np.min_scalar_type(-top - 1), np.min_scalar_type(-int(enc.dom.max(initial=1)) - 1)

    @functools.cached_property
    def changed(self) -> tuple[np.ndarray, np.ndarray]:
        """The levels each transition's firing changes, ``(ptr, lev)``: those of transition t are
        ``lev[ptr[t]:ptr[t + 1]]``, increasing, −1 first when it changes a place on no level (for
        :meth:`_LevelValues.after`)."""
        arc_t = np.repeat(np.arange(self.n_t, dtype=np.int64), np.diff(self.inc_ptr))
        pairs = np.unique(np.stack([arc_t, self.enc.place_level[self.inc_places]], axis=1), axis=0)
        pairs = pairs.reshape(-1, 2)
        return np.searchsorted(pairs[:, 0], np.arange(self.n_t + 1)).astype(np.int64), pairs[:, 1].copy()

    def enabled(self, m: np.ndarray) -> np.ndarray:
        """(k,) int64: the transitions that the (|P|,) marking ``m`` enables, in index order."""
        off = np.zeros(self.n_t, dtype=bool)
        off[self.pre_t[m[self.pre.indices] < self.pre.data]] = True
        off[self.inh_t[(self.inh.data > 0) & (m[self.inh.indices] >= self.inh.data)]] = True
        return np.flatnonzero(~off)

    def fired(self, m: np.ndarray, ts: np.ndarray, sign: int = 1) -> np.ndarray:
        """(len(ts), |P|) int64: the (|P|,) marking ``m`` plus ``sign`` times the incidence column
        of each transition of ``ts`` (its successors by them, or with ``sign`` −1 the predecessors
        they lead from), dense rows built from the arcs alone."""
        ptr = self.inc_ptr
        counts = ptr[ts + 1] - ptr[ts]
        rows = np.repeat(np.arange(ts.size), counts)
        at = concat_ranges(ptr[ts], counts)
        out = np.repeat(m[None, :].astype(np.int64), ts.size, axis=0)
        out[rows, self.inc_places[at]] += sign * self.inc_data[at]
        return out

    def reached_by(self, m: np.ndarray) -> np.ndarray:
        """(k,) int64: the transitions that can have led to the (|P|,) marking ``m``: ``m`` holds
        their output tokens (so the predecessor m − C[:, t] holds their input tokens) and the
        predecessor satisfies their inhibitor arcs."""
        off = np.zeros(self.n_t, dtype=bool)
        off[self.post_t[m[self.post.indices] < self.post.data]] = True
        off[self.inh_t[(self.inh.data > 0) & (m[self.inh.indices] - self.inh_c >= self.inh.data)]] = True
        return np.flatnonzero(~off)


def _guided_sequence(store: _Store, ex: _Explicit, net: PetriNet, inside: int, targets: int, goal: np.ndarray,
                     limit: int, stop: float, max_bytes: int = _GUIDED_BYTES) -> tuple[list[str], np.ndarray] | None:
    """A firing sequence from M0 to one of ``targets`` by a best-first search over explicit markings
    that never leaves ``inside`` (every marking of which can reach a target), always going on from
    the marking nearest (in tokens) to the dead marking ``goal``, the deepest first among equals; so
    it mostly walks straight to a target. None when it has seen ``limit`` markings, or as many as
    ``max_bytes`` hold, or at ``stop`` (``time.monotonic()`` seconds), first. A marking costs the
    net's arcs (sparse Pre, inhibitor and incidence) and its successors, built in blocks
    (:func:`_blocks`), not |P|·|T|; one it has seen is kept in the narrowest integer types
    (:attr:`_Explicit.narrow`): 2·|P| + K + 600 bytes on a 1-safe net whose K levels have fewer
    than 128 values each (AirplaneLD-PT-2000: 14,019 places, 8,017 levels; as int64 arrays,
    100,000 markings would take 22 GB)."""
    import heapq

    lookup, m0 = ex.lookup, ex.m0
    vals0 = lookup.of(m0[None, :])[0]
    if vals0[0] >= 0 and store.contains(targets, vals0):
        return [], m0
    if vals0[0] < 0:  # M0 outside the encoding: nothing to search from
        return None
    small, small_vals = ex.narrow
    per = 2 * ex.n_places * small.itemsize + vals0.size * small_vals.itemsize + _SEEN_OVERHEAD
    limit = min(limit, max(1, max_bytes // per))
    lev_ptr, lev = ex.changed
    marks = [m0.astype(small)]
    levels = [vals0.astype(small_vals)]  # the level values of each marking of marks
    parent = [-1]
    via = [-1]
    depth = [0]
    seen = {marks[0].tobytes()}
    heap = [(int(np.abs(m0 - goal).sum()), 0, 0)]
    while heap:
        if len(seen) > limit or time.monotonic() > stop:
            return None
        _, _, i = heapq.heappop(heap)
        m = marks[i].astype(np.int64)
        for ts in _blocks(ex.enabled(m), ex.n_places):
            succ = ex.fired(m, ts)
            vals = lookup.after(levels[i], succ, ts, lev_ptr, lev)
            keys = succ.astype(small)  # a row outside the encoding may wrap: it is never looked at
            for j, t in enumerate(ts):
                if vals[j, 0] < 0:  # outside the encoding: never inside, and not kept as seen
                    continue
                key = keys[j].tobytes()
                if key in seen:
                    continue
                seen.add(key)
                if not store.contains(inside, vals[j]):
                    continue
                marks.append(keys[j].copy())  # copies: a view would keep its whole block of successors alive
                levels.append(vals[j].astype(small_vals))
                parent.append(i)
                via.append(int(t))
                depth.append(depth[i] + 1)
                node = len(marks) - 1
                if store.contains(targets, vals[j]):
                    path: list[str] = []
                    while node > 0:
                        path.append(net.transitions[via[node]].id)
                        node = parent[node]
                    return path[::-1], succ[j]
                heapq.heappush(heap, (int(np.abs(succ[j] - goal).sum()), -depth[-1], len(marks) - 1))
    return None


def _walk_sequence(store: _Store, ex: _Explicit, net: PetriNet, targets: int, stop: float,
                   inside: int | None = None) -> tuple[list[str], np.ndarray] | None:
    """A firing sequence from M0 to one of ``targets`` by random walks: from M0, a transition drawn
    among the enabled ones fires, again and again, until none is enabled (the walk ends in a dead
    marking, kept when it is one of ``targets``) or after :data:`_WALK_STEPS` steps; at most
    :data:`_WALKS` walks, until ``stop`` (``time.monotonic()`` seconds). Where deadlocks are many
    and reachable from almost everywhere, a walk falls into one within a few dozen steps while the
    search guided by the token distance wanders: CloudReconfiguration-PT-303, whose dead marking
    is the empty one, has walks of 51 to 172 steps, milliseconds each, where the guided search
    found none among 100,000 markings and breadth-first images took 174 s. None if no walk ends
    in a target. A step costs the net's arcs, not |P|·|T|.

    With ``inside``, the reachable markings that can reach one of ``targets`` (a backward closure),
    the walks never leave it (:func:`_step_inside`), for up to :data:`_INSIDE_WALK_STEPS` steps:
    every marking of it that is not a target has a successor in it, so a walk ends in a target or
    goes round a cycle. Where free walks leave for markings from which no deadlock is reachable,
    these cannot: CloudDeployment-PT-5a's dead marking, which neither free walks nor the guided
    search reached, and whose breadth-first images were not done by the answer's 50 s, is at the end
    of a walk of 7,628 steps. A walk takes no step by a transition whose firing changes no count
    (:attr:`_Explicit.still`), and stops where only such are enabled: it would stand still
    (CloudDeployment-PT-6a's walk inside: 32,917 steps in 2.3 s with them, 4,716 without)."""
    ptr, places, data = ex.inc_ptr, ex.inc_places, ex.inc_data
    rng = np.random.default_rng(0xDEAD if inside is None else 0xD1CE)
    steps = _WALK_STEPS if inside is None else _INSIDE_WALK_STEPS
    for _ in range(_WALKS):
        m = ex.m0.copy()
        vals = None if inside is None else ex.lookup.of(m[None, :])[0]  # kept along a walk inside
        seq: list[int] = []
        while len(seq) < steps:
            on = ex.enabled(m)
            if on.size == 0:
                if vals is None:
                    vals = ex.lookup.of(m[None, :])[0]
                if vals[0] >= 0 and store.contains(targets, vals):
                    return [net.transitions[t].id for t in seq], m
                break
            on = on[~ex.still[on]]  # a firing that changes nothing is no step
            if on.size == 0:  # only such: the walk would stay here for ever
                break
            if inside is None:
                t = int(on[rng.integers(on.size)])
                m[places[ptr[t]:ptr[t + 1]]] += data[ptr[t]:ptr[t + 1]]
            else:
                assert vals is not None
                step = _step_inside(store, ex, m, vals, on[rng.permutation(on.size)], inside)
                if step is None:  # no successor inside: only a marking outside could be so (M0, if not in it)
                    break
                t, m, vals = step
            seq.append(t)
            if len(seq) % 64 == 0 and time.monotonic() > stop:
                return None
        if time.monotonic() > stop:
            return None
    return None


def _step_inside(store: _Store, ex: _Explicit, m: np.ndarray, vals: np.ndarray, on: np.ndarray,
                 inside: int) -> tuple[int, np.ndarray, np.ndarray] | None:
    """The first transition of ``on`` (enabled in the (|P|,) marking ``m``, whose level values are
    ``vals``) whose successor lies in ``inside``, with that successor and its level values; None if
    none does. Costs the transitions' arcs and a path through the diagram for each successor tried,
    its level values looked up on the levels the transition changes alone: the first
    :data:`_ONE_BY_ONE` one at a time (:meth:`_LevelValues.after_one`), as the first one tried is
    most often inside (CloudDeployment-PT-6a: 33,288 tried in a walk of 32,917 steps), the others
    in blocks."""
    lev_ptr, lev = ex.changed
    ptr, places, data = ex.inc_ptr, ex.inc_places, ex.inc_data
    for t in on[:_ONE_BY_ONE].tolist():
        succ1 = m.copy()
        succ1[places[ptr[t]:ptr[t + 1]]] += data[ptr[t]:ptr[t + 1]]
        after1 = ex.lookup.after_one(vals, succ1, t, lev_ptr, lev)
        if after1[0] >= 0 and store.contains(inside, after1):
            return t, succ1, after1
    for ts in _blocks(on[_ONE_BY_ONE:], ex.n_places):
        succ = ex.fired(m, ts)
        after = ex.lookup.after(vals, succ, ts, lev_ptr, lev)
        for j in range(ts.size):
            if after[j, 0] >= 0 and store.contains(inside, after[j]):
                return int(ts[j]), succ[j], after[j]
    return None


def _bfs_sequence(store: _Store, ex: _Explicit, net: PetriNet, fwd: Events, inside: int,
                  targets: int) -> tuple[list[str], np.ndarray] | None:
    """A shortest firing sequence from M0 to one of ``targets`` and that marking: breadth-first
    images of M0 inside ``inside`` until a layer meets the targets, then back from that marking,
    layer by layer, through transitions whose predecessor lies in the layer before."""
    m0 = store.m0
    layers = [m0]
    seen = m0
    hit = store.call(mk.MODE_APPLY, fwd, m0, targets, arg=mk.APPLY_INTER)
    while hit == mk.EMPTY:
        step = store.call(mk.MODE_IMAGE, fwd, layers[-1], c=inside)
        new = store.call(mk.MODE_APPLY, fwd, step, seen, arg=mk.APPLY_DIFF)
        if new == mk.EMPTY:
            return None
        seen = store.call(mk.MODE_APPLY, fwd, seen, new, arg=mk.APPLY_UNION)
        layers.append(new)
        hit = store.call(mk.MODE_APPLY, fwd, new, targets, arg=mk.APPLY_INTER)
    cur = _marking(ex.enc, store.pick(hit), net)
    end = cur.copy()
    if len(layers) == 1:  # M0 is a target
        return [], end
    seq: list[str] = []
    lev_ptr, lev = ex.changed
    cur_vals = ex.lookup.of(cur[None, :])[0]
    for layer in reversed(layers[:-1]):
        before = None
        for ts in _blocks(ex.reached_by(cur), ex.n_places):
            prev = ex.fired(cur, ts, -1)
            vals = ex.lookup.after(cur_vals, prev, ts, lev_ptr, lev)
            for j in np.flatnonzero(vals[:, 0] >= 0):
                if store.contains(layer, vals[j]):
                    seq.append(net.transitions[int(ts[j])].id)
                    before = prev[j]
                    cur_vals = vals[j]
                    break
            if before is not None:
                break
        if before is None:
            raise AnalysisError("internal: no predecessor found while tracing a firing sequence back")
        cur = before
    seq.reverse()
    return seq, end


def analyse_symbolic(net: PetriNet, bounds: np.ndarray, *, flows: list[np.ndarray] | None = None,
                     max_bytes: int = 4 << 30, seconds: float = 600.0, answer_seconds: float = ANSWER_SECONDS,
                     progress: Callable[[str], None] | None = None, probes: int = PROBES,
                     stop: threading.Event | None = None, borrow: Callable[[], int] | None = None,
                     seen: Callable[[], np.ndarray | None] | None = None, rival: Rival | None = None) -> SymbolicResult:
    """The reachable set of a bounded net by saturation, and its properties (module docstring).

    Args:
        net: the ordinary net (events dropped; no priorities).
        bounds: (|P|,) proven upper bound of every place (state equation, P-invariants), -1 where
            none is proven (the levels are then guessed from ``seen``, and the net is shown bounded
            when the reachable set on them is closed under firing: :func:`_reachable`).
        flows: P-semiflows of the net (groups and order, :mod:`.mdd_order`); none: only places.
        max_bytes: byte budget of the decision diagram.
        seconds: time budget; liveness and witnesses are left undecided when it runs out after the
            reachable set was built.
        answer_seconds: the firing sequence to a dead marking (its quick search at least),
            reversibility and liveness (beyond what the deadlocks and quasi-liveness
            decide) are worked on only until this many seconds after the start (and within
            ``seconds``), and left undecided after: the whole answer, the place bounds proven
            before included, comes within a minute by default when the reachable set and its
            counts are quick.
        progress: called with short phase descriptions.
        probes: markings drawn from the reachable set for the forward test of liveness on a net
            that is not reversible, before the backward saturations (:func:`_probe`); 0: backward only,
            which decides every transition's liveness when there is time (the probe stops at the
            first transition it shows not live).
        stop: an event another thread sets to stop the engine (the automatic engine's explicit
            search finished first): the race for the reachable set ends with AnalysisError, and a
            later phase stops as at its deadline, leaving what it had not decided undecided.
        borrow: called (once, from any thread) when the decision diagram outgrows ``max_bytes``,
            while the reachable set is built or after: the bytes it frees for the engine (the
            automatic engine's explicit search beside it stops and hands its share over), 0 for
            none; the call that outgrew the budget goes on from its store.
        seen: called once, when the proven bounds make levels too wide or some place has none
            (:func:`_reachable`): (|P|,) int64, the largest count of each place in some reachable
            markings (those of an explicit search stopped early), or None for none.
        rival: another search racing the engine for the reachable set (:class:`Rival`), whose
            markings found so far decide which of the race's lanes yield the CPUs to it, and which
            stops when the set is built (:attr:`Rival.settled`).

    Returns:
        A :class:`SymbolicResult`.

    Raises:
        AnalysisError: a place without a proven bound and no counts seen, or whose guessed values a
            firing still leaves after their last raise, the memory budget, the time budget reached before
            the reachable set was complete, or ``stop`` set before it was.
    """
    _await_kernels()
    start = time.monotonic()
    deadline = start + seconds
    say = progress or (lambda _text: None)
    sn = sparse_net(net)
    secs: dict[str, float] = {}
    notes: list[str] = []
    t0 = time.monotonic()

    def widen() -> int:
        extra = 0 if borrow is None else borrow()
        if extra > 0:
            say(f"symbolic: {extra / 2**30:.2f} GiB more for the decision diagram (the explicit search beside it "
                "stopped)")
        return extra

    try:
        (enc, fwd, store, reach), kept, states = _reachable(sn, net, bounds, seen, list(flows or []), max_bytes,
                                                            deadline, say, stop, None if borrow is None else widen,
                                                            rival,
                                                            notes)
        if rival is not None:
            rival.settled.set()  # the search racing for the same set stops
        single = events(sn, enc, like=fwd)  # the transitions' functions of the forward events, again
        secs["encode"] = enc.seconds
        secs["reach"] = time.monotonic() - t0 - enc.seconds
        say(f"symbolic: {states:,} markings, {store.nodes:,} nodes, {secs['reach']:.1f} s")
        t0 = time.monotonic()
        free = enc.free(touched_places(sn))
        fireable = free.copy()
        store.count(reach, at_most=_as_float(states) * max(1, single.n_events))
        # the counts per transition (edges, quasi-liveness) beside the deadlocks, bounds and witness
        enabled = _Counting(store, reach, single, beside=cpus() >= 2)
        dead = _dead(store, fwd, single, reach, enabled, states) if not free.any() else mk.EMPTY
        n_dead = store.count(dead)
        present = store.presence(reach)
        place_bounds = np.zeros(len(net.places), dtype=np.int64)
        low = np.zeros(len(net.places), dtype=np.int64)
        place_bounds[enc.fixed] = low[enc.fixed] = enc.fixed_values
        for k, ps in enumerate(enc.levels):
            vals = np.flatnonzero(present[store.dom_ptr[k]:store.dom_ptr[k + 1]])
            loc = enc.local[k][vals]
            place_bounds[ps] = loc.max(axis=0)
            low[ps] = loc.min(axis=0)
        weight = np.concatenate([np.zeros(0, np.int64), *enc.weight]).astype(np.int64)
        max_total = store.max_weight(reach, weight) + enc.fixed_tokens
        secs["properties"] = time.monotonic() - t0
        result = SymbolicResult(
            states=states, edges=0, deadlock=n_dead > 0, n_deadlocks=n_dead, deadlock_marking=None,
            deadlock_sequence=None, fireable=fireable, place_bounds=place_bounds, stable=place_bounds == low,
            max_token_per_marking=max_total, live=None,
            live_transitions=np.full(len(net.transitions), None, dtype=object), reversible=None,
            levels=enc.n_levels, groups=enc.groups, nodes=store.nodes, order_score=enc.score,
            method="chaining" if store.chain else "saturation", seconds=secs, notes=notes)
        back: Events | None = None
        if sn.n_resets == 0:
            back = events(sn, enc, inverse=True, merge=True, like=fwd)
        # the firing sequence to a dead marking is traced within the answer's time too (its quick
        # search at least): the verdict and the dead marking are already known
        until = min(deadline, start + answer_seconds)
        traced = min(deadline, max(until, time.monotonic() + _QUICK_SECONDS))
        mk.set_watch(traced, None, stop)
        _witness(store, sn, enc, net, fwd, back, reach, dead, result, say, traced)
        mk.set_watch(until, None, stop)
        t0 = time.monotonic()
        edges, counts = _edges(enabled.result(), single, fireable)  # fireable is the result's
        result.edges = edges + int(free.sum()) * states
        secs["properties"] += time.monotonic() - t0  # the wait for the counts
        upside: _Beside | None = None
        held = 0 if kept is None else kept.store.held()  # already taken from the store's budget
        spare = max(0, store.max_bytes - store.held()) // 2
        beside = back is not None and cpus() >= 2 and states > 1 and not result.deadlock
        if kept is not None and beside:
            store.max_bytes -= spare
            upside = _Upside(sn, kept, held + spare, until, stop, say)
        else:  # the kept store, if any, is freed (the race and its lanes refer to it) and its bytes go back
            if kept is not None:
                kept.drop()
            store.max_bytes += held
            if beside and back is not None:
                store.max_bytes -= spare
                upside = _Home(sn, store, back, reach, spare, until, stop, say)
        try:
            _liveness(store, fwd, single, back, reach, counts, result, say, until, probes, stop, upside)
        finally:
            if upside is not None:
                _take_back(store, upside)
        result.nodes = store.nodes
        return result
    finally:
        mk.set_watch(None, None)


#: most times the guessed values of levels are raised after a firing left them (:func:`_reachable`)
_RAISES = 6


def _reachable(sn: SparseNet, net: PetriNet, bounds: np.ndarray, seen: Callable[[], np.ndarray | None] | None,
               flows: list[np.ndarray], max_bytes: int, deadline: float, say: Callable[[str], None],
               stop: threading.Event | None, borrow: Callable[[], int] | None, rival: Rival | None,
               notes: list[str]) -> tuple[_Won, _Candidate | None, int]:
    """The reachable set (:func:`_race`), the race's order upside down if its store was kept, and
    the number of markings. On the proven bounds first;
    when they make levels too wide (:class:`~.mdd_order.EncodingTooLarge`: AirplaneLD-PT-1000's
    state equation bounds its 1-safe places by 3,004 and 3,008, and its 4,017 levels would take
    3.7 GiB) and ``seen()`` gives counts, each place gets min(bound, 2·seen + 1) values instead.
    Saturation checks every firing against the levels' values (``check_overflow``) and
    :func:`_check_suspects` the fixed places, so when neither finds a firing that leaves them, the
    set is the reachable set, exactly; when one does, the places of that level are raised to
    min(bound, 4·value + 3) and the race runs again, at most :data:`_RAISES` times (a note says
    so). AirplaneLD-PT-1000: every place seen at 1 in a million markings, 3 values a place, its
    34,087,074,023 markings in 23 s. A place without a proven bound (-1 in ``bounds``) starts
    from its count seen and is raised without a cap: a set that no firing leaves contains every
    reachable marking, so it is the reachable set and the net is bounded (Murphy-PT-D2N050, whose
    state equation bounds none of its nine places p3_1 … p5_3: 41,538,421,296 markings in 4 s).
    Those places then start from their counts seen, the others from their proven bounds (all are
    guessed if those are too wide), and when a firing leaves one of them all of them are raised.

    Raises:
        AnalysisError: as :func:`_race`; EncodingTooLarge when no counts are seen; BeyondBounds on
            proven bounds (a fault), or when the guessed values are left after their last raise.
    """
    known = bounds >= 0  # a place without a proven bound (-1) is bounded only by a closed set
    domains, raises, why = bounds, 0, ""

    counts: np.ndarray | None = None

    def guessed(reason: str, proven_too: bool) -> np.ndarray:
        assert counts is not None
        g = 2 * np.asarray(counts, dtype=np.int64) + 1
        out = np.where(known, np.minimum(bounds, g) if proven_too else bounds, g)
        which = "each place's count" if proven_too else "the count of each place without one"
        top = int((out if proven_too else out[~known]).max(initial=0))
        say(f"symbolic: {reason}; the levels take {which} seen by the explicit search, doubled, plus one (at most "
            f"{top:,} tokens a place)")
        return out

    if not known.all():
        why = (f"{int((~known).sum()):,} places have no proven bound (the symbolic engine needs a bounded net: "
               "its reachable set on levels guessed from counts seen must be closed under firing)")
        counts = None if seen is None else seen()
        if counts is None:
            raise AnalysisError(f"{why}, and no counts were seen")
        domains = guessed(why, False)  # the proven bounds where there are some
    while True:
        try:
            won, kept = _race(sn, domains, flows, max_bytes, deadline, say, stop, borrow, rival)
            enc, _, store, reach = won
            states = store.count(reach)
            _check_suspects(store, sn, enc, net, reach)
        except EncodingTooLarge as exc:
            if why and (counts is None or (domains[known] <= 2 * np.asarray(counts)[known] + 1).all()):
                raise EncodingTooLarge(f"{why}; on the counts seen, {exc}") from exc
            if counts is None:
                counts = None if seen is None else seen()
            if counts is None:
                raise
            why = why or f"on the proven bounds {exc}"
            domains = guessed(why, True)
            continue
        except BeyondBounds as exc:
            pl = exc.places
            if not why or (known[pl] & (domains[pl] >= bounds[pl])).all():
                raise
            if not known[pl].all():  # the places no bound is proven for grow together
                pl = np.union1d(pl, np.flatnonzero(~known)).astype(np.int64)
            if raises == _RAISES or time.monotonic() >= deadline:
                raise AnalysisError(f"{why}, and a firing still left the values guessed from "
                                    f"the counts the explicit search saw after {raises} raises") from exc
            raises += 1
            domains = domains.copy()
            up = 4 * domains[pl] + 3
            domains[pl] = np.where(known[pl], np.minimum(bounds[pl], up), up)
            say(f"symbolic: a firing left the values guessed for {pl.size} places; raised to at most "
                f"{int(domains[pl].max()):,} tokens, the reachable set again ({raises} of {_RAISES})")
            continue
        if why:
            raised = "" if not raises else (", raised once where a firing left them" if raises == 1 else
                                            f", raised {raises} times where firings left them")
            closed = ("so every count is exact" if known.all() else
                      "so the reachable set is closed under firing: the net is bounded and every count is exact")
            notes.append(f"{why}: the levels took each place's count seen by the explicit search, doubled, plus "
                         f"one{raised}; saturation checked every firing against them, {closed}")
        return won, kept, states


def _check_suspects(store: _Store, sn: SparseNet, enc: Encoding, net: PetriNet, reach: int) -> None:
    """No reachable marking enables a transition that fixed places enable but that would change them
    (:class:`~.mdd_order.Encoding`: such a transition never fires if the bounds are right, and the
    first of them to fire on any firing sequence would be enabled in a marking of ``reach``).

    Raises:
        AnalysisError: one does: the bounds were wrong."""
    suspect = np.flatnonzero(enc.suspect)
    if not suspect.size:
        return
    ev = events(sn, enc, transitions=suspect)
    wrong = sorted(set(suspect.tolist()) - {ms[0] for ms in ev.members})  # on fixed places only
    if not wrong and ev.n_events:
        wrong = [ev.members[e][0] for e, n in enumerate(store.enabled_counts(reach, ev)) if n > 0]
    if wrong:
        t = wrong[0]
        raise BeyondBounds(f"transition {net.transitions[t].id} would take a place beyond its proven "
                           "bound: the place bounds given to the symbolic engine are wrong",
                           np.intersect1d(touched_places(sn)[t], enc.fixed).astype(np.int64))


def _edges(counts: list[int], single: Events, fireable: np.ndarray) -> tuple[int, list[int]]:
    """Mark in ``fireable`` the transitions enabled in some reachable marking, from ``counts``: per
    event of ``single`` (one transition each), the number of reachable markings enabling it
    (:meth:`_Store.enabled_counts`); return the number of edges (reachable marking, enabled
    transition) and ``counts``."""
    for e, n in enumerate(counts):
        fireable[list(single.members[e])] = n > 0
    return sum(counts), counts


class _Counting:
    """The number of reachable markings enabling each event (:meth:`_Store.counting`), counted in a
    thread beside the phases that follow the reachable set (``beside``: two CPUs or more), or at
    once. After the race the second CPU is idle; the deadlocks, the bounds and the witness's
    firing sequence need no count per transition, and the count reads only nodes the store never
    changes, so it runs beside them (BridgeAndVehicles-PT-V80P20N20, 3,728 transitions: 4.7 s of
    counts; Sudoku-PT-AN04: 2.1 s beside 3.2 s of deadlocks; docs/BENCHMARKS.md). While it runs,
    a buffer the store outgrows stays allocated until the count ends, so what the count reads
    (:meth:`_Store.read_bytes`: the nodes' buffers and their counts) is lent out of the store's
    budget until :meth:`result` (AirplaneLD-PT-2000: 0.47 GiB of a store of 0.97 GiB; in a run
    before, its process grew from 2.9 to 3.85 GiB during the witness, buffers doubled beside those
    the count still read), or until a call on the store outgrows what is left: that call waits for
    the count to end and goes on with the bytes given back (:attr:`_Store.reclaim`)."""

    def __init__(self, store: _Store, node: int, ev: Events, beside: bool) -> None:
        self._count: Callable[[], list[int]] | None = store.counting(node, ev)
        self._counts: list[int] | None = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._store, self._lent = store, 0
        if beside:
            self._lent = store.read_bytes()
            store.max_bytes -= self._lent
            store.reclaim = self._give_back
            self._thread = threading.Thread(target=self._run, name="petrobot-enabled-counts", daemon=True)
            self._thread.start()
        else:
            self._run()

    def _run(self) -> None:
        # the function holds the buffers it reads: dropped here, those the store has outgrown are
        # freed when the count ends, not with this object
        count, self._count = self._count, None
        assert count is not None
        try:
            self._counts = count()
        except BaseException as exc:  # raised again in the caller's thread, by result()
            self._error = exc

    def now(self) -> list[int] | None:
        """The counts if they are done, else None (no wait)."""
        return self._counts

    def _give_back(self) -> int:
        """Wait for the count to end (Ctrl-C stays possible), then give the bytes lent back to the
        store's budget (once: 0 after); the bytes given back."""
        if self._thread is not None:
            while self._thread.is_alive():
                self._thread.join(0.2)
        lent, self._lent = self._lent, 0
        self._store.max_bytes += lent  # the buffers it read are the store's alone again
        if self._store.reclaim == self._give_back:
            self._store.reclaim = None
        return lent

    def result(self) -> list[int]:
        """The counts, once done; raises what the count raised."""
        self._give_back()
        if self._error is not None:
            raise self._error
        assert self._counts is not None
        return self._counts


def _dead(store: _Store, fwd: Events, single: Events, reach: int, counts: list[int] | _Counting, states: int,
          max_sets: int = 1 << 19, table_bytes: int | None = None, by_turns: bool = True) -> int:
    """The reachable markings that enable no event of ``fwd``: empty at once when one is enabled in
    every reachable marking (known when ``counts`` are, per event of ``single``: a list, or a
    :class:`_Counting` done already); else in one pass over the reachable set, with the conditions
    pending on each path (MODE_DEAD, :func:`.mdd_kernel.dead_tables`: at most ``max_sets`` sets of
    them, of 8 ``max_sets`` residuals in all, :data:`_DEAD_SET_BYTES` each); when those outgrow
    their tables, the pass again on tables twice as large while they fit in ``table_bytes`` (default:
    half of what the store's budget has left then), and between two passes the reachable set
    restricted event by event (:class:`_ByEvents`, once the counts are done) for as long as the
    passes have taken in all, less what it took before: whichever is done first answers, and the
    restriction alone goes on to the end when the tables no longer fit. One pass:
    AirplaneLD-PT-1000, whose 8,008 events share six places, in 0.15 s where event by event took
    24.5 s; AirplaneLD-PT-2000's 16,008 events need 7,305,766 residuals in 3,833 sets, past the
    first tables after 0.2 s, then 0.1 s on twice their size, where event by event was not done in
    100 s. SharedMemory-PT-000050 outgrew tables of up to 16,777,216 sets in six passes (9.7 s),
    where event by event takes 1.7 s (docs/BENCHMARKS.md). ``by_turns`` False: no restriction
    between the passes, only after the last (bench/deadlocks.py measures both ways)."""
    known = counts if isinstance(counts, list) else counts.now()
    if known is not None and states in known:
        return mk.EMPTY
    dz = mk.dead_tables(store.dom, fwd.top, fwd.bot, fwd.slot_ptr, fwd.slot, fwd.fn_ptr, fwd.fn,
                        max_sets=max_sets, max_items=8 * max_sets)
    if dz is None:  # an event enabled in every marking
        return mk.EMPTY
    by_events = _ByEvents(store, fwd, single, reach)
    passes = 0.0  # the seconds the passes took
    while True:
        t0 = time.monotonic()
        try:
            return store.call(mk.MODE_DEAD, fwd, reach, dz=dz)
        except _TooWide:
            passes += time.monotonic() - t0
        finally:
            mk.clear_cache(store.arrays)  # its results name sets of dz
        max_sets *= 2
        room = max(0, store.max_bytes - store.held()) // 2 if table_bytes is None else table_bytes
        if max_sets * _DEAD_SET_BYTES > room:
            break
        known = counts if isinstance(counts, list) else counts.now()
        if by_turns and known is not None and by_events.run(known, passes - by_events.seconds):
            return by_events.dead
        dz = mk.wider_dead_tables(dz, max_sets, 8 * max_sets)
    by_events.run(counts if isinstance(counts, list) else counts.result())
    return by_events.dead


#: bytes of :func:`.mdd_kernel.dead_tables` per set: its pointer, two hash slots and 8 residuals
_DEAD_SET_BYTES = 8 * (1 + 2 + 8)


class _ByEvents:
    """The reachable markings that enable no event of ``fwd`` (:func:`_dead`), by restricting the
    reachable set event by event, from the top level down (the events of one level, those enabled
    in the most markings first), in slices of time (:meth:`run`): :attr:`dead` once done, the
    markings left so far before. Restricting level by level builds fewer intermediate nodes than
    the most-enabled events first across levels (Sudoku-PT-AN04: 4.3 million new nodes in 17 s
    against 7.8 million in 26 s; ASLink-PT-02a: 2.4 million in 4.6 s against 6.0 million in 9.6 s)."""

    def __init__(self, store: _Store, fwd: Events, single: Events, reach: int) -> None:
        self.store, self.fwd, self.single = store, fwd, single
        #: the markings that enable none of the events restricted so far
        self.dead = reach
        #: the seconds the slices have taken
        self.seconds = 0.0
        self._order: list[int] | None = None
        self._next = 0  # the position in the order of the next event to restrict
        self._failed: _OutOfMemory | None = None

    def run(self, counts: list[int], seconds: float | None = None) -> bool:
        """Go on restricting, for about ``seconds`` (None: to the end; the clock is read after each
        restriction, one at least, and by the kernel within a restriction); whether it is done.
        ``counts``: per event of ``single``, the reachable markings enabling it
        (:meth:`_Store.enabled_counts`), which order the events at the first call. A restriction
        stopped at the slice's end is made again at the next (what it had computed is dropped when
        the store's cache is cleared).

        Raises:
            _OutOfMemory: the store's budget, at once when ``seconds`` is None, else at the call
                to the end (a slice that outgrows it ends the slices: what the restrictions built stays
                in the store). _OutOfTime: the watch this thread had before (:func:`.mdd_kernel.set_watch`)."""
        if self._failed is not None:
            if seconds is None:
                raise self._failed
            return False
        if self._order is None:
            by_t = {self.single.members[e][0]: n for e, n in enumerate(counts)}
            fwd = self.fwd
            self._order = sorted(range(fwd.n_events),
                                 key=lambda e: (int(fwd.top[e]), -sum(by_t.get(t, 0) for t in fwd.members[e])))
        before = mk.watch()
        t0 = time.monotonic()
        end = None if seconds is None else t0 + max(0.0, seconds)
        if end is not None:
            mk.set_watch(end if before[0] is None else min(before[0], end), before[1], before[2])
        try:
            while self._next < len(self._order) and self.dead != mk.EMPTY:
                self.dead = self.store.call(mk.MODE_RESTRICT, self.fwd, self.dead, 0, arg=self._order[self._next])
                self._next += 1
                if end is not None and time.monotonic() >= end:
                    break  # the slice is over (a restriction at least is made in each)
            return self._next == len(self._order) or self.dead == mk.EMPTY
        except _OutOfTime:
            cancel = before[2]
            if end is None or (cancel is not None and cancel.is_set()) or (
                    before[0] is not None and time.monotonic() > before[0]):
                raise  # the watch before, not the slice's end
            return False
        except _OutOfMemory as exc:
            if seconds is None:
                raise
            self._failed = exc
            return False
        finally:
            mk.set_watch(*before)
            self.seconds += time.monotonic() - t0


def _dead_by_events(store: _Store, fwd: Events, single: Events, reach: int, counts: list[int]) -> int:
    """:func:`_dead` event by event alone, to the end (:class:`_ByEvents`)."""
    by_events = _ByEvents(store, fwd, single, reach)
    by_events.run(counts)
    return by_events.dead


#: candidate variable orders raced against each other, and the first time slice of each (seconds)
_CANDIDATES = 4
_FIRST_SLICE = 2.0
#: seeds of the order search tried for the candidates (a seed whose order is already a candidate's
#: is passed over; fewer candidates race when no other order is found)
_SEEDS = 5
#: the job of the candidate that is the first order reversed (:meth:`.mdd_order.Encoding.reversed`)
_REVERSE = -1
#: the job of the candidate ordered by the token flow from M0 (:func:`.mdd_order.encode` with ``flow``)
_FLOW = -2
#: the first candidate's turns are this many times longer than the others' when it shares a lane
#: with them (module docstring of _race)
_LEAD = 2.0
#: seconds from the start of the race before the first order's chaining starts in the second lane: a
#: net that both finish is most often saturated first, and the later phases' closures by saturation
#: mostly take less memory (Railroad-PT-005: inside 9 MiB, where those by chaining outgrow it)
_HEAD_START = 2.0
#: most seconds the first order's chaining runs before the second lane's other orders (:func:`_race`)
_CHAIN_SECONDS = 10.0
#: most passes of chained images the first order's chaining makes in the race: where it was the first
#: done, its fixed point came at the third pass (Dekker-PT-050 in 1.5 s, SharedMemory-PT-000050 in
#: 6.6 s, Philosophers-PT-000100 in 0.8 s), the fourth (Dekker-PT-100, 11.9 s) or the twelfth
#: (CANConstruction-PT-010, 5.8 s); where it was not, many cheap passes went on adding markings
#: (ERK-PT-001000: 79 passes in 10 s, DBSingleClientW-PT-d0m09 27, IOTPpurchase-PT-C12M10P15D17
#: 17, their twelfth within 0.4, 0.4 and 1.2 s), and the other orders waited for the 10 s
_CHAIN_PASSES = 12
#: while the explicit search runs beside the race (:class:`Rival`), a lane that saturates or chains
#: without turns stops this often to tell it how many markings it has shown reachable
#: (:meth:`_Race.bounded_below`), and resumes where it stopped
_TELL_SECONDS = 1.0
#: a lane stopped part-way yields to the search beside when its diagram holds fewer than this many
#: reachable markings a node (and fewer than the search has found: :meth:`Rival.shown`). Measured at
#: the first order's stops every second: NQueens-PT-10 (7,535,369 markings, the search answers) at
#: most 0.28 over its first 36 s, QuasiCertifProtocol-PT-06 (2,271,960, the search answers) at most
#: 0.09; SafeBus-PT-06 (6,816,756, the diagram answers) at least 0.98 in one run, 1.3 in another
#: (docs/BENCHMARKS.md)
_YIELD_RATIO = 0.5


def _same_order(a: Encoding, b: Encoding) -> bool:
    return len(a.levels) == len(b.levels) and all(np.array_equal(x, y) for x, y in zip(a.levels, b.levels))


_Won = tuple[Encoding, Events, _Store, int]


class _Candidate:
    """An order raced in a lane (:func:`_race`): its number in the race, encoding, events and store."""

    def __init__(self, name: int, enc: Encoding, fwd: Events, store: _Store) -> None:
        self.name, self.enc, self.fwd, self.store = name, enc, fwd, store
        self.spent = 0.0  # the seconds of its turns so far, s

    def outdone(self, others: list[_Candidate], spent: float) -> bool:
        """Whether one of ``others`` (the lane's candidates still in the race), not by chaining, has
        had at least ``spent`` seconds of turns (this one's, its current turn included) and holds
        fewer nodes. The test of a candidate that outgrew its part of a lane's memory
        (:meth:`_Lane._run`): if so it is dropped, not the others. RobotManipulation-PT-00050: the
        token flow's order outgrew its part at 2 million nodes, not done alone in 30 s; the first
        order reversed beside it held 950,000 and is done alone in 8.2 s. Where the order that
        outgrew its part is the faster (IOTPpurchase-PT-C12M10P15D17, DBSingleClientW-PT-d0m10), it
        outgrew it after more time than the others had had, or holding fewer nodes."""
        return any(not o.store.chain and o.spent >= spent and o.store.nodes < self.store.nodes for o in others)

    def drop(self) -> None:
        """Free the store (the candidate is out of the race)."""
        self.store = _Store(self.enc, 0)

    @property
    def dropped(self) -> bool:
        """Its store was freed (:meth:`drop`: the only store of no bytes)."""
        return self.store.max_bytes == 0


class _Cancel:
    """A lane's cancel flag: set by the race (:meth:`set`), or by whoever stops the whole engine
    (``outer``, another thread's event)."""

    def __init__(self, outer: mk.Flag | None) -> None:
        self.own = threading.Event()
        self.outer = outer

    def set(self) -> None:
        self.own.set()

    def is_set(self) -> bool:
        return self.own.is_set() or (self.outer is not None and self.outer.is_set())

    def wait(self, seconds: float) -> bool:
        """Wait until the race sets the flag, at most ``seconds``; whether it is set."""
        self.own.wait(max(0.0, seconds))
        return self.is_set()


class _Race:
    """What the lanes of one race share (:func:`_race`): the orders found so far, the seeds left,
    the winner, and which lane, if any, has outgrown its share of the memory and taken the whole."""

    def __init__(self, sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], max_bytes: int,
                 deadline: float, say: Callable[[str], None], stop: threading.Event | None = None,
                 borrow: Callable[[], int] | None = None) -> None:
        self.sn, self.bounds, self.flows = sn, bounds, flows
        self.stop, self.borrow = stop, borrow
        self.max_bytes, self.deadline, self.say = max_bytes, deadline, say
        self.lock = threading.Lock()
        self.orders: list[Encoding] = []  # every candidate's encoding, the first one's first
        self.groups = PlaceGroups()  # the groups of places, found by the first encoding for all
        self.first = threading.Event()  # the first candidate's encoding is known (or never will be)
        # its forward events, built once by its lane and read by the lane that chains the same order
        self.first_fwd: Events | None = None
        self.first_built = threading.Event()  # first_fwd is set, or never will be
        # order searches still to run for candidates after the first: (seed, sink); seed _REVERSE:
        # no search, the first order reversed; _FLOW: no search, the token flow's order
        self.jobs: list[tuple[int, bool]] = [(_REVERSE, False), (_FLOW, False)]
        self.next_seed = 1
        self.plain_first = False  # the first order without its shared levels sunk was queued
        self.reverse = 0  # the number of the candidate that is the first order reversed (0: none yet)
        self.flow = 0  # the number of the candidate ordered by the token flow (0: none yet)
        self.start = time.monotonic()
        self.winner: _Won | None = None
        self.error: BaseException | None = None
        self.lanes: list[_Lane] = []
        self.exclusive: _Lane | None = None
        self.candidates: list[_Candidate] = []  # every lane's, in the order they joined
        self.rival: Rival | None = None  # the search racing the engine, if any (:class:`Rival`)

    def bounded_below(self, lane: _Lane, store: _Store, whose: str) -> None:
        """Tell the rival search, if any, how many markings ``store`` (``lane``'s forward closure
        from M0 stopped part-way, ``whose``: at the end of a turn, dropped, or at a stop to tell
        while it has no turns) has shown reachable already (:meth:`Rival.shown`): past its limit
        the search stops, and with too few markings a node the lane yields to it."""
        if self.telling():
            assert self.rival is not None
            self.rival.shown(lane, store.fewest_reachable(), store.nodes, whose)

    def telling(self) -> bool:
        """A rival search is beside the race and still going: lanes without turns stop every
        :data:`_TELL_SECONDS` for :meth:`bounded_below`."""
        rival = self.rival
        return rival is not None and not rival.settled.is_set()

    def upside_down(self) -> _Candidate | None:
        """Once the race is decided, when the winner is the first order reversed: the first order's
        candidate, its store not dropped (its saturation stopped where the winner's end stopped it),
        if it is there; its bytes are taken from the winner's budget (:class:`_Upside` resumes it).
        Not the other way round: backward, the first order was the faster on five of the six nets
        where both directions were measured (MAPK-PT-00040: 0.02 s against 0.01 s; docs/BENCHMARKS.md,
        "The first order reversed, raced"), and a thread beside a backward closure the winner's
        order decides takes a CPU and memory bandwidth from it (SwimmingPool-PT-10, the first order
        winning: 37.7 s with the thread, 31.8 s without)."""
        if self.winner is None:
            return None
        enc, _, store, _ = self.winner
        rev = enc.reversed()
        for cand in self.candidates:
            if (cand.name == 1 and not cand.dropped and not cand.store.chain and cand.store is not store
                    and _same_order(cand.enc, rev)):
                store.max_bytes -= cand.store.held()
                return cand
        return None

    def encode(self, seed: int, sink: bool = False, stop: Callable[[], bool] | None = None) -> Encoding:
        """The encoding of order search ``seed`` (``sink``: shared levels at the bottom; seed
        :data:`_FLOW`: the token flow's order, no search), the search given up to 10 s, ended early
        when ``stop()`` says so (the race is decided)."""
        seconds = min(10.0, max(1.0, (self.deadline - time.monotonic()) / 20))
        # an encoding and its events may take a quarter of the budget (two lanes hold one each)
        enc = encode(self.sn, self.bounds, self.flows, seconds=seconds, seed=max(seed, 0), sink=sink,
                     flow=seed == _FLOW, stop=stop, max_bytes=self.max_bytes // 4, place_groups=self.groups)
        if sink and enc.sunk:
            with self.lock:
                if not self.plain_first:  # the same search with its shared levels left in place, next
                    self.plain_first = True
                    self.jobs.insert(0, (0, False))
        return enc

    def another_order(self, lane: _Lane) -> tuple[int, Encoding] | None:
        """A candidate order none of the others has, for ``lane``, with its number in the race
        (compared once the first candidate's is known); None when the seeds are used up, the
        deadline passed or the lane is cancelled."""
        while time.monotonic() < self.deadline and not lane.cancel.is_set():
            with self.lock:
                if self.jobs:
                    seed, sink = self.jobs.pop(0)
                elif self.next_seed < _SEEDS:
                    seed, sink = self.next_seed, False
                    self.next_seed += 1
                else:
                    return None
            # the searches run while the first order is still being found; its reverse waits for it
            enc = None if seed == _REVERSE else self.encode(seed, sink=sink, stop=lane.cancel.is_set)
            self.first.wait()
            with self.lock:
                if enc is None:
                    if not self.orders:
                        continue
                    enc = self.orders[0].reversed()
                if not any(_same_order(enc, o) for o in self.orders):
                    self.orders.append(enc)
                    if seed == _REVERSE:
                        self.reverse = len(self.orders)
                    elif seed == _FLOW:
                        self.flow = len(self.orders)
                    return len(self.orders), enc
        return None

    def name(self, number: int) -> str:
        """How the progress names candidate ``number``."""
        kind = {self.reverse: " (order 1 reversed)", self.flow: " (the token flow's order)"}
        return f"order {number}" + kind.get(number, "")

    def won(self, lane: _Lane, found: _Won) -> None:
        with self.lock:
            if self.winner is None and self.error is None:
                self.winner = found
        self.cancel_all(but=lane)

    def failed(self, exc: BaseException) -> None:
        with self.lock:
            if self.winner is None and self.error is None:
                self.error = exc
        self.cancel_all()

    def cancel_all(self, but: _Lane | None = None) -> None:
        self.first.set()  # nobody waits for an order that may never come
        self.first_built.set()
        for other in self.lanes:
            if other is not but:
                other.cancel.set()

    def take_borrow(self) -> Callable[[], int] | None:
        """``borrow``, for the first who asks (None after)."""
        with self.lock:
            borrow, self.borrow = self.borrow, None
        return borrow

    def widen(self) -> bool:
        """The whole budget is outgrown: add what ``borrow`` frees (asked once, by the first lane
        that outgrows the whole); False if nothing was freed."""
        borrow = self.take_borrow()
        extra = 0 if borrow is None else borrow()
        if extra <= 0:
            return False
        with self.lock:
            self.max_bytes += extra
        return True

    def widen_shares(self) -> bool:
        """A lane outgrew its share while the search beside has stopped (:attr:`Rival.settled`): what
        that search held goes to the lanes at once, split evenly (``borrow``, asked once), rather
        than only when one outgrows the whole, which first stops the other lanes. ERK-PT-001000:
        the first order outgrew its 1 GiB share, took the whole and stopped the second lane before
        its first candidate, the first order reversed, had its turn; it was not done in 70 s, where
        the reversed order is done in its first 2 s turn. False when there is one lane, the search
        is still going, or nothing was freed."""
        rival = self.rival
        if rival is None or not rival.settled.is_set() or len(self.lanes) < 2:
            return False
        before = self.max_bytes
        if not self.widen():
            return False
        for lane in self.lanes:
            lane.share += (self.max_bytes - before) // len(self.lanes)
        return True

    def smaller_beside(self, lane: _Lane, nodes: int) -> bool:
        """Another lane than ``lane`` is still working on a diagram of fewer than ``nodes`` nodes. When
        the diagram of a later candidate (the second lane's) outgrows its lane's share of the memory
        beside the first lane's smaller one, the first is the better bet: the later candidate is
        dropped rather than the first lane stopped (TwoPhaseLocking-PT-nC00500vN: the token flow's
        order, past a million nodes, took the whole budget and stopped the first order, 445,508 nodes
        when done; the set was not built in 80 s, and is now in 26–34 s). Not the other way round: the
        first lane's diagram, grown for as long as the race has run, is compared with a later one
        a turn or two old (Angiogenesis-PT-15: the first order, 1.4 million nodes at 24 s, would give
        way to the fourth, 250,429 nodes after its first 2 s turn; it takes the whole and is done at
        32 s, and the fourth was not done in 70 s)."""
        return any(other is not lane and not other.ended.is_set() and 0 < other.nodes_now() < nodes
                   for other in self.lanes)

    def take_whole(self, lane: _Lane) -> bool:
        """``lane``'s store outgrew its share: the other lanes are stopped (and waited for, so that
        their stores are gone) and it gets the whole budget; False if another lane took it first."""
        with self.lock:
            if self.exclusive is not None and self.exclusive is not lane:
                return False
            self.exclusive = lane
        self.cancel_all(but=lane)
        for other in self.lanes:
            if other is not lane:
                other.ended.wait()
        return True


class _Lane:
    """One CPU's share of a race: candidate orders taking turns of doubling time slices, each resuming
    where it stopped (its store, computed table included, kept between turns), until one is done.

    Args:
        race: the shared state.
        first: this lane holds the race's first candidate (seed 0, shared levels sunk).
        others: how many candidates besides the first it races (0: the first alone, to the deadline).
        share: the bytes of all this lane's stores; each store has an equal part of it.
    """

    def __init__(self, race: _Race, first: bool, others: int, share: int) -> None:
        self.race, self.has_first, self.others, self.share = race, first, others, share
        self.cancel = _Cancel(race.stop)
        self.ended = threading.Event()
        self.timed_out = False
        self.nodes = 0
        self.cands: list[_Candidate] = []  # its candidates, in the order they joined
        self.tid: int | None = None  # its thread's native id, once it runs
        self.working: _Store | None = None  # the store of the call it is in, if any
        self.yielded = False  # its thread's priority was lowered for a rival (:class:`Rival`)

    def nodes_now(self) -> int:
        """The nodes of the store this lane's call is working on now (0 between calls); read from
        another thread, the count may be a moment old."""
        store = self.working
        return 0 if store is None else store.nodes

    def run(self) -> None:
        race = self.race
        self.tid = threading.get_native_id()
        try:
            self._run()
        except BaseException as exc:  # Ctrl-C in the main thread, or a failure: the race ends
            race.failed(exc)
        finally:
            mk.set_watch(None, None)
            with race.lock:
                decided = race.winner is not None
            if not decided:  # stopped for a lane that took the whole, or failed: its stores are freed now
                for cand in self.cands:
                    cand.drop()
            if self.has_first:
                race.first.set()
                race.first_built.set()
            self.ended.set()

    def _chained(self, max_bytes: int, fwd: Events | None = None) -> tuple[bool, _Candidate | None, int]:
        """The first order by chaining (:meth:`_Store.closure`), once its saturation has run alone
        for :data:`_HEAD_START` seconds, within ``max_bytes``, for at most :data:`_CHAIN_SECONDS` and
        :data:`_CHAIN_PASSES` passes. The second lane's first work, or on one CPU the single lane's
        after the first candidate's first turn (``fwd``: its events, when this lane has them); not
        when the first order has shared levels sunk (the lane's first candidate is then that order
        with them in place, which chaining would delay: Referendum-PT-0050's answer in 3.2 s, 16.3 s
        with chaining first). Whether the race is decided (by it or another lane), and the chaining
        as a candidate that takes turns with the lane's other orders when its time ran out, with
        the bytes it holds (:meth:`_held`): its store is kept, and each turn resumes from its last
        pass. Where it found no fixed point in its passes, or outgrew the memory, its store is
        dropped."""
        race = self.race
        race.first.wait()
        with race.lock:
            enc = race.orders[0] if race.orders else None
        if enc is None or enc.sunk or self.cancel.is_set():  # sunk: the same order unsunk is raced instead
            return self.cancel.is_set(), None, 0
        if self.cancel.wait(race.start + _HEAD_START - time.monotonic()):
            return True, None, 0
        if fwd is None:  # the first lane builds the same events: 6 s on StigmergyElection-PT-09b's 41,210
            while not race.first_built.wait(0.05):  # transitions, done twice at once on two CPUs
                if self.cancel.is_set():
                    return True, None, 0
            fwd = race.first_fwd if race.orders and race.orders[0] is enc else None
        fwd = fwd if fwd is not None else events(race.sn, enc, merge=True)
        store = _Store(enc, max_bytes)
        store.chain = True
        end = min(race.deadline, time.monotonic() + _CHAIN_SECONDS)
        self.working = store
        try:
            while True:
                told = race.telling()
                mk.set_watch(min(end, time.monotonic() + _TELL_SECONDS) if told else end, None, self.cancel)
                try:
                    reach = store.closure(fwd, store.m0, check_overflow=True, passes=_CHAIN_PASSES)
                    break
                except _OutOfTime:
                    if not told or self.cancel.is_set() or time.monotonic() >= end:
                        raise
                    race.bounded_below(self, store, "order 1 by chaining")  # and on, from its last pass
        except (_OutOfTime, _NoFixedPoint, _OutOfMemory) as exc:
            if isinstance(exc, _OutOfTime) and self.cancel.is_set():  # cancelled: the race is decided
                return True, None, 0
            race.bounded_below(self, store, "order 1 by chaining")
            if isinstance(exc, _OutOfTime) and time.monotonic() < race.deadline:
                race.say(f"symbolic: order 1 by chaining not done within {_CHAIN_SECONDS:.0f} s ({store.nodes:,} "
                         "nodes), it takes turns with the other orders")
                chain = _Candidate(1, enc, fwd, store)
                held = self._held(chain)
                return False, chain if held else None, held
            why = ("not done by the deadline" if isinstance(exc, _OutOfTime)
                   else f"found no fixed point in {_CHAIN_PASSES} passes" if isinstance(exc, _NoFixedPoint)
                   else "outgrew this lane's share of the memory")
            race.say(f"symbolic: order 1 by chaining {why} ({store.nodes:,} nodes), dropped")
            return self.cancel.is_set(), None, 0
        finally:
            mk.set_watch(None, None)
            self.working = None
        store.max_bytes = race.max_bytes
        race.say("symbolic: order 1 by chaining was the first done")
        race.won(self, (enc, fwd, store, reach))
        return True, None, 0

    def _held(self, chain: _Candidate) -> int:
        """The bytes the first order by chaining (:meth:`_chained`) holds when its time ran out, to
        be kept for it out of the lane's share, once the search beside, if it has stopped, has
        handed its memory to the lanes (:meth:`_Race.widen_shares`). 0 when it holds more than half
        of the share: it is then dropped."""
        if not self.race.telling():
            self.race.widen_shares()
        held = chain.store.held()
        if 2 * held > self.share:
            self.race.say(f"symbolic: order 1 by chaining holds more than half of this lane's memory "
                          f"({chain.store.nodes:,} nodes), dropped")
            chain.drop()
            return 0
        return held

    def _join(self, chain: _Candidate, held: int, part: int) -> None:
        """The first order by chaining joins the lane's candidates (:meth:`_run`), with the bytes it
        holds and an equal part of the rest of the share, ``part``, as the others have: when it
        outgrows them it is dropped, the others going on."""
        chain.store.max_bytes = held + part
        self.cands.append(chain)
        with self.race.lock:
            self.race.candidates.append(chain)

    def _split(self, alive: list[bool], held: int) -> None:
        """Share the lane's memory among its candidates still in the race (``alive``, by their
        place in :attr:`cands`): an equal part each of what the first order by chaining does not
        hold, and that one its bytes besides (``held``, :meth:`_held`). No part is made smaller;
        a dropped candidate gets none."""
        left = [cand for cand, live in zip(self.cands, alive) if live]
        for cand in left:
            part = (self.share - held) // len(left) + (held if cand.store.chain else 0)
            cand.store.max_bytes = max(cand.store.max_bytes, part)

    def _run(self) -> None:
        race, say = self.race, self.race.say
        want = int(self.has_first) + self.others
        if want == 0:
            return
        cands = self.cands
        alive: list[bool] = []
        slice_s = _FIRST_SLICE
        turn = 0
        chain: _Candidate | None = None  # the first order by chaining, to take turns once the others joined
        held = 0  # the bytes it holds, kept for it out of the share
        if not self.has_first:
            decided, chain, held = self._chained(self.share)
            if decided:
                return
            want += chain is not None
        n_cands = want
        while not self.cancel.is_set():
            i = turn % n_cands
            turn += 1
            if i < len(alive) and not alive[i]:
                if not any(alive):
                    return
                if turn % n_cands == 0:
                    slice_s *= 2
                continue
            if i == len(cands) and chain is not None and i + 1 == want:  # the other orders are in
                self._join(chain, held, (self.share - held) // want)
                alive.append(True)
                chain = None
            elif i == len(cands):
                found: tuple[int, Encoding] | None = None
                if self.has_first and not cands:
                    enc0 = race.encode(0, sink=True)
                    with race.lock:
                        race.orders.insert(0, enc0)
                    race.first.set()
                    found = (1, enc0)
                else:
                    first = cands[0] if self.has_first and len(cands) == 1 else None
                    if first is not None:  # one CPU: the first order by chaining, beside its saturated part
                        decided, chain, held = self._chained(self.share - first.store.max_bytes, first.fwd)
                        if decided:
                            return
                        want += chain is not None
                        n_cands = want
                    found = race.another_order(self)
                if found is None or self.cancel.is_set():  # no other order: race those there are
                    if chain is not None:
                        self._join(chain, held, (self.share - held) // want)
                        alive.append(True)
                        chain = None
                    n_cands = len(cands)
                    if n_cands == 0:
                        return
                    turn = 0
                    self._split(alive, held)
                    if self.others:
                        plural = "s" if len(race.orders) > 1 else ""
                        say(f"symbolic: {len(race.orders)} distinct variable order{plural} found")
                    continue
                name, enc = found
                fwd = events(race.sn, enc, merge=True)
                if name == 1:
                    race.first_fwd = fwd
                    race.first_built.set()
                cands.append(_Candidate(name, enc, fwd, _Store(enc, (self.share - held) // want)))
                alive.append(True)
                with race.lock:
                    race.candidates.append(cands[-1])
                if name == 1:
                    say(f"symbolic: {enc.n_levels} levels ({enc.groups} groups of places"
                        + (f", {enc.sunk} shared levels at the bottom of the first order" if enc.sunk else "")
                        + f"), {fwd.n_events} events for {race.sn.n_transitions} transitions")
            cand = cands[i]
            store = cand.store
            label = race.name(cand.name) + (" by chaining" if store.chain else "")
            mine = slice_s * (_LEAD if cand.name == 1 else 1.0)
            # by turns; alone, no turns, but stops to tell the rival while it goes on
            pause = mine if n_cands > 1 else _TELL_SECONDS if race.telling() else inf
            mk.set_watch(min(race.deadline, time.monotonic() + pause), None, self.cancel)
            self.working = store
            began = time.monotonic()
            try:
                reach = store.closure(cand.fwd, store.m0, check_overflow=True, passes=_CHAIN_PASSES)
                store.max_bytes = race.max_bytes  # the others are dropped: the winner has the whole budget
                if cand.name != 1 or store.chain:
                    say(f"symbolic: {label} was the first done")
                race.won(self, (cand.enc, cand.fwd, store, reach))
                return
            except _NoFixedPoint:
                say(f"symbolic: {label} found no fixed point in {_CHAIN_PASSES} passes ({store.nodes:,} nodes), "
                    "dropped")
                alive[i] = False
                cand.drop()
            except _OutOfTime:
                self.nodes = store.nodes
                if self.cancel.is_set():
                    return
                if time.monotonic() >= race.deadline:
                    self.timed_out = True
                    return
                if n_cands > 1:
                    say(f"symbolic: {label} not done after its {mine:.0f} s turn ({store.nodes:,} "
                        "nodes)")
                race.bounded_below(self, store, label)
            except AnalysisError as exc:
                if "memory budget" not in str(exc):
                    raise
                if store.chain and sum(alive) > 1:  # what it held and its part: dropped, the others go on
                    say(f"symbolic: {label} outgrew its part of the memory ({store.nodes:,} nodes), dropped")
                    alive[i] = False
                    cand.drop()
                    continue
                # first this lane's share (the other lane goes on), then the whole (the others stopped)
                whole = store.max_bytes >= self.share
                if whole and race.widen_shares():  # the stopped search's memory: every lane's share grew
                    store.max_bytes = self.share  # the call resumes from its store
                    turn -= 1
                    continue
                # on the lane of the later candidates, not while the first lane's diagram is smaller:
                # this one is dropped instead
                if (whole and not self.has_first and store.max_bytes < race.max_bytes
                        and race.smaller_beside(self, store.nodes)):
                    say(f"symbolic: {label} outgrew this lane's share of the memory ({store.nodes:,} "
                        "nodes) beside a smaller diagram, dropped")
                    alive[i] = False
                    cand.drop()
                    continue
                if not whole and cand.outdone([c for j, c in enumerate(cands) if j != i and alive[j]],
                                              cand.spent + time.monotonic() - began):
                    say(f"symbolic: {label} outgrew its part of the memory ({store.nodes:,} nodes) beside a "
                        "smaller diagram that has had as long, dropped")
                    alive[i] = False
                    cand.drop()
                    self._split(alive, held)
                    continue
                if not whole or (store.max_bytes < race.max_bytes and race.take_whole(self)):
                    if not whole and sum(alive) > 1:
                        say(f"symbolic: {label} outgrew its part of the memory, the orders it took "
                            "turns with are dropped")
                    for j, other in enumerate(cands):
                        if j != i:  # no other is added after
                            alive[j] = False
                            other.drop()
                    if chain is not None:  # nor the chaining that was to join
                        chain.drop()
                        chain = None
                    n_cands, turn = len(cands), i
                    store.max_bytes = race.max_bytes if whole else self.share
                    continue
                if store.max_bytes >= race.max_bytes and race.widen():
                    store.max_bytes = race.max_bytes  # the call resumes from its store
                    turn -= 1
                    continue
                alive[i] = False
                cand.drop()
            finally:
                mk.set_watch(None, None)
                self.working = None
                cand.spent += time.monotonic() - began
            if turn % n_cands == 0:
                slice_s *= 2


class Rival:
    """Another search racing the symbolic engine for the same answer: the automatic engine's
    explicit search beside it (:mod:`.structure`). The search reports how many markings it has
    found (:meth:`found`, from its own thread, every few ten thousand); a lane of the engine's
    race for the reachable set (:func:`_race`) whose decision diagram has more nodes than that
    yields the CPUs to the search: its thread's scheduling priority is lowered by ``nice`` steps
    (:func:`.budget.lower_priority`), the same as the search's own, so the two share what the
    other lane leaves. A diagram larger than the explicit graph found so far is not compressing
    the set, and the search is then the better bet: on NQueens-PT-10 the first order by chaining
    held 4.2 million nodes when the search had 2.5 million of its 7,535,369 markings, and the race
    was undecided after 110 s, where the search alone completes in 23 s. Where the decision
    diagrams win, their nodes seldom pass the markings found, and then by little (over eight
    contest models they won, at most 1.29 times, on Railroad-PT-020's second lane, which then
    yields; the answer still comes in about 40 s; docs/BENCHMARKS.md). A lane also yields when,
    stopped part-way (at the end of a turn, or at a stop to tell while it has no turns), its
    diagram holds fewer than :data:`_YIELD_RATIO` markings a node and fewer than the search has
    found (:meth:`shown`). A lane that yielded stays so until the race ends (an unprivileged
    process may not raise a priority again); with the search over, nothing competes with it.

    :attr:`settled` is set when the engine has the reachable set: the search stops then (its
    answer would come after this one's), and the phases that follow have the CPUs. SafeBus-PT-06:
    the set at 51 s, its liveness and reversibility in 2 s more; the search, left going, completed
    its 6,816,756 markings during them, stopped them, and its graph's passes gave the answer at
    75 s. It is set as well when a lane shows more markings reachable than the search's ``limit``
    (:meth:`beyond`): the search cannot complete, and the CPU and memory it takes are the engine's.

    Args:
        nice: how many steps lower a lane that yields runs.
        say: where its notices go (a line each).
        limit: the markings at which the search stops, incomplete (None: no limit).
    """

    def __init__(self, nice: int, say: Callable[[str], None] | None = None, limit: int | None = None) -> None:
        self.nice = nice
        self.say = say or (lambda _text: None)
        self.limit = limit
        self._found = 0  # the markings the search has found, at its last report
        self.settled = threading.Event()
        self._lock = threading.Lock()
        self._race: _Race | None = None

    def _enter(self, race: _Race) -> None:
        with self._lock:
            self._race = race

    def _leave(self) -> None:
        with self._lock:
            self._race = None

    def found(self, markings: int) -> None:
        """The search has found ``markings`` markings: the lanes whose diagrams have more nodes
        yield to it (each once)."""
        with self._lock:
            race = self._race
            self._found = markings
        if race is None:
            return
        for i, lane in enumerate(race.lanes):
            nodes = lane.nodes_now()
            if lane.tid is None or lane.yielded or nodes <= markings:
                continue
            self._yield(lane, f"symbolic: lane {i + 1} of the race yields to the explicit search: its decision "
                              f"diagram has {nodes:,} nodes, the search {markings:,} markings")

    def _yield(self, lane: _Lane, why: str) -> None:
        """Lower ``lane``'s thread priority, once (the search's thread and the lane's may both ask)."""
        with self._lock:
            if lane.yielded:
                return
            lane.yielded = True
        if lane.tid is not None:
            lower_priority(lane.tid, self.nice)
        self.say(why)

    def shown(self, lane: _Lane, markings: float, nodes: int, whose: str) -> None:
        """``lane``'s diagram (``whose``, stopped part-way: at the end of a turn, dropped, or at a
        stop to tell while it has no turns) holds ``markings`` reachable markings
        (:meth:`_Store.fewest_reachable`) in ``nodes`` nodes. Past :attr:`limit`, the search is
        stopped (:meth:`beyond`). Fewer than :data:`_YIELD_RATIO` a node and fewer than the search
        has found, the diagram is neither compressing the set nor ahead of the search, and the lane
        yields to it (once): on NQueens-PT-10 every order held 0.03 to 0.2 markings a node at the
        end of its turns, the first order at most 0.28 at its stops to tell, and chaining 0.23 three
        seconds in, 0.95 when dropped; whether chaining's nodes passed the markings the search had
        found while it ran, the one other reason to yield, was a matter of a few thousand either way
        (docs/BENCHMARKS.md)."""
        self.beyond(markings, whose)
        with self._lock:
            found = self._found
            lanes = [] if self._race is None else self._race.lanes
        if self.settled.is_set() or lane.yielded or markings >= _YIELD_RATIO * nodes or markings >= found:
            return
        i = next((k for k, other in enumerate(lanes) if other is lane), 0)
        self._yield(lane, f"symbolic: lane {i + 1} of the race yields to the explicit search: {whose} holds "
                          f"{markings:,.0f} reachable markings in {nodes:,} nodes, the search has found {found:,}")

    def beyond(self, markings: float, whose: str) -> None:
        """A lane's diagram (``whose``, part-way) holds ``markings`` reachable markings
        (:meth:`_Store.fewest_reachable`): past :attr:`limit`, the search is stopped
        (:attr:`settled`), once."""
        with self._lock:
            if self.limit is None or markings <= self.limit or self.settled.is_set():
                return
            self.settled.set()
        shown = f"{markings:,.0f}" if markings < 1e15 else f"{markings:.3g}"
        self.say(f"symbolic: {whose} holds {shown} reachable markings already, more than the explicit "
                 f"search's limit of {self.limit:,}: the search beside is stopped")


def _race(sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], max_bytes: int, deadline: float,
          say: Callable[[str], None], stop: threading.Event | None = None,
          borrow: Callable[[], int] | None = None, rival: Rival | None = None) -> tuple[_Won, _Candidate | None]:
    """The reachable set, by saturation on candidate variable orders raced against each other, until
    one finishes. How long saturation takes on an order is hard to predict from the order (on
    Railroad-PT-010, orders whose scores differ by 2 % take 0.15 to 13 s), so a few candidates are
    raced. Candidates are distinct orders: the order search from another seed often ends in the same
    order, which would only race itself (on LamportFastMutEx-PT-5 all three seeds give one order);
    up to :data:`_SEEDS` seeds are tried. When the net is components that meet only through shared
    levels (:func:`.mdd_order.shared_levels`: resources that every component takes and gives back),
    the first candidate is the order with those levels at the bottom (seed 0, whose starts include
    the net's own place order and its reverse), and the seeds' orders follow.

    The next candidate is the first order upside down (:meth:`.mdd_order.Encoding.reversed`, no
    search): an order scores the same from either end, but saturation fires an event at its top
    level, and on Kanban-PT-00100 the order found takes 1.9 s and 113,617 nodes where its reverse
    takes 0.01 s and 1,924 (GPPP-PT-C0100N0000000100: not done in 25 s, 3.7 s; MAPK-PT-00040 the
    other way, 0.04 s and 0.18 s). When the first order has shared levels sunk, that order with
    them in place comes before it. Then comes the order in which tokens flow from M0 (``flow`` of
    :func:`.mdd_order.encode`, no search either), which a low score can miss: on the business process
    IBMB2S565S3960-PT-none it saturates in 4.2 s, where the first order and its reverse are not done
    in 20 s; then seed 1's.

    The first order is raced a second time, by **chaining** (:meth:`_Store.closure`): saturation
    fires an event on the nodes of its top level, and when many events read levels far below their
    top, the sets it builds on the way can be exponentially larger than the reachable set. Dekker's
    'enter' transitions read every other process's flag: saturation builds the partial unions of
    which processes may be in their critical sections (66,827 nodes at 20 processes, 745 at 10)
    where the reachable set has 115, and chained images reach Dekker-PT-050's 2.9·10^16 markings in
    0.6 s, three passes, 320,725 nodes. Chaining is no better in general (Railroad-PT-020: not done
    in 80 s, saturation 14 s), hence the race: on two CPUs or more the second lane starts with it
    (:meth:`_Lane._chained`; not when the first order has shared levels sunk), with its whole share
    of the memory, for at most :data:`_CHAIN_SECONDS` (it mostly grows fast where it does not win:
    Referendum-PT-0050 took 5 million nodes in 5 s, where its reachable set has 396), after the
    first lane has saturated alone for :data:`_HEAD_START` seconds; then the lane goes on with the
    other orders. Where only its time ran out (not its passes, nor the memory), the chaining is not
    dropped: it joins the lane's turns after the other orders' first turns, as the first order with
    its turns :data:`_LEAD` times as long, its store kept, each turn resuming from its last pass
    (:meth:`_Store.closure`). It keeps the bytes it holds, and has an equal part of the rest of the
    share, as the others do; when it outgrows that it is dropped and the others go on (where it
    holds more than half of the share, it is dropped at once). CloudDeployment-PT-6a's chained
    images reach the fixed point in 8 passes, 19 s alone, where no order's saturation is done in
    60 s. The winner's way also builds the later phases' closures (liveness, reversibility, the
    witness). On one CPU the single lane tries it after the first candidate's first turn, with
    the memory the others would have had.

    On two CPUs or more the race has two lanes, threads that run at once (the kernel releases the
    GIL): one saturates the first candidate without a pause, the other searches the other orders
    while the first saturates and races them by turns. When the first order is the fastest, the
    race costs it nothing. On one CPU a single lane runs them all by turns of doubling time slices, each
    resuming where it stopped (its store, computed table included, is kept between turns), the first
    candidate's turns :data:`_LEAD` times as long as the others' (when it is the fastest the others
    cost about half its time; Railroad-PT-020: 39 s of CPU for the race instead of 55 s). Each lane
    has an equal share of the memory budget, and each of its stores an equal part of the lane's.
    When a store outgrows its part, its lane's other candidates are dropped and it gets the lane's
    share, the other lane going on (a candidate that grows fast is seldom the fastest: on
    Railroad-PT-020 beside the explicit search, with 2 GiB, the second order took the whole at 6 s
    and finished at 38 s, where the first finishes alone in 14 s); when it outgrows that, the
    other lanes are stopped and dropped and it gets the whole; when it outgrows the whole,
    ``borrow`` may add to it once (:meth:`_Race.widen`). ``stop`` set (by another thread) ends
    every lane. A lane whose decision diagram has more nodes than ``rival``'s search has markings
    yields the CPUs to it (:class:`Rival`), as does one whose diagram holds fewer than
    :data:`_YIELD_RATIO` markings a node and fewer than the search has found, at the end of a turn;
    one whose diagram holds more than the search's limit stops the search (:meth:`Rival.shown`). A
    lane without turns (the first on two CPUs, and chaining) stops every :data:`_TELL_SECONDS` while
    the search goes on, to tell it so (:meth:`_Race.bounded_below`), and resumes: the search, which
    cannot complete, then stops seconds earlier than at the lane's end, and its CPU is the race's
    (SwimmingPool-PT-10: at 4.3 s instead of 16.2 s); where the search can complete, the lane whose
    diagram does not compress the set yields to it seconds after the start (NQueens-PT-10: answered
    in 45 to 50 s instead of 70 to 74 s; docs/BENCHMARKS.md).

    Returns:
        The winner, and the candidate whose order is the winner's upside down if the race kept its
        store (:meth:`_Race.upside_down`, for :class:`_Upside`).

    Raises:
        AnalysisError: every candidate outgrew the memory budget, none was done by the deadline, or
            ``stop`` was set first.
    """
    race = _Race(sn, bounds, flows, max_bytes, deadline, say, stop, borrow)
    race.rival = rival
    if cpus() >= 2:
        race.lanes = [_Lane(race, True, 0, max_bytes // 2), _Lane(race, False, _CANDIDATES - 1, max_bytes // 2)]
    else:
        race.lanes = [_Lane(race, True, _CANDIDATES - 1, max_bytes)]
    # with a rival every lane has a thread of its own, whose priority may be lowered (the caller's stays
    # its own); without, the last lane runs in the caller's thread
    own = race.lanes if rival is not None else race.lanes[:-1]
    helpers = [threading.Thread(target=lane.run, name="petrobot-saturation", daemon=True) for lane in own]
    try:
        for thread in helpers:
            thread.start()
        if rival is not None:
            rival._enter(race)
        else:
            race.lanes[-1].run()  # the caller's lane: Ctrl-C reaches it
        for thread in helpers:
            while thread.is_alive():
                thread.join(0.2)  # Ctrl-C reaches the caller here: the race is cancelled below
    finally:
        if rival is not None:
            rival._leave()
        race.cancel_all()
        for thread in helpers:
            thread.join()
    if race.winner is not None:
        race.winner[2].borrow = race.take_borrow()  # the later phases may outgrow the budget too
        kept = race.upside_down()
        for cand in race.candidates:  # the others' stores are freed now (lanes and race refer to each other)
            if cand is not kept and cand.store is not race.winner[2]:
                cand.drop()
        return race.winner, kept
    if race.error is not None:
        raise race.error
    if stop is not None and stop.is_set():
        raise AnalysisError("the symbolic engine was stopped before its reachable set was complete")
    if any(lane.timed_out for lane in race.lanes):
        nodes = max(lane.nodes for lane in race.lanes)
        raise AnalysisError(f"the symbolic reachable set was not complete within the time budget "
                            f"({nodes:,} nodes on the largest variable order tried)")
    raise AnalysisError("the decision diagram outgrew the memory budget on every candidate variable order")


#: the share of the time left to the liveness phase that the forward probe (:func:`_probe`) may take
_PROBE_SHARE = 0.4


#: a marking drawn by :func:`_probe` (its value per level and its node) and the node of what it reaches
_Drawn = tuple[np.ndarray, int, int]


def _probe(store: _Store, fwd: Events, single: Events, reach: int, result: SymbolicResult, until: float,
           probes: int, stop: mk.Flag | None = None, drawn: list[_Drawn] | None = None) -> None:
    """Decide what a few markings drawn from the reachable set tell, forward: from a marking m, the
    set R(m) of the markings it reaches is saturated (the reachable set's own events, its computed
    table kept); a transition enabled in no marking of R(m) can never fire again after m, so it is
    not live (L4), and M0 outside R(m) makes the net not reversible. Nets with a one-shot start
    (an initialisation the net never returns to) are decided so in a forward saturation or two,
    where the backward saturations below may not finish (UtahNoC-PT-none: 2 s against undecided
    after 40 s). At most ``probes`` markings; stops at ``until`` (or ``stop``) or when both are decided,
    or after a marking that reaches the whole reachable set (R(m) = R(M0)) and decided nothing: the
    net then looks strongly connected, where more markings drawn tell no more and the backward
    saturation decides (SmallOperatingSystem-PT-MT0512DC0128, live and reversible: each R(m) took
    about 5 s, which the backward saturation needed). Each marking whose R(m) is done is added to
    ``drawn``, for :func:`_terminal`."""
    rng = np.random.default_rng(0x11FE)
    live_t = result.live_transitions
    mk.set_watch(until, None, stop)
    for _ in range(probes):
        if result.reversible is not None and result.live is not None:
            return
        values = store.sample(reach, rng)
        m = store.path(values)
        r = store.closure(fwd, m)
        if drawn is not None:
            drawn.append((values, m, r))
        if not store.contains(r, store.enc.m0):
            result.reversible = False
        store.count(r, at_most=_as_float(result.states) * max(1, single.n_events))
        for e, n in enumerate(store.enabled_counts(r, single)):
            if n == 0:
                live_t[list(single.members[e])] = False
                result.live = False
        if r == reach and result.live is None and result.reversible is None:
            return


class _Beside:
    """A thread that decides reversibility beside the main thread's closure (:class:`_Upside`,
    :class:`_Home`): :attr:`reversible` once :attr:`decided` is set (which stops the main thread's
    closure: it watches that flag, which ``stop`` sets too), :attr:`lent` the bytes it took from
    the main store's budget while it runs (:func:`_take_back`), :meth:`end` stops it. The thread,
    ``name``, runs ``run(*args)`` and starts here, last."""

    def __init__(self, how: str, max_bytes: int, stop: threading.Event | None, name: str, run: Callable[..., None],
                 *args: Any) -> None:
        #: where the thread decides, for the progress lines
        self.how = how
        #: the bytes it took from the main store's budget (:func:`_take_back`)
        self.lent = max_bytes
        self.reversible: bool | None = None
        self.decided = _Cancel(stop)
        self.cancel = _Cancel(stop)
        self.thread = threading.Thread(target=run, args=args, name=name, daemon=True)
        self.thread.start()

    def end(self) -> None:
        """Stop the thread and wait for it (its store is freed with it)."""
        self.cancel.set()
        self.thread.join()


class _Upside(_Beside):
    """Reversibility on the reachable set's order upside down (:meth:`.mdd_order.Encoding.reversed`),
    in a thread beside the later phases (two CPUs or more, :func:`analyse_symbolic`), when the race
    left that order's candidate with its store (``kept``, :meth:`_Race.upside_down`): first, for
    at most :data:`_CLOSED_SECONDS`, whether the markings that reach M0 are closed under firing
    (:func:`_closed_home`, on a store of its own: the net is reversible if they are); then its
    saturation forward resumes where the race stopped it, and the markings that reach M0 by
    saturation backward inside its reachable set decide. Saturation fires an event at its top level, so an
    order that is fast one way is often slow the other: the race's winner on Kanban-PT-00200 is the
    first order reversed (0.32 s forward), whose backward saturation is not done in 40 s, where the
    first order takes 20.9 s forward and 0.05 s backward (docs/BENCHMARKS.md). Whichever thread
    decides first answers: :attr:`decided` is set when this one has, which stops the main thread's
    closure (it watches that flag, which ``stop`` sets too); :meth:`end` stops this one. Its store
    has ``max_bytes``, which the caller takes from the main store's budget while it runs. Not
    started from M0 on an order the race did not keep: it would take a CPU and memory bandwidth
    from the main thread's closures for a whole saturation forward first (where the race kept
    none, :class:`_Home` works on the winner's order instead)."""

    def __init__(self, sn: SparseNet, kept: _Candidate, max_bytes: int, until: float, stop: threading.Event | None,
                 say: Callable[[str], None]) -> None:
        self.say, self.kept = say, kept
        super().__init__("on the order upside down", max_bytes, stop, "petrobot-upside-down", self._run, sn, kept,
                         max_bytes, until)

    def _run(self, sn: SparseNet, kept: _Candidate, max_bytes: int, until: float) -> None:
        mk.set_watch(until, None, self.cancel)
        try:
            # its time, its memory or a stop ends it undecided: the main thread's answer stands
            with contextlib.suppress(_OutOfTime, AnalysisError):
                back = events(sn, kept.enc, inverse=True, merge=True, like=kept.fwd)
                t0 = time.monotonic()
                mk.set_watch(min(until, t0 + _CLOSED_SECONDS), None, self.cancel)
                with contextlib.suppress(_OutOfTime):  # its slice: the way below goes on
                    if _closed_home(kept.enc, kept.fwd, back, max(0, max_bytes - kept.store.held())):
                        self.say(f"symbolic: order {kept.name}, the winner's upside down: the markings that reach M0 "
                                 f"are closed under firing, in {time.monotonic() - t0:.1f} s")
                        self.reversible = True
                        self.decided.set()
                        return
                mk.set_watch(until, None, self.cancel)
                store = kept.store
                store.max_bytes = max_bytes
                t0 = time.monotonic()
                reach = store.call(mk.MODE_SATURATE, kept.fwd, store.m0, check_overflow=True)
                self.say(f"symbolic: order {kept.name}, the winner's upside down: its reachable set resumed from the "
                         f"race in {time.monotonic() - t0:.1f} s ({store.nodes:,} nodes), backward from M0 next")
                self.reversible = store.call(mk.MODE_SATURATE, back, store.m0, c=reach) == reach
                self.decided.set()
        finally:
            mk.set_watch(None, None)

    def end(self) -> None:
        """Stop the thread, wait for it and free the kept candidate's store."""
        super().end()
        self.kept.drop()


#: seconds :class:`_Upside` gives :func:`_closed_home` before it resumes its saturation forward, and
#: :class:`_Home` on the order upside down before its own saturation (2 s was too short for
#: RobotManipulation-PT-00050's 1.4 to 2.3 s while the main thread's closure runs beside)
_CLOSED_SECONDS = 5.0


def _closed_home(enc: Encoding, fwd: Events, back: Events, max_bytes: int) -> bool:
    """Whether the markings that reach M0, by saturation backward from M0 on a store of their own
    (``max_bytes``; not kept inside the reachable set, which is not built on this order), are closed
    under firing forward (one image of each event, ``fwd``). If they are, they hold every reachable
    marking (M0 is in them), so the net is reversible; if not, nothing is known (a marking that is not
    reachable may reach M0 and leave it by a firing). A firing from a reachable marking never leaves
    the levels' local markings (the reachable set was built checking it, on the same levels in
    another order), so the image misses none of those. SmallOperatingSystem-PT-MT0512DC0128, on the
    order upside down from the race's winner: 1.2 s backward and 0.3 s for the image, where
    resuming its saturation forward takes tens of seconds. False also when the budget is too small;
    raises _OutOfTime as :meth:`_Store.call`."""
    store = _Store(enc, max_bytes)
    try:
        home = store.call(mk.MODE_SATURATE, back, store.m0)
        ahead = store.call(mk.MODE_IMAGE, fwd, home, arg=mk.IMAGE_EACH)
        return store.call(mk.MODE_APPLY, fwd, ahead, home, arg=mk.APPLY_DIFF) == mk.EMPTY
    except _OutOfMemory:
        return False


class _Home(_Beside):
    """Reversibility beside the main thread where the race kept no order upside down (two CPUs or
    more, :func:`analyse_symbolic`): first, for at most :data:`_CLOSED_SECONDS`, whether the
    markings that reach M0 on the reachable set's order upside down are closed under firing
    (:func:`_closed_home`: the net is reversible if they are; RobotManipulation-PT-00050, 1.4 s,
    where backward saturation on the race's winning order takes 12 to 14 s; TCPcondis-PT-15,
    where it takes 5.2 s and the way below decides, pays those 5 s); then, on a store of its own,
    on the reachable set's encoding, the
    markings that reach M0 by saturation backward from M0, not kept inside the reachable set (that
    set is in the main store), then whether the reachable set is inside them
    (:func:`.mdd_kernel.subset`, which reads the main store's nodes of that set: a store never
    changes a node, :meth:`_Store.counting`). The net is reversible iff it is, since a path from a
    reachable marking to M0 stays in the reachable set. Without the constraint the backward
    saturation may take markings that are not reachable, but those keep every P-semiflow's
    weighted sum and the levels' local markings, and on the nets measured they were few:
    TCPcondis-PT-15, one beside its 5,397,066,447,019 reachable markings, in 7.6 s from scratch,
    where the main thread's probe took 5 s and its saturation inside the reachable set 7 to 12 s
    more; SmallOperatingSystem-PT-MT0512DC0128 on its first order, none, in 0.8 s. Where they are
    many, the thread's time or its memory (``max_bytes``, taken from the main store's budget while
    it runs) ends it undecided, and the main thread's answer stands. The interface of
    :class:`_Beside`."""

    def __init__(self, sn: SparseNet, store: _Store, back: Events, reach: int, max_bytes: int, until: float,
                 stop: threading.Event | None, say: Callable[[str], None]) -> None:
        self.say = say
        _meta, _level, offset, size, kids = store.arrays[:5]
        super().__init__("beside, on a store of its own", max_bytes, stop, "petrobot-home", self._run, sn, store.enc,
                         back, (reach, offset, size, kids), max_bytes, until)

    def _run(self, sn: SparseNet, enc: Encoding, back: Events, reach: tuple[int, np.ndarray, np.ndarray, np.ndarray],
             max_bytes: int, until: float) -> None:
        try:
            # its time, its memory or a stop ends it undecided: the main thread's answer stands
            with contextlib.suppress(_OutOfTime, AnalysisError):
                t0 = time.monotonic()
                mk.set_watch(min(until, t0 + _CLOSED_SECONDS), None, self.cancel)
                with contextlib.suppress(_OutOfTime):  # its slice: the way below goes on
                    upside = enc.reversed()
                    ahead = events(sn, upside, merge=True)
                    if _closed_home(upside, ahead, events(sn, upside, inverse=True, merge=True, like=ahead),
                                    max_bytes):
                        self.say(f"symbolic: on the reachable set's order upside down, the markings that reach M0 "
                                 f"are closed under firing, in {time.monotonic() - t0:.1f} s")
                        self.reversible = True
                        self.decided.set()
                        return
                if self.cancel.is_set():
                    return
                mk.set_watch(until, None, self.cancel)
                t0 = time.monotonic()
                store = _Store(enc, max_bytes)
                home = store.call(mk.MODE_SATURATE, back, store.m0)
                self.reversible = bool(mk.subset(*reach, home, *store.arrays[2:5]))
                self.say(f"symbolic: the markings that reach M0, {self.how}: {store.nodes:,} nodes, "
                         f"{time.monotonic() - t0:.1f} s")
                self.decided.set()
        finally:
            mk.set_watch(None, None)


def _take_back(store: _Store, beside: _Beside) -> None:
    """End the thread ``beside`` (it is waited for) and give ``store`` back the bytes it lent it;
    once (again: nothing more)."""
    beside.end()
    store.max_bytes += beside.lent
    beside.lent = 0


#: most terminal components :func:`_terminal` looks for, and most steps it takes towards one, before the
#: backward saturation per transition decides what is left
_TERMINALS = 8
_TERMINAL_STEPS = 16


def _terminal(store: _Store, fwd: Events, back: Events, single: Events, reach: int, result: SymbolicResult,
              say: Callable[[str], None], first_suffices: bool, drawn: list[_Drawn]) -> bool:
    """Liveness (L4) from the terminal strongly connected components of the reachability graph (its
    bottom components: no edge leaves them). In a finite graph every marking reaches a terminal
    component, and in one every marking reaches every other, so a transition is live iff some
    marking of every terminal component enables it (the liveness levels of Murata 1989, section
    IV-C, as :mod:`.structure` reads them off the explicit graph; the components found symbolically
    as in Xie and Beerel, implicit enumeration of strongly connected components, 1999). A component
    is found from a marking m: F = R(m) by saturation forward, B = the markings of F that reach m,
    by saturation backward inside F (a path from F stays in F); F is terminal iff B = F, else m
    moves to a marking of F \\ B, whose R is inside F without m, so F shrinks. The markings that
    reach a component found (backward inside the reachable set) are set aside, and the next
    component is looked for from one that is left; when none is left, every terminal component is
    known. The markings m are first those :func:`_probe` drew (``drawn``), whose R(m) is built
    already, then markings drawn about uniformly among those left: such a marking is most often
    in a terminal component already. A net that is not reversible and has one terminal component
    then takes about two saturations, where the backward saturation per transition takes one for
    each: Anderson-PT-06 (600 transitions, live) is decided in 1.1 s, where those saturations had
    not decided it in 46 s.

    Sets ``result.live`` and ``result.live_transitions`` and returns True when it decides them;
    ``first_suffices``: a transition missing from one component answers the net (not live), the
    others stay undecided. Returns False after :data:`_TERMINALS` components or
    :data:`_TERMINAL_STEPS` steps towards one, with the transitions missing from a component found
    set not live. Raises _OutOfTime, _OutOfMemory as :meth:`_Store.call`."""
    say("symbolic: liveness, from the terminal components of the reachability graph")
    live_t = result.live_transitions
    n_t = live_t.shape[0]
    missing = np.zeros(n_t, dtype=bool)
    rng = np.random.default_rng(0x7E2)
    starts = list(drawn)
    left, found = reach, 0
    while left != mk.EMPTY and found < _TERMINALS:
        start = next((x for x in starts if store.contains(left, x[0])), None)
        ahead: int | None = None
        if start is not None:
            starts.remove(start)
            _values, m, ahead = start
        else:
            m = store.path(store.sample(left, rng))
        for _ in range(_TERMINAL_STEPS):
            if ahead is None:
                ahead = store.closure(fwd, m)
            back_in = store.closure(back, m, c=ahead)
            if back_in == ahead:
                break
            m = store.path(store.sample(store.call(mk.MODE_APPLY, back, ahead, back_in, arg=mk.APPLY_DIFF), rng))
            ahead = None
        else:
            break
        assert ahead is not None
        found += 1
        store.count(ahead, at_most=_as_float(result.states) * max(1, single.n_events))
        for e, n in enumerate(store.enabled_counts(ahead, single)):
            if n == 0:
                missing[list(single.members[e])] = True
        if missing.any():
            live_t[missing] = False
            result.live = False
            if first_suffices:
                return True
        reaching = store.closure(back, ahead, c=reach)
        left = store.call(mk.MODE_APPLY, back, left, reaching, arg=mk.APPLY_DIFF)
    live_t[missing] = False
    if left != mk.EMPTY:
        return False
    say(f"symbolic: {found} terminal component{'s' if found > 1 else ''}")
    live_t[[t for t in range(n_t) if live_t[t] is None]] = True
    result.live = not missing.any() and bool(result.fireable.all())
    return True


def _has_way_back(store: _Store, back: Events, reach: int) -> bool:
    """Whether a reachable marking other than M0 enables a transition whose firing gives M0: one
    image of the inverse events ``back`` from M0, inside the reachable set ``reach``. Without one
    the net is not reversible (a path back to M0 ends with such a firing) when the reachable set
    holds more than M0. Raises as :meth:`_Store.call`."""
    before = store.call(mk.MODE_IMAGE, back, store.m0, c=reach, arg=mk.IMAGE_EACH)
    return store.call(mk.MODE_APPLY, back, before, store.m0, arg=mk.APPLY_DIFF) != mk.EMPTY


def _liveness(store: _Store, fwd: Events, single: Events, back: Events | None, reach: int, counts: list[int],
              result: SymbolicResult, say: Callable[[str], None], until: float, probes: int,
              stop: threading.Event | None = None, upside: _Beside | None = None) -> None:
    """Reversibility and liveness (module docstring), until ``until`` (``time.monotonic()``
    seconds): first whether a reachable marking fires into M0 (:func:`_has_way_back`: without one,
    the net is not reversible); if one does, backward saturation from M0 (reversibility; a
    reversible quasi-live net is live); else, or when the net is not reversible, what the drawn
    markings tell forward (:func:`_probe`, within a share of the time), then the terminal
    components (:func:`_terminal`, from the drawn markings whose R(m) the probe built). If there
    are more than it looks for, or the probe built no R(m) within its share, each transition not
    yet decided gets a backward saturation from the markings that enable it, the transitions
    enabled in the fewest reachable markings (``counts``, per event of ``single``) first: they are
    the likeliest not to be live.
    ``upside``: reversibility decided beside (:class:`_Upside`, on the order upside down, or
    :class:`_Home`, on a store of its own); whichever is done first answers, before the probe."""
    t0 = time.monotonic()
    n_t = result.fireable.shape[0]
    quasi = bool(result.fireable.all())
    live_t = result.live_transitions
    live_t[~result.fireable] = False
    if result.states == 1:
        result.reversible = True
    elif result.deadlock:
        result.reversible = False  # a dead marking other than the only one cannot go back to M0
    if result.deadlock or not quasi:
        result.live = False
    if back is None:
        if result.reversible is None or result.live is None:
            result.notes.append("liveness and reversibility: backward reachability is not available with "
                                "reset arcs; left undecided")
        result.seconds["liveness"] = time.monotonic() - t0
        return
    drawn: list[_Drawn] = []
    try:
        if result.reversible is None and not _has_way_back(store, back, reach):
            result.reversible = False
            say("symbolic: no reachable marking other than M0 fires into M0: the net is not reversible")
        if upside is not None and result.reversible is not None:
            upside.cancel.set()  # decided: the thread's work is not needed
        if result.reversible is None and upside is not None:
            say(f"symbolic: reversibility (backward from M0, and {upside.how})")
            mk.set_watch(until, None, upside.decided)
            try:
                home = store.closure(back, store.m0, c=reach)
                result.reversible = home == reach
                upside.cancel.set()
            except _OutOfTime:  # its answer, the deadline or a stop
                while upside.thread.is_alive():  # it ends by the same deadline and stop
                    upside.thread.join(0.2)
                if upside.reversible is None:
                    raise
                result.reversible = upside.reversible
                say(f"symbolic: reversibility decided {upside.how}")
            except _OutOfMemory:  # this store's budget, the thread's part lent: it stops, and gives it back
                _take_back(store, upside)
                if upside.reversible is None:
                    mk.set_watch(until, None, stop)
                    result.reversible = store.closure(back, store.m0, c=reach) == reach
                else:
                    result.reversible = upside.reversible
                    say(f"symbolic: reversibility decided {upside.how}")
            mk.set_watch(until, None, stop)
        if upside is not None:
            _take_back(store, upside)  # its answer is in, or not needed: its bytes are the main store's again
        if result.reversible is None:
            say("symbolic: reversibility (backward from M0)")
            home = store.closure(back, store.m0, c=reach)
            result.reversible = home == reach
        if result.live is None and result.reversible:
            result.live = quasi
            live_t[:] = True
        elif result.live is None and probes:
            # not reversible: a transition enabled nowhere in what a drawn marking reaches is not live
            # (a net whose initialisation is left for good, decided so in a forward saturation or two)
            say("symbolic: liveness, forward from drawn markings")
            # a drawn marking reaches a part of the reachable set, on the computed table of the
            # whole: worth at most as long as the whole took, and a share of the time left; at its
            # deadline what it decided stays and the backward saturations take the rest
            start = time.monotonic()
            share = min(_PROBE_SHARE * max(0.0, until - start), max(1.0, result.seconds.get("reach", 0.0)))
            with contextlib.suppress(_OutOfTime):
                _probe(store, fwd, single, reach, result, min(until, start + share), probes, stop, drawn)
            mk.set_watch(until, None, stop)
        if result.live is None and (probes and not drawn or not _terminal(store, fwd, back, single, reach,
                                                                          result, say, probes > 0, drawn)):
            # more terminal components than it looks for, or no drawn marking's R(m) done within the
            # probe's share (forward saturation from one marking is slow on this net, and the terminal
            # components need it; NoC3x3-PT-1A: 34 s for one, where the backward saturation of the
            # first transition tried shows it not live in 0.4 s): a backward saturation each
            say("symbolic: liveness, transition by transition")
            todo = sorted((e for e in range(single.n_events) if live_t[single.members[e][0]] is None),
                          key=lambda e: counts[e])
            # every restriction first, then every backward saturation: the computed table is
            # cleared when the events change, so alternating would start each saturation afresh
            enabled = [store.call(mk.MODE_RESTRICT, single, reach, 1, arg=e) for e in todo]
            for e, en in zip(todo, enabled):
                t = single.members[e][0]
                can = store.closure(back, en, c=reach)
                live_t[t] = can == reach
                if not live_t[t]:
                    result.live = False
                    if probes:  # the answer is known; without the probe every transition is decided
                        break
            else:  # those left have no event: enabled in every marking (Encoding.free)
                live_t[[t for t in range(n_t) if live_t[t] is None]] = True
                if result.live is None:
                    result.live = True
    except _OutOfTime:
        result.notes.append("liveness and reversibility: not decided within the time budget (answer_seconds "
                            "or seconds)")
    except _OutOfMemory as exc:
        result.notes.append(f"liveness and reversibility: not decided, {exc}")
    result.seconds["liveness"] = time.monotonic() - t0


class _TowardDead:
    """The reachable markings that can reach a dead marking (the backward closure of ``dead`` by
    ``back`` inside ``reach``, :meth:`_Store.closure`), computed in a thread beside the witness's
    quick searches over explicit markings (:func:`_witness`): those run in the interpreter and only
    read the store (:meth:`_Store.contains`; a store never changes a node), the closure runs compiled
    without it. The closure's budget is the store's less ``lent`` bytes, the quick searches' own,
    until :meth:`result` or :meth:`cancel` gives them back. The thread stops at the deadline or
    cancel flag of the caller's watch (:func:`.mdd_kernel.watch`) too. CloudDeployment-PT-6a: its
    quick searches find no sequence in 4.0 s and the closure takes 5.0 s after them; beside them,
    it is done 1.0 s after they give up."""

    def __init__(self, store: _Store, back: Events, dead: int, reach: int, lent: int) -> None:
        deadline, _progress, outer = mk.watch()
        self.store = store
        self.args = (back, dead, reach)
        self.lent = lent
        self.flag = _Cancel(outer)
        self.node: int | None = None
        self.error: BaseException | None = None
        store.max_bytes -= lent
        self.thread = threading.Thread(target=self._run, args=(deadline,), name="petrobot-toward-dead",
                                       daemon=True)
        self.thread.start()

    def _run(self, deadline: float | None) -> None:
        back, dead, reach = self.args
        mk.set_watch(deadline, None, self.flag)
        try:
            self.node = self.store.closure(back, dead, c=reach)
        except BaseException as exc:  # raised again in the caller's thread, by :meth:`result`
            self.error = exc
        finally:
            mk.set_watch(None, None)

    def _end(self) -> None:
        self.thread.join()
        self.store.max_bytes += self.lent
        self.lent = 0

    def cancel(self) -> None:
        """Stop the closure and wait for the thread; the store keeps the nodes it made."""
        self.flag.set()
        self._end()

    def result(self) -> int:
        """Wait for the closure: its node. Where it outgrew its budget it is made again here, on the
        whole budget (chained images resume where they stopped, :meth:`_Store.closure`).

        Raises:
            _OutOfTime: the caller's deadline or cancel flag stopped it. As :meth:`_Store.call`."""
        self._end()
        if isinstance(self.error, _OutOfMemory):
            back, dead, reach = self.args
            return self.store.closure(back, dead, c=reach)
        if self.error is not None:
            raise self.error
        assert self.node is not None
        return self.node


def _witness(store: _Store, sn: SparseNet, enc: Encoding, net: PetriNet, fwd: Events, back: Events | None,
             reach: int, dead: int, result: SymbolicResult, say: Callable[[str], None], deadline: float) -> None:
    """One dead marking with a firing sequence to it, within the deadline (``time.monotonic()``
    seconds): a search over explicit markings guided towards the dead marking, first inside the
    reachable set alone (briefly), then random walks (as briefly, :func:`_walk_sequence`); then,
    inside the markings that can reach a deadlock (a backward closure, on two CPUs computed beside
    the first two, :class:`_TowardDead`), random walks that stay there (:func:`_walk_sequence` with
    ``inside``) and the guided search, each within its share of the time, and breadth-first images
    (a shortest sequence) when neither has found one."""
    if dead == mk.EMPTY:
        return
    t0 = time.monotonic()
    marking = _marking(enc, store.pick(dead), net)
    result.deadlock_marking = {net.places[p].id: int(marking[p]) for p in np.flatnonzero(marking)}
    if back is None:
        result.notes.append("deadlock: no firing sequence is traced back on a net with reset arcs")
        return
    try:
        say("symbolic: a firing sequence to a deadlock")
        explicit = enc.n_levels > 0
        ex = _Explicit(sn, enc)

        def room() -> int:  # the guided search's bytes, outside the diagram's: half of what it has left
            return min(_GUIDED_BYTES, max(_GUIDED_MIN_BYTES, (store.max_bytes - store.held()) // 2))

        def until(most: float, part: float = 1.0) -> float:  # a share of the time left, at most ``most``
            now = time.monotonic()
            return now + min(most, max(0.0, (deadline - now) * part))

        found = None
        toward: _TowardDead | None = None
        if explicit:  # first inside the reachable set alone: most often a deadlock is reachable from
            # everywhere, and the backward closure below costs more; on two CPUs that closure starts
            # beside these quick searches, which hold the interpreter while it runs compiled
            lent = room()
            toward = _TowardDead(store, back, dead, reach, lent) if cpus() >= 2 else None
            try:
                found = _guided_sequence(store, ex, net, reach, dead, marking, limit=20_000,
                                         stop=until(_QUICK_SECONDS), max_bytes=lent)
                if found is None:  # then random walks, as briefly
                    found = _walk_sequence(store, ex, net, dead, until(_QUICK_SECONDS))
            except BaseException:
                if toward is not None:
                    toward.cancel()
                raise
            if toward is not None and found is not None:
                toward.cancel()
        if found is None:
            inside = store.closure(back, dead, c=reach) if toward is None else toward.result()
            if explicit:  # walks that stay inside, then the guided search inside
                found = _walk_sequence(store, ex, net, dead, until(_GUIDED_SECONDS, 1 / 3), inside=inside)
            if explicit and found is None:
                found = _guided_sequence(store, ex, net, inside, dead, marking, limit=100_000,
                                         stop=until(_GUIDED_SECONDS, 1 / 3), max_bytes=room())
            if found is None:
                found = _bfs_sequence(store, ex, net, fwd, inside, dead)
        if found is not None:
            seq, end = found
            result.deadlock_sequence = seq
            result.deadlock_marking = {net.places[p].id: int(end[p]) for p in np.flatnonzero(end)}
    except _OutOfTime:
        result.notes.append("deadlock: the firing sequence to the dead marking was not traced within the time "
                            "budget; the marking is shown without it")
    except _OutOfMemory as exc:
        result.notes.append(f"deadlock: the firing sequence to the dead marking was not traced ({exc}); the "
                            "marking is shown without it")
    result.seconds["witness"] = time.monotonic() - t0
