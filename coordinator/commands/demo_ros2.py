"""``petrobot demo ros2``: a task net whose primitive actions are ROS 2 interfaces, reached over Zenoh.

Starts on this machine what a ROS 2 lab would have: a Zenoh router (``petrobot sim zenoh``, as
rmw_zenohd) and a stand-in ROS 2 robot speaking rmw_zenoh (``petrobot sim ros2``, built on
zenoh-ros2-sdk: the AddTwoInts service, the Fibonacci action, the /crossfire topic); then the node
that services.toml gives these actions (``rosbot``), and runs ``nets/ros2.toml`` with the token
flow visible (:func:`coordinator.commands.demo_start.run_demo`, as every demo): each run plans with
/add_two_ints, counts with /fibonacci (its feedback counted) and waits for a ball in the crossfire
(the external event ``crossfire``, the rising edge of /crossfire). The router listens where
services.toml has the node connect, which must be this machine's loopback. It prints one line per run (:class:`Ros2Report`) and
what the robot saw; the robot's and the router's logs go to ``runs/logs/ros2.log`` and
``zenoh.log``. docs/ros2.md says how the same net reaches a real ROS 2 machine.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coordinator.commands.demo_start import ROOT, DemoWorld, nodes_of, run_demo, say
from coordinator.events import ActionEnded, ActionFeedback, Observer, RunEvent, TransitionFired
from coordinator.net import PetriNet
from services.errors import PetrobotError

__all__ = ["Ros2Report", "run_ros2"]


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


def _local_router(services: str, net: PetriNet) -> str:
    """The one Zenoh router on this machine the net's ROS 2 nodes connect to (the demo serves it).

    Raises:
        PetrobotError: they connect to none, to several, or to one off this machine's loopback.
    """
    from services.location import load_location

    location = load_location(services)
    nodes = nodes_of(net, location)
    routers = sorted({c for n in nodes for c in location.nodes[n].ros2.connect})
    if len(routers) != 1 or not routers[0].startswith("tcp/127.0.0.1:"):
        raise PetrobotError(f"the ROS 2 demo serves one Zenoh router on this machine; the nodes {', '.join(nodes)} "
                            f"connect to {', '.join(routers) or 'none'} (expected one tcp/127.0.0.1:PORT)")
    return routers[0]


async def run_ros2(args: argparse.Namespace) -> int:
    """The ROS 2 demo (see the module docstring); returns the run's exit code."""
    from coordinator.netfile import load_net

    net_path = Path(args.net) if args.net else ROOT / "nets" / "ros2.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    router = _local_router(args.services, net)
    say(f"a Zenoh router on {router} and the stand-in ROS 2 robot (zenoh-ros2-sdk) play the ROS 2 side")
    done = await run_demo(
        args, net, net_path, journal="runs/ros2.sqlite", report=Ros2Report,
        worlds=[DemoWorld("zenoh", log="zenoh.log"),
                DemoWorld("ros2", ["--crossfire-period", "1.5", "--crossfire-pulse", "0.3"], log="ros2.log")])
    report = done.report
    assert report is not None
    print(done.summary.format())
    print(report.format())
    seen = done.worlds.get("ros2", [])
    goals = [e for e in seen if e.get("event") == "goal"]
    results = [e for e in seen if e.get("event") == "result"]
    calls = [e for e in seen if e.get("event") == "service"]
    balls = [e for e in seen if e.get("event") == "crossfire" and e.get("data")]
    print(f"the robot saw {len(calls)} service call(s), {len(goals)} goal(s) "
          f"({sum(1 for g in goals if g.get('accepted'))} accepted), ended {len(results)} "
          f"({', '.join(sorted({r['status'] for r in results})) or 'none'}), and {len(balls)} ball(s) in its crossfire")
    print(f"journal: {done.journal}; logs: {done.logs}/")
    return done.summary.exit_code
