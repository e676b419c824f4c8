"""Fault campaign: does the journal agree with the nodes' own record of what ran, whatever breaks?

Usage::

    python bench/faults.py [--rounds 10] [--scenarios node-sigkill,...] [--seed S] [--json] [--keep DIR]
    python bench/faults.py check --journal J --node NAME=STATE_DIR[:LOG] ... [--run RUN] [--json]
    python bench/faults.py mobile-stop|catching-stop [--rounds 5] [--json] [--keep DIR]
    python bench/faults.py device-takeover [--rounds 2] [--testbeds mobile,catching] [--json] [--keep DIR]

**The campaign** runs each scenario ``--rounds`` times with real processes on 127.0.0.1: two nodes
(``python -m services.node``: ``alpha`` hosts ``echo`` and the global memory, ``beta`` hosts
``slow`` and the ``unattended`` action ``move``, both 1 s waits) and the coordinator
(``python -m coordinator.cli run``) running a net of two runs of sense (alpha) → work (``slow``)
→ carry (``move``), every task with an error branch. In each round a fault hits at a random moment
inside a call on ``beta`` (the round's target: its first or second ``slow`` or ``move`` call, the
action alternating from round to round, 0.05–0.7 s after the node logged the call):

* ``node-sigkill``: SIGKILL the node; start it again 0.5–3 s later;
* ``node-sigstop``: SIGSTOP the node for 1–3 s (longer than the coordinator's heartbeat window),
  then SIGCONT;
* ``node-restart``: SIGTERM the node (an orderly stop) and start it again at once;
* ``coordinator-sigkill``: SIGKILL the coordinator, then ``petrobot run --resume``;
* ``coordinator-sigint``: SIGINT (Ctrl-C) the coordinator, then ``petrobot run --resume``.

When the run is over the nodes are stopped and :func:`check` compares the journal with the nodes'
result stores and logs. Per scenario it prints: rounds, faults that hit inside a call, the hit
call's error branch taken, calls reconciled (and those whose node did otherwise than the net
assumed), disagreements (must be 0), calls run twice (must be 0), resumed runs completed, and the
coordinator's exit codes. The exit status is 0 when there is no disagreement, no call ran twice
and every round ended its run, else 1.

**mobile-stop** (``python bench/faults.py mobile-stop [--rounds 5]``) kills the coordinator of the
mobile robot mid-course (issue 22, section 2): the simulated world (``petrobot sim mobile``, ground
truth every 20 ms), the perception and drive nodes and ``petrobot run`` on a short course, each
its own process; 1.3 s into the first ``follow_track`` (the robot at cruise speed) the coordinator
gets SIGKILL, and the world's ground truth says how long after the kill (simulated time) and how far
the robot went before it came to rest (< 0.01 m/s). Target: at rest within 0.7 s. The follow action
is a motion: the node cancels it as soon as its caller's connection drops and it sends a zero-speed
set point, on which the drive brakes at once (before: cancelled 2.5 s later, then the watchdog:
3.9-4.3 s and 2.0-2.4 m). **catching-stop** does the same to the catching testbed (nets/catch.toml,
the vision and motion nodes): the coordinator killed while ``catch`` moves the arm (a joint faster
than 0.5 rad/s on the world's ground truth, every camera frame), every joint at rest within the
bound of the catch's own watchdog: 0.2 s of stale set points plus the slowest joint's braking time
at its acceleration limit.

**device-takeover** (issue 22, section 3) puts another station on the CAN gateway's port (python-can's
socketcand client, as any process on the lab network can) while a motion runs on its testbed: the
mobile robot 1.3 s into its first ``follow_track``, the arm while ``catch`` moves it. Each round sends
either one NMT "stop" to all nodes (``nmt-stop``) or a second master's RPDOs to one drive, every 8 ms
for 0.3 s (``second-master``: the left wheel at cruise speed, or joint 4 to zero). It reports the time
from the first foreign frame to the moment the running motion's node kept its ``error`` result (the
node's result store, wall clock), and the reason. Target: one heartbeat period of the drives (their
device files' ``heartbeat_ms``, 100 ms).

**check** compares any journal with nodes' state directories (and their logs, for calls started
twice): every call id the journal started is either absent from every node (it never ran there,
or the node no longer keeps it) or its final status on the node equals the journal's last word on
it (the reconciliation if there is one, else the result); no node started a call id twice (its
log has one ``call ID ACTION from`` line per start).
"""

from __future__ import annotations

import argparse
import collections
import itertools
import json
import math
import os
import random
import re
import secrets
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coordinator.journal import JournalReader
from services.protocol import Result, from_map, unpack_map
from services.protocol.framing import HEADER_BYTES

__all__ = ["SCENARIOS", "Agreement", "NodeRecord", "Rig", "StopMeasure", "TestbedRig", "campaign",
           "catching_coordinator_kill", "check", "device_takeover", "mobile_coordinator_kill", "node_starts", "node_store", "run_round",
           "stops"]

SCENARIOS = ("node-sigkill", "node-sigstop", "node-restart", "coordinator-sigkill", "coordinator-sigint")
TIMEOUT_S = 120.0  # generous bound of every wait: a failing round fails, a loaded machine passes

# ------------------------------------------------------------------------------------ agreement


@dataclass(frozen=True)
class NodeRecord:
    """What a node's result store says about one call id: its final ``status`` and ``reason``.

    A call found started but not finished (the node died during it and was not started again
    since) is ``error``/``node_restarted``: that is what the node answers for it once restarted.
    """

    node: str
    call_id: str
    action: str
    status: str
    reason: str | None


_CALL_LINE = re.compile(r" call (\S+) ([^\s(]\S*) from ")


