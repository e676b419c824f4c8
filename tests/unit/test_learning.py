"""Learning automata of coordinator.learning and the `petrobot learn` command (paper section 4)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from coordinator.commands import learn as learn_cmd
from coordinator.errors import JournalError, NetError
from coordinator.journal import Journal
from coordinator.learning import (
    FixedChoice,
    Learner,
    LearnerConfigError,
    LearningAutomaton,
    LinearRewardInaction,
    PursuitAutomaton,
    automaton_from_state,
    make_learner,
    state_from_json,
    state_to_json,
    task_seed,
)
from coordinator.netfile import loads_net
from coordinator.performance import cost_function, rho_for
from services.errors import PetrobotError
from services.results import ActionResult, Status


def _run(auto: LearningAutomaton, reliability: dict[str, float], env_seed: int, trials: int,
         costs: dict[str, float] | None = None, until_converged: bool = True) -> list[str]:
    """Drive an automaton against a Bernoulli environment; return the actions chosen."""
    env = np.random.default_rng(env_seed)
    chosen = []
    for _ in range(trials):
        action = auto.choose()
        chosen.append(action)
        status = "success" if env.random() < reliability[action] else "failure"
        auto.update(action, status, None if costs is None else costs[action])
        if until_converged and auto.converged() is not None:
            break
    return chosen


# -- convergence ----------------------------------------------------------------------------------


@pytest.mark.parametrize("scheme, rate", [("pursuit", None), ("lri", 0.02)])
def test_clear_cut_case_converges_to_the_most_reliable_action_on_every_seed(scheme: str, rate: float | None) -> None:
    reliability = {"grab": 0.9, "push": 0.55, "poke": 0.4}
    config: dict[str, Any] = {"scheme": scheme}
    if rate is not None:
        config["rate"] = rate
    for seed in range(20):
        auto = make_learner(config, list(reliability), seed=seed)
        _run(auto, reliability, env_seed=1000 + seed, trials=5000)
        assert auto.converged() == "grab", (seed, auto)


def test_pursuit_prefers_a_cheaper_less_reliable_action_when_its_j_is_lower() -> None:
    reliability = {"careful": 0.95, "quick": 0.80}
    costs = {"careful": 4.0, "quick": 1.0}  # rho = 1/4: J = 1.0 vs 0.45
    for seed in range(10):
        auto = make_learner({"learner": "pursuit"}, list(reliability), costs, seed=seed)
        _run(auto, reliability, env_seed=seed, trials=3000)
        assert auto.converged() == "quick"


def test_lri_rewards_low_j_not_only_success_when_costs_differ() -> None:
    reliability = {"careful": 0.95, "quick": 0.80}
    costs = {"careful": 4.0, "quick": 1.0}
    for seed in range(10):
        auto = make_learner({"scheme": "lri", "rate": 0.02}, list(reliability), costs, seed=seed)
        _run(auto, reliability, env_seed=seed, trials=20000)
        assert auto.converged() == "quick"


def test_lri_reward_is_a_decreasing_affine_map_of_the_j_sample() -> None:
    auto = LinearRewardInaction(["a", "b"], costs={"a": 2.0, "b": 1.0})
    # rho = 1/2; j_lo = 0.5, j_hi = 2.0
    assert auto.reward(1, True, None) == pytest.approx(1.0)
    assert auto.reward(0, True, None) == pytest.approx(1.0 - 0.5 / 1.5)
    assert auto.reward(0, False, None) == pytest.approx(0.0)
    equal = LinearRewardInaction(["a", "b"], costs={"a": 3.0, "b": 3.0})
    assert equal.reward(0, True, None) == 1.0 and equal.reward(0, False, None) == 0.0


def test_pursuit_warmup_runs_every_action_in_turn_before_learning() -> None:
    auto = PursuitAutomaton(["a", "b", "c"], warmup=2)
    seen = []
    for _ in range(6):
        action = auto.choose()
        seen.append(action)
        auto.update(action, "success")
    assert sorted(seen) == ["a", "a", "b", "b", "c", "c"]
    assert auto.probabilities["a"] != pytest.approx(1 / 3)  # the sixth result moved p


def test_mean_estimator_is_the_classic_pursuit_update() -> None:
    auto = PursuitAutomaton(["a", "b"], rate=0.1, warmup=1, estimator="mean")
    auto.update("a", "failure")
    auto.update("b", "success")  # warm-up complete: pursue b (R̂ 1 vs 0)
    assert auto.probabilities == pytest.approx({"a": 0.45, "b": 0.55})


# -- error counts as failure ----------------------------------------------------------------------


@pytest.mark.parametrize("scheme", ["pursuit", "lri", "fixed"])
def test_error_status_counts_as_failure_for_learning(scheme: str) -> None:
    outcomes = ["success", "failure", "success", "success", "failure"] * 6
    as_error = make_learner({"scheme": scheme}, ["x", "y"], seed=3)
    as_failure = make_learner({"scheme": scheme}, ["x", "y"], seed=3)
    for k, status in enumerate(outcomes):
        action = "x" if k % 3 else "y"
        as_error.update(action, "error" if status == "failure" else status, 1.0)
        as_failure.update(action, status, 1.0)
    assert as_error.probabilities == as_failure.probabilities
    assert as_error.estimates == as_failure.estimates
    assert as_error.estimates["x"].successes < as_error.estimates["x"].trials


def test_estimates_give_r_hat_c_and_j_of_equation_1() -> None:
    auto = make_learner({}, ["a", "b"], {"a": 2.0, "b": 8.0})
    for status in ("success", "success", "error", "failure"):
        auto.update("a", status, 2.5)
    est = auto.estimates["a"]
    assert (est.trials, est.successes, est.reliability) == (4, 2, 0.5)
    assert est.cost == 2.0 and est.measured_cost == 2.5
    assert est.j == pytest.approx(cost_function(0.5, 2.0, rho_for([2.0, 8.0])))
    assert auto.estimates["b"].reliability is None and auto.estimates["b"].j is None


def test_measured_costs_set_rho_from_the_largest_mean_cost() -> None:
    auto = make_learner({"scheme": "pursuit"}, ["a", "b"])
    auto.update("a", "success", 0.1)
    auto.update("a", "success", 0.3)
    auto.update("b", "failure", 0.8)
    assert auto.cost_source == "measured"
    assert auto.rho == pytest.approx(1 / 0.8)
    assert auto.estimates["a"].j == pytest.approx(0.0 + 0.2 / 0.8)


def test_a_declared_rho_weighs_cost_in_j_and_survives_a_state_round_trip() -> None:
    costs = {"a": 0.29, "b": 0.18}
    auto = make_learner({"scheme": "pursuit", "rho": 0.5}, ["a", "b"], costs, seed=3)
    assert auto.rho == 0.5  # not 1 / 0.29
    auto.update("a", "success")
    auto.update("b", "failure")
    assert auto.estimates["a"].j == pytest.approx(0.0 + 0.5 * 0.29)
    assert auto.estimates["b"].j == pytest.approx(1.0 + 0.5 * 0.18)
    again = automaton_from_state(state_from_json(state_to_json(auto.state_dict())))
    assert again.rho == 0.5
    assert make_learner({"scheme": "pursuit"}, ["a", "b"], costs).rho == pytest.approx(1 / 0.29)


def test_perf_uses_the_rho_a_task_declares() -> None:
    from coordinator.performance import action_performance

    net = loads_net("""
