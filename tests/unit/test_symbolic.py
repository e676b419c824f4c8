"""The symbolic engine (coordinator.analysis.symbolic) against the explicit search and the contest's answers."""

from __future__ import annotations

import contextlib
import csv
import os
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from analysis_nets import dekker, make_net, philosophers_arcs

from coordinator.analysis import lp
from coordinator.analysis.matrices import SparseNet, sparse_net
from coordinator.analysis.mdd_order import Encoding, Events
from coordinator.analysis.statespace import explore
from coordinator.analysis.structure import Analysis, analyse
from coordinator.analysis.symbolic import SymbolicResult, _Store, analyse_symbolic
from coordinator.errors import AnalysisError
from coordinator.net import Marking, PetriNet
from coordinator.netfile.pnml import load_pnml
from tests.unit.mcc_models import MCC, ROOT

SCALE = ROOT / "tests" / "data" / "mcc-scale"


def rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "oracle.tsv").open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def proven_bounds(net: PetriNet) -> tuple[np.ndarray, list[np.ndarray]]:
    sn = sparse_net(net)
    pb = lp.place_bounds(sn, seconds=10.0)
    return pb.bounds, lp.semiflow_cover(sn, seconds=3.0)


def columns(r: SymbolicResult) -> dict[str, object]:
    top = int(r.place_bounds.max(initial=0))
    return {"states": r.states, "edges": r.edges, "max_token_in_place": top,
            "max_token_per_marking": r.max_token_per_marking, "deadlock": r.deadlock, "live": r.live,
            "quasi_live": bool(r.fireable.all()), "one_safe": top <= 1, "stable_marking": bool(r.stable.any())}


def expected(row: dict[str, str]) -> dict[str, object]:
    return {k: (v == "true" if v in ("true", "false") else int(v)) for k, v in row.items() if k != "model"}


def replays_to(net: PetriNet, sequence: list[str], marking: dict[str, int]) -> bool:
    m = net.initial_marking
    for t in sequence:
        assert t in net.enabled_transitions(m), f"{t} is not enabled on the way to the deadlock"
        m = net.fire(m, t)
    return m == Marking(marking) and not net.enabled_transitions(m)


def assert_agrees_with_oracle(folder: Path, row: dict[str, str]) -> None:
    net = load_pnml(folder / row["model"] / "model.pnml")
    bounds, flows = proven_bounds(net)
    # the counts a short explicit search sees, for places without a proven bound (Murphy-PT-D1N010)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0, seen=lambda: explore(
        net, max_states=100_000, finish_level=False, edges=False).seen_counts())
    assert columns(r) == expected(row)
    if r.deadlock:
        assert r.deadlock_sequence is not None and r.deadlock_marking is not None
        assert replays_to(net, r.deadlock_sequence, r.deadlock_marking)


@pytest.mark.parametrize("row", rows(MCC), ids=lambda r: r["model"])
def test_every_mcc_model_in_tests_data_agrees_with_its_oracle_on_all_nine_columns(row: dict[str, str]) -> None:
    assert_agrees_with_oracle(MCC, row)


FAST_SCALE = ["HouseConstruction-PT-00010", "Eratosthenes-PT-050", "CircularTrains-PT-048"]


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("row", [r for r in rows(SCALE) if r["model"] in FAST_SCALE], ids=lambda r: r["model"])
def test_the_fastest_scale_models_agree_with_their_oracle_beyond_explicit_reach(row: dict[str, str]) -> None:
    assert_agrees_with_oracle(SCALE, row)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_neoelection_pt_3_has_its_published_974325_markings() -> None:
    net = load_pnml(ROOT / "tests" / "data" / "mcc-large" / "NeoElection-PT-3" / "model.pnml")
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=200.0)
    assert r.states == 974_325 and int(r.place_bounds.max()) == 1
    assert r.deadlock and r.deadlock_sequence is not None and r.deadlock_marking is not None
    assert replays_to(net, r.deadlock_sequence, r.deadlock_marking)


def generated_net(seed: int) -> PetriNet:
    """A random net: half the seeds conservative (tokens move, state machine like, so P-semiflows
    group places), half with weighted arcs, inhibitor arcs and token sources held by inhibitors."""
    rng = np.random.default_rng(seed)
    n_p = int(rng.integers(3, 8))
    places = [f"p{i}" for i in range(n_p)]
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    inhibitors: dict[str, dict[str, int]] = {}
    conservative = seed % 2 == 0
    for t in range(int(rng.integers(3, 10))):
        if conservative:
            k = int(rng.integers(1, 3))
            ins = rng.choice(places, size=k, replace=False)
            outs = rng.choice(places, size=k, replace=False)
            transitions[f"t{t}"] = ({str(p): 1 for p in ins}, {str(p): 1 for p in outs})
        else:
            ins = rng.choice(places, size=int(rng.integers(0, 3)), replace=False)
            outs = rng.choice(places, size=int(rng.integers(0, 3)), replace=False)
            transitions[f"t{t}"] = ({str(p): int(rng.integers(1, 3)) for p in ins},
                                    {str(p): int(rng.integers(1, 3)) for p in outs})
            for p in outs:  # keep every place that grows bounded: an inhibitor arc on it
                inhibitors.setdefault(f"t{t}", {})[str(p)] = int(rng.integers(2, 5))
        if rng.random() < 0.3:
            inhibitors.setdefault(f"t{t}", {})[str(rng.choice(places))] = int(rng.integers(1, 4))
    marking = {p: int(rng.integers(0, 3)) for p in places}
    return make_net(f"generated-{seed}", marking, transitions, places=tuple(places), inhibitors=inhibitors)


@pytest.mark.parametrize("seed", range(40))
def test_generated_nets_agree_with_the_explicit_search_on_every_property(seed: int) -> None:
    net = generated_net(seed)
    a = analyse(net, max_states=200_000)
    assert a.complete and a.liveness is not None
    per_place = np.array([a.place_bounds[p.id] for p in net.places], dtype=np.int64)
    rng = np.random.default_rng(1000 + seed)
    bounds, flows = proven_bounds(net)
    # any valid upper bound will do: the LP's where it has one, else the true bound plus some slack
    loose = per_place + rng.integers(0, 3, size=per_place.size)
    bounds = np.where((bounds >= per_place) & (bounds < 40), bounds, loose)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=30.0)
    assert r.states == a.states and r.edges == a.edges
    assert r.deadlock == a.deadlock and r.n_deadlocks == a.n_deadlocks
    assert r.place_bounds.tolist() == per_place.tolist()
    assert r.max_token_per_marking == a.max_token_per_marking
    assert [net.places[int(i)].id for i in np.flatnonzero(r.stable)] == a.stable_places
    assert r.fireable.tolist() == [a.liveness[t.id] >= 1 for t in net.transitions]
    assert r.reversible == a.reversible
    assert r.live == a.live
    for decided, t in zip(r.live_transitions.tolist(), net.transitions):  # None: undecided, never a guess
        assert decided is None or decided == (a.liveness[t.id] == 4)
    if r.deadlock:
        assert r.deadlock_sequence is not None and r.deadlock_marking is not None
        assert replays_to(net, r.deadlock_sequence, r.deadlock_marking)


def shortest_to_a_deadlock(net: PetriNet) -> int:
    """Length of a shortest firing sequence from M0 to a dead marking (plain breadth-first search)."""
    layer, seen, depth = [net.initial_marking], {net.initial_marking}, 0
    while layer:
        if any(not net.enabled_transitions(m) for m in layer):
            return depth
        nxt = []
        for m in layer:
            for t in net.enabled_transitions(m):
                m2 = net.fire(m, t)
                if m2 not in seen:
                    seen.add(m2)
                    nxt.append(m2)
        layer, depth = nxt, depth + 1
    raise AssertionError("no dead marking")


def generated_encoding(seed: int) -> tuple[PetriNet, Analysis, SparseNet, Encoding]:
    """A generated net (the odd seeds with inhibitor arcs), its explicit analysis, sparse form and
    encoding, on the LP's bounds where they hold and are small, else the true ones."""
    from coordinator.analysis.mdd_order import encode

    net = generated_net(seed)
    a = analyse(net, max_states=200_000)
    bounds, flows = proven_bounds(net)
    per_place = np.array([a.place_bounds[p.id] for p in net.places], dtype=np.int64)
    bounds = np.where((bounds >= per_place) & (bounds < 40), bounds, per_place)
    sn = sparse_net(net)
    return net, a, sn, encode(sn, bounds, flows, seconds=5.0, seed=0)


def counts_per_transition(store: _Store, single: Events, reach: int, states: int) -> list[int]:
    """Per event of ``single``: the markings of ``reach`` enabling it, counted as analyse_symbolic counts them."""
    store.count(reach, at_most=float(states) * max(1, single.n_events))
    return store.enabled_counts(reach, single)


@pytest.mark.parametrize("seed", range(40))
def test_the_breadth_first_trace_to_a_deadlock_is_a_shortest_firing_sequence(seed: int) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events, touched_places
    from coordinator.analysis.symbolic import _bfs_sequence, _dead, _Explicit, _Store

    net, a, sn, enc = generated_encoding(seed)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach)
    counts = counts_per_transition(store, single, reach, states)
    free = enc.free(touched_places(sn)).any()  # a transition enabled everywhere: no dead marking
    dead = mk.EMPTY if free else _dead(store, fwd, single, reach, counts, states)
    assert store.count(dead) == a.n_deadlocks
    if not a.deadlock:
        return
    found = _bfs_sequence(store, _Explicit(sn, enc), net, fwd, reach, dead)
    assert found is not None
    seq, end = found
    assert replays_to(net, seq, {p.id: int(end[i]) for i, p in enumerate(net.places) if end[i]})
    assert len(seq) == shortest_to_a_deadlock(net)


def event_functions(ev: Events) -> list[tuple[int, int, tuple[bytes | None, ...]]]:
    """Each event's top and bottom level and its local function on every level between (bytes of
    the function's values, None where it leaves the level alone): what the kernel reads."""
    out = []
    for e in range(ev.n_events):
        fs = [int(ev.slot[j]) for j in range(int(ev.slot_ptr[e]), int(ev.slot_ptr[e + 1]))]
        out.append((int(ev.top[e]), int(ev.bot[e]),
                    tuple(None if f < 0 else ev.fn[ev.fn_ptr[f]:ev.fn_ptr[f + 1]].tobytes() for f in fs)))
    return out


@pytest.mark.parametrize("seed", range(12))
def test_events_built_like_the_forward_ones_take_their_functions_again_and_store_a_shared_one_once(
        seed: int) -> None:
    from coordinator.analysis.mdd_order import encode, events

    _, _, sn, enc = generated_encoding(seed)
    fwd = events(sn, enc, merge=True)
    for kw in ({}, {"merge": True}, {"inverse": True, "merge": True}):
        if kw.get("inverse") and sn.n_resets:
            continue
        fresh, like = events(sn, enc, **kw), events(sn, enc, **kw, like=fwd)
        assert event_functions(like) == event_functions(fresh)
        assert like.members == fresh.members
        assert like.local is fwd.local and fresh.local is not fwd.local
    # the transitions of a coloured net share their local functions: the single events store each once
    net = make_net("philosophers", *philosophers_arcs(12))
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    enc = encode(sn, bounds, flows, seconds=1.0)
    single = events(sn, enc)
    slots = single.slot[single.slot >= 0]
    assert np.unique(slots).size == single.fn_ptr.size - 1 < slots.size
    assert event_functions(single) == event_functions(events(sn, enc, like=events(sn, enc, merge=True)))


@pytest.mark.parametrize("seed", range(10))
def test_saturation_s_loop_lists_per_value_the_events_of_the_level_enabled_on_it(seed: int) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events

    _, _, sn, enc = generated_encoding(seed)
    ev = events(sn, enc, merge=True)
    top, _, slot_ptr, slot, fn_ptr, fn, by_top_ptr, by_top = ev.tables()
    dom_ptr, byval_ptr, byval = mk._by_value(enc.dom, slot_ptr, slot, fn_ptr, fn, by_top_ptr, by_top, True)
    for k in range(enc.n_levels):
        assert dom_ptr[k + 1] - dom_ptr[k] == enc.dom[k]
        for i in range(int(enc.dom[k])):
            x = int(dom_ptr[k] + i)
            want = [int(e) for e in by_top[by_top_ptr[k]:by_top_ptr[k + 1]]
                    if fn[fn_ptr[slot[slot_ptr[e]]] + i] >= 0]
            assert byval[byval_ptr[x]:byval_ptr[x + 1]].tolist() == want
    assert mk._by_value(enc.dom, slot_ptr, slot, fn_ptr, fn, by_top_ptr, by_top, False)[2].size == 0


