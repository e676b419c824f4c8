"""``petrobot demo``: the project's main job on one machine, in one command.

``petrobot demo`` (``catching``) recreates the paper's visual servoing and catching testbed
(section 6, Fig. 1) on localhost: the simulated world (``petrobot sim catching``: table, thrower,
ball, PUMA 560 with its cup, overhead camera, CAN bus), the vision and motion nodes placed by
services.toml, and the coordinator running ``nets/catch.toml`` with the token flow visible. It
prints, per run, the outcome, the prediction error at the catch line (against the simulator's
ground truth) and the time of each primitive task. ``petrobot demo foundation`` runs the small
two-node net ``nets/demo.toml`` instead.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["SimWorld", "add_parser", "run"]

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
  foundation   nets/demo.toml: sense on node alpha, compute on alpha or beta, three runs.

Every firing, action start and result goes to the journal (--journal)."""


def add_parser(subparsers: Any) -> None:
    """Register ``demo`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("demo", help="run a demonstration on localhost (sim + nodes + coordinator)",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("which", nargs="?", default="catching", choices=["catching", "foundation"],
                   help="which demonstration (default: %(default)s)")
    p.add_argument("--runs", type=int, default=None,
                   help="tokens in runs_remaining at the start (default: the net's own, 4 for catching)")
    options.add_services(p, default=str(ROOT / "services.toml"), help="location file (default: the project's)")
    options.add_journal(p, help="SQLite journal (default: runs/catching.sqlite or runs/demo.sqlite)")
    options.add_seed(p, help="seed of the thrower, random switches and learners")
    p.add_argument("--renderer", choices=["tiny", "analytic"], default="tiny",
                   help="camera back end: pybullet's TinyRenderer (default) or the fast analytic one")
    options.add_key_file(p)
    options.add_max_seconds(p, default=300.0)
    options.add_view(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------------------- the world
class SimWorld:
    """The ``petrobot sim catching`` process, its JSON event lines read by a thread."""

    def __init__(self, args: list[str]) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator.commands.sim", "catching", *args],
                                     cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.events: list[dict[str, Any]] = []
        self._ready = threading.Event()
        threading.Thread(target=self._read, name="sim-events", daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                try:
                    event = json.loads(line)
                except ValueError:
                    continue
                event["t_wall"] = time.time()
                self.events.append(event)
                if event.get("event") == "ready":
                    self._ready.set()

    def wait_ready(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while not self._ready.wait(0.1):
            if self.proc.poll() is not None:
                raise PetrobotError(f"the simulator exited with status {self.proc.returncode} before it was ready")
            if time.monotonic() > end:
                raise PetrobotError(f"the simulator was not ready after {timeout_s:.0f} s")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)


# --------------------------------------------------------------------------------------- demos
async def _catching(args: argparse.Namespace) -> int:
    import asyncio

    from coordinator.catching_report import CatchReport
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
    journal_path = Path(args.journal or "runs/catching.sqlite")
    journal_path.parent.mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        print(f"demo: {text}", file=sys.stderr, flush=True)

    say(f"starting the simulated world (renderer {args.renderer}, camera :{camera_port}, CAN :{can_port})")
    sim = SimWorld(["--realtime", "--seed", str(args.seed), "--renderer", args.renderer, "--throws", "0",
                    "--interval", "0", "--throw-when-home", "1.0", "--first-throw", "6",
                    "--camera-port", str(camera_port), "--can-port", str(can_port)])
    try:
        await asyncio.to_thread(sim.wait_ready, 90.0)
        say(f"starting nodes {', '.join(nodes)}")
        async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="WARNING"):
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
    print(f"journal: {journal_path}")
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
    journal_path = Path(args.journal or "runs/demo.sqlite")
    journal_path.parent.mkdir(parents=True, exist_ok=True)
    print(f"demo: starting nodes {', '.join(nodes)} on this machine", file=sys.stderr, flush=True)
    async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="WARNING"):
        with Journal(journal_path) as journal:
            summary = await execute(net, location=location, key=key, journal=journal, seed=args.seed,
                                    net_text=net_path.read_text(encoding="utf-8"), live=args.live,
                                    read_input=sys.stdin.isatty(), max_seconds=args.max_seconds)
    print(summary.format())
    print(f"journal: {journal_path}")
    return summary.exit_code


def run(args: argparse.Namespace) -> int:
    """Run the chosen demonstration; the exit code of the run's end state (0 completed), 2 on an error."""
    import asyncio

    demo = _catching if args.which == "catching" else _foundation
    try:
        return asyncio.run(demo(args))
    except PetrobotError as exc:
        print(f"petrobot demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            print("petrobot demo: interrupted", file=sys.stderr)
        return 130
