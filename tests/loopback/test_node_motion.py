"""A motion action whose caller is lost is cancelled at once (issue 22, section 2), on a node served in
the test process: the caller's connection closed (a coordinator killed) or silent (frozen, cut off)
for three heartbeat periods. An ordinary action keeps its grace period; an unattended motion runs on.
What the cancelled action does then (brake the robot) is tested on the testbeds with ground truth
(tests/integration/test_mobile.py, test_catching.py)."""

from __future__ import annotations

import asyncio
import time

from node_rig import KEY, eventually, running_node

from services.client import NodeLink
from services.protocol import Call, Connection, Role

ACTIONS = """
[actions.move]
node = "alpha"
impl = "services.actions.demo:wait"
motion = true

[actions.slow]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.glide]
node = "alpha"
impl = "services.actions.demo:wait"
motion = true
unattended = true
"""


async def call_and_lose(node, action: str, cid: str, *, silent: bool  # type: ignore[no-untyped-def]
                        ) -> tuple[float, asyncio.StreamWriter]:
    """Call ``action`` by hand, then lose the caller: abort the connection, or fall silent (no ping,
    nothing read). Returns the loop time the caller was lost at, and its writer (keep it: a silent
    caller's connection stays open)."""
    conn = Connection(Role.CLIENT, KEY, name="coordinator", node=node.name)
    reader, writer = await asyncio.open_connection(node.host, node.port)
    while conn.welcome is None:
        conn.receive_data(await reader.read(65536))
        list(conn.messages())
        writer.write(conn.data_to_send())
    conn.send(Call(id=cid, action=action, params={"seconds": 30.0, "step": 0.01}))
    writer.write(conn.data_to_send())
    await eventually(f"{cid} running", lambda: node._calls.running(cid) is not None)
    lost = asyncio.get_running_loop().time()
    if not silent:
        writer.transport.abort()  # the coordinator process killed: the kernel resets its connection
    return lost, writer


async def outcome(node, cid: str) -> tuple[str, str | None, float]:  # type: ignore[no-untyped-def]
    link = NodeLink("alpha", (node.host, node.port), KEY, name="later", connect_timeout_s=5.0)
    try:
        res = await link.query(cid)
    finally:
        await link.close()
    assert res is not None
    return res.status.value, res.reason, res.wall_s


async def test_a_motion_whose_caller_is_killed_is_cancelled_at_once_and_an_ordinary_call_after_its_grace() -> None:
    # a grace far longer than any stall of a loaded machine, so "at once" and "after the grace" differ
    async with running_node(ACTIONS, peer_timeout_s=10.0) as node:
        await call_and_lose(node, "move", "m-1", silent=False)
        t0 = time.monotonic()
        await eventually("m-1 cancelled", lambda: node._calls.running("m-1") is None, timeout_s=10)
        assert time.monotonic() - t0 < 5.0  # at once: not after the 10 s an ordinary call is given
        status, reason, wall = await outcome(node, "m-1")
        assert (status, reason) == ("error", "caller_gone") and wall < 5.0
        await call_and_lose(node, "slow", "s-1", silent=False)
        await asyncio.sleep(1.0)
        assert node._calls.running("s-1") is not None  # an ordinary action waits for its caller 10 s
        await call_and_lose(node, "glide", "g-1", silent=False)
        await asyncio.sleep(0.5)
        assert node._calls.running("g-1") is not None  # an unattended motion runs on


async def test_a_motion_whose_caller_falls_silent_is_cancelled_after_three_heartbeat_periods() -> None:
    async with running_node(ACTIONS, peer_timeout_s=10.0) as node:
        _, ordinary = await call_and_lose(node, "slow", "s-2", silent=True)  # silent first, for longer
        before = asyncio.get_running_loop().time()  # the caller's last frame is sent after this
        _, writer = await call_and_lose(node, "move", "m-2", silent=True)
        await eventually("m-2 cancelled", lambda: node._calls.running("m-2") is None, timeout_s=10)
        waited = asyncio.get_running_loop().time() - before
        assert node.motion_silence_s <= waited, waited
        # before any ordinary peer is dropped: the ordinary call, silent for longer, still waits for its caller
        assert node._calls.running("s-2") is not None
        status, reason, _ = await outcome(node, "m-2")
        assert (status, reason) == ("error", "caller_gone")
        writer.close()
        ordinary.close()
