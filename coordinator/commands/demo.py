"""``petrobot demo``: the project's main job on one machine, in one command.

``petrobot demo`` (``catching``) recreates the paper's visual servoing and catching testbed
(section 6, Fig. 1) on localhost: the simulated world (``petrobot sim catching``: table, thrower,
ball, PUMA 560 with its cup, overhead camera, CAN bus), the vision and motion nodes placed by
services.toml, and the coordinator running ``nets/catch.toml`` with the token flow visible. It
prints, per run, the outcome, the prediction error at the catch line (against the simulator's
ground truth), the time of each primitive task and the reason of every error. ``petrobot demo
ros2`` runs ``nets/ros2.toml``, whose primitive actions are ROS 2 interfaces reached over Zenoh, and
``petrobot demo foundation`` the small two-node net ``nets/demo.toml``.

Reproducibility: ``--seed S`` seeds the thrower, the camera noise, the engine's random switches and
the learners. Without ``--journal`` every demo starts from a fresh journal (``runs/catching.sqlite``;
the previous one is kept under the time it was last written, ``runs/catching.YYYYmmdd-HHMMSS.sqlite``,
once the new run starts), hence with fresh learners, so the same seed gives the same throws, the
same warm-up of the learners, and choices and learner states that follow from the seed and the
outcomes alone; with ``--journal FILE`` the learners continue from the state saved there. The
simulator runs in real time in its own process, so timings differ from one demo to the next, and
now and then an outcome (which frames an action sees depends on the machine's load). The world's
ground truth (throws, crossings, results) is written to ``logs/sim.events.jsonl``.

The node logs and the simulator's log go beside the journal, in ``logs/`` (``runs/logs/vision.log``,
``motion.log``, ``sim.log``), said on screen. What every demo does to start and run is
:func:`coordinator.commands.demo_start.run_demo`; each demo and its report are
:mod:`coordinator.commands.demo_catching`, :mod:`coordinator.commands.demo_mobile` and
:mod:`coordinator.commands.demo_ros2`.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

ROOT = Path(__file__).resolve().parents[2]

__all__ = ["add_parser", "run"]


DESCRIPTION = """\
Run a demonstration on this machine: start the simulated world and the nodes of services.toml
as local processes, execute the task net with the token flow visible, print a report, stop
everything.

  catching     (default) the paper's Fig. 1: a PUMA 560 catches ping-pong balls rolled across a
               table, guided by an overhead camera. Vision node: locate (three alternative
               primitive actions, chosen by a learning automaton) and predict, which streams
               catching set points to the motion node over TCP; motion node: catch and move home
               over the CAN drives. A 4-run experiment by default (--runs). While it runs, type
               "+ runs_remaining", "- runs_remaining", "pause", "step", "resume" or "abort".
  mobile       the paper's Figs. 2-3: a differential-drive robot follows a track on a chessboard
               floor, crosses interruptions guided by a beacon and stops on the T mark
               (nets/courses/fig2.toml by default, --course). Perception node: follow the track
               (three alternative detectors, chosen by the learner), find and approach the beacon,
               reacquire the track, stop at the T, streaming steering set points to the drive node,
               which drives the wheels over the CAN bus and stops them if the set points stop.
               Prints a report (completion, time, speed, cross-track error, interruptions, stop
               error, per-task statistics) and writes a top view of the driven path.
  ros2         nets/ros2.toml: primitive actions that are ROS 2 interfaces, reached over Zenoh
               (docs/ros2.md). Starts a Zenoh router and a stand-in ROS 2 robot (zenoh-ros2-sdk)
               serving the tutorials' AddTwoInts service and Fibonacci action and a /crossfire
               Bool topic; node rosbot plans with the service, counts with the action (feedback
               shown) and waits for a ball in the crossfire (an external event from the topic).
  foundation   nets/demo.toml: sense on node alpha, compute on alpha or beta, three runs.

