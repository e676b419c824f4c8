"""The node health the web console shows (connected, heartbeat round trip, calls in flight) comes
from the client's read-only ``health()``, here against a real node on 127.0.0.1."""

from __future__ import annotations

import asyncio

from node_rig import KEY, eventually, running_node

from services.client import ServiceClient


async def test_the_client_reports_each_nodes_connection_heartbeat_round_trip_and_calls_in_flight():
    async with running_node() as node, ServiceClient(node.location, KEY, heartbeat_s=0.05) as client:
        assert client.health() == {"alpha": {"connected": False, "heartbeat_rtt_s": None, "in_flight": 0}}
        call = asyncio.ensure_future(client.call("wait", {"seconds": 0.5}))
        await eventually("the call to be in flight", lambda: client.health()["alpha"]["in_flight"] == 1)
        await eventually("a heartbeat to be answered",
                         lambda: client.health()["alpha"]["heartbeat_rtt_s"] is not None, timeout_s=30)
        health = client.health()["alpha"]
        assert health["connected"] is True and health["heartbeat_rtt_s"] > 0
        result = await asyncio.wait_for(call, 60)
        assert result.ok, result
        assert client.health()["alpha"]["in_flight"] == 0
