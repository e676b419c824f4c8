"""``petrobot perf``: R, C, ρ and J per primitive action, primitive task and task (paper section 3)."""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
from pathlib import Path
from typing import Any

from coordinator.errors import JournalError
from services.errors import PetrobotError
from coordinator.netfile import load_any
from coordinator.performance import (
    COST_MEASURES,
    ActionRecord,
    action_performance,
    gspn_task_performance,
    task_performance,
    usage_frequencies,
)

__all__ = ["add_parser", "parse_pairs", "read_records", "run"]


def read_records(path: str | Path) -> list[ActionRecord]:
    """Read every row of the journal's ``action_result`` table (read-only).

    Raises:
        JournalError: if the file is missing or has no usable ``action_result`` table.
    """
    if not Path(path).is_file():
        raise JournalError(f"journal {path} does not exist")
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            rows = con.execute(
                "SELECT task, action, status, outcome, cost, wall_s, cpu_s FROM action_result").fetchall()
        finally:
            con.close()
    except sqlite3.Error as exc:
        raise JournalError(f"journal {path}: {exc}") from exc
    return [ActionRecord(task=r[0], action=r[1], status=r[2], outcome=r[3], cost=r[4], wall_s=r[5], cpu_s=r[6])
            for r in rows]


def parse_pairs(items: list[str] | None, what: str, cast: type = float) -> dict[str, Any]:
    """Parse ``NAME=VALUE`` arguments into a dict.

    Raises:
        PetrobotError: on an item without ``=`` or a bad value.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = cast(value)
        except ValueError:
            raise PetrobotError(f"bad {what} {item!r}: expected NAME=VALUE") from None
    return out


def add_parser(subparsers: Any) -> None:
    """Register ``perf`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "perf",
        help="J = 1 - R + rho*C per primitive action, primitive task and task",
        description=(
            "Compute the performance function of section 3 of the paper, J = 1 - R + rho*C. Per primitive "
            "action: R = relative frequency of 'success' in the journal (failure and error fail the "
            "specifications), C = mean measured cost (or the a-priori cost of the net file), rho = 1/max C "
            "over the actions of the primitive task. Per primitive task: the values of its best action "
            "(least J, where the learning automaton converges) and of the mix of actions actually used. "
            "Per task: through the GSPN view, R = probability of ending in a goal marking, C = mean time "
            "to absorption (s), rho = 1/C_max with every primitive task at its slowest action. Exit status "
            "0 on success, 1 on an unreadable net or journal, 2 if the analysis fails."),
    )
    parser.add_argument("net", metavar="NET", help="task net file (.toml, .pnml or .xml)")
    parser.add_argument("--journal", metavar="FILE", required=True,
                        help="SQLite journal of real runs (table action_result)")
    parser.add_argument("--cost", choices=COST_MEASURES, default="wall",
                        help="cost measure C of an action: wall (actual time, s), cpu (CPU time, s), cost "
                             "(the cost the action reports) or apriori (the net file); default wall")
    parser.add_argument("--ext-rate", action="append", metavar="TOPIC=RATE",
                        help="rate (1/s) of an external event ext:TOPIC in the GSPN view; repeat as needed")
    parser.add_argument("--goal", action="append", metavar="PLACE=N",
                        help="a goal marking holds at least N tokens in PLACE (repeatable); default: a dead "
                             "marking with no token in a place fed only by error exits")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g}"


def report(args: argparse.Namespace) -> dict[str, Any]:
    """Compute the ``perf`` report as a JSON-ready dict (raises PetrobotError subclasses)."""
    net = load_any(args.net, interpreted=False)
    records = read_records(args.journal)
    per_action = action_performance(net, records, measure=args.cost)
    usage = usage_frequencies(records)
    tasks: dict[str, Any] = {}
    for name, acts in per_action.items():
        best = task_performance(acts)
        entry: dict[str, Any] = {"best": _row(best)}
        mix = usage.get(name)
        if mix:
            entry["used_mix"] = _row(task_performance(acts, probabilities=mix)) | {"probabilities": mix}
        tasks[name] = entry
    task, details = gspn_task_performance(net, records, ext_rates=parse_pairs(args.ext_rate, "--ext-rate"),
                                          goal=parse_pairs(args.goal, "--goal", int) or None)
    return {
        "net": net.name, "cost_measure": args.cost, "results": len(records),
        "actions": {t: {a: _row(p) for a, p in acts.items()} for t, acts in per_action.items()},
        "primitive_tasks": tasks,
        "task": _row(task) | {k: v for k, v in details.items()},
    }


def _row(obj: Any) -> dict[str, Any]:
    return {k: getattr(obj, k) for k in obj.__slots__} if hasattr(obj, "__slots__") else dict(obj.__dict__)


def render(rep: dict[str, Any]) -> str:
    """Return the readable text of a :func:`report` dict."""
    lines = [f"net {rep['net']!r}: {rep['results']} journal results, cost measure {rep['cost_measure']}", "",
             f"{'primitive action':32} {'runs':>5} {'R':>7} {'C':>9} {'rho':>8} {'J':>7}  source"]
    for task, acts in rep["actions"].items():
        for a, p in acts.items():
            lines.append(f"{task + '.' + a:32} {p['runs']:5d} {_fmt(p['reliability']):>7} {_fmt(p['cost']):>9} "
                         f"{_fmt(p['rho']):>8} {_fmt(p['j']):>7}  {p['source']}")
    lines += ["", f"{'primitive task':20} {'R':>7} {'C':>9} {'J':>7}  basis"]
    for task, entry in rep["primitive_tasks"].items():
        for key in ("best", "used_mix"):
            if key in entry:
                p = entry[key]
                lines.append(f"{task:20} {_fmt(p['reliability']):>7} {_fmt(p['cost']):>9} {_fmt(p['j']):>7}  "
                             f"{p['basis'] if key == 'best' else 'mix of actions used in the journal'}")
    t = rep["task"]
    lines += ["", (f"task {rep['net']!r} (GSPN view): R = {_fmt(t['reliability'])} (probability of a goal "
                   f"marking), C = {_fmt(t['cost'])} s (mean time to absorption), rho = {_fmt(t['rho'])} 1/s, "
                   f"J = {_fmt(t['j'])}")]
    for w in t.get("warnings", []):
        lines.append(f"  warning: {w}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the report; 0 on success, 1 on an unreadable net or journal, 2 if the analysis fails."""
    from coordinator.errors import AnalysisError, JournalError, NetError

    try:
        rep = report(args)
    except (NetError, JournalError) as exc:
        print(f"petrobot perf: {exc}", file=sys.stderr)
        return 1
    except (AnalysisError, PetrobotError) as exc:
        print(f"petrobot perf: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(rep, indent=2) if args.json else render(rep))
    return 0
