"""``petrobot export NET --to pnml|dot|toml [-o FILE]``: write a net in another format.

Reads any net file :func:`coordinator.netfile.load_any` reads (``.toml``, ``.pnml``, ``.xml``) and
writes canonical TOML (docs/netfile.md), PNML 2009 with petrobot tool-specific data
(:mod:`coordinator.netfile.pnml`) or a Graphviz picture (:mod:`coordinator.netfile.dot`), to stdout by default.
A net that does not load is reported as ``FILE:LINE: problem`` with exit status 2, and nothing is
written; the output file is replaced in one step (a temporary file renamed over it), so a failed
write leaves no partial file either.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from typing import Any

from services.errors import PetrobotError
from services.textfile import write_atomically

__all__ = ["EXIT_ERROR", "FORMATS", "add_parser", "run"]

#: Exit status when the net does not load or the output cannot be written.
EXIT_ERROR = 2

#: Output formats and what they are.
FORMATS = {
    "toml": "canonical petrobot TOML net file (docs/netfile.md)",
    "pnml": "PNML 2009 P/T net; the interpretation kept in <toolspecific tool=\"petrobot\">",
    "dot": "Graphviz picture (render with: dot -Tsvg FILE -o net.svg)",
}


def add_parser(subparsers: Any) -> None:
    """Register ``export`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "export",
        help="write a net as TOML, PNML or Graphviz DOT",
        description=textwrap.fill(
            "Read a net file (.toml, .pnml or .xml) and write it in another format: canonical "
            "TOML, PNML 2009 (readable by other Petri-net tools; the task interpretation travels in "
            "petrobot tool-specific elements, so TOML -> PNML -> TOML is lossless) or a Graphviz "
            "DOT picture. Writes to standard output unless -o is given. A net that does not load "
            "is reported as FILE:LINE: PROBLEM (exit status 2) and nothing is written."),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="formats:\n" + "\n".join(f"  {k:5} {v}" for k, v in FORMATS.items()),
    )
    parser.add_argument("net", metavar="NET", help="net file to read (.toml, .pnml or .xml)")
    parser.add_argument("--to", required=True, choices=sorted(FORMATS), help="output format")
    parser.add_argument("-o", "--output", metavar="FILE", default=None,
                        help="file to write (default: standard output)")
    parser.add_argument("--no-hidden", action="store_true",
                        help="dot only: leave out hidden error-recovery transitions and the places only they touch")
    parser.add_argument("--no-check", action="store_true",
                        help="skip the interpreted-net rules (exits of primitive tasks, int: events); "
                             "structural errors are still reported")


def run(args: argparse.Namespace) -> int:
    """Export a net; return 0, or 2 after printing the problem on stderr."""
    from coordinator.netfile import dump_net, load_any
    from coordinator.netfile.dot import to_dot
    from coordinator.netfile.pnml import dump_pnml

    try:
        net = load_any(args.net, interpreted=not args.no_check)
        if args.to == "toml":
            text = dump_net(net)
        elif args.to == "pnml":
            text = dump_pnml(net)
        else:
            text = to_dot(net, show_hidden=not args.no_hidden)
    except PetrobotError as exc:
        print(f"petrobot export: {exc}", file=sys.stderr)
        return EXIT_ERROR
    if args.output is None:
        sys.stdout.write(text)
        return 0
    try:
        write_atomically(args.output, text)
    except OSError as exc:
        print(f"petrobot export: cannot write {args.output}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_ERROR
    return 0
