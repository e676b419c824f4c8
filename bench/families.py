"""Model Checking Contest families scaled to any size, for the state-space benchmarks.

The contest publishes each family at a few sizes; these build the same nets at the size asked, so
that the symbolic engine can be measured on families beyond the instances in ``tests/data``. Each
is checked against the contest's instance of the same size in ``tests/data/mcc``
(``tests/unit/test_bench_families.py``): the same places, transitions, arcs and initial marking.

* ``philosophers:N`` — Philosophers-PT-N: N dining philosophers, each taking the fork on either
  side first (transitions FF1a/FF1b), then the other (FF2a/FF2b), eating and putting both back
  (End). 3^N markings, and a deadlock.
* ``sharedmemory:N`` — SharedMemory-PT-N: N processes, each with its own memory, reaching another
  process's memory over one shared bus.
* ``fms:N`` — FMS-PT-N: the flexible manufacturing system of Ciardo and Trivedi with N pallets of
  each part type (FMS-PT-00002's structure, its three pallet places scaled).
* ``kanban:N`` — Kanban-PT-N: the Kanban net of Ciardo and Tilgner with N cards per stage
  (Kanban-PT-00005's structure, its four card places scaled).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from coordinator.net import Arc, Marking, PetriNet, Place, Transition

__all__ = ["FAMILIES", "build"]

Pre = dict[str, int]


def _net(name: str, marking: dict[str, int], places: list[str], transitions: dict[str, tuple[Pre, Pre]]) -> PetriNet:
    arcs = [Arc(source=p, target=t, weight=w) for t, (pre, _) in transitions.items() for p, w in pre.items()]
    arcs += [Arc(source=t, target=p, weight=w) for t, (_, post) in transitions.items() for p, w in post.items()]
    return PetriNet(name=name, places=tuple(Place(id=p) for p in places),
                    transitions=tuple(Transition(id=t) for t in transitions), arcs=tuple(arcs),
                    initial_marking=Marking({p: k for p, k in marking.items() if k}))


def philosophers(n: int, mcc: Path) -> PetriNet:
    """Philosophers-PT-n (places Think/Fork/Catch1/Catch2/Eat_i, i = 1..n; fork i − 1 is on the left)."""
    places = [f"{kind}_{i}" for kind in ("Think", "Fork", "Catch1", "Catch2", "Eat") for i in range(1, n + 1)]
    t: dict[str, tuple[Pre, Pre]] = {}
    for i in range(1, n + 1):
        left = f"Fork_{(i - 2) % n + 1}"
        t[f"FF1a_{i}"] = ({f"Think_{i}": 1, left: 1}, {f"Catch1_{i}": 1})
        t[f"FF1b_{i}"] = ({f"Think_{i}": 1, f"Fork_{i}": 1}, {f"Catch2_{i}": 1})
        t[f"FF2a_{i}"] = ({f"Catch1_{i}": 1, f"Fork_{i}": 1}, {f"Eat_{i}": 1})
        t[f"FF2b_{i}"] = ({f"Catch2_{i}": 1, left: 1}, {f"Eat_{i}": 1})
        t[f"End_{i}"] = ({f"Eat_{i}": 1}, {f"Think_{i}": 1, f"Fork_{i}": 1, left: 1})
    marking = {f"{kind}_{i}": 1 for kind in ("Think", "Fork") for i in range(1, n + 1)}
    return _net(f"Philosophers-{n}", marking, places, t)


def shared_memory(n: int, mcc: Path) -> PetriNet:
    """SharedMemory-PT-n (processes i = 1..n; Ext_Mem_Acc_i_j: process i holds the bus and memory j)."""
    procs = range(1, n + 1)
    places = ["Ext_Bus"] + [f"{kind}_{i}" for i in procs for kind in ("Active", "Memory", "Queue", "OwnMemAcc")]
    places += [f"Ext_Mem_Acc_{i}_{j}" for i in procs for j in procs if i != j]
    t: dict[str, tuple[Pre, Pre]] = {}
    for i in procs:
        t[f"Begin_Own_Acc_{i}"] = ({f"Active_{i}": 1}, {f"OwnMemAcc_{i}": 1})
        t[f"End_Own_Acc_{i}_{i}"] = ({f"OwnMemAcc_{i}": 1, f"Memory_{i}": 1}, {f"Memory_{i}": 1, f"Active_{i}": 1})
        t[f"Req_Ext_Acc_{i}"] = ({f"Active_{i}": 1}, {f"Queue_{i}": 1})
        for j in procs:
            if i != j:
                t[f"Begin_Ext_Acc_{i}_{j}"] = ({"Ext_Bus": 1, f"Queue_{i}": 1, f"Memory_{j}": 1},
                                               {f"Ext_Mem_Acc_{i}_{j}": 1})
                t[f"End_Ext_Acc_{i}_{j}"] = ({f"Ext_Mem_Acc_{i}_{j}": 1},
                                             {"Ext_Bus": 1, f"Memory_{j}": 1, f"Active_{i}": 1})
    marking = {"Ext_Bus": 1, **{f"{kind}_{i}": 1 for kind in ("Active", "Memory") for i in procs}}
    return _net(f"SharedMemory-{n}", marking, places, t)


def _scaled(model: str, family: str, scaled: tuple[str, ...] | None) -> Callable[[int, Path], PetriNet]:
    def build_scaled(n: int, mcc: Path) -> PetriNet:
        from coordinator.netfile.pnml import load_pnml

        base = load_pnml(mcc / model / "model.pnml")
        marking = {p: (n if scaled is None or p in scaled else k) for p, k in base.initial_marking.items()}
        return PetriNet(name=f"{family}-{n}", places=base.places, transitions=base.transitions, arcs=base.arcs,
                        initial_marking=Marking(marking))

    what = "every marked place" if scaled is None else ", ".join(scaled)
    build_scaled.__doc__ = f"{model}'s structure with n tokens on {what}."
    return build_scaled


#: family name → builder(n, folder of the contest's models)
FAMILIES: dict[str, Callable[[int, Path], PetriNet]] = {
    "philosophers": philosophers,
    "sharedmemory": shared_memory,
    "fms": _scaled("FMS-PT-00002", "FMS", ("P1", "P2", "P3")),
    "kanban": _scaled("Kanban-PT-00005", "Kanban", None),
}


def build(spec: str, mcc: Path) -> PetriNet:
    """The net of ``FAMILY:N`` (e.g. ``philosophers:100``).

    Raises:
        ValueError: an unknown family, or N not a positive integer.
    """
    family, _, size = spec.partition(":")
    if family not in FAMILIES:
        raise ValueError(f"{spec!r}: unknown family {family!r} (known: {', '.join(sorted(FAMILIES))})")
    if not size.isdigit() or int(size) < 1:
        raise ValueError(f"{spec!r}: the size after the colon must be a positive integer")
    return FAMILIES[family](int(size), mcc)
