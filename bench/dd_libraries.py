"""Benchmark: which decision-diagram library for the symbolic engine? oxidd and dd (CUDD) against
petrobot's own MDD kernel, on the same nets and the same encoding.

For each PNML model, in one child process per engine (so memory peaks do not mix, and an engine
that runs over its time is killed): the encoding of the symbolic engine
(:func:`coordinator.analysis.mdd_order.encode`: levels from P-semiflow groups, their local markings,
the FORCE+sifting order, seed 0) and its merged events (:func:`~coordinator.analysis.mdd_order.events`)
are built untimed; then

* ``oxidd`` and ``cudd`` (the ``dd`` package's CUDD binding): each level's value in
  ceil(log2 values) Boolean variables, current and next bits interleaved, levels in the engine's
  order; one transition relation per event over the levels it reads or changes (a disjunction of
  ``cur = i ∧ next = f(i)`` per level, conjoined), the reachable set by **chaining** (Roig,
  Cortadella, Pastor 1995: the events fired one after the other, bottom level first, each image
  ``∃cur. S ∧ R_e`` renamed next → cur and added to S, until nothing changes);
* ``own``: :func:`coordinator.analysis.symbolic.analyse_symbolic`'s reachable set by saturation
  (``reach`` phase) and the whole analysis (``seconds``).

Reported per model and engine: states (for oxidd exact; CUDD's count is a double), seconds of the
reachable set, peak RSS, nodes of the result, or ``timeout``. The libraries are optional (``pip
install oxidd dd``, the ``bench`` extra); an engine whose library is missing is reported as such.

Usage::

    python bench/dd_libraries.py [--json] [--seconds S] [--engines oxidd,cudd,own] MODEL...
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def _peak_rss() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _encoding(path: str) -> tuple[Any, Any, Any, Any]:
    sys.path.insert(0, str(ROOT))
    from coordinator.analysis import jit

    jit.configure()
    from coordinator.analysis import lp
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(path)
    sn = sparse_net(net)
    bounds = lp.place_bounds(sn, seconds=10.0).bounds
    flows = lp.semiflow_cover(sn, seconds=3.0)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0)
    return net, bounds, flows, (enc, events(sn, enc, merge=True))


class _Oxidd:
    def __init__(self, n_vars: int) -> None:
        import oxidd.bdd as ob
        from oxidd.util import BooleanOperator

        self.m = ob.BDDManager(1 << 24, 1 << 22, 1)
        self.m.add_vars(n_vars)
        self.and_op = BooleanOperator.AND
        self.ob = ob

    def var(self, i: int) -> Any:
        return self.m.var(i)

    def true(self) -> Any:
        return self.m.true()

    def false(self) -> Any:
        return self.m.false()

    def subst(self, pairs: list[tuple[int, int]]) -> Any:
        return self.ob.BDDFunction.make_substitution([(a, self.m.var(b)) for a, b in pairs])

    def cube(self, idx: list[int]) -> Any:
        out = self.m.true()
        for i in idx:
            out = out & self.m.var(i)
        return out

    def image(self, s: Any, r: Any, cube: Any, sub: Any) -> Any:
        return s.apply_exists(self.and_op, r, cube).substitute(sub)

    def count(self, s: Any, n_vars: int) -> int:
        return int(s.sat_count(n_vars))

    def nodes(self, s: Any) -> int:
        return int(s.node_count())


class _Cudd:
    def __init__(self, n_vars: int) -> None:
        from dd import cudd

        self.cudd = cudd
        self.b = cudd.BDD()
        self.b.configure(reordering=False)
        self.names = [f"v{i}" for i in range(n_vars)]
        self.b.declare(*self.names)

    def var(self, i: int) -> Any:
        return self.b.var(self.names[i])

    def true(self) -> Any:
        return self.b.true

    def false(self) -> Any:
        return self.b.false

    def subst(self, pairs: list[tuple[int, int]]) -> Any:
        return {self.names[a]: self.names[b] for a, b in pairs}

    def cube(self, idx: list[int]) -> Any:
        return {self.names[i] for i in idx}

    def image(self, s: Any, r: Any, cube: Any, sub: Any) -> Any:
        return self.b.let(sub, self.cudd.and_exists(s, r, cube))

    def count(self, s: Any, n_vars: int) -> int:
        return int(self.b.count(s, nvars=n_vars))

    def nodes(self, s: Any) -> int:
        return len(s)


def child_library(kind: str, path: str, seconds: float) -> dict[str, Any]:
    """The reachable set by chaining in a BDD library (module docstring)."""
    import numpy as np

    _, _, _, (enc, ev) = _encoding(path)
    dom = enc.dom.tolist()
    bits = [max(1, int(np.ceil(np.log2(d)))) if d > 1 else 1 for d in dom]
    base = np.concatenate([[0], np.cumsum(bits)]).astype(int).tolist()
    n_vars = 2 * base[-1]

    def cur(k: int, b: int) -> int:
        return 2 * (base[k] + b)

    def nxt(k: int, b: int) -> int:
        return 2 * (base[k] + b) + 1

    try:
        lib: Any = _Oxidd(n_vars) if kind == "oxidd" else _Cudd(n_vars)
    except ImportError as exc:
        return {"engine": kind, "error": f"not installed: {exc}"}
    start = time.perf_counter()

    def value(k: int, v: int, which: Any) -> Any:
        out = lib.true()
        for b in range(bits[k]):
            x = lib.var(which(k, b))
            out = out & (x if (v >> b) & 1 else ~x)
        return out

    s = lib.true()
    for k in range(len(dom)):
        s = s & value(k, int(enc.m0[k]), cur)
    rels = []
    for e in range(ev.n_events):
        top, bot = int(ev.top[e]), int(ev.bot[e])
        r = lib.true()
        quantified: list[int] = []
        pairs: list[tuple[int, int]] = []
        for k in range(top, bot + 1):
            sl = int(ev.slot[ev.slot_ptr[e] + k - top])
            if sl < 0:
                continue
            fn = ev.fn[ev.fn_ptr[sl]:ev.fn_ptr[sl + 1]].tolist()
            part = lib.false()
            for i, j in enumerate(fn):
                if 0 <= j < dom[k]:
                    part = part | (value(k, i, cur) & value(k, j, nxt))
            r = r & part
            for b in range(bits[k]):
                quantified.append(cur(k, b))
                pairs.append((nxt(k, b), cur(k, b)))
        rels.append((top, r, lib.cube(quantified), lib.subst(pairs)))
    rels.sort(key=lambda x: -x[0])  # chaining: the bottom events first
    built = time.perf_counter() - start
    rounds = 0
    while True:
        rounds += 1
        old = s
        for _, r, cube, sub in rels:
            s = s | lib.image(s, r, cube, sub)
            if time.perf_counter() - start > seconds:
                return {"engine": kind, "timeout": seconds, "rounds": rounds, "peak_rss_bytes": _peak_rss()}
        if s == old:
            break
    wall = time.perf_counter() - start
    states = lib.count(s, n_vars) >> (n_vars // 2)  # S reads the current bits only
    return {"engine": kind, "states": states, "seconds": wall, "relations_seconds": built, "rounds": rounds,
            "nodes": lib.nodes(s), "boolean_variables": n_vars, "peak_rss_bytes": _peak_rss()}


def child_own(path: str, seconds: float) -> dict[str, Any]:
    """The own kernel: analyse_symbolic (saturation) with the same bounds and semiflows."""
    net, bounds, flows, _ = _encoding(path)
    from coordinator.analysis.symbolic import analyse_symbolic

    start = time.perf_counter()
    r = analyse_symbolic(net, bounds, flows=flows, seconds=seconds)
    wall = time.perf_counter() - start
    return {"engine": "own", "states": r.states, "seconds": r.seconds["reach"] + r.seconds["encode"],
            "all_properties_seconds": wall, "nodes": r.nodes, "peak_rss_bytes": _peak_rss()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("models", nargs="+", metavar="MODEL", help="PNML model files")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    parser.add_argument("--seconds", type=float, default=120.0, metavar="S",
                        help="time cap of each engine per model (default 120)")
    parser.add_argument("--engines", default="oxidd,cudd,own", help="comma-separated: oxidd, cudd, own")
    parser.add_argument("--child", choices=["oxidd", "cudd", "own"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        out = child_own(args.models[0], args.seconds) if args.child == "own" else child_library(
            args.child, args.models[0], args.seconds)
        print(json.dumps(out))
        return 0
    rows = []
    for path in args.models:
        name = Path(path).parent.name
        for kind in args.engines.split(","):
            cmd = [sys.executable, __file__, "--child", kind, "--seconds", str(args.seconds), path]
            try:
                done = subprocess.run(cmd, capture_output=True, text=True, timeout=args.seconds + 120, check=True)
                row = json.loads(done.stdout.strip().splitlines()[-1])
            except subprocess.TimeoutExpired:
                row = {"engine": kind, "timeout": args.seconds}
            except subprocess.CalledProcessError as exc:
                row = {"engine": kind, "error": exc.stderr.strip().splitlines()[-1] if exc.stderr else "failed"}
            row["model"] = name
            rows.append(row)
            if not args.json:
                if "states" in row:
                    print(f"{name:<28} {kind:<6} {row['states']:>22,} markings {row['seconds']:8.2f} s "
                          f"peak {row['peak_rss_bytes'] / 2**20:7.0f} MiB  {row['nodes']:,} nodes", flush=True)
                else:
                    print(f"{name:<28} {kind:<6} {row.get('error') or 'timeout after %.0f s' % row['timeout']}",
                          flush=True)
    if args.json:
        print(json.dumps({"date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count(), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
