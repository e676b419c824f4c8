"""Reflection and relay of the node handshake against a real node process (issue 22, section 1).

All nodes share one key, and every node is both a server and, through its links, a client. With
node ``alpha`` down, a process without the key squats alpha's port; node ``beta`` reaches alpha
for the global memory (its ``remember`` action), so beta's own link connects to the squatter, which
relays beta's outgoing handshake to beta's server. The handshake binds the names of both ends
(docs/protocol.md §3): the relay is refused whether it renames beta's ``hello`` to alpha (beta's
server finds a MAC made for alpha) or not (beta's link finds a node calling itself beta on alpha's
port), and neither side ever sends the squatter a ``welcome``.
"""

from __future__ import annotations

import asyncio
import struct
from typing import Any

import msgpack
import pytest
from tests.integration.cluster import DEMO_SERVICES, Cluster

pytestmark = pytest.mark.integration


async def read_frame(reader: asyncio.StreamReader) -> dict[str, Any] | None:
    try:
        header = await reader.readexactly(4)
        body = await reader.readexactly(struct.unpack(">I", header)[0])
    except (asyncio.IncompleteReadError, ConnectionError):
        return None
    msg = msgpack.unpackb(body, raw=False)
    assert isinstance(msg, dict)
    return msg


def write_frame(writer: asyncio.StreamWriter, msg: dict[str, Any]) -> None:
    body = msgpack.packb(msg, use_bin_type=True)
    writer.write(struct.pack(">I", len(body)) + body)


class Relay:
    """Listens on the squatted port; relays each incoming connection's handshake to ``target``."""

    def __init__(self, target: tuple[str, int], rename: str | None) -> None:
        self.target = target
        self.rename = rename
        self.seen: list[tuple[str, dict[str, Any] | None]] = []  # (from which side, message)
        self.done = asyncio.Event()

    async def handle(self, victim_r: asyncio.StreamReader, victim_w: asyncio.StreamWriter) -> None:
        server_r, server_w = await asyncio.open_connection(*self.target)
        try:
            hello = await read_frame(server_r)
            assert hello is not None and hello["type"] == "hello"
            if self.rename is not None:
                hello["node"] = self.rename
            write_frame(victim_w, hello)  # the victim's link takes the server's nonce
            auth = await read_frame(victim_r)
            self.seen.append(("link", auth))
            if auth is not None:
                write_frame(server_w, auth)  # ... and its MAC goes to its own server
                answer = await read_frame(server_r)
                self.seen.append(("server", answer))
                if answer is not None:
                    write_frame(victim_w, answer)
                    self.seen.append(("link", await read_frame(victim_r)))
        finally:
            for w in (victim_w, server_w):
                w.close()
            self.done.set()


@pytest.mark.parametrize("rename", ["alpha", None], ids=["hello-renamed", "hello-as-is"])
async def test_a_nodes_own_handshake_relayed_to_its_server_from_another_nodes_port_is_refused(
        cluster: Cluster, rename: str | None) -> None:
    cluster.write_services(DEMO_SERVICES)
    cluster.start("beta")  # alpha, the memory node, is down: its port is free for the squatter
    relay = Relay(cluster.location.address("beta"), rename)
    host, port = cluster.location.address("alpha")
    squatter = await asyncio.start_server(relay.handle, host, port)
    try:
        async with cluster.client(connect_timeout_s=5.0) as client:
            res = await client.call("remember", {"key": "k", "value": 1}, deadline_s=10.0)
            await asyncio.wait_for(relay.done.wait(), 10)
    finally:
        squatter.close()
        await squatter.wait_closed()
    assert res.status == "error", res  # beta could not reach its memory
    kinds = [(side, None if m is None else m.get("type"), None if m is None else m.get("reason"))
             for side, m in relay.seen]
    assert all(kind != "welcome" for _, kind, _ in kinds), kinds  # no side opened for the squatter
    log = cluster.log("beta")
    if rename is not None:
        # beta's link sent its auth (for alpha); beta's server refused it as a failed login
        assert kinds[0][:2] == ("link", "auth") and kinds[1] == ("server", "bye", "auth_failed"), kinds
        assert "client node:beta failed authentication" in log, log
    else:
        # beta's link saw a node calling itself beta on alpha's port and sent nothing
        assert kinds[0][0] == "link" and kinds[0][1] in (None, "bye"), kinds
        assert "says it is beta, not 'alpha'" in log, log
