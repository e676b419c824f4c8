"""`petrobot up` as the README's typical session uses it: the nodes that need no simulator start,
the others are named with the reason, a node that exits is reported while the others go on, and
the node logs go to files (real processes on 127.0.0.1)."""

from __future__ import annotations

import asyncio
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from tests.integration.cluster import ROOT, Cluster

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {port[alpha]}

[nodes.beta]
host = "127.0.0.1"
port = {port[beta]}

[nodes.vision]
host = "127.0.0.1"
port = {port[vision]}

[memory]
node = "alpha"

[actions.wait]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.coin]
node = "alpha"
impl = "services.actions.demo:coin"

[actions.compute_primes]
node = "beta"
impl = "services.actions.demo:ComputePrimes"

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = {{ port = {port[camera]}, connect_timeout_s = 1.0 }}

[actions.locate_threshold]
node = "vision"
impl = "services.catching.vision_node:LocateThreshold"
"""


class Up:
    """`python -m coordinator.cli up ...` in ``cwd``, its stderr lines read by a thread."""

    def __init__(self, cluster: Cluster, cwd: Path, *names: str) -> None:
        cmd = [sys.executable, "-m", "coordinator.cli", "up", *names, "--services", str(cluster.services_path),
               "--key-file", str(cluster.key_file)]
        self.proc = subprocess.Popen(cmd, cwd=cwd, env=cluster.env(), stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, text=True, start_new_session=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.put(line.rstrip())

    def wait_line(self, text: str, timeout: float = 60.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.lines.get(timeout=max(0.01, end - time.monotonic()))
            except queue.Empty:
                break
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f"up said no {text!r} within {timeout} s:\n" + "\n".join(self.seen))

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        return self.proc.wait(timeout=30)


def _petrobot(cluster: Cluster, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coordinator.cli", *args], cwd=cwd, env=cluster.env(),
                          capture_output=True, text=True, timeout=90, stdin=subprocess.DEVNULL, check=False)


async def _call(cluster: Cluster, action: str, params: dict[str, Any]) -> Any:
    async with cluster.client() as client:
        return await client.call(action, params, deadline_s=20.0)


def _node_pid(cluster: Cluster, name: str) -> int:
    found = subprocess.run(["pgrep", "-f", f"services.node {name} --services {cluster.services_path}"],
                           capture_output=True, text=True, check=False)
    pids = [int(p) for p in found.stdout.split()]
    assert len(pids) == 1, found
    return pids[0]


def test_up_starts_the_nodes_that_need_no_simulator_and_the_readme_session_runs(cluster: Cluster, tmp_path: Path):
    cluster.write_services(SERVICES)
    up = Up(cluster, tmp_path)
    try:
        refused = up.wait_line("not starting node vision")
        assert f"camera server 127.0.0.1:{cluster.ports['camera']}" in refused and "petrobot sim catching" in refused
        up.wait_line("node alpha listening")
        up.wait_line("node beta listening")
        up.wait_line("2 node(s) running")
        checked = _petrobot(cluster, tmp_path, "check", str(ROOT / "nets" / "demo.toml"),
                            "--services", str(cluster.services_path))
        assert checked.returncode == 0, checked.stdout + checked.stderr
        ran = _petrobot(cluster, tmp_path, "run", str(ROOT / "nets" / "demo.toml"), "--services",
                        str(cluster.services_path), "--journal", str(tmp_path / "j.sqlite"), "--lines")
        assert ran.returncode == 0, ran.stdout + ran.stderr
        assert "completed after" in ran.stdout
        logs = tmp_path / "runs" / "logs"
        assert "node alpha listening on" in (logs / "alpha.log").read_text()
        assert " coin from " in (logs / "alpha.log").read_text()  # the calls are logged there, not on screen
        assert not (logs / "vision.log").exists()
        # one node exits: it is reported and the other goes on
        os.kill(_node_pid(cluster, "alpha"), signal.SIGKILL)
        gone = up.wait_line("node alpha exited")
        assert "still running: beta" in gone
        assert asyncio.run(_call(cluster, "compute_primes", {"n": 1000})).status == "success"  # beta answers
    finally:
        code = up.stop()
    assert code == 0
    assert "all nodes stopped" in "\n".join(up.seen) or up.wait_line("all nodes stopped", 10.0)


def test_a_named_node_is_started_anyway_and_up_ends_when_no_node_is_left(cluster: Cluster, tmp_path: Path):
    cluster.write_services(SERVICES)
    up = Up(cluster, tmp_path, "vision")
    try:
        failed = up.wait_line("node vision did not start")
        assert "camera" in failed and "unreachable" in failed
        assert up.proc.wait(timeout=30) == 1
    finally:
        up.stop()
    assert (tmp_path / "runs" / "logs" / "vision.log").exists()
