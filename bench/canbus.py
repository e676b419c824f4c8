"""CAN master benchmark: the motion node's CPU per SYNC with the PUMA's six drives, and how it keeps up.

Usage::

    python bench/canbus.py [--syncs 5000] [--rounds 3] [--baseline REF] [--json]

Three processes on 127.0.0.1, as the catching demo runs them: the simulated catching world
(``coordinator.commands.sim catching``: the six joint drives and the crossfire module on its CAN bus
behind the socketcand gateway, SYNC every 2 ms of simulated time, in real time; analytic camera,
no throws), and the CAN master of the motion node in a process of its own
(:class:`services.catching.drives.PumaDrives`, started and enabled as the PUMA driver does), which
then answers ``--syncs`` SYNCs in a row the way the PUMA driver's control thread does: wait for the
SYNC, send six joint targets (a slow sine around the resting pose). Measured in the master's process:

* ``cpu_us_per_sync``: CPU time of the whole process (its receive thread, the control loop and
  everything the CAN stack does) over the measured SYNCs, divided by their number, µs;
* ``sync_gaps``: SYNCs the loop did not answer (several arrived while it was busy), and the
  ``late_p99_ms`` of the loop's wake-up after each SYNC arrived (the master's own latency);
* ``start_s``: wall time from opening the bus to every drive operation enabled (with SDO
  configuration, where the master does it).

``--baseline REF`` runs the same master measurement, in the same run, alternating round by round,
with the ``services`` package of git revision REF (extracted with ``git archive`` into a temporary
directory; this repository's work tree and metadata are untouched) against the same simulated world,
and prints the ratio. The world is taken from this tree; a master of REF talks to it over the same
frames. The machine's load (1-minute average) is printed beside the numbers: the CPU per SYNC does
not depend on it much, the lateness does.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# --------------------------------------------------------------------------------------------------
# the master, in its own process (python bench/canbus.py --master PORT --syncs N)
# --------------------------------------------------------------------------------------------------
def _open_master(port: int) -> Any:
    """A started and enabled PumaDrives of whichever tree is first on sys.path."""
    import inspect

    from services.catching.drives import PumaDrives

    params = inspect.signature(PumaDrives).parameters
    if "bus" in params:  # the canopen master: its drives from the device file
        from services.devices.devicefile import load_bus

        drives = PumaDrives("127.0.0.1", port, bus=load_bus(ROOT / "devices" / "puma.toml"))
    else:
        drives = PumaDrives("127.0.0.1", port)
    return drives


def master(port: int, syncs: int) -> dict[str, Any]:
    """Enable the drives and answer ``syncs`` SYNCs; the measurements as a dict."""
    import numpy as np

    t0 = time.monotonic()
    drives = _open_master(port)
    drives.open(timeout=10.0)
    try:
        drives.enable(timeout=20.0)
        start_s = time.monotonic() - t0
        q0 = drives.positions()
        for _ in range(50):  # settle: the first cycles after enabling
            drives.wait_sync(timeout=2.0)
            drives.send_targets(q0)
        late: list[float] = []
        gaps = 0
        t_prev: float | None = None
        cpu0 = time.process_time()
        w0 = time.monotonic()
        for k in range(syncs):
            t = drives.wait_sync(timeout=2.0)
            if t_prev is not None:
                gaps += max(0, round((t - t_prev) / 0.002) - 1)
            t_prev = t
            late.append(_wake_latency(drives))
            drives.send_targets(q0 + 0.05 * math.sin(2.0 * math.pi * 0.5 * k * 0.002) * np.ones(len(q0)))
        cpu = time.process_time() - cpu0
        wall = time.monotonic() - w0
        drives.check()
    finally:
        drives.close()
    late.sort()
    return {"cpu_us_per_sync": 1e6 * cpu / syncs, "syncs": syncs, "wall_s": wall, "sync_gaps": gaps,
            "late_p50_ms": 1e3 * late[len(late) // 2], "late_p99_ms": 1e3 * late[int(0.99 * (len(late) - 1))],
            "start_s": start_s}


def _wake_latency(drives: Any) -> float:
    """Seconds between the arrival of the latest SYNC and now (0 where the master does not record it)."""
    arrived = getattr(drives, "sync_arrived", None)
    return max(0.0, time.monotonic() - arrived) if isinstance(arrived, float) else 0.0


# --------------------------------------------------------------------------------------------------
# the bench
# --------------------------------------------------------------------------------------------------
def _start_world(port: int) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "coordinator.commands.sim", "catching", "--renderer", "analytic", "--fps", "5",
           "--first-throw", "1e9", "--camera-wait-ms", "0",
           "--can-port", str(port), "--camera-port", str(_free_port()), "--services", os.devnull]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:  # pybullet prints a line of its own first
        if '"ready"' in line:
            return proc
    proc.kill()
    raise SystemExit("the simulated world did not start")


def _run_master(port: int, syncs: int, tree: Path | None) -> dict[str, Any]:
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
        env["CANBUS_BENCH_TREE"] = str(tree)
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--master", str(port), "--syncs", str(syncs)],
                         cwd=tree or ROOT, env=env, capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        raise SystemExit(f"master failed ({'baseline' if tree else 'this tree'}):\n{out.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def _extract(ref: str, into: Path) -> Path:
    """The services package of git revision ``ref``, extracted under ``into``."""
    archive = subprocess.run(["git", "archive", ref, "services"], cwd=ROOT, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return into


def bench(syncs: int, rounds: int, baseline: str | None) -> dict[str, Any]:
    """Run the rounds; the report as a dict."""
    port = _free_port()
    world = _start_world(port)
    results: dict[str, list[dict[str, Any]]] = {"this": [], "baseline": []}
    try:
        with tempfile.TemporaryDirectory(prefix="canbus-bench-") as tmp:
            tree = _extract(baseline, Path(tmp)) if baseline else None
            for r in range(rounds):
                if tree is not None:
                    results["baseline"].append(_run_master(port, syncs, tree))
                results["this"].append(_run_master(port, syncs, None))
                print(f"... round {r + 1}/{rounds}", file=sys.stderr, flush=True)
    finally:
        world.terminate()
        world.wait(timeout=10)

    def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
        if not rows:
            return {}
        return {"cpu_us_per_sync": statistics.median(r["cpu_us_per_sync"] for r in rows),
                "cpu_us_per_sync_all": [round(r["cpu_us_per_sync"], 1) for r in rows],
                "sync_gaps": sum(r["sync_gaps"] for r in rows), "syncs": sum(r["syncs"] for r in rows),
                "late_p99_ms": max(r["late_p99_ms"] for r in rows),
                "start_s": statistics.median(r["start_s"] for r in rows)}

    report: dict[str, Any] = {"this": summary(results["this"]), "load_average_1min": os.getloadavg()[0]}
    if baseline:
        report["baseline"] = {"ref": baseline, **summary(results["baseline"])}
        report["ratio_cpu_this_over_baseline"] = (report["this"]["cpu_us_per_sync"]
                                                  / report["baseline"]["cpu_us_per_sync"])
    return report


def render(report: dict[str, Any]) -> str:
    lines = []
    for key in ("baseline", "this"):
        row = report.get(key)
        if not row:
            continue
        name = f"baseline {row['ref']}" if key == "baseline" else "this tree"
        lines.append(f"{name:>20}: {row['cpu_us_per_sync']:7.1f} µs CPU per SYNC (rounds {row['cpu_us_per_sync_all']}), "
                     f"{row['sync_gaps']} of {row['syncs']} SYNCs unanswered, late p99 {row['late_p99_ms']:.2f} ms, "
                     f"start {row['start_s']:.2f} s")
    if "ratio_cpu_this_over_baseline" in report:
        lines.append(f"ratio this / baseline: {report['ratio_cpu_this_over_baseline']:.2f}")
    lines.append(f"load average (1 min): {report['load_average_1min']:.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--syncs", type=int, default=5000, help="SYNCs answered per round (default %(default)s: 10 s)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds (default %(default)s)")
    ap.add_argument("--baseline", metavar="REF", help="also measure the master of git revision REF, round by round")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--master", type=int, metavar="PORT", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.master is not None:
        print(json.dumps(master(args.master, args.syncs)))
        return 0
    report = bench(args.syncs, args.rounds, args.baseline)
    print(json.dumps(report, indent=1) if args.json else render(report))
    return 0


if __name__ == "__main__":
    if "CANBUS_BENCH_TREE" not in os.environ:
        sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
