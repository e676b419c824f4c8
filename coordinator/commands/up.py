"""``petrobot up``: start the nodes of services.toml on this machine (a one-machine setup).

Which nodes: those named on the command line; with none, every node whose devices answer. A node
whose driver needs a device server (the camera server, the CAN gateway, served by ``petrobot sim
catching`` in the simulation) is left out, with the reason, when nothing answers at that address:
start the simulator first, or name the node to start it anyway. Each node runs as ``python -m
services.node NAME`` in its own process; its log goes to ``LOG_DIR/NAME.log`` (``runs/logs`` by
default, said on screen). A node that exits is reported with its last log line, and the others go
on; ``up`` ends on Ctrl-C or SIGTERM (status 0), or when no node is left (status 1), and stops the
nodes with SIGTERM (SIGKILL after 5 s). The machinery is :class:`coordinator.nodegroup.NodeGroup`.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_parser", "missing_devices", "run"]

DESCRIPTION = """\
Start nodes of the location file as subprocesses on this machine and stay in the foreground until
Ctrl-C or SIGTERM; then stop them all. Use it for a one-machine setup; on several hosts run
`petrobot node NAME` on each host instead.

Which nodes:
  petrobot up                  every node whose devices answer. A node whose driver needs a device
                               server (the camera server or the CAN gateway of the catching testbed,
                               served by `petrobot sim catching`) is not started while nothing
                               answers there; `up` says which and why. With the project's
                               services.toml: alpha and beta; vision and motion too once
                               `petrobot sim catching` is running.
  petrobot up vision motion    exactly the nodes named (also --node NAME), devices or not.

Each node's log goes to LOG_DIR/NAME.log (default runs/logs; the paths are printed). A node that
exits is reported with its last log line; the others keep running. `up` ends with status 0 on
Ctrl-C/SIGTERM, 1 when no node is left running, 2 on a bad location file or node name."""


def add_parser(subparsers: Any) -> None:
    """Register ``up`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("up", help="start the nodes of services.toml on this machine",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("names", nargs="*", metavar="NODE",
                   help="nodes to start (default: every node whose devices answer)")
    options.add_services(p, help="location file whose nodes to start (default: %(default)s)")
    p.add_argument("--node", action="append", dest="nodes", metavar="NAME",
                   help="start this node too (repeatable; same as naming it)")
    options.add_key_file(p)
    p.add_argument("--node-log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level of the nodes (default: INFO: one line per connection, call, result)")
    p.add_argument("--log-dir", default="runs/logs", metavar="DIR",
                   help="directory of the nodes' log files NAME.log (default: %(default)s)")
    p.set_defaults(func=run)


def _say(text: str) -> None:
    print(f"up: {text}", file=sys.stderr, flush=True)


def missing_devices(location: Any, node: str, timeout_s: float = 0.5) -> list[tuple[str, str]]:
    """The device servers node ``node``'s drivers need that do not answer: (server, served by).

    A driver class with a ``device(params)`` class method (a
    :class:`services.devices.endpoint.DeviceEndpoint`) names its server; each is asked whether it
    is there the way its protocol allows, without taking a frame or opening the bus
    (:func:`services.devices.probe.probe`, ``timeout_s`` each): the probe changes nothing in the
    world it probes.
    """
    from services.devices.probe import device_endpoints, probe

    return [(end.describe(), end.served_by) for _, end in device_endpoints(location, [node])
            if probe(end, timeout_s) is not None]


async def _up(args: argparse.Namespace) -> int:
    import asyncio
    import signal

    from coordinator.nodegroup import NodeGroup
    from services.location import load_location

    location = load_location(args.services)
    named = list(dict.fromkeys([*(args.names or []), *(args.nodes or [])]))
    for name in named:
        location.address(name)  # LocationError for an unknown node
    if named:
        names = named
    else:
        names = []
        for name in location.nodes:
            missing = await asyncio.to_thread(missing_devices, location, name)
            if missing:
                servers = " and ".join(d for d, _ in missing)
                by = " and ".join(dict.fromkeys(b for _, b in missing))
                _say(f"not starting node {name}: nothing answers at its {servers}; start {by} first, "
                     f"or name the node to start it anyway: petrobot up {name}")
            else:
                names.append(name)
        if not names:
            _say("no node to start")
            return 1
    group = NodeGroup(args.services, names, key_file=args.key_file, log_level=args.node_log_level,
                      log_dir=args.log_dir)
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        failed = await group.start(tolerate=True)
        for name in names:
            host, port = location.address(name)
            if name in failed:
                _say(f"node {name} did not start: {'; '.join(group.tail(name, 1)) or 'no output'} "
                     f"(log {group.log_path(name)})")
            else:
                _say(f"node {name} listening on {host}:{port} (log {group.log_path(name)})")
        if group.running():
            _say(f"{len(group.running())} node(s) running (Ctrl-C stops them)")
        stopper = loop.create_task(stop.wait())
        while group.running():
            dead = loop.create_task(group.wait_any_exit())
            done, _ = await asyncio.wait({stopper, dead}, return_when=asyncio.FIRST_COMPLETED)
            if stopper in done:
                dead.cancel()
                return 0
            name = dead.result()
            await asyncio.sleep(0.2)  # let the log follower read the last lines
            last = "; ".join(line for line in group.tail(name, 1) if line) or "no output"
            left = group.running()
            _say(f"node {name} exited with status {group.procs[name].returncode}: {last} "
                 f"(log {group.log_path(name)}); "
                 + (f"still running: {', '.join(left)}" if left else "no node left"))
        stopper.cancel()
        return 1
    except PetrobotError as exc:
        _say(f"error: {exc}")
        return 1
    finally:
        await group.stop()
        _say("all nodes stopped")


def run(args: argparse.Namespace) -> int:
    """Start the nodes and block until Ctrl-C/SIGTERM or no node is left; return the exit code."""
    import asyncio

    from services.errors import LocationError

    try:
        return asyncio.run(_up(args))
    except LocationError as exc:
        print(f"up: error: {exc}", file=sys.stderr)
        return 2
