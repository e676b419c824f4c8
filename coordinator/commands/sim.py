"""``petrobot sim catching`` / ``petrobot sim mobile``: a testbed's physical world as a process (paper §6).

The worlds live in :mod:`sim` (:mod:`sim.catching.process`, :mod:`sim.mobile.process`); this
command parses their options and runs the one asked for. ``python -m coordinator.commands.sim
WORLD [options]`` does the same without the ``petrobot`` front end (the demo starts its world so).

Ports: services.toml is the one source of truth. Unless ``--camera-port`` or ``--can-port`` say
otherwise, the world serves its camera and its CAN bus on the ports services.toml gives the drivers
that use them (each driver says which server it needs, and that this world serves it:
:func:`services.devices.probe.device_endpoints`); without such a driver, or without the file, on
the world's defaults.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_parser", "device_ports", "main", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``sim`` (with its ``catching`` and ``mobile`` worlds) on the ``petrobot`` sub-command parser."""
    from sim.catching.process import add_arguments as add_catching_arguments
    from sim.mobile.process import add_arguments as add_mobile_arguments

    parser = subparsers.add_parser(
        "sim",
        help="run a simulated world (the catching or the mobile testbed) as a process",
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


def _add_services(parser: argparse.ArgumentParser) -> None:
    options.add_services(parser, help="location file whose drivers give the camera and CAN ports (default: "
                                      "%(default)s, when it exists)")


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
        if end.served_by == f"petrobot sim {world}":
            found.setdefault(end.protocol, {})[end.port] = spec.name
    for protocol, ports in found.items():
        if len(ports) > 1:
            which = ", ".join(f"{port} (driver {name})" for port, name in sorted(ports.items()))
            raise PetrobotError(f"{services}: the drivers want the {world} world's {protocol} server on "
                                f"different ports: {which}")
    return {protocol: next(iter(ports)) for protocol, ports in found.items()}


def run(args: argparse.Namespace) -> int:
    """Run the world ``args.world`` until stopped (or ``--duration``); returns the exit code (2 when
    it cannot start, with the reason on stderr: e.g. a port already in use)."""
    if args.world == "mobile":
        from sim.mobile.process import run as run_world
    elif args.world == "catching":
        from sim.catching.process import run as run_world
    else:
        print(f"unknown world {args.world!r}", file=sys.stderr)
        return 2
    try:
        if args.camera_port is None or args.can_port is None:
            services = getattr(args, "services", None)
            if services is not None and (os.path.exists(services) or services != options.DEFAULT_SERVICES):
                ports = device_ports(services, args.world)
                if args.camera_port is None:
                    args.camera_port = ports.get("frames")
                if args.can_port is None:
                    args.can_port = ports.get("socketcand")
        return run_world(args)
    except PetrobotError as exc:  # ServeError among them: a port in use...
        print(f"petrobot sim {args.world}: {exc}", file=sys.stderr)
        return 2


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point: ``python -m coordinator.commands.sim catching|mobile [options]``."""
    parser = argparse.ArgumentParser(prog="python -m coordinator.commands.sim")
    sub = parser.add_subparsers(dest="command")
    add_parser(sub)
    args = parser.parse_args(["sim", *(sys.argv[1:] if argv is None else argv)])
    return run(args)


if __name__ == "__main__":
    raise SystemExit(main())
