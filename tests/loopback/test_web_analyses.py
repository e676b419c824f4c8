"""The console's analyses agree with the command line: the page runs them on the journal it has open
(a console on 127.0.0.1 over a journal of real results, its WebSocket, and `petrobot gspn` itself)."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from pathlib import Path

import aiohttp

from coordinator.journal import Journal
from coordinator.netfile import loads_net
from coordinator.runtime import Runtime
from coordinator.web.draft import draft_of_net
from coordinator.web.server import ConsoleConfig, ConsoleServer
from services.results import ActionResult, Status
from tests.unit.runtime_fakes import FakeClient

ROOT = Path(__file__).resolve().parents[2]

# the net file says a grasp takes 5 s and succeeds 9 times in 10; the journal says 0.5 s and 1 in 2
GRASPING = """
[net]
name = "grasping"
home = { hand = 1 }

[[place]]
id = "runs"
kind = "control"
tokens = 4

[[place]]
id = "hand"
kind = "resource"
tokens = 1

[[place]]
id = "grasping"
kind = "primitive_task"
task = "grasp"

[[place]]
id = "held"

[[place]]
id = "dropped"

[task.grasp]
actions = ["grasp"]
mean_time_s = 5.0
reliability = 0.9

[[transition]]
id = "start"
inputs = { runs = 1, hand = 1 }
outputs = { grasping = 1 }

[[transition]]
id = "grasped"
events = ["int:grasp.success"]
inputs = { grasping = 1 }
outputs = { hand = 1, held = 1 }

[[transition]]
id = "slipped"
events = ["int:grasp.failure"]
inputs = { grasping = 1 }
outputs = { hand = 1, dropped = 1 }

[[transition]]
id = "grasp_failed"
events = ["int:grasp.error"]
hidden = true
inputs = { grasping = 1 }
outputs = { hand = 1, dropped = 1 }
"""


def _grasps() -> object:
    """Every other grasp slips; each takes 0.5 s on the node."""
    calls = iter(range(1000))

    def grasp(params: dict[str, object]) -> ActionResult:
        if next(calls) % 2:
            return ActionResult(status=Status.FAILURE, outcome="slipped", wall_s=0.5)
        return ActionResult(status=Status.SUCCESS, wall_s=0.5)
    return grasp


async def test_the_consoles_gspn_reads_the_journal_it_has_open_as_the_command_line_does(tmp_path: Path):
    net = loads_net(GRASPING)
    journal = tmp_path / "journal.sqlite"
    with Journal(journal) as j:
        summary = await Runtime(net, FakeClient({"grasp": _grasps()}), j).run(max_seconds=60)
    assert summary.end_state == "completed" and summary.calls == 4
    net_file = tmp_path / "grasping.toml"
    net_file.write_text(GRASPING)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cli = subprocess.run([sys.executable, "-m", "coordinator.cli", "gspn", str(net_file), "--journal", str(journal)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert cli.returncode == 0, cli.stderr

    server = ConsoleServer(ConsoleConfig(root=tmp_path, nets=[net_file], journal=journal))
    await server.start()
    try:
        async with aiohttp.ClientSession() as session, session.ws_connect(
                f"ws://127.0.0.1:{server.port}/ws", headers={"Origin": f"http://127.0.0.1:{server.port}"}) as ws:
            await ws.send_str(json.dumps({"type": "hello", "v": 1, "token": server.token}))
            await ws.send_str(json.dumps({"type": "analyze", "id": 1, "kind": "gspn", "draft": draft_of_net(net)}))

            async def reply() -> dict[str, object]:
                while True:
                    msg = json.loads((await ws.receive()).data)
                    if msg["type"] == "reply" and msg["id"] == 1:
                        return msg
            answer = await asyncio.wait_for(reply(), 120)
    finally:
        await server.close()
    report = answer["report"]
    assert answer["ok"] and report["exit"] == 0, answer
    assert f"--journal {journal}" in report["command"]
    assert report["stdout"] == cli.stdout.replace(str(net_file), "grasping.toml")
    assert "mean time to absorption 2 s" in report["stdout"]  # 4 grasps of 0.5 s (the journal), not of 5 s
