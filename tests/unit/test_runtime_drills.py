"""Breakpoints, injected external events and forced outcomes (paper section 5): each pauses or
drives the run where the operator asked, is journaled as the operator's, and a forced outcome is
never a measured one (no learner update, left out of ``perf``). No sockets: a fake service client."""

from __future__ import annotations

import asyncio
import json
import sqlite3
from pathlib import Path

import pytest

from coordinator.breakpoints import BreakKind, Breakpoint, parse_breakpoint
from coordinator.cli import main
from coordinator.events import ActionEnded, BreakpointHit, PulseDelivered, RunStateChanged
from coordinator.journal import Journal, JournalReader, OperatorRow, ResultRow
from coordinator.learning import Learner
from coordinator.netfile import loads_net
from coordinator.operator import Command, OperatorCommand, parse_operator_command
from coordinator.runtime import Runtime
from services.results import ActionResult
from tests.unit.runtime_fakes import FakeClient
from tests.unit.test_runtime import TIMEOUT_S, Recorder, waiting

DRILL = """
[net]
name = "drill"
home = { idle = 1 }

[operator]
inject = ["ext:tick"]
force = { work = ["error", "failure.nothing"] }

[[place]]
id = "runs"
kind = "control"
tokens = RUNS

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "working"
task = "work"

[[place]]
id = "done"

[[place]]
id = "failed"

[task.work]
actions = ["act", "other"]
learner = { scheme = "pursuit", warmup = 1, rate = 0.1 }

[[transition]]
id = "start"
events = ["ext:tick"]
inputs = { runs = 1, idle = 1 }
outputs = { working = 1 }

[[transition]]
id = "finished"
events = ["int:work.ok"]
inputs = { working = 1 }
outputs = { idle = 1, done = 1 }

[[transition]]
id = "broke"
events = ["int:work.error"]
hidden = true
inputs = { working = 1 }
outputs = { idle = 1, failed = 1 }
"""


def drill(runs: int = 1):
    return loads_net(DRILL.replace("RUNS", str(runs)))


def operator_rows(path: Path) -> list[OperatorRow]:
    with JournalReader.open(path) as reader:
        return reader.operator_commands()


def test_breakpoints_are_typed_like_commands_and_checked_against_the_net():
    assert parse_breakpoint("count done 2") == Breakpoint(BreakKind.COUNT, "done", 2)
    assert str(parse_operator_command("break fires finished").breakpoint) == "fires finished"
    for bad in ("fire x", "count done", "count done -1", "enabled"):
        with pytest.raises(ValueError):
            parse_breakpoint(bad)


