"""Marking-dependent rates and weights (docs/netfile.md, "Rates and weights"; docs/gspn.md): the
format and its errors, the engine's random switch, the GSPN chain against closed forms (M/M/c/K,
Erlang C), constant rates written as expressions, the simulator against the chain, and the FMS
example against its published state-space sizes."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coordinator.analysis.gspn import analyse
from coordinator.analysis.gspn_graph import explore_gspn
from coordinator.analysis.simulate import simulate_steady
from coordinator.cli import main
from coordinator.engine import Engine, Firing
from coordinator.errors import AnalysisError, EngineError, NetError
from coordinator.net import Arc, PetriNet, Place, Transition, TransitionKind
from coordinator.netfile import dump_net, load_net, loads_net
from coordinator.netfile.dot import to_dot
from coordinator.netfile.pnml import dump_pnml, loads_pnml
from tests.unit.gspn_nets import FMS_IMMEDIATE, fork_join, literature_net, queue, repairman, vanishing_loop

EXP = TransitionKind.EXPONENTIAL
FMS = Path(__file__).resolve().parents[2] / "nets" / "examples" / "fms.toml"


def mmc(lam: float, mu: float, c: int, k: int) -> PetriNet:
    """M/M/c/K with the c servers written into a rate expression: ``serve`` at min(#queue, c) * mu."""
    return PetriNet(
        name="mmc", places=[Place(id="queue"), Place(id="free")],
        transitions=[Transition(id="arrive", kind=EXP, rate=lam),
                     Transition(id="serve", kind=EXP, rate_expr=f"min(#queue, {c}) * {mu}")],
        arcs=[Arc(source="free", target="arrive"), Arc(source="arrive", target="queue"),
              Arc(source="queue", target="serve"), Arc(source="serve", target="free")],
        initial_marking={"free": k},
    )


def mmck_closed_form(lam: float, mu: float, c: int, k: int) -> np.ndarray:
    """Stationary distribution of M/M/c/K: p_n ∝ a^n / n! for n ≤ c, a^n / (c! c^(n-c)) above."""
    a = lam / mu
    p = np.array([a ** n / math.factorial(n) if n <= c else a ** n / (math.factorial(c) * c ** (n - c))
                  for n in range(k + 1)])
    return p / p.sum()


# ------------------------------------------------------------------ the format
def toml(rate: str, weight: str = "", inputs: str = "a = 1") -> str:
    return f"""
[net]
name = "md"
[[place]]
id = "a"
tokens = 1
[[place]]
id = "queue"
[[transition]]
id = "t"
kind = "exponential"
rate = {rate}
inputs = {{ {inputs} }}
outputs = {{ queue = 1 }}
[[transition]]
id = "u"
{weight}
inputs = {{ queue = 1 }}
outputs = {{ a = 1 }}
"""


def test_a_rate_expression_is_read_written_and_read_back_equal() -> None:
    net = loads_net(toml('"min(1, #a / 3) * #queue + 0.5"', 'weight = "1 + #a"'))
    t, u = net.transitions
    assert t.rate is None and t.rate_expr == "min(1, #a / 3) * #queue + 0.5" and t.servers == 1
    assert u.weight_expr == "1 + #a"
    assert loads_net(dump_net(net)) == net
    assert loads_pnml(dump_pnml(net)) == net


@pytest.mark.parametrize("rate, problem, line", [
    ('"#aa * 2"', r"rate of transition 't': unknown place 'aa'; did you mean #a\? \(column 1 of", 12),
    ('"min(#a, 3) * * 2"', r"rate of transition 't': unexpected '\*' \(column 14 of", 12),
    ('"#a > 1"', r"expected a number, but the expression is a truth value \(column 1", 12),
    ('"#a - 2"', r"the rate of transition 't' is -1 in the initial marking \{'a': 1\}, where it is enabled; it "
                 r"must be finite and >= 0", 12),
    ('"1 / (#a - 1)"', r"the rate of transition 't' is inf in the initial marking", 12),
    ('"__import__(1)"', r"unknown name '__import__'", 12),
])
def test_bad_rate_expressions_are_reported_at_their_line_and_column(rate: str, problem: str, line: int) -> None:
    with pytest.raises(NetError, match=problem) as info:
        loads_net(toml(rate), "md.toml")
    assert str(info.value).startswith(f"md.toml:{line}:")


def test_a_negative_rate_where_the_transition_is_disabled_is_not_an_error_at_load_time() -> None:
    net = loads_net(toml('"#a - 2"', inputs="a = 2"))
    assert not net.enabled(net.initial_marking, "t")


def test_a_weight_expression_that_is_zero_where_enabled_in_the_initial_marking_is_refused() -> None:
    text = toml("1.0", 'weight = "#queue - 1"').replace('id = "queue"', 'id = "queue"\ntokens = 1')
    with pytest.raises(NetError, match=r"the weight of transition 'u' is 0 in the initial marking") as info:
        loads_net(text, "md.toml")
    assert str(info.value).startswith("md.toml:18:")


def test_servers_and_a_rate_expression_do_not_go_together() -> None:
    with pytest.raises(NetError, match="servers") as info:
        loads_net(toml('"2 * #a"').replace('kind = "exponential"', 'kind = "exponential"\nservers = 3'), "md.toml")
    assert "md.toml:" in str(info.value)


def test_an_immediate_transition_cannot_take_a_rate_expression() -> None:
    with pytest.raises(NetError, match="cannot have a rate"):
        loads_net(toml('"#a"').replace('kind = "exponential"\n', ""))
    with pytest.raises(NetError, match="cannot have a rate"):
        Transition(id="t", rate_expr="#a")


def test_the_net_model_refuses_an_expression_that_does_not_parse_and_names_the_column() -> None:
    with pytest.raises(NetError, match=r"rate of transition 't': the expression ends too early \(column 5"):
        Transition(id="t", kind=EXP, rate_expr="#a +")
    with pytest.raises(NetError, match="unknown place 'b'"):
        PetriNet(name="n", places=[Place(id="a")], transitions=[Transition(id="t", kind=EXP, rate_expr="#b")],
                 arcs=[Arc(source="a", target="t")])


def test_pnml_refuses_an_expression_on_an_unknown_place() -> None:
    text = dump_pnml(loads_net(toml('"2 * #a"'))).replace('rate_expr="2 * #a"', 'rate_expr="2 * #b"')
    with pytest.raises(NetError, match="unknown place 'b'"):
        loads_pnml(text)


def test_dot_shows_a_rate_expression() -> None:
    assert "rate min(1, #a / 3) /s" in to_dot(loads_net(toml('"min(1, #a / 3)"')))


# ------------------------------------------------------------------ GSPN against closed forms
def test_an_mmck_queue_with_its_servers_in_a_rate_expression_matches_the_closed_form() -> None:
    lam, mu, c, k = 3.0, 1.25, 3, 8
    res = analyse(mmc(lam, mu, c, k))
    p = mmck_closed_form(lam, mu, c, k)
    assert res.tangible_markings == k + 1
    assert res.mean_tokens["queue"] == pytest.approx(float(np.arange(k + 1) @ p), rel=1e-10)
    assert res.throughput["arrive"] == pytest.approx(lam * (1 - p[k]), rel=1e-10)
    assert res.throughput["serve"] == pytest.approx(mu * float(np.minimum(np.arange(k + 1), c) @ p), rel=1e-10)


def test_an_mmc_queue_written_with_a_rate_expression_gives_the_erlang_c_formula() -> None:
    # a buffer of 150 places stands in for an infinite one: the mass beyond it is below 1e-25
    lam, mu, c = 4.0, 2.0, 3
    res = analyse(mmc(lam, mu, c, 150), measures=[f"P{{#queue >= {c}}}"])
    a, rho = lam / mu, lam / (mu * c)
    top = a ** c / math.factorial(c) / (1 - rho)
    erlang_c = top / (sum(a ** n / math.factorial(n) for n in range(c)) + top)
    assert erlang_c == pytest.approx(4 / 9)  # the textbook value for a = 2, c = 3
    assert res.measures[0]["value"] == pytest.approx(erlang_c, rel=1e-10)
    assert res.mean_tokens["queue"] == pytest.approx(a + erlang_c * rho / (1 - rho), rel=1e-10)


def test_a_rate_expression_that_is_zero_stops_the_transition_like_a_disabled_one() -> None:
    net = PetriNet(
        name="z", places=[Place(id="a"), Place(id="b")],
        transitions=[Transition(id="go", kind=EXP, rate_expr="#a - 1"), Transition(id="back", kind=EXP, rate=1.0)],
        arcs=[Arc(source="a", target="go"), Arc(source="go", target="b"), Arc(source="b", target="back"),
              Arc(source="back", target="a")],
        initial_marking={"a": 2},
    )
    res = analyse(net)
    # go fires at rate 1 with two tokens in a and not at all with one: states a=2 and a=1,b=1 only
    assert res.tangible_markings == 2
    assert res.mean_tokens["b"] == pytest.approx(0.5)
    assert res.throughput["go"] == pytest.approx(0.5)


def test_a_negative_rate_met_in_a_reachable_marking_names_the_transition_and_the_marking() -> None:
    net = replace_rate(queue(1.0, 1.0, 3), "serve", "2 - #queue")
    with pytest.raises(AnalysisError, match=r"rate of transition 'serve' \(2 - #queue\) is -1 in marking "
                                            r"\{'queue': 3\}"):
        analyse(net)


def two_way_switch(weight_a: str, weight_b: str) -> PetriNet:
    """``go`` (rate 1) puts a token in ``choice``; immediate ``a`` and ``b`` take it back to ``start``
    with weights given as expressions over ``start`` (two tokens cycle)."""
    return PetriNet(
        name="switch", places=[Place(id="start"), Place(id="choice")],
        transitions=[Transition(id="go", kind=EXP, rate=1.0), Transition(id="a", weight_expr=weight_a),
                     Transition(id="b", weight_expr=weight_b)],
        arcs=[Arc(source="start", target="go"), Arc(source="go", target="choice"), Arc(source="choice", target="a"),
              Arc(source="a", target="start"), Arc(source="choice", target="b"), Arc(source="b", target="start")],
        initial_marking={"start": 2},
    )


def test_weight_expressions_are_evaluated_in_the_vanishing_marking() -> None:
    # from start=2 the switch happens in {start: 1, choice: 1} (weights 1 and 3) and, after a second
    # go, in {choice: 2}... which the first switch empties first; only the first marking is reached
    res = analyse(two_way_switch("#start", "3 * #start"))
    assert res.throughput["a"] / res.throughput["go"] == pytest.approx(0.25)
    with pytest.raises(AnalysisError, match=r"weight of transition 'a' \(#start - 1\) is 0 in marking"):
        analyse(two_way_switch("#start - 1", "1"))


# ------------------------------------------------------------------ constant rates as expressions
def as_expressions(net: PetriNet) -> PetriNet:
    """The same GSPN with every constant rate and weight written as an expression: rate r with k
    servers over input places p_i (arc weight 1) is ``r * min(#p_1, ..., k)``."""
    out = []
    for t in net.transitions:
        if t.kind is EXP:
            ins = [f"#{p}" for p in net.input_places[t.id]]
            assert all(w == 1 for w in net.input_places[t.id].values())
            degree = ins if t.servers is None else [*ins, str(t.servers)]
            if t.servers == 1:
                text = repr(t.rate)  # min(d, 1) is 1 wherever the transition is enabled
            elif len(degree) == 1:
                text = f"{t.rate!r} * {degree[0]}"
            else:
                text = f"{t.rate!r} * min({', '.join(degree)})"
            out.append(replace(t, rate=None, servers=1, rate_expr=text))
        else:
            out.append(replace(t, weight=1.0, weight_expr=repr(t.weight)))
    return PetriNet(name=net.name, places=net.places, transitions=tuple(out), arcs=net.arcs,
                    initial_marking=net.initial_marking)


def replace_rate(net: PetriNet, tid: str, text: str) -> PetriNet:
    ts = tuple(replace(t, rate=None, servers=1, rate_expr=text) if t.id == tid else t for t in net.transitions)
    return PetriNet(name=net.name, places=net.places, transitions=ts, arcs=net.arcs,
                    initial_marking=net.initial_marking)


NETS = {
    "queue": lambda r: queue(r[0], r[1], 5, servers=2),
    "repairman": lambda r: repairman(4, r[0], r[1]),
    "vanishing_loop": lambda r: vanishing_loop(r[0], r[1]),
    "fork_join": lambda r: fork_join(r[0], r[1], 0.3),
}


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(sorted(NETS)), rates=st.tuples(st.floats(0.05, 20.0), st.floats(0.05, 20.0)))
def test_constant_rates_written_as_expressions_give_the_same_results(name: str, rates: tuple[float, float]) -> None:
    net = NETS[name](rates)
    plain, expr = analyse(net), analyse(as_expressions(net))
    assert expr.tangible_markings == plain.tangible_markings
    for key in ("mean_tokens", "throughput"):
        a, b = getattr(plain, key), getattr(expr, key)
        assert a.keys() == b.keys()
        for k in a:
            assert b[k] == pytest.approx(a[k], rel=1e-9, abs=1e-12), (key, k)
    if plain.mean_time_to_absorption is not None:
        assert expr.mean_time_to_absorption == pytest.approx(plain.mean_time_to_absorption, rel=1e-9)


