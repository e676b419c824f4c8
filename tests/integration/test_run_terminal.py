"""`petrobot run` in a real terminal (tmux): the live view and the operator's input line.

The README's session (`petrobot run nets/demo.toml`, then typed commands) runs in a tmux pane of
120 × 40 cells; the test types into it with ``send-keys`` and reads the screen with
``capture-pane``, and ``pipe-pane`` records every byte the run writes to the terminal. A view that
redraws what did not change, wipes a half-typed command, refuses an arrow key as a command, floods
the scrollback or shows ``waiting`` while paused fails here.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from coordinator.commands.run import console_address_file
from coordinator.journal import JournalReader
from tests.integration.test_run_cli import SERVICES  # the README example's two nodes

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 90.0  # generous bound of every wait: a failing test fails, a loaded machine passes

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300),
              pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (apt-get install tmux)")]


class Pane:
    """One tmux pane (its own tmux server) running a command."""

    def __init__(self, tmp: Path, command: list[str], env: dict[str, str]) -> None:
        self.socket = tmp / "tmux.sock"
        self.bytes_log = tmp / "pane.bytes"
        self.rc_file = tmp / "rc"
        self.env = {k: v for k, v in env.items() if not k.startswith("TMUX")}
        self.env["TERM"] = "xterm-256color"
        shell = f"cd {shlex.quote(str(ROOT))} && {shlex.join(command)}; echo $? > {shlex.quote(str(self.rc_file))}"
        self.tmux("-f", "/dev/null", "new-session", "-d", "-s", "t", "-x", "120", "-y", "40", "sh", "-c", shell)
        self.tmux("set-option", "-t", "t", "remain-on-exit", "on")
        self.tmux("pipe-pane", "-t", "t", "-o", f"cat >> {shlex.quote(str(self.bytes_log))}")

    def tmux(self, *args: str) -> str:
        done = subprocess.run(["tmux", "-S", str(self.socket), *args], env=self.env, capture_output=True, text=True,
                              timeout=30)
        assert done.returncode == 0, f"tmux {' '.join(args)}: {done.stderr}"
        return done.stdout

    def screen(self) -> str:
        return self.tmux("capture-pane", "-p", "-t", "t")

    def lines(self) -> list[str]:
        return [line.rstrip() for line in self.screen().splitlines()]

    def keys(self, *keys: str) -> None:
        """Named keys (``End``, ``Left``, ``Enter``...)."""
        self.tmux("send-keys", "-t", "t", *keys)

    def type(self, text: str) -> None:
        """Literal text, as typed."""
        self.tmux("send-keys", "-t", "t", "-l", text)

    def history(self) -> int:
        """Lines in the pane's scrollback."""
        return int(self.tmux("display-message", "-p", "-t", "t", "#{history_size}").strip())

    def written(self) -> int:
        """Bytes the command has written to the terminal so far."""
        return self.bytes_log.stat().st_size if self.bytes_log.exists() else 0

    def wait(self, what: str, test: Callable[[str], bool]) -> str:
        end = time.monotonic() + TIMEOUT_S
        while True:
            screen = self.screen()
            if test(screen):
                return screen
            if time.monotonic() > end:
                raise AssertionError(f"waited {TIMEOUT_S:.0f} s for {what}; the screen:\n{screen}")
            time.sleep(0.1)

    def wait_for(self, text: str) -> str:
        return self.wait(repr(text), lambda screen: text in screen)

    def exit_code(self) -> int:
        end = time.monotonic() + TIMEOUT_S
        while not self.rc_file.exists() or not self.rc_file.read_text().strip():
            assert time.monotonic() < end, f"the command did not end; the screen:\n{self.screen()}"
            time.sleep(0.1)
        return int(self.rc_file.read_text())

    def close(self) -> None:
        subprocess.run(["tmux", "-S", str(self.socket), "kill-server"], env=self.env, capture_output=True, timeout=30)