def node_store(node: str, state_dir: str | os.PathLike[str]) -> dict[str, NodeRecord]:
    """Every call id node ``node`` keeps in the result store of ``state_dir``, read-only."""
    path = Path(state_dir) / "results.sqlite3"
    if not path.exists():
        return {}
    db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=10.0)
    try:
        rows = db.execute("SELECT call_id, action, frame FROM calls").fetchall()
    finally:
        db.close()
    out = {}
    for cid, action, frame in rows:
        if frame is None:
            out[cid] = NodeRecord(node, cid, action, "error", "node_restarted")
            continue
        msg = from_map(unpack_map(bytes(frame)[HEADER_BYTES:]))
        assert isinstance(msg, Result)
        out[cid] = NodeRecord(node, cid, action, msg.result.status.value, msg.result.reason)
    return out


def node_starts(log_text: str) -> collections.Counter[str]:
    """How many times a node's log says it started each call id (``call ID ACTION from PEER``)."""
    return collections.Counter(m.group(1) for m in _CALL_LINE.finditer(log_text))


@dataclass
class Agreement:
    """The comparison of a journal with the nodes (see :func:`check`).

    Attributes:
        calls: call ids the journal started.
        ran: those that some node keeps.
        agreed: those whose final status on the node is the journal's last word.
        disagreements: one line per call whose node and journal disagree (or that the journal has
            no last word on, although a node ran it).
        twice: one line per call id a node started more than once.
        reconciled: reconciliations journaled; differed: those in which the node had done
            otherwise than the net assumed.
    """

    calls: int = 0
    ran: int = 0
    agreed: int = 0
    disagreements: list[str] = field(default_factory=list)
    twice: list[str] = field(default_factory=list)
    reconciled: int = 0
    differed: int = 0

    @property
    def ok(self) -> bool:
        """No disagreement and no call started twice."""
        return not self.disagreements and not self.twice


def check(journal: str | os.PathLike[str], nodes: Mapping[str, tuple[str | os.PathLike[str], str | None]],
          run: str | None = None) -> Agreement:
    """Compare ``journal`` (one run, or all) with ``nodes``: name → (state directory, log text or ``None``).

    Raises:
        JournalError: the journal cannot be read.
    """
    stores = {name: node_store(name, state) for name, (state, _) in nodes.items()}
    with JournalReader.open(journal) as reader:
        starts = reader.starts(run)
        words = reader.final_words(run)
        recs = reader.reconciliations(run)
    out = Agreement(reconciled=len(recs), differed=sum(r.differs for r in recs))
    for start in {s.instance: s for s in starts}.values():
        out.calls += 1
        kept = [store[start.instance] for store in stores.values() if start.instance in store]
        if not kept:
            continue
        out.ran += 1
        if len(kept) > 1:
            out.disagreements.append(f"{start.instance}: kept by several nodes: {', '.join(k.node for k in kept)}")
            continue
        (truth,) = kept
        word = words.get(start.instance)
        said = None if word is None or word.status is None else word.status.value
        if said == truth.status:
            out.agreed += 1
            continue
        journal_says = "nothing" if word is None else (
            f"{said} ({word.reason})" if said is not None else "the node did not know it")
        out.disagreements.append(f"{start.instance} {start.action}: the journal says {journal_says}, node "
                                 f"{truth.node} says {truth.status} ({truth.reason})")
    for name, (_, log) in nodes.items():
        if log is None:
            continue
        for cid, n in sorted(node_starts(log).items()):
            if n > 1:
                out.twice.append(f"node {name} started {cid} {n} times")
    return out


# ------------------------------------------------------------------------------------ the rig

SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {alpha}

[nodes.beta]
host = "127.0.0.1"
port = {beta}

[memory]
node = "alpha"

