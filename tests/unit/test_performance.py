"""J = 1 - R + rho C (paper section 3) per primitive action, primitive task and task."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from coordinator.analysis.gspn_performance import gspn_task_performance
from coordinator.commands import gspn as gspn_cmd
from coordinator.commands import perf as perf_cmd
from coordinator.journal import Journal
from coordinator.performance import (
    ActionRecord,
    action_performance,
    cost_function,
    error_sink_places,
    rho_for,
    task_performance,
)
from services.results import ActionResult, Status
from tests.unit.test_ptimed import two_step_task


def records() -> list[ActionRecord]:
    out = []
    for i in range(10):  # a1: 8/10 success, 1 s; a2: 5/10 success, 0.5 s
        out.append(ActionRecord(task="a", action="a1", status="success" if i < 8 else "failure", wall_s=1.0, cpu_s=0.2))
        out.append(ActionRecord(task="a", action="a2", status="success" if i < 5 else "error", wall_s=0.5, cpu_s=0.1))
    out.append(ActionRecord(task="b", action="b1", status="success", wall_s=0.4))
    return out


def test_cost_function_follows_equation_one() -> None:
    assert cost_function(0.9, 2.0, 0.25) == pytest.approx(0.6)
    assert rho_for([1.0, 4.0, 2.0]) == pytest.approx(0.25)


def test_action_reliability_is_the_frequency_of_success_and_error_counts_as_failure() -> None:
    perf = action_performance(two_step_task(), records())
    a1, a2 = perf["a"]["a1"], perf["a"]["a2"]
    assert (a1.reliability, a2.reliability) == (0.8, 0.5)
    assert a1.rho == pytest.approx(1.0) and a1.cost == pytest.approx(1.0)
    assert a1.j == pytest.approx(1 - 0.8 + 1.0)
    assert a2.j == pytest.approx(1 - 0.5 + 0.5)
    assert a2.errors == 5


def test_cpu_measure_and_a_priori_fallback() -> None:
    perf = action_performance(two_step_task(), records(), measure="cpu")
    assert perf["a"]["a1"].rho == pytest.approx(5.0)
    assert perf["b"]["b1"].cost is None and perf["b"]["b1"].j is None


def test_primitive_task_takes_its_best_action_or_a_given_mix() -> None:
    acts = action_performance(two_step_task(), records())["a"]
    best = task_performance(acts)
    assert best.basis == "best action a2" and best.j == pytest.approx(1.0)
    mix = task_performance(acts, probabilities={"a1": 0.5, "a2": 0.5})
    assert mix.j == pytest.approx(0.5 * acts["a1"].j + 0.5 * acts["a2"].j)


def test_task_performance_comes_from_the_gspn_absorption() -> None:
    net = two_step_task()
    task, details = gspn_task_performance(net, records(), ext_rates={"tick": 4.0})
    # a: mean 0.75 s, normal branch 15/20; b: 0.4 s, always normal (journal).
    assert task.reliability == pytest.approx(0.75)
    assert task.cost == pytest.approx(0.25 + 0.75 + 0.75 * 0.4)
    assert details["c_max"] == pytest.approx(0.25 + 1.0 + 0.75 * 0.4)
    assert task.j == pytest.approx(1 - task.reliability + task.cost / details["c_max"])
    assert error_sink_places(net) == {"failed"}


def make_journal(path: Path, *, runs: int = 1) -> list[str]:
    """A journal written through its API: the results of :func:`records` once per run; the run ids."""
    ids = []
    with Journal(path) as journal:
        for _ in range(runs):
            run = journal.begin_run(two_step_task())
            for i, r in enumerate(records()):
                result = ActionResult(status=r.status, wall_s=r.wall_s or 0.0, cpu_s=r.cpu_s or 0.0)
                journal.action_result(run, str(i), r.task, r.action, "n", result)
            journal.end_run(run, "dead")
            ids.append(run)
    return ids


def test_perf_and_gspn_commands_report_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.netfile import dump_net

    net_file = tmp_path / "two.toml"
    net_file.write_text(dump_net(two_step_task()))
    journal = tmp_path / "j.sqlite"
    make_journal(journal)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    perf_cmd.add_parser(sub)
    gspn_cmd.add_parser(sub)
    args = parser.parse_args(["perf", str(net_file), "--journal", str(journal), "--ext-rate", "tick=4", "--json"])
    assert perf_cmd.run(args) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["actions"]["a"]["a1"]["reliability"] == 0.8
    assert rep["task"]["reliability"] == pytest.approx(0.75)
    args = parser.parse_args(["gspn", str(net_file), "--journal", str(journal), "--ext-rate", "tick=4", "--json",
                              "--write-gspn", str(tmp_path / "view.toml"), "--simulate", "200"])
    assert gspn_cmd.run(args) == 0
    rep = json.loads(capsys.readouterr().out)
    for key in ("tangible_markings", "vanishing_markings", "mean_tokens", "probability_nonempty", "throughput",
                "mean_time_to_absorption", "absorption"):
        assert key in rep
    assert rep["mean_time_to_absorption"] == pytest.approx(0.25 + 0.75 + 0.75 * 0.4)
    assert (tmp_path / "view.toml").exists()
    sim = rep["simulation"]
    assert sim["delays"]["run_a.run"] == "empirical"
    assert abs(sim["mean_time_to_absorption"]["mean"] - rep["mean_time_to_absorption"]) < 0.2
    args = parser.parse_args(["perf", str(net_file), "--journal", str(tmp_path / "missing.sqlite")])
    assert perf_cmd.run(args) == 2


def test_a_record_takes_its_status_as_the_result_vocabulary() -> None:
    assert ActionRecord(task="a", action="a1", status="failure").status is Status.FAILURE
    with pytest.raises(ValueError):
        ActionRecord(task="a", action="a1", status="cancelled")


def test_perf_and_gspn_take_one_run_of_the_journal_with_run(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.netfile import dump_net

    net_file = tmp_path / "two.toml"
    net_file.write_text(dump_net(two_step_task()))
    journal = tmp_path / "j.sqlite"
    first, _ = make_journal(journal, runs=2)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    perf_cmd.add_parser(sub)
    gspn_cmd.add_parser(sub)
    assert perf_cmd.run(parser.parse_args(["perf", str(net_file), "--journal", str(journal), "--json"])) == 0
    assert json.loads(capsys.readouterr().out)["results"] == 2 * len(records())
    args = parser.parse_args(["perf", str(net_file), "--journal", str(journal), "--run", first, "--json"])
    assert perf_cmd.run(args) == 0
    rep = json.loads(capsys.readouterr().out)
    assert (rep["run"], rep["results"]) == (first, len(records()))
    assert rep["actions"]["a"]["a1"]["reliability"] == 0.8
    args = parser.parse_args(["gspn", str(net_file), "--journal", str(journal), "--run", first, "--json"])
    assert gspn_cmd.run(args) == 0
    assert json.loads(capsys.readouterr().out)["mean_time_to_absorption"] > 0
    args = parser.parse_args(["perf", str(net_file), "--journal", str(journal), "--run", "nope"])
    assert perf_cmd.run(args) == 2
    assert "no run 'nope'" in capsys.readouterr().err


def catch_journal(path: Path, caught: int = 17, missed: int = 0) -> None:
    """A journal of the catch net's results as the actions report them: named outcomes on every exit."""
    with Journal(path) as journal:
        run = journal.begin_run(two_step_task())
        rows = [("locate", "locate_threshold", ActionResult(status=Status.SUCCESS, wall_s=1.0))] * (caught + missed)
        rows += [("predict", "predict", ActionResult(status=Status.SUCCESS, wall_s=1.5))] * (caught + missed)
        rows += [("catch", "catch", ActionResult(status=Status.SUCCESS, outcome="caught", wall_s=1.2))] * caught
        rows += [("catch", "catch", ActionResult(status=Status.FAILURE, outcome="missed", wall_s=1.4))] * missed
        rows += [("home", "move_home", ActionResult(status=Status.SUCCESS, wall_s=0.0))] * (caught + missed)
        for i, (task, action, result) in enumerate(rows):
            journal.action_result(run, str(i), task, action, "n", result)
        journal.end_run(run, "completed")


