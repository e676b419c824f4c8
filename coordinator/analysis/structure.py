"""Qualitative analysis of the ordinary net of a task (paper section 2, "Qualitative Performance
Evaluation"): boundedness, safeness, deadlocks, liveness levels, reversibility, home states,
stable places, invariants, structural conflicts.

Pure: no I/O. The ordinary view (:func:`ordinary_view`) drops the events of the interpreted net —
a transition fires as soon as it is enabled — and keeps the interpretation as labels.

Boundedness is always decided when it can be: the reachability graph (:func:`explore`) is finite
and complete ⇒ bounded; a place covered by a positive P-invariant is bounded by it (structural
bound, Murata 1989 section VI); a marking strictly covering a breadth-first ancestor proves
unboundedness; otherwise the Karp–Miller coverability graph decides (for nets without inhibitor
arcs). Properties that need the whole graph (liveness, reversibility) are ``None`` when only a
coverability graph or a truncated graph is available.

Liveness levels (Murata 1989, section IV-C) on a finite reachability graph, through its strongly
connected components (Tarjan 1972, via scipy.sparse.csgraph): L0 dead — t labels no edge; L1 — t
labels some edge; L3 (= L2 on finite graphs) — t labels an edge inside a strongly connected
component, so it can fire infinitely often; L4 live — t labels an edge in every terminal component
(a component no edge leaves), so from every reachable marking t can still fire. The net is
reversible iff the graph is strongly connected; the home states are the states of the terminal
component when there is exactly one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from coordinator.analysis.coverability import (
    Coverability,
    CoveringWitness,
    covering_witness,
    karp_miller,
)
from coordinator.analysis.invariants import (
    Invariants,
    p_invariants,
    structural_bounds,
    t_invariants,
)
from coordinator.analysis.statespace import StateSpace, enabled_mask, explore
from coordinator.net import Marking, PetriNet

__all__ = [
    "PROBE_STATES",
    "Analysis",
    "Conflict",
    "Deadlock",
    "analyse",
    "graph_liveness",
    "liveness_levels",
    "ordinary_view",
    "record_only_places",
    "without_places",
]

#: States explored first when the net is not structurally bounded, to look for cheap unboundedness.
PROBE_STATES = 2_000
#: How many deadlock witnesses are kept.
MAX_WITNESSES = 10


def ordinary_view(net: PetriNet) -> PetriNet:
    """Return the ordinary Petri net of an interpreted net: events dropped, kept in the labels.

    Each transition loses its events (it fires as soon as it is enabled); its label becomes
    ``"<label or id> [<event>, ...]"`` so reports still say what the transition waited for.
    Places, arcs, priorities, weights and markings are unchanged.
    """
    trans = []
    for t in net.transitions:
        if t.events:
            label = f"{t.label or t.id} [{', '.join(t.events)}]"
            trans.append(replace(t, events=(), label=label))
        else:
            trans.append(t)
    return PetriNet(name=net.name, places=net.places, transitions=tuple(trans), arcs=net.arcs,
                    initial_marking=net.initial_marking, tasks=net.tasks, description=net.description,
                    home_marking=net.home_marking)


def record_only_places(net: PetriNet) -> list[str]:
    """Places no transition consumes from or is inhibited by: they only record what happened."""
    touched = (np.asarray(net.pre) > 0) | (np.asarray(net.inhibitor) > 0)
    return [p.id for i, p in enumerate(net.places) if not touched[i].any()]


def without_places(net: PetriNet, drop: list[str]) -> PetriNet:
    """Return the net with some places (and their arcs and tokens) removed."""
    gone = set(drop)

    def keep(m: Marking) -> Marking:
        return Marking({p: c for p, c in m.items() if p not in gone})

    home = None if net.home_marking is None else keep(net.home_marking)
    return PetriNet(name=net.name, places=tuple(p for p in net.places if p.id not in gone),
                    transitions=net.transitions,
                    arcs=tuple(a for a in net.arcs if a.source not in gone and a.target not in gone),
                    initial_marking=keep(net.initial_marking), tasks=net.tasks,
                    description=net.description, home_marking=home)


@dataclass(frozen=True)
class Deadlock:
    """A reachable marking that enables no transition.

    Attributes:
        marking: place id → tokens (ω written as -1 when found on a coverability graph).
        firing_sequence: a shortest firing sequence (transition ids) from M0 reaching it.
    """

    marking: dict[str, int]
    firing_sequence: list[str]


@dataclass(frozen=True)
class Conflict:
    """A structural conflict: transitions sharing an input place.

    Attributes:
        place: the shared input place.
        transitions: the transitions that compete for its tokens (≥ 2).
        effective: True if, in some reachable marking, two of them are enabled and firing one
            disables the other; ``None`` if the graph is not available.
    """

    place: str
    transitions: list[str]
    effective: bool | None


@dataclass(frozen=True)
class Analysis:
    """Result of :func:`analyse`. ``None`` means "not decided" (see the module docstring).

    Attributes:
        net: the ordinary net analysed.
        space: the reachability graph (possibly truncated), or ``None``.
        coverability: the Karp–Miller graph when one was built, else ``None``.
        states: reachable markings found (all of them when ``complete``).
        edges: edges found.
        complete: the reachability graph is complete.
        bounded: every place has a bound.
        place_bounds: place id → bound (``None``: unbounded or unknown).
        unbounded_places: places proven to grow without bound.
        covering: a pumping witness for unboundedness, if one was found on the graph.
        max_token_in_place: largest count of a place in a reachable marking.
        max_token_per_marking: largest total count of a reachable marking.
        one_safe: no place ever holds more than one token.
        deadlock: some reachable marking enables no transition.
        deadlocks: up to 10 deadlocks with shortest firing sequences.
        n_deadlocks: number of dead markings found.
        liveness: transition id → level 0, 1, 3 or 4 (L2 = L3 on finite graphs), or ``None``.
        quasi_live: every transition can fire (L1).
        live: every transition is L4.
        reversible: M0 is reachable from every reachable marking.
        home_states: number of home states (0 if none), or ``None``.
        home_marking_is_home: the declared home marking is a home state (``None`` if none declared).
        stable_places: places whose count never changes.
        p_invariants: minimal semi-positive P-invariants.
        t_invariants: minimal semi-positive T-invariants.
        conservative: some positive P-invariant covers every place.
        consistent: some positive T-invariant covers every transition.
        conflicts: structural conflicts.
        notes: plain sentences on what could not be decided and why.
        projection: when the graph is infinite or too large and the net has record-only places (no
            transition reads them) that account for any growth, the analysis of the net without
            them (complete): same enabling, so its liveness, deadlocks and graph stand for the
            task's behaviour.
    """

    net: PetriNet
    space: StateSpace | None
    coverability: Coverability | None
    states: int
    edges: int
    complete: bool
    bounded: bool | None
    place_bounds: dict[str, int | None]
    unbounded_places: list[str]
    covering: CoveringWitness | None
    max_token_in_place: int | None
    max_token_per_marking: int | None
    one_safe: bool | None
    deadlock: bool | None
    deadlocks: list[Deadlock]
    n_deadlocks: int | None
    liveness: dict[str, int] | None
    quasi_live: bool | None
    live: bool | None
    reversible: bool | None
    home_states: int | None
    home_marking_is_home: bool | None
    stable_places: list[str] | None
    p_invariants: Invariants
    t_invariants: Invariants
    conservative: bool
    consistent: bool
    conflicts: list[Conflict]
    notes: list[str] = field(default_factory=list)
    projection: Analysis | None = None

    @property
    def stable_marking(self) -> bool | None:
        """Some place keeps the same count in every reachable marking (MCC StableMarking)."""
        return None if self.stable_places is None else bool(self.stable_places)

    @property
    def dead_transitions(self) -> list[str] | None:
        """Transitions that can never fire (L0)."""
        if self.liveness is None:
            return None
        return [t for t, lvl in self.liveness.items() if lvl == 0]


def liveness_levels(space: StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liveness level of each transition on a complete reachability graph.

    Returns:
        ``(levels, labels, terminal)``: levels (|T|,) int64 in {0, 1, 3, 4}; the strongly connected
        component of each state (N,) int64; a boolean (n_components,) marking terminal components.
    """
    # edges are sorted by source, so the CSR matrix is built without sorting
    return graph_liveness(space.n_states, len(space.net.transitions), space.src, space.dst, space.transition,
                          out_ptr=space.out_ptr)


