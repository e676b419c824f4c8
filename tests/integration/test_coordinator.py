"""The coordinator runs task nets whose primitive actions live on real node processes (127.0.0.1)."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from coordinator.errors import JournalError
from coordinator.events import ActionEnded, ActionStarted, TransitionFired
from coordinator.journal import Journal, JournalReader
from coordinator.netfile import loads_net
from coordinator.operator import Command, OperatorCommand
from coordinator.runtime import Runtime
from services.client import ServiceClient
from services.results import Status

ROOT = Path(__file__).resolve().parents[2]
Cluster = Any  # the `cluster` fixture of conftest.py

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]

TWO_NODE_NET = """
[net]
name = "two_nodes"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "robot"
kind = "resource"
tokens = 1

[[place]]
id = "sensing"
kind = "primitive_task"
task = "sense"

[[place]]
id = "computing"
kind = "primitive_task"
task = "compute"

[[place]]
id = "done"

[[place]]
id = "failed"

[task.sense]
actions = [{ name = "echo", params = { x = 1 } }]
deadline_s = 5.0

[task.compute]
actions = [{ name = "SLOW_ACTION", params = { seconds = SECONDS } }]
deadline_s = 30.0

[[transition]]
id = "start"
inputs = { runs = 1, robot = 1 }
outputs = { sensing = 1 }

[[transition]]
id = "sensed"
events = ["int:sense.ok"]
inputs = { sensing = 1 }
outputs = { computing = 1 }

[[transition]]
id = "sense_error"
events = ["int:sense.error"]
hidden = true
inputs = { sensing = 1 }
outputs = { robot = 1, failed = 1 }

[[transition]]
id = "computed"
events = ["int:compute.ok"]
inputs = { computing = 1 }
outputs = { robot = 1, done = 1 }

