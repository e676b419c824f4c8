"""Karp–Miller coverability graph, and a cheap unboundedness witness from a breadth-first tree.

Pure: no I/O. Karp and Miller (1969), "Parallel program schemata"; Murata (1989), "Petri nets:
properties, analysis and applications", section V-A. A node is an ω-marking: a count per place, or
ω ("as many as you like") where a firing sequence can be repeated to pump that place without
bound. Nodes are expanded breadth-first; a new marking M' that strictly covers an ancestor M on its
tree path (M' ≥ M, M' ≠ M) gets ω in every place where M' > M; a marking equal to one already in the
graph is not expanded again. The net is bounded iff no node holds ω; a place is bounded iff no node
holds ω in it, and then its bound is the largest count any node gives it.

Karp–Miller is only sound for nets without inhibitor arcs (with them boundedness is undecidable);
:func:`karp_miller` refuses such nets, and nets with reset arcs too: with resets the acceleration is
unsound (a pumped place can be emptied again, so ω overstates it) and the construction need not
terminate, and boundedness of reset nets is undecidable in general (Dufourd, Finkel, Schnoebelen,
"Reset nets between decidability and undecidability", ICALP 1998). :func:`covering_witness` works
on any net: it needs the pumped difference to be zero on every place read by an inhibitor arc, which
makes the repetition legal, and growth on a place that the repeated firings do not reset, which
keeps it growing.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from coordinator.analysis.matrices import SparseNet, sparse_net
from coordinator.analysis.statespace import StateSpace
from coordinator.errors import AnalysisError
from coordinator.net import PetriNet

__all__ = ["OMEGA", "Coverability", "CoveringWitness", "Walks", "covering_witness", "karp_miller", "random_walks"]

#: Value standing for ω in :attr:`Coverability.markings`.
OMEGA = -1


@dataclass(frozen=True)
class Coverability:
    """A Karp–Miller coverability graph.

    Attributes:
        net: the net.
        markings: ω-markings, shape (K, |P|), int64, :data:`OMEGA` (-1) for ω; row 0 is M0.
        src: edge sources, shape (F,), int64.
        dst: edge targets, shape (F,), int64.
        transition: transition index per edge, shape (F,), int32.
        parent: tree parent node per node, shape (K,), int64, -1 for the root.
        parent_transition: transition index fired from the parent, shape (K,), int32, -1 for the root.
        complete: False if ``max_nodes`` or the time budget stopped the construction.
        stopped: why an incomplete construction stopped (a phrase for reports), "" when complete.
    """

    net: PetriNet
    markings: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    transition: np.ndarray
    parent: np.ndarray
    parent_transition: np.ndarray
    complete: bool
    stopped: str = ""

    @property
    def bounded(self) -> bool:
        """True if no node holds ω (meaningful when ``complete``)."""
        return not bool((self.markings == OMEGA).any())

    def unbounded_places(self) -> list[str]:
        """Ids of the places that hold ω in some node."""
        cols = np.flatnonzero((self.markings == OMEGA).any(axis=0))
        return [self.net.places[int(p)].id for p in cols]

    def place_bounds(self) -> list[int | None]:
        """Bound per place in ``net.places`` order; ``None`` for unbounded places."""
        out: list[int | None] = []
        for p in range(self.markings.shape[1]):
            col = self.markings[:, p]
            out.append(None if (col == OMEGA).any() else int(col.max(initial=0)))
        return out

    def firing_sequence(self, node: int) -> list[str]:
        """Transition ids along the tree path from M0 to ``node``."""
        seq: list[str] = []
        while node > 0:
            seq.append(self.net.transitions[int(self.parent_transition[node])].id)
            node = int(self.parent[node])
        seq.reverse()
        return seq

    def dead_nodes(self) -> np.ndarray:
        """Nodes enabling no transition, shape (k,), int64 (each stands for reachable dead markings)."""
        has_out = np.zeros(self.markings.shape[0], dtype=bool)
        has_out[self.src] = True
        return np.flatnonzero(~has_out).astype(np.int64)

    def fireable_transitions(self) -> np.ndarray:
        """Boolean (|T|,): transitions labelling some edge (quasi-live ones, when ``complete``)."""
        out = np.zeros(len(self.net.transitions), dtype=bool)
        out[self.transition] = True
        return out


def karp_miller(net: PetriNet, *, max_nodes: int = 200_000, seconds: float = 60.0,
                may_fire: np.ndarray | None = None) -> Coverability:
    """Build the Karp–Miller coverability graph of ``net``.

    Args:
        net: a net without inhibitor arcs.
        max_nodes: stop after this many nodes (``complete`` is then False).
        seconds: stop after this much wall-clock time (``complete`` is then False).
        may_fire: (|T|,) bool, the transitions of :meth:`.SparseNet.markable` when the caller has
            them (computed here otherwise); the others are never tried.

    Returns:
        The :class:`Coverability` graph.

    Raises:
        AnalysisError: if the net has inhibitor or reset arcs (Karp–Miller is unsound for them).
    """
    sn = sparse_net(net)
    if sn.inhibitor.nnz:
        raise AnalysisError("Karp–Miller coverability is unsound for nets with inhibitor arcs")
    if sn.n_resets:
        raise AnalysisError("Karp–Miller coverability is unsound for nets with reset arcs (a pumped place can be "
                            "emptied again; boundedness of reset nets is undecidable in general)")
    n_t = sn.n_transitions
    pre, inc = sn.pre, sn.incidence
    inputs = [list(zip(pre.indices[pre.indptr[t]:pre.indptr[t + 1]].tolist(),
                       pre.data[pre.indptr[t]:pre.indptr[t + 1]].tolist())) for t in range(n_t)]
    changes = [list(zip(inc.indices[inc.indptr[t]:inc.indptr[t + 1]].tolist(),
                        inc.data[inc.indptr[t]:inc.indptr[t + 1]].tolist())) for t in range(n_t)]
    inf = math.inf
    deadline = time.monotonic() + seconds
    stopped = ""
    root = tuple(float(v) for v in sn.m0)
    nodes: list[tuple[float, ...]] = [root]
    index: dict[tuple[float, ...], int] = {root: 0}
    parent = [-1]
    ptrans = [-1]
    src: list[int] = []
    dst: list[int] = []
    trs: list[int] = []
    todo = deque([0])
    complete = True
    # a transition consuming from the largest siphon unmarked at M0 is enabled at no node: those
    # places stay 0 in every node (never ω: no firing raises them), so it is never tried
    tried = np.flatnonzero(sn.markable()[1] if may_fire is None else may_fire).tolist()
    while todo:
        if len(nodes) & 255 == 0 and time.monotonic() > deadline:
            complete = False
            stopped = f"ran out of time ({seconds:g} s, {len(nodes):,} nodes)"
            break
        i = todo.popleft()
        m = nodes[i]
        for t in tried:
            if any(m[p] < w for p, w in inputs[t]):
                continue
            new = list(m)
            for p, c in changes[t]:
                if new[p] != inf:
                    new[p] += c
            # accelerate against every ancestor on the tree path (the new node's own path)
            a = i
            while a >= 0:
                anc = nodes[a]
                if all(x >= y for x, y in zip(new, anc)) and any(x > y for x, y in zip(new, anc)):
                    for p in range(len(new)):
                        if new[p] > anc[p]:
                            new[p] = inf
                a = parent[a]
            key = tuple(new)
            j = index.get(key)
            if j is None:
                if len(nodes) >= max_nodes:
                    complete = False
                    stopped = f"outgrew its limit of {max_nodes:,} nodes"
                    todo.clear()
                    break
                j = len(nodes)
                nodes.append(key)
                index[key] = j
                parent.append(i)
                ptrans.append(t)
                todo.append(j)
            src.append(i)
            dst.append(j)
            trs.append(t)
    mat = np.array(nodes, dtype=float).reshape(len(nodes), len(root))
    markings = np.where(np.isinf(mat), OMEGA, mat).astype(np.int64)
    return Coverability(
        net=net, markings=markings, src=np.array(src, dtype=np.int64), dst=np.array(dst, dtype=np.int64),
        transition=np.array(trs, dtype=np.int32), parent=np.array(parent, dtype=np.int64),
        parent_transition=np.array(ptrans, dtype=np.int32), complete=complete, stopped=stopped,
    )


@dataclass(frozen=True)
class CoveringWitness:
    """Proof that a net is unbounded: M0 →σ M →τ M' with M' ≥ M, M' ≠ M, so τ can be repeated forever.

    Attributes:
        prefix: transition ids of σ (a shortest firing sequence from M0 to M).
        loop: transition ids of τ.
        growing: ids of the places where M' > M (they grow by at least one token per repetition).
    """

    prefix: list[str]
    loop: list[str]
    growing: list[str]


def _reset_masks(space: StateSpace, sn: SparseNet, rplaces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per state, as uint64 bit sets over ``rplaces`` (at most 64 places): the reset places emptied by
    the tree edge into the state (``edge_mask``, 0 for M0), and a copy to accumulate along paths."""
    assert sn.reset is not None
    col = np.full(sn.n_places, -1, np.int64)
    col[rplaces] = np.arange(rplaces.size)
    per_t = np.zeros(sn.n_transitions, np.uint64)
    for t in range(sn.n_transitions):
        for p in sn.reset.indices[sn.reset.indptr[t]:sn.reset.indptr[t + 1]]:
            per_t[t] |= np.uint64(1) << np.uint64(col[int(p)])
    into = space.parent_edge
    edge_mask = np.where(into >= 0, per_t[space.transition[np.maximum(into, 0)]], np.uint64(0)).astype(np.uint64)
    return edge_mask, edge_mask.copy()


