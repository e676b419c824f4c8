"""``petrobot node NAME``: run one node, the server of a host's primitive actions (paper section 5).

The same program as ``python -m services.node NAME``; see :mod:`services.node`.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_parser", "run"]

DESCRIPTION = """\
Run node NAME of the location file: import and set up the drivers and primitive actions that
services.toml places on it, then serve them over TCP on the node's host:port (docs/protocol.md)
until SIGTERM or Ctrl-C. Calls are authenticated with the shared key; each call runs with its
deadline, can be cancelled, and a repeated call id gets the first result. Logs one line per
connection, call and result to stderr; prints "node NAME listening on HOST:PORT" when ready."""


def add_parser(subparsers: Any) -> None:
    """Register ``node`` on the ``petrobot`` sub-command parser."""
    from services.node import build_parser

    parser = subparsers.add_parser(
        "node", help="run one node (a host's primitive-action server)", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    build_parser(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the node until it is stopped; return the exit code (0 clean, 1 runtime error, 2 bad setup)."""
    from services.node import run_node

    return run_node(args)
