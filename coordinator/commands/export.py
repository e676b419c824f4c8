"""``petrobot export NET --to pnml|dot|toml [-o FILE]``: write a net in another format;
``petrobot export RUN --to mcap [--journal FILE] [-o DIR]``: a run of the journal as a rosbag2 bag.

Reads any net file :func:`coordinator.netfile.load_any` reads (``.toml``, ``.pnml``, ``.xml``) and
writes canonical TOML (docs/netfile.md), PNML 2009 with petrobot tool-specific data
(:mod:`coordinator.netfile.pnml`) or a Graphviz picture (:mod:`coordinator.netfile.dot`), to stdout by default.
A net that does not load is reported as ``FILE:LINE: problem`` with exit status 2, and nothing is
written; the output file is replaced in one step (a temporary file renamed over it), so a failed
write leaves no partial file either. ``--to mcap`` writes run RUN of the journal as a rosbag2 MCAP
bag for the ROS tools (:mod:`coordinator.rosbag`).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from typing import Any

from coordinator.commands import options
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
    "mcap": "a RUN of the journal as a rosbag2 bag (a directory with an .mcap file) for Foxglove and ros2 bag",
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
            "is reported as FILE:LINE: PROBLEM (exit status 2) and nothing is written. With --to mcap, the "
            "argument is a RUN of the journal instead (an id, a unique prefix, or 'last'): its firings, "
            "markings, action starts and results, operator commands and reconciliations are written as a "
            "rosbag2 bag in MCAP (default -o: RUN.bag beside the journal), schemas embedded, then read back "
            "and counted; docs/ros2.md lists its topics."),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="formats:\n" + "\n".join(f"  {k:5} {v}" for k, v in FORMATS.items()),
    )
    parser.add_argument("net", metavar="NET|RUN", help="net file to read (.toml, .pnml or .xml); with --to mcap, "
                                                       "a run id, a unique prefix of one, or 'last'")
    parser.add_argument("--to", required=True, choices=sorted(FORMATS), help="output format")
    parser.add_argument("-o", "--output", metavar="FILE", default=None,
                        help="file to write (default: standard output; mcap: the bag directory RUN.bag beside "
                             "the journal)")
    parser.add_argument("--journal", metavar="FILE", default="runs/journal.sqlite",
                        help="mcap: the SQLite journal of the run (default: %(default)s)")
    parser.add_argument("--no-hidden", action="store_true",
                        help="dot only: leave out hidden error-recovery transitions and the places only they touch")
    parser.add_argument("--no-check", action="store_true",
                        help="skip the interpreted-net rules (exits of primitive tasks, int: events); "
                             "structural errors are still reported")


def _run_to_mcap(args: argparse.Namespace) -> int:
    from pathlib import Path

    from coordinator.commands.show import find_run
    from coordinator.journal import JournalReader
    from coordinator.rosbag import export_run

    try:
        with JournalReader.open(args.journal) as reader:
            run_id = find_run(reader, args.net).id
        target = Path(args.output) if args.output else Path(args.journal).parent / f"{run_id}.bag"
        written = export_run(args.journal, run_id, target)
    except PetrobotError as exc:
        print(f"petrobot export: {exc}", file=sys.stderr)
        return EXIT_ERROR
    counts = ", ".join(f"{n} {topic.rsplit('/', 1)[1]}" for topic, n in written.counts.items())
    print(f"run {run_id}: {written.mcap} ({counts}; read back with mcap-ros2-support)", file=sys.stderr)
    if written.note:
        print(f"petrobot export: {written.note}", file=sys.stderr)
    return options.report_damage("petrobot export", written.damaged)


def run(args: argparse.Namespace) -> int:
    """Export a net (or a run); return 0, or 2 after printing the problem on stderr."""
    if args.to == "mcap":
        return _run_to_mcap(args)
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
