"""Where a run has come to rest, and why (paper sections 2 and 5); pure, no I/O.

When nothing can fire, no primitive action runs and no external event could let anything fire,
a run has come to rest. :func:`at_rest` tells the runtime what that rest means:

* **home**: the marking is the net's home marking (declared with ``home`` in the net file, else its
  initial marking, as the qualitative analysis takes it), compared on the places that hold work:
  control places (the operator's) and *sink* places (no transition takes their tokens: counters
  such as ``done`` or ``aborted_runs``) are left out, so a run that did more or fewer runs than
  the home marking counts is home all the same;
* **stuck places**: tokens left in primitive-task places (an action ended and no transition takes
  its outcome), and every other place that differs from home, each named with its count;
* **operator options**: commands on control places that would let a transition fire
  (:meth:`Engine.operator_options`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from coordinator.engine.effects import OperatorOption
from coordinator.engine.engine import Engine
from coordinator.net import PetriNet, PlaceKind

__all__ = ["Rest", "at_rest", "home_marking", "work_places"]


@dataclass(frozen=True, slots=True)
class Rest:
    """What a run at rest looks like.

    Attributes:
        at_home: the marking is home on every work place (:func:`work_places`).
        stuck: one line per place that holds the run away from home, e.g.
            ``"sensing: 1 token (sense ended error; no transition takes it)"`` or
            ``"robot: 0 tokens (home 1)"``; empty when at home.
        options: operator commands that would let a transition fire.
    """

    at_home: bool
    stuck: tuple[str, ...]
    options: tuple[OperatorOption, ...]


def home_marking(net: PetriNet) -> Mapping[str, int]:
    """The net's declared home marking, else its initial marking (places not listed hold 0)."""
    return net.home_marking if net.home_marking is not None else net.initial_marking


def work_places(net: PetriNet) -> tuple[str, ...]:
    """Places compared with home, in net order: every primitive-task place, and every other place
    that is neither a control place nor a sink (a place no transition takes tokens from; an
    inhibitor arc takes none)."""
    taken = {a.source for a in net.arcs if not a.inhibitor}
    return tuple(p.id for p in net.places if p.kind is PlaceKind.PRIMITIVE_TASK
                 or (p.kind is not PlaceKind.CONTROL and p.id in taken))


def _tokens(n: int) -> str:
    return f"{n} token{'' if n == 1 else 's'}"


def at_rest(engine: Engine, work: tuple[str, ...] | None = None,
            home: Mapping[str, int] | None = None) -> Rest:
    """Describe the engine's marking as a place of rest (see the module docstring).

    Args:
        engine: the engine of the run (its marking and ended instances are read, nothing changes).
        work: the places to compare (default :func:`work_places` of its net; pass it to save the
            O(|arcs|) scan when called often).
        home: the home marking (default :func:`home_marking` of its net).

    Returns:
        :class:`Rest`. O(|P| + |T|).
    """
    net = engine.net
    work = work_places(net) if work is None else work
    home = home_marking(net) if home is None else home
    marking = engine.marking
    ended: dict[str, list[str]] = {}
    for inst in engine.ended_instances():
        status = inst.status.value if inst.status is not None else "?"
        extra = sorted(inst.outcomes - {"ok", "success", "failure", "error"})
        ended.setdefault(inst.place, []).append(status + (f" ({', '.join(extra)})" if extra else ""))
    stuck: list[str] = []
    for pid in work:
        have, want = marking[pid], home.get(pid, 0)
        if have == want:
            continue
        place = net.place(pid)
        if place.kind is PlaceKind.PRIMITIVE_TASK and pid in ended:
            how = ", ".join(sorted(set(ended[pid])))
            stuck.append(f"{pid}: {_tokens(have)} ({place.task} ended {how}; no transition takes it)")
        else:
            stuck.append(f"{pid}: {_tokens(have)} (home {want})")
    return Rest(not stuck, tuple(stuck), engine.operator_options())
