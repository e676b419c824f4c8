"""The robotic reading (stable, error recoverable, controllable) and the `petrobot analyze` command."""

from __future__ import annotations

import argparse
import json

import pytest

from coordinator.analysis.robotic import error_transitions, report
from coordinator.commands import analyze
from coordinator.netfile import loads_net

HEADER = """
[net]
name = "{name}"
format = 1
{home}

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "locating"
kind = "primitive_task"
task = "locate"

[task.locate]
actions = [{{ name = "locate_threshold" }}]

[[transition]]
id = "start"
events = ["ext:tick"]
inputs = {{ idle = 1 }}
outputs = {{ locating = 1 }}

[[transition]]
id = "located"
events = ["int:locate.ok"]
inputs = {{ locating = 1 }}
outputs = {{ idle = 1 }}
"""

RECOVERS = """
[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { idle = 1 }
"""

STRANDS = """
[[place]]
id = "broken"

[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { broken = 1 }
"""

LEAKS = """
[[place]]
id = "frames"

[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { idle = 1, frames = 1 }
"""


def task(body: str, name: str = "locate_task", home: str = "") -> str:
    return HEADER.format(name=name, home=home) + body


def test_task_with_a_recovery_branch_is_stable_recoverable_and_controllable() -> None:
    net = loads_net(task(RECOVERS))
    assert error_transitions(net) == ["locate_failed"]
    rep = report(net)
    rob = rep["robotic"]
    assert rob["stable"]["holds"] is True
    assert rob["error_recoverable"]["holds"] is True
    assert rob["error_recoverable"]["witness"]["markings_after_error_branches"] == 1
    assert "error branch" in rob["error_recoverable"]["explanation"]
    assert rob["controllable"]["holds"] is True
    assert rep["live"] is True and rep["reversible"] is True


def test_error_branch_into_a_dead_end_is_not_recoverable_and_names_the_marking() -> None:
    rep = report(loads_net(task(STRANDS)))
    rec = rep["robotic"]["error_recoverable"]
    assert rec["holds"] is False
    example = rec["witness"]["examples"][0]
    assert example == {"marking": {"broken": 1}, "firing_sequence": ["start", "locate_failed"],
                       "after_error_branch": True}
    assert "start → locate_failed" in rec["explanation"]
    ctl = rep["robotic"]["controllable"]
    assert ctl["holds"] is False
    assert set(ctl["witness"]["not_live_transitions"]) == {"start", "located", "locate_failed"}
    assert rep["deadlock"] is True and rep["deadlocks"][0]["firing_sequence"] == ["start", "locate_failed"]


def test_error_branch_that_leaks_a_token_is_not_stable_and_names_the_growing_place() -> None:
    rep = report(loads_net(task(LEAKS)))
    stable = rep["robotic"]["stable"]
    assert stable["holds"] is False
    assert stable["witness"]["growing_places"] == ["frames"]
    assert stable["witness"]["repeatable_loop"] == ["start", "locate_failed"]
    assert "frames" in stable["explanation"]
    assert rep["bounded"] is False and rep["place_bounds"]["frames"] is None
    # frames is only a record: recovery is decided on the net without it
    assert rep["robotic"]["error_recoverable"]["holds"] is True


TERMINATES = """
[net]
name = "locate_once"
format = 1
home = { done = 1 }

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "locating"
kind = "primitive_task"
task = "locate"

[[place]]
id = "done"

[task.locate]
actions = [{ name = "locate_threshold" }]

[[transition]]
id = "start"
inputs = { idle = 1 }
outputs = { locating = 1 }

[[transition]]
id = "located"
events = ["int:locate.ok"]
inputs = { locating = 1 }
outputs = { done = 1 }

[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { done = 1 }
"""


def test_the_report_finds_the_graph_s_strongly_connected_components_once(monkeypatch: pytest.MonkeyPatch) -> None:
    # the analysis's liveness levels and the controllable verdict read the same components
    from coordinator.analysis import robotic, structure

    calls: list[int] = []
    components = structure.graph_liveness
    for module in (structure, robotic):
        monkeypatch.setattr(module, "graph_liveness", lambda *a, **k: calls.append(a[0]) or components(*a, **k))
    rep = report(loads_net(task(RECOVERS)))
    assert rep["robotic"]["controllable"]["holds"] is True and rep["live"] is True
    assert calls == [rep["states"]]


def test_terminating_task_ending_in_its_home_marking_is_controllable_with_the_end_restarted() -> None:
    rep = report(loads_net(TERMINATES))
    assert rep["deadlock"] is True and rep["live"] is False
    assert rep["home_marking_is_home"] is True
    assert rep["robotic"]["error_recoverable"]["holds"] is True
    ctl = rep["robotic"]["controllable"]
    assert ctl["holds"] is True and ctl["witness"]["finished_task_restarted"] is True


