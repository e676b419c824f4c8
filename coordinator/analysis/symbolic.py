"""Symbolic state space of a bounded net: the reachable markings as a decision diagram (pure, no I/O).

The explicit search (:mod:`.statespace`) stores every marking; a net of twenty robots has 10^15 of
them. Here the reachable set is a multi-valued decision diagram (MDD, :mod:`.mdd_kernel`; Bryant
1986 for the binary case), built by **saturation** (Ciardo, Lüttgen, Siminiceanu 2001): the events
of the lower levels are fired to a fixed point on each node before the node is used above, so no
breadth-first frontier of the whole state space is ever built. The encoding (levels, their local
markings, their order, the merged events) comes from the net's structure and its proven place
bounds (:mod:`.mdd_order`). From the set, with exact integers of any size:

* the number of markings and of edges (one per reachable marking and transition enabled in it:
  the Model Checking Contest's count);
* deadlocks: the dead markings (the reachable set restricted, event by event, to the markings
  where the event is disabled), their number, one of them with a firing sequence from M0: a
  depth-first search over explicit markings that never leaves the markings able to reach a
  deadlock (backward saturation from the dead markings inside the reachable set), so it walks
  straight to one; breadth-first images (a shortest sequence) when that search is too long;
* quasi-liveness (each transition fireable in some reachable marking), the exact bound of every
  place, one-safety, the largest token count of a marking, stable places;
* reversibility (M0 is reachable from every reachable marking: backward saturation from M0 inside
  the reachable set, Zhao & Ciardo 2009) and liveness (L4): a quasi-live reversible net is live;
  otherwise each transition t is live iff every reachable marking can reach one that enables t,
  one backward saturation per transition within the time left; what is not decided in time stays
  ``None`` ("undecided"), never a guess.

Counts are exact: every count is computed modulo a few primes below 2**61 (sums only) and rebuilt
by the Chinese remainder theorem, with as many primes as a float estimate of the count asks for.

Budgets: ``max_bytes`` bounds the store, its tables and stacks (:class:`~coordinator.errors.
AnalysisError` when it is reached), ``seconds`` the whole computation (the reachable set first;
liveness and witnesses get what is left and are left undecided beyond it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from math import ceil, log2

import numpy as np

from coordinator.analysis import mdd_kernel as mk
from coordinator.analysis.matrices import SparseNet, sparse_net
from coordinator.analysis.mdd_order import Encoding, Events, encode, events, touched_places
from coordinator.errors import AnalysisError
from coordinator.net import PetriNet

__all__ = ["SymbolicResult", "analyse_symbolic", "load_kernel"]

_TWO61 = (1 << 61) - 1
#: largest |P|·|T| for which a witness is searched depth first on dense matrices
_DENSE_WITNESS = 4_000_000


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
        deadlock_marking: one dead marking (place id → tokens), with deadlock_sequence: a shortest
            firing sequence from M0 to it (None if it was not found within the time).
        fireable: (|T|,) bool: the transition is enabled in some reachable marking.
        place_bounds: (|P|,) int64 exact bound of every place; stable: (|P|,) bool, the count never changes.
        max_token_per_marking: the largest total count of a reachable marking.
        live: every transition is live (L4); live_transitions: (|T|,) object array of True/False/None.
        reversible: M0 is reachable from every reachable marking.
        levels, groups, nodes, order_score: the diagram: levels, levels holding several places,
            nodes of the reachable set, score of the variable order.
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
        self.dom_ptr = np.concatenate([[0], np.cumsum(enc.dom)]).astype(np.int64)
        self._count_cap = 0
        self._primes: list[int] = []
        self._done = np.zeros(0, np.uint8)
        self._approx = np.zeros(0, np.float64)
        self._residue = np.zeros((0, 1), np.int64)

    def call(self, mode: int, ev: Events, a: int, b: int = 0, c: int = mk.NO_CONSTRAINT, arg: int = 0,
             check_overflow: bool = False) -> int:
        if ev is not self._events:  # cached results name events by their index in a set of events
            mk.clear_cache(self.arrays)
            self._events = ev
        args = (mode, self.dom, *ev.tables(), *self.arrays, a, b, c, arg, check_overflow, self.max_bytes)
        status, ret, *arrays = mk.run(*args)  # type: ignore[arg-type]
        self.arrays = tuple(arrays)
        if status == mk.MEMORY:
            raise AnalysisError(f"the decision diagram outgrew the memory budget of {self.max_bytes / 2**30:.2f} GiB "
                                f"({self.nodes:,} nodes)")
        if status == mk.STOPPED:
            raise _OutOfTime()
        if status == mk.OVERFLOW:
            k = int(self.arrays[0][mk.META_OVERFLOW_LEVEL])
            raise AnalysisError(f"a firing took level {k} beyond its proven local markings: the place bounds "
                                "given to the symbolic engine are wrong")
        return int(ret)

    @property
    def nodes(self) -> int:
        return int(self.arrays[0][mk.META_NODES])

    def contains(self, node: int, values: np.ndarray) -> bool:
        offset, size, kids = self.arrays[2:5]
        return bool(mk.node_of_path(node, values.astype(np.int64), offset, size, kids) == mk.TERMINAL)

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

    def count(self, node: int) -> int:
        """The exact number of paths (markings) of a set (the first count, of the largest set, sets
        how many primes every count uses)."""
        if node <= mk.TERMINAL:
            return node
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
        if estimate >= 2.0 ** (60 * len(self._primes) - 3):  # more primes than the first estimate asked for
            self._primes = _primes(ceil((log2(estimate) + 3) / 60))
            self._count_cap = 0
            return self.count(node)
        return _crt([int(r) for r in self._residue[node]], self._primes)

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


def _crt(residues: list[int], primes: list[int]) -> int:
    value, modulus = 0, 1
    for r, p in zip(residues, primes):
        # value + modulus * x ≡ r (mod p)
        x = ((r - value) * pow(modulus, -1, p)) % p
        value += modulus * x
        modulus *= p
    return value


def load_kernel() -> None:
    """Import the compiled MDD kernel (numba; its cache, or a first compile) with numba's cache in the
    user's cache directory (:mod:`.jit`)."""
    from coordinator.analysis import jit

    jit.configure()