@pytest.mark.parametrize("seed", range(40))
def test_the_dead_markings_in_one_pass_are_those_restricted_event_by_event_and_too_many_conditions_fall_back(
        seed: int) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events, touched_places
    from coordinator.analysis.symbolic import _dead, _dead_by_events, _Store

    net, a, sn, enc = generated_encoding(seed)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 64 << 20)  # one store: equal sets are the same node
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach)
    counts = counts_per_transition(store, single, reach, states)
    if enc.free(touched_places(sn)).any():  # a transition that reads no level: enabled everywhere
        return
    by_events = _dead_by_events(store, fwd, single, reach, counts)
    assert store.count(by_events) == a.n_deadlocks
    if states in counts:  # an event enabled in every marking: no pass at all
        assert _dead(store, fwd, single, reach, counts, states) == mk.EMPTY == by_events
        return
    assert _dead(store, fwd, single, reach, counts, states) == by_events
    assert _dead(store, fwd, single, reach, counts, states, max_sets=1) == by_events  # WIDE, then tables twice as large
    assert _dead(store, fwd, single, reach, counts, states, max_sets=1, table_bytes=0) == by_events  # WIDE, by events


@pytest.mark.parametrize("seed", range(0, 40, 3))
def test_the_restriction_event_by_event_stopped_at_the_end_of_each_slice_resumes_to_the_same_dead_markings(
        seed: int) -> None:
    # slices of no time at all: each makes one restriction and stops at its first look at the clock;
    # with the store's cache cleared between them, they hold at the end what one run holds
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _ByEvents, _dead_by_events, _Store

    _net, _a, sn, enc = generated_encoding(seed)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    counts = counts_per_transition(store, single, reach, store.count(reach))
    whole = _dead_by_events(store, fwd, single, reach, counts)
    outer = time.monotonic() + 600.0
    mk.set_watch(outer, None, None)
    slices = 0
    try:
        sliced = _ByEvents(store, fwd, single, reach)
        while not sliced.run(counts, 0.0):
            mk.clear_cache(store.arrays)  # as a pass of MODE_DEAD between two slices does
            slices += 1
            assert slices <= fwd.n_events
            assert mk.watch() == (outer, None, None)  # the watch before each slice, restored after it
    finally:
        mk.set_watch(None, None)
    assert sliced.dead == whole
    assert slices > 0 or whole == mk.EMPTY or fwd.n_events <= 1


def test_the_conditions_pending_on_a_path_are_shared_by_the_events_of_one_place_below() -> None:
    # a controller place read by 40 stations' transitions, each also reading a place of its own:
    # every path down has the controller's one condition pending, not one per station
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _dead_by_events, _Store

    n = 40
    marking = {f"idle{i}": 1 for i in range(n)} | {"go": 1}
    transitions = {f"start{i}": ({f"idle{i}": 1, "go": 1}, {f"busy{i}": 1}) for i in range(n)}
    transitions |= {f"end{i}": ({f"busy{i}": 1}, {f"done{i}": 1, "go": 1}) for i in range(n)}
    net = make_net("stations", marking, transitions)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 256 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach)
    counts = counts_per_transition(store, single, reach, states)
    dz = mk.dead_tables(store.dom, fwd.top, fwd.bot, fwd.slot_ptr, fwd.slot, fwd.fn_ptr, fwd.fn)
    assert dz is not None
    dead = store.call(mk.MODE_DEAD, fwd, reach, dz=dz)
    sets_met = int(dz[9][0])
    mk.clear_cache(store.arrays)
    assert dead == _dead_by_events(store, fwd, single, reach, counts)
    assert store.count(dead) == 1  # every station done
    assert sets_met <= 4 * len(enc.levels)


@pytest.mark.parametrize("seed", range(40))
def test_chained_images_reach_the_sets_saturation_reaches_forward_and_backward_inside_a_constraint(seed: int) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _Store

    net, a, sn, enc = generated_encoding(seed)
    fwd, back = events(sn, enc, merge=True), events(sn, enc, inverse=True, merge=True)
    store = _Store(enc, 64 << 20)  # one store: equal sets are the same node
    reach = store.closure(fwd, store.m0)
    home = store.closure(back, store.m0, c=reach)
    for how in (mk.IMAGE_CHAIN_DEEP, mk.IMAGE_CHAIN_ROOT):  # one pass reaches a superset of one image
        step = store.call(mk.MODE_IMAGE, fwd, store.m0, arg=mk.IMAGE_EACH)
        chained = store.call(mk.MODE_IMAGE, fwd, store.m0, arg=how)
        assert store.call(mk.MODE_APPLY, fwd, step, chained, arg=mk.APPLY_DIFF) == mk.EMPTY
    store.chain = True
    assert store.closure(fwd, store.m0) == reach and store.count(reach) == a.states
    assert store.closure(back, store.m0, c=reach) == home


def counter(n: int) -> tuple[Encoding, Events]:
    """One event moving one token of ``n`` a firing: each pass of chained images fires it once on
    the set so far, so the counts 0..n take n passes and the (n + 1)-th finds nothing new."""
    from coordinator.analysis.mdd_order import encode, events

    net = make_net("counter", {"free": n}, {"take": ({"free": 1}, {"held": 1})})
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=1.0)
    return enc, events(sn, enc, merge=True)


def test_chained_images_given_a_number_of_passes_give_up_when_they_do_not_reach_their_fixed_point() -> None:
    # the race gives the first order's chaining _CHAIN_PASSES passes at most (symbolic._chained)
    from coordinator.analysis.symbolic import _CHAIN_PASSES, _NoFixedPoint

    n = _CHAIN_PASSES + 2
    enc, fwd = counter(n)
    for passes in (1, n, _CHAIN_PASSES):
        store = _Store(enc, 64 << 20)  # a store each: no images kept from the last try
        store.chain = True
        with pytest.raises(_NoFixedPoint):
            store.closure(fwd, store.m0, passes=passes)
    for passes in (n + 1, 0):  # enough, and no limit
        store = _Store(enc, 64 << 20)
        store.chain = True
        assert store.count(store.closure(fwd, store.m0, passes=passes)) == n + 1


def test_chained_images_stopped_part_way_resume_from_the_set_their_last_pass_built() -> None:
    # the counter: n + 1 passes reach the fixed point. Stopped after n - 1 and called again with
    # the same start, the closure makes the two passes left, not n + 1 from M0 again: with the
    # computed table cleared in between, it fills far fewer entries than a fresh store does
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.symbolic import _CHAIN_PASSES, _NoFixedPoint

    n = _CHAIN_PASSES + 2
    enc, fwd = counter(n)
    used = []
    for stopped_first in (True, False):
        store = _Store(enc, 64 << 20)
        store.chain = True
        if stopped_first:
            with pytest.raises(_NoFixedPoint):
                store.closure(fwd, store.m0, passes=n - 1)
            mk.clear_cache(store.arrays)
        assert store.count(store.closure(fwd, store.m0, passes=n + 1)) == n + 1
        used.append(int(store.arrays[0][mk.META_CT_USED]))
    assert used[0] * 4 < used[1]


@pytest.mark.parametrize("cpus", [n for n in (1, 2) if n <= len(os.sched_getaffinity(0))])  # the CPUs there are
def test_chaining_out_of_its_seconds_takes_turns_with_the_other_orders_and_wins_where_it_is_the_faster(
        cpus: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # Dekker's flags read by every enter (test_dekker_s_flags_..., below): chaining is the faster.
    # Given almost no time of its own (_CHAIN_SECONDS), it is not dropped but takes turns with the
    # other orders, resuming from its last pass, and is still the first done; on one CPU and on two
    from coordinator.analysis import symbolic

    monkeypatch.setattr(symbolic, "_CHAIN_SECONDS", 0.01)
    monkeypatch.setattr(symbolic, "_HEAD_START", 0.0)
    monkeypatch.setattr(symbolic, "_FIRST_SLICE", 0.25)
    n = 50
    net = dekker(n)
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    mine = os.sched_getaffinity(0)
    os.sched_setaffinity(0, sorted(mine)[:cpus])
    try:
        r = analyse_symbolic(net, bounds, flows=flows, seconds=120.0, progress=said.append)
    finally:
        os.sched_setaffinity(0, mine)
    assert any("by chaining not done within" in line and "takes turns" in line for line in said), said
    assert r.method == "chaining" and any("by chaining was the first done" in line for line in said), said
    assert r.states == 2 ** (n - 1) * (n + 2)


@pytest.mark.parametrize("seed", range(40))
def test_a_store_part_way_through_a_forward_closure_bounds_the_reachable_set_from_below_and_meets_it_at_the_end(
        seed: int) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _Store

    net, a, sn, enc = generated_encoding(seed)
    fwd = events(sn, enc, merge=True)
    store = _Store(enc, 64 << 20)
    assert store.fewest_reachable() == 1  # M0 alone
    reached = store.m0
    for _ in range(6):  # breadth-first layers: every node checked in holds reachable sub-markings
        step = store.call(mk.MODE_IMAGE, fwd, reached, arg=mk.IMAGE_EACH)
        reached = store.call(mk.MODE_APPLY, fwd, reached, step, arg=mk.APPLY_UNION)
        assert store.count(reached) <= store.fewest_reachable() <= a.states
    for chain in (False, True):
        whole = _Store(enc, 64 << 20)
        whole.chain = chain
        reach = whole.closure(fwd, whole.m0)
        assert whole.fewest_reachable() == whole.count(reach) == a.states


@pytest.mark.parametrize("seed", range(24))
def test_reversibility_on_the_order_upside_down_beside_the_later_phases_agrees_with_the_graph(seed: int) -> None:
    # the candidate the race kept, its saturation stopped part way by a deadline, or not begun
    import time

    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _Candidate, _OutOfTime, _Store, _Upside

    net, a, sn, enc = generated_encoding(seed)
    assert a.complete and a.reversible is not None
    rev = enc.reversed()
    for begun in (False, True):
        kept = _Candidate(2, rev, events(sn, rev, merge=True), _Store(rev, 64 << 20))
        if begun:
            mk.set_watch(time.monotonic() - 1.0, None)  # stopped at its first check, if it gets that far
            try:
                with contextlib.suppress(_OutOfTime):
                    kept.store.call(mk.MODE_SATURATE, kept.fwd, kept.store.m0, check_overflow=True)
            finally:
                mk.set_watch(None, None)
        said: list[str] = []
        upside = _Upside(sn, kept, 64 << 20, time.monotonic() + 60.0, None, said.append)
        upside.thread.join()
        assert upside.decided.is_set() and upside.reversible == a.reversible
        # the markings that reach M0 closed under firing (reversible), or else the reachable set resumed
        assert len(said) == 1 and said[0].startswith("symbolic: order 2, the winner's upside down: ")
        assert ("the markings that reach M0 are closed under firing" in said[0]) is (
            "its reachable set resumed" not in said[0]) and (a.reversible or "closed" not in said[0])
    upside = _Upside(sn, kept, 64 << 20, time.monotonic() + 60.0, None, lambda _text: None)
    upside.end()  # stopped (or done) and waited for
    assert not upside.thread.is_alive()


@pytest.mark.timeout(180)
def test_kanban_s_reversibility_is_decided_on_the_first_order_kept_when_its_reverse_wins_the_race() -> None:
    # Kanban-PT-00005's net with 200 tokens in each of its four stages (the contest's Kanban-PT-00200):
    # the first order reversed saturates forward in a fraction of a second and is not done backward
    # in 40 s; the first order takes about 20 s forward and a twentieth of a second backward
    from dataclasses import replace

    small = load_pnml(ROOT / "tests" / "data" / "mcc" / "Kanban-PT-00005" / "model.pnml")
    net = replace(small, initial_marking=Marking({p: 200 for p in small.initial_marking}))
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    r = analyse_symbolic(net, bounds, flows=flows, progress=said.append)
    assert r.states == 31_731_714_717_364_931_267_341 and not r.deadlock
    if any("order 2 (order 1 reversed) was the first done" in line for line in said):
        assert any("order 1, the winner's upside down: " in line for line in said)
    assert r.reversible is True and r.live is True


def reversible_or_not(reversible: bool) -> tuple[PetriNet, np.ndarray, list[np.ndarray], SparseNet, Encoding]:
    """Kanban-6 (reversible) or a net whose first firing cannot be undone (not reversible), with its
    proven bounds, P-semiflows, sparse form and an encoding for saturation."""
    from coordinator.analysis.mdd_order import encode

    net = kanban(6) if reversible else one_shot_net(4)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    return net, bounds, flows, sn, encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)


@pytest.mark.parametrize("reversible", [True, False])
def test_the_markings_that_reach_m0_closed_under_firing_show_the_net_reversible(reversible: bool) -> None:
    # symbolic._closed_home: backward from M0 without the reachable set, then one image forward
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _closed_home

    _net, _bounds, _flows, sn, enc = reversible_or_not(reversible)
    for e in (enc, enc.reversed()):
        fwd, back = events(sn, e, merge=True), events(sn, e, inverse=True, merge=True)
        assert _closed_home(e, fwd, back, 64 << 20) is reversible


def test_the_token_flow_s_order_places_the_levels_as_tokens_flow_from_the_initial_marking() -> None:
    from coordinator.analysis.mdd_order import encode

    # a → t0 → b → t1 → {c, d}; e is reached by no token: it comes last, from a second start
    net = make_net("flow", {"a": 1}, {"t0": ({"a": 1}, {"b": 1}), "t1": ({"b": 1}, {"c": 1, "d": 1}),
                                      "t2": ({"e": 1}, {"a": 1})}, places=("e", "d", "c", "b", "a"))
    sn = sparse_net(net)
    enc = encode(sn, np.ones(sn.n_places, dtype=np.int64), [], flow=True)
    names = [net.places[int(ps[0])].id for ps in enc.levels]
    assert names == ["a", "b", "d", "c", "e"] and enc.sunk == 0


