"""A run's events reach the console's pages as coalesced frames: the observer only appends, a burst of
firings becomes one frame with counts and the latest marking, and commands are answered with the
engine's own verdict (no sockets: a fake service client)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from coordinator.events import (
    ActionEnded,
    ActionStarted,
    LearnerUpdated,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.journal import Journal, JournalReader
from coordinator.learning import Learner
from coordinator.netfile import loads_net
from coordinator.operator import Command, OperatorCommand
from coordinator.runtime import Runtime
from coordinator.web.frames import LiveFeed, learner_view
from services.results import ActionResult, Status
from tests.unit.runtime_fakes import FakeClient
from tests.unit.test_runtime import CYCLE, TASKS, TIMEOUT_S, Recorder

RECOVER = """
[[transition]]
id = "recover"
events = ["int:work.error"]
inputs = { working = 1 }
outputs = { robot = 1 }
"""

CONTROLLED_CYCLE = CYCLE + """
[[place]]
id = "gate"
kind = "control"
tokens = 1
"""


def fire(runtime: Runtime, feed: LiveFeed, times: int = 1) -> None:
    """Fire the next enabled transition ``times`` times and tell the feed, as the runtime does."""
    engine = runtime.engine
    for _ in range(times):
        firing = engine.next_firing()
        assert firing is not None
        engine.apply(firing)
        feed(TransitionFired(runtime.run_id, firing))


def frames_of(feed: LiveFeed) -> list[dict[str, Any]]:
    sent: list[dict[str, Any]] = []
    feed.subscribe(lambda text: sent.append(json.loads(text)))
    return sent


async def test_the_observer_only_appends_and_a_burst_of_firings_becomes_one_frame(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        runtime.engine.start()
        fire(runtime, feed, 1000)
        assert sent == []  # nothing is built or sent while the engine fires
        feed.flush()
    assert len(sent) == 1
    frame = sent[0]
    assert frame["fired"] == {"there": 500, "back": 500}
    assert frame["firings"] == 1000
    assert frame["t_fired"][0] <= frame["t_fired"][1]
    assert "marking" not in frame  # 1,000 firings later the cycle is back where it started: nothing changed


async def test_the_observer_keeps_no_firing_event_alive_between_frames(tmp_path: Path):
    """A run firing thousands of transitions a second would otherwise keep as many event objects
    alive until the next frame: a firing is counted when it comes, then let go."""
    import gc

    def alive() -> int:
        return sum(type(o) is TransitionFired for o in gc.get_objects())

    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        runtime.engine.start()
        before = alive()
        fire(runtime, feed, 500)
        assert alive() == before
        feed.flush()
    assert sent[0]["fired"] == {"there": 250, "back": 250}


async def test_the_runs_state_travels_in_a_frame_only_when_it_changed(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        runtime.engine.start()
        feed(RunStateChanged(runtime.run_id, "started", "", detail=()))
        fire(runtime, feed)
        feed.flush()
        fire(runtime, feed)
        feed.flush()
        feed(RunStateChanged(runtime.run_id, "waiting", "waiting for ext:tick", detail=("ext:tick",)))
        feed.flush()
        fire(runtime, feed)  # firing again after a wait: the page is told the run is running
        feed.flush()
    assert sent[0]["state"]["state"] == "started"
    assert "state" not in sent[1]  # the page redraws its panels only when something there changed
    assert sent[2]["state"]["state"] == "waiting"
    assert sent[3]["state"] == {"state": "running", "reason": "", "detail": []}


async def test_a_frame_carries_only_the_places_whose_tokens_changed(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        runtime.engine.start()
        fire(runtime, feed)
        feed.flush()
        feed.flush()  # nothing new: no frame
    assert len(sent) == 1
    assert sent[0]["marking"] == {"a": 0, "b": 1}


async def test_actions_latched_events_and_learners_travel_in_frames(tmp_path: Path):
    net = loads_net(TASKS.replace("RUNS", "1").replace("ACTION", "echo") + RECOVER)
    with Journal(tmp_path / "j.sqlite") as journal:
        learner = Learner.from_net(net, 0)
        runtime = Runtime(net, FakeClient({"echo": ActionResult.success()}), journal, learner=learner)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        state = learner.update("work", "echo", ActionResult.success())
        feed(ActionStarted(runtime.run_id, "r-1", "work", "working", "echo", "fake"))
        feed(ActionEnded(runtime.run_id, "r-1", "work", "echo", "fake", ActionResult.error("node down")))
        feed(LearnerUpdated(runtime.run_id, "work", state))
        feed(RunStateChanged(runtime.run_id, "waiting", "waiting for ext:tick", detail=("ext:tick",)))
        feed.flush()
    frame = sent[0]
    assert frame["started"][0] == {"i": "r-1", "task": "work", "place": "working", "action": "echo", "node": "fake",
                                   "t": frame["started"][0]["t"]}
    assert frame["ended"][0]["status"] == "error" and frame["ended"][0]["reason"] == "node down"
    assert frame["learner"]["work"]["actions"][0]["trials"] == 1
    assert frame["state"] == {"state": "waiting", "reason": "waiting for ext:tick", "detail": ["ext:tick"]}
    assert feed.snapshot()["errors"][0]["reason"] == "node down"


async def test_the_latest_feedback_of_each_running_action_travels_in_frames_cut_to_size(tmp_path: Path):
    from coordinator.events import ActionFeedback
    from coordinator.web.frames import FEEDBACK_CHARS

    net = loads_net(TASKS.replace("RUNS", "1").replace("ACTION", "echo") + RECOVER)
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(net, FakeClient({"echo": ActionResult.success()}), journal)
        feed = LiveFeed(runtime)
        sent = frames_of(feed)
        feed(ActionStarted(runtime.run_id, "r-1", "work", "working", "echo", "fake"))
        feed(ActionFeedback(runtime.run_id, "r-1", "work", "echo", {"progress": 0.25}))
        feed(ActionFeedback(runtime.run_id, "r-1", "work", "echo", {"progress": 0.5}))
        feed.flush()
        feed(ActionFeedback(runtime.run_id, "r-1", "work", "echo", {"log": "x" * 1000}))
        feed.flush()
        feed(ActionFeedback(runtime.run_id, "r-1", "work", "echo", {"progress": 1.0}))
        feed(ActionEnded(runtime.run_id, "r-1", "work", "echo", "fake", ActionResult.success()))
        feed.flush()
    assert sent[0]["feedback"] == {"r-1": '{"progress": 0.5}'}  # the latest wins
    assert len(sent[1]["feedback"]["r-1"]) == FEEDBACK_CHARS
    assert "feedback" not in sent[2] and sent[2]["ended"][0]["i"] == "r-1"  # ended: no stale feedback


def test_the_learner_view_gives_the_automatons_own_estimates():
    net = loads_net(TASKS.replace("RUNS", "1").replace('actions = ["ACTION"]', """actions = [
    { name = "fast", cost = 1.0 }, { name = "slow", cost = 3.0 },
]
learner = { scheme = "pursuit", rate = 0.1 }""") + RECOVER)
    learner = Learner.from_net(net, 1)
    for ok in (True, True, False):
        learner.update("work", "fast", ActionResult.success() if ok else ActionResult.failure())
    auto = learner.automaton("work")
    view = learner_view(auto)
    fast = next(a for a in view["actions"] if a["name"] == "fast")
    est = auto.estimates["fast"]
    assert (fast["trials"], fast["successes"]) == (3, 2)
    assert fast["R"] == round(est.reliability, 6) and fast["C"] == 1.0 and fast["J"] == round(est.j, 6)
    assert abs(sum(a["p"] for a in view["actions"]) - 1.0) < 1e-5
    assert view["scheme"] == "pursuit" and view["rho"] == round(1 / 3.0, 6)


async def test_a_command_from_a_page_gets_the_engines_verdict_and_is_journaled(tmp_path: Path):
    seen = Recorder()
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CONTROLLED_CYCLE), FakeClient(), journal, observer=seen, operator=True)
        feed = LiveFeed(runtime)
        runtime.add_observer(feed)
        frames = asyncio.create_task(feed.run())
        run = asyncio.create_task(runtime.run(max_seconds=TIMEOUT_S))
        replies: asyncio.Queue[tuple[bool, str]] = asyncio.Queue()
        try:
            refused = OperatorCommand(Command.REMOVE, "a", 1)
            feed.expect_reply(refused, lambda ok, why: replies.put_nowait((ok, why)))
            runtime.command(refused)
            ok, why = await asyncio.wait_for(replies.get(), TIMEOUT_S)
            assert not ok and "not a control place" in why
            applied = OperatorCommand(Command.REMOVE, "gate", 1)
            feed.expect_reply(applied, lambda ok, why: replies.put_nowait((ok, why)))
            runtime.command(applied)
            assert await asyncio.wait_for(replies.get(), TIMEOUT_S) == (True, "")
            runtime.command(OperatorCommand(Command.ABORT))
            await asyncio.wait_for(run, TIMEOUT_S)
        finally:
            frames.cancel()
    with JournalReader.open(tmp_path / "j.sqlite") as reader:
        rows = [(r.command, r.place, r.accepted) for r in reader.operator_commands()]
    assert rows == [("remove", "a", False), ("remove", "gate", True), ("abort", None, True)]


async def test_every_added_observer_sees_every_event_and_a_failing_one_stops_nothing(tmp_path: Path):
    first, second = Recorder(), Recorder()

    def broken(event: RunEvent) -> None:
        raise RuntimeError("a display fell over")

    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(TASKS.replace("RUNS", "2").replace("ACTION", "echo") + RECOVER), FakeClient({"echo": ActionResult.success()}), journal, observer=first)
        runtime.add_observer(broken)
        runtime.add_observer(second)
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
        runtime.remove_observer(second)
    assert summary.end_state == "completed"
    assert [type(e) for e in first.events] == [type(e) for e in second.events]
    assert sum(isinstance(e, ActionEnded) and e.result.status is Status.SUCCESS for e in second.events) == 2


class HealthyClient(FakeClient):
    """A fake client that reports its nodes' health like ``ServiceClient.health``."""

    def __init__(self) -> None:
        super().__init__()
        self.nodes = {"alpha": {"connected": True, "heartbeat_rtt_s": 0.00123456, "in_flight": 1}}

    def health(self) -> dict[str, Any]:
        return {node: dict(h) for node, h in self.nodes.items()}


