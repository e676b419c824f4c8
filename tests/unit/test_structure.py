"""Behavioural properties of the ordinary net: coverability, boundedness, liveness levels, deadlocks."""

from __future__ import annotations

import numpy as np
import pytest
from analysis_nets import make_net

from coordinator.analysis.coverability import OMEGA, covering_witness, karp_miller
from coordinator.analysis.statespace import explore
from coordinator.analysis.structure import analyse, ordinary_view
from coordinator.errors import AnalysisError
from coordinator.net import Arc, Marking, PetriNet, Place, Transition


def producer() -> PetriNet:
    return make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})


def pump() -> PetriNet:
    """p1 →t1 p2 →t2 p1 + p3 (p3 grows); t3 leaves for the dead end p4."""
    return make_net("pump", {"p1": 1}, {
        "t1": ({"p1": 1}, {"p2": 1}),
        "t2": ({"p2": 1}, {"p1": 1, "p3": 1}),
        "t3": ({"p1": 1}, {"p4": 1}),
    })


def levels_net() -> PetriNet:
    return make_net("levels", {"a": 1, "x": 1}, {
        "t_left": ({"a": 1}, {"l": 1}),
        "l_loop": ({"l": 1}, {"l": 1}),
        "t_right": ({"a": 1}, {"r": 1}),
        "r_loop": ({"r": 1}, {"r": 1}),
        "t_dead": ({"z": 1}, {"a": 1}),
        "x_go": ({"x": 1}, {"y": 1}),
        "y_go": ({"y": 1}, {"x": 1}),
    })


def mutex() -> PetriNet:
    return make_net("mutex", {"idle1": 1, "idle2": 1, "free": 1}, {
        "enter1": ({"idle1": 1, "free": 1}, {"crit1": 1}),
        "leave1": ({"crit1": 1}, {"idle1": 1, "free": 1}),
        "enter2": ({"idle2": 1, "free": 1}, {"crit2": 1}),
        "leave2": ({"crit2": 1}, {"idle2": 1, "free": 1}),
    })


def test_karp_miller_puts_omega_on_the_buffer_of_a_producer_without_consumer() -> None:
    cov = karp_miller(producer())
    assert cov.complete and not cov.bounded
    assert cov.markings.tolist() == [[1, 0], [1, OMEGA]]
    assert cov.unbounded_places() == ["buf"]
    assert cov.place_bounds() == [1, None]


def test_karp_miller_textbook_pump_has_the_hand_computed_graph() -> None:
    cov = karp_miller(pump())
    nodes = {tuple(int(v) for v in row) for row in cov.markings}
    w = OMEGA
    assert nodes == {(1, 0, 0, 0), (0, 1, 0, 0), (1, 0, w, 0), (0, 0, 0, 1), (0, 1, w, 0), (0, 0, w, 1)}
    assert cov.place_bounds() == [1, 1, None, 1]
    dead = {tuple(int(v) for v in cov.markings[i]) for i in cov.dead_nodes()}
    assert dead == {(0, 0, 0, 1), (0, 0, w, 1)}
    assert cov.fireable_transitions().all()
    node = next(i for i in cov.dead_nodes() if cov.markings[i, 2] == 0)
    assert cov.firing_sequence(int(node)) == ["t3"]


def test_karp_miller_on_a_bounded_net_is_its_reachability_graph() -> None:
    cov = karp_miller(mutex())
    assert cov.complete and cov.bounded
    assert cov.markings.shape[0] == explore(mutex()).n_states


def test_karp_miller_refuses_inhibitor_arcs() -> None:
    net = make_net("inh", {"a": 1}, {"t": ({"a": 1}, {"a": 1, "b": 1})}, inhibitors={"t": {"c": 1}})
    with pytest.raises(AnalysisError):
        karp_miller(net)


def test_covering_witness_gives_a_pumping_loop() -> None:
    ss = explore(pump(), max_states=40)
    wit = covering_witness(ss)
    assert wit is not None
    assert wit.growing == ["p3"]
    assert wit.prefix == [] and wit.loop == ["t1", "t2"]


def test_covering_witness_ignores_pumps_that_change_an_inhibitor_place() -> None:
    net = make_net("guarded", {"go": 1}, {"t": ({"go": 1}, {"go": 1, "b": 1})}, inhibitors={"t": {"b": 5}})
    ss = explore(net)
    assert ss.complete and ss.n_states == 6
    assert covering_witness(ss) is None


