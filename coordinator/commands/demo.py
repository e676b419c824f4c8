"""``petrobot demo``: the project's main job on one machine, in one command.

``petrobot demo foundation`` starts every node of services.toml on localhost, runs
``nets/demo.toml`` (a small task net whose primitive actions live on two nodes) with the token
flow visible, prints the summary and stops the nodes. Everything is journaled.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import Any

from coordinator.errors import PetrobotError

ROOT = Path(__file__).resolve().parents[2]

DESCRIPTION = """\
Run a demonstration on this machine: start the nodes of services.toml as local processes,
execute the task net with the token flow visible, print the summary, stop everything.

  foundation   nets/demo.toml: sense on node alpha, compute on alpha or beta (learnt), three
               runs, error recovery hidden. Needs only the two demo nodes.

Every firing, action start and result goes to the journal (--journal)."""


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("demo", help="run a demonstration on localhost (nodes + coordinator)",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("which", nargs="?", default="foundation", choices=["foundation"],
                   help="which demonstration (default: %(default)s)")
    p.add_argument("--services", default=str(ROOT / "services.toml"), help="location file (default: the project's)")
    p.add_argument("--journal", default="runs/demo.sqlite", help="SQLite journal (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of random switches and learners")
    p.add_argument("--key-file", default=None, help="shared key file (default: $PETROBOT_KEY, then "
                   "~/.config/petrobot/key, created if missing)")
    p.add_argument("--live", dest="live", action="store_true", default=None,
                   help="redraw a live screen (default on a terminal)")
    p.add_argument("--lines", dest="live", action="store_false", help="print one line per event")
    p.set_defaults(func=run)


async def _foundation(args: argparse.Namespace) -> int:
    from coordinator.commands.run import execute
    from coordinator.commands.up import NodeGroup
    from coordinator.journal import Journal
    from coordinator.netfile import load_net
    from services.keys import load_key
    from services.location import load_location

    net_path = ROOT / "nets" / "demo.toml"
    net = load_net(net_path)
    location = load_location(args.services)
    key = load_key(args.key_file)
    Path(args.journal).parent.mkdir(parents=True, exist_ok=True)
    print(f"demo: starting nodes {', '.join(location.nodes)} on this machine", file=sys.stderr, flush=True)
    async with NodeGroup(args.services, key_file=args.key_file, log_level="WARNING"):
        with Journal(args.journal) as journal:
            summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                    net_text=net_path.read_text(encoding="utf-8"), live=args.live,
                                    read_input=sys.stdin.isatty(), max_seconds=120)
    print(summary.format())
    print(f"journal: {args.journal}")
    return 0 if summary.end_state == "dead" else 1


def run(args: argparse.Namespace) -> int:
    try:
        return asyncio.run(_foundation(args))
    except PetrobotError as exc:
        print(f"petrobot demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
