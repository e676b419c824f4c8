"""The runtime serves the operator and the deadline between firings, waits when it should and says
why, and ends in a state that tells the truth (no sockets: a fake service client)."""

from __future__ import annotations

import asyncio
import os
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from coordinator.console import read_operator_commands
from coordinator.events import OperatorRefused, RunEvent, RunStateChanged, TransitionFired
from coordinator.journal import FiringRow, Journal, JournalReader, OperatorRow
from coordinator.netfile import loads_net
from coordinator.operator import Command, OperatorCommand
from coordinator.runtime import Runtime
from services.results import ActionResult, Status
from tests.unit.runtime_fakes import FakeClient

TIMEOUT_S = 60.0  # generous bound of every wait: a failing test fails, a slow machine passes

CYCLE = """
[net]
name = "cycle"

[[place]]
id = "a"
tokens = 1

[[place]]
id = "b"

[[transition]]
id = "there"
inputs = { a = 1 }
outputs = { b = 1 }

[[transition]]
id = "back"
inputs = { b = 1 }
outputs = { a = 1 }
"""

GATED = """
[net]
name = "gated"

[[place]]
id = "runs"
kind = "control"
tokens = 1

[[place]]
id = "gate"
kind = "control"
tokens = GATE

[[place]]
id = "hold"
kind = "control"
tokens = HOLD

[[place]]
id = "ready"
kind = "resource"
tokens = 1

[[place]]
id = "mid"

[[place]]
id = "done"

[[transition]]
id = "go"
inputs = { runs = 1, ready = 1 }
outputs = { mid = 1 }

[[transition]]
id = "finish"
inputs = { mid = 1, gate = 1 }
inhibitors = { hold = 1 }
outputs = { ready = 1, done = 1 }
"""

TASKS = """
[net]
name = "tasks"

[[place]]
id = "runs"
kind = "control"
tokens = RUNS

[[place]]
id = "robot"
kind = "resource"
tokens = 1

[[place]]
id = "working"
kind = "primitive_task"
task = "work"

[[place]]
id = "done"

[task.work]
actions = ["ACTION"]

[[transition]]
id = "start"
inputs = { runs = 1, robot = 1 }
outputs = { working = 1 }

[[transition]]
id = "worked"
events = ["int:work.ok"]
inputs = { working = 1 }
outputs = { robot = 1, done = 1 }
"""

ERROR_EXIT = """
[[transition]]
id = "recover"
events = ["int:work.error"]
hidden = true
inputs = { working = 1 }
outputs = { robot = 1, done = 1 }
"""

TICKS = """
[net]
name = "ticks"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "armed"

[[place]]
id = "shots"

[[transition]]
id = "arm"
inputs = { runs = 1 }
outputs = { armed = 1 }

[[transition]]
id = "shoot"
events = ["ext:tick"]
inputs = { armed = 1 }
outputs = { shots = 1 }
"""


def gated(gate: int = 0, hold: int = 0):
    return loads_net(GATED.replace("GATE", str(gate)).replace("HOLD", str(hold)))


def tasks(action: str = "act", runs: int = 1, error_exit: bool = True):
    text = TASKS.replace("ACTION", action).replace("RUNS", str(runs)) + (ERROR_EXIT if error_exit else "")
    return loads_net(text, interpreted=error_exit)  # a net without error exit breaks a rule of net files


class Recorder:
    """An observer that keeps the events and lets a test wait for one."""

    def __init__(self) -> None:
        self.events: list[RunEvent] = []
        self._waiters: list[tuple[Any, asyncio.Future[RunEvent]]] = []

    def __call__(self, event: RunEvent) -> None:
        self.events.append(event)
        for pred, future in list(self._waiters):
            if not future.done() and pred(event):
                future.set_result(event)

    async def wait_for(self, pred: Any) -> RunEvent:
        for event in self.events:
            if pred(event):
                return event
        future: asyncio.Future[RunEvent] = asyncio.get_running_loop().create_future()
        self._waiters.append((pred, future))
        return await asyncio.wait_for(future, TIMEOUT_S)

    def states(self) -> list[str]:
        return [e.state for e in self.events if isinstance(e, RunStateChanged)]


def waiting(event: RunEvent) -> bool:
    return isinstance(event, RunStateChanged) and event.state == "waiting"


def operator_rows(path: Path) -> list[OperatorRow]:
    with JournalReader.open(path) as reader:
        return reader.operator_commands()


