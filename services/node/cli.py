"""The command line of a node process: ``python -m services.node NAME`` (or ``petrobot node NAME``).

``python -m services.node NAME [--services services.toml] [--key-file F] [--log-level L]`` reads the
location file and the shared key, starts the :class:`~services.node.server.Node` named ``NAME``,
prints ``node NAME listening on HOST:PORT`` to stderr when it accepts connections, and runs until
SIGTERM or SIGINT. Exit codes: 0 after a clean stop, 1 when the node cannot start (address in use,
an action or driver that cannot be built), 2 for a bad services file, node name or key.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import logging
import signal
import sys
from collections.abc import Sequence

from services.errors import PetrobotError
from services.keys import load_key
from services.location import load_location
from services.node.server import Node

__all__ = ["build_parser", "main", "run_node"]


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """Options of ``python -m services.node`` / ``petrobot node``."""
    p = parser or argparse.ArgumentParser(
        prog="python -m services.node", description="Run one petrobot node: host the primitive actions "
        "services.toml places on it and serve them over TCP (docs/protocol.md).")
    p.add_argument("name", help="node name, a [nodes.NAME] table of the services file")
    p.add_argument("--services", default="services.toml", metavar="FILE",
                   help="location file naming nodes, actions, drivers and events (default: services.toml)")
    p.add_argument("--key-file", default=None, metavar="FILE",
                   help="shared key file (default: $PETROBOT_KEY, else $PETROBOT_KEY_FILE, "
                        "else ~/.config/petrobot/key, created if missing)")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level of the stderr log (default: INFO: one line per connection, call, result)")
    return p


async def _serve(node: Node) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await node.start()
    # Long-lived objects made during start-up need no more collection; and a larger first-generation
    # threshold spares the per-call allocations most collector runs (fewer multi-ms pauses at p99).
    gc.freeze()
    gc.set_threshold(20_000, 50, 100)
    print(f"node {node.name} listening on {node.host}:{node.port}", file=sys.stderr, flush=True)
    try:
        await stop.wait()
    finally:
        await node.stop()


def run_node(args: argparse.Namespace) -> int:
    """Run a node from parsed arguments until SIGTERM/SIGINT; return the exit code."""
    logging.basicConfig(level=args.log_level, stream=sys.stderr, force=True,
                        format=f"%(asctime)s {args.name} %(levelname)s %(message)s")
    try:
        location = load_location(args.services)
        key = load_key(args.key_file)
        node = Node(args.name, location, key)
    except PetrobotError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        asyncio.run(_serve(node))
    except OSError as exc:
        print(f"error: node {args.name}: {exc}", file=sys.stderr)
        return 1
    except PetrobotError as exc:
        print(f"error: node {args.name}: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m services.node``."""
    return run_node(build_parser().parse_args(argv))
