"""Mobile-robot benchmark: seeded random courses driven end to end in lock-step simulated time.

Usage::

    python bench/mobile.py --courses 100 --seed 1 [--json] [--detector ransac|centroid|scanline]
        [--camera analytic|tiny] [--noise default|noisy|scuffed|harsh] [--latency 0.0]
        [--cruise 0.8] [--look-ahead 0.26] [--course FILE.toml] [--timing] [--detectors N]
    python bench/mobile.py --learn --condition clean|noisy|harsh ...   (bench/mobile_learning.py)

Paper section 6 ("Mobile Robot Task"). For every course of a seeded generator
(:func:`sim.mobile.course.random_course`: 8–16 tiles, 0–3 interruptions) — or the course file given
with ``--course`` — one process builds the pybullet world (250 Hz physics), renders the downward
camera (analytic floor-map warp with blur, vignetting, gain and grey-level noise by default), scans
the beacon sensor at 20 Hz and runs, at 50 Hz, the primitive actions the perception node runs
(:mod:`services.mobile.tasks`: follow the track, find the beacon, go to it, reacquire the track, stop
at the T), called in process and sequenced as the task net does (:class:`sim.mobile.lockstep.TaskSequence`);
``--mission phase1`` runs phase 1's in-process :class:`sim.mobile.harness.MobileMission` instead.

Reported (JSON keys):

* ``completion_rate`` — courses on which the robot stopped on its own within 0.3 m of the T mark,
  recovered every interruption and never strayed 0.4 m from the track;
* ``interruptions``, ``recovered``, ``recovery_rate`` — interruptions met, and those after which the
  robot was on the next tile's track (|offset| < 0.1 m half a metre into it);
* ``cross_track_rmse_m``, ``cross_track_max_m`` — the axle midpoint's distance to the track's
  centre line, sampled every control tick on painted tiles while following (pooled over courses);
* ``mean_speed_m_s`` — mean over completed courses of course length / time to stop;
* ``t_stop_error_m`` (mean), ``t_stop_error_max_m`` — distance of the stopped axle midpoint from
  the T mark's centre;
* ``sim_speed_x_realtime`` — simulated seconds per wall-clock second of the closed loops (world
  construction excluded; reported separately as ``build_s``); it depends on the machine's load
  (``load_average_1min``), so ``sim_speed_x_cpu`` gives simulated seconds per CPU second of this
  process as well.

With the nodes' action code (the default) the ``follow_track`` segments are also judged against
their specification as the follow actions judge them (ended with ``interruption`` or ``end``, no
detector dropout): ``follow_segments``, ``follow_spec_rate`` (share within it), ``follow_dropouts``
and ``follow_cpu_ms_per_frame`` (the follow action's cost per frame: detector, end-mark detector,
steering).

``--timing`` adds the per-call cost of the cameras, detectors and a physics step.

``--detectors N`` instead measures the three track detectors frame by frame against ground truth
(no closed loop): N frames from seeded courses, the robot placed on the track with a random lateral
offset (±4 cm) and heading error (±0.15 rad), rendered by the analytic camera under four
conditions (``default`` noise; ``noisy``: σ = 25 grey levels, 1 px blur, 15 % gain jitter;
``scuffed``: 3 scuffs per frame on average; ``harsh``: both), plus as many frames of squares
without track. Per detector and condition: ``hit_rate`` (frames with track where it returned a
line of confidence ≥ 0.2), ``rms_mm`` and ``outlier_rate`` (|error| > 10 mm) of the track's lateral
position at the pure-pursuit look-ahead (0.26 m) over the hits, ``false_rate`` (lines reported on
frames without track) and ``ms`` per call.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench.stdio import stdout_to_stderr
from services.mobile.lines import DETECTORS, make_detector
from services.mobile.marks import EndMarkDetector
from sim.mobile.course import CourseError, random_course
from sim.mobile.coursefile import load_course
from sim.mobile.floor import FloorMap
from sim.mobile.harness import MissionParams, RunResult, run_course
from sim.mobile.lockstep import TaskSequence
from sim.mobile.sensors import AnalyticCamera, ImageNoise, robot_camera
from sim.mobile.world import DEFAULT_DT, MobileWorld
from sim.world import World


def _summary(results: list[RunResult], build_s: float) -> dict[str, Any]:
    done = [r for r in results if r.completed]
    xt = np.concatenate([np.asarray(r.cross_track) for r in results if r.cross_track]) if results else np.zeros(0)
    stops = [r.stop_error for r in results if not math.isnan(r.stop_error)]
    n_int = sum(r.interruptions for r in results)
    n_rec = sum(r.recovered for r in results)
    t_sim = sum(r.t_sim for r in results)
    wall = sum(r.wall for r in results)
    cpu = sum(r.cpu for r in results)
    return {
        "courses": len(results),
        "completed": len(done),
        "completion_rate": len(done) / len(results) if results else math.nan,
        "interruptions": n_int,
        "recovered": n_rec,
        "recovery_rate": n_rec / n_int if n_int else math.nan,
        "cross_track_rmse_m": float(np.sqrt(np.mean(xt * xt))) if xt.size else math.nan,
        "cross_track_p99_m": float(np.percentile(xt, 99)) if xt.size else math.nan,
        "cross_track_max_m": float(xt.max()) if xt.size else math.nan,
        "mean_speed_m_s": float(np.mean([r.mean_speed for r in done])) if done else math.nan,
        "t_stop_error_m": float(np.mean(stops)) if stops else math.nan,
        "t_stop_error_max_m": float(np.max(stops)) if stops else math.nan,
        "sim_speed_x_realtime": t_sim / wall if wall > 0 else math.nan,
        "sim_speed_x_cpu": t_sim / cpu if cpu > 0 else math.nan,
        "sim_s": t_sim,
        "loop_wall_s": wall,
        "build_s": build_s,
        "track_m": float(sum(r.length for r in results)),
        "failures": [{"course": r.course, "reason": r.reason} for r in results if not r.completed],
    }


def _table(res: dict[str, Any]) -> str:
    lines = [f"{res['frames']} frames with track, {res['frames_without_track']} without"]
    for cond in CONDITIONS:
        for name, r in res[cond].items():
            lines.append(
                f"{cond:>8} {name:>9}: hit {r['hit_rate']:.3f}  rms {r['rms_mm']:5.2f} mm  "
                f"outliers {r['outlier_rate']:.4f}  false {r['false_rate']:.3f}  {r['ms']:.3f} ms"
            )
    return "\n".join(lines)


def _timing(detector_names: list[str]) -> dict[str, float]:
    """Per-call cost (ms) of the cameras, detectors and a physics step on a fixed course."""
    course = random_course(7, tiles=10, interruptions=1)
    out: dict[str, float] = {}
    with World(dt=DEFAULT_DT, solver_iterations=10) as world:
        mw = MobileWorld(world, course, textured=True)
        cam = mw.camera_model()
        analytic, tiny = mw.analytic_camera(cam), mw.tiny_camera(cam)
        poses = [course.pose_at(s) for s in np.linspace(0.2, course.length - 0.5, 60)]

        def per_call(fn: Any, args: list[Any], repeat: int = 1) -> float:
            t0 = time.perf_counter()
            for _ in range(repeat):
                for a in args:
                    fn(a)
            return (time.perf_counter() - t0) / (repeat * len(args)) * 1e3

        out["analytic_frame_ms"] = per_call(analytic.render, poses, 5)
        out["tiny_frame_ms"] = per_call(tiny.render, poses)
        big = mw.camera_model(width=160, height=120, metres_per_px=0.002)
        out["tiny_frame_160x120_ms"] = per_call(mw.tiny_camera(big).render, poses)
        frames = [analytic.render(p) for p in poses]
        for name in detector_names:
            out[f"{name}_ms"] = per_call(make_detector(name, cam).detect, frames, 5)
        out["end_mark_ms"] = per_call(EndMarkDetector(camera=cam).detect, frames, 5)
        out["physics_step_ms"] = per_call(lambda _: world.step(), list(range(500)))
        mw.close()
    return out


CONDITIONS = {
    "default": ImageNoise(),
    "noisy": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15),
    "scuffed": ImageNoise(spots=3.0),
    "harsh": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15, spots=3.0),
}


def _detector_bench(frames: int, seed: int, look_ahead: float = 0.26) -> dict[str, Any]:
    """Frame-level reliability of the track detectors (see the module docstring)."""
    rng = np.random.default_rng(seed)
    cam = robot_camera()
    samples: list[tuple[Any, tuple[float, float, float], float | None]] = []  # (floor map, pose, truth)
    k = 0
    while len(samples) < 2 * frames:
        course = random_course(seed * 1_000_003 + k, interruptions=3)
        k += 1
        fmap = FloorMap(course)
        for _ in range(40):
            s0 = float(rng.uniform(0.3, course.length - 1.5))
            x, y, th = course.pose_at(s0)
            off, dth = float(rng.uniform(-0.04, 0.04)), float(rng.uniform(-0.15, 0.15))
            pose = (x - math.sin(th) * off, y + math.cos(th) * off, th + dth)
            c, sn = math.cos(pose[2]), math.sin(pose[2])
            views = [(pose[0] + c * d, pose[1] + sn * d) for d in np.linspace(0.05, 0.35, 7)]
            tiles = [course.tile_at(*v) for v in views]
            if any(t is None or t.shape == "E" for t in tiles):
                continue
            if all(t.blank for t in tiles):  # type: ignore[union-attr]
                samples.append((fmap, pose, None))
                continue
            if any(t.blank for t in tiles):  # type: ignore[union-attr]
                continue
            gx, gy = pose[0] + c * look_ahead, pose[1] + sn * look_ahead
            tile = course.tile_at(gx, gy)
            assert tile is not None
            _, d = course.project(tile, gx, gy)
            # the point look_ahead ahead is d left of the track: the track is -d/cos(angle) to its side
            _, _, th_t = course.pose_at(course.locate(gx, gy)[1])  # type: ignore[index]
            truth = -d / max(0.5, math.cos(pose[2] - th_t))
            samples.append((fmap, pose, truth))
    with_track = [smp for smp in samples if smp[2] is not None][:frames]
    without = [smp for smp in samples if smp[2] is None]
    # squares without track: a blank square is uniform; add plain squares beside the course
    while len(without) < frames:
        fmap, pose, _ = with_track[len(without) % len(with_track)]
        without.append((fmap, (pose[0] + 0.9, pose[1] + 0.9, pose[2]), None))
    without = without[:frames]
    out: dict[str, Any] = {"frames": len(with_track), "frames_without_track": len(without)}
    for cond, noise in CONDITIONS.items():
        cams: dict[int, AnalyticCamera] = {}

        def render(
            fmap: FloorMap, pose: tuple[float, float, float], cams: dict[int, AnalyticCamera] = cams,
            noise: ImageNoise = noise,
        ) -> np.ndarray:
            key = id(fmap)
            if key not in cams:
                cams[key] = AnalyticCamera(cam, fmap, noise=noise, seed=seed + len(cams))
            return cams[key].render(pose)

        imgs = [render(f, p) for f, p, _ in with_track]
        blanks = [render(f, p) for f, p, _ in without]
        truths = np.array([t for _, _, t in with_track])
        res: dict[str, Any] = {}
        for name in sorted(DETECTORS):
            det = make_detector(name, cam)
            t0 = time.perf_counter()
            lines = [det.detect(im) for im in imgs]
            ms = (time.perf_counter() - t0) / len(imgs) * 1e3
            hit = np.array([ln is not None and ln.confidence >= 0.2 for ln in lines])
            err = np.array([ln.lateral_at(look_ahead) - tr for ln, tr, h in zip(lines, truths, hit) if h and ln])
            false = sum(1 for im in blanks if (ln := det.detect(im)) is not None and ln.confidence >= 0.2)
            res[name] = {
                "hit_rate": float(hit.mean()),
                "rms_mm": float(np.sqrt(np.mean(err**2)) * 1e3) if err.size else math.nan,
                "outlier_rate": float(np.mean(np.abs(err) > 0.010)) if err.size else math.nan,
                "false_rate": false / len(blanks),
                "ms": ms,
            }
        out[cond] = res
    return out


def main(argv: list[str] | None = None) -> int:
    args_in = sys.argv[1:] if argv is None else argv
    if "--learn" in args_in:  # learning the follow_track detector: bench/mobile_learning.py
        from bench.mobile_learning import main as learn_main

        return learn_main(args_in)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--courses", type=int, default=100, help="number of random courses")
    ap.add_argument("--seed", type=int, default=1, help="seed of the course generator and the noise")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--detector", choices=sorted(DETECTORS), default="ransac")
    ap.add_argument("--camera", choices=["analytic", "tiny"], default="analytic")
    ap.add_argument("--cruise", type=float, default=0.8, help="following speed, m/s")
    ap.add_argument("--look-ahead", type=float, default=0.26, help="pure-pursuit goal distance, m")
    ap.add_argument("--course", help="run this course file (once) instead of random courses")
    ap.add_argument("--timing", action="store_true", help="also time cameras, detectors and physics")
    ap.add_argument("--detectors", type=int, metavar="N", help="frame-level detector benchmark on N frames instead")
    ap.add_argument("--noise", choices=sorted(CONDITIONS), default="default", help="image condition of the runs")
    ap.add_argument("--latency", type=float, default=0.0, help="frame-to-drive set-point delay, s")
    ap.add_argument("--mission", choices=["nodes", "phase1"], default="nodes",
                    help="nodes (default): the nodes' primitive actions (services.mobile.tasks) sequenced as "
                         "the net does; phase1: the in-process MobileMission of phase 1")
    args = ap.parse_args(argv)
    if args.detectors:
        res = _detector_bench(args.detectors, args.seed)
        print(json.dumps(res, indent=1) if args.json else _table(res))
        return 0
    if args.courses < 1 and not args.course:
        ap.error("--courses must be at least 1")
    if args.latency < 0:
        ap.error("--latency must not be negative")
    if not 0.08 <= args.look_ahead <= 0.32:
        ap.error("--look-ahead must lie in the camera's view, 0.08-0.32 m")
    params = MissionParams(detector=args.detector, cruise=args.cruise, look_ahead=args.look_ahead)
    results: list[RunResult] = []
    build = 0.0
    if args.course:
        try:
            courses = [load_course(args.course)]
        except CourseError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        courses = [random_course(args.seed * 1_000_003 + k) for k in range(args.courses)]
    t_all = time.perf_counter()
    sequences: list[TaskSequence] = []

    def task_sequence(*a: Any, **kw: Any) -> TaskSequence:
        sequences.append(TaskSequence(*a, **kw))
        return sequences[-1]

    for k, course in enumerate(courses):
        with stdout_to_stderr():
            r = run_course(
                course, params=params, mission_factory=None if args.mission == "phase1" else task_sequence, camera=args.camera, noise=CONDITIONS[args.noise],
                seed=args.seed * 7919 + k, latency=args.latency,
            )
        results.append(r)
        if not args.json:
            status = "ok  " if r.completed else "FAIL"
            print(
                f"{status} {course.name:>18} {' '.join(course.codes()):<46} "
                f"int {r.recovered}/{r.interruptions} rms {r.cross_track_rms * 1e3:4.1f} mm "
                f"max {r.cross_track_max * 1e3:4.1f} mm stop {r.stop_error * 100:4.1f} cm "
                f"v {r.mean_speed:4.2f} m/s  {r.reason}",
                flush=True,
            )
    build = time.perf_counter() - t_all - sum(r.wall for r in results)
    out = _summary(results, build)
    out.update({
        "load_average_1min": os.getloadavg()[0],  # the machine's load: wall-clock speed depends on it
        "seed": args.seed, "detector": args.detector, "camera": args.camera, "noise": args.noise,
        "cruise_m_s": args.cruise, "latency_s": args.latency, "look_ahead_m": args.look_ahead,
        "mission": args.mission,
    })
    follows = [x for seq in sequences for x in seq.records if x.task == "follow_track" and x.outcome]
    if follows:
        frames = sum(x.frames for x in follows)
        out["follow_segments"] = len(follows)
        out["follow_spec_rate"] = sum(x.success for x in follows) / len(follows)
        out["follow_dropouts"] = sum(x.dropouts for x in follows)
        out["follow_cpu_ms_per_frame"] = 1000.0 * sum(x.cpu_s for x in follows) / frames if frames else math.nan
    if args.timing:
        with stdout_to_stderr():
            out["timing_ms"] = _timing(sorted(DETECTORS))
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for key, value in out.items():
            if key != "failures":
                print(f"{key:>22}: {value:.4g}" if isinstance(value, float) else f"{key:>22}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
