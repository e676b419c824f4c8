"""``petrobot demo ros2``: a task net whose primitive actions are ROS 2 interfaces, reached over Zenoh.

Starts on this machine what a ROS 2 lab would have: a Zenoh router (``petrobot sim zenoh``, as
rmw_zenohd) and a stand-in ROS 2 robot speaking rmw_zenoh (``petrobot sim ros2``, built on
zenoh-ros2-sdk: the AddTwoInts service, the Fibonacci action, the /crossfire topic); then the node
that services.toml gives these actions (``rosbot``), and runs ``nets/ros2.toml`` with the token
flow visible: each run plans with /add_two_ints, counts with /fibonacci (its feedback counted) and
waits for a ball in the crossfire (the external event ``crossfire``, the rising edge of /crossfire).
It prints one line per run and what the robot saw; the robot's and the router's logs go to
``runs/logs/ros2.log`` and ``zenoh.log``. docs/ros2.md says how the same net reaches a real ROS 2
machine.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coordinator.events import ActionEnded, ActionFeedback, Observer, RunEvent, TransitionFired
from services.errors import PetrobotError

__all__ = ["Ros2Report", "run_ros2"]

ROOT = Path(__file__).resolve().parents[2]


@dataclass
class _Run:
    n: int
    started: float
    outcome: str = "running"
    sum: Any = None
    sequence: list[int] = field(default_factory=list)
    feedback: int = 0
    counted: float | None = None
    crossed: float | None = None
    notes: list[str] = field(default_factory=list)


class Ros2Report:
    """Groups the run's events into runs of ``nets/ros2.toml`` and passes each on to ``forward``."""

    def __init__(self, forward: Observer) -> None:
        self.forward = forward
        self.runs: list[_Run] = []

    def __call__(self, event: RunEvent) -> None:
        run = self.runs[-1] if self.runs else None
        if isinstance(event, TransitionFired):
            tid = event.firing.transition
            if tid == "start_run":
                self.runs.append(_Run(len(self.runs) + 1, event.t_wall))
            elif run is not None and tid == "counted":
                run.counted = event.t_wall
            elif run is not None and tid == "ball_crossed":
                run.crossed, run.outcome = event.t_wall, "crossed"
            elif run is not None and tid == "recovered":
                run.outcome = "recovered"
        elif isinstance(event, ActionFeedback) and run is not None:
            run.feedback += 1
        elif isinstance(event, ActionEnded) and run is not None:
            result = event.result
            value = result.value if isinstance(result.value, dict) else {}
            if event.action == "add_two_ints":
                run.sum = value.get("sum")
            elif event.action == "fibonacci" and isinstance(value.get("result"), dict):
                run.sequence = list(value["result"].get("sequence", []))
            if result.status.value != "success":
                run.notes.append(f"{event.action}: {result.status.value}: {result.reason or 'no reason given'}")
        self.forward(event)

    def format(self) -> str:
        """One line per run: the sum, the sequence, the feedback messages, the wait for the ball."""
        lines = ["run  outcome     sum  fibonacci                         feedback  ball after"]
        for r in self.runs:
            seq = ", ".join(map(str, r.sequence[-4:]))
            seq = f"[..., {seq}] ({len(r.sequence)})" if len(r.sequence) > 4 else f"[{seq}]"
            wait = f"{r.crossed - r.counted:.2f}s" if r.crossed is not None and r.counted is not None else "-"
            lines.append(f"{r.n:3}  {r.outcome:10}  {r.sum if r.sum is not None else '-':>3}  {seq:32}  "
                         f"{r.feedback:8}  {wait:>10}")
            lines.extend(f"       {note}" for note in r.notes)
        return "\n".join(lines)


async def run_ros2(args: argparse.Namespace) -> int:
    """The ROS 2 demo (see the module docstring); returns the run's exit code."""
    import asyncio

    from coordinator.commands.simworld import SimWorld, journal_for
    from coordinator.console import Console
    from coordinator.journal import Journal
    from coordinator.netfile import load_net
    from coordinator.nodegroup import NodeGroup
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location

    net_path = Path(args.net) if args.net else ROOT / "nets" / "ros2.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    location = load_location(args.services)
    key = load_key(args.key_file)
    nodes = sorted({location.node_of(a.name) for t in net.tasks.values() for a in t.actions}
                   | {location.publisher_of(e[4:]) for t in net.transitions for e in t.external_events})
    routers = sorted({c for n in nodes for c in location.nodes[n].ros2.connect})
    if len(routers) != 1 or not routers[0].startswith("tcp/127.0.0.1:"):
        raise PetrobotError(f"the ROS 2 demo serves one Zenoh router on this machine; the nodes {', '.join(nodes)} "
                            f"connect to {', '.join(routers) or 'none'} (expected one tcp/127.0.0.1:PORT)")
    router = routers[0]
    journal_path = journal_for(args.journal, "runs/ros2.sqlite")
    logs = journal_path.parent / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        print(f"demo: {text}", file=sys.stderr, flush=True)

    say(f"journal {journal_path}; logs in {logs}/ (zenoh.log, ros2.log, {', '.join(f'{n}.log' for n in nodes)})")
    say(f"starting a Zenoh router on {router} and the stand-in ROS 2 robot (zenoh-ros2-sdk)")
    zenoh = SimWorld(["--listen", router], log=logs / "zenoh.log", world="zenoh")
    robot: SimWorld | None = None
    try:
        await asyncio.to_thread(zenoh.wait_ready, 30.0)
        robot = SimWorld(["--router", router, "--crossfire-period", "1.5", "--crossfire-pulse", "0.3"],
                         log=logs / "ros2.log", world="ros2")
        await asyncio.to_thread(robot.wait_ready, 60.0)
        say(f"starting nodes {', '.join(nodes)}")
        async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="INFO", log_dir=logs):
            console = Console(net, live=args.live)
            report = Ros2Report(console)
            with Journal(journal_path) as journal:
                say(f"running {net_path.relative_to(ROOT) if net_path.is_relative_to(ROOT) else net_path}: "
                    f"{net.initial_marking.get('runs_remaining', 0)} runs")
                summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                        net_text=net_path.read_text(encoding="utf-8"), observer=report,
                                        read_input=sys.stdin.isatty(), max_seconds=args.max_seconds,
                                        console=console)
    finally:
        if robot is not None:
            robot.stop()
        zenoh.stop()
    print(summary.format())
    print(report.format())
    seen = robot.events if robot is not None else []
    goals = [e for e in seen if e.get("event") == "goal"]
    results = [e for e in seen if e.get("event") == "result"]
    calls = [e for e in seen if e.get("event") == "service"]
    balls = [e for e in seen if e.get("event") == "crossfire" and e.get("data")]
    print(f"the robot saw {len(calls)} service call(s), {len(goals)} goal(s) "
          f"({sum(1 for g in goals if g.get('accepted'))} accepted), ended {len(results)} "
          f"({', '.join(sorted({r['status'] for r in results})) or 'none'}), and {len(balls)} ball(s) in its crossfire")
    print(f"journal: {journal_path}; logs: {logs}/")
    return summary.exit_code