def _replay(net: PetriNet, sequence: list[str]) -> list[np.ndarray]:
    """The markings along ``sequence`` from M0 by the firing rule (each firing checked enabled)."""
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.statespace import enabled_mask

    sn = sparse_net(net)
    index = {t.id: i for i, t in enumerate(net.transitions)}
    path = [sn.m0.astype(np.int64)[None, :]]
    for tid in sequence:
        assert enabled_mask(net, path[-1])[0, index[tid]], tid
        path.append(sn.firing_rows(path[-1], index[tid]))
    return [row[0] for row in path]


def _with_random_resets(net: PetriNet, rng: np.random.Generator, share: float) -> PetriNet:
    """``net`` plus, for about ``share`` of its transitions, a reset arc from a random place (none
    where an arc already joins the two)."""
    resets = [(str(rng.choice([p.id for p in net.places])), t.id) for t in net.transitions if rng.random() < share]
    return PetriNet(name=net.name, places=net.places, transitions=net.transitions,
                    arcs=(*net.arcs, *(Arc(source=p, target=t, reset=True) for p, t in resets
                                       if not any(a.source == p and a.target == t for a in net.arcs))),
                    initial_marking=net.initial_marking)


def test_random_walks_find_only_true_witnesses_and_dead_markings_on_random_nets() -> None:
    from test_statespace import random_net

    from coordinator.analysis.coverability import random_walks
    from coordinator.analysis.statespace import enabled_mask

    witnesses = dead = 0
    for seed in range(150):
        rng = np.random.default_rng(seed)
        net = random_net(rng, n_places=int(rng.integers(2, 6)), n_transitions=int(rng.integers(2, 7)))
        net = _with_random_resets(net, rng, 0.25)
        walks = random_walks(net, seconds=5.0, max_steps=400, length=40, seed=seed)
        for marking, sequence in walks.dead:
            dead += 1
            end = _replay(net, sequence)[-1]
            assert np.array_equal(end, marking) and not enabled_mask(net, end[None, :]).any(), seed
        if walks.witness is not None:
            witnesses += 1
            w = walks.witness
            path = _replay(net, w.prefix + w.loop * 4)  # the loop repeats, and the growing places grow
            ends = [path[len(w.prefix) + k * len(w.loop)] for k in range(5)]
            grow = [i for i, p in enumerate(net.places) if p.id in w.growing]
            assert grow and all((b[grow] > a[grow]).all() for a, b in zip(ends, ends[1:])), seed
            assert not explore(net, max_states=5_000).complete, seed  # a finite graph has no witness
    assert witnesses >= 20 and dead >= 20  # both were put to the test


def test_random_walks_find_a_pumping_loop_deeper_than_the_breadth_first_probe() -> None:
    from coordinator.analysis.coverability import random_walks
    from coordinator.analysis.structure import PROBE_STATES

    # twelve toggles make 4,096 markings at each position of a token on a chain of 30 places: the
    # probe's 2,000 markings never reach the chain's end, where grow pumps g
    toggles = {**{f"on{i}": ({f"x{i}": 1}, {f"y{i}": 1}) for i in range(12)},
               **{f"off{i}": ({f"y{i}": 1}, {f"x{i}": 1}) for i in range(12)}}
    chain = {f"s{k}": ({f"c{k}": 1}, {f"c{k + 1}": 1}) for k in range(30)}
    net = make_net("deep", {"c0": 1, **{f"x{i}": 1 for i in range(12)}},
                   {**toggles, **chain, "grow": ({"c30": 1}, {"c30": 1, "g": 1}), "use": ({"g": 2}, {})})
    assert covering_witness(explore(net, max_states=PROBE_STATES)) is None
    w = random_walks(net)
    assert w.witness is not None and w.witness.loop[-1] == "grow" and w.witness.growing == ["g"]
    a = analyse(net, max_states=20_000, coverability_seconds=1.0)
    assert a.bounded is False and a.unbounded_places == ["g"] and a.covering is not None
    assert any("the pumping witness comes from a random walk" in n for n in a.notes)
    # the chain's far places never vary in the explored markings, but the walk fired the transitions
    # that move them: no place is stable
    assert a.space is not None and (a.space.extremes()[0][[p.id == "c30" for p in net.places]] == 0).all()
    assert a.stable_marking_partial is False
    assert a.sources["stable_marking"].startswith("every place varies: between explored markings, or by the firing")