def test_fms_with_unit_rates_written_as_expressions_gives_the_same_chain() -> None:
    net = literature_net("FMS-PT-00002", 1, FMS_IMMEDIATE)
    plain, expr = analyse(net), analyse(as_expressions(net))
    for tid, value in plain.throughput.items():
        assert expr.throughput[tid] == pytest.approx(value, rel=1e-9, abs=1e-15)


# ------------------------------------------------------------------ engine
def engine_switch(weight_a: str) -> PetriNet:
    return PetriNet(
        name="e", places=[Place(id="src"), Place(id="a_done"), Place(id="b_done"), Place(id="bias")],
        transitions=[Transition(id="a", weight_expr=weight_a), Transition(id="b")],
        arcs=[Arc(source="src", target="a"), Arc(source="a", target="a_done"),
              Arc(source="src", target="b"), Arc(source="b", target="b_done")],
        initial_marking={"src": 1, "bias": 3},
    )


def test_the_engine_draws_the_switch_with_the_weights_of_the_current_marking() -> None:
    counts: Counter[str] = Counter()
    for seed in range(800):  # bounded: 800 one-firing runs
        effects = Engine(engine_switch("#bias"), seed=seed).advance()
        counts.update(e.transition for e in effects if isinstance(e, Firing))
    # weight 3 against 1: a wins 3/4 of the draws; 800 draws give a standard deviation of ~12
    assert 600 - 60 < counts["a"] < 600 + 60


