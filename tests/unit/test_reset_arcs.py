"""Reset ("flush") arcs across the views: the net model, the TOML and PNML formats, DOT, the engine
and the journal's recovery, the compiled reachability search, the structural analysis and the GSPN
chain and simulator (semantics: docs/netfile.md, "Reset arcs")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from analysis_nets import make_net
from test_statespace import assert_matches_reference, assert_same_as_reference, random_net

from coordinator.analysis.coverability import covering_witness, karp_miller
from coordinator.analysis.gspn import analyse as gspn_analyse
from coordinator.analysis.simulate import simulate_steady
from coordinator.analysis.statespace import explore
from coordinator.analysis.structure import analyse
from coordinator.engine import Engine, Firing
from coordinator.errors import AnalysisError, EngineError, NetError, NotEnabledError
from coordinator.journal import Journal
from coordinator.net import Arc, Marking, PetriNet, Place, PlaceKind, PrimitiveTask, ActionSpec, Transition, TransitionKind
from coordinator.netfile import dump_net, loads_net
from coordinator.netfile.dot import to_dot
from coordinator.netfile.pnml import dump_pnml, loads_pnml

EXP = TransitionKind.EXPONENTIAL


def with_resets(net: PetriNet, resets: list[tuple[str, str]]) -> PetriNet:
    """``net`` plus a reset arc p → t for each pair."""
    return PetriNet(name=net.name, places=net.places, transitions=net.transitions,
                    arcs=(*net.arcs, *(Arc(source=p, target=t, reset=True) for p, t in resets)),
                    initial_marking=net.initial_marking)


def flush_net() -> PetriNet:
    """``fill`` adds a token to ``buf`` (while it has fewer than 3); ``flush`` takes one and empties the rest."""
    return with_resets(make_net("flush", {"go": 1}, {
        "fill": ({"go": 1}, {"go": 1, "buf": 1}),
        "flush": ({"buf": 1}, {}),
    }, inhibitors={"fill": {"buf": 3}}), [("buf", "flush")])


# ------------------------------------------------------------------ the net model
def test_firing_consumes_then_empties_the_reset_places_then_produces() -> None:
    net = with_resets(make_net("r", {"a": 3, "b": 2}, {"t": ({"a": 1}, {"a": 2, "c": 1})}), [("a", "t"), ("b", "t")])
    assert net.fire(net.initial_marking, "t") == Marking({"a": 2, "c": 1})
    assert net.reset_places["t"] == ("a", "b")
    assert net.has_resets


def test_a_reset_arc_does_not_take_part_in_enabling() -> None:
    net = with_resets(make_net("r", {"go": 1}, {"t": ({"go": 1}, {})}, places=("go", "empty")), [("empty", "t")])
    assert net.enabled(net.initial_marking, "t")
    assert net.fire(net.initial_marking, "t") == Marking({})


@pytest.mark.parametrize("arc, problem", [
    (Arc(source="t", target="p", reset=True), "must go from a place to a transition"),
])
def test_a_reset_arc_from_a_transition_is_refused(arc: Arc, problem: str) -> None:
    with pytest.raises(NetError, match=problem):
        PetriNet(name="n", places=[Place(id="p")], transitions=[Transition(id="t")], arcs=[arc])


def test_a_reset_arc_takes_no_weight_and_is_not_an_inhibitor_arc() -> None:
    with pytest.raises(NetError, match="takes no weight|has weight"):
        Arc(source="p", target="t", weight=2, reset=True)
    with pytest.raises(NetError, match="both a reset and an inhibitor"):
        Arc(source="p", target="t", inhibitor=True, reset=True)


def test_a_reset_arc_may_sit_beside_an_input_and_an_inhibitor_arc_of_the_same_pair() -> None:
    net = PetriNet(name="n", places=[Place(id="p")], transitions=[Transition(id="t")],
                   arcs=[Arc(source="p", target="t"), Arc(source="p", target="t", reset=True),
                         Arc(source="p", target="t", weight=5, inhibitor=True)],
                   initial_marking={"p": 4})
    assert net.enabled(net.initial_marking, "t")
    assert net.fire(net.initial_marking, "t") == Marking({})
    assert not net.enabled(Marking({"p": 5}), "t")
    with pytest.raises(NetError, match="given twice"):
        PetriNet(name="n", places=[Place(id="p")], transitions=[Transition(id="t")],
                 arcs=[Arc(source="p", target="t", reset=True), Arc(source="p", target="t", reset=True)])


def test_a_reset_arc_on_a_primitive_task_place_is_an_interpretation_problem() -> None:
    net = PetriNet(name="n", places=[Place(id="w", kind=PlaceKind.PRIMITIVE_TASK, task="work"), Place(id="s")],
                   transitions=[Transition(id="t"), Transition(id="ok", events=("int:work.ok",)),
                                Transition(id="err", events=("int:work.error",))],
                   arcs=[Arc(source="s", target="t"), Arc(source="w", target="t", reset=True),
                         Arc(source="w", target="ok"), Arc(source="w", target="err")],
                   tasks={"work": PrimitiveTask(name="work", actions=(ActionSpec(name="a"),))})
    assert any("reset arc from primitive-task place" in p for _, p in net.interpretation_problems())
    with pytest.raises(EngineError, match="reset arc from primitive-task place"):
        Engine(net)


# ------------------------------------------------------------------ formats
RESET_TOML = """
[net]
name = "flush"
[[place]]
id = "go"
tokens = 1
[[place]]
id = "buf"
[[transition]]
id = "fill"
inputs = { go = 1 }
outputs = { go = 1, buf = 1 }
inhibitors = { buf = 3 }
[[transition]]
id = "flush"
inputs = { buf = 1 }
outputs = {}
[[arc]]
from = "buf"
to = "flush"
reset = true
"""


def test_toml_reads_a_reset_arc_and_writes_it_back_equal() -> None:
    net = loads_net(RESET_TOML)
    assert net.reset_places["flush"] == ("buf",)
    assert net.input_places["flush"] == {"buf": 1}
    again = loads_net(dump_net(net))
    assert again == net
    assert "reset = true" in dump_net(net)


@pytest.mark.parametrize("extra, problem, line", [
    ('[[arc]]\nfrom = "flush"\nto = "buf"\nreset = true\n', "must go from a place to a transition", 25),
    ('[[arc]]\nfrom = "buf"\nto = "flush"\nreset = true\nweight = 2\n', "takes no weight", 26),
    ('[[arc]]\nfrom = "go"\nto = "flush"\nreset = true\ninhibitor = true\n', "both a reset and an inhibitor", 25),
    ('[[arc]]\nfrom = "buf"\nto = "flush"\nreset = true\n', "given twice", 23),
    ('[[arc]]\nfrom = "buf"\nto = "flush"\nreset = "yes"\n', "reset of an \\[\\[arc\\]\\] must be true or false", 25),
])
def test_toml_refuses_bad_reset_arcs_at_their_line(extra: str, problem: str, line: int) -> None:
    with pytest.raises(NetError, match=problem) as info:
        loads_net(RESET_TOML + extra, "flush.toml")
    assert f"flush.toml:{line}:" in str(info.value)


def test_pnml_carries_reset_arcs_and_reads_them_back_equal() -> None:
    net = loads_net(RESET_TOML)
    text = dump_pnml(net)
    assert 'value="reset"' in text or "reset" in text
    assert loads_pnml(text) == net


def test_pnml_reads_the_standard_reset_arc_type_of_other_tools() -> None:
    text = dump_pnml(loads_net(RESET_TOML)).replace(
        '<toolspecific tool="petrobot" version="1" reset="true"/>', '<type value="reset"/>')
    assert 'reset="true"' not in text
    assert loads_pnml(text).reset_places["flush"] == ("buf",)


def test_pnml_refuses_a_reset_arc_with_a_weight() -> None:
    text = dump_pnml(loads_net(RESET_TOML)).replace(
        '<toolspecific tool="petrobot" version="1" reset="true"/>',
        '<type value="reset"/><inscription><text>2</text></inscription>')
    with pytest.raises(NetError, match="reset arc"):
        loads_pnml(text)


def test_dot_draws_a_reset_arc_dashed_with_a_double_head() -> None:
    dot = to_dot(loads_net(RESET_TOML))
    line = next(line for line in dot.splitlines() if '"p:buf" -> "t:flush"' in line and "reset" in line)
    assert "normalnormal" in line and "dashed" in line


# ------------------------------------------------------------------ engine and journal
def test_the_engine_empties_the_reset_place_and_records_what_it_removed() -> None:
    engine = Engine(with_resets(make_net("r", {"go": 1, "buf": 4}, {"flush": ({"go": 1, "buf": 1}, {"done": 1})}),
                                [("buf", "flush")]))
    effects = engine.advance()
    firing = next(e for e in effects if isinstance(e, Firing))
    assert dict(firing.consumed) == {"go": 1, "buf": 4}
    assert engine.marking == {"done": 1}


def test_a_stale_reset_firing_that_would_remove_other_counts_is_refused() -> None:
    net = with_resets(make_net("r", {"go": 2, "buf": 4}, {"flush": ({"go": 1}, {})}), [("buf", "flush")])
    engine = Engine(net)
    stale = Firing(1, "flush", {"go": 1, "buf": 2}, {}, (), None)
    with pytest.raises(NotEnabledError, match="reset arcs would remove"):
        engine.apply(stale)
    assert engine.marking == {"go": 2, "buf": 4}
    engine.apply(Firing(1, "flush", {"go": 1, "buf": 4}, {}, (), None))
    assert engine.marking == {"go": 1}


def test_a_replayed_reset_firing_recovers_the_marking(tmp_path: Path) -> None:
    net = with_resets(make_net("r", {"go": 2, "buf": 3}, {
        "flush": ({"go": 1}, {"buf": 1}),
    }), [("buf", "flush")])
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net, seed=1)
        engine = Engine(net)
        engine.advance(lambda f: journal.firing(run, f))
        assert engine.marking == {"buf": 1}
    with Journal(tmp_path / "j.sqlite") as journal:
        rec = journal.recover(net, run)
    assert rec.marking == engine.marking == {"buf": 1}


# ------------------------------------------------------------------ the compiled search
@pytest.mark.parametrize("seed", range(12))
def test_random_nets_with_reset_arcs_match_the_reference_search(seed: int) -> None:
    rng = np.random.default_rng(1000 + seed)
    base = random_net(rng, n_places=int(rng.integers(3, 7)), n_transitions=int(rng.integers(3, 9)))
    pairs = {(str(rng.choice([p.id for p in base.places])), t.id)
             for k, t in enumerate(base.transitions) if k == 0 or rng.random() < 0.5}
    net = with_resets(base, sorted(pairs))
    assert net.has_resets
    levels = rng.integers(0, 3, size=len(net.transitions))
    for priority in (None, levels):
        for limit in (1, 7, 60, 400):
            assert_matches_reference(net, max_states=limit, priority=priority)


def test_a_reset_arc_keeps_an_otherwise_unbounded_counter_finite_in_the_search() -> None:
    net = with_resets(make_net("counter", {"go": 1}, {
        "tick": ({"go": 1}, {"go": 1, "n": 1}),
        "clear": ({"go": 1}, {"go": 1}),
    }, inhibitors={"tick": {"n": 200}}), [("n", "clear")])
    ss = assert_same_as_reference(net)
    assert_matches_reference(net)
    assert ss.n_states == 201  # every count 0..200, cleared back to 0 from each


def test_reset_arcs_on_a_marking_wider_than_64_bits_use_the_verified_hash_and_stay_exact() -> None:
    chain = {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(80)}
    chain["back"] = ({"p80": 1}, {"p0": 1})
    net = with_resets(make_net("chain", {"p0": 1, "p40": 1}, chain), [("p40", "t20"), ("p5", "t60")])
    assert_same_as_reference(net)
    assert_matches_reference(net)


# ------------------------------------------------------------------ structural analysis
def test_the_analysis_of_a_reset_net_decides_from_its_graph_and_notes_what_no_longer_holds() -> None:
    a = analyse(flush_net())
    assert a.complete and a.bounded and a.place_bounds["buf"] == 3
    assert a.conservative is None
    assert any("reset arcs" in note for note in a.notes)


def test_karp_miller_refuses_a_net_with_reset_arcs() -> None:
    net = with_resets(make_net("pump", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}),
                                                    "flush": ({"go": 1}, {"go": 1})}), [("buf", "flush")])
    with pytest.raises(AnalysisError, match="reset arcs"):
        karp_miller(net)


# ------------------------------------------------------------------ GSPN chain and simulator
def flush_queue(lam: float, mu: float, k: int) -> PetriNet:
    """Tokens arrive in ``buf`` at rate lam while it holds fewer than k; ``flush`` (rate mu, one
    server) takes one token and empties the rest."""
    return PetriNet(
        name="flushq", places=[Place(id="buf")],
        transitions=[Transition(id="arrive", kind=EXP, rate=lam), Transition(id="flush", kind=EXP, rate=mu)],
        arcs=[Arc(source="arrive", target="buf"), Arc(source="buf", target="arrive", weight=k, inhibitor=True),
              Arc(source="buf", target="flush"), Arc(source="buf", target="flush", reset=True)],
    )


def flush_queue_closed_form(lam: float, mu: float, k: int) -> np.ndarray:
    """pi_n of the chain n -> n+1 at lam (n < k), n -> 0 at mu (n >= 1): pi_n = pi_0 r^n with
    r = lam / (lam + mu) for 0 < n < k, and pi_k mu = lam pi_{k-1}."""
    r = lam / (lam + mu)
    pi = np.array([r ** n for n in range(k)] + [r ** (k - 1) * lam / mu])
    return pi / pi.sum()


def test_the_gspn_chain_of_a_reset_queue_matches_its_closed_form() -> None:
    lam, mu, k = 2.0, 0.5, 4
    res = gspn_analyse(flush_queue(lam, mu, k))
    pi = flush_queue_closed_form(lam, mu, k)
    assert res.tangible_markings == k + 1
    assert res.mean_tokens["buf"] == pytest.approx(float(np.arange(k + 1) @ pi), rel=1e-12)
    assert res.throughput["flush"] == pytest.approx(mu * (1 - pi[0]), rel=1e-12)
    assert res.throughput["arrive"] == pytest.approx(lam * (1 - pi[k]), rel=1e-12)


def test_the_simulator_empties_reset_places_as_the_chain_does() -> None:
    lam, mu, k = 2.0, 0.5, 4
    net = flush_queue(lam, mu, k)
    exact = gspn_analyse(net)
    est = simulate_steady(net, seed=5, batch_time=200.0, batches=20, warmup=20.0, confidence=0.99)
    assert est.mean_tokens["buf"].contains(exact.mean_tokens["buf"])
    assert est.throughput["flush"].contains(exact.throughput["flush"])


def test_a_pumping_loop_that_resets_no_growing_place_proves_unboundedness() -> None:
    # fill grows buf without resetting it; flush (elsewhere) empties buf: buf is still unbounded
    net = with_resets(make_net("pump", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}),
                                                    "flush": ({"go": 1}, {"go": 1})}), [("buf", "flush")])
    a = analyse(net, max_states=50)
    assert a.bounded is False and a.unbounded_places == ["buf"]
    witness = covering_witness(explore(net, max_states=50))
    assert witness is not None and witness.loop == ["fill"] and witness.growing == ["buf"]


def test_a_loop_whose_growth_its_own_reset_undoes_is_no_witness() -> None:
    # refill empties buf then puts one token back: buf = 1 covers buf = 0, but repeating refill
    # leaves buf at 1, so the graph is finite and no witness may claim otherwise
    net = with_resets(make_net("refill", {"go": 1}, {"refill": ({"go": 1}, {"go": 1, "buf": 1})}),
                      [("buf", "refill")])
    space = explore(net)
    assert space.complete and space.n_states == 2
    assert covering_witness(space) is None
