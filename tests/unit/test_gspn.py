"""Tests of the GSPN solution (coordinator.analysis.gspn) against closed forms and published counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coordinator.analysis import ctmc
from coordinator.analysis.gspn import analyse, tangible_chain
from coordinator.analysis.gspn_graph import explore_gspn
from coordinator.errors import AnalysisError
from coordinator.net import Arc, PetriNet, Place
from tests.unit.gspn_nets import (
    FMS_IMMEDIATE,
    MCC,
    exp,
    fork_join,
    imm,
    literature_net,
    queue,
    repairman,
    vanishing_loop,
)


def mmck(lam: float, mu: float, c: int, k: int) -> np.ndarray:
    pi = np.ones(k + 1)
    for n in range(1, k + 1):
        pi[n] = pi[n - 1] * lam / (mu * min(n, c))
    return pi / pi.sum()


def test_mm1k_queue_matches_the_closed_form() -> None:
    lam, mu, k = 2.0, 3.0, 6
    res = analyse(queue(lam, mu, k))
    pi = mmck(lam, mu, 1, k)
    assert res.tangible_markings == k + 1 and res.vanishing_markings == 0
    assert res.mean_tokens["queue"] == pytest.approx(float(np.arange(k + 1) @ pi), rel=1e-9)
    assert res.probability_nonempty["queue"] == pytest.approx(1 - pi[0], rel=1e-9)
    assert res.throughput["serve"] == pytest.approx(mu * (1 - pi[0]), rel=1e-9)
    assert res.throughput["arrive"] == pytest.approx(lam * (1 - pi[k]), rel=1e-9)
    assert res.utilisation["serve"] == pytest.approx(1 - pi[0], rel=1e-9)
    assert not res.terminates


def test_mmck_queue_uses_k_server_rates() -> None:
    lam, mu, c, k = 5.0, 1.5, 3, 8
    res = analyse(queue(lam, mu, k, servers=c))
    pi = mmck(lam, mu, c, k)
    assert res.mean_tokens["queue"] == pytest.approx(float(np.arange(k + 1) @ pi), rel=1e-9)
    busy = float(np.minimum(np.arange(k + 1), c) @ pi)
    assert res.busy_servers["serve"] == pytest.approx(busy, rel=1e-9)
    assert res.throughput["serve"] == pytest.approx(mu * busy, rel=1e-9)


def test_repairman_birth_death_chain_with_infinite_server_failures() -> None:
    n, lam, mu = 5, 0.3, 1.0
    res = analyse(repairman(n, lam, mu))
    w = np.array([math.factorial(n) / math.factorial(n - j) * (lam / mu) ** j for j in range(n + 1)])
    pi = w / w.sum()
    assert res.mean_tokens["down"] == pytest.approx(float(np.arange(n + 1) @ pi), rel=1e-9)
    assert res.throughput["fail"] == pytest.approx(lam * float((n - np.arange(n + 1)) @ pi), rel=1e-9)
    assert res.bottlenecks[0]["transition"] == "repair"
    assert all(b["transition"] != "fail" for b in res.bottlenecks)


def test_fork_join_with_random_switch_gives_time_and_reliability() -> None:
    a, b, r = 2.0, 0.5, 0.9
    res = analyse(fork_join(a, b, r))
    assert res.terminates
    assert res.mean_time_to_absorption == pytest.approx(1 / a + 1 / b - 1 / (a + b), rel=1e-9)
    probs = {tuple(sorted(x["marking"])): x["probability"] for x in res.absorption}
    assert probs[("ok",)] == pytest.approx(r)
    assert probs[("failed",)] == pytest.approx(1 - r)
    assert res.expected_firings["join"] == pytest.approx(1.0)
    assert res.expected_firings["succeed"] == pytest.approx(r)
    assert res.bottlenecks[0]["transition"] == "tb"
    assert res.time_enabled["tb"] == pytest.approx(1 / b)


def test_vanishing_loop_is_eliminated_and_its_throughputs_follow_the_flows() -> None:
    lam, mu = 2.0, 1.0
    res = analyse(vanishing_loop(lam, mu))
    assert res.tangible_markings == 2 and res.vanishing_markings == 2
    pi_s = mu / (mu + 0.75 * lam)
    assert res.probability_nonempty["S"] == pytest.approx(pi_s, rel=1e-9)
    assert res.throughput["go"] == pytest.approx(lam * pi_s, rel=1e-9)
    # From B: back to A with prob 1/5, so 5/4 visits to B per entry and 1/4 loop-backs.
    assert res.throughput["b2a"] == pytest.approx(lam * pi_s / 4, rel=1e-9)
    assert res.throughput["a2b"] == pytest.approx(lam * pi_s * 5 / 4, rel=1e-9)
    assert res.throughput["b2t"] == pytest.approx(lam * pi_s * 3 / 4, rel=1e-9)


def test_a_timeless_trap_is_reported() -> None:
    with pytest.raises(AnalysisError, match="timeless trap"):
        analyse(vanishing_loop(1.0, 1.0, trap=True))


def test_priorities_decide_which_immediate_transition_fires() -> None:
    net = PetriNet(
        name="prio", places=[Place(id=p) for p in ("p", "hi", "lo")],
        transitions=[imm("low", 5.0, priority=0), imm("high", 1.0, priority=2)],
        arcs=[Arc(source="p", target="low"), Arc(source="low", target="lo"),
              Arc(source="p", target="high"), Arc(source="high", target="hi")],
        initial_marking={"p": 1},
    )
    res = analyse(net)
    assert res.absorption == [{"marking": {"hi": 1}, "probability": 1.0}]


def test_inhibitor_arc_bounds_a_source_transition() -> None:
    net = PetriNet(
        name="inh", places=[Place(id="q")], transitions=[exp("arrive", 1.0), exp("serve", 2.0)],
        arcs=[Arc(source="arrive", target="q"), Arc(source="q", target="arrive", weight=3, inhibitor=True),
              Arc(source="q", target="serve")],
    )
    res = analyse(net)
    assert res.tangible_markings == 4
    assert res.mean_tokens["q"] == pytest.approx(float(np.arange(4) @ mmck(1.0, 2.0, 1, 3)), rel=1e-9)


def test_initial_vanishing_marking_spreads_over_tangible_markings() -> None:
    net = PetriNet(
        name="init", places=[Place(id=p) for p in ("s", "x", "y")],
        transitions=[imm("tx", 1.0), imm("ty", 3.0), exp("dx", 1.0), exp("dy", 2.0)],
        arcs=[Arc(source="s", target="tx"), Arc(source="tx", target="x"), Arc(source="s", target="ty"),
              Arc(source="ty", target="y"), Arc(source="x", target="dx"), Arc(source="y", target="dy")],
        initial_marking={"s": 1},
    )
    res = analyse(net)
    assert res.mean_time_to_absorption == pytest.approx(0.25 * 1.0 + 0.75 * 0.5)


def test_steady_state_and_transient_at_large_time_agree() -> None:
    chain = tangible_chain(queue(3.0, 2.0, 5, servers=2))
    late = ctmc.transient(chain.q, chain.alpha, 100.0)
    assert np.allclose(late, ctmc.steady_state(chain.q).pi, atol=1e-10)


def test_kanban_tangible_state_counts_match_the_published_ones() -> None:
    # Kanban of G. Ciardo and M. Tilgner (ICASE report 96-35, 1996), every transition exponential:
    # they report 160, 4600 and 58400 tangible markings for N = 1, 2, 3.
    counts = [explore_gspn(literature_net("Kanban-PT-00005", n)).states.shape[0] for n in (1, 2, 3)]
    assert counts == [160, 4600, 58400]
    res = analyse(literature_net("Kanban-PT-00005", 2))
    assert res.residual < 1e-10
    assert min(res.throughput.values()) > 0


def test_fms_gspn_tangible_and_vanishing_counts_match_the_published_ones() -> None:
    # FMS of G. Ciardo and K. S. Trivedi (1993): 54, 810, 6520 tangible markings for N = 1, 2, 3.
    graphs = [explore_gspn(literature_net("FMS-PT-00002", n, FMS_IMMEDIATE)) for n in (1, 2, 3)]
    assert [int((~g.vanishing).sum()) for g in graphs] == [54, 810, 6520]
    res = analyse(literature_net("FMS-PT-00002", 2, FMS_IMMEDIATE))
    assert (res.tangible_markings, res.vanishing_markings) == (810, 1392)
    # Conservation of parts: each machining exit is followed by exactly one of its two switches.
    assert res.throughput["tP1M1"] == pytest.approx(res.throughput["tP1e"] + res.throughput["tP1j"], rel=1e-8)
    assert res.throughput["tP1j"] == pytest.approx(res.throughput["tx"], rel=1e-8)


def test_reachability_graph_of_all_exponential_nets_matches_the_mcc_oracle() -> None:
    # With every transition exponential the GSPN graph is the ordinary reachability graph:
    # the Model Checking Contest publishes 3444 markings and 16311 edges for FMS-PT-00002.
    g = explore_gspn(literature_net("FMS-PT-00002", 2))
    assert (g.states.shape[0], g.src.size) == (3444, 16311)


def test_explorer_counts_edges_like_a_marking_by_marking_search() -> None:
    net = queue(1.0, 1.0, 4, servers=2)
    g = explore_gspn(net)
    seen = {net.initial_marking}
    todo = [net.initial_marking]
    edges = 0
    while todo:
        m = todo.pop()
        for t in net.enabled_transitions(m):
            edges += 1
            nxt = net.fire(m, t)
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    assert g.states.shape[0] == len(seen) and g.src.size == edges


def test_state_limit_is_reported() -> None:
    with pytest.raises(AnalysisError, match="max_states"):
        explore_gspn(queue(1.0, 1.0, 50), max_states=10)



# ------------------------------------------------------------------------------- reward measures
def test_measures_of_the_mm1k_queue_match_the_closed_form() -> None:
    lam, mu, k = 2.0, 3.0, 4
    pi = mmck(lam, mu, 1, k)
    res = analyse(queue(lam, mu, k), measures=["P{#queue == 0}", "P{#queue >= 2 and #free >= 1}",
                                               "E{#queue}", "E{#queue * #queue - 1}", "X{serve}", "X{arrive}"],
                  markings=True)
    got = {m["measure"]: m["value"] for m in res.measures}
    assert got["P{#queue == 0}"] == pytest.approx(pi[0], rel=1e-9)
    assert got["P{#queue >= 2 and #free >= 1}"] == pytest.approx(pi[2] + pi[3], rel=1e-9)
    assert got["E{#queue}"] == pytest.approx(float(np.arange(k + 1) @ pi), rel=1e-9)
    assert got["E{#queue * #queue - 1}"] == pytest.approx(float((np.arange(k + 1) ** 2) @ pi) - 1, rel=1e-9)
    assert got["X{serve}"] == pytest.approx(mu * (1 - pi[0]), rel=1e-9)
    assert got["X{arrive}"] == pytest.approx(lam * (1 - pi[k]), rel=1e-9)  # = X{serve}: flow balance
    assert all("until_absorption" not in m for m in res.measures)
    assert res.ctmc == {"tangible_states": k + 1, "arcs": 2 * k}
    probs = res.marking_probabilities
    assert probs is not None and len(probs) == k + 1
    assert [p["probability"] for p in probs] == sorted((p["probability"] for p in probs), reverse=True)
    by_queue = {p["marking"].get("queue", 0): p["probability"] for p in probs}
    assert by_queue == pytest.approx({n: pi[n] for n in range(k + 1)}, rel=1e-9)


def erlang_loss(c: int, lam: float, mu: float) -> PetriNet:
    """M/M/c/c: arrivals find a free server or are lost; each busy server finishes at rate mu."""
    return PetriNet(name="erlang", places=[Place(id="free"), Place(id="busy")],
                    transitions=[exp("arrive", lam), exp("finish", mu, None)],
                    arcs=[Arc(source="free", target="arrive"), Arc(source="arrive", target="busy"),
                          Arc(source="busy", target="finish"), Arc(source="finish", target="free")],
                    initial_marking={"free": c})


def test_blocking_probability_is_erlangs_loss_formula() -> None:
    """Erlang's B formula (1917): P(all c servers busy) = (a^c/c!) / sum_k a^k/k!, a = lam/mu;
    c = 3, a = 2 gives 4/19 by hand."""
    res = analyse(erlang_loss(3, 2.0, 1.0), measures=["P{#free == 0}", "E{#busy}", "X{arrive}"])
    blocked, busy, accepted = (m["value"] for m in res.measures)
    assert blocked == pytest.approx(4 / 19, rel=1e-9)
    assert busy == pytest.approx(2.0 * (1 - 4 / 19), rel=1e-9)  # Little: lam (1 - B) / mu
    assert accepted == pytest.approx(2.0 * (1 - 4 / 19), rel=1e-9)


def test_measures_of_a_terminating_net_also_accumulate_until_absorption() -> None:
    a, b, r = 2.0, 0.5, 0.9
    res = analyse(fork_join(a, b, r), measures=["P{#ok == 1}", "P{#a == 1}", "E{#a + #b}", "X{ta}"])
    ok, a_on, pending, ta = res.measures
    assert ok["value"] == pytest.approx(r) and ok["until_absorption"] == pytest.approx(0.0)
    assert a_on["value"] == 0.0 and a_on["until_absorption"] == pytest.approx(1 / a)  # time ta is pending
    assert pending["until_absorption"] == pytest.approx(1 / a + 1 / b)
    assert ta["value"] == 0.0 and ta["until_absorption"] == pytest.approx(1.0)  # fires once


@pytest.mark.parametrize(("measure", "column", "words"), [
    ("P{#queue + 1}", 3, "expected a condition"),
    ("E{#queue > 1}", 3, "expected a number"),
    ("P{#qeue == 1}", 3, "did you mean #queue"),
    ("X{srve}", 3, "did you mean serve"),
    ("Q{#queue}", 1, "starts with P{...}"),
    ("P #queue == 1", 2, "braces missing"),
    ("E{#queue +}", 11, "ends too early"),
])
def test_bad_measures_are_reported_with_their_column_before_anything_is_solved(measure: str, column: int,
                                                                             words: str) -> None:
    from coordinator.analysis.expr import ExprError

    with pytest.raises(ExprError) as info:
        analyse(queue(1.0, 2.0, 3), measures=[measure])
    assert info.value.column == column and words in str(info.value)


def test_gspn_command_prints_measures_markings_and_the_ctmc_size(tmp_path: pytest.TempPathFactory,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    import json
    from pathlib import Path

    from coordinator.cli import main
    from coordinator.netfile import dump_net

    path = Path(str(tmp_path)) / "queue.toml"
    path.write_text(dump_net(queue(2.0, 3.0, 4)), encoding="utf-8")
    assert main(["gspn", str(path), "--json", "--measure", "P{#queue == 0}", "--measure", "E{#queue}",
                 "--measure", "X{serve}", "--markings"]) == 0
    rep = json.loads(capsys.readouterr().out)
    pi = mmck(2.0, 3.0, 1, 4)
    assert rep["ctmc"] == {"tangible_states": 5, "arcs": 8}
    assert [m["kind"] for m in rep["measures"]] == ["P", "E", "X"]
    assert rep["measures"][0]["value"] == pytest.approx(pi[0], rel=1e-9)
    assert len(rep["marking_probabilities"]) == 5
    assert main(["gspn", str(path), "--measure", "P{#queue == 0}"]) == 0
    text = capsys.readouterr().out
    assert "CTMC: 5 states, 8 arcs" in text and "P{#queue == 0}" in text
    assert main(["gspn", str(path), "--measure", "P{#queue +}"]) == 2
    assert "bad --measure" in capsys.readouterr().err


def parallel_system() -> PetriNet:
    """The parallel-processing GSPN of Ajmone Marsan, Balbo, Conte, Donatelli, Franceschinis,
    *Modelling with Generalized Stochastic Petri Nets* (1995), section 6.3 (its Fig. 6.9, tables
    6.7 and 6.8): two tokens in p1; new data at rate 0.2 per token (infinite server) to p2; an
    immediate fork into two parallel branches (rates 2.0 and 1.0) that join immediately in p7; a
    consistency check that passes with weight 0.99 (then I/O at rate 5.0 back to p1) or fails with
    weight 0.01 (then a check at rate 0.1, back to the fork)."""
    tr = [exp("Tndata", 0.2, None), imm("tstart", priority=1), exp("Tpar1", 2.0), exp("Tpar2", 1.0),
          imm("tsyn", priority=1), imm("tOK", 0.99, priority=1), imm("tKO", 0.01, priority=1), exp("TIO", 5.0),
          exp("Tcheck", 0.1)]
    spec = [("p1", "Tndata"), ("Tndata", "p2"), ("p2", "tstart"), ("tstart", "p3"), ("tstart", "p4"),
            ("p3", "Tpar1"), ("Tpar1", "p5"), ("p4", "Tpar2"), ("Tpar2", "p6"), ("p5", "tsyn"), ("p6", "tsyn"),
            ("tsyn", "p7"), ("p7", "tOK"), ("tOK", "p9"), ("p7", "tKO"), ("tKO", "p8"), ("p9", "TIO"),
            ("TIO", "p1"), ("p8", "Tcheck"), ("Tcheck", "p2")]
    return PetriNet(name="parallel", places=[Place(id=f"p{i}") for i in range(1, 10)], transitions=tr,
                    arcs=[Arc(source=a, target=b) for a, b in spec], initial_marking={"p1": 2})


def test_the_parallel_system_of_the_gspn_book_gives_its_published_figures() -> None:
    """Published: 38 reachable markings; steady-state probability 0.57990 of the initial marking and
    0.07949 of {p1, p3, p4}; processing power E[M(p1)] = 1.50555."""
    net = parallel_system()
    assert explore_gspn(net).states.shape[0] == 38
    res = analyse(net, measures=["P{#p1 == 2}", "P{#p1 == 1 and #p3 == 1 and #p4 == 1}", "E{#p1}"])
    m0, m2, power = (round(m["value"], 5) for m in res.measures)
    assert (m0, m2, power) == (0.57990, 0.07949, 1.50555)