[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"

[actions.slow]
node = "beta"
impl = "services.actions.demo:wait"

[actions.move]
node = "beta"
impl = "services.actions.demo:wait"
unattended = true
"""

NET = """
[net]
name = "faults"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "robot"
kind = "resource"
tokens = 1

[[place]]
id = "sensing"
kind = "primitive_task"
task = "sense"

[[place]]
id = "working"
kind = "primitive_task"
task = "work"

[[place]]
id = "carrying"
kind = "primitive_task"
task = "carry"

[[place]]
id = "done"

[[place]]
id = "failed"

[task.sense]
actions = [{ name = "echo", params = { x = 1 } }]
deadline_s = 30.0

[task.work]
actions = [{ name = "slow", params = { seconds = CALL_S } }]
deadline_s = 30.0

[task.carry]
actions = [{ name = "move", params = { seconds = CALL_S } }]
deadline_s = 30.0

[[transition]]
id = "start"
inputs = { runs = 1, robot = 1 }
outputs = { sensing = 1 }

[[transition]]
id = "sensed"
events = ["int:sense.ok"]
inputs = { sensing = 1 }
outputs = { working = 1 }

[[transition]]
id = "sense_error"
events = ["int:sense.error"]
hidden = true
inputs = { sensing = 1 }
outputs = { robot = 1, failed = 1 }

[[transition]]
id = "worked"
events = ["int:work.ok"]
inputs = { working = 1 }
outputs = { carrying = 1 }

[[transition]]
id = "work_error"
events = ["int:work.error"]
hidden = true
inputs = { working = 1 }
outputs = { robot = 1, failed = 1 }

[[transition]]
id = "carried"
events = ["int:carry.ok"]
inputs = { carrying = 1 }
outputs = { robot = 1, done = 1 }

[[transition]]
id = "carry_error"
events = ["int:carry.error"]
hidden = true
inputs = { carrying = 1 }
outputs = { robot = 1, failed = 1 }
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until(what: str, cond: Callable[[], Any], timeout_s: float = TIMEOUT_S) -> Any:
    """Poll ``cond`` until it returns something true; fail naming ``what`` after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not (got := cond()):
        if time.monotonic() > end:
            raise TimeoutError(f"not true after {timeout_s:g} s: {what}")
        time.sleep(0.02)
    return got


class Rig:
    """Two node processes and the coordinator's command line in a directory of their own.

    Args:
        workdir: where services.toml, the key, the net, the journal, the nodes' state directories
            and every process's output go.
        call_s: how long each call of ``slow`` and ``move`` lasts on the node, seconds.
    """

    def __init__(self, workdir: Path, *, call_s: float = 1.0) -> None:
        self.dir = workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.key_file = workdir / "key"
        self.key_file.write_text(secrets.token_hex(32) + "\n")
        self.key_file.chmod(0o600)
        self.services = workdir / "services.toml"
        self.services.write_text(SERVICES.format(alpha=_free_port(), beta=_free_port()))
        self.net = workdir / "faults.toml"
        self.net.write_text(NET.replace("CALL_S", repr(float(call_s))))
        self.journal = workdir / "journal.sqlite"
        self.nodes: dict[str, subprocess.Popen[bytes]] = {}
        self.coordinator: subprocess.Popen[bytes] | None = None
        self._runs = 0

    def env(self) -> dict[str, str]:
        env = dict(os.environ)
        env.pop("PETROBOT_KEY", None)
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        return env

    def state_dir(self, name: str) -> Path:
        return self.dir / "state" / name

    def node_log_path(self, name: str) -> Path:
        return self.dir / f"{name}.log"

    def node_log(self, name: str) -> str:
        path = self.node_log_path(name)
        return path.read_text(errors="replace") if path.exists() else ""

    def start_node(self, name: str) -> None:
        """Start node ``name`` (its log appended to ``NAME.log``) and wait until it listens."""
        before = self.node_log(name).count(f"node {name} listening on ")
        with open(self.node_log_path(name), "ab") as log:
            self.nodes[name] = subprocess.Popen(
                [sys.executable, "-m", "services.node", name, "--services", str(self.services), "--key-file",
                 str(self.key_file), "--state-dir", str(self.state_dir(name))],
                cwd=ROOT, env=self.env(), stdout=log, stderr=subprocess.STDOUT)
        proc = self.nodes[name]

        def listening() -> bool:
            if proc.poll() is not None:
                raise RuntimeError(f"node {name} exited with {proc.returncode}:\n{self.node_log(name)[-2000:]}")
            return self.node_log(name).count(f"node {name} listening on ") > before

        wait_until(f"node {name} listening", listening)

    def signal_node(self, name: str, sig: int) -> None:
        self.nodes[name].send_signal(sig)

    def stop_node(self, name: str) -> None:
        """SIGTERM node ``name`` (SIGKILL if it does not stop) and reap it."""
        proc = self.nodes[name]
        if proc.poll() is None:
            proc.send_signal(signal.SIGCONT)
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)

    def run(self, *extra: str) -> subprocess.Popen[bytes]:
        """Start ``petrobot run`` on the net (its output in ``run-N.out``)."""
        self._runs += 1
        out = open(self.dir / f"run-{self._runs}.out", "wb")  # noqa: SIM115 - closed by the child's end
        self.coordinator = subprocess.Popen(
            [sys.executable, "-m", "coordinator.cli", "run", str(self.net), "--services", str(self.services),
             "--key-file", str(self.key_file), "--journal", str(self.journal), "--lines", "--no-input", *extra],
            cwd=ROOT, env=self.env(), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        out.close()
        return self.coordinator

    def output(self, n: int) -> str:
        path = self.dir / f"run-{n}.out"
        return path.read_text(errors="replace") if path.exists() else ""

    def close(self) -> None:
        """Stop every process still running."""
        if self.coordinator is not None and self.coordinator.poll() is None:
            self.coordinator.kill()
            self.coordinator.wait(timeout=10)
        for name in list(self.nodes):
            self.stop_node(name)

    def check(self) -> Agreement:
        return check(self.journal, {n: (self.state_dir(n), self.node_log(n)) for n in self.nodes})


# ------------------------------------------------------------------------------------ one round


@dataclass
class Round:
    """What one round of a scenario did and found."""

    scenario: str
    target: str = ""  # the call id the fault hit
    inside: bool = False  # the fault hit while the target call ran on its node
    error_branch: bool = False  # the journal's result for the target is an error
    reconciled: int = 0
    differed: int = 0
    disagreements: list[str] = field(default_factory=list)
    twice: list[str] = field(default_factory=list)
    resumed_completed: bool | None = None  # coordinator scenarios: the resumed run ended completed
    exit_code: int | None = None  # of the last coordinator process
    end_state: str | None = None
    notes: list[str] = field(default_factory=list)


def _calls_on(log: str, action: str) -> list[str]:
    return [m.group(1) for m in _CALL_LINE.finditer(log) if m.group(2) == action]


def run_round(scenario: str, workdir: Path, rng: random.Random, *, action: str | None = None,
              call_s: float = 1.0) -> Round:
    """Run one round of ``scenario`` in ``workdir`` (see the module docstring) and check it.

    ``action`` is the target's action (``slow`` or ``move``; default: chosen by ``rng``); ``call_s``
    the duration of each ``slow`` and ``move`` call, seconds (the fault comes 0.05–0.7 s after the
    node logged the target's start).
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r} (one of {', '.join(SCENARIOS)})")
    rig = Rig(workdir, call_s=call_s)
    result = Round(scenario)
    action = action or rng.choice(("slow", "move"))
    nth = rng.randrange(2)
    try:
        rig.start_node("alpha")
        rig.start_node("beta")
        first = rig.run()
        target = wait_until(f"call #{nth + 1} of {action} on beta",
                            lambda: (calls := _calls_on(rig.node_log("beta"), action)) and len(calls) > nth
                            and calls[nth])
        result.target = target
        time.sleep(rng.uniform(0.05, 0.7))
        result.inside = f"result {target} " not in rig.node_log("beta")
        last = first
        if scenario == "node-sigkill":
            rig.signal_node("beta", signal.SIGKILL)
            rig.nodes["beta"].wait(timeout=30)
            time.sleep(rng.uniform(0.5, 3.0))
            rig.start_node("beta")
        elif scenario == "node-restart":
            rig.stop_node("beta")
            rig.start_node("beta")
        elif scenario == "node-sigstop":
            rig.signal_node("beta", signal.SIGSTOP)
            time.sleep(rng.uniform(1.0, 3.0))
            rig.signal_node("beta", signal.SIGCONT)
        else:
            first.send_signal(signal.SIGKILL if scenario == "coordinator-sigkill" else signal.SIGINT)
            code = first.wait(timeout=TIMEOUT_S)
            expected = -signal.SIGKILL if scenario == "coordinator-sigkill" else 130
            if code != expected:
                result.notes.append(f"the interrupted coordinator exited {code}, not {expected}")
            last = rig.run("--resume")
        result.exit_code = last.wait(timeout=TIMEOUT_S)
        if scenario.startswith("coordinator"):
            result.resumed_completed = result.exit_code == 0
    finally:
        rig.close()
    with JournalReader.open(rig.journal) as reader:
        runs = reader.runs()
        result.end_state = runs[-1].end_state if runs else None
        if len(runs) != 1:
            result.notes.append(f"{len(runs)} runs in the journal")
        hit = [r for r in reader.results() if r.instance == result.target]
        result.error_branch = bool(hit) and hit[-1].status.value == "error"
    agreement = rig.check()
    result.reconciled, result.differed = agreement.reconciled, agreement.differed
    result.disagreements, result.twice = agreement.disagreements, agreement.twice
    return result


def campaign(rounds: int, scenarios: tuple[str, ...] = SCENARIOS, *, seed: int = 0,
             keep: Path | None = None, progress: Callable[[Round], None] | None = None) -> dict[str, Any]:
    """Run ``rounds`` rounds of each scenario; return the counts per scenario and every round."""
    rng = random.Random(seed)
    table: dict[str, dict[str, Any]] = {}
    every: list[dict[str, Any]] = []
    base = keep or Path(tempfile.mkdtemp(prefix="petrobot-faults-"))
    for scenario in scenarios:
        row = {"rounds": 0, "inside_call": 0, "error_branch": 0, "reconciled": 0, "differed": 0,
               "disagreements": 0, "run_twice": 0, "resumed_completed": None, "exit_codes": {}}
        codes: collections.Counter[str] = collections.Counter()
        for i in range(rounds):
            done = run_round(scenario, base / f"{scenario}-{i}", rng, action=("slow", "move")[i % 2])
            row["rounds"] += 1
            row["inside_call"] += done.inside
            row["error_branch"] += done.error_branch
            row["reconciled"] += done.reconciled
            row["differed"] += done.differed
            row["disagreements"] += len(done.disagreements)
            row["run_twice"] += len(done.twice)
            if done.resumed_completed is not None:
                row["resumed_completed"] = (row["resumed_completed"] or 0) + done.resumed_completed
            codes[str(done.exit_code)] += 1
            every.append(asdict(done))
            if progress is not None:
                progress(done)
        row["exit_codes"] = dict(sorted(codes.items()))
        table[scenario] = row
    return {"date": time.strftime("%Y-%m-%d %H:%M"), "seed": seed, "rounds": rounds,
            "load": os.getloadavg(), "cpus": os.cpu_count(), "scenarios": table, "runs": every,
            "workdir": str(base) if keep else None}


def render(report: dict[str, Any]) -> str:
    """The per-scenario table as Markdown."""
    lines = [("| scenario | rounds | fault inside a call | error branch taken | reconciled (node did otherwise) | "
              "disagreements | calls run twice | resumed runs completed | exit codes |"),
             "|---|---|---|---|---|---|---|---|---|"]
    for name, r in report["scenarios"].items():
        resumed = "–" if r["resumed_completed"] is None else f"{r['resumed_completed']}/{r['rounds']}"
        codes = ", ".join(f"{c}×{n}" for c, n in r["exit_codes"].items())
        lines.append(f"| {name} | {r['rounds']} | {r['inside_call']} | {r['error_branch']} | {r['reconciled']} "
                     f"({r['differed']}) | {r['disagreements']} | {r['run_twice']} | {resumed} | {codes} |")
    return "\n".join(lines)


def _parse_nodes(specs: list[str]) -> dict[str, tuple[str, str | None]]:
    nodes = {}
    for spec in specs:
        name, sep, rest = spec.partition("=")
        if not sep or not name:
            raise SystemExit(f"--node {spec!r}: expected NAME=STATE_DIR[:LOG]")
        state, _, log = rest.partition(":")
        nodes[name] = (state, Path(log).read_text(errors="replace") if log else None)
    return nodes


# ------------------------------------------------------------------------------------ stops

MOBILE_SERVICES = """
[nodes.perception]
host = "127.0.0.1"
port = {perception}

[nodes.drive]
host = "127.0.0.1"
port = {drive}

[drivers.mobile_camera]
node = "perception"
impl = "services.mobile.perception_node:PerceptionDriver"
params = {{ port = {camera} }}

[actions.follow_centroid]
node = "perception"
impl = "services.mobile.perception_node:FollowCentroid"

[actions.follow_ransac]
node = "perception"
impl = "services.mobile.perception_node:FollowRansac"

[actions.follow_scanline]
node = "perception"
impl = "services.mobile.perception_node:FollowScanline"

[actions.find_beacon]
node = "perception"
impl = "services.mobile.perception_node:FindBeaconAction"

[actions.goto_beacon]
node = "perception"
impl = "services.mobile.perception_node:GotoBeaconAction"

[actions.reacquire_track]
node = "perception"
impl = "services.mobile.perception_node:ReacquireTrackAction"

[actions.stop_at_t]
node = "perception"
impl = "services.mobile.perception_node:StopAtTAction"

[drivers.wheels]
node = "drive"
impl = "services.mobile.drive_node:DriveDriver"
params = {{ can_port = {can} }}

[actions.stop_robot]
node = "drive"
impl = "services.mobile.drive_node:StopRobot"
"""
CATCHING_SERVICES = """
[nodes.vision]
host = "127.0.0.1"
port = {vision}

[nodes.motion]
host = "127.0.0.1"
port = {motion}

[drivers.camera]
node = "vision"
impl = "services.catching.vision_node:CameraDriver"
params = {{ port = {camera} }}

[actions.locate_threshold]
node = "vision"
impl = "services.catching.vision_node:LocateThreshold"

[actions.locate_bgdiff]
node = "vision"
impl = "services.catching.vision_node:LocateBgdiff"

[actions.locate_average]
node = "vision"
impl = "services.catching.vision_node:LocateAverage"

[actions.predict]
node = "vision"
impl = "services.catching.vision_node:Predict"
params = {{ camera_port = {camera} }}

[events.image_sampling_tick]
node = "vision"

[drivers.puma]
node = "motion"
impl = "services.catching.arm:PumaDriver"
params = {{ can_port = {can} }}

[actions.move_home]
node = "motion"
impl = "services.catching.motion_node:MoveHome"

[actions.catch]
node = "motion"
impl = "services.catching.motion_node:Catch"
deadline_s = 20.0

[events.ball_caught]
node = "motion"
"""
MOBILE_NET = ROOT / "tests" / "data" / "mobile_min.toml"
MOBILE_COURSE = ROOT / "tests" / "data" / "course_short.toml"
CATCHING_NET = ROOT / "nets" / "catch.toml"
POSE_PERIOD_S = 0.02
REST_SPEED = 0.01  # m/s, the mobile robot
REST_JOINT_SPEED = 0.02  # rad/s, every joint of the arm
SETPOINT_MAX_AGE_S = 0.2  # the catch's watchdog (services.catching.setpoints.LatestSetPoint)


@dataclass
class StopMeasure:
    """How a robot came to rest after its coordinator was killed (ground truth).

    Attributes:
        speed: its speed when the coordinator was killed: m/s for the mobile robot, rad/s of the
            fastest joint for the arm.
        stop_s: simulated time from the kill to the first ground-truth sample at rest, s.
        distance_m: the path the mobile robot drove meanwhile, m (``None`` for the arm).
        bound_s: the arm's watchdog bound from that speed: the set points' staleness limit plus the
            slowest joint's braking time at its acceleration limit, s (``None`` for the mobile robot,
            whose bound is 0.7 s at 0.8 m/s).
        call: status and reason of the running motion call, as its node kept it.
        log: the nodes' lines about the stop.
    """

    speed: float = 0.0
    stop_s: float | None = None
    distance_m: float | None = None
    bound_s: float | None = None
    call: tuple[str, str | None] | None = None
    log: list[str] = field(default_factory=list)


class TestbedRig:
    """A testbed's world, its two nodes and ``petrobot run`` as processes of their own.

    Args:
        workdir: where services.toml, the key, the journal, the nodes' states and logs go.
        world: ``mobile`` or ``catching``.
        services: services.toml text with ``{NAME}`` port placeholders for the nodes, ``camera``, ``can``.
        nodes: the two nodes.
        net: the net ``petrobot run`` runs.
        sim_args: the world's options besides its ports.
    """

    def __init__(self, workdir: Path, *, world: str, services: str, nodes: tuple[str, str], net: Path,
                 sim_args: list[str]) -> None:
        from coordinator.commands.demo_start import SimWorld

        self.dir = workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.key_file = workdir / "key"
        self.key_file.write_text(secrets.token_hex(32) + "\n")
        self.key_file.chmod(0o600)
        self.names = nodes
        self.ports = {n: _free_port() for n in (*nodes, "camera", "can")}
        self.services = workdir / "services.toml"
        self.services.write_text(services.format(**self.ports))
        self.net = net
        self.journal = workdir / "journal.sqlite"
        self.world = SimWorld([*sim_args, "--camera-port", str(self.ports["camera"]), "--can-port",
                               str(self.ports["can"])], log=workdir / "sim.log", world=world)
        self.nodes: dict[str, subprocess.Popen[bytes]] = {}
        self.coordinator: subprocess.Popen[bytes] | None = None

    def env(self) -> dict[str, str]:
        env = dict(os.environ)
        env.pop("PETROBOT_KEY", None)
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        return env

    def log(self, name: str) -> str:
        path = self.dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def start(self) -> None:
        """The world, then the nodes (each listening), then ``petrobot run``."""
        self.world.wait_ready(TIMEOUT_S)
        for name in self.names:
            with open(self.dir / f"{name}.log", "ab") as log:
                self.nodes[name] = subprocess.Popen(
                    [sys.executable, "-m", "services.node", name, "--services", str(self.services), "--key-file",
                     str(self.key_file), "--state-dir", str(self.dir / "state" / name)],
                    cwd=ROOT, env=self.env(), stdout=log, stderr=subprocess.STDOUT)
        for name, proc in self.nodes.items():
            wait_until(f"node {name} listening", lambda proc=proc, name=name: (
                proc.poll() is None or _raise(f"node {name} exited:\n{self.log(name)[-2000:]}"))
                and f"node {name} listening on " in self.log(name))
        out = open(self.dir / "run.out", "wb")  # noqa: SIM115 - closed by the child's end
        self.coordinator = subprocess.Popen(
            [sys.executable, "-m", "coordinator.cli", "run", str(self.net), "--services", str(self.services),
             "--key-file", str(self.key_file), "--journal", str(self.journal), "--lines", "--no-input",
             "--max-seconds", "200"],
            cwd=ROOT, env=self.env(), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        out.close()

    def output(self) -> str:
        path = self.dir / "run.out"
        return path.read_text(errors="replace") if path.exists() else ""

    def events(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in list(self.world.events) if e.get("event") == kind]

    def wait_output(self, text: str) -> None:
        """Wait until ``petrobot run`` printed ``text`` (fail if it ended first)."""
        wait_until(repr(text), lambda: text in self.output() or (
            self.coordinator is not None and self.coordinator.poll() is not None
            and _raise(f"the run ended first:\n{self.output()[-3000:]}")))

    def kill_coordinator(self) -> float:
        """SIGKILL ``petrobot run``; the wall time of the kill."""
        assert self.coordinator is not None
        t_kill = time.time()
        self.coordinator.send_signal(signal.SIGKILL)
        self.coordinator.wait(timeout=30)
        return t_kill

    def kept_call(self, node: str, action: str) -> tuple[str, str | None] | None:
        """The status and reason of the last call of ``action`` node ``node`` keeps."""
        kept = [r for r in node_store(node, self.dir / "state" / node).values() if r.action.startswith(action)]
        return (kept[-1].status, kept[-1].reason) if kept else None

    def close(self) -> None:
        if self.coordinator is not None and self.coordinator.poll() is None:
            self.coordinator.kill()
            self.coordinator.wait(timeout=10)
        for proc in self.nodes.values():
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(timeout=10)
        self.world.stop()


def _raise(message: str) -> bool:
    raise RuntimeError(message)


def measure_stop(poses: list[dict[str, Any]], t_kill_wall: float) -> StopMeasure:
    """The mobile robot's stop after a kill at wall time ``t_kill_wall``, from ground-truth pose lines."""
    before = [p for p in poses if p["wall"] <= t_kill_wall]
    out = StopMeasure()
    if not before:
        return out
    kill = before[-1]
    out.speed = float(kill["v"])
    after = [p for p in poses if p["t"] > kill["t"]]
    rest = next((i for i, p in enumerate(after) if p["v"] < REST_SPEED), None)
    if rest is None:
        return out
    out.stop_s = float(after[rest]["t"]) - float(kill["t"])
    path = [kill, *after[:rest + 1]]
    out.distance_m = sum(math.hypot(b["x"] - a["x"], b["y"] - a["y"]) for a, b in itertools.pairwise(path))
    return out


def mobile_coordinator_kill(workdir: Path, *, delay_s: float = 1.3) -> StopMeasure:
    """One round of mobile-stop (module docstring) in ``workdir``."""
    rig = TestbedRig(workdir, world="mobile", services=MOBILE_SERVICES, nodes=("perception", "drive"),
                     net=MOBILE_NET, sim_args=["--realtime", "--renderer", "analytic", "--course",
                                               str(MOBILE_COURSE), "--pose-every", str(POSE_PERIOD_S)])
    try:
        rig.start()
        rig.wait_output("start follow_track -> ")
        time.sleep(delay_s)  # at cruise speed on the first straight
        t_kill = rig.kill_coordinator()
        wait_until("the robot at rest on the ground truth", lambda: any(
            p["wall"] > t_kill and p["v"] < REST_SPEED for p in rig.events("pose")))
        time.sleep(0.5)
        out = measure_stop(rig.events("pose"), t_kill)
        out.log = [line for line in rig.log("drive").splitlines() if "watchdog" in line or "steering" in line]
    finally:
        rig.close()
    out.call = rig.kept_call("perception", "follow_")
    return out


def catching_coordinator_kill(workdir: Path, *, moving: float = 0.5) -> StopMeasure:
    """One round of catching-stop in ``workdir``: the coordinator killed while ``catch`` moves the arm
    (a joint faster than ``moving`` rad/s on the ground truth); the time to rest of every joint."""
    from services.catching.robot.puma560 import QDD_MAX

    period = 0.04  # one camera frame at 25 fps
    rig = TestbedRig(workdir, world="catching", services=CATCHING_SERVICES, nodes=("vision", "motion"),
                     net=CATCHING_NET, sim_args=["--realtime", "--renderer", "analytic", "--throws", "0",
                                                 "--interval", "0", "--throw-when-home", "1.0", "--first-throw",
                                                 "4", "--after-camera-client", "--arm-every", str(period)])
    try:
        rig.start()
        rig.wait_output("start catch -> catch on motion")
        t_start = time.time()
        fast = wait_until("the arm moving for the catch", lambda: next(
            (a for a in rig.events("arm") if a["wall"] > t_start and max(a["qd"]) > moving), None))
        t_kill = rig.kill_coordinator()
        wait_until("the arm at rest on the ground truth", lambda: any(
            a["wall"] > t_kill and max(a["qd"]) < REST_JOINT_SPEED for a in rig.events("arm")))
        arm = rig.events("arm")
        time.sleep(0.3)
        out = StopMeasure()
        kill = [a for a in arm if a["wall"] <= t_kill][-1]
        out.speed = max(kill["qd"])
        rest = next(a for a in arm if a["t"] > kill["t"] and max(a["qd"]) < REST_JOINT_SPEED)
        out.stop_s = float(rest["t"]) - float(kill["t"])
        braking = max(float(v) / float(a) for v, a in zip(kill["qd"], QDD_MAX, strict=True))
        out.bound_s = SETPOINT_MAX_AGE_S + braking + 2 * period
        out.log = [line for line in rig.log("motion").splitlines() if "catch" in line and "call" in line]
        assert fast is not None
    finally:
        rig.close()
    out.call = rig.kept_call("motion", "catch")
    return out


TAKEOVERS = ("nmt-stop", "second-master")
HEARTBEAT_S = 0.1  # the drives' heartbeat period (devices/puma.toml, devices/wheels.toml: heartbeat_ms)


@dataclass
class Takeover:
    """How fast a running motion erred when another station took its drives over.

    Attributes:
        testbed: ``mobile`` or ``catching``.
        how: ``nmt-stop`` or ``second-master``.
        detect_s: wall time from the first foreign frame to the node keeping the motion's result, s.
        call: status and reason of the running motion call, as its node kept it.
        log: the motion node's lines naming the takeover.
    """

    testbed: str
    how: str
    detect_s: float | None = None
    call: tuple[str, str | None] | None = None
    log: list[str] = field(default_factory=list)


def _kept_at(state_dir: Path, action: str, after: float) -> tuple[float, str, str | None] | None:
    """The wall time a node kept its first result of ``action`` (a prefix) after ``after``, with its
    status and reason (``None``: not yet)."""
    path = state_dir / "results.sqlite3"
    if not path.exists():
        return None
    db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=10.0)
    try:
        rows = db.execute("SELECT at, frame FROM calls WHERE frame IS NOT NULL AND action LIKE ? AND at > ? "
                          "ORDER BY at LIMIT 1", (action + "%", after)).fetchall()
    finally:
        db.close()
    if not rows:
        return None
    msg = from_map(unpack_map(bytes(rows[0][1])[HEADER_BYTES:]))
    assert isinstance(msg, Result)
    return float(rows[0][0]), msg.result.status.value, msg.result.reason


def device_takeover(workdir: Path, *, testbed: str, how: str) -> Takeover:
    """One round of device-takeover (module docstring) in ``workdir``."""
    import struct

    import can

    out = Takeover(testbed, how)
    if testbed == "mobile":
        rig = TestbedRig(workdir, world="mobile", services=MOBILE_SERVICES, nodes=("perception", "drive"),
                         net=MOBILE_NET, sim_args=["--realtime", "--renderer", "analytic", "--course",
                                                   str(MOBILE_COURSE)])
        node, action, started = "perception", "follow_", "start follow_track -> "
        drive, target = 1, round(16.0 / 1e-4)  # the left wheel at 16 rad/s (0.8 m/s), in counts of 0x60FF
    else:
        rig = TestbedRig(workdir, world="catching", services=CATCHING_SERVICES, nodes=("vision", "motion"),
                         net=CATCHING_NET, sim_args=["--realtime", "--renderer", "analytic", "--throws", "0",
                                                     "--interval", "0", "--throw-when-home", "1.0", "--first-throw",
                                                     "4", "--after-camera-client"])
        node, action, started = "motion", "catch", "start catch -> catch on motion"
        drive, target = 4, 0
    bus: can.BusABC | None = None
    try:
        rig.start()
        rig.wait_output(started)
        bus = can.Bus(interface="socketcand", host="127.0.0.1", port=rig.ports["can"], channel="can0")
        time.sleep(1.3 if testbed == "mobile" else 0.6)  # at cruise speed; the arm on its way
        t_inject = time.time()
        if how == "nmt-stop":
            bus.send(can.Message(arbitration_id=0x000, data=bytes([0x02, 0]), is_extended_id=False))
        else:
            rpdo = struct.pack("<Hi", 0x0F, target)
            for _ in range(int(0.3 / 0.008)):
                bus.send(can.Message(arbitration_id=0x200 + drive, data=rpdo, is_extended_id=False))
                time.sleep(0.008)
        kept = wait_until(f"the {action} call's result", lambda: _kept_at(rig.dir / "state" / node, action, t_inject))
        out.detect_s = kept[0] - t_inject
        out.call = (kept[1], kept[2])
        motion = "drive" if testbed == "mobile" else "motion"
        out.log = [line for line in rig.log(motion).splitlines()
                   if "another station" in line or "left operational" in line or "wheel drives: fault" in line][:3]
    finally:
        if bus is not None:
            bus.shutdown()
        rig.close()
    return out


def takeovers(rounds: int, testbeds: tuple[str, ...] = ("mobile", "catching"), keep: Path | None = None,
              progress: Callable[[Takeover], None] | None = None) -> dict[str, Any]:
    """``rounds`` rounds of each takeover on each testbed; the detection times with their worst."""
    base = keep or Path(tempfile.mkdtemp(prefix="petrobot-takeover-"))
    done = []
    for testbed in testbeds:
        for how in TAKEOVERS:
            for i in range(rounds):
                got = device_takeover(base / f"{testbed}-{how}-{i}", testbed=testbed, how=how)
                done.append(got)
                if progress is not None:
                    progress(got)
    times = [d.detect_s for d in done if d.detect_s is not None]
    erred = [d for d in done if d.call is not None and d.call[0] == "error"]
    within = [d for d in erred if d.detect_s is not None and d.detect_s <= HEARTBEAT_S]
    return {"date": time.strftime("%Y-%m-%d %H:%M"), "what": "device-takeover", "rounds": len(done),
            "load": os.getloadavg(), "cpus": os.cpu_count(), "heartbeat_s": HEARTBEAT_S, "detect_s": times,
            "detect_s_max": max(times) if times else None, "erred": len(erred), "within_bound": len(within),
            "runs": [asdict(d) for d in done], "workdir": str(base) if keep else None}


def stops(kind: str, rounds: int, keep: Path | None = None, progress: Callable[[StopMeasure], None] | None = None
          ) -> dict[str, Any]:
    """``rounds`` rounds of mobile-stop or catching-stop; the stop times (and distances) with their worst."""
    base = keep or Path(tempfile.mkdtemp(prefix=f"petrobot-{kind}-"))
    kill = mobile_coordinator_kill if kind == "mobile-stop" else catching_coordinator_kill
    done = []
    for i in range(rounds):
        got = kill(base / f"round-{i}")
        done.append(got)
        if progress is not None:
            progress(got)
    times = [d.stop_s for d in done if d.stop_s is not None]
    dist = [d.distance_m for d in done if d.distance_m is not None]
    within = [d for d in done if d.stop_s is not None and d.stop_s <= (d.bound_s if d.bound_s is not None else 0.7)]
    return {"date": time.strftime("%Y-%m-%d %H:%M"), "what": kind, "rounds": rounds, "load": os.getloadavg(),
            "cpus": os.cpu_count(), "stop_s": times, "distance_m": dist,
            "stop_s_max": max(times) if times else None, "distance_m_max": max(dist) if dist else None,
            "within_bound": len(within), "runs": [asdict(d) for d in done], "workdir": str(base) if keep else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", nargs="?", default="campaign",
                        choices=["campaign", "check", "mobile-stop", "catching-stop", "device-takeover"])
    parser.add_argument("--rounds", type=int, help="rounds per scenario (default: 10; device-takeover: 2)")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS), help="comma-separated scenarios (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the fault moments (default: %(default)s)")
    parser.add_argument("--keep", type=Path, help="keep every round's files (journal, logs, stores) under this directory")
    parser.add_argument("--journal", help="check: the journal")
    parser.add_argument("--node", action="append", default=[], metavar="NAME=STATE_DIR[:LOG]",
                        help="check: a node's state directory and, optionally, its log file (repeatable)")
    parser.add_argument("--run", help="check: only this run of the journal")
    parser.add_argument("--testbeds", default="mobile,catching",
                        help="device-takeover: comma-separated testbeds (default: %(default)s)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args(argv)
    if args.what == "device-takeover":
        def told(got: Takeover) -> None:
            print(f"{got.testbed} {got.how}: motion call {got.call} "
                  f"{'-' if got.detect_s is None else f'{got.detect_s * 1000:.0f} ms'} after the first foreign frame",
                  file=sys.stderr, flush=True)

        rep = takeovers(args.rounds or 2, tuple(t for t in args.testbeds.split(",") if t),
                        keep=args.keep, progress=told)
        if args.json:
            print(json.dumps(rep, indent=2))
        else:
            worst = "-" if rep["detect_s_max"] is None else f"{rep['detect_s_max'] * 1000:.0f} ms"
            print(f"{rep['erred']}/{rep['rounds']} motions ended in error, {rep['within_bound']} within one heartbeat "
                  f"period ({rep['heartbeat_s'] * 1000:.0f} ms); detection max {worst}; load {rep['load']}")
        return 0 if rep["within_bound"] == rep["rounds"] else 1
    if args.what in ("mobile-stop", "catching-stop"):
        def said(got: StopMeasure) -> None:
            unit = "m/s" if args.what == "mobile-stop" else "rad/s (fastest joint)"
            bound = 0.7 if got.bound_s is None else got.bound_s
            print(f"coordinator killed at {got.speed:.2f} {unit}: at rest after "
                  f"{'-' if got.stop_s is None else f'{got.stop_s:.2f} s'} (bound {bound:.2f} s)"
                  + ("" if got.distance_m is None else f" and {got.distance_m:.2f} m") + f"; motion call {got.call}",
                  file=sys.stderr, flush=True)

        rep = stops(args.what, args.rounds or 10, keep=args.keep, progress=said)
        if args.json:
            print(json.dumps(rep, indent=2))
        else:
            print(f"{rep['within_bound']}/{rep['rounds']} rounds at rest within the bound; stop time max "
                  f"{rep['stop_s_max']} s, distance max {rep['distance_m_max']} m; load {rep['load']}")
        return 0 if rep["within_bound"] == rep["rounds"] else 1
    if args.what == "check":
        if not args.journal or not args.node:
            parser.error("check needs --journal and at least one --node")
        agreement = check(args.journal, _parse_nodes(args.node), args.run)
        if args.json:
            print(json.dumps({**asdict(agreement), "ok": agreement.ok}, indent=2))
        else:
            print(f"{agreement.calls} calls started, {agreement.ran} kept by a node, {agreement.agreed} agree; "
                  f"{agreement.reconciled} reconciled ({agreement.differed} differed from what the net assumed)")
            for line in agreement.disagreements + agreement.twice:
                print(f"  {line}")
        return 0 if agreement.ok else 1
    scenarios = tuple(s for s in args.scenarios.split(",") if s)

    def progress(done: Round) -> None:
        bad = done.disagreements + done.twice + done.notes
        print(f"{done.scenario:<20} {done.target:<16} inside={int(done.inside)} error_branch={int(done.error_branch)} "
              f"reconciled={done.reconciled} differed={done.differed} exit={done.exit_code} "
              f"{done.end_state}{'  ' + '; '.join(bad) if bad else ''}", file=sys.stderr, flush=True)

    report = campaign(args.rounds or 10, scenarios, seed=args.seed, keep=args.keep, progress=progress)
    print(json.dumps(report, indent=2) if args.json else render(report))
    table = report["scenarios"].values()
    ended = all(r["end_state"] is not None for r in report["runs"])
    return 0 if ended and all(r["disagreements"] == 0 and r["run_twice"] == 0 for r in table) else 1


if __name__ == "__main__":
    sys.exit(main())