@pytest.fixture
def pane_for(cluster: Any, tmp_path: Path) -> Iterator[Callable[..., Pane]]:
    panes: list[Pane] = []

    def start(*args: str) -> Pane:
        cluster.write_services(SERVICES)
        cluster.start("alpha", "beta")
        command = [sys.executable, "-m", "coordinator.cli", *args, "--services", str(cluster.services_path),
                   "--key-file", str(cluster.key_file)]
        pane = Pane(tmp_path, command, cluster.env())
        panes.append(pane)
        return pane

    yield start
    for pane in panes:
        pane.close()


def _header(screen: str) -> str:
    return next((line for line in screen.splitlines() if line.startswith("petrobot  net")), "")


def test_typing_into_the_live_view_keeps_the_line_ignores_escape_keys_and_shows_paused(pane_for: Any,
                                                                                      tmp_path: Path):
    journal = tmp_path / "j.sqlite"
    pane = pane_for("run", "nets/demo.toml", "--journal", str(journal))
    pane.wait("the run waiting at home for the operator",
              lambda s: "state waiting" in _header(s) and "+ runs_remaining 1 would enable start_run" in s)

    pane.type("+ runs_rem")
    pane.wait("the half-typed command echoed", lambda s: s.rstrip().endswith("> + runs_rem"))
    before = pane.written()
    time.sleep(1.5)  # a run at rest: nothing changes, so nothing is redrawn
    assert pane.written() - before < 64, "the view wrote to the terminal while nothing changed"
    assert pane.screen().rstrip().endswith("> + runs_rem"), "the half-typed command vanished"

    pane.keys("Left", "Left", "Home", "End", "Right", "Up", "Down", "End")  # escape sequences
    pane.wait("the line as typed after the cursor keys", lambda s: s.rstrip().endswith("> + runs_rem"))
    pane.type("aining 2")
    pane.keys("Enter")
    pane.wait_for("applied: insert runs_remaining 2")

    pane.type("pause")
    pane.keys("Enter")
    pane.wait("the header saying paused", lambda s: "state paused" in _header(s))
    pane.type("+ runs_remaining 1")
    pane.keys("Enter")
    screen = pane.wait_for("applied: insert runs_remaining 1")
    pane.wait("the run at rest while paused", lambda s: "paused: resume" in s)
    assert "state paused" in _header(pane.screen()), pane.screen()
    pane.type("resume")
    pane.keys("Enter")
    pane.wait("the run back at home after its three more runs",
              lambda s: "state waiting" in _header(s) and "at the home marking" in s)
    assert pane.history() == 0, "the live view pushed lines into the terminal's scrollback"
    pane.type("end")
    pane.keys("Enter")
    assert pane.exit_code() == 0, pane.screen()

    with JournalReader.open(journal) as reader:
        commands = reader.operator_commands()
        assert [(c.command, c.place, c.count, c.accepted) for c in commands] == [
            ("insert", "runs_remaining", 2, True), ("pause", None, None, True),
            ("insert", "runs_remaining", 1, True), ("resume", None, None, True), ("end", None, None, True)]
        assert sum(1 for f in reader.firings() if f.transition == "start_run") == 6
    assert screen  # the screen read after the insertion while paused


def test_run_with_the_web_console_keeps_its_address_on_screen_and_in_a_file_beside_the_journal(
        pane_for: Any, tmp_path: Path):
    journal = tmp_path / "j.sqlite"
    pane = pane_for("run", "nets/demo.toml", "--journal", str(journal), "--console", "0")
    screen = pane.wait("the address in the live view", lambda s: "web console: http://127.0.0.1:" in s)
    url = next(line.split("web console: ")[1].strip() for line in screen.splitlines() if "web console: " in line)
    assert "?token=" in url
    address = console_address_file(journal)
    assert address.read_text(encoding="utf-8").strip() == url
    assert oct(address.stat().st_mode & 0o777) == oct(0o600), "the file holds the token: owner only"
    pane.wait("the run waiting at home", lambda s: "state waiting" in _header(s))
    assert f"web console: {url}" in pane.screen(), "a redraw wiped the address"
    pane.type("end")
    pane.keys("Enter")
    assert pane.exit_code() == 0, pane.screen()
    assert not address.exists(), "the address of a console that has closed was left behind"
    assert os.path.exists(journal)
