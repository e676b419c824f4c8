"""The compiled explorer against the firing rule of coordinator.net and against a plain reference search."""

from __future__ import annotations

import itertools
import threading
from collections import deque

import numpy as np
import pytest
from analysis_nets import make_net

from coordinator.analysis.statespace import StateSpace, enabled_mask, explore, packed_layout
from coordinator.errors import AnalysisError
from coordinator.net import Marking, PetriNet
from tests.unit.mcc_models import MCC


def reference_graph(net: PetriNet, limit: int = 100_000) -> tuple[set[Marking], set[tuple[Marking, str, Marking]]]:
    """Breadth-first search with PetriNet.fire, one marking at a time."""
    seen = {net.initial_marking}
    edges: set[tuple[Marking, str, Marking]] = set()
    todo = deque([net.initial_marking])
    while todo and len(seen) < limit:
        m = todo.popleft()
        for t in net.enabled_transitions(m):
            m2 = net.fire(m, t)
            edges.add((m, t, m2))
            if m2 not in seen:
                seen.add(m2)
                todo.append(m2)
    return seen, edges


def graph_of(ss: StateSpace) -> tuple[set[Marking], set[tuple[Marking, str, Marking]]]:
    marks = [ss.marking(i) for i in range(ss.n_states)]
    ids = [t.id for t in ss.net.transitions]
    edges = {(marks[s], ids[t], marks[d]) for s, d, t in zip(ss.src.tolist(), ss.dst.tolist(), ss.transition.tolist())}
    return set(marks), edges


def assert_same_as_reference(net: PetriNet, **kwargs: object) -> StateSpace:
    ss = explore(net, **kwargs)  # type: ignore[arg-type]
    ref_states, ref_edges = reference_graph(net)
    states, edges = graph_of(ss)
    assert ss.complete
    assert ss.n_states == len(states) == len(ref_states)
    assert states == ref_states
    assert ss.n_edges == len(edges) == len(ref_edges)
    assert edges == ref_edges
    return ss


def mutex() -> PetriNet:
    return make_net("mutex", {"idle1": 1, "idle2": 1, "free": 1}, {
        "enter1": ({"idle1": 1, "free": 1}, {"crit1": 1}),
        "leave1": ({"crit1": 1}, {"idle1": 1, "free": 1}),
        "enter2": ({"idle2": 1, "free": 1}, {"crit2": 1}),
        "leave2": ({"crit2": 1}, {"idle2": 1, "free": 1}),
    })


def test_initial_marking_is_state_zero_and_edges_are_sorted_by_source() -> None:
    ss = assert_same_as_reference(mutex())
    assert ss.marking(0) == mutex().initial_marking
    assert ss.n_states == 3 and ss.n_edges == 4
    assert np.all(np.diff(ss.src) >= 0)
    assert ss.src.dtype == ss.dst.dtype == ss.transition.dtype == np.int32


def test_weighted_arcs_and_inhibitor_arcs_follow_the_firing_rule() -> None:
    net = make_net("weighted", {"a": 4}, {
        "split": ({"a": 2}, {"b": 3}),
        "merge": ({"b": 3}, {"a": 1, "c": 1}),
        "guarded": ({"c": 1}, {"a": 1}),
    }, inhibitors={"guarded": {"b": 2}})
    assert_same_as_reference(net)


def test_counts_above_255_switch_the_storage_to_a_wider_dtype() -> None:
    net = make_net("counter", {"go": 1}, {"tick": ({"go": 1}, {"go": 1, "n": 1})}, inhibitors={"tick": {"n": 300}})
    ss = assert_same_as_reference(net)
    assert_matches_reference(net)
    assert ss.n_states == 301
    assert ss.states.dtype == np.uint16
    assert int(ss.states[:, ss.net.place_index["n"]].max()) == 300


def test_more_than_64_bits_of_marking_uses_the_verified_hash_and_stays_exact() -> None:
    chain = {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(80)}
    chain["back"] = ({"p80": 1}, {"p0": 1})
    net = make_net("chain", {"p0": 1, "p40": 1}, chain)
    ss = assert_same_as_reference(net)
    assert_matches_reference(net)
    assert ss.n_states == 81 * 80 // 2 + 81  # two tokens on a ring of 81 places


