"""The command line of a node process: ``python -m services.node NAME`` (or ``petrobot node NAME``).

``python -m services.node NAME [--services services.toml] [--key-file F] [--state-dir DIR]
[--volatile] [--synchronous normal|full] [--log-level L]`` reads the location file and the shared
key(s), opens the node's result store (an SQLite file in its state directory, so that a repeated
call id is answered with its first result across restarts: :mod:`services.node.store`), starts the
:class:`~services.node.server.Node` named ``NAME``, prints ``node NAME listening on HOST:PORT`` to
stderr when it accepts connections, and runs until SIGTERM or SIGINT. Exit codes: 0 after a clean
stop, 1 when the node cannot start (address in use, an action or driver that cannot be built), 2
for a bad services file, node name, key or state directory.
"""

from __future__ import annotations

import argparse
import ctypes
import asyncio
import gc
import logging
import signal
import sys
import time
from collections.abc import Sequence

from services.errors import LocationError, PetrobotError
from services.keys import load_keys
from services.location import parse_location
from services.node.calls import ResultCache
from services.node.server import Node
from services.node.store import SqliteResultCache, default_state_dir
from services.node.watch import digest_of

__all__ = ["MMAP_THRESHOLD", "build_parser", "main", "return_large_blocks", "run_node"]


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
    p.add_argument("--state-dir", default=None, metavar="DIR",
                   help="where the node keeps call results across restarts (default: state_dir of "
                        "[nodes.NAME], else $XDG_STATE_HOME/petrobot/NAME, i.e. ~/.local/state/petrobot/NAME)")
    p.add_argument("--volatile", action="store_true",
                   help="keep call results in memory only: after a restart a repeated call id runs again")
    p.add_argument("--synchronous", default="normal", choices=["normal", "full"],
                   help="normal (default): results survive the node process dying; full: also a power "
                        "cut, at the cost of an fsync per group commit")
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


MMAP_THRESHOLD = 256 * 1024
"""Blocks at least this large (bytes) are mapped and unmapped on their own by the C allocator."""


def return_large_blocks() -> bool:
    """Make glibc's allocator give memory of large blocks back to the system when they are freed.

    By default glibc raises its mmap threshold to the size of the largest block freed (up to
    32 MiB): after one 16 MiB frame, later frames come from the heap, which is seldom given back,
    and a node's RSS grows by what it once held, far beyond what its result store is allowed (issue
    22: 30 -> 147 MiB under a 64 MiB budget). A fixed threshold (:data:`MMAP_THRESHOLD`) keeps
    large frames, parameters and results in blocks of their own, unmapped when freed. A no-op
    returning False where the C library is not glibc.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # malloc.h
    return bool(mallopt(m_mmap_threshold, MMAP_THRESHOLD)) and bool(mallopt(m_trim_threshold, 2 * MMAP_THRESHOLD))


def run_node(args: argparse.Namespace) -> int:
    """Run a node from parsed arguments until SIGTERM/SIGINT; return the exit code."""
    logging.basicConfig(level=args.log_level, stream=sys.stderr, force=True,
                        format=f"%(asctime)s {args.name} %(levelname)s %(message)s")
    return_large_blocks()
    try:
        try:
            with open(args.services, "rb") as fh:
                data = fh.read()
            text = data.decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise LocationError(f"{args.services}: cannot read location file: {exc}") from exc
        location = parse_location(text, path=args.services)
        location.address(args.name)
        keys = load_keys(args.key_file)
        results: ResultCache | None = None
        if not args.volatile:
            state_dir = args.state_dir or location.nodes[args.name].state_dir or default_state_dir(args.name)
            results = SqliteResultCache(state_dir, now=time.time(), synchronous=args.synchronous.upper())
        node = Node(args.name, location, keys[0], previous_keys=keys[1:], results=results,
                    location_digest=digest_of(data))
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
