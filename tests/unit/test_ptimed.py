"""The interpreted net becomes a P-timed GSPN (paper section 2)."""

from __future__ import annotations

import pytest

from coordinator.analysis.gspn import analyse
from coordinator.analysis.ptimed import task_stats, to_gspn
from coordinator.net import (
    ActionSpec,
    Arc,
    PetriNet,
    Place,
    PlaceKind,
    PrimitiveTask,
    Transition,
    TransitionKind,
)
from coordinator.netfile import dump_net, loads_net
from coordinator.performance import ActionRecord


def two_step_task(*, rel_a: float | None = 0.9, mean_a: float | None = 2.0) -> PetriNet:
    """start -> task a (ok -> task b, error -> failed) ; b ok -> done, b error -> failed."""
    tasks = {
        "a": PrimitiveTask(name="a", actions=(ActionSpec(name="a1"), ActionSpec(name="a2")),
                           mean_time_s=mean_a, reliability=rel_a),
        "b": PrimitiveTask(name="b", actions=(ActionSpec(name="b1"),), mean_time_s=0.5, reliability=0.8),
    }
    places = [Place(id="start"), Place(id="run_a", kind=PlaceKind.PRIMITIVE_TASK, task="a"),
              Place(id="run_b", kind=PlaceKind.PRIMITIVE_TASK, task="b"), Place(id="done"), Place(id="failed")]
    transitions = [
        Transition(id="go", events=("ext:tick",)),
        Transition(id="a_ok", events=("int:a.ok",)), Transition(id="a_err", events=("int:a.error",)),
        Transition(id="b_ok", events=("int:b.ok",), priority=3), Transition(id="b_err", events=("int:b.error",)),
    ]
    arcs = [Arc(source=s, target=t) for s, t in [
        ("start", "go"), ("go", "run_a"), ("run_a", "a_ok"), ("a_ok", "run_b"), ("run_a", "a_err"),
        ("a_err", "failed"), ("run_b", "b_ok"), ("b_ok", "done"), ("run_b", "b_err"), ("b_err", "failed")]]
    return PetriNet(name="two", places=places, transitions=transitions, arcs=arcs,
                    initial_marking={"start": 1}, tasks=tasks)


def test_a_priori_values_give_the_task_time_and_reliability() -> None:
    model = to_gspn(two_step_task(), ext_rates={"tick": 4.0})
    res = analyse(model.net)
    assert res.terminates
    # tick (0.25 s) + a (2 s) + with prob 0.9: b (0.5 s)
    assert res.mean_time_to_absorption == pytest.approx(0.25 + 2.0 + 0.9 * 0.5)
    probs = {tuple(a["marking"]): a["probability"] for a in res.absorption}
    assert probs[("done",)] == pytest.approx(0.9 * 0.8)
    assert probs[("failed",)] == pytest.approx(1 - 0.9 * 0.8)
    assert model.sources["a"] == "time:apriori reliability:apriori"


def test_exits_of_one_place_share_one_priority_so_the_switch_decides() -> None:
    model = to_gspn(two_step_task(), ext_rates={"tick": 1.0})
    assert model.net.transition("b_err").priority == model.net.transition("b_ok").priority == 3


def test_journal_statistics_override_the_a_priori_values() -> None:
    records = [ActionRecord(task="a", action="a1", status="success", wall_s=1.0),
               ActionRecord(task="a", action="a2", status="failure", wall_s=3.0),
               ActionRecord(task="a", action="a1", status="error", wall_s=2.0),
               ActionRecord(task="a", action="a1", status="success", wall_s=2.0)]
    model = to_gspn(two_step_task(), stats=task_stats(records), ext_rates={"tick": 1.0})
    assert model.means["a"] == pytest.approx(2.0)
    assert model.normal["a"] == pytest.approx(0.75)  # failure still takes the normal branch
    assert model.net.transition("run_a.run").rate == pytest.approx(0.5)
    assert model.net.transition("run_a.run").servers is None
    assert model.net.transition("a_err").weight == pytest.approx(0.25)


