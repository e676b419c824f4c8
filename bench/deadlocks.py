"""Benchmark: the dead markings of a reachable set, the passes and the restriction by turns.

The symbolic engine finds the reachable markings that enable no transition in one pass over the
reachable set (the kernel's ``MODE_DEAD``), again on tables twice as large while the conditions
pending on its paths outgrow them, and by restricting the set event by event between two passes
for as long as the passes have taken (:func:`coordinator.analysis.symbolic._dead`). The baseline,
in the same run, is the way before: the passes alone, then the restriction after the last
(``by_turns=False``).

For each net, once: its encoding (:func:`.mdd_order.encode`, seed 0, shared levels at the bottom:
the race's first order). For each way, on a fresh store: the reachable set by saturation, or with
``--chain`` by chained images (untimed), its enabled counts (untimed, as the engine has them
by then on most nets), then the dead markings, timed. Printed per net: markings, dead markings
(the same both ways, checked), the seconds each way and their ratio (before / by turns).

A model is a PNML path, or ``FAMILY:N``: a contest family at size N (``bench/families.py``;
``sharedmemory:50`` is SharedMemory-PT-000050). ``--repeat`` runs each way that many times, by turns.

Usage::

    python bench/deadlocks.py [--json] [--repeat N] [--chain] [--max-memory GIB] [--mcc DIR] MODEL...
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def prepare(net: Any) -> tuple[Any, Any, Any]:
    """The net's encoding and its forward and single events, once per net: every run of both ways
    is on the same variable order (its search is time-limited, so two searches may differ)."""
    from coordinator.analysis import lp
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.mdd_order import encode, events

    sn = sparse_net(net)
    bounds = lp.place_bounds(sn, seconds=10.0).bounds  # as bench/statespace.py --symbolic proves them
    enc = encode(sn, bounds, lp.semiflow_cover(sn, seconds=3.0), seconds=5.0, seed=0, sink=True)
    return enc, events(sn, enc, merge=True), events(sn, enc)


def measure(prepared: tuple[Any, Any, Any], by_turns: bool, max_bytes: int, chain: bool) -> dict[str, Any]:
    """One way on a fresh store: the markings, the dead markings and the seconds they took."""
    from coordinator.analysis.symbolic import _dead, _Store

    enc, fwd, single = prepared
    store = _Store(enc, max_bytes)
    store.chain = chain
    t0 = time.monotonic()
    reach = store.closure(fwd, store.m0, check_overflow=True)
    states = store.count(reach)
    store.count(reach, at_most=float(states) * max(1, single.n_events))
    counts = store.enabled_counts(reach, single)
    set_up = time.monotonic() - t0
    t0 = time.monotonic()
    dead = _dead(store, fwd, single, reach, counts, states, by_turns=by_turns)
    seconds = time.monotonic() - t0
    return {"states": states, "dead": store.count(dead), "seconds": seconds, "set_up_seconds": set_up,
            "nodes": store.nodes}


def arguments(doc: str, chain_example: str, argv: list[str] | None) -> argparse.Namespace:
    """The command line of a bench that times two ways on fresh stores of one encoding per net
    (this one and ``bench/witness.py``): models, ``--repeat``, ``--max-memory``, ``--mcc``,
    ``--chain`` (``chain_example`` ends its help) and ``--json``; ``doc`` is the bench's docstring."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=doc)
    ap.add_argument("models", nargs="+", help="PNML paths or FAMILY:N")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each way, by turns (default 1)")
    ap.add_argument("--max-memory", type=float, default=4.0, help="the store's budget, GiB (default 4)")
    ap.add_argument("--mcc", metavar="DIR", help="folder of the MCC models (default: where the tests find them)")
    ap.add_argument("--chain", action="store_true",
                    help=f"build the reachable set by chained images, not saturation (the race's first order "
                         f"by chaining; {chain_example})")
    ap.add_argument("--json", action="store_true", help="one JSON object per model")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = arguments(__doc__, "SharedMemory-PT-000050 is not saturated in 10 minutes on this order", argv)
    sys.path.insert(0, str(ROOT))
    from bench.statespace import load_model
    from coordinator.analysis.symbolic import load_kernel

    load_kernel()
    for spec in args.models:
        prepared = prepare(load_model(spec, args.mcc))
        runs: dict[str, list[dict[str, Any]]] = {"before": [], "by_turns": []}
        for _ in range(max(1, args.repeat)):
            for way in ("before", "by_turns"):
                runs[way].append(measure(prepared, way == "by_turns", int(args.max_memory * 2**30), args.chain))
        dead = {r["dead"] for rs in runs.values() for r in rs}
        if len(dead) != 1:
            print(f"{spec}: the two ways disagree on the dead markings: {sorted(dead)}", file=sys.stderr)
            return 1
        best = {way: min(r["seconds"] for r in rs) for way, rs in runs.items()}
        row = {"model": spec, "states": runs["before"][0]["states"], "dead": dead.pop(),
               "before_seconds": [round(r["seconds"], 3) for r in runs["before"]],
               "by_turns_seconds": [round(r["seconds"], 3) for r in runs["by_turns"]],
               "set_up_seconds": round(runs["before"][0]["set_up_seconds"], 2),
               "ratio": round(best["before"] / max(best["by_turns"], 1e-9), 2)}
        if args.json:
            print(json.dumps(row), flush=True)
        else:
            print(f"{spec}: {row['states']:,} markings, {row['dead']:,} dead; before {best['before']:.2f} s, "
                  f"by turns {best['by_turns']:.2f} s: {row['ratio']:.2f}x", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