def _marking(enc: Encoding, values: np.ndarray, net: PetriNet) -> np.ndarray:
    out = np.zeros(len(net.places), dtype=np.int64)
    for k, ps in enumerate(enc.levels):
        out[ps] = enc.local[k][int(values[k])]
    return out


def _values(enc: Encoding, marking: np.ndarray) -> np.ndarray | None:
    out = np.empty(enc.n_levels, dtype=np.int64)
    for k in range(enc.n_levels):
        v = enc.value_of(k, marking)
        if v < 0:
            return None
        out[k] = v
    return out


def _dfs_sequence(store: _Store, sn: SparseNet, enc: Encoding, net: PetriNet, inside: int, targets: int,
                  limit: int) -> tuple[list[str], np.ndarray] | None:
    """A firing sequence from M0 to one of ``targets`` by a depth-first search over explicit markings
    that never leaves ``inside`` (every marking of which can reach a target, so the search never
    backtracks far); None when it visits ``limit`` markings first."""
    pre = sn.pre.toarray()
    inh = sn.inhibitor.toarray()
    inc = sn.incidence.toarray()
    has_inh = bool((inh > 0).any())
    m0 = np.asarray(sn.m0, dtype=np.int64)
    seen = {m0.tobytes()}
    path: list[int] = []
    stack: list[tuple[np.ndarray, np.ndarray, int]] = []

    def enabled(m: np.ndarray) -> np.ndarray:
        ok = (m[:, None] >= pre).all(axis=0)
        if has_inh:
            ok &= ((inh == 0) | (m[:, None] < inh)).all(axis=0)
        return np.flatnonzero(ok)

    cur = m0
    vals = _values(enc, cur)
    if vals is not None and store.contains(targets, vals):
        return [], cur
    stack.append((cur, enabled(cur), 0))
    while stack:
        m, ts, i = stack[-1]
        if i == ts.size:
            stack.pop()
            if path:
                path.pop()
            continue
        stack[-1] = (m, ts, i + 1)
        t = int(ts[i])
        nxt = m + inc[:, t]
        key = nxt.tobytes()
        if key in seen:
            continue
        seen.add(key)
        if len(seen) > limit:
            return None
        vals = _values(enc, nxt)
        if vals is None or not store.contains(inside, vals):
            continue
        path.append(t)
        if store.contains(targets, vals):
            return [net.transitions[x].id for x in path], nxt
        stack.append((nxt, enabled(nxt), 0))
    return None


