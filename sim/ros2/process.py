"""``petrobot sim zenoh`` and ``petrobot sim ros2``: the ROS 2 side of the ROS 2 demo, as processes.

``petrobot sim zenoh --listen tcp/127.0.0.1:7457`` is a Zenoh router (what ``ros2 run rmw_zenoh_cpp
rmw_zenohd`` is on a ROS 2 machine): eclipse-zenoh opened in router mode, multicast scouting off,
on the loopback unless told otherwise.

``petrobot sim ros2 --router tcp/127.0.0.1:7457`` is the stand-in robot of
:class:`sim.ros2.robot.Ros2Robot`. With ``--commands`` its standard input takes commands, one per
line: ``crossfire true``, ``crossfire false``, ``crossfire auto`` (back to the periodic pulses) and
``quit``.

Both print one JSON line per event on stdout (``ready`` first) and stop on SIGTERM, Ctrl-C or
``quit``.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
from typing import Any

__all__ = ["add_robot_arguments", "add_router_arguments", "run_robot", "run_router"]

DEFAULT_ROUTER = "tcp/127.0.0.1:7457"


def add_router_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``petrobot sim zenoh``."""
    parser.add_argument("--listen", default=DEFAULT_ROUTER, metavar="ENDPOINT",
                        help=f"Zenoh endpoint to listen on (default {DEFAULT_ROUTER}; rmw_zenoh's own router "
                             "listens on tcp/[::]:7447)")


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``petrobot sim ros2``."""
    parser.add_argument("--router", default=DEFAULT_ROUTER, metavar="ENDPOINT",
                        help=f"the Zenoh router to connect to, tcp/HOST:PORT (default {DEFAULT_ROUTER})")
    parser.add_argument("--step-s", type=float, default=0.1,
                        help="seconds per Fibonacci term (the tutorial's server takes 1; default 0.1)")
    parser.add_argument("--crossfire-hz", type=float, default=20.0, help="/crossfire messages per second (default 20)")
    parser.add_argument("--crossfire-period", type=float, default=0.0, metavar="S",
                        help="a ball crosses the crossfire every S seconds (default 0: only on command)")
    parser.add_argument("--crossfire-pulse", type=float, default=0.3, metavar="S",
                        help="seconds the crossfire sees each ball (default 0.3)")
    parser.add_argument("--node-name", default="stand_in_robot", help="the robot's ROS 2 node name")
    parser.add_argument("--commands", action="store_true",
                        help="read commands on standard input: crossfire true|false|auto, quit")


def _emit(event: str, **data: Any) -> None:
    print(json.dumps({"event": event, "t": round(time.time(), 6), **data}), flush=True)


def _stop_on_signals(stop: threading.Event) -> None:
    def on_signal(signum: int, frame: Any) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)


def run_router(args: argparse.Namespace) -> int:
    """Run the router until stopped; exit status 0, or 2 if it cannot listen."""
    import zenoh

    config = zenoh.Config()
    for key, value in (("mode", "router"), ("listen/endpoints", [args.listen]), ("scouting/multicast/enabled", False),
                       ("scouting/gossip/enabled", True)):
        config.insert_json5(key, json.dumps(value))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        print(f"petrobot sim zenoh: cannot listen on {args.listen}: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    _stop_on_signals(stop)
    _emit("ready", listen=args.listen, zid=str(session.info.zid()))
    while not stop.wait(0.2):
        pass
    session.close()
    _emit("stopped")
    return 0


def _endpoint(text: str) -> tuple[str, int]:
    proto, _, address = text.partition("/")
    host, _, port = address.rpartition(":")
    if proto != "tcp" or not host or not port.isdigit():
        raise SystemExit(f"petrobot sim ros2: --router must be tcp/HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


def run_robot(args: argparse.Namespace) -> int:
    """Run the stand-in robot until stopped (stdin commands: see the module docstring)."""
    from sim.ros2.robot import Ros2Robot

    robot = Ros2Robot(_endpoint(args.router), sys.stdout, step_s=args.step_s, rate_hz=args.crossfire_hz,
                      period_s=args.crossfire_period, pulse_s=args.crossfire_pulse, node_name=args.node_name)
    stop = threading.Event()
    _stop_on_signals(stop)

    def commands() -> None:
        for line in sys.stdin:
            words = line.split()
            if words[:1] == ["quit"]:
                break
            if words[:1] == ["crossfire"] and len(words) == 2 and words[1] in ("true", "false", "auto"):
                robot.force_crossfire(None if words[1] == "auto" else words[1] == "true")
            elif words:
                print(f"petrobot sim ros2: unknown command {line.strip()!r} (crossfire true|false|auto, quit)",
                      file=sys.stderr)
                continue
            robot.emit("command", text=line.strip())
        else:
            return  # end of input: keep serving
        stop.set()

    if args.commands:
        threading.Thread(target=commands, name="commands", daemon=True).start()
    robot.ready(router=args.router)
    while not stop.wait(0.2):
        pass
    robot.close()
    robot.emit("stopped")
    return 0
