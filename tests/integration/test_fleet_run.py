"""The generated fleet net run by `petrobot run` on a real node serving the simulated fleet actions
(services/actions/fleet.py): the two commands docs/analysis.md and `petrobot example --help` give,
word for word, typed in a folder whose services.toml places the actions on node alpha."""

from __future__ import annotations

import shlex
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from coordinator.commands.example import EPILOG
from coordinator.journal import JournalReader
from coordinator.netfile import load_net
from services.results import Status

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

COMMANDS = ("petrobot example fleet --robots 2 --safe --missions 2 -o runs/fleet.toml",
            "petrobot run runs/fleet.toml")


def services(p_error: dict[str, float]) -> str:
    """The fleet's actions as services.toml places them, quicker, with these error probabilities."""
    return '[nodes.alpha]\nhost = "127.0.0.1"\nport = {port[alpha]}\n' + "".join(
        f'\n[actions.{name}]\nnode = "alpha"\nimpl = "services.actions.fleet:simulated_task"\n'
        f"params = {{{{ seconds = 0.02, p_error = {p_error.get(name, 0.0)} }}}}\n"
        for name in ("load_tote", "drive_aisle", "ride_lift", "unload_tote", "charge_battery", "manual_recovery"))


# a robot's primitive-task places in mission order (coordinator.netfile.fleet)
MISSION = ["loading", "drive_1_out", "lift_up", "drive_2_out", "unloading", "drive_2_back", "lift_down",
           "drive_1_back", "charging"]


def petrobot(cluster: Any, command: str) -> subprocess.CompletedProcess[str]:
    """``command`` as typed in the cluster's folder (its services.toml; the key from the environment)."""
    args = shlex.split(command)
    assert args[0] == "petrobot"
    return subprocess.run([sys.executable, "-m", "coordinator.cli", *args[1:]], cwd=cluster.tmp, env=cluster.env(),
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=100)


def check_exits(reader: JournalReader, run: str) -> None:
    """Every primitive action called has ended, and its primitive task was left by the exit its result
    said: ``<place>_ok`` on success, ``<place>_failed`` into the robot's recovery on error."""
    starts = {s.instance: s for s in reader.starts(run)}
    results = {r.instance: r for r in reader.results(run)}
    assert set(results) == set(starts)
    ended_by = {inst: f.transition for f in reader.firings(run) for inst in f.instances}
    for inst, start in starts.items():
        if start.place.partition("_")[2].startswith("recover_"):
            assert ended_by[inst] == f"{start.place}_{'ok' if results[inst].status is not Status.ERROR else 'error'}"
        else:
            exit_ = "failed" if results[inst].status is Status.ERROR else "ok"
            assert ended_by[inst] == f"{start.place}_{exit_}", (start.place, results[inst].status)


def test_the_documented_commands_run_a_safe_fleet_of_two_whose_every_error_exit_goes_into_recovery(
        cluster: Any) -> None:
    docs = " ".join((ROOT / "docs" / "analysis.md").read_text(encoding="utf-8").split())
    for command in COMMANDS:
        assert command in docs and command in EPILOG, f"docs/analysis.md or example --help no longer says {command}"
    cluster.write_services(services({"charge_battery": 1.0}))  # every charge ends in its error exit
    cluster.start("alpha")
    made = petrobot(cluster, COMMANDS[0])
    assert made.returncode == 0, made.stderr
    ran = petrobot(cluster, COMMANDS[1])
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "completed" in ran.stdout

    with JournalReader.open(cluster.tmp / "runs" / "journal.sqlite") as reader:
        (run,) = reader.runs()
        assert run.end_state == "completed"
        check_exits(reader, run.id)
        starts = reader.starts(run.id)
        fired = Counter(f.transition for f in reader.firings(run.id))
    # every robot went its whole mission twice, each time from its charge's error exit into recovery
    for r in ("r0", "r1"):
        assert fired[f"{r}_start"] == 2
        assert [s.place for s in starts if s.place.startswith(f"{r}_")] == (
            [f"{r}_{p}" for p in MISSION] + [f"{r}_recover_charging"]) * 2
        assert fired[f"{r}_charging_failed"] == 2 and fired[f"{r}_recover_charging_ok"] == 2


def test_a_fleet_without_the_corridor_token_ends_completed_or_stuck_in_one_of_its_deadlocks(
        cluster: Any) -> None:
    cluster.write_services(services({name: 0.2 for name in ("load_tote", "drive_aisle", "ride_lift", "unload_tote",
                                                             "charge_battery", "manual_recovery")}))
    cluster.start("alpha")
    assert petrobot(cluster, "petrobot example fleet --robots 2 --missions 3 -o fleet.toml").returncode == 0
    ran = petrobot(cluster, "petrobot run fleet.toml --quiet")
    net = load_net(cluster.tmp / "fleet.toml")
    with JournalReader.open(cluster.tmp / "runs" / "journal.sqlite") as reader:
        (run,) = reader.runs()
        check_exits(reader, run.id)
        marking = net.initial_marking
        for f in reader.firings(run.id):
            marking = net.fire(marking, f.transition)
    # the run ends where the net lets nothing fire: home after the missions, or one of the deadlocks
    # analyze finds (a robot done with a task, waiting for what the other holds)
    assert not net.enabled_transitions(marking)
    if run.end_state == "completed":
        assert ran.returncode == 0 and all(marking.get(f"r{i}_ready", 0) == 1 for i in range(2))
    else:
        assert run.end_state == "stuck" and ran.returncode == 1, ran.stdout
        assert any(marking.get(f"r{i}_ready", 0) == 0 for i in range(2))
        assert any("waiting_after" in p for p in marking)