def test_a_probe_with_a_pumping_witness_and_a_dead_marking_needs_no_longer_search() -> None:
    from coordinator.analysis.structure import PROBE_STATES

    net = make_net("producer_stop", {"go": 1, "r": 1}, {
        "produce": ({"go": 1, "r": 1}, {"go": 1, "r": 1, "buf": 1}),
        "drain": ({"buf": 2}, {"buf": 1}),
        "stop": ({"go": 1}, {"done": 1}),
        "never": ({"z": 1}, {"go": 1}),
    })
    a = analyse(net, max_states=100_000)
    assert a.bounded is False and a.quasi_live is False and a.deadlock is True
    assert a.sources["deadlock"] == "reachability graph (explored part)"
    assert a.space is not None and a.space.n_states == PROBE_STATES  # the probe settled all a search could


def test_a_walk_that_meets_a_dead_marking_goes_back_a_firing_and_climbs_past_twenty_dead_ends() -> None:
    from coordinator.analysis.coverability import random_walks

    # at each of 20 stages the token goes on or dies: one walk from M0 in a million reaches grow
    stages = {**{f"go{k}": ({f"s{k}": 1}, {f"s{k + 1}": 1}) for k in range(20)},
              **{f"die{k}": ({f"s{k}": 1}, {f"dead{k}": 1}) for k in range(20)}}
    net = make_net("gauntlet", {"s0": 1}, {**stages, "grow": ({"s20": 1}, {"s20": 1, "g": 1})})
    w = random_walks(net, max_steps=20_000)
    assert w.witness is not None and w.witness.prefix == [f"go{k}" for k in range(20)]
    assert w.witness.loop == ["grow"] and w.witness.growing == ["g"]
    assert w.dead and all(seq[-1].startswith("die") for _, seq in w.dead)  # the dead ends met on the way


def test_random_walks_past_the_pumping_loop_find_a_dead_marking_the_search_does_not_reach() -> None:
    from coordinator.analysis.statespace import enabled_mask

    # grow pumps g from the start (the probe's witness), and the run halts only when a token has
    # walked down a chain of 30 places among twelve toggles: the dead markings lie beyond 20,000
    # markings of breadth-first search
    toggles = {**{f"on{i}": ({f"x{i}": 1, "run": 1}, {f"y{i}": 1, "run": 1}) for i in range(12)},
               **{f"off{i}": ({f"y{i}": 1, "run": 1}, {f"x{i}": 1, "run": 1}) for i in range(12)}}
    chain = {f"s{k}": ({f"c{k}": 1}, {f"c{k + 1}": 1}) for k in range(30)}
    net = make_net("halting", {"c0": 1, "run": 1, **{f"x{i}": 1 for i in range(12)}},
                   {**toggles, **chain, "grow": ({"run": 1}, {"run": 1, "g": 1}), "use": ({"g": 2}, {}),
                    "halt": ({"c30": 1, "run": 1}, {})})
    a = analyse(net, max_states=20_000, coverability_seconds=1.0)
    assert a.bounded is False and a.space is not None and not a.space.deadlocks().size
    assert a.deadlock is True and a.sources["deadlock"] == "a dead marking: a random walk from M0 ended in it"
    assert a.live is False and a.deadlocks
    for d in a.deadlocks:
        end = _replay(net, d.firing_sequence)[-1]
        assert {p.id: int(c) for p, c in zip(net.places, end) if c} == d.marking
        assert not enabled_mask(net, end[None, :]).any()


def test_a_transition_that_fires_changes_the_places_of_its_incidence_but_not_those_it_resets() -> None:
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.structure import _changed_by

    net = make_net("flush", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}), "flush": ({"buf": 1}, {"out": 1})})
    net = PetriNet(name=net.name, places=net.places, transitions=net.transitions,
                   arcs=(*net.arcs, Arc(source="buf", target="flush", reset=True)), initial_marking=net.initial_marking)
    sn = sparse_net(net)
    assert [p.id for p in net.places] == ["go", "buf", "out"]
    assert _changed_by(sn, np.array([True, False])).tolist() == [False, True, False]  # go: a self-loop
    assert _changed_by(sn, np.array([False, True])).tolist() == [False, False, True]  # buf: reset, maybe to 0


