"""``petrobot sim catching|mobile|zenoh|ros2``: a testbed's physical world as a process (paper §6).

The worlds live in :mod:`sim` (:mod:`sim.catching.process`, :mod:`sim.mobile.process`, and the ROS 2
demo's Zenoh router and stand-in ROS 2 robot in :mod:`sim.ros2.process`); this command parses their
options and runs the one asked for. ``python -m coordinator.commands.sim WORLD [options]`` does the
same without the ``petrobot`` front end (the demos start their worlds so).

Ports: services.toml is the one source of truth. Unless ``--camera-port`` or ``--can-port`` say
otherwise, the world serves its camera and its CAN bus on the ports services.toml gives the drivers
that use them (each driver says which server it needs, and that this world serves it:
:func:`services.devices.probe.device_endpoints`); without such a driver, or without the file, on
the world's defaults. Likewise, unless ``--listen`` (``zenoh``) or ``--router`` (``ros2``) say
otherwise, the router is on 127.0.0.1 at the port of the Zenoh router the file's ROS 2 nodes
connect to (their ``ros2.NODE`` drivers name it).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_parser", "device_ports", "main", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``sim`` (with its ``catching``, ``mobile``, ``zenoh`` and ``ros2`` worlds) on the
    ``petrobot`` sub-command parser."""
    from sim.catching.process import add_arguments as add_catching_arguments
    from sim.mobile.process import add_arguments as add_mobile_arguments
    from sim.ros2.process import add_robot_arguments, add_router_arguments

    parser = subparsers.add_parser(
        "sim",
        help="run a simulated world (the catching or the mobile testbed, the ROS 2 demo's router or robot) as a "
             "process",
        description="Run a simulated physical world with hardware-like back ends on 127.0.0.1.",
    )
    worlds = parser.add_subparsers(dest="world", required=True, metavar="WORLD")
    c = worlds.add_parser(
        "catching",
        help="table, thrower, ball, PUMA 560 with cup; camera server and CAN gateway",
        description=(
            "The catching testbed (paper section 6): a pybullet world at 1 kHz with a rolling table, "
            "a seeded thrower, a 40 mm ping-pong ball and a PUMA 560 with a cup and a crossfire "
            "sensor. Serves the overhead camera (TCP frame server) and the PUMA's CAN bus (a "
            "socketcand-protocol gateway for python-can) on 127.0.0.1, and prints one JSON line per "
            "event (ready, throw, crossing, result) on stdout. Stop it with Ctrl-C or SIGTERM."
        ),
    )
    add_catching_arguments(c)
    _add_services(c)
    m = worlds.add_parser(
        "mobile",
        help="the mobile robot's course: downward camera + beacon sensor server, CAN gateway (velocity mode)",
        description=(
            "The mobile-robot testbed (paper section 6, Figs. 2-3): a pybullet world at 250 Hz with the "
            "course's chessboard floor, track, beacons and a differential-drive robot. Serves the downward "
            "camera with the beacon scans (TCP frame server) and the two wheel drives (CiA 402 profile "
            "velocity mode on a socketcand-protocol CAN gateway) on 127.0.0.1, and prints one JSON line "
            "per event (ready, pose: ground truth, drive_fault, stopped) on stdout."
        ),
    )
    add_mobile_arguments(m)
    _add_services(m)
    z = worlds.add_parser(
        "zenoh", help="a Zenoh router on the loopback (the middle of the ROS 2 demo's graph)",
        description="A Zenoh router (eclipse-zenoh in router mode, multicast scouting off), as rmw_zenohd is on a "
                    "ROS 2 machine. Prints a JSON ready line; stop it with Ctrl-C or SIGTERM.")
    add_router_arguments(z)
    _add_services(z, "the Zenoh router's port")
    r = worlds.add_parser(
        "ros2", help="a stand-in ROS 2 robot (zenoh-ros2-sdk): AddTwoInts, Fibonacci action, /crossfire",
        description="A stand-in ROS 2 robot built on zenoh-ros2-sdk, speaking rmw_zenoh through the router: the "
                    "service /add_two_ints (example_interfaces/srv/AddTwoInts), the action /fibonacci "
                    "(example_interfaces/action/Fibonacci: feedback per term, cancellable) and the topic "
                    "/crossfire (std_msgs/msg/Bool). Prints one JSON line per event (ready, service, goal, cancel, "
                    "result, crossfire); stop it with Ctrl-C or SIGTERM.")
    add_robot_arguments(r)
    _add_services(r, "the Zenoh router's port")


