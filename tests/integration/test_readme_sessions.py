"""The README's hand-run sessions, as a new user types them: `petrobot sim catching &`, `petrobot up &`,
`petrobot run nets/catch.toml`, and for the mobile robot `petrobot sim mobile &`,
`petrobot up perception drive &`, `petrobot run nets/mobile.toml`.

The commands are taken word for word from the README (the test fails if the README changes them) and
run as real processes with the project's services.toml and nets, in a fresh directory with a fresh
home (a new shared key is made on first use, as for a new user). The project's services.toml uses
fixed ports, so each session runs in a network namespace of its own (its own loopback: nothing else
on the machine can hold those ports); like a user, the test waits for each background command to say
it is ready before typing the next. Needs root (`ip netns add`); elsewhere it skips, saying why.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from tests.integration.cluster import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.netns, pytest.mark.timeout(480)]

PETROBOT = Path(sys.executable).parent / "petrobot"
SESSIONS = {
    "catching": ("petrobot sim catching &", "petrobot up &", "petrobot run nets/catch.toml"),
    "mobile": ("petrobot sim mobile &", "petrobot up perception drive &", "petrobot run nets/mobile.toml"),
}
NODES = {"catching": 4, "mobile": 2}


def _readme_says(command: str) -> bool:
    text = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    return f"`{command}`" in text


class Session:
    """A user's shell in a network namespace of its own: background commands and their output."""

    def __init__(self, tmp: Path) -> None:
        self.ns = f"pbreadme{os.getpid() % 100000}"
        self.cwd = tmp / "project"
        self.cwd.mkdir()
        shutil.copy(ROOT / "services.toml", self.cwd / "services.toml")
        shutil.copytree(ROOT / "nets", self.cwd / "nets")
        shutil.copytree(ROOT / "devices", self.cwd / "devices")  # services.toml names its device files
        (tmp / "home").mkdir()
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("PETROBOT_")}
        self.env["HOME"] = str(tmp / "home")
        self.procs: list[subprocess.Popen[str]] = []
        self.lines: dict[int, queue.Queue[str]] = {}
        self.seen: dict[int, list[str]] = {}

    def __enter__(self) -> Session:
        for cmd in (("netns", "add", self.ns), ("-n", self.ns, "link", "set", "lo", "up")):
            done = subprocess.run(["ip", *cmd], capture_output=True, text=True, timeout=20)
            if done.returncode != 0:
                raise RuntimeError(f"ip {' '.join(cmd)}: {done.stderr.strip()}")
        return self

    def __exit__(self, *exc: object) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)
        subprocess.run(["ip", "netns", "del", self.ns], capture_output=True, timeout=20)

    def _argv(self, command: str) -> list[str]:
        words = command.removesuffix("&").split()
        assert words[0] == "petrobot"
        return ["ip", "netns", "exec", self.ns, str(PETROBOT), *words[1:]]

    def background(self, command: str) -> int:
        """Start ``command`` (ending in ``&``) as a shell would; returns its handle."""
        proc = subprocess.Popen(self._argv(command), cwd=self.cwd, env=self.env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
        self.procs.append(proc)
        n = len(self.procs) - 1
        self.lines[n], self.seen[n] = queue.Queue(), []

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                self.lines[n].put(line.rstrip())

        threading.Thread(target=read, daemon=True).start()
        return n

    def wait_for(self, n: int, what: str, pattern: str, timeout_s: float = 240.0) -> str:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            try:
                line = self.lines[n].get(timeout=0.5)
            except queue.Empty:
                if self.procs[n].poll() is not None and self.lines[n].empty():
                    break
                continue
            self.seen[n].append(line)
            if re.search(pattern, line):
                return line
        raise AssertionError(f"{what}: not seen; output so far:\n" + "\n".join(self.seen[n][-30:]))

    def still_running(self, n: int) -> bool:
        return self.procs[n].poll() is None

    def foreground(self, command: str, timeout_s: float = 360.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run(self._argv(command), cwd=self.cwd, env=self.env, stdin=subprocess.DEVNULL,
                              capture_output=True, text=True, timeout=timeout_s)

    def log(self, name: str) -> str:
        path = self.cwd / "runs" / "logs" / f"{name}.log"
        return path.read_text(errors="replace")[-3000:] if path.exists() else f"(no {path})"


@pytest.fixture
def session(tmp_path: Path) -> Iterator[Session]:
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("needs root and iproute2 to give the session a network namespace of its own")
    if not PETROBOT.exists():
        pytest.skip(f"no {PETROBOT}: petrobot is not installed in this environment")
    with Session(tmp_path) as s:
        yield s


@pytest.mark.parametrize("testbed", ["catching", "mobile"])
def test_the_readme_hand_run_session_works_as_written(testbed: str, session: Session) -> None:
    sim_cmd, up_cmd, run_cmd = SESSIONS[testbed]
    for command in SESSIONS[testbed]:
        assert _readme_says(command), f"the README no longer says `{command}`"
    sim = session.background(sim_cmd)
    ready = json.loads(session.wait_for(sim, sim_cmd, r'^\{"event": "ready"'))
    assert (ready["camera_port"], ready["can_port"]) == ((7210, 7211) if testbed == "catching" else (7220, 7221))
    up = session.background(up_cmd)
    session.wait_for(up, up_cmd, rf"up: {NODES[testbed]} node\(s\) running")
    done = session.foreground(run_cmd)
    out = done.stdout + done.stderr
    diagnosis = f"{out[-4000:]}\n--- up:\n" + "\n".join(session.seen[up][-20:])
    for name in ("motion", "vision") if testbed == "catching" else ("drive", "perception"):
        diagnosis += f"\n--- {name}.log:\n{session.log(name)}"
    assert done.returncode == 0, diagnosis
    assert "completed" in out, diagnosis
    assert "no socketcand server" not in out and "unreachable" not in out, diagnosis
    assert session.still_running(sim), "the simulator died during the session"
    assert session.still_running(up), "petrobot up ended during the session"
    assert not [line for line in session.seen[up] if "exited with status" in line], session.seen[up]
