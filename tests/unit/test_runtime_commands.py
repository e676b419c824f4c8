"""`petrobot runs` and `petrobot show` read what the runtime journaled, reasons included (no sockets)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from coordinator.cli import main
from coordinator.journal import Journal
from coordinator.operator import Command, OperatorCommand
from coordinator.runtime import Runtime
from services.results import ActionResult
from tests.unit.runtime_fakes import FakeClient
from tests.unit.test_runtime import tasks


def journal_of_two_runs(path: Path) -> tuple[str, str]:
    async def go() -> tuple[str, str]:
        with Journal(path) as journal:
            faulty = FakeClient({"act": ActionResult.error("drive 1 is in FAULT (following error)")})
            first = Runtime(tasks(runs=2), faulty, journal)
            first.command(OperatorCommand(Command.INSERT, "working", 1))  # refused: not a control place
            await first.run()
            second = Runtime(tasks(runs=1), FakeClient({"act": ActionResult.success()}), journal)
            await second.run()
            return first.run_id, second.run_id
    return asyncio.run(go())


def test_runs_lists_each_run_with_its_outcome_and_counts(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    path = tmp_path / "j.sqlite"
    first, second = journal_of_two_runs(path)
    assert main(["runs", "--journal", str(path), "--json"]) == 0
    rows = {r["run"]: r for r in json.loads(capsys.readouterr().out)}
    assert (rows[first]["end_state"], rows[first]["calls"], rows[first]["errors"], rows[first]["refused"]) == (
        "completed", 2, 2, 1)
    assert (rows[second]["end_state"], rows[second]["calls"], rows[second]["errors"]) == ("completed", 1, 0)
    assert main(["runs", "--journal", str(path)]) == 0
    text = capsys.readouterr().out
    assert first in text and "completed" in text and "1[1]" in text


def test_show_gives_a_run_in_order_with_the_reasons_of_its_errors(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]):
    path = tmp_path / "j.sqlite"
    first, _ = journal_of_two_runs(path)
    assert main(["show", first[:6], "--journal", str(path)]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert lines[0].startswith(f"run {first} of net 'tasks'") and "completed after" in lines[0]
    body = [line.split("s  ", 1)[1] for line in lines if "s  " in line and line.strip()[0].isdigit()]
    assert body[0].startswith("operator insert working 1 REFUSED: place 'working' is not a control place")
    assert body[1].startswith("fire     #1     start   robot, runs -> working")
    assert body[2].startswith("start    work -> act on fake")
    assert body[3].startswith("result   work/act on fake: error in 0.000 s: drive 1 is in FAULT (following error)")
    assert "    2 x work/act: drive 1 is in FAULT (following error)" in text
    assert main(["show", first, "--journal", str(path), "--no-firings", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert {r["kind"] for r in rep["records"]} == {"operator", "start", "result"}
    assert rep["error_reasons"] == {"work/act: drive 1 is in FAULT (following error)": 2}


def test_show_names_what_is_wrong_with_an_unknown_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    path = tmp_path / "j.sqlite"
    journal_of_two_runs(path)
    assert main(["show", "zzz", "--journal", str(path)]) == 1
    assert "no run 'zzz'" in capsys.readouterr().err
    assert main(["show", "", "--journal", str(path)]) == 1
    assert "names 2 runs" in capsys.readouterr().err


def test_show_and_runs_tell_what_a_node_said_about_a_call_the_run_had_given_up_on(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    from tests.unit.test_runtime_reconcile import RAN, AskableClient

    path = tmp_path / "j.sqlite"

    async def go() -> str:
        with Journal(path) as journal:
            client = AskableClient({"act": ActionResult.error("heartbeat timeout")})
            runtime = Runtime(tasks(), client, journal)
            client.truth[f"{runtime.run_id}-1"] = RAN
            await runtime.run()
            return runtime.run_id

    run = asyncio.run(go())
    assert main(["show", run, "--journal", str(path), "--no-firings"]) == 0
    text = capsys.readouterr().out
    assert "1 call given up on reconciled with its node; 1 ended otherwise than the net assumed" in text
    assert (f"reconcile DIFFERS  work/act: node fake finished act with success after the coordinator declared it "
            f"lost [{run}-1]") in text
    assert main(["show", run, "--journal", str(path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    (rec,) = [r for r in rep["records"] if r["kind"] == "reconciliation"]
    assert (rec["assumed"], rec["status"], rep["reconciled"], rep["differed"]) == ("error", "success", 1, 1)
    assert main(["runs", "--journal", str(path), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert (row["reconciled"], row["differed"]) == (1, 1)
    assert main(["runs", "--journal", str(path)]) == 0
    assert "[1 reconciled differently] at the home marking" in capsys.readouterr().out