# ---------------------------------------------------------------------- deadline, pause, abort
async def test_a_net_cycling_without_events_ends_at_its_deadline(tmp_path: Path, record_property: Any):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        t0 = time.monotonic()
        summary = await asyncio.wait_for(runtime.run(max_seconds=0.5), TIMEOUT_S)
        late = time.monotonic() - t0 - 0.5
        row = journal.run(runtime.run_id)
    record_property("deadline_late_s", round(late, 4))  # measured, not asserted (a loaded machine)
    assert summary.end_state == "deadline" and summary.exit_code == 4
    assert summary.firings > 0
    assert row.end_state == "deadline" and "--max-seconds 0.5" in (row.note or "")


async def test_pause_during_a_cycle_is_journaled_and_takes_effect_before_the_next_firing(tmp_path: Path):
    seen = Recorder()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        await seen.wait_for(lambda e: isinstance(e, TransitionFired) and e.firing.seq >= 200)
        fired_when_sent = runtime.engine.fired
        runtime.command(OperatorCommand(Command.PAUSE))
        await seen.wait_for(lambda e: isinstance(e, RunStateChanged) and e.state == "paused")
        await seen.wait_for(waiting)
        assert runtime.engine.fired == fired_when_sent
        runtime.command(OperatorCommand(Command.STEP))
        runtime.command(OperatorCommand(Command.ABORT))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
        timeline = journal.timeline(runtime.run_id)
    assert summary.end_state == "aborted" and summary.exit_code == 5
    kinds = [r.command if isinstance(r, OperatorRow) else r.seq for r in timeline if
             isinstance(r, (OperatorRow, FiringRow))]
    pause = kinds.index("pause")
    assert kinds[pause - 1] == fired_when_sent  # the pause came right after the firing it followed
    assert kinds[pause:] == ["pause", "step", fired_when_sent + 1, "abort"]  # then only the step fired


async def test_a_pause_typed_on_standard_input_stops_a_cycling_net(tmp_path: Path):
    seen = Recorder()
    read_fd, write_fd = os.pipe()
    with Journal(tmp_path / "j.sqlite") as journal, os.fdopen(read_fd) as typed, os.fdopen(write_fd, "w") as keys:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        read_operator_commands(runtime, typed, on_error=lambda text, reason: None)
        await seen.wait_for(lambda e: isinstance(e, TransitionFired) and e.firing.seq >= 100)
        await asyncio.to_thread(lambda: (keys.write("pause\n"), keys.flush()))
        await seen.wait_for(waiting)
        paused_at = runtime.engine.fired
        await asyncio.to_thread(lambda: (keys.write("abort\n"), keys.flush()))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
        firings = journal.firings(runtime.run_id)
    assert summary.end_state == "aborted"
    assert [(c.command, c.accepted) for c in operator_rows(tmp_path / "j.sqlite")] == [("pause", True), ("abort", True)]
    assert firings[-1].seq == paused_at == summary.firings


async def test_abort_cancels_the_running_actions_and_ends_the_run(tmp_path: Path):
    client = FakeClient(blocking={"act"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(), client, journal)
        run = asyncio.create_task(runtime.run())
        await asyncio.wait_for(client.started.wait(), TIMEOUT_S)
        runtime.command(OperatorCommand(Command.ABORT))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
        (result,) = journal.results(runtime.run_id)
    assert summary.end_state == "aborted" and client.cancelled == [client.calls[0][1]]
    assert result.status == "error" and "cancelled" in (result.reason or "")


async def test_feedback_of_a_running_action_reaches_the_observers_as_events(tmp_path: Path):
    from coordinator.events import ActionEnded, ActionFeedback

    client = FakeClient({"act": ActionResult.success()}, feedback={"act": [{"progress": 0.5}, {"progress": 1.0}]})
    seen: list[RunEvent] = []
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(), client, journal, observer=seen.append)
        await asyncio.wait_for(runtime.run(max_seconds=30), TIMEOUT_S)
    feedback = [e for e in seen if isinstance(e, ActionFeedback)]
    assert [e.data for e in feedback][:2] == [{"progress": 0.5}, {"progress": 1.0}]
    assert feedback[0].task and feedback[0].action == "act"
    ended = next(i for i, e in enumerate(seen) if isinstance(e, ActionEnded))
    assert seen.index(feedback[0]) < ended