def test_random_walks_take_no_loop_that_changes_an_inhibitor_place_or_resets_its_growth() -> None:
    from coordinator.analysis.coverability import random_walks

    guarded = make_net("guarded", {"go": 1}, {"t": ({"go": 1}, {"go": 1, "b": 1})}, inhibitors={"t": {"b": 5}})
    w = random_walks(guarded, max_steps=2_000)
    assert w.witness is None and len(w.dead) == 1 and w.dead[0][1] == ["t"] * 5
    refill = make_net("refill", {"go": 1}, {"refill": ({"go": 1}, {"go": 1, "buf": 1})})
    refill = PetriNet(name=refill.name, places=refill.places, transitions=refill.transitions,
                      arcs=(*refill.arcs, Arc(source="buf", target="refill", reset=True)),
                      initial_marking=refill.initial_marking)
    assert random_walks(refill, max_steps=2_000).witness is None


def test_unbounded_net_is_decided_with_growing_places_and_bounds_of_the_others() -> None:
    a = analyse(pump(), max_states=100)
    assert a.bounded is False
    assert a.unbounded_places == ["p3"]
    assert a.place_bounds == {"p1": 1, "p2": 1, "p3": None, "p4": 1}
    assert a.one_safe is False
    assert a.quasi_live is True
    assert a.deadlock is True and a.deadlocks[0].firing_sequence == ["t3"]
    assert a.covering is not None and a.covering.growing == ["p3"]
    # p3 is only written: the net without it decides liveness (t3 leads to a dead end)
    assert a.projection is not None and a.live is False and a.reversible is False


def test_unbounded_net_is_found_with_the_default_limit_without_exploring_millions() -> None:
    a = analyse(producer())
    assert a.bounded is False and a.unbounded_places == ["buf"]
    assert a.states <= 50_000


def test_unbounded_net_with_an_untouched_inhibitor_is_decided_by_the_witness() -> None:
    net = make_net("inh", {"a": 1}, {"t": ({"a": 1}, {"a": 1, "b": 1})}, inhibitors={"t": {"c": 1}})
    a = analyse(net, max_states=100)
    assert a.bounded is False and a.unbounded_places == ["b"]


def test_bounded_net_that_is_too_large_is_decided_by_karp_miller() -> None:
    net = make_net("drain", {"a": 3}, {"t": ({"a": 1}, {"b": 1}), "u": ({"b": 1}, {})})
    a = analyse(net, max_states=2)
    assert not a.complete
    assert a.bounded is True
    assert a.place_bounds == {"a": 3, "b": 3}
    assert a.max_token_in_place == 3


def test_structurally_bounded_net_that_is_too_large_uses_the_invariant_bounds() -> None:
    a = analyse(mutex(), max_states=2)
    assert not a.complete and a.bounded is True
    assert a.place_bounds == {"idle1": 1, "idle2": 1, "free": 1, "crit1": 1, "crit2": 1}
    assert a.one_safe is True
    assert a.deadlock is None and a.live is None


def test_truncated_graph_still_reports_the_deadlocks_it_found() -> None:
    net = make_net("stop", {"a": 1}, {"end": ({"a": 1}, {}), "u": ({"a": 1}, {"a": 1, "c": 1})},
                   inhibitors={"u": {"d": 1}})
    a = analyse(net, max_states=6)
    assert not a.complete and a.coverability is None
    assert a.bounded is False and a.unbounded_places == ["c"]
    assert a.quasi_live is True
    assert a.deadlock is True and a.deadlocks[0].firing_sequence == ["end"]


def test_liveness_levels_follow_the_terminal_components() -> None:
    a = analyse(levels_net())
    assert a.liveness == {"t_left": 1, "l_loop": 3, "t_right": 1, "r_loop": 3, "t_dead": 0, "x_go": 4, "y_go": 4}
    assert a.quasi_live is False and a.live is False
    assert a.dead_transitions == ["t_dead"]
    assert a.reversible is False and a.home_states == 0
    assert a.stable_places == ["z"] and a.stable_marking is True
    assert a.deadlock is False


