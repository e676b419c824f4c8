"""ROS 2 over Zenoh against an implementation petrobot did not write: a Zenoh router process, a
zenoh-ros2-sdk robot process (an AddTwoInts service, a cancellable Fibonacci action with feedback, a
Bool topic), a petrobot node placed by services.toml and `petrobot run` of nets that use them. The
robot prints what it sees; the journal must agree with it (real processes, TCP on 127.0.0.1)."""

from __future__ import annotations

import json
import os
import pty
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from tests.integration.cluster import Cluster, free_port
from test_run_cli import Output, petrobot

from coordinator.journal import JournalReader
from coordinator.rosbag import export_run
from services.results import Status

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 60.0  # generous bound of every wait (the machine is shared)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

SERVICES = """
[nodes.robot]
host = "127.0.0.1"
port = {port[robot]}

[nodes.robot.ros2]
connect = ["tcp/127.0.0.1:{port[zenoh]}"]

[actions.add_two_ints]
node = "robot"
ros2 = {{ service = "/add_two_ints", type = "example_interfaces/srv/AddTwoInts", success = "sum > 0" }}

[actions.fibonacci]
node = "robot"
deadline_s = 60.0
ros2 = {{ action = "/fibonacci", type = "example_interfaces/action/Fibonacci", success = "len(sequence) > 1" }}

[actions.drive_to_dock]
node = "robot"
deadline_s = 30.0
params = {{ linear = {{ x = 2.0 }} }}
ros2 = {{ publish = "/cmd_vel", type = "geometry_msgs/msg/Twist", rate_hz = 20.0, fill = true, until = {{ topic = "/docked", type = "std_msgs/msg/Bool", when = "data" }} }}

[events.crossfire]
node = "robot"
ros2 = {{ topic = "/crossfire", type = "std_msgs/msg/Bool", when = "data", fields = ["data"] }}
"""

FLOW = """
[net]
name = "ros2_flow"
home = { done = 1 }

[[place]]
id = "go"
tokens = 1

[[place]]
id = "planning"
kind = "primitive_task"
task = "plan"

[[place]]
id = "counting"
kind = "primitive_task"
task = "count"

[[place]]
id = "watching"

[[place]]
id = "failed"

[[place]]
id = "done"

[task.plan]
actions = [{ name = "add_two_ints", params = { a = 2, b = 3 } }]
deadline_s = 10.0

[task.count]
actions = [{ name = "fibonacci", params = { order = 6 } }]
deadline_s = 30.0

[[transition]]
id = "start"
inputs = { go = 1 }
outputs = { planning = 1 }

[[transition]]
id = "planned"
events = ["int:plan.ok"]
inputs = { planning = 1 }
outputs = { counting = 1 }

[[transition]]
id = "counted"
events = ["int:count.success"]
inputs = { counting = 1 }
outputs = { watching = 1 }

[[transition]]
id = "crossed"
events = ["ext:crossfire"]
inputs = { watching = 1 }
outputs = { done = 1 }

[[transition]]
id = "plan_failed"
events = ["int:plan.error"]
inputs = { planning = 1 }
outputs = { failed = 1 }

[[transition]]
id = "count_failed"
events = ["int:count.error"]
inputs = { counting = 1 }
outputs = { failed = 1 }

[[transition]]
id = "count_unmet"
events = ["int:count.failure"]
inputs = { counting = 1 }
outputs = { failed = 1 }

[[transition]]
id = "given_up"
inputs = { failed = 1 }
outputs = { done = 1 }
"""

LONG = FLOW.replace('name = "ros2_flow"', 'name = "ros2_long"').replace("order = 6", "order = 40")


