"""The catching testbed on separate hosts: network namespaces with their own addresses.

The test builds its own network: a switch namespace with a bridge, and one namespace per host with
a veth pair to the bridge and an address on 10.231.0.0/24 (nothing leaves the namespaces):

    sim (10.231.0.10): `sim catching`, its camera server and CAN gateway bound to that address
    vis (10.231.0.11): the vision node          mot (10.231.0.12): the motion node
    co  (10.231.0.13): the coordinator, `petrobot run` of a 3-run catching net

A link between two hosts is cut with a blackhole route to the other's address in each of them
(packets dropped silently, as with a pulled cable) and restored by deleting the routes.

Run 1: the vision–motion link is cut while the motion node catches: the motion node's watchdog
stops the arm and `catch` ends in error (stream_lost), the net takes the error branch and the robot
goes home; the link comes back. Run 2: the catch gets set points again (recovery). Run 3: the
motion–sim link (the CAN bus) is cut mid-catch: the drives' own watchdog brings every moving joint
to rest (RPDO timeout, EMCY) and `catch` ends in error (bus); the link comes back and the move home
recovers the drives (fault reset, enable) before moving.

Needs root (`ip netns add`); CI runs as root. Elsewhere it skips, saying why.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from tests.integration.cluster import ROOT
from waiting import file_says

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.netns, pytest.mark.timeout(420)]

SUBNET = "10.231.0"
HOSTS = {"sim": 10, "vis": 11, "mot": 12, "co": 13}

SERVICES = f"""
[nodes.vision]
host = "{SUBNET}.11"
port = 7103

[nodes.motion]
host = "{SUBNET}.12"
port = 7104

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = {{ host = "{SUBNET}.10", port = 7210 }}

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
params = {{ camera_host = "{SUBNET}.10", camera_port = 7210 }}

[events.image_sampling_tick]
node = "vision"

[drivers.puma]
node = "motion"
impl = "services.catching.arm:PumaDriver"
params = {{ can_host = "{SUBNET}.10", can_port = 7211 }}

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


def _ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=False)