@pytest.mark.parametrize("seed", range(40))
def test_the_token_flow_s_order_holds_the_markings_of_the_explicit_graph(seed: int) -> None:
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Store

    net, a, sn, _ = generated_encoding(seed)
    bounds = np.array([a.place_bounds[p.id] for p in net.places], dtype=np.int64)
    flow, plain = (encode(sn, bounds, [], flow=f) for f in (True, False))  # the same levels, another order
    assert sorted(int(p) for ps in flow.levels for p in ps) == sorted(int(p) for ps in plain.levels for p in ps)
    store = _Store(flow, 64 << 20)
    assert store.count(store.closure(events(sn, flow, merge=True), store.m0)) == a.states


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_ibmb2s565s3960_s_markings_are_counted_on_the_token_flow_s_order() -> None:
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Store

    net = load_pnml(ROOT / "tests" / "data" / "mcc-large" / "IBMB2S565S3960-PT-none" / "model.pnml")
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, flow=True)
    store = _Store(enc, 2 << 30)
    assert store.count(store.closure(events(sn, enc, merge=True), store.m0)) == 15_510_635_947_410_534
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.states == 15_510_635_947_410_534 and int(r.place_bounds.max()) == 7
    assert r.deadlock and r.deadlock_sequence is not None and r.deadlock_marking is not None
    assert replays_to(net, r.deadlock_sequence, r.deadlock_marking)


@pytest.mark.parametrize("seed", range(40))
def test_the_reversed_order_holds_the_same_markings_level_for_level_upside_down(seed: int) -> None:
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _Store

    net, a, sn, enc = generated_encoding(seed)
    rev = enc.reversed()
    back = rev.reversed()
    assert all(np.array_equal(x, y) for x, y in zip(back.levels, enc.levels))
    assert np.array_equal(back.place_level, enc.place_level) and rev.score == enc.score
    k_last = enc.n_levels - 1
    for p in range(sn.n_places):  # a place's level counts from the other end, its column stays
        assert rev.place_level[p] == (-1 if enc.place_level[p] < 0 else k_last - enc.place_level[p])
    m0 = np.asarray(sn.m0, dtype=np.int64)
    assert [rev.value_of(k, m0) for k in range(rev.n_levels)] == rev.m0.tolist() == enc.m0[::-1].tolist()
    stores = [_Store(e, 64 << 20) for e in (enc, rev)]
    reach = [s.closure(events(sn, e, merge=True), s.m0) for s, e in zip(stores, (enc, rev))]
    assert stores[0].count(reach[0]) == stores[1].count(reach[1]) == a.states
    present = [s.presence(r) for s, r in zip(stores, reach)]
    for k in range(enc.n_levels):  # the same local markings occur on each level
        mine = present[0][stores[0].dom_ptr[k]:stores[0].dom_ptr[k + 1]]
        other = present[1][stores[1].dom_ptr[k_last - k]:stores[1].dom_ptr[k_last - k + 1]]
        assert np.array_equal(mine, other)


def kanban(n: int) -> PetriNet:
    """The MCC's Kanban net (tests/data/mcc) with n tokens in each of its four stages."""
    net = load_pnml(MCC / "Kanban-PT-00005" / "model.pnml")
    return net.with_initial_marking({f"P{i}": n for i in range(1, 5)})


def advised_huge(address: int) -> bool:
    """Whether the mapping of this process holding ``address`` is advised for transparent huge pages
    (``hg`` among its ``VmFlags`` in /proc/self/smaps: ``madvise(MADV_HUGEPAGE)``)."""
    inside = False
    with open("/proc/self/smaps", encoding="ascii") as fh:
        for line in fh:
            head = line.split()
            if head and "-" in head[0] and not head[0].endswith(":"):
                lo, hi = (int(x, 16) for x in head[0].split("-"))
                inside = lo <= address < hi
            elif inside and head and head[0] == "VmFlags:":
                return "hg" in head[1:]
    raise AssertionError(f"no mapping holds {address:#x}")


def test_the_store_s_grown_buffers_are_numpy_s_advised_for_transparent_huge_pages() -> None:
    # the unique and computed tables are read at random: with 4 KiB pages nearly every look-up misses
    # the TLB (mdd_kernel's docstring); numpy advises an array of 4 MiB or more, numba does not
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Store

    net = kanban(60)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)
    store = _Store(enc, 256 << 20)
    store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0)
    big = [a for a in store.arrays if a.nbytes >= 8 << 20]  # kids and the computed table, grown in the call
    assert len(big) >= 2
    assert all(advised_huge(a.ctypes.data + a.nbytes // 2) for a in big)


def kanban_20_counted() -> tuple[_Store, Events, Events, int, int]:
    """kanban(20)'s reachable set (805,422,366,595 markings) saturated in a store of 256 MiB, counted
    with primes enough for its enabled counts: the store, the forward and the single events, the
    set's node and its count."""
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events

    net = kanban(20)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 256 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach, at_most=float(store.count(reach)) * single.n_events)
    return store, fwd, single, reach, states


def test_the_counts_per_transition_taken_before_the_store_moves_on_are_the_counts_after() -> None:
    # symbolic._Counting counts beside the deadlocks and the witness, which grow the store's buffers
    # and may give the counts new primes: what _Store.counting took stays valid (nodes are only appended)
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.symbolic import _Counting

    store, fwd, single, reach, states = kanban_20_counted()
    taken = store.counting(reach, single)
    budget, lent = store.max_bytes, store.read_bytes()
    beside = _Counting(store, reach, single, beside=True)
    # what the count reads stays allocated while it runs, so it is lent out of the store's budget
    assert store.max_bytes == budget - lent and lent >= sum(a.nbytes for a in store.arrays[1:5])
    kids, primes = store.arrays[4], list(store._primes)
    # the markings reached from another one (as the witness's and liveness's closures): the children
    # buffer grows; then a count with more primes: new arrays of counts
    other = store.call(mk.MODE_APPLY, fwd, reach, store.m0, arg=mk.APPLY_DIFF)
    ahead = store.closure(fwd, store.path(store.pick(other)))
    store.count(ahead, at_most=2.0**200)
    assert store.arrays[4] is not kids and store._primes != primes
    alone = store.enabled_counts(reach, single)
    assert taken() == beside.result() == alone
    assert store.max_bytes == budget  # given back once the counts are taken
    assert 0 < min(alone) and max(alone) < states


def test_a_call_that_outgrows_what_the_counts_beside_left_waits_for_them_and_goes_on() -> None:
    # the bytes lent to the enabled counts beside (_Counting) come back when a call needs them:
    # the call waits for the counts to end, then goes on from what its store kept
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.symbolic import _Counting

    store, fwd, single, reach, _ = kanban_20_counted()
    alone = store.enabled_counts(reach, single)
    beside = _Counting(store, reach, single, beside=True)
    held = store.held()
    store.max_bytes, beside._lent = held, 256 << 20  # nothing left to grow by but what was lent
    other = store.call(mk.MODE_APPLY, fwd, reach, store.m0, arg=mk.APPLY_DIFF)
    ahead = store.closure(fwd, store.path(store.pick(other)))
    assert store.count(ahead) > 0 and store.held() > held
    assert store.reclaim is None and store.max_bytes == held + (256 << 20)
    assert beside.result() == alone and store.max_bytes == held + (256 << 20)  # given back once


def test_kanban_s_order_is_saturated_fastest_upside_down_and_the_race_takes_the_reverse() -> None:
    # the order search scores a span alike both ways up, but saturation fires an event at its top:
    # on the order found the stages' nodes are rebuilt for every token count on the way (113,617
    # nodes at 100 tokens a stage), reversed each is built about once (1,924)
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Store

    net = kanban(30)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)
    built = []
    for e in (enc, enc.reversed()):
        store = _Store(e, 256 << 20)
        reach = store.call(mk.MODE_SATURATE, events(sn, e, merge=True), store.m0)
        built.append((store.count(reach), store.nodes))
    assert built[0][0] == built[1][0] and built[1][1] * 5 < built[0][1]
    # with 300 tokens a stage the reverse takes 0.2 s: the second lane takes it after the first
    # order's chaining (10 s), when the order found is still saturating (at 200 tokens it took 10-13 s
    # and sometimes won the race first)
    said: list[str] = []
    big = kanban(300)
    bounds, flows = proven_bounds(big)
    r = analyse_symbolic(big, bounds, flows=flows, seconds=120.0, answer_seconds=0.0, progress=said.append)
    assert any("order 1 reversed" in line and "first done" in line for line in said), said
    sn = sparse_net(big)
    rev = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True).reversed()
    store = _Store(rev, 256 << 20)
    assert r.states == store.count(store.call(mk.MODE_SATURATE, events(sn, rev, merge=True), store.m0))


