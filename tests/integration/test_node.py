"""Real node processes on 127.0.0.1 served to a real ServiceClient (docs/protocol.md behaviour)."""

from __future__ import annotations

import asyncio
import signal
import socket
import struct
import time

import pytest
from tests.integration.cluster import Cluster
from waiting import eventually, log_says

from services.client import NodeLink
from services.protocol import Bye, Connection, Role

pytestmark = pytest.mark.integration


async def test_calls_reach_actions_on_two_nodes(cluster: Cluster) -> None:
    cluster.start("alpha", "beta")
    async with cluster.client() as client:
        a, b = await asyncio.gather(client.call("echo", {"x": [1, 2]}), client.call("compute_primes"))
    assert (a.status, a.value) == ("success", {"x": [1, 2]})
    assert (b.status, b.value) == ("success", {"n": 100000, "count": 9592})
    assert " echo from " in cluster.log("alpha") and " echo from " not in cluster.log("beta")
    assert " compute_primes from " in cluster.log("beta") and " compute_primes from " not in cluster.log("alpha")
    assert b.cost is not None and b.cost > 0 and b.wall_s > 0


async def test_global_memory_is_shared_across_nodes(cluster: Cluster) -> None:
    cluster.start("alpha", "beta")
    async with cluster.client() as client:
        res = await client.call("remember", {"key": "ball", "value": [0.1, 0.2]})  # runs on beta
        assert (res.status, res.value) == ("success", [0.1, 0.2])
        got = await client.call("memory.get", {"key": "ball"})  # served by alpha
        assert got.value == [0.1, 0.2] and " memory.get from " in cluster.log("alpha")
        keys = await client.call("memory.keys")
        assert keys.value == ["ball"]


async def test_a_wrong_key_is_refused(cluster: Cluster) -> None:
    cluster.start("alpha")
    from services.client import ServiceClient

    async with ServiceClient(cluster.location, b"not the key") as client:
        res = await client.call("echo")
    assert res.status == "error"
    assert res.reason is not None and "auth" in res.reason
    assert "refused" in cluster.log("alpha") or "auth" in cluster.log("alpha")


