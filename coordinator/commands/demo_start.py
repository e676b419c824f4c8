"""What every ``petrobot demo`` does to start and run, once: the world, the nodes, the run, the journal.

:func:`run_demo` starts the demo's simulated worlds as child processes (``petrobot sim WORLD``,
:class:`SimWorld`: the testbed's world; for the ROS 2 demo a Zenoh router, then the stand-in robot;
none for the foundation demo), each ready before the next starts, then the nodes the net's actions
and events are placed on (:class:`coordinator.nodegroup.NodeGroup`), runs the net with the live view
(:class:`coordinator.console.Console`, seen first by the demo's own observer, its report) into the
journal, and stops everything, whatever happens. Each demo's module
(:mod:`coordinator.commands.demo_catching`, :mod:`coordinator.commands.demo_mobile`,
:mod:`coordinator.commands.demo_ros2`) gives its worlds' options and its report.

The journal (paper section 5: every firing, action start and result) is never lost: without
``--journal`` each demo starts a fresh one (``runs/catching.sqlite``...; fresh learners, so the same
seed gives the same warm-up, and choices that follow from the seed and the outcomes), and the previous one is moved aside, under the time it was last
written (``runs/catching.20261122-043316.sqlite``), only once the world and the nodes are up and the
new run is about to start: a demo that cannot start leaves every journal as it was, and names the
cause and the log to read. Nothing is ever overwritten or removed. The node logs and the world's log
go beside the journal, in ``logs/``, with the world's JSON event lines (its ground truth) in
``logs/sim.events.jsonl``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

from coordinator.console import Console
from coordinator.events import Observer
from coordinator.net import PetriNet
from coordinator.runsummary import RunSummary
from services.errors import PetrobotError

__all__ = ["DemoRun", "DemoWorld", "SimWorld", "keep_previous", "nodes_of", "run_demo", "say", "world_lines"]

ROOT = Path(__file__).resolve().parents[2]

R = TypeVar("R", bound=Observer)


def say(text: str) -> None:
    """One line of the demo's own, on stderr."""
    print(f"demo: {text}", file=sys.stderr, flush=True)


def keep_previous(path: Path) -> Path | None:
    """Move the journal at ``path`` (with its SQLite side files ``-wal``, ``-shm``) aside under a
    name of its own: ``STEM.YYYYmmdd-HHMMSS.SUFFIX`` from when it was last written (``-2``, ``-3``...
    when that name is taken). Nothing is overwritten or removed.

    Returns:
        Where it went, or ``None`` when there was no journal at ``path``.

    Raises:
        OSError: it cannot be moved (then it stays where it was).
    """
    if not path.exists():
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(path.stat().st_mtime))
    n = 1
    while True:
        kept = path.with_name(f"{path.stem}.{stamp}{'' if n == 1 else f'-{n}'}{path.suffix}")
        if not any(Path(str(kept) + side).exists() for side in ("", "-wal", "-shm")):
            break
        n += 1
    for side in ("", "-wal", "-shm"):
        old, new = Path(str(path) + side), Path(str(kept) + side)
        if old.exists():
            try:
                os.link(old, new)  # fails rather than overwrite
            except FileExistsError:
                raise
            except OSError:  # a file system without hard links: the name was free a moment ago
                os.rename(old, new)
                continue
            old.unlink()
    return kept