def test_the_computed_table_stops_growing_at_the_budget_and_only_the_nodes_can_outgrow_it() -> None:
    # the table is a cache: a budget that leaves it no room to double is not outgrown by it (two
    # orders racing in a lane of 1 GiB had 0.5 GiB a store, and a table of 2^23 entries doubling
    # held 0.6 GiB: the store failed with a few hundred thousand nodes)
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _OutOfMemory, _Store

    net = load_pnml(MCC / "Railroad-PT-005" / "model.pnml")
    bounds, _ = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, [], seconds=5.0, seed=0)  # a place a level: 2,298 nodes, not 303 in groups
    fwd = events(sn, enc, merge=True)

    def table_and_nodes(store: _Store) -> tuple[int, int]:
        meta, level, offset, size, kids, unique, ct = store.arrays
        return ct.nbytes, level.nbytes + offset.nbytes + size.nbytes + kids.nbytes + unique.nbytes

    free = _Store(enc, 256 << 20)
    states = free.count(free.call(mk.MODE_SATURATE, fwd, free.m0))
    table, nodes = table_and_nodes(free)
    assert states == 1_838 and table > 2 * nodes  # unbounded, the table holds most of the bytes
    tight = _Store(enc, nodes + table // 4)
    assert tight.count(tight.call(mk.MODE_SATURATE, fwd, tight.m0)) == states
    assert table_and_nodes(tight)[0] * 3 <= table
    starved = _Store(enc, nodes // 8)
    with pytest.raises(_OutOfMemory):  # the nodes' own buffers do outgrow it
        starved.call(mk.MODE_SATURATE, fwd, starved.m0)


def test_the_event_tables_of_a_call_count_against_the_store_s_budget() -> None:
    # each order raced has event tables of its own (169 MB to 490 MB on AirplaneLD-PT-2000's 16,008
    # events): memory the process holds beside the store, so the budget of a call counts them
    import dataclasses

    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _OutOfMemory, _Store

    net = load_pnml(MCC / "Railroad-PT-005" / "model.pnml")
    bounds, _ = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, [], seconds=5.0, seed=0)
    fwd = events(sn, enc, merge=True)
    pad = 1 << 20  # slots past the last one an event names: the same events, larger tables
    padded = dataclasses.replace(fwd, slot=np.concatenate([fwd.slot, np.zeros(pad // 8, fwd.slot.dtype)]))
    assert padded.nbytes == fwd.nbytes + pad

    def saturates(ev: Events, budget: int) -> bool:
        store = _Store(enc, budget)
        try:
            store.call(mk.MODE_SATURATE, ev, store.m0)
        except _OutOfMemory:
            return False
        return True

    low, high = 0, 256 << 20  # the least budget that saturates with fwd, to the byte
    assert saturates(fwd, high)
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (low, mid) if saturates(fwd, mid) else (mid, high)
    assert high > fwd.nbytes and not saturates(padded, high) and saturates(padded, high + pad)


def test_dekker_s_flags_read_by_every_enter_are_chained_where_saturation_grows_exponentially() -> None:
    # every process's enter reads the other 29 flags: saturation builds the partial unions of the
    # processes that may be in their critical sections (66,827 nodes at 20 processes, 745 at 10),
    # chained images about a node per level and value of the final set; the race picks them
    n = 30
    net = dekker(n)
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0, progress=said.append)
    assert r.method == "chaining" and any("by chaining was the first done" in line for line in said)
    assert r.states == 2 ** (n - 1) * (n + 2) and not r.deadlock and bool(r.fireable.all())
    assert r.place_bounds.max() == 1 and r.max_token_per_marking == 2 * n
    assert r.reversible is True and r.live is True  # backward closures by chaining too


def test_a_count_beyond_two_to_the_64_is_exact() -> None:
    n = 70
    net = make_net("toggles", {f"off{i}": 1 for i in range(n)},
                   {**{f"on{i}": ({f"off{i}": 1}, {f"lit{i}": 1}) for i in range(n)},
                    **{f"out{i}": ({f"lit{i}": 1}, {f"off{i}": 1}) for i in range(n)}})
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.states == 2**n
    assert r.edges == n * 2**n
    assert r.live is True and r.reversible is True and r.deadlock is False


@pytest.mark.timeout(120)
def test_a_net_of_over_a_thousand_levels_is_saturated() -> None:
    # a token going round a ring of 1,100 places: its semiflow has too many local markings to be a
    # group, so every place is a level of its own (the unique table's first size hung past 1,020)
    n = 1_100
    net = make_net("ring", {"p0": 1}, {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % n}": 1}) for i in range(n)})
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.levels == n and r.states == n and r.edges == n
    assert r.live is True and r.reversible is True and not r.deadlock


def test_a_stop_event_set_by_another_thread_ends_the_engine_with_a_clear_error() -> None:
    net = load_pnml(SCALE / "LamportFastMutEx-PT-5" / "model.pnml")  # its reachable set takes seconds
    bounds, flows = proven_bounds(net)
    stop = threading.Event()
    timer = threading.Timer(0.5, stop.set)
    timer.start()
    with pytest.raises(AnalysisError, match="stopped before its reachable set was complete"):
        analyse_symbolic(net, bounds, flows=flows, seconds=600.0, stop=stop)
    timer.join()


# outgrown in the race, and after it (the computed table stops growing within the budget: the
# reachable set, its counts and the event tables fit in 312 KiB, reversibility from 560 KiB)
@pytest.mark.parametrize("budget", [256 << 10, 312 << 10])
def test_a_diagram_that_outgrows_its_budget_borrows_once_and_goes_on(budget: int) -> None:
    # a place a level (no semiflow given): groups make this net's diagram too small to outgrow a budget
    net = load_pnml(MCC / "SharedMemory-PT-000005" / "model.pnml")
    bounds, _ = proven_bounds(net)
    flows: list[np.ndarray] = []
    if budget == 256 << 10:  # the reachable set does not fit: no answer
        with pytest.raises(AnalysisError, match="outgrew the memory budget"):
            analyse_symbolic(net, bounds, flows=flows, max_bytes=budget)
    else:  # it fits, reversibility does not: the answer, liveness and reversibility undecided
        alone = analyse_symbolic(net, bounds, flows=flows, max_bytes=budget)
        assert alone.states == 1_863 and not alone.deadlock and alone.live is None and alone.reversible is None
        assert any("outgrew the memory budget" in note for note in alone.notes)
    lent: list[int] = []

    def borrow() -> int:
        lent.append(8 << 20)
        return lent[-1]

    r = analyse_symbolic(net, bounds, flows=flows, max_bytes=budget, borrow=borrow)
    assert lent == [8 << 20] and r.states == 1_863 and r.reversible is True and r.live is True  # the oracle's


def test_a_bound_below_the_truth_is_an_error_not_a_wrong_count() -> None:
    net = make_net("pile", {"go": 1}, {"put": ({"go": 1}, {"go": 1, "pile": 1})}, inhibitors={"put": {"pile": 5}})
    with pytest.raises(AnalysisError, match="place bounds"):
        analyse_symbolic(net, np.array([1, 3], dtype=np.int64))
    r = analyse_symbolic(net, np.array([1, 5], dtype=np.int64))
    assert r.states == 6 and r.deadlock and r.deadlock_sequence == ["put"] * 5


def test_levels_too_wide_on_the_proven_bounds_take_the_counts_seen_and_are_raised_where_a_firing_leaves_them() -> None:
    # a bound above what a level may hold (65,535): refused on it, taken on what was seen
    net = make_net("pile", {"go": 1}, {"put": ({"go": 1}, {"go": 1, "pile": 1})}, inhibitors={"put": {"pile": 5}})
    loose = np.array([1, 100_000], dtype=np.int64)
    with pytest.raises(AnalysisError, match="100,000 tokens"):
        analyse_symbolic(net, loose)
    asked: list[int] = []
    lines: list[str] = []

    def seen() -> np.ndarray:  # the pile seen empty: one value guessed, left by the first put
        asked.append(1)
        return np.array([1, 0], dtype=np.int64)

    r = analyse_symbolic(net, loose, seen=seen, progress=lines.append)
    assert asked == [1]
    assert r.states == 6 and r.deadlock and r.deadlock_sequence == ["put"] * 5 and int(r.place_bounds[1]) == 5
    assert any("raised to at most 7 tokens" in line for line in lines)
    assert any("raised once where a firing left them" in note for note in r.notes)


def test_a_station_never_given_its_key_leaves_a_bound_too_wide_and_the_explicit_search_gives_the_levels() -> None:
    # three stations share a pool of 5 tokens; the fourth's key is never handed out, so it never
    # holds the 70,000 tokens a take would give it, but the state equation bounds it by 350,000
    tr = {f"take{i}": ({f"key{i}": 1, "pool": 1}, {f"key{i}": 1, f"held{i}": 1}) for i in range(3)}
    tr |= {f"give{i}": ({f"held{i}": 1}, {"pool": 1}) for i in range(3)}
    tr |= {"take9": ({"key9": 1, "pool": 1}, {"key9": 1, "locked": 70_000}), "give9": ({"locked": 70_000}, {"pool": 1})}
    net = make_net("stations", {"pool": 5, "key0": 1, "key1": 1, "key2": 1}, tr, places=("key9",))
    lines: list[str] = []
    a = analyse(net, engine="symbolic", phase=lines.append)
    assert any("350,000 tokens" in line and "count seen by the explicit search" in line for line in lines)
    assert any("so every count is exact" in note for note in a.notes)
    b = analyse(net, engine="explicit")
    assert (a.states, a.edges, a.deadlock, a.live, a.reversible, a.place_bounds) == (
        b.states, b.edges, b.deadlock, b.live, b.reversible, b.place_bounds) == (56, 210, False, False, True, {
            "key9": 0, "pool": 5, "key0": 1, "key1": 1, "key2": 1, "held0": 5, "held1": 5, "held2": 5, "locked": 0})


def test_guessed_levels_give_what_the_explicit_search_gives_on_a_ring_with_loose_bounds() -> None:
    # 200 places each bounded by 5,000 (true, but loose): too wide for a 64 MiB budget; on the
    # counts seen (1 each) the ring is exact
    n = 200
    net = make_net("ring", {"p0": 1}, {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % n}": 1}) for i in range(n)})
    loose = np.full(n, 5_000, dtype=np.int64)
    with pytest.raises(AnalysisError, match="would take about"):
        analyse_symbolic(net, loose, max_bytes=64 << 20)
    r = analyse_symbolic(net, loose, max_bytes=64 << 20, seen=lambda: np.ones(n, dtype=np.int64))
    space = analyse(net, engine="explicit")
    assert (r.states, r.edges, r.live, r.reversible) == (space.states, space.edges, True, True) == (n, n, True, True)
    assert int(r.place_bounds.max()) == 1 and r.levels == n


def test_a_place_wrongly_bounded_by_its_initial_count_is_an_error_and_a_never_marked_one_disables_for_good() -> None:
    # c claimed bounded by 0 has a single local marking, so it is fixed, not a level: mark is left
    # out of saturation and must be found enabled in a reachable marking; ghost (bound 0, truly)
    # is fixed too, and haunt, which needs it, is never enabled
    net = make_net("fixed", {"a": 1}, {"go": ({"a": 1}, {"b": 1}), "back": ({"b": 1}, {"a": 1}),
                                       "mark": ({"b": 1}, {"b": 1, "c": 1}), "haunt": ({"ghost": 1}, {"a": 1})},
                   places=("a", "b", "c", "ghost"), inhibitors={"mark": {"c": 1}})
    with pytest.raises(AnalysisError, match="place bounds"):
        analyse_symbolic(net, np.array([1, 1, 0, 0], dtype=np.int64))
    r = analyse_symbolic(net, np.array([1, 1, 1, 0], dtype=np.int64))
    assert r.states == 4 and r.edges == 5 and not r.deadlock
    assert r.fireable.tolist() == [True, True, True, False]
    assert r.place_bounds.tolist() == [1, 1, 1, 0] and r.stable.tolist() == [False, False, False, True]
    assert r.max_token_per_marking == 2 and r.live is False


def one_shot_net(n: int) -> PetriNet:
    """A one-shot start, then n toggles that need it: 2**n + 1 markings, every toggle live, the
    start not, the net not reversible."""
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        transitions[f"on{i}"] = ({f"off{i}": 1, "run": 1}, {f"lit{i}": 1, "run": 1})
        transitions[f"out{i}"] = ({f"lit{i}": 1, "run": 1}, {f"off{i}": 1, "run": 1})
    transitions["start"] = ({"idle": 1}, {"run": 1})
    return make_net("one_shot", {**{f"off{i}": 1 for i in range(n)}, "idle": 1}, transitions)


def test_backward_saturation_inside_the_reachable_set_stays_inside_it() -> None:
    # a one-shot start, then toggles: every toggle is live, the start is not. Backward saturation
    # inside the reachable set once moved a node to another value of a level without cutting it to
    # that value's part of the set below the event's bottom level, so it left the set and every
    # toggle was reported not live
    n = 3
    net = one_shot_net(n)
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0, probes=0)  # backward saturations only
    assert r.states == 2**n + 1 and not r.deadlock and r.reversible is False and r.live is False
    assert r.live_transitions.tolist() == [True] * (2 * n) + [False]
    # forward from markings drawn after the start: the start can never fire again, and M0 is not
    # reached again
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0)
    assert r.reversible is False and r.live is False and r.live_transitions[-1] is False


@pytest.mark.parametrize("seed", range(40))
def test_a_way_back_into_m0_is_found_iff_the_explicit_graph_has_an_edge_into_m0_from_another_marking(
        seed: int) -> None:
    # _liveness runs the backward saturation from M0 before the probe when such an edge exists; with
    # none (and more than one marking) the net is not reversible at once
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _has_way_back

    net, a, sn, enc = generated_encoding(seed)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0)
    back = events(sn, enc, inverse=True, merge=True)
    m0 = a.space.index_of(net.initial_vector)
    expected = any(src != m0 for src, _t in a.space.predecessors(m0))
    assert _has_way_back(store, back, reach) is expected
    if not expected and a.states > 1:
        assert a.reversible is False


def test_a_one_shot_start_has_no_way_back_into_m0_and_a_self_loop_at_m0_is_none() -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _has_way_back

    for net, way_back in ((one_shot_net(3), False), (kanban(2), True),
                          (make_net("loop", {"a": 1}, {"stay": ({"a": 1}, {"a": 1}), "go": ({"a": 1}, {"b": 1}),
                                                       "on": ({"b": 1}, {"c": 1})}), False)):
        bounds, flows = proven_bounds(net)
        sn = sparse_net(net)
        enc = encode(sn, bounds, flows, seconds=1.0)
        store = _Store(enc, 64 << 20)
        reach = store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0)
        assert _has_way_back(store, events(sn, enc, inverse=True, merge=True), reach) is way_back


def _toggles_search(n: int, ways: int, max_bytes: int | None = None) -> tuple[Any, int]:
    """``n`` toggles, each going one way by ``ways`` parallel transitions and back by one: the
    guided search from M0 with no target (it goes on until its limits), traced; the search's
    _Explicit and its traced peak (bytes). The level lookups are built before the trace."""
    import tracemalloc

    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Explicit, _guided_sequence

    arcs = {f"go{i}_{k}": ({f"p{i}": 1}, {f"q{i}": 1}) for i in range(n) for k in range(ways)}
    arcs.update({f"back{i}": ({f"q{i}": 1}, {f"p{i}": 1}) for i in range(n)})
    net = make_net("toggles", {f"p{i}": 1 for i in range(n)}, arcs)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=1.0)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0)
    ex = _Explicit(sn, enc)
    assert ex.lookup.exact and ex.changed[0].size == sn.n_transitions + 1  # built before the search is traced
    goal = np.zeros(sn.n_places, dtype=np.int64)
    budget = {} if max_bytes is None else {"max_bytes": max_bytes}
    tracemalloc.start()
    try:
        assert _guided_sequence(store, ex, net, reach, mk.EMPTY, goal, limit=10**6, stop=float("inf"),
                                **budget) is None
        _now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return ex, peak


def test_the_guided_search_keeps_no_block_of_successors_alive_for_the_markings_it_keeps() -> None:
    # each of 10 toggles goes one way by 40 parallel transitions: a marking has up to 400 successors,
    # of which at most 10 are new, so each block of successors a kept marking was a view of stayed
    # allocated (CloudDeployment-PT-5a: 2.5 GiB beside a 4 GiB budget; docs/BENCHMARKS.md); with no
    # target, it goes on from every one of the 1,024 markings
    _ex, peak = _toggles_search(10, 40)
    assert peak < 6 << 20  # 1.1 MB; the views kept 15 MB alive


def test_the_guided_search_stops_at_its_byte_budget_with_its_markings_kept_narrow() -> None:
    # 300 toggles, 600 places: 2^300 markings and no target, so only its budget stops the search;
    # a marking seen is kept as int8 (1-safe), not as the int64 it is built in
    budget = 8 << 20
    ex, peak = _toggles_search(300, 1, max_bytes=budget)
    assert ex.narrow[0] == np.int8
    # the markings within the budget (11.0 MiB in all), beside one block of successors (300 × 600
    # int64, 1.4 MB) and its level values; as int64 arrays, as many markings took 52 MiB
    assert peak < budget + (4 << 20), peak


