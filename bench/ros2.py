"""ROS 2 benchmark: a ROS 2 service call through petrobot beside the same call made directly with
zenoh-ros2-sdk, and goal-to-feedback latency, in one run.

Usage: ``python bench/ros2.py [--json] [--calls N] [--goals G] [--results sqlite|memory]``

Starts, on 127.0.0.1: a Zenoh router (``petrobot sim zenoh``), the stand-in ROS 2 robot
(``petrobot sim ros2``: zenoh-ros2-sdk serving ``/add_two_ints`` and ``/fibonacci``) and a petrobot
node (``python -m services.node bench``, log level WARNING as in bench/rpc.py: a log line per call
would dominate) whose services.toml makes
``add_two_ints`` and ``fibonacci`` ROS 2 primitive actions. Then measures, in alternating rounds so
that every path sees the same machine load:

* **direct**: ``zenoh_ros2_sdk.ROS2ServiceClient.call(a, b)`` from this process (its own session to
  the router): the baseline;
* **petrobot**: the coordinator's call of the ``add_two_ints`` primitive action
  (:class:`services.client.NodeLink`, TCP to the node, which makes the ROS 2 call with its own
  Zenoh session);
* **client only**: petrobot's ROS 2 service client in this process (no node hop), which splits
  petrobot's overhead into the node hop and the ROS 2 client;

and for G goals of ``/fibonacci`` (order 2, the robot waits ``--step-s`` before its first
feedback) the time from sending the call to the first feedback at the caller, through petrobot
and with petrobot's action client in this process. Prints p50/p99 and the overhead; target (issue
21): petrobot's p50 at most 1 ms above the direct call's.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from services.client import NodeLink  # noqa: E402

KEY = "bench-key-0123456789abcdef0123456789abcdef"

SERVICES = """
[nodes.bench]
host = "127.0.0.1"
port = {node}

[nodes.bench.ros2]
connect = ["tcp/127.0.0.1:{router}"]

[actions.add_two_ints]
node = "bench"
ros2 = {{ service = "/add_two_ints", type = "example_interfaces/srv/AddTwoInts" }}

[actions.fibonacci]
node = "bench"
ros2 = {{ action = "/fibonacci", type = "example_interfaces/action/Fibonacci" }}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _percentile(xs: list[float], q: float) -> float:
    ordered = sorted(xs)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def _wait_line(proc: subprocess.Popen[str], text: str, timeout_s: float = 60.0) -> None:
    assert proc.stdout is not None
    end = time.monotonic() + timeout_s
    for line in proc.stdout:
        if text in line:
            threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
            return
        if time.monotonic() > end:
            break
    raise SystemExit(f"bench/ros2.py: no {text!r} from {proc.args}")


