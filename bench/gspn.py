"""Benchmark: build and solve the tangible CTMC of scaled Kanban and FMS GSPNs.

Models, from the Model Checking Contest's PNML (found where the tests find them, or ``--mcc DIR``):

* Kanban of G. Ciardo and M. Tilgner (ICASE report 96-35, 1996), every transition exponential of
  rate 1/s, N kanbans per cell: N = 2, 3, 4, 5 give 4,600, 58,400, 454,475 and 2,546,432 tangible
  markings.
* FMS of G. Ciardo and K. S. Trivedi (Performance Evaluation 18, 1993) with its immediate
  transitions (machine grabs, joins, end/join switches; weights 1) and the others exponential of
  rate 1/s (our rates, not the paper's): N = 5, 6, 7 give 152,712, 537,768 and 1,639,440 tangible
  markings plus vanishing ones, which are eliminated.
* ``fms-md``: the same FMS structure with the marking-dependent rates and the weights of
  ``nets/examples/fms.toml`` (``--fms-md``, default N = 5): the same markings, and the build time
  shows what evaluating the rate expressions on every edge costs against the constant-rate FMS.

The baseline is a dense numpy LU solve of the same steady-state system where it still fits
(Kanban N = 2), run beside SuperLU and BiCGSTAB in the same process; ratios are printed.

Reward measures (``--measure-kanban N``, default 4): on the solved Kanban chain, the measures
``P{...}``, ``E{...}`` and ``X{...}`` of ``petrobot gspn --measure`` (docs/gspn.md) are compiled and
evaluated over every tangible marking by :mod:`coordinator.analysis.expr` (one numpy operation per
node of the expression), against a baseline that evaluates the same syntax tree marking by marking
in Python, in the same run; the values must agree.

The models are found where the tests find them (``tests/unit/mcc_models.py``) or in ``--mcc DIR``.

Usage: ``python bench/gspn.py [--json] [--kanban 2 3 4 5] [--fms 5 6 7] [--fms-md 5] [--tol 1e-8]
[--measure-kanban N] [--mcc DIR]``.
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

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from coordinator.analysis import ctmc
from coordinator.analysis.expr import Node, compile_expr
from coordinator.analysis.gspn import compile_measure, tangible_chain
from coordinator.net import PetriNet, TransitionKind
from coordinator.netfile import load_net
from coordinator.netfile.pnml import load_pnml

#: the Model Checking Contest models: $PETROBOT_MCC, else tests/data/mcc in this repository (``--mcc`` overrides)
MCC = Path(os.environ.get("PETROBOT_MCC") or Path(__file__).resolve().parents[1] / "tests" / "data" / "mcc")
MEASURES = ("P{#Pm1 == 0 and #Pm2 == 0}", "E{#P1 + #P2 + #P3 + #P4}", "P{0 < #Pback1 <= 2 or #Pout4 >= 1}",
            "E{max(#Pm1, #Pm2) - min(#P1, #P4) / 2}", "X{tredo1}")
FMS_IMMEDIATE = frozenset({"tM1", "tM2", "tM3", "tx", "tP1e", "tP1j", "tP2e", "tP2j"})


def model(name: str, n: int) -> PetriNet:
    """``kanban``, ``fms`` or ``fms-md`` with N tokens per pallet place, GSPN attributes as in the
    docstring."""
    if name == "fms-md":
        net = load_net(Path(__file__).resolve().parents[1] / "nets" / "examples" / "fms.toml")
        return net.with_initial_marking({**net.initial_marking, "P1": n, "P2": n, "P3": n})
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


def _python_value(node: Node, m: dict[str, int]) -> float | int | bool:
    """Baseline: the syntax tree evaluated on one marking in plain Python."""
    a = [_python_value(x, m) for x in node.args]
    op = node.op
    if op in ("num", "bool"):
        return node.value  # type: ignore[return-value]
    if op == "place":
        return m.get(str(node.value), 0)
    if op == "neg":
        return -a[0]
    if op == "not":
        return not a[0]
    if op in ("min", "max"):
        return min(a) if op == "min" else max(a)
    if op == "/":
        return a[0] / a[1] if a[1] else float("nan")
    return {"+": lambda: a[0] + a[1], "-": lambda: a[0] - a[1], "*": lambda: a[0] * a[1],
            "==": lambda: a[0] == a[1], "!=": lambda: a[0] != a[1], "<": lambda: a[0] < a[1],
            "<=": lambda: a[0] <= a[1], ">": lambda: a[0] > a[1], ">=": lambda: a[0] >= a[1],
            "and": lambda: bool(a[0] and a[1]), "or": lambda: bool(a[0] or a[1])}[op]()


def measure_case(n: int, tol: float) -> dict[str, Any]:
    """Reward measures on the solved Kanban N chain: compiled and vectorised against a per-marking
    Python evaluation of the same trees."""
    net = model("kanban", n)
    chain = tangible_chain(net, max_states=20_000_000)
    pi = ctmc.steady_state(chain.q, method="bicgstab", tol=tol).pi
    states = chain.graph.states[chain.tangible]
    names = [p.id for p in net.places]
    rows = []
    for text in MEASURES:
        start = time.perf_counter()
        meas, target = compile_measure(text, net)
        compile_s = time.perf_counter() - start
        if isinstance(target, int):
            continue
        start = time.perf_counter()
        value = float(pi @ np.asarray(target(states), dtype=float))
        ours = time.perf_counter() - start
        start = time.perf_counter()
        tree = compile_expr(meas.body, names).tree
        base = [float(_python_value(tree, dict(zip(names, r)))) for r in states.tolist()]
        baseline = float(pi @ np.array(base))
        base_s = time.perf_counter() - start
        assert abs(value - baseline) <= 1e-9 * max(1.0, abs(value)), (text, value, baseline)
        rows.append({"measure": text, "value": value, "compile_seconds": compile_s, "seconds": ours,
                     "python_seconds": base_s, "speedup": base_s / max(ours, 1e-12)})
    return {"model": f"kanban N={n}", "tangible_markings": int(chain.tangible.size), "measures": rows}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    parser.add_argument("--kanban", type=int, nargs="*", default=[2, 3, 4, 5],
                        help="kanbans per cell of the Kanban cases solved iteratively (default: 2 3 4 5)")
    parser.add_argument("--fms", type=int, nargs="*", default=[5, 6, 7],
                        help="parts per pallet place of the FMS cases (default: 5 6 7)")
    parser.add_argument("--fms-md", type=int, nargs="*", default=[5],
                        help="parts per pallet place of the FMS cases with marking-dependent rates (default: 5)")
    parser.add_argument("--tol", type=float, default=1e-8, help="target residual ||pi Q||_inf (default 1e-8)")
    parser.add_argument("--measure-kanban", type=int, default=4, metavar="N",
                        help="Kanban N of the reward-measure case (default 4; 0 skips it)")
    parser.add_argument("--mcc", metavar="DIR", help="folder of the MCC models (default: where the tests find them)")
    args = parser.parse_args()
    global MCC
    if args.mcc:
        MCC = Path(args.mcc)
    rows = [case("kanban", 2, "dense", args.tol), case("kanban", 2, "direct", args.tol)]
    rows += [case("kanban", n, "bicgstab", args.tol) for n in args.kanban]
    rows += [case("fms", n, "bicgstab", args.tol) for n in args.fms]
    rows += [case("fms-md", n, "bicgstab", args.tol) for n in args.fms_md]
    dense = rows[0]["solve_seconds"]
    for row in rows[1:]:
        if row["tangible_markings"] == rows[0]["tangible_markings"] and row["solve_seconds"] > 0:
            row["speedup_vs_dense"] = round(dense / row["solve_seconds"], 1)
    measures = measure_case(args.measure_kanban, args.tol) if args.measure_kanban else None
    if args.json:
        print(json.dumps({"cases": rows, "measures": measures}, indent=2))
    else:
        print(f"{'model':14} {'method':9} {'tangible':>9} {'vanishing':>9} {'build s':>8} {'solve s':>8} "
              f"{'iter':>5} {'residual':>9} {'x dense':>7}")
        for r in rows:
            print(f"{r['model']:14} {r['method']:9} {r['tangible_markings']:9d} {r['vanishing_markings']:9d} "
                  f"{r['build_seconds']:8.2f} "
                  f"{r['solve_seconds']:8.2f} {r['iterations']:5d} {r['residual']:9.1e} "
                  f"{r.get('speedup_vs_dense', ''):>7}")
        if measures:
            print(f"\nreward measures on {measures['model']} ({measures['tangible_markings']:,} tangible markings)")
            for m in measures["measures"]:
                print(f"  {m['measure']:45} {m['value']:12.6g}  compile {m['compile_seconds'] * 1e3:6.2f} ms  "
                      f"evaluate {m['seconds'] * 1e3:8.2f} ms  python loop {m['python_seconds']:7.2f} s  "
                      f"x{m['speedup']:,.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
