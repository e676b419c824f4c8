"""``petrobot demo catching``: the paper's Fig. 1 on one machine, and its report (paper section 6).

:func:`run_catching` starts the simulated world (``petrobot sim catching``: table, thrower, ball,
PUMA 560 with its cup, overhead camera, CAN bus), the vision and motion nodes placed by
services.toml, and runs ``nets/catch.toml`` with the token flow visible
(:func:`coordinator.commands.demo_start.run_demo`); then prints, per run, the outcome, the
prediction error at the catch line (against the simulator's ground truth), the time of each
primitive task and the reason of every error.

:class:`CatchReport` observes a run of the catching net (:mod:`coordinator.events`): it groups the
events into runs of the experiment (each starts with the transition ``start_run``), keeps the
outcome, the locate action the learner chose, the final prediction of the catch point, the time
of each primitive task and the reason of every error (and of a miss), and pairs each prediction
with the simulator's ground truth. Pure: it only reads events.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from coordinator.commands.demo_start import ROOT, DemoWorld, run_demo, world_lines
from coordinator.events import ActionEnded, Observer, RunEvent, TransitionFired
from services.results import ActionResult, Status

__all__ = ["CatchReport", "RunRecord", "run_catching"]


@dataclass
class RunRecord:
    """What happened in one run of the catching net."""

    n: int
    outcome: str = "running"
    times: dict[str, float] = field(default_factory=dict)
    locate_action: str = ""
    predicted: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    """Why an action of the run ended in error (or a catch missed), one line each."""

    @property
    def error_mm(self) -> float | None:
        """|predicted − actual| lateral position at the catch line, millimetres."""
        if not self.predicted or not self.truth:
            return None
        return abs(float(self.predicted["y"]) - float(self.truth["y"])) * 1000.0


def _note(event: ActionEnded, result: ActionResult) -> str:
    """One line saying why an action did not succeed: its reason, else its value's ``reason``."""
    outcome = f" ({result.outcome})" if result.outcome else ""
    where = f" on {event.node}" if event.node else ""
    why = result.reason
    if not why and isinstance(result.value, dict):
        detail = result.value.get("reason")
        residual = result.value.get("residual_m")
        why = str(detail) if detail else None
        if why and isinstance(residual, (int, float)):
            why += f", track residual {residual * 1000:.1f} mm"
    return f"{event.task}/{event.action}{where}: {result.status.value}{outcome}: {why or 'no reason given'}"


class CatchReport:
    """A runtime observer that groups events into runs (each starts with ``start_run``).

    Args:
        forward: the observer every event is passed on to (the console).
    """

    #: Final transition of a run → its outcome in the report.
    OUTCOMES: ClassVar[Mapping[str, str]] = {
        "ball_caught": "caught", "ball_missed": "missed", "ball_bounced_out": "bounced out",
        "catch_failed": "error", "catch_failed_after_sensor": "error", "locate_failed": "error",
        "no_ball_seen": "no ball", "home_given_up": "out of service"}

    def __init__(self, forward: Observer) -> None:
        self.forward = forward
        self.runs: list[RunRecord] = []

    def __call__(self, event: RunEvent) -> None:
        """Take in one event of the run, then pass it on to ``forward``."""
        if isinstance(event, TransitionFired):
            tid = event.firing.transition
            if tid == "start_run":
                self.runs.append(RunRecord(len(self.runs) + 1))
            elif self.runs and tid in self.OUTCOMES:
                self.runs[-1].outcome = self.OUTCOMES[tid]
        elif isinstance(event, ActionEnded) and self.runs:
            run = self.runs[-1]
            result = event.result
            run.times[event.task] = run.times.get(event.task, 0.0) + result.wall_s
            if result.status is not Status.SUCCESS:
                run.notes.append(_note(event, result))
            if event.task == "locate":
                run.locate_action = event.action
            if event.task == "predict" and result.status is Status.SUCCESS and isinstance(result.value, dict):
                run.predicted = result.value
        self.forward(event)

    def match_truth(self, crossings: list[dict[str, Any]]) -> None:
        """Pair each run's final prediction with the simulator's crossing nearest in time."""
        for run in self.runs:
            if run.predicted is None:
                continue
            t = float(run.predicted.get("t", 0.0))
            near = min(crossings, key=lambda c: abs(float(c["t"]) - t), default=None)
            if near is not None and abs(float(near["t"]) - t) < 1.0:
                run.truth = near

    def format(self) -> str:
        """The table of runs: outcome, locate action, prediction error, lead and task times."""
        head = (f"{'run':>3}  {'outcome':<12}{'locate with':<18}{'pred. error':>12}{'lead':>7}"
                f"{'locate':>8}{'predict':>9}{'catch':>7}{'home':>7}")
        lines = ["", "catching experiment (times in seconds; prediction error at the catch line, final set point)",
                 head]
        for r in self.runs:
            err = f"{r.error_mm:9.2f} mm" if r.error_mm is not None else f"{'-':>12}"
            lead = f"{float(r.predicted.get('lead_s', 0.0)):6.2f}s" if r.predicted else f"{'-':>7}"
            times = "".join(f"{r.times[k]:>{w}.2f}" if k in r.times else f"{'-':>{w}}"
                            for k, w in (("locate", 8), ("predict", 9), ("catch", 7), ("home", 7)))
            lines.append(f"{r.n:>3}  {r.outcome:<12}{r.locate_action:<18}{err}{lead}{times}")
        for r in self.runs:
            lines.extend(f"  run {r.n}: {note}" for note in r.notes)
        caught = sum(r.outcome == "caught" for r in self.runs)
        restarted = sum(r.outcome == "no ball" for r in self.runs)
        attempts = len(self.runs) - restarted
        note = (f" ({restarted} run{'s' * (restarted != 1)} restarted: no ball located within specification)"
                if restarted else "")
        lines.append(f"caught {caught} of {attempts} balls{note}")
        if any(r.outcome == "out of service" for r in self.runs):
            lines.append("the PUMA is out of service: the move home failed after every retry (see the reasons above)")
        return "\n".join(lines)

    def outcomes(self) -> list[tuple[str, str]]:
        """(outcome, locate action) of each run: what two demos of one seed share on a quiet machine
        (the README says what a seed repeats for sure)."""
        return [(r.outcome, r.locate_action) for r in self.runs]


async def run_catching(args: argparse.Namespace) -> int:
    """The catching demo (see the module docstring); returns the run's exit code."""
    from coordinator.netfile import load_net

    net_path = ROOT / "nets" / "catch.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    done = await run_demo(
        args, net, net_path, journal="runs/catching.sqlite", report=CatchReport,
        worlds=[DemoWorld("catching", ["--realtime", "--seed", str(args.seed), "--renderer", args.renderer,
                                       "--throws", "0", "--interval", "0", "--throw-when-home", "1.0",
                                       "--first-throw", "4", "--after-camera-client"])])
    report = done.report
    assert report is not None
    report.match_truth([e for e in done.world if e.get("event") == "crossing"])
    print(done.summary.format())
    print(report.format())
    for line in world_lines(done.world):
        print(line)
    print(f"journal: {done.journal}; logs: {done.logs}/")
    from coordinator.commands.learn import print_learned

    print_learned(done.journal, net_path)
    return done.summary.exit_code