Every firing, action start and result goes to the journal. Without --journal each demo starts a
fresh one (runs/catching.sqlite, runs/mobile.sqlite, runs/ros2.sqlite or runs/demo.sqlite), so the
learners start afresh and --seed S repeats the throws, the learners' warm-up and every random
draw, so that the choices follow from the seed and the outcomes alone (the simulator runs in real
time, so timings differ, and now and then an outcome); the previous journal is kept, never
overwritten, under the time it was last written (runs/catching.YYYYmmdd-HHMMSS.sqlite), once the
new run starts, and the demo says where. A
demo that cannot start leaves every journal as it was and names the cause and the log to read.
With --journal FILE the learners continue from FILE's saved state. The nodes' and the simulator's
logs go to logs/ beside the journal (runs/logs/NODE.log, runs/logs/sim.log; for ros2 zenoh.log and
ros2.log), the world's ground truth (throws, crossings, results) to runs/logs/sim.events.jsonl."""


def add_parser(subparsers: Any) -> None:
    """Register ``demo`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("demo", help="run a demonstration on localhost (sim + nodes + coordinator)",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("which", nargs="?", default="catching", choices=["catching", "mobile", "ros2", "foundation"],
                   help="which demonstration (default: %(default)s)")
    p.add_argument("--runs", type=int, default=None,
                   help="tokens in runs_remaining at the start (default: the net's own, 4 for catching)")
    options.add_services(p, default=str(ROOT / "services.toml"), help="location file (default: the project's)")
    options.add_journal(p, help="SQLite journal whose learner state the demo continues (default: a fresh "
                                "runs/catching.sqlite, runs/mobile.sqlite, runs/ros2.sqlite or runs/demo.sqlite, the previous one "
                                "kept as *.YYYYmmdd-HHMMSS.sqlite)")
    options.add_seed(p, help="seed of the thrower, random switches and learners")
    p.add_argument("--renderer", choices=["tiny", "analytic"], default="tiny",
                   help="camera back end: pybullet's TinyRenderer (default) or the fast analytic one")
    p.add_argument("--course", default=None,
                   help="mobile: course file (default nets/courses/fig2.toml)")
    p.add_argument("--net", default=None, help="mobile, ros2: task net (default nets/mobile.toml, nets/ros2.toml)")
    p.add_argument("--noise", choices=["default", "noisy", "scuffed", "harsh", "clean"], default="default",
                   help="mobile: image condition of the downward camera (default: default)")
    p.add_argument("--truth-every", type=float, default=0.1, metavar="S",
                   help="mobile: period of the world's ground-truth pose lines, s of simulated time (default 0.1)")
    options.add_key_file(p)
    options.add_max_seconds(p, default=300.0)
    options.add_view(p)
    p.set_defaults(func=run)


async def _foundation(args: argparse.Namespace) -> int:
    from coordinator.commands.demo_start import run_demo
    from coordinator.netfile import load_net

    net_path = ROOT / "nets" / "demo.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    done = await run_demo(args, net, net_path, journal="runs/demo.sqlite")
    print(done.summary.format())
    print(f"journal: {done.journal}; logs: {done.logs}/")
    return done.summary.exit_code


def _terminate(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt  # SIGTERM stops the demo as Ctrl-C does: the sim and the nodes with it


def run(args: argparse.Namespace) -> int:
    """Run the chosen demonstration; the exit code of the run's end state (0 completed), 2 on an error."""
    import asyncio
    import signal

    from coordinator.commands.demo_catching import run_catching
    from coordinator.commands.demo_mobile import run_mobile
    from coordinator.commands.demo_ros2 import run_ros2

    demo = {"catching": run_catching, "mobile": run_mobile, "ros2": run_ros2}.get(args.which, _foundation)
    signal.signal(signal.SIGTERM, _terminate)
    try:
        return asyncio.run(demo(args))
    except PetrobotError as exc:
        print(f"petrobot demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            print("petrobot demo: interrupted", file=sys.stderr)
        return 130