def test_the_engine_refuses_a_weight_expression_that_is_not_positive_where_it_is_used() -> None:
    engine = Engine(engine_switch("#bias - 3"), seed=1)
    with pytest.raises(EngineError, match=r"weight of transition 'a' is 0 in marking"):
        engine.advance()


def test_constant_weights_written_as_expressions_make_the_same_draws_in_the_engine() -> None:
    plain, expr = engine_switch("1"), engine_switch("1")
    plain = PetriNet(name="e", places=plain.places, transitions=(Transition(id="a", weight=2.5), Transition(id="b")),
                     arcs=plain.arcs, initial_marking=plain.initial_marking)
    expr = PetriNet(name="e", places=expr.places, transitions=(Transition(id="a", weight_expr="2.5"),
                                                              Transition(id="b")),
                    arcs=expr.arcs, initial_marking=expr.initial_marking)
    for seed in range(50):
        a = [e.transition for e in Engine(plain, seed=seed).advance() if isinstance(e, Firing)]
        b = [e.transition for e in Engine(expr, seed=seed).advance() if isinstance(e, Firing)]
        assert a == b


# ------------------------------------------------------------------ simulator
def test_the_simulator_agrees_with_the_chain_on_a_marking_dependent_queue() -> None:
    net = mmc(3.0, 1.25, 3, 8)
    exact = analyse(net)
    est = simulate_steady(net, seed=9, batch_time=200.0, batches=20, warmup=20.0, confidence=0.99)
    assert est.mean_tokens["queue"].contains(exact.mean_tokens["queue"])
    assert est.throughput["serve"].contains(exact.throughput["serve"])


