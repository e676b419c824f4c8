"""Hostile-network benchmark: a real node process fuzzed and flooded, and a legitimate client timed.

Usage: ``python bench/hostile.py [--json] [--frames N] [--fuzz-addresses A] [--results N] [--relays N]
[--flood C] [--flood-addresses A] [--flood-s S] [--baseline-s S] [--reconnect-s S] [--same-host] [--seed K]``

Starts a node process (``python -m services.node``) on 127.0.0.1 hosting ``echo``, ``wait`` and
``announce``, with its result store in a temporary state directory and its log (INFO) in a file,
then, in this one run:

0. **Relay** (``--relays``, default 20): the reflection of the node handshake (docs/protocol.md §3,
   "Threat model"). A process without the key listens on a port of its own, standing for the port
   of another node ("other") that is down; a link of the node's own name (``node:bench``, meaning
   to reach "other") connects to it, and the process relays that link's handshake to the node's
   server, half the time renaming the node's ``hello`` to "other". An attempt is refused when
   neither side ever sends a ``welcome`` through it (``relays_refused``, target: all).
1. **Fuzz** (``--frames``, default 100,000): connections before and after authentication send
   seeded random frames: garbage bytes, oversize headers, random maps, forged ``bye`` reasons
   (newlines, ANSI escapes, NUL, kilobytes), wrong MACs, and from logged-in peers calls (known
   and unknown actions, random ids and parameters up to 256 KiB), queries, cancels, pings,
   subscriptions to random topics, deep nesting, booleans for numbers, extension types. Each
   connection ends by waiting for the node to answer a ping or to close it: a connection where
   neither happens within 10 s is a **hang**. Unauthenticated garbage comes from
   ``--fuzz-addresses`` loopback addresses (default 1,000: the node's log limit per address alone
   let such a fuzz grow its log to 26.7 MB).
   Then ``--results`` calls (default 24) of ``echo`` whose kept results are 1 to 16 MiB each, so
   that the node's result store runs at its 64 MiB budget (``rss_after_results_mib``).
2. **Flood** (``--flood``, default 2,000 connections for ``--flood-s`` seconds): slow-handshake
   peers that connect and then send one byte a second, and connect again when the node drops
   them (``--reconnect-s`` later, default 1 s; 0 for at once); from ``--flood-addresses`` loopback
   addresses (default 1,000, other "hosts" that never logged in), or half of them from the client's
   own 127.0.0.1 with ``--same-host``. The
   flood runs in two processes of its own at the lowest CPU priority (nice 19): on a network the
   attackers' CPU would not be the node's. ``--flood 1`` gives the baseline of the same
   measurement without a flood. Meanwhile a legitimate client (127.0.0.1) repeatedly opens a connection,
   authenticates and makes one call (its latency: ``legit_*``), and makes calls over a link it
   keeps open (``established_*``). The same client runs for ``--baseline-s`` seconds (default 10)
   just before the flood, in the same state of the node and of the machine (``*_no_flood``): the
   baseline of this run, since on a shared machine the tail moves with the other jobs' load.

Reports (``--json``): ``relays``, ``relays_refused``, ``frames``, ``connections``, ``hangs``,
``rss_start_mib``, ``rss_after_results_mib``, ``rss_end_mib``, ``rss_growth_mib`` (the node's
highest RSS after the fuzz, the results and the flood, minus after warm-up),
``legit_p50_s_under_flood``, ``legit_p99_s_under_flood``, ``legit_failures`` (and ``legit_failure_reasons``),
``established_p99_s_under_flood``, ``flood_connections`` (connections the flood opened in all),
``node_log_bytes``, ``node_log_lines``, ``node_log_limit_lines`` (the log limit's summaries),
``node_alive``. Targets (issue 22): every relay refused, 0 hangs, RSS growth <= 50 MiB, legitimate
p99 <= 50 ms and 0 failures under a flood of slow handshakes reconnecting from many addresses, the
log bounded.

The soft ``RLIMIT_NOFILE`` of this process is raised (within the hard limit) to hold the flood.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import hashlib
import hmac
import json
import os
import random
import resource
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgpack

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from services.client import NodeLink

KEY_HEX = "4be1f07a92c35d68e01b7f4c3a9d2e586f1c0b74d93a2e85c6017fb4e2d9a31c"
KEY = bytes.fromhex(KEY_HEX)
ANSWER_S = 10.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def frame(obj: Any) -> bytes:
    body = obj if isinstance(obj, bytes) else msgpack.packb(obj, use_bin_type=True)
    return struct.pack(">I", len(body)) + body


def mac(role: bytes, client: str, server: str, nonce_s: bytes, nonce_c: bytes, key: bytes = KEY) -> bytes:
    """docs/protocol.md §3: the MAC over the role, both names and both nonces."""
    def named(text: str) -> bytes:
        data = text.encode()
        return struct.pack(">I", len(data)) + data

    msg = b"petrobot-auth-v2\x00" + role + b"\x00" + named(client) + named(server) + nonce_s + nonce_c
    return hmac.new(key, msg, hashlib.sha256).digest()


# --------------------------------------------------------------------------- random frames


class Garbage:
    """Seeded generator of hostile frames."""

    EVIL = "\n2026-11-21 10:00:00 alpha INFO forged\x1b[31m\x00\u2028"

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)

    def value(self, depth: int = 0) -> Any:
        r = self.rng
        kind = r.randrange(10 if depth < 3 else 6)
        if kind == 0:
            return None
        if kind == 1:
            return r.choice([True, False])
        if kind == 2:
            return r.randrange(-2**63, 2**64)
        if kind == 3:
            return r.choice([0.5, -1e300, float("inf"), float("nan"), 3.0])
        if kind == 4:
            return self.text()
        if kind == 5:
            return r.randbytes(r.randrange(64))
        if kind in (6, 7):
            return [self.value(depth + 1) for _ in range(r.randrange(5))]
        return {self.text(8): self.value(depth + 1) for _ in range(r.randrange(5))}

    def text(self, n: int = 40) -> str:
        r = self.rng
        if r.random() < 0.1:
            return self.EVIL * r.randrange(1, 50)
        return "".join(chr(r.randrange(32, 0x2FF)) for _ in range(r.randrange(n)))

    def preauth(self) -> bytes:
        """One frame a peer sends before logging in (each should end the connection)."""
        r = self.rng
        kind = r.randrange(7)
        if kind == 0:
            return r.randbytes(r.randrange(1, 300))
        if kind == 1:
            return struct.pack(">I", r.choice([4097, 1 << 24, 1 << 31, 0xFFFFFFFF])) + r.randbytes(r.randrange(100))
        if kind == 2:
            return frame({"type": "bye", "reason": self.text(4000) + self.EVIL * 40})
        if kind == 3:
            return frame({"type": "auth", "client": self.text(), "nonce": r.randbytes(16), "mac": r.randbytes(32)})
        if kind == 4:
            return frame({"type": r.choice(["call", "query", "ping", "subscribe", "welcome"]), "id": "x", "seq": 1})
        if kind == 5:
            return frame({self.text(8): self.value() for _ in range(r.randrange(6))})
        return frame(b"\x81\xa4type" + b"\x91" * r.randrange(10, 5000) + b"\xc0")

    def open_frame(self) -> tuple[bytes, bool]:
        """One frame for a logged-in connection, and whether the node should close on it."""
        r = self.rng
        kind = r.randrange(100) if r.random() < 0.05 else r.randrange(80)  # 1 frame in ~70 closes
        cid = self.text(20) or "x"
        if kind < 30:
            action = r.choice(["echo", "echo", "wait", "announce", "no_such", self.text(30)])
            params: dict[str, Any] = {self.text(8): self.value() for _ in range(r.randrange(4))}
            if action == "wait":
                params = {"seconds": r.random() * 0.05, "step": 0.01}
            if action == "announce":
                params = {"topic": r.choice(["t1", "t2", self.text(10)]), "data": self.value()}
            if r.random() < 0.02:
                params = {"blob": r.randbytes(r.randrange(256 * 1024))}
            msg: dict[str, Any] = {"type": "call", "id": cid, "action": action, "params": params}
            if r.random() < 0.2:
                msg["deadline_ms"] = r.randrange(0, 100)
            return frame(msg), False
        if kind < 45:
            return frame({"type": "query", "id": cid}), False
        if kind < 55:
            return frame({"type": "cancel", "id": cid}), False
        if kind < 70:
            return frame({"type": "ping", "seq": r.randrange(2**63)}), False
        if kind < 80:
            return frame({"type": r.choice(["subscribe", "unsubscribe"]), "topic": self.text(r.choice([10, 300]))}), False
        if kind < 83:
            return frame({"type": "call", "id": cid, "action": "echo", "deadline_ms": True}), True
        if kind < 86:
            return frame({"type": "call", "id": cid, "action": "echo", "params": {"t": msgpack.ExtType(3, b"x")}}), True
        if kind < 89:
            return frame({"type": r.choice(["result", "event", "hello", "teleport"]), "id": cid}), True
        if kind < 92:
            return r.randbytes(r.randrange(1, 64)), True
        if kind < 95:
            return frame({self.text(8): self.value() for _ in range(r.randrange(6))}), True
        return frame({"type": "call", "id": cid, "action": self.value(), "params": self.value()}), True


# --------------------------------------------------------------------------- fuzz


FUZZ_ADDRESSES = 1000


def spread_address(i: int, block: int) -> str:
    """The ``i``-th loopback address of block ``block`` (127.BLOCK.x.y: other "hosts" for the node)."""
    return f"127.{block}.{i // 250}.{i % 250 + 1}"


class Stats:
    def __init__(self) -> None:
        self.frames = 0
        self.connections = 0
        self.hangs = 0


async def read_until_closed_or(reader: asyncio.StreamReader, want_pong: int | None) -> bool:
    """Read frames until end of stream, or a pong with ``want_pong``; False on a hang."""
    try:
        async with asyncio.timeout(ANSWER_S):
            while True:
                header = await reader.readexactly(4)
                (size,) = struct.unpack(">I", header)
                body = await reader.readexactly(size)
                if want_pong is not None:
                    obj = msgpack.unpackb(body, raw=False, strict_map_key=False)
                    if isinstance(obj, dict) and obj.get("type") == "pong" and obj.get("seq") == want_pong:
                        return True
    except (asyncio.IncompleteReadError, ConnectionError):
        return True
    except TimeoutError:
        return False


async def login(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    header = await reader.readexactly(4)
    hello = msgpack.unpackb(await reader.readexactly(struct.unpack(">I", header)[0]), raw=False)
    if hello["type"] != "hello":
        raise ConnectionError(f"refused: {hello}")
    nonce = os.urandom(16)
    writer.write(frame({"type": "auth", "client": "fuzzer", "nonce": nonce,
                        "mac": mac(b"client", "fuzzer", hello["node"], hello["nonce"], nonce)}))
    header = await reader.readexactly(4)
    welcome = msgpack.unpackb(await reader.readexactly(struct.unpack(">I", header)[0]), raw=False)
    assert welcome["type"] == "welcome", welcome


async def fuzz_one(port: int, g: Garbage, stats: Stats, frames: int, authenticated: bool) -> None:
    # unauthenticated garbage comes from other addresses (it gets them throttled for failed logins)
    source = "127.0.0.1" if authenticated else spread_address(g.rng.randrange(FUZZ_ADDRESSES), 2)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
    except OSError:
        return
    stats.connections += 1
    try:
        if not authenticated:
            await reader.readexactly(4)  # hello's header; the rest is read below or dropped
            writer.write(g.preauth())
            stats.frames += 1
            if not await read_until_closed_or(reader, None):
                stats.hangs += 1
            return
        await login(reader, writer)
        closes = False
        sent = 0
        while sent < frames and not closes:
            data, closes = g.open_frame()
            writer.write(data)
            sent += 1
        stats.frames += sent
        seq = g.rng.randrange(2**62)
        writer.write(frame({"type": "ping", "seq": seq}))
        if not await read_until_closed_or(reader, None if closes else seq):
            stats.hangs += 1
    except (ConnectionError, asyncio.IncompleteReadError):
        pass  # the node closed on us: an answer
    finally:
        writer.close()


async def fuzz(port: int, total: int, seed: int) -> Stats:
    g = Garbage(seed)
    stats = Stats()
    while stats.frames < total:
        batch = []
        for _ in range(48):
            if g.rng.random() < 0.6:
                batch.append(fuzz_one(port, g, stats, 0, authenticated=False))
            else:
                batch.append(fuzz_one(port, g, stats, g.rng.randrange(50, 1500), authenticated=True))
        await asyncio.gather(*batch)
    return stats


# --------------------------------------------------------------------------- flood


RECONNECT_S = 1.0


async def slow_peer(port: int, source: str, stop: asyncio.Event, opened: list[int]) -> None:
    first = True
    while not stop.is_set():
        if not first:
            await asyncio.sleep(RECONNECT_S)
        first = False
        try:
            reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
        except OSError:
            continue
        opened[0] += 1
        try:
            while not stop.is_set():
                writer.write(b"\x00")
                try:
                    await asyncio.wait_for(reader.read(4096), 1.0)
                    if reader.at_eof():
                        break
                except TimeoutError:
                    pass
        except (ConnectionError, OSError):
            pass
        finally:
            writer.close()


async def legit_round(port: int) -> float:
    t0 = time.perf_counter()
    link = NodeLink("bench", ("127.0.0.1", port), KEY, name="legit", connect_timeout_s=5.0, local_addr=("127.0.0.1", 0))
    try:
        res = await link.call("echo", {"legit": True})
    finally:
        await link.close()
    if res.status != "success":
        raise RuntimeError(res.reason)
    return time.perf_counter() - t0


def percentile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


async def flood_worker(port: int, sources: list[str], seconds: float) -> int:
    """One flood process: a slow peer per source address for ``seconds``; returns connections opened."""
    stop = asyncio.Event()
    opened = [0]
    peers = []
    for i, src in enumerate(sources):
        peers.append(asyncio.create_task(slow_peer(port, src, stop, opened)))
        if i % 100 == 99:
            await asyncio.sleep(0.01)  # let the node breathe while the flood builds
    await asyncio.sleep(seconds)
    stop.set()
    for p in peers:
        p.cancel()
    await asyncio.gather(*peers, return_exceptions=True)
    return opened[0]


FLOOD_WORKERS = 2
FLOOD_CPUS: set[int] | None = None
NODE_CPUS: set[int] | None = None


def _flood_process(cpus: set[int] | None) -> Any:
    """A ``preexec_fn`` for a flood process: the lowest CPU priority (on a network, the attackers'
    CPU is not the node's), pinned to ``cpus`` if given."""
    def setup() -> None:
        os.nice(19)
        if cpus is not None:
            os.sched_setaffinity(0, cpus)
    return setup


FLOOD_ADDRESSES = 1000


async def flood(port: int, conns: int, seconds: float, same_host: bool) -> dict[str, Any]:
    sources = [spread_address(i % FLOOD_ADDRESSES, 3) for i in range(conns)]
    if same_host:
        sources = [("127.0.0.1" if i % 2 else s) for i, s in enumerate(sources)]
    workers = []
    for w in range(FLOOD_WORKERS):
        mine = ",".join(sources[w::FLOOD_WORKERS])
        workers.append(await asyncio.create_subprocess_exec(
            sys.executable, __file__, "--flood-worker", f"{port}:{seconds + 2.0}:{RECONNECT_S}:{mine}",
            stdout=asyncio.subprocess.PIPE, preexec_fn=_flood_process(FLOOD_CPUS)))
    await asyncio.sleep(2.0)  # the flood builds up
    timed = await legit_client(port, seconds, "under_flood")
    opened = 0
    for proc in workers:
        out, _ = await proc.communicate()
        opened += int(out.decode().strip() or 0)
    return {**timed, "flood_connections": opened}


async def legit_client(port: int, seconds: float, suffix: str) -> dict[str, Any]:
    """For ``seconds``: a legitimate client on 127.0.0.1 opens a connection, logs in and makes one
    call, again and again, and makes calls over a link it keeps open; their latencies (keys ending
    in ``suffix``), failures and why."""
    keeper = NodeLink("bench", ("127.0.0.1", port), KEY, name="legit-established", connect_timeout_s=5.0)
    await keeper.connect()
    fresh: list[float] = []
    established: list[float] = []
    failures = 0
    reasons: collections.Counter[str] = collections.Counter()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            fresh.append(await legit_round(port))
        except Exception as exc:  # noqa: BLE001 - counted, not fatal
            failures += 1
            reasons[f"fresh: {exc}"[:120]] += 1
        t0 = time.perf_counter()
        res = await keeper.call("echo", {"x": 1})
        established.append(time.perf_counter() - t0)
        if res.status != "success":
            failures += 1
            reasons[f"established: {res.reason}"[:120]] += 1
        await asyncio.sleep(0.02)
    await keeper.close()
    tail = "" if suffix == "under_flood" else f"_{suffix}"
    return {
        f"legit_rounds{tail}": len(fresh),
        f"legit_p50_s_{suffix}": percentile(fresh, 0.5),
        f"legit_p99_s_{suffix}": percentile(fresh, 0.99),
        f"legit_max_s_{suffix}": max(fresh) if fresh else float("nan"),
        f"legit_failures{tail}": failures,
        f"legit_failure_reasons{tail}": dict(reasons),
        f"established_p50_s_{suffix}": percentile(established, 0.5),
        f"established_p99_s_{suffix}": percentile(established, 0.99),
    }


# --------------------------------------------------------------------------- relay


async def read_map(reader: asyncio.StreamReader) -> dict[str, Any] | None:
    try:
        header = await reader.readexactly(4)
        body = await reader.readexactly(struct.unpack(">I", header)[0])
    except (asyncio.IncompleteReadError, ConnectionError):
        return None
    obj = msgpack.unpackb(body, raw=False)
    return obj if isinstance(obj, dict) else None


async def relay(port: int, attempts: int) -> dict[str, Any]:
    """Relay the handshake of a link named for this node to this node's server (module docstring)."""
    welcomes = 0
    done: asyncio.Queue[None] = asyncio.Queue()
    rename = [False]

    async def handle(victim_r: asyncio.StreamReader, victim_w: asyncio.StreamWriter) -> None:
        nonlocal welcomes
        server_r, server_w = await asyncio.open_connection("127.0.0.1", port)
        try:
            hello = await read_map(server_r)
            if hello is not None:
                if rename[0]:
                    hello["node"] = "other"
                victim_w.write(frame(hello))
                auth = await read_map(victim_r)
                if auth is not None:
                    server_w.write(frame(auth))
                    answer = await read_map(server_r)
                    if answer is not None:
                        welcomes += answer.get("type") == "welcome"
                        victim_w.write(frame(answer))
                        back = await read_map(victim_r)
                        welcomes += back is not None and back.get("type") == "welcome"
        finally:
            victim_w.close()
            server_w.close()
            done.put_nowait(None)

    squatter = await asyncio.start_server(handle, "127.0.0.1", 0)
    squat_port = squatter.sockets[0].getsockname()[1]
    try:
        for i in range(attempts):
            rename[0] = i % 2 == 0
            link = NodeLink("other", ("127.0.0.1", squat_port), KEY, name="node:bench", connect_timeout_s=2.0)
            await link.call("echo", {"relayed": i})
            await link.close()
            await asyncio.wait_for(done.get(), ANSWER_S)
    finally:
        squatter.close()
    return {"relays": attempts, "relays_refused": attempts - welcomes}


async def big_results(port: int, calls: int, seed: int) -> None:
    """``calls`` echo calls whose results are 1 to 16 MiB (random bytes), kept by the node."""
    rng = random.Random(seed)
    # committing a 16 MiB result to the node's store can hold its event loop for seconds on a loaded
    # disk (SQLite writes, its checkpoints): this phase measures memory, so a heartbeat that waits
    link = NodeLink("bench", ("127.0.0.1", port), KEY, name="results", connect_timeout_s=10.0, heartbeat_s=5.0)
    try:
        for i in range(calls):
            size = rng.randrange(1 << 20, 16 << 20)
            res = await link.call("echo", {"blob": rng.randbytes(size), "i": i}, deadline_s=60.0)
            if res.status != "success":
                raise RuntimeError(f"echo of {size} bytes: {res.reason}")
    finally:
        await link.close()


# --------------------------------------------------------------------------- run


async def warm_up(port: int) -> None:
    link = NodeLink("bench", ("127.0.0.1", port), KEY, name="warm-up", connect_timeout_s=10.0)
    for i in range(200):
        await link.call("echo", {"i": i})
    await link.close()


async def alive(port: int) -> bool:
    link = NodeLink("bench", ("127.0.0.1", port), KEY, name="probe", connect_timeout_s=10.0)
    try:
        return (await link.call("echo", {"alive": True})).status == "success"
    finally:
        await link.close()


async def measure(args: argparse.Namespace, port: int, pid: int) -> dict[str, Any]:
    await warm_up(port)
    rss_start = rss_mib(pid)
    relays = await relay(port, args.relays) if args.relays else {"relays": 0, "relays_refused": 0}
    t0 = time.monotonic()
    stats = await fuzz(port, args.frames, args.seed) if args.frames else Stats()
    fuzz_s = time.monotonic() - t0
    after_fuzz = rss_mib(pid)
    if args.results:
        await big_results(port, args.results, args.seed)
    after_results = rss_mib(pid)
    # the same client in the same state of the node and of the machine, without the flood: the baseline
    base = await legit_client(port, args.baseline_s, "no_flood") if args.baseline_s > 0 and args.flood else {}
    cpu0 = proc_cpu_s(pid)
    children0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    fl = await flood(port, args.flood, args.flood_s, args.same_host) if args.flood else {}
    children1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    fl["node_cpu_s_during_flood"] = proc_cpu_s(pid) - cpu0
    fl["flood_cpu_s"] = (children1.ru_utime + children1.ru_stime) - (children0.ru_utime + children0.ru_stime)
    await asyncio.sleep(3.0)  # handshakes and orphaned calls time out
    ok = await alive(port)
    rss_end = rss_mib(pid)
    return {
        **relays,
        "frames": stats.frames,
        "connections": stats.connections,
        "hangs": stats.hangs,
        "fuzz_s": fuzz_s,
        "fuzz_addresses": FUZZ_ADDRESSES,
        "rss_start_mib": rss_start,
        "rss_after_fuzz_mib": after_fuzz,
        "results_1_to_16_mib": args.results,
        "rss_after_results_mib": after_results,
        "rss_end_mib": rss_end,
        "rss_growth_mib": max(after_fuzz, after_results, rss_end) - rss_start,
        **base,
        **fl,
        "flood": args.flood,
        "flood_addresses": FLOOD_ADDRESSES,
        "flood_s": args.flood_s,
        "same_host": args.same_host,
        "reconnect_s": args.reconnect_s,
        "pinned": args.pin,
        "node_alive": ok,
        "load_average_1min": os.getloadavg()[0],
    }


def wait_listening(port: int, proc: subprocess.Popen[bytes], timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"node exited with {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"node not listening on {port} after {timeout} s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="fuzz and flood a node; time a legitimate client")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--relays", type=int, default=20, help="relayed handshakes to try (default 20; 0: none)")
    p.add_argument("--frames", type=int, default=100_000, help="fuzz frames to send (default 100000; 0: none)")
    p.add_argument("--fuzz-addresses", type=int, default=1000,
                   help="loopback addresses the unauthenticated fuzz comes from (default 1000)")
    p.add_argument("--results", type=int, default=24,
                   help="calls whose kept results are 1-16 MiB each, after the fuzz (default 24; 0: none)")
    p.add_argument("--flood", type=int, default=2000, help="slow-handshake connections (default 2000; 0: none)")
    p.add_argument("--flood-s", type=float, default=15.0, help="seconds the flood lasts (default 15)")
    p.add_argument("--baseline-s", type=float, default=10.0,
                   help="seconds of the legitimate client without a flood, just before it (default 10; 0: none)")
    p.add_argument("--flood-addresses", type=int, default=1000,
                   help="loopback addresses the flood comes from (default 1000)")
    p.add_argument("--same-host", action="store_true", help="half the flood also comes from the client's 127.0.0.1")
    p.add_argument("--reconnect-s", type=float, default=1.0,
                   help="a dropped flood peer reconnects after this (default 1 s; 0: at once)")
    p.add_argument("--seed", type=int, default=1, help="fuzz seed (default 1)")
    p.add_argument("--node-nofile", type=int, default=None, help="the node's RLIMIT_NOFILE (default: inherited)")
    p.add_argument("--pin", action="store_true",
                   help="run the flood on the last CPU and the node and the timed client on the others, "
                        "as if the attackers were other hosts (Linux, 2 CPUs or more)")
    p.add_argument("--keep-log", default=None, metavar="FILE", help="copy the node's log to FILE")
    p.add_argument("--flood-worker", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if args.flood_worker is not None:
        port, seconds, reconnect, sources = args.flood_worker.split(":", 3)
        globals()["RECONNECT_S"] = float(reconnect)
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, max(soft, 2 * len(sources.split(",")) + 256)), hard))
        print(asyncio.run(flood_worker(int(port), sources.split(","), float(seconds))))
        return 0
    globals()["RECONNECT_S"] = args.reconnect_s
    globals()["FUZZ_ADDRESSES"] = max(1, args.fuzz_addresses)
    globals()["FLOOD_ADDRESSES"] = max(1, args.flood_addresses)
    if args.pin:
        cpus = sorted(os.sched_getaffinity(0))
        if len(cpus) < 2:
            p.error("--pin needs 2 CPUs or more")
        globals()["FLOOD_CPUS"], globals()["NODE_CPUS"] = {cpus[-1]}, set(cpus[:-1])
        os.sched_setaffinity(0, set(cpus[:-1]))
    want = args.flood + 1024
    if soft < want:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(want, hard), hard))

    port = free_port()
    env = dict(os.environ, PETROBOT_KEY=KEY_HEX, PYTHONPATH=str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        services = Path(tmp) / "services.toml"
        services.write_text(
            f'[nodes.bench]\nhost = "127.0.0.1"\nport = {port}\nmax_in_flight = 16\n\n'
            '[actions.echo]\nnode = "bench"\nimpl = "services.actions.demo:echo"\n'
            '[actions.wait]\nnode = "bench"\nimpl = "services.actions.demo:wait"\n'
            '[actions.announce]\nnode = "bench"\nimpl = "services.actions.demo:announce"\n'
        )
        log_path = Path(tmp) / "node.log"

        def limits() -> None:
            if args.node_nofile:
                resource.setrlimit(resource.RLIMIT_NOFILE, (args.node_nofile, hard))
            if NODE_CPUS is not None:
                os.sched_setaffinity(0, NODE_CPUS)

        with open(log_path, "wb") as log:
            node = subprocess.Popen(
                [sys.executable, "-m", "services.node", "bench", "--services", str(services),
                 "--state-dir", str(Path(tmp) / "state"), "--log-level", "INFO"],
                cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, preexec_fn=limits,  # noqa: PLW1509 - no threads yet
            )
        try:
            wait_listening(port, node)
            try:
                res = asyncio.run(measure(args, port, node.pid))
            finally:
                if args.keep_log:
                    shutil.copyfile(log_path, args.keep_log)
            res["node_log_bytes"] = log_path.stat().st_size
            log_text = log_path.read_text(errors="replace")
            res["node_log_lines"] = log_text.count("\n")
            res["node_log_limit_lines"] = log_text.count("log limit:")
        finally:
            node.terminate()
            try:
                node.wait(timeout=10)
            except subprocess.TimeoutExpired:
                node.kill()
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(f"relay of the node's own handshake: {res['relays_refused']} of {res['relays']} refused (target: all)")
        print(f"fuzz: {res['frames']} frames over {res['connections']} connections in {res['fuzz_s']:.1f} s "
              f"(unauthenticated ones from {res['fuzz_addresses']} addresses), {res['hangs']} hangs (target 0)")
        print(f"node RSS: {res['rss_start_mib']:.1f} -> {res['rss_after_fuzz_mib']:.1f} (after fuzz) -> "
              f"{res['rss_after_results_mib']:.1f} (after {res['results_1_to_16_mib']} results of 1-16 MiB) -> "
              f"{res['rss_end_mib']:.1f} MiB; growth {res['rss_growth_mib']:.1f} MiB (target <= 50)")
        if args.flood:
            print(f"flood: {args.flood} slow-handshake peers from {res['flood_addresses']} addresses for "
                  f"{args.flood_s:g} s, reconnecting {args.reconnect_s:g} s after a drop ({res['flood_connections']} "
                  f"connections opened{', half from the client host' if args.same_host else ''})")
            print(f"legitimate connect+login+call: p50 {res['legit_p50_s_under_flood'] * 1e3:.1f} ms, "
                  f"p99 {res['legit_p99_s_under_flood'] * 1e3:.1f} ms (target <= 50), max "
                  f"{res['legit_max_s_under_flood'] * 1e3:.1f} ms over {res['legit_rounds']} rounds, "
                  f"{res['legit_failures']} failures")
            for reason, n in res["legit_failure_reasons"].items():
                print(f"  failed {n}x: {reason}")
            print(f"established link call: p50 {res['established_p50_s_under_flood'] * 1e3:.2f} ms, "
                  f"p99 {res['established_p99_s_under_flood'] * 1e3:.2f} ms")
            if "legit_p99_s_no_flood" in res:
                print(f"the same client just before the flood ({args.baseline_s:g} s): connect+login+call p50 "
                      f"{res['legit_p50_s_no_flood'] * 1e3:.1f} ms, p99 {res['legit_p99_s_no_flood'] * 1e3:.1f} ms, "
                      f"{res['legit_failures_no_flood']} failures; established p99 "
                      f"{res['established_p99_s_no_flood'] * 1e3:.2f} ms")
            print(f"CPU during the flood: node {res['node_cpu_s_during_flood']:.1f} s, flood processes "
                  f"{res['flood_cpu_s']:.1f} s")
        print(f"node log: {res['node_log_bytes']} bytes, {res['node_log_lines']} lines ({res['node_log_limit_lines']} "
              f"log-limit summaries); node alive: {res['node_alive']}; load average {res['load_average_1min']:.2f}")
    return 0 if res["node_alive"] and res["hangs"] == 0 and res["relays_refused"] == res["relays"] else 1


if __name__ == "__main__":
    sys.exit(main())
