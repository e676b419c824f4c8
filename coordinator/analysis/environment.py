"""The operator as the environment of a task net, and retry loops (paper sections 2 and 7).

Pure: no I/O. A control place (``kind = "control"``: remaining runs, a stop or reset request) is
the operator's: while the task runs, a person (or the console, or a node's external event) puts
tokens into it. The ordinary view of a net leaves control places with their initial tokens only,
so a task whose recovery goes through the operator looks stuck. :func:`with_environment` adds the
operator to the net as transitions without input places, one per control place, each putting one
token into its place while the place holds fewer than its *environment limit*:

* the place's declared ``capacity``, when given;
* otherwise the larger of its initial and home counts, and at least 1.

So the operator may top a control place up again at any moment, never past that limit (the
analysed net stays bounded if the task's net is). Removing tokens is not modelled: emptying a
control place only stops the task (a run is not started), which the ordinary view already covers
once the place runs out. External events (``ext:``) need no such transitions: the ordinary view
drops every event, so a transition waiting for one is already assumed to get it.

:func:`retry_loops` finds the retries of a net — transitions of an error branch (linked to
``int:<task>.error`` or hidden) that start the primitive task they consume from again (the task's
place is both an input and an output) — and tells, on the reachability graph, whether each can
fire for ever: whether one of its firings lies on a cycle of markings made only of error-branch
firings (the task fails and is retried again and again while nothing else happens). A retry whose
count is bounded by a counter place (``nets/catch.toml``: ``home_retries_left``) lies on no such
cycle.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from coordinator.analysis.statespace import StateSpace
from coordinator.net import Arc, PetriNet, PlaceKind, Transition, parse_event

__all__ = ["ENV_PREFIX", "environment_limits", "retry_loops", "retry_transitions", "with_environment"]

#: Prefix of the ids of the operator's transitions added by :func:`with_environment`.
ENV_PREFIX = "operator_adds_to."
_MAX_EXAMPLES = 3


def environment_limits(net: PetriNet) -> dict[str, int]:
    """Control place id → the most tokens the operator may bring it up to (see the module doc)."""
    home = net.home_marking
    out = {}
    for p in net.places:
        if p.kind is not PlaceKind.CONTROL:
            continue
        if p.capacity is not None:
            limit = p.capacity
        else:
            limit = max(net.initial_marking[p.id], home[p.id] if home is not None else 0, 1)
        if limit > 0:
            out[p.id] = limit
    return out


def with_environment(net: PetriNet) -> tuple[PetriNet, dict[str, int]]:
    """Return ``(net with the operator's transitions appended, control place → limit)``.

    For each control place ``p`` with limit ``k`` (:func:`environment_limits`), the transition
    ``operator_adds_to.p`` has no input place, one output arc to ``p`` and an inhibitor arc from
    ``p`` of threshold ``k``. The task's own transitions keep their order and indices (the added
    ones come last). A net without control places is returned unchanged with ``{}``.
    """
    limits = environment_limits(net)
    if not limits:
        return net, {}
    taken = {t.id for t in net.transitions} | {p.id for p in net.places}
    trans = list(net.transitions)
    arcs = list(net.arcs)
    for pid, k in limits.items():
        tid = ENV_PREFIX + pid
        while tid in taken:  # an id the task already uses: make ours unique
            tid += "_"
        trans.append(Transition(id=tid, label=f"the operator adds a token to {pid}", hidden=False))
        arcs.append(Arc(source=tid, target=pid))
        arcs.append(Arc(source=pid, target=tid, weight=k, inhibitor=True))
    return replace(net, transitions=tuple(trans), arcs=tuple(arcs)), limits


def _error_branch_ids(net: PetriNet) -> set[str]:
    return {t.id for t in net.transitions
            if t.hidden or any(parse_event(e)[2] == "error" for e in t.internal_events)}


def retry_transitions(net: PetriNet) -> dict[str, str]:
    """Transition id → task name, for every retry: an error-branch transition that consumes a token
    of a primitive-task place and gives one back to the same place (the task runs again)."""
    errors = _error_branch_ids(net)
    ins, outs = net.input_places, net.output_places
    out: dict[str, str] = {}
    for t in net.transitions:
        if t.id not in errors:
            continue
        for pid in ins.get(t.id, {}):
            place = net.place(pid)
            if place.kind is PlaceKind.PRIMITIVE_TASK and pid in outs.get(t.id, {}):
                out[t.id] = str(place.task)
                break
    return out


def retry_loops(space: StateSpace | None, original: PetriNet) -> dict[str, Any]:
    """Judge each retry of ``original`` on a complete reachability graph of it (or of a net with
    the same transition ids: its environment or its projection).

    Returns:
        ``{"retries": [{"transition", "task", "bounded": bool | None, "example"?}], "unbounded":
        [ids]}``; ``bounded`` is None for every retry when ``space`` is None or incomplete. An
        unbounded retry's ``example`` is ``{"marking", "firing_sequence"}``: a marking from which
        it can fire for ever, reached from M0 by a shortest firing sequence.
    """
    retries = retry_transitions(original)
    rows: list[dict[str, Any]] = [{"transition": t, "task": task, "bounded": None} for t, task in retries.items()]
    if space is None or not space.complete or not retries:
        return {"retries": rows, "unbounded": []}
    errors = _error_branch_ids(original)
    idx = space.net.transition_index
    err = np.array(sorted(idx[t] for t in errors if t in idx), dtype=np.int64)
    keep = np.isin(space.transition, err)
    src, dst, tr = space.src[keep], space.dst[keep], space.transition[keep]
    n = space.n_states
    g = sp.csr_matrix((np.ones(src.size, dtype=np.int8), (src, dst)), shape=(n, n))
    _, comp = csgraph.connected_components(g, directed=True, connection="strong")
    on_cycle = (src == dst) | (comp[src] == comp[dst])
    unbounded = []
    for row in rows:
        j = idx[row["transition"]]
        hits = np.flatnonzero((tr == j) & on_cycle)
        row["bounded"] = not hits.size
        if hits.size:
            unbounded.append(row["transition"])
            if len(unbounded) <= _MAX_EXAMPLES:
                i = int(src[hits[0]])
                row["example"] = {"marking": space.marking(i).to_dict(), "firing_sequence": space.firing_sequence(i)}
    return {"retries": rows, "unbounded": unbounded}