def covering_witness(space: StateSpace, *, max_work: int = 200_000_000, block_bytes: int = 1 << 26) -> CoveringWitness | None:
    """Look for a state that strictly covers one of its ancestors on the breadth-first tree.

    Vectorised: all states are compared with their k-th tree ancestor for k = 1, 2, ... until no
    state has one or ``max_work`` element comparisons are spent; states are taken in blocks whose
    int64 differences stay below ``block_bytes``, so a wide net never needs an (N, |P|) copy. Sound
    on every net: a pair counts only if the difference is zero on the places read by inhibitor arcs
    (their counts then follow the same course when the loop repeats) and some place grows that no
    transition of the loop empties by a reset arc (a place the loop resets ends each repetition with
    the same count, whatever it started with; the others gain the difference again each time). With
    more than 64 reset places the paths are not tracked and the difference must be zero on all of
    them.
    Not complete: None means "no witness found", not "bounded".

    Args:
        space: a (possibly truncated) state space with its ``parent_edge`` tree.
        max_work: budget of element comparisons (states × |P| per ancestor level).
        block_bytes: size limit of the temporaries.

    Returns:
        A :class:`CoveringWitness`, or ``None``.
    """
    states = space.states
    n, n_p = states.shape
    if n < 2 or space.parent_edge.shape[0] != n:
        return None
    par = np.where(space.parent_edge >= 0, space.src[np.maximum(space.parent_edge, 0)], -1).astype(np.int64)
    sn = sparse_net(space.net)
    inhibited = np.flatnonzero(sn.inhibitor.getnnz(axis=1) > 0).astype(np.int64)
    rplaces = sn.reset_places()
    edge_mask = seen = np.zeros(0, np.uint64)
    if rplaces.size > 64:  # too many to track per path: ask for no change on any of them
        inhibited = np.union1d(inhibited, rplaces).astype(np.int64)
        rplaces = rplaces[:0]
    elif rplaces.size:
        edge_mask, seen = _reset_masks(space, sn, rplaces)
    bits = np.arange(rplaces.size, dtype=np.uint64)
    anc = par.copy()
    alive = np.flatnonzero(anc >= 0)
    work = 0
    step = max(1, block_bytes // max(8 * n_p, 1))
    while alive.size and work < max_work:
        for lo in range(0, alive.size, step):
            part = alive[lo:lo + step]
            a = anc[part]
            diff = states[part].astype(np.int64) - states[a].astype(np.int64)
            grows = diff > 0
            if rplaces.size:  # a place the loop resets does not grow when the loop repeats
                grows[:, rplaces] &= ((seen[part][:, None] >> bits[None, :]) & np.uint64(1)) == 0
            ok = (diff >= 0).all(axis=1) & grows.any(axis=1)
            if inhibited.size:
                ok &= (diff[:, inhibited] == 0).all(axis=1)
            hit = np.flatnonzero(ok)
            if hit.size:
                i, j = int(part[hit[0]]), int(a[hit[0]])
                full_i = space.firing_sequence(i)
                full_j = space.firing_sequence(j)
                grow = [space.net.places[int(p)].id for p in np.flatnonzero(grows[hit[0]])]
                return CoveringWitness(prefix=full_j, loop=full_i[len(full_j):], growing=grow)
        work += alive.size * n_p
        if rplaces.size:
            seen[alive] |= edge_mask[anc[alive]]
        anc[alive] = par[anc[alive]]
        alive = alive[anc[alive] >= 0]
    return None


@dataclass(frozen=True)
class Walks:
    """What random firing sequences from M0 found (:func:`random_walks`); all of it holds for the net.

    Attributes:
        witness: a pumping witness found on one walk (a marking that strictly covers an earlier one of
            the same walk, under :func:`covering_witness`'s conditions), or None.
        dead: up to ``max_dead`` distinct dead markings the walks ended in, each as (its counts,
            (|P|,) int64; the transition ids of its firing sequence from M0).
        fired: (|T|,) bool, the transitions fired on some walk.
        walks: how many walks started.
        steps: how many firings they made in all.
    """

    witness: CoveringWitness | None
    dead: list[tuple[np.ndarray, list[str]]]
    fired: np.ndarray
    walks: int
    steps: int


class _Walker:
    """The enabling counts of one marking, updated firing by firing (:func:`random_walks`), over the
    transitions that may fire (:meth:`.SparseNet.markable`: the others are never enabled).

    ``missing[k]`` is the number of the k-th such transition's input arcs whose place holds fewer
    tokens than the arc's weight plus the number of its inhibitor arcs whose place holds at least the
    threshold: it is enabled iff ``missing[k]`` is 0. A firing changes the counts of a few places,
    and only the arcs from those places are looked at again.

    Attributes:
        ids: (k,) int64, the net's index of each transition walked.
        m: (|P|,) int64, the current marking.
    """

    def __init__(self, sn: SparseNet) -> None:
        self.m0 = sn.m0
        self.ids = np.flatnonzero(sn.markable()[1]).astype(np.int64)
        self.pre = sp.csc_matrix(sn.pre[:, self.ids])
        self.inh = sp.csc_matrix(sn.inhibitor[:, self.ids])
        self.inc = sp.csc_matrix(sn.incidence[:, self.ids])
        self.pre_rows = self.pre.tocsr()
        self.inh_rows = self.inh.tocsr()
        self.resets: sp.csc_matrix | None = None
        self.post: sp.csc_matrix | None = None
        if sn.reset is not None and sn.reset.nnz:
            self.resets = sp.csc_matrix(sn.reset[:, self.ids])
            self.post = sp.csc_matrix(sn.post[:, self.ids])
        self.m = sn.m0.astype(np.int64).copy()
        self.missing = np.zeros(self.ids.size, dtype=np.int64)
        self._cache: dict[int, tuple[np.ndarray, ...]] = {}
        self.restart()

    def restart(self, marking: np.ndarray | None = None) -> None:
        """Back to M0, or to ``marking`` ((|P|,) int64, one the walk reached)."""
        self.m[:] = self.m0 if marking is None else marking
        n = self.ids.size
        self.missing[:] = 0
        for mat, disabled in ((self.pre, self.m[self.pre.indices] < self.pre.data),
                              (self.inh, self.m[self.inh.indices] >= self.inh.data)):
            cols = np.repeat(np.arange(n), np.diff(mat.indptr))
            self.missing += np.bincount(cols[disabled], minlength=n)

    def _arcs(self, k: int) -> tuple[np.ndarray, ...]:
        """What firing the k-th transition walked touches, gathered on its first firing: the places
        its incidence changes and by how much, the places its reset arcs set and their values, and
        the input and inhibitor arcs from all of them (place, weight, transition walked)."""
        found = self._cache.get(k)
        if found is not None:
            return found
        lo, hi = self.inc.indptr[k], self.inc.indptr[k + 1]
        moved, delta = self.inc.indices[lo:hi], self.inc.data[lo:hi]
        reset = np.zeros(0, dtype=np.int64)
        value = np.zeros(0, dtype=np.int64)
        if self.resets is not None and self.post is not None:
            reset = self.resets.indices[self.resets.indptr[k]:self.resets.indptr[k + 1]].astype(np.int64)
            value = self.post[:, k].toarray().ravel()[reset].astype(np.int64)
        places = np.union1d(moved, reset)
        arcs: list[np.ndarray] = []
        for rows in (self.pre_rows, self.inh_rows):
            lo_r, hi_r = rows.indptr[places], rows.indptr[places + 1]
            idx = np.concatenate([np.arange(a, b) for a, b in zip(lo_r.tolist(), hi_r.tolist())] or [np.zeros(0, np.int64)])
            idx = idx.astype(np.int64)
            owner = np.repeat(places, hi_r - lo_r)
            arcs.extend((owner, rows.data[idx], rows.indices[idx]))
        found = (moved, delta, reset, value, *arcs)
        self._cache[k] = found
        return found

    def reset_places(self, k: int) -> np.ndarray:
        """The places the reset arcs of the k-th transition walked set, (r,) int64."""
        return self._arcs(k)[2]

    def fire(self, k: int) -> np.ndarray:
        """Fire the k-th transition walked (enabled); return the places its reset arcs set, (r,) int64."""
        moved, delta, reset, value, pre_p, pre_w, pre_t, inh_p, inh_w, inh_t = self._arcs(k)
        m = self.m
        before_pre = m[pre_p] < pre_w
        before_inh = m[inh_p] >= inh_w
        m[moved] += delta
        if reset.size:
            m[reset] = value  # a reset place ends with what the transition puts in it
        if pre_t.size:
            np.add.at(self.missing, pre_t, (m[pre_p] < pre_w).astype(np.int64) - before_pre)
        if inh_t.size:
            np.add.at(self.missing, inh_t, (m[inh_p] >= inh_w).astype(np.int64) - before_inh)
        return reset


def _covered(m: np.ndarray, hist: np.ndarray, sums: np.ndarray, parts: np.ndarray, part: np.ndarray, i: int,
             inhibited: np.ndarray, reset_since: np.ndarray | None) -> tuple[int, np.ndarray] | None:
    """The first of the walk's markings ``hist[:i]`` that ``m`` covers as a pumping witness requires
    (:func:`covering_witness`), and the (|P|,) bool places that grow; or None. A marking ``m`` covers
    strictly has fewer tokens (``sums``) and no more in any set of places (``parts``: (rows, k) token
    counts of k fixed sets, ``part`` those of ``m``); only the markings that pass both are compared
    place by place."""
    below = np.flatnonzero((sums[:i] < int(m.sum())) & (parts[:i] <= part).all(axis=1))
    if not below.size:
        return None
    diff = m[None, :] - hist[below]
    ok = (diff >= 0).all(axis=1)
    if inhibited.size:
        ok &= (diff[:, inhibited] == 0).all(axis=1)
    grows = diff > 0
    if reset_since is not None:
        grows &= ~reset_since[below]
    hit = np.flatnonzero(ok & grows.any(axis=1))
    if not hit.size:
        return None
    return int(below[hit[0]]), grows[hit[0]]


#: random sets of places whose token counts sift the walk's markings a new one may cover
_SETS = 16
#: memory of the markings a walk keeps to compare with each new one, bytes
_WALK_BYTES = 64 << 20
#: the first walk's length at most; each next one twice the last, up to ``length``, then again
_FIRST_LENGTH = 50
#: how many times a walk that looks for a witness and meets a dead marking goes back one firing and
#: on from there, before a new walk starts from M0
_BACKTRACKS = 4


def random_walks(net: PetriNet, *, seconds: float = 2.0, max_steps: int = 200_000, length: int = 2_000,
                 seed: int = 0, max_dead: int = 10, witness: bool = True) -> Walks:
    """Fire random sequences from M0 (each step a transition drawn uniformly among the enabled ones),
    looking for a pumping witness and for dead markings.

    A breadth-first search meets a pumping loop only after it has expanded every marking closer to M0,
    and on a net whose loop is forty firings deep that is more markings than any budget holds
    (Medical-PT-08 in the Model Checking Contest's models: no witness among the first million markings).
    One walk reaches such depths at once. Each walk compares every marking it reaches with the earlier
    ones of the same walk, under :func:`covering_witness`'s conditions: covering, equal on the places
    read by inhibitor arcs, and larger on a place that no transition of the loop resets. The first walk
    makes at most 50 firings, each next one twice as many as the last, up to ``length``, and then the
    same lengths again (short walks try many starts, long ones reach deep). A walk stops at the first
    witness (returned) or after its length; at a dead marking (kept) it goes back to the marking
    before and on from there, up to :data:`_BACKTRACKS` times (where most walks end in a dead marking
    soon, the loops lie past them), then stops, and the next starts from M0 again. With ``witness``
    False the walks look for dead markings alone (no comparison, no stop at a covering marking, a new
    walk at each dead marking): they go on past the loops, to the dead ends beyond them. All that is
    found is reachable, so it holds for the net; what is not found says nothing.

    Args:
        net: a plain net (its ordinary view: events and priorities play no part).
        seconds: time budget, seconds.
        max_steps: budget of firings over all walks (each walk counts one more).
        length: firings of the longest walk (when looking for a witness, also at most as many as
            :data:`_WALK_BYTES` hold of the walk's markings).
        seed: seed of the random draws (the same seed, the same walks).
        max_dead: how many distinct dead markings are kept.
        witness: look for a pumping witness (and stop at the first).

    Returns:
        A :class:`Walks`.
    """
    sn = sparse_net(net)
    rng = np.random.default_rng(seed)
    inhibited = np.flatnonzero(sn.inhibitor.getnnz(axis=1) > 0).astype(np.int64)
    walker = _Walker(sn)
    ids = [net.transitions[int(t)].id for t in walker.ids]
    rows = 1
    if witness:  # the walk's markings, compared with each new one: at most _WALK_BYTES of them
        length = max(1, min(length, _WALK_BYTES // (9 * max(sn.n_places, 1)) - 1))
        rows = length + 1
    hist = np.empty((rows, sn.n_places), dtype=np.int64)
    sums = np.empty(rows, dtype=np.int64)
    sets = np.random.default_rng(seed + 1).integers(0, 2, size=(sn.n_places, _SETS)).astype(np.int64)
    parts = np.zeros((rows, _SETS), dtype=np.int64)
    reset_since = np.zeros((rows, sn.n_places), dtype=bool) if walker.resets is not None and witness else None
    fired = np.zeros(sn.n_transitions, dtype=bool)
    dead: list[tuple[np.ndarray, list[str]]] = []
    seen_dead: set[bytes] = set()
    start = time.monotonic()
    walks = steps = 0
    m = walker.m
    lengths = 1 + max(0, math.ceil(math.log2(length / _FIRST_LENGTH)))  # 50, 100, ..., length in turn
    while steps + walks < max_steps and time.monotonic() - start < seconds:  # a walk costs one step at least
        walks += 1
        if walks > 1:
            walker.restart()
        if witness:
            hist[0] = m
            sums[0] = int(m.sum())
            parts[0] = m @ sets
        if reset_since is not None:
            reset_since[0] = False
        seq: list[int] = []
        backs = _BACKTRACKS if witness else 0
        cap = min(length, _FIRST_LENGTH << ((walks - 1) % lengths))
        while len(seq) < cap:
            i = len(seq) + 1  # the index of the marking the next firing reaches
            enabled = np.flatnonzero(walker.missing == 0)
            if not enabled.size:
                key = m.tobytes()
                if key not in seen_dead and len(dead) < max_dead:
                    seen_dead.add(key)
                    dead.append((m.copy(), [ids[t] for t in seq]))
                if not seq or (not witness and len(dead) >= max_dead):  # M0 dead: every walk would end there
                    return Walks(witness=None, dead=dead, fired=fired, walks=walks, steps=steps)
                if not backs:
                    break
                backs -= 1  # back to the marking before, and on from there
                seq.pop()
                walker.restart(hist[len(seq)])
                if reset_since is not None:
                    _resets_since(reset_since, seq, walker)
                continue
            t = int(enabled[rng.integers(enabled.size)]) if enabled.size > 1 else int(enabled[0])
            reset = walker.fire(t)
            seq.append(t)
            fired[walker.ids[t]] = True
            steps += 1
            if reset_since is not None:
                reset_since[i] = False
                if reset.size:
                    reset_since[:i, reset] = True  # the loop from each earlier marking holds t
            if witness:
                part = m @ sets
                pair = _covered(m, hist, sums, parts, part, i, inhibited, reset_since)
                if pair is not None:
                    j, grows = pair
                    found = CoveringWitness(prefix=[ids[u] for u in seq[:j]], loop=[ids[u] for u in seq[j:]],
                                            growing=[net.places[int(p)].id for p in np.flatnonzero(grows)])
                    return Walks(witness=found, dead=dead, fired=fired, walks=walks, steps=steps)
                hist[i] = m
                sums[i] = int(m.sum())
                parts[i] = part
            if steps >= max_steps or (steps & 255 == 0 and time.monotonic() - start >= seconds):
                break
    return Walks(witness=None, dead=dead, fired=fired, walks=walks, steps=steps)


def _resets_since(reset_since: np.ndarray, seq: list[int], walker: _Walker) -> None:
    """Row j of ``reset_since`` for j ≤ len(seq): the places the reset arcs of ``seq[j:]`` empty
    (after a walk went back to the marking ``seq`` reaches)."""
    acc = np.zeros(reset_since.shape[1], dtype=bool)
    reset_since[len(seq)] = False
    for j in range(len(seq) - 1, -1, -1):
        acc[walker.reset_places(seq[j])] = True
        reset_since[j] = acc