def test_a_set_is_inside_a_set_of_another_store_on_the_same_levels() -> None:
    # _Home compares the reachable set of the main store with the markings that reach M0, built on
    # a store of its own: mdd_kernel.subset walks pairs of nodes, one of each store
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Store

    net = kanban(6)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)
    fwd = events(sn, enc, merge=True)
    one, other = _Store(enc, 64 << 20), _Store(enc, 64 << 20)
    reach = one.call(mk.MODE_SATURATE, fwd, one.m0)
    other.path(np.zeros(enc.n_levels, dtype=np.int64))  # the two stores number their nodes apart
    again = other.call(mk.MODE_SATURATE, fwd, other.m0)
    but_m0 = other.call(mk.MODE_APPLY, fwd, again, other.m0, arg=mk.APPLY_DIFF)
    assert other.count(again) == one.count(reach) == other.count(but_m0) + 1
    assert reach != again  # the same set, numbered apart

    def inside(a: int, sa: _Store, b: int, sb: _Store) -> bool:
        return bool(mk.subset(a, sa.arrays[2], sa.arrays[3], sa.arrays[4], b, sb.arrays[2], sb.arrays[3], sb.arrays[4]))

    assert inside(reach, one, again, other) and inside(again, other, reach, one)
    assert inside(but_m0, other, reach, one) and not inside(reach, one, but_m0, other)
    assert inside(mk.EMPTY, one, mk.EMPTY, other) and not inside(reach, one, mk.EMPTY, other)


def test_the_main_thread_takes_back_the_bytes_lent_beside_when_its_closure_outgrows_the_rest() -> None:
    # the thread beside reversibility takes part of the main store's budget while it runs; when the
    # main thread's backward saturation outgrows what is left and the thread has not decided, the
    # thread is stopped and the saturation goes on with the whole budget
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import SymbolicResult, _Home, _liveness, _Store

    net = kanban(20)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True).reversed()  # backward: 404 to 6,829 nodes
    fwd, single, back = events(sn, enc, merge=True), events(sn, enc), events(sn, enc, inverse=True, merge=True)
    store = _Store(enc, 256 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach, at_most=float(store.count(reach)) * single.n_events)
    counts = store.enabled_counts(reach, single)
    home = _Home(sn, store, back, reach, 0, float("inf"), None, lambda _text: None)  # no bytes: it cannot decide
    home.thread.join()
    assert home.reversible is None
    home.lent = 64 << 20  # as analyse_symbolic lends it: the main store keeps only what it holds
    store.max_bytes = store.held()
    result = SymbolicResult(
        states=states, edges=sum(counts), deadlock=False, n_deadlocks=0, deadlock_marking=None,
        deadlock_sequence=None, fireable=np.array([n > 0 for n in counts]), place_bounds=np.zeros(len(net.places),
                                                                                                  dtype=np.int64),
        stable=np.zeros(len(net.places), dtype=bool), max_token_per_marking=0, live=None,
        live_transitions=np.full(len(net.transitions), None, dtype=object), reversible=None, levels=enc.n_levels,
        groups=enc.groups, nodes=store.nodes, order_score=enc.score, seconds={}, notes=[])
    held = store.held()
    _liveness(store, fwd, single, back, reach, counts, result, lambda _text: None, float("inf"), 0, None, home)
    assert result.reversible is True and result.live is True and not result.notes
    assert store.held() > held and store.max_bytes == held + (64 << 20) and home.lent == 0


@pytest.mark.parametrize("reversible", [True, False])
def test_reversibility_is_decided_beside_on_a_store_of_its_own(reversible: bool) -> None:
    # where the race kept no order upside down, symbolic._Home first asks whether the markings that
    # reach M0 on the order upside down are closed under firing (yes: reversible; no: nothing
    # known), then saturates backward from M0 without the reachable set as its constraint, and
    # compares the two across the stores
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import events
    from coordinator.analysis.symbolic import _Home

    net, bounds, flows, sn, enc = reversible_or_not(reversible)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0)
    said: list[str] = []
    home = _Home(sn, store, events(sn, enc, inverse=True, merge=True), reach, 64 << 20, float("inf"), None,
                 said.append)
    assert home.decided.wait(60.0)
    home.end()
    assert home.reversible is reversible
    assert len(said) == 1
    if reversible:
        assert "on the reachable set's order upside down, the markings that reach M0 are closed" in said[0]
    else:
        assert "the markings that reach M0, beside, on a store of its own" in said[0]
    # the answer of the whole engine is the same, whichever thread gave it
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0)
    assert r.reversible is reversible and r.live is reversible

def branches_net(n: int) -> PetriNet:
    """A one-shot choice among n branches, each a two-step cycle of its own, beside a clock that
    ticks in every marking: n terminal components, each missing the others' cycles; only the tick
    is live."""
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {"tick": ({"clock": 1}, {"clock": 1})}
    for i in range(n):
        transitions[f"go{i}"] = ({"start": 1}, {f"a{i}": 1})
        transitions[f"up{i}"] = ({f"a{i}": 1}, {f"b{i}": 1})
        transitions[f"down{i}"] = ({f"b{i}": 1}, {f"a{i}": 1})
    return make_net("branches", {"start": 1, "clock": 1}, transitions)


@pytest.mark.parametrize("n", [2, 10])
def test_liveness_from_the_terminal_components_and_beyond_their_number_by_a_saturation_per_transition(
        n: int) -> None:
    from coordinator.analysis.symbolic import _TERMINALS

    net = branches_net(n)
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0, probes=0, progress=said.append)
    a = analyse(net, engine="explicit")
    assert r.states == a.states == 2 * n + 1 and r.reversible is False and r.live is False
    assert r.live_transitions.tolist() == [a.liveness[t.id] == 4 for t in net.transitions]
    assert r.live_transitions.tolist() == [t.id == "tick" for t in net.transitions]
    if n <= _TERMINALS:
        assert f"symbolic: {n} terminal components" in said
        assert "symbolic: liveness, transition by transition" not in said
    else:  # the components found decided every cycle's transitions; the tick's saturation the rest
        assert "symbolic: liveness, transition by transition" in said


def modes_net(seed: int) -> PetriNet:
    """Components each with one token: it enters a cycle q of its component at a place drawn, and
    falls, from a place drawn, into another cycle, r, or one of two, r or s, never to leave it;
    transitions drawn synchronise two components' cycles, and every cycle's own moves keep each
    marking from being dead. Not reversible, no deadlock, and one terminal component per choice of
    r or s in every component: a transition of a cycle q is not live, one of r or s may be in some
    components and not in others."""
    rng = np.random.default_rng(7000 + seed)
    n_comp, length = int(rng.integers(2, 4)), int(rng.integers(2, 4))
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    cycles = []
    for c in range(n_comp):
        cycles.append("qrs"[:int(rng.integers(2, 4))])
        transitions[f"enter{c}"] = ({f"b{c}": 1}, {f"q{c}_{int(rng.integers(length))}": 1})
        for cyc in cycles[c][1:]:
            transitions[f"fall{c}{cyc}"] = ({f"q{c}_{int(rng.integers(length))}": 1}, {f"{cyc}{c}_0": 1})
        for cyc in cycles[c]:
            for i in range(length):
                transitions[f"{cyc}step{c}_{i}"] = ({f"{cyc}{c}_{i}": 1}, {f"{cyc}{c}_{(i + 1) % length}": 1})
    for j in range(int(rng.integers(1, 4))):
        c1, c2 = (int(x) for x in rng.choice(n_comp, size=2, replace=False))
        cyc1, cyc2 = str(rng.choice(list(cycles[c1]))), str(rng.choice(list(cycles[c2])))
        i1, i2, o1, o2 = (int(x) for x in rng.integers(length, size=4))
        transitions[f"sync{j}"] = ({f"{cyc1}{c1}_{i1}": 1, f"{cyc2}{c2}_{i2}": 1},
                                   {f"{cyc1}{c1}_{o1}": 1, f"{cyc2}{c2}_{o2}": 1})
    return make_net(f"modes-{seed}", {f"b{c}": 1 for c in range(n_comp)}, transitions)


@pytest.mark.parametrize("seed", range(12))
def test_every_transition_s_liveness_is_decided_as_on_the_explicit_graph_without_probes(seed: int) -> None:
    net = modes_net(seed)
    a = analyse(net, engine="explicit")
    assert a.complete and a.liveness is not None and not a.deadlock and a.reversible is False
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0, probes=0)
    assert r.live == a.live and r.reversible == a.reversible and r.fireable.all()
    assert r.live_transitions.tolist() == [a.liveness[t.id] == 4 for t in net.transitions]


def test_liveness_beyond_the_memory_budget_is_undecided_and_the_rest_of_the_answer_stays(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis import symbolic
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import SymbolicResult, _liveness, _Store

    # the terminal component of this net is found within the nodes the reachable set left room for:
    # no component is looked for, so that the backward saturation per transition outgrows them
    monkeypatch.setattr(symbolic, "_TERMINALS", 0)
    n = 40  # liveness needs the backward saturations
    net = one_shot_net(n)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    fwd, single, back = events(sn, enc, merge=True), events(sn, enc), events(sn, enc, inverse=True, merge=True)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    store.count(reach, at_most=float(2**n + 1) * single.n_events)  # primes enough for the enabled counts
    counts = store.enabled_counts(reach, single)
    result = SymbolicResult(
        states=store.count(reach), edges=0, deadlock=False, n_deadlocks=0, deadlock_marking=None,
        deadlock_sequence=None, fireable=np.ones(len(net.transitions), dtype=bool),
        place_bounds=np.ones(len(net.places), dtype=np.int64), stable=np.zeros(len(net.places), dtype=bool),
        max_token_per_marking=n + 1, live=None, live_transitions=np.full(len(net.transitions), None, dtype=object),
        reversible=None, levels=enc.n_levels, groups=enc.groups, nodes=store.nodes, order_score=enc.score,
        seconds={}, notes=[])
    store.max_bytes = 0  # every buffer is full from here on
    _liveness(store, fwd, single, back, reach, counts, result, lambda _text: None, float("inf"), 0, None)
    assert result.live is None  # undecided, never a guess
    assert result.reversible is False  # decided before the budget was reached: M0 is left for ever
    assert any("not decided" in note and "outgrew the memory budget" in note for note in result.notes)
    assert result.states == 2**n + 1


def philosophers(n: int) -> PetriNet:
    """``n`` philosophers round a table, each taking the left fork, then the right: one deadlock."""
    return make_net("philosophers", *philosophers_arcs(n))


def test_a_deadlock_deep_in_a_ring_of_thirty_philosophers_is_reached_by_a_straight_firing_sequence() -> None:
    n = 30
    net = philosophers(n)
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=60.0)
    assert r.deadlock and r.n_deadlocks == 1
    assert r.deadlock_sequence is not None and r.deadlock_marking is not None
    assert replays_to(net, r.deadlock_sequence, r.deadlock_marking)
    assert sorted(r.deadlock_sequence) == sorted(f"left{i}" for i in range(n))  # n steps, no detour


def test_level_values_of_many_markings_at_once_are_those_of_the_encoding() -> None:
    from coordinator.analysis.mdd_order import encode
    from coordinator.analysis.symbolic import _LevelValues, _values

    net = load_pnml(MCC / "FMS-PT-00002" / "model.pnml")
    bounds, flows = proven_bounds(net)
    enc = encode(sparse_net(net), bounds, flows, seconds=5.0, seed=0)
    rng = np.random.default_rng(3)
    markings = rng.integers(0, 4, size=(500, len(net.places))).astype(np.int64)
    markings[:5] = np.asarray(sparse_net(net).m0, dtype=np.int64)
    got = _LevelValues(enc).of(markings)
    for m, row in zip(markings, got):
        want = _values(enc, m)
        assert (row < 0).all() if want is None else row.tolist() == want.tolist()
    assert (got[:5] >= 0).all()