[[transition]]
id = "compute_error"
events = ["int:compute.error"]
hidden = true
inputs = { computing = 1 }
outputs = { robot = 1, failed = 1 }
"""


def two_node_net(action: str = "wait", seconds: float = 0.05):
    return loads_net(TWO_NODE_NET.replace("SLOW_ACTION", action).replace("SECONDS", str(seconds)))


async def run_net(cluster: Cluster, net, journal_path: Path, *, key: bytes | None = None,
                  commands=(), max_seconds: float = 30.0):
    events: list = []
    with Journal(journal_path) as journal:
        async with ServiceClient(cluster.location, key or cluster.key) as client:
            runtime = Runtime(net, client, journal, seed=3, observer=events.append)
            for cmd in commands:
                runtime.command(cmd)
            summary = await runtime.run(max_seconds=max_seconds)
    return summary, events


def nodes_of(journal_path: Path) -> dict[str, set[str]]:
    with JournalReader.open(journal_path) as journal:
        rows = journal.results()
    out: dict[str, set[str]] = {}
    for row in rows:
        out.setdefault(row.action, set()).add(row.node)
    return out


async def test_a_net_runs_with_its_actions_on_two_nodes(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    summary, events = await run_net(cluster, two_node_net("slow"), tmp_path / "j.sqlite")
    assert summary.end_state == "completed"
    assert summary.final_marking == {"robot": 1, "done": 2}
    assert nodes_of(tmp_path / "j.sqlite") == {"echo": {"alpha"}, "slow": {"beta"}}
    fired = [e.firing.transition for e in events if isinstance(e, TransitionFired)]
    assert fired == ["start", "sensed", "computed", "start", "sensed", "computed"]


async def test_moving_an_action_to_another_node_is_an_edit_of_services_toml_only(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    net = two_node_net("slow")
    await run_net(cluster, net, tmp_path / "before.sqlite")
    assert nodes_of(tmp_path / "before.sqlite")["slow"] == {"beta"}
    text = cluster.services_path.read_text()
    moved = text.replace('[actions.slow]\nnode = "beta"', '[actions.slow]\nnode = "alpha"')
    assert moved != text
    cluster.services_path.write_text(moved)
    cluster._location = None
    cluster.restart("alpha")
    summary, _ = await run_net(cluster, net, tmp_path / "after.sqlite")
    assert summary.final_marking == {"robot": 1, "done": 2}
    assert nodes_of(tmp_path / "after.sqlite")["slow"] == {"alpha"}


async def test_a_node_killed_mid_action_takes_the_error_branch_and_loses_no_token(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    net = two_node_net("slow", seconds=20.0).with_initial_marking({"runs": 1, "robot": 1})
    killed_at: list[float] = []

    async def killer():
        while not any(isinstance(e, ActionStarted) and e.action == "slow" for e in seen):
            await asyncio.sleep(0.02)
        await asyncio.sleep(0.2)
        cluster.kill("beta")
        killed_at.append(time.monotonic())

    seen: list = []
    with Journal(tmp_path / "j.sqlite") as journal:
        async with ServiceClient(cluster.location, cluster.key) as client:
            runtime = Runtime(net, client, journal, observer=seen.append)
            kill_task = asyncio.create_task(killer())
            summary = await runtime.run(max_seconds=30)
            await kill_task
    results = [e.result for e in seen if isinstance(e, ActionEnded) and e.action == "slow"]
    assert results and results[0].status is Status.ERROR
    assert killed_at
    assert summary.final_marking == {"robot": 1, "failed": 1}
    fired = [e.firing.transition for e in seen if isinstance(e, TransitionFired)]
    assert fired[-1] == "compute_error"
    # the node stayed dead: the call given up on could not be reconciled, and the summary says so
    (line,) = summary.unreconciled
    assert line.startswith("slow on beta [") and "unreachable" in line


async def test_a_call_whose_node_died_is_reconciled_once_the_node_is_back_and_never_run_again(
        cluster: Cluster, tmp_path: Path):
    from coordinator.events import CallReconciled

    cluster.write_services()
    cluster.start("alpha", "beta")
    net = two_node_net("slow", seconds=20.0).with_initial_marking({"runs": 1, "robot": 1})
    seen: list = []

    async def crash_and_restart():
        while not any(isinstance(e, ActionStarted) and e.action == "slow" for e in seen):
            await asyncio.sleep(0.02)
        cluster.kill("beta")
        while not any(isinstance(e, ActionEnded) and e.action == "slow" for e in seen):
            await asyncio.sleep(0.02)
        await asyncio.to_thread(cluster.start, "beta")

    with Journal(tmp_path / "j.sqlite") as journal:
        async with ServiceClient(cluster.location, cluster.key) as client:
            runtime = Runtime(net, client, journal, observer=seen.append, reconcile_s=120.0)
            chaos = asyncio.create_task(crash_and_restart())
            summary = await runtime.run(max_seconds=120)
            await chaos
        (rec,) = journal.reconciliations()
    (event,) = [e for e in seen if isinstance(e, CallReconciled)]
    assert (rec.status, rec.reason, rec.assumed, rec.differs) == ("error", "node_restarted", "error", False)
    assert event.instance == rec.instance and not event.differs
    assert summary.reconciled == 1 and summary.unreconciled == ()
    assert cluster.log("beta").count(f"call {rec.instance} slow from") == 1


async def test_an_error_result_arrives_from_the_heartbeat_when_a_node_falls_silent(cluster: Cluster, tmp_path: Path):
    # The detection time (three 0.25 s heartbeat periods) is measured by bench/faults.py; here the
    # test asserts the cause: the call ends on the heartbeat timeout, long before its 20 s action.
    cluster.write_services()
    cluster.start("alpha", "beta")
    async with ServiceClient(cluster.location, cluster.key) as client:
        call = asyncio.create_task(client.call("slow", {"seconds": 20.0}))
        await asyncio.sleep(0.5)
        cluster.kill("beta", signal.SIGSTOP)  # a hung host: no FIN, no RST, only silence
        t0 = time.monotonic()
        result = await asyncio.wait_for(call, 10)
        elapsed = time.monotonic() - t0
        cluster.kill("beta", signal.SIGCONT)
    assert result.status == "error"
    assert "heartbeat" in (result.reason or "") + (result.outcome or ""), result
    assert elapsed < 20.0, "the error came from the action's end, not from the node's silence"


async def test_a_coordinator_with_a_wrong_key_is_refused_and_takes_the_error_branch(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    net = two_node_net("slow").with_initial_marking({"runs": 1, "robot": 1})
    summary, events = await run_net(cluster, net, tmp_path / "j.sqlite", key=b"not the key" * 3)
    results = [e.result for e in events if isinstance(e, ActionEnded)]
    assert results[0].status is Status.ERROR
    assert "auth" in (results[0].reason or "").lower() or "key" in (results[0].reason or "").lower()
    assert summary.final_marking == {"robot": 1, "failed": 1}
    assert "auth" in cluster.log("alpha").lower() or "refus" in cluster.log("alpha").lower()


async def test_operator_removing_runs_stops_the_experiment_early(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    net = two_node_net("slow", seconds=0.3).with_initial_marking({"runs": 4, "robot": 1})
    summary, _ = await run_net(cluster, net, tmp_path / "j.sqlite",
                               commands=[OperatorCommand(Command.REMOVE, "runs", 3)])
    assert summary.final_marking == {"robot": 1, "done": 1}
    with JournalReader.open(tmp_path / "j.sqlite") as journal:
        commands = journal.operator_commands()
    assert [(c.command, c.place, c.count) for c in commands] == [("remove", "runs", 3)]


TICK_NET = """
[net]
name = "ticks"

