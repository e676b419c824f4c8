"""The ``petrobot`` command: one subcommand per job, each in ``coordinator/commands/``."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

__all__ = ["COMMANDS", "build_parser", "main"]

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
over TCP. Run `petrobot COMMAND --help` for each command."""


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
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
