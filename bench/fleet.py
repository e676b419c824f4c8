"""Benchmark: ``petrobot analyze`` on the fleet net for N robots, safe and unsafe (the table of
docs/analysis.md section 9).

For each N and each variant (``--safe``: with the corridor token; unsafe: without), the fleet net is
written by :func:`coordinator.netfile.fleet.fleet_toml` (as ``petrobot example fleet --robots N
[--safe]`` writes it) and ``petrobot analyze FILE --json`` runs on it in its own process, with the
command's defaults unless ``--engine`` or ``--max-memory`` say otherwise, so each row is what a user
gets from the command. Reported per row: the markings (exact), the deadlock verdict with the number
of dead markings and the length of the firing sequence to the first, which engine answered and the
report's reason (where the explicit search gave up and the symbolic engine took over), the wall
and CPU seconds of the process and its peak RSS (``os.wait4``: the child alone).

Usage::

    python bench/fleet.py [--robots 2-20] [--variants safe,unsafe] [--engine auto] [--max-memory SIZE]
                          [--json]

``--robots`` takes a range ``A-B``, a list ``2,8,20`` or one number. The rows are printed as they
finish (a Markdown table), or one JSON document at the end with ``--json``; the load average is
printed beside each row, since the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def robots(spec: str) -> list[int]:
    """``A-B`` (inclusive), ``a,b,c`` or ``n``, as a sorted list of robot counts.

    Raises:
        argparse.ArgumentTypeError: anything else, or a count below 1.
    """
    try:
        if "-" in spec:
            lo, hi = (int(x) for x in spec.split("-", 1))
            out = list(range(lo, hi + 1))
        else:
            out = sorted({int(x) for x in spec.split(",")})
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a robot count, range or list: {spec!r} (e.g. 2-20 or 2,8,20)") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"robot counts start at 1: {spec!r}")
    return out


def run_one(n: int, safe: bool, folder: Path, extra: list[str]) -> dict[str, Any]:
    """``petrobot analyze`` on the fleet of ``n`` robots in a child process: its report and costs."""
    sys.path.insert(0, str(ROOT))
    from bench.contest import analyze_in_child
    from coordinator.netfile.fleet import fleet_toml

    path = folder / f"fleet_{n}{'_safe' if safe else ''}.toml"
    path.write_text(fleet_toml(n, safe=safe), encoding="utf-8")
    child = analyze_in_child(path, extra=extra)
    row: dict[str, Any] = {"robots": n, "safe": safe, "seconds": child["seconds"],
                           "cpu_seconds": child["cpu_seconds"], "peak_rss_bytes": child["peak_rss_bytes"],
                           "load": os.getloadavg()[0]}
    if "error" in child:
        row["error"] = child["error"]
        return row
    rep = child["report"]
    first = (rep.get("deadlocks") or [None])[0]
    found = rep["states"] if rep["complete"] else (rep.get("truncated") or {}).get("states_found")
    row.update({"markings": found, "complete": rep["complete"], "deadlock": rep["deadlock"],
                "n_deadlocks": rep.get("n_deadlocks"), "engine": rep["engine"]["used"],
                "reason": rep["engine"]["reason"],
                "witness_length": None if first is None else len(first["firing_sequence"]),
                "witness": None if first is None else first["marking"]})
    return row


def _verdict(row: dict[str, Any]) -> str:
    if row["deadlock"] is None:
        return "undecided"
    if not row["deadlock"]:
        return "no"
    n = row["n_deadlocks"]
    seq = "no sequence" if row["witness_length"] is None else f"{row['witness_length']}-step witness"
    return f"yes, {n:,} dead ({seq})" if n is not None else f"yes ({seq})"


def _print(row: dict[str, Any]) -> None:
    name = f"N = {row['robots']}{', safe' if row['safe'] else ''}"
    cost = f"{row['seconds']:.1f} s ({row['cpu_seconds']:.1f} s CPU), {row['peak_rss_bytes'] / 2**30:.2f} GiB"
    if "error" in row:
        print(f"| {name} | – | – | gave up: {row['error']} | {cost} | {row['load']:.1f} |", flush=True)
        return
    marks = f"{row['markings']:,}" + ("" if row["complete"] else " (incomplete)")
    print(f"| {name} | {marks} | {_verdict(row)} | {row['reason']} | {cost} | {row['load']:.1f} |",
          flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", type=robots, default=robots("2-20"), metavar="N",
                        help="robot counts: a range A-B, a list a,b,c or one number (default 2-20)")
    parser.add_argument("--variants", default="safe,unsafe", metavar="LIST",
                        help="safe (with the corridor token), unsafe, or both (default safe,unsafe)")
    parser.add_argument("--engine", choices=("auto", "explicit", "symbolic"), default="auto",
                        help="passed to petrobot analyze (default auto: the command's own choice)")
    parser.add_argument("--max-memory", metavar="SIZE", help="passed to petrobot analyze (default: its own)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    args = parser.parse_args(argv)
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    if not variants or set(variants) - {"safe", "unsafe"}:
        parser.error(f"--variants takes safe, unsafe or both, not {args.variants!r}")
    extra = ["--engine", args.engine] + (["--max-memory", args.max_memory] if args.max_memory else [])
    rows = []
    if not args.json:
        print("| fleet | markings | deadlock | engine: why | time, peak | load |\n|---|---|---|---|---|---|", flush=True)
    with tempfile.TemporaryDirectory(prefix="petrobot-fleet-") as tmp:
        for n in args.robots:
            for variant in variants:
                row = run_one(n, variant == "safe", Path(tmp), extra)
                rows.append(row)
                if not args.json:
                    _print(row)
    if args.json:
        print(json.dumps({"date": time.strftime("%Y-%m-%d"), "python": sys.version.split()[0],
                          "cpus": os.cpu_count(), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