async def test_the_nodes_health_is_in_the_snapshot_and_a_frame_carries_it_when_it_changes(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        client = HealthyClient()
        runtime = Runtime(loads_net(CYCLE), client, journal)
        feed = LiveFeed(runtime)
        # the net calls no action: its client's node is there, not used
        assert feed.snapshot()["nodes"] == {"alpha": {"connected": True, "heartbeat_rtt_s": 0.0012, "in_flight": 1,
                                                      "used": False}}
        sent = frames_of(feed)
        feed.flush()                      # nothing happened, but the health was never sent
        assert sent[-1]["nodes"]["alpha"]["connected"] is True
        count = len(sent)
        feed.flush()                      # unchanged (and looked at less than a second ago): no frame
        assert len(sent) == count
        client.nodes["alpha"] = {"connected": False, "heartbeat_rtt_s": None, "in_flight": 0}
        feed._health_at = 0.0             # as if a second had passed
        feed.flush()
        assert sent[-1]["nodes"] == {"alpha": {"connected": False, "heartbeat_rtt_s": None, "in_flight": 0,
                                               "used": False}}


async def test_the_nodes_the_net_uses_come_first_and_the_others_are_marked_not_used(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        client = HealthyClient()
        client.results["echo"] = ActionResult.success()
        client.location.actions.add("echo")  # placed on node "fake"
        client.nodes["fake"] = {"connected": True, "heartbeat_rtt_s": 0.001, "in_flight": 0}
        net = loads_net(TASKS.replace("RUNS", "1").replace("ACTION", "echo") + RECOVER)
        feed = LiveFeed(Runtime(net, client, journal))
        nodes = feed.snapshot()["nodes"]
        assert list(nodes) == ["fake", "alpha"]
        assert nodes["fake"]["used"] is True and nodes["alpha"]["used"] is False


async def test_a_client_without_health_gives_an_empty_node_table(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        feed = LiveFeed(Runtime(loads_net(CYCLE), FakeClient(), journal))
        assert feed.snapshot()["nodes"] == {}
        sent = frames_of(feed)
        feed.flush()
        assert sent == []


async def test_the_frame_task_stops_when_cancelled_even_as_an_event_wakes_it(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        feed = LiveFeed(Runtime(loads_net(CYCLE), FakeClient(), journal))
        task = asyncio.get_running_loop().create_task(feed.run())
        for _ in range(3):
            await asyncio.sleep(0)            # the task waits for events
        feed._wake.set()                      # an event wakes it in the very step it is cancelled
        task.cancel()
        done, _ = await asyncio.wait({task}, timeout=TIMEOUT_S)
        assert done, "the frame task swallowed its cancellation and went on"
        assert task.cancelled()


async def test_a_task_failing_in_a_row_and_the_runs_summary_reach_the_page(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        net = loads_net(TASKS.replace("RUNS", "3").replace("ACTION", "echo") + RECOVER)
        runtime = Runtime(net, FakeClient({"echo": ActionResult.error("the gripper reports an overcurrent on "
                                                                      "joint 2 after 0.4 s (limit 1.2 A)")}),
                          journal)
        feed = LiveFeed(runtime)
        runtime.add_observer(feed)
        sent = frames_of(feed)
        summary = await asyncio.wait_for(runtime.run(), TIMEOUT_S)
        feed.flush()
    tasks = [f["tasks"]["work"] for f in sent if "tasks" in f]
    assert tasks[-1]["in_a_row"] == 3 and tasks[-1]["errors"] == tasks[-1]["results"] == 3
    assert tasks[-1]["last_error"]["reason"] == "the gripper reports an overcurrent on joint 2 after 0.4 s (limit 1.2 A)"
    (end,) = [f["summary"] for f in sent if "summary" in f]
    assert end["state"] == summary.end_state == "completed" and end["firings"] == summary.firings
    assert end["all_calls_failed"] is True and end["n_errors"] == 3
    assert end["actions"] == [{"task": "work", "action": "echo", "node": "fake", "calls": 3, "success": 0,
                               "failure": 0, "error": 3, "mean_s": 0.0}]
    assert feed.snapshot()["summary"] == end and feed.snapshot()["tasks"]["work"]["in_a_row"] == 3
