"""The fault campaign, a few rounds of each scenario: real node processes and real `petrobot run`
processes, a fault at a random moment inside a call (bench/faults.py), then the journal is compared
with the nodes' own result stores and logs.

In every round: the journal agrees with the nodes on every call (its final status on the node is
the journal's last word on it, or no node ran it), no node started a call twice, the run ended,
and the call the fault hit took the net's error branch (node faults) or was re-issued under its id
(coordinator faults: the resumed run completes). Every wait is on an event (a log line, a process
exit, a journal row), bounded by a generous timeout.
"""

from __future__ import annotations

import importlib.util
import random
import sys
from pathlib import Path
from types import ModuleType

import pytest

from coordinator.journal import JournalReader

pytestmark = [pytest.mark.integration, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parents[2]
CALL_S = 2.0  # each call of the targeted actions lasts this long; the fault comes 0.05-0.7 s into it


def _faults() -> ModuleType:
    spec = importlib.util.spec_from_file_location("petrobot_bench_faults", ROOT / "bench" / "faults.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


faults = _faults()


def rounds(scenario: str, tmp_path: Path, seed: int) -> list:
    """Two rounds: the fault hits an ordinary action (``slow``), then an unattended one (``move``)."""
    rng = random.Random(seed)
    done = []
    for i, action in enumerate(("slow", "move")):
        got = faults.run_round(scenario, tmp_path / f"round-{i}", rng, action=action, call_s=CALL_S)
        assert got.target, got
        assert got.end_state == "completed", got
        assert got.disagreements == [] and got.twice == [], got
        assert not got.notes, got
        done.append(got)
    return done


def unreconciled(workdir: Path) -> str:
    with JournalReader.open(workdir / "journal.sqlite") as reader:
        return reader.runs()[-1].note or ""


def test_a_node_killed_inside_a_call_and_started_again_leaves_journal_and_node_agreeing(tmp_path: Path):
    for i, got in enumerate(rounds("node-sigkill", tmp_path, seed=1)):
        assert got.error_branch or not got.inside, got
        assert got.exit_code == 0, got
        # the call died with its node: reconciled as node_restarted once the node is back, or named.
        # On a loaded machine another call may be given up on too (its heartbeats late, on a node
        # not killed): it ran to its end there and is reconciled with that success, so the target's
        # reconciliation is looked up by its call id
        with JournalReader.open(tmp_path / f"round-{i}" / "journal.sqlite") as reader:
            recs = {r.instance: r for r in reader.reconciliations()}
        assert len(recs) == got.reconciled, recs
        assert got.target in recs or "not reconciled" in unreconciled(tmp_path / f"round-{i}"), got
        for instance, rec in recs.items():
            if instance != got.target:
                assert (rec.assumed, rec.status) == ("error", "success"), rec


def test_a_node_frozen_inside_a_call_then_thawed_leaves_journal_and_node_agreeing(tmp_path: Path):
    slow, move = rounds("node-sigstop", tmp_path, seed=2)
    for got in (slow, move):
        assert got.error_branch or not got.inside, got
        assert got.exit_code == 0, got
    assert move.inside, move  # the call lasts CALL_S: the freeze came while it ran
    # the unattended move ran to its end on the node after the coordinator declared it lost: the
    # journal says so (a reconciliation with the node's success) and so does the console. On a
    # loaded machine another call may be given up on too (its heartbeats late, not the freeze's):
    # it is reconciled the same way, so the target's reconciliation is looked up by its call id
    assert move.reconciled >= 1 and move.differed >= 1, move
    out = (tmp_path / "round-1" / "run-1.out").read_text()
    assert "node beta finished move with success after the coordinator declared it lost" in out
    with JournalReader.open(tmp_path / "round-1" / "journal.sqlite") as reader:
        recs = {r.instance: r for r in reader.reconciliations()}
    assert len(recs) == move.reconciled, recs
    rec = recs[move.target]
    assert (rec.assumed, rec.status) == ("error", "success")


def test_a_node_restarted_inside_a_call_leaves_journal_and_node_agreeing(tmp_path: Path):
    for got in rounds("node-restart", tmp_path, seed=3):
        assert got.error_branch or not got.inside, got  # the node ended it: "node shutdown"
        assert got.exit_code == 0, got
        assert got.reconciled == 0, got  # the node said so itself: nothing was given up on


def test_a_coordinator_killed_inside_a_call_resumes_and_never_runs_a_call_twice(tmp_path: Path):
    for got in rounds("coordinator-sigkill", tmp_path, seed=4):
        assert got.resumed_completed, got


def test_a_coordinator_interrupted_inside_a_call_resumes_and_never_runs_a_call_twice(tmp_path: Path):
    for got in rounds("coordinator-sigint", tmp_path, seed=5):
        assert got.resumed_completed, got
        assert got.error_branch or not got.inside, got  # Ctrl-C cancelled the call on its node


def test_the_comparison_finds_a_journal_that_disagrees_with_a_node_and_a_call_run_twice(tmp_path: Path):
    got = faults.run_round("node-sigstop", tmp_path / "round", random.Random(6), action="move", call_s=CALL_S)
    # the frozen move, and on a loaded machine now and then a call before it whose heartbeats came
    # late: each ran to its end on the node after the coordinator gave up on it, and was reconciled
    assert got.disagreements == [] and got.differed >= 1, got
    workdir = tmp_path / "round"
    nodes = {n: (workdir / "state" / n, (workdir / f"{n}.log").read_text()) for n in ("alpha", "beta")}
    import sqlite3

    with sqlite3.connect(workdir / "journal.sqlite") as db:  # forget what the node said afterwards
        db.execute("DELETE FROM reconciliation")
    agreement = faults.check(workdir / "journal.sqlite", nodes)
    assert len(agreement.disagreements) == got.differed, agreement
    (line,) = [d for d in agreement.disagreements if d.startswith(f"{got.target} ")]
    assert line.startswith(f"{got.target} move: the journal says error (heartbeat timeout), node beta says success")
    alpha_state, alpha_log = nodes["alpha"]
    started = next(line for line in alpha_log.splitlines() if " call " in line and " echo from " in line)
    nodes["alpha"] = (alpha_state, alpha_log + "\n" + started + "\n")
    (twice,) = faults.check(workdir / "journal.sqlite", nodes).twice
    assert twice.startswith("node alpha started ") and twice.endswith(" 2 times")