@pytest.mark.parametrize("model", ["FMS-PT-00002", "Eratosthenes-PT-010", "seed-3", "seed-6"])
def test_level_values_after_a_firing_are_looked_up_on_the_changed_levels_as_on_all_and_one_at_a_time(
        model: str) -> None:
    # the witness's searches look up only the levels a transition changes; every transition, enabled
    # or not, from reachable markings: counts below zero or beyond a level's values, and places fixed
    # on no level (Eratosthenes' primes, read only) that a firing would change, are not found either way
    from coordinator.analysis.mdd_order import encode
    from coordinator.analysis.symbolic import _Explicit

    if model.startswith("seed-"):
        net, _, sn, enc = generated_encoding(int(model[5:]))
    else:
        net = load_pnml(MCC / model / "model.pnml")
        bounds, flows = proven_bounds(net)
        sn = sparse_net(net)
        enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    ex = _Explicit(sn, enc)
    space = explore(net, max_states=2_000)
    ts = np.arange(len(net.transitions), dtype=np.int64)
    dense = sn.incidence.toarray().T.astype(np.int64)
    lev_ptr, lev = ex.changed
    found = 0
    for i in range(0, space.n_states, max(1, space.n_states // 40)):
        m = np.asarray(space.rows(i, i + 1)[0], dtype=np.int64)
        succ = ex.fired(m, ts)
        assert (succ == m[None, :] + dense).all() and (ex.fired(m, ts, -1) == m[None, :] - dense).all()
        vals = ex.lookup.of(m[None, :])[0]
        assert (vals >= 0).all()
        got = ex.lookup.after(vals, succ, ts, lev_ptr, lev)
        assert got.tolist() == ex.lookup.of(succ).tolist()
        # one transition at a time, as a walk's step tries them (its plans gathered once, then kept)
        for _ in range(2):
            assert [ex.lookup.after_one(vals, succ[t], int(t), lev_ptr, lev).tolist() for t in ts] == got.tolist()
        found += int((got[:, 0] >= 0).sum())
    assert found > 0


def test_a_place_that_is_only_read_is_fixed_at_its_initial_count_and_the_counts_stay_exact() -> None:
    from coordinator.analysis.mdd_order import encode
    from coordinator.analysis.statespace import explore

    # Eratosthenes: a prime is read by the transitions that remove its multiples, never changed
    net = load_pnml(MCC / "Eratosthenes-PT-010" / "model.pnml")
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    read_only = [p for p in range(len(net.places)) if not abs(sn.incidence[[p], :]).sum()]
    assert read_only and set(read_only) <= set(enc.fixed.tolist())
    assert enc.n_levels == len(net.places) - len(enc.fixed)
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.states == explore(net).n_states == 32  # the contest's answer


def test_fixed_places_disable_the_transitions_they_cannot_feed_and_flag_those_that_would_change_them() -> None:
    # mdd_order._fixed reads the arcs of every fixed place (a group of one local marking) at once
    from coordinator.analysis.mdd_order import _fixed

    net = make_net("fixed", {"lock": 1, "a": 1},
                   {"use": ({"lock": 1, "a": 1}, {"lock": 1, "b": 1}), "take": ({"lock": 1}, {"a": 1}),
                    "need": ({"empty": 1}, {"a": 1}), "blocked": ({"a": 1}, {"b": 1}), "free": ({"b": 1}, {"a": 1})},
                   places=("lock", "empty", "a", "b"), inhibitors={"blocked": {"lock": 1}})
    sn = sparse_net(net)
    kept = (np.array([2, 3]), np.array([[1, 0], [0, 1]]))
    groups = [(np.array([0]), np.array([[1]])), kept, (np.array([1]), np.array([[0]]))]
    keep, fixed, never, suspect = _fixed(sn, groups)
    names = [tr.id for tr in net.transitions]
    assert len(keep) == 1 and keep[0][0] is kept[0] and fixed.tolist() == [0, 1]
    assert {names[i] for i in np.flatnonzero(never)} == {"need", "blocked"}
    assert {names[i] for i in np.flatnonzero(suspect)} == {"take"}


def test_what_a_semiflow_leaves_beside_a_group_above_is_a_group_of_its_own_with_the_semiflow_s_bound() -> None:
    from coordinator.analysis.mdd_order import encode
    from coordinator.analysis.statespace import explore

    # an idle place forks k components of three stages each and joins them: idle + Σ stages_i = 1
    # for each i, every semiflow through idle (ARMCacheCoherence-PT-none's shape); the first makes a
    # group with idle, each other's stages are a group too, whose local markings keep Σ ≤ 1
    k = 4
    trans = {"fork": ({"idle": 1}, {f"c{i}s0": 1 for i in range(k)}),
             "join": ({f"c{i}s2": 1 for i in range(k)}, {"idle": 1})}
    for i in range(k):
        trans |= {f"c{i}a": ({f"c{i}s0": 1}, {f"c{i}s1": 1}), f"c{i}b": ({f"c{i}s1": 1}, {f"c{i}s2": 1})}
    net = make_net("forks", {"idle": 1}, trans)
    bounds, flows = proven_bounds(net)
    assert len(flows) == k and all(f[0] == 1 for f in flows)  # every semiflow holds idle
    enc = encode(sparse_net(net), bounds, flows, seconds=5.0, seed=0)
    assert sorted(len(ps) for ps in enc.levels) == [3] * (k - 1) + [4]
    ids = [p.id for p in net.places]
    for ps, local in zip(enc.levels, enc.local, strict=True):
        if "idle" not in [ids[p] for p in ps]:
            # not the 2^3 local markings of three one-bounded places: no stage, or one of three
            assert sorted(map(tuple, local.tolist())) == [(0, 0, 0), (0, 0, 1), (0, 1, 0), (1, 0, 0)]
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.states == explore(net).n_states == 1 + 3 ** k


def test_an_encoding_beyond_its_memory_share_is_refused_before_it_is_built() -> None:
    from coordinator.analysis.mdd_order import encode

    net = load_pnml(MCC / "Kanban-PT-00005" / "model.pnml")
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, max_bytes=64 << 20)
    with pytest.raises(AnalysisError, match="would take about"):
        encode(sn, bounds, flows, seconds=5.0, seed=0, max_bytes=1024)
    assert enc.n_levels > 0


def _hypergraph(n: int, seed: int) -> tuple[np.ndarray, ...]:
    """A random hypergraph of ``n`` levels in the arrays the order search sifts (hp, hidx, hw, vp, vidx)."""
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    hypers = [np.unique(rng.choice(n, size=int(rng.integers(2, 5)), replace=False)) for _ in range(2 * n)]
    sizes = np.array([h.size for h in hypers])
    hp = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    hidx = np.concatenate(hypers).astype(np.int64)
    hw = np.ones(len(hypers), dtype=np.int64)
    mat_t = sp.csr_matrix((np.ones(hidx.size), (hidx, np.repeat(np.arange(len(hypers)), sizes))),
                          shape=(n, len(hypers)))
    return hp, hidx, hw, mat_t.indptr.astype(np.int64), mat_t.indices.astype(np.int64)


@pytest.mark.parametrize("seed", range(3))
def test_a_neighbour_swap_changes_the_score_by_what_it_returns_and_keeps_each_hyperedge_s_ends(seed: int) -> None:
    # the swap reads only the ends of the hyperedges of the two levels (not their members): its
    # returned change is the change of the whole score, with weights, for hyperedges up to 40 levels
    import scipy.sparse as sp

    from coordinator.analysis import mdd_order

    n = 60
    rng = np.random.default_rng(seed)
    hypers = [np.unique(rng.choice(n, size=int(rng.integers(2, 40)), replace=False)) for _ in range(2 * n)]
    sizes = np.array([h.size for h in hypers])
    hp = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    hidx = np.concatenate(hypers).astype(np.int64)
    hw = rng.integers(1, 4, len(hypers)).astype(np.int64)
    mat_t = sp.csr_matrix((np.ones(hidx.size), (hidx, np.repeat(np.arange(len(hypers)), sizes))),
                          shape=(n, len(hypers)))
    vp, vidx = mat_t.indptr.astype(np.int64), mat_t.indices.astype(np.int64)
    order = rng.permutation(n).astype(np.int64)
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    lo = np.minimum.reduceat(pos[hidx], hp[:-1])
    hi = np.maximum.reduceat(pos[hidx], hp[:-1])
    mark = np.zeros(len(hypers), dtype=np.int64)
    score = mdd_order._score(pos, hp, hidx, hw)
    for _ in range(500):
        a = int(rng.integers(0, n - 1))
        p, q = (int(order[a]), int(order[a + 1])) if rng.random() < 0.5 else (int(order[a + 1]), int(order[a]))
        score += mdd_order._swap(p, q, pos, order, hw, lo, hi, vp, vidx, mark)
        assert score == mdd_order._score(pos, hp, hidx, hw)
        assert np.array_equal(lo, np.minimum.reduceat(pos[hidx], hp[:-1]))
        assert np.array_equal(hi, np.maximum.reduceat(pos[hidx], hp[:-1]))
        assert not mark.any() and np.array_equal(order[pos], np.arange(n))


@pytest.mark.parametrize("seed", range(4))
def test_sifting_by_chunks_moves_the_levels_as_sifting_at_once_and_a_deadline_or_stop_only_ends_it(seed: int) -> None:
    from coordinator.analysis import mdd_order

    n = 120
    hp, hidx, hw, vp, vidx = _hypergraph(n, seed)
    start = np.random.default_rng(seed).permutation(n).astype(np.int64)

    def score(order: np.ndarray) -> float:
        pos = np.empty(n, dtype=np.int64)
        pos[order] = np.arange(n)
        return mdd_order._score(pos, hp, hidx, hw)

    whole = start.copy()
    mdd_order._sift(whole, hp, hidx, hw, vp, vidx, 20)
    chunked = start.copy()
    mdd_order._sift(chunked, hp, hidx, hw, vp, vidx, 20, float("inf"), lambda: False)
    assert np.array_equal(whole, chunked)  # a look at the clock between levels changes no move
    assert score(whole) < score(start) and sorted(whole.tolist()) == list(range(n))
    late = start.copy()
    mdd_order._sift(late, hp, hidx, hw, vp, vidx, 20, 0.0)
    stopped = start.copy()
    mdd_order._sift(stopped, hp, hidx, hw, vp, vidx, 20, None, lambda: True)
    assert np.array_equal(late, start) and np.array_equal(stopped, start)


def test_beyond_the_sifted_levels_each_seed_makes_one_start_of_its_own_and_the_counts_stay_exact(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.analysis import mdd_order
    from coordinator.analysis.statespace import explore

    net = load_pnml(MCC / "Kanban-PT-00005" / "model.pnml")
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    small = mdd_order.encode(sn, bounds, flows, seconds=5.0, seed=0)
    monkeypatch.setattr(mdd_order, "MAX_SIFTED", 2)  # Kanban's levels count as many: one start a seed
    encs = [mdd_order.encode(sn, bounds, flows, seconds=5.0, seed=s) for s in range(3)]
    orders = [tuple(tuple(ps.tolist()) for ps in e.levels) for e in encs]
    assert len(set(orders)) == 3  # the net's own order, its reverse, a random one
    assert all(e.n_levels == small.n_levels for e in encs)
    r = analyse_symbolic(net, bounds, flows=flows)
    assert r.states == explore(net).n_states


@pytest.mark.parametrize("n", [2, 8])
def test_random_walks_fall_into_a_deadlock_and_give_a_firing_sequence_that_replays_to_it(n: int) -> None:
    import time

    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis import symbolic
    from coordinator.analysis.mdd_order import encode, events

    net = philosophers(n)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    fwd = events(sn, enc, merge=True)
    store = symbolic._Store(enc, 1 << 30)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0, check_overflow=True)
    single = events(sn, enc)
    states = store.count(reach)
    counts = counts_per_transition(store, single, reach, states)
    dead = symbolic._dead(store, fwd, single, reach, counts, states)
    ex = symbolic._Explicit(sn, enc)
    found = symbolic._walk_sequence(store, ex, net, dead, time.monotonic() + 60.0)
    assert found is not None
    seq, end = found
    assert replays_to(net, seq, {p.id: int(end[i]) for i, p in enumerate(net.places) if end[i]})
    assert len(seq) >= n  # every philosopher took a fork
    # a walk that ends in a dead marking outside the targets gives nothing: M0 is not dead
    assert symbolic._walk_sequence(store, ex, net, store.m0, time.monotonic() + 60.0) is None


def _ladder(n: int) -> PetriNet:
    """Rungs 0..n with a way up from each and a way down into a cycle that never ends."""
    ts: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        ts[f"up{i}"] = ({f"rung{i}": 1}, {f"rung{i + 1}": 1})
        ts[f"fall{i}"] = ({f"rung{i}": 1}, {"trap_a": 1})
    ts["round"] = ({"trap_a": 1}, {"trap_b": 1})
    ts["again"] = ({"trap_b": 1}, {"trap_a": 1})
    return make_net("ladder", {"rung0": 1}, ts)


class _Deadlocked:
    """A net's encoding (seed 0), its forward, single and inverse events, and a store holding its
    reachable set and dead markings (:func:`symbolic._dead`), for the witness's tests."""

    def __init__(self, net: PetriNet) -> None:
        from coordinator.analysis import mdd_kernel as mk
        from coordinator.analysis import symbolic
        from coordinator.analysis.mdd_order import encode, events

        self.sn = sparse_net(net)
        bounds, flows = proven_bounds(net)
        self.enc = encode(self.sn, bounds, flows, seconds=5.0, seed=0)
        self.fwd, self.single = events(self.sn, self.enc, merge=True), events(self.sn, self.enc)
        self.back = events(self.sn, self.enc, merge=True, inverse=True)
        self.store = store = symbolic._Store(self.enc, 1 << 30)
        self.reach = store.call(mk.MODE_SATURATE, self.fwd, store.m0, check_overflow=True)
        self.states = store.count(self.reach)
        self.dead = symbolic._dead(store, self.fwd, self.single, self.reach,
                                   counts_per_transition(store, self.single, self.reach, self.states), self.states)


def test_walks_that_stay_where_a_deadlock_is_reachable_reach_one_where_free_walks_fall_into_a_trap() -> None:
    """A ladder of 40 rungs, each with a way down into a cycle that never ends: a free walk reaches
    the top, the only dead marking, once in 2^40 walks; a walk that never leaves the markings that
    can reach it climbs straight up."""
    import time

    from coordinator.analysis import symbolic

    n = 40
    net = _ladder(n)
    d = _Deadlocked(net)
    sn, enc, back, store, reach, states, dead = d.sn, d.enc, d.back, d.store, d.reach, d.states, d.dead
    assert states == n + 3 and store.count(dead) == 1
    ex = symbolic._Explicit(sn, enc)
    assert symbolic._walk_sequence(store, ex, net, dead, time.monotonic() + 0.5) is None
    inside = store.closure(back, dead, c=reach)
    assert store.count(inside) == n + 1  # the rungs: not the cycle
    found = symbolic._walk_sequence(store, ex, net, dead, time.monotonic() + 60.0, inside=inside)
    assert found is not None
    seq, end = found
    assert seq == [f"up{i}" for i in range(n)]
    assert replays_to(net, seq, {p.id: int(end[i]) for i, p in enumerate(net.places) if end[i]})
    # M0 outside ``inside`` (here the top rung alone, and M0 the target): every walk stops at its first step
    assert symbolic._walk_sequence(store, ex, net, store.m0, time.monotonic() + 60.0, inside=dead) is None


def test_walks_toward_a_deadlock_take_no_step_that_changes_nothing() -> None:
    """Every step of a chain also enables five transitions that read its token and put it back: a
    walk that fired them would mostly stand still (CloudDeployment-PT-6a: 219 of its 908
    transitions change no count, and its walk inside took 32,917 firings, 4,716 without them).
    Both walks, free and inside, climb the chain in n firings, the dead marking at its top."""
    import time

    from coordinator.analysis import symbolic

    n = 30
    ts: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        ts[f"next{i}"] = ({f"step{i}": 1}, {f"step{i + 1}": 1})
        for k in range(5):
            ts[f"look{i}_{k}"] = ({f"step{i}": 1}, {f"step{i}": 1})
    net = make_net("chain", {"step0": 1}, ts)
    d = _Deadlocked(net)
    assert d.states == n + 1 and d.store.count(d.dead) == 1
    ex = symbolic._Explicit(d.sn, d.enc)
    assert int(ex.still.sum()) == 5 * n
    inside = d.store.closure(d.back, d.dead, c=d.reach)
    for within in (None, inside):
        found = symbolic._walk_sequence(d.store, ex, net, d.dead, time.monotonic() + 60.0, inside=within)
        assert found is not None and found[0] == [f"next{i}" for i in range(n)]


@pytest.mark.parametrize("quick", [True, False])
def test_the_closure_toward_the_dead_markings_runs_beside_the_quick_searches_and_gives_its_budget_back(
        monkeypatch: pytest.MonkeyPatch, quick: bool) -> None:
    """On two CPUs the witness's backward closure starts beside its quick searches: stopped when
    they find the sequence, taken when they do not (their time cut to nothing), and either way the
    store has its whole budget back and no thread is left."""
    from coordinator.analysis import symbolic

    monkeypatch.setattr(symbolic, "cpus", lambda: 2)
    if not quick:
        monkeypatch.setattr(symbolic, "_QUICK_SECONDS", 0.0)
    made: list[symbolic._TowardDead] = []
    real = symbolic._TowardDead

    def spy(*args: Any) -> symbolic._TowardDead:
        made.append(real(*args))
        return made[-1]

    monkeypatch.setattr(symbolic, "_TowardDead", spy)
    net = _ladder(40)
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=flows, max_bytes=1 << 30)
    assert r.states == 43 and r.n_deadlocks == 1
    assert r.deadlock_sequence == [f"up{i}" for i in range(40)]
    assert len(made) == 1
    toward = made[0]
    assert not toward.thread.is_alive() and toward.lent == 0 and toward.store.max_bytes == 1 << 30
    assert toward.flag.is_set() is quick  # cancelled only when the quick searches found it