async def test_a_burst_of_feedback_journals_its_first_and_its_last_message_before_the_result(tmp_path: Path):
    burst = [{"progress": i / 499} for i in range(500)]  # a 500 Hz stream's second, at once
    client = FakeClient({"act": ActionResult.success()}, feedback={"act": burst})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(), client, journal)
        await asyncio.wait_for(runtime.run(max_seconds=30), TIMEOUT_S)
        kept = journal.feedback_messages(runtime.run_id)
        (result,) = journal.results(runtime.run_id)
    assert [f.data for f in kept] == [burst[0], burst[-1]]
    assert kept[-1].entry < result.entry and kept[0].instance == result.instance and kept[0].action == "act"


def test_the_feedback_sampler_keeps_at_most_its_rate_per_call_and_always_the_last():
    from coordinator.feedback import FeedbackSampler

    sampler: FeedbackSampler[int] = FeedbackSampler(per_s=10)
    kept = [i for i in range(1000) if sampler.offer("a", i / 500, i) is not None]  # 500 Hz for 2 s
    other = sampler.offer("b", 0.001, -1)  # another call has a rate of its own
    assert 20 <= len(kept) <= 21 and kept[0] == 0 and other == -1
    assert sampler.finish("a") == 999 and sampler.finish("a") is None and len(sampler) == 1
    with pytest.raises(ValueError):
        FeedbackSampler(per_s=0)


# ---------------------------------------------------------------------- waiting and coming to rest
@pytest.mark.parametrize("gate, hold, command", [
    (0, 0, OperatorCommand(Command.INSERT, "gate", 1)),
    (1, 1, OperatorCommand(Command.REMOVE, "hold", 1)),
])
async def test_a_run_waiting_on_a_control_place_stays_alive_until_the_operator_moves_it(
        tmp_path: Path, gate: int, hold: int, command: OperatorCommand):
    seen = Recorder()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(gated(gate, hold), FakeClient(), journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run())
        event = await seen.wait_for(waiting)
        assert not run.done()
        assert "waiting for the operator" in event.reason
        assert f"{'+ gate 1' if hold == 0 else '- hold 1'} would enable finish" in event.reason
        runtime.command(command)
        summary = await asyncio.wait_for(run, TIMEOUT_S)
    assert summary.end_state == "completed" and summary.exit_code == 0
    assert summary.final_marking == {"ready": 1, "done": 1}


async def test_a_run_waiting_on_a_control_place_ends_on_abort(tmp_path: Path):
    seen = Recorder()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(gated(), FakeClient(), journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run())
        await seen.wait_for(waiting)
        runtime.command(OperatorCommand(Command.ABORT))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
    assert summary.end_state == "aborted" and summary.exit_code == 5


async def test_without_an_operator_a_run_that_only_the_operator_could_move_ends_at_once(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(gated(), FakeClient(), journal)
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
        row = journal.run(runtime.run_id)
    assert summary.end_state == "waiting_for_operator" and summary.exit_code == 3
    assert "+ gate 1 would enable finish" in summary.note
    assert "mid: 1 token (home 0)" in summary.detail
    assert row.end_state == "waiting_for_operator" and "+ gate 1" in (row.note or "")


async def test_a_run_ending_with_a_token_stuck_in_a_primitive_task_place_names_it_and_fails(tmp_path: Path):
    client = FakeClient({"act": ActionResult.error("drive 1 is in FAULT (following error)")})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(error_exit=False), client, journal)
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
    assert summary.end_state == "stuck" and summary.exit_code == 1
    assert summary.detail == ("robot: 0 tokens (home 1)",
                              "working: 1 token (work ended error; no transition takes it)")
    assert "working" in summary.note and "robot" in summary.note
    assert "drive 1 is in FAULT (following error)" in summary.format()


async def test_a_run_whose_every_call_errored_exits_non_zero_even_at_home(tmp_path: Path):
    client = FakeClient({"act": ActionResult.error("set-point stream stale")})
    with Journal(tmp_path / "j.sqlite") as journal:
        summary = await asyncio.wait_for(Runtime(tasks(runs=3), client, journal).run(), TIMEOUT_S)
    assert summary.end_state == "completed" and summary.all_calls_failed
    assert summary.exit_code == 6
    text = summary.format(max_errors=2)
    assert "every one of the 3 primitive-action calls ended in error" in text
    assert "... and 1 more errors" in text


