"""``petrobot example fleet --robots N [--safe] [--chargers C] [--missions M] [-o FILE]``: write a generated task net.

Thin shell over :func:`coordinator.netfile.fleet.fleet_toml`: N mobile robots sharing two aisles, a
lift and chargers, each mission a chain of primitive tasks with error exits (docs/analysis.md,
section 9, "The fleet"). The net goes to FILE, or to stdout; ``petrobot analyze FILE`` then answers
whether the fleet can deadlock, with the explicit or the symbolic engine by the fleet's size; with
``--missions M``, ``petrobot run FILE`` executes it on the simulated fleet actions of services.toml.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


DESCRIPTION = """\
Write a generated task net. fleet: N mobile robots sharing two aisles (capacity one each), a lift
and chargers; each robot loads at station A, drives through aisle 1, rides the lift, drives through
aisle 2, unloads at station B, comes back the same way and charges; every primitive task has an
error exit into a manual recovery. A robot waits for the next resource holding the one it is in, so
the fleet can deadlock; --safe adds a corridor token (one robot in the aisles and lift at a time).
Without --missions the robots go round for ever (the net `petrobot analyze` is about); with
--missions M each robot runs M missions, so that a run of the net ends."""

EPILOG = """\
running a fleet on this machine (nodes started once with `petrobot up &`):
  petrobot example fleet --robots 2 --safe --missions 2 -o runs/fleet.toml
  petrobot run runs/fleet.toml
services.toml places simulated primitive actions for the fleet's primitive tasks on node alpha
(load_tote, drive_aisle, ride_lift, unload_tote, charge_battery, manual_recovery): each takes its
`seconds` and ends in its error exit (into recovery) with probability `p_error`, both set in its
params there. The run ends completed when every robot is parked again after its missions, stuck
(exit 1) when a fleet without --safe deadlocks."""


def add_parser(subparsers: Any) -> None:
    """Register ``example`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "example", help="write a generated example net (a fleet of N robots)",
        description=DESCRIPTION, epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("kind", choices=["fleet"], help="the example to write")
    parser.add_argument("--robots", type=int, default=4, metavar="N", help="number of robots (default 4)")
    parser.add_argument("--chargers", type=int, default=None, metavar="C",
                        help="number of chargers (default: one per four robots, rounded up)")
    parser.add_argument("--safe", action="store_true", help="add the corridor token: a deadlock-free fleet")
    parser.add_argument("--missions", type=int, default=None, metavar="M",
                        help="missions per robot, then the run ends (default: endless, for analyze)")
    parser.add_argument("-o", "--output", metavar="FILE", help="write the net here (default: stdout)")


def run(args: argparse.Namespace) -> int:
    """Write the net; return 0, or 2 on a bad size or a file that cannot be written."""
    from coordinator.netfile.fleet import fleet_toml

    try:
        text = fleet_toml(args.robots, chargers=args.chargers, safe=args.safe, missions=args.missions)
    except ValueError as exc:
        print(f"petrobot example: {exc}", file=sys.stderr)
        return 2
    if args.output:
        try:
            Path(args.output).parent.mkdir(parents=True, exist_ok=True)
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as exc:
            print(f"petrobot example: cannot write {args.output}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        print(f"wrote {args.output}: {args.robots} robots", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