[[place]]
id = "p"
tokens = 1
[[place]]
id = "run"
kind = "primitive_task"
task = "t"
[[transition]]
id = "go"
inputs = { p = 1 }
outputs = { run = 1 }
[[transition]]
id = "back"
inputs = { run = 1 }
outputs = { p = 1 }
events = ["int:t.ok"]
[[transition]]
id = "recover"
inputs = { run = 1 }
outputs = { p = 1 }
events = ["int:t.error"]
[task.t]
actions = [{ name = "a", cost = 2.0 }, { name = "b", cost = 4.0 }]
learner = { scheme = "pursuit", rho = 0.1 }
""")
    perf = action_performance(net, [])
    assert perf["t"]["a"].rho == pytest.approx(0.1)


# -- persistence and reproducibility --------------------------------------------------------------


@pytest.mark.parametrize("scheme", ["pursuit", "lri", "fixed"])
def test_state_round_trip_through_json_gives_identical_probabilities_and_draws(scheme: str) -> None:
    reliability = {"a": 0.7, "b": 0.5, "c": 0.6}
    auto = make_learner({"scheme": scheme}, list(reliability), {"a": 1.0, "b": 2.0, "c": 3.0}, seed=9)
    _run(auto, reliability, env_seed=4, trials=137, until_converged=False)
    text = state_to_json(auto.state_dict())
    again = automaton_from_state(state_from_json(text))
    assert type(again) is type(auto)
    assert again.probabilities == auto.probabilities
    assert again.estimates == auto.estimates
    assert again.state_dict() == auto.state_dict()
    assert [again.choose() for _ in range(50)] == [auto.choose() for _ in range(50)]


def test_restart_continues_exactly_where_the_learner_stopped() -> None:
    reliability = {"a": 0.6, "b": 0.8}
    straight = Learner(seed=5)
    straight.add_task("locate", ["a", "b"], {"learner": "pursuit", "learning_rate": 0.05})
    restarted = Learner(seed=5)
    restarted.add_task("locate", ["a", "b"], {"learner": "pursuit", "learning_rate": 0.05})
    env1, env2 = np.random.default_rng(1), np.random.default_rng(1)
    saved: dict[str, str] = {}
    for step in range(120):
        if step == 60:  # "crash": rebuild from the persisted rows only
            restarted = Learner(seed=5)
            restarted.add_task("locate", ["a", "b"], {"learner": "pursuit", "learning_rate": 0.05})
            assert restarted.restore({t: state_from_json(s) for t, s in saved.items()}) == []
            assert restarted.automaton("locate").probabilities == \
                straight.automaton("locate").probabilities
        for learner, env in ((straight, env1), (restarted, env2)):
            action = learner.choose("locate")
            status = "success" if env.random() < reliability[action] else "failure"
            state = learner.update("locate", action, ActionResult(status=Status(status), cost=1.0))
            if learner is restarted:
                saved["locate"] = state_to_json(state)
    assert restarted.state_dict() == straight.state_dict()


def test_learner_round_trip_rebuilds_every_task() -> None:
    learner = Learner(seed=2)
    learner.add_task("locate", ["hsv", "diff"], {"scheme": "lri"})
    learner.add_task("grasp", ["only"])
    learner.update("locate", "hsv", ActionResult(status=Status.SUCCESS, cost=0.01))
    again = Learner.from_state(json.loads(json.dumps(learner.state_dict())), seed=2)
    assert again.tasks == ("locate", "grasp")
    assert again.automaton("locate").probabilities == learner.automaton("locate").probabilities
    assert isinstance(again.automaton("grasp"), FixedChoice)


def test_restore_keeps_the_nets_current_rate_and_the_saved_probabilities() -> None:
    old = Learner(seed=3)
    old.add_task("locate", ["a", "b"], {"scheme": "pursuit", "rate": 0.05, "warmup": 1})
    for status in ("success", "failure", "success", "success"):
        old.update("locate", "a", ActionResult(status=Status(status)))
        old.update("locate", "b", ActionResult(status=Status.FAILURE))
    new = Learner(seed=3)
    new.add_task("locate", ["a", "b"], {"scheme": "pursuit", "rate": 0.2, "warmup": 1})
    assert new.restore(old.state_dict()) == []
    restored = new.automaton("locate")
    assert isinstance(restored, PursuitAutomaton) and restored.rate == 0.2
    assert restored.probabilities == old.automaton("locate").probabilities
    assert restored.estimates == old.automaton("locate").estimates


def test_restore_refuses_a_state_whose_actions_differ_from_the_net() -> None:
    old = Learner()
    old.add_task("locate", ["a", "b"])
    new = Learner()
    new.add_task("locate", ["a", "b", "c"])
    with pytest.raises(JournalError, match="does not match"):
        new.restore(old.state_dict())
    assert new.restore(old.state_dict(), strict=False) == ["locate"]


def test_malformed_state_raises_journal_error() -> None:
    state = make_learner({}, ["a", "b"]).state_dict()
    state["probabilities"] = [0.9, 0.9]
    with pytest.raises(JournalError):
        automaton_from_state(state)
    with pytest.raises(JournalError):
        state_from_json("not json")


def test_same_seed_gives_the_same_choices_and_other_seeds_differ() -> None:
    reliability = {"a": 0.6, "b": 0.65, "c": 0.5}

    def trace(seed: int) -> list[str]:
        auto = make_learner({"scheme": "pursuit", "warmup": 0}, list(reliability), seed=seed)
        return _run(auto, reliability, env_seed=0, trials=200, until_converged=False)

    assert trace(11) == trace(11)
    assert trace(11) != trace(12)
    assert task_seed(1, "locate") == task_seed(1, "locate") != task_seed(1, "grasp")


def test_fixed_choice_always_runs_the_named_action() -> None:
    auto = make_learner({"scheme": "fixed", "action": "b"}, ["a", "b"])
    assert isinstance(auto, FixedChoice)
    assert {auto.choose() for _ in range(20)} == {"b"}
    auto.update("b", "failure")
    assert auto.probabilities == {"a": 0.0, "b": 1.0} and auto.converged() == "b"
    assert isinstance(make_learner({}, ["only"]), FixedChoice)


# -- validation -----------------------------------------------------------------------------------


@pytest.mark.parametrize("config, costs, words", [
    ({"scheme": "qlearning"}, None, "unknown learner 'qlearning'"),
    ({"scheme": "pursuit", "rate": 0.0}, None, "(0, 1]"),
    ({"learning_rate": 1.5}, None, "(0, 1]"),
    ({"rate": "fast"}, None, "learning rate"),
    ({"learning_rte": 0.1}, None, "unknown learner key"),
    ({"scheme": "pursuit", "learner": "lri"}, None, "either"),
    ({"warmup": -1}, None, "warmup"),
    ({"estimator": "median"}, None, "estimator"),
    ({"scheme": "lri", "estimator": "mean"}, None, "only to learner 'pursuit'"),
    ({"scheme": "fixed", "action": "z"}, None, "not one of"),
    ({"scheme": "fixed", "rate": 0.1}, None, "does not learn"),
    ({}, {"a": 1.0}, "not for: b"),
    ({}, {"a": 1.0, "b": 1.0, "zz": 2.0}, "unknown primitive actions: zz"),
    ({}, {"a": -1.0, "b": 1.0}, ">= 0"),
    ({"cost_source": "apriori"}, None, "needs costs"),
    ({"rho": -0.5}, None, "rho must be a finite number >= 0"),
    ({"rho": True}, None, "rho must be"),
])
def test_invalid_learner_configuration_gets_a_clear_error(config: dict[str, Any], costs: dict[str, float] | None,
                                                          words: str) -> None:
    with pytest.raises(LearnerConfigError) as info:
        make_learner(config, ["a", "b"], costs)
    assert words in str(info.value)
    assert isinstance(info.value, NetError) and isinstance(info.value, ValueError)
    assert isinstance(info.value, PetrobotError) and info.value.problem == str(info.value)


def test_bad_action_lists_and_results_are_rejected() -> None:
    with pytest.raises(LearnerConfigError, match="at least one"):
        make_learner({}, [])
    with pytest.raises(LearnerConfigError, match="twice"):
        make_learner({}, ["a", "a"])
    auto = make_learner({}, ["a", "b"])
    with pytest.raises(ValueError, match="unknown primitive action"):
        auto.update("c", "success")
    with pytest.raises(ValueError, match="cost"):
        auto.update("a", "success", -0.5)


# -- `petrobot learn` ------------------------------------------------------------------------------

NET = """
[net]
name = "locate_and_move"
format = 1

