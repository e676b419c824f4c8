"""``petrobot sim zenoh`` and ``petrobot sim ros2``: the ROS 2 side of the ROS 2 demo, as processes.

``petrobot sim zenoh --listen tcp/127.0.0.1:7457`` is a Zenoh router (what ``ros2 run rmw_zenoh_cpp
rmw_zenohd`` is on a ROS 2 machine): eclipse-zenoh opened in router mode, multicast scouting off,
on the loopback unless told otherwise.

``petrobot sim ros2 --router tcp/127.0.0.1:7457`` is the stand-in robot of
:class:`sim.ros2.robot.Ros2Robot`. With ``--commands`` its standard input takes commands, one per
line: ``crossfire true``, ``crossfire false``, ``crossfire auto`` (back to the periodic pulses) and
``quit``.

Both print one JSON line per event on stdout (``ready`` first) and stop on SIGTERM, Ctrl-C or
``quit`` (:func:`sim.process.stop_on_signals`, as the testbeds' worlds do). Unless ``--listen`` or
``--router`` say otherwise, the router is the one services.toml's ROS 2 nodes connect to, on
127.0.0.1 (``petrobot sim`` takes its port from the file), else :data:`DEFAULT_ROUTER`. A router
that cannot listen, or a ``--router`` that is no ``tcp/HOST:PORT``, ends the process with status 2
and one line saying why.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

from services.errors import PetrobotError
from sim.process import ServeError, stop_on_signals

__all__ = ["DEFAULT_ROUTER", "add_robot_arguments", "add_router_arguments", "run_robot", "run_router"]

DEFAULT_ROUTER = "tcp/127.0.0.1:7457"


def add_router_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``petrobot sim zenoh``."""
    parser.add_argument("--listen", default=None, metavar="ENDPOINT",
                        help=f"Zenoh endpoint to listen on (default: tcp/127.0.0.1 on the port of the router the "
                             f"ROS 2 nodes of services.toml connect to, else {DEFAULT_ROUTER}; rmw_zenoh's own "
                             "router listens on tcp/[::]:7447)")


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``petrobot sim ros2``."""
    parser.add_argument("--router", default=None, metavar="ENDPOINT",
                        help=f"the Zenoh router to connect to, tcp/HOST:PORT (default: tcp/127.0.0.1 on the port of "
                             f"the router the ROS 2 nodes of services.toml connect to, else {DEFAULT_ROUTER})")
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


def run_router(args: argparse.Namespace) -> int:
    """Run the router until stopped; exit status 0.

    Raises:
        ServeError: it cannot listen on ``--listen``.
    """
    import zenoh

    listen = args.listen or DEFAULT_ROUTER
    config = zenoh.Config()
    for key, value in (("mode", "router"), ("listen/endpoints", [listen]), ("scouting/multicast/enabled", False),
                       ("scouting/gossip/enabled", True)):
        config.insert_json5(key, json.dumps(value))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        raise ServeError(f"cannot listen on {listen}: {exc}") from None
    stop = threading.Event()
    restore = stop_on_signals(stop.set)
    _emit("ready", listen=listen, zid=str(session.info.zid()))
    while not stop.wait(0.2):
        pass
    session.close()
    restore()
    _emit("stopped")
    return 0


def _endpoint(text: str) -> tuple[str, int]:
    proto, _, address = text.partition("/")
    host, _, port = address.rpartition(":")
    if proto != "tcp" or not host or not port.isdigit():
        raise PetrobotError(f"--router must be tcp/HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


def run_robot(args: argparse.Namespace) -> int:
    """Run the stand-in robot until stopped (stdin commands: see the module docstring); exit status 0.

    Raises:
        PetrobotError: ``--router`` is no ``tcp/HOST:PORT``.
    """
    from sim.ros2.robot import Ros2Robot

    router = args.router or DEFAULT_ROUTER
    robot = Ros2Robot(_endpoint(router), sys.stdout, step_s=args.step_s, rate_hz=args.crossfire_hz,
                      period_s=args.crossfire_period, pulse_s=args.crossfire_pulse, node_name=args.node_name)
    stop = threading.Event()
    restore = stop_on_signals(stop.set)

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
    robot.ready(router=router)
    while not stop.wait(0.2):
        pass
    robot.close()
    restore()
    robot.emit("stopped")
    return 0
