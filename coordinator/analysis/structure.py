"""Qualitative analysis of the ordinary net of a task (paper section 2, "Qualitative Performance
Evaluation"): boundedness, safeness, deadlocks, liveness levels, reversibility, home states,
stable places, invariants, structural conflicts.

Pure: no I/O. The ordinary view (:func:`ordinary_view`) drops the events of the interpreted net —
a transition fires as soon as it is enabled — and keeps the interpretation as labels.

Boundedness is always decided when it can be: the reachability graph (:func:`explore`) is finite
and complete ⇒ bounded; the state equation bounds the total token count (an LP with an exact dual
certificate, :mod:`.lp`) or the P-invariants cover every place ⇒ bounded, with an upper bound per
place (Murata 1989 section VI; Silva, Teruel, Colom 1998); a marking strictly covering a
breadth-first ancestor proves unboundedness; otherwise the Karp–Miller coverability graph decides
(for nets without inhibitor arcs). Properties that need the whole graph (liveness, reversibility)
are ``None`` when only a coverability graph or a truncated graph is available; :attr:`Analysis.sources`
says what decided each property, so a report can tell the explicit search from the structure.
Conservativeness and consistency come from linear programs (:mod:`.lp`), never from the Farkas
enumeration, which is only there to list the minimal invariants when its budgets allow.

Reset arcs (docs/analysis.md, "Reset arcs"): the reachability graph honours them, so everything
decided on a complete graph stands. The incidence matrix C leaves them out, and what rests on C
changes: a reset only removes tokens, so for y ≥ 0 with yᵀC ≤ 0 every reachable M still has
y·M ≤ y·M0 (the state-equation and P-invariant *bounds* stay valid upper bounds), but y·M is no
longer conserved. So the P-invariants listed are the semiflows of C whose support holds no reset
place (those are still invariants), the T-invariants those with no transition that has a reset arc,
and conservative / consistent are left undecided (their value on the net without reset arcs is in
a note). Karp–Miller is not run on a net with reset arcs (unsound, and boundedness is undecidable
for reset nets): when the graph is too large and the bounds do not settle boundedness, it stays
undecided unless a pumping witness proves unboundedness (one whose growing places the repeated
firings do not reset; :func:`.coverability.covering_witness`).

Every analysis runs within a state limit and a byte budget (:func:`analyse`): the search stops
with what it has when either is reached, and the passes over a complete graph run only if their
memory need (estimated from its size) fits.

Liveness levels (Murata 1989, section IV-C) on a finite reachability graph, through its strongly
connected components (Tarjan 1972, via scipy.sparse.csgraph): L0 dead — t labels no edge; L1 — t
labels some edge; L3 (= L2 on finite graphs) — t labels an edge inside a strongly connected
component, so it can fire infinitely often; L4 live — t labels an edge in every terminal component
(a component no edge leaves), so from every reachable marking t can still fire. The net is
reversible iff the graph is strongly connected; the home states are the states of the terminal
component when there is exactly one.

Length: about 1,100 lines because :func:`analyse` is one decision procedure (graph, then LP bounds,
then invariants, then coverability, each step deciding what the previous one left open) and its
result types and graph passes are read together with it; the LP, invariants, siphons and the
search live in their own modules.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from coordinator.analysis import lp
from coordinator.analysis.coverability import (
    Coverability,
    CoveringWitness,
    Walks,
    covering_witness,
    karp_miller,
    random_walks,
)
from coordinator.analysis.invariants import (
    DEFAULT_MAX_BYTES as DEFAULT_INVARIANT_BYTES,
)
from coordinator.analysis.invariants import (
    Invariants,
    p_invariants,
    structural_bounds,
    t_invariants,
)
from coordinator.analysis.budget import cpus, lower_priority, room
from coordinator.analysis.lp import PlaceBounds, Support
from coordinator.analysis.matrices import SparseNet, sparse_net
from coordinator.analysis.statespace import (
    PROGRESS_STATES,
    StateSpace,
    default_max_bytes,
    enabled_mask,
    explore,
    implicit_pass_bytes,
)
from coordinator.errors import AnalysisError
from coordinator.net import Marking, PetriNet

if TYPE_CHECKING:  # the symbolic engine is imported when it runs: analyze's cold start
    from coordinator.analysis.symbolic import Rival

__all__ = [
    "PROBE_STATES",
    "Analysis",
    "Conflict",
    "Deadlock",
    "Structural",
    "analyse",
    "graph_liveness",
    "graph_pass_bytes",
    "search_bounds",
    "liveness_levels",
    "ordinary_view",
    "record_only_places",
    "without_places",
]

#: States explored first when the net is not structurally bounded, to look for cheap unboundedness.
PROBE_STATES = 2_000
#: When the probe holds no pumping witness, random firing sequences look for one deeper
#: (:func:`.coverability.random_walks`), within this many seconds and firings (DoubleLock-PT-p1s2's
#: witness takes 0.3-1.4 s, depending on the seed)
WALK_SECONDS = 2.0
WALK_STEPS = 100_000
#: firings per walk at most when the walks look for a pumping witness (50, 100, 200, 400 in turn;
#: longer walks spend their time comparing markings: FunctionPointer-PT-c016's witness took
#: 0.4-2.7 s over four seeds at 400, and was not found within 4 s on three of them at 2,000)
WALK_LENGTH = 400
#: When the explored part holds no dead marking and the structure does not show none is reachable,
#: random walks look for one within this many seconds and :data:`WALK_STEPS` firings
DEAD_WALK_SECONDS = 1.0
#: firings per walk at most when the walks look for a dead marking (a dead end may lie thousands of
#: firings deep: BugTracking-PT-q8m256's, about 4,400)
DEAD_WALK_LENGTH = 10_000
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
    touched = sparse_net(net).consumed_or_read()
    return [p.id for i, p in enumerate(net.places) if not touched[i]]


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
class Structural:
    """What linear programming says about a net's structure (see :mod:`.lp`).

    Attributes:
        p_support: places covered by some P-semiflow (conservative iff all), with certificates.
        t_support: transitions covered by some T-semiflow (consistent iff all), with certificates.
        total_bound: state-equation bound on the total token count (None: the LP is unbounded or
            did not finish), and whether an exact dual certificate backs it.
        total_certified: see ``total_bound``.
        place_bounds: per-place state-equation bounds, computed only when the graph is incomplete.
    """

    p_support: Support
    t_support: Support
    total_bound: int | None
    total_certified: bool
    place_bounds: PlaceBounds | None = None


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
        place_bounds: place id → bound (``None``: unbounded or unknown); exact for the places listed
            in ``exact_bounds``, an upper bound otherwise.
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
        conservative: a strictly positive P-semiflow exists (LP, :mod:`.lp`); None if undecided.
        consistent: a strictly positive T-semiflow exists (LP); None if undecided.
        conflicts: structural conflicts.
        notes: plain sentences on what could not be decided and why.
        projection: when the graph is infinite or too large and the net has record-only places (no
            transition reads them) that account for any growth, the analysis of the net without
            them (complete): same enabling, so its liveness, deadlocks and graph stand for the
            task's behaviour.
        sources: property name → what decided it (``"reachability graph"``, ``"state equation
            (LP)"``, ``"P-invariants"``, ``"Karp-Miller coverability graph"``, ...); properties
            left undecided are absent.
        structural: the LP results.
        exact_bounds: places whose bound in ``place_bounds`` is exact (all of them when complete).
        graph_work_done: False when the graph is complete but the passes over its edges that need
            memory beyond the budget (scipy's components, the robotic recovery checks) were
            skipped; liveness and reversibility may then still come from the markings
            (:meth:`.statespace.StateSpace.implicit_liveness`, ``liveness`` not None).
        stopped_by: why the search stopped early: ``"max_states"``, ``"max_memory"``, or None.
        stable_marking_partial: on a truncated graph, False when every place varies among the
            markings found (then no place is stable), True when no transition that may fire
            changes some place (:meth:`.SparseNet.markable`); else None.
        engine: ``"explicit"`` (reachability graph) or ``"symbolic"`` (decision diagram: ``space`` is
            None, every count is exact); engine_reason: which engine and why, one sentence.
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
    conservative: bool | None
    consistent: bool | None
    conflicts: list[Conflict]
    notes: list[str] = field(default_factory=list)
    projection: Analysis | None = None
    sources: dict[str, str] = field(default_factory=dict)
    structural: Structural | None = None
    exact_bounds: list[str] = field(default_factory=list)
    graph_work_done: bool = True
    stopped_by: str | None = None
    stable_marking_partial: bool | None = None
    engine: str = "explicit"
    engine_reason: str = ""

    @property
    def stable_marking(self) -> bool | None:
        """Some place keeps the same count in every reachable marking (MCC StableMarking); on a
        truncated graph, "no" when every place varies among the markings found, "yes" when the
        structure shows a place no transition that may fire changes."""
        if self.stable_places is None:
            return self.stable_marking_partial
        return bool(self.stable_places)

    @property
    def dead_transitions(self) -> list[str] | None:
        """Transitions that can never fire (L0)."""
        if self.liveness is None:
            return None
        return [t for t, lvl in self.liveness.items() if lvl == 0]

    @property
    def undecided(self) -> list[str]:
        """Names of the properties left undecided (``None``)."""
        values = {
            "bounded": self.bounded, "one_safe": self.one_safe, "max_token_in_place": self.max_token_in_place,
            "max_token_per_marking": self.max_token_per_marking, "deadlock": self.deadlock,
            "quasi_live": self.quasi_live, "live": self.live, "reversible": self.reversible,
            "stable_marking": self.stable_marking, "conservative": self.conservative,
            "consistent": self.consistent,
        }
        return [k for k, v in values.items() if v is None]


#: liveness_levels of the graphs still held (a graph's passes read them again: the robotic reading's
#: controllability, beside the analysis; SafeBus-PT-06, 6,816,756 markings: 5.9 s a pass)
_LIVENESS: weakref.WeakKeyDictionary[StateSpace, tuple[np.ndarray, np.ndarray, np.ndarray]] = (
    weakref.WeakKeyDictionary())


def liveness_levels(space: StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liveness level of each transition on a complete reachability graph: from its edges by
    scipy's strongly connected components, or, when the edges were not kept, by
    :meth:`.statespace.StateSpace.implicit_liveness` (the edges computed again from the markings).
    Found once per graph: a second call on the same graph, while it is held, returns the same
    arrays (read-only), the components not computed again.

    Returns:
        ``(levels, labels, terminal)``: levels (|T|,) int64 in {0, 1, 3, 4}; the strongly connected
        component of each state (N,) int32; a boolean (n_components,) marking terminal components.
    """
    found = _LIVENESS.get(space)
    if found is None:
        if not space.edges_kept:
            found = space.implicit_liveness()
        else:  # edges are sorted by source, so the CSR matrix is built without sorting
            found = graph_liveness(space.n_states, len(space.net.transitions), space.src, space.dst,
                                   space.transition, out_ptr=space.out_ptr)
        for array in found:
            array.flags.writeable = False
        _LIVENESS[space] = found
    return found


