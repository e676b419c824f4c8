"""The runtime reconciles the calls it gave up on with what their nodes did: it asks the node as soon
as it can be reached, journals the node's final word, says when it is not what the net assumed,
and does it again on resume (no sockets: a fake service client that can be asked)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coordinator.console import Console
from coordinator.events import CallReconciled
from coordinator.journal import Journal, JournalReader
from coordinator.reconcile import describe, given_up, never_sent
from coordinator.runtime import Runtime
from services.results import ActionResult, Status
from tests.unit.runtime_fakes import FakeClient, FakeLocation
from tests.unit.test_runtime import TIMEOUT_S, Recorder, tasks

LOST = ActionResult.error("heartbeat timeout")  # what the client says when it gives up: no duration
RAN = ActionResult(status=Status.SUCCESS, value={"waited_s": 3.0}, wall_s=3.0, cpu_s=0.01)
CANCELLED = ActionResult(status=Status.ERROR, reason="cancelled", wall_s=0.8, cpu_s=0.001)
UNREACHABLE = ActionResult.error("node fake unreachable: Connection refused (errno 111)")


@dataclass(frozen=True)
class Placement:
    unattended: bool = False


class AskableLocation(FakeLocation):
    def __init__(self, actions: set[str], unattended: set[str]) -> None:
        super().__init__(actions)
        self.unattended = unattended

    def action(self, name: str) -> Placement:
        self.node_of(name)
        return Placement(name in self.unattended)


class AskableClient(FakeClient):
    """A fake client whose node can be asked what became of a call (``truth``: id → final result,
    ``None`` for an id it never saw); while ``reachable`` is False a query is node trouble."""

    def __init__(self, results: dict[str, Any], *, truth: dict[str, ActionResult | None] | None = None,
                 unattended: set[str] = frozenset(), reachable: bool = True, **kwargs: Any) -> None:
        super().__init__(results, **kwargs)
        self.location = AskableLocation(self.location.actions, set(unattended))
        self.truth = dict(truth or {})
        self.reachable = reachable
        self.queries: list[tuple[str, str, bool]] = []
        self.asked = asyncio.Event()

    async def query(self, action: str, call_id: str, *, cancel: bool = False) -> ActionResult | None:
        self.queries.append((action, call_id, cancel))
        self.asked.set()
        await asyncio.sleep(0)
        if not self.reachable:
            return UNREACHABLE
        return self.truth.get(call_id)


def reconciliations(path: Path):
    with JournalReader.open(path) as reader:
        return reader.reconciliations()


def test_only_errors_no_node_measured_and_no_node_gave_are_given_up_on():
    assert given_up(LOST) and given_up(UNREACHABLE)
    assert given_up(ActionResult.error("deadline (no answer from node)"))
    assert not given_up(CANCELLED)  # the node ran it and measured it
    assert not given_up(ActionResult.error("busy")) and not given_up(ActionResult.error("node_restarted"))
    assert not given_up(RAN) and not given_up(ActionResult.failure())
    assert never_sent(UNREACHABLE, "fake") and not never_sent(LOST, "fake")
    assert never_sent(ActionResult.error("authentication failed: node fake refused our key"), "fake")


def test_the_words_say_when_the_node_did_otherwise_than_the_net_assumed():
    assert describe("beta", "slow", Status.ERROR, RAN, "heartbeat timeout") == (
        "node beta finished slow with success after the coordinator declared it lost (heartbeat timeout)")
    assert describe("beta", "slow", Status.ERROR, CANCELLED) == "node beta ended slow with error: cancelled, as the net assumed"
    assert describe("beta", "slow", Status.ERROR, None).startswith("node beta never ran slow")
    assert describe("beta", "slow", None, CANCELLED).endswith("after the run had stopped waiting for it")


async def test_a_call_given_up_on_is_cancelled_and_asked_for_and_the_nodes_word_is_journaled(tmp_path: Path):
    client = AskableClient({"act": LOST})
    path = tmp_path / "j.sqlite"
    seen = Recorder()
    with Journal(path) as journal:
        runtime = Runtime(tasks(), client, journal, observer=seen)
        call_id = f"{runtime.run_id}-1"
        client.truth[call_id] = RAN  # the node finished it after all
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
    assert client.queries == [("act", call_id, True)]
    (row,) = reconciliations(path)
    assert (row.instance, row.node, row.assumed, row.status, row.value, row.differs) == (
        call_id, "fake", Status.ERROR, Status.SUCCESS, {"waited_s": 3.0}, True)
    event = next(e for e in seen.events if isinstance(e, CallReconciled))
    assert event.differs and event.lost == "heartbeat timeout"
    assert summary.final_marking == {"robot": 1, "done": 1}  # the net went on along its error branch
    assert summary.reconciled == 1
    assert summary.differed == (("node fake finished act with success after the coordinator declared it lost "
                                 "(heartbeat timeout)"),)
    assert "after the coordinator declared it lost" in summary.format()
    with JournalReader.open(path) as reader:
        (run,) = reader.runs()
        assert "reconciled differently: node fake finished act with success" in (run.note or "")
        assert reader.final_words()[call_id] == row


async def test_the_console_prints_a_differing_reconciliation_even_when_quiet(tmp_path: Path):
    import io

    client = AskableClient({"act": LOST})
    out = io.StringIO()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(), client, journal)
        client.truth[f"{runtime.run_id}-1"] = RAN
        Console(tasks(), stream=out, live=False, quiet=True).attach(runtime)
        await asyncio.wait_for(runtime.run(), TIMEOUT_S)
    line = next(line for line in out.getvalue().splitlines() if "reconciled" in line)
    assert "reconciled work: node fake finished act with success after the coordinator declared it lost" in line


async def test_an_unattended_action_is_asked_for_without_being_cancelled(tmp_path: Path):
    client = AskableClient({"act": LOST}, unattended={"act"})
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(tasks(), client, journal)
        client.truth[f"{runtime.run_id}-1"] = RAN
        await asyncio.wait_for(runtime.run(), TIMEOUT_S)
    assert client.queries == [("act", f"{runtime.run_id}-1", False)]


async def test_a_node_that_cannot_be_reached_is_asked_again_until_it_answers(tmp_path: Path):
    client = AskableClient({"act": LOST}, reachable=False)
    path = tmp_path / "j.sqlite"
    with Journal(path) as journal:
        runtime = Runtime(tasks(), client, journal, reconcile_s=TIMEOUT_S)
        client.truth[f"{runtime.run_id}-1"] = CANCELLED
        run = asyncio.create_task(runtime.run())
        while len(client.queries) < 3:  # retried, with a growing pause
            await asyncio.wait_for(client.asked.wait(), TIMEOUT_S)
            client.asked.clear()
        assert not run.done()  # the end of the run waits for the node's word
        client.reachable = True
        summary = await asyncio.wait_for(run, TIMEOUT_S)
    (row,) = reconciliations(path)
    assert (row.status, row.reason, row.differs) == (Status.ERROR, "cancelled", False)
    assert summary.reconciled == 1 and summary.differed == () and summary.unreconciled == ()


async def test_calls_whose_node_never_answers_are_named_at_the_end_of_the_run(tmp_path: Path):
    client = AskableClient({"act": LOST}, reachable=False)
    path = tmp_path / "j.sqlite"
    with Journal(path) as journal:
        runtime = Runtime(tasks(), client, journal, reconcile_s=0.3)
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
    assert reconciliations(path) == []
    (line,) = summary.unreconciled
    assert line == f"act on fake [{runtime.run_id}-1]: node fake unreachable: Connection refused (errno 111)"
    assert "not reconciled: 1 call given up on" in summary.format()
    with JournalReader.open(path) as reader:
        assert "not reconciled: act on fake" in (reader.runs()[0].note or "")


async def test_results_a_node_gave_and_calls_that_never_left_are_not_reconciled(tmp_path: Path):
    for result in (CANCELLED, ActionResult.error("busy"), ActionResult.error("node_restarted"), UNREACHABLE, RAN):
        client = AskableClient({"act": result})
        with Journal(tmp_path / "j.sqlite") as journal:
            await asyncio.wait_for(Runtime(tasks(), client, journal).run(), TIMEOUT_S)
        assert client.queries == [], result


async def test_a_call_still_running_when_the_deadline_ends_the_run_is_reconciled_without_a_result(tmp_path: Path):
    client = AskableClient({}, blocking={"act"})
    path = tmp_path / "j.sqlite"
    with Journal(path) as journal:
        runtime = Runtime(tasks(), client, journal, cancel_grace_s=0.0)
        client.truth[f"{runtime.run_id}-1"] = CANCELLED
        client.cancel = _ignore_cancel  # type: ignore[method-assign]  # the result never comes back
        summary = await asyncio.wait_for(runtime.run(max_seconds=0.2), TIMEOUT_S)
    assert summary.end_state == "deadline"
    (row,) = reconciliations(path)
    assert (row.assumed, row.status, row.reason, row.differs) == (None, Status.ERROR, "cancelled", False)


async def _ignore_cancel(call_id: str) -> bool:
    return False


async def test_a_resumed_run_reconciles_the_calls_given_up_on_before_it_stopped(tmp_path: Path):
    path = tmp_path / "j.sqlite"
    net = tasks(runs=2)
    first = AskableClient({"act": LOST}, reachable=False)
    with Journal(path) as journal:
        runtime = Runtime(net, first, journal)
        run = asyncio.create_task(runtime.run())
        await asyncio.wait_for(first.asked.wait(), TIMEOUT_S)  # given up on, its node unreachable
        run.cancel()  # Ctrl-C
        await asyncio.gather(run, return_exceptions=True)
        given_up_id = f"{runtime.run_id}-1"
    assert reconciliations(path) == []
    later = AskableClient({"act": RAN}, truth={given_up_id: RAN})
    with Journal(path) as journal:
        again = Runtime(net, later, journal, recovered=journal.recover(net, runtime.run_id))
        summary = await asyncio.wait_for(again.run(), TIMEOUT_S)
    assert (given_up_id, True) in [(cid, cancel) for _, cid, cancel in later.queries]
    row = {r.instance: r for r in reconciliations(path)}[given_up_id]
    assert (row.status, row.differs) == (Status.SUCCESS, True)
    assert summary.end_state == "completed" and summary.reconciled >= 1
