"""``petrobot run NET``: execute a task net on the nodes of services.toml (paper sections 2 and 5).

A thin command over :func:`coordinator.session.execute`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from pathlib import Path
from typing import Any

from coordinator.commands import options
from coordinator.commands.console import add_listen_options
from services.errors import PetrobotError

__all__ = ["add_parser", "console_address_file", "run"]

DESCRIPTION = """\
Execute a task net. Every primitive action is called on the node that services.toml places it
on; start the nodes first (`petrobot up` starts every node of services.toml on this machine).
Before the first firing the run checks that every primitive action of the net is placed in
services.toml and offered by a reachable node started from the same services.toml; if not, it
names each problem and exits 2 without running or journaling anything (--degraded starts anyway:
the calls of the missing actions then end in error and the net takes its error branches).
The token flow is shown live on a terminal (line by line otherwise); type operator commands
and Enter:  + PLACE [N] (insert tokens in a control place), - PLACE [N] (remove), pause, step,
resume, abort, end. Every firing, action start, result and operator command (refused ones too)
is journaled in SQLite before it takes effect; --resume continues the last unfinished or
interrupted run of the net from the journal.

Calls given up on: when a node is lost during a call (killed, frozen, cut off), the call ends in
error at once and the net takes its error branch. The node cancels such a call once its caller
has been gone for its heartbeat window (2 s), unless the action is placed `unattended = true`.
As soon as the node can be reached again (and at the end of the run, and on --resume) the run
asks it what became of the call, cancelling it if it still runs (an unattended one is waited
for), and journals the node's answer as a reconciliation (`petrobot show RUN`); a node that ran
the call otherwise than the net assumed is reported on the console ("node beta finished slow with
success after the coordinator declared it lost").

Waiting: when nothing can fire the run waits for its running primitive actions and for external
events that would let a transition fire. When only the operator could move it on (paused, or a
transition held back only by a control place) it waits for the operator if one is reading a
terminal, or with --wait; on a terminal it also waits at the home marking while a control place
could start more (type `+ runs_remaining 2` to run two more), until `end` or Ctrl-D. Without an
operator (--no-input, standard input not a terminal) such a run ends at once as
waiting_for_operator and names the commands it waited for. The live view and the summary say
what the run waits for and why it ended."""

EPILOG = """\
end states and exit codes:
  0    completed             nothing more can happen and the marking is home (declared `home`,
                             else the initial marking; control places and counters aside),
                             or meets --goal
  1    stuck                 tokens left away from home (a primitive-task place whose outcome no
                             transition takes, a resource not returned); the places are named
  2    (no run)              bad net, services.toml, key or journal; nothing to resume; the
                             nodes are not ready for the net (without --degraded)
  3    waiting_for_operator  only an operator command could go on and nobody can type one
  4    deadline              --max-seconds ran out while the run was going (a run waiting at home
                             for the operator ends completed)
  5    aborted               the operator typed abort
  6    completed             ... but every primitive-action call ended in error
  130  interrupted           Ctrl-C; `petrobot run NET --resume` continues the run"""


def add_parser(subparsers: Any) -> None:
    """Register ``run`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("run", help="execute a task net on the nodes", description=DESCRIPTION,
                              epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("net", help="task net file (.toml or .pnml)")
    options.add_services(p)
    options.add_journal(p, default="runs/journal.sqlite",
                        help="SQLite journal, created if missing (default: %(default)s)")
    options.add_seed(p)
    p.add_argument("--resume", action="store_true",
                   help="continue the last unfinished or interrupted run of this net in the journal")
    options.add_key_file(p)
    options.add_max_seconds(p)
    options.add_view(p, quiet=True)
    p.add_argument("--no-input", action="store_true", help="do not read operator commands from stdin")
    p.add_argument("--goal", action="append", metavar="PLACE=N",
                   help="the run has reached its goal when it comes to rest with at least N tokens in PLACE "
                        "(repeatable): it ends completed even away from home (a net that runs once)")
    p.add_argument("--degraded", action="store_true",
                   help="start even when the preflight finds actions no reachable node offers (they then "
                        "end in error); without it such a run exits 2 and journals nothing")
    p.add_argument("--wait", action="store_true",
                   help="wait for the operator even when nobody can type (no terminal, --no-input): the run "
                        "then ends on --max-seconds or Ctrl-C instead of ending waiting_for_operator")
    p.add_argument("--console", metavar="[HOST:]PORT", default=None,
                   help="also serve the web console attached to this run (petrobot console; port 0 picks a free "
                        "one): prints its address with the token that gives control, keeps it in the live view's "
                        "header and writes it to JOURNAL_STEM.console-url beside the journal for scripts "
                        "(runs/journal.console-url; removed at the end); the page is an operator, so the run "
                        "waits for it as with --wait")
    add_listen_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the net to its end; the exit code of its end state (see EPILOG), 2 on an error."""
    import asyncio

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
            return 2
        location = load_location(args.services)
        key = load_key(args.key_file)
        Path(args.journal).parent.mkdir(parents=True, exist_ok=True)
        text = Path(args.net).read_text(encoding="utf-8") if args.net.endswith(".toml") else None
        read_input = not args.no_input and sys.stdin.isatty()
        goal = options.parse_pairs(args.goal, "--goal", int) or None
        with Journal(args.journal) as journal:
            summary = asyncio.run(_execute(args, net, location=location, key=key, journal=journal, seed=args.seed,
                                           resume=args.resume, net_text=text, live=args.live, quiet=args.quiet,
                                           read_input=read_input, max_seconds=args.max_seconds, wait=args.wait,
                                           linger=True, goal=goal, degraded=args.degraded))
    except PetrobotError as exc:
        print(f"petrobot run: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("petrobot run: interrupted; resume with --resume", file=sys.stderr)
        return 130
    print(summary.format())
    print(f"journal: {args.journal}   (petrobot show {summary.run_id} --journal {args.journal})")
    logging.getLogger("petrobot").debug("run finished")
    return summary.exit_code


async def _execute(args: argparse.Namespace, net: Any, **kwargs: Any) -> Any:
    """:func:`coordinator.session.execute`, with the web console attached when ``--console`` is given."""
    from coordinator.session import execute

    if not args.console:
        return await execute(net, **kwargs)
    from coordinator.commands.console import start_console
    from coordinator.web.attach import WebAttachedConsole
    from services.textfile import write_atomically

    server = await start_console(nets=[Path(args.net)], journal=Path(args.journal), services=args.services,
                                 listen=args.console, bind_any=args.bind_any, root=Path.cwd(), key_file=args.key_file)
    address = console_address_file(Path(args.journal))
    try:
        write_atomically(address, server.url + "\n")  # a fresh file is readable by its owner only
    except OSError as exc:
        print(f"petrobot run: cannot write {address}: {exc.strerror or exc}", file=sys.stderr, flush=True)
    else:
        print(f"petrobot console: the address is also in {address} (removed when the run ends)", flush=True)
    console = WebAttachedConsole(net, server, Path(args.net), live=kwargs.get("live"), quiet=kwargs.get("quiet", False))
    console.banner = [f"web console: {server.url}"]
    kwargs["wait"] = True  # the page is an operator
    summary = None
    try:
        summary = await execute(net, console=console, **kwargs)
        return summary
    finally:
        ended = f"the run ended ({summary.end_state})" if summary is not None else "the run stopped"
        await server.close(ended)
        with contextlib.suppress(OSError):
            if address.read_text(encoding="utf-8").strip() == server.url:
                address.unlink()


def console_address_file(journal: Path) -> Path:
    """Where ``run --console`` writes the web console's address (with its token) for scripts: beside
    the journal, ``JOURNAL_STEM.console-url`` (``runs/journal.sqlite`` → ``runs/journal.console-url``)."""
    return journal.with_name(journal.stem + ".console-url")