def test_the_simulator_uses_weight_expressions_of_the_switch_marking() -> None:
    net = two_way_switch("#start", "3 * #start")
    exact = analyse(net)
    est = simulate_steady(net, seed=4, batch_time=200.0, batches=20, warmup=20.0, confidence=0.99)
    assert est.throughput["a"].contains(exact.throughput["a"])
    assert est.throughput["b"].contains(exact.throughput["b"])


def test_the_simulator_refuses_a_negative_rate_it_meets() -> None:
    net = replace_rate(queue(5.0, 1.0, 3), "serve", "2 - #queue")
    with pytest.raises(AnalysisError, match="rate of transition 'serve' is -1"):
        simulate_steady(net, seed=1, batch_time=50.0, batches=5, warmup=5.0)


# ------------------------------------------------------------------ the FMS example
def fms(n: int) -> PetriNet:
    net = load_net(FMS)
    return net.with_initial_marking({**net.initial_marking, "P1": n, "P2": n, "P3": n})


def test_the_fms_example_has_the_structure_of_the_contest_model() -> None:
    net, mcc = fms(2), literature_net("FMS-PT-00002", 2, FMS_IMMEDIATE)
    assert {p.id for p in net.places} == {p.id for p in mcc.places}
    for t in mcc.transitions:
        assert net.input_places[t.id] == mcc.input_places[t.id]
        assert net.output_places[t.id] == mcc.output_places[t.id]
        assert (net.transition(t.id).kind is EXP) == (t.kind is EXP)
    assert net.initial_marking == mcc.initial_marking


def test_the_fms_example_has_the_published_numbers_of_tangible_markings() -> None:
    """G. Ciardo and K. S. Trivedi, "A decomposition approach for stochastic reward net models",
    Performance Evaluation 18 (1993): 54, 810 and 6520 tangible markings for N = 1, 2, 3 (its table
    of state-space sizes). The marking-dependent rates are positive wherever their transitions are
    enabled, so none of them prunes a marking."""
    assert [int((~explore_gspn(fms(n)).vanishing).sum()) for n in (1, 2, 3)] == [54, 810, 6520]
    assert analyse(fms(1)).tangible_markings == 54


def test_the_fms_chain_agrees_with_the_simulator() -> None:
    net = fms(1)
    exact = analyse(net)
    est = simulate_steady(net, seed=1, batch_time=50_000.0, batches=20, warmup=2_000.0, confidence=0.99)
    for tid in ("tP1", "tP2", "tP3", "tP12", "tx"):
        assert est.throughput[tid].contains(exact.throughput[tid]), tid


def test_petrobot_gspn_solves_the_fms_example(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["gspn", str(FMS)]) == 0
    out = capsys.readouterr().out
    assert "810 tangible" in out and "tP12M3" in out