def test_mutex_is_live_reversible_and_safe_with_an_effective_conflict() -> None:
    a = analyse(mutex())
    assert (a.states, a.edges) == (3, 4)
    assert a.live and a.quasi_live and a.reversible and a.one_safe and a.bounded
    assert a.home_states == 3
    assert a.max_token_per_marking == 3
    assert [(c.place, c.transitions, c.effective) for c in a.conflicts] == [("free", ["enter1", "enter2"], True)]
    assert a.conservative and a.consistent


def test_conflict_that_never_bites_is_not_effective() -> None:
    net = make_net("readers", {"p": 1}, {"a": ({"p": 1}, {"p": 1, "q": 1}), "b": ({"p": 1}, {"p": 1, "r": 1}),
                                         "c": ({"q": 1}, {}), "d": ({"r": 1}, {})},
                   inhibitors={"a": {"q": 1}, "b": {"r": 1}})
    a = analyse(net)
    assert [(c.place, c.effective) for c in a.conflicts] == [("p", False)]


def test_deadlocks_come_with_shortest_firing_sequences() -> None:
    net = make_net("paths", {"s": 1}, {
        "long1": ({"s": 1}, {"m": 1}), "long2": ({"m": 1}, {"n": 1}), "long3": ({"n": 1}, {"end": 1}),
        "short": ({"s": 1}, {"end": 1}),
    })
    a = analyse(net)
    assert a.deadlock and a.n_deadlocks == 1
    assert a.deadlocks[0].marking == {"end": 1}
    assert a.deadlocks[0].firing_sequence == ["short"]


def test_declared_home_marking_is_checked_as_a_home_state() -> None:
    base = make_net("finish", {"todo": 2}, {"work": ({"todo": 1}, {"done": 1})})
    net = PetriNet(name=base.name, places=base.places, transitions=base.transitions, arcs=base.arcs,
                   initial_marking=base.initial_marking, home_marking=Marking({"done": 2}))
    a = analyse(net)
    assert a.home_marking_is_home is True and a.home_states == 1 and a.reversible is False


def test_ordinary_view_drops_events_and_keeps_them_in_labels() -> None:
    net = PetriNet(
        name="evt", places=(Place(id="a"), Place(id="b")),
        transitions=(Transition(id="go", events=("ext:button",)),),
        arcs=(Arc(source="a", target="go"), Arc(source="go", target="b")),
        initial_marking=Marking({"a": 1}),
    )
    view = ordinary_view(net)
    assert view.transitions[0].events == ()
    assert "ext:button" in view.transitions[0].label
    assert np.array_equal(view.incidence, net.incidence)


def test_growing_record_only_place_leaves_liveness_decidable_on_the_rest() -> None:
    net = make_net("counting", {"idle": 1}, {
        "start": ({"idle": 1}, {"busy": 1}),
        "done": ({"busy": 1}, {"idle": 1, "count": 1}),
    })
    a = analyse(net, max_states=100)
    assert a.bounded is False and a.unbounded_places == ["count"]
    assert a.projection is not None and a.projection.complete
    assert [p.id for p in a.projection.net.places] == ["idle", "busy"]
    assert a.live is True and a.deadlock is False and a.quasi_live is True
    assert a.liveness == {"start": 4, "done": 4}
    assert a.reversible is False


def test_growing_place_that_is_read_keeps_liveness_undecided() -> None:
    base = pump()
    net = make_net("pump_read", {"p1": 1}, {
        "t1": ({"p1": 1}, {"p2": 1}),
        "t2": ({"p2": 1}, {"p1": 1, "p3": 1}),
        "t3": ({"p1": 1}, {"p4": 1}),
        "drain": ({"p3": 1}, {}),
    })
    assert [p.id for p in net.places] == [p.id for p in base.places]
    a = analyse(net, max_states=100)
    assert a.bounded is False and a.unbounded_places == ["p3"]
    assert a.projection is None and a.reversible is None
    # t3 leads to a dead end: a reachable deadlock alone rules out liveness
    assert a.deadlock is True and a.live is False and "deadlock" in a.sources["live"]