def _add_services(parser: argparse.ArgumentParser, what: str = "the camera and CAN ports") -> None:
    options.add_services(parser, help=f"location file whose drivers give {what} (default: %(default)s, when it "
                                      "exists)")


def device_ports(services: str | os.PathLike[str], world: str) -> dict[str, int]:
    """The ports services.toml gives the device servers world ``world`` serves: ``{"frames": camera
    port, "socketcand": CAN port}`` (a key is missing when no driver needs that server).

    Raises:
        LocationError: the file is bad.
        PetrobotError: two drivers want the same server of this world on different ports.
    """
    from services.devices.probe import device_endpoints
    from services.location import load_location

    found: dict[str, dict[int, str]] = {}
    for spec, end in device_endpoints(load_location(services)):
        if end.served_by.split(" (", 1)[0] == f"petrobot sim {world}":
            found.setdefault(end.protocol, {})[end.port] = spec.name
    for protocol, ports in found.items():
        if len(ports) > 1:
            which = ", ".join(f"{port} (driver {name})" for port, name in sorted(ports.items()))
            raise PetrobotError(f"{services}: the drivers want the {world} world's {protocol} server on "
                                f"different ports: {which}")
    return {protocol: next(iter(ports)) for protocol, ports in found.items()}


# what each world takes from services.toml: the world whose servers its drivers name, {option: protocol}
_FROM_SERVICES: dict[str, tuple[str, dict[str, str]]] = {
    "catching": ("catching", {"camera_port": "frames", "can_port": "socketcand"}),
    "mobile": ("mobile", {"camera_port": "frames", "can_port": "socketcand"}),
    "zenoh": ("zenoh", {"listen": "zenoh"}),
    "ros2": ("zenoh", {"router": "zenoh"}),  # the robot connects to the router petrobot sim zenoh serves
}


def _ports_from_services(args: argparse.Namespace) -> None:
    """Fill in the ports the command line left open from services.toml (module docstring)."""
    served_by, wanted = _FROM_SERVICES[args.world]
    open_options = [option for option in wanted if getattr(args, option) is None]
    services = getattr(args, "services", None)
    if not open_options or services is None or not (os.path.exists(services)
                                                    or services != options.DEFAULT_SERVICES):
        return
    ports = device_ports(services, served_by)
    for option in open_options:
        port = ports.get(wanted[option])
        if port is not None:
            setattr(args, option, port if wanted[option] != "zenoh" else f"tcp/127.0.0.1:{port}")


def run(args: argparse.Namespace) -> int:
    """Run the world ``args.world`` until stopped (or ``--duration``); returns the exit code (2 when
    it cannot start, with the reason on stderr: e.g. a port already in use)."""
    run_world: Callable[[argparse.Namespace], int]
    if args.world == "mobile":
        from sim.mobile.process import run as run_world
    elif args.world == "catching":
        from sim.catching.process import run as run_world
    elif args.world == "zenoh":
        from sim.ros2.process import run_router as run_world
    elif args.world == "ros2":
        from sim.ros2.process import run_robot as run_world
    else:
        print(f"unknown world {args.world!r}", file=sys.stderr)
        return 2
    try:
        _ports_from_services(args)
        return run_world(args)
    except PetrobotError as exc:  # ServeError among them: a port in use...
        print(f"petrobot sim {args.world}: {exc}", file=sys.stderr)
        return 2


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point: ``python -m coordinator.commands.sim catching|mobile|zenoh|ros2 [options]``."""
    parser = argparse.ArgumentParser(prog="python -m coordinator.commands.sim")
    sub = parser.add_subparsers(dest="command")
    add_parser(sub)
    args = parser.parse_args(["sim", *(sys.argv[1:] if argv is None else argv)])
    return run(args)


if __name__ == "__main__":
    raise SystemExit(main())
