"""A node under hostile peers on loopback: every resource bounded, legitimate clients served.

Each test names the attack it stands for (docs/protocol.md §6, "Connection limits", and §8):
slow handshakes, connection floods, partial frames before authentication, failed-login floods,
forged log lines, peers that do not read, subscriptions and calls left behind by a closed
connection, and key rotation.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct

import msgpack
import pytest
from node_rig import ACTIONS, KEY, eventually, running_node

from services.client import NodeLink, ServiceClient
from services.node import Node
from services.node.guard import Caps
from services.node.peer import Peer
from services.protocol import Bye, Call, Connection, Role, Subscribe

SMALL_CAPS = Caps(max_open=32, max_open_per_host=16, max_pending=16, max_pending_per_host=8, handshake_timeout_s=1.0)


def link(node: Node, key: bytes = KEY, source: str | None = None) -> NodeLink:
    return NodeLink("alpha", (node.host, node.port), key, connect_timeout_s=5.0,
                    local_addr=(source, 0) if source else None)


async def raw(node: Node, source: str | None = None) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection(node.host, node.port, local_addr=(source, 0) if source else None)


async def logged_in(node: Node) -> tuple[Connection, asyncio.StreamReader, asyncio.StreamWriter]:
    """An authenticated connection driven by hand (the protocol's own sans-IO client)."""
    conn = Connection(Role.CLIENT, KEY, name="by-hand", node=node.name)
    reader, writer = await raw(node)
    while conn.welcome is None:
        conn.receive_data(await reader.read(65536))
        list(conn.messages())
        writer.write(conn.data_to_send())
    return conn, reader, writer


def peers_of(node: Node, name: str) -> list[Peer]:
    return [p for p in node._peers if p.conn.peer == name]


async def test_slow_handshakes_are_dropped_at_the_deadline_while_a_client_is_served() -> None:
    async with running_node(caps=SMALL_CAPS) as node:
        writers = []
        for _ in range(40):
            _, w = await raw(node)
            writers.append(w)

        async def trickle() -> None:
            while True:
                for w in writers:
                    if not w.is_closing():
                        w.write(b"\x00")
                await asyncio.sleep(0.1)

        drip = asyncio.create_task(trickle())
        try:
            assert node._guard.pending <= SMALL_CAPS.max_pending_per_host
            client = link(node)
            res = await client.call("echo", {"during": "flood"})
            assert (res.status, res.value) == ("success", {"during": "flood"})
            await client.close()
            await eventually("every slow handshake was dropped", lambda: node._guard.pending == 0)
        finally:
            drip.cancel()
            for w in writers:
                w.close()


async def test_a_connection_flood_keeps_pending_handshakes_within_the_caps() -> None:
    async with running_node(caps=SMALL_CAPS) as node:
        most = 0
        writers = []
        for i in range(200):
            _, w = await raw(node, source=f"127.0.1.{i % 4 + 1}")
            writers.append(w)
            most = max(most, node._guard.pending)
        await asyncio.sleep(0.05)
        assert most <= SMALL_CAPS.max_pending + 1
        assert node._guard.pending <= SMALL_CAPS.max_pending
        client = link(node)
        assert (await client.call("echo")).status == "success"
        await client.close()
        for w in writers:
            w.close()


async def test_partial_16_mib_frames_before_authentication_are_refused_from_the_header() -> None:
    async with running_node() as node:
        streams = []
        for _ in range(20):
            reader, writer = await raw(node)
            writer.write(struct.pack(">I", 16 * 1024 * 1024) + b"x" * 1024)
            streams.append((reader, writer))
        for reader, writer in streams:
            data = await asyncio.wait_for(reader.read(), 10)  # to end of stream: the node closed it
            assert b"oversize frame" in data
            writer.close()
        assert node._guard.pending == 0 and not node._peers


async def test_failed_logins_are_throttled_per_address_and_other_addresses_are_served() -> None:
    async with running_node() as node:
        refused_at = None
        for attempt in range(40):
            reader, writer = await raw(node, source="127.0.0.3")
            first = await asyncio.wait_for(reader.read(4096), 5)
            conn = Connection(Role.CLIENT, b"wrong key, long enough", name="guesser", node=node.name)
            conn.receive_data(first)
            msg = next(conn.messages(), None)
            writer.write(conn.data_to_send())
            if isinstance(msg, Bye):
                assert msg.reason == "auth_throttled"
                refused_at = attempt
                writer.close()
                break
            await asyncio.wait_for(reader.read(), 5)  # bye auth_failed, then the close
            writer.close()
        assert refused_at is not None and refused_at <= 25
        good = link(node)
        assert (await good.call("echo")).status == "success"  # from 127.0.0.1
        await good.close()


async def test_a_process_failing_logins_does_not_lock_out_a_client_of_the_same_host_that_logged_in_before() -> None:
    """Issue 22: 20 wrong keys from 127.0.0.1 throttled every client there, the coordinator included."""
    async with running_node() as node:
        coordinator = link(node, source="127.0.0.4")
        assert (await coordinator.call("echo")).status == "success"  # 127.0.0.4 logged in: it is known
        await coordinator.close()
        stop = asyncio.Event()
        answers: list[str] = []

        async def guesser() -> None:  # a process of the same host with a wrong key, retrying at once
            while not stop.is_set():
                reader, writer = await raw(node, source="127.0.0.4")
                conn = Connection(Role.CLIENT, b"a wrong key, long enough", name="guesser", node=node.name)
                try:
                    while conn.state.name != "CLOSED":
                        data = await asyncio.wait_for(reader.read(4096), 5)
                        conn.receive_data(data)
                        for msg in conn.messages():
                            if isinstance(msg, Bye):
                                answers.append(msg.reason)
                        writer.write(conn.data_to_send())
                except Exception:  # noqa: BLE001 - refused: try again
                    pass
                finally:
                    writer.close()

        task = asyncio.create_task(guesser())
        try:
            await eventually("30 failed logins", lambda: len(answers) >= 30, timeout_s=20)  # past the throttle's 20
            for _ in range(3):
                again = NodeLink("alpha", (node.host, node.port), KEY, connect_timeout_s=1.0,
                                 local_addr=("127.0.0.4", 0))
                assert (await again.call("echo")).status == "success"
                await again.close()
        finally:
            stop.set()
            await task
        assert "auth_failed" in answers


async def test_untrusted_text_is_logged_escaped_short_and_rate_limited(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "petrobot.node")
    evil = "bye\n2026-11-21 10:00:00 alpha INFO forged line\x1b[2J\x00" + "A" * 3000
    async with running_node() as node:
        for i in range(60):
            reader, writer = await raw(node)
            await reader.read(4096)  # hello
            body = msgpack.packb({"type": "bye", "reason": evil}) if i % 2 else b"\xc1" + evil.encode()[:2000]
            writer.write(struct.pack(">I", len(body)) + body)
            await asyncio.wait_for(reader.read(), 5)
            writer.close()
    text = "\n".join(r.getMessage() for r in caplog.records)
    assert "forged line" in text  # shown, escaped
    for r in caplog.records:
        line = r.getMessage()
        assert "\x1b" not in line and "\x00" not in line and "\n" not in line and len(line) < 600
    assert text.count("unauthenticated 127.0.0.1 said bye") <= 5
    assert text.count("bad frame from") <= 5


async def test_a_peer_that_does_not_read_cannot_make_the_node_hold_its_answers() -> None:
    async with running_node(max_output=256 * 1024) as node:
        good = link(node)
        big = {"blob": b"x" * (128 * 1024)}
        assert (await good.call("echo", big, call_id="big")).status == "success"
        conn, _reader, writer = await logged_in(node)
        conn.send(Call(id="slow-feedback", action="wait", params={"seconds": 1.0, "step": 0.01}))
        for _ in range(2000):  # 2000 answers of 128 KiB asked for in one write, none read
            conn.send(Call(id="big", action="echo", params=big))
        writer.write(conn.data_to_send())
        peer = None
        await eventually("the node stopped reading from the peer", lambda: any(
            not p.reading for p in peers_of(node, "by-hand")))
        peer = peers_of(node, "by-hand")[0]
        for _ in range(20):
            assert peer.output_backlog <= 256 * 1024 + 2 * (128 * 1024 + 1024)
            await asyncio.sleep(0.05)
        res = await good.call("echo", {"meanwhile": True})  # the node serves others all along
        assert res.status == "success"
        await eventually("feedback to the stalled peer was dropped", lambda: peer.dropped_feedback > 0)
        writer.close()
        await good.close()


async def test_subscriptions_are_capped_per_connection_and_forgotten_when_it_closes() -> None:
    async with running_node() as node:
        conn, _reader, writer = await logged_in(node)
        for i in range(300):
            conn.send(Subscribe(topic=f"topic-{i}"))
        conn.send(Subscribe(topic="t" * 300))
        writer.write(conn.data_to_send())
        await eventually("subscriptions processed", lambda: any(
            len(node._fanout.topics(p)) == 256 for p in peers_of(node, "by-hand")))
        peer = peers_of(node, "by-hand")[0]
        assert "t" * 300 not in node._fanout.topics(peer)
        writer.close()
        await eventually("the closed connection's subscriptions are gone", lambda: not node._fanout._subs
                         and not node._fanout._topics)


async def test_calls_left_by_a_closed_connection_do_not_keep_the_node_busy() -> None:
    async with running_node(peer_timeout_s=0.5) as node:  # max_in_flight = 4
        first = link(node)
        calls = [asyncio.create_task(first.call("wait", {"seconds": 15, "step": 1})) for _ in range(4)]
        await eventually("four calls running", lambda: node._calls.in_flight == 4)
        second = link(node)
        assert (await second.call("echo")).reason == "busy"
        await first.close()
        assert [r.status for r in await asyncio.gather(*calls)] == ["error"] * 4
        await eventually("the orphaned calls were cancelled", lambda: node._calls.in_flight == 0)
        assert (await second.call("echo")).status == "success"
        await second.close()


async def test_an_unattended_action_finishes_after_its_caller_left() -> None:
    actions = ACTIONS + '\n[actions.move]\nnode = "alpha"\nimpl = "services.actions.demo:wait"\nunattended = true\n'
    async with running_node(actions, peer_timeout_s=0.3) as node:
        first = link(node)
        task = asyncio.create_task(first.call("move", {"seconds": 1.0, "step": 1}, call_id="m1"))
        await eventually("the move runs", lambda: node._calls.running("m1") is not None)
        await first.close()
        await task
        await eventually("the move finished", lambda: node._calls.running("m1") is None)
        later = link(node)
        res = await later.query("m1")
        assert res is not None and res.status == "success" and res.value["waited_s"] >= 1.0
        await later.close()


async def test_a_previous_key_is_accepted_during_a_rotation_with_a_warning(caplog: pytest.LogCaptureFixture) -> None:
    old = b"the previous shared key, 32 bytes"
    async with running_node(previous_keys=[old]) as node:
        legacy = link(node, key=old)
        assert (await legacy.call("echo")).status == "success"
        current = link(node)
        assert (await current.call("echo")).status == "success"
        stranger = link(node, key=b"never was a key of this node....")
        assert "auth" in ((await stranger.call("echo")).reason or "")
        for c in (legacy, current, stranger):
            await c.close()
    assert "authenticated with a previous key" in caplog.text


async def test_a_handshake_over_the_open_connection_cap_gets_only_a_bye() -> None:
    caps = Caps(max_open=2, max_open_per_host=2)
    async with running_node(caps=caps) as node:
        held = [link(node), link(node)]
        for c in held:
            assert (await c.call("echo")).status == "success"
        conn = Connection(Role.CLIENT, KEY, name="third", node=node.name)
        reader, writer = await raw(node)
        got = []
        while conn.state.name != "CLOSED":
            data = await asyncio.wait_for(reader.read(65536), 10)
            conn.receive_data(data)
            got.extend(conn.messages())
            writer.write(conn.data_to_send())
        assert [type(m).__name__ for m in got] == ["Hello", "Bye"] and got[-1].reason == "overloaded"
        writer.close()
        for c in held:
            await c.close()


async def test_a_preflight_tries_a_busy_node_again_until_its_deadline() -> None:
    """Issue 22: under a flood a real petrobot run failed its preflight 4 times of 5 ("node
    unreachable") although the node was up; a node that refuses connections at a limit is now tried
    again until the preflight's deadline."""
    caps = Caps(accept_burst=1, accepts_per_s=0.5)  # one connection, then one every 2 s
    async with running_node(caps=caps) as node:
        with socket.create_connection((node.host, node.port)):  # takes the token
            pass
        async with ServiceClient(node.location, KEY, connect_timeout_s=0.3) as client:
            assert await client.preflight(["echo"], deadline_s=10.0) == []
        with socket.create_connection((node.host, node.port)):
            pass
        async with ServiceClient(node.location, KEY, connect_timeout_s=0.3) as client:
            problems = await client.preflight(["echo"], deadline_s=0.5)
        assert len(problems) == 1 and "overloaded" in problems[0] and "busy" in problems[0], problems
