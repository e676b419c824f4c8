"""Learning the track detector of the follow_track primitive task (paper section 4 on section 6's
mobile robot).

Usage::

    python bench/mobile.py --learn --condition clean|noisy|harsh [--courses 150] [--seed 1]
        [--cost apriori|measured] [--spec-mm 20] [--json] [--plot PREFIX]
    python bench/mobile_learning.py ...   (the same)

One process, lock-step simulated time: the closed loop of :func:`sim.mobile.harness.run_course`
(pybullet world, analytic downward camera, beacon sensor, :class:`MobileMission` at 50 Hz) on seeded
random courses (:func:`sim.mobile.course.random_course`). Every *follow segment* — from the start of a
course, or from a track reacquisition after an interruption, to the next interruption, the T mark
or the end of the run — is one instance of ``nets/mobile.toml``'s ``follow_track`` primitive task:
the project's learner (:meth:`coordinator.learning.Learner.from_net`: the pursuit automaton of
``[task.follow_track]``, a-priori costs 0.29 / 0.28 / 0.18 ms per frame) draws ``follow_ransac``,
``follow_centroid`` or ``follow_scanline``, the mission's detector is switched to it for the segment,
and the segment's result goes back to the learner.

**Specification of a segment** (judged against ground truth, as the nodes cannot): it ends with the
correct outcome — an interruption declared within :data:`OUTCOME_WINDOW_M` before or on a blank
square, the T mark taken on or just before the end square — and the axle's cross-track error on
painted squares stays within ``--spec-mm`` (default 20 mm: the track is 50 mm wide, phase 1 measured
at most 12.6–14.7 mm with every detector). Otherwise the segment is a ``failure`` (a false
interruption, a missed one, the T missed, the track lost, or too far off). A failed segment usually
ends the course (the mission fails safe); the next course starts.

**Conditions** are the phase-1 image conditions of ``bench/mobile.py`` (nothing tuned here):
``clean`` its ``default`` camera (σ = 5 grey levels, 0.6 px blur, vignetting, 5 % gain jitter);
``noisy`` its ``noisy`` one (σ = 25, 1 px blur, 15 % gain jitter); ``harsh`` noisy plus 3 scuffs per
frame.

**Cost**: the net's a-priori costs (ρ = 1 / 0.29), or with ``--cost measured`` the detector's mean
CPU time per frame in the segment (ρ = 1 / the largest mean).

Reported per condition: segments, the action converged to (p ≥ 0.95) and when, final
probabilities, per action the trials, R̂, C and Ĵ and the failures by kind, completion of the
courses in the first and last 20, mean Ĵ of a uniform choice against the learned action's.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench.stdio import stdout_to_stderr
from coordinator.learning import Learner, LearningAutomaton
from coordinator.netfile import load_net
from services.mobile.lines import make_detector
from sim.mobile.course import Course, random_course
from sim.mobile.harness import MissionParams, MobileMission, Phase, run_course
from sim.mobile.sensors import ImageNoise

TASK = "follow_track"
NET_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "nets", "mobile.toml")

#: The phase-1 image conditions (bench/mobile.py's ``default``, ``noisy`` and ``harsh``).
CONDITIONS: dict[str, ImageNoise] = {
    "clean": ImageNoise(),
    "noisy": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15),
    "harsh": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15, spots=3.0),
}
#: An interruption (T mark) is the correct outcome when the robot's axle is on the blank (end)
#: square or this close before it along its heading, m (the camera looks ahead of the axle).
OUTCOME_WINDOW_M = 0.6
WINDOW = 20


def detector_of(action: str) -> str:
    """``follow_ransac`` → ``ransac`` (the detector a follow action runs)."""
    return action.removeprefix("follow_")


@dataclass
class Segment:
    """One follow_track instance."""

    course: int
    action: str
    outcome: str  # interruption | end | lost | off_spec | false_interruption | missed_end | run_ended
    success: bool
    max_offset_m: float
    cpu_ms_per_frame: float
    frames: int


@dataclass
class ConditionResult:
    """Everything measured under one image condition."""

    condition: str
    segments: list[Segment] = field(default_factory=list)
    courses: list[bool] = field(default_factory=list)
    curve: list[dict[str, float]] = field(default_factory=list)
    automaton: LearningAutomaton | None = None
    wall_s: float = 0.0
    cpu_s: float = 0.0
    sim_s: float = 0.0


class _TimedDetector:
    """A track detector that counts its frames and CPU time."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.frames = 0
        self.cpu = 0.0

    def detect(self, image: np.ndarray) -> Any:
        c0 = time.thread_time()
        out = self.inner.detect(image)
        self.cpu += time.thread_time() - c0
        self.frames += 1
        return out


def make_automaton(seed: int, cost: str) -> LearningAutomaton:
    """follow_track's automaton as nets/mobile.toml configures it (``cost="measured"``: the measured
    CPU time per frame is the C of J instead of the a-priori costs)."""
    net = load_net(NET_PATH)
    if cost == "apriori":
        return Learner.from_net(net, seed=seed).automaton(TASK)
    task = net.tasks[TASK]
    return Learner(seed).add_task(TASK, [a.name for a in task.actions], dict(task.learner), None)


