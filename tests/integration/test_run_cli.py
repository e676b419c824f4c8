"""`petrobot run` as a user runs it: the README's example on a terminal, Ctrl-C and --resume, the
deadline of a net that cycles without events, a run that only an absent operator could move on
(real processes: the coordinator's CLI, and node processes when the net calls actions)."""

from __future__ import annotations

import os
import pty
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from coordinator.journal import JournalReader

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 90.0  # generous bound of every wait

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {port[alpha]}

[nodes.beta]
host = "127.0.0.1"
port = {port[beta]}

[memory]
node = "alpha"

[actions.coin]
node = "alpha"
impl = "services.actions.demo:coin"

[actions.wait]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.compute_primes]
node = "beta"
impl = "services.actions.demo:ComputePrimes"

[actions.slow]
node = "beta"
impl = "services.actions.demo:wait"
"""

CYCLE = """
[net]
name = "cycle"

[[place]]
id = "a"
tokens = 1

[[place]]
id = "b"

[[transition]]
id = "there"
inputs = { a = 1 }
outputs = { b = 1 }

[[transition]]
id = "back"
inputs = { b = 1 }
outputs = { a = 1 }
"""

GATED = """
[net]
name = "gated"

[[place]]
id = "gate"
kind = "control"

[[place]]
id = "ready"
kind = "resource"
tokens = 1

[[place]]
id = "mid"

[[place]]
id = "done"

[[transition]]
id = "go"
inputs = { ready = 1 }
outputs = { mid = 1 }

[[transition]]
id = "finish"
inputs = { mid = 1, gate = 1 }
outputs = { done = 1 }
"""

SLOW = """
[net]
name = "slow_runs"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "robot"
kind = "resource"
tokens = 1

[[place]]
id = "working"
kind = "primitive_task"
task = "work"

[[place]]
id = "done"

[task.work]
actions = [{ name = "slow", params = { seconds = 3.0 } }]
deadline_s = 30.0

[[transition]]
id = "start"
inputs = { runs = 1, robot = 1 }
outputs = { working = 1 }

[[transition]]
id = "worked"
events = ["int:work.ok"]
inputs = { working = 1 }
outputs = { robot = 1, done = 1 }

[[transition]]
id = "failed"
events = ["int:work.error"]
hidden = true
inputs = { working = 1 }
outputs = { robot = 1, done = 1 }
"""


class Output:
    """Collects a process's merged output in a thread; tests wait for a line to appear."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        self._cond = threading.Condition()
        assert proc.stdout is not None
        self._thread = threading.Thread(target=self._pump, args=(proc.stdout,), daemon=True)
        self._thread.start()

    def _pump(self, stream: Any) -> None:
        for line in stream:
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()

    def wait_for(self, text: str, *, after: int = 0) -> int:
        """Index of the first line from ``after`` that contains ``text`` (fails after TIMEOUT_S)."""
        end = time.monotonic() + TIMEOUT_S
        with self._cond:
            while True:
                for i in range(after, len(self.lines)):
                    if text in self.lines[i]:
                        return i
                left = end - time.monotonic()
                assert left > 0, f"no line with {text!r} in:\n{self.text}"
                self._cond.wait(left)

    @property
    def text(self) -> str:
        return "".join(self.lines)


def petrobot(cluster: Any, *args: str, **kwargs: Any) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "coordinator.cli", *args, "--services", str(cluster.services_path),
           "--key-file", str(cluster.key_file)]
    kwargs.setdefault("stdin", subprocess.DEVNULL)
    return subprocess.Popen(cmd, cwd=ROOT, env=cluster.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, **kwargs)


def test_the_readme_example_waits_on_a_terminal_for_more_runs_and_ends_on_end(cluster: Any, tmp_path: Path):
    """README: `petrobot run nets/demo.toml`, then type "+ runs_remaining 2"."""
    cluster.write_services(SERVICES)
    cluster.start("alpha", "beta")
    journal = tmp_path / "j.sqlite"
    master, slave = pty.openpty()
    try:
        proc = petrobot(cluster, "run", "nets/demo.toml", "--journal", str(journal), "--lines", stdin=slave)
        os.close(slave)
        out = Output(proc)
        first = out.wait_for("waiting: completed: at the home marking")
        assert "+ runs_remaining 1 would enable start_run" in out.text
        os.write(master, b"+ runs_remaining 2\n")
        applied = out.wait_for("operator insert runs_remaining 2", after=first)
        out.wait_for("waiting: completed: at the home marking", after=applied)
        os.write(master, b"end\n")
        assert proc.wait(timeout=TIMEOUT_S) == 0, out.text
    finally:
        os.close(master)
    with JournalReader.open(journal) as reader:
        (run,) = reader.runs()
        assert run.end_state == "completed"
        assert [(c.command, c.place, c.count) for c in reader.operator_commands()] == [
            ("insert", "runs_remaining", 2), ("end", None, None)]
        assert sum(1 for f in reader.firings() if f.transition == "start_run") == 5


