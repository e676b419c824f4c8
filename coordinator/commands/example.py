"""``petrobot example fleet --robots N [--safe] [--chargers C] [-o FILE]``: write a generated task net.

Thin shell over :func:`coordinator.netfile.fleet.fleet_toml`: N mobile robots sharing two aisles, a
lift and chargers, each mission a chain of primitive tasks with error exits (docs/analysis.md,
section 9, "The fleet"). The net goes to FILE, or to stdout; ``petrobot analyze FILE`` then answers
whether the fleet can deadlock, with the explicit or the symbolic engine by the fleet's size.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``example`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "example", help="write a generated example net (a fleet of N robots)",
        description="Write a generated task net. fleet: N mobile robots sharing two aisles (capacity one "
                    "each), a lift and chargers; each robot loads at station A, drives through aisle 1, "
                    "rides the lift, drives through aisle 2, unloads at station B, comes back the same way "
                    "and charges; every primitive task has an error exit into a manual recovery. A robot "
                    "waits for the next resource holding the one it is in, so the fleet can deadlock; "
                    "--safe adds a corridor token (one robot in the aisles and lift at a time).")
    parser.add_argument("kind", choices=["fleet"], help="the example to write")
    parser.add_argument("--robots", type=int, default=4, metavar="N", help="number of robots (default 4)")
    parser.add_argument("--chargers", type=int, default=None, metavar="C",
                        help="number of chargers (default: one per four robots, rounded up)")
    parser.add_argument("--safe", action="store_true", help="add the corridor token: a deadlock-free fleet")
    parser.add_argument("-o", "--output", metavar="FILE", help="write the net here (default: stdout)")


def run(args: argparse.Namespace) -> int:
    """Write the net; return 0, or 2 on a bad size."""
    from coordinator.netfile.fleet import fleet_toml

    try:
        text = fleet_toml(args.robots, chargers=args.chargers, safe=args.safe)
    except ValueError as exc:
        print(f"petrobot example: {exc}", file=sys.stderr)
        return 2
    if args.output:
        Path(args.output).write_text(text, encoding="utf-8")
        print(f"wrote {args.output}: {args.robots} robots", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