class SimWorld:
    """The ``petrobot sim WORLD`` process, its JSON event lines read by a thread.

    Args:
        args: command-line arguments after ``sim WORLD``.
        log: file for the simulator's stderr (log lines, warnings), or ``None`` to drop them; its
            JSON event lines (the world's ground truth: ``throw``, ``crossing``, ``result``...) go
            beside it, one per line as they came, in ``<log stem>.events.jsonl``.
        world: ``catching``, ``mobile``, ``zenoh`` or ``ros2``.
    """

    def __init__(self, args: list[str], log: Path | None = None, world: str = "catching") -> None:
        self.log = log
        self._log = open(log, "w") if log is not None else None  # noqa: SIM115 (kept open for the process, closed by stop())
        #: the file of the world's event lines, or ``None`` without a log
        self.events_log = None if log is None else log.with_name(f"{log.stem}.events.jsonl")
        self._events_log = (open(self.events_log, "w", buffering=1)  # noqa: SIM115 (closed by stop())
                            if self.events_log is not None else None)
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator.commands.sim", world, *args],
                                     cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=self._log if self._log is not None else subprocess.DEVNULL, text=True)
        self.events: list[dict[str, Any]] = []
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._read, name="sim-events", daemon=True)
        self._reader.start()

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
                if self._events_log is not None:
                    with contextlib.suppress(OSError, ValueError):  # a full disk loses the copy, not the demo
                        self._events_log.write(json.dumps(event) + "\n")
                if event.get("event") == "ready":
                    self._ready.set()

    @property
    def ready(self) -> dict[str, Any]:
        """The world's ``ready`` line (ports, mode...); empty before it came."""
        return next((e for e in self.events if e.get("event") == "ready"), {})

    def wait_ready(self, timeout_s: float) -> None:
        """Wait for the world's ``ready`` line.

        Raises:
            PetrobotError: the world exited first, or was not ready within ``timeout_s``; the
                message gives the last line of its log (the cause: "Address already in use"...)
                and the log's path.
        """
        end = time.monotonic() + timeout_s
        while not self._ready.wait(0.1):
            if self.proc.poll() is not None:
                raise PetrobotError(f"the simulator exited with status {self.proc.returncode} before it was ready"
                                    + self._cause())
            if time.monotonic() > end:
                raise PetrobotError(f"the simulator was not ready after {timeout_s:.0f} s" + self._cause())

    def _cause(self) -> str:
        if self.log is None:
            return ""
        if self._log is not None:
            self._log.flush()
        try:
            lines = [line.strip() for line in self.log.read_text(errors="replace").splitlines() if line.strip()]
        except OSError:
            lines = []
        return (f": {lines[-1]}" if lines else "") + f" (log {self.log})"

    def stop(self) -> None:
        """Stop the world (SIGTERM, SIGKILL after 10 s) and read its last lines."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._reader.join(timeout=5)  # the last lines ("stopped") are read before the report
        if self._log is not None:
            self._log.close()
        if self._events_log is not None:
            self._events_log.close()


@dataclass(frozen=True, slots=True)
class DemoWorld:
    """A world process a demo starts: ``petrobot sim NAME ARGS --services FILE``.

    Attributes:
        name: ``catching``, ``mobile``, ``zenoh`` or ``ros2``.
        args: its options (its ports come from the demo's services.toml).
        log: the name of its log file in the logs directory.
    """

    name: str
    args: Sequence[str] = ()
    log: str = "sim.log"


@dataclass(frozen=True, slots=True)
class DemoRun(Generic[R]):
    """What a demo's run left.

    Attributes:
        summary: the run's summary (end state, final marking, per-action statistics).
        worlds: each world's JSON event lines, each with ``t_wall``, by world name (empty without a
            world).
        journal: the journal the run was written to.
        logs: the directory of the node and world logs.
        report: the demo's report, the observer that saw the run's events (``None`` without one).
    """

    summary: RunSummary
    worlds: dict[str, list[dict[str, Any]]]
    journal: Path
    logs: Path
    report: R | None = None

    @property
    def world(self) -> list[dict[str, Any]]:
        """The event lines of the last world started, the testbed's own (those before it serve it, as
        the ROS 2 demo's router does); empty without a world."""
        return list(self.worlds.values())[-1] if self.worlds else []


def world_lines(world: Sequence[dict[str, Any]], drives: str = "drive") -> list[str]:
    """What the world said of itself, for the report: each drive fault (``drives`` names them) and
    its ``stopped`` line (simulated and wall time, the waits for the camera client and the CAN
    master that ran out)."""
    lines = [f"  {drives} {f['node']} faulted at t={f['t']:.3f} s: {f['reason']}; stopped in {f['stop_s']:.3f} s"
             for f in world if f.get("event") == "drive_fault"]
    lines += [f"simulator: {st['t']:.1f} s simulated in {st['wall_s']:.1f} s ({st['slipped_s']:.1f} s slipped); "
              f"waits for the camera client {st.get('camera_misses', 0)}/{st.get('camera_waits', 0)} and for the "
              f"CAN master {st.get('master_misses', 0)}/{st.get('master_waits', 0)} ran out; "
              f"{st['drive_faults']} drive fault(s)" for st in world if st.get("event") == "stopped"]
    return lines