def test_a_run_interrupted_with_ctrl_c_resumes_where_it_stopped(cluster: Any, tmp_path: Path):
    cluster.write_services(SERVICES)
    cluster.start("alpha", "beta")
    net = tmp_path / "slow.toml"
    net.write_text(SLOW)
    journal = tmp_path / "j.sqlite"
    proc = petrobot(cluster, "run", str(net), "--journal", str(journal), "--lines")
    out = Output(proc)
    out.wait_for("start work -> slow on beta")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=TIMEOUT_S) == 130, out.text
    assert "resume with --resume" in out.text
    with JournalReader.open(journal) as reader:
        (run,) = reader.runs()
        assert run.end_state == "interrupted"
    again = petrobot(cluster, "run", str(net), "--journal", str(journal), "--lines", "--resume")
    rest = Output(again)
    assert again.wait(timeout=TIMEOUT_S) == 0, rest.text
    assert f"run {run.id} resumed" in rest.text
    # the interrupted call was cancelled on its node, and its result is kept: the resumed run gets
    # it at once, never waiting out the call's deadline (the node ends a call cancelled before it started)
    assert "no answer from node" not in rest.text and "not reconciled" not in rest.text, rest.text
    with JournalReader.open(journal) as reader:
        (resumed,) = reader.runs()
        assert (resumed.id, resumed.end_state) == (run.id, "completed")
        assert [f.transition for f in reader.firings()].count("start") == 2


def test_a_net_cycling_without_events_ends_on_max_seconds(cluster: Any, tmp_path: Path, record_property: Any):
    cluster.write_services(SERVICES)
    net = tmp_path / "cycle.toml"
    net.write_text(CYCLE)
    journal = tmp_path / "j.sqlite"
    proc = petrobot(cluster, "run", str(net), "--journal", str(journal), "--quiet", "--max-seconds", "2")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 4, out.text
    with JournalReader.open(journal) as reader:
        (stats,) = reader.run_stats()
    record_property("deadline_late_s", round(stats.duration_s - 2.0, 4))  # measured, not asserted
    assert stats.run.end_state == "deadline" and stats.firings > 0
    assert "deadline after" in out.text and "--max-seconds 2 ran out" in out.text


def test_without_a_terminal_a_run_only_the_operator_could_move_on_ends_and_says_what_it_needed(
        cluster: Any, tmp_path: Path):
    cluster.write_services(SERVICES)
    net = tmp_path / "gated.toml"
    net.write_text(GATED)
    proc = petrobot(cluster, "run", str(net), "--journal", str(tmp_path / "j.sqlite"), "--lines")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 3, out.text
    assert "waiting_for_operator" in out.text and "+ gate 1 would enable finish" in out.text


STUCK = """
[net]
name = "stuck"

[[place]]
id = "a"
tokens = 1

[[place]]
id = "b"

[[place]]
id = "c"

[[place]]
id = "out"

[[transition]]
id = "first"
inputs = { a = 1 }
outputs = { b = 1 }

[[transition]]
id = "second"
inputs = { b = 1, c = 1 }
outputs = { out = 1 }
"""


def test_a_run_ending_with_tokens_away_from_home_exits_non_zero_and_names_the_places(cluster: Any, tmp_path: Path):
    cluster.write_services(SERVICES)
    net = tmp_path / "stuck.toml"
    net.write_text(STUCK)
    proc = petrobot(cluster, "run", str(net), "--journal", str(tmp_path / "j.sqlite"), "--quiet")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 1, out.text
    assert "stuck after 1 firings" in out.text
    assert "a: 0 tokens (home 1)" in out.text and "b: 1 token (home 0)" in out.text


def test_a_run_whose_nodes_are_not_running_is_refused_before_its_first_firing_and_journals_nothing(
        cluster: Any, tmp_path: Path):
    """Before: the whole net played on "unreachable" errors and exited 0."""
    cluster.write_services(SERVICES)  # no node started
    net = tmp_path / "slow.toml"
    net.write_text(SLOW)
    journal = tmp_path / "j.sqlite"
    proc = petrobot(cluster, "run", str(net), "--journal", str(journal), "--lines")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 2, out.text
    host, port = cluster.location.address("beta")
    assert "the nodes are not ready for this net (1 problem); nothing was run (--degraded starts anyway)" in out.text
    assert f"  - node beta at {host}:{port} is unreachable: " in out.text
    assert "fire" not in out.text
    with JournalReader.open(journal) as reader:
        assert reader.runs() == []


def test_a_run_refuses_nodes_started_before_services_toml_was_edited_and_says_which(cluster: Any, tmp_path: Path):
    """Before: calls failed with unknown_action and the net took its error branch, exit status 0."""
    cluster.write_services(SERVICES)
    cluster.start("alpha", "beta")
    moved = cluster.services_path.read_text().replace('[actions.slow]\nnode = "beta"', '[actions.slow]\nnode = "alpha"')
    cluster.services_path.write_text(moved)  # the nodes still run the old placement
    net = tmp_path / "slow.toml"
    net.write_text(SLOW)
    journal = tmp_path / "j.sqlite"
    proc = petrobot(cluster, "run", str(net), "--journal", str(journal), "--lines")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 2, out.text
    assert "node alpha does not offer 'slow'" in out.text
    assert "node alpha's services.toml changed on disk since it started: restart it" in out.text
    with JournalReader.open(journal) as reader:
        assert reader.runs() == []


def test_with_degraded_a_run_starts_without_its_nodes_and_exits_non_zero_when_every_call_errored(
        cluster: Any, tmp_path: Path):
    cluster.write_services(SERVICES)  # no node started
    net = tmp_path / "slow.toml"
    net.write_text(SLOW)
    journal = tmp_path / "j.sqlite"
    proc = petrobot(cluster, "run", str(net), "--journal", str(journal), "--lines", "--degraded")
    out = Output(proc)
    assert proc.wait(timeout=TIMEOUT_S) == 6, out.text
    assert "petrobot: starting degraded: node beta at " in out.text
    assert "every one of the 2 primitive-action calls ended in error" in out.text
    with JournalReader.open(journal) as reader:
        (run,) = reader.runs()
        assert run.end_state == "completed" and reader.reconciliations() == []  # the calls never left
