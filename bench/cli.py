"""Benchmark: how long the ``petrobot`` command takes to start and to answer, against ``python -c pass``.

Each case is a fresh process, run the same way as the installed console script (a ``-c`` launcher
calling ``coordinator.cli.main`` from this checkout), timed by wall clock from ``subprocess`` start
to exit, repeated ``--repeat`` times (median and best reported), interleaved case by case so that a
change in the machine's load touches every case alike:

* ``python -c pass``: the interpreter alone, the baseline of every ratio;
* ``petrobot --help``;
* ``petrobot check NET``;
* ``petrobot analyze NET --json`` cold: numba's cache pointed at a fresh empty directory
  (``NUMBA_CACHE_DIR``), as on the first use on a machine: a small net is searched by the
  interpreter, nothing compiled (:func:`coordinator.analysis.statespace.explore`);
* ``petrobot analyze NET --json`` warm: the compiled search loaded from a cache filled before the
  timed runs;
* ``petrobot analyze LARGE --json`` cold: a net beyond the interpreter's share with an empty cache,
  so the search is compiled first, once per machine (LARGE defaults to the MCC model
  Murphy-PT-D1N010, 39,780 markings).

NET defaults to the repository's ``nets/demo.toml``. Usage::

    python bench/cli.py [--json] [--repeat N] [--cold-repeat N] [--net NET] [--large NET]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
LAUNCHER = "import sys; from coordinator.cli import main; sys.exit(main())"


def _time(cmd: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          timeout=600, check=False)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    parser.add_argument("--repeat", type=int, default=7, help="runs of each fast case (default 7)")
    parser.add_argument("--cold-repeat", type=int, default=3, help="runs of the cold analyze (default 3)")
    parser.add_argument("--net", default=str(ROOT / "nets" / "demo.toml"), help="net of check and analyze")
    parser.add_argument("--large", default=str(ROOT / "tests" / "data" / "mcc" / "Murphy-PT-D1N010" / "model.pnml"),
                        help="net whose cold analyze compiles the search (default: the MCC model Murphy-PT-D1N010)")
    args = parser.parse_args(argv)
    py = sys.executable
    base_env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    with tempfile.TemporaryDirectory(prefix="petrobot-bench-") as tmp:
        warm_env = dict(base_env, NUMBA_CACHE_DIR=str(Path(tmp) / "warm"))
        cases: dict[str, tuple[list[str], int]] = {
            "python -c pass": ([py, "-c", "pass"], args.repeat),
            "petrobot --help": ([py, "-c", LAUNCHER, "--help"], args.repeat),
            "petrobot check NET": ([py, "-c", LAUNCHER, "check", args.net, "--services",
                                    str(ROOT / "services.toml")], args.repeat),
            "petrobot analyze NET (warm)": ([py, "-c", LAUNCHER, "analyze", args.net, "--json"], args.repeat),
            "petrobot analyze NET (cold)": ([py, "-c", LAUNCHER, "analyze", args.net, "--json"], args.cold_repeat),
            "petrobot analyze LARGE (cold)": ([py, "-c", LAUNCHER, "analyze", args.large, "--json"], args.cold_repeat),
        }
        # fills the warm cache (compiles the search)
        prime = _time([py, "-c", "from coordinator.analysis.statespace import load_search; load_search()"], warm_env)
        times: dict[str, list[float]] = {name: [] for name in cases}
        for k in range(max(args.repeat, args.cold_repeat)):
            for name, (cmd, runs) in cases.items():
                if k >= runs:
                    continue
                if name.endswith("(cold)"):
                    env = dict(base_env, NUMBA_CACHE_DIR=str(Path(tmp) / f"cold-{list(cases).index(name)}-{k}"))
                elif name.endswith("(warm)"):
                    env = warm_env
                else:
                    env = base_env
                times[name].append(_time(cmd, env))
    floor = statistics.median(times["python -c pass"])
    rows: list[dict[str, Any]] = []
    for name, values in times.items():
        med = statistics.median(values)
        rows.append({"case": name, "runs": len(values), "median_s": med, "best_s": min(values),
                     "ratio_to_python": med / floor, "above_python_s": med - floor})
    result = {"date": time.strftime("%Y-%m-%d"), "python": sys.version.split()[0], "cpus": os.cpu_count(),
              "load_average": os.getloadavg(), "net": os.path.relpath(args.net, ROOT),
              "large": os.path.relpath(args.large, ROOT), "first_compile_s": prime, "cases": rows}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"{'case':32} {'runs':>4} {'median s':>9} {'best s':>8} {'x python':>9}")
        for r in rows:
            print(f"{r['case']:32} {r['runs']:4d} {r['median_s']:9.3f} {r['best_s']:8.3f} {r['ratio_to_python']:9.1f}")
        print(f"(load average {result['load_average'][0]:.2f}; net {result['net']}; large {result['large']}; "
              f"the first compile took {prime:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