class SimProcess:
    """A ``petrobot sim zenoh|ros2`` process: its JSON event lines collected by a thread."""

    def __init__(self, world: str, args: list[str], log: Path, env: dict[str, str]) -> None:
        self._log = open(log, "w")  # noqa: SIM115 (closed by stop())
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator.cli", "sim", world, *args], cwd=ROOT,
                                     env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log,
                                     text=True)
        self.events: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                with self._cond:
                    self.events.append(json.loads(line))
                    self._cond.notify_all()

    def wait_for(self, what: str, match: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        end = time.monotonic() + TIMEOUT_S
        with self._cond:
            while True:
                for event in self.events:
                    if match(event):
                        return event
                left = end - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    raise AssertionError(f"no {what} from the simulated side; events: {self.events[-10:]}")
                self._cond.wait(min(left, 0.5))

    def seen(self, kind: str) -> list[dict[str, Any]]:
        with self._cond:
            return [e for e in self.events if e.get("event") == kind]

    def command(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._log.close()


class Ros2World:
    """The router, the robot and the petrobot node of one test."""

    def __init__(self, cluster: Cluster, tmp: Path) -> None:
        self.cluster = cluster
        self.tmp = tmp
        cluster.write_services(SERVICES)
        self.router = f"tcp/127.0.0.1:{cluster.ports['zenoh']}"
        env = cluster.env()
        self.zenoh = SimProcess("zenoh", ["--listen", self.router], tmp / "zenoh.log", env)
        self.zenoh.wait_for("router ready line", lambda e: e["event"] == "ready")
        self.robot = SimProcess("ros2", ["--router", self.router, "--commands", "--step-s", "0.1"],
                                tmp / "robot.log", env)
        self.robot.wait_for("robot ready line", lambda e: e["event"] == "ready")
        cluster.start("robot", timeout=60.0)

    def run(self, net_text: str, *args: str, **kwargs: Any) -> tuple[subprocess.Popen[str], Output, Path]:
        net = self.tmp / "net.toml"
        net.write_text(net_text)
        journal = self.tmp / f"journal-{time.monotonic_ns()}.sqlite"
        proc = petrobot(self.cluster, "run", str(net), "--journal", str(journal), "--lines", *args, **kwargs)
        return proc, Output(proc), journal

    def close(self) -> None:
        self.robot.stop()
        self.zenoh.stop()


@pytest.fixture
def world(cluster: Cluster, tmp_path: Path) -> Iterator[Ros2World]:
    w = Ros2World(cluster, tmp_path)
    try:
        yield w
    finally:
        cluster.close()
        w.close()


def _result(reader: JournalReader, action: str) -> Any:
    (row,) = [r for r in reader.results() if r.action == action]
    return row


def test_a_net_calls_the_service_and_the_action_then_fires_on_the_topics_rising_edge(world: Ros2World):
    proc, out, journal = world.run(FLOW)
    out.wait_for("waiting for ext:crossfire")
    world.robot.command("crossfire true")
    assert proc.wait(timeout=TIMEOUT_S) == 0, out.text
    assert "fire  #4     crossed on ext:crossfire" in out.text
    with JournalReader.open(journal) as reader:
        add = _result(reader, "add_two_ints")
        fib = _result(reader, "fibonacci")
        firings = [f.transition for f in reader.firings()]
        kept = [f for f in reader.feedback_messages() if f.action == "fibonacci"]
        run = reader.runs()[-1].id
    assert firings == ["start", "planned", "counted", "crossed"]
    # what the robot saw, call by call
    (call,) = world.robot.seen("service")
    assert (call["a"], call["b"], call["sum"]) == (2, 3, 5)
    assert (add.status, add.value) == (Status.SUCCESS, {"sum": 5})
    (goal,) = world.robot.seen("goal")
    (ended,) = world.robot.seen("result")
    assert goal["order"] == 6 and goal["accepted"] and ended["status"] == "SUCCEEDED"
    assert fib.status == Status.SUCCESS
    assert fib.value == {"status": "SUCCEEDED", "goal_id": goal["goal_id"], "result": {"sequence": ended["sequence"]}}
    assert ended["sequence"] == [0, 1, 1, 2, 3, 5, 8]
    # the action's feedback is journaled (sampled, the last one always) and exported with the run
    assert kept and kept[-1].instance == fib.instance and kept[-1].entry < fib.entry
    assert kept[-1].data["sequence"] == ended["sequence"][:len(kept[-1].data["sequence"])]
    bag = export_run(journal, run, journal.with_suffix(".bag"))
    assert bag.counts["/petrobot/action_feedback"] == len(kept)


def test_feedback_reaches_the_caller_and_the_ros_graph_shows_petrobots_node(world: Ros2World):
    import asyncio

    feedback: list[Any] = []

    async def call() -> Any:
        async with world.cluster.client() as client:
            return await client.call("fibonacci", {"order": 5}, on_feedback=feedback.append)

    result = asyncio.run(call())
    assert result.status == Status.SUCCESS, result
    assert [f["sequence"] for f in feedback] == [[0, 1, 1], [0, 1, 1, 2], [0, 1, 1, 2, 3], [0, 1, 1, 2, 3, 5]]
    # the robot's side lists petrobot's node and its subscription, as `ros2 topic info -v /crossfire` would
    probe = textwrap.dedent(f"""
        from zenoh_ros2_sdk import get_topic_info
        from zenoh_ros2_sdk.session import ZenohSession
        for attempt in range(40):  # the probe's own session may take a moment to reach the router
            info = get_topic_info("/crossfire", router_port={world.cluster.ports['zenoh']}, timeout=1.0, verbose=True)
            if info is not None and any(e.node_name == "petrobot_robot" for e in info.subscribers):
                break
        print(sorted((e.node_name, e.node_namespace) for e in info.subscribers) if info else None)
        ZenohSession.get_instance().session.close()
    """)
    done = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S)
    assert "('petrobot_robot', '/')" in done.stdout, done.stdout + done.stderr


def test_a_bad_goal_is_an_error_naming_the_field_and_nothing_reaches_the_robot(world: Ros2World):
    import asyncio

    async def call() -> Any:
        async with world.cluster.client() as client:
            return await client.call("fibonacci", {"order": "ten"})

    result = asyncio.run(call())
    assert result.status == Status.ERROR
    assert "goal field 'goal.order': expected an integer (int32), got 'ten' (str)" in result.reason
    assert world.robot.seen("goal") == []


def test_abort_cancels_the_goal_on_the_robot_and_the_journal_says_canceled(world: Ros2World):
    master, slave = pty.openpty()
    try:
        proc, out, journal = world.run(LONG, stdin=slave)
        os.close(slave)
        out.wait_for("start count -> fibonacci on robot")
        goal = world.robot.wait_for("goal", lambda e: e["event"] == "goal")
        world.robot.wait_for("the goal running", lambda e: e["event"] == "executing")
        os.write(master, b"abort\n")
        assert proc.wait(timeout=TIMEOUT_S) == 5, out.text
    finally:
        os.close(master)
    cancel = world.robot.wait_for("cancel request", lambda e: e["event"] == "cancel")
    ended = world.robot.wait_for("the goal's end", lambda e: e["event"] == "result")
    assert cancel["goal_id"] == goal["goal_id"] == ended["goal_id"] and cancel["return_code"] == 0
    assert ended["status"] == "CANCELED" and len(ended["sequence"]) < 41
    with JournalReader.open(journal) as reader:
        fib = _result(reader, "fibonacci")
        (run,) = reader.runs()
    assert run.end_state == "aborted"
    assert (fib.status, fib.outcome, fib.reason) == (Status.ERROR, "canceled", "cancelled")
    assert fib.value == {"status": "CANCELED", "goal_id": goal["goal_id"], "result": {"sequence": ended["sequence"]}}


def test_the_robot_killed_mid_goal_takes_the_error_branch_at_once(world: Ros2World, record_property: Any):
    proc, out, journal = world.run(LONG)
    out.wait_for("start count -> fibonacci on robot")
    goal = world.robot.wait_for("goal", lambda e: e["event"] == "goal")
    world.robot.wait_for("the goal running", lambda e: e["event"] == "executing")
    killed = time.time()
    world.robot.proc.kill()
    assert proc.wait(timeout=TIMEOUT_S) == 0, out.text
    with JournalReader.open(journal) as reader:
        fib = _result(reader, "fibonacci")
        firings = [f.transition for f in reader.firings()]
    assert firings == ["start", "planned", "count_failed", "given_up"]
    assert fib.status == Status.ERROR, fib
    assert "went away" in fib.reason or "left the ROS 2 graph" in fib.reason, fib.reason
    assert fib.value["goal_id"] == goal["goal_id"]
    record_property("error_after_kill_s", round(fib.t_wall - killed, 3))  # measured, not asserted


def test_a_publication_at_a_rate_ends_when_a_condition_on_another_topic_holds(world: Ros2World):
    import asyncio

    async def call() -> Any:
        async with world.cluster.client() as client:
            return await client.call("drive_to_dock", {})

    result = asyncio.run(call())
    assert result.status == Status.SUCCESS, result
    docked = world.robot.wait_for("docked", lambda e: e["event"] == "docked")
    assert result.value["until"] == {"data": True}
    # the robot drove 1 m at 2 m/s on commands every 0.05 s: it saw about ten, the last ones after it docked
    assert docked["commands"] >= 2 and result.value["published"] >= docked["commands"]


def test_a_rejected_goal_is_a_failure_and_a_deadline_cancels_the_goal_on_the_robot(world: Ros2World):
    import asyncio

    async def calls() -> tuple[Any, Any]:
        async with world.cluster.client() as client:
            rejected = await client.call("fibonacci", {"order": 99})
            late = await client.call("fibonacci", {"order": 40}, deadline_s=0.5)
            return rejected, late

    rejected, late = asyncio.run(calls())
    assert (rejected.status, rejected.outcome) == (Status.FAILURE, "rejected")
    assert rejected.reason == "the action server rejected the goal"
    goals = world.robot.seen("goal")
    assert [(g["order"], g["accepted"]) for g in goals] == [(99, False), (40, True)]
    assert (late.status, late.outcome, late.reason) == (Status.ERROR, "canceled", "deadline")
    cancel = world.robot.wait_for("cancel request", lambda e: e["event"] == "cancel")
    ended = world.robot.wait_for("the goal's end", lambda e: e["event"] == "result")
    assert cancel["goal_id"] == goals[1]["goal_id"] == late.value["goal_id"] and ended["status"] == "CANCELED"


def test_a_goal_left_running_by_a_node_that_died_is_cancelled_when_the_node_restarts(world: Ros2World):
    import asyncio

    async def call() -> Any:
        async with world.cluster.client() as client:
            return await client.call("fibonacci", {"order": 40}, call_id="run-1-count")

    async def start_then_crash() -> None:
        task = asyncio.create_task(call())
        await asyncio.to_thread(world.robot.wait_for, "the goal running", lambda e: e["event"] == "executing")
        world.cluster.kill("robot")  # the petrobot node dies mid-goal (SIGKILL)
        task.cancel()

    asyncio.run(start_then_crash())
    (goal,) = world.robot.seen("goal")
    assert world.robot.seen("cancel") == []
    world.cluster.start("robot", timeout=60.0)
    cancel = world.robot.wait_for("the goal cancelled", lambda e: e["event"] == "cancel")
    ended = world.robot.wait_for("the goal's end", lambda e: e["event"] == "result")
    assert cancel["goal_id"] == goal["goal_id"] == ended["goal_id"] and ended["status"] == "CANCELED"
    # the node answers the call as it ended for the journal: it died with the node
    again = asyncio.run(call())
    assert (again.status, again.reason) == (Status.ERROR, "node_restarted")
    assert len(world.robot.seen("goal")) == 1
