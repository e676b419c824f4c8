"""RPC benchmark: petrobot call round trip and pipelined throughput beside a raw asyncio echo.

Usage: ``python bench/rpc.py [--json] [--calls N] [--pipelined M] [--window W]``

Starts, on 127.0.0.1 and in this one run:

* a real node process (``python -m services.node bench``) hosting the ``echo`` action, from a
  temporary services.toml, with logging at WARNING (one log line per call would dominate), its
  results kept in an SQLite file in a temporary state directory (``--results sqlite``, the node's
  default: every call's start and result committed, one commit per event-loop iteration) or in
  memory (``--results memory``, the node's ``--volatile``), with ``--synchronous normal`` (default)
  or ``full``;
* a raw asyncio echo server process: length-prefixed frames echoed back by an ``asyncio.Protocol``
  (no msgpack, no handshake, no call bookkeeping): the floor our protocol is measured against.

Measures, for each, round trips one at a time (p50, p99 over N, echo and call alternating so that
both see the same machine load) and pipelined throughput (M requests in alternating rounds, W in
flight at once over one connection), and prints the ratios. Targets (issue 2): call p50 within
2x of the echo p50, >= 20,000 calls/s pipelined.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from services.client import NodeLink

KEY = "bench-key-0123456789abcdef0123456789abcdef"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# --------------------------------------------------------------------------- echo baseline


class _EchoServer(asyncio.Protocol):
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.buf = bytearray()

    def data_received(self, data: bytes) -> None:
        # echo back every complete frame, one write per read
        self.buf += data
        n = 0
        while len(self.buf) - n >= 4:
            size = int.from_bytes(self.buf[n:n + 4], "big")
            if len(self.buf) - n < 4 + size:
                break
            n += 4 + size
        if n:
            self.transport.write(bytes(self.buf[:n]))
            del self.buf[:n]


def run_echo_server(port: int) -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        server = await loop.create_server(_EchoServer, "127.0.0.1", port)
        print("echo ready", flush=True)
        async with server:
            await server.serve_forever()

    asyncio.run(main())


class _EchoClient(asyncio.Protocol):
    def __init__(self) -> None:
        self.buf = bytearray()
        self.waiting: collections.deque[asyncio.Future[bytes]] = collections.deque()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self.buf += data
        while len(self.buf) >= 4:
            size = int.from_bytes(self.buf[:4], "big")
            if len(self.buf) < 4 + size:
                break
            body = bytes(self.buf[4:4 + size])
            del self.buf[:4 + size]
            self.waiting.popleft().set_result(body)

    async def request(self, body: bytes) -> bytes:
        fut = asyncio.get_running_loop().create_future()
        self.waiting.append(fut)
        self.transport.write(len(body).to_bytes(4, "big") + body)
        return await fut


# --------------------------------------------------------------------------- measurement


def _percentile(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


async def _interleaved(req_a, req_b, n: int, warmup: int) -> tuple[list[float], list[float]]:  # type: ignore[no-untyped-def]
    """Round trips of ``req_a`` and ``req_b`` taken alternately, so both see the same machine load."""
    for _ in range(warmup):
        await req_a()
        await req_b()
    a: list[float] = []
    b: list[float] = []
    for _ in range(n):
        t0 = time.perf_counter()
        await req_a()
        t1 = time.perf_counter()
        await req_b()
        t2 = time.perf_counter()
        a.append(t1 - t0)
        b.append(t2 - t1)
    return a, b


async def _pipelined(request, m: int, window: int) -> float:  # type: ignore[no-untyped-def]
    left = m

    async def worker() -> None:
        nonlocal left
        while left > 0:
            left -= 1
            await request()

    t0 = time.perf_counter()
    async with asyncio.timeout(120):
        await asyncio.gather(*(worker() for _ in range(window)))
    return m / (time.perf_counter() - t0)


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def measure(args: argparse.Namespace, node_port: int, echo_port: int,
                  node_pid: int, echo_pid: int) -> dict[str, float]:
    link = NodeLink("bench", ("127.0.0.1", node_port), KEY.encode(), name="bench", connect_timeout_s=5.0)
    params = {"x": 1}
    failures = 0

    async def call() -> None:
        nonlocal failures
        res = await link.call("echo", params)
        if res.status != "success":
            failures += 1

    loop = asyncio.get_running_loop()
    _, echo = await loop.create_connection(_EchoClient, "127.0.0.1", echo_port)
    # same payload size as a call frame, so the echo moves as many bytes
    payload = b"x" * 60

    async def echo_req() -> None:
        await echo.request(payload)

    await link.connect()
    rtt_echo, rtt_call = await _interleaved(echo_req, call, args.calls, args.calls // 10)
    # Pipelined runs alternate (echo, call) in ``rounds`` rounds; the median rate of each is kept.
    # CPU per request on each side is read from each process's own CPU time: it says what the
    # throughput would be with a whole core per process (wall-clock rates suffer from other load).
    share = max(1, args.pipelined // args.rounds)
    echo_rates, call_rates = [], []
    echo_client_cpu = echo_server_cpu = call_client_cpu = call_node_cpu = 0.0
    for _ in range(args.rounds):
        c0, s0 = time.process_time(), proc_cpu_s(echo_pid)
        echo_rates.append(await _pipelined(echo_req, share, args.window))
        echo_client_cpu += time.process_time() - c0
        echo_server_cpu += proc_cpu_s(echo_pid) - s0
        c0, s0 = time.process_time(), proc_cpu_s(node_pid)
        call_rates.append(await _pipelined(call, share, args.window))
        call_client_cpu += time.process_time() - c0
        call_node_cpu += proc_cpu_s(node_pid) - s0
    echo_rate, call_rate = statistics.median(echo_rates), statistics.median(call_rates)
    total = share * args.rounds
    await link.close()
    echo.transport.close()
    if failures:
        raise RuntimeError(f"{failures} calls did not succeed")
    return {
        "rtt_p50_s": statistics.median(rtt_call),
        "rtt_p99_s": _percentile(rtt_call, 0.99),
        "echo_rtt_p50_s": statistics.median(rtt_echo),
        "echo_rtt_p99_s": _percentile(rtt_echo, 0.99),
        "calls_per_s": call_rate,
        "echo_msgs_per_s": echo_rate,
        "client_cpu_per_call_s": call_client_cpu / total,
        "node_cpu_per_call_s": call_node_cpu / total,
        "echo_client_cpu_per_msg_s": echo_client_cpu / total,
        "echo_server_cpu_per_msg_s": echo_server_cpu / total,
        "cpu_bound_calls_per_s": total / max(call_client_cpu, call_node_cpu, 1e-9),
        "load_average_1min": os.getloadavg()[0],
        "rtt_p50_ratio": statistics.median(rtt_call) / statistics.median(rtt_echo),
        "throughput_ratio": call_rate / echo_rate,
        "calls": args.calls,
        "pipelined": args.pipelined,
        "window": args.window,
        "rounds": args.rounds,
    }


def _wait_listening(port: int, proc: subprocess.Popen[bytes], timeout: float = 15.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited with {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"nothing listening on port {port} after {timeout} s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="petrobot call RTT and throughput vs a raw asyncio echo")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--calls", type=int, default=3000, help="sequential round trips per side (default 3000)")
    p.add_argument("--pipelined", type=int, default=30000, help="requests in the pipelined run (default 30000)")
    p.add_argument("--window", type=int, default=256, help="requests in flight at once when pipelined (default 256)")
    p.add_argument("--rounds", type=int, default=3, help="alternating pipelined rounds per side (default 3)")
    p.add_argument("--results", choices=["sqlite", "memory"], default="sqlite",
                   help="where the node keeps results: its SQLite store (default) or memory (--volatile)")
    p.add_argument("--synchronous", choices=["normal", "full"], default="normal",
                   help="the node's --synchronous (default normal)")
    p.add_argument("--echo-server", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.echo_server is not None:
        run_echo_server(args.echo_server)
        return 0

    node_port, echo_port = free_port(), free_port()
    env = dict(os.environ, PETROBOT_KEY=KEY, PYTHONPATH=str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        services = Path(tmp) / "services.toml"
        services.write_text(
            f'[nodes.bench]\nhost = "127.0.0.1"\nport = {node_port}\nmax_in_flight = {max(64, 2 * args.window)}\n\n'
            '[actions.echo]\nnode = "bench"\nimpl = "services.actions.demo:echo"\n'
        )
        store = (["--volatile"] if args.results == "memory"
                 else ["--state-dir", str(Path(tmp) / "state"), "--synchronous", args.synchronous])
        node = subprocess.Popen(
            [sys.executable, "-m", "services.node", "bench", "--services", str(services), "--log-level", "WARNING",
             *store],
            cwd=ROOT, env=env, stderr=subprocess.DEVNULL,
        )
        echo = subprocess.Popen(
            [sys.executable, __file__, "--echo-server", str(echo_port)], cwd=ROOT, env=env, stdout=subprocess.DEVNULL
        )
        try:
            _wait_listening(node_port, node)
            _wait_listening(echo_port, echo)
            res = asyncio.run(measure(args, node_port, echo_port, node.pid, echo.pid))
            res["results"] = args.results if args.results == "memory" else f"sqlite/{args.synchronous}"
        finally:
            for proc in (node, echo):
                proc.terminate()
            for proc in (node, echo):
                try:
                    proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    proc.kill()
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        us = 1e6
        print(f"call RTT    p50 {res['rtt_p50_s'] * us:8.1f} us   p99 {res['rtt_p99_s'] * us:8.1f} us")
        print(f"echo RTT    p50 {res['echo_rtt_p50_s'] * us:8.1f} us   p99 {res['echo_rtt_p99_s'] * us:8.1f} us")
        print(f"p50 ratio call/echo: {res['rtt_p50_ratio']:.2f}  (target <= 2)")
        print(f"pipelined   calls {res['calls_per_s']:9.0f} /s   echo {res['echo_msgs_per_s']:9.0f} msg/s   "
              f"ratio {res['throughput_ratio']:.2f}  (target >= 20000 calls/s)")
        print(f"CPU per call: client {res['client_cpu_per_call_s'] * us:.1f} us, node {res['node_cpu_per_call_s'] * us:.1f} us"
              f" -> {res['cpu_bound_calls_per_s']:.0f} calls/s with a free core per process; "
              f"echo: client {res['echo_client_cpu_per_msg_s'] * us:.1f} us, server {res['echo_server_cpu_per_msg_s'] * us:.1f} us")
        print(f"machine load average (1 min): {res['load_average_1min']:.2f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    sys.exit(main())
