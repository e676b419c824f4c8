"""``petrobot runs``: the runs of a journal with their outcome, duration, firings and errors."""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from coordinator.commands import options

__all__ = ["add_parser", "report", "render", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``runs`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser(
        "runs", help="list the runs of a journal: outcome, duration, firings, errors",
        description="List the runs recorded in a journal, oldest first: run id, net, start time, duration, end "
                    "state (completed, stuck, waiting_for_operator, aborted, deadline, interrupted; '-' while "
                    "unfinished), firings, primitive-action calls with their errors and failures, operator "
                    "commands (refused ones in brackets) and why the run ended, after the number of calls given "
                    "up on that ended on their node otherwise than the net assumed, if any. `petrobot show RUN` "
                    "gives one run in detail. The journal is opened read-only. Exit status 0; 1 on a missing journal; "
                    "2 on a damaged one (the damaged records are named on stderr and the rest is listed) or on one "
                    "written by a newer petrobot.")
    options.add_journal(p, default="runs/journal.sqlite", help="SQLite journal (default: %(default)s)")
    p.add_argument("--net", metavar="NAME", help="only the runs of this net")
    options.add_json(p)
    p.set_defaults(func=run)


def report(args: argparse.Namespace, damaged: list[str] | None = None) -> list[dict[str, Any]]:
    """The runs as JSON-ready dicts (raises JournalError); the damaged records skipped are added to
    ``damaged`` when given."""
    from coordinator.journal import JournalReader

    with JournalReader.open(args.journal) as journal:
        stats = journal.run_stats()
        if damaged is not None:
            damaged.extend(journal.damage_report())
    return [{
        "run": s.run.id, "net": s.run.net_name, "seed": s.run.seed, "started_wall": s.run.started_wall,
        "ended_wall": s.run.ended_wall, "duration_s": round(s.duration_s, 3), "end_state": s.run.end_state,
        "firings": s.firings, "calls": s.calls, "errors": s.errors, "failures": s.failures,
        "operator_commands": s.operator_commands, "refused": s.refused, "note": s.run.note or "",
        "resumable": s.run.resumable, "reconciled": s.reconciled, "differed": s.differed,
    } for s in stats if args.net is None or s.run.net_name == args.net]


def render(rows: list[dict[str, Any]]) -> str:
    """Readable table of :func:`report` rows."""
    if not rows:
        return "no runs"
    lines = [f"{'run':<13} {'net':<14} {'started':<19} {'time s':>8} {'end':<21} {'firings':>8} {'calls':>6} "
             f"{'err':>5} {'fail':>5} {'oper.':>7}  why"]
    for r in rows:
        started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(r["started_wall"]))
        end = r["end_state"] or ("- (resumable)" if r["resumable"] else "-")
        oper = f"{r['operator_commands']}" + (f"[{r['refused']}]" if r["refused"] else "")
        note = r["note"].split(" | ")[0]
        if r.get("differed"):
            note = f"[{r['differed']} reconciled differently] {note}"
        note = note if len(note) <= 70 else note[:67] + "..."
        lines.append(f"{r['run']:<13} {r['net'][:14]:<14} {started:<19} {r['duration_s']:>8.2f} {end:<21} "
                     f"{r['firings']:>8} {r['calls']:>6} {r['errors']:>5} {r['failures']:>5} {oper:>7}  {note}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the runs; 0, 1 on a missing journal, 2 on a damaged or newer one."""
    from coordinator.errors import JournalError

    damaged: list[str] = []
    try:
        rows = report(args, damaged)
    except JournalError as exc:
        print(f"petrobot runs: {exc}", file=sys.stderr)
        return exc.exit_status
    print(json.dumps(rows, indent=2) if args.json else render(rows))
    return options.report_damage("petrobot runs", damaged)
