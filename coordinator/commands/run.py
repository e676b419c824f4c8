"""``petrobot run NET``: execute a task net on the nodes of services.toml (paper sections 2 and 5)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path
from typing import Any

from services.errors import PetrobotError

DESCRIPTION = """\
Execute a task net. Every primitive action is called on the node that services.toml places it
on; start the nodes first (`petrobot up` starts every node of services.toml on this machine).
The token flow is shown live on a terminal (line by line otherwise); type operator commands
and Enter:  + PLACE [N] (insert tokens in a control place), - PLACE [N] (remove), pause, step,
resume, abort. Every firing, action start, result and operator command is journaled in SQLite
before it takes effect; --resume continues the last unfinished run of the net from the journal.
The run ends when nothing more can happen (the net is dead) or on abort, with a summary."""


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("run", help="execute a task net on the nodes", description=DESCRIPTION,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("net", help="task net file (.toml or .pnml)")
    p.add_argument("--services", default="services.toml", help="location file (default: %(default)s)")
    p.add_argument("--journal", default="runs/journal.sqlite",
                   help="SQLite journal, created if missing (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of random switches and learners (default: 0)")
    p.add_argument("--resume", action="store_true",
                   help="continue the last unfinished run of this net recorded in the journal")
    p.add_argument("--key-file", default=None, help="shared key file (default: $PETROBOT_KEY, then "
                   "~/.config/petrobot/key)")
    p.add_argument("--max-seconds", type=float, default=None, help="abort the run after this many seconds")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--live", dest="live", action="store_true", default=None,
                      help="redraw a live screen (default on a terminal)")
    view.add_argument("--lines", dest="live", action="store_false", help="print one line per event")
    p.add_argument("--quiet", action="store_true", help="print only errors and the summary")
    p.add_argument("--no-input", action="store_true", help="do not read operator commands from stdin")
    p.set_defaults(func=run)


def build_learner(net: Any, seed: int, journal: Any) -> Any:
    """One learning automaton per primitive task (section 4), restored from the journal if saved there.

    Raises:
        LearnerConfigError: a task's ``learner`` table or its costs are invalid (names the task).
    """
    from coordinator.learning import Learner

    learner = Learner.from_net(net, seed)
    saved = {task: state for task, (_, state) in journal.load_learner().items()}
    if saved:
        learner.restore(saved, strict=False)
    return learner


async def execute(net: Any, *, location: Any, key: bytes, journal: Any, seed: int = 0, resume: bool = False,
                  net_text: str | None = None, live: bool | None = None, quiet: bool = False,
                  read_input: bool = False, max_seconds: float | None = None,
                  observer: Any = None, console: Any = None) -> Any:
    """Run ``net`` to its end and return the :class:`~coordinator.runtime.RunSummary`.

    ``console`` (a :class:`~coordinator.console.Console`, made from ``live``/``quiet`` if not given)
    shows the run; ``observer``, if given, receives the runtime's events instead and is expected
    to forward them to the console."""
    from coordinator.console import Console, read_operator_commands
    from coordinator.runtime import Runtime
    from services.client import ServiceClient

    recovered = None
    if resume:
        run_id = journal.last_unfinished_run(net.name)
        if run_id is None:
            raise PetrobotError(f"{journal.path}: no unfinished run of net {net.name!r} to resume")
        recovered = journal.recover(net, run_id)
    learner = build_learner(net, recovered.seed if recovered else seed, journal)
    async with ServiceClient(location, key) as client:
        runtime = Runtime(net, client, journal, seed=seed, learner=learner, recovered=recovered,
                          net_text=net_text)
        console = console or Console(net, live=live, quiet=quiet)
        console.attach(runtime)
        if observer is not None:
            runtime.observer = observer
        if read_input:
            read_operator_commands(runtime)
        refresher = asyncio.get_running_loop().create_task(_redraw(console)) if console.live else None
        try:
            return await runtime.run(max_seconds=max_seconds)
        finally:
            if refresher is not None:
                refresher.cancel()


async def _redraw(console: Any, period_s: float = 0.25) -> None:
    """Redraw the live screen so running actions' elapsed times advance between events."""
    while True:
        await asyncio.sleep(period_s)
        console.draw()


def run(args: argparse.Namespace) -> int:
    from coordinator.journal import Journal
    from coordinator.netfile import load_any
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