def graph_liveness(n: int, n_t: int, src: np.ndarray, dst: np.ndarray, transition: np.ndarray,
                   out_ptr: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`liveness_levels` on raw edge arrays (shapes (E,)); ``out_ptr`` if ``src`` is sorted."""
    if out_ptr is not None:
        graph = sp.csr_matrix((np.ones(src.shape[0], dtype=np.int8), dst.astype(np.int32), out_ptr),
                              shape=(n, n))
    else:
        graph = sp.csr_matrix((np.ones(src.shape[0], dtype=np.int8), (src, dst)), shape=(n, n))
    n_comp, labels32 = csgraph.connected_components(graph, directed=True, connection="strong")
    del graph
    labels = labels32.astype(np.int64)
    cs = labels[src]
    same = cs == labels[dst]
    terminal = np.ones(n_comp, dtype=bool)
    terminal[cs[~same]] = False
    levels = np.zeros(n_t, dtype=np.int64)
    fired = np.zeros(n_t, dtype=bool)
    fired[transition] = True
    levels[fired] = 1
    cyc = np.zeros(n_t, dtype=bool)
    cyc[transition[same]] = True
    levels[cyc] = 3
    n_term = int(terminal.sum())
    inside = terminal[cs]
    if n_term * n_t <= 50_000_000:
        term_index = np.cumsum(terminal) - 1
        hit = np.zeros((n_term, n_t), dtype=bool)
        hit[term_index[cs[inside]], transition[inside]] = True
        live = hit.all(axis=0)
    else:
        pairs = np.unique(cs[inside] * n_t + transition[inside].astype(np.int64))
        live = np.bincount(pairs % n_t, minlength=n_t) == n_term
    levels[live & cyc] = 4
    return levels, labels, terminal


def _conflicts(net: PetriNet, space: StateSpace | None, block: int = 1 << 16) -> list[Conflict]:
    """Structural conflicts; effective when, in a reachable marking enabling two of the transitions,
    firing one disables the other."""
    pre = np.asarray(net.pre)
    inc = np.asarray(net.incidence, dtype=np.int64)
    shared = [(p, np.flatnonzero(pre[p])) for p in range(pre.shape[0]) if np.count_nonzero(pre[p]) >= 2]
    effective: dict[int, bool | None] = {p: None for p, _ in shared}
    if space is not None and space.complete and shared:
        effective = {p: False for p, _ in shared}
        pairs = {p: [(int(a), int(b)) for i, a in enumerate(ts) for b in ts[i + 1:]] for p, ts in shared}
        for lo in range(0, space.n_states, block):
            rows = space.states[lo:lo + block]
            mask = enabled_mask(net, rows)
            for p, _ in shared:
                if effective[p]:
                    continue
                for a, b in pairs[p]:
                    both = np.flatnonzero(mask[:, a] & mask[:, b])
                    if not both.size:
                        continue
                    base = rows[both].astype(np.int64)
                    after_a = enabled_mask(net, base + inc[:, a])[:, b]
                    after_b = enabled_mask(net, base + inc[:, b])[:, a]
                    if not (after_a.all() and after_b.all()):
                        effective[p] = True
                        break
    return [Conflict(place=net.places[p].id, transitions=[net.transitions[int(t)].id for t in ts],
                     effective=effective[p]) for p, ts in shared]


def analyse(net: PetriNet, *, max_states: int = 10_000_000, max_coverability_nodes: int = 200_000,
            max_invariant_rows: int = 20_000,
            progress: Callable[[int, int], None] | None = None) -> Analysis:
    """Analyse the ordinary view of ``net`` (see the module docstring for the decision procedure).

    Args:
        net: the (interpreted or plain) net.
        max_states: limit of the reachability graph.
        max_coverability_nodes: limit of the Karp–Miller graph.
        max_invariant_rows: size guard of the Farkas algorithm.
        progress: passed to :func:`~coordinator.analysis.statespace.explore`.

    Returns:
        An :class:`Analysis`.
    """
    net = ordinary_view(net)
    notes: list[str] = []
    pinv = p_invariants(net, max_rows=max_invariant_rows)
    tinv = t_invariants(net, max_rows=max_invariant_rows)
    if not pinv.complete:
        notes.append("P-invariants: the Farkas table outgrew its size guard; none are listed")
    if not tinv.complete:
        notes.append("T-invariants: the Farkas table outgrew its size guard; none are listed")
    sbounds = structural_bounds(net, pinv)
    structurally_bounded = bool(pinv.complete and (sbounds >= 0).all())
    has_inhibitors = bool(np.any(net.inhibitor))

    space: StateSpace | None = None
    witness: CoveringWitness | None = None
    if not structurally_bounded and max_states > PROBE_STATES:
        probe = explore(net, max_states=PROBE_STATES, progress=progress)
        if probe.complete:
            space = probe
        else:
            witness = covering_witness(probe)
            if witness is not None:
                space = probe
    if space is None:
        space = explore(net, max_states=max_states, progress=progress)
        if not space.complete and not structurally_bounded and witness is None:
            witness = covering_witness(space)

    cover: Coverability | None = None
    if space.complete:
        return _from_graph(net, space, pinv, tinv, notes)
    # the graph is truncated: decide boundedness by other means
    ids = [p.id for p in net.places]
    place_bounds: dict[str, int | None] = {pid: None for pid in ids}
    unbounded: list[str] = []
    bounded: bool | None = None
    deadlock: bool | None = None
    deadlocks: list[Deadlock] = []
    quasi: bool | None = None
    levels: dict[str, int] | None = None
    live: bool | None = None
    if structurally_bounded:
        bounded = True
        place_bounds = {pid: int(b) for pid, b in zip(ids, sbounds)}
        notes.append(f"the net is bounded (covered by P-invariants; the bounds listed are the invariants' "
                     f"bounds) but has more than {max_states:,} reachable markings")
    elif not has_inhibitors:
        cover = karp_miller(net, max_nodes=max_coverability_nodes)
        if cover.complete:
            bounded = cover.bounded
            place_bounds = dict(zip(ids, cover.place_bounds()))
            unbounded = cover.unbounded_places()
            fire = cover.fireable_transitions()
            quasi = bool(fire.all())
            if not quasi:
                levels = None
                live = False
            for node in cover.dead_nodes()[:MAX_WITNESSES]:
                deadlocks.append(Deadlock(marking=_omega_marking(net, cover.markings[node]),
                                          firing_sequence=cover.firing_sequence(int(node))))
            deadlock = True if deadlocks else None
            notes.append("the reachability graph is infinite or too large; boundedness, place bounds, "
                         "quasi-liveness and dead transitions come from the Karp–Miller coverability graph; "
                         "liveness and reversibility are not decided on it")
            if not quasi:
                notes.append("dead transitions: " + ", ".join(
                    t.id for t, f in zip(net.transitions, fire) if not f))
        elif witness is not None:
            bounded = False
            notes.append("the coverability graph outgrew its limit; unboundedness comes from a pumping witness")
        else:
            notes.append("neither the reachability graph nor the coverability graph fit their limits; "
                         "boundedness is not decided")
    else:
        if witness is not None:
            bounded = False
        else:
            notes.append("the net has inhibitor arcs and its reachability graph exceeds the limit: "
                         "boundedness is undecidable in general and was not decided")
    if witness is not None:
        bounded = False
        for pid in witness.growing:
            if pid not in unbounded:
                unbounded.append(pid)
    for pid in unbounded:
        place_bounds[pid] = None
    # what the explored part proves on its own: its dead markings are reachable deadlocks, and a
    # transition that fired there is not dead
    dead_seen = space.deadlocks()
    if dead_seen.size:
        deadlock = True
        if not deadlocks:
            deadlocks = [Deadlock(marking=space.marking(int(i)).to_dict(), firing_sequence=space.firing_sequence(int(i)))
                         for i in dead_seen[:MAX_WITNESSES]]
    if quasi is None and space.n_edges and np.unique(space.transition).size == len(net.transitions):
        quasi = True
    projection: Analysis | None = None
    reversible: bool | None = None
    record = record_only_places(net)
    growth_is_recorded = bounded is not False or (bool(unbounded) and set(unbounded) <= set(record))
    if record and len(record) < len(net.places) and growth_is_recorded:
        projection = analyse(without_places(net, record), max_states=max_states,
                             max_coverability_nodes=max_coverability_nodes, max_invariant_rows=max_invariant_rows,
                             progress=progress)
        if projection.complete:
            # record-only places never change what is enabled: liveness and deadlocks carry over
            levels, quasi, live = projection.liveness, projection.quasi_live, projection.live
            deadlock = projection.deadlock
            deadlocks = list(projection.deadlocks)
            # the projection of a path is a path; the record places come back only if never written
            post = np.asarray(net.post)
            writers = [t.id for j, t in enumerate(net.transitions)
                       if any(post[net.place_index[p], j] for p in record)]
            written = any((projection.liveness or {}).get(t, 0) > 0 for t in writers)
            reversible = bool(projection.reversible) and not written
            notes.append(f"liveness, deadlocks and reversibility come from the net without its record-only "
                         f"places ({', '.join(record)}), which has the same enabled transitions in every marking "
                         "and a finite reachability graph")
        else:
            projection = None
    if set(unbounded) & set(record):
        reversible = False  # a record-only place never loses tokens: once it has grown, M0 is out of reach
    if projection is None and levels is None:
        notes.append("liveness and reversibility need the whole reachability graph and were not decided")
    max_in_place: int | None = None
    one_safe: bool | None = None
    if bounded is False:
        one_safe = False
    elif cover is not None and cover.complete:
        max_in_place = max([0, *(b for b in place_bounds.values() if b is not None)])
        one_safe = max_in_place <= 1
    elif structurally_bounded and int(sbounds.max(initial=0)) <= 1:
        one_safe = True
    return Analysis(
        net=net, space=space, coverability=cover, states=space.n_states, edges=space.n_edges, complete=False,
        bounded=bounded, place_bounds=place_bounds, unbounded_places=unbounded, covering=witness,
        max_token_in_place=max_in_place, max_token_per_marking=None, one_safe=one_safe,
        deadlock=deadlock, deadlocks=deadlocks, n_deadlocks=None, liveness=levels, quasi_live=quasi, live=live,
        reversible=reversible, home_states=None, home_marking_is_home=None, stable_places=None,
        p_invariants=pinv, t_invariants=tinv, conservative=pinv.covered, consistent=tinv.covered,
        conflicts=_conflicts(net, None), notes=notes, projection=projection,
    )


def _omega_marking(net: PetriNet, row: np.ndarray) -> dict[str, int]:
    return {net.places[p].id: int(row[p]) for p in np.flatnonzero(row)}


def _from_graph(net: PetriNet, space: StateSpace, pinv: Invariants, tinv: Invariants,
                notes: list[str]) -> Analysis:
    states = space.states
    per_place = states.max(axis=0).astype(np.int64) if space.n_states else np.zeros(len(net.places), np.int64)
    totals = states.sum(axis=1, dtype=np.int64)
    dead = space.deadlocks()
    deadlocks = [Deadlock(marking=space.marking(int(i)).to_dict(), firing_sequence=space.firing_sequence(int(i)))
                 for i in dead[:MAX_WITNESSES]]
    levels, labels, terminal = liveness_levels(space)
    n_terminal = int(terminal.sum())
    home_count = int(np.count_nonzero(terminal[labels])) if n_terminal == 1 else 0
    home_is_home: bool | None = None
    if net.home_marking is not None:
        try:
            h = space.index_of(net.home_marking)
            home_is_home = bool(n_terminal == 1 and terminal[labels[h]])
        except KeyError:
            home_is_home = False
    stable = np.flatnonzero(states.min(axis=0) == states.max(axis=0))
    return Analysis(
        net=net, space=space, coverability=None, states=space.n_states, edges=space.n_edges, complete=True,
        bounded=True, place_bounds={p.id: int(b) for p, b in zip(net.places, per_place)}, unbounded_places=[],
        covering=None, max_token_in_place=int(per_place.max(initial=0)),
        max_token_per_marking=int(totals.max(initial=0)), one_safe=bool(per_place.max(initial=0) <= 1),
        deadlock=bool(dead.size), deadlocks=deadlocks, n_deadlocks=int(dead.size),
        liveness={t.id: int(lv) for t, lv in zip(net.transitions, levels)},
        quasi_live=bool((levels >= 1).all()), live=bool((levels == 4).all()),
        reversible=bool(np.unique(labels).size == 1), home_states=home_count, home_marking_is_home=home_is_home,
        stable_places=[net.places[int(p)].id for p in stable],
        p_invariants=pinv, t_invariants=tinv, conservative=pinv.covered, consistent=tinv.covered,
        conflicts=_conflicts(net, space), notes=notes,
    )
