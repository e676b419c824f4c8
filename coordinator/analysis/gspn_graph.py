"""Reachability graph of a GSPN under its priority rules, explored level by level with numpy (pure).

Firing rule (M. Ajmone Marsan, G. Balbo, G. Conte, S. Donatelli, G. Franceschinis, *Modelling with
Generalized Stochastic Petri Nets*, Wiley, 1995, ch. 6): in a marking where an immediate transition
is enabled, only the immediate transitions of the highest priority level may fire (the marking is
*vanishing*); otherwise every enabled exponential transition may fire (the marking is *tangible*).
Inhibitor arcs hold transitions back as in :mod:`coordinator.net`.

The search is the compiled breadth-first explorer of :mod:`coordinator.analysis.statespace`
run with GSPN priority levels; this module only classifies its markings.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from coordinator.analysis.statespace import explore
from coordinator.errors import AnalysisError
from coordinator.net import PetriNet, TransitionKind

__all__ = ["GSPNGraph", "explore_gspn", "priority_levels"]


@dataclass(frozen=True, slots=True)
class GSPNGraph:
    """The reachability graph of a GSPN.

    Attributes:
        states: reachable markings, shape (N, |P|), in discovery order (row 0 is M0).
        src: source marking of each edge, shape (E,).
        dst: target marking of each edge, shape (E,).
        transition: index of the transition fired on each edge, shape (E,).
        vanishing: True for vanishing markings, shape (N,).
    """

    states: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    transition: np.ndarray
    vanishing: np.ndarray


def priority_levels(net: PetriNet) -> np.ndarray:
    """Return the GSPN priority level of each transition, shape (|T|,): 0 for exponential
    transitions, ``1 + priority`` for immediate ones (priorities below 0 are shifted up)."""
    imm = [t.priority for t in net.transitions if t.kind is TransitionKind.IMMEDIATE]
    base = min(imm) if imm else 0
    return np.array(
        [0 if t.kind is TransitionKind.EXPONENTIAL else 1 + t.priority - base for t in net.transitions],
        dtype=np.int64,
    )


def explore_gspn(
    net: PetriNet,
    *,
    max_states: int = 5_000_000,
    progress: Callable[[int, int], None] | None = None,
    max_bytes: int | None = None,
) -> GSPNGraph:
    """Explore the reachability graph of ``net`` under GSPN priority rules.

    The search itself is :func:`coordinator.analysis.statespace.explore` with the levels of
    :func:`priority_levels`; a marking is vanishing when the transitions that fire in it are
    immediate (dead markings are tangible).

    Args:
        net: the net; transitions' ``kind`` and ``priority`` are used.
        max_states: limit on the number of markings.
        progress: called as ``progress(markings, edges)`` while exploring.
        max_bytes: byte budget of the search (default: half the physical memory or 4 GiB).

    Returns:
        :class:`GSPNGraph`.

    Raises:
        AnalysisError: past ``max_states`` markings or the byte budget.
    """
    space = explore(net, max_states=max_states, priority=priority_levels(net), progress=progress,
                    max_bytes=max_bytes)
    if not space.complete and space.stopped_by == "max_memory":
        raise AnalysisError(
            f"net {net.name!r}: the reachability graph outgrew the memory budget after {space.n_states:,} "
            "markings; give the search more memory (or the net is unbounded)"
        )
    if not space.complete:
        raise AnalysisError(
            f"net {net.name!r} has more than {max_states} reachable markings; raise max_states "
            "(or the net is unbounded)"
        )
    immediate = np.array([t.kind is TransitionKind.IMMEDIATE for t in net.transitions], dtype=bool)
    transition = np.asarray(space.transition, dtype=np.int64)
    n = space.states.shape[0]
    vanishing = np.zeros(n, dtype=bool)
    if transition.size:
        vanishing[np.asarray(space.src)[immediate[transition]]] = True
    return GSPNGraph(
        states=np.asarray(space.states, dtype=np.int64),
        src=np.asarray(space.src, dtype=np.int64),
        dst=np.asarray(space.dst, dtype=np.int64),
        transition=transition,
        vanishing=vanishing,
    )
