"""How the markings of a bounded net become paths of a decision diagram (pure, no I/O).

Internal to :mod:`.symbolic`. Three decisions, each from the net's structure alone:

1. **Variables.** A level of the diagram holds one place, or a group of places whose joint token
   counts are few: the support of a P-semiflow y (y·M is the same in every reachable marking, so
   the places of a state machine component hold one token between them, and a one-hot encoded
   variable of a coloured net is one such group). The values of a level are its *local markings*,
   found by closing the initial marking of the group under every transition's effect on the group
   alone, each place capped by its proven bound: an over-approximation of the local markings that
   occur (the diagram only ever holds those that do), finite because every place is bounded
   (Ciardo, Lüttgen, Siminiceanu 2001 use such local state spaces; Pastor, Cortadella 1998 encode
   state machine components the same way). A group is kept when it has at most :data:`MAX_LOCAL`
   local markings; groups are disjoint, packed greedily twice (the larger first; the one most of
   whose transitions stay inside it first) and the packing that leaves more transitions on one
   level is kept; in it, what a support leaves beside the groups packed before it (two places
   or more) is then a group too, its local markings kept within y·M ≤ y·M0; the remaining places
   get a level each with the values 0 .. bound. A group (or
   place) with a single local marking is no level at all:
   its places are *fixed* (their counts are the same in every reachable marking), a transition
   disabled by them is never enabled, and the others ignore them; so events span fewer levels and
   every path is shorter. A transition enabled by them that would change them (beyond a proven
   bound: it never fires if the bounds are right) is left out of saturation too, and
   :mod:`.symbolic` checks afterwards that no reachable marking enables it (else the bounds were
   wrong: an error, as for a firing beyond a level's values).
2. **Order.** Levels are ordered so that transitions and P-semiflows span few levels (saturation
   works on the levels between an event's top and bottom): FORCE (Aloul, Markov, Sakallah 2003:
   each level moves to the mean centre of gravity of its hyperedges), from several starts, each
   followed by sifting (Rudell 1993: every level moved to its best position while that lowers the
   score; on more than :data:`MAX_SIFTED` levels, where a round costs the square of the levels,
   one start a seed, sifted for a few seconds); the score is the sum of the spans of transitions
   and semiflows. On CloudReconfiguration-PT-303 (2,584 levels) FORCE alone scores 170,332 and
   saturation takes 20 s; a round of sifting (2 s) brings it to 130,163 and 5 s, two rounds to
   121,145 and 3.5 s. On nets of at most :data:`RANK_LEVELS` levels where a semiflow holds more
   than one token, the order is then sifted on the ranks of the semiflows' partial sums at each
   cut (:class:`_PartialSums`), which bound the nodes below it. Resources shared by components that
   meet only through them (:func:`shared_levels`) can be put below all the components instead.
   With ``flow`` there is no search: the levels come in the order a token flows from the initial
   marking (:func:`_flow_order`), an order a low score can miss (a business process's, its forks
   and joins one after the other).
3. **Events.** A transition becomes an event: its top and bottom levels and a local function per
   level it reads or changes (local value → local value, -1 where it is disabled). Events that are
   equal on every level but one, where they are enabled on disjoint values, are merged into one (the
   unfolded transitions of a coloured net that differ in the colour they read), which divides the
   work of saturation; deadlocks and saturation use merged events, counts per transition the
   original ones, backward reachability the inverse functions.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from math import comb

import numpy as np
import scipy.sparse as sp

from coordinator.analysis import jit

jit.configure()  # numba's cache in the user's cache directory: before numba is imported

from numba import njit  # noqa: E402

from coordinator.analysis.matrices import SparseNet
from coordinator.errors import AnalysisError

__all__ = ["MAX_LOCAL", "SHARED_DEGREE", "Encoding", "EncodingTooLarge", "Events", "PlaceGroups", "concat_ranges",
           "encode", "events", "shared_levels", "touched_places"]

#: most local markings of a group of places on one level
MAX_LOCAL = 512
#: most levels sifted to the end (each level tries every position: quadratic); beyond, the order
#: search makes one start, sifted for at most ``_SIFT_SECONDS`` (:func:`_order`)
MAX_SIFTED = 2000
#: seconds of sifting for a start beyond MAX_SIFTED levels (a round of 2,584 levels takes 2 s)
_SIFT_SECONDS = 3.0
#: neighbour swaps per call of the compiled sifting between two looks at the deadline (about 0.1 s)
_SIFT_SWAPS = 1 << 19
#: most values of a level (a place with a larger bound makes the symbolic engine refuse the net)
MAX_DOMAIN = 1 << 16
#: bytes an encoding holds per local marking beyond its counts (its entry in ``Encoding.index``), and
#: per value of a level a transition spans: one int64 in its function. The events of one transition
#: each (``events(sn, enc)``) take exactly that; merged ones (forward, backward) take at most that,
#: most often far less, as transitions alike share one function (StigmergyElection-PT-09b: 41,210
#: transitions on 10 levels, 383 MiB unmerged, 0.14 MiB merged into 95 events). 32 bytes (forward,
#: single, backward, each as if unmerged) refused that net's encoding at 1.5 GiB, and the explicit
#: search alone did not finish it; with 8, the symbolic engine counts its 3.6·10^18 markings
_INDEX_BYTES = 160
_EVENT_BYTES = 8


class EncodingTooLarge(AnalysisError):
    """The bounds given make levels too wide: a bound above :data:`MAX_DOMAIN`, or an encoding and
    events beyond their share of the memory (:func:`encode`)."""


@dataclass(frozen=True)
class Encoding:
    """Levels of the diagram (level 0 at the root) and their local markings.

    Attributes:
        levels: the place indices of each level, top to bottom.
        local: per level, its local markings, shape (values, places of the level), int64.
        dom: (K,) int64 number of values of each level.
        place_level: (|P|,) int64 level of each place; place_col: its column in that level.
        m0: (K,) int64 value of each level in the initial marking.
        weight: per level, (values,) int64 tokens of each local marking (for max tokens per marking).
        groups: levels holding more than one place.
        score: the order's score (sum of spans of transitions and semiflows over levels).
        seconds: time spent finding groups and order.
        fixed: the places on no level, whose counts never change: ``fixed_values`` (same shape),
            in every reachable marking; ``never``: (|T|,) bool, the transitions such a place
            disables (never enabled); ``suspect``: (|T|,) bool, those it enables but that would
            change it (never enabled if the bounds are right). ``place_level`` is -1 for a fixed
            place.
        sunk: shared levels moved below all others (:func:`encode` with ``sink``), 0 if none.
    """

    levels: tuple[np.ndarray, ...]
    local: tuple[np.ndarray, ...]
    dom: np.ndarray
    place_level: np.ndarray
    place_col: np.ndarray
    m0: np.ndarray
    weight: tuple[np.ndarray, ...]
    groups: int
    score: float
    seconds: float
    index: tuple[dict[tuple[int, ...], int], ...] = field(default_factory=tuple)
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fixed_values: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    never: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    suspect: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    sunk: int = 0

    @property
    def n_levels(self) -> int:
        """Number of levels K."""
        return int(self.dom.shape[0])

    @property
    def fixed_tokens(self) -> int:
        """Tokens on the fixed places (the same in every reachable marking)."""
        return int(self.fixed_values.sum())

    def free(self, touched: list[np.ndarray]) -> np.ndarray:
        """(|T|,) bool: the transitions enabled in every reachable marking that change no level
        (they read or change fixed places only, or none); ``touched``: :func:`touched_places`."""
        return np.array([not self.never[t] and not self.suspect[t] and bool((self.place_level[ps] < 0).all())
                         for t, ps in enumerate(touched)], dtype=bool)

    def value_of(self, k: int, marking: np.ndarray) -> int:
        """The value of level k in a full marking (|P|,), or -1 if that local marking is not a value."""
        key = tuple(int(marking[p]) for p in self.levels[k])
        return self.index[k].get(key, -1)

    def reversed(self) -> Encoding:
        """The same levels in the opposite order (level K − 1 at the root). Its score is the same
        (a span does not depend on the direction), but saturation fires an event at its top level,
        so the two directions can differ by orders of magnitude: Kanban-PT-00100, 1.9 s and 113,617
        nodes on the order found, 0.01 s and 1,924 nodes on its reverse. Shared levels sunk at the
        bottom come to the top (``sunk`` is 0)."""
        place_level = np.where(self.place_level >= 0, self.n_levels - 1 - self.place_level, -1)
        return replace(self, levels=self.levels[::-1], local=self.local[::-1], dom=self.dom[::-1].copy(),
                       place_level=place_level, m0=self.m0[::-1].copy(), weight=self.weight[::-1],
                       index=self.index[::-1], sunk=0)


@dataclass(frozen=True)
class Events:
    """Events for :func:`.mdd_kernel.run`: arrays (see there) and the transitions behind each.

    Attributes:
        top, bot, slot_ptr, slot, fn_ptr, fn, by_top_ptr, by_top: the kernel's event tables.
        members: the transition indices of each event (one, or several merged).
        local: the transitions' local functions these events were built from, kept so that other
            events of the same encoding take them again (:func:`events`, ``like``).
    """

    top: np.ndarray
    bot: np.ndarray
    slot_ptr: np.ndarray
    slot: np.ndarray
    fn_ptr: np.ndarray
    fn: np.ndarray
    by_top_ptr: np.ndarray
    by_top: np.ndarray
    members: tuple[tuple[int, ...], ...]
    local: _LocalFunctions | None = field(default=None, repr=False, compare=False)

    def tables(self) -> tuple[np.ndarray, ...]:
        """The arrays in the order :func:`.mdd_kernel.run` takes them after ``dom``."""
        return (self.top, self.bot, self.slot_ptr, self.slot, self.fn_ptr, self.fn, self.by_top_ptr, self.by_top)

    @property
    def n_events(self) -> int:
        """Number of events."""
        return int(self.top.shape[0])

    @property
    def nbytes(self) -> int:
        """The bytes of the kernel's tables (AirplaneLD-PT-2000's 16,008 events: 169 MB to 490 MB by
        the order)."""
        return sum(a.nbytes for a in self.tables())


def concat_ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The integers ``starts[i] .. starts[i] + counts[i] - 1`` for every i, one after the other."""
    return np.repeat(starts - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))