[[place]]
id = "runs"
kind = "control"
tokens = 3

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


async def test_external_events_from_a_node_driver_fire_transitions_as_pulses(cluster: Cluster, tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    summary, events = await run_net(cluster, loads_net(TICK_NET), tmp_path / "j.sqlite", max_seconds=20)
    assert summary.final_marking == {"shots": 3}
    pulses = [e.firing.pulse for e in events if isinstance(e, TransitionFired) and e.firing.transition == "shoot"]
    assert pulses == ["ext:tick"] * 3


@pytest.mark.slow
def test_a_killed_coordinator_resumes_from_the_journal_without_running_an_action_twice(cluster: Cluster,
                                                                                        tmp_path: Path):
    cluster.write_services()
    cluster.start("alpha", "beta")
    net_path = tmp_path / "net.toml"
    net_path.write_text(TWO_NODE_NET.replace("SLOW_ACTION", "tally").replace("params = { seconds = SECONDS }",
                                                                             "params = { key = \"k\" }")
                        .replace('{ name = "echo", params = { x = 1 } }', '{ name = "slow", params = { seconds = 1.5 } }'))
    journal = tmp_path / "j.sqlite"
    cmd = [sys.executable, "-m", "coordinator.cli", "run", str(net_path), "--services", str(cluster.services_path),
           "--journal", str(journal), "--key-file", str(cluster.key_file), "--lines", "--no-input"]
    env = cluster.env()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:  # wait until the first 'slow' call has been journaled
        time.sleep(0.1)
        if journal.exists():
            try:
                with JournalReader.open(journal) as reader:
                    if any(s.action == "slow" for s in reader.starts()):
                        break
            except JournalError:  # the coordinator has not created its tables yet
                continue
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    done = subprocess.run(cmd + ["--resume"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    with JournalReader.open(journal) as reader:
        runs = reader.runs()
        assert len(runs) == 1 and runs[0].end_state == "completed"
        starts = [s for s in reader.starts() if s.action == "slow"]
        assert len(starts) == 2  # two runs; the interrupted call was re-issued, not started anew
    assert "{'robot': 1, 'done': 2}" in done.stdout or "'done': 2" in done.stdout
    # tally counts in global memory how often the compute action really ran: once per run
    with Journal(journal) as j:
        values = [r for r in j.results() if r.action == "tally"]
    assert len(values) == 2


async def test_the_learner_continues_where_it_stopped_after_a_restart_of_the_coordinator(cluster: Cluster,
                                                                                        tmp_path: Path):
    from coordinator.session import build_learner, execute

    cluster.write_services()
    cluster.start("alpha", "beta")
    text = TWO_NODE_NET.replace(
        '[task.compute]\nactions = [{ name = "SLOW_ACTION", params = { seconds = SECONDS } }]',
        '[task.compute]\nactions = [{ name = "echo", cost = 1.0 }, { name = "slow", params = { seconds = 0.01 }, '
        'cost = 2.0 }]\nlearner = { scheme = "pursuit", rate = 0.2, warmup = 1 }')
    net = loads_net(text).with_initial_marking({"runs": 3, "robot": 1})
    path = tmp_path / "j.sqlite"
    quiet = lambda kind, info: None  # noqa: E731
    with Journal(path) as journal:
        await execute(net, location=cluster.location, key=cluster.key, journal=journal, seed=1, observer=quiet)
        stored = journal.learner_states()["compute"]
        scheme, saved = stored.scheme, stored.state
        reloaded = build_learner(net, 1, journal).automaton("compute")
    assert scheme == "pursuit"
    assert reloaded.state_dict() == saved
    assert reloaded.steps == 3
    with Journal(path) as journal:
        await execute(net, location=cluster.location, key=cluster.key, journal=journal, seed=1, observer=quiet)
        after = journal.learner_states()["compute"].state
        assert build_learner(net, 1, journal).automaton("compute").steps == 6
    assert after != saved
