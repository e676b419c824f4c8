"""Learning the locate primitive task in the catching testbed (paper section 4 on section 6's testbed).

Usage::

    python bench/learning_catching.py --runs 200 --seed 1 [--json] [--plot PREFIX]
        [--cost apriori|measured] [--rate R] [--warmup W] [--no-catch]

One process, lock-step simulated time (pybullet at 1 kHz, analytic camera at 50 frames/s), the same
world as ``bench/catching.py``. For each camera noise level (``clean``: grey-level σ = 2 and 0.5 px
position jitter, the catching bench's camera; ``noisy``: grey-level σ = 40 and 2 px jitter) a fresh
learner runs ``--runs`` seeded throws. In every throw the *locate* primitive task starts on the first
frame; each instance draws one of the three primitive actions (``locate_threshold``, ``locate_bgdiff``,
``locate_average``) from a pursuit automaton configured as ``nets/catch.toml``'s locate task
(:meth:`coordinator.learning.Learner.from_net`), runs the same pure locator function the vision
action runs on the rendered frames, and judges the location as the vision action does with
``spec_m`` (:func:`services.catching.vision_node.track_residual` over the next ``VERIFY_FRAMES`` frames;
the node has no ground truth). The status (``success`` within specification, else ``failure``) and
the locator's measured CPU time go to the automaton. A failed instance is followed by a new one on
the next frame, as the net's *no ball seen* transition restarts the run. After a success, prediction
and catch run as in ``bench/catching.py``: threshold locator → homography → ``RollingPredictor`` →
``CatchServo`` → CiA 402 RPDOs → simulated drives, and the same geometric catch criterion.

Costs: by default the a-priori costs of the net (1.0, 0.5, 3.0; ρ = 1/3); ``--cost measured`` uses
the mean measured CPU time instead (ρ = 1 / the largest mean). The ground-truth error of every
location (from the simulator) is reported separately from the judged success.

Baseline in the same run: the catch rate over the first 50 throws (learning, near-uniform choice)
against the last 50 (after learning), and the mean J of a uniform random choice against the J of the
action learned (from the per-action estimates).

``--no-catch`` stops each throw once the ball is located (no robot; for quick checks and tests).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench.catching import InProcessDrives, rim_position
from bench.stdio import stdout_to_stderr
from coordinator.learning import Learner, LearningAutomaton
from coordinator.netfile import load_net
from services.catching.vision_node import VERIFY_FRAMES, track_residual
from services.catching.robot import motion_control, puma560
from services.catching.vision import (
    BallTracker,
    Detection,
    Homography,
    RollingModel,
    RollingPredictor,
    calibration_points,
    locate_average,
    locate_bgdiff,
    locate_threshold,
)
from sim.catching.camera import AnalyticRenderer, calibrate, overhead_camera
from sim.catching.drives import SimDrives
from sim.catching.world import CatchingWorld, Thrower
from sim.world import World

TASK = "locate"
NET_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "nets", "catch.toml")

#: Camera noise levels: (grey-level σ, position jitter σ in pixels) of the analytic renderer.
NOISE_LEVELS: dict[str, tuple[float, float]] = {"clean": (2.0, 0.5), "noisy": (40.0, 2.0)}

#: Specification of a location: residual against the next frames' track, m.
SPEC_M = 0.006

#: Frames the averaging locator uses (the vision action's default ``k``).
AVERAGE_K = 4

FPS = 50.0
WINDOW = 50


@dataclass
class Attempt:
    """One locate instance: the action drawn, its judged status and errors."""

    run: int
    action: str
    status: str
    cost_s: float
    residual_m: float | None
    truth_error_m: float | None


@dataclass
class RunResult:
    """One throw."""

    attempts: int
    located: bool
    t_located: float | None
    caught: bool | None


@dataclass
class LevelResult:
    """Everything measured at one noise level."""

    level: str
    attempts: list[Attempt] = field(default_factory=list)
    runs: list[RunResult] = field(default_factory=list)
    curve: list[dict[str, float]] = field(default_factory=list)
    automaton: LearningAutomaton | None = None
    wall_s: float = 0.0


def make_automaton(seed: int, cost: str, rate: float | None, warmup: int | None) -> LearningAutomaton:
    """The locate task's automaton, configured from nets/catch.toml (optionally overridden).

    Args:
        seed: run seed (the automaton's own is derived with :func:`coordinator.learning.task_seed`).
        cost: ``"apriori"`` (the net's costs) or ``"measured"`` (mean CPU time per action, s).
        rate: learning rate λ overriding the net's (None: keep it).
        warmup: trials of every action before p moves, overriding the net's (None: keep it).
    """
    net = load_net(NET_PATH)
    task = net.tasks[TASK]
    config = dict(task.learner)
    if rate is not None:
        config["rate"] = rate
    if warmup is not None:
        config["warmup"] = warmup
    names = [a.name for a in task.actions]
    costs = {a.name: a.cost for a in task.actions if a.cost is not None}
    learner = Learner(seed)
    if cost == "measured":
        return learner.add_task(TASK, names, config, None)
    return learner.add_task(TASK, names, config, costs or None)


def _locate(action: str, frames: list[tuple[np.ndarray, float]], background: np.ndarray) -> Detection | None:
    img, t = frames[-1]
    if action == "locate_threshold":
        return locate_threshold(img, t)
    if action == "locate_bgdiff":
        return locate_bgdiff(img, background, t)
    return locate_average(frames)


def frames_needed(action: str) -> int:
    """Frames one instance of ``action`` consumes before it can locate."""
    return AVERAGE_K if action == "locate_average" else 1


class _Rig:
    """World, camera, calibration, predictor, robot and drives of one noise level."""

    def __init__(self, level: str, seed: int, catch: bool) -> None:
        with stdout_to_stderr():
            self.world = World()
            self.cw = CatchingWorld(self.world, robot=catch)
        cam = overhead_camera()
        isig, psig = NOISE_LEVELS[level]
        self.renderer = AnalyticRenderer(cam, intensity_sigma=isig, position_sigma_px=psig, seed=seed)
        self.background = self.renderer.noiseless_background()
        z = self.cw.ball_plane_z
        cal = AnalyticRenderer(cam, intensity_sigma=0.0)
        self.hom: Homography = calibrate(lambda x, y: cal.render((x, y, z)), calibration_points(1.5, 0.76))
        self.model = RollingModel(*self.cw.ball.rolling_decel_params())
        self.catch = catch
        self.geo = motion_control.CatchGeometry()
        if catch:
            self.tf = self.cw.table_to_base()
            q_home = motion_control.home_pose(self.geo)
            self.cw.set_joint_positions(q_home)
            self.drives = SimDrives()
            assert self.cw.robot_id is not None
            self.drives.attach(self.world.client, self.cw.robot_id, self.cw.joint_indices,
                               crossfire=self.cw.crossfire)
            self.world.add_step_hook(self.drives.step)
            self.bus = InProcessDrives(self.drives, self.world)
            self.bus.enable()
            self.servo = motion_control.CatchServo(q_home, self.geo)

    def table_xy(self, det: Detection) -> tuple[float, float]:
        x, y = self.hom.to_table([det.u, det.v])
        return float(x), float(y)

    def close(self) -> None:
        self.world.close()


def run_level(
    level: str, runs: int, seed: int, *, cost: str = "apriori", rate: float | None = None,
    warmup: int | None = None, catch: bool = True, progress: bool = False,
) -> LevelResult:
    """Run ``runs`` seeded throws at one noise level with a fresh locate automaton.

    Args:
        level: key of :data:`NOISE_LEVELS`.
        runs: number of throws.
        seed: seed of the thrower, the camera noise and the automaton.
        cost: ``"apriori"`` or ``"measured"`` (see :func:`make_automaton`).
        rate, warmup: overrides of the net's learner configuration.
        catch: simulate prediction and catch with the robot (False: stop once located).
        progress: print progress to stderr.

    Returns:
        Attempts, per-run results, the probability vector after every locate instance, the automaton.
    """
    rig = _Rig(level, seed, catch)
    auto = make_automaton(seed, cost, rate, warmup)
    out = LevelResult(level, automaton=auto)
    thrower = Thrower(seed)
    world, cw = rig.world, rig.cw
    frame_steps = max(1, round(1.0 / FPS / world.dt))
    cycle_steps = round(motion_control.CYCLE_S / world.dt)
    capture = puma560.CUP_INNER_RADIUS - cw.ball.radius
    t_fall = math.sqrt(2.0 * (cw.ball.radius + rig.geo.rim_drop) / motion_control.G)
    wall0 = time.perf_counter()
    for i in range(runs):
        if progress and i and i % 25 == 0:
            print(f"... {level}: {i}/{runs} throws, {time.perf_counter() - wall0:.0f} s",
                  file=sys.stderr, flush=True)
        spec = thrower.next()
        cw.park()
        world.step(5)
        cw.launch(spec)
        t0 = world.t
        tracker = BallTracker(rig.hom, RollingPredictor(rig.model, position_sigma=0.001))
        phase = "locate"
        action: str | None = None
        frames: list[tuple[np.ndarray, float]] = []
        truth: list[np.ndarray] = []
        pending: tuple[str, float, float, float, float, float, np.ndarray] | None = None
        track: list[tuple[float, float, float]] = []
        attempts = 0
        t_located: float | None = None
        last_sp: tuple[float, float] | None = None
        rim_at_catch: np.ndarray | None = None
        k = 0
        while world.t < t0 + 6.0:
            if catch and k % cycle_steps == 0:
                rig.bus.send_targets(rig.servo.step())
            if k % frame_steps == 0:
                pos, _ = cw.ball_state()
                visible = cw.ball_on_table()
                img = rig.renderer.render(pos if visible else None)
                t = world.t
                if phase == "locate" and visible:
                    if action is None:
                        action = auto.choose()
                        frames, truth = [], []
                    frames.append((img, t))
                    truth.append(pos[:2].copy())
                    if len(frames) >= frames_needed(action):
                        c0 = time.thread_time()
                        det = _locate(action, frames, rig.background)
                        cpu = time.thread_time() - c0
                        attempts += 1
                        xy = rig.table_xy(det) if det is not None else None
                        if det is None or xy is None or xy[0] >= 0.0:
                            auto.update(action, "failure", cpu)
                            out.attempts.append(Attempt(i, action, "failure", cpu, None, None))
                            out.curve.append(auto.probabilities)
                            action = None
                        else:
                            true_xy = np.mean(truth, axis=0)
                            pending = (action, cpu, det.t, xy[0], xy[1], 0.0, true_xy)
                            track = []
                            phase = "verify"
                elif phase == "verify" and pending is not None:
                    d = locate_threshold(img, t) if visible else None
                    if d is not None:
                        track.append((t, *rig.table_xy(d)))
                    if len(track) >= VERIFY_FRAMES or not visible:
                        act, cpu, t_det, x_det, y_det, _, true_xy = pending
                        truth_err = float(np.hypot(x_det - true_xy[0], y_det - true_xy[1]))
                        residual = (track_residual((t_det, x_det, y_det), track)
                                    if len(track) >= 3 else None)
                        ok = residual is not None and residual <= SPEC_M
                        status = "success" if ok else "failure"
                        auto.update(act, status, cpu)
                        out.attempts.append(Attempt(i, act, status, cpu, residual, truth_err))
                        out.curve.append(auto.probabilities)
                        pending, action = None, None
                        if ok:
                            phase = "predict"
                            t_located = t - t0
                            if not catch:
                                break
                        else:
                            phase = "locate"
                elif phase == "predict":
                    det = locate_threshold(img, t) if visible else None
                    pred = tracker.observe(det, t)
                    if pred is not None:
                        x_b, y_b, _ = rig.tf.point(pred.x, pred.y)
                        vx_b, vy_b = rig.tf.vector(pred.vx, pred.vy)
                        try:
                            rig.servo.aim(x_b, y_b, pred.t, vx_b, vy_b)
                        except puma560.UnreachableError:
                            pass
                        last_sp = (t, pred.y)
            world.step()
            k += 1
            cr = cw.crossing
            if cr is not None:
                if not catch:
                    break
                if rim_at_catch is None and world.t >= cr.t + t_fall:
                    rim_at_catch = rim_position(puma560.fk(cw.joint_positions()))
                if world.t > cr.t + 0.6:
                    break
        caught: bool | None = None
        if catch:
            cr = cw.crossing
            caught = False
            if cr is not None and last_sp is not None and rim_at_catch is not None:
                x_b, y_b, _ = rig.tf.point(0.0, cr.y)
                vx_b, vy_b = rig.tf.vector(cr.vx, cr.vy)
                ideal = np.array([x_b + vx_b * t_fall, y_b + vy_b * t_fall,
                                  rig.geo.table_z - rig.geo.rim_drop])
                caught = (abs(last_sp[1] - cr.y) <= capture
                          and float(np.linalg.norm(rim_at_catch - ideal)) <= capture)
        out.runs.append(RunResult(attempts, t_located is not None, t_located, caught))
    out.wall_s = time.perf_counter() - wall0
    rig.close()
    return out


def _rate(values: list[bool]) -> float | None:
    return sum(values) / len(values) if values else None


def summarise_level(res: LevelResult) -> dict[str, Any]:
    """JSON-ready summary of one noise level (see the module docstring for the keys)."""
    auto = res.automaton
    assert auto is not None
    est = auto.estimates
    rho = auto.rho
    n = len(res.runs)
    first = res.runs[: min(WINDOW, n)]
    last = res.runs[max(0, n - WINDOW):]
    per_action: dict[str, Any] = {}
    for name in auto.actions:
        att = [a for a in res.attempts if a.action == name]
        errs = [a.truth_error_m for a in att if a.truth_error_m is not None]
        e = est[name]
        per_action[name] = {
            "trials": e.trials, "successes": e.successes, "R_hat": e.reliability, "C": e.cost,
            "J": e.j, "measured_cpu_s": e.measured_cost,
            "no_detection": sum(a.truth_error_m is None for a in att),
            "truth_error_median_m": float(np.median(errs)) if errs else None,
            "truth_error_p90_m": float(np.percentile(errs, 90)) if errs else None,
            "truth_within_spec": (sum(x <= SPEC_M for x in errs) / len(att)) if att else None,
        }
    js = [v["J"] for v in per_action.values() if v["J"] is not None]
    learned = min(per_action, key=lambda a: per_action[a]["J"] if per_action[a]["J"] is not None else math.inf)
    catches_first = [r.caught for r in first if r.caught is not None]
    catches_last = [r.caught for r in last if r.caught is not None]
    return {
        "noise": {"intensity_sigma": NOISE_LEVELS[res.level][0],
                  "position_sigma_px": NOISE_LEVELS[res.level][1]},
        "runs": n,
        "locate_instances": len(res.attempts),
        "converged_action": auto.converged(0.95),
        "converged_at_instance": next(
            (j + 1 for j, p in enumerate(res.curve) if max(p.values()) >= 0.95), None),
        "best_estimated_action": learned,
        "probabilities": auto.probabilities,
        "rho": rho,
        "estimates": per_action,
        "J_uniform_choice": float(np.mean(js)) if len(js) == len(per_action) else None,
        "J_learned_action": per_action[learned]["J"],
        "catch_rate": _rate([r.caught for r in res.runs if r.caught is not None]),
        "catch_rate_first_50": _rate(catches_first),
        "catch_rate_last_50": _rate(catches_last),
        "locate_attempts_per_run_first_50": float(np.mean([r.attempts for r in first])) if first else None,
        "locate_attempts_per_run_last_50": float(np.mean([r.attempts for r in last])) if last else None,
        "time_to_location_first_50_s": _mean_t(first),
        "time_to_location_last_50_s": _mean_t(last),
        "located_rate": _rate([r.located for r in res.runs]),
        "wall_s": res.wall_s,
    }


def _mean_t(runs: list[RunResult]) -> float | None:
    ts = [r.t_located for r in runs if r.t_located is not None]
    return float(np.mean(ts)) if ts else None


def plot_curve(res: LevelResult, path: str) -> None:
    """Write the learning curve (probability of each action against the locate instance) as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    auto = res.automaton
    assert auto is not None
    fig, ax = plt.subplots(figsize=(7, 4))
    trials = np.arange(1, len(res.curve) + 1)
    for name, style in zip(auto.actions, ("-", "--", ":")):
        ax.plot(trials, [p[name] for p in res.curve], style, lw=1.8, label=name)
    isig, psig = NOISE_LEVELS[res.level]
    ax.set_xlabel("locate instance (trial)")
    ax.set_ylabel("probability of choosing the action")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"locate task, {res.level} camera (grey σ = {isig:g}, jitter {psig:g} px)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=200, help="seeded throws per noise level")
    ap.add_argument("--seed", type=int, default=1, help="seed of thrower, camera noise and learner")
    ap.add_argument("--cost", choices=("apriori", "measured"), default="apriori",
                    help="C of J: the net's a-priori costs, or the measured CPU time of the locator")
    ap.add_argument("--rate", type=float, default=None, help="learning rate λ (default: the net's)")
    ap.add_argument("--warmup", type=int, default=None,
                    help="trials of every action before p moves (default: the net's)")
    ap.add_argument("--levels", default=",".join(NOISE_LEVELS),
                    help="comma-separated noise levels to run (default: clean,noisy)")
    ap.add_argument("--no-catch", action="store_true",
                    help="stop each throw once located (no robot, no catch rate)")
    ap.add_argument("--json", action="store_true", help="print the results as one JSON object")
    ap.add_argument("--plot", metavar="PREFIX",
                    help="write the learning curves to PREFIX_<level>.png")
    args = ap.parse_args(argv)
    levels = [lv for lv in args.levels.split(",") if lv]
    for lv in levels:
        if lv not in NOISE_LEVELS:
            ap.error(f"unknown noise level {lv!r}; known: {', '.join(NOISE_LEVELS)}")
    summary: dict[str, Any] = {"runs": args.runs, "seed": args.seed, "cost": args.cost,
                               "spec_m": SPEC_M, "verify_frames": VERIFY_FRAMES, "levels": {}}
    for lv in levels:
        res = run_level(lv, args.runs, args.seed, cost=args.cost, rate=args.rate,
                        warmup=args.warmup, catch=not args.no_catch, progress=True)
        summary["levels"][lv] = summarise_level(res)
        if args.plot:
            plot_curve(res, f"{args.plot}_{lv}.png")
    if len(levels) == 2:
        a, b = (summary["levels"][lv]["best_estimated_action"] for lv in levels)
        summary["different_action_under_noise"] = a != b
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for lv, s in summary["levels"].items():
            print(f"== {lv} camera {s['noise']}")
            for key, v in s.items():
                if key in ("estimates", "noise"):
                    continue
                print(f"  {key:40s} {v}")
            print(f"  {'action':18s} {'trials':>6s} {'R_hat':>6s} {'C':>8s} {'J':>6s} "
                  f"{'cpu ms':>7s} {'truth med mm':>12s}")
            for name, e in s["estimates"].items():
                def f(v: Any, spec: str) -> str:
                    return format(v, spec) if v is not None else "-"
                print(f"  {name:18s} {e['trials']:6d} {f(e['R_hat'], '6.3f')} {f(e['C'], '8.4g')} "
                      f"{f(e['J'], '6.3f')} {f(e['measured_cpu_s'] and 1000 * e['measured_cpu_s'], '7.2f')} "
                      f"{f(e['truth_error_median_m'] and 1000 * e['truth_error_median_m'], '12.2f')}")
        if "different_action_under_noise" in summary:
            print(f"different action under noise: {summary['different_action_under_noise']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
