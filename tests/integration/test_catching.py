"""The catching task net end to end: simulator, vision node, motion node and coordinator, each a
separate process on 127.0.0.1 (the README's main job, `petrobot demo catching`)."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from coordinator.journal import JournalReader
from coordinator.rosbag import export_run
from waiting import file_says

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]

SERVICES = """
[nodes.vision]
host = "127.0.0.1"
port = {port[vision]}

[nodes.motion]
host = "127.0.0.1"
port = {port[motion]}

[drivers.camera]
node = "vision"
impl = "services.catching.vision_node:CameraDriver"
params = {{ port = {port[camera]} }}

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
node = "PREDICT_NODE"
impl = "services.catching.vision_node:Predict"
params = {{ camera_port = {port[camera]} }}

[events.image_sampling_tick]
node = "vision"

[drivers.puma]
node = "motion"
impl = "services.catching.arm:PumaDriver"
params = {{ can_port = {port[can]} }}

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


def demo(cluster: Any, tmp_path: Path, runs: int, predict_node: str = "vision", seed: int = 1) -> subprocess.Popen[str]:
    cluster.write_services(SERVICES.replace("PREDICT_NODE", predict_node))
    cmd = [sys.executable, "-m", "coordinator.cli", "demo", "catching", "--runs", str(runs),
           "--renderer", "analytic", "--services", str(cluster.services_path), "--journal",
           str(tmp_path / "j.sqlite"), "--key-file", str(cluster.key_file), "--lines", "--max-seconds", "150",
           "--seed", str(seed)]
    return subprocess.Popen(cmd, cwd=ROOT, env=cluster.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, stdin=subprocess.DEVNULL)


def journal_rows(path: Path, sql: str) -> list[tuple[Any, ...]]:
    with sqlite3.connect(path) as db:
        return db.execute(sql).fetchall()


def test_a_two_run_catch_net_catches_both_balls_across_processes(cluster: Any, tmp_path: Path):
    proc = demo(cluster, tmp_path, runs=2)
    out, _ = proc.communicate(timeout=200)
    assert proc.returncode == 0, out
    assert "caught 2 of 2 balls" in out, out
    journal = tmp_path / "j.sqlite"
    placed = dict(journal_rows(journal, "SELECT DISTINCT task, node FROM action_result"))
    assert placed == {"locate": "vision", "predict": "vision", "catch": "motion", "home": "motion"}
    fired = [t for (t,) in journal_rows(journal, "SELECT transition FROM firing ORDER BY seq")]
    assert fired.count("ball_caught") == 2
    assert fired.count("crossfire") == 2  # ext:ball_caught from the motion node's crossfire sensor
    # predict's feedback (its predicted catching point) is journaled, sampled, and exported with the run
    with JournalReader.open(journal) as reader:
        run = reader.runs()[-1].id
        kept = reader.feedback_messages(run)
        predicts = [r for r in reader.results(run) if r.task == "predict"]
    assert {f.task for f in kept} == {"predict"} and {"y", "t", "sigma_y"} <= set(kept[-1].data)
    assert {f.instance for f in kept} == {r.instance for r in predicts}
    bag = export_run(journal, run, tmp_path / "run.bag")
    assert bag.counts["/petrobot/action_feedback"] == len(kept)


def test_a_seeded_demo_repeats_what_the_readme_promises_the_throws_the_warm_up_and_choices_that_follow_the_outcomes(
        cluster: Any, tmp_path: Path):
    """README: the same seed gives the same throws, the same first locate of each locator, and
    choices and learner state that follow from the seed and the outcomes alone; the outcomes
    themselves may differ (the world runs in real time)."""
    from coordinator.learning import Learner
    from coordinator.netfile import load_net

    seed, demos = 11, []
    for name in ("first", "second"):
        folder = tmp_path / name
        folder.mkdir()
        proc = demo(cluster, folder, runs=3, seed=seed)
        out, _ = proc.communicate(timeout=200)
        assert proc.returncode == 0, out
        lines = (folder / "logs" / "sim.events.jsonl").read_text().splitlines()  # the world's ground truth
        throws = [(e["n"], e["speed"], e["heading"], e["y0"]) for e in map(_json_line, lines) if e.get("event") == "throw"]
        with JournalReader.open(folder / "j.sqlite") as reader:
            starts = [s for s in reader.starts() if s.task == "locate"]
            results = {r.instance: r.result for r in reader.results() if r.task == "locate"}
            learned = reader.learner_states()["locate"].state
        demos.append((throws, starts, results, learned))
    (throws_a, starts_a, *_), (throws_b, starts_b, *_) = demos
    common = min(len(throws_a), len(throws_b))
    assert common >= 3 and throws_a[:common] == throws_b[:common]  # ball n: the same start, speed and heading
    warm_up = ["locate_threshold", "locate_bgdiff", "locate_average"]
    assert [s.action for s in starts_a[:3]] == [s.action for s in starts_b[:3]] == warm_up
    for throws, starts, results, learned in demos:  # choices and learner state: the seed and the outcomes
        learner = Learner.from_net(load_net(ROOT / "nets" / "catch.toml"), seed)
        state = None
        for start in starts:
            assert learner.choose("locate") == start.action
            state = learner.update("locate", start.action, results[start.instance])
        assert state == learned