def _bfs_sequence(store: _Store, sn: SparseNet, enc: Encoding, net: PetriNet, fwd: Events, inside: int,
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
    cur = _marking(enc, store.pick(hit), net)
    end = cur.copy()
    seq: list[str] = []
    inc = sn.incidence.tocsc()
    for layer in reversed(layers[:-1]):
        for t in range(sn.n_transitions):
            prev = cur - inc[:, t].toarray().ravel()
            if (prev < 0).any() or (prev < sn.pre[:, t].toarray().ravel()).any():
                continue
            inh = sn.inhibitor[:, t].toarray().ravel()
            if ((inh > 0) & (prev >= inh)).any():
                continue
            vals = _values(enc, prev)
            if vals is not None and store.contains(layer, vals):
                seq.append(net.transitions[t].id)
                cur = prev
                break
        else:
            raise AnalysisError("internal: no predecessor found while tracing a firing sequence back")
    seq.reverse()
    return seq, end


def analyse_symbolic(net: PetriNet, bounds: np.ndarray, *, flows: list[np.ndarray] | None = None,
                     max_bytes: int = 4 << 30, seconds: float = 600.0,
                     progress: Callable[[str], None] | None = None) -> SymbolicResult:
    """The reachable set of a bounded net by saturation, and its properties (module docstring).

    Args:
        net: the ordinary net (events dropped; no priorities).
        bounds: (|P|,) proven upper bound of every place (state equation, P-invariants).
        flows: P-semiflows of the net (groups and order, :mod:`.mdd_order`); none: only places.
        max_bytes: byte budget of the decision diagram.
        seconds: time budget; liveness and witnesses are left undecided when it runs out after the
            reachable set was built.
        progress: called with short phase descriptions.

    Returns:
        A :class:`SymbolicResult`.

    Raises:
        AnalysisError: a place without a bound, the memory budget, or the time budget reached before
            the reachable set was complete.
    """
    start = time.monotonic()
    deadline = start + seconds
    say = progress or (lambda _text: None)
    sn = sparse_net(net)
    secs: dict[str, float] = {}
    notes: list[str] = []
    t0 = time.monotonic()
    enc, fwd, store, reach = _race(sn, bounds, list(flows or []), max_bytes, deadline, say)
    single = events(sn, enc)
    secs["encode"] = enc.seconds
    secs["reach"] = time.monotonic() - t0 - enc.seconds
    try:
        mk.set_watch(None, None)
        states = store.count(reach)
        say(f"symbolic: {states:,} markings, {store.nodes:,} nodes, {secs['reach']:.1f} s")
        t0 = time.monotonic()
        free = np.array([not ps.size for ps in touched_places(sn)], dtype=bool)
        fireable = free.copy()
        edges = int(free.sum()) * states
        edges += _fireable(store, fwd, single, reach, fireable)
        dead = reach if not free.any() else mk.EMPTY
        for e in range(fwd.n_events):
            if dead == mk.EMPTY:
                break
            dead = store.call(mk.MODE_RESTRICT, fwd, dead, 0, arg=e)
        n_dead = store.count(dead)
        present = store.presence(reach)
        place_bounds = np.zeros(len(net.places), dtype=np.int64)
        low = np.zeros(len(net.places), dtype=np.int64)
        for k, ps in enumerate(enc.levels):
            vals = np.flatnonzero(present[store.dom_ptr[k]:store.dom_ptr[k + 1]])
            loc = enc.local[k][vals]
            place_bounds[ps] = loc.max(axis=0)
            low[ps] = loc.min(axis=0)
        weight = np.concatenate(enc.weight).astype(np.int64)
        max_total = store.max_weight(reach, weight)
        secs["properties"] = time.monotonic() - t0
        result = SymbolicResult(
            states=states, edges=edges, deadlock=n_dead > 0, n_deadlocks=n_dead, deadlock_marking=None,
            deadlock_sequence=None, fireable=fireable, place_bounds=place_bounds, stable=place_bounds == low,
            max_token_per_marking=max_total, live=None,
            live_transitions=np.full(len(net.transitions), None, dtype=object), reversible=None,
            levels=enc.n_levels, groups=enc.groups, nodes=store.nodes, order_score=enc.score, seconds=secs,
            notes=notes)
        back: Events | None = None
        if sn.n_resets == 0:
            back = events(sn, enc, inverse=True)
        mk.set_watch(deadline, None)
        _liveness(store, single, back, reach, result, say)
        _witness(store, sn, enc, net, fwd, back, reach, dead, result, say)
        result.nodes = store.nodes
        return result
    finally:
        mk.set_watch(None, None)


def _level_functions(ev: Events, e: int) -> dict[int, np.ndarray]:
    """Event e's local function on each level it reads or changes."""
    top = int(ev.top[e])
    out: dict[int, np.ndarray] = {}
    for k in range(top, int(ev.bot[e]) + 1):
        sl = int(ev.slot[ev.slot_ptr[e] + k - top])
        if sl >= 0:
            out[k] = ev.fn[ev.fn_ptr[sl]:ev.fn_ptr[sl + 1]]
    return out


def _fireable(store: _Store, fwd: Events, single: Events, reach: int, fireable: np.ndarray) -> int:
    """Mark the transitions enabled in some reachable marking; return the number of edges (reachable
    marking, enabled transition). One restriction per *merged* event: its members are enabled on
    disjoint values of the levels where they differ, so each marking of the restriction enables
    exactly one member (its count is the members' edges), and a member is enabled in some marking of
    it iff one of the values the restriction takes on the level where the member differs enables it
    (exact for one such level; a member that differs on more gets its own restriction)."""
    own_event = {ms[0]: i for i, ms in enumerate(single.members)}
    edges = 0
    for e in range(fwd.n_events):
        en = store.call(mk.MODE_RESTRICT, fwd, reach, 1, arg=e)
        n = store.count(en)
        edges += n
        members = fwd.members[e]
        if len(members) == 1 or n == 0:
            fireable[list(members)] = n > 0
            continue
        merged = _level_functions(fwd, e)
        present = store.presence(en)
        for t in members:
            own = _level_functions(single, own_event[t])
            differ = [k for k in own if k not in merged or not np.array_equal(own[k], merged[k])]
            ok = all((own[k][np.flatnonzero(present[store.dom_ptr[k]:store.dom_ptr[k + 1]])] >= 0).any()
                     for k in differ)
            if ok and len(differ) > 1:
                ok = store.call(mk.MODE_RESTRICT, single, reach, 1, arg=own_event[t]) != mk.EMPTY
            fireable[t] = ok
    return edges


#: candidate variable orders raced against each other, and the first time slice of each (seconds)
_CANDIDATES = 3
_FIRST_SLICE = 2.0


def _race(sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], max_bytes: int, deadline: float,
          say: Callable[[str], None]) -> tuple[Encoding, Events, _Store, int]:
    """The reachable set, by saturation on candidate variable orders taking turns, each turn a time
    slice that doubles after every round, until one finishes. How long saturation takes on an order
    is hard to predict from the order (on Railroad-PT-010, orders whose scores differ by 2 % take
    0.15 to 13 s), so a few candidates are raced; a candidate's store, computed table included, is
    kept between its turns, so a turn resumes where the last one stopped and the total stays within
    about the number of candidates times the best one's time. Each store has an equal share of the
    memory budget; when one outgrows its share, the others are dropped and it gets the whole."""
    cands: list[tuple[Encoding, Events, _Store]] = []
    alive: list[bool] = []
    slice_s = _FIRST_SLICE
    turn = 0
    while True:
        i = turn % _CANDIDATES
        turn += 1
        if i < len(alive) and not alive[i]:
            if not any(alive):
                raise AnalysisError("the decision diagram outgrew the memory budget on every candidate "
                                    "variable order")
            if turn % _CANDIDATES == 0:
                slice_s *= 2
            continue
        if i == len(cands):
            seconds = min(10.0, max(1.0, (deadline - time.monotonic()) / 20))
            enc = encode(sn, bounds, flows, seconds=seconds, seed=i)
            cands.append((enc, events(sn, enc, merge=True), _Store(enc, max_bytes // _CANDIDATES)))
            alive.append(True)
            if i == 0:
                say(f"symbolic: {enc.n_levels} levels ({enc.groups} groups of places), {cands[0][1].n_events} "
                    f"events for {sn.n_transitions} transitions")
        enc, fwd, store = cands[i]
        mk.set_watch(min(deadline, time.monotonic() + slice_s), None)
        try:
            reach = store.call(mk.MODE_SATURATE, fwd, store.m0, check_overflow=True)
            store.max_bytes = max_bytes  # the others are dropped: the winner has the whole budget
            return enc, fwd, store, reach
        except _OutOfTime:
            if time.monotonic() >= deadline:
                raise AnalysisError(f"the symbolic reachable set was not complete within the time budget "
                                    f"({store.nodes:,} nodes on the last variable order tried)") from None
            if sum(alive) > 1:
                say(f"symbolic: order {i + 1} not done after its {slice_s:.0f} s turn ({store.nodes:,} nodes)")
        except AnalysisError as exc:
            if "memory budget" not in str(exc):
                raise
            if store.max_bytes < max_bytes:  # drop the others, give this one the whole budget
                for j in range(len(cands)):
                    if j != i:
                        alive[j] = False
                        cands[j] = (cands[j][0], cands[j][1], _Store(cands[j][0], 0))
                store.max_bytes = max_bytes
                turn -= 1
                continue
            alive[i] = False
        finally:
            mk.set_watch(None, None)
        if turn % _CANDIDATES == 0:
            slice_s *= 2


def _liveness(store: _Store, single: Events, back: Events | None, reach: int, result: SymbolicResult,
              say: Callable[[str], None]) -> None:
    """Reversibility and liveness (module docstring), within the watch's deadline."""
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
    try:
        if result.reversible is None:
            say("symbolic: reversibility (backward from M0)")
            home = store.call(mk.MODE_SATURATE, back, store.m0, c=reach)
            result.reversible = home == reach
        if result.live is None and result.reversible:
            result.live = quasi
            live_t[:] = True
        elif result.live is None:
            say("symbolic: liveness, transition by transition")
            for e in range(single.n_events):
                t = single.members[e][0]
                if live_t[t] is not None:
                    continue
                enabled = store.call(mk.MODE_RESTRICT, single, reach, 1, arg=e)
                can = store.call(mk.MODE_SATURATE, back, enabled, c=reach)
                live_t[t] = can == reach
                if not live_t[t]:
                    result.live = False
                    break
            else:
                free = [t for t in range(n_t) if live_t[t] is None]
                live_t[free] = True
                result.live = True
    except _OutOfTime:
        result.notes.append("liveness and reversibility: not decided within the time budget")
    result.seconds["liveness"] = time.monotonic() - t0


def _witness(store: _Store, sn: SparseNet, enc: Encoding, net: PetriNet, fwd: Events, back: Events | None,
             reach: int, dead: int, result: SymbolicResult, say: Callable[[str], None]) -> None:
    """One dead marking with a shortest firing sequence to it, within the deadline."""
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
        inside = store.call(mk.MODE_SATURATE, back, dead, c=reach)
        found = None
        if sn.n_places * sn.n_transitions <= _DENSE_WITNESS:
            found = _dfs_sequence(store, sn, enc, net, inside, dead, limit=100_000)
        if found is None:
            found = _bfs_sequence(store, sn, enc, net, fwd, inside, dead)
        if found is not None:
            seq, end = found
            result.deadlock_sequence = seq
            result.deadlock_marking = {net.places[p].id: int(end[p]) for p in np.flatnonzero(end)}
    except _OutOfTime:
        result.notes.append("deadlock: the firing sequence to the dead marking was not traced within the time "
                            "budget; the marking is shown without it")
    result.seconds["witness"] = time.monotonic() - t0
