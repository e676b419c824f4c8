"""Benchmark: saturation on the symbolic engine's first candidate order and on the same order
upside down (:meth:`coordinator.analysis.mdd_order.Encoding.reversed`).

An order's score (the sum of the spans of transitions and semiflows) is the same read from either
end, but saturation fires an event at its top level, so the two directions can differ by orders of
magnitude, and the race of variable orders (:func:`coordinator.analysis.symbolic._race`) runs the
reverse of its first order as a candidate. For each PNML model, in one child process per direction
(so memory peaks do not mix; a child that runs over ``--seconds`` is stopped at its deadline): the
place bounds of the LP and the semiflows are computed untimed, the encoding of the race's first
candidate (seed 0, shared levels sunk) is built, then

* ``forward``: the reachable set by saturation from M0 (seconds, nodes of the store, markings);
* ``backward``: the markings of the reachable set that can reach M0, by backward saturation inside
  it (what reversibility needs; seconds), when the forward set was done.

Printed per model: each direction's seconds and nodes, and the ratio found/reversed of the forward
seconds (above 1: the reverse is faster).

Usage::

    python bench/orientation.py [--json] [--seconds S] MODEL.pnml...
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def child(path: str, direction: str, seconds: float) -> dict[str, Any]:
    """One direction on one model, in this process: the record printed as JSON."""
    sys.path.insert(0, str(ROOT))
    from coordinator.analysis import jit

    jit.configure()
    from coordinator.analysis import lp
    from coordinator.analysis import mdd_kernel as mk
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.mdd_order import encode, events
    from coordinator.analysis.symbolic import _OutOfMemory, _OutOfTime, _Store, load_kernel
    from coordinator.netfile.pnml import load_pnml

    load_kernel()
    sn = sparse_net(load_pnml(path))
    bounds = lp.place_bounds(sn, seconds=10.0).bounds
    flows = lp.semiflow_cover(sn, seconds=3.0)
    enc = encode(sn, bounds, flows, seconds=5.0, seed=0, sink=True)
    if direction == "reversed":
        enc = enc.reversed()
    out: dict[str, Any] = {"model": Path(path).parent.name, "direction": direction, "levels": enc.n_levels}
    store = _Store(enc, 3 << 30)
    deadline = time.monotonic() + seconds
    mk.set_watch(deadline, None)
    t0 = time.monotonic()
    try:
        reach = store.call(mk.MODE_SATURATE, events(sn, enc, merge=True), store.m0, check_overflow=True)
        out["forward_seconds"] = round(time.monotonic() - t0, 3)
        out["nodes"] = store.nodes
        out["states"] = str(store.count(reach))
        t0 = time.monotonic()
        store.closure(events(sn, enc, inverse=True, merge=True), store.m0, c=reach)
        out["backward_seconds"] = round(time.monotonic() - t0, 3)
    except (_OutOfTime, _OutOfMemory) as exc:
        out.setdefault("nodes", store.nodes)
        out["stopped"] = "time" if isinstance(exc, _OutOfTime) else "memory"
    return out


def _run(path: str, direction: str, seconds: float) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, __file__, "--child", direction, "--seconds", str(seconds), path],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        return {"model": Path(path).parent.name, "direction": direction, "error": proc.stderr.strip()[-300:]}
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def _cell(r: dict[str, Any], key: str) -> str:
    if "error" in r:
        return "error"
    if key in r:
        return f"{r[key]:.2f} s"
    if key == "backward_seconds" and "forward_seconds" not in r:
        return "-"  # no reachable set to go backward in
    return f"stopped ({r.get('stopped', '-')})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="+", help="PNML files")
    ap.add_argument("--seconds", type=float, default=25.0, help="time of each direction's saturations (default 25)")
    ap.add_argument("--json", action="store_true", help="one JSON object per model and direction")
    ap.add_argument("--child", choices=("found", "reversed"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.models[0], args.child, args.seconds)))
        return 0
    for path in args.models:
        found, rev = (_run(path, d, args.seconds) for d in ("found", "reversed"))
        if args.json:
            print(json.dumps(found), flush=True)
            print(json.dumps(rev), flush=True)
            continue
        ratio = "-"
        if "forward_seconds" in found and "forward_seconds" in rev:
            ratio = f"{found['forward_seconds'] / max(rev['forward_seconds'], 1e-3):.2f}"
        print(f"{found['model'][:30]:30s} forward {_cell(found, 'forward_seconds'):>15s} "
              f"{found.get('nodes', 0):>10,} nodes | reversed {_cell(rev, 'forward_seconds'):>15s} {rev.get('nodes', 0):>10,} nodes | found/reversed "
              f"{ratio:>7s} | backward {_cell(found, 'backward_seconds'):>10s} / {_cell(rev, 'backward_seconds'):>10s}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