def test_markable_places_and_transitions_hold_every_reachable_one_on_random_nets() -> None:
    from test_statespace import random_net

    from coordinator.analysis.matrices import sparse_net

    dead_seen = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        net = random_net(rng, n_places=int(rng.integers(3, 8)), n_transitions=int(rng.integers(3, 10)))
        marking = {p.id: int(rng.integers(0, 3)) if rng.random() < 0.4 else 0 for p in net.places}
        net = PetriNet(name=net.name, places=net.places, transitions=net.transitions, arcs=net.arcs,
                       initial_marking=Marking(marking))
        space = explore(net, max_states=20_000)
        if not space.complete:
            continue
        places, fires = sparse_net(net).markable()
        fired = np.zeros(len(net.transitions), dtype=bool)
        fired[np.unique(space.transition)] = True
        assert not (fired & ~fires).any(), seed  # a transition outside the set never fires
        assert not ((space.states.max(axis=0) > 0) & ~places).any(), seed  # a place outside it stays empty
        dead_seen += int((~fires).sum())
    assert dead_seen > 0  # the property was put to the test


def test_the_lone_input_trap_keeps_a_transition_enabled_in_every_reachable_marking_on_random_nets() -> None:
    from test_statespace import random_net

    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.statespace import enabled_mask

    claimed = traps = 0
    for seed in range(300):
        rng = np.random.default_rng(seed)
        net = random_net(rng, n_places=int(rng.integers(2, 7)), n_transitions=int(rng.integers(2, 8)))
        net = _with_random_resets(net, rng, 0.2)
        sn = sparse_net(net)
        free, trap = sn.lone_input_trap()
        marked_trap = bool((trap & (sn.m0 > 0)).any())
        if not (free.any() or marked_trap):
            continue
        claimed += 1
        space = explore(net, max_states=3_000)
        assert enabled_mask(net, space.states).any(axis=1).all(), seed  # no explored marking is dead
        if marked_trap:
            traps += 1
            assert (space.states[:, trap] > 0).any(axis=1).all(), seed  # the trap stays marked
    assert claimed >= 30 and traps >= 10  # the rule was put to the test, the trap part too


def test_a_marked_trap_of_lone_input_places_shows_an_unbounded_net_never_dead() -> None:
    # a and b pass one token around; each is the only input place of a transition, and {a, b} is a
    # trap: some transition is enabled in every reachable marking, which the search cannot show
    net = make_net("ring_pump", {"a": 1, "x": 1}, {
        "ab": ({"a": 1}, {"b": 1, "c": 1}),
        "ba": ({"b": 1}, {"a": 1}),
        "use": ({"c": 2, "x": 1}, {"x": 1, "d": 1}),
    })
    a = analyse(net, max_states=100)
    assert a.bounded is False and a.complete is False
    assert a.deadlock is False and a.sources["deadlock"].startswith("structure: the trap {a, b}")
    # with a reset arc that empties a without putting a token back, {a, b} is no trap: not decided
    reset = PetriNet(name=net.name, places=net.places, transitions=net.transitions,
                     arcs=(*net.arcs, Arc(source="a", target="use", reset=True)), initial_marking=net.initial_marking)
    assert analyse(reset, max_states=100).deadlock is not False
    # a transition with no input place and no inhibitor arc is enabled in every marking
    source = make_net("source", {"x": 1}, {"make": ({}, {"c": 1}), "use": ({"c": 2, "x": 1}, {"d": 1})})
    a = analyse(source, max_states=100)
    assert a.deadlock is False and a.sources["deadlock"].startswith("structure: transition make has no input place")


def test_an_unbounded_net_gets_its_dead_transitions_from_the_unmarked_siphon_without_karp_miller() -> None:
    net = make_net("producer_dead", {"go": 1, "r": 1}, {
        "produce": ({"go": 1, "r": 1}, {"go": 1, "r": 1, "buf": 1}),
        "drain": ({"buf": 2}, {"buf": 1}),  # buf is read: no projection decides liveness
        "never": ({"z": 1}, {"go": 1}),
    })
    a = analyse(net, max_states=100)
    assert a.bounded is False and a.covering is not None
    assert a.coverability is None  # the witness and the siphon leave Karp-Miller nothing the columns need
    assert any("coverability graph was not built" in n for n in a.notes)
    assert a.quasi_live is False and a.live is False
    assert a.sources["quasi_live"].startswith("structure") and a.sources["live"].startswith("structure")
    assert any("never" in n and "siphon" in n for n in a.notes)
    # z is never marked and produce only reads r: both keep their counts
    assert a.stable_marking is True and "r, z" in a.sources["stable_marking"]
    assert a.reversible is None