def test_report_is_json_with_the_required_keys() -> None:
    rep = report(loads_net(task(RECOVERS)))
    text = json.dumps(rep)
    for key in ("states", "edges", "max_token_in_place", "max_token_per_marking", "bounded", "deadlock", "live",
                "quasi_live", "reversible", "one_safe", "stable_marking", "p_invariants", "t_invariants"):
        assert key in rep
    assert set(rep["robotic"]) == {"stable", "error_recoverable", "controllable"}
    assert json.loads(text)["p_invariants"] == [{"idle": 1, "locating": 1}]


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    analyze.add_parser(sub)
    return parser.parse_args(["analyze", *argv])


def test_analyze_command_prints_json_and_text(tmp_path: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "task.toml"  # type: ignore[operator]
    path.write_text(task(STRANDS), encoding="utf-8")
    assert analyze.run(parse([str(path), "--json"])) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["states"] == 3 and rep["robotic"]["error_recoverable"]["holds"] is False
    assert analyze.run(parse([str(path), "--max-states", "100"])) == 0
    out = capsys.readouterr().out
    assert "error recoverable: no" in out and "deadlock:           yes" in out


def test_analyze_command_reports_an_unreadable_net(tmp_path: pytest.TempPathFactory,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.toml"  # type: ignore[operator]
    path.write_text("[net\n", encoding="utf-8")
    assert analyze.run(parse([str(path)])) == 2
    assert "petrobot analyze" in capsys.readouterr().err


def test_analyze_command_shows_progress_on_request(tmp_path: pytest.TempPathFactory,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "task.toml"  # type: ignore[operator]
    path.write_text(task(RECOVERS), encoding="utf-8")
    assert analyze.run(parse([str(path), "--progress"])) == 0
    err = capsys.readouterr().err
    assert err.endswith("\n")
    # the compiled search is loaded before the clock of the markings/s figure starts
    assert err.startswith("  loading the compiled state-space search ... ") and "markings/s" in err


def test_analyze_progress_writes_each_phase_as_a_whole_line(capsys: pytest.CaptureFixture[str]) -> None:
    # a phase's line ends with its newline when it is written (a log fed by a pipe shows it then),
    # and no blank line comes before it: the counter's line, rewritten in place, is ended first
    from tests.unit.mcc_models import MCC

    path = MCC / "Kanban-PT-00005" / "model.pnml"
    assert analyze.run(parse([str(path), "--progress", "--engine", "symbolic", "--json"])) == 0
    err = capsys.readouterr().err
    lines = err.split("\n")
    phases = [line for line in lines if line.startswith("  symbolic: ")]
    assert phases and phases[0].startswith("  symbolic: 5 levels (4 groups of places)")
    assert err.endswith("\n") and "" not in lines[:-1]


def test_analyze_progress_puts_a_notice_on_a_line_of_its_own() -> None:
    # a notice (the compile's) met while the counter's line, or the loading line, is open starts a
    # line of its own; the loading line then ends as a line of its own too
    import io

    out = io.StringIO()
    shown = analyze._Progress(out)
    shown.count(10, 20)
    shown.note("compiling the state-space search (once per machine)...")
    shown.phase("symbolic: 7 levels")
    shown.end()
    lines = out.getvalue().split("\n")
    assert lines[0].startswith("\r  ") and lines[0].endswith("markings/s")
    assert lines[1:] == ["compiling the state-space search (once per machine)...", "  symbolic: 7 levels", ""]
    out = io.StringIO()
    shown = analyze._Progress(out)
    shown.begin("  loading ...")
    shown.end(" 0.1 s", "  loaded in 0.1 s")
    shown.begin("  loading ...")
    shown.note("compiling")
    shown.end(" 9.0 s", "  loaded in 9.0 s")
    assert out.getvalue() == "  loading ... 0.1 s\n  loading ...\ncompiling\n  loaded in 9.0 s\n"


EXPERIMENT = """
[net]
name = "two_runs"
format = 1
home = { idle = 1 }

[[place]]
id = "runs_remaining"
kind = "control"
tokens = 2

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "locating"
kind = "primitive_task"
task = "locate"

[[place]]
id = "found"

[[place]]
id = "aborted"

[task.locate]
actions = [{ name = "locate_threshold" }]

[[transition]]
id = "start"
inputs = { runs_remaining = 1, idle = 1 }
outputs = { locating = 1 }

[[transition]]
id = "located"
events = ["int:locate.ok"]
inputs = { locating = 1 }
outputs = { idle = 1, found = 1 }

[[transition]]
id = "locate_failed"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { idle = 1, aborted = 1 }
"""


def test_finite_experiment_recovers_when_its_resources_come_back_whatever_the_counters() -> None:
    from coordinator.analysis.robotic import home_condition, record_places

    net = loads_net(EXPERIMENT)
    assert record_places(net) == ["found", "aborted"]
    assert home_condition(net) == ({"idle": 1, "locating": 0}, ["runs_remaining", "found", "aborted"])
    rep = report(net)
    assert rep["reversible"] is False and rep["home_marking_is_home"] is False
    rec = rep["robotic"]["error_recoverable"]
    assert rec["holds"] is True and "not counting runs_remaining, found, aborted" in rec["explanation"]
    ctl = rep["robotic"]["controllable"]
    # the operator (the environment) gives the finished experiment new runs: no restart is needed
    assert ctl["holds"] is True and ctl["witness"]["finished_task_restarted"] is False
    assert rep["environment"]["control_places"] == {"runs_remaining": 2}


def test_task_that_counts_its_runs_for_ever_is_unstable_but_recoverable_and_controllable() -> None:
    text = EXPERIMENT.replace("tokens = 2\n", "tokens = 1\n").replace(
        "inputs = { runs_remaining = 1, idle = 1 }\noutputs = { locating = 1 }",
        "inputs = { runs_remaining = 1, idle = 1 }\noutputs = { locating = 1, runs_remaining = 1 }")
    rep = report(loads_net(text))
    stable = rep["robotic"]["stable"]
    assert stable["holds"] is False
    assert sorted(stable["witness"]["growing_places"]) == ["aborted", "found"]
    assert "only record" in stable["explanation"]
    assert rep["robotic"]["error_recoverable"]["holds"] is True
    assert rep["robotic"]["controllable"]["holds"] is True
    assert rep["live"] is True and rep["reversible"] is False


def test_unbounded_task_whose_growing_place_is_read_leaves_recovery_undecided() -> None:
    text = task(LEAKS) + """
[[transition]]
id = "discard"
inputs = { frames = 2 }
outputs = {}
"""
    rep = report(loads_net(text))
    assert rep["robotic"]["stable"]["holds"] is False
    assert rep["robotic"]["error_recoverable"]["holds"] is None
    assert "could not be checked" in rep["robotic"]["error_recoverable"]["explanation"]
    assert rep["robotic"]["controllable"]["holds"] is None


def test_too_large_experiment_is_judged_on_the_net_without_its_counters() -> None:
    net = loads_net(EXPERIMENT.replace("tokens = 2\n", "tokens = 30\n"))
    rep = report(net, max_states=100, engine="explicit")  # ~1,000 markings, without its counters 61
    assert rep["complete"] is False and rep["bounded"] is True
    assert rep["live"] is False and rep["deadlock"] is True and rep["reversible"] is False
    rec = rep["robotic"]["error_recoverable"]
    assert rec["holds"] is True and "counted without the record-only places" in rec["explanation"]
    assert rep["robotic"]["controllable"]["holds"] is True


def test_the_catch_net_of_fig_1_is_stable_and_recovers_from_every_error_but_a_robot_out_of_service():
    from pathlib import Path

    from coordinator.analysis.robotic import report
    from coordinator.netfile import load_any

    root = Path(__file__).resolve().parents[2]
    doc = report(load_any(root / "nets" / "catch.toml", interpreted=False))
    assert (doc["states"], doc["edges"]) == (998, 2900)
    assert doc["bounded"] is True
    robotic = doc["robotic"]
    assert robotic["stable"]["holds"] is True
    # the bounded retries of the move home end in a robot out of service: the only unrecoverable state
    recoverable = robotic["error_recoverable"]
    assert recoverable["holds"] is False and "home_given_up" in recoverable["explanation"]
    assert "robot_out_of_service" in recoverable["explanation"]
    # the experiment ends: every dead marking has the robot home and the camera free, or the robot
    # out of service after its last retry
    for d in doc["deadlocks"]:
        m = d["marking"]
        assert (m.get("robot_ready") == 1 and m.get("camera_free") == 1) or m.get("robot_out_of_service") == 1


def _paper_net(name: str) -> dict:
    from pathlib import Path

    from coordinator.netfile import load_any

    return report(load_any(Path(__file__).resolve().parents[2] / "nets" / name, interpreted=False))


def test_the_catch_nets_dead_markings_are_its_intended_ends_and_its_designed_stop_not_unexplained_deadlocks():
    doc = _paper_net("catch.toml")
    ends = doc["ends"]
    assert ends["decided"] and ends["total"] == doc["n_deadlocks"] == 49
    # the experiment over (runs_remaining empty), robot and camera home: the run ends completed
    assert (ends["intended"], ends["operator"], ends["stuck"]) == (15, 0, 34)
    assert {"robot_ready": 1, "camera_free": 1, "missed": 4, "home_retries_left": 3} in [
        e["marking"] for e in ends["examples"]["intended"]]
    # every real deadlock comes after home_given_up: the robot out of service, as the net says
    assert ends["stuck_designed_stop"] == 34
    assert all("home_given_up" in e["firing_sequence"] and e["designed_stop"] for e in ends["examples"]["stuck"])
    recoverable = doc["robotic"]["error_recoverable"]["explanation"]
    controllable = doc["robotic"]["controllable"]["explanation"]
    assert "by design" in recoverable and "add a recovery branch" not in recoverable
    assert "by design" in controllable and "only a person" in recoverable and "a person" in controllable
    text = analyze.render(doc)
    assert "deadlock:           yes [a real deadlock = " in text and "34 of the 49 dead markings; 15 intended" in text
    assert "intended ends (the run completes at home" in text
    # the two marking counts say what each counts
    assert "998 markings" in text and "another graph, of 194 markings: without those counts" in text
    # L-levels and properties in plain words
    for words in ("L1 (can fire at least once, but not for ever", "L3 (can fire again and again along some run",
                  "consistent = some sequence of firings that fires every transition brings the net back"):
        assert words in text


def test_the_mobile_nets_out_of_service_ends_wait_for_the_operators_reset_and_none_is_a_real_deadlock():
    doc = _paper_net("mobile.toml")
    ends = doc["ends"]
    assert (ends["intended"], ends["operator"], ends["stuck"]) == (2, 3, 0)
    assert all(e["operator"] == ["+ reset_request 1 would enable operator_reset"] for e in ends["examples"]["operator"])
    assert doc["robotic"]["error_recoverable"]["holds"] is True and doc["robotic"]["controllable"]["holds"] is True
    assert "deadlock:           no [" in analyze.render(doc)


def test_an_undecided_deadlock_is_not_reported_as_no_dead_marking() -> None:
    from analysis_nets import make_net

    # pump can fire for ever, c grows without bound, and no search or structural rule here decides
    # whether a dead marking is reachable
    net = make_net("pump", {"src": 1, "x": 1}, {"pump": ({"src": 1, "x": 1}, {"src": 1, "x": 1, "c": 1}),
                                                 "drain": ({"c": 2}, {"d": 1})})
    doc = report(net)
    assert doc["bounded"] is False and doc["deadlock"] is None
    text = analyze.render(doc)
    assert "ends:               not decided: no dead marking was found" in text
    assert "none: in every reachable marking" not in text


def test_a_long_firing_sequence_shows_its_first_and_last_firings_and_its_length() -> None:
    from analysis_nets import make_net

    # the only dead marking lies 60 firings deep
    net = make_net("chain", {"c0": 1}, {f"s{k}": ({f"c{k}": 1}, {f"c{k + 1}": 1}) for k in range(60)})
    text = analyze.render(report(net))
    first = " ".join(f"s{k}" for k in range(30))
    last = " ".join(f"s{k}" for k in range(50, 60))
    assert f"after: {first} ... (60 firings in all, --json lists them) ... {last}" in text


def test_a_conflict_of_many_transitions_lists_ten_of_them_and_counts_the_rest() -> None:
    from analysis_nets import make_net

    fan = {f"t{i}": ({"p": 1}, {f"q{i}": 1}) for i in range(25)}
    text = analyze.render(report(make_net("fan", {"p": 1}, fan)))
    assert "    p: t0, t1, t2, t3, t4, t5, t6, t7, t8, t9 and 15 more (see --json)" in text


def test_home_states_compared_in_row_blocks_match_a_column_by_column_comparison() -> None:
    import numpy as np
    from analysis_nets import make_net

    from coordinator.analysis.robotic import _home_states
    from coordinator.analysis.statespace import explore

    # five independent one-way moves and a counter: 32 markings with 2 tokens on "c" at most
    net = make_net("moves", {**{f"a{i}": 1 for i in range(5)}, "c": 0},
                   {f"go{i}": ({f"a{i}": 1}, {f"b{i}": 1, **({"c": 1} if i < 2 else {})}) for i in range(5)})
    space = explore(net)
    states = space.states
    for expected in ({"a0": 1, "a1": 1}, {"b3": 1, "c": 2}, {"c": 1}, {"c": 3}, {}):
        want = np.ones(space.n_states, dtype=bool)
        for p, v in expected.items():
            want &= states[:, net.place_index[p]] == v
        for block_bytes in (1, 7, 1 << 24):  # one row a block, blocks that do not divide the rows, one block
            assert _home_states(space, expected, block_bytes=block_bytes).tolist() == want.tolist()