async def test_a_breakpoint_on_a_firing_pauses_the_run_right_after_it_and_is_journaled(tmp_path: Path):
    seen = Recorder()
    client = FakeClient({"act": ActionResult.success(), "other": ActionResult.success()}, topics={"tick"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(drill(runs=3), client, journal, observer=seen, operator=True)
        runtime.command(parse_operator_command("break fires finished"))
        runtime.command(parse_operator_command("break fires nowhere"))  # refused: no such transition
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(waiting)
        client.publish("tick")
        hit = await seen.wait_for(lambda e: isinstance(e, BreakpointHit))
        assert str(hit.breakpoint) == "fires finished" and hit.why == "finished fired"
        await seen.wait_for(lambda e: waiting(e) and e.reason.startswith("paused"))
        assert runtime.engine.paused and runtime.engine.marking["done"] == 1
        runtime.command(OperatorCommand(Command.CLEAR, breakpoint=Breakpoint(BreakKind.FIRES, "finished")))
        runtime.command(OperatorCommand(Command.RESUME))
        runtime.command(OperatorCommand(Command.END))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
    rows = [(r.command, r.accepted, r.detail) for r in operator_rows(tmp_path / "j.sqlite")]
    assert rows[0] == ("break", True, {"breakpoint": {"kind": "fires", "target": "finished", "count": None}})
    assert rows[1][:2] == ("break", False)
    assert rows[2] == ("pause", True, {"breakpoint": {"kind": "fires", "target": "finished", "count": None},
                                       "why": "finished fired"})
    assert [r[0] for r in rows[3:]] == ["clear", "resume", "end"]
    assert summary.final_marking.get("done") == 1 and summary.final_marking.get("runs") == 2


async def test_breakpoints_on_an_enabled_transition_a_place_count_and_a_task_error(tmp_path: Path):
    seen = Recorder()
    client = FakeClient({"other": ActionResult.success()}, blocking={"act"}, topics={"tick"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(drill(runs=2), client, journal, observer=seen, operator=True)
        for text in ("break enabled start", "break error work", "break count failed 1"):
            runtime.command(parse_operator_command(text))
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(waiting)
        assert not runtime.engine.paused  # start was ready when its breakpoint was set: edges only
        client.publish("tick")
        await asyncio.wait_for(client.started.wait(), TIMEOUT_S)
        (call,) = [cid for action, cid in client.calls if action == "act"]
        client.release(call, ActionResult.error("gripper jammed"))
        hit = await seen.wait_for(lambda e: isinstance(e, BreakpointHit))
        assert str(hit.breakpoint) == "error work"
        assert runtime.engine.marking["working"] == 1  # the error is latched; its branch waits
        runtime.command(OperatorCommand(Command.RESUME))
        second = await seen.wait_for(lambda e: isinstance(e, BreakpointHit) and e is not hit)
        # the error branch fired: failed reached 1, and start became ready again, in that firing
        assert str(second.breakpoint) in ("count failed 1", "enabled start")
        runtime.command(OperatorCommand(Command.ABORT))
        await asyncio.wait_for(run, TIMEOUT_S)
    pauses = [r.detail["breakpoint"]["kind"] for r in operator_rows(tmp_path / "j.sqlite") if r.command == "pause"]
    assert pauses[0] == "error"


async def test_an_events_payload_reaches_the_blackboard_from_its_publisher_and_from_the_operator(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    from coordinator.web.frames import LiveFeed

    seen = Recorder()
    client = FakeClient({"act": ActionResult.success(), "other": ActionResult.success()}, topics={"tick"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(drill(runs=2), client, journal, observer=seen, operator=True)
        feed = LiveFeed(runtime)
        runtime.add_observer(feed)
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(waiting)
        client.publish("tick", {"sensor": "crossfire", "beam": [1, 0]})  # a node's event and its data
        published = await seen.wait_for(lambda e: isinstance(e, PulseDelivered))
        assert published.payload == {"sensor": "crossfire", "beam": [1, 0]} and not published.operator
        feed.build_frame()  # the feed takes the events as it builds a frame
        assert feed.blackboard("working")["events"][0]["payload"] == {"sensor": "crossfire", "beam": [1, 0]}
        await seen.wait_for(lambda e: isinstance(e, ActionEnded))
        runtime.command(parse_operator_command('inject ext:tick {"by": "drill"}'))
        injected = await seen.wait_for(lambda e: isinstance(e, PulseDelivered) and e.operator)
        assert injected.payload == {"by": "drill"}
        feed.build_frame()
        (event,) = feed.blackboard("working")["events"]  # the latest of each event
        assert (event["payload"], event["operator"]) == ({"by": "drill"}, True)
        runtime.command(OperatorCommand(Command.ABORT))
        await asyncio.wait_for(run, TIMEOUT_S)
    (row,) = [r for r in operator_rows(tmp_path / "j.sqlite") if r.command == "inject"]
    assert row.detail == {"event": "ext:tick", "payload": {"by": "drill"}}
    assert main(["show", "last", "--journal", str(tmp_path / "j.sqlite")]) == 0
    assert 'inject ext:tick {"by":"drill"}' in capsys.readouterr().out
    with pytest.raises(ValueError, match="not JSON"):
        parse_operator_command("inject ext:tick {nope")


async def test_an_injected_event_is_delivered_as_a_pulse_and_journaled_as_the_operators(tmp_path: Path):
    seen = Recorder()
    client = FakeClient({"act": ActionResult.success(), "other": ActionResult.success()}, topics={"tick"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(drill(runs=1), client, journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(waiting)
        runtime.command(OperatorCommand(Command.INJECT, event="ext:tock"))  # not allowed by [operator]
        runtime.command(OperatorCommand(Command.INJECT, event="ext:tick"))
        pulse = await seen.wait_for(lambda e: isinstance(e, PulseDelivered))
        assert pulse.operator and pulse.fired == 1 and pulse.event == "ext:tick"
        await seen.wait_for(lambda e: isinstance(e, ActionEnded))
        runtime.command(OperatorCommand(Command.END))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
        firings = journal.firings(runtime.run_id)
    rows = operator_rows(tmp_path / "j.sqlite")
    assert (rows[0].command, rows[0].accepted) == ("inject", False) and "does not let the operator" in rows[0].reason
    assert (rows[1].command, rows[1].detail) == ("inject", {"event": "ext:tick"})
    assert firings[0].transition == "start" and firings[0].pulse == "ext:tick" and firings[0].entry > rows[1].entry
    assert summary.end_state == "completed"


async def test_a_forced_error_takes_the_error_branch_and_is_no_measured_result(tmp_path: Path,
                                                                                capsys: pytest.CaptureFixture[str]):
    seen = Recorder()
    client = FakeClient({"other": ActionResult.success()}, blocking={"act"}, topics={"tick"})
    net = drill(runs=1)
    learner = Learner.from_net(net, 0)
    before = learner.automaton("work").probabilities
    path = tmp_path / "j.sqlite"
    with Journal(path) as journal:
        runtime = Runtime(net, client, journal, observer=seen, operator=True, learner=learner)
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(waiting)
        client.publish("tick")
        await asyncio.wait_for(client.started.wait(), TIMEOUT_S)
        (call,) = [cid for action, cid in client.calls]
        runtime.command(OperatorCommand(Command.FORCE, instance=call, outcome="success"))  # not allowed
        runtime.command(OperatorCommand(Command.FORCE, instance="nobody", outcome="error"))  # not running
        runtime.command(OperatorCommand(Command.FORCE, instance=call, outcome="error", reason="drill: camera lost"))
        ended = await seen.wait_for(lambda e: isinstance(e, ActionEnded))
        assert ended.forced and ended.result.reason == "forced by the operator: drill: camera lost"
        await seen.wait_for(lambda e: isinstance(e, RunStateChanged) and e.state == "waiting" or
                            isinstance(e, RunStateChanged) and e.state == "completed")
        runtime.command(OperatorCommand(Command.END))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
        assert client.cancelled == [call]  # the node was told to stop the real action
    assert summary.final_marking.get("failed") == 1  # the error branch fired
    assert learner.automaton("work").probabilities == before  # the learner learned nothing from a drill
    assert summary.actions == {}  # nor do the run's statistics count it
    with JournalReader.open(path) as reader:
        (result,) = reader.results()
        assert isinstance(result, ResultRow) and result.forced and result.status.value == "error"
        assert reader.results(forced=False) == []
        refused = [r.reason for r in reader.operator_commands() if not r.accepted]
    assert "does not let the operator force 'success'" in refused[0] and "no primitive action" in refused[1]
    # perf leaves it out, and says so
    net_file = tmp_path / "drill.toml"
    net_file.write_text(DRILL.replace("RUNS", "1"))
    assert main(["perf", str(net_file), "--journal", str(path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["results"] == 0 and rep["forced_left_out"] == 1
    assert main(["show", summary.run_id, "--journal", str(path)]) == 0
    text = capsys.readouterr().out
    assert "FORCED   work/act on fake: error" in text and "operator force error on" in text


def test_a_journal_of_schema_3_is_migrated_to_the_current_schema_keeping_its_records(tmp_path: Path):
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    db.executescript("""
        CREATE TABLE run (id TEXT PRIMARY KEY, net_name TEXT NOT NULL, net_text TEXT, seed INTEGER,
            started_wall REAL NOT NULL, ended_wall REAL, end_state TEXT, note TEXT);
        CREATE TABLE firing (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, seq INTEGER NOT NULL, transition TEXT NOT NULL,
            consumed TEXT NOT NULL, produced TEXT NOT NULL, instances TEXT NOT NULL, pulse TEXT, t_wall REAL NOT NULL);
        CREATE TABLE action_start (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL,
            task TEXT NOT NULL, place TEXT NOT NULL, action TEXT NOT NULL, node TEXT, params TEXT, t_wall REAL NOT NULL);
        CREATE TABLE action_result (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL,
            task TEXT NOT NULL, action TEXT NOT NULL, node TEXT, status TEXT NOT NULL, outcome TEXT, cost REAL,
            wall_s REAL, cpu_s REAL, t_wall REAL NOT NULL, reason TEXT, value TEXT);
        CREATE TABLE operator (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, command TEXT NOT NULL, place TEXT,
            count INTEGER, t_wall REAL NOT NULL, accepted INTEGER NOT NULL DEFAULT 1, reason TEXT);
        CREATE TABLE reconciliation (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL,
            task TEXT NOT NULL, action TEXT NOT NULL, node TEXT, assumed TEXT, status TEXT, outcome TEXT, reason TEXT,
            cost REAL, wall_s REAL, cpu_s REAL, value TEXT, t_wall REAL NOT NULL);
        CREATE TABLE learner_state (task TEXT PRIMARY KEY, scheme TEXT, state TEXT NOT NULL, updated_wall REAL NOT NULL);
        INSERT INTO run VALUES ('r1', 'drill', NULL, 0, 1.0, 2.0, 'completed', '');
        INSERT INTO action_result VALUES (1, 'r1', 'r1-1', 'work', 'act', 'fake', 'success', NULL, NULL, 0.1, 0.1,
            1.5, NULL, NULL);
        INSERT INTO operator VALUES (2, 'r1', 'pause', NULL, NULL, 1.6, 1, NULL);
        PRAGMA user_version = 3;
    """)
    db.close()
    with JournalReader.open(path) as reader:  # read-only: the old columns are enough
        assert [r.forced for r in reader.results()] == [False]
        assert [r.detail for r in reader.operator_commands()] == [None]
    with Journal(path) as journal:
        journal.operator("r1", "inject", detail={"event": "ext:tick"})
        assert [r.detail for r in journal.operator_commands()] == [None, {"event": "ext:tick"}]
        assert [r.forced for r in journal.results()] == [False]
    db = sqlite3.connect(path)
    assert db.execute("PRAGMA user_version").fetchone()[0] == 5
    db.close()


async def test_breakpoints_set_before_an_interruption_are_re_armed_when_the_run_is_resumed(tmp_path: Path):
    path = tmp_path / "j.sqlite"
    net = drill(runs=2)
    client = FakeClient({"act": ActionResult.success(), "other": ActionResult.success()}, topics={"tick"})
    with Journal(path) as journal:
        first = Recorder()
        runtime = Runtime(net, client, journal, observer=first, operator=True)
        for line in ("break fires finished", "break error work", "break count done 2", "clear error work"):
            runtime.command(parse_operator_command(line))
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await first.wait_for(waiting)
        run.cancel()  # Ctrl-C
        with pytest.raises(asyncio.CancelledError):
            await run
    with Journal(path) as journal:
        recovered = journal.recover(net, runtime.run_id)
        assert [str(bp) for bp in recovered.breakpoints] == ["fires finished", "count done 2"]
        seen = Recorder()
        again = Runtime(net, client, journal, observer=seen, operator=True, recovered=recovered)
        assert [str(bp) for bp in again.breakpoints.breakpoints] == ["fires finished", "count done 2"]
        run = asyncio.create_task(again.run(max_seconds=TIMEOUT_S))
        resumed = await seen.wait_for(lambda e: isinstance(e, RunStateChanged) and e.state == "resumed")
        assert resumed.reason == "breakpoints re-armed from the journal: fires finished, count done 2"
        await seen.wait_for(waiting)
        client.publish("tick")
        hit = await seen.wait_for(lambda e: isinstance(e, BreakpointHit))
        assert str(hit.breakpoint) == "fires finished"  # the resumed run pauses where the operator asked
        again.command(OperatorCommand(Command.ABORT))
        await asyncio.wait_for(run, TIMEOUT_S)


def test_a_break_command_whose_breakpoint_is_damaged_refuses_the_resume(tmp_path: Path):
    from coordinator.errors import DamagedJournal

    path = tmp_path / "j.sqlite"
    net = drill()
    with Journal(path) as journal:
        run = journal.begin_run(net)
        journal.operator(run, "break", detail={"breakpoint": {"kind": "fires", "target": "nowhere", "count": None}})
        journal.end_run(run, "interrupted")
        with pytest.raises(DamagedJournal, match="break fires nowhere: no transition 'nowhere'"):
            journal.recover(net, run)