def test_a_place_only_read_is_stable_on_a_truncated_graph_though_every_transition_may_fire() -> None:
    a = analyse(producer(), max_states=100, max_coverability_nodes=1)
    assert a.quasi_live is True and not any("siphon" in n for n in a.notes)
    assert a.stable_marking is True and a.sources["stable_marking"].endswith("the places go")


def test_liveness_comes_from_a_compiled_pass_over_the_edges_when_they_do_not_fit_scipys_passes() -> None:
    from coordinator.analysis.statespace import implicit_pass_bytes
    from coordinator.analysis.structure import graph_pass_bytes

    # ten independent two-state cycles: 1,024 markings, 10,240 edges, one terminal component
    net = make_net("cycles", {f"a{i}": 1 for i in range(10)},
                   {**{f"go{i}": ({f"a{i}": 1}, {f"b{i}": 1}) for i in range(10)},
                    **{f"back{i}": ({f"b{i}": 1}, {f"a{i}": 1}) for i in range(10)}})
    full = analyse(net)
    space = full.space
    assert space is not None and full.graph_work_done and full.live
    # a budget that holds the graph and the compiled pass, not scipy's passes over its edges
    budget = 2 * (space.nbytes + implicit_pass_bytes(space.n_states)) + (1 << 16)
    assert space.nbytes + graph_pass_bytes(space.n_states, space.n_edges) > budget
    small = analyse(net, max_bytes=budget)
    assert small.complete and not small.graph_work_done
    assert small.liveness == full.liveness and small.live and small.reversible and small.home_states == 1024
    assert small.sources["live"] == "reachability graph, a compiled pass over its edges"
    assert any("by a compiled pass over the edges" in n for n in small.notes)


