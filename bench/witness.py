"""Benchmark: the firing sequence to a dead marking, its backward closure after or beside the quick searches.

The symbolic engine traces a firing sequence from M0 to one of the dead markings
(:func:`coordinator.analysis.symbolic._witness`): two quick searches over explicit markings first
(guided by the token distance, then random walks, :data:`.symbolic._QUICK_SECONDS` each); where
they find none, walks and the guided search inside the reachable markings that can reach a dead
marking, a backward closure. On two CPUs that closure runs in a thread beside the quick searches
(:class:`.symbolic._TowardDead`). The baseline, in the same run, is the way before: the closure
after them, as on one CPU.

For each net, once: its encoding (``bench/deadlocks.py``'s: the race's first order). For each way,
on a fresh store: the reachable set by saturation, or with ``--chain`` by chained images, its dead
markings (untimed), then the witness, timed. Printed per net: markings, dead markings, the length
of the sequence found each way (the same searches from the same seeds find the same one), the
seconds each way and their ratio (after / beside). On a net whose quick searches find a sequence,
the closure beside is stopped and the ratio is about 1.

A model is a PNML path, or ``FAMILY:N`` (``bench/families.py``). ``--repeat`` runs each way that
many times, by turns.

Usage::

    python bench/witness.py [--json] [--repeat N] [--chain] [--max-memory GIB] [--mcc DIR] MODEL...
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def measure(net: Any, prepared: tuple[Any, Any, Any], beside: bool, max_bytes: int, chain: bool) -> dict[str, Any]:
    """One way on a fresh store: the witness's sequence and the seconds it took."""
    from coordinator.analysis import symbolic
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.mdd_order import events

    enc, fwd, single = prepared
    sn = sparse_net(net)
    back = events(sn, enc, inverse=True, merge=True, like=fwd)
    store = symbolic._Store(enc, max_bytes)
    store.chain = chain
    reach = store.closure(fwd, store.m0, check_overflow=True)
    states = store.count(reach)
    store.count(reach, at_most=float(states) * max(1, single.n_events))
    dead = symbolic._dead(store, fwd, single, reach, store.enabled_counts(reach, single), states)
    # the fields of the result the witness writes
    result = SimpleNamespace(deadlock_marking=None, deadlock_sequence=None, notes=[], seconds={})
    real = getattr(symbolic, "cpus")
    setattr(symbolic, "cpus", (lambda: 2) if beside else (lambda: 1))  # the CPUs the witness sees
    try:
        t0 = time.monotonic()
        symbolic._witness(store, sn, enc, net, fwd, back, reach, dead, result, lambda _text: None,  # type: ignore[arg-type]
                          t0 + symbolic.ANSWER_SECONDS)
        seconds = time.monotonic() - t0
    finally:
        setattr(symbolic, "cpus", real)
    seq = result.deadlock_sequence
    return {"states": states, "dead": store.count(dead), "seconds": seconds,
            "length": None if seq is None else len(seq), "notes": result.notes}


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(ROOT))
    from bench.deadlocks import arguments, prepare
    from bench.statespace import load_model
    from coordinator.analysis.symbolic import load_kernel

    args = arguments(__doc__, "as CloudDeployment-PT-6a's race finishes it", argv)
    load_kernel()
    for spec in args.models:
        net = load_model(spec, args.mcc)
        prepared = prepare(net)
        runs: dict[str, list[dict[str, Any]]] = {"after": [], "beside": []}
        for _ in range(max(1, args.repeat)):
            for way in ("after", "beside"):
                runs[way].append(measure(net, prepared, way == "beside", int(args.max_memory * 2**30), args.chain))
        first = runs["after"][0]
        if first["dead"] == 0:
            print(f"{spec}: {first['states']:,} markings and no dead marking: no witness to time", flush=True)
            continue
        lengths = {r["length"] for rs in runs.values() for r in rs}
        if len(lengths) != 1:
            print(f"{spec}: the two ways found sequences of lengths {sorted(lengths, key=str)}", file=sys.stderr)
        best = {way: min(r["seconds"] for r in rs) for way, rs in runs.items()}
        row = {"model": spec, "states": first["states"], "dead": first["dead"], "length": first["length"],
               "after_seconds": [round(r["seconds"], 3) for r in runs["after"]],
               "beside_seconds": [round(r["seconds"], 3) for r in runs["beside"]],
               "ratio": round(best["after"] / max(best["beside"], 1e-9), 2),
               "notes": sorted({n for rs in runs.values() for r in rs for n in r["notes"]})}
        if args.json:
            print(json.dumps(row), flush=True)
        else:
            print(f"{spec}: {row['states']:,} markings, {row['dead']:,} dead, a sequence of {row['length']} firings; "
                  f"after {best['after']:.2f} s, beside {best['beside']:.2f} s: {row['ratio']:.2f}x", flush=True)
            for note in row["notes"]:
                print(f"  {note}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
