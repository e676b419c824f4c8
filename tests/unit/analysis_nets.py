"""Small nets built in code for the analysis tests (tests/unit/test_statespace.py and siblings)."""

from __future__ import annotations

from collections.abc import Mapping

from coordinator.net import Arc, Marking, PetriNet, Place, Transition


def make_net(
    name: str,
    marking: Mapping[str, int],
    transitions: Mapping[str, tuple[Mapping[str, int], Mapping[str, int]]],
    *,
    places: tuple[str, ...] = (),
    inhibitors: Mapping[str, Mapping[str, int]] | None = None,
) -> PetriNet:
    """Build a plain P/T net: ``transitions[t] = ({input place: weight}, {output place: weight})``.

    Places are those of ``places`` then any other place named, in order of first mention.
    """
    order: list[str] = list(places)

    def see(p: str) -> None:
        if p not in order:
            order.append(p)

    for p in marking:
        see(p)
    arcs: list[Arc] = []
    for t, (pre, post) in transitions.items():
        for p, w in pre.items():
            see(p)
            arcs.append(Arc(source=p, target=t, weight=w))
        for p, w in post.items():
            see(p)
            arcs.append(Arc(source=t, target=p, weight=w))
    for t, inh in (inhibitors or {}).items():
        for p, w in inh.items():
            see(p)
            arcs.append(Arc(source=p, target=t, weight=w, inhibitor=True))
    return PetriNet(
        name=name,
        places=tuple(Place(id=p) for p in order),
        transitions=tuple(Transition(id=t) for t in transitions),
        arcs=tuple(arcs),
        initial_marking=Marking(marking),
    )


def philosophers_arcs(n: int) -> tuple[dict[str, int], dict[str, tuple[dict[str, int], dict[str, int]]]]:
    """The initial marking and transitions (as :func:`make_net` takes them) of ``n`` philosophers
    round a table, each taking the left fork, then the right: one deadlock."""
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        right = f"fork{(i + 1) % n}"
        transitions[f"left{i}"] = ({f"think{i}": 1, f"fork{i}": 1}, {f"hold{i}": 1})
        transitions[f"right{i}"] = ({f"hold{i}": 1, right: 1}, {f"eat{i}": 1})
        transitions[f"done{i}"] = ({f"eat{i}": 1}, {f"think{i}": 1, f"fork{i}": 1, right: 1})
    return {**{f"think{i}": 1 for i in range(n)}, **{f"fork{i}": 1 for i in range(n)}}, transitions


def dekker(n: int) -> PetriNet:
    """Dekker's mutual exclusion generalised to ``n`` processes (the Model Checking Contest's Dekker
    family): process i raises its flag (``try``), enters its critical section when every other
    flag is down (``enter`` reads them all), or lowers its flag and withdraws when it sees another
    one up; it leaves (``exit``) with its flag down. 2**(n - 1) * (n + 2) markings, live."""
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        transitions[f"try_{i}"] = ({f"p0_{i}": 1, f"flag_0_{i}": 1}, {f"p1_{i}": 1, f"flag_1_{i}": 1})
        others = {f"flag_0_{j}": 1 for j in range(n) if j != i}
        transitions[f"enter_{i}"] = ({f"p1_{i}": 1, **others}, {f"p3_{i}": 1, **others})
        transitions[f"exit_{i}"] = ({f"p3_{i}": 1, f"flag_1_{i}": 1}, {f"p0_{i}": 1, f"flag_0_{i}": 1})
        for j in range(n):
            if j != i:
                transitions[f"withdraw_{i}_{j}"] = ({f"p1_{i}": 1, f"flag_1_{i}": 1, f"flag_1_{j}": 1},
                                                    {f"p0_{i}": 1, f"flag_0_{i}": 1, f"flag_1_{j}": 1})
    marking = {**{f"flag_0_{i}": 1 for i in range(n)}, **{f"p0_{i}": 1 for i in range(n)}}
    return make_net(f"dekker{n}", marking, transitions)
