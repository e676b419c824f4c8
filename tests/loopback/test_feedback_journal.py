"""A fast feedback stream from a real node (the demo's ``wait`` at 500 Hz) keeps the journal bounded:
at most ten feedback rows a second of the call, and the last feedback before the result (a real node
on 127.0.0.1, a real service client, the runtime)."""

from __future__ import annotations

import asyncio

from coordinator.events import ActionFeedback, RunEvent
from coordinator.feedback import FEEDBACK_PER_S
from coordinator.journal import Journal
from coordinator.netfile import loads_net
from coordinator.runtime import Runtime
from services.client import ServiceClient
from tests.loopback.node_rig import KEY, running_node

SECONDS = 1.5

STREAM = f"""
[net]
name = "stream"

[[place]]
id = "runs"
kind = "control"
tokens = 1

[[place]]
id = "waiting"
kind = "primitive_task"
task = "w"

[[place]]
id = "done"

[task.w]
actions = [{{ name = "wait", params = {{ seconds = {SECONDS}, step = 0.002 }} }}]

[[transition]]
id = "go"
inputs = {{ runs = 1 }}
outputs = {{ waiting = 1 }}

[[transition]]
id = "finished"
events = ["int:w.ok"]
inputs = {{ waiting = 1 }}
outputs = {{ done = 1 }}
"""


async def test_a_500_hz_feedback_stream_journals_at_most_ten_a_second_and_the_last_one(tmp_path):
    seen: list[ActionFeedback] = []

    def observe(event: RunEvent) -> None:
        if isinstance(event, ActionFeedback):
            seen.append(event)

    async with running_node() as node, ServiceClient(node.location, KEY) as client:
        with Journal(tmp_path / "j.sqlite") as journal:
            runtime = Runtime(loads_net(STREAM, interpreted=False), client, journal, observer=observe)
            summary = await asyncio.wait_for(runtime.run(max_seconds=30), 30)
            kept = journal.feedback_messages(runtime.run_id)
            (result,) = journal.results(runtime.run_id)
    assert summary.end_state == "completed"
    assert len(seen) > 200  # the consoles saw the whole stream
    assert 2 <= len(kept) <= FEEDBACK_PER_S * result.wall_s + 2
    assert kept[-1].data == seen[-1].data == {"fraction": 1.0} and kept[-1].entry < result.entry
    gaps = [b.t_wall - a.t_wall for a, b in zip(kept, kept[1:-1])]
    assert all(gap >= 0.9 / FEEDBACK_PER_S for gap in gaps)  # sampled, not the first burst