def touched_places(sn: SparseNet) -> list[np.ndarray]:
    """The places each transition reads or changes (input, output, inhibitor, reset), sorted."""
    mats = [sn.pre, sn.post, sn.inhibitor] + ([sn.reset] if sn.reset is not None and sn.reset.nnz else [])
    both = sp.csc_matrix(sum((abs(m) for m in mats), sp.csc_matrix(sn.pre.shape, dtype=np.int64)))
    both.sort_indices()
    idx = both.indices.astype(np.int64)  # converted once: a conversion per slice took 1 s on 41,210 transitions
    ptr = both.indptr.tolist()
    return [idx[ptr[t]:ptr[t + 1]] for t in range(sn.n_transitions)]


def _local_space(places: np.ndarray, sn: SparseNet, bounds: np.ndarray, trans: np.ndarray,
                 cap: int, within: tuple[np.ndarray, int] | None = None) -> np.ndarray | None:
    """The local markings of a group of places (module docstring), shape (n, len(places)); None if
    more than ``cap``. ``within``: (weights (len(places),), total) with weights·M ≤ total in every
    reachable marking (part of a semiflow's support: the rest holds no negative count), which
    the local markings keep too."""
    rows = np.asarray(places, dtype=np.int64)
    has_reset = sn.reset is not None and bool(sn.reset.nnz)
    parts = [sn.pre[rows][:, trans], sn.post[rows][:, trans], sn.inhibitor[rows][:, trans]]
    if has_reset:
        assert sn.reset is not None
        parts.append((sn.reset[rows][:, trans] > 0).astype(np.int64))
    # transitions of the same effect on the group are one (BridgeAndVehicles-PT-V80P20N20: 3,728
    # transitions, a handful of effects on a group, each looked at in every local marking): an
    # effect is named by its column's entries, sparse, and only the first of each is made dense
    # (StigmergyElection-PT-09b: 41,210 transitions on groups of 125 places, 3 s a group as
    # sorted dense rows)
    sub = sp.csc_matrix(sp.vstack(parts, format="csc"), dtype=np.int64)
    sub.eliminate_zeros()
    sub.sort_indices()
    ptr, ind, dat = sub.indptr, sub.indices, sub.data
    firsts: dict[bytes, int] = {}
    for j in range(trans.size):
        firsts.setdefault(ind[ptr[j]:ptr[j + 1]].tobytes() + dat[ptr[j]:ptr[j + 1]].tobytes(), j)
    effects = sub[:, np.array(sorted(firsts.values()), dtype=np.int64)].toarray().T
    k = rows.size
    pre, post, inh = effects[:, :k], effects[:, k:2 * k], effects[:, 2 * k:3 * k]
    reset = effects[:, 3 * k:] > 0 if has_reset else None
    top = bounds[rows]
    # breadth first, a whole level of the search at once: the markings in the order a first-in
    # first-out search finds them (each marking's successors by effect, in the order of the markings
    # before them); IBMB2S565S3960-PT-none's 100 semiflow supports, each beyond the cap: 2.8 s one
    # marking at a time
    found = sn.m0[rows].astype(np.int64)[None, :]
    seen = {found[0].tobytes()}
    frontier = found
    n = 1
    # the markings × effects × places compared a step at most: 8 MiB of booleans, and at most 64 MiB
    # of successors
    step = max(1, (1 << 23) // max(1, pre.shape[0] * k))
    while frontier.shape[0]:
        new: list[np.ndarray] = []
        for lo in range(0, frontier.shape[0], step):
            m = frontier[lo:lo + step, None, :]
            ok = (m >= pre[None]).all(axis=2) & ((inh[None] == 0) | (m < inh[None])).all(axis=2)
            at, r = np.nonzero(ok)
            nxt = m[at, 0] - pre[r] + post[r]
            if reset is not None:
                nxt = np.where(reset[r], post[r], nxt)
            keep = ~(nxt > top).any(axis=1)  # beyond a proven bound: never reached
            if within is not None:
                keep &= nxt @ within[0] <= within[1]
            for row in nxt[keep]:
                key = row.tobytes()
                if key not in seen:
                    seen.add(key)
                    new.append(row)
                    n += 1
                    if n > cap:
                        return None
        frontier = np.array(new, dtype=np.int64).reshape(len(new), k)
        found = np.concatenate([found, frontier])
    return found


def _groups(sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], touched: list[np.ndarray],
            deadline: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Disjoint groups of places (semiflow supports) with their local markings, the larger first.

    Two greedy packings of the semiflow supports are built and the one that leaves more transitions
    inside a single level is kept (a local event is fired on one level alone; an event across levels
    makes saturation walk every level between its top and bottom): the larger support first, and the
    support whose places are most often read and changed by transitions inside it first. They differ
    on nets of components that share resources: the places that hold one shared resource, across
    every component, form a semiflow larger than each component's, and taking it first splits every
    component into single places (a fleet of robots sharing an aisle); the second packing keeps each
    component whole. In the packing kept, the places a support leaves beside the groups already packed
    are a group of their own where their local markings, kept within y·M ≤ y·M0, are few and fewer
    than their bounds allow (semiflows through a shared place: ARMCacheCoherence-PT-none's twelve,
    72 levels before, 12 now, and a reachable set in 10 s against none in 60 s)."""
    n_p = sn.n_places
    trans_of: list[list[int]] = [[] for _ in range(n_p)]
    for t, ps in enumerate(touched):
        for p in ps.tolist():
            trans_of[p].append(t)
    # candidates by an upper bound of their local markings (a weighted count y·M = y·M0 caps each
    # place at ⌊y·M0 / y_p⌋): those surely within MAX_LOCAL first, the larger support first among
    # them; then the others, the smallest bound first
    cands: list[tuple[float, int, np.ndarray, np.ndarray]] = []
    for y in flows:
        support = np.flatnonzero(y)
        if support.size < 2:
            continue
        total = int(np.dot(y[support], sn.m0[support]))
        caps = np.minimum(bounds[support], total // y[support])
        with np.errstate(over="ignore"):  # a product beyond 1e308 is inf: far above MAX_LOCAL either way
            upper = float(np.prod((caps + 1).astype(np.float64)))
        if (y[support] == 1).all() and total < 64:
            upper = min(upper, float(comb(support.size + total - 1, total)))
        cands.append((upper, -support.size, support, y))
    cands.sort(key=lambda c: (c[0] > MAX_LOCAL, c[1] if c[0] <= MAX_LOCAL else c[0], c[1]))
    found: dict[bytes, tuple[np.ndarray, np.ndarray] | None] = {}  # a support's group, None if not one
    left: dict[bytes, tuple[np.ndarray, np.ndarray] | None] = {}  # the same for what a support leaves
    changed = np.zeros(n_p, dtype=bool)
    changed[sp.csc_matrix(sn.incidence).indices] = True  # the places of a CSC matrix's entries
    if sn.reset is not None and sn.reset.nnz:
        changed[sp.csc_matrix(sn.reset).indices] = True
    constant = ~changed

    def pack(order: list[tuple[float, int, np.ndarray, np.ndarray]], rests: bool = False
             ) -> list[tuple[np.ndarray, np.ndarray]]:
        used = np.zeros(n_p, dtype=bool)
        out: list[tuple[np.ndarray, np.ndarray]] = []
        seen: set[bytes] = set()
        for _, _, support, _ in order:
            if time.monotonic() > deadline:
                break
            key = support.tobytes()
            if used[support].any() or key in seen:
                continue
            seen.add(key)
            if key not in found:
                found[key] = None
                with np.errstate(over="ignore"):
                    product = float(np.prod((bounds[support] + 1).astype(np.float64)))
                if product > 1:
                    trans = np.array(sorted({t for p in support.tolist() for t in trans_of[p]}), dtype=np.int64)
                    local = _local_space(support, sn, bounds, trans, MAX_LOCAL)
                    if local is not None and local.shape[0] < product:  # else too many, or uncorrelated
                        found[key] = (support.astype(np.int64), local)
            group = found[key]
            if group is not None:
                used[support] = True
                out.append(group)
        for _, _, support, y in order:
            # what a semiflow whose support meets the groups above leaves (ARMCacheCoherence-PT-none:
            # twelve one-hot semiflows, each through its own places and one shared idle place, so
            # only the first was a group): its places still hold y·M ≤ y·M0 between them
            rest = support[~used[support]]
            if not rests or rest.size < 2 or rest.size == support.size or time.monotonic() > deadline:
                continue
            total = int(np.dot(y[support], sn.m0[support]))
            key = rest.tobytes() + y[rest].tobytes() + total.to_bytes(16, "little", signed=True)
            if key not in left:
                left[key] = None
                with np.errstate(over="ignore"):
                    product = float(np.prod((bounds[rest] + 1).astype(np.float64)))
                trans = np.array(sorted({t for p in rest.tolist() for t in trans_of[p]}), dtype=np.int64)
                local = _local_space(rest, sn, bounds, trans, MAX_LOCAL, within=(y[rest], total))
                if local is not None and local.shape[0] < product:
                    left[key] = (rest.astype(np.int64), local)
            group = left[key]
            if group is not None:
                used[rest] = True
                out.append(group)
        for p in np.flatnonzero(~used).tolist():
            # a place no firing changes (only read: pre = post, no reset) keeps its initial count, one
            # local marking: :func:`_fixed` takes it off the levels (Eratosthenes' primes)
            values = sn.m0[p:p + 1] if constant[p] else np.arange(int(bounds[p]) + 1)
            out.append((np.array([p], dtype=np.int64), values.astype(np.int64)[:, None]))
        return out

    def inside(support: np.ndarray) -> int:
        """Transitions that read or change places of ``support`` only."""
        mine = np.zeros(n_p, dtype=bool)
        mine[support] = True
        ts = {t for p in support.tolist() for t in trans_of[p]}
        return sum(1 for t in ts if mine[touched[t]].all())

    def local_events(groups: list[tuple[np.ndarray, np.ndarray]]) -> int:
        owner = np.empty(n_p, dtype=np.int64)
        for k, (ps, _) in enumerate(groups):
            owner[ps] = k
        return sum(1 for ps in touched if ps.size and (owner[ps] == owner[ps[0]]).all())

    # the packing is chosen on the supports alone, and what they leave is grouped after: with those
    # groups the first packing of a fleet (the aisles' semiflows first, each robot's places left
    # beside them) keeps as many transitions on one level as the second, and would split the robots
    first = pack(cands)
    n_small = sum(1 for c in cands if c[0] <= MAX_LOCAL)
    by_density = sorted(range(n_small), key=lambda i: (-inside(cands[i][2]) / cands[i][2].size, cands[i][1]))
    if by_density == list(range(n_small)) or time.monotonic() > deadline:
        return pack(cands, rests=True)
    dense = [cands[i] for i in by_density] + cands[n_small:]
    second = pack(dense)
    return pack(dense, rests=True) if local_events(second) > local_events(first) else pack(cands, rests=True)


def _fixed(sn: SparseNet, groups: list[tuple[np.ndarray, np.ndarray]]
           ) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray, np.ndarray]:
    """The groups that stay levels, the fixed places (a group of one local marking), the transitions
    they disable and those they enable but that would change them (module docstring). A transition
    is disabled by some fixed place or enabled by all of them, so both are read off the arcs of the
    fixed places at once (AirplaneLD-PT-2000's 6,002 fixed groups: 2.9 s group by group)."""
    keep = [(ps, loc) for ps, loc in groups if loc.shape[0] != 1]
    one = [(np.asarray(ps, dtype=np.int64), loc[0]) for ps, loc in groups if loc.shape[0] == 1]
    never = np.zeros(sn.n_transitions, dtype=bool)
    changed = np.zeros(sn.n_transitions, dtype=bool)
    if not one:
        return keep, np.zeros(0, np.int64), never, changed
    rows = np.concatenate([ps for ps, _ in one])
    value = np.zeros(sn.n_places, dtype=np.int64)
    value[rows] = np.concatenate([v for _, v in one])
    is_fixed = np.zeros(sn.n_places, dtype=bool)
    is_fixed[rows] = True

    def arcs(m: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = sp.coo_matrix(m)
        on = is_fixed[c.row] & (c.data != 0)
        return c.row[on].astype(np.int64), c.col[on].astype(np.int64), c.data[on].astype(np.int64)

    p, t, w = arcs(sn.pre)
    never[t[value[p] < w]] = True
    p, t, w = arcs(sn.inhibitor)
    never[t[value[p] >= w]] = True
    p, t, _ = arcs(sn.incidence)  # a firing changes p by C[p, t], where no reset arc empties p
    if sn.reset is not None and sn.reset.nnz:
        rp, rt, _ = arcs(sn.reset)
        emptied = np.isin(p * sn.n_transitions + t, rp * sn.n_transitions + rt)
        p, t = p[~emptied], t[~emptied]
        after = np.asarray(sp.csr_matrix(sn.post)[rp, rt]).ravel()  # a reset leaves p what t puts back
        changed[rt[after != value[rp]]] = True
    changed[t] = True
    return keep, np.sort(rows), never, changed & ~never


def _score(pos: np.ndarray, hp: np.ndarray, hidx: np.ndarray, hw: np.ndarray | None = None) -> float:
    """Sum of the spans of the hyperedges (each ``hw`` times, default once) under positions ``pos``."""
    lo = np.minimum.reduceat(pos[hidx], hp[:-1]) if hidx.size else np.zeros(0)
    hi = np.maximum.reduceat(pos[hidx], hp[:-1]) if hidx.size else np.zeros(0)
    return float(((hi - lo) * (1 if hw is None else hw)).sum())


@njit(cache=True)
def _swap(p: int, q: int, pos: np.ndarray, order: np.ndarray, hw: np.ndarray, lo: np.ndarray, hi: np.ndarray,
          vp: np.ndarray, vidx: np.ndarray, mark: np.ndarray) -> int:
    """Swap the neighbours p and q; return the change of the score. Only a hyperedge holding exactly
    one of them changes, and only when that one is its top or bottom (``lo``, ``hi``: each
    hyperedge's smallest and largest position, kept up to date): the end moves with it, one position,
    so a swap costs the hyperedges of p and q, not their sizes (RwMutex-PT-r0500w0010's transitions
    read 500 levels). Hyperedge h counts ``hw[h]`` times."""
    a = pos[p]
    b = pos[q]
    for x in range(vp[q], vp[q + 1]):
        mark[vidx[x]] += 1
    for x in range(vp[p], vp[p + 1]):
        mark[vidx[x]] += 2
    delta = 0
    # the two loops are mirror images, written out: as a helper taking the arrays, numba counted
    # their references at each call, and sifting 600 levels took 14-18 s instead of 3.7-5.3 s
    for x in range(vp[p], vp[p + 1]):  # p goes from a to b
        h = vidx[x]
        if mark[h] == 2:
            if lo[h] == a:
                lo[h] = b
                delta += hw[h] * (a - b)
            if hi[h] == a:
                hi[h] = b
                delta += hw[h] * (b - a)
    for x in range(vp[q], vp[q + 1]):  # q goes from b to a
        h = vidx[x]
        if mark[h] == 1:
            if lo[h] == b:
                lo[h] = a
                delta += hw[h] * (b - a)
            if hi[h] == b:
                hi[h] = a
                delta += hw[h] * (a - b)
    order[a] = q
    order[b] = p
    pos[p] = b
    pos[q] = a
    for x in range(vp[q], vp[q + 1]):
        mark[vidx[x]] = 0
    for x in range(vp[p], vp[p + 1]):
        mark[vidx[x]] = 0
    return delta


@njit(cache=True, nogil=True)  # while one thread saturates, another searches orders
def _sift_levels(order: np.ndarray, pos: np.ndarray, hw: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 vp: np.ndarray, vidx: np.ndarray, mark: np.ndarray, first: int, last: int) -> bool:
    """Sifting of the levels ``first`` .. ``last`` - 1, in place: move each to the position of the
    lowest score, by neighbour swaps (:func:`_swap`); True when one moved (the score went down)."""
    n = order.shape[0]
    improved = False
    for p in range(first, last):
        start = pos[p]
        best = 0
        best_pos = start
        for direction in (-1, 1):
            cur = 0
            while 0 <= pos[p] + direction < n:
                cur += _swap(p, order[pos[p] + direction], pos, order, hw, lo, hi, vp, vidx, mark)
                if cur < best:
                    best = cur
                    best_pos = pos[p]
            while pos[p] != start:
                step = 1 if start > pos[p] else -1
                _swap(p, order[pos[p] + step], pos, order, hw, lo, hi, vp, vidx, mark)
        while pos[p] != best_pos:
            step = 1 if best_pos > pos[p] else -1
            _swap(p, order[pos[p] + step], pos, order, hw, lo, hi, vp, vidx, mark)
        if best < 0:
            improved = True
    return improved


def _sift(order: np.ndarray, hp: np.ndarray, hidx: np.ndarray, hw: np.ndarray, vp: np.ndarray, vidx: np.ndarray,
          rounds: int, deadline: float | None = None, stop: Callable[[], bool] | None = None) -> None:
    """Sifting, in place (Rudell 1993): rounds of every level moved to the position of the lowest
    score, until a round moves none or ``rounds`` are done; also ended at ``deadline``
    (``time.monotonic()`` seconds) or when ``stop()`` says so, between levels (each move only
    lowers the score, so the order is the better for every level sifted)."""
    n = order.shape[0]
    pos = np.empty(n, np.int64)
    pos[order] = np.arange(n)
    mark = np.zeros(hp.shape[0], np.int64)
    at = pos[hidx]
    lo = np.minimum.reduceat(at, hp[:-1]) if hidx.size else np.zeros(0, np.int64)
    hi = np.maximum.reduceat(at, hp[:-1]) if hidx.size else np.zeros(0, np.int64)
    timed = deadline is not None or stop is not None
    chunk = max(1, _SIFT_SWAPS // max(1, n)) if timed else n
    for _ in range(rounds):
        improved = False
        for first in range(0, n, chunk):
            if (deadline is not None and time.monotonic() > deadline) or (stop is not None and stop()):
                return
            improved |= _sift_levels(order, pos, hw, lo, hi, vp, vidx, mark, first, min(n, first + chunk))
        if not improved:
            break


def _order(n: int, hypers: list[np.ndarray], deadline: float, starts: int = 8, seed: int = 0,
           stop: Callable[[], bool] | None = None) -> tuple[np.ndarray, float]:
    """The best order of ``n`` levels found by FORCE and sifting from several starts (module
    docstring), and its score; the starts end at ``deadline`` or when ``stop()`` says so (after
    the first start; ``stop()`` ends sifting too). Beyond :data:`MAX_SIFTED` levels one start
    only, another for each seed (the net's own order for seed 0, its reverse for seed 1, random
    ones after), sifted for at most :data:`_SIFT_SECONDS`: the first candidate saturates sooner,
    and other seeds give other candidates to race."""
    # equal hyperedges (the unfolded transitions of a coloured net touch the same levels) are one,
    # counted as many times: the score is the same, sifting's work is per distinct hyperedge
    weights: dict[bytes, int] = {}
    distinct: list[np.ndarray] = []
    for h in hypers:
        if h.size > 1:
            key = h.tobytes()
            if key not in weights:
                weights[key] = 0
                distinct.append(h)
            weights[key] += 1
    hypers = distinct
    if n <= 1 or not hypers:
        return np.arange(n, dtype=np.int64), 0.0
    hw = np.array([weights[h.tobytes()] for h in hypers], dtype=np.int64)
    sizes = np.array([h.size for h in hypers], dtype=np.int64)
    hp = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    hidx = np.concatenate(hypers).astype(np.int64)
    rows = np.repeat(np.arange(len(hypers)), sizes)
    mat = sp.csr_matrix((np.repeat(hw, sizes).astype(np.float64), (rows, hidx)), shape=(len(hypers), n))
    mat_t = sp.csr_matrix(mat.T)
    deg = np.asarray(mat_t.sum(axis=1)).ravel()
    by_v = mat_t.indices.astype(np.int64)
    vp = mat_t.indptr.astype(np.int64)
    rng = np.random.default_rng(0x5A7 + 7919 * seed)
    best: tuple[float, np.ndarray] | None = None
    large = n > MAX_SIFTED
    for s in range(starts):
        if best is not None and (large or time.monotonic() > deadline or (stop is not None and stop())):
            break
        kind = seed if large else s
        start = np.arange(n) if kind == 0 else (np.arange(n)[::-1] if kind == 1 else rng.permutation(n))
        pos = np.empty(n)
        pos[start] = np.arange(n)
        cand: tuple[float, np.ndarray] | None = None
        for _ in range(30):  # FORCE: levels to the mean centre of gravity of their hyperedges
            cog = (mat @ pos) / (sizes * hw)
            moved = np.where(deg > 0, (mat_t @ cog) / np.maximum(deg, 1), pos)
            order = np.lexsort((pos, moved))
            pos = np.empty(n)
            pos[order] = np.arange(n)
            score = _score(pos.astype(np.int64), hp, hidx, hw)
            if cand is None or score < cand[0]:
                cand = (score, order.astype(np.int64))
        assert cand is not None
        order = cand[1].copy()
        # sifting is quadratic in the levels: beyond MAX_SIFTED it has a few seconds
        _sift(order, hp, hidx, hw, vp, by_v, 20, min(deadline, time.monotonic() + _SIFT_SECONDS) if large else None,
              stop)
        pos_i = np.empty(n, dtype=np.int64)
        pos_i[order] = np.arange(n)
        score = _score(pos_i, hp, hidx, hw)
        if best is None or score < best[0]:
            best = (score, order)
    assert best is not None
    return best[1], best[0]


#: most levels whose order is also sifted on the ranks of the semiflows' partial sums (:func:`_rank_sift`;
#: a swap computes one matrix rank, a round costs the square of the levels)
RANK_LEVELS = 128
#: seconds of that sifting at most
_RANK_SECONDS = 1.0
#: the sifted order is taken only with a span score at most this many times the span score's order
_RANK_SPAN = 4 / 3


class _PartialSums:
    """The width of each cut of an order as the semiflows see it. In a marking that satisfies
    y·M = y·M0 for every semiflow y, the markings below a cut that complete a marking above it
    depend on the markings above only through the partial sums y·M over the levels above, for the
    semiflows *open* at the cut (support on both sides); so a cut has at most r^d diagram nodes
    below it, d the rank of the open semiflows restricted to the places above (or, the same
    argument from below, to those below, whichever is smaller) and r the range of a sum. The span
    score cannot see it: on TwoPhaseLocking-PT-nC00500vN (8 places, three semiflows of 250 to 500
    tokens) the order of the lowest span score has a cut of rank 3, and 3.1 million nodes; the order
    sifted on the ranks (:func:`_rank_sift`) none above 2, and 445,508 nodes."""

    def __init__(self, flows: list[np.ndarray], owner: np.ndarray, n: int) -> None:
        cols = np.flatnonzero(owner >= 0)
        rows = [np.asarray(y)[cols] for y in flows]
        self.y = np.array(rows, dtype=np.float64) if rows else np.zeros((0, cols.size))
        self.level = owner[cols]
        self.n = n

    def rank(self, above: np.ndarray) -> int:
        """d of the cut below the levels ``above`` ((n,) bool)."""
        up = above[self.level]
        on_up = (self.y[:, up] != 0).any(axis=1)
        on_down = (self.y[:, ~up] != 0).any(axis=1)
        crossing = on_up & on_down
        if not crossing.any():
            return 0
        y = self.y[crossing]
        return int(min(np.linalg.matrix_rank(y[:, up]), np.linalg.matrix_rank(y[:, ~up])))

    def cuts(self, order: np.ndarray) -> np.ndarray:
        """(n - 1,) the rank of the cut below each position of ``order`` but the last."""
        above = np.zeros(self.n, dtype=bool)
        out = np.zeros(max(0, self.n - 1), dtype=np.int64)
        for i in range(self.n - 1):
            above[order[i]] = True
            out[i] = self.rank(above)
        return out


def _spans(order: np.ndarray, hypers: list[np.ndarray]) -> float:
    """The span score (:func:`_score`) of ``order`` over the hyperedges ``hypers`` of two levels or more."""
    pos = np.empty(order.shape[0], dtype=np.int64)
    pos[order] = np.arange(order.shape[0])
    kept = [h for h in hypers if h.size > 1]
    if not kept:
        return 0.0
    return _score(pos, np.concatenate([[0], np.cumsum([h.size for h in kept])]).astype(np.int64),
                  np.concatenate(kept).astype(np.int64))


def _rank_sift(order: np.ndarray, cuts: np.ndarray, sums: _PartialSums, deadline: float,
               rounds: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Sifting (as :func:`_sift`) of ``order`` on the sum of its cuts' ranks (:class:`_PartialSums`;
    ``cuts``: those of ``order``, :meth:`_PartialSums.cuts`): each level moved to the position where
    that sum is lowest, when it is lower than where it is; ties leave a level where the span score
    put it. A neighbour swap changes the set above one cut only, so a swap computes one rank. Ends
    at ``deadline`` (``time.monotonic()``) between levels. Returns the order sifted and its cuts."""
    order, cuts = order.copy(), cuts.copy()
    n = order.shape[0]
    above = np.zeros(n, dtype=bool)

    def cut(i: int) -> int:  # the rank below position i of the current order
        above[:] = False
        above[order[:i + 1]] = True
        return sums.rank(above)

    for _ in range(rounds):
        improved = False
        for v in order.copy().tolist():
            if time.monotonic() > deadline:
                return order, cuts
            start = int(np.flatnonzero(order == v)[0])
            best, best_at = 0, start
            for step in (-1, 1):
                kept_order, kept_cuts, change, at = order.copy(), cuts.copy(), 0, start
                while 0 <= at + step < n:
                    lo = min(at, at + step)
                    order[lo], order[lo + 1] = order[lo + 1], order[lo]
                    new = cut(lo)
                    change += new - int(cuts[lo])
                    cuts[lo] = new
                    at += step
                    if change < best:
                        best, best_at = change, at
                order, cuts = kept_order, kept_cuts
            if best < 0:
                order = np.insert(np.delete(order, start), best_at, v)
                cuts = sums.cuts(order)
                improved = True
        if not improved:
            break
    return order, cuts


def _flow_order(sn: SparseNet, owner: np.ndarray, n: int) -> np.ndarray:
    """The ``n`` levels in the order a token flows from the initial marking: breadth first over
    places, from the marked ones (by index) through each place's output transitions to their output
    places, a level taking its position when the first of its places is reached; when the search
    runs dry it starts again from the first place not reached. ``owner``: (|P|,) level of each
    place, -1 for a fixed one (passed through, on no level). No score is lowered: on
    IBMB2S565S3960-PT-none (a business process, one token at the start) this order scores 24,023
    against FORCE's 18,553, but saturation takes 4.2 s on it and is not done in 20 s on FORCE's."""
    outputs = sp.csr_matrix(sn.pre)  # row p: the transitions p feeds
    post = sn.post  # column t: the places t marks
    reached = np.zeros(sn.n_places, dtype=bool)
    placed = np.zeros(n, dtype=bool)
    order: list[int] = []
    queue: deque[int] = deque()

    def reach(p: int) -> None:
        reached[p] = True
        queue.append(p)
        k = int(owner[p])
        if k >= 0 and not placed[k]:
            placed[k] = True
            order.append(k)

    for marked in np.flatnonzero(np.asarray(sn.m0) > 0):
        reach(int(marked))
    nxt = 0
    while len(order) < n:
        if not queue:
            while reached[nxt]:
                nxt += 1
            reach(nxt)
        p = queue.popleft()
        for t in outputs.indices[outputs.indptr[p]:outputs.indptr[p + 1]]:
            for q in post.indices[post.indptr[t]:post.indptr[t + 1]]:
                if not reached[q]:
                    reach(int(q))
    return np.array(order, dtype=np.int64)


#: a shared level meets at least this many other levels through transitions (and twice the median)
SHARED_DEGREE = 8


def shared_levels(n: int, hypers: list[np.ndarray]) -> np.ndarray:
    """(n,) bool: the levels of resources that the net's components share — levels that transitions
    connect to many others (at least ``SHARED_DEGREE`` and twice the median) — when the components
    meet only through them: no transition joins two other levels (the robots of a fleet, each one
    level, connected only through the aisles, the lift and the chargers they take and give back).
    None otherwise (processes that also meet each other directly, or components of several levels).

    With such a level in the middle of the order, the events of all the components below it have
    their top there, and saturating a node of that level interleaves every one of them; below all
    the components, each component's events have their top at the component's own level and are
    saturated there, on the saturated diagram of the components beneath (Ciardo, Lüttgen,
    Siminiceanu 2001: an event is fired at its top level).
    """
    none = np.zeros(n, dtype=bool)
    near: list[set[int]] = [set() for _ in range(n)]
    for h in hypers:
        ls = h.tolist()
        if len(ls) > 1:
            for a in ls:
                near[a].update(ls)
    if n < 2:
        return none
    degree = np.array([len(s) - 1 if s else 0 for s in near], dtype=np.int64)
    shared = degree >= max(SHARED_DEGREE, 2 * float(np.median(degree)))
    if not shared.any() or shared.all():
        return none
    joined = any(int((~shared[h]).sum()) > 1 for h in hypers)
    return none if joined else shared


class PlaceGroups:
    """The groups of places of one net with its bounds and semiflows (:func:`_groups`), found once
    for all the encodings :func:`encode` is given it for: candidate orders of one net differ in
    their order alone, and its groups are the same (IBMB2S565S3960-PT-none: 0.9 s a search, each of
    its 100 semiflow supports beyond :data:`MAX_LOCAL` local markings). Thread-safe: an encoding
    that needs them while another thread finds them waits for them."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._found: list[tuple[np.ndarray, np.ndarray]] | None = None

    def of(self, sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], touched: list[np.ndarray],
           deadline: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """The groups found first (the arguments of that first call decide them; the arrays are
        shared, never written)."""
        with self._lock:
            if self._found is None:
                self._found = _groups(sn, bounds, flows, touched, deadline)
            return self._found


def encode(sn: SparseNet, bounds: np.ndarray, flows: list[np.ndarray], *, seconds: float = 5.0,
           seed: int = 0, sink: bool = False, flow: bool = False, stop: Callable[[], bool] | None = None,
           max_bytes: int | None = None, place_groups: PlaceGroups | None = None) -> Encoding:
    """Levels, local markings and order of the diagram of a bounded net (module docstring).

    Args:
        sn: the net's sparse matrices.
        bounds: (|P|,) proven upper bound of every place (≥ 0).
        flows: P-semiflows (y ≥ 0, yᵀC = 0), for groups and order; may be empty.
        seconds: time allowed to the search of groups and order.
        seed: the random starts of the order (another seed, another candidate order).
        sink: move the shared levels (:func:`shared_levels`) below all the others, each part in the
            order found; ``sunk`` says how many moved (0: the net has none, the order is unchanged).
        flow: order the levels as tokens flow from the initial marking (:func:`_flow_order`)
            instead of searching (``seed`` and ``sink`` are then not used).
        stop: asked between the starts of the order search; True ends it early (another thread
            needs no more orders).
        max_bytes: the bytes the encoding and its events may take (estimated from the levels'
            local markings and the levels each transition spans, before they are built); None: no
            limit.
        place_groups: the groups of places found for another encoding of the same net, bounds and
            semiflows (or to be kept for the next); None: found for this one alone.

    Raises:
        AnalysisError: a place has no bound.
        EncodingTooLarge: a bound above :data:`MAX_DOMAIN`, or the encoding would outgrow
            ``max_bytes`` (AirplaneLD-PT-1000 on its proven bounds: 4,017 levels of up to 3,009
            values, about 4 GiB before a single node).
    """
    start = time.monotonic()
    bounds = np.asarray(bounds, dtype=np.int64)
    if (bounds < 0).any():
        raise AnalysisError("the symbolic engine needs a proven bound for every place")
    if bounds.size and int(bounds.max()) >= MAX_DOMAIN:
        raise EncodingTooLarge(f"a place is bounded by {int(bounds.max()):,} tokens only: the symbolic engine "
                            f"takes places of at most {MAX_DOMAIN - 1:,}")
    touched = touched_places(sn)
    memo = PlaceGroups() if place_groups is None else place_groups
    groups, fixed, never, suspect = _fixed(sn, memo.of(sn, bounds, flows, touched, start + seconds / 2))
    n_k = len(groups)
    owner = np.full(sn.n_places, -1, dtype=np.int64)
    for k, (ps, _) in enumerate(groups):
        owner[ps] = k
    hypers = [np.unique(o[o >= 0]) for o in (owner[ps] for ps in touched)]
    if max_bytes is not None:
        dom = np.array([loc.shape[0] for _, loc in groups], dtype=np.int64)
        need = sum(loc.shape[0] * (_INDEX_BYTES + 8 * loc.shape[1]) for _, loc in groups) + _EVENT_BYTES * sum(
            int(dom[h].sum()) for h in hypers)
        if need > max_bytes:
            raise EncodingTooLarge(f"the encoding ({n_k:,} levels, {int(dom.sum()):,} local markings) would take about "
                                f"{need / 2**30:.1f} GiB, above the {max_bytes / 2**30:.1f} GiB it may use")
    shared = shared_levels(n_k, hypers) if sink and not flow else np.zeros(n_k, dtype=bool)
    hypers += [np.unique(o[o >= 0]) for o in (owner[np.flatnonzero(y)] for y in flows)]
    if flow:
        order = _flow_order(sn, owner, n_k)
    else:
        order, score = _order(n_k, hypers, start + seconds, seed=seed, stop=stop)
    ranked = False
    # only where a semiflow holds more than one token: where each sum has two values, ranks count for
    # little beside the spans (LamportFastMutEx-PT-5's semiflows, all of one token: its first
    # saturation and liveness take 11 s on the span score's order, 33 s on the ranks'); where one
    # does, the ranks are of all of them (Railroad-PT-020: 4.7 s; the ranks of its semiflows of
    # more than one token alone give an order not done in 90 s)
    many = any(int(np.dot(y, sn.m0)) > 1 for y in flows)
    if not flow and 2 < n_k <= RANK_LEVELS and many:
        sums = _PartialSums(flows, owner, n_k)
        cuts = sums.cuts(order)
        sifted, sifted_cuts = _rank_sift(order, cuts, sums, min(start + seconds, time.monotonic() + _RANK_SECONDS))
        # a lower sum of ranks alone is not enough: the nodes grow as r^d, so the widest cut must
        # narrow, and the spans, which saturation walks, must not grow much (Angiogenesis-PT-15: the
        # sum 107 → 89, the widest cut 5 either way, and 36 s → not done in 70 s; AutoFlight-PT-04b:
        # the widest 14 → 10 but the span score 578 → 989, and 4.5 s → 16 s)
        if int(sifted_cuts.max()) < int(cuts.max()) and _spans(sifted, hypers) <= _RANK_SPAN * score:
            order, ranked = sifted, True
    if shared.any():
        order = np.concatenate([order[~shared[order]], order[shared[order]]])
    if flow or ranked or shared.any():
        score = _spans(order, hypers)
    groups = [groups[int(i)] for i in order]
    levels = tuple(ps for ps, _ in groups)
    local = tuple(loc for _, loc in groups)
    place_level = np.full(sn.n_places, -1, dtype=np.int64)
    place_col = np.full(sn.n_places, -1, dtype=np.int64)
    for k, ps in enumerate(levels):
        place_level[ps] = k
        place_col[ps] = np.arange(ps.size)
    index = tuple({tuple(int(v) for v in row): i for i, row in enumerate(loc)} for loc in local)
    m0 = np.array([index[k][tuple(int(sn.m0[p]) for p in ps)] for k, ps in enumerate(levels)], dtype=np.int64)
    return Encoding(levels=levels, local=local, dom=np.array([loc.shape[0] for loc in local], dtype=np.int64),
                    place_level=place_level, place_col=place_col, m0=m0,
                    weight=tuple(loc.sum(axis=1) for loc in local), groups=sum(ps.size > 1 for ps in levels),
                    score=score, seconds=time.monotonic() - start, index=index, fixed=fixed,
                    fixed_values=np.asarray(sn.m0, dtype=np.int64)[fixed], never=never, suspect=suspect,
                    sunk=int(shared.sum()))


class _LocalFunctions:
    """Every transition's local function on each level it reads or changes: value → value (-1:
    disabled; a value beyond the level's local markings is ``dom``, an overflow).

    Built from the arrays of the net's CSC matrices (no sparse indexing per transition), and
    computed once per distinct local pattern (the level and the transition's pre, post, inhibitor
    and reset weights on it): the unfolded transitions of a coloured net share a few patterns per
    level (ARMCacheCoherence-PT-none: 33,676 transitions)."""

    def __init__(self, sn: SparseNet, enc: Encoding) -> None:
        self.enc = enc
        mats = [sn.pre.tocsc(), sn.post.tocsc(), sn.inhibitor.tocsc()]
        self.has_reset = sn.reset is not None and bool(sn.reset.nnz)
        if self.has_reset:
            assert sn.reset is not None
            mats.append(sn.reset.tocsc())
        for m in mats:
            m.sort_indices()
        self.mats = [(m.indptr, m.indices.astype(np.int64), m.data.astype(np.int64)) for m in mats]
        self.cache: dict[tuple[object, ...], np.ndarray] = {}
        # each transition's functions, once: the forward, single and backward events of an
        # encoding are built from the same (StigmergyElection-PT-09b: 2.4 s a set of events)
        self.by_transition: dict[int, dict[int, np.ndarray]] = {}
        # per level: its local markings as mixed-radix numbers (a digit per place, radix its largest
        # local value + 1), sorted, when they fit in 62 bits; else a dictionary of their bytes
        self.radix: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None] = []
        self.by_bytes: list[dict[bytes, int] | None] = []
        for loc in enc.local:
            top = loc.max(axis=0).astype(np.int64)
            span = 1
            mult = []
            for r in top.tolist():
                mult.append(span)
                span *= int(r) + 1
            if span < 1 << 62:
                m = np.array(mult, dtype=np.int64)
                keys = loc.astype(np.int64) @ m
                rank = np.argsort(keys, kind="stable")
                self.radix.append((m, top, keys[rank], rank.astype(np.int64)))
                self.by_bytes.append(None)
            else:
                self.radix.append(None)
                self.by_bytes.append({np.ascontiguousarray(row, dtype=np.int64).tobytes(): i
                                      for i, row in enumerate(loc)})

    def fill(self, ts: list[int]) -> None:
        """Each transition of ``ts``'s function on each level it reads or changes, into
        :attr:`by_transition` (level → function, the levels in order). A transition's pattern on a
        level is named by the (matrix, column, weight) triples of its arcs there, sorted out for all
        the transitions at once: dense weight vectors are built only for a pattern not seen before
        (StigmergyElection-PT-09b, 41,210 transitions: 6 s a set of events when dense vectors were
        built for each, 2.3 s when the triples were sorted out transition by transition)."""
        enc = self.enc
        tsa = np.asarray(ts, dtype=np.int64)
        parts: list[tuple[np.ndarray, ...]] = []
        for i, (indptr, indices, data) in enumerate(self.mats):
            first = indptr[tsa].astype(np.int64)
            counts = indptr[tsa + 1].astype(np.int64) - first
            at = concat_ranges(first, counts)
            owner = np.repeat(np.arange(tsa.size, dtype=np.int64), counts)
            lev = enc.place_level[indices[at]]
            on = lev >= 0
            parts.append((owner[on], lev[on], np.full(int(on.sum()), i, dtype=np.int64),
                          enc.place_col[indices[at[on]]], data[at[on]], at[on]))
        owner, lev, mat, col, weight, at = (np.concatenate(x) for x in zip(*parts))
        # by transition, level, matrix, and the matrix's own order (its rows, sorted)
        order = np.lexsort((at, mat, lev, owner))
        owner, lev, mat, col, weight = owner[order], lev[order], mat[order], col[order], weight[order]
        if not owner.size:
            return
        cut = np.flatnonzero((owner[1:] != owner[:-1]) | (lev[1:] != lev[:-1])) + 1
        starts = np.concatenate([[0], cut]).tolist()
        ends = np.concatenate([cut, [owner.size]]).tolist()
        whose = [ts[o] for o in owner[starts].tolist()]
        levels = lev[starts].tolist()
        mat_l, col_l, w_l = mat.tolist(), col.tolist(), weight.tolist()
        n_mats = len(self.mats)
        by_t = self.by_transition
        for t, k, a, b in zip(whose, levels, starts, ends):
            key = (k, tuple(zip(mat_l[a:b], col_l[a:b], w_l[a:b])))
            f = self.cache.get(key)
            if f is None:
                vecs = [np.zeros(enc.levels[k].size, dtype=np.int64) for _ in range(n_mats)]
                for i, c, w in key[1]:
                    vecs[i][c] = w
                f = self.cache[key] = self._compute(k, *vecs)
            by_t.setdefault(t, {})[k] = f

    def _compute(self, k: int, pre: np.ndarray, post: np.ndarray, inh: np.ndarray,
                 reset: np.ndarray | None = None) -> np.ndarray:
        loc = self.enc.local[k]
        dom = int(self.enc.dom[k])
        ok = (loc >= pre).all(axis=1) & ((inh == 0) | (loc < inh)).all(axis=1)
        nxt = loc - pre + post
        if reset is not None:
            nxt = np.where((reset > 0)[None, :], post[None, :], nxt)
        out = np.full(loc.shape[0], -1, dtype=np.int64)
        rows = np.flatnonzero(ok)
        if not rows.size:
            return out
        got = nxt[rows]
        radix = self.radix[k]
        if radix is not None:
            mult, top, keys, rank = radix
            inside = (got <= top).all(axis=1)
            key = got @ mult
            pos = np.minimum(np.searchsorted(keys, key), keys.size - 1)
            found = inside & (keys[pos] == key)
            out[rows] = np.where(found, rank[pos], dom)
        else:
            table = self.by_bytes[k]
            assert table is not None
            out[rows] = [table.get(np.ascontiguousarray(r).tobytes(), dom) for r in got]
        return out


#: most merged events a group of events equal but on one level is packed into per round (first fit)
_MERGE_BINS = 64


def _merge(funcs: list[dict[int, np.ndarray]], members: list[tuple[int, ...]]
           ) -> tuple[list[dict[int, np.ndarray]], list[tuple[int, ...]]]:
    """Merge events equal on every level but one, enabled on disjoint values there (module docstring).

    Each distinct local function is named by a number, so that an event's key on a level is a tuple
    of small integers; a round merges what it can, and the next round looks again only while some
    merge happened (a merge on one level can make two events equal on another)."""
    ids: dict[bytes, int] = {}
    tabs: list[np.ndarray] = []
    masks: list[int] = []  # the values each function is enabled on, as the bits of an integer

    def name(tab: np.ndarray) -> int:
        b = tab.tobytes()
        i = ids.get(b)
        if i is None:
            i = ids[b] = len(tabs)
            tabs.append(tab)
            masks.append(int.from_bytes(np.packbits(tab >= 0, bitorder="little").tobytes(), "little"))
        return i

    # identical events (equal functions on every level: duplicated transitions) are one event; the
    # transitions share their functions' arrays (_LocalFunctions), so an array is named by its id
    # first (``funcs`` holds every one of them alive meanwhile, so no id is taken again)
    by_id: dict[int, int] = {}

    def named(tab: np.ndarray) -> int:
        i = by_id.get(id(tab))
        if i is None:
            i = by_id[id(tab)] = name(tab)
        return i

    same: dict[tuple[tuple[int, int], ...], list[int]] = {}
    for idx, f in enumerate(funcs):
        same.setdefault(tuple((k, named(f[k])) for k in sorted(f)), []).append(idx)
    evs = list(same)
    mem = [tuple(sorted(t for i in idxs for t in members[i])) for idxs in same.values()]
    changed = True
    while changed:
        changed = False
        # keyed by the position and level left out and the rest: the rest names the other levels,
        # so events of one key have the same levels (a tuple of them per event took 0.7 s on 09b)
        groups: dict[tuple[int, int, tuple[tuple[int, int], ...]], list[int]] = {}
        for idx, ev in enumerate(evs):
            for a in range(len(ev)):
                groups.setdefault((a, ev[a][0], ev[:a] + ev[a + 1:]), []).append(idx)
        gone = np.zeros(len(evs), dtype=bool)
        new_e: list[tuple[tuple[int, int], ...]] = []
        new_m: list[tuple[int, ...]] = []
        for key, idxs in groups.items():
            if len(idxs) < 2:
                continue
            idxs = [i for i in idxs if not gone[i]]
            if len(idxs) < 2:
                continue
            a = key[0]
            # first fit: each event joins the first merged event it is disjoint from there, so a
            # large group is merged in one round, not one merged event a round
            bins: list[list[int]] = []  # each: its enabled values' bits, then its events
            for i in idxs:
                on = masks[evs[i][a][1]]
                for b in bins:
                    if not on & b[0]:
                        b[0] |= on
                        b.append(i)
                        break
                else:
                    if len(bins) < _MERGE_BINS:
                        bins.append([on, i])
            for b in bins:
                used = b[1:]
                if len(used) > 1:
                    merged = tabs[evs[used[0]][a][1]]
                    for i in used[1:]:
                        tab = tabs[evs[i][a][1]]
                        merged = np.where(tab >= 0, tab, merged)
                    ev = evs[used[0]]
                    new_e.append(ev[:a] + ((ev[a][0], name(merged)),) + ev[a + 1:])
                    new_m.append(tuple(sorted(t for i in used for t in mem[i])))
                    gone[used] = True
                    changed = True
        evs = [e for i, e in enumerate(evs) if not gone[i]] + new_e
        mem = [m for i, m in enumerate(mem) if not gone[i]] + new_m
    return [{k: tabs[f] for k, f in ev} for ev in evs], mem


def _inverse(tab: np.ndarray, dom: int) -> np.ndarray | None:
    """The inverse of a local function on a level of ``dom`` values (value → value, -1 where
    disabled, ``dom`` for an overflow), or None when it is not injective (a reset arc)."""
    src = np.flatnonzero((tab >= 0) & (tab < dom))
    dst = tab[src]
    if np.unique(dst).size < dst.size:
        return None
    inv = np.full(dom, -1, dtype=np.int64)
    inv[dst] = src
    return inv


def events(sn: SparseNet, enc: Encoding, *, merge: bool = False, inverse: bool = False,
           transitions: np.ndarray | None = None, like: Events | None = None) -> Events:
    """The events of the net's transitions (module docstring).

    Args:
        sn, enc: the net and its encoding.
        merge: merge events that differ on one level only (for saturation and deadlocks).
        inverse: the inverse functions (backward reachability).
        transitions: the transitions to include (default all that read or change some level and
            are not disabled by fixed places, :class:`Encoding`; given, those that read or change
            some level, with their functions there).
        like: events built before on ``enc``, whose transitions' local functions are taken again
            instead of computed (ignored when they were built on another encoding).

    Raises:
        AnalysisError: ``inverse`` on a net with reset arcs.
    """
    touched = touched_places(sn)
    ts = range(sn.n_transitions) if transitions is None else transitions.tolist()
    funcs: list[dict[int, np.ndarray]] = []
    members: list[tuple[int, ...]] = []
    local = like.local if like is not None and like.local is not None and like.local.enc is enc else (
        _LocalFunctions(sn, enc))
    # the inverse of each function once: transitions alike share their functions (_LocalFunctions),
    # which the cache keeps alive, so that an id names one function
    inverses: dict[tuple[int, int], np.ndarray | None] = {}
    kept: list[int] = []
    for t in ts:
        if not (enc.place_level[touched[t]] >= 0).any() or (transitions is None and (enc.never[t] or enc.suspect[t])):
            continue  # enabled everywhere and changing no level (Encoding.free), or never enabled
        kept.append(t)
    local.fill([t for t in kept if t not in local.by_transition])
    for t in kept:
        f = local.by_transition[t]
        if inverse:
            g: dict[int, np.ndarray] = {}
            for k, tab in f.items():
                inv = inverses.get((k, id(tab)), tab)
                if inv is tab:
                    inv = inverses[k, id(tab)] = _inverse(tab, int(enc.dom[k]))
                if inv is None:
                    raise AnalysisError("backward reachability is not available on a net with reset arcs")
                g[k] = inv
            f = g
        funcs.append(f)
        members.append((t,))
    if merge:
        funcs, members = _merge(funcs, members)
    top, bot, slot_ptr, slot, fn_ptr, fn = [], [], [0], [], [0], []
    # a function the events share (transitions alike share their arrays: _LocalFunctions) is stored
    # once, its slots naming the same index (StigmergyElection-PT-09b's 41,210 events of one
    # transition: 383 MiB of functions as one copy each, then copied again by the conversion);
    # ``funcs`` holds every array alive meanwhile, so no id is taken again
    index_of: dict[int, int] = {}
    for f in funcs:
        ks = sorted(f)
        lo, hi = ks[0], ks[-1]
        slots = [-1] * (hi - lo + 1)
        for k in ks:
            tab = f[k]
            i = index_of.get(id(tab))
            if i is None:
                i = index_of[id(tab)] = len(fn_ptr) - 1
                fn.append(tab)
                fn_ptr.append(fn_ptr[-1] + tab.size)
            slots[k - lo] = i
        top.append(lo)
        bot.append(hi)
        slot.extend(slots)
        slot_ptr.append(len(slot))
    top_a = np.array(top, dtype=np.int64)
    counts = np.bincount(top_a, minlength=enc.n_levels) if top_a.size else np.zeros(enc.n_levels, np.int64)
    return Events(top=top_a, bot=np.array(bot, dtype=np.int64), slot_ptr=np.array(slot_ptr, dtype=np.int64),
                  slot=np.array(slot, dtype=np.int64), fn_ptr=np.array(fn_ptr, dtype=np.int64),
                  fn=np.concatenate(fn).astype(np.int64, copy=False) if fn else np.zeros(0, np.int64),
                  by_top_ptr=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                  by_top=np.argsort(top_a, kind="stable").astype(np.int64), members=tuple(members), local=local)