def _near(course: Course, x: float, y: float, th: float, want: Any) -> bool:
    """Whether the point, or a point up to OUTCOME_WINDOW_M ahead of it, is on a square ``want``
    accepts."""
    for d in np.linspace(0.0, OUTCOME_WINDOW_M, 7):
        tile = course.tile_at(x + d * math.cos(th), y + d * math.sin(th))
        if tile is not None and want(tile):
            return True
    return False


class _Segments:
    """The on_tick hook: opens a segment when the mission (re)enters FOLLOW, judges it when it
    leaves FOLLOW, switches the mission's detector to the learner's choice."""

    def __init__(self, course: Course, index: int, auto: LearningAutomaton, cost: str, spec_m: float,
                 out: ConditionResult, first: str) -> None:
        self.course, self.index, self.auto, self.cost, self.spec = course, index, auto, cost, spec_m
        self.out = out
        self.action: str | None = None
        self.timed: _TimedDetector | None = None
        self.max_off = 0.0
        self.phase = Phase.FOLLOW
        self._first = first
        self.started = False

    def _open(self, mission: MobileMission, action: str) -> None:
        self.action = action
        self.timed = _TimedDetector(make_detector(detector_of(action), mission.camera,
                                                  track_width=self.course.track_width))
        mission.detector = self.timed  # type: ignore[assignment]
        self.max_off = 0.0

    def _close(self, outcome: str, success: bool) -> None:
        assert self.action is not None and self.timed is not None
        ms = 1000.0 * self.timed.cpu / max(1, self.timed.frames)
        if success and self.max_off > self.spec:
            outcome, success = "off_spec", False
        self.auto.update(self.action, "success" if success else "failure",
                         ms if self.cost == "measured" else None)
        self.out.segments.append(Segment(self.index, self.action, outcome, success, self.max_off, ms,
                                         self.timed.frames))
        self.out.curve.append(self.auto.probabilities)
        self.action, self.timed = None, None

    def __call__(self, t: float, mission: MobileMission, mw: Any, sp: Any) -> None:
        if not self.started:  # the first tick: the mission built the first segment's detector
            self.started = True
            self.action, self.timed = self._first, _TimedDetector(mission.detector)
            mission.detector = self.timed  # type: ignore[assignment]
        x, y, th = mw.pose()
        if mission.phase is Phase.FOLLOW and self.action is not None:
            here = mw.where(x, y)
            if here is not None and not here[0].blank:
                self.max_off = max(self.max_off, abs(here[2]))
        if mission.phase is not self.phase:
            left, self.phase = self.phase, mission.phase
            if left is Phase.FOLLOW and self.action is not None:
                if mission.phase is Phase.APPROACH:
                    ok = _near(self.course, x, y, th, lambda tl: tl.blank)
                    self._close("interruption" if ok else "false_interruption", ok)
                elif mission.phase in (Phase.STOPPING, Phase.DONE):
                    ok = _near(self.course, x, y, th, lambda tl: tl.shape == "E")
                    self._close("end" if ok else "early_end", ok)
                else:  # FAILED straight from FOLLOW: an interruption without a beacon, or lost
                    ok = _near(self.course, x, y, th, lambda tl: tl.blank)
                    self._close("interruption_no_beacon" if ok else "false_interruption", False)
            if mission.phase is Phase.FOLLOW and self.action is None:
                self._open(mission, self.auto.choose())

    def finish(self, reason: str) -> None:
        """The run ended: a segment still open failed (off the track, time limit)."""
        if self.action is not None:
            self._close("lost" if "left the track" in reason else "run_ended", False)


def run_condition(condition: str, courses: int, seed: int, *, cost: str = "apriori", spec_m: float = 0.020,
                  progress: bool = False) -> ConditionResult:
    """Drive ``courses`` seeded random courses under one image condition with a fresh automaton."""
    auto = make_automaton(seed, cost)
    out = ConditionResult(condition, automaton=auto)
    noise = CONDITIONS[condition]
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(courses):
        if progress and k and k % 10 == 0:
            print(f"... {condition}: {k}/{courses} courses, {len(out.segments)} segments, "
                  f"{time.perf_counter() - wall0:.0f} s", file=sys.stderr, flush=True)
        course = random_course(seed * 1_000_003 + k)
        first = auto.choose()
        hook = _Segments(course, k, auto, cost, spec_m, out, first)
        with stdout_to_stderr():
            res = run_course(course, params=MissionParams(detector=detector_of(first)), noise=noise,
                             seed=seed * 7919 + k, on_tick=hook)
        hook.finish(res.reason)
        out.courses.append(res.completed)
        out.sim_s += res.t_sim
    out.wall_s = time.perf_counter() - wall0
    out.cpu_s = time.process_time() - cpu0
    return out


