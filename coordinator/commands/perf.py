"""``petrobot perf``: R, C, ρ and J per primitive action, primitive task and task (paper section 3)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from coordinator.commands import options
from coordinator.commands.options import parse_pairs
from coordinator.performance import COST_MEASURES
from services.errors import PetrobotError

__all__ = ["add_parser", "render", "report", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``perf`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "perf",
        help="J = 1 - R + rho*C per primitive action, primitive task and task",
        description=(
            "Compute the performance function of section 3 of the paper, J = 1 - R + rho*C (eq. 1): between "
            "0 and 2, lower is better. Per primitive action: R = relative frequency of 'success' in the "
            "journal (failure and error fail the specifications); C and rho as the learning automata take "
            "them (petrobot learn shows the same numbers): C = the net file's a-priori costs when every action "
            "of the task has one, else the mean over the results of the cost each action reported, or its "
            "wall time on the node (s) when it reported none; rho = the task's declared rho, else 1/max C over "
            "its actions, and for a task of one action 1/its deadline_s (the share of its time budget it used; "
            "0 without a deadline). Per primitive task: the values of its best action (least J, where the "
            "learning automaton converges) and of the mix of actions actually used. Per task: through the GSPN "
            "view, R = probability of ending in a goal marking, C = mean time to absorption (s), rho = 1/C_max "
            "with every primitive task at its slowest action. Exit status 0 on success, 2 on an unreadable net "
            "or journal, 1 if the analysis fails."),
    )
    parser.add_argument("net", metavar="NET", help="task net file (.toml, .pnml or .xml)")
    options.add_journal(parser, required=True, help="SQLite journal of real runs (read only)")
    options.add_run(parser)
    parser.add_argument("--cost", choices=COST_MEASURES, default="learner",
                        help="cost measure C of an action: learner (as the learning automata take it, see above; "
                             "the default), wall (actual time, s), cpu (CPU time, s), cost (the cost the action "
                             "reports) or apriori (the net file)")
    options.add_ext_rate(parser, help="rate (1/s) of an external event ext:TOPIC in the GSPN view; repeat as "
                                      "needed")
    parser.add_argument("--goal", action="append", metavar="PLACE=N",
                        help="a goal marking holds at least N tokens in PLACE (repeatable); default: a dead "
                             "marking with no token in a place fed only by error exits")
    options.add_json(parser)


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g}"


def report(args: argparse.Namespace, damaged: list[str] | None = None) -> dict[str, Any]:
    """Compute the ``perf`` report as a JSON-ready dict (raises PetrobotError subclasses); the
    journal's damaged records, left out, are added to ``damaged`` when given."""
    from coordinator.analysis.gspn_performance import gspn_task_performance
    from coordinator.journal import read_results
    from coordinator.netfile import load_any
    from coordinator.performance import (
        action_performance,
        task_performance,
        usage_frequencies,
    )

    net = load_any(args.net, interpreted=False)
    records = read_results(args.journal, args.run, damaged)  # an outcome the operator forced measures nothing
    every = read_results(args.journal, args.run, forced=True)
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
        "net": net.name, "run": args.run, "cost_measure": args.cost, "results": len(records),
        "forced_left_out": len(every) - len(records),
        "actions": {t: {a: _row(p) for a, p in acts.items()} for t, acts in per_action.items()},
        "primitive_tasks": tasks,
        "task": _row(task) | {k: v for k, v in details.items()},
    }


def _row(obj: Any) -> dict[str, Any]:
    return {k: getattr(obj, k) for k in obj.__slots__} if hasattr(obj, "__slots__") else dict(obj.__dict__)


def render(rep: dict[str, Any]) -> str:
    """Return the readable text of a :func:`report` dict."""
    scope = f"run {rep['run']}" if rep.get("run") else "journal"
    measure = {"learner": "as the learners take it: a-priori costs if the net gives every action one, else "
                          "each result's reported cost or its wall time on the node (s)",
               "wall": "wall time on the node (s)", "cpu": "CPU time on the node (s)",
               "cost": "the cost each action reported", "apriori": "the net file's a-priori costs"}
    lines = [f"net {rep['net']!r}: {rep['results']} {scope} results",
             "J = 1 - R + rho*C (paper eq. 1), from 0 to 2: LOWER IS BETTER. R: share of results that met the "
             "specifications (success);",
             f"C: cost, {measure.get(rep['cost_measure'], rep['cost_measure'])}; rho: the task's declared rho, "
             "else 1/max C over its actions (one action: 1/its deadline_s)", "",
             f"{'primitive action':32} {'runs':>5} {'R':>7} {'C':>9} {'rho':>8} {'J':>7}  source (R/C)"]
    if rep.get("forced_left_out"):
        n = rep["forced_left_out"]
        lines.insert(1, f"{n} outcome{'' if n == 1 else 's'} forced by the operator (drills) left out: "
                        "they measure nothing")
    for task, acts in rep["actions"].items():
        for a, p in acts.items():
            lines.append(f"{task + '.' + a:32} {p['runs']:5d} {_fmt(p['reliability']):>7} {_fmt(p['cost']):>9} "
                         f"{_fmt(p['rho']):>8} {_fmt(p['j']):>7}  {p['source']}")
    lines += ["", f"{'primitive task':20} {'R':>7} {'C':>9} {'J':>7}  basis (least J: where the learner converges)"]
    for task, entry in rep["primitive_tasks"].items():
        for key in ("best", "used_mix"):
            if key in entry:
                p = entry[key]
                lines.append(f"{task:20} {_fmt(p['reliability']):>7} {_fmt(p['cost']):>9} {_fmt(p['j']):>7}  "
                             f"{p['basis'] if key == 'best' else 'mix of actions used in the journal'}")
    t = rep["task"]
    lines += ["", (f"task {rep['net']!r} (GSPN view): R = {_fmt(t['reliability'])} (probability of a goal "
                   f"marking), C = {_fmt(t['cost'])} s (mean time to absorption), rho = {_fmt(t['rho'])} 1/s, "
                   f"J = {_fmt(t['j'])} (lower is better)")]
    for w in t.get("warnings", []):
        lines.append(f"  warning: {w}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the report; 0 on success, 2 on an unreadable net or journal, 1 if the analysis fails."""
    from coordinator.errors import AnalysisError, JournalError, NetError

    damaged: list[str] = []
    try:
        rep = report(args, damaged)
    except (NetError, JournalError) as exc:
        print(f"petrobot perf: {exc}", file=sys.stderr)
        return 2
    except (AnalysisError, PetrobotError) as exc:
        print(f"petrobot perf: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(rep, indent=2) if args.json else render(rep))
    return options.report_damage("petrobot perf", damaged)