def test_missing_values_fall_back_on_defaults_with_warnings() -> None:
    model = to_gspn(two_step_task(rel_a=None, mean_a=None))
    text = " ".join(model.warnings)
    assert "'a'" in text and "ext:tick" in text
    assert model.net.transition("go").kind is TransitionKind.EXPONENTIAL


def test_the_gspn_view_is_a_net_file_that_loads_back_equal() -> None:
    model = to_gspn(two_step_task(), ext_rates={"tick": 2.0})
    again = loads_net(dump_net(model.net), interpreted=False)
    assert analyse(again).mean_time_to_absorption == pytest.approx(analyse(model.net).mean_time_to_absorption)


def test_normal_exits_split_by_the_observed_outcome_shares() -> None:
    tasks = {"look": PrimitiveTask(name="look", actions=(ActionSpec(name="cam"),), mean_time_s=1.0)}
    places = [Place(id="s"), Place(id="run", kind=PlaceKind.PRIMITIVE_TASK, task="look"),
              Place(id="seen"), Place(id="empty"), Place(id="err")]
    transitions = [Transition(id="go"), Transition(id="saw", events=("int:look.ok",)),
                   Transition(id="none", events=("int:look.nothing",), priority=2),
                   Transition(id="bad", events=("int:look.error",))]
    arcs = [Arc(source=a, target=b) for a, b in [
        ("s", "go"), ("go", "run"), ("run", "saw"), ("saw", "seen"), ("run", "none"), ("none", "empty"),
        ("run", "bad"), ("bad", "err")]]
    net = PetriNet(name="look", places=places, transitions=transitions, arcs=arcs, initial_marking={"s": 1},
                   tasks=tasks)
    recs = ([ActionRecord(task="look", action="cam", status="success", outcome="ok", wall_s=1.0)] * 6
            + [ActionRecord(task="look", action="cam", status="failure", outcome="nothing", wall_s=1.0)] * 2
            + [ActionRecord(task="look", action="cam", status="error", outcome="error", wall_s=1.0)] * 2)
    res = analyse(to_gspn(net, stats=task_stats(recs)).net)
    probs = {tuple(a["marking"]): a["probability"] for a in res.absorption}
    assert probs[("seen",)] == pytest.approx(0.6)
    assert probs[("empty",)] == pytest.approx(0.2)
    assert probs[("err",)] == pytest.approx(0.2)


def test_journal_durations_become_empirical_delays_for_the_simulator() -> None:
    from coordinator.analysis.ptimed import empirical_delays
    from coordinator.analysis.simulate import simulate_absorption

    recs = ([ActionRecord(task="a", action="a1", status="success", wall_s=w) for w in (1.0, 3.0)] * 5
            + [ActionRecord(task="b", action="b1", status="success", wall_s=0.5)] * 4)
    stats = task_stats(recs)
    model = to_gspn(two_step_task(), stats=stats, ext_rates={"tick": 4.0})
    delays = empirical_delays(model, stats)
    assert delays["run_a.run"].samples == (1.0, 3.0) * 5
    est = simulate_absorption(model.net, delays, seed=4, replications=2000, confidence=0.99)
    # A sequential task: its mean time depends on the mean durations only.
    assert est.mean_time_to_absorption.contains(analyse(model.net).mean_time_to_absorption or 0.0)


def catch_like(*, exits: tuple[tuple[str, str, str], ...] | None = None) -> PetriNet:
    """One primitive task 'catch' whose exits lead to sinks: (transition, event outcome, sink)."""
    exits = exits or (("got", "success", "caught"), ("lost", "failure", "missed"), ("broke", "error", "aborted"))
    tasks = {"catch": PrimitiveTask(name="catch", actions=(ActionSpec(name="catch"),), mean_time_s=1.0,
                                    reliability=0.5)}
    places = [Place(id="s"), Place(id="run", kind=PlaceKind.PRIMITIVE_TASK, task="catch")]
    places += [Place(id=sink) for sink in dict.fromkeys(s for _, _, s in exits)]
    transitions = [Transition(id="go")] + [Transition(id=t, events=(f"int:catch.{o}",)) for t, o, _ in exits]
    arcs = [Arc(source="s", target="go"), Arc(source="go", target="run")]
    arcs += [a for t, _, sink in exits for a in (Arc(source="run", target=t), Arc(source=t, target=sink))]
    return PetriNet(name="catchlike", places=places, transitions=transitions, arcs=arcs, initial_marking={"s": 1},
                    tasks=tasks)