def test_perf_and_gspn_on_a_journal_of_17_caught_balls_give_a_reliable_task(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every catch succeeded with outcome 'caught': no run can end in aborted_runs, R is 1, and a
    measured mean time of 0 s (move_home) is no division by zero."""
    journal = tmp_path / "j.sqlite"
    catch_journal(journal)
    net = str(Path(__file__).resolve().parents[2] / "nets" / "catch.toml")
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    perf_cmd.add_parser(sub)
    gspn_cmd.add_parser(sub)
    rates = ["--ext-rate", "image_sampling_tick=30", "--ext-rate", "ball_caught=2"]
    assert perf_cmd.run(parser.parse_args(["perf", net, "--journal", str(journal), "--json", *rates])) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["actions"]["catch"]["catch"]["reliability"] == 1.0
    assert rep["task"]["reliability"] == pytest.approx(1.0, abs=1e-6)
    assert gspn_cmd.run(parser.parse_args(["gspn", net, "--journal", str(journal), "--json", *rates])) == 0
    rep = json.loads(capsys.readouterr().out)
    aborted = sum(a["probability"] for a in rep["absorption"] if a["marking"].get("aborted_runs"))
    assert aborted == pytest.approx(0.0, abs=1e-6)
    assert not [w for w in rep["warnings"] if "ball_caught" in w and "probability 0" in w]


def test_learn_on_a_journal_of_known_frequencies_counts_named_outcomes_by_their_status(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.cli import main

    journal = tmp_path / "j.sqlite"
    catch_journal(journal, caught=17, missed=3)
    net = str(Path(__file__).resolve().parents[2] / "nets" / "catch.toml")
    assert main(["learn", net, "--journal", str(journal), "--json"]) == 0
    catch = json.loads(capsys.readouterr().out)["tasks"]["catch"]["actions"]["catch"]
    assert (catch["trials"], catch["successes"]) == (20, 17)
    assert catch["reliability"] == pytest.approx(0.85)
    assert main(["perf", net, "--journal", str(journal), "--json", "--ext-rate", "image_sampling_tick=30",
                 "--ext-rate", "ball_caught=2"]) == 0
    assert json.loads(capsys.readouterr().out)["actions"]["catch"]["catch"]["reliability"] == pytest.approx(0.85)


AGREE = """
[net]
name = "pick_and_place"
home = { arm = 1 }

[[place]]
id = "runs"
kind = "control"
tokens = 6

[[place]]
id = "arm"
kind = "resource"
tokens = 1

[[place]]
id = "picking"
kind = "primitive_task"
task = "pick"

[[place]]
id = "placing"
kind = "primitive_task"
task = "place"

[task.pick]
actions = ["pick_fast", "pick_slow"]
learner = { scheme = "pursuit", warmup = 1 }

[task.place]
actions = ["place_down"]
deadline_s = 20.0

[[transition]]
id = "start"
inputs = { runs = 1, arm = 1 }
outputs = { picking = 1 }

[[transition]]
id = "picked"
events = ["int:pick.ok"]
inputs = { picking = 1 }
outputs = { placing = 1 }

[[transition]]
id = "pick_failed"
events = ["int:pick.error"]
inputs = { picking = 1 }
outputs = { arm = 1 }

[[transition]]
id = "placed"
events = ["int:place.ok"]
inputs = { placing = 1 }
outputs = { arm = 1 }

[[transition]]
id = "place_failed"
events = ["int:place.error"]
inputs = { placing = 1 }
outputs = { arm = 1 }
"""


def _agree_journal(tmp_path: Path) -> tuple[Path, Path]:
    """A journal of six runs: pick_fast 0.5 s, pick_slow 1.5 s (wall time only), place_down reporting a
    cost of 0.05 (its CPU time) for 2 s of wall time, failing one time in three."""
    import asyncio

    from coordinator.runtime import Runtime
    from coordinator.session import build_learner
    from coordinator.journal import JournalReader
    from coordinator.netfile import loads_net
    from tests.unit.runtime_fakes import FakeClient

    placed = iter(range(100))
    client = FakeClient({
        "pick_fast": ActionResult(status=Status.SUCCESS, wall_s=0.5),
        "pick_slow": ActionResult(status=Status.SUCCESS, wall_s=1.5),
        "place_down": lambda params: ActionResult(status=Status.FAILURE if next(placed) % 3 == 2 else Status.SUCCESS,
                                                  wall_s=2.0, cost=0.05)})
    net = loads_net(AGREE)
    net_file, journal = tmp_path / "pick_and_place.toml", tmp_path / "j.sqlite"
    net_file.write_text(AGREE)
    with Journal(journal) as j:
        with JournalReader.open(journal) as reader:
            learner = build_learner(net, 0, reader)
        summary = asyncio.run(Runtime(net, client, j, learner=learner).run(max_seconds=60))
    assert summary.calls == 12
    return net_file, journal


def test_perf_and_learn_give_the_same_c_rho_and_j_and_a_single_action_is_weighed_against_its_deadline(
        tmp_path: Path) -> None:
    from coordinator.commands import learn as learn_cmd

    net_file, journal = _agree_journal(tmp_path)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    perf_cmd.add_parser(sub)
    learn_cmd.add_parser(sub)
    perf = perf_cmd.report(parser.parse_args(["perf", str(net_file), "--journal", str(journal)]))
    args = parser.parse_args(["learn", str(net_file), "--journal", str(journal)])
    from coordinator.learning import Learner
    from coordinator.netfile import load_any

    states, results = learn_cmd.read_journal(journal)
    learn = learn_cmd.report_json(learn_cmd.build_reports(states, results, None, Learner.from_net(load_any(net_file))),
                                  args.threshold)["tasks"]
    for task, actions in perf["actions"].items():
        assert perf["actions"][task][next(iter(actions))]["rho"] == pytest.approx(learn[task]["rho"])
        for action, row in actions.items():
            mine = learn[task]["actions"][action]
            assert (row["cost"], row["reliability"], row["j"]) == pytest.approx((mine["cost"], mine["reliability"],
                                                                                 mine["j"])), (task, action)
    place = perf["actions"]["place"]["place_down"]
    # the reported cost (0.05), not the wall time (2 s); rho = 1/deadline: J = 1 - 2/3 + 0.05/20
    assert place["cost"] == pytest.approx(0.05) and place["rho"] == pytest.approx(1 / 20)
    assert place["j"] == pytest.approx(1 - 4 / 6 + 0.05 / 20)
    assert perf["actions"]["pick"]["pick_slow"]["rho"] == pytest.approx(1 / 1.5)


def test_perf_and_learn_say_that_lower_j_is_better(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.commands import learn as learn_cmd

    net_file, journal = _agree_journal(tmp_path)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    perf_cmd.add_parser(sub)
    learn_cmd.add_parser(sub)
    assert perf_cmd.run(parser.parse_args(["perf", str(net_file), "--journal", str(journal)])) == 0
    assert "LOWER IS BETTER" in capsys.readouterr().out
    assert learn_cmd.run(parser.parse_args(["learn", str(net_file), "--journal", str(journal)])) == 0
    out = capsys.readouterr().out
    assert "lower is better" in out and "1/its deadline 20 s" in out
