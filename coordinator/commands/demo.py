"""``petrobot demo``: the project's main job on one machine, in one command.

``petrobot demo`` (``catching``) recreates the paper's visual servoing and catching testbed
(section 6, Fig. 1) on localhost: the simulated world (``petrobot sim catching``: table, thrower,
ball, PUMA 560 with its cup, overhead camera, CAN bus), the vision and motion nodes placed by
services.toml, and the coordinator running ``nets/catch.toml`` with the token flow visible. It
prints, per run, the outcome, the prediction error at the catch line (against the simulator's
ground truth), the time of each primitive task and the reason of every error. ``petrobot demo
foundation`` runs the small two-node net ``nets/demo.toml`` instead.

Reproducibility: ``--seed S`` seeds the thrower, the camera noise, the engine's random switches and
the learners. Without ``--journal`` every demo starts from a fresh journal (``runs/catching.sqlite``;
the previous one is kept as ``runs/catching.prev.sqlite``), hence with fresh learners, so the same
seed gives the same runs; with ``--journal FILE`` the learners continue from the state saved there.
The simulator runs in real time across processes, so timings differ from one demo to the next.

The node logs and the simulator's log go beside the journal, in ``logs/`` (``runs/logs/vision.log``,
``motion.log``, ``sim.log``), said on screen.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["SimWorld", "add_parser", "journal_for", "run"]

ROOT = Path(__file__).resolve().parents[2]

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
  foundation   nets/demo.toml: sense on node alpha, compute on alpha or beta, three runs.

Every firing, action start and result goes to the journal. Without --journal each demo starts a
fresh one (runs/catching.sqlite or runs/demo.sqlite; the previous one is kept as *.prev.sqlite), so
the learners start afresh and --seed S reproduces a demo's outcomes and choices (the simulator runs
in real time, so timings differ). With --journal FILE the learners continue from FILE's saved state.
The nodes' and the simulator's logs go to logs/ beside the journal (runs/logs/NODE.log)."""


