"""``petrobot up``: start every node of services.toml on this machine (a one-machine setup).

Each node runs as ``python -m services.node NAME`` in its own process; their log lines are printed
prefixed with the node name. The command waits until every node accepts connections, then stays in
the foreground until Ctrl-C or SIGTERM (or until a node dies), and stops them all with SIGTERM
(SIGKILL after 5 s). The machinery is :class:`coordinator.nodegroup.NodeGroup`.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_parser", "run"]

DESCRIPTION = """\
Start every node of the location file as a subprocess on this machine, print their log lines
prefixed with the node name, wait until all of them listen, and stay in the foreground until
Ctrl-C or SIGTERM; then stop them all. Use it for a one-machine setup; on several hosts run
`petrobot node NAME` on each host instead."""


def add_parser(subparsers: Any) -> None:
    """Register ``up`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("up", help="start every node of services.toml on this machine",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    options.add_services(p, help="location file whose nodes to start (default: %(default)s)")
    p.add_argument("--node", action="append", dest="nodes", metavar="NAME",
                   help="start only this node (repeatable; default: every node of the file)")
    options.add_key_file(p)
    p.add_argument("--node-log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level of the nodes (default: INFO: one line per connection, call, result)")
    p.set_defaults(func=run)


async def _up(args: argparse.Namespace) -> int:
    import asyncio
    import signal

    from coordinator.nodegroup import NodeGroup

    group = NodeGroup(args.services, args.nodes, key_file=args.key_file, log_level=args.node_log_level)
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await group.start()
        print(f"up: {len(group.names)} node(s) listening: "
              + ", ".join(f"{n} {h}:{p}" for n in group.names for h, p in [group.location.address(n)])
              + " (Ctrl-C stops them)", file=sys.stderr, flush=True)
        stopper = loop.create_task(stop.wait())
        dead = loop.create_task(group.wait_any_exit())
        done, _ = await asyncio.wait({stopper, dead}, return_when=asyncio.FIRST_COMPLETED)
        code = 0
        if dead in done:
            name = dead.result()
            print(f"up: node {name} exited with status {group.procs[name].returncode}; stopping the others",
                  file=sys.stderr, flush=True)
            code = 1
        for t in (stopper, dead):
            t.cancel()
        return code
    except PetrobotError as exc:
        print(f"up: error: {exc}", file=sys.stderr)
        return 1
    finally:
        await group.stop()
        print("up: all nodes stopped", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Start the nodes and block until Ctrl-C/SIGTERM; return the exit code."""
    import asyncio

    from services.errors import LocationError

    try:
        return asyncio.run(_up(args))
    except LocationError as exc:
        print(f"up: error: {exc}", file=sys.stderr)
        return 2