def test_a_graph_whose_edges_fill_the_budget_is_searched_on_without_them_and_still_gets_its_liveness() -> None:
    # fourteen independent two-state cycles: 16,384 markings, 229,376 edges (1.8 MB of them)
    net = make_net("cycles", {f"a{i}": 1 for i in range(14)},
                   {**{f"go{i}": ({f"a{i}": 1}, {f"b{i}": 1}) for i in range(14)},
                    **{f"back{i}": ({f"b{i}": 1}, {f"a{i}": 1}) for i in range(14)}})
    budget = 5 * 2**20
    assert explore(net, max_bytes=budget // 2).stopped_by == "max_memory"  # the edges do not fit
    a = analyse(net, max_bytes=budget)
    assert a.complete and a.states == 16_384 and a.edges == 229_376
    assert a.space is not None and not a.space.edges_kept
    assert a.live and a.reversible and a.quasi_live and a.deadlock is False and a.home_states == 16_384
    assert a.space.edges_shed_at is not None and 0 < a.space.edges_shed_at < 16_384
    assert any("the search went on counting them without keeping them, and the graph is complete" in n
               for n in a.notes)
    assert any("the edges were not kept" in n for n in a.notes)


def test_a_graph_without_cycles_by_the_state_equation_gets_its_liveness_without_a_pass_over_it() -> None:
    # ten tokens each moving a -> b -> c, or a -> c at once: 3^10 = 59,049 markings, no T-semiflow
    # (tokens only move on), so every component is one marking and the one deadlock is the home state
    net = make_net("onward", {f"a{i}": 1 for i in range(10)},
                   {**{f"ab{i}": ({f"a{i}": 1}, {f"b{i}": 1}) for i in range(10)},
                    **{f"bc{i}": ({f"b{i}": 1}, {f"c{i}": 1}) for i in range(10)},
                    **{f"ac{i}": ({f"a{i}": 1}, {f"c{i}": 1}) for i in range(10)}})
    full = analyse(net)
    assert full.complete and full.states == 59_049 and full.space is not None and full.space.edges_kept
    budget = 16 * 2**20  # the edges (4.7 MB) do not fit half of it beside the markings, the markings do
    small = analyse(net, max_bytes=budget, engine="explicit")
    assert small.complete and small.space is not None and not small.space.edges_kept
    assert small.space.edges_shed_at is not None
    assert (small.liveness, small.quasi_live, small.live, small.reversible, small.home_states) == (
        full.liveness, full.quasi_live, full.live, full.reversible, full.home_states)
    assert set(small.liveness.values()) == {1} and small.home_states == 1 and small.reversible is False
    assert small.sources["live"].endswith("without cycles since no T-semiflow exists (state equation)")
    assert any("every strongly connected component of the graph is one marking" in n for n in small.notes)


def test_when_the_search_without_edges_stops_too_its_markings_still_show_every_transition_fires() -> None:
    # sixteen cycles: 65,536 markings, 2,097,152 edges; half of 5 MiB holds neither the graph nor
    # its markings alone, once the edges are dropped
    net = make_net("cycles", {f"a{i}": 1 for i in range(16)},
                   {**{f"go{i}": ({f"a{i}": 1}, {f"b{i}": 1}) for i in range(16)},
                    **{f"back{i}": ({f"b{i}": 1}, {f"a{i}": 1}) for i in range(16)}})
    a = analyse(net, max_bytes=5 * 2**20, engine="explicit")
    assert not a.complete and a.stopped_by == "max_memory"
    assert a.space is not None and not a.space.edges_kept and a.space.n_states < 65_536
    assert a.space.edges_shed_at is not None and a.space.edges_shed_at < a.space.n_states
    assert any("without keeping them, and stopped too, after" in n for n in a.notes)
    assert a.quasi_live is True and a.sources["quasi_live"] == "reachability graph (explored part)"
    assert a.live is None
    # each a_i and b_i is the only input place of a transition and {a_i, b_i} a marked trap
    assert a.deadlock is False and a.sources["deadlock"].startswith("structure: the trap {")


def conflict_flags(net: PetriNet, **how: object) -> tuple[list[tuple[str, bool | None]], bool]:
    from coordinator.analysis.structure import _conflicts

    conflicts, finished = _conflicts(net, explore(net, max_states=5_000), **how)  # type: ignore[arg-type]
    return [(c.place, c.effective) for c in conflicts], finished


def test_the_edges_decide_the_conflicts_as_the_markings_do_on_random_nets_with_inhibitor_arcs() -> None:
    from test_statespace import random_net

    compared = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        net = random_net(rng, n_places=int(rng.integers(3, 7)), n_transitions=int(rng.integers(4, 10)))
        if not explore(net, max_states=5_000).complete:
            continue
        blocks, done = conflict_flags(net)
        edges, finished = conflict_flags(net, seconds=-1.0, on_edges=True)  # the blocks get no time at all
        assert done and finished and edges == blocks, seed
        compared += any(flag is not None for _, flag in blocks)
    assert compared >= 30


def test_a_conflict_of_more_than_64_transitions_is_decided_pair_by_pair_on_the_edges() -> None:
    n = 70
    bites = make_net("bites", {"p": 1}, {f"t{i}": ({"p": 1}, {f"q{i}": 1}) for i in range(n)})
    loops = make_net("loops", {"p": 1, **{f"r{i}": 1 for i in range(n)}},
                     {f"t{i}": ({"p": 1, f"r{i}": 1}, {"p": 1, f"r{i}": 1}) for i in range(n)})
    for net, effective in ((bites, True), (loops, False)):
        flags, finished = conflict_flags(net, seconds=-1.0, on_edges=True)
        assert finished and flags[0] == ("p", effective)
        assert conflict_flags(net) == (flags, True)


def test_without_their_edges_the_conflicts_left_when_time_runs_out_are_undecided() -> None:
    net = mutex()
    assert conflict_flags(net, seconds=-1.0) == ([("free", None)], False)
    assert conflict_flags(net, seconds=-1.0, on_edges=True) == ([("free", True)], True)


def test_an_unbounded_net_whose_probe_misses_a_transition_is_searched_on_to_see_it_fire() -> None:
    net = make_net("late", {"go": 1}, {
        "produce": ({"go": 1}, {"go": 1, "buf": 1}),
        "late": ({"buf": 2500}, {"buf": 2500, "done": 1}),  # needs 2,500 firings of produce first
    })
    a = analyse(net, max_states=5000, max_coverability_nodes=1)
    assert a.bounded is False and a.covering is not None
    assert a.quasi_live is True and a.sources["quasi_live"] == "reachability graph (explored part)"
    assert 2500 < a.states <= 5000  # past the probe's 2,000, up to the state limit
    assert any("state limit (5,000 markings)" in n for n in a.notes)
