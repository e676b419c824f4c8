"""``petrobot check NET [--services FILE]``: validate a net file, and its placement on nodes.

Checks the net file (syntax, structure, the interpreted-net rules of paper section 2) and, against
the location file ``services.toml`` (section 5), that every primitive action of every primitive task
is placed on a node and every ``ext:`` event has a publishing node. Prints ``OK`` and a one-line
summary, or every problem as ``file:line: problem`` and exits with status 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coordinator.commands.options import DEFAULT_SERVICES

if TYPE_CHECKING:
    from coordinator.net import PetriNet
    from coordinator.netfile import SourceMap

__all__ = ["add_parser", "run", "summary"]

def add_parser(subparsers: Any) -> None:
    """Register ``check`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "check",
        help="validate a net file and its placement in services.toml",
        description=(
            "Validate a net file (.toml, .pnml or .xml): syntax, structure (arcs join a place and a "
            "transition, known ids, integer weights >= 1), the interpreted-net rules (every "
            "primitive-task place has a normal and an error exit, well-formed int:/ext: events), and, "
            "against the location file, that every primitive action is placed on a node and every "
            "external event has a publisher. Prints OK with a summary, or each problem as "
            "FILE:LINE: PROBLEM and exits with status 1."),
    )
    parser.add_argument("net", metavar="NET", help="net file to check (.toml, .pnml or .xml)")
    parser.add_argument("--services", metavar="FILE", default=None,
                        help=f"location file to check placement against (default: ./{DEFAULT_SERVICES} "
                             "if it exists; placement is not checked without one)")


def summary(net: PetriNet) -> str:
    """One line describing a net: places, transitions, arcs, tasks, actions, tokens."""
    actions = sum(len(t.actions) for t in net.tasks.values())
    return (f"net {net.name!r}: {len(net.places)} places, {len(net.transitions)} transitions, "
            f"{len(net.arcs)} arcs, {len(net.tasks)} primitive tasks ({actions} actions), "
            f"{net.initial_marking.total} initial tokens")


def run(args: argparse.Namespace) -> int:
    """Check a net; return 0 when it is valid, 1 after printing its problems."""
    from coordinator.errors import NetError
    from coordinator.netfile import SourceMap, check_net, lint_net, load_any
    from services.errors import LocationError
    from services.location import load_location

    path = str(args.net)
    smap: SourceMap | None = None
    problems: list[str] = []
    net: PetriNet | None = None
    try:
        if Path(path).suffix.lower() == ".toml":
            text = Path(path).read_text(encoding="utf-8")
            smap = SourceMap.scan(text)
            net, errors = lint_net(text, path)
            problems += [str(e) for e in errors]
        else:
            net = load_any(path)
    except OSError as exc:
        problems.append(f"{path}: cannot read net file: {exc.strerror or exc}")
    except NetError as exc:
        problems.append(str(exc))

    services = args.services
    if services is None and Path(DEFAULT_SERVICES).exists():
        services = DEFAULT_SERVICES
    placed = ""
    if net is not None and services is not None:
        try:
            location = load_location(services)
        except LocationError as exc:
            problems.append(str(exc))
        else:
            for element, problem in check_net(net, location):
                line = smap.of_id(element) if smap is not None else None
                problems.append(f"{path}:{line}: {problem}" if line else f"{path}: {problem}")
            placed = f"; placement checked against {services}"
    elif net is not None:
        placed = "; placement not checked (no services.toml)"

    if problems:
        for problem in problems:
            print(problem)
        print(f"{len(problems)} problem{'s' if len(problems) != 1 else ''} in {path}", file=sys.stderr)
        return 1
    assert net is not None
    print(f"OK {path}: {summary(net)}{placed}")
    return 0