def test_priority_fires_only_the_highest_enabled_level() -> None:
    net = make_net("prio", {"a": 1}, {
        "slow": ({"a": 1}, {"b": 1}),
        "fast": ({"a": 1}, {"c": 1}),
        "back": ({"c": 1}, {"a": 1}),
    })
    ss = explore(net, priority=np.array([0, 1, 0]))
    assert ss.n_states == 2
    assert [net.transitions[int(t)].id for t in ss.transition] == ["fast", "back"]
    with pytest.raises(AnalysisError):
        explore(net, priority=np.array([0, 1]))


def test_max_states_truncates_and_says_so() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    ss = explore(net, max_states=50)
    assert not ss.complete
    assert ss.n_states == 50
    assert int(ss.dst.max()) < 50
    assert not ss.expanded.all()
    assert ss.deadlocks().size == 0


@pytest.mark.parametrize("model", ["FMS-PT-00002", "Railroad-PT-005"])
def test_a_search_that_stops_at_its_limit_at_once_expands_a_prefix_of_the_finished_level(model: str) -> None:
    """``finish_level=False`` (the automatic engine's explicit share): the same markings in the same
    order, fewer expanded, and what was expanded has the edges the finished search gives it."""
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    limit = explore(net).n_states // 3
    level = explore(net, max_states=limit)
    now = explore(net, max_states=limit, finish_level=False)
    assert not now.complete and not level.complete and now.n_states == level.n_states == limit
    assert np.array_equal(now.words, level.words) and np.array_equal(now.parent, level.parent)
    done = int(np.flatnonzero(now.expanded).max()) + 1
    assert not now.expanded[done:].any() and now.n_edges < level.n_edges  # the level went on
    assert np.array_equal(now.expanded[:done - 1], level.expanded[:done - 1])
    assert np.array_equal(now.out_ptr[:done + 1], level.out_ptr[:done + 1])
    assert np.array_equal(now.dst, level.dst[:now.n_edges])
    assert set(now.deadlocks().tolist()) <= set(level.deadlocks().tolist())


def test_index_of_and_firing_sequence_give_a_shortest_path() -> None:
    net = make_net("line", {"p0": 1}, {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(5)}
                   | {"skip": ({"p0": 1}, {"p4": 1})})
    ss = explore(net)
    target = ss.index_of({"p5": 1})
    assert ss.firing_sequence(target) == ["skip", "t4"]
    assert ss.deadlocks().tolist() == [target]
    with pytest.raises(KeyError):
        ss.index_of({"p5": 2})
    m = net.initial_marking
    for t in ss.firing_sequence(target):
        m = net.fire(m, t)
    assert m == Marking({"p5": 1})


def test_successors_predecessors_and_the_sparse_graph_agree() -> None:
    ss = explore(mutex())
    mat = ss.successor_matrix()
    assert mat.shape == (3, 3) and int(mat.sum()) == ss.n_edges
    assert (ss.predecessor_matrix() != mat.T).nnz == 0
    s0 = ss.successors(0)
    assert sorted(t for t, _ in s0) == ["enter1", "enter2"]
    for t, j in s0:
        assert (0, t) in ss.predecessors(j)


def test_enabled_mask_matches_the_net_for_every_state() -> None:
    net = mutex()
    ss = explore(net)
    mask = enabled_mask(net, ss.states)
    for i in range(ss.n_states):
        expected = [net.enabled(ss.marking(i), t.id) for t in net.transitions]
        assert mask[i].tolist() == expected


@pytest.mark.parametrize("model", ["ERK-PT-000001", "Philosophers-PT-000005", "CircularTrains-PT-012",
                                   "Eratosthenes-PT-010", "TokenRing-PT-005"])