def _json_line(line: str) -> dict[str, Any]:
    import json

    try:
        got = json.loads(line)
    except ValueError:
        return {}
    return got if isinstance(got, dict) else {}


def test_moving_the_prediction_to_the_motion_node_is_an_edit_of_services_toml_only(cluster: Any, tmp_path: Path):
    proc = demo(cluster, tmp_path, runs=1, predict_node="motion")
    out, _ = proc.communicate(timeout=200)
    assert proc.returncode == 0, out
    assert "caught 1 of 1 balls" in out, out
    placed = dict(journal_rows(tmp_path / "j.sqlite", "SELECT DISTINCT task, node FROM action_result"))
    assert placed["predict"] == "motion"


def test_a_vision_node_killed_mid_run_turns_the_catch_into_an_error_and_takes_the_error_branch(
        cluster: Any, tmp_path: Path):
    proc = demo(cluster, tmp_path, runs=1)
    assert proc.stdout is not None
    lines: list[str] = []
    end = time.monotonic() + 120
    for line in proc.stdout:
        lines.append(line)
        if "start catch -> catch on motion" in line:
            break
        assert time.monotonic() < end, "".join(lines)
    # killed once the catch has a set point (before the first one, a lost stream has no motion for
    # the watchdog to stop); the motion node logs it
    file_says(tmp_path / "logs" / "motion.log", "catch: first set point")
    found = subprocess.run(["pgrep", "-f", f"services.node vision --services {cluster.services_path}"],
                           capture_output=True, text=True)
    pids = [int(p) for p in found.stdout.split()]
    assert pids, "".join(lines)
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    rest, _ = proc.communicate(timeout=120)
    out = "".join(lines) + rest
    journal = tmp_path / "j.sqlite"
    catch = journal_rows(journal, "SELECT status, outcome FROM action_result WHERE task='catch'")
    assert catch == [("error", "stream_lost")], out
    assert "watchdog stopped the arm" in out, out  # the report shows the reason
    fired = [t for (t,) in journal_rows(journal, "SELECT transition FROM firing ORDER BY seq")]
    assert "catch_failed" in fired, out
    assert fired[-1] == "at_home", out  # the error branch returns the robot home; no token is lost
    assert "final marking: {'aborted_runs': 1, 'camera_free': 1, 'home_retries_left': 3, 'robot_ready': 1}" in out, out
    assert (tmp_path / "logs" / "motion.log").exists() and (tmp_path / "logs" / "sim.log").exists()


def _faults() -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location("petrobot_bench_faults", ROOT / "bench" / "faults.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_killing_the_coordinator_mid_catch_brings_the_arm_to_rest_within_the_watchdog_bound(tmp_path: Path):
    """Issue 22, section 2, on the catching testbed: the coordinator killed while catch moves the
    arm; catch is a motion, cancelled as soon as its caller's connection drops, and brakes every
    joint at its acceleration limit. Ground truth of the joints from the world process; the world,
    both nodes and petrobot run are processes of their own (bench/faults.py catching-stop)."""
    got = _faults().catching_coordinator_kill(tmp_path)
    assert got.speed > 0.5, got  # the arm was moving when the coordinator died
    assert got.call == ("error", "caller_gone"), got
    assert got.stop_s is not None and got.bound_s is not None and got.stop_s <= got.bound_s, got
    print(f"arm at rest {got.stop_s:.2f} s after the coordinator was killed (bound {got.bound_s:.2f} s)")
