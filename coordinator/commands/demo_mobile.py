"""``petrobot demo mobile``: the mobile-robot testbed on one machine (paper section 6, Figs. 2-3).

Starts the world (``petrobot sim mobile``: the course, the robot, the downward camera with the
beacon sensor, the wheel drives on the CAN bus), the nodes services.toml places the net's actions
on (``perception``, ``drive``), and runs the course's task net (``nets/mobile.toml``, or ``--net``)
with the live token flow (:func:`coordinator.commands.demo_start.run_demo`); then prints the report
and writes a top-view PNG of the course with the driven path beside the journal, and the world's
JSON event lines (ground truth: ``pose`` every 0.1 s of simulated time, each stamped with the wall
clock it was read at, ``t_wall``) as ``*.truth.jsonl``.

The report scores the world's ground truth against the course geometry
(:mod:`sim.mobile.report`: ``render_report``, ``write_top_view``), with the run's primitive-action
ends that :class:`MobileRunLog` keeps: completion, time, mean speed, cross-track error per kind of
square, each interruption and how it was recovered, the stop relative to the T mark.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from coordinator.commands.demo_start import ROOT, DemoWorld, run_demo, say, world_lines
from coordinator.events import ActionEnded, Observer, RunEvent, TransitionFired
from services.errors import PetrobotError

__all__ = ["MobileRunLog", "run_mobile"]


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


async def run_mobile(args: argparse.Namespace) -> int:
    """The mobile demo (see the module docstring); returns the run's exit code."""
    from coordinator.netfile import load_net
    from sim.mobile import report as course_report
    from sim.mobile.coursefile import load_course

    net_path = Path(args.net) if args.net else ROOT / "nets" / "mobile.toml"
    if not net_path.exists():
        raise PetrobotError(f"{net_path}: no such net file (give one with --net)")
    net = load_net(net_path)
    if args.runs is not None and "runs_remaining" in net.initial_marking:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    course_path = args.course or str(ROOT / "nets" / "courses" / "fig2.toml")
    course = load_course(course_path)
    say(f"course {course.name} ({course.length:.1f} m), renderer {args.renderer}")
    done = await run_demo(
        args, net, net_path, journal="runs/mobile.sqlite", report=MobileRunLog, settle_s=0.5,
        worlds=[DemoWorld("mobile", ["--realtime", "--seed", str(args.seed), "--renderer", args.renderer,
                                     "--noise", args.noise, "--course", course_path,
                                     "--pose-every", str(args.truth_every)])])
    log = done.report
    assert log is not None
    poses = [e for e in done.world if e.get("event") == "pose"]
    truth = done.journal.with_suffix(".truth.jsonl")
    truth.write_text("".join(json.dumps(e) + "\n" for e in done.world), encoding="utf-8")
    print(done.summary.format())
    png = done.journal.with_suffix(".png")
    path = [(float(p["t"]), float(p["x"]), float(p["y"]), float(p["heading"])) for p in poses]
    print(course_report.render_report(course, path, log.actions, _stop_pose(poses)))
    course_report.write_top_view(course, path, str(png))
    for line in world_lines(done.world, drives="wheel drive"):
        print(line)
    print(f"journal: {done.journal}; logs: {done.logs}/; ground truth: {truth}"
          + (f"; top view: {png}" if png.exists() else ""))
    from coordinator.commands.learn import print_learned

    print_learned(done.journal, net_path, "mobile")
    return done.summary.exit_code