async def test_a_run_that_comes_home_completes_and_exits_zero(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        summary = await asyncio.wait_for(Runtime(tasks(runs=2), FakeClient({"act": ActionResult.success()}),
                                                 journal).run(), TIMEOUT_S)
    assert (summary.end_state, summary.exit_code, summary.note) == ("completed", 0, "at the home marking")
    assert summary.final_marking == {"robot": 1, "done": 2}


async def test_with_linger_a_run_at_home_waits_for_more_runs_until_the_operator_ends_it(tmp_path: Path):
    seen = Recorder()
    client = FakeClient({"act": ActionResult.success()})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(runs=1), client, journal, observer=seen, operator=True, linger=True)
        run = asyncio.create_task(runtime.run())
        event = await seen.wait_for(waiting)
        assert event.reason.startswith("completed: at the home marking")
        assert event.detail == ("+ runs 1 would enable start",)
        seen.events.clear()
        runtime.command(OperatorCommand(Command.INSERT, "runs", 2))
        await seen.wait_for(lambda e: waiting(e) and runtime.engine.marking["done"] == 3)
        runtime.command(OperatorCommand(Command.END))
        summary = await asyncio.wait_for(run, TIMEOUT_S)
    assert (summary.end_state, summary.exit_code) == ("completed", 0)
    assert summary.final_marking == {"robot": 1, "done": 3}
    assert [c.command for c in operator_rows(tmp_path / "j.sqlite")] == ["insert", "end"]


async def test_with_linger_the_deadline_ends_a_run_waiting_at_home_as_completed(tmp_path: Path):
    # No runs queued: the run is at home from its first step, however late the deadline is looked at
    # (with a run to do first, a loaded machine could still be running it when 0.3 s ran out).
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(runs=0), FakeClient({"act": ActionResult.success()}), journal, operator=True,
                          linger=True)
        summary = await asyncio.wait_for(runtime.run(max_seconds=0.3), TIMEOUT_S)
    assert summary.end_state == "completed", summary
    assert summary.note == "at the home marking when --max-seconds 0.3 ran out"


