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