def nodes_of(net: PetriNet, location: Any) -> list[str]:
    """The nodes the net's primitive actions are placed on and its external events published by."""
    nodes = {location.node_of(a.name) for t in net.tasks.values() for a in t.actions}
    nodes |= {location.events[e[4:]] for t in net.transitions for e in t.external_events if e[4:] in location.events}
    return sorted(nodes)


async def run_demo(args: argparse.Namespace, net: PetriNet, net_path: Path, *, journal: str,
                   worlds: Sequence[DemoWorld] = (), report: Callable[[Console], R] | None = None,
                   settle_s: float = 0.0) -> DemoRun[R]:
    """Start the worlds and the nodes, run ``net`` to its end, stop everything (module docstring).

    Args:
        args: the demo's options (``services``, ``key_file``, ``journal``, ``seed``, ``live``,
            ``max_seconds``).
        net: the task net; ``net_path`` its file (its text goes to the journal).
        journal: the fresh journal's path when ``--journal`` is not given.
        worlds: the world processes to start, in order, each ready before the next (none: no
            world); stopped in the reverse order.
        report: builds the demo's report from the console: the runtime's observer, which passes every
            event on to the console (e.g. the report's class).
        settle_s: time to wait after the run, before the worlds are stopped (their last lines at rest).

    Raises:
        PetrobotError: a world or a node did not start (the message names the cause and the
            log), services.toml or the key is unusable, the nodes are not ready.
    """
    from coordinator.journal import Journal
    from coordinator.nodegroup import NodeGroup
    from coordinator.session import execute
    from services.keys import load_key
    from services.location import load_location

    location = load_location(args.services)
    key = load_key(args.key_file)
    nodes = nodes_of(net, location)
    journal_path = Path(args.journal or journal)
    journal_path.parent.mkdir(parents=True, exist_ok=True)
    logs = journal_path.parent / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    say(f"seed {args.seed}; journal {journal_path}"
        + (" (learners continue from it)" if args.journal else " (fresh: new learners)")
        + f"; logs in {logs}/ ({', '.join([w.log for w in worlds] + [f'{n}.log' for n in nodes])})")
    started: dict[str, SimWorld] = {}
    try:
        for w in worlds:
            say(f"starting the simulated {w.name} world")
            sim = started[w.name] = SimWorld([*w.args, "--services", str(args.services)], log=logs / w.log,
                                             world=w.name)
            await asyncio.to_thread(sim.wait_ready, 90.0)
            say(_ready_text(w.name, sim.ready))
        say(f"starting nodes {', '.join(nodes)}")
        async with NodeGroup(args.services, nodes, key_file=args.key_file, log_level="INFO", log_dir=logs):
            console = Console(net, live=args.live)
            observer = report(console) if report is not None else None
            if not args.journal:
                kept = keep_previous(journal_path)
                if kept is not None:
                    say(f"previous journal kept as {kept}")
            with Journal(journal_path) as jnl:
                say(f"running {_shown(net_path)}: {net.name}"
                    + (f", {net.initial_marking['runs_remaining']} runs" if "runs_remaining" in net.initial_marking else ""))
                summary = await execute(net, location=location, key=key, journal=jnl, seed=args.seed,
                                        net_text=net_path.read_text(encoding="utf-8"), observer=observer,
                                        read_input=sys.stdin.isatty(), max_seconds=args.max_seconds,
                                        console=console)
                if settle_s > 0:
                    await asyncio.sleep(settle_s)
    finally:
        for sim in reversed(started.values()):
            sim.stop()
    return DemoRun(summary, {name: list(sim.events) for name, sim in started.items()}, journal_path, logs, observer)


def _ready_text(world: str, ready: dict[str, Any]) -> str:
    if "camera_port" in ready:
        return (f"the {world} world serves its camera on :{ready['camera_port']} and its CAN bus on "
                f":{ready.get('can_port')}")
    shown = ", ".join(f"{key} {value}" for key, value in ready.items()
                      if key not in ("event", "t", "t_wall") and isinstance(value, (str, int, float)))
    return f"the {world} world is ready ({shown})"


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)