async def test_a_run_waits_for_an_external_event_that_would_let_a_transition_fire(tmp_path: Path):
    seen = Recorder()
    client = FakeClient(topics={"tick"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(TICKS), client, journal, observer=seen)
        run = asyncio.create_task(runtime.run())
        event = await seen.wait_for(waiting)
        assert event.reason == "waiting for ext:tick"
        while not run.done():
            client.publish("tick")
            await asyncio.sleep(0.01)
        summary = await run
    assert summary.end_state == "completed" and summary.final_marking == {"shots": 2}


async def test_an_event_no_node_publishes_is_not_waited_for(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        summary = await asyncio.wait_for(Runtime(loads_net(TICKS), FakeClient(), journal).run(), TIMEOUT_S)
    # it ends at once (only adding runs could still fire something) instead of waiting for ext:tick
    assert summary.end_state == "waiting_for_operator" and "armed: 2 tokens (home 0)" in summary.detail
    assert "ext:tick" not in summary.note and any("tick" in e for e in summary.errors)


# ---------------------------------------------------------------------- operator commands refused
async def test_refused_operator_commands_are_journaled_with_their_reason(tmp_path: Path):
    seen = Recorder()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(gated(), FakeClient(), journal, observer=seen, operator=True)
        run = asyncio.create_task(runtime.run())
        await seen.wait_for(waiting)
        runtime.command(OperatorCommand(Command.INSERT, "mid", 1))
        runtime.command(OperatorCommand(Command.RESUME))
        runtime.refuse_input("fly away", "commands: + PLACE [N] | ...")
        runtime.command(OperatorCommand(Command.ABORT))
        await asyncio.wait_for(run, TIMEOUT_S)
    rows = [(c.command, c.place, c.count, c.accepted) for c in operator_rows(tmp_path / "j.sqlite")]
    assert rows == [("insert", "mid", 1, False), ("resume", None, None, False), ("invalid", None, None, False),
                    ("abort", None, None, True)]
    reasons = [c.reason for c in operator_rows(tmp_path / "j.sqlite")]
    assert "not a control place" in reasons[0] and reasons[1] == "the run is not paused"
    assert reasons[2].startswith("'fly away'")
    refused = [e for e in seen.events if isinstance(e, OperatorRefused)]
    assert [str(e.command) for e in refused] == ["insert mid 1", "resume", "fly away"]


# ---------------------------------------------------------------------- interrupted and resumed
async def test_an_interrupted_run_is_resumed_and_reissues_the_call_it_interrupted(tmp_path: Path):
    client = FakeClient(blocking={"act"})
    path = tmp_path / "j.sqlite"
    net = tasks(runs=2)
    with Journal(path) as journal:
        runtime = Runtime(net, client, journal)
        run = asyncio.create_task(runtime.run())
        await asyncio.wait_for(client.started.wait(), TIMEOUT_S)
        run.cancel()  # what Ctrl-C does to the main task
        with pytest.raises(asyncio.CancelledError):
            await run
        assert journal.run(runtime.run_id).end_state == "interrupted"
        interrupted = client.calls[0][1]
    done = FakeClient({"act": ActionResult.success()})
    with Journal(path) as journal:
        run_id = journal.last_unfinished_run("tasks")
        assert run_id == runtime.run_id
        again = Runtime(net, done, journal, recovered=journal.recover(net, run_id))
        summary = await asyncio.wait_for(again.run(), TIMEOUT_S)
        assert journal.run(run_id).end_state == "completed"
    assert summary.end_state == "completed" and summary.final_marking == {"robot": 1, "done": 2}
    assert done.calls[0][1] == interrupted  # the same call id: a node that kept its result answers it


async def test_a_resumed_run_counts_the_results_before_its_interruption_in_its_summary_and_exit_code(
        tmp_path: Path):
    """Before: a resumed run whose only new call errored said "every call ended in error" (exit 6)
    though the run's first call had succeeded before Ctrl-C."""

    class SucceedsThenHolds(FakeClient):
        async def call(self, action: str, params: dict[str, Any], *, call_id: str, deadline_s: float | None = None,
                       on_feedback: Any = None) -> ActionResult:
            if not self.calls:
                self.calls.append((action, call_id))
                return ActionResult(status=Status.SUCCESS, wall_s=0.5)
            return await super().call(action, params, call_id=call_id, deadline_s=deadline_s)

    path = tmp_path / "j.sqlite"
    net = tasks(runs=2)
    first = SucceedsThenHolds(blocking={"act"})
    with Journal(path) as journal:
        runtime = Runtime(net, first, journal)
        run = asyncio.create_task(runtime.run())
        while len(first.calls) < 2:
            await asyncio.wait_for(first.started.wait(), TIMEOUT_S)
            first.started.clear()
        run.cancel()
        await asyncio.gather(run, return_exceptions=True)
    with Journal(path) as journal:
        again = Runtime(net, FakeClient({"act": ActionResult.error("drive 1 is in FAULT")}), journal,
                        recovered=journal.recover(net, runtime.run_id))
        summary = await asyncio.wait_for(again.run(), TIMEOUT_S)
        note = journal.run(runtime.run_id).note or ""
    assert summary.end_state == "completed" and summary.calls == 2
    assert not summary.all_calls_failed and summary.exit_code == 0
    assert "every one of" not in note


def test_the_reader_thread_turns_end_of_input_into_end(tmp_path: Path):
    class Sink:
        def __init__(self) -> None:
            self.got: list[Any] = []

        def command(self, cmd: OperatorCommand) -> None:
            self.got.append(cmd)

        def refuse_input(self, text: str, reason: str) -> None:
            self.got.append(text)

    async def main() -> list[Any]:
        sink = Sink()
        import io
        thread: threading.Thread = read_operator_commands(sink, io.StringIO("+ runs 2\nfly\n"),  # type: ignore[arg-type]
                                                          on_error=lambda text, reason: None)
        await asyncio.to_thread(thread.join, TIMEOUT_S)
        await asyncio.sleep(0)
        return sink.got

    got = asyncio.run(main())
    assert got == [OperatorCommand(Command.INSERT, "runs", 2), "fly", OperatorCommand(Command.END)]


async def test_a_run_that_reaches_its_goal_away_from_home_completes(tmp_path: Path):
    once = CYCLE.split('[[transition]]\nid = "back"')[0]  # a -> there -> b, and no way back
    net = loads_net(once)
    with Journal(tmp_path / "j.sqlite") as journal:
        away = await asyncio.wait_for(Runtime(net, FakeClient(), journal).run(), TIMEOUT_S)
        goal = await asyncio.wait_for(Runtime(net, FakeClient(), journal, goal={"b": 1}).run(), TIMEOUT_S)
        with pytest.raises(Exception, match="does not have: nope"):
            Runtime(net, FakeClient(), journal, goal={"nope": 1})
    assert away.end_state == "stuck"  # a runs once: its token is not back in a
    assert (goal.end_state, goal.exit_code) == ("completed", 0)
    assert goal.note == "the goal marking is reached (1 place away from home)" and goal.detail == ("a: 0 tokens (home 1)",)