def absorption(net: PetriNet, recs: list[ActionRecord]) -> dict[tuple[str, ...], float]:
    res = analyse(to_gspn(net, stats=task_stats(recs)).net)
    return {tuple(a["marking"]): a["probability"] for a in res.absorption}


def test_exits_on_status_events_count_the_results_that_also_report_a_named_outcome() -> None:
    """17 balls caught (success, outcome 'caught') and 3 missed (failure, 'missed'): the exit on
    int:catch.success is taken 85 % of the time, not 'probability 0 measured'."""
    recs = ([ActionRecord(task="catch", action="catch", status="success", outcome="caught", wall_s=1.0)] * 17
            + [ActionRecord(task="catch", action="catch", status="failure", outcome="missed", wall_s=1.0)] * 3)
    model = to_gspn(catch_like(), stats=task_stats(recs))
    assert not [w for w in model.warnings if "probability 0" in w and "got" in w]
    probs = absorption(catch_like(), recs)
    assert probs[("caught",)] == pytest.approx(0.85)
    assert probs[("missed",)] == pytest.approx(0.15)
    assert probs.get(("aborted",), 0.0) == pytest.approx(0.0, abs=1e-9)


def test_exits_on_named_outcomes_and_on_ok_follow_the_engine_rules() -> None:
    """Exits on int:catch.ok and int:catch.caught (priority 2): a 'caught' result latches both and
    the priority takes 'caught'; the others take 'ok'; errors take the error exit."""
    net = catch_like(exits=(("any", "ok", "other"), ("got", "caught", "caught"), ("broke", "error", "aborted")))
    net = PetriNet(name=net.name, places=net.places, arcs=net.arcs, initial_marking=net.initial_marking,
                   tasks=net.tasks, transitions=tuple(Transition(id=t.id, events=t.events, priority=2)
                                                      if t.id == "got" else t for t in net.transitions))
    recs = ([ActionRecord(task="catch", action="catch", status="success", outcome="caught", wall_s=1.0)] * 5
            + [ActionRecord(task="catch", action="catch", status="success", wall_s=1.0)] * 3
            + [ActionRecord(task="catch", action="catch", status="failure", outcome="missed", wall_s=1.0)] * 1
            + [ActionRecord(task="catch", action="catch", status="error", outcome="timeout", wall_s=1.0)] * 1)
    probs = absorption(net, recs)
    assert probs[("caught",)] == pytest.approx(0.5)
    assert probs[("other",)] == pytest.approx(0.4)
    assert probs[("aborted",)] == pytest.approx(0.1)


def test_results_that_no_exit_takes_are_left_out_with_a_warning() -> None:
    net = catch_like(exits=(("got", "caught", "caught"), ("broke", "error", "aborted")))
    recs = ([ActionRecord(task="catch", action="catch", status="success", outcome="caught", wall_s=1.0)] * 6
            + [ActionRecord(task="catch", action="catch", status="failure", outcome="missed", wall_s=1.0)] * 2
            + [ActionRecord(task="catch", action="catch", status="error", wall_s=1.0)] * 2)
    model = to_gspn(net, stats=task_stats(recs))
    assert any("no exit" in w and "20%" in w for w in model.warnings), model.warnings
    probs = absorption(net, recs)
    assert probs[("caught",)] == pytest.approx(0.75)
    assert probs[("aborted",)] == pytest.approx(0.25)


def test_a_measured_mean_time_of_zero_falls_back_and_does_not_divide_by_zero() -> None:
    recs = [ActionRecord(task="catch", action="catch", status="success", wall_s=0.0)] * 4
    model = to_gspn(catch_like(), stats=task_stats(recs), means={"catch": 0.0})
    assert model.means["catch"] == pytest.approx(1.0)  # the a-priori mean_time_s
    assert any("mean time 0" in w for w in model.warnings)