async def test_a_repeated_call_id_is_not_run_twice(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        first = await client.call("tally", {"key": "n"}, call_id="run1-t1")
        again = await client.call("tally", {"key": "n"}, call_id="run1-t1")
        other = await client.call("tally", {"key": "n"}, call_id="run1-t2")
        clash = await client.call("echo", call_id="run1-t1")  # the same id for another action
    assert first.value == 1 and again.value == 1 and other.value == 2
    assert (clash.status, clash.reason) == ("error", "duplicate_id")
    assert again.wall_s == first.wall_s  # the very same stored result


async def test_a_repeat_from_a_new_connection_while_running_joins_the_first_run(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as c1, cluster.client() as c2:
        t1 = asyncio.create_task(c1.call("wait", {"seconds": 1.0}, call_id="same"))
        await log_says(cluster, "alpha", "call same wait from")
        r2 = await c2.call("wait", {"seconds": 1.0}, call_id="same")
        r1 = await t1
    assert r1.status == r2.status == "success"
    assert r1.wall_s == r2.wall_s
    assert cluster.log("alpha").count("call same wait from") == 1


async def test_a_call_past_its_deadline_ends_in_error(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        res = await client.call("wait", {"seconds": 30}, deadline_s=0.3)
    assert (res.status, res.reason) == ("error", "deadline")  # the node's deadline, not the client's
    assert res.wall_s < 30


async def test_cancel_stops_a_running_call(cluster: Cluster) -> None:
    cluster.start("alpha")
    feedback: list[object] = []
    async with cluster.client() as client:
        task = asyncio.create_task(client.call("wait", {"seconds": 30, "step": 0.05}, call_id="c1",
                                               on_feedback=feedback.append))
        await eventually("progress feedback arrived", lambda: bool(feedback))
        assert await client.cancel("c1")
        res = await asyncio.wait_for(task, 20)
    assert (res.status, res.reason) == ("error", "cancelled")
    assert feedback, "progress feedback arrived before the cancel"


async def test_more_calls_than_the_in_flight_cap_are_rejected_busy(cluster: Cluster) -> None:
    cluster.write_services(
        '[nodes.alpha]\nhost = "127.0.0.1"\nport = {port[alpha]}\nmax_in_flight = 2\n'
        '[actions.wait]\nnode = "alpha"\nimpl = "services.actions.demo:wait"\n'
    )
    cluster.start("alpha")
    async with cluster.client() as client:
        results = await asyncio.gather(*(client.call("wait", {"seconds": 0.3}) for _ in range(3)))
    statuses = sorted((r.status, r.reason) for r in results)
    assert statuses == [("error", "busy"), ("success", None), ("success", None)]


async def test_a_local_only_action_serves_callers_from_any_address_of_the_node_host(cluster: Cluster) -> None:
    # the node binds a loopback alias; a caller on the same host comes from 127.0.0.1 or another alias
    cluster.write_services(
        '[nodes.alpha]\nhost = "127.0.0.5"\nport = {port[alpha]}\n'
        '[actions.private_echo]\nnode = "alpha"\nimpl = "services.actions.demo:echo"\nlocal_only = true\n'
    )
    cluster.start("alpha")
    for source in ("127.0.0.1", "127.0.0.2", "127.0.0.5"):
        async with cluster.client(local_addr=(source, 0)) as client:
            res = await client.call("private_echo", {"from": source})
        assert (res.status, res.value) == ("success", {"from": source}), source


async def test_an_action_exception_is_an_error_result_and_the_node_goes_on(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        bad = await client.call("fail", {"message": "gripper jammed"})
        good = await client.call("echo")
    assert bad.status == "error" and bad.reason == "RuntimeError: gripper jammed"
    assert good.status == "success"


async def test_unknown_action_on_a_node_is_rejected(cluster: Cluster) -> None:
    cluster.start("alpha")
    link = NodeLink("alpha", cluster.location.address("alpha"), cluster.key)
    try:
        res = await link.call("no_such_action")
    finally:
        await link.close()
    assert (res.status, res.reason) == ("error", "unknown_action")


async def test_a_node_killed_mid_call_gives_an_error_at_once_not_a_hang(cluster: Cluster) -> None:
    cluster.start("alpha", "beta")
    async with cluster.client() as client:
        task = asyncio.create_task(client.call("slow", {"seconds": 60}, call_id="doomed"))
        await log_says(cluster, "beta", "call doomed slow from")
        cluster.kill("beta")
        res = await asyncio.wait_for(task, 20)
        assert (res.status, res.reason) == ("error", "connection lost")  # the closed socket, not a timer
        assert (await client.call("echo")).status == "success"  # the other node is untouched


async def test_a_frozen_node_misses_heartbeats_and_its_calls_fail_not_hang(cluster: Cluster) -> None:
    cluster.start("beta")
    async with cluster.client() as client:
        task = asyncio.create_task(client.call("slow", {"seconds": 60}, call_id="frozen"))
        await log_says(cluster, "beta", "call frozen slow from")
        cluster.kill("beta", signal.SIGSTOP)
        try:
            res = await asyncio.wait_for(task, 20)
        finally:
            cluster.kill("beta", signal.SIGCONT)
        assert (res.status, res.reason) == ("error", "heartbeat timeout")


async def test_a_down_node_gives_an_error_and_a_restarted_node_is_reached_again(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client(connect_timeout_s=0.3) as client:
        assert (await client.call("echo")).status == "success"
        cluster.kill("alpha")
        await eventually("the client saw the connection drop", lambda: not client.link("alpha").connected)
        down = await client.call("echo")
        assert down.status == "error" and "unreachable" in (down.reason or "")
        cluster.start("alpha")
        up = await client.call("echo", {"back": True})
    assert (up.status, up.value) == ("success", {"back": True})


async def test_a_bad_frame_closes_only_that_connection(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        assert (await client.call("echo")).status == "success"
        host, port = cluster.location.address("alpha")
        conn = Connection(Role.CLIENT, cluster.key, name="fuzzer", node="alpha")
        reader, writer = await asyncio.open_connection(host, port)
        try:
            conn.receive_data(await reader.read(4096))
            conn.next_message()  # hello
            writer.write(conn.data_to_send())  # auth
            conn.receive_data(await reader.read(4096))
            conn.next_message()  # welcome: open
            writer.write(struct.pack(">I", 4) + b"\xc1\xc1\xc1\xc1")  # not msgpack
            await writer.drain()
            data = await asyncio.wait_for(reader.read(), 3)  # until EOF: the node closed it
        finally:
            writer.close()
        conn.receive_data(data)
        bye = conn.next_message()
        assert isinstance(bye, Bye) and bye.reason.startswith("protocol_error")
        # an oversize header on yet another connection: refused before the body is sent
        with socket.create_connection((host, port), timeout=3) as raw:
            raw.sendall(struct.pack(">I", 1 << 30))
            raw.settimeout(3)
            got = b""
            while chunk := raw.recv(4096):
                got += chunk
        assert b"protocol_error" in got or b"hello" in got
        assert (await client.call("echo", {"still": "here"})).value == {"still": "here"}


async def test_subscribers_get_driver_and_action_events_and_resubscribe_after_restart(cluster: Cluster) -> None:
    cluster.start("beta")
    ticks: list[int] = []
    shouts: list[object] = []
    async with cluster.client() as client:
        client.subscribe("ext:tick", lambda ev: ticks.append(ev.seq))
        client.subscribe("shout", lambda ev: shouts.append(ev.data))
        await eventually("three ticks", lambda: len(ticks) >= 3)
        assert ticks == sorted(ticks)
        await client.call("announce", {"topic": "shout", "data": "hello"})
        await eventually("the shout", lambda: bool(shouts))
        assert shouts == ["hello"]
        cluster.restart("beta")
        ticks.clear()
        await eventually("ticks again: resubscribed after the restart", lambda: len(ticks) >= 2)


async def test_sigterm_stops_a_node_cleanly(cluster: Cluster) -> None:
    cluster.start("alpha")
    async with cluster.client() as client:
        task = asyncio.create_task(client.call("wait", {"seconds": 60}, call_id="interrupted"))
        await log_says(cluster, "alpha", "call interrupted wait from")
        code = await asyncio.to_thread(cluster.stop, "alpha")
        res = await asyncio.wait_for(task, 20)
    assert code == 0
    assert res.status == "error"
    assert "stopped" in cluster.log("alpha")


async def test_up_starts_every_node_and_stops_them_all_on_sigterm(cluster: Cluster) -> None:
    import subprocess
    import sys

    cluster.write_services()
    script = ("import argparse, sys; from coordinator.commands import up; p = argparse.ArgumentParser(); "
              "up.add_parser(p.add_subparsers()); a = p.parse_args(sys.argv[1:]); sys.exit(a.func(a))")
    logs = cluster.tmp / "logs"
    proc = subprocess.Popen(  # noqa: ASYNC220 - starting a process does not block
        [sys.executable, "-c", script, "up", "--services", str(cluster.services_path),
         "--key-file", str(cluster.key_file), "--log-dir", str(logs)],
        env=cluster.env(), stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stderr is not None
        lines: list[str] = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            line = await asyncio.to_thread(proc.stderr.readline)
            lines.append(line)
            if line.startswith("up: 2 node(s) running") or not line:
                break
        assert any(ln.startswith("up: node alpha listening on") for ln in lines), lines
        async with cluster.client() as client:
            a, b = await asyncio.gather(client.call("echo", {"via": "up"}), client.call("compute_primes"))
        assert a.status == b.status == "success"
        proc.send_signal(signal.SIGTERM)
        _, rest = await asyncio.to_thread(proc.communicate, timeout=15)
        assert proc.returncode == 0
        assert "up: all nodes stopped" in rest
        assert "node beta listening on" in (logs / "beta.log").read_text()  # the node logs go to files
        with socket.socket() as s:  # the nodes are gone: their ports are free again
            # as a server binds: connections the node closed may sit in TIME_WAIT on its port, which
            # only a live listener, not SO_REUSEADDR, would make a bind fail on
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(cluster.location.address("alpha"))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)
