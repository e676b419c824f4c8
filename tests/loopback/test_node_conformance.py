"""Conformance: a node driven only by the bytes docs/protocol.md describes.

The client here knows nothing of ``services.protocol``: it writes 4-byte big-endian lengths and
msgpack maps, computes the MACs with the formula of §3, and checks the node's answers against the
rules of §2–§9, section by section. A second implementation written from the specification alone
should pass these tests against the reference node; the reference node must.
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import os
import struct
from collections.abc import AsyncIterator
from typing import Any

import msgpack
import pytest
from node_rig import ACTIONS, KEY, eventually, running_node

from services.node import Node

ORPHAN_GRACE_S = 0.5


def mac(key: bytes, role: bytes, client: str, server: str, nonce_s: bytes, nonce_c: bytes) -> bytes:
    """§3: HMAC-SHA256(K, "petrobot-auth-v2" || 0x00 || role || 0x00 || len(client) || client ||
    len(server) || server || nonce_s || nonce_c), each length a 4-byte big-endian integer."""
    def named(text: str) -> bytes:
        data = text.encode()
        return struct.pack(">I", len(data)) + data

    msg = b"petrobot-auth-v2\x00" + role + b"\x00" + named(client) + named(server) + nonce_s + nonce_c
    return hmac.new(key, msg, hashlib.sha256).digest()


def frame(body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + body


class SpecClient:
    """A raw connection speaking the specification."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        self.hello: dict[str, Any] = {}
        self.nonce = os.urandom(16)

    def send(self, obj: dict[str, Any]) -> None:
        self.writer.write(frame(msgpack.packb(obj, use_bin_type=True)))

    def send_raw(self, data: bytes) -> None:
        self.writer.write(data)

    async def recv(self, timeout: float = 5.0) -> dict[str, Any] | None:
        """The next map, or ``None`` at end of stream."""
        try:
            header = await asyncio.wait_for(self.reader.readexactly(4), timeout)
        except asyncio.IncompleteReadError:
            return None
        (size,) = struct.unpack(">I", header)
        body = await asyncio.wait_for(self.reader.readexactly(size), timeout)
        obj = msgpack.unpackb(body, raw=False)
        assert isinstance(obj, dict) and isinstance(obj.get("type"), str)
        return obj

    async def recv_type(self, kind: str, timeout: float = 5.0) -> dict[str, Any]:
        """The next map that is not a ping (answered) or a feedback (§5: any number may come before a
        result), which must be of type ``kind``."""
        while True:
            got = await self.recv(timeout)
            assert got is not None, f"connection closed while waiting for {kind}"
            if got["type"] == "ping":
                self.send({"type": "pong", "seq": got["seq"]})
                continue
            if got["type"] == "feedback" and kind != "feedback":
                continue
            assert got["type"] == kind, got
            return got

    async def closed_with_bye(self, reason: str, timeout: float = 10.0) -> dict[str, Any]:
        """Read until the node's bye (its reason starts with ``reason``) and then end of stream."""
        while True:
            got = await self.recv(timeout)
            assert got is not None, "closed without a bye"
            if got["type"] == "bye":
                assert got["reason"].startswith(reason), got
                assert await self.recv(timeout) is None  # nothing after bye, then the close
                return got

    async def login(self, key: bytes = KEY, name: str = "spec-client") -> dict[str, Any]:
        self.hello = await self.recv_type("hello")
        self.send({"type": "auth", "client": name, "nonce": self.nonce,
                   "mac": mac(key, b"client", name, self.hello["node"], self.hello["nonce"], self.nonce)})
        return await self.recv_type("welcome")

    async def call(self, cid: str, action: str, params: dict[str, Any] | None = None,
                   **extra: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        self.send({"type": "call", "id": cid, "action": action, "params": params or {}, **extra})
        accepted = await self.recv_type("accepted")
        assert accepted["id"] == cid
        result = await self.recv_type("result", timeout=10.0)
        assert result["id"] == cid
        return accepted, result

    def close(self) -> None:
        self.writer.close()


@pytest.fixture
async def node() -> AsyncIterator[Node]:
    async with running_node(ACTIONS, peer_timeout_s=ORPHAN_GRACE_S) as n:
        yield n


async def connect(node: Node) -> SpecClient:
    reader, writer = await asyncio.open_connection(node.host, node.port)
    return SpecClient(reader, writer)


# --------------------------------------------------------------------------- §2 framing, §3 handshake


async def test_s3_the_node_speaks_first_with_hello_and_authenticates_itself_in_welcome(node: Node) -> None:
    c = await connect(node)
    welcome = await c.login()
    hello = c.hello
    assert set(hello) >= {"type", "node", "version", "nonce"}
    assert (hello["node"], hello["version"]) == ("alpha", 2)
    assert isinstance(hello["nonce"], bytes) and len(hello["nonce"]) == 16
    assert welcome["mac"] == mac(KEY, b"server", "spec-client", "alpha", hello["nonce"], c.nonce)
    assert welcome["actions"] == ["announce", "echo", "wait"]  # sorted
    assert isinstance(welcome["location"], str) and len(welcome["location"]) == 64
    assert welcome["location_changed"] is False
    c.close()


async def test_s3_a_wrong_mac_gets_bye_auth_failed_and_the_connection_closes(node: Node) -> None:
    c = await connect(node)
    hello = await c.recv_type("hello")
    c.send({"type": "auth", "client": "x", "nonce": c.nonce, "mac": mac(b"w" * 32, b"client", "x", "alpha", hello["nonce"], c.nonce)})
    await c.closed_with_bye("auth_failed")


async def test_s3_a_mac_made_for_another_node_or_another_client_name_gets_bye_auth_failed(node: Node) -> None:
    # the client's auth says "x"; its MAC names another node, another client, or the node twice
    for client, server in (("x", "beta"), ("y", "alpha"), ("alpha", "alpha")):
        c = await connect(node)
        hello = await c.recv_type("hello")
        c.send({"type": "auth", "client": "x", "nonce": c.nonce,
                "mac": mac(KEY, b"client", client, server, hello["nonce"], c.nonce)})
        await c.closed_with_bye("auth_failed")


async def test_s3_an_auth_mac_that_is_not_32_bytes_is_a_protocol_error(node: Node) -> None:
    c = await connect(node)
    await c.recv_type("hello")
    c.send({"type": "auth", "client": "x", "nonce": c.nonce, "mac": b"\0" * 31})
    await c.closed_with_bye("protocol_error")


async def test_s3_nothing_is_served_before_authentication(node: Node) -> None:
    c = await connect(node)
    await c.recv_type("hello")
    c.send({"type": "call", "id": "1", "action": "echo", "params": {}})
    await c.closed_with_bye("protocol_error")


async def test_s3_a_handshake_not_finished_by_its_deadline_is_dropped_however_slow_the_bytes(node: Node) -> None:
    loop = asyncio.get_running_loop()
    accepted = loop.time()
    c = await connect(node)
    await c.recv_type("hello")
    auth = frame(msgpack.packb({"type": "auth", "client": "x" * 100, "nonce": c.nonce, "mac": b"\0" * 32}))

    async def trickle() -> None:
        # bytes keep coming through the whole handshake window, never the last one; none is sent
        # after the deadline, when a byte reaching the closed socket would be answered with a reset
        # that can overtake the node's bye on a loaded machine
        for byte in auth[:-1]:
            if loop.time() - accepted > node.caps.handshake_timeout_s - 0.2:
                return
            c.send_raw(bytes([byte]))
            await asyncio.sleep(0.05)

    drip = asyncio.create_task(trickle())
    try:
        await c.closed_with_bye("handshake_timeout", timeout=node.caps.handshake_timeout_s + 5)
    finally:
        drip.cancel()


async def test_s2_before_authentication_a_frame_over_4_kib_is_refused_from_its_header(node: Node) -> None:
    c = await connect(node)
    await c.recv_type("hello")
    c.send_raw(struct.pack(">I", 4097))  # the header alone: the body never comes
    bye = await c.closed_with_bye("protocol_error")
    assert "oversize" in bye["reason"]


@pytest.mark.parametrize("body", [
    b"\xc1",  # not msgpack
    msgpack.packb([1, 2]),  # not a map
    msgpack.packb({"type": "teleport"}),  # unknown type
    msgpack.packb({"type": "call", "id": "1", "action": "echo", "deadline_ms": True}),  # a boolean is no number
    msgpack.packb({"type": "call", "id": "1", "action": "echo", "params": {1: 2}}),  # a key that is no string
    msgpack.packb({"type": "call", "id": "1", "action": "echo", "params": {"t": msgpack.ExtType(1, b"")}}),
    msgpack.packb({"type": "result", "id": "1", "status": "success"}),  # wrong direction
])
async def test_s2_s4_a_malformed_frame_gets_bye_protocol_error_and_only_that_connection_closes(
        node: Node, body: bytes) -> None:
    bystander = await connect(node)
    await bystander.login()
    c = await connect(node)
    await c.login()
    c.send_raw(frame(body))
    await c.closed_with_bye("protocol_error")
    _, result = await bystander.call("b1", "echo", {"still": "here"})
    assert result["value"] == {"still": "here"}
    bystander.close()


async def test_s4_the_frame_of_the_example_is_a_call(node: Node) -> None:
    example = bytes.fromhex(
        "00000046"
        "85"
        "a26964" "b3356630633961316532623364346335662d3137"
        "a6616374696f6e" "a46563686f"
        "a6706172616d73" "81a17801"
        "ab646561646c696e655f6d73" "c0"
        "a474797065" "a463616c6c")
    c = await connect(node)
    await c.login()
    c.send_raw(example)
    assert (await c.recv_type("accepted"))["id"] == "5f0c9a1e2b3d4c5f-17"
    result = await c.recv_type("result")
    assert (result["status"], result["value"]) == ("success", {"x": 1})
    c.close()


async def test_s4_unknown_keys_are_ignored(node: Node) -> None:
    c = await connect(node)
    await c.login()
    c.send({"type": "ping", "seq": 9, "from_the_future": [1, 2]})
    assert await c.recv_type("pong") == {"type": "pong", "seq": 9}
    c.close()


# --------------------------------------------------------------------------- §5 calls


async def test_s5_a_call_is_accepted_then_ends_with_one_result_carrying_every_field(node: Node) -> None:
    c = await connect(node)
    await c.login()
    _, result = await c.call("c1", "echo", {"x": [1, 2]})
    assert result["status"] == "success" and result["value"] == {"x": [1, 2]}
    assert isinstance(result["wall_s"], float) and isinstance(result["cpu_s"], float)
    assert result["outcome"] is None and result["reason"] is None
    c.close()


async def test_s5_a_repeated_id_is_answered_with_the_identical_result_and_another_action_is_a_duplicate(
        node: Node) -> None:
    c = await connect(node)
    await c.login()
    _, first = await c.call("r1", "echo", {"n": 1})
    _, again = await c.call("r1", "echo", {"n": 2})
    assert again == first
    c.send({"type": "call", "id": "r1", "action": "wait", "params": {}})
    assert await c.recv_type("rejected") == {"type": "rejected", "id": "r1", "reason": "duplicate_id"}
    c.close()


async def test_s5_a_query_tells_a_kept_result_joins_a_running_call_and_knows_no_unknown_id(node: Node) -> None:
    c = await connect(node)
    await c.login()
    _, first = await c.call("q1", "echo", {"k": 1})
    c.send({"type": "query", "id": "q1"})
    assert (await c.recv_type("accepted"))["id"] == "q1"
    assert await c.recv_type("result") == first
    c.send({"type": "query", "id": "never-sent"})
    assert await c.recv_type("rejected") == {"type": "rejected", "id": "never-sent", "reason": "unknown_call"}
    c.send({"type": "call", "id": "q2", "action": "wait", "params": {"seconds": 0.3, "step": 1}})
    assert (await c.recv_type("accepted"))["id"] == "q2"
    other = await connect(node)
    await other.login()
    other.send({"type": "query", "id": "q2"})
    assert (await other.recv_type("accepted"))["id"] == "q2"
    assert (await other.recv_type("result"))["status"] == "success"
    assert (await c.recv_type("result"))["status"] == "success"
    c.close()
    other.close()


async def test_s5_calls_over_the_in_flight_cap_are_rejected_busy_in_the_order_received(node: Node) -> None:
    c = await connect(node)
    await c.login()
    for i in range(6):  # one write: the node reads them together (max_in_flight = 4)
        c.send({"type": "call", "id": f"p{i}", "action": "wait", "params": {"seconds": 0.2, "step": 1}})
    answers = [await c.recv_type("accepted") if i < 4 else await c.recv_type("rejected") for i in range(6)]
    assert [a["id"] for a in answers] == [f"p{i}" for i in range(6)]
    assert [a.get("reason") for a in answers[4:]] == ["busy", "busy"]
    ended = {(await c.recv_type("result"))["id"] for _ in range(4)}
    assert ended == {"p0", "p1", "p2", "p3"}
    c.close()


async def test_s5_a_deadline_ends_a_call_with_reason_deadline(node: Node) -> None:
    c = await connect(node)
    await c.login()
    _, result = await c.call("d1", "wait", {"seconds": 10, "step": 1}, deadline_ms=100)
    assert (result["status"], result["reason"]) == ("error", "deadline")
    c.close()


async def test_s5_a_cancel_ends_a_call_with_reason_cancelled_and_an_unknown_cancel_is_ignored(node: Node) -> None:
    c = await connect(node)
    await c.login()
    c.send({"type": "cancel", "id": "nobody"})
    c.send({"type": "call", "id": "k1", "action": "wait", "params": {"seconds": 10, "step": 1}})
    await c.recv_type("accepted")
    c.send({"type": "cancel", "id": "k1"})
    result = await c.recv_type("result")
    assert (result["id"], result["status"], result["reason"]) == ("k1", "error", "cancelled")
    c.close()


async def test_s5_a_cancel_read_with_its_call_before_the_call_starts_still_ends_it(node: Node) -> None:
    # call and cancel in one write: the node admits the call and cancels its task before the task's
    # first step, so the action never runs; the call must still end (it held its slot for ever, and
    # a coordinator resumed after Ctrl-C waited for it until its deadline)
    c = await connect(node)
    await c.login()
    c.send({"type": "call", "id": "k2", "action": "wait", "params": {"seconds": 10, "step": 1}})
    c.send({"type": "cancel", "id": "k2"})
    await c.recv_type("accepted")
    result = await c.recv_type("result")
    assert (result["id"], result["status"], result["reason"]) == ("k2", "error", "cancelled")
    assert result["wall_s"] > 0  # timed by the node: its own word, not a coordinator's guess
    assert node._calls.running("k2") is None and node._calls.in_flight == 0
    c.send({"type": "call", "id": "k2", "action": "wait", "params": {"seconds": 10, "step": 1}})
    await c.recv_type("accepted")
    again = await c.recv_type("result")  # the kept result, not a second run
    assert (again["status"], again["reason"]) == ("error", "cancelled")
    c.close()


async def test_s5_a_call_whose_caller_is_gone_is_cancelled_after_the_grace_and_a_query_tells_so(
        node: Node) -> None:
    c = await connect(node)
    await c.login()
    c.send({"type": "call", "id": "o1", "action": "wait", "params": {"seconds": 30, "step": 1}})
    await c.recv_type("accepted")
    c.close()
    await eventually("the orphaned call ended", lambda: node._calls.running("o1") is None,
                     timeout_s=ORPHAN_GRACE_S + 10)
    later = await connect(node)
    await later.login()
    later.send({"type": "query", "id": "o1"})
    await later.recv_type("accepted")
    result = await later.recv_type("result")
    assert (result["status"], result["reason"]) == ("error", "caller_gone")
    later.close()


# --------------------------------------------------------------------------- §6 heartbeats, §9 events


async def test_s6_a_ping_is_answered_with_a_pong_of_the_same_seq_and_a_silent_peer_is_dropped(node: Node) -> None:
    c = await connect(node)
    await c.login()
    c.send({"type": "ping", "seq": 2**40})
    assert await c.recv_type("pong") == {"type": "pong", "seq": 2**40}
    await c.closed_with_bye("heartbeat_timeout", timeout=ORPHAN_GRACE_S + 10)


async def test_s9_a_subscriber_gets_events_numbered_per_topic(node: Node) -> None:
    c = await connect(node)
    await c.login()
    c.send({"type": "subscribe", "topic": "shout"})
    for word in ("a", "b"):
        c.send({"type": "call", "id": f"s-{word}", "action": "announce", "params": {"topic": "shout", "data": word}})
    events, results = [], 0
    while results < 2:  # events and the calls' answers interleave
        got = await c.recv()
        assert got is not None
        if got["type"] == "event":
            events.append(got)
        results += got["type"] == "result"
    seen = [(e["topic"], e["seq"], e["data"]) for e in events]
    assert seen == [("shout", 1, "a"), ("shout", 2, "b")] and all(isinstance(e["t"], float) for e in events)
    c.close()