[[place]]
id = "idle"
tokens = 1

[[place]]
id = "locating"
kind = "primitive_task"
task = "locate"

[[place]]
id = "moving"
kind = "primitive_task"
task = "move"

[[place]]
id = "grasping"
kind = "primitive_task"
task = "grasp"

[task.locate]
actions = [{ name = "hsv", cost = 1.0 }, { name = "avg4", cost = 4.0 }]
learner = { scheme = "pursuit", rate = 0.05 }

[task.move]
actions = ["puma"]

[task.grasp]
actions = ["pinch", "scoop"]
learner = { scheme = "lri" }

[[transition]]
id = "start"
inputs = { idle = 1 }
outputs = { locating = 1 }

[[transition]]
id = "located"
events = ["int:locate.ok"]
inputs = { locating = 1 }
outputs = { moving = 1 }

[[transition]]
id = "moved"
events = ["int:move.ok"]
inputs = { moving = 1 }
outputs = { grasping = 1 }

[[transition]]
id = "grasped"
events = ["int:grasp.ok"]
inputs = { grasping = 1 }
outputs = { idle = 1 }

[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { idle = 1 }

[[transition]]
id = "move_failed"
events = ["int:move.error"]
hidden = true
inputs = { moving = 1 }
outputs = { idle = 1 }

[[transition]]
id = "grasp_failed"
events = ["int:grasp.error"]
hidden = true
inputs = { grasping = 1 }
outputs = { idle = 1 }
"""


def test_learner_from_net_configures_every_primitive_task(tmp_path: Path) -> None:
    from coordinator.netfile import loads_net

    learner = Learner.from_net(loads_net(NET), seed=4)
    assert learner.tasks == ("locate", "move", "grasp")
    locate = learner.automaton("locate")
    assert isinstance(locate, PursuitAutomaton) and locate.rate == 0.05
    assert locate.cost_source == "apriori" and locate.rho == 0.25
    assert isinstance(learner.automaton("move"), FixedChoice)
    assert isinstance(learner.automaton("grasp"), LinearRewardInaction)
    assert learner("grasp", ("pinch", "scoop")) in {"pinch", "scoop"}


def test_bad_learner_table_in_a_net_file_names_the_task_and_problem() -> None:
    from coordinator.errors import NetError
    from coordinator.netfile import loads_net

    bad = NET.replace('learner = { scheme = "lri" }', 'learner = { scheme = "lri", rate = 2 }')
    with pytest.raises(NetError, match=r"learning rate must lie in \(0, 1\]") as info:  # caught at load time
        loads_net(bad, path="grasp.toml")
    assert info.value.line is not None and str(info.value).startswith(f"grasp.toml:{info.value.line}:")
    good = loads_net(NET)
    task = good.tasks["grasp"]
    broken = good.__class__(name=good.name, places=good.places, transitions=good.transitions, arcs=good.arcs,
                            initial_marking=good.initial_marking,
                            tasks={**good.tasks, "grasp": task.__class__(
                                name="grasp", actions=task.actions, learner={"scheme": "lri", "rate": 2})})
    with pytest.raises(LearnerConfigError, match=r"primitive task 'grasp': learning rate must lie in \(0, 1\]"):
        Learner.from_net(broken)  # a net built in code


def _journal(tmp_path: Path, runs: int = 300, *, grasp: bool = True,
             skip: str | None = None) -> tuple[Path, Path, Learner]:
    """A journal written through the runtime's journal API, as the runtime does: result, then state.

    ``grasp``: run the grasp task too; ``skip``: an instance whose result is not journaled (the
    learner still saw it).
    """
    db = tmp_path / "journal.sqlite"
    net = tmp_path / "catch.toml"
    net.write_text(NET)
    learner = Learner(seed=7)
    learner.add_task("locate", ["hsv", "avg4"], {"learner": "pursuit", "learning_rate": 0.05},
                     {"hsv": 1.0, "avg4": 4.0})
    reliability = {"hsv": 0.9, "avg4": 0.97}
    env = np.random.default_rng(3)
    with Journal(db) as journal:
        run = journal.begin_run(loads_net(NET), seed=7)
        for k in range(runs):
            action = learner.choose("locate")
            status = Status.SUCCESS if env.random() < reliability[action] else Status.ERROR
            result = ActionResult(status=status, cost=0.02, wall_s=0.02, cpu_s=0.01)
            if f"i{k}" != skip:
                journal.action_result(run, f"i{k}", "locate", action, "vision", result)
            journal.save_learner("locate", "pursuit", learner.update("locate", action, result))
        if grasp:
            learner.add_task("grasp", ["pinch", "scoop"], {"scheme": "lri", "rate": 0.05})
            for k in range(runs // 10):  # no cost reported: the runtime feeds wall_s, the journal keeps NULL
                action = learner.choose("grasp")
                wall_s = float(env.uniform(0.5, 1.5)) * (2.0 if action == "scoop" else 1.0)
                status = Status.SUCCESS if env.random() < 0.8 else Status.FAILURE
                result = ActionResult(status=status, wall_s=wall_s, cpu_s=0.01)
                journal.action_result(run, f"g{k}", "grasp", action, "motion", result)
                journal.save_learner("grasp", "lri", learner.update("grasp", action, result))
        # move runs without a saved learner state: its estimates come from its results alone
        journal.action_result(run, "m0", "move", "puma", "motion",
                              ActionResult(status=Status.SUCCESS, cost=1.2, wall_s=1.2, cpu_s=0.1))
        journal.end_run(run, "dead")
    return net, db, learner


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="petrobot")
    learn_cmd.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["learn", *argv])


def test_learn_command_reports_probabilities_and_estimates_per_task(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    net, db, learner = _journal(tmp_path)
    assert learn_cmd.run(_args(str(net), "--journal", str(db), "--json")) == 0
    doc = json.loads(capsys.readouterr().out)
    locate = doc["tasks"]["locate"]
    auto = learner.automaton("locate")
    assert {a: v["probability"] for a, v in locate["actions"].items()} == auto.probabilities
    assert locate["converged"] == auto.converged() == "hsv"
    assert locate["actions"]["avg4"]["j"] == auto.estimates["avg4"].j
    assert locate["replay_matches_state"] is True and locate["journal_results"] == 300
    move = doc["tasks"]["move"]
    assert move["scheme"] is None and move["actions"]["puma"]["trials"] == 1
    grasp = doc["tasks"]["grasp"]  # measured costs: replayed with wall_s where cost is NULL
    assert grasp["scheme"] == "lri" and grasp["replay_matches_state"] is True
    assert grasp["actions"]["scoop"]["cost"] == learner.automaton("grasp").estimates["scoop"].cost

    assert learn_cmd.run(_args(str(net), "--journal", str(db), "--task", "locate")) == 0
    text = capsys.readouterr().out
    assert "locate: pursuit" in text and "converged to hsv" in text and "move" not in text


def test_learn_command_lists_configured_tasks_that_have_not_run(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    net, db, _ = _journal(tmp_path, runs=5, grasp=False)
    assert learn_cmd.run(_args(str(net), "--journal", str(db), "--json")) == 0
    grasp = json.loads(capsys.readouterr().out)["tasks"]["grasp"]
    assert grasp["scheme"] == "lri" and grasp["note"] == "no result yet"
    assert grasp["actions"]["pinch"]["probability"] == 0.5 and grasp["steps"] == 0


def test_learn_command_plots_the_probabilities_over_trials(tmp_path: Path) -> None:
    net, db, _ = _journal(tmp_path, runs=80)
    png = tmp_path / "curve.png"
    assert learn_cmd.run(_args(str(net), "--journal", str(db), "--plot", str(png), "--json")) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_learn_command_flags_a_journal_that_misses_results(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    net, db, _ = _journal(tmp_path, runs=50, skip="i10")
    assert learn_cmd.run(_args(str(net), "--journal", str(db))) == 0
    assert "does NOT match" in capsys.readouterr().out


def test_learn_command_fails_cleanly_on_a_missing_journal(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    net = tmp_path / "n.toml"
    net.write_text(NET)
    assert learn_cmd.run(_args(str(net), "--journal", str(tmp_path / "none.sqlite"))) == 2
    assert "no such journal" in capsys.readouterr().err


def test_learn_command_fails_cleanly_on_a_bad_net(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, db, _ = _journal(tmp_path, runs=5)
    bad = tmp_path / "bad.toml"
    bad.write_text(NET.replace('learner = { scheme = "lri" }', 'learner = { scheme = "sarsa" }'))
    assert learn_cmd.run(_args(str(bad), "--journal", str(db))) == 2
    assert "unknown learner 'sarsa'" in capsys.readouterr().err


def test_learn_command_reads_a_journal_written_by_the_runtime_journal(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    net_path = tmp_path / "net.toml"
    net_path.write_text(NET)
    net = loads_net(NET)
    learner = Learner.from_net(net, seed=1)
    env = np.random.default_rng(8)
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net, seed=1)
        for k in range(60):
            action = learner.choose("grasp")
            status = "success" if env.random() < (0.9 if action == "pinch" else 0.6) else "error"
            wall_s = 0.5 if action == "pinch" else 0.2
            result = ActionResult(status=Status(status), wall_s=wall_s)
            journal.action_result(run, f"i{k}", "grasp", action, "motion", result)
            journal.save_learner("grasp", "lri", learner.update("grasp", action, result))
    assert learn_cmd.run(_args(str(net_path), "--journal", str(tmp_path / "j.sqlite"), "--json")) == 0
    grasp = json.loads(capsys.readouterr().out)["tasks"]["grasp"]
    assert grasp["replay_matches_state"] is True and grasp["steps"] == 60
    assert grasp["actions"]["pinch"]["probability"] == learner.automaton("grasp").probabilities["pinch"]


def test_learn_command_replays_one_run_from_a_fresh_learner_with_run(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    net_path = tmp_path / "net.toml"
    net_path.write_text(NET)
    net = loads_net(NET)
    learner = Learner.from_net(net, seed=1)
    env = np.random.default_rng(8)
    runs = []
    with Journal(tmp_path / "j.sqlite") as journal:
        for trials in (40, 20):
            run = journal.begin_run(net, seed=1)
            for k in range(trials):
                action = learner.choose("grasp")
                status = Status.SUCCESS if env.random() < (0.9 if action == "pinch" else 0.6) else Status.ERROR
                result = ActionResult(status=status, wall_s=0.5 if action == "pinch" else 0.2)
                journal.action_result(run, f"{run}-{k}", "grasp", action, "motion", result)
                journal.save_learner("grasp", "lri", learner.update("grasp", action, result))
            journal.end_run(run, "dead")
            runs.append(run)
    db = str(tmp_path / "j.sqlite")
    assert learn_cmd.run(_args(str(net_path), "--journal", db, "--run", runs[1], "--json")) == 0
    grasp = json.loads(capsys.readouterr().out)["tasks"]["grasp"]
    assert grasp["steps"] == grasp["journal_results"] == 20 and grasp["replay_matches_state"] is None
    assert grasp["note"] == f"a fresh learner over the 20 results of run {runs[1]}"
    assert learn_cmd.run(_args(str(net_path), "--journal", db, "--run", "nope")) == 2
    assert "no run 'nope'" in capsys.readouterr().err


def test_the_catch_nets_locate_learner_moves_within_the_four_runs_of_the_demo():
    """After the default 4-run demo the learner shows what it learned (section 4), not p = 1/3."""
    from coordinator.learning import Learner
    from coordinator.netfile import load_net

    auto = Learner.from_net(load_net(Path(__file__).resolve().parents[2] / "nets" / "catch.toml"), seed=0) \
        .automaton("locate")
    for _ in range(4):
        auto.update(auto.choose(), Status.SUCCESS, 1.0)
    assert max(auto.probabilities.values()) > 0.4
    assert max(auto.probabilities, key=auto.probabilities.get) == "locate_bgdiff"  # least J: the cheapest


def test_learn_plot_without_a_file_writes_beside_the_journal_and_a_demo_line_says_what_was_learned(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    from tests.unit.test_performance import _agree_journal

    net_file, journal = _agree_journal(tmp_path)
    parser = argparse.ArgumentParser()
    learn_cmd.add_parser(parser.add_subparsers())
    assert learn_cmd.run(parser.parse_args(["learn", str(net_file), "--journal", str(journal), "--plot"])) == 0
    target = tmp_path / "j.learning.png"
    assert target.stat().st_size > 0
    assert f"plot: 1 task(s) drawn to {target}" in capsys.readouterr().out  # pick; place has one action
    (line,) = learn_cmd.learned_so_far(journal, net_file)
    assert line.startswith("learner pick (pursuit, 6 results, ") and "p = pick_fast 0." in line
    assert "least J so far: pick_fast" in line


def test_the_mobile_demos_learner_line_says_to_go_on_learning_with_the_mobile_demo(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    from tests.unit.test_performance import _agree_journal

    net_file, journal = _agree_journal(tmp_path)
    learn_cmd.print_learned(journal, net_file, "mobile")
    assert capsys.readouterr().out.rstrip().endswith(f"go on learning from here: petrobot demo mobile --journal {journal}")
    learn_cmd.print_learned(journal, net_file)
    assert capsys.readouterr().out.rstrip().endswith(f"go on learning from here: petrobot demo --journal {journal}")