class Lab:
    """Network namespaces of one test, the processes started in them, and link cuts."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.prefix = f"pbn{os.getpid() % 100000}"
        self.names = [f"{self.prefix}-{h}" for h in (*HOSTS, "sw")]
        self.procs: list[subprocess.Popen[Any]] = []

    def ns(self, host: str) -> str:
        return f"{self.prefix}-{host}"

    def addr(self, host: str) -> str:
        return f"{SUBNET}.{HOSTS[host]}"

    def build(self) -> None:
        sw = self.ns("sw")
        for cmd in (("netns", "add", sw), ("-n", sw, "link", "add", "br0", "type", "bridge"),
                    ("-n", sw, "link", "set", "br0", "up")):
            self._ok(*cmd)
        for host in HOSTS:
            ns, a, b = self.ns(host), f"{self.prefix}{host}a", f"{self.prefix}{host}b"
            for cmd in (("netns", "add", ns), ("link", "add", a, "type", "veth", "peer", "name", b),
                        ("link", "set", a, "netns", ns), ("link", "set", b, "netns", sw),
                        ("-n", ns, "link", "set", a, "name", "eth0"),
                        ("-n", ns, "addr", "add", f"{self.addr(host)}/24", "dev", "eth0"),
                        ("-n", ns, "link", "set", "eth0", "up"), ("-n", ns, "link", "set", "lo", "up"),
                        ("-n", sw, "link", "set", b, "master", "br0"), ("-n", sw, "link", "set", b, "up")):
                self._ok(*cmd)

    @staticmethod
    def _ok(*args: str) -> None:
        out = _ip(*args)
        if out.returncode != 0:
            raise RuntimeError(f"ip {' '.join(args)}: {out.stderr.strip()}")

    def cut(self, a: str, b: str) -> None:
        """Drop every packet between hosts ``a`` and ``b`` (both directions)."""
        self._ok("-n", self.ns(a), "route", "add", "blackhole", f"{self.addr(b)}/32")
        self._ok("-n", self.ns(b), "route", "add", "blackhole", f"{self.addr(a)}/32")

    def restore(self, a: str, b: str) -> None:
        self._ok("-n", self.ns(a), "route", "del", "blackhole", f"{self.addr(b)}/32")
        self._ok("-n", self.ns(b), "route", "del", "blackhole", f"{self.addr(a)}/32")

    def spawn(self, host: str, cmd: list[str], log: Path, *, pipe: bool = False,
              merge: bool = False) -> subprocess.Popen[str]:
        """Start ``cmd`` in host ``host``'s namespace: stdout to a pipe (``pipe``) or to ``log``;
        stderr to ``log``, or into stdout (``merge``)."""
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        env.pop("PETROBOT_KEY", None)
        with open(log, "w") as fh:
            proc = subprocess.Popen(["ip", "netns", "exec", self.ns(host), *cmd], cwd=ROOT, env=env, text=True,
                                    stdout=subprocess.PIPE if pipe else fh,
                                    stderr=subprocess.STDOUT if merge or not pipe else fh)
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        for name in self.names:
            _ip("netns", "del", name)


def _cannot_make_namespaces() -> str | None:
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add); CI runs this test as root"
    probe = f"pbnprobe{os.getpid() % 100000}"
    made = _ip("netns", "add", probe)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    _ip("netns", "del", probe)
    return None


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[Lab]:
    why = _cannot_make_namespaces()
    if why is not None:
        pytest.skip(f"cannot build the network namespaces of this test: {why}")
    lab = Lab(tmp_path)
    try:
        lab.build()
        yield lab
    finally:
        lab.close()


class Lines:
    """A process's output lines, read by a thread; ``wait`` for one containing a text."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.q: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        assert proc.stdout is not None
        threading.Thread(target=self._read, args=(proc.stdout,), daemon=True).start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            self.q.put(line.rstrip())

    def wait(self, text: str, timeout: float) -> str:
        """The next line containing ``text``."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.q.get(timeout=max(0.01, end - time.monotonic()))
            except queue.Empty:
                break
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f"no line with {text!r} within {timeout} s; last lines:\n" + "\n".join(self.seen[-40:]))

    def drain(self) -> None:
        while True:
            try:
                self.seen.append(self.q.get_nowait())
            except queue.Empty:
                return


def _results(journal: Path, task: str) -> list[tuple[str, str | None, str | None, dict[str, Any]]]:
    with sqlite3.connect(journal) as db:
        rows = db.execute("SELECT status, outcome, reason, value FROM action_result WHERE task = ? ORDER BY entry",
                          (task,)).fetchall()
    return [(s, o, r, json.loads(v) if v else {}) for s, o, r, v in rows]


def test_catching_across_hosts_survives_cut_links_with_the_watchdogs_and_recovers(lab: Lab, tmp_path: Path):
    key = tmp_path / "key"
    key.write_text(os.urandom(32).hex() + "\n")
    key.chmod(0o600)
    services = tmp_path / "services.toml"
    services.write_text(SERVICES)
    net = tmp_path / "catch3.toml"
    net.write_text((ROOT / "nets" / "catch.toml").read_text().replace(
        'id = "runs_remaining"\nkind = "control"\ntokens = 4', 'id = "runs_remaining"\nkind = "control"\ntokens = 3'))
    assert "tokens = 3" in net.read_text()
    sim = lab.spawn("sim", [sys.executable, "-m", "coordinator.commands.sim", "catching", "--host", lab.addr("sim"),
                            "--camera-port", "7210", "--can-port", "7211", "--renderer", "analytic", "--seed", "3",
                            "--throws", "0", "--interval", "0", "--throw-when-home", "1.0", "--first-throw", "4",
                            "--after-camera-client"],
                    tmp_path / "sim.log", pipe=True)
    sim_out = Lines(sim)
    sim_out.wait('"event": "ready"', 120)
    logs = {}
    for host, node in (("vis", "vision"), ("mot", "motion")):
        logs[node] = tmp_path / f"{node}.log"
        lab.spawn(host, [sys.executable, "-m", "services.node", node, "--services", str(services),
                         "--key-file", str(key), "--state-dir", str(tmp_path / "state" / node)], logs[node])
    for node, path in logs.items():
        file_says(path, f"node {node} listening on", 60)
    journal = tmp_path / "journal.sqlite"
    co = lab.spawn("co", [sys.executable, "-m", "coordinator.cli", "run", str(net), "--services", str(services),
                          "--journal", str(journal), "--key-file", str(key), "--lines", "--no-input",
                          "--seed", "3", "--max-seconds", "300"],
                   tmp_path / "coordinator.log", pipe=True, merge=True)
    out = Lines(co)

    # run 1: the vision-motion link is cut while the arm servoes: once the catch has a set point, as
    # the motion node logs (before the first one, a cut link is a stream lost with no motion to stop)
    out.wait("start catch -> catch on motion", 120)
    file_says(logs["motion"], "catch: first set point")
    lab.cut("vis", "mot")
    line = out.wait("done  catch/catch on motion", 60)
    assert "error (stream_lost)" in line and "watchdog stopped the arm" in line, line
    lab.restore("vis", "mot")
    out.wait("fire", 10)  # the error branch fires
    # run 2: the link is back, set points flow again
    out.wait("start catch -> catch on motion", 120)
    line = out.wait("done  catch/catch on motion", 60)
    assert "stream_lost" not in line, line
    # run 3: the CAN bus link is cut mid-catch
    out.wait("start catch -> catch on motion", 120)
    time.sleep(0.3)
    lab.cut("mot", "sim")
    fault = json.loads(sim_out.wait('"event": "drive_fault"', 60))
    line = out.wait("done  catch/catch on motion", 60)
    assert "error (bus)" in line, line
    time.sleep(1.0)
    lab.restore("mot", "sim")
    out.wait("fire", 10)
    code = co.wait(timeout=180)
    out.drain()
    text = "\n".join(out.seen)
    # the run's last lines first (what ended it), then the motion node's (the drives' recovery)
    assert code == 0, (f"petrobot run exited {code}:\n" + "\n".join(out.seen[-25:]) + "\n--- motion.log (end):\n"
                       + "\n".join(logs["motion"].read_text(errors="replace").splitlines()[-25:]))
    assert "completed after" in text and "home_retries_left': 3" in text, text[-3000:]

    catches = _results(journal, "catch")
    assert catches[0][:2] == ("error", "stream_lost")
    dog = catches[0][3]["watchdog"]
    assert dog["stale_s"] > 0.2 and 0.0 <= dog["stop_s"] < 1.0, dog  # braked to rest at QDD_MAX: < 0.3 s
    assert catches[1][0] in ("success", "failure") and catches[1][3]["set_points"] > 0, catches[1]
    assert (catches[2][0], catches[2][1]) == ("error", "bus"), catches[2]
    # the drives' watchdog: RPDO timeout, each moving joint at rest within the timeout plus v / QDD_MAX
    assert fault["code"] == "0x8250" and fault["stop_s"] <= fault["speed"] / 10.0 + 0.01, fault
    homes = _results(journal, "home")
    assert homes[-1][0] == "success"
    recovered = [h[3].get("recovered") for h in homes if h[0] == "success"]
    assert any(r and ("fault reset" in r or "reconnected" in r) for r in recovered), homes