def test_mcc_models_give_the_same_graph_as_the_one_marking_at_a_time_search(model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    assert_same_as_reference(load_pnml(str(MCC / model / "model.pnml")))


def test_progress_is_reported_with_growing_counts() -> None:
    seen: list[tuple[int, int]] = []
    ss = explore(mutex(), progress=lambda states, edges: seen.append((states, edges)))
    assert seen and seen[-1] == (ss.n_states, ss.n_edges)
    assert all(a <= b for a, b in itertools.pairwise(seen))


def test_inhibitor_arcs_and_priorities_combine() -> None:
    net = make_net("both", {"a": 2}, {
        "low": ({"a": 1}, {"b": 1}),
        "high": ({"a": 1}, {"c": 1}),
    }, inhibitors={"high": {"c": 1}})
    ss = explore(net, priority=np.array([0, 1]))
    # high fires first, then is inhibited by its own output; low takes the last token
    assert [ss.marking(i) for i in range(ss.n_states)] == [Marking({"a": 2}), Marking({"a": 1, "c": 1}),
                                                         Marking({"b": 1, "c": 1})]


# ------------------------------------------------------------ array for array against a plain search
MCC_MODELS = sorted(p.name for p in MCC.iterdir() if (p / "model.pnml").exists() and p.name != "Kanban-PT-00005")


def reference_space(net: PetriNet, max_states: int = 10**9, priority: np.ndarray | None = None) -> dict[str, object]:
    """Breadth-first search over tuples and a dict with explore's numbering, edge order, parent
    edges and truncation; a reset place ends a firing with ``Post[p, t]`` tokens (the level in progress is finished, edges to new markings dropped)."""
    pre, inh, inc = net.pre.T.tolist(), net.inhibitor.T.tolist(), net.incidence.T.tolist()
    post, rst = net.post.T.tolist(), net.reset.T.tolist()
    states = [tuple(net.initial_vector.tolist())]
    seen = {states[0]: 0}
    src: list[int] = []
    dst: list[int] = []
    tr: list[int] = []
    parent = [-1]
    truncated: set[int] = set()
    lo, hi = 0, 1
    while lo < hi:
        for i in range(lo, hi):
            m = states[i]
            enabled = [t for t in range(len(pre))
                       if all(m[p] >= w for p, w in enumerate(pre[t]) if w)
                       and all(m[p] < w for p, w in enumerate(inh[t]) if w)]
            if priority is not None and enabled:
                top = max(int(priority[t]) for t in enabled)
                enabled = [t for t in enabled if int(priority[t]) == top]
            for t in enabled:
                succ = tuple(post[t][p] if rst[t][p] else a + d for p, (a, d) in enumerate(zip(m, inc[t])))
                j = seen.get(succ)
                if j is None:
                    if len(states) == max_states:
                        truncated.add(i)
                        continue
                    j = seen[succ] = len(states)
                    states.append(succ)
                    parent.append(len(src))
                src.append(i)
                dst.append(j)
                tr.append(t)
        lo, hi = hi, len(states)
        if truncated:
            break
    complete = not truncated
    expanded = [complete or (i < lo and i not in truncated) for i in range(len(states))]
    return {"states": np.array(states, dtype=np.int64).reshape(len(states), len(net.places)),
            "src": src, "dst": dst, "transition": tr, "parent_edge": parent, "expanded": expanded,
            "complete": complete}


def assert_matches_reference(net: PetriNet, **kwargs: object) -> StateSpace:
    ss = explore(net, **kwargs)  # type: ignore[arg-type]
    ref = reference_space(net, **kwargs)  # type: ignore[arg-type]
    assert ss.complete == ref["complete"]
    assert np.array_equal(ss.states.astype(np.int64), ref["states"])
    for name in ("src", "dst", "transition", "parent_edge", "expanded"):
        assert getattr(ss, name).tolist() == ref[name], name
    assert ss.parent_edge.dtype == ss.out_ptr.dtype == np.int64
    assert ss.src.dtype == ss.dst.dtype == ss.transition.dtype == np.int32
    assert ss.out_ptr.tolist() == np.searchsorted(ss.src, np.arange(ss.n_states + 1)).tolist()
    return ss


@pytest.mark.parametrize("model", MCC_MODELS)
def test_mcc_models_match_the_reference_search_array_for_array_also_when_truncated(model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    full = assert_matches_reference(net)
    assert full.complete
    for limit in (1, 2, 17, full.n_states // 3, full.n_states - 1, full.n_states):
        if limit >= 1:
            assert_matches_reference(net, max_states=limit)


def random_net(rng: np.random.Generator, n_places: int, n_transitions: int) -> PetriNet:
    """A random net with weighted arcs, inhibitor arcs and transitions without input places."""
    places = [f"p{i}" for i in range(n_places)]
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    inhibitors: dict[str, dict[str, int]] = {}
    for t in range(n_transitions):
        ins = rng.choice(places, size=int(rng.integers(0, 3)), replace=False)
        outs = rng.choice(places, size=int(rng.integers(0, 3)), replace=False)
        transitions[f"t{t}"] = ({p: int(rng.integers(1, 3)) for p in ins}, {p: int(rng.integers(1, 3)) for p in outs})
        if rng.random() < 0.4:
            inhibitors[f"t{t}"] = {str(rng.choice(places)): int(rng.integers(1, 4))}
    marking = {p: int(rng.integers(0, 3)) for p in places}
    return make_net("random", marking, transitions, places=tuple(places), inhibitors=inhibitors)


@pytest.mark.parametrize("seed", range(12))
def test_random_nets_with_inhibitor_arcs_and_priorities_match_the_reference_search(seed: int) -> None:
    rng = np.random.default_rng(seed)
    net = random_net(rng, n_places=int(rng.integers(3, 7)), n_transitions=int(rng.integers(3, 9)))
    levels = rng.integers(0, 3, size=len(net.transitions))
    for priority in (None, levels):
        for limit in (1, 7, 60, 400):
            assert_matches_reference(net, max_states=limit, priority=priority)


def test_source_transitions_weights_and_inhibitors_follow_the_firing_rule() -> None:
    net = make_net("weighted", {"a": 4}, {
        "split": ({"a": 2}, {"b": 3}),
        "merge": ({"b": 3}, {"a": 1, "c": 1}),
        "guarded": ({"c": 1}, {"a": 1}),
        "source": ({}, {"d": 1}),
    }, inhibitors={"guarded": {"b": 2}, "source": {"d": 2}})
    assert_same_as_reference(net)
    assert_matches_reference(net)



def test_a_transition_that_never_fires_is_listed_under_a_place_no_marking_marks(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # "stuck" consumes from "a" (marked) and from the unmarked siphon {s, u}: its trigger in the
    # search is s, which no marking marks, so it is never tested; the graph is the firing rule's
    from coordinator.analysis import statespace
    from coordinator.analysis.reach_kernel import HEAD
    from coordinator.analysis.statespace import arc_table

    tables: list[np.ndarray] = []
    monkeypatch.setattr(statespace, "_FEW_TRANSITIONS", 0)  # these lists, not the dense matrices, even so small
    monkeypatch.setattr(statespace, "arc_table", lambda net: tables.append(arc_table(net)) or tables[-1])

    net = make_net("siphon", {"a": 2, "b": 0}, {
        "go": ({"a": 1}, {"b": 1}),
        "back": ({"b": 1}, {"a": 1}),
        "stuck": ({"a": 1, "s": 1}, {"u": 1}),
        "refill": ({"u": 1}, {"s": 1, "b": 1}),
    }, places=("a", "b", "s", "u"))
    tab = arc_table(net)
    assert tab[0] == HEAD
    in_ptr, in_p = tab[tab[0]:tab[1]], tab[tab[1]:tab[2]]
    firsts = [int(in_p[in_ptr[t]]) for t in range(4)]
    assert firsts == [0, 1, 2, 3]  # go: a; back: b; stuck: s (not a, its lower-numbered place); refill: u
    assert sorted(in_p[in_ptr[2]:in_ptr[3]].tolist()) == [0, 2]
    ss = assert_same_as_reference(net)
    assert ss.n_states == 3 and set(ss.transition.tolist()) == {0, 1}
    assert_matches_reference(net)
    assert len(tables) == 2  # both searches ran on these lists


def test_a_count_beyond_int32_is_a_clear_error_not_a_wrong_graph() -> None:
    net = make_net("huge", {"go": 1}, {"t": ({"go": 1}, {"go": 1, "n": 2**30})})
    with pytest.raises(AnalysisError, match="2\\*\\*31 - 1"):
        explore(net)
    edge = make_net("edge", {"go": 1, "n": 2**30 - 1}, {"t": ({"go": 1}, {"n": 2**30})})
    assert int(explore(edge).states.max()) == 2**31 - 1  # the largest count an int32 holds is fine


def test_progress_can_stop_a_long_search() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    calls: list[int] = []

    def stop(states: int, edges: int) -> None:
        calls.append(states)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        explore(net, max_states=200_000, progress=stop)
    assert calls == [65_537]
    assert explore(net, max_states=10).n_states == 10  # the hook is cleared after an interrupted search


def test_a_stop_event_ends_the_search_at_its_next_report_with_what_it_found() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    stop = threading.Event()
    stop.set()  # set before the search: it ends at its first report, after 65,536 expanded markings
    space = explore(net, max_states=200_000, stop=stop)
    assert (space.complete, space.stopped_by, space.n_states) == (False, "stopped", 65_537)
    assert int(space.expanded.sum()) == 65_536 and not space.expanded[-1]
    assert explore(net, max_states=10).n_states == 10  # the event is cleared with the hook


def test_a_search_in_another_thread_runs_beside_this_one_and_stops_when_asked() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    stop = threading.Event()
    reports: list[int] = []
    found: list[StateSpace] = []

    def progress(states: int, edges: int) -> None:
        reports.append(states)
        if len(reports) == 3:
            stop.set()

    helper = threading.Thread(target=lambda: found.append(explore(net, max_states=2_000_000, progress=progress,
                                                                    stop=stop)))
    helper.start()
    assert explore(net, max_states=1_000).n_states == 1_000  # this thread's search has no hook: not stopped
    helper.join()
    assert found[0].stopped_by == "stopped" and found[0].n_states == 3 * 65_536 + 1


def test_a_count_beyond_its_narrow_field_widens_the_field_and_never_wraps() -> None:
    # a counter to 300: with a (wrong) bound of 1, of 7 and of 255, and with none (8 bits), the
    # field overflows; the search widens it and repacks the markings found, never storing a wrapped count
    net = make_net("counter", {"go": 1}, {"tick": ({"go": 1}, {"go": 1, "n": 1})}, inhibitors={"tick": {"n": 300}})
    n = net.place_index["n"]
    for claimed in (1, 7, 255, -1):
        bounds = np.array([1, claimed], np.int64) if n == 1 else np.array([claimed, 1], np.int64)
        ss = assert_same_as_reference(net, bounds=bounds)
        assert sorted(ss.states[:, n].tolist()) == list(range(301))
        assert ss.packed_bits >= 1 + 9  # the counter's field was widened to hold 300


def test_a_one_safe_net_packs_one_bit_a_place_and_reports_its_bytes_per_marking() -> None:
    chain = {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(80)}
    chain["back"] = ({"p80": 1}, {"p0": 1})
    net = make_net("ring", {"p0": 1}, chain)
    ss = assert_same_as_reference(net, bounds=np.ones(81, np.int64))  # 81 one-bit fields: two words
    assert ss.packed_bits == 81
    assert 16 <= ss.memory_per_marking_bytes == ss.store_bytes / ss.n_states
    wide = explore(net)  # no proven bound: 8 bits a place, 11 words
    assert wide.packed_bits == 8 * 81 and wide.n_states == ss.n_states
    assert wide.memory_per_marking_bytes > ss.memory_per_marking_bytes


def test_packed_fields_never_straddle_two_words() -> None:
    layout, words = packed_layout(np.array([31, 31, 3, 1, 31, 31], np.int64))
    n = 6
    word, shift, width = layout[:n], layout[n:2 * n], layout[2 * n:]
    assert words == 3 and word.tolist() == [0, 0, 1, 1, 1, 2]
    assert ((shift + width) <= 64).all()


def test_analyze_json_reports_bytes_per_marking() -> None:
    from coordinator.analysis.robotic import report

    out = report(mutex())
    assert out["memory_per_marking_bytes"] > 0
    assert out["packed_bits_per_marking"] == len(mutex().places)  # every place bounded by 1


@pytest.mark.parametrize("model", ["CircularTrains-PT-012", "FMS-PT-00002", "Railroad-PT-005"])
def test_widening_fields_mid_search_keeps_the_graph_exact_also_when_truncated(model: str) -> None:
    # every place claimed to hold at most 0 tokens: its field starts at the bits of M0 and each count
    # above overflows, so fields widen while the search runs (the parent re-expanded, the markings
    # repacked), also in a level the state limit cuts
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    wrong = np.zeros(len(net.places), np.int64)
    full = explore(net)
    for limit in (2, 17, full.n_states // 3, full.n_states):
        ss = explore(net, max_states=limit, bounds=wrong)
        ref = explore(net, max_states=limit)
        assert ss.complete == ref.complete and np.array_equal(ss.states, ref.states)
        for name in ("out_ptr", "dst", "transition", "parent_edge", "expanded"):
            assert np.array_equal(getattr(ss, name), getattr(ref, name)), name


@pytest.mark.parametrize("model", ["ERK-PT-000001", "FMS-PT-00002", "Kanban-PT-00005", "Railroad-PT-005"])
def test_the_extremes_read_from_the_packed_markings_are_those_of_the_unpacked_ones(model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    for limit in (1, 500, 10_000_000):
        space = explore(net, max_states=limit)
        hi, lo, top = space.extremes()
        states = space.states.astype(np.int64)
        assert hi.tolist() == states.max(axis=0).tolist() and lo.tolist() == states.min(axis=0).tolist()
        assert top == int(states.sum(axis=1).max())


@pytest.mark.parametrize("model", ["ERK-PT-000001", "FMS-PT-00002", "Railroad-PT-005", "TokenRing-PT-005"])
def test_the_transitions_the_search_says_fired_are_those_labelling_an_edge_kept_or_counted(model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    full = explore(net)
    for limit in (1, full.n_states // 3, full.n_states):
        kept = explore(net, max_states=limit)
        labels = np.zeros(len(net.transitions), dtype=bool)
        labels[kept.transition] = True
        assert kept.fired is not None and kept.fired.tolist() == labels.tolist()
        counted = explore(net, max_states=limit, edges=False)
        assert counted.fired is not None and counted.fired.tolist() == labels.tolist()


@pytest.mark.parametrize("model", ["FMS-PT-00002", "ResAllocation-PT-R003C005", "SharedMemory-PT-000005"])
def test_a_search_that_drops_its_edges_when_they_fill_the_budget_goes_on_to_the_graph_a_counting_search_finds(
        model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    counted = explore(net, edges=False)
    budget = 1 << 16  # the smallest budget (in steps of a tenth) the search that drops its edges completes in
    while not (shed := explore(net, max_bytes=budget, shed_edges=True)).complete:
        budget = budget * 11 // 10
    assert explore(net, max_bytes=budget).stopped_by == "max_memory"  # keeping its edges, it stops there
    assert shed.edges_shed_at is not None and 0 < shed.edges_shed_at < shed.n_states
    assert not shed.edges_kept and shed.dst.size == shed.transition.size == 0
    assert shed.n_edges == counted.n_edges
    for name in ("words", "out_ptr", "parent", "expanded"):
        assert np.array_equal(getattr(shed, name), getattr(counted, name)), name
    assert explore(net, shed_edges=True).edges_shed_at is None  # within the default budget nothing is dropped


@pytest.mark.parametrize("model", ["ERK-PT-000001", "FMS-PT-00002", "Railroad-PT-005", "TokenRing-PT-005"])
def test_a_search_that_only_counts_edges_finds_the_same_markings_edge_count_deadlocks_and_firing_sequences(
        model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    full = explore(net)
    for limit in (full.n_states // 3, full.n_states):
        kept = explore(net, max_states=limit)
        counted = explore(net, max_states=limit, edges=False)
        assert not counted.edges_kept and counted.dst.size == counted.transition.size == 0
        assert counted.complete == kept.complete and counted.n_edges == kept.n_edges
        for name in ("words", "out_ptr", "parent", "expanded"):
            assert np.array_equal(getattr(counted, name), getattr(kept, name)), name
        assert counted.deadlocks().tolist() == kept.deadlocks().tolist()
        step = max(1, kept.n_states // 40)
        for i in [*range(0, kept.n_states, step), *kept.deadlocks().tolist()[:5]]:
            assert counted.firing_sequence(i) == kept.firing_sequence(i)
        assert counted.nbytes < kept.nbytes
        with pytest.raises(AnalysisError, match="without keeping its edges"):
            counted.successor_matrix()
        with pytest.raises(AnalysisError, match="without keeping its edges"):
            counted.parent_edge  # noqa: B018 - the property raises


def test_without_its_edges_a_firing_sequence_names_the_transition_the_priorities_let_fire() -> None:
    # t0 and t1 lead from M0 to the same marking; with t1 on the higher level only t1 fires
    net = make_net("twins", {"a": 1}, {"t0": ({"a": 1}, {"b": 1}), "t1": ({"a": 1}, {"b": 1})})
    order = [t.id for t in net.transitions]
    prio = np.array([1 if t == "t1" else 0 for t in order], np.int64)
    for edges in (True, False):
        assert explore(net, edges=edges).firing_sequence(1) == ["t0"]
        assert explore(net, edges=edges, priority=prio).firing_sequence(1) == ["t1"]


def test_without_its_edges_a_firing_sequence_replays_reset_arcs() -> None:
    from coordinator.net import Arc

    base = make_net("flush", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}), "flush": ({"go": 1, "buf": 1}, {"done": 1})},
                    inhibitors={"fill": {"buf": 3}})
    net = PetriNet(name=base.name, places=base.places, transitions=base.transitions,
                   arcs=(*base.arcs, Arc(source="buf", target="flush", reset=True)), initial_marking=base.initial_marking)
    kept, counted = explore(net), explore(net, edges=False)
    assert kept.complete and counted.n_states == kept.n_states == 5 and counted.n_edges == kept.n_edges
    for i in range(kept.n_states):
        seq = counted.firing_sequence(i)
        assert seq == kept.firing_sequence(i)
        m = net.initial_marking
        for t in seq:
            m = net.fire(m, t)
        assert m == counted.marking(i)


def test_markings_stay_packed_until_a_consumer_asks_for_the_unpacked_states() -> None:
    net = mutex()
    ss = explore(net, bounds=np.ones(len(net.places), np.int64))
    held = ss.nbytes
    assert ss.words.shape == (ss.n_states, 1) and ss.words.dtype == np.uint64
    for i in range(ss.n_states):  # markings, lookups and firing sequences read the packed words
        assert ss.index_of(ss.marking(i).to_dict()) == i
    assert ss.nbytes == held
    states = ss.states
    assert ss.nbytes == held + states.nbytes and states.dtype == np.uint8
    assert np.array_equal(states.astype(np.int64), ss.rows(0, ss.n_states))
    assert [net.marking(row) for row in states] == [ss.marking(i) for i in range(ss.n_states)]
    assert ss.marking(-1) == net.marking(states[-1])
    with pytest.raises(IndexError):
        ss.marking(ss.n_states)


@pytest.mark.parametrize("model", ["CircularTrains-PT-012", "ERK-PT-000001", "Eratosthenes-PT-010", "FMS-PT-00002",
                                   "Philosophers-PT-000005", "Railroad-PT-005", "ResAllocation-PT-R003C005",
                                   "SharedMemory-PT-000005", "TokenRing-PT-005"])
def test_bytes_per_marking_stay_within_twice_the_packed_size_plus_the_hash_tables_least_overhead(model: str) -> None:
    # the hash table holds one 8-byte slot per marking at a load of at most 3/4: 8 / 0.75 bytes a
    # marking at least; the buffers start small and double, so a model of 13 markings holds no
    # room for 256
    from coordinator.netfile.pnml import load_pnml

    ss = explore(load_pnml(str(MCC / model / "model.pnml")))
    packed = 8 * ss.words.shape[1]
    assert ss.memory_per_marking_bytes <= 2 * (packed + 8 / 0.75)


def _same_components(space: StateSpace, kept: StateSpace) -> None:
    """The compiled pass on ``space`` (from its markings alone when its edges were not kept, else
    over its edges) agrees with scipy's on the kept edges: same levels, same partition of the
    states, same terminal states."""
    from coordinator.analysis.structure import liveness_levels

    levels, labels, terminal = space.implicit_liveness()
    ref_levels, ref_labels, ref_terminal = liveness_levels(kept)
    assert levels.tolist() == ref_levels.tolist()
    pairs = {(int(a), int(b)) for a, b in zip(labels, ref_labels)}
    assert len(pairs) == len(set(labels.tolist())) == len(set(ref_labels.tolist()))
    assert terminal[labels].tolist() == ref_terminal[ref_labels].tolist()


@pytest.mark.parametrize("seed", range(16))
def test_both_compiled_component_passes_agree_with_scipys_on_random_nets(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    net = random_net(rng, n_places=int(rng.integers(3, 7)), n_transitions=int(rng.integers(3, 9)))
    levels = rng.integers(0, 3, size=len(net.transitions))
    for priority in (None, levels):
        kept = explore(net, max_states=5_000, priority=priority)
        if not kept.complete:
            continue
        _same_components(explore(net, max_states=5_000, priority=priority, edges=False), kept)
        _same_components(kept, kept)  # the compiled pass over the edges, with and without priorities


@pytest.mark.parametrize("model", MCC_MODELS)
def test_both_compiled_component_passes_agree_with_scipys_on_mcc_models(model: str) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    kept = explore(net)
    _same_components(explore(net, edges=False), kept)
    _same_components(kept, kept)


def test_the_pass_over_the_edges_follows_a_depth_first_path_as_long_as_the_graph() -> None:
    # a pile of up to 200,000 tokens, put and taken one at a time: one component whose depth-first
    # path holds every marking, and a stop that leaves it for a dead marking
    net = make_net("pile", {"go": 1}, {"put": ({"go": 1}, {"go": 1, "pile": 1}),
                                       "take": ({"go": 1, "pile": 1}, {"go": 1}),
                                       "stop": ({"go": 1}, {"done": 1})},
                   inhibitors={"put": {"pile": 200_000}})
    kept = explore(net)
    assert kept.n_states == 2 * 200_001
    stats: dict[str, int] = {}
    levels, labels, terminal = kept.implicit_liveness(stats)
    assert stats["deepest_path"] >= 200_001
    assert levels.tolist() == [3, 3, 1] and terminal.sum() == 200_001 and len(set(labels.tolist())) == 200_002
    _same_components(kept, kept)
    _same_components(explore(net, edges=False), kept)


def test_components_from_the_markings_alone_follow_reset_arcs_and_need_a_complete_graph() -> None:
    from coordinator.net import Arc

    base = make_net("flush", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}),
                                         "flush": ({"go": 1, "buf": 1}, {"go": 1}),
                                         "stop": ({"go": 1}, {"done": 1})},
                    inhibitors={"fill": {"buf": 3}})
    net = PetriNet(name=base.name, places=base.places, transitions=base.transitions,
                   arcs=(*base.arcs, Arc(source="buf", target="flush", reset=True)), initial_marking=base.initial_marking)
    _same_components(explore(net, edges=False), explore(net))
    with pytest.raises(AnalysisError, match="complete"):
        explore(net, max_states=2, edges=False).implicit_liveness()


def test_the_counts_seen_are_each_places_largest_and_a_sample_of_them_keeps_m0() -> None:
    net = make_net("pile", {"go": 1}, {"put": ({"go": 1}, {"go": 1, "pile": 1}), "stop": ({"go": 1}, {"done": 1})},
                   inhibitors={"put": {"pile": 9}})
    space = explore(net)
    assert space.seen_counts().tolist() == space.states.max(axis=0).tolist() == [1, 9, 1]
    assert space.n_states == 20
    sampled = space.seen_counts(max_values=6)  # 20 markings of 3 places: every 10th, rows 0 and 10
    assert (sampled <= space.states.max(axis=0)).all() and (sampled >= space.states[0]).all()
    assert sampled.tolist() == space.states[[0, 10]].max(axis=0).tolist()
