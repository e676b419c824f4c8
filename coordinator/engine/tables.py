"""The static tables the engine compiles from a net once, at construction (paper section 2).

The engine's firing loop looks things up by transition id thousands of times per second: arcs,
events, priorities, which transitions a place change may enable or disable. :class:`EngineTables`
holds those lookups, computed once from the frozen :class:`~coordinator.net.PetriNet`; nothing in
it changes during a run. Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from coordinator.expr import Scalar, scalar
from coordinator.net import PetriNet, PlaceKind, parse_event

__all__ = ["EngineTables"]

Arcs = tuple[tuple[str, int], ...]
"""``((place id, weight), ...)`` of one transition, in the net's arc order."""


@dataclass(frozen=True, slots=True)
class EngineTables:
    """Lookups by transition id (``tid``) and place id (``pid``) for one net.

    Attributes:
        tids: transition ids in net order (a transition's *index* is its position here).
        order: tid → index.
        inputs, outputs, inhib: tid → ``((pid, weight), ...)`` of its input, output and inhibitor
            arcs.
        priority: tid → priority (higher fires first).
        weight: tid → weight of the random switch among equal priorities.
        ext: tid → topic of its ``ext:<topic>`` event, or ``None``.
        pulse_of: tid → ``"ext:<topic>"``, or ``None``.
        by_topic: topic → tids linked to ``ext:<topic>``.
        needs: tid → {task: outcomes its ``int:<task>.<outcome>`` events require}.
        task_of: primitive-task pid → task name.
        task_place_ids: primitive-task pids in net order.
        control: pids of control places (the operator may edit them, section 5).
        dependents: pid → indices of the transitions that have it as input or inhibitor place
            (the ones a change of its tokens may enable or disable), ascending.
        touch: tid → indices of the transitions its firing may enable or disable.
        task_outputs: tid → its output arcs into primitive-task places.
        task_inputs: tid → whether an input place is a primitive-task place.
        consumed_map, produced_map: tid → read-only {pid: weight} of a :class:`Firing` (for a
            transition with reset arcs, ``consumed_map`` holds its input arcs only: the engine adds
            what the resets remove when it decides a firing).
        resets: tid → ids of the places its reset arcs empty (most transitions: ``()``).
        weight_fn: tid → its weight expression compiled for the engine's counts (a dict place id →
            tokens), for the transitions whose weight is an expression.
        uniform: every transition has the same priority and a constant, equal weight (a conflict is
            a uniform draw).
    """

    tids: tuple[str, ...]
    order: Mapping[str, int]
    inputs: Mapping[str, Arcs]
    outputs: Mapping[str, Arcs]
    inhib: Mapping[str, Arcs]
    priority: Mapping[str, int]
    weight: Mapping[str, float]
    ext: Mapping[str, str | None]
    pulse_of: Mapping[str, str | None]
    by_topic: Mapping[str, tuple[str, ...]]
    needs: Mapping[str, Mapping[str, frozenset[str]]]
    task_of: Mapping[str, str]
    task_place_ids: tuple[str, ...]
    control: frozenset[str]
    dependents: Mapping[str, tuple[int, ...]]
    touch: Mapping[str, frozenset[int]]
    task_outputs: Mapping[str, Arcs]
    task_inputs: Mapping[str, bool]
    consumed_map: Mapping[str, Mapping[str, int]]
    produced_map: Mapping[str, Mapping[str, int]]
    uniform: bool
    resets: Mapping[str, tuple[str, ...]]
    weight_fn: Mapping[str, Callable[[Any], Scalar]]

    @classmethod
    def compile(cls, net: PetriNet) -> EngineTables:
        """Compute the tables of ``net`` (O(|P| + |T| + |arcs|) plus the touch sets)."""
        transitions = net.transitions
        inputs = {t.id: tuple(net.input_places[t.id].items()) for t in transitions}
        outputs = {t.id: tuple(net.output_places[t.id].items()) for t in transitions}
        inhib = {t.id: tuple(net.inhibitor_places[t.id].items()) for t in transitions}
        ext = {t.id: (t.external_events[0][4:] if t.external_events else None) for t in transitions}
        needs: dict[str, dict[str, frozenset[str]]] = {}
        for t in transitions:
            per_task: dict[str, set[str]] = {}
            for event in t.internal_events:
                _, task, outcome = parse_event(event)
                per_task.setdefault(task, set()).add(outcome)
            needs[t.id] = {k: frozenset(v) for k, v in per_task.items()}
        task_of = {p.id: p.task for p in net.places if p.kind is PlaceKind.PRIMITIVE_TASK and p.task is not None}
        resets = {t.id: net.reset_places[t.id] for t in transitions}
        weight_fn: dict[str, Callable[[Any], Scalar]] = {}
        for t in transitions:
            tree = t.weight_tree
            if tree is not None:
                weight_fn[t.id] = scalar(tree)
        deps: dict[str, set[str]] = {p.id: set() for p in net.places}
        for t in transitions:
            for pid, _ in inputs[t.id] + inhib[t.id]:
                deps[pid].add(t.id)
        order = {t.id: j for j, t in enumerate(transitions)}
        # transition *indices*: a set of ints iterates in the same order in every process
        dependents = {pid: tuple(sorted(order[t] for t in ts)) for pid, ts in deps.items()}
        by_topic: dict[str, tuple[str, ...]] = {}
        for t in transitions:
            topic = ext[t.id]
            if topic is not None:
                by_topic[topic] = by_topic.get(topic, ()) + (t.id,)
        return cls(
            tids=tuple(t.id for t in transitions),
            order=order,
            inputs=inputs,
            outputs=outputs,
            inhib=inhib,
            priority={t.id: t.priority for t in transitions},
            weight={t.id: t.weight for t in transitions},
            ext=ext,
            pulse_of={tid: (f"ext:{topic}" if topic else None) for tid, topic in ext.items()},
            by_topic=by_topic,
            needs=needs,
            task_of=task_of,
            task_place_ids=tuple(p.id for p in net.places if p.kind is PlaceKind.PRIMITIVE_TASK),
            control=frozenset(p.id for p in net.places if p.kind is PlaceKind.CONTROL),
            dependents=dependents,
            touch={t.id: frozenset(j for pid in [p for p, _ in inputs[t.id] + outputs[t.id]] + list(resets[t.id])
                                   for j in dependents[pid])
                   for t in transitions},
            task_outputs={t.id: tuple((pid, w) for pid, w in outputs[t.id] if pid in task_of) for t in transitions},
            task_inputs={t.id: any(pid in task_of for pid, _ in inputs[t.id]) for t in transitions},
            consumed_map={t.id: MappingProxyType(dict(inputs[t.id])) for t in transitions},
            produced_map={t.id: MappingProxyType(dict(outputs[t.id])) for t in transitions},
            uniform=len({(t.priority, t.weight) for t in transitions}) <= 1 and not weight_fn,
            resets=resets,
            weight_fn=weight_fn,
        )
