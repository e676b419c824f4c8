"""Real node processes on 127.0.0.1 for the integration tests (the ``cluster`` fixture of
tests/integration/conftest.py gives one per test, and modules import from here).

A :class:`Cluster` can write a services.toml whose ports are picked free
(``{port[NAME]}`` placeholders), start ``python -m services.node NAME --services FILE`` processes,
wait until each accepts TCP connections, kill/stop/restart them, read their logs, and build clients;
:meth:`Cluster.close` kills every process. Example::

    async def test_something(cluster):
        cluster.write_services(DEMO_SERVICES)     # or any text with {port[alpha]} placeholders
        cluster.start("alpha", "beta")
        async with cluster.client() as client:
            res = await client.call("echo", {"x": 1})
"""

from __future__ import annotations

import contextlib
import os
import resource
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from services.client import ServiceClient
from services.location import Location, load_location
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[2]

DEMO_SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {port[alpha]}
max_in_flight = 8

[nodes.beta]
host = "127.0.0.1"
port = {port[beta]}
max_in_flight = 8

[memory]
node = "alpha"

[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"

[actions.wait]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.tally]
node = "alpha"
impl = "services.actions.demo:tally"

[actions.fail]
node = "alpha"
impl = "services.actions.demo:fail"

[actions.private_echo]
node = "alpha"
impl = "services.actions.demo:echo"
local_only = true

[actions.compute_primes]
node = "beta"
impl = "services.actions.demo:ComputePrimes"
params = {{ n = 100000 }}

[actions.remember]
node = "beta"
impl = "services.actions.demo:remember"

[actions.slow]
node = "beta"
impl = "services.actions.demo:wait"

[actions.announce]
node = "beta"
impl = "services.actions.demo:announce"

[drivers.ticker]
node = "beta"
impl = "services.actions.demo:Ticker"
params = {{ period_s = 0.05 }}

[events.tick]
node = "beta"

[events.shout]
node = "beta"
"""
"""A two-node layout of the demo actions (``alpha`` with memory, ``beta`` with a ticker driver)."""


class Cluster:
    """Node processes for one test (see the module docstring)."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.key_hex = secrets.token_hex(32)
        self.key = bytes.fromhex(self.key_hex)
        self.key_file = tmp / "key"
        self.key_file.write_text(self.key_hex + "\n")
        self.services_path = tmp / "services.toml"
        self.ports: defaultdict[str, int] = defaultdict(free_port)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: dict[str, Path] = {}
        self._location: Location | None = None

    # ---- configuration

    def write_services(self, text: str = DEMO_SERVICES) -> Path:
        """Write services.toml from ``text``; ``{port[NAME]}`` becomes a free port per NAME."""
        self.services_path.write_text(text.format(port=self.ports))
        self._location = None
        return self.services_path

    @property
    def location(self) -> Location:
        """The parsed services.toml."""
        if self._location is None:
            self._location = load_location(self.services_path)
        return self._location

    def env(self) -> dict[str, str]:
        """Environment for child processes (key file, import path, the nodes' state under ``tmp``)."""
        env = dict(os.environ)
        env.pop("PETROBOT_KEY", None)
        env["PETROBOT_KEY_FILE"] = str(self.key_file)
        env["XDG_STATE_HOME"] = str(self.tmp / "state")  # each test's nodes keep results of their own
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        return env

    # ---- processes

    def start(self, *names: str, timeout: float = 15.0, max_open_files: int | None = None) -> None:
        """Start nodes ``names`` and wait until each accepts connections; with ``max_open_files``,
        each node's soft RLIMIT_NOFILE is set to it."""
        if not self.services_path.exists():
            self.write_services()
        hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]

        def limit() -> None:  # in the child, before the node starts
            if max_open_files is not None:
                resource.setrlimit(resource.RLIMIT_NOFILE, (max_open_files, hard))

        for name in names:
            log = self.tmp / f"{name}.log"
            self._logs[name] = log
            with open(log, "ab") as fh:
                self.procs[name] = subprocess.Popen(
                    [sys.executable, "-m", "services.node", name, "--services", str(self.services_path),
                     "--key-file", str(self.key_file)],
                    cwd=ROOT, env=self.env(), stdout=fh, stderr=subprocess.STDOUT,
                    preexec_fn=None if max_open_files is None else limit,  # noqa: PLW1509
                )
        for name in names:
            self.wait_listening(name, timeout)

    def wait_listening(self, name: str, timeout: float = 15.0) -> None:
        """Block until node ``name`` accepts a TCP connection (fail if it exits first)."""
        host, port = self.location.address(name)
        end = time.monotonic() + timeout
        proc = self.procs[name]
        while time.monotonic() < end:
            if proc.poll() is not None:
                raise RuntimeError(f"node {name} exited with {proc.returncode}:\n{self.log(name)}")
            try:
                with socket.create_connection((host, port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError(f"node {name} not listening after {timeout} s:\n{self.log(name)}")

    def kill(self, name: str, sig: int = signal.SIGKILL) -> None:
        """Send ``sig`` (default SIGKILL) to node ``name`` and, unless it is SIGSTOP, reap it."""
        proc = self.procs[name]
        proc.send_signal(sig)
        if sig not in (signal.SIGSTOP, signal.SIGCONT):
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)

    def stop(self, name: str) -> int:
        """SIGTERM node ``name``; return its exit code (it must exit within 10 s)."""
        proc = self.procs[name]
        proc.send_signal(signal.SIGTERM)
        return proc.wait(timeout=10)

    def restart(self, name: str) -> None:
        """Kill (if running) and start node ``name`` again on the same port."""
        if name in self.procs and self.procs[name].poll() is None:
            self.kill(name)
        self.start(name)

    def log(self, name: str) -> str:
        """Everything node ``name`` wrote to stdout/stderr so far."""
        path = self._logs.get(name)
        return path.read_text(errors="replace") if path and path.exists() else ""

    def client(self, **kwargs: Any) -> ServiceClient:
        """A ServiceClient on this cluster's services.toml and key."""
        return ServiceClient(self.location, self.key, **kwargs)

    def close(self) -> None:
        """Kill every node still running."""
        for proc in self.procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):  # it ended in between
                    proc.send_signal(signal.SIGCONT)
                    proc.kill()
        for proc in self.procs.values():
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=5)
