"""``petrobot check [NET] [--services FILE] [--services-only]``: validate a net file and the location file.

Checks the net file (syntax, limits, structure, the interpreted-net rules of paper section 2) and the
location file ``services.toml`` (section 5): its own consistency, that every action's ``impl``
imports and names a primitive action, every driver's ``impl`` a driver, every host resolves
(:mod:`services.location_check`), and that every primitive action of every primitive task of the net
is placed on a node and every ``ext:`` event has a publishing node. Prints ``OK`` and a one-line
summary, or every problem as ``FILE:LINE: problem`` and exits with status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coordinator.commands.options import DEFAULT_SERVICES

if TYPE_CHECKING:
    from coordinator.net import PetriNet
    from services.location import Location

__all__ = ["EXIT_PROBLEMS", "add_parser", "run"]

#: Exit status when a problem is found (usage errors exit 2 too, as with argparse).
EXIT_PROBLEMS = 2


def add_parser(subparsers: Any) -> None:
    """Register ``check`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "check",
        help="validate a net file and services.toml (imports the action modules)",
        description=(
            "Validate a net file (.toml, .pnml or .xml): syntax, limits (docs/netfile.md), structure "
            "(arcs join a place and a transition, known ids, integer weights >= 1), the interpreted-net "
            "rules (every primitive-task place has a normal and an error exit, well-formed int:/ext: "
            "events); and the location file: its keys, names and addresses, that every host resolves, "
            "that the impl of every action the net uses (every action with --services-only) imports "
            "and names a PrimitiveAction or an async function and the drivers of their nodes a Driver "
            "subclass, and that every primitive action of the net is "
            "placed on a node and every external event has a publisher. The impl modules are imported "
            "into this process (as a node would import them): check only location files you trust. "
            "Prints OK with a summary, or each problem as FILE:LINE: PROBLEM and exits with status 2."),
    )
    parser.add_argument("net", metavar="NET", nargs="?", default=None,
                        help="net file to check (.toml, .pnml or .xml); not with --services-only")
    parser.add_argument("--services", metavar="FILE", default=None,
                        help=f"location file to check, and to check placement against (default: "
                             f"./{DEFAULT_SERVICES} if it exists; not checked without one)")
    parser.add_argument("--services-only", action="store_true",
                        help=f"check the location file alone (--services, default ./{DEFAULT_SERVICES})")


def _location_summary(location: Location) -> str:
    return (f"{len(location.nodes)} nodes, {len(location.actions)} actions, {len(location.drivers)} "
            f"drivers, {len(location.events)} event topics")


def _finish(problems: list[str], subject: str, ok: str) -> int:
    if problems:
        for problem in problems:
            print(problem)
        print(f"{len(problems)} problem{'s' if len(problems) != 1 else ''} in {subject}", file=sys.stderr)
        return EXIT_PROBLEMS
    print(ok)
    return 0


def run(args: argparse.Namespace) -> int:
    """Check a net and/or the location file; return 0 when valid, 2 after printing the problems."""
    from services.location_check import check_location_file

    services: str | None = args.services
    if args.services_only:
        if args.net is not None:
            print("petrobot check: give NET or --services-only, not both", file=sys.stderr)
            return EXIT_PROBLEMS
        services = services or DEFAULT_SERVICES
        location, errors = check_location_file(services)
        ok = f"OK {services}: {_location_summary(location)}" if location is not None else ""
        return _finish([str(e) for e in errors], services, ok)
    if args.net is None:
        print("petrobot check: NET is required (or --services-only)", file=sys.stderr)
        return EXIT_PROBLEMS

    path = str(args.net)
    net, problems, line_of = _check_net(path)
    if services is None and Path(DEFAULT_SERVICES).exists():
        services = DEFAULT_SERVICES
    placed = "; placement not checked (no services.toml)"
    if services is not None:
        needed = None if net is None else {a.name for task in net.tasks.values() for a in task.actions}
        location, errors = check_location_file(services, needed)
        problems += [str(e) for e in errors]
        placed = ""
        if location is not None and net is not None:
            from coordinator.netfile import check_net

            for element, problem in check_net(net, location):
                line = line_of(element)
                problems.append(f"{path}:{line}: {problem}" if line else f"{path}: {problem}")
            if any(location.actions[a].ros2 is not None for a in needed or () if a in location.actions):
                from services.ros2.preflight import params_problem

                for task in net.tasks.values():
                    for action in task.actions:
                        problem = params_problem(location, action.name, action.params)
                        if problem is not None:
                            line = line_of(task.name)
                            problems.append(f"{path}:{line}: task {task.name!r}: {problem}" if line
                                            else f"{path}: task {task.name!r}: {problem}")
            placed = f"; placement checked against {services}"
    ok = f"OK {path}: {net.summary()}{placed}" if net is not None else ""
    return _finish(problems, path if services is None else f"{path} and {services}", ok)


def _check_net(path: str) -> tuple[PetriNet | None, list[str], Any]:
    """Load a net file: ``(net or None, problems, line_of(element id) -> line or None)``."""
    from coordinator.errors import NetError
    from coordinator.netfile import SourceMap, lint_net, load_any
    from coordinator.netfile.loader import read_text

    if Path(path).suffix.lower() != ".toml":
        try:
            return load_any(path), [], lambda _: None
        except NetError as exc:
            return None, [str(exc)], lambda _: None
    try:
        text = read_text(path)
    except NetError as exc:
        return None, [str(exc)], lambda _: None
    net, errors = lint_net(text, path)
    return net, [str(e) for e in errors], SourceMap.scan(text).of_id
