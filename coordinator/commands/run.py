"""``petrobot run NET``: execute a task net on the nodes of services.toml (paper sections 2 and 5).

A thin command over :func:`coordinator.session.execute`.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_parser", "run"]

DESCRIPTION = """\
Execute a task net. Every primitive action is called on the node that services.toml places it
on; start the nodes first (`petrobot up` starts every node of services.toml on this machine).
The token flow is shown live on a terminal (line by line otherwise); type operator commands
and Enter:  + PLACE [N] (insert tokens in a control place), - PLACE [N] (remove), pause, step,
resume, abort. Every firing, action start, result and operator command is journaled in SQLite
before it takes effect; --resume continues the last unfinished run of the net from the journal.
The run ends when nothing more can happen (the net is dead) or on abort, with a summary."""


def add_parser(subparsers: Any) -> None:
    """Register ``run`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("run", help="execute a task net on the nodes", description=DESCRIPTION,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("net", help="task net file (.toml or .pnml)")
    options.add_services(p)
    options.add_journal(p, default="runs/journal.sqlite",
                        help="SQLite journal, created if missing (default: %(default)s)")
    options.add_seed(p)
    p.add_argument("--resume", action="store_true",
                   help="continue the last unfinished run of this net recorded in the journal")
    options.add_key_file(p)
    options.add_max_seconds(p)
    options.add_view(p, quiet=True)
    p.add_argument("--no-input", action="store_true", help="do not read operator commands from stdin")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the net to its end; 0 when it ended dead, 1 otherwise, 2 on an error, 130 on Ctrl-C."""
    import asyncio

    from coordinator.journal import Journal
    from coordinator.netfile import load_any
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location

    try:
        net = load_any(args.net)
        problems = net.interpretation_problems()
        if problems:
            for element, problem in problems:
                print(f"{args.net}: {element}: {problem}", file=sys.stderr)
            return 1
        location = load_location(args.services)
        key = load_key(args.key_file)
        Path(args.journal).parent.mkdir(parents=True, exist_ok=True)
        text = Path(args.net).read_text(encoding="utf-8") if args.net.endswith(".toml") else None
        with Journal(args.journal) as journal:
            summary = asyncio.run(execute(
                net, location=location, key=key, journal=journal, seed=args.seed, resume=args.resume,
                net_text=text, live=args.live, quiet=args.quiet,
                read_input=not args.no_input and sys.stdin.isatty(), max_seconds=args.max_seconds))
    except PetrobotError as exc:
        print(f"petrobot run: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("petrobot run: interrupted; resume with --resume", file=sys.stderr)
        return 130
    print(summary.format())
    print(f"journal: {args.journal}")
    logging.getLogger("petrobot").debug("run finished")
    return 0 if summary.end_state == "dead" else 1
