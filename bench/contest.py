"""Benchmark: ``petrobot analyze`` on Model Checking Contest models, against the contest's answers.

Each model is a folder holding ``model.pnml``, beside the others in a directory with an
``oracle.tsv`` (the layout of ``tests/data/mcc``: columns ``model``, ``states``, ``edges``,
``max_token_in_place``, ``max_token_per_marking``, ``deadlock``, ``live``, ``quasi_live``,
``one_safe``, ``stable_marking``; ``?`` where the contest has no answer). Every model runs in a
process of its own, as a user runs it: ``python -m coordinator.cli analyze MODEL --json`` with its
defaults (the engine chosen by itself, the default memory budget), killed after ``--kill`` seconds.
Reported per model: the nine columns against the oracle (``agree``: every column with an answer
agrees; ``wrong``: the columns that differ, a decided value against the contest's; ``undecided``:
the columns left ``null``), the engine and why, wall-clock and CPU seconds of the whole command
(process start, imports and the bounds' LPs included), the peak RSS, and whether it met the
target (``--seconds``, default 60, and ``--max-memory``, default 4 GiB). A column the report
leaves undecided is not agreement: the row meets the target only when every column the contest
answers is decided and agrees.

The exit status is 1 when some model gets a wrong answer (never when it is only slow or
undecided), so the bench can guard a change of the engines.

Usage::

    python bench/contest.py [--json] [--seconds S] [--kill S] [--max-memory GIB] DIR [MODEL ...]

``DIR`` is the directory of model folders with its ``oracle.tsv``; the models (folder names) default
to every row of the oracle that has a folder. E.g. ``python bench/contest.py tests/data/mcc-scale``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ("states", "edges", "max_token_in_place", "max_token_per_marking", "deadlock", "live", "quasi_live",
           "one_safe", "stable_marking")


def oracle(directory: Path) -> dict[str, dict[str, str]]:
    """The rows of ``directory/oracle.tsv`` by model name."""
    with (directory / "oracle.tsv").open(encoding="utf-8") as fh:
        return {row["model"]: row for row in csv.DictReader(fh, delimiter="\t")}


def expected(text: str) -> bool | int | None:
    """An oracle cell: true/false, an integer, or None (no answer: ``?``, ``+inf``, ``-1``)."""
    if text in ("true", "false"):
        return text == "true"
    return int(text) if text.isdigit() else None


def analyze_in_child(path: Path, kill: float | None = None, extra: tuple[str, ...] | list[str] = ()) -> dict[str, Any]:
    """``petrobot analyze PATH --json [EXTRA...]`` in a child process, as a user runs it (from the
    repository root, its own session), stopped after ``kill`` seconds if given: ``seconds`` (wall),
    ``cpu_seconds`` and ``peak_rss_bytes`` of the child alone (``wait4``), ``killed``, ``exit``, and
    its whole JSON ``report`` or an ``error`` (the last line it wrote to stderr)."""
    cmd = [sys.executable, "-m", "coordinator.cli", "analyze", str(path), "--json", *extra]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.monotonic()
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=err, text=True, start_new_session=True)
        killed = False
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if kill is not None and time.monotonic() - start > kill:
                os.killpg(proc.pid, 9)
                killed = True
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.05)
        wall = time.monotonic() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text, errors = out.read(), err.read()
    row: dict[str, Any] = {"seconds": round(wall, 2), "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 2),
                           "peak_rss_bytes": usage.ru_maxrss * 1024, "killed": killed, "exit": proc.returncode}
    if killed:
        row["error"] = f"killed after {kill:.0f} s"
        return row
    try:
        row["report"] = json.loads(text)
    except json.JSONDecodeError:
        row["error"] = (errors.strip().splitlines() or [f"exit status {proc.returncode}, no report"])[-1][:300]
    return row


def run_one(model: Path, kill: float) -> dict[str, Any]:
    """:func:`analyze_in_child` on a model folder's ``model.pnml``: the nine columns of its report,
    the engine and why, and the child's costs."""
    row = {"model": model.name, **analyze_in_child(model / "model.pnml", kill)}
    report = row.pop("report", None)
    if report is not None:
        row["report"] = {k: report.get(k) for k in (*COLUMNS, "complete")}
        row["engine"] = (report.get("engine") or {}).get("used")
        row["engine_reason"] = (report.get("engine") or {}).get("reason")
    return row


def judge(row: dict[str, Any], answers: dict[str, str]) -> None:
    """Add ``agree``, ``wrong`` and ``undecided`` to a row from the oracle's answers (counts of an
    incomplete search are undecided, not wrong)."""
    got = row.get("report") or {}
    wrong, undecided, checked = [], [], 0
    for col in COLUMNS:
        want = expected(answers.get(col, "?"))
        if want is None:
            continue
        checked += 1
        value = got.get(col)
        if value is None or (col in ("states", "edges") and got.get("complete") is False):
            undecided.append(col)
        elif value != want:
            wrong.append(col)
    row["wrong"] = wrong
    row["undecided"] = undecided if "report" in row else list(COLUMNS)
    row["agree"] = "report" in row and not wrong and not undecided and checked > 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directory", type=Path, help="folder of model folders with its oracle.tsv")
    ap.add_argument("models", nargs="*", help="model folder names (default: every row of the oracle with a folder)")
    ap.add_argument("--seconds", type=float, default=60.0, help="the time target of a model (default 60)")
    ap.add_argument("--kill", type=float, default=120.0, help="stop a model after this many seconds (default 120)")
    ap.add_argument("--max-memory", type=float, default=4.0, help="the memory target, GiB (default 4)")
    ap.add_argument("--json", action="store_true", help="one JSON object per model, then a summary object")
    args = ap.parse_args(argv)
    answers = oracle(args.directory)
    names = args.models or [m for m in answers if (args.directory / m / "model.pnml").is_file()]
    rows = []
    for name in names:
        row = run_one(args.directory / name, args.kill)
        judge(row, answers.get(name, {}))
        row["met"] = bool(row["agree"] and row["seconds"] <= args.seconds
                          and row["peak_rss_bytes"] <= args.max_memory * 2**30)
        rows.append(row)
        if args.json:
            print(json.dumps(row), flush=True)
        else:
            status = ("agree" if row["agree"] else f"WRONG {row['wrong']}" if row["wrong"]
                      else f"undecided {row['undecided']}" if "report" in row else row.get("error", "no report"))
            print(f"{name:44s} {status:40s} {row.get('engine') or '-':9s} {row['seconds']:7.1f} s "
                  f"{row['cpu_seconds']:7.1f} s CPU  {row['peak_rss_bytes'] / 2**30:5.2f} GiB"
                  f"{'  met' if row['met'] else ''}", flush=True)
    summary = {"models": len(rows), "agree": sum(r["agree"] for r in rows), "met": sum(r["met"] for r in rows),
               "wrong": [r["model"] for r in rows if r["wrong"]], "seconds_target": args.seconds,
               "memory_target_gib": args.max_memory}
    print(json.dumps(summary) if args.json else
          f"{summary['models']} models: {summary['agree']} agree on every answered column, {summary['met']} "
          f"also within {args.seconds:.0f} s and {args.max_memory:g} GiB; wrong: {summary['wrong'] or 'none'}")
    return 1 if summary["wrong"] else 0


if __name__ == "__main__":
    sys.exit(main())
