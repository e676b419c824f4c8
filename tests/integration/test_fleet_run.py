"""The generated fleet net run by `petrobot run` on a real node serving the simulated fleet actions
(services/actions/fleet.py): the commands docs/analysis.md gives, as a user types them."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from coordinator.journal import JournalReader
from services.results import Status

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

# the fleet's actions as services.toml places them, shorter; every charge ends in its error exit
SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {port[alpha]}
""" + "".join(f"""
[actions.{name}]
node = "alpha"
impl = "services.actions.fleet:simulated_task"
params = {{{{ seconds = 0.02, p_error = {1.0 if name == "charge_battery" else 0.0} }}}}
""" for name in ("load_tote", "drive_aisle", "ride_lift", "unload_tote", "charge_battery", "manual_recovery"))

# a robot's primitive-task places in mission order (coordinator.netfile.fleet)
MISSION = ["loading", "drive_1_out", "lift_up", "drive_2_out", "unloading", "drive_2_back", "lift_down",
           "drive_1_back", "charging"]


def petrobot(cluster: Any, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coordinator.cli", *args], cwd=ROOT, env=cluster.env(),
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=100)


def test_a_safe_fleet_of_two_runs_its_missions_on_a_node_and_every_error_exit_goes_into_recovery(
        cluster: Any, tmp_path: Path) -> None:
    cluster.write_services(SERVICES)
    cluster.start("alpha")
    net, journal = tmp_path / "fleet.toml", tmp_path / "fleet.sqlite"
    made = petrobot(cluster, "example", "fleet", "--robots", "2", "--safe", "--missions", "1", "-o", str(net))
    assert made.returncode == 0, made.stderr
    ran = petrobot(cluster, "run", str(net), "--journal", str(journal), "--services", str(cluster.services_path),
                   "--key-file", str(cluster.key_file), "--quiet")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "completed" in ran.stdout

    with JournalReader.open(journal) as reader:
        (run,) = reader.runs()
        assert run.end_state == "completed"
        starts = {s.instance: s for s in reader.starts(run.id)}
        results = {r.instance: r for r in reader.results(run.id)}
        firings = reader.firings(run.id)
    assert set(results) == set(starts)  # every primitive action called has ended
    # each primitive task left by the exit its action's result said: ok, or error into recovery
    ended_by = {inst: f.transition for f in firings for inst in f.instances}
    for inst, start in starts.items():
        robot, _, place = start.place.partition("_")
        if place.startswith("recover_"):
            assert ended_by[inst] == f"{start.place}_ok"
        elif results[inst].status is Status.ERROR:
            assert start.task == "charge" and ended_by[inst] == f"{start.place}_failed"
        else:
            assert ended_by[inst] == f"{start.place}_ok"
    # every robot went its whole mission once, and its charge's error exit took it into recovery
    fired = Counter(f.transition for f in firings)
    for r in ("r0", "r1"):
        assert fired[f"{r}_start"] == 1
        assert [s.place for s in starts.values() if s.place.startswith(f"{r}_")] == (
            [f"{r}_{p}" for p in MISSION] + [f"{r}_recover_charging"])
        assert fired[f"{r}_charging_failed"] == 1 and fired[f"{r}_recover_charging_ok"] == 1
