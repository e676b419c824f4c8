"""`petrobot demo` never loses a journal: a demo that cannot start leaves the previous journal where
it was and says why, with the log to read; a demo that starts keeps the previous journal under a
name of its own and says where (real processes: the demo, its simulator, its nodes)."""

from __future__ import annotations

import re
import secrets
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from tests.integration.cluster import ROOT, free_port

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


def _demo(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    key = cwd / "key"
    if not key.exists():
        key.write_text(secrets.token_hex(32) + "\n")
        key.chmod(0o600)
    return subprocess.run([sys.executable, "-m", "coordinator.cli", "demo", *args, "--key-file", str(key)],
                          cwd=cwd, capture_output=True, text=True, timeout=200, stdin=subprocess.DEVNULL)


def test_a_demo_whose_simulator_cannot_start_keeps_the_previous_journal_and_names_the_cause_and_the_log(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        services = tmp_path / "services.toml"
        services.write_text((ROOT / "services.toml").read_text().replace("7210", str(port)))
        previous = tmp_path / "runs" / "catching.sqlite"
        previous.parent.mkdir()
        previous.write_bytes(b"the previous demo's journal")
        done = _demo(tmp_path, "--services", str(services), "--renderer", "analytic")
    assert done.returncode == 2, done.stderr
    assert "Address already in use" in done.stderr
    assert str(Path("runs") / "logs" / "sim.log") in done.stderr
    assert previous.read_bytes() == b"the previous demo's journal"
    assert sorted(p.name for p in previous.parent.iterdir() if p.is_file()) == ["catching.sqlite"]


def test_a_demo_keeps_the_previous_journal_under_a_name_of_its_own_and_says_where(tmp_path):
    services = tmp_path / "services.toml"
    services.write_text((ROOT / "services.toml").read_text().replace("7101", str(free_port()))
                        .replace("7102", str(free_port())))
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "demo.sqlite").write_bytes(b"the first journal")
    (runs / "demo.prev.sqlite").write_bytes(b"an older one")
    done = _demo(tmp_path, "foundation", "--services", str(services))
    assert done.returncode == 0, done.stderr
    kept = re.search(r"previous journal kept as (\S+\.sqlite)", done.stderr)
    assert kept is not None, done.stderr
    assert (tmp_path / kept.group(1)).read_bytes() == b"the first journal"
    assert (runs / "demo.prev.sqlite").read_bytes() == b"an older one"
    assert (runs / "demo.sqlite").read_bytes()[:16] == b"SQLite format 3\x00"
