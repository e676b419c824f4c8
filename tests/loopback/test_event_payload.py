"""An external event's payload travels from the node that publishes it to the coordinator's runtime
and the console's blackboard (a real node on 127.0.0.1, a real service client, the runtime and the
console's feed; no browser)."""

from __future__ import annotations

import asyncio
from typing import Any

from coordinator.events import PulseDelivered, RunEvent
from coordinator.journal import Journal
from coordinator.netfile import loads_net
from coordinator.operator import Command, OperatorCommand
from coordinator.runtime import Runtime
from coordinator.web.frames import LiveFeed
from services.client import ServiceClient
from tests.loopback.node_rig import ACTIONS, KEY, running_node

TICKER = ACTIONS + """
[drivers.ticker]
node = "alpha"
impl = "services.actions.demo:Ticker"
params = { period_s = 0.05 }

[events.tick]
node = "alpha"
"""

HEARD = """
[net]
name = "heard"

[[place]]
id = "ear"
tokens = 1

[[place]]
id = "heard"

[[transition]]
id = "hear"
events = ["ext:tick"]
inputs = { ear = 1 }
outputs = { heard = 1 }
"""


async def test_a_published_events_data_reaches_the_runtime_and_the_blackboard_as_its_payload(tmp_path):
    pulses: asyncio.Queue[PulseDelivered] = asyncio.Queue()

    def observe(event: RunEvent) -> None:
        if isinstance(event, PulseDelivered):
            pulses.put_nowait(event)

    async with running_node(TICKER) as node, ServiceClient(node.location, KEY) as client:
        with Journal(tmp_path / "j.sqlite") as journal:
            runtime = Runtime(loads_net(HEARD, interpreted=False), client, journal, observer=observe, operator=True)
            feed = LiveFeed(runtime)
            runtime.add_observer(feed)
            run = asyncio.create_task(runtime.run(max_seconds=30))
            first = await asyncio.wait_for(pulses.get(), 20)
            assert first.event == "ext:tick" and first.fired == 1 and not first.operator
            assert isinstance(first.payload, dict) and first.payload["n"] >= 1  # the Ticker's {"n": k}
            feed.build_frame()
            (shown,) = feed.blackboard("ear")["events"]
            # the latest tick's payload (more may have come since the first)
            assert shown["event"] == "ext:tick" and shown["payload"]["n"] >= first.payload["n"]
            runtime.command(OperatorCommand(Command.ABORT))
            summary: Any = await asyncio.wait_for(run, 20)
    assert summary.final_marking.get("heard") == 1
