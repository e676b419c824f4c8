#!/usr/bin/env python3
"""Engine firings per second on a net with >= 1,000 transitions, beside pm4py and a naive loop.

The net: R rings of L places and L transitions (R*L transitions), one token per ring, so R
transitions are fireable at every step and each firing is a conflict draw among them. Three
executors fire the same net in the same run:

* petrobot's engine (coordinator.engine.Engine.advance: incremental enabling, write-ahead hooks off);
* a naive loop over coordinator.net.PetriNet: recompute every enabled transition, fire one;
* pm4py's Petri-net semantics (enabled_transitions + execute), if pm4py is installed
  (`pip install -e .[bench]`).

With ``--runtime`` it also measures the asyncio runtime (coordinator.runtime.Runtime, journal on a
temporary SQLite file, no node: the net has no primitive task) on one ring whose first transition
takes a token from a control place holding ``--budget`` tokens, so the run ends by itself, and the
lateness of ``--max-seconds`` on a ring that cycles forever.

Usage: python bench/engine.py [--rings R] [--length L] [--firings N] [--seconds S] [--runtime] [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import sys
import time

from coordinator.engine import Engine
from coordinator.net import Arc, PetriNet, Place, Transition


def ring_net(rings: int, length: int) -> PetriNet:
    """R rings of L place/transition pairs; a token at the start of each ring."""
    places, transitions, arcs, marking = [], [], [], {}
    for r in range(rings):
        for k in range(length):
            places.append(Place(id=f"p{r}_{k}"))
            transitions.append(Transition(id=f"t{r}_{k}"))
            arcs.append(Arc(source=f"p{r}_{k}", target=f"t{r}_{k}"))
            arcs.append(Arc(source=f"t{r}_{k}", target=f"p{r}_{(k + 1) % length}"))
        marking[f"p{r}_0"] = 1
    return PetriNet(name=f"rings{rings}x{length}", places=places, transitions=transitions, arcs=arcs,
                    initial_marking=marking)


def bench_engine(net: PetriNet, firings: int, seconds: float) -> tuple[int, float]:
    engine = Engine(net, seed=1)
    done, t0 = 0, time.perf_counter()
    while done < firings and time.perf_counter() - t0 < seconds:
        done += len(engine.advance(max_firings=10_000))
    return done, time.perf_counter() - t0


def bench_naive(net: PetriNet, firings: int, seconds: float) -> tuple[int, float]:
    rng = random.Random(1)
    marking = net.initial_marking
    done, t0 = 0, time.perf_counter()
    while done < firings and time.perf_counter() - t0 < seconds:
        enabled = net.enabled_transitions(marking)
        marking = net.fire(marking, enabled[rng.randrange(len(enabled))])
        done += 1
    return done, time.perf_counter() - t0


def bench_pm4py(net: PetriNet, firings: int, seconds: float) -> tuple[int, float] | None:
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # pm4py prints a banner on import
            import pm4py  # noqa: F401
        from pm4py.objects.petri_net import semantics
        from pm4py.objects.petri_net.obj import Marking as PmMarking
        from pm4py.objects.petri_net.obj import PetriNet as PmNet
        from pm4py.objects.petri_net.utils import petri_utils
    except ImportError:
        return None
    pm = PmNet(net.name)
    places = {p.id: PmNet.Place(p.id) for p in net.places}
    trans = {t.id: PmNet.Transition(t.id, t.id) for t in net.transitions}
    for p in places.values():
        pm.places.add(p)
    for t in trans.values():
        pm.transitions.add(t)
    for arc in net.arcs:
        src = places.get(arc.source) or trans[arc.source]
        dst = places.get(arc.target) or trans[arc.target]
        petri_utils.add_arc_from_to(src, dst, pm, weight=arc.weight)
    marking = PmMarking({places[p]: n for p, n in net.initial_marking.items()})
    rng = random.Random(1)
    done, t0 = 0, time.perf_counter()
    while done < firings and time.perf_counter() - t0 < seconds:
        enabled = sorted(semantics.enabled_transitions(pm, marking), key=lambda t: t.name)
        marking = semantics.execute(enabled[rng.randrange(len(enabled))], pm, marking)
        done += 1
    return done, time.perf_counter() - t0


def budget_ring(length: int, budget: int | None) -> PetriNet:
    """One ring of ``length`` places; with a ``budget`` its first transition consumes a control token."""
    from coordinator.net import PlaceKind

    places = [Place(id=f"p{k}") for k in range(length)]
    transitions = [Transition(id=f"t{k}") for k in range(length)]
    arcs = [a for k in range(length) for a in (Arc(source=f"p{k}", target=f"t{k}"),
                                                Arc(source=f"t{k}", target=f"p{(k + 1) % length}"))]
    marking = {"p0": 1}
    if budget is not None:
        places.append(Place(id="budget", kind=PlaceKind.CONTROL))
        arcs.append(Arc(source="budget", target="t0"))
        marking["budget"] = budget
    return PetriNet(name=f"ring{length}", places=places, transitions=transitions, arcs=arcs,
                    initial_marking=marking)


class _NoNodes:
    """A service client for nets without primitive tasks or external events."""

    location = None

    def subscribe(self, topic: str, callback: object) -> None:
        raise AssertionError("the bench net has no external event")


def bench_runtime(net: PetriNet, max_seconds: float | None) -> tuple[int, float, str]:
    """Run ``net`` in the asyncio runtime; return (firings, seconds, end state)."""
    import asyncio
    import tempfile
    from pathlib import Path

    from coordinator.journal import Journal
    from coordinator.runtime import Runtime

    with tempfile.TemporaryDirectory() as tmp, Journal(Path(tmp) / "bench.sqlite") as journal:
        runtime = Runtime(net, _NoNodes(), journal)
        t0 = time.perf_counter()
        summary = asyncio.run(runtime.run(max_seconds=max_seconds))
        return summary.firings, time.perf_counter() - t0, summary.end_state


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rings", type=int, default=100, help="rings (fireable transitions at once)")
    parser.add_argument("--length", type=int, default=10, help="transitions per ring")
    parser.add_argument("--firings", type=int, default=500_000, help="firings per executor (upper bound)")
    parser.add_argument("--seconds", type=float, default=10.0, help="time cap per executor, seconds")
    parser.add_argument("--runtime", action="store_true", help="also measure the asyncio runtime and the "
                        "lateness of --max-seconds")
    parser.add_argument("--budget", type=int, default=20_000, help="firings of the runtime's terminating ring")
    parser.add_argument("--max-seconds", type=float, default=1.0, help="deadline of the runtime's endless ring")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    net = ring_net(args.rings, args.length)
    n, s = bench_engine(net, args.firings, args.seconds)
    engine_rate = n / s
    n2, s2 = bench_naive(net, min(args.firings, 20_000), args.seconds)
    naive_rate = n2 / s2
    pm = bench_pm4py(net, min(args.firings, 20_000), args.seconds)
    pm_rate = None if pm is None else pm[0] / pm[1]
    result = {
        "net": net.name, "transitions": len(net.transitions), "places": len(net.places),
        "firings": n, "seconds": round(s, 3), "firings_per_s": round(engine_rate),
        "naive_firings_per_s": round(naive_rate), "pm4py_firings_per_s": None if pm_rate is None else round(pm_rate),
        "speedup_vs_naive": round(engine_rate / naive_rate, 1),
        "speedup_vs_pm4py": None if pm_rate is None else round(engine_rate / pm_rate, 1),
    }
    if args.runtime:
        n3, s3, end = bench_runtime(budget_ring(args.length, args.budget // args.length), None)
        n4, s4, end4 = bench_runtime(budget_ring(args.length, None), args.max_seconds)
        result.update(runtime_firings=n3, runtime_seconds=round(s3, 3), runtime_end_state=end,
                      runtime_firings_per_s=round(n3 / s3), deadline_s=args.max_seconds,
                      deadline_end_state=end4, deadline_firings=n4,
                      deadline_late_s=round(s4 - args.max_seconds, 4))
    if args.json:
        print(json.dumps(result))
    else:
        print(f"net {net.name}: {len(net.transitions)} transitions, {args.rings} fireable at each step")
        print(f"engine      {engine_rate:12,.0f} firings/s ({n} firings in {s:.2f} s)")
        print(f"naive loop  {naive_rate:12,.0f} firings/s   engine is {engine_rate / naive_rate:,.1f}x")
        if pm_rate is None:
            print("pm4py       not installed (pip install -e .[bench])")
        else:
            print(f"pm4py       {pm_rate:12,.0f} firings/s   engine is {engine_rate / pm_rate:,.1f}x")
        if args.runtime:
            print(f"runtime     {result['runtime_firings_per_s']:12,} firings/s ({n3} firings, journaled, "
                  f"ended {end})")
            print(f"deadline    --max-seconds {args.max_seconds}: ended {end4} after {n4} firings, "
                  f"{result['deadline_late_s']:+.4f} s late")
    return 0


if __name__ == "__main__":
    sys.exit(main())