def summarise(res: ConditionResult) -> dict[str, Any]:
    """JSON-ready summary of one condition (see the module docstring)."""
    auto = res.automaton
    assert auto is not None
    est = auto.estimates
    per: dict[str, Any] = {}
    for name in auto.actions:
        seg = [s for s in res.segments if s.action == name]
        kinds: dict[str, int] = {}
        for s in seg:
            if not s.success:
                kinds[s.outcome] = kinds.get(s.outcome, 0) + 1
        e = est[name]
        per[name] = {"trials": e.trials, "successes": e.successes, "R_hat": e.reliability, "C": e.cost,
                     "J": e.j, "failures": kinds,
                     "cpu_ms_per_frame": float(np.mean([s.cpu_ms_per_frame for s in seg])) if seg else None,
                     "max_offset_p90_mm": float(np.percentile([1000 * s.max_offset_m for s in seg if s.success], 90))
                     if any(s.success for s in seg) else None}
    js = [v["J"] for v in per.values() if v["J"] is not None]
    learned = min(per, key=lambda a: per[a]["J"] if per[a]["J"] is not None else math.inf)
    n = len(res.courses)
    return {
        "noise": dataclasses.asdict(CONDITIONS[res.condition]),
        "courses": n,
        "segments": len(res.segments),
        "converged_action": auto.converged(0.95),
        "converged_at_segment": next((j + 1 for j, p in enumerate(res.curve) if max(p.values()) >= 0.95), None),
        "best_estimated_action": learned,
        "probabilities": auto.probabilities,
        "rho": auto.rho,
        "estimates": per,
        "J_uniform_choice": float(np.mean(js)) if len(js) == len(per) else None,
        "J_learned_action": per[learned]["J"],
        "completion_rate": sum(res.courses) / n if n else None,
        "completion_first": sum(res.courses[:WINDOW]) / min(WINDOW, n) if n else None,
        "completion_last": sum(res.courses[-WINDOW:]) / min(WINDOW, n) if n else None,
        "sim_s": res.sim_s, "wall_s": res.wall_s, "cpu_s": res.cpu_s,
        "load_average_1min": os.getloadavg()[0],
    }


def plot_curve(res: ConditionResult, path: str, spec_mm: float) -> None:
    """Write the learning curve (probability of each action against the follow segment) as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    auto = res.automaton
    assert auto is not None
    fig, ax = plt.subplots(figsize=(7, 4))
    trials = np.arange(1, len(res.curve) + 1)
    for name, style in zip(auto.actions, ("-", "--", ":")):
        ax.plot(trials, [p[name] for p in res.curve], style, lw=1.8, label=name)
    n = CONDITIONS[res.condition]
    ax.set_xlabel("follow_track instance (segment)")
    ax.set_ylabel("probability of choosing the action")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"follow_track, {res.condition} camera (grey σ = {n.sigma:g}, scuffs {n.spots:g}/frame; "
                 f"spec {spec_mm:g} mm)", fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--learn", action="store_true", help="(accepted: the dispatch flag of bench/mobile.py)")
    ap.add_argument("--condition", default="clean",
                    help=f"comma-separated image conditions: {', '.join(CONDITIONS)} (default clean)")
    ap.add_argument("--courses", type=int, default=150, help="seeded random courses per condition")
    ap.add_argument("--seed", type=int, default=1, help="seed of the courses, the image noise and the learner")
    ap.add_argument("--cost", choices=("apriori", "measured"), default="apriori",
                    help="C of J: the net's a-priori costs, or the measured CPU time per frame")
    ap.add_argument("--spec-mm", type=float, default=20.0, help="largest cross-track error of a good segment, mm")
    ap.add_argument("--json", action="store_true", help="print the results as one JSON object")
    ap.add_argument("--plot", metavar="PREFIX", help="write the learning curves to PREFIX_<condition>.png")
    args = ap.parse_args(argv)
    conds = [c for c in args.condition.split(",") if c]
    for c in conds:
        if c not in CONDITIONS:
            ap.error(f"unknown condition {c!r}; known: {', '.join(CONDITIONS)}")
    if args.courses < 1:
        ap.error("--courses must be at least 1")
    summary: dict[str, Any] = {"courses": args.courses, "seed": args.seed, "cost": args.cost,
                               "spec_mm": args.spec_mm, "conditions": {}}
    for c in conds:
        res = run_condition(c, args.courses, args.seed, cost=args.cost, spec_m=args.spec_mm / 1000.0,
                            progress=True)
        summary["conditions"][c] = summarise(res)
        if args.plot:
            plot_curve(res, f"{args.plot}_{c}.png", args.spec_mm)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for c, s in summary["conditions"].items():
            print(f"== {c}: {s['noise']}")
            for key, v in s.items():
                if key not in ("estimates", "noise"):
                    print(f"  {key:28s} {v}")
            print(f"  {'action':16s} {'trials':>6s} {'R_hat':>6s} {'C':>7s} {'J':>6s} {'ms/frame':>8s}  failures")
            for name, e in s["estimates"].items():
                def f(v: Any, spec: str) -> str:
                    return format(v, spec) if v is not None else "-"
                print(f"  {name:16s} {e['trials']:6d} {f(e['R_hat'], '6.3f')} {f(e['C'], '7.4g')} "
                      f"{f(e['J'], '6.3f')} {f(e['cpu_ms_per_frame'], '8.3f')}  {e['failures']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
