"""Benchmark: build and solve the tangible CTMC of scaled Kanban and FMS GSPNs.

Models, from the Model Checking Contest's PNML in ``tests/data/mcc``:

* Kanban of G. Ciardo and M. Tilgner (ICASE report 96-35, 1996), every transition exponential of
  rate 1/s, N kanbans per cell: N = 2, 3, 4, 5 give 4,600, 58,400, 454,475 and 2,546,432 tangible
  markings.
* FMS of G. Ciardo and K. S. Trivedi (Performance Evaluation 18, 1993) with its immediate
  transitions (machine grabs, joins, end/join switches; weights 1) and the others exponential of
  rate 1/s (our rates, not the paper's): N = 5, 6, 7 give 152,712, 537,768 and 1,639,440 tangible
  markings plus vanishing ones, which are eliminated.

The baseline is a dense numpy LU solve of the same steady-state system where it still fits
(Kanban N = 2), run beside SuperLU and BiCGSTAB in the same process; ratios are printed.

Usage: ``python bench/gspn.py [--json] [--kanban 2 3 4 5] [--fms 5 6 7] [--tol 1e-8]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from coordinator.analysis import ctmc
from coordinator.analysis.gspn import tangible_chain
from coordinator.net import PetriNet, TransitionKind
from coordinator.netfile.pnml import load_pnml

#: the Model Checking Contest models: $PETROBOT_MCC, else tests/data/mcc in this repository
MCC = Path(os.environ.get("PETROBOT_MCC") or Path(__file__).resolve().parents[1] / "tests" / "data" / "mcc")
FMS_IMMEDIATE = frozenset({"tM1", "tM2", "tM3", "tx", "tP1e", "tP1j", "tP2e", "tP2j"})


def model(name: str, n: int) -> PetriNet:
    """``kanban`` or ``fms`` with N tokens per pallet place, GSPN attributes as in the docstring."""
    if name == "kanban":
        base, immediate = load_pnml(MCC / "Kanban-PT-00005" / "model.pnml"), frozenset()
        m0 = {p: n for p in base.initial_marking}
    else:
        base, immediate = load_pnml(MCC / "FMS-PT-00002" / "model.pnml"), FMS_IMMEDIATE
        m0 = {p: (n if p in ("P1", "P2", "P3") else c) for p, c in base.initial_marking.items()}
    transitions = tuple(t if t.id in immediate else replace(t, kind=TransitionKind.EXPONENTIAL, rate=1.0)
                        for t in base.transitions)
    return PetriNet(name=f"{name}{n}", places=base.places, transitions=transitions, arcs=base.arcs,
                    initial_marking=m0)


def case(name: str, n: int, method: str, tol: float) -> dict[str, Any]:
    t0 = time.perf_counter()
    chain = tangible_chain(model(name, n), max_states=20_000_000)
    t1 = time.perf_counter()
    sol = ctmc.steady_state(chain.q, method=method, tol=tol)
    t2 = time.perf_counter()
    return {
        "model": f"{name} N={n}", "method": sol.method, "tangible_markings": int(chain.tangible.size),
        "vanishing_markings": chain.vanishing_count, "nonzeros": int(chain.q.nnz),
        "build_seconds": round(t1 - t0, 3), "solve_seconds": round(t2 - t1, 3),
        "iterations": sol.iterations, "residual": sol.residual,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    parser.add_argument("--kanban", type=int, nargs="*", default=[2, 3, 4, 5],
                        help="kanbans per cell of the Kanban cases solved iteratively (default: 2 3 4 5)")
    parser.add_argument("--fms", type=int, nargs="*", default=[5, 6, 7],
                        help="parts per pallet place of the FMS cases (default: 5 6 7)")
    parser.add_argument("--tol", type=float, default=1e-8, help="target residual ||pi Q||_inf (default 1e-8)")
    args = parser.parse_args()
    rows = [case("kanban", 2, "dense", args.tol), case("kanban", 2, "direct", args.tol)]
    rows += [case("kanban", n, "bicgstab", args.tol) for n in args.kanban]
    rows += [case("fms", n, "bicgstab", args.tol) for n in args.fms]
    dense = rows[0]["solve_seconds"]
    for row in rows[1:]:
        if row["tangible_markings"] == rows[0]["tangible_markings"] and row["solve_seconds"] > 0:
            row["speedup_vs_dense"] = round(dense / row["solve_seconds"], 1)
    if args.json:
        print(json.dumps({"cases": rows}, indent=2))
    else:
        print(f"{'model':14} {'method':9} {'tangible':>9} {'vanishing':>9} {'build s':>8} {'solve s':>8} "
              f"{'iter':>5} {'residual':>9} {'x dense':>7}")
        for r in rows:
            print(f"{r['model']:14} {r['method']:9} {r['tangible_markings']:9d} {r['vanishing_markings']:9d} "
                  f"{r['build_seconds']:8.2f} "
                  f"{r['solve_seconds']:8.2f} {r['iterations']:5d} {r['residual']:9.1e} "
                  f"{r.get('speedup_vs_dense', ''):>7}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