def test_the_closure_toward_the_dead_markings_is_made_again_on_the_whole_budget_when_its_part_is_outgrown() -> None:
    """Lent all but what the store holds, the closure beside outgrows its part and stops; the
    caller makes it again on the whole budget, to the same set (200 philosophers: the store's
    buffers grow from about 1 MB to 13 MB). The thread watches the caller's cancel flag too."""
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis import symbolic

    d = _Deadlocked(make_net("philosophers", *philosophers_arcs(200)))
    back, store, reach, states, dead = d.back, d.store, d.reach, d.states, d.dead
    assert store.count(dead) == 1
    toward = symbolic._TowardDead(store, back, dead, reach, store.max_bytes - store.held())
    inside = toward.result()
    assert isinstance(toward.error, symbolic._OutOfMemory)
    assert store.max_bytes == 1 << 30
    assert inside == store.closure(back, dead, c=reach)  # the same node: the set made on one thread
    assert store.count(inside) == states  # every marking can still reach the deadlock
    # the thread watches the caller's cancel flag (read by the kernel every million steps or so)
    flag = threading.Event()
    mk.set_watch(None, None, flag)
    try:
        beside = symbolic._TowardDead(store, back, dead, reach, 0)
        assert not beside.flag.is_set()
        flag.set()
        assert beside.flag.is_set()
        beside.cancel()
        assert not beside.thread.is_alive() and store.max_bytes == 1 << 30
    finally:
        mk.set_watch(None, None)


def test_a_count_beyond_a_float_s_range_is_exact() -> None:
    """2^1100 markings: the float estimate of the count is infinite, and the primes of the exact
    count come from the product of the level domains."""
    n = 1100
    transitions = {}
    for i in range(n):
        transitions[f"t{i}"] = ({f"a{i}": 1}, {f"b{i}": 1})
        transitions[f"u{i}"] = ({f"b{i}": 1}, {f"a{i}": 1})
    net = make_net("toggles", {f"a{i}": 1 for i in range(n)}, transitions)
    r = analyse_symbolic(net, np.ones(2 * n, dtype=np.int64), flows=[], seconds=120.0)
    assert r.states == 2**n and r.edges == n * 2**n
    assert r.deadlock is False and r.max_token_per_marking == n


def test_a_lane_whose_diagram_outgrows_the_rival_search_s_markings_yields_and_the_answer_stands() -> None:
    from coordinator.analysis.symbolic import Rival

    net = kanban(100)  # the first order saturates for about 2 s, through 113,617 nodes
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    rival = Rival(3, said.append)
    done = threading.Event()

    def search() -> None:  # a rival that never gets past one marking: every lane at work outgrows it
        while not done.wait(0.005):
            rival.found(1)

    before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    thread = threading.Thread(target=search)
    thread.start()
    try:
        r = analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0, progress=said.append,
                             rival=rival)
    finally:
        done.set()
        thread.join()
    assert r.states == analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0).states
    assert any(line.startswith("symbolic: lane ") and "yields to the explicit search" in line for line in said), said
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == before  # the lanes had threads of their own
    rival.found(1)  # after the race: nothing to yield


def test_a_lane_whose_diagram_holds_under_half_a_marking_a_node_and_less_than_the_search_yields_past_the_limit_stops_it(
        ) -> None:
    from coordinator.analysis.symbolic import Rival, _Lane, _Race

    net = kanban(5)
    bounds, flows = proven_bounds(net)
    race = _Race(sparse_net(net), bounds, flows, 1 << 26, 0.0, lambda _text: None)
    race.lanes = [_Lane(race, True, 0, 1 << 25), _Lane(race, False, 3, 1 << 25)]  # no thread: no priority
    said: list[str] = []
    rival = Rival(3, said.append, limit=10_000)
    rival.found(5_000)  # before the race: nothing to yield
    rival._enter(race)
    first, second = race.lanes
    rival.shown(first, 4_000.0, 3_000, "order 1")  # more markings than nodes: compressing
    rival.shown(first, 6_000.0, 9_000, "order 1")  # ahead of the search
    rival.shown(first, 4_600.0, 9_000, "order 1")  # over half a marking a node (_YIELD_RATIO)
    assert not first.yielded and said == []
    rival.shown(second, 4_000.0, 9_000, "order 3")
    rival.shown(second, 3_000.0, 9_000, "order 4")  # once
    assert second.yielded and said == [
        "symbolic: lane 2 of the race yields to the explicit search: order 3 holds 4,000 reachable markings in "
        "9,000 nodes, the search has found 5,000"]
    rival.shown(first, 20_000.0, 30_000, "order 1")  # past the search's limit: it is stopped, no lane yields
    assert rival.settled.is_set() and not first.yielded
    assert said[1:] == ["symbolic: order 1 holds 20,000 reachable markings already, more than the explicit search's "
                        "limit of 10,000: the search beside is stopped"]
    rival._leave()


def test_a_lane_alone_tells_the_search_beside_what_it_has_shown_reachable_part_way_and_past_the_limit_stops_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # without turns a lane would tell only when done; it stops every _TELL_SECONDS instead (here
    # at its kernel's first check of the clock), and the search, told of more markings than it may
    # find, stops there, while the lanes go on from where they stopped to the exact set
    from coordinator.analysis import symbolic

    monkeypatch.setattr(symbolic, "_TELL_SECONDS", 0.0)
    net = kanban(100)  # the first order saturates for about 2 s, through 113,617 nodes
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    rival = symbolic.Rival(3, said.append, limit=1_000)
    r = analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0, rival=rival)
    assert r.states == analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0).states
    assert rival.settled.is_set()
    told = [line for line in said if "more than the explicit search's limit of 1,000" in line]
    assert len(told) == 1 and told[0].startswith("symbolic: order 1 "), said  # the first lane, or the chaining
    assert not any("yields" in line for line in said)  # the search has found nothing: no lane yields to it


def test_a_lane_alone_that_shows_too_few_markings_a_node_part_way_yields_to_the_search_beside_and_the_set_is_exact(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the stops to tell (_TELL_SECONDS) carry the yield by the lower bound too: with every ratio of
    # markings to nodes too low (_YIELD_RATIO) and a search that has found more than any diagram
    # holds, the lanes yield at their first stops, part-way, and go on to the exact set
    from coordinator.analysis import symbolic

    monkeypatch.setattr(symbolic, "_TELL_SECONDS", 0.0)
    monkeypatch.setattr(symbolic, "_YIELD_RATIO", 1e30)
    net = kanban(100)
    bounds, flows = proven_bounds(net)
    said: list[str] = []
    rival = symbolic.Rival(3, said.append)
    rival.found(10**30)  # more than Kanban-PT-00100's 1.7·10^19 markings; before the race: kept
    r = analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0, rival=rival)
    assert r.states == analyse_symbolic(net, bounds, flows=flows, seconds=120.0, answer_seconds=0.0).states
    yielded = [line for line in said if "yields to the explicit search" in line]
    assert yielded and ": order 1 " in yielded[0], said
    assert yielded[0].endswith(f"the search has found {10**30:,}")


def test_a_closure_stopped_at_every_check_of_the_clock_and_resumed_each_time_gives_the_whole_set() -> None:
    # what a lane alone does while it tells the search beside (_TELL_SECONDS), at its most often:
    # each call stopped at the kernel's first check of its clock (every 2^20 steps), by saturation
    # and by chaining (whose images are mostly shorter than that), resumed from the store it kept
    import time

    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _OutOfTime, _Store

    net = kanban(40)  # its saturation is stopped twice or so
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    fwd = events(sn, enc, merge=True)
    whole = _Store(enc, 1 << 30)
    states = whole.count(whole.call(mk.MODE_SATURATE, fwd, whole.m0))
    stopped = 0
    for chain in (False, True):
        store = _Store(enc, 1 << 30)
        store.chain = chain
        try:
            while True:
                mk.set_watch(time.monotonic() - 1.0, None)
                try:
                    reach = store.closure(fwd, store.m0, check_overflow=True)
                    break
                except _OutOfTime:
                    stopped += 1
                    assert store.fewest_reachable() <= states
        finally:
            mk.set_watch(None, None)
        assert store.count(reach) == states
    assert stopped > 0


def test_events_alike_below_their_top_level_share_one_condition_number() -> None:
    from coordinator.analysis import mdd_kernel as mk

    dom = np.array([3, 2, 4], dtype=np.int64)
    # local functions (value -> next value, -1: not enabled), one table per (event, level)
    tables = [
        [0, -1, -1], [-1, 0], [1, 2, 3, 0],  # event 0, levels 0..2: level 2 takes every value
        [-1, 2, -1], [-1, 1],  # event 1, levels 0..1 (level 2 below: no function)
        [-1, 0], [1, -1, -1, -1],  # event 2, levels 1..2: on level 2 value 0 only
    ]
    fn_ptr = np.concatenate([[0], np.cumsum([len(t) for t in tables])]).astype(np.int64)
    fn = np.concatenate([np.array(t, dtype=np.int64) for t in tables])
    top, bot = np.array([0, 0, 1], dtype=np.int64), np.array([2, 2, 2], dtype=np.int64)
    slot_ptr = np.array([0, 3, 6, 8], dtype=np.int64)
    slot = np.array([0, 1, 2, 3, 4, -1, 5, 6], dtype=np.int64)
    on_ptr, on_val = mk.enabling_values(fn_ptr, fn)
    sid = mk.suffix_ids(top, bot, slot_ptr, slot, on_ptr, on_val, dom).tolist()
    assert sid[0] == sid[3] == sid[6] == -1  # the top levels: no number
    assert sid[1] == sid[4] and sid[2] == sid[5]  # value 1 on level 1 and any on level 2, for events 0 and 1
    assert sid[7] not in (sid[2], sid[5])  # event 2: value 0 only on level 2
    assert len({sid[1], sid[2], sid[7]}) == 3


