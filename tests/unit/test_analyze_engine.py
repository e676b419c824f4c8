"""``petrobot analyze`` picks the explicit or the symbolic engine, says which and why, and the two agree."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from coordinator.analysis import structure
from coordinator.analysis.budget import cpus
from coordinator.cli import main
from coordinator.netfile.pnml import load_pnml
from tests.unit.mcc_models import MCC, ROOT

SCALE = ROOT / "tests" / "data" / "mcc-scale"

SHARED_MEMORY = str(MCC / "SharedMemory-PT-000005" / "model.pnml")
KANBAN = str(MCC / "Kanban-PT-00005" / "model.pnml")


def run_json(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    assert main(["analyze", "--json", *args]) == 0
    out = json.loads(capsys.readouterr().out)
    assert isinstance(out, dict)
    return out


def test_importing_the_cli_and_the_analysis_imports_neither_numba_nor_a_decision_diagram_library() -> None:
    code = ("import sys, coordinator.cli, coordinator.commands.analyze, coordinator.analysis.structure, "
            "coordinator.analysis.robotic; "
            "print(sorted(m for m in ('numba', 'oxidd', 'dd', 'coordinator.analysis.mdd_kernel', "
            "'coordinator.analysis.symbolic') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_beyond_the_explicit_share_the_symbolic_engine_takes_over_and_agrees_with_the_explicit_one(
        capsys: pytest.CaptureFixture[str]) -> None:
    explicit = run_json([SHARED_MEMORY, "--engine", "explicit"], capsys)
    auto = run_json([SHARED_MEMORY, "--max-states", "100"], capsys)
    assert explicit["engine"]["used"] == "explicit"  # type: ignore[index]
    assert auto["engine"]["used"] == "symbolic"  # type: ignore[index]
    assert "stopped at 100 markings" in auto["engine"]["reason"]  # type: ignore[index]
    for key in ("states", "edges", "bounded", "place_bounds", "max_token_in_place", "max_token_per_marking",
                "one_safe", "deadlock", "n_deadlocks", "quasi_live", "live", "reversible", "stable_places",
                "conservative", "consistent"):
        assert auto[key] == explicit[key], key
    assert auto["complete"] is True and auto["truncated"] is None


def test_a_small_net_stays_explicit_and_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    rep = run_json([SHARED_MEMORY], capsys)
    assert rep["engine"]["used"] == "explicit"  # type: ignore[index]
    assert "complete with 1,863 markings" in rep["engine"]["reason"]  # type: ignore[index]


def no_search_left_running() -> bool:
    return not any(t.name == "petrobot-explicit" for t in threading.enumerate())


def test_beside_the_symbolic_engine_the_search_goes_on_and_whichever_completes_first_answers(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(structure, "AUTO_PROBE_STATES", 100)  # the explicit share: 100 markings
    phases: list[str] = []
    # 2,546,432 markings: the search is still going when it passes its share (a graph it completes
    # before the wait for the share returns is the answer, and no race starts)
    a = structure.analyse(load_pnml(KANBAN), engine="auto", phase=phases.append)
    assert (a.complete, a.states, a.edges, a.deadlock) == (True, 2_546_432, 24_460_016, False)
    assert no_search_left_running()
    if cpus() >= 2:
        assert any(p.startswith("explicit: the search goes on beside the symbolic engine") for p in phases)
        # whichever answered, the report says which
        assert a.engine == "symbolic" or "beside the symbolic engine" in a.engine_reason


@pytest.mark.skipif(not sys.platform.startswith("linux"),
                    reason="only Linux gives a thread a scheduling priority of its own; elsewhere _yield_cpus does nothing")
def test_the_search_beside_the_symbolic_engine_lowers_its_own_thread_priority_only() -> None:
    seen: dict[str, int] = {}

    def beside() -> None:
        structure._yield_cpus()
        seen["thread"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    thread = threading.Thread(target=beside)
    thread.start()
    thread.join()
    assert seen["thread"] == min(19, before + structure._BESIDE_NICE)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == before  # the caller's is its own


def test_the_search_beside_starts_first_and_waits_only_for_its_share_of_markings() -> None:
    net = structure.ordinary_view(load_pnml(KANBAN))
    sn = structure.sparse_net(net)
    st = structure._structure_phase(net, sn, 1 << 30, 20_000, 5.0, 10.0)
    reports: list[int] = []
    # a share of 100 markings: the search is still going when it has passed them (up to 500,000)
    b = structure._Beside(net, sn, st, 500_000, 1 << 29, 100, lambda n, _e: reports.append(n), None)
    assert b.wait_share() is True
    assert reports and reports[-1] >= 100
    b.end(stop=False)  # the symbolic engine gave up: the search goes on to its limits
    assert b.found is not None and b.found[0].stopped_by == "max_states" and b.found[0].n_states >= 500_000
    assert reports == sorted(reports)  # one search: its count never starts again
    # a share the graph fits in: the search has ended when the wait returns, its graph complete
    net = structure.ordinary_view(load_pnml(SHARED_MEMORY))
    sn = structure.sparse_net(net)
    st = structure._structure_phase(net, sn, 1 << 30, 20_000, 5.0, 10.0)
    small = structure._Beside(net, sn, st, 1_000_000, 1 << 29, 10_000, None, None)
    assert small.wait_share() is False
    assert small.found is not None and small.found[0].complete and small.finished.is_set()
    assert no_search_left_running()


def test_the_search_beside_ends_its_share_after_its_time_too(monkeypatch: pytest.MonkeyPatch) -> None:
    # a net of many transitions is searched slowly: the share also ends after AUTO_PROBE_SECONDS
    # (here none), and the symbolic engine starts while the search goes on
    monkeypatch.setattr(structure, "AUTO_PROBE_SECONDS", 0.0)
    net = structure.ordinary_view(load_pnml(KANBAN))  # 2,546,432 markings
    sn = structure.sparse_net(net)
    st = structure._structure_phase(net, sn, 1 << 30, 20_000, 5.0, 10.0)
    b = structure._Beside(net, sn, st, 2_000_000, 1 << 29, 1_000_000_000, None, None)
    assert b.wait_share() is True and b.timed_out
    b.end(stop=True)
    assert no_search_left_running()
    a = structure.analyse(load_pnml(KANBAN), engine="auto")
    if cpus() >= 2:
        assert "ran its 0 s share before finding 1,000,000 markings" in a.engine_reason or a.engine == "explicit"
    assert (a.complete, a.states) == (True, 2_546_432)


def test_a_lane_that_shows_more_markings_reachable_than_the_search_may_find_stops_the_search_beside() -> None:
    net = structure.ordinary_view(load_pnml(KANBAN))  # 2,546,432 markings
    sn = structure.sparse_net(net)
    st = structure._structure_phase(net, sn, 1 << 30, 20_000, 5.0, 10.0)
    said: list[str] = []
    b = structure._Beside(net, sn, st, 2_000_000, 1 << 29, 100, None, said.append)
    assert b.wait_share() is True
    b.rival.beyond(2_000_000, "order 2")  # not more than the search's limit: it goes on
    assert not b.rival.settled.is_set()
    b.rival.beyond(2.5e6, "order 2")
    b.rival.beyond(3e6, "order 3")  # once
    b.end(stop=False)  # the search had been stopped: its graph, cut short, was dropped
    assert b.found is None and not b.finished.is_set()
    assert no_search_left_running()
    assert [line for line in said if "beyond" in line or "holds" in line] == [
        "symbolic: order 2 holds 2,500,000 reachable markings already, more than the explicit search's limit "
        "of 2,000,000: the search beside is stopped"]


def test_when_the_symbolic_engine_answers_first_the_search_beside_it_is_stopped(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(structure, "AUTO_PROBE_STATES", 1_000)
    net = load_pnml(SCALE / "Eratosthenes-PT-050" / "model.pnml")  # 17,179,869,184 markings: 2 s symbolic
    a = structure.analyse(net, engine="auto", max_states=100_000_000)
    assert a.engine == "symbolic" and a.states == 17_179_869_184
    assert no_search_left_running()


def test_forcing_the_symbolic_engine_gives_a_deadlock_with_its_firing_sequence(
        capsys: pytest.CaptureFixture[str]) -> None:
    rep = run_json([str(MCC / "Philosophers-PT-000005" / "model.pnml"), "--engine", "symbolic"], capsys)
    assert rep["engine"]["used"] == "symbolic" and "asked for" in rep["engine"]["reason"]  # type: ignore[index]
    assert (rep["states"], rep["edges"], rep["deadlock"], rep["n_deadlocks"]) == (243, 945, True, 2)
    assert len(rep["deadlocks"][0]["firing_sequence"]) == 5  # type: ignore[index]
    assert main(["analyze", str(MCC / "Philosophers-PT-000005" / "model.pnml"), "--engine", "symbolic"]) == 0
    text = capsys.readouterr().out
    assert "reachable set (symbolic): 243 markings" in text and "engine: symbolic" in text


def test_a_net_the_state_equation_does_not_bound_goes_symbolic_and_a_closed_reachable_set_shows_it_bounded(
        monkeypatch: pytest.MonkeyPatch) -> None:
    net = load_pnml(MCC / "Murphy-PT-D1N010" / "model.pnml")  # p3_1 ... p5_3: no proven bound
    explicit = structure.analyse(net)
    symbolic = structure.analyse(net, engine="symbolic")
    assert symbolic.engine == "symbolic"
    assert any("closed under firing: the net is bounded" in n for n in symbolic.notes)
    assert (symbolic.states, symbolic.edges, symbolic.bounded, symbolic.place_bounds) == (
        39_780, 267_984, True, explicit.place_bounds)
    for key in ("max_token_in_place", "max_token_per_marking", "deadlock", "quasi_live", "live", "one_safe",
                "stable_marking", "reversible"):
        assert getattr(symbolic, key) == getattr(explicit, key), key
    monkeypatch.setattr(structure, "AUTO_PROBE_STATES", 1_000)  # the explicit share: 1,000 markings
    auto = structure.analyse(net, engine="auto")
    assert (auto.states, auto.complete, auto.bounded) == (39_780, True, True)
    # on two CPUs the search goes on beside the symbolic engine, and whichever completes first answers
    assert "no pumping witness" in auto.engine_reason or "beside the symbolic engine" in auto.engine_reason
    assert no_search_left_running()


def test_forcing_the_symbolic_engine_on_an_unbounded_net_is_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "pump.toml"
    path.write_text('[net]\nname = "pump"\nformat = 1\n[[place]]\nid = "go"\ntokens = 1\n[[place]]\nid = "out"\n'
                    '[[transition]]\nid = "t"\ninputs = { go = 1 }\noutputs = { go = 1, out = 1 }\n',
                    encoding="utf-8")
    assert main(["analyze", str(path), "--engine", "symbolic"]) == 1
    assert "symbolic engine needs a bounded net" in capsys.readouterr().err
