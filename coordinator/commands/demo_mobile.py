"""``petrobot demo mobile``: the mobile-robot testbed on one machine (paper section 6, Figs. 2-3).

Starts the world (``petrobot sim mobile``: the course, the robot, the downward camera with the
beacon sensor, the wheel drives on the CAN bus), the nodes services.toml places the net's actions
on (``perception``, ``drive``), and runs the course's task net (``nets/mobile.toml``, or ``--net``)
with the live token flow; then prints the report and writes a top-view PNG of the course with the
driven path beside the journal, and the world's JSON event lines (ground truth: ``pose`` every 0.1 s of
simulated time, each stamped with the wall clock it was read at, ``t_wall``) as ``*.truth.jsonl``.

The report comes from :mod:`sim.mobile.report` (``render_report``, ``write_top_view``) when that
module is present; otherwise :func:`basic_report` gives the numbers this module measures itself
from the world's ground truth (its ``pose`` lines) and the run's events: completion, time, mean
speed, cross-track error (RMS, max) per tile kind, each interruption and how it ended, the stop
relative to the T mark, and per-primitive-task statistics.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

from coordinator.events import ActionEnded, Observer, RunEvent, TransitionFired
from services.errors import PetrobotError
from services.results import Status

__all__ = ["MobileRunLog", "basic_report", "run_mobile"]

ROOT = Path(__file__).resolve().parents[2]
KINDS = {"S": "straight", "L": "arc", "R": "arc", "E": "end"}


class MobileRunLog:
    """A runtime observer keeping the action results and firings (then passing events on)."""

    def __init__(self, forward: Observer) -> None:
        self.forward = forward
        self.actions: list[ActionEnded] = []
        self.fired: list[str] = []

    def __call__(self, event: RunEvent) -> None:
        if isinstance(event, ActionEnded):
            self.actions.append(event)
        elif isinstance(event, TransitionFired):
            self.fired.append(event.firing.transition)
        self.forward(event)


def _stop_pose(poses: list[dict[str, Any]]) -> tuple[float, float, float] | None:
    if not poses:
        return None
    p = poses[-1]
    return float(p["x"]), float(p["y"]), float(p["heading"])


def basic_report(course: Any, poses: list[dict[str, Any]], log: MobileRunLog, final: dict[str, int]) -> str:
    """The demo's report from ground truth and the run's events (see the module docstring)."""
    head = (f"mobile robot on course {course.name} ({course.length:.1f} m, "
            f"{sum(t.blank for t in course.tiles)} interruptions)")
    lines = ["", head]
    completed = final.get("completed_runs", final.get("completed", 0)) > 0
    moving = [p for p in poses if (p.get("v") or 0.0) > 0.02]
    t0 = float(moving[0]["t"]) if moving else math.nan
    t1 = float(moving[-1]["t"]) if moving else math.nan
    lines.append(f"course {'completed' if completed else 'NOT completed'}; driving time {t1 - t0:.1f} s"
                 + (f", mean speed {course.length / (t1 - t0):.2f} m/s" if completed and t1 > t0 else ""))
    per: dict[str, list[float]] = defaultdict(list)
    for p in poses:
        if p.get("tile") is None or p.get("blank") or p.get("offset") is None or (p.get("v") or 0.0) < 0.05:
            continue
        per[KINDS.get(course.tiles[int(p["tile"])].shape, "other")].append(float(p["offset"]))
    for kind, offs in sorted(per.items()):
        a = [abs(o) for o in offs]
        rms = math.sqrt(sum(o * o for o in offs) / len(offs))
        lines.append(f"  cross-track on {kind} tiles: RMS {rms * 1000:.1f} mm, max {max(a) * 1000:.1f} mm "
                     f"({len(offs)} samples, ground truth every 0.1 s)")
    n_int = 0
    for k, ev in enumerate(log.actions):
        r = ev.result
        if ev.task == "follow_track" and r.outcome == "interruption":
            n_int += 1
            rest = [e for e in log.actions[k + 1:k + 4]]
            how = ", ".join(f"{e.task} {e.result.status.value}{'/' + e.result.outcome if e.result.outcome else ''}"
                            for e in rest)
            lines.append(f"  interruption {n_int}: {how or 'no recovery started'}")
    stop = _stop_pose(poses)
    if stop is not None:
        ex, ey = course.end_point()
        d = math.hypot(stop[0] - ex, stop[1] - ey)
        lines.append(f"  stopped at ({stop[0]:.3f}, {stop[1]:.3f}) m: {d * 100:.1f} cm from the T mark's centre")
    stats: dict[tuple[str, str], list[Any]] = defaultdict(list)
    for ev in log.actions:
        stats[(ev.task, ev.action)].append(ev.result)
    lines.append(f"  {'task':<16}{'action':<18}{'n':>3}{'ok':>4}{'fail':>5}{'err':>4}{'mean s':>8}{'cpu ms':>8}")
    for (task, action), rs in stats.items():
        ok = sum(r.status is Status.SUCCESS for r in rs)
        fail = sum(r.status is Status.FAILURE for r in rs)
        err = sum(r.status is Status.ERROR for r in rs)
        mean = sum(r.wall_s for r in rs) / len(rs)
        cpu = sum(r.cost or 0.0 for r in rs) * 1000.0
        lines.append(f"  {task:<16}{action:<18}{len(rs):>3}{ok:>4}{fail:>5}{err:>4}{mean:>8.2f}{cpu:>8.1f}")
    for ev in log.actions:
        if ev.result.status is Status.ERROR:
            lines.append(f"  {ev.task}/{ev.action} on {ev.node}: error: {ev.result.reason}")
    return "\n".join(lines)


async def run_mobile(args: argparse.Namespace) -> int:
    """The mobile demo (see the module docstring); returns the run's exit code."""
    import asyncio

    from coordinator.commands.demo_start import SimWorld, journal_for
    from coordinator.console import Console
    from coordinator.journal import Journal
    from coordinator.netfile import load_net
    from coordinator.nodegroup import NodeGroup
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location
    from sim.mobile.coursefile import load_course

    net_path = Path(args.net) if args.net else ROOT / "nets" / "mobile.toml"
    if not net_path.exists():
        raise PetrobotError(f"{net_path}: no such net file (give one with --net)")
    net = load_net(net_path)
    if args.runs is not None and "runs_remaining" in net.initial_marking:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    course_path = args.course or str(ROOT / "nets" / "courses" / "fig2.toml")
    course = load_course(course_path)
    location = load_location(args.services)
    key = load_key(args.key_file)
    nodes = sorted({location.node_of(a.name) for t in net.tasks.values() for a in t.actions})
    cam_port, can_port = 7220, 7221
    for n in nodes:
        for d in location.drivers_on(n):
            if d.impl.endswith(":PerceptionDriver"):
                cam_port = int(d.params.get("port", cam_port))
            if d.impl.endswith(":DriveDriver"):
                can_port = int(d.params.get("can_port", can_port))
    journal_path = journal_for(args.journal, "runs/mobile.sqlite")
    logs = journal_path.parent / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        print(f"demo: {text}", file=sys.stderr, flush=True)

    say(f"seed {args.seed}; journal {journal_path}; logs in {logs}/ (sim.log, {', '.join(f'{n}.log' for n in nodes)})")
    say(f"starting the world: course {course.name} ({course.length:.1f} m), renderer {args.renderer}, "
        f"camera :{cam_port}, CAN :{can_port}")
    sim = SimWorld(["--realtime", "--seed", str(args.seed), "--renderer", args.renderer,
                    "--noise", args.noise, "--course", course_path, "--camera-port", str(cam_port),
                    "--can-port", str(can_port), "--pose-every", str(args.truth_every)],
                   log=logs / "sim.log", world="mobile")
    try:
        await asyncio.to_thread(sim.wait_ready, 90.0)
        say(f"starting nodes {', '.join(nodes)}")
        async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="INFO", log_dir=logs):
            console = Console(net, live=args.live)
            log = MobileRunLog(console)
            with Journal(journal_path) as journal:
                say(f"running {net_path}")
                summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                        net_text=net_path.read_text(encoding="utf-8"), observer=log,
                                        read_input=sys.stdin.isatty(), max_seconds=args.max_seconds,
                                        console=console)
                await asyncio.sleep(0.5)  # the last ground-truth lines at rest
    finally:
        sim.stop()
    poses = [e for e in sim.events if e.get("event") == "pose"]
    truth = journal_path.with_suffix(".truth.jsonl")
    truth.write_text("".join(json.dumps(e) + "\n" for e in sim.events), encoding="utf-8")
    print(summary.format())
    png = journal_path.with_suffix(".png")
    report: str | None = None
    try:
        from sim.mobile import (
            report as course_report,  # the course report module, when present
        )
    except ImportError:
        course_report = None  # type: ignore[assignment]
    path = [(float(p["t"]), float(p["x"]), float(p["y"]), float(p["heading"])) for p in poses]
    if course_report is not None:
        report = course_report.render_report(course, path, log.actions, _stop_pose(poses))
        course_report.write_top_view(course, path, str(png))
    print(report if report is not None else basic_report(course, poses, log, summary.final_marking))
    for fault in (e for e in sim.events if e.get("event") == "drive_fault"):
        print(f"  wheel drive {fault['node']} faulted at t={fault['t']:.3f} s: {fault['reason']}; "
              f"stopped in {fault['stop_s']:.3f} s")
    for st in (e for e in sim.events if e.get("event") == "stopped"):
        print(f"simulator: {st['t']:.1f} s simulated in {st['wall_s']:.1f} s ({st['slipped_s']:.1f} s slipped); "
              f"waits for the camera client {st.get('camera_misses', 0)}/{st.get('camera_waits', 0)} and for the "
              f"CAN master {st.get('master_misses', 0)}/{st.get('master_waits', 0)} ran out; "
              f"{st['drive_faults']} drive fault(s)")
    print(f"journal: {journal_path}; logs: {logs}/; ground truth: {truth}"
          + (f"; top view: {png}" if png.exists() else ""))
    return summary.exit_code