def add_parser(subparsers: Any) -> None:
    """Register ``demo`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("demo", help="run a demonstration on localhost (sim + nodes + coordinator)",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("which", nargs="?", default="catching", choices=["catching", "mobile", "foundation"],
                   help="which demonstration (default: %(default)s)")
    p.add_argument("--runs", type=int, default=None,
                   help="tokens in runs_remaining at the start (default: the net's own, 4 for catching)")
    options.add_services(p, default=str(ROOT / "services.toml"), help="location file (default: the project's)")
    options.add_journal(p, help="SQLite journal whose learner state the demo continues (default: a fresh "
                                "runs/catching.sqlite or runs/demo.sqlite, the previous one kept as *.prev.sqlite)")
    options.add_seed(p, help="seed of the thrower, random switches and learners")
    p.add_argument("--renderer", choices=["tiny", "analytic"], default="tiny",
                   help="camera back end: pybullet's TinyRenderer (default) or the fast analytic one")
    p.add_argument("--course", default=None,
                   help="mobile: course file (default nets/courses/fig2.toml)")
    p.add_argument("--net", default=None, help="mobile: task net (default nets/mobile.toml)")
    p.add_argument("--noise", choices=["default", "noisy", "scuffed", "harsh", "clean"], default="default",
                   help="mobile: image condition of the downward camera (default: default)")
    p.add_argument("--truth-every", type=float, default=0.1, metavar="S",
                   help="mobile: period of the world's ground-truth pose lines, s of simulated time (default 0.1)")
    options.add_key_file(p)
    options.add_max_seconds(p, default=300.0)
    options.add_view(p)
    p.set_defaults(func=run)


from coordinator.commands.demo_start import SimWorld, journal_for


# --------------------------------------------------------------------------------------- demos
async def _catching(args: argparse.Namespace) -> int:
    import asyncio

    from coordinator.commands.demo_catching import CatchReport
    from coordinator.console import Console
    from coordinator.journal import Journal
    from coordinator.netfile import load_net
    from coordinator.nodegroup import NodeGroup
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location

    net_path = ROOT / "nets" / "catch.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    location = load_location(args.services)
    key = load_key(args.key_file)
    nodes = sorted({location.node_of(a.name) for t in net.tasks.values() for a in t.actions}
                   | {location.publisher_of(e[4:]) for t in net.transitions for e in t.external_events})
    camera = location.drivers_on(location.node_of("locate_threshold"))
    camera_port = next((int(d.params["port"]) for d in camera if "port" in d.params), 7210)
    puma = [d for n in nodes for d in location.drivers_on(n) if "can_port" in d.params]
    can_port = int(puma[0].params["can_port"]) if puma else 7211
    journal_path = journal_for(args.journal, "runs/catching.sqlite")
    logs = journal_path.parent / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        print(f"demo: {text}", file=sys.stderr, flush=True)

    say(f"seed {args.seed}; journal {journal_path}"
        + (" (learners continue from it)" if args.journal else " (fresh: new learners)")
        + f"; logs in {logs}/ (sim.log, {', '.join(f'{n}.log' for n in nodes)})")
    say(f"starting the simulated world (renderer {args.renderer}, camera :{camera_port}, CAN :{can_port})")
    sim = SimWorld(["--realtime", "--seed", str(args.seed), "--renderer", args.renderer, "--throws", "0",
                    "--interval", "0", "--throw-when-home", "1.0", "--first-throw", "4", "--after-camera-client",
                    "--camera-port", str(camera_port), "--can-port", str(can_port)], log=logs / "sim.log")
    try:
        await asyncio.to_thread(sim.wait_ready, 90.0)
        say(f"starting nodes {', '.join(nodes)}")
        async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="INFO", log_dir=logs):
            console = Console(net, live=args.live)
            report = CatchReport(console)
            with Journal(journal_path) as journal:
                say(f"running {net_path.relative_to(ROOT)}: {net.initial_marking['runs_remaining']} runs")
                summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                        net_text=net_path.read_text(encoding="utf-8"), observer=report,
                                        read_input=sys.stdin.isatty(), max_seconds=args.max_seconds,
                                        console=console)
    finally:
        sim.stop()
    report.match_truth([e for e in sim.events if e.get("event") == "crossing"])
    print(summary.format())
    print(report.format())
    for fault in (e for e in sim.events if e.get("event") == "drive_fault"):
        print(f"  drive {fault['node']} faulted at t={fault['t']:.3f} s: {fault['reason']}; "
              f"stopped in {fault['stop_s']:.3f} s")
    for st in (e for e in sim.events if e.get("event") == "stopped"):
        print(f"simulator: {st['t']:.1f} s simulated in {st['wall_s']:.1f} s ({st['slipped_s']:.1f} s slipped); "
              f"waits for the camera client {st['camera_misses']}/{st['camera_waits']} and for the CAN master "
              f"{st['master_misses']}/{st['master_waits']} ran out; {st['drive_faults']} drive fault(s)")
    print(f"journal: {journal_path}; logs: {logs}/")
    return summary.exit_code


async def _foundation(args: argparse.Namespace) -> int:
    from coordinator.journal import Journal
    from coordinator.netfile import load_net
    from coordinator.nodegroup import NodeGroup
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location

    net_path = ROOT / "nets" / "demo.toml"
    net = load_net(net_path)
    if args.runs is not None:
        net = net.with_initial_marking({**net.initial_marking, "runs_remaining": args.runs})
    location = load_location(args.services)
    key = load_key(args.key_file)
    nodes = sorted({location.node_of(a.name) for t in net.tasks.values() for a in t.actions})
    journal_path = journal_for(args.journal, "runs/demo.sqlite")
    logs = journal_path.parent / "logs"
    print(f"demo: starting nodes {', '.join(nodes)} on this machine (logs in {logs}/)", file=sys.stderr, flush=True)
    async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="INFO", log_dir=logs):
        with Journal(journal_path) as journal:
            summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                    net_text=net_path.read_text(encoding="utf-8"), live=args.live,
                                    read_input=sys.stdin.isatty(), max_seconds=args.max_seconds)
    print(summary.format())
    print(f"journal: {journal_path}")
    return summary.exit_code


def _terminate(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt  # SIGTERM stops the demo as Ctrl-C does: the sim and the nodes with it


def run(args: argparse.Namespace) -> int:
    """Run the chosen demonstration; the exit code of the run's end state (0 completed), 2 on an error."""
    import asyncio
    import signal

    from coordinator.commands.demo_mobile import run_mobile

    demo = {"catching": _catching, "mobile": run_mobile}.get(args.which, _foundation)
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