def test_condition_numbers_are_those_of_a_dictionary_as_first_met_past_the_hash_table_s_growth() -> None:
    # mdd_kernel.suffix_ids numbers the conditions in a compiled hash table that starts at 4,096 slots
    # and grows; 3,000 events over 12 levels give more conditions than its first slots hold
    from coordinator.analysis import mdd_kernel as mk

    rng = np.random.default_rng(7)
    n_levels, n_ev = 12, 3000
    dom = rng.integers(2, 5, size=n_levels).astype(np.int64)
    top = rng.integers(0, n_levels - 1, size=n_ev).astype(np.int64)
    bot = np.array([rng.integers(t + 1, n_levels) for t in top], dtype=np.int64)
    tables: list[np.ndarray] = []
    slot: list[int] = []
    slot_ptr = [0]
    for t, b in zip(top.tolist(), bot.tolist()):
        for k in range(t, b + 1):
            if k > t and rng.random() < 0.3:
                slot.append(-1)  # no function on this level
                continue
            slot.append(len(tables))
            tables.append(np.where(rng.random(dom[k]) < 0.6, rng.integers(0, dom[k], size=dom[k]), -1))
        slot_ptr.append(len(slot))
    fn_ptr = np.concatenate([[0], np.cumsum([len(x) for x in tables])]).astype(np.int64)
    fn = np.concatenate(tables).astype(np.int64)
    on_ptr, on_val = mk.enabling_values(fn_ptr, fn)
    sid = mk.suffix_ids(top, bot, np.array(slot_ptr, np.int64), np.array(slot, np.int64), on_ptr, on_val, dom)
    kinds: dict[bytes, int] = {}
    named: dict[tuple[int, int, int], int] = {}
    expected = np.full(len(slot), -1, np.int64)
    for e in range(n_ev):
        t, b, at = int(top[e]), int(bot[e]), slot_ptr[e]
        below = -1
        for j in range(b - t, 0, -1):
            f = slot[at + j]
            vals = on_val[on_ptr[f]:on_ptr[f + 1]] if f >= 0 else None
            v = -1 if vals is None or len(vals) == dom[t + j] else kinds.setdefault(vals.tobytes(), len(kinds))
            below = expected[at + j] = named.setdefault((t + j, v, below), len(named))
    assert len(named) > 2048 and np.array_equal(sid, expected)


def lookers_net(n: int) -> PetriNet:
    """``n`` three-place cycles, each with one token, and transitions that read where one cycle's
    token is and where the tokens of two other cycles are (the same two places for every
    transition of the first cycle's index): many transitions alike below their top level."""
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        for j in range(3):
            transitions[f"step{i}_{j}"] = ({f"c{i}_{j}": 1}, {f"c{i}_{(j + 1) % 3}": 1})
            for k in range(1, n - 1):  # the two other cycles: i + k and i + k + 1, neither i
                a, b = f"c{(i + k) % n}_0", f"c{(i + k + 1) % n}_{k % 3}"
                pre = {f"c{i}_{j}": 1, a: 1, b: 1}
                transitions[f"look{i}_{j}_{k}"] = (pre, dict(pre))
    return make_net("lookers", {f"c{i}_0": 1 for i in range(n)}, transitions)


@pytest.mark.parametrize("seed", range(3))
def test_the_edges_of_transitions_alike_below_their_top_level_are_counted_as_on_the_explicit_graph(seed: int) -> None:
    net = lookers_net(5)
    a = analyse(net, engine="explicit")
    bounds, flows = proven_bounds(net)
    r = analyse_symbolic(net, bounds, flows=[] if seed else flows, seconds=60.0)
    assert r.states == a.states == 3**5 and r.edges == a.edges
    assert r.fireable.tolist() == [a.liveness[t.id] >= 1 for t in net.transitions]


def test_the_probe_draws_no_more_markings_after_one_that_reaches_the_whole_reachable_set() -> None:
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _probe, _Store

    net = lookers_net(4)  # strongly connected: every marking reaches every other
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    fwd, single = events(sn, enc, merge=True), events(sn, enc)
    store = _Store(enc, 64 << 20)
    reach = store.call(mk.MODE_SATURATE, fwd, store.m0)
    states = store.count(reach, at_most=81.0 * single.n_events)
    result = SymbolicResult(
        states=states, edges=0, deadlock=False, n_deadlocks=0, deadlock_marking=None, deadlock_sequence=None,
        fireable=np.ones(len(net.transitions), dtype=bool), place_bounds=np.ones(len(net.places), dtype=np.int64),
        stable=np.zeros(len(net.places), dtype=bool), max_token_per_marking=4, live=None,
        live_transitions=np.full(len(net.transitions), None, dtype=object), reversible=None, levels=enc.n_levels,
        groups=enc.groups, nodes=store.nodes, order_score=enc.score, seconds={}, notes=[])
    drawn: list = []
    _probe(store, fwd, single, reach, result, float("inf"), 3, None, drawn)
    assert len(drawn) == 1 and drawn[0][2] == reach  # one marking, whose R(m) is the whole set
    assert result.live is None and result.reversible is None  # decided by the backward saturation after
    mk.set_watch(None, None)


def two_phase_locking(clients: int) -> PetriNet:
    """The Model Checking Contest's TwoPhaseLocking (PT, nC…vN): clients lock A, then B, release A,
    lock A again, release both; resources A and B hold ``clients // 2`` and ``clients // 2 + 1``."""
    return make_net("two-phase-locking", {"Clients": clients, "resA": clients // 2, "resB": clients // 2 + 1}, {
        "lockA": ({"resA": 1, "Clients": 1}, {"haveA": 1}),
        "lockB": ({"resB": 1, "haveA": 1}, {"haveAandB": 1}),
        "relA": ({"haveAandB": 1}, {"resA": 1, "haveB": 1}),
        "lockA2": ({"resA": 1, "haveB": 1}, {"haveA2andB": 1}),
        "relB": ({"haveA2andB": 1}, {"resB": 1, "haveA2": 1}),
        "relA2": ({"haveA2": 1}, {"Clients": 1, "resA": 1})})


def test_the_order_is_sifted_on_the_ranks_of_the_semiflows_partial_sums_and_holds_the_same_markings(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.analysis import mdd_order
    from coordinator.analysis.mdd_order import _PartialSums, encode, events

    net = two_phase_locking(40)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    assert len(flows) == 3
    ranked = encode(sn, bounds, flows)
    monkeypatch.setattr(mdd_order, "RANK_LEVELS", 0)
    spans = encode(sn, bounds, flows)
    owner = np.arange(sn.n_places)

    def widths(enc: Encoding) -> np.ndarray:
        order = np.array([int(ps[0]) for ps in enc.levels])  # one place a level: no group on this net
        return _PartialSums(flows, owner, sn.n_places).cuts(order)

    # the span score's order has a cut of rank 3 (three partial sums free below it), the ranks' none
    assert int(widths(spans).max()) == 3 and int(widths(ranked).max()) == 2
    assert int(widths(ranked).sum()) < int(widths(spans).sum())
    graph = explore(net)
    nodes = []
    for enc in (ranked, spans):
        store = _Store(enc, 256 << 20)
        reach = store.closure(events(sn, enc, merge=True), store.m0)
        assert store.count(reach) == graph.n_states
        nodes.append(store.nodes)
    assert nodes[0] < nodes[1]


def test_a_lane_that_outgrows_its_share_gives_way_to_a_lane_still_working_on_a_smaller_diagram() -> None:
    import time

    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Lane, _Race

    net = two_phase_locking(20)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    enc = encode(sn, bounds, flows)
    race = _Race(sn, bounds, flows, 64 << 20, time.monotonic() + 60.0, lambda _text: None)
    first, second = _Lane(race, True, 0, 32 << 20), _Lane(race, False, 2, 32 << 20)
    race.lanes = [first, second]
    small, large = _Store(enc, 32 << 20), _Store(enc, 32 << 20)
    large.closure(events(sn, enc, merge=True), large.m0)
    assert small.nodes < large.nodes
    first.working, second.working = small, large
    assert race.smaller_beside(second, large.nodes) and not race.smaller_beside(first, small.nodes)
    first.working = None  # between calls: nothing to compare
    assert not race.smaller_beside(second, large.nodes)
    first.working = small
    first.ended.set()  # a lane that ended works on nothing
    assert not race.smaller_beside(second, large.nodes)


def test_an_order_that_outgrows_its_part_of_a_lane_gives_way_to_a_smaller_one_that_has_had_as_long() -> None:
    # _Lane._run: the order that outgrew its part is dropped, not the others, when another order of
    # the lane, not by chaining, has had at least its seconds of turns and holds fewer nodes; the
    # lane's share is then split among those left, and a dropped order gets none of it
    import time

    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _Candidate, _Lane, _Race

    net = two_phase_locking(20)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    enc = encode(sn, bounds, flows)
    fwd = events(sn, enc, merge=True)
    large = _Candidate(1, enc, fwd, _Store(enc, 8 << 20))
    large.store.closure(fwd, large.store.m0)
    small, chained, gone = (_Candidate(n, enc, fwd, _Store(enc, 8 << 20)) for n in (2, 1, 3))
    chained.store.chain = True
    gone.drop()
    assert small.store.nodes < large.store.nodes
    large.spent = 3.0
    small.spent = 3.0
    assert large.outdone([small], large.spent) and not small.outdone([large], small.spent)
    assert not large.outdone([small], 3.5)  # the smaller one has had less time
    assert not large.outdone([], 0.0)
    chained.spent = 10.0  # by chaining: its diagram is dropped when it outgrows its part in any case
    assert not large.outdone([chained], 3.0)
    race = _Race(sn, bounds, flows, 64 << 20, time.monotonic() + 60.0, lambda _text: None)
    lane = _Lane(race, True, 3, 32 << 20)
    lane.cands = [large, small, chained, gone]
    held = 2 << 20  # what the order by chaining holds, kept for it
    lane._split([False, True, True, False], held)
    assert small.store.max_bytes == 15 << 20 and chained.store.max_bytes == (15 << 20) + held
    assert gone.dropped and large.store.max_bytes == 8 << 20
    small.store.max_bytes = 20 << 20
    lane._split([False, True, True, False], held)
    assert small.store.max_bytes == 20 << 20  # no part is made smaller


def test_the_memory_of_the_search_beside_goes_to_the_lanes_once_it_stopped() -> None:
    import time

    from coordinator.analysis.symbolic import Rival, _Lane, _Race

    net = two_phase_locking(20)
    sn = sparse_net(net)
    bounds, flows = proven_bounds(net)
    lent: list[int] = []

    def borrow() -> int:
        lent.append(8 << 20)
        return lent[-1]

    race = _Race(sn, bounds, flows, 64 << 20, time.monotonic() + 60.0, lambda _text: None, borrow=borrow)
    race.rival = Rival(nice=0)
    race.lanes = [_Lane(race, True, 0, 32 << 20), _Lane(race, False, 2, 32 << 20)]
    assert not race.widen_shares() and not lent  # the search is still going: its memory is its own
    race.rival.settled.set()
    assert race.widen_shares() and lent == [8 << 20]
    assert race.max_bytes == 72 << 20 and [lane.share for lane in race.lanes] == [36 << 20, 36 << 20]
    assert not race.widen_shares() and len(lent) == 1  # asked once


def test_the_candidate_orders_of_one_net_share_its_groups_of_places_found_once() -> None:
    # mdd_order.PlaceGroups: the race's encodings differ in their order alone
    from coordinator.analysis.mdd_order import PlaceGroups, encode

    net = kanban(6)
    bounds, flows = proven_bounds(net)
    sn = sparse_net(net)
    found = PlaceGroups()
    how = ((0, False), (1, False), (0, True))
    alone = [encode(sn, bounds, flows, seed=s, flow=f) for s, f in how]
    shared = [encode(sn, bounds, flows, seed=s, flow=f, place_groups=found) for s, f in how]
    assert any(len(ps) > 1 for ps in shared[0].levels)
    for a, b in zip(alone, shared):
        assert len(a.levels) == len(b.levels)
        assert all(np.array_equal(x, y) for x, y in zip(a.levels, b.levels))
        assert all(np.array_equal(x, y) for x, y in zip(a.local, b.local))
    # found once: every encoding holds the same arrays of local markings, level by level
    first = {ps.tobytes(): loc for ps, loc in zip(shared[0].levels, shared[0].local)}
    for enc in shared[1:]:
        assert all(loc is first[ps.tobytes()] for ps, loc in zip(enc.levels, enc.local))
    assert not any(loc is first[ps.tobytes()] for ps, loc in zip(alone[1].levels, alone[1].local))