def _wait_listening(proc: subprocess.Popen[Any], port: int, timeout_s: float = 60.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and proc.poll() is None:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise SystemExit(f"bench/ros2.py: the node is not listening on {port}")


def _stats(xs: list[float]) -> dict[str, float]:
    return {"p50_ms": round(_percentile(xs, 0.5) * 1e3, 3), "p99_ms": round(_percentile(xs, 0.99) * 1e3, 3),
            "mean_ms": round(statistics.fmean(xs) * 1e3, 3)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--calls", type=int, default=2000, help="service calls per path (default 2000)")
    parser.add_argument("--rounds", type=int, default=10, help="alternating rounds (default 10)")
    parser.add_argument("--goals", type=int, default=100, help="Fibonacci goals per path (default 100)")
    parser.add_argument("--step-s", type=float, default=0.005, help="the robot's seconds per term (default 0.005)")
    parser.add_argument("--results", choices=("sqlite", "memory"), default="sqlite",
                        help="the node keeps results in SQLite (default, as `petrobot node`) or in memory")
    args = parser.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="petrobot-bench-ros2-"))
    router_port, node_port = free_port(), free_port()
    router = f"tcp/127.0.0.1:{router_port}"
    (tmp / "services.toml").write_text(SERVICES.format(node=node_port, router=router_port))
    (tmp / "key").write_text(KEY + "\n")
    os.chmod(tmp / "key", 0o600)
    env = dict(os.environ, PYTHONPATH=str(ROOT), XDG_STATE_HOME=str(tmp / "state"))
    cli = [sys.executable, "-m", "coordinator.cli", "sim"]
    procs = [subprocess.Popen([*cli, "zenoh", "--listen", router], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)]
    try:
        _wait_line(procs[0], '"ready"')
        procs.append(subprocess.Popen([*cli, "ros2", "--router", router, "--step-s", str(args.step_s)], cwd=ROOT,
                                      env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True))
        _wait_line(procs[1], '"ready"')
        node = [sys.executable, "-m", "services.node", "bench", "--services", str(tmp / "services.toml"),
                "--key-file", str(tmp / "key"), "--log-level", "WARNING"]
        if args.results == "memory":
            node.append("--volatile")
        procs.append(subprocess.Popen(node, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_listening(procs[2], node_port)
        results = measure(args, node_port, router_port, tmp)
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
    results["load_average_1min"] = round(os.getloadavg()[0], 2)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        d, p, c = results["direct_sdk"], results["petrobot"], results["petrobot_client_only"]
        print(f"service call p50: direct {d['p50_ms']:.3f} ms, petrobot {p['p50_ms']:.3f} ms "
              f"(+{results['overhead_p50_ms']:.3f} ms, {results['ratio_p50']:.2f}x; target +1 ms), "
              f"petrobot's client alone {c['p50_ms']:.3f} ms")
        g, gc = results["goal_to_feedback_petrobot"], results["goal_to_feedback_client_only"]
        print(f"goal to first feedback p50: through petrobot {g['p50_ms']:.3f} ms, client alone {gc['p50_ms']:.3f} ms "
              f"(the robot waits {args.step_s * 1e3:.1f} ms before its first feedback)")
        print(f"load average {results['load_average_1min']}")
    return 0


def measure(args: argparse.Namespace, node_port: int, router_port: int, tmp: Path) -> dict[str, Any]:
    from zenoh_ros2_sdk import ROS2ServiceClient

    from services.ros2.config import SessionSettings
    from services.ros2.endpoints import ActionClient, ServiceClient
    from services.ros2.session import Ros2Session
    from services.ros2.typestore import TypeStore, load_definitions
    from sim.ros2.robot import forbid_fetching

    forbid_fetching()
    sdk = ROS2ServiceClient("/add_two_ints", "example_interfaces/srv/AddTwoInts", request_definition="int64 a\nint64 b",
                            response_definition="int64 sum", router_port=router_port, timeout=10.0)
    loop = asyncio.new_event_loop()
    link = NodeLink("bench", ("127.0.0.1", node_port), KEY.encode(), name="bench", connect_timeout_s=10.0)
    session = Ros2Session(SessionSettings(connect=(f"tcp/127.0.0.1:{router_port}",)), "bench_client",
                          TypeStore(load_definitions()))
    loop.run_until_complete(session.open())
    ours = ServiceClient(session, "/add_two_ints", "example_interfaces/srv/AddTwoInts")
    fib = ActionClient(session, "/fibonacci", "example_interfaces/action/Fibonacci")
    loop.run_until_complete(asyncio.sleep(1.0))  # the graph and the routes settle

    direct: list[float] = []
    petrobot: list[float] = []
    client: list[float] = []
    per_round = max(1, args.calls // args.rounds)

    async def through_petrobot(n: int, out: list[float]) -> None:
        for i in range(n):
            t0 = time.perf_counter()
            result = await link.call("add_two_ints", {"a": i, "b": 1}, call_id=uuid.uuid4().hex)
            out.append(time.perf_counter() - t0)
            assert result.status.value == "success" and result.value == {"sum": i + 1}, result

    async def client_only(n: int, out: list[float]) -> None:
        for i in range(n):
            t0 = time.perf_counter()
            response = await ours.call({"a": i, "b": 1})
            out.append(time.perf_counter() - t0)
            assert response == {"sum": i + 1}

    def sdk_calls(n: int, out: list[float]) -> None:
        for i in range(n):
            t0 = time.perf_counter()
            response = sdk.call(a=i, b=1)
            out.append(time.perf_counter() - t0)
            assert response is not None and response.sum == i + 1

    sdk_calls(50, [])  # warm up every path
    loop.run_until_complete(through_petrobot(50, []))
    loop.run_until_complete(client_only(50, []))
    for _ in range(args.rounds):
        sdk_calls(per_round, direct)
        loop.run_until_complete(through_petrobot(per_round, petrobot))
        loop.run_until_complete(client_only(per_round, client))

    feedback_petrobot: list[float] = []
    feedback_client: list[float] = []

    async def goal_petrobot() -> None:
        first: asyncio.Future[float] = loop.create_future()
        t0 = time.perf_counter()

        def on_feedback(data: Any) -> None:
            if not first.done():
                first.set_result(time.perf_counter() - t0)

        result = await link.call("fibonacci", {"order": 2}, call_id=uuid.uuid4().hex, on_feedback=on_feedback)
        assert result.status.value == "success", result
        feedback_petrobot.append(await first)

    async def goal_client() -> None:
        first: asyncio.Future[float] = loop.create_future()
        t0 = time.perf_counter()

        def on_feedback(data: Any) -> None:
            if not first.done():
                first.set_result(time.perf_counter() - t0)

        status, _ = await fib.run(uuid.uuid4().bytes, {"order": 2}, on_feedback=on_feedback)
        assert status == 4
        feedback_client.append(await first)

    for _ in range(args.goals):
        loop.run_until_complete(goal_petrobot())
        loop.run_until_complete(goal_client())
    loop.run_until_complete(link.close())
    loop.run_until_complete(session.close())
    sdk.session_mgr.session.close()
    loop.close()
    d, p, c = _stats(direct), _stats(petrobot), _stats(client)
    return {
        "calls_per_path": len(direct), "goals_per_path": args.goals, "results": args.results,
        "robot_step_s": args.step_s, "direct_sdk": d, "petrobot": p, "petrobot_client_only": c,
        "overhead_p50_ms": round(p["p50_ms"] - d["p50_ms"], 3), "ratio_p50": round(p["p50_ms"] / d["p50_ms"], 3),
        "node_hop_p50_ms": round(p["p50_ms"] - c["p50_ms"], 3),
        "goal_to_feedback_petrobot": _stats(feedback_petrobot), "goal_to_feedback_client_only": _stats(feedback_client),
    }


if __name__ == "__main__":
    sys.exit(main())