def graph_liveness(n: int, n_t: int, src: np.ndarray, dst: np.ndarray, transition: np.ndarray,
                   out_ptr: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`liveness_levels` on raw edge arrays (shapes (E,)); ``out_ptr`` if ``src`` is sorted.

    Memory: scipy's strongly-connected-components pass copies the graph with float64 weights and
    int32 indices (~13 bytes per edge); the level computation adds ~9 bytes per edge.
    """
    if out_ptr is not None:
        graph = sp.csr_matrix((np.ones(dst.shape[0], dtype=np.int8), dst.astype(np.int32, copy=False), out_ptr),
                              shape=(n, n))
    else:
        graph = sp.csr_matrix((np.ones(src.shape[0], dtype=np.int8), (src, dst)), shape=(n, n))
    n_comp, labels = csgraph.connected_components(graph, directed=True, connection="strong")
    del graph
    labels = labels.astype(np.int32, copy=False)
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
        pairs = np.unique(cs[inside].astype(np.int64) * n_t + transition[inside].astype(np.int64))
        live = np.bincount(pairs % n_t, minlength=n_t) == n_term
    levels[live & cyc] = 4
    return levels, labels, terminal


def graph_pass_bytes(n_states: int, n_edges: int) -> int:
    """Bytes the passes over a complete graph need beyond the graph itself (liveness levels through
    strongly connected components, the robotic recovery and control checks): about 48 per edge
    (edge sources, scipy's copies, reversed graph) and 48 per state."""
    return 48 * n_edges + 48 * n_states


def _enabled_one(sn: SparseNet, rows: np.ndarray, t: int) -> np.ndarray:
    """Whether transition t is enabled in each row of ``rows`` (k, |P|): (k,) bool."""
    out = np.ones(rows.shape[0], dtype=bool)
    pre, inh = sn.pre, sn.inhibitor
    for k in range(pre.indptr[t], pre.indptr[t + 1]):
        out &= rows[:, pre.indices[k]] >= pre.data[k]
    for k in range(inh.indptr[t], inh.indptr[t + 1]):
        out &= rows[:, inh.indices[k]] < inh.data[k]
    return out


def _effective_on_edges(space: StateSpace, shared: list[tuple[int, np.ndarray]]) -> dict[int, bool]:
    """Whether each structural conflict (place, its output transitions) is effective, read off the
    edges of a complete graph that kept them: a state enables transition t when it has an edge
    labelled t (one edge per state and enabled transition), so a conflict is effective when some
    edge s → s' labelled a leaves a transition b ≠ a of the conflict that s enables disabled in s'.
    Per conflict of up to 64 transitions, the ones each state enables are a bit mask (uint64), and
    every edge of the conflict's transitions is checked at once; beyond 64, pair by pair. Exact
    for every arc kind (the edges are the firings). Temporaries: about 20 bytes per edge of the
    transitions in conflict, and 8 bytes per state."""
    involved = np.unique(np.concatenate([ts for _, ts in shared]))
    keep = np.isin(space.transition, involved)
    tr = space.transition[keep]
    order = np.argsort(tr, kind="stable")  # stable: each transition's sources stay sorted
    tr = tr[order]
    src = space.src[keep][order]
    dst = space.dst[keep][order]
    del keep, order
    lo = np.searchsorted(tr, involved, side="left")
    hi = np.searchsorted(tr, involved, side="right")
    at = {int(t): (int(a), int(b)) for t, a, b in zip(involved, lo, hi)}
    mask = np.zeros(space.n_states, dtype=np.uint64)  # zero but for the sources of the conflict checked

    def edges_of(ts: list[int]) -> np.ndarray:
        return np.concatenate([np.arange(*at[t]) for t in ts])

    def disables(a: int, b: int) -> bool:  # some state enabling both where firing a disables b
        (la, ha), (lb, hb) = at[a], at[b]
        mask[src[lb:hb]] = 1
        both = mask[src[la:ha]] != 0
        found = bool(both.any()) and not bool(mask[dst[la:ha][both]].all())
        mask[src[lb:hb]] = 0
        return found

    effective: dict[int, bool] = {}
    for p, ts in shared:
        t_list = [int(t) for t in ts.tolist()]
        if len(t_list) > 64:
            effective[p] = any(disables(a, b) or disables(b, a) for i, a in enumerate(t_list) for b in t_list[i + 1:])
            continue
        e = edges_of(t_list)
        s_e = src[e]
        bit = np.left_shift(np.uint64(1), np.searchsorted(np.array(sorted(t_list)), tr[e]).astype(np.uint64))
        np.bitwise_or.at(mask, s_e, bit)
        effective[p] = bool(((mask[s_e] & ~bit) & ~mask[dst[e]]).any())
        mask[s_e] = 0
    return effective


def _effective_in_blocks(sn: SparseNet, space: StateSpace, shared: list[tuple[int, np.ndarray]], seconds: float,
                         block_bytes: int) -> tuple[dict[int, bool | None], bool]:
    """Whether each structural conflict (place, its output transitions) is effective, from the
    markings of a complete graph in blocks of rows (temporaries below about ``block_bytes``), each
    pair's markings that enable both fired both ways; within ``seconds``, after which the
    conflicts not yet found effective are None. Returns them and whether the check finished."""
    start = time.monotonic()
    effective: dict[int, bool | None] = {p: False for p, _ in shared}
    block = max(1, min(1 << 16, block_bytes // max(8 * sn.n_places, 1)))
    for lo in range(0, space.n_states, block):
        if time.monotonic() - start > seconds:
            for p, _ in shared:
                if not effective[p]:
                    effective[p] = None
            return effective, False
        rows = space.states[lo:lo + block]
        cache: dict[int, np.ndarray] = {}

        def en(t: int, rows: np.ndarray = rows, cache: dict[int, np.ndarray] = cache) -> np.ndarray:
            if t not in cache:
                cache[t] = _enabled_one(sn, rows, t)
            return cache[t]

        for p, ts in shared:
            if effective[p]:
                continue
            for i, a in enumerate(ts.tolist()):
                for b in ts[i + 1:].tolist():
                    both = np.flatnonzero(en(a) & en(b))
                    if not both.size:
                        continue
                    base = rows[both]
                    if not (_enabled_one(sn, sn.firing_rows(base, a), b).all()
                            and _enabled_one(sn, sn.firing_rows(base, b), a).all()):
                        effective[p] = True
                        break
                if effective[p]:
                    break
    return effective, True


#: seconds the blocks of states get before the edges decide the conflicts still open (:func:`_conflicts`)
_BLOCKS_FIRST = 1.0


def _conflicts(net: PetriNet, space: StateSpace | None, *, seconds: float = 10.0,
               block_bytes: int = 1 << 26, on_edges: bool = False) -> tuple[list[Conflict], bool]:
    """Structural conflicts; effective when, in a reachable marking enabling two of the transitions,
    firing one disables the other. Checked on the complete graph in blocks of states (temporaries
    below ``block_bytes``, :func:`_effective_in_blocks`) within ``seconds``, which finds most
    effective conflicts in the first blocks; when ``on_edges`` (the edges were kept and the passes
    over them fit the budget), the blocks get :data:`_BLOCKS_FIRST` seconds and the edges decide
    the rest without a time limit (:func:`_effective_on_edges`; SafeBus-PT-06, 6,816,756
    markings and 132 conflicts: 5.7 s, where the blocks alone take 25 s). Returns the conflicts
    and whether the check finished."""
    sn = sparse_net(net)
    pre_r = sp.csr_matrix(sn.pre)
    counts = np.diff(pre_r.indptr)
    shared = [(p, pre_r.indices[pre_r.indptr[p]:pre_r.indptr[p + 1]]) for p in np.flatnonzero(counts >= 2).tolist()]
    effective: dict[int, bool | None] = {p: None for p, _ in shared}
    finished = True
    if space is not None and space.complete and shared:
        on_edges = on_edges and space.edges_kept
        effective, finished = _effective_in_blocks(sn, space, shared, min(seconds, _BLOCKS_FIRST) if on_edges
                                                   else seconds, block_bytes)
        if not finished and on_edges:
            effective.update(_effective_on_edges(space, [(p, ts) for p, ts in shared if effective[p] is None]))
            finished = True
    return ([Conflict(place=net.places[p].id, transitions=[net.transitions[int(t)].id for t in ts],
                      effective=effective[p]) for p, ts in shared], finished)


#: the explicit search's share in the automatic choice: it runs up to this many markings (a few
#: seconds); a net whose graph is larger and whose places all have a proven bound goes symbolic
#: (and, on two CPUs or more, the explicit search, started in a thread of its own, goes on beside
#: the symbolic engine: _Beside)
AUTO_PROBE_STATES = 1_000_000
#: ... or for this long, on two CPUs or more (seconds from the search's start): a net of many
#: transitions is searched slowly (ARMCacheCoherence-PT-none's 33,676: 15,000 markings a second, so
#: its share took 60 s, where its decision diagram takes 10 s), and the search goes on beside anyway,
#: so a short share costs a net the search completes little (ARMCacheCoherence and EnergyBus-PT-none
#: answered in 17.3 s and 9.3 s with 4 s, 22.3 s and 16.0 s with 10 s; docs/BENCHMARKS.md)
AUTO_PROBE_SECONDS = 4.0
#: markings of the explicit search run for the symbolic engine's guessed levels when it was asked
#: for alone (``--engine symbolic``) and the proven bounds make its levels too wide
SEEN_STATES = 100_000
#: time budget of the symbolic engine inside :func:`analyse` (seconds)
SYMBOLIC_SECONDS = 300.0
#: the symbolic engine's time budget on a net some of whose places have no proven bound (levels
#: guessed from the counts seen; the net may be unbounded, and the explicit search and
#: coverability run after it when it gives up), seconds
UNPROVEN_SECONDS = 60.0
#: how much lower the search beside the symbolic engine runs (a nice increment, Linux): the symbolic
#: engine's race of variable orders has the CPUs first, the search takes what they leave
_BESIDE_NICE = 6
#: the engines :func:`analyse` takes
ENGINES = ("auto", "explicit", "symbolic")


@dataclass
class _Structure:
    """What the structure says before any search (:func:`_structure_phase`)."""

    pinv: Invariants
    tinv: Invariants
    psup: Support
    tsup: Support
    structural: Structural
    bounding_pinv: Invariants
    sbounds: np.ndarray
    total: int | None
    total_cert: bool
    notes: list[str]
    sources: dict[str, str]
    lp_bounds: np.ndarray  # per place, from the certificate of the total token count's LP (-1: none)
    walks: Walks | None = None  # the random walks of the first search of a net not bounded (_search_phase)

    @property
    def bounded(self) -> bool:
        """The state equation or the P-invariants bound the net."""
        return self.total is not None or bool(self.bounding_pinv.complete and (self.sbounds >= 0).all())


def _structure_phase(net: PetriNet, sn: SparseNet, budget: int, max_invariant_rows: int, invariant_seconds: float,
                     lp_seconds: float) -> _Structure:
    """What linear programming and the invariants say before any search: supports, invariants (the
    reset-arc reading, :func:`_without_reset_results`), the total token bound, the invariant bounds."""
    notes: list[str] = []
    sources: dict[str, str] = {}
    psup = lp.conservative(sn, seconds=lp_seconds)
    tsup = lp.consistent(sn, seconds=lp_seconds)
    for key, sup in (("conservative", psup), ("consistent", tsup)):
        if sup.covered is None:
            notes.append(f"{key}: the linear program did not finish ({sup.message}); not decided")
        else:
            sources[key] = "LP (semiflow support, " + ("exact certificate)" if sup.certified else "floating point)")
    farkas_bytes = min(DEFAULT_INVARIANT_BYTES, budget // 4)
    pinv = p_invariants(net, max_rows=max_invariant_rows, max_bytes=farkas_bytes, seconds=invariant_seconds,
                        support=psup.covered)
    tinv = t_invariants(net, max_rows=max_invariant_rows, max_bytes=farkas_bytes, seconds=invariant_seconds,
                        support=tsup.covered)
    for name, inv in (("P-invariants", pinv), ("T-invariants", tinv)):
        if not inv.complete:
            notes.append(f"{name}: not enumerated ({inv.reason}); none are listed")
    bounding_pinv = pinv  # every semiflow of C bounds the net, reset arcs or not
    if sn.n_resets:
        pinv, tinv, psup, tsup = _without_reset_results(net, sn, pinv, tinv, psup, tsup, notes, sources)
    total, total_done, total_cert, lp_bounds = lp.total_place_bounds(sn, seconds=lp_seconds)
    structural = Structural(p_support=psup, t_support=tsup, total_bound=total, total_certified=total_cert)
    if not total_done:
        notes.append("the state-equation LP of the total token count did not finish in time")
    return _Structure(pinv=pinv, tinv=tinv, psup=psup, tsup=tsup, structural=structural,
                      bounding_pinv=bounding_pinv, sbounds=structural_bounds(net, bounding_pinv), total=total,
                      total_cert=total_cert, notes=notes, sources=sources, lp_bounds=lp_bounds)


def _beside_bytes(budget: int, graph_bytes: int, whole: int) -> int:
    """The bytes of the explicit search beside the symbolic engine (:class:`_Beside`): its share of the
    budget, ``graph_bytes``, less what the process holds where :func:`.budget.room` gives less than
    ``budget`` (``whole``), so the symbolic engine keeps the rest of the budget as before: the search's
    count of its bytes is an upper bound (a byte a place for a copy of each marking it may not make),
    the decision diagram's is what it holds (IOTPpurchase-PT-C12M10P15D17, whose search beside is
    stopped at 4 s: with the process's 0.6 GiB taken from the diagram's part, its reachable set came
    at 41 s instead of 34 s, and liveness was left undecided)."""
    return max(0, graph_bytes - (budget - whole))


def _search_bounds(st: _Structure) -> np.ndarray:
    """Per-place bounds known before the search (-1 where none): the P-invariants' and those of the
    total token count's LP certificate; they size the fields of the search's packed markings (a wrong one costs a wider
    field and a new start, never a wrong graph: :func:`~coordinator.analysis.statespace.explore`)."""
    bounds = st.sbounds.copy()
    tighter = (st.lp_bounds >= 0) & ((bounds < 0) | (st.lp_bounds < bounds))
    bounds[tighter] = st.lp_bounds[tighter]
    return bounds


def search_bounds(net: PetriNet, *, max_bytes: int | None = None, invariant_seconds: float = 5.0,
                  lp_seconds: float = 10.0) -> np.ndarray:
    """The place bounds :func:`analyse` proves before its explicit search and gives it to size the
    packed markings (P-invariants, the certificate of the total token count's LP).

    Returns:
        (|P|,) int64 bounds of the ordinary view's places, -1 where none is proven.
    """
    net = ordinary_view(net)
    budget = default_max_bytes() if max_bytes is None else int(max_bytes)
    return _search_bounds(_structure_phase(net, sparse_net(net), budget, 20_000, invariant_seconds, lp_seconds))


def _search_phase(net: PetriNet, sn: SparseNet, st: _Structure, max_states: int, graph_bytes: int,
                  progress: Callable[[int, int], None] | None, finish_level: bool = True,
                  stop: threading.Event | None = None,
                  report_every: int = PROGRESS_STATES) -> tuple[StateSpace, CoveringWitness | None]:
    """The reachability graph within its limits, and a pumping witness of unboundedness when the
    structure does not bound the net (a short probe first: unboundedness is often cheap to see; then,
    once per analysis, random walks, which reach a loop deeper than any breadth-first budget:
    ``st.walks``).
    ``finish_level`` False: stop at once at ``max_states`` (:func:`.statespace.explore`), for the
    automatic engine's question whether the graph fits its explicit share. ``stop``: another
    thread's event that ends the search, ``report_every`` how often ``progress`` is called and
    ``stop`` checked (:func:`.statespace.explore`). The search of a bounded
    net keeps its edges while they fit ``graph_bytes`` and then drops them, going on counting
    them (``shed_edges``): the markings alone may fit, and liveness and reversibility come from
    them (:meth:`.StateSpace.implicit_liveness`). A note says so."""
    space: StateSpace | None = None
    witness: CoveringWitness | None = None
    bounds = _search_bounds(st)
    if not st.bounded and max_states > PROBE_STATES:
        probe = explore(net, max_states=PROBE_STATES, progress=progress, max_bytes=graph_bytes, bounds=bounds)
        if probe.complete:
            space = probe
        else:
            witness = covering_witness(probe)
            if witness is None:
                if st.walks is None:  # once per analysis: a later search of the same net finds them here
                    st.walks = random_walks(net, seconds=WALK_SECONDS, max_steps=WALK_STEPS, length=WALK_LENGTH)
                    if st.walks.witness is not None:
                        st.notes.append(f"the pumping witness comes from a random walk ({st.walks.walks:,} walks, "
                                        f"{st.walks.steps:,} firings): the breadth-first search's first "
                                        f"{probe.n_states:,} markings hold none")
                witness = st.walks.witness
            if witness is not None:
                space = probe
    if space is None:
        space = explore(net, max_states=max_states, progress=progress, max_bytes=graph_bytes, bounds=bounds,
                        finish_level=finish_level, stop=stop, shed_edges=st.bounded, report_every=report_every)
        if space.edges_shed_at is not None:
            shed = (f"the edges of the reachability graph filled its memory budget ({graph_bytes / 2**30:.2f} GiB) "
                    f"at {space.edges_shed_at:,} markings; the search went on counting them without keeping them")
            if space.complete:
                st.notes.append(shed + f", and the graph is complete with {space.n_states:,} markings")
            elif space.stopped_by == "max_memory":
                st.notes.append(shed + f", and stopped too, after {space.n_states:,} markings")
            else:
                st.notes.append(shed + f", to {space.n_states:,} markings")
        if not space.complete and not st.bounded and witness is None:
            witness = covering_witness(space)
    return space, witness


def _upper_bounds(sn: SparseNet, st: _Structure, lp_seconds: float, seen: np.ndarray,
                  more: Sequence[np.ndarray] = (), lp_above: int = 0) -> tuple[PlaceBounds, np.ndarray]:
    """Per-place upper bounds of a bounded net: the state equation's (one LP per place not yet
    reached by ``seen``, :func:`.lp.place_bounds` with ``lp_above``) and the P-invariants' and
    ``more`` semiflows', the smallest; -1 where none bounds."""
    flows = tuple(v for v in st.bounding_pinv.vectors) + (
        (st.psup.semiflow,) if st.psup.semiflow is not None else ()) + tuple(more)
    pb = lp.place_bounds(sn, seconds=lp_seconds, seen=seen, semiflows=flows, lp_above=lp_above)
    upper = pb.bounds.copy()
    if st.bounding_pinv.complete:
        both = (st.sbounds >= 0) & ((upper < 0) | (st.sbounds < upper))
        upper[both] = st.sbounds[both]
    return pb, upper


def analyse(net: PetriNet, *, max_states: int = 10_000_000, max_bytes: int | None = None,
            max_coverability_nodes: int = 200_000, max_invariant_rows: int = 20_000,
            invariant_seconds: float = 5.0, lp_seconds: float = 10.0, coverability_seconds: float = 30.0,
            progress: Callable[[int, int], None] | None = None, engine: str = "explicit",
            symbolic_seconds: float = SYMBOLIC_SECONDS, phase: Callable[[str], None] | None = None) -> Analysis:
    """Analyse the ordinary view of ``net`` (see the module docstring for the decision procedure).

    Args:
        net: the (interpreted or plain) net.
        max_states: limit of the reachability graph.
        max_bytes: memory budget of the whole analysis, bytes (default
            :func:`~coordinator.analysis.statespace.default_max_bytes`): half goes to the
            reachability graph's search, up to a quarter (at most 512 MiB) to each invariant
            enumeration (before the search, freed after), and the passes over a complete graph
            (liveness, recovery) run only if their estimated need fits in the budget beside the graph;
            the symbolic engine has the whole budget (half while the explicit search runs beside it).
            Under the default budget, what the process holds when the symbolic engine starts is
            taken from the symbolic engine's part, or from the search's beside it
            (:func:`.budget.room`, :func:`_beside_bytes`).
        max_coverability_nodes: limit of the Karp–Miller graph (lowered to what the budget holds).
        max_invariant_rows: size guard of the Farkas algorithm.
        invariant_seconds: time budget of each Farkas enumeration.
        lp_seconds: time budget of each linear program (the per-place bounds share one such budget).
        coverability_seconds: time budget of the Karp–Miller construction.
        progress: passed to :func:`~coordinator.analysis.statespace.explore`.
        engine: ``"explicit"`` (the reachability graph), ``"symbolic"`` (the reachable set as a
            decision diagram, :mod:`.symbolic`; needs a proven bound on every place) or ``"auto"``:
            explicit up to :data:`AUTO_PROBE_STATES` markings (or, on two CPUs or more,
            :data:`AUTO_PROBE_SECONDS` of search), symbolic beyond when every place has
            a proven bound, with the explicit search going on beside it on two CPUs or more
            (:class:`_Beside`: whichever completes first answers; :attr:`Analysis.engine_reason`
            says which and why).
        symbolic_seconds: time budget of the symbolic engine.
        phase: called with a short line when a phase of the symbolic engine starts.

    Returns:
        An :class:`Analysis`.

    Raises:
        AnalysisError: ``engine="symbolic"`` on a net the symbolic engine cannot take (a place
            without a proven bound, its time or memory budget), or an unknown engine.
    """
    if engine not in ENGINES:
        raise AnalysisError(f"unknown analysis engine {engine!r}; choose one of {', '.join(ENGINES)}")
    started = time.monotonic()
    net = ordinary_view(net)
    budget = default_max_bytes() if max_bytes is None else int(max_bytes)
    sn = sparse_net(net)
    st = _structure_phase(net, sn, budget, max_invariant_rows, invariant_seconds, lp_seconds)
    graph_bytes = budget // 2  # the explicit search's share
    if engine == "symbolic":
        return _symbolic_phase(net, sn, st, room(budget), lp_seconds, symbolic_seconds, phase,
                               "symbolic: asked for (--engine symbolic)", started)
    limit = max_states
    if engine == "auto":
        limit = min(max_states, AUTO_PROBE_STATES)
    reason = "explicit: asked for (--engine explicit)"
    beside: _Beside | None = None
    whole = budget  # the budget less what the process holds when a search beside starts (budget.room)
    searched = False  # the graph below is that of the search over the whole limit
    dropped = False  # ... and it was dropped for the symbolic engine: searched again if that gives up
    if engine == "auto" and st.bounded and limit < max_states and cpus() >= 2:
        # two CPUs and a bounded net: the search over the whole limit starts at once, in a thread,
        # and the symbolic engine starts beside it when it passes the explicit share (searched once)
        whole = room(budget)
        beside = _Beside(net, sn, st, max_states, _beside_bytes(budget, graph_bytes, whole), limit, progress, phase)
        try:
            going = beside.wait_share()
        except BaseException:
            beside.end(stop=True)
            raise
        if not going:
            if beside.found is not None:  # complete, or stopped by its memory: the search's own answer
                space, witness = beside.found
                st.notes.extend(beside.st.notes[len(st.notes):])
                searched = True
            beside = None
    if beside is None and not searched:
        # the automatic engine's share of the explicit search asks only whether the graph fits it: the
        # search stops at its limit at once (a level being finished may be most of the graph); the
        # search over the whole limit, when the symbolic engine gives up, finishes its level
        space, witness = _search_phase(net, sn, st, limit, graph_bytes, progress,
                                       finish_level=not (engine == "auto" and limit < max_states))
    if engine == "auto" and beside is None and space.complete:
        reason = f"explicit: the reachability graph is complete with {space.n_states:,} markings" + (
            f", within the explicit search's share of {limit:,}" if st.bounded and space.n_states <= limit else "")
    elif engine == "auto" and (st.bounded or (witness is None and limit < max_states
                                               and space.stopped_by == "max_states")):
        # every place has a proven bound; or some have none but the search passed its share with no
        # pumping witness: the symbolic engine tries levels guessed from the counts seen (a set no
        # firing leaves shows the net bounded), within UNPROVEN_SECONDS as the net may be unbounded
        # (a search its memory stopped first keeps its graph: FunctionPointer-PT-c128, unbounded,
        # whose 1,123 places without a bound fill the search's 2 GiB at 262,138 markings)
        proven = ("every place has a proven bound" if st.bounded else
                  "not every place has a proven bound but no pumping witness was found")
        guessed = "" if st.bounded else (" on levels guessed from the counts seen, and no firing left them: the net "
                                         "is bounded")
        seen: np.ndarray | None = None  # counts for levels guessed from them
        if beside is not None:
            share = (f"passed its share of {limit:,} markings" if not beside.timed_out else
                     f"ran its {AUTO_PROBE_SECONDS:g} s share before finding {limit:,} markings")
            reason = (f"symbolic: the explicit search {share} and {proven}, so the "
                      f"symbolic engine takes over (the search goes on beside it){guessed}")
        else:
            why = "its memory budget" if space.stopped_by == "max_memory" else f"{space.n_states:,} markings"
            reason = f"symbolic: the explicit search stopped at {why} and {proven}, so the symbolic engine takes over"
            reason += guessed
            seen = space.seen_counts()
            if st.bounded:
                # its graph is dropped while the decision diagram takes the memory: if the symbolic
                # engine gives up, the search runs again (AirplaneLD-PT-2000: 0.3 GiB of 14,019-place
                # markings held beside a decision diagram of 3 GiB)
                del space
                dropped = True
            elif cpus() >= 2:
                # its share told whether a pumping witness shows in it: the search over the whole
                # limit goes on beside the symbolic engine, from the start
                del space
                whole = room(budget)
                beside = _Beside(net, sn, st, max_states, _beside_bytes(budget, graph_bytes, whole), 0, progress,
                                 phase)
                beside.wait_share()
        found: Analysis | None = None
        try:
            found = _symbolic_phase(net, sn, st, room(budget) if beside is None else whole - beside.graph_bytes,
                                    lp_seconds,
                                    symbolic_seconds if st.bounded else min(symbolic_seconds, UNPROVEN_SECONDS),
                                    phase, reason, started,
                                    stop=None if beside is None else beside.finished,
                                    borrow=None if beside is None else beside.lend, seen=seen, seen_states=limit,
                                    rival=None if beside is None else beside.rival)
        except AnalysisError as exc:
            if beside is None or not beside.finished.is_set():
                what = "the symbolic engine" if st.bounded else (
                    "not every place has a proven bound, and the symbolic engine on levels guessed from the counts "
                    "seen")
                reason = f"explicit: {what} gave up ({exc})"
                st.notes.append(f"{what[0].upper()}{what[1:]} gave up ({exc}); the explicit search goes on to its "
                                "limits")
        except BaseException:
            if beside is not None:
                beside.end(stop=True)
            raise
        if beside is not None:
            beside.end(stop=found is not None)  # the symbolic engine gave up: the search goes on to its limits
        if found is not None and (beside is None or not beside.finished.is_set()):
            return found
        rerun = (limit < max_states and not searched) or dropped
        if beside is not None and beside.found is not None:
            space, witness = beside.found
            beside.found = None
            st.notes.extend(beside.st.notes[len(st.notes):])
            rerun = False  # the search beside had the explicit search's own share of the budget
            if space.complete:
                reason = (f"explicit: the reachability graph is complete with {space.n_states:,} markings, found by "
                          "the explicit search that went on beside the symbolic engine (which it stopped)")
        if rerun:
            space, witness = _search_phase(net, sn, st, max_states, graph_bytes, progress)
            st.notes[:] = dict.fromkeys(st.notes)  # a search run again says again what it said the first time
    elif engine == "auto":
        reason = "explicit: not every place has a proven bound, so only the explicit search (and coverability) apply"
        if limit < max_states and space.stopped_by == "max_states" and space.n_states >= limit:
            # the pumping witness came after the probe: the partial graph goes on to the whole limit
            # (a search its memory stopped first would stop there again)
            space, witness = _search_phase(net, sn, st, max_states, graph_bytes, progress)
    pinv, tinv, psup, tsup, structural = st.pinv, st.tinv, st.psup, st.tsup, st.structural
    notes, sources = st.notes, st.sources
    has_inhibitors = bool(sn.inhibitor.nnz)
    if space.complete:
        return replace(_from_graph(net, space, pinv, tinv, psup, tsup, structural, notes, sources, budget),
                       engine="explicit", engine_reason=reason)
    v = _Partial(place_bounds={p.id: None for p in net.places})
    seen_max = space.extremes()[0]
    fires = _partial_from_siphon(v, net, sn, st)
    if st.bounded:
        structural = _partial_from_bounds(v, sn, st, space, seen_max, lp_seconds)
    elif witness is not None and v.quasi is False:
        notes.append("the Karp-Miller coverability graph was not built: a pumping witness shows the net is unbounded "
                     "and the unmarked siphon that it is not quasi-live")
    elif not has_inhibitors and not sn.n_resets:
        _partial_from_coverability(v, net, st, witness, min(max_coverability_nodes, (budget // 4) // (
            96 * max(len(net.places), 1) + 256)), coverability_seconds, fires)
    elif witness is None:
        arcs = "inhibitor and reset" if has_inhibitors and sn.n_resets else ("inhibitor" if has_inhibitors else "reset")
        notes.append(f"the net has {arcs} arcs, its reachability graph exceeds the limit and the state "
                     "equation does not bound it: boundedness is undecidable in general and was not decided "
                     "(Karp-Miller coverability is unsound for such nets and was not run)")
    longer = min(max_states, AUTO_PROBE_STATES)
    dead_known = v.deadlock is not None or bool(space.deadlocks().size)
    if witness is not None and not dead_known and not space.complete:
        _deadlock_unexplored(v, net, sn, st)  # before a longer search: the structure or a walk may settle it
        dead_known = v.deadlock is not None
    if witness is not None and (v.quasi is None or not dead_known) and not space.complete and (
            space.n_states < longer):
        # the probe's pumping witness ended the search; a longer one may still show every transition
        # fire, or a dead marking (FunctionPointer-PT-c002's, 13 firings deep, that walks seldom meet)
        space = explore(net, max_states=longer, progress=progress, max_bytes=graph_bytes, bounds=_search_bounds(st),
                        finish_level=False)
        seen_max = space.extremes()[0] if space.n_states else seen_max
    if space.stopped_by == "max_memory":
        notes.append(f"the reachability graph was stopped by the memory budget ({graph_bytes / 2**30:.2f} GiB of "
                     f"{budget / 2**30:.2f} GiB) after {space.n_states:,} markings")
    elif space.n_states < max_states and witness is not None:
        notes.append(f"the reachability graph was stopped after {space.n_states:,} markings: a pumping witness "
                     "shows the net is unbounded")
    else:
        notes.append(f"the reachability graph was stopped at the state limit ({max_states:,} markings)")
    _partial_from_explored(v, net, sn, st, space, witness, seen_max)
    # the net without its record-only places has the budget the partial graph (held meanwhile) leaves
    _partial_from_projection(v, net, sn, st, lambda small: analyse(
        small, max_states=max_states, max_bytes=budget - graph_bytes, max_coverability_nodes=max_coverability_nodes,
        max_invariant_rows=max_invariant_rows, invariant_seconds=invariant_seconds, lp_seconds=lp_seconds,
        coverability_seconds=coverability_seconds, progress=progress))
    conflicts, _ = _conflicts(net, None)
    return Analysis(
        net=net, space=space, coverability=v.cover, states=space.n_states, edges=space.n_edges, complete=False,
        bounded=v.bounded, place_bounds=v.place_bounds, unbounded_places=v.unbounded, covering=witness,
        max_token_in_place=v.max_in_place, max_token_per_marking=v.max_per_marking, one_safe=v.one_safe,
        deadlock=v.deadlock, deadlocks=v.deadlocks, n_deadlocks=None, liveness=v.levels, quasi_live=v.quasi,
        live=v.live, reversible=v.reversible, home_states=None, home_marking_is_home=None, stable_places=None,
        p_invariants=pinv, t_invariants=tinv, conservative=psup.all_covered, consistent=tsup.all_covered,
        conflicts=conflicts, notes=notes, projection=v.projection, sources=sources, structural=structural,
        exact_bounds=v.exact, stopped_by=space.stopped_by, stable_marking_partial=v.stable_known,
        engine="explicit", engine_reason=reason,
    )


@dataclass
class _Partial:
    """The verdicts on a net whose reachability graph is not complete, filled phase by phase."""

    place_bounds: dict[str, int | None]
    cover: Coverability | None = None
    exact: list[str] = field(default_factory=list)
    unbounded: list[str] = field(default_factory=list)
    bounded: bool | None = None
    deadlock: bool | None = None
    deadlocks: list[Deadlock] = field(default_factory=list)
    quasi: bool | None = None
    levels: dict[str, int] | None = None
    live: bool | None = None
    max_in_place: int | None = None
    max_per_marking: int | None = None
    one_safe: bool | None = None
    reversible: bool | None = None
    stable_known: bool | None = None
    projection: Analysis | None = None
    dead_walked: bool = False  # _deadlock_unexplored ran


def _partial_from_bounds(v: _Partial, sn: SparseNet, st: _Structure, space: StateSpace, seen_max: np.ndarray,
                         lp_seconds: float) -> Structural:
    """A structurally bounded net: the per-place upper bounds, exact where explored markings reach
    them, and the maxima they settle; returns the structural results with the place bounds."""
    ids = list(v.place_bounds)
    sources = st.sources
    v.bounded = True
    pb, upper = _upper_bounds(sn, st, lp_seconds, seen_max)
    st.notes.extend(pb.notes)
    v.place_bounds = {pid: (int(b) if b >= 0 else None) for pid, b in zip(ids, upper)}
    v.exact = [pid for pid, b, m in zip(ids, upper, seen_max) if b >= 0 and m == b]
    if st.total is not None:
        sources["bounded"] = "state equation (LP" + (", exact certificate)" if st.total_cert else ", floating point)")
    else:
        sources["bounded"] = "P-invariants"
    sources["place_bounds"] = ("upper bounds from the state equation (LP) and the P-invariants; exact where the "
                               "explored markings reach them")
    if (upper >= 0).all():
        top = int(upper.max(initial=0))
        if top <= 1:
            v.one_safe = True
            sources["one_safe"] = sources["bounded"]
        if int(seen_max.max(initial=0)) == top:
            v.max_in_place = top
            sources["max_token_in_place"] = "explored markings reach the structural upper bound"
    if st.total is not None and space.n_states:
        reached = int(space.states.sum(axis=1, dtype=np.int64).max())
        if reached == st.total:
            v.max_per_marking = st.total
            sources["max_token_per_marking"] = "explored markings reach the state-equation bound"
    st.notes.append(f"the net is bounded ({sources['bounded']}); the place bounds listed are upper bounds, "
                    f"exact for {len(v.exact)} of {len(ids)} places (reached by an explored marking)")
    return replace(st.structural, place_bounds=pb)


def _partial_from_coverability(v: _Partial, net: PetriNet, st: _Structure, witness: CoveringWitness | None,
                               max_nodes: int, seconds: float, may_fire: np.ndarray) -> None:
    """A net the structure does not bound, without inhibitor or reset arcs: the Karp–Miller graph
    (``may_fire``: :meth:`.SparseNet.markable`'s transitions, the only ones it tries)."""
    sources, notes = st.sources, st.notes
    cover = v.cover = karp_miller(net, max_nodes=max(1, max_nodes), seconds=seconds, may_fire=may_fire)
    if cover.complete:
        v.bounded = cover.bounded
        v.place_bounds = dict(zip(v.place_bounds, cover.place_bounds()))
        v.exact = [pid for pid, b in v.place_bounds.items() if b is not None]
        v.unbounded = cover.unbounded_places()
        fire = cover.fireable_transitions()
        v.quasi = bool(fire.all())
        sources["bounded"] = sources["place_bounds"] = sources["quasi_live"] = "Karp-Miller coverability graph"
        if not v.quasi:
            v.live = False
            sources["live"] = "Karp-Miller coverability graph"
        for node in cover.dead_nodes()[:MAX_WITNESSES]:
            v.deadlocks.append(Deadlock(marking=_omega_marking(net, cover.markings[node]),
                                        firing_sequence=cover.firing_sequence(int(node))))
        v.deadlock = True if v.deadlocks else None
        if v.deadlock:
            sources["deadlock"] = "Karp-Miller coverability graph"
        notes.append("the reachability graph is infinite or too large; boundedness, place bounds, "
                     "quasi-liveness and dead transitions come from the Karp–Miller coverability graph; "
                     "liveness and reversibility are not decided on it")
        if not v.quasi:
            notes.append("dead transitions: " + ", ".join(t.id for t, f in zip(net.transitions, fire) if not f))
        if v.bounded:
            v.max_in_place = max([0, *(b for b in v.place_bounds.values() if b is not None)])
            v.one_safe = v.max_in_place <= 1
            sources["max_token_in_place"] = sources["one_safe"] = "Karp-Miller coverability graph"
    elif witness is not None:
        v.bounded = False
        notes.append(f"the coverability graph {cover.stopped}; unboundedness comes from a pumping witness")
    else:
        notes.append(f"the coverability graph {cover.stopped}, and the state-equation LP does not bound the "
                     "net: boundedness is not decided")


def _partial_from_explored(v: _Partial, net: PetriNet, sn: SparseNet, st: _Structure, space: StateSpace,
                           witness: CoveringWitness | None, seen_max: np.ndarray) -> None:
    """What a pumping witness and the explored part prove on their own: its dead markings are
    reachable deadlocks (and then no transition is live), a transition that fired there is not dead,
    a count above 1 breaks safeness, a place that varies is not stable."""
    sources = st.sources
    if witness is not None:
        v.bounded = False
        sources["bounded"] = "pumping witness (a firing sequence that can repeat for ever)"
        v.one_safe = False
        sources["one_safe"] = sources["bounded"]
        for pid in witness.growing:
            if pid not in v.unbounded:
                v.unbounded.append(pid)
    for pid in v.unbounded:
        v.place_bounds[pid] = None
        if pid in v.exact:
            v.exact.remove(pid)
    dead_seen = space.deadlocks()
    if dead_seen.size:
        v.deadlock = True
        sources["deadlock"] = "reachability graph (explored part)"
        if not v.deadlocks:
            v.deadlocks = [Deadlock(marking=space.marking(int(i)).to_dict(),
                                    firing_sequence=space.firing_sequence(int(i))) for i in dead_seen[:MAX_WITNESSES]]
    elif v.deadlock is None:
        _deadlock_unexplored(v, net, sn, st)
    fired: np.ndarray | None = None  # the transitions known to fire from a reachable marking
    if v.quasi is None and space.n_edges:
        fired = _fired_seen(net, sn, space)
        if st.walks is not None:
            fired |= st.walks.fired
        if fired.all():
            v.quasi = True
            sources["quasi_live"] = "reachability graph (explored part)" + (
                " and random walks" if st.walks is not None else "")
    if v.one_safe is None and int(seen_max.max(initial=0)) > 1:
        v.one_safe = False
        sources["one_safe"] = "reachability graph (explored part)"
    if space.n_states and v.stable_known is not True:
        varies = space.extremes()[1] != space.extremes()[0]
        how = "reachability graph (explored part): every place varies"
        if not varies.all():
            if v.quasi:
                fired = np.ones(sn.n_transitions, dtype=bool)
            elif v.cover is not None and v.cover.complete:
                fired = v.cover.fireable_transitions()
            elif fired is None and space.n_edges:
                fired = _fired_seen(net, sn, space)
            if fired is not None:
                varies |= _changed_by(sn, fired)
                how = ("every place varies: between explored markings, or by the firing of a transition that can "
                       "fire (it changes the place's count)")
        if varies.all():
            v.stable_known = False
            sources["stable_marking"] = how
    if v.live is None and v.deadlock and net.transitions:
        v.live = False
        sources["live"] = "a reachable deadlock: no transition can fire from it"


def _changed_by(sn: SparseNet, fired: np.ndarray) -> np.ndarray:
    """(|P|,) bool: the places whose count some transition of ``fired`` ((|T|,) bool) changes
    whenever it fires (a nonzero incidence, no reset arc from the place to the transition)."""
    changed = np.zeros(sn.n_places, dtype=bool)
    moves = sp.csc_matrix(sn.incidence[:, fired] != 0, dtype=np.int8)
    if sn.reset is not None and sn.reset.nnz:
        moves = sp.csc_matrix(moves - moves.multiply(sn.reset[:, fired] != 0))
        moves.eliminate_zeros()
    changed[moves.indices] = True
    return changed


def _deadlock_unexplored(v: _Partial, net: PetriNet, sn: SparseNet, st: _Structure) -> None:
    """The deadlock question when the explored part holds no dead marking: a dead marking the random
    walks of the search ended in; else the structure's proof that none is dead
    (:func:`_never_dead`); else random walks that look for dead markings alone, past the pumping
    loops (:func:`.coverability.random_walks`, within :data:`DEAD_WALK_SECONDS` and :data:`WALK_STEPS`,
    :data:`DEAD_WALK_LENGTH` firings per walk)."""
    if v.dead_walked:
        return
    v.dead_walked = True
    walked = st.walks.dead if st.walks is not None else []
    how = "a random walk from M0 (looking for a pumping loop) ended in it"
    if not walked:
        never = _never_dead(net, sn)
        if never is not None:
            v.deadlock = False
            st.sources["deadlock"] = never
            return
        walked = random_walks(net, seconds=DEAD_WALK_SECONDS, max_steps=WALK_STEPS, length=DEAD_WALK_LENGTH,
                              witness=False, max_dead=MAX_WITNESSES).dead
        how = "a random walk from M0 ended in it"
    if walked:
        v.deadlock = True
        st.sources["deadlock"] = f"a dead marking: {how}"
        v.deadlocks = [Deadlock(marking={p.id: int(c) for p, c in zip(net.places, m) if c}, firing_sequence=seq)
                       for m, seq in walked[:MAX_WITNESSES]]


def _never_dead(net: PetriNet, sn: SparseNet) -> str | None:
    """Why some transition is enabled in every reachable marking, when the structure shows it
    (:meth:`.SparseNet.lone_input_trap`), else None."""
    free, trap = sn.lone_input_trap()
    if free.any():
        return (f"structure: transition {net.transitions[int(np.flatnonzero(free)[0])].id} has no input place and "
                "no inhibitor arc, so it is enabled in every marking")
    if (trap & (sn.m0 > 0)).any():
        places = [net.places[int(p)].id for p in np.flatnonzero(trap)]
        return (f"structure: the trap {{{_some(places)}}} is marked at M0, so it stays marked, and each of its "
                "places is the only input place of a transition (arc weight 1, no inhibitor arc), which it "
                "enables when marked")
    return None


def _partial_from_siphon(v: _Partial, net: PetriNet, sn: SparseNet, st: _Structure) -> np.ndarray:
    """What the largest initially unmarked siphon proves (:meth:`.SparseNet.markable`): a
    transition that consumes from it is dead, so the net is neither quasi-live nor live; a place in
    it holds no token ever, and a place that no transition that may fire changes keeps its count, so
    the net has a stable place. Returns the (|T|,) bool transitions that may fire."""
    sources, notes = st.sources, st.notes
    _, fires = sn.markable()
    if not fires.all():
        dead = [t.id for t, f in zip(net.transitions, fires) if not f]
        v.quasi = v.live = False
        sources["quasi_live"] = sources["live"] = ("structure: the largest siphon unmarked at M0 stays unmarked, "
                                                   "and the transitions that consume from it are dead")
        notes.append(f"dead transitions (they consume from the largest siphon unmarked at M0): {_some(dead)}")
    touched = np.zeros(sn.n_places, dtype=bool)  # changed by a transition that may fire
    touched[sp.csc_matrix(sn.incidence[:, fires]).indices] = True
    if sn.reset is not None and sn.reset.nnz:
        touched[sp.csc_matrix(sn.reset[:, fires]).indices] = True
    if not touched.all():
        v.stable_known = True
        sources["stable_marking"] = ("structure: no transition that may fire changes the places "
                                     + _some([p.id for p, k in zip(net.places, touched) if not k]))
    return fires


def _some(ids: list[str]) -> str:
    """The first :data:`MAX_WITNESSES` of ``ids``, and how many more."""
    more = len(ids) - MAX_WITNESSES
    return ", ".join(ids[:MAX_WITNESSES]) + (f" and {more:,} more" if more > 0 else "")


def _fired_seen(net: PetriNet, sn: SparseNet, space: StateSpace, seconds: float = 5.0,
                block_bytes: int = 1 << 26) -> np.ndarray:
    """(|T|,) bool: the transitions that label an edge of the explored part (``space.fired``, or
    its kept edges); when its edges were counted, not kept, also those enabled in one of its
    markings, the ones not expanded included (each is reachable, so they can fire): found in blocks
    of markings (temporaries below about ``block_bytes``), each block asked only about the
    transitions not seen yet, within ``seconds`` (the rest stay False: not seen)."""
    n_t = len(net.transitions)
    seen = np.zeros(n_t, dtype=bool) if space.fired is None else space.fired.copy()
    if space.edges_kept:
        if space.fired is None:
            seen[np.unique(space.transition)] = True
        return seen
    start = time.monotonic()
    block = max(1, block_bytes // max(8 * (len(net.places) + n_t), 1))
    for lo in range(0, space.n_states, block):
        if seen.all():
            break
        rows = space.states[lo:lo + block]
        left = np.flatnonzero(~seen)
        if left.size > 64:
            seen |= enabled_mask(net, rows).any(axis=0)
        else:
            for t in left.tolist():
                seen[t] = bool(_enabled_one(sn, rows, t).any())
        if seen.all() or time.monotonic() - start > seconds:
            break
    return seen


def _partial_from_projection(v: _Partial, net: PetriNet, sn: SparseNet, st: _Structure,
                             analyse_small: Callable[[PetriNet], Analysis]) -> None:
    """When the growth is in record-only places (no transition reads them), liveness, deadlocks and
    reversibility of the net without them (same enabled transitions in every marking)."""
    sources, notes = st.sources, st.notes
    record = record_only_places(net)
    growth_is_recorded = v.bounded is not False or (bool(v.unbounded) and set(v.unbounded) <= set(record))
    if record and len(record) < len(net.places) and growth_is_recorded:
        projection = analyse_small(without_places(net, record))
        if projection.complete and projection.liveness is not None:
            # record-only places never change what is enabled: liveness and deadlocks carry over
            v.levels, v.quasi, v.live = projection.liveness, projection.quasi_live, projection.live
            v.deadlock = projection.deadlock
            v.deadlocks = list(projection.deadlocks)
            # the projection of a path is a path; the record places come back only if never written
            post = sp.csr_matrix(sn.post)
            writers = {int(t) for p in record for t in post.indices[post.indptr[net.place_index[p]]:
                                                                   post.indptr[net.place_index[p] + 1]]}
            written = any((projection.liveness or {}).get(net.transitions[t].id, 0) > 0 for t in writers)
            v.reversible = bool(projection.reversible) and not written
            for key in ("deadlock", "quasi_live", "live", "reversible"):
                sources[key] = "reachability graph of the net without its record-only places"
            notes.append(f"liveness, deadlocks and reversibility come from the net without its record-only "
                         f"places ({', '.join(record)}), which has the same enabled transitions in every marking "
                         "and a finite reachability graph")
            v.projection = projection
    if set(v.unbounded) & set(record):
        v.reversible = False  # a record-only place never loses tokens: once it has grown, M0 is out of reach
        sources["reversible"] = "a record-only place grows for ever"
    if v.projection is None and v.levels is None:
        notes.append("liveness and reversibility need the whole reachability graph and were not decided" if v.live is None
                     else "reversibility needs the whole reachability graph and was not decided")


def _yield_cpus() -> None:
    """Lower the calling thread's scheduling priority by :data:`_BESIDE_NICE` (Linux, where a
    thread's id is a scheduling entity of its own; elsewhere, or when refused, nothing changes).
    Beside a race that keeps both CPUs busy, the search at the same priority slowed the symbolic
    engine by a fifth to a half (Sudoku-PT-AN04: 57.5 s before the search ran beside it, 68.3 s
    after; Angiogenesis-PT-10: 15.7 s, 22.9 s); at this increment, 63.3 s and 17.3 s, and the
    search still answers first where it did (docs/BENCHMARKS.md)."""
    lower_priority(threading.get_native_id(), _BESIDE_NICE)


class _Beside:
    """The explicit search of the automatic engine, run on to ``max_states`` in a thread, beside the
    symbolic engine once it has passed the explicit share (two CPUs or more: :func:`analyse`).

    It starts before the symbolic engine: :meth:`wait_share` returns when it has found ``share``
    markings (checked every ``min(share, 65,536)`` expanded markings), or searched for
    :data:`AUTO_PROBE_SECONDS` (:attr:`timed_out`), or when it has ended
    (complete, or stopped by its memory), so the share's markings are searched once, not by a probe
    and again by the search beside (``share`` 0: at once, for a net not every proven bound covers,
    whose share was searched first for a pumping witness). Then whichever completes first answers:
    the search when its graph is complete, the symbolic engine when it has the reachable set (the
    search stops then, :attr:`.symbolic.Rival.settled`). A complete graph sets
    :attr:`finished`, which stops the symbolic engine. When the symbolic engine answers, :meth:`end`
    stops the search; when it gives up, the search goes on to its limits and its graph, complete or
    not, is the explicit answer. The search has ``graph_bytes`` of the budget (half, the explicit
    search's own share; the symbolic engine has the other half meanwhile, and the whole when it
    outgrows its half: :meth:`lend`). It keeps its edges while they fit that share and then goes on
    counting them (:func:`_search_phase`), and stops at ``max_states`` at once (the level it is in
    left unfinished: a partial graph is only the fallback). It works on its own copy of the
    structure's notes (:attr:`st`), taken over if its graph is used. Nets of a few million markings
    that decision diagrams take long over are answered by the search (SafeBus-PT-06: 6,816,756
    markings, docs/BENCHMARKS.md)."""

    def __init__(self, net: PetriNet, sn: SparseNet, st: _Structure, max_states: int, graph_bytes: int,
                 share: int, progress: Callable[[int, int], None] | None,
                 phase: Callable[[str], None] | None) -> None:
        self.graph_bytes = graph_bytes
        self.max_states = max_states
        self.phase = phase
        self.st = replace(st, notes=list(st.notes))
        from coordinator.analysis.symbolic import Rival  # the symbolic engine runs next: loaded anyway

        # its lanes whose diagrams outgrow the graph yield to the search; one that shows more than
        # max_states markings reachable stops it
        self.rival = Rival(_BESIDE_NICE, phase, limit=max_states)
        self.finished = threading.Event()  # the graph is complete: the symbolic engine stops
        # the symbolic engine has the reachable set, or is done, or has shown more markings
        # reachable than the search may find: the search stops
        self.answered = self.rival.settled
        self.passed = threading.Event()  # the search found ``share`` markings, or it ended
        if share <= 0:
            self.passed.set()
        self.started = time.monotonic()
        self.timed_out = False  # the share ended by its time (AUTO_PROBE_SECONDS), not its markings
        self.found: tuple[StateSpace, CoveringWitness | None] | None = None

        def report(states: int, edges: int) -> None:
            if progress is not None:
                progress(states, edges)
            self.rival.found(states)
            if states >= share:
                self.passed.set()

        def search() -> None:
            _yield_cpus()
            try:
                found = _search_phase(net, sn, self.st, max_states, graph_bytes, report, finish_level=False,
                                      stop=self.answered, report_every=min(share or PROGRESS_STATES, PROGRESS_STATES))
                if found[0].complete:
                    self.finished.set()
                # a search cut short says nothing the other searches do not: its graph is freed now
                self.found = None if found[0].stopped_by == "stopped" else found
            except Exception:
                # e.g. a count beyond 31 bits: nothing found here; analyse runs the search again
                # (as the probe or, if the symbolic engine gives up, over its whole limit), which
                # meets the same error and reports it
                self.found = None
            finally:
                self.passed.set()

        self.thread = threading.Thread(target=search, name="petrobot-explicit", daemon=True)
        self.thread.start()

    def wait_share(self) -> bool:
        """Wait (Ctrl-C stays possible) until the search has found its share of markings, run its
        share of time, or ended;
        True if it goes on (the symbolic engine starts beside it: a phase line says so), False if it
        ended (:attr:`found`: its graph, complete or stopped by its memory; None if it failed)."""
        while not self.passed.wait(0.2):
            if time.monotonic() - self.started >= AUTO_PROBE_SECONDS:
                self.timed_out = True
                break
        if not self.thread.is_alive() or self.finished.is_set():
            self.end(stop=False)
            return False
        if self.phase is not None:
            self.phase(f"explicit: the search goes on beside the symbolic engine, up to {self.max_states:,} markings "
                       f"within {self.graph_bytes / 2**30:.2f} GiB")
        return True

    def lend(self) -> int:
        """The symbolic engine outgrew its half of the budget: the search is stopped (its graph
        dropped) and its share handed over, bytes; 0 if its graph is complete (the symbolic engine
        is being stopped then). A reachable set that outgrows half the budget is seldom one the
        search completes (SmallOperatingSystem-PT-MT1024DC0512: 7.7e12 markings, 3.6 GiB)."""
        if self.finished.is_set():
            return 0
        self.end(stop=True)
        if self.finished.is_set():
            return 0
        self.found = None
        return self.graph_bytes

    def end(self, stop: bool) -> None:
        """Wait for the search (Ctrl-C stays possible), stopped first if ``stop`` (the symbolic
        engine answered); else it goes on to its limits."""
        if stop:
            self.answered.set()
        while self.thread.is_alive():
            self.thread.join(0.2)


def _symbolic_phase(net: PetriNet, sn: SparseNet, st: _Structure, budget: int, lp_seconds: float, seconds: float,
                    phase: Callable[[str], None] | None, reason: str, started: float,
                    stop: threading.Event | None = None, borrow: Callable[[], int] | None = None,
                    seen: np.ndarray | None = None, seen_states: int = SEEN_STATES,
                    rival: Rival | None = None) -> Analysis:
    """The analysis from the symbolic engine (:mod:`.symbolic`): the reachable set as a decision
    diagram over the proven place bounds, every count exact. Liveness levels (L1 vs L3), home
    states and the effectiveness of conflicts need the graph and stay undecided. Reversibility
    and liveness are worked on until :data:`~.symbolic.ANSWER_SECONDS` after ``started`` (the
    analysis's start, ``time.monotonic()``: the LPs and the explicit search before count too).
    ``stop``: another thread's event that stops the engine; ``borrow``: what frees more memory
    for it when it outgrows ``budget`` (:func:`.symbolic.analyse_symbolic`); ``seen``: (|P|,) the
    largest count of each place the explicit search saw, for levels guessed from them when the proven
    bounds make them too wide or some place has none (none: an explicit search of ``seen_states``
    markings is run then);
    ``rival``: the explicit search beside the engine, to which its lanes may yield (:class:`.symbolic.Rival`).

    Raises:
        AnalysisError: a place without a proven bound whose levels guessed from the counts seen a
            firing still leaves (the net may be unbounded: :func:`.symbolic.analyse_symbolic`), the
            engine's time or memory budget, or ``stop`` set before the reachable set was complete.
    """
    # small semiflows for the diagram's groups and order, skipping the places no semiflow covers;
    # each also bounds its places (y·M = y·M0, so M(p) ≤ ⌊y·M0 / y_p⌋): then only the places they
    # leave above one token get the state equation's LP of their own (Philosophers-PT-000500: the
    # cover bounds its 2,500 places by 1, which 2,500 LPs would take 5 s to say again; where they
    # do not, as NeoElection-PT-4's 483 places, the LPs lower them)
    from coordinator.analysis import jit

    jit.configure()  # numba's cache directory, before the kernel (and numba) is imported
    from coordinator.analysis.mdd_order import MAX_LOCAL
    from coordinator.analysis.symbolic import ANSWER_SECONDS, analyse_symbolic

    # the 0/1 semiflows a weighted one hides too, where they fit on one level (lp.semiflow_cover)
    flows = lp.semiflow_cover(sn, seconds=min(lp_seconds, 3.0), spread=MAX_LOCAL,
                              covered=None if st.psup.covered is None else ~st.psup.covered)
    _, upper = _upper_bounds(sn, st, lp_seconds, np.asarray(sn.m0, dtype=np.int64), more=flows, lp_above=1)

    def counts() -> np.ndarray:
        if seen is not None:
            return seen
        probe = explore(net, max_states=seen_states, max_bytes=budget // 4, bounds=_search_bounds(st),
                        finish_level=False, edges=False)
        return probe.seen_counts()

    r = analyse_symbolic(net, upper, flows=flows, max_bytes=budget, seconds=seconds, progress=phase,
                         answer_seconds=max(1.0, ANSWER_SECONDS - (time.monotonic() - started)), stop=stop,
                         borrow=borrow, seen=counts, rival=rival)
    ids = [p.id for p in net.places]
    tids = [t.id for t in net.transitions]
    notes = list(st.notes)
    sources = dict(st.sources)
    how = f"symbolic reachable set ({r.levels} levels, {r.nodes:,} decision-diagram nodes, by {r.method})"
    for key in ("bounded", "place_bounds", "max_token_in_place", "max_token_per_marking", "one_safe", "deadlock",
                "quasi_live", "stable_marking"):
        sources[key] = how
    if r.live is not None:
        sources["live"] = how + ", backward reachability"
    if r.reversible is not None:
        sources["reversible"] = how + ", backward reachability"
    deadlocks: list[Deadlock] = []
    if r.deadlock_marking is not None and r.deadlock_sequence is not None:
        deadlocks.append(Deadlock(marking=r.deadlock_marking, firing_sequence=r.deadlock_sequence))
    elif r.deadlock_marking is not None:
        notes.append(f"a dead marking: {r.deadlock_marking}; its firing sequence was not traced")
    dead = [tids[t] for t in np.flatnonzero(~r.fireable)]
    if dead:
        notes.append("dead transitions (L0): " + ", ".join(dead))
    undecided = [tids[t] for t, v in enumerate(r.live_transitions.tolist()) if v is None]
    if r.live is False and undecided and len(undecided) < len(tids):
        notes.append("live transitions (L4): " + (", ".join(tids[t] for t, v in enumerate(r.live_transitions.tolist())
                                                             if v is True) or "none"))
    notes.append("the symbolic engine gives the number of markings and edges, deadlocks, quasi-liveness, bounds, "
                 "liveness and reversibility; the liveness level of each transition (L1/L3), home states and the "
                 "effectiveness of conflicts need the explicit graph and are not given")
    notes.extend(r.notes)
    conflicts, _ = _conflicts(net, None)
    stable = [ids[p] for p in np.flatnonzero(r.stable)]
    top = int(r.place_bounds.max(initial=0))
    return Analysis(
        net=net, space=None, coverability=None, states=r.states, edges=r.edges, complete=True, bounded=True,
        place_bounds={pid: int(b) for pid, b in zip(ids, r.place_bounds)}, unbounded_places=[], covering=None,
        max_token_in_place=top, max_token_per_marking=r.max_token_per_marking, one_safe=top <= 1,
        deadlock=r.deadlock, deadlocks=deadlocks, n_deadlocks=r.n_deadlocks, liveness=None,
        quasi_live=bool(r.fireable.all()), live=r.live, reversible=r.reversible, home_states=None,
        home_marking_is_home=None, stable_places=stable, p_invariants=st.pinv, t_invariants=st.tinv,
        conservative=st.psup.all_covered, consistent=st.tsup.all_covered, conflicts=conflicts, notes=notes,
        sources=sources, structural=st.structural, exact_bounds=list(ids), engine="symbolic",
        engine_reason=reason,
    )


def _without_reset_results(net: PetriNet, sn: SparseNet, pinv: Invariants, tinv: Invariants, psup: Support,
                           tsup: Support, notes: list[str],
                           sources: dict[str, str]) -> tuple[Invariants, Invariants, Support, Support]:
    """What the structural results of C still say on a net with reset arcs (module docstring): the
    P-semiflows avoiding reset places, the T-semiflows avoiding transitions with reset arcs, and
    conservative / consistent left undecided, each with a note."""
    reset = sn.reset
    assert reset is not None
    rplaces = sn.reset_places()
    rtrans = np.flatnonzero(np.diff(reset.indptr) > 0)
    names = ", ".join(net.places[int(p)].id for p in rplaces)
    keep_p = ~pinv.vectors[:, rplaces].any(axis=1) if pinv.vectors.size else np.zeros(0, dtype=bool)
    keep_t = ~tinv.vectors[:, rtrans].any(axis=1) if tinv.vectors.size else np.zeros(0, dtype=bool)
    dropped_p = int((~keep_p).sum())
    dropped_t = int((~keep_t).sum())
    notes.append(f"the net has reset arcs (emptying {names}): its incidence matrix leaves them out, so the "
                 "structural results are those of the net without them, read with care: upper bounds from the "
                 "state equation and the P-semiflows still hold (a reset only removes tokens), but no weighted "
                 "token count through a reset place is conserved")
    if dropped_p:
        notes.append(f"{dropped_p} P-semiflow(s) of the net without reset arcs hold a reset place: they only bound "
                     "the net (y·M <= y·M0) and are not listed as P-invariants")
    if dropped_t:
        notes.append(f"{dropped_t} T-semiflow(s) of the net without reset arcs hold a transition with a reset arc: "
                     "firing them need not return to the same marking; they are not listed as T-invariants")
    for key, sup in (("conservative", psup), ("consistent", tsup)):
        if sup.covered is not None:
            value = "yes" if sup.all_covered else "no"
            notes.append(f"{key}: not decided with reset arcs (the net without them: {value})")
        sources.pop(key, None)
    pinv = replace(pinv, vectors=pinv.vectors[keep_p] if pinv.vectors.size else pinv.vectors)
    tinv = replace(tinv, vectors=tinv.vectors[keep_t] if tinv.vectors.size else tinv.vectors)
    return pinv, tinv, replace(psup, covered=None), replace(tsup, covered=None)


def _omega_marking(net: PetriNet, row: np.ndarray) -> dict[str, int]:
    return {net.places[p].id: int(row[p]) for p in np.flatnonzero(row)}


def _acyclic(tsup: Support) -> bool:
    """Whether the reachability graph has no cycle, by the state equation: a firing sequence from a
    marking back to itself fires a count vector x ≥ 0, x ≠ 0 with C·x = 0, a T-semiflow; the LP
    (:func:`.lp.consistent`) found no transition in the support of one, with its certificate checked
    exactly. Inhibitor arcs only restrict which sequences fire, so the argument stands; a net with
    reset arcs has no such support (:func:`_without_reset_results`). Murata 1989, section IV-B."""
    return tsup.covered is not None and tsup.certified and not tsup.covered.any()


def _from_graph(net: PetriNet, space: StateSpace, pinv: Invariants, tinv: Invariants, psup: Support,
                tsup: Support, structural: Structural, notes: list[str], sources: dict[str, str],
                budget: int) -> Analysis:
    per_place, least, totals_max = space.extremes()
    dead = space.deadlocks()
    deadlocks = [Deadlock(marking=space.marking(int(i)).to_dict(), firing_sequence=space.firing_sequence(int(i)))
                 for i in dead[:MAX_WITNESSES]]
    for key in ("bounded", "place_bounds", "max_token_in_place", "max_token_per_marking", "one_safe", "deadlock",
                "stable_marking"):
        sources[key] = "reachability graph"
    need = graph_pass_bytes(space.n_states, space.n_edges)
    work = space.edges_kept and space.nbytes + need <= budget
    acyclic = not work and _acyclic(tsup) and space.fired is not None
    # edges too many for scipy's passes: a compiled pass over them; not kept: the components from
    # the markings, each marking's successors computed again (none on a graph without cycles)
    implicit = not work and not acyclic and space.nbytes + implicit_pass_bytes(space.n_states) <= budget
    liveness: dict[str, int] | None = None
    quasi: bool | None = None
    live: bool | None = None
    reversible: bool | None = None
    home_count: int | None = None
    home_is_home: bool | None = None
    if work or implicit or acyclic:
        if acyclic:  # every component one marking; the terminal ones the deadlocks
            assert space.fired is not None
            levels, labels = space.fired.astype(np.int64), np.arange(space.n_states, dtype=np.int32)
            terminal = np.zeros(space.n_states, dtype=bool)
            terminal[dead] = True
        else:
            levels, labels, terminal = space.implicit_liveness() if implicit else liveness_levels(space)
        n_terminal = int(terminal.sum())
        home_count = int(np.count_nonzero(terminal[labels])) if n_terminal == 1 else 0
        if net.home_marking is not None:
            try:
                h = space.index_of(net.home_marking)
                home_is_home = bool(n_terminal == 1 and terminal[labels[h]])
            except KeyError:
                home_is_home = False
        liveness = {t.id: int(lv) for t, lv in zip(net.transitions, levels)}
        quasi, live = bool((levels >= 1).all()), bool((levels == 4).all())
        reversible = bool(labels.size == 0 or (labels == labels[0]).all())  # one component: M0 reached from all
        how = "" if not implicit else (", a compiled pass over its edges" if space.edges_kept
                                        else ", its edges computed again from the markings")
        if acyclic:
            how = ", without cycles since no T-semiflow exists (state equation)"
        for key in ("quasi_live", "live", "reversible"):
            sources[key] = "reachability graph" + how
        if implicit and space.edges_kept:
            notes.append(f"liveness and reversibility: the {space.n_edges:,} edges need about {need / 2**30:.1f} GiB "
                         "in scipy's passes, over the memory budget, so the strongly connected components were found "
                         "by a compiled pass over the edges; the robotic recovery check, which needs those passes, "
                         "was skipped")
        elif implicit:
            notes.append("liveness and reversibility: the edges were not kept, so the strongly connected components "
                         "were found from the markings, each marking's successors computed again; the robotic "
                         "recovery check, which needs the edges, was skipped")
        elif acyclic:
            notes.append("liveness and reversibility: the net has no T-semiflow (certified by the state equation), "
                         "so no firing sequence returns to a marking and every strongly connected component of the "
                         "graph is one marking; no pass over the graph was needed, and the robotic recovery check, "
                         "which needs its edges, was skipped")
    else:
        if space.edges_kept:
            used = np.zeros(len(net.transitions), dtype=bool)
            used[space.transition] = True
            quasi = bool(used.all())
            sources["quasi_live"] = "reachability graph"
        notes.append(f"liveness, reversibility and the robotic recovery check were skipped: on a graph of "
                     f"{space.n_edges:,} edges they need about {need / 2**30:.1f} GiB beyond the graph's "
                     f"{space.nbytes / 2**30:.1f} GiB, over the memory budget of {budget / 2**30:.1f} GiB")
    stable = np.flatnonzero(least == per_place) if space.n_states else np.arange(len(net.places))
    conflicts, finished = _conflicts(net, space, on_edges=work)
    if not finished:
        notes.append("structural conflicts: the effectiveness check ran out of time; some are left undecided")
    return Analysis(
        net=net, space=space, coverability=None, states=space.n_states, edges=space.n_edges, complete=True,
        bounded=True, place_bounds={p.id: int(b) for p, b in zip(net.places, per_place)}, unbounded_places=[],
        covering=None, max_token_in_place=int(per_place.max(initial=0)),
        max_token_per_marking=totals_max, one_safe=bool(per_place.max(initial=0) <= 1),
        deadlock=bool(dead.size), deadlocks=deadlocks, n_deadlocks=int(dead.size),
        liveness=liveness, quasi_live=quasi, live=live,
        reversible=reversible, home_states=home_count, home_marking_is_home=home_is_home,
        stable_places=[net.places[int(p)].id for p in stable],
        p_invariants=pinv, t_invariants=tinv, conservative=psup.all_covered, consistent=tsup.all_covered,
        conflicts=conflicts, notes=notes, sources=sources, structural=structural,
        exact_bounds=[p.id for p in net.places], graph_work_done=work,
    )
