"""The ``petrobot`` command: one subcommand per job, each in ``coordinator/commands/``."""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import select
import signal
import sys
from typing import IO, Any

__all__ = ["COMMANDS", "EXIT_READER_GONE", "build_parser", "main", "reader_gone"]

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "demo",      # the catching demo on localhost (the README's first command)
    "run",       # execute a task net on the nodes
    "console",   # the operator console in a browser: draw, follow, steer, replay
    "runs",      # the runs of a journal: outcome, duration, firings, errors
    "show",      # one run of a journal in order
    "node",      # run one node (a host's primitive-action server)
    "up",        # start every node of services.toml on this machine
    "sim",       # the simulated worlds of the testbeds
    "check",     # validate a net against services.toml
    "export",    # net to PNML, DOT or TOML
    "analyze",   # qualitative analysis (ordinary-net view)
    "example",   # generated example nets (a fleet of N robots)
    "gspn",      # quantitative analysis (GSPN view)
    "perf",      # J = 1 - R + rho C from the journal
    "learn",     # learning automata state from the journal
)

DESCRIPTION = """\
petrobot models, analyses, executes and improves robotic tasks as interpreted Petri nets
(Lima et al., "Petri Nets for Modeling and Coordination of Robotic Tasks"). Nodes host primitive
actions (services.toml says which node hosts which); the coordinator runs the net and calls them
over TCP. Run `petrobot COMMAND --help` for each command. A command whose output goes to a reader
that stops early (`petrobot analyze --json NET | head`) ends quietly with exit status 141, as a
filter ended by SIGPIPE does."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="petrobot", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--log-level", default="WARNING",
                        choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="logging level (default: WARNING)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        qualified = f"coordinator.commands.{name}"
        try:
            module = importlib.import_module(qualified)
        except ModuleNotFoundError as exc:
            if exc.name != qualified:  # a missing dependency inside the command is a real error
                raise
            continue  # this checkout has no such command module
        module.add_parser(sub)
        chosen = sub.choices.get(name)
        if chosen is not None and chosen.get_default("func") is None:
            chosen.set_defaults(func=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``petrobot`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=getattr(args, "log_level", "WARNING"),
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()
    except BrokenPipeError:
        if not reader_gone(sys.stdout):
            raise  # a broken pipe elsewhere (a socket, a child's stdin) is a failure to show
        return _quiet_exit()
    return code


#: Exit code when the reader of stdout went away, as a shell reports a command SIGPIPE ended.
EXIT_READER_GONE = 128 + signal.SIGPIPE


def reader_gone(stream: IO[Any]) -> bool:
    """Whether ``stream`` (a file object) is the write end of a pipe or socket whose reader has
    closed its end: polled for writing, it reports an error or a hang-up. False for a terminal, a
    file, or a stream without a file descriptor or already closed."""
    try:
        poller = select.poll()
        poller.register(stream.fileno(), select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (OSError, ValueError):  # no descriptor (io.UnsupportedOperation), or closed
        return False


def _quiet_exit() -> int:
    """The reader of stdout closed its end (``petrobot analyze --json | head``): stop quietly, as
    a Unix filter does, with no traceback. Python ignores SIGPIPE, so a write raised
    ``BrokenPipeError`` instead; stdout is pointed at ``/dev/null`` so that the interpreter's own
    flush at exit does not raise again. Returns :data:`EXIT_READER_GONE` (141)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return EXIT_READER_GONE


if __name__ == "__main__":
    sys.exit(main())
