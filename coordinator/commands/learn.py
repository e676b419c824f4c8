"""``petrobot learn NET --journal FILE``: what the learning automata have learned (paper section 4).

Reads the journal read-only (:class:`coordinator.journal.JournalReader`): the saved learner state
of each primitive task (:meth:`coordinator.learning.LearningAutomaton.state_dict`) and every
primitive action's result, in journal order.

The net file gives the primitive tasks and their configured learners, so tasks that have not run
yet are listed too (uniform probabilities, no trials). For each primitive task it reports the
probability of each primitive action, R̂, C and Ĵ (eq. 1), and whether one action has reached the
convergence threshold. ``--plot [FILE.png]`` draws the probability of each action over the trials
(without a file name: beside the journal, ``JOURNAL_STEM.learning.png``, and says where). The
history is not stored: it is rebuilt by replaying the task's results, in journal order, through a
fresh automaton of the saved configuration and seed; the cost of a result is its ``cost``, or
``wall_s`` when the action reported none, as the runtime feeds the learner. The learning updates
are deterministic in (action, status, cost), so the replay ends on the saved probabilities exactly
when the journal holds every result the learner saw; the report says whether it does.

``--run RUN_ID`` takes the results of that run only. The journal saves one learner state per
primitive task across runs, not per run, so each task is then reported as a fresh automaton of its
saved configuration that has seen that run's results (no comparison with the saved state).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coordinator.commands import options
from services.errors import PetrobotError
from services.results import Status

if TYPE_CHECKING:
    from coordinator.learning import Learner, LearningAutomaton

__all__ = ["TaskReport", "add_parser", "build_reports", "default_plot_path", "learned_so_far", "plot", "print_learned",
           "read_journal", "report_json", "report_text", "run"]

_EPS = 1e-12

Trial = tuple[str, Status, float | None]
"""One result as the learner took it in: (action, status, cost)."""


@dataclass
class TaskReport:
    """What is known about one primitive task's learning.

    Attributes:
        task: primitive task name.
        automaton: the saved automaton, or one rebuilt from the results (``saved`` False).
        saved: whether ``learner_state`` holds a state for the task.
        results: (action, status, cost) of the task's results in journal order.
        history: probability vectors after each replayed result, shape (len(results) + 1, r);
            empty when there is no saved state to replay.
        replay_matches: replayed probabilities equal the saved ones (``None`` without a state).
        note: a remark for the reader (e.g. the saved learner no longer matches the net).
    """

    task: str
    automaton: LearningAutomaton
    saved: bool
    results: list[Trial] = field(default_factory=list)
    history: list[list[float]] = field(default_factory=list)
    replay_matches: bool | None = None
    note: str | None = None


def add_parser(subparsers: Any) -> None:
    """Register ``learn`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "learn",
        help="report what the learning automata learned (probabilities, R, C, J per action)",
        description=(
            "For every primitive task with a learner, report the probability of choosing each "
            "primitive action, its estimated reliability R, cost C and J = 1 - R + rho*C "
            "(paper eq. 1), and whether one action reached the convergence threshold. Reads the "
            "journal's saved learner states and results; never writes to the journal."),
    )
    parser.add_argument("net", metavar="NET", help="the task net file the journal was recorded with")
    options.add_journal(parser, required=True, help="SQLite journal of the runs (read only)")
    options.add_run(parser)
    options.add_json(parser, help="print a JSON document instead of text")
    parser.add_argument("--plot", metavar="FILE.png", nargs="?", const="",
                        help="draw the probability of each action over the trials, one panel per task "
                             "(rebuilt by replaying the journal's results; PNG written with matplotlib); without "
                             "FILE.png, beside the journal: JOURNAL_STEM.learning.png (runs/catching.learning.png)")
    parser.add_argument("--threshold", type=float, default=0.95,
                        help="probability at which a task counts as converged (default 0.95)")
    parser.add_argument("--task", action="append", metavar="NAME",
                        help="report only this primitive task (repeatable)")


def default_plot_path(journal: str | Path) -> Path:
    """Where ``--plot`` without a file name writes: beside the journal, ``JOURNAL_STEM.learning.png``."""
    path = Path(journal)
    return path.with_name(path.stem + ".learning.png")


def learned_so_far(journal: str | Path, net: str | Path) -> list[str]:
    """What the learners of ``net`` have learned in ``journal``, one line per primitive task that
    chooses among alternatives (section 4): its probabilities, most likely first, its results, the
    action of least Ĵ so far and whether it converged or still warms up. For a demo's report.

    Raises:
        JournalError, NetError: an unreadable journal or net.
    """
    from coordinator.learning import Learner
    from coordinator.netfile import load_any

    states, results = read_journal(journal)
    lines = []
    for rep in build_reports(states, results, None, Learner.from_net(load_any(net))):
        auto = rep.automaton
        if len(auto.actions) < 2 or not rep.saved:
            continue
        probs = sorted(auto.probabilities.items(), key=lambda kv: -kv[1])
        js = {a: e.j for a, e in auto.estimates.items() if e.j is not None}
        best = min(js, key=lambda a: js[a]) if js else None
        warmup = getattr(auto, "warmup", 0) or 0
        done = auto.converged()
        state = (f"converged to {done}" if done else
                 f"warming up (each action is tried {warmup} time{'s' * (warmup != 1)} first)"
                 if any(e.trials < warmup for e in auto.estimates.values()) else "learning")
        lines.append(f"learner {rep.task} ({auto.scheme}, {auto.steps} result{'s' * (auto.steps != 1)}, {state}): "
                     f"p = {', '.join(f'{a} {p:.2f}' for a, p in probs)}"
                     + (f"; least J so far: {best} (J = {js[best]:.3f}, lower is better)" if best else ""))
    return lines


def print_learned(journal: Path, net: Path, demo: str = "") -> None:
    """Print what a demo's learners have learned so far (:func:`learned_so_far`) and how to go on
    learning (``petrobot demo DEMO --journal JOURNAL``; ``demo`` empty for the default, catching); a
    journal or net that cannot be read gets one line saying so (the demo's exit code stays its
    run's)."""
    try:
        lines = learned_so_far(journal, net)
    except PetrobotError as exc:
        lines = [f"learner: not read ({exc})"]
    for line in lines:
        print(line)
    shown = net.relative_to(Path.cwd()) if net.is_absolute() and net.is_relative_to(Path.cwd()) else net
    print(f"learning: petrobot learn {shown} --journal {journal} --plot; go on learning from here: "
          f"petrobot demo {demo + ' ' if demo else ''}--journal {journal}")


def read_journal(path: str | Path, run: str | None = None, damaged: list[str] | None = None
                 ) -> tuple[dict[str, dict[str, Any]], dict[str, list[Trial]]]:
    """Read saved learner states and learning results from a journal, read-only.

    Args:
        path: the journal file.
        run: take the results of this run only (``None``: every run).
        damaged: the damaged records left out are added here when given
            (:meth:`coordinator.journal.JournalReader.damage_report`).

    Returns:
        ({task: state dict}, {task: [(action, status, cost), ...] in journal order}), where cost is
        the result's ``cost`` or, when the action reported none, its ``wall_s`` (as the runtime
        feeds the learner); a cost that is not finite and ≥ 0 is ``None``.

    Raises:
        JournalError: if the file is missing or not a journal, has no run ``run``, or a saved
            state is not a JSON object of its scheme.
    """
    from coordinator.journal import JournalReader
    from coordinator.performance import result_cost

    with JournalReader.open(path) as journal:
        if run is not None:
            journal.run(run)
        states = {task: dict(saved.state) for task, saved in journal.learner_states().items()}
        results: dict[str, list[Trial]] = {}
        for row in journal.results(run, forced=False):  # the operator's forced outcomes taught nothing
            cost = result_cost(row.cost, row.wall_s)  # what the runtime feeds the learner
            value = None if cost is None else float(cost)
            if value is not None and (not math.isfinite(value) or value < 0.0):
                value = None
            results.setdefault(row.task, []).append((row.action, row.status, value))
        if damaged is not None:
            damaged.extend(journal.damage_report())
    return states, results


def _replay(state: Mapping[str, Any], results: list[Trial]) -> tuple[list[list[float]], LearningAutomaton]:
    """Probability vectors of a fresh automaton of ``state``'s configuration over ``results``."""
    from coordinator.learning import make_learner

    config = dict(state["config"])
    config["scheme"] = state["scheme"]
    fresh = make_learner(config, list(state["actions"]), state["costs"], int(state["seed"]), state.get("cost_budget"))
    history = [list(fresh.probabilities.values())]
    for action, status, cost in results:
        if action in fresh.actions:
            fresh.update(action, status, cost)
            history.append(list(fresh.probabilities.values()))
    return history, fresh


def build_reports(states: dict[str, dict[str, Any]],
                  results: dict[str, list[Trial]],
                  tasks: Sequence[str] | None = None,
                  configured: Learner | None = None,
                  *,
                  fresh_from: str | None = None) -> list[TaskReport]:
    """Combine saved states and results into one :class:`TaskReport` per primitive task.

    Args:
        states: {task: saved state dict}.
        results: {task: [(action, status, cost), ...]} in journal order.
        tasks: report only these tasks (all when ``None`` or empty).
        configured: the learners the net configures (:meth:`Learner.from_net`), or ``None``.
        fresh_from: the run ``results`` come from, when they are one run's only: each saved
            task is then reported as a fresh automaton of its saved configuration that took in
            ``results`` (the saved state is the journal's latest, not that run's).

    Tasks configured but neither saved nor run are reported fresh. Tasks with results but no saved
    state get estimates rebuilt from their results (measured costs; no probabilities learned).
    Pure: no I/O.

    Raises:
        JournalError: if a saved state is malformed.
    """
    from coordinator.learning import automaton_from_state, make_learner

    known = configured.tasks if configured is not None else ()
    names = sorted(set(states) | set(results) | set(known))
    if tasks:
        names = [t for t in names if t in set(tasks)]
    reports: list[TaskReport] = []
    for task in names:
        rows = results.get(task, [])
        if task in states:
            auto = automaton_from_state(states[task])
            rows = [r for r in rows if r[0] in auto.actions]
            history, replayed = _replay(states[task], rows)
            if fresh_from is not None:
                reports.append(TaskReport(task, replayed, True, rows, history, None,
                                          f"a fresh learner over the {len(rows)} results of run {fresh_from}"))
                continue
            final = replayed.probabilities.values()
            matches = all(abs(a - b) <= _EPS for a, b in zip(final, auto.probabilities.values()))
            note = None
            if configured is not None and task in known:
                now = configured.automaton(task)
                if (now.scheme, now.actions) != (auto.scheme, auto.actions):
                    note = (f"the net now configures {now.scheme} over {', '.join(now.actions)}: "
                            "the saved learner will not be restored")
            elif configured is not None:
                note = "this primitive task is not in the net"
            reports.append(TaskReport(task, auto, True, rows, history, matches, note))
        elif not rows and configured is not None:
            fresh = configured.automaton(task)
            reports.append(TaskReport(task, fresh, True, [], [list(fresh.probabilities.values())],
                                      None, "no result yet"))
        else:
            actions = list(dict.fromkeys(a for a, _, _ in rows))
            auto = make_learner({"scheme": "fixed", "cost_source": "measured"}, actions)
            for action, status, cost in rows:
                auto.update(action, status, cost)
            reports.append(TaskReport(task, auto, False, rows))
    return reports


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def report_json(reports: list[TaskReport], threshold: float) -> dict[str, Any]:
    """The ``--json`` document: {"tasks": {task: {...}}}."""
    out: dict[str, Any] = {}
    for rep in reports:
        auto = rep.automaton
        est = auto.estimates
        probs = auto.probabilities
        js = {a: e.j for a, e in est.items() if e.j is not None}
        out[rep.task] = {
            "scheme": auto.scheme if rep.saved else None,
            "config": auto.state_dict()["config"] if rep.saved else None,
            "steps": auto.steps,
            "rho": auto.rho,
            "converged": auto.converged(threshold) if rep.saved else None,
            "best_estimated": min(js, key=lambda a: js[a]) if js else None,
            "actions": {
                a: {"probability": probs[a] if rep.saved else None, "trials": e.trials,
                    "successes": e.successes, "reliability": e.reliability, "cost": e.cost,
                    "measured_cost": e.measured_cost, "j": e.j}
                for a, e in est.items()
            },
            "journal_results": len(rep.results),
            "replay_matches_state": rep.replay_matches,
            "note": rep.note,
        }
    return {"threshold": threshold, "tasks": out}


def _rho_source(auto: LearningAutomaton) -> str:
    """Where an automaton's ρ comes from (:func:`coordinator.performance.task_rho`), in words."""
    if "rho" in auto.state_dict()["config"]:
        return "declared"
    if len(auto.actions) > 1:
        return "1/max C"
    if auto.cost_source == "measured" and auto.cost_budget is not None:
        return f"one action: 1/its deadline {auto.cost_budget:g} s"
    return "one action without a deadline: cost not weighed"


def _cost_source(auto: LearningAutomaton) -> str:
    """Where an automaton's C comes from, in words."""
    if auto.cost_source == "apriori":
        return "the net file's a-priori costs"
    return "the mean of the cost each result reported, else of its wall time on the node (s)"


def report_text(reports: list[TaskReport], threshold: float) -> str:
    """Human-readable report, one block per primitive task."""
    if not reports:
        return "no primitive task has a learner state or a result in this journal\n"
    lines: list[str] = ["J = 1 - R + rho*C (paper eq. 1), lower is better; p: the probability of choosing the action "
                        "next (section 4)", ""]
    for rep in reports:
        auto = rep.automaton
        if rep.saved:
            cfg = auto.state_dict()["config"]
            extra = ", ".join(f"{k}={v}" for k, v in cfg.items())
            done = auto.converged(threshold)
            verdict = f"converged to {done}" if done else f"not converged (threshold {threshold})"
            lines.append(f"{rep.task}: {auto.scheme} ({extra}), {auto.steps} trials, {verdict}")
        else:
            lines.append(f"{rep.task}: no saved learner state; estimates from {len(rep.results)} results")
        lines.append(f"  rho = {auto.rho:.4g} ({_rho_source(auto)}); C: {_cost_source(auto)}")
        lines.append(f"  {'action':20s}{'p':>8s}{'trials':>8s}{'R':>8s}{'C':>10s}{'J':>8s}")
        probs = auto.probabilities
        for name, e in auto.estimates.items():
            p = _fmt(probs[name]) if rep.saved else "-"
            lines.append(f"  {name:20s}{p:>8s}{e.trials:8d}{_fmt(e.reliability):>8s}"
                         f"{_fmt(e.cost, 4):>10s}{_fmt(e.j):>8s}")
        if rep.replay_matches is not None:
            how = "matches" if rep.replay_matches else "does NOT match"
            lines.append(f"  replay of {len(rep.results)} journal results {how} the saved state")
        if rep.note:
            lines.append(f"  note: {rep.note}")
    return "\n".join(lines) + "\n"


def plot(reports: list[TaskReport], path: str, threshold: float) -> int:
    """Draw p(action) over trials for every task with alternatives, a saved state and results; return the
    panels drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawn = [r for r in reports if len(r.history) > 1 and len(r.automaton.actions) > 1]  # a fixed choice: p = 1
    if not drawn:
        return 0
    fig, axes = plt.subplots(len(drawn), 1, figsize=(7.0, 2.6 * len(drawn)), squeeze=False)
    for ax, rep in zip(axes[:, 0], drawn):
        for k, name in enumerate(rep.automaton.actions):
            ax.plot(range(len(rep.history)), [h[k] for h in rep.history], label=name)
        ax.axhline(threshold, color="grey", linestyle=":", linewidth=1)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("probability")
        ax.set_title(f"{rep.task} ({rep.automaton.scheme})")
        ax.legend(loc="center right", fontsize="small")
    axes[-1, 0].set_xlabel("trial")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return len(drawn)


def run(args: argparse.Namespace) -> int:
    """Run ``petrobot learn``; return 0, or 2 on an unreadable net or journal or bad option."""
    if not 0.5 < args.threshold <= 1.0:
        print("petrobot learn: --threshold must lie in (0.5, 1]", file=sys.stderr)
        return 2
    try:
        from coordinator.learning import Learner
        from coordinator.netfile import load_any

        configured = Learner.from_net(load_any(args.net))
        damaged: list[str] = []
        states, results = read_journal(args.journal, args.run, damaged)
        reports = build_reports(states, results, args.task, configured, fresh_from=args.run)
    except PetrobotError as exc:
        print(f"petrobot learn: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report_json(reports, args.threshold), indent=2))
    else:
        sys.stdout.write(report_text(reports, args.threshold))
    if args.plot is not None:
        target = args.plot or str(default_plot_path(args.journal))
        try:
            n = plot(reports, target, args.threshold)
        except OSError as exc:
            print(f"petrobot learn: cannot write {target}: {exc}", file=sys.stderr)
            return 2
        out = sys.stderr if args.json else sys.stdout
        if n:
            print(f"plot: {n} task(s) drawn to {target}", file=out)
        else:
            print(f"plot: nothing drawn (no primitive task has both a saved learner and results); {target} "
                  "not written", file=out)
    return options.report_damage("petrobot learn", damaged)
