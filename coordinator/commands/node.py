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
    """Register ``node`` on the ``petrobot`` sub-command parser.

    The options are :func:`services.node.build_parser`'s own, added when the ``node`` command is
    parsed (:func:`_options_on_first_use`): ``petrobot --help`` and the other commands do not
    import the node.
    """
    parser = subparsers.add_parser(
        "node", help="run one node (a host's primitive-action server)", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=run)
    _options_on_first_use(parser)


def _options_on_first_use(parser: argparse.ArgumentParser) -> None:
    """Add the node's options to ``parser`` the first time it parses arguments (``--help`` too)."""
    parse = parser.parse_known_args

    def parse_known_args(args: Any = None, namespace: Any = None) -> Any:
        from services.node import build_parser

        del parser.parse_known_args  # back to the class's method, now that the options are there
        build_parser(parser)
        return parse(args, namespace)

    parser.parse_known_args = parse_known_args  # type: ignore[method-assign]


def run(args: argparse.Namespace) -> int:
    """Run the node until it is stopped; return the exit code (0 clean, 1 runtime error, 2 bad setup)."""
    from services.node import run_node

    return run_node(args)
