"""What a run tells its observers: typed events, one class per kind (paper section 5).

The runtime (:mod:`coordinator.runtime`) calls its observer with one of these records, right after
the journal has recorded what it describes; displays (the terminal console, the web console, the
catching demo's report) follow the token flow from them. Events are frozen; ``t_wall`` is the Unix
time in seconds at which the runtime emitted the event.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from coordinator.breakpoints import Breakpoint
from coordinator.engine import Firing
from coordinator.operator import OperatorCommand
from coordinator.reconcile import differs
from services.results import ActionResult, Status

__all__ = [
    "ActionEnded",
    "ActionFeedback",
    "ActionStarted",
    "BreakpointHit",
    "CallReconciled",
    "LearnerUpdated",
    "Observer",
    "OperatorApplied",
    "OperatorRefused",
    "PulseDelivered",
    "RunEvent",
    "RunStateChanged",
    "TransitionFired",
]


def _now() -> float:
    return time.time()


@dataclass(frozen=True, slots=True)
class RunStateChanged:
    """The run started, resumed, paused, resumed firing, waits, or ended.

    Attributes:
        run: run id.
        state: ``started``, ``resumed``, ``paused``, ``running``, ``waiting`` (nothing can fire
            now; ``reason`` says what the run waits for) or an end state (``completed``,
            ``stuck``, ``waiting_for_operator``, ``aborted``, ``deadline``, ``interrupted``; see
            :data:`coordinator.runtime.END_STATES`).
        reason: why, in words, or ``""``.
        detail: one line per item behind the reason: the places that are stuck, the operator
            commands that would let a transition fire, the external events awaited.
    """

    run: str
    state: str
    reason: str = ""
    t_wall: float = field(default_factory=_now)
    detail: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class TransitionFired:
    """A transition fired (already journaled); the engine's marking is the one it produced."""

    run: str
    firing: Firing
    t_wall: float = field(default_factory=_now)


@dataclass(frozen=True, slots=True)
class ActionStarted:
    """A primitive action was sent to its node for a new instance of a primitive task.

    Attributes:
        instance: instance id (also the call id on the node).
        task: primitive task.
        place: its primitive-task place.
        action: the primitive action chosen (by the learner, section 4).
        node: the node services.toml places it on, or ``None`` if it is not placed.
        params: the parameters the action was called with (the task's, then the action's own).
    """

    run: str
    instance: str
    task: str
    place: str
    action: str
    node: str | None
    t_wall: float = field(default_factory=_now)
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class ActionEnded:
    """A primitive action returned (already journaled, not yet latched in the engine); ``forced``: the
    operator forced this outcome (the net's ``[operator]`` table), it is no measured result."""

    run: str
    instance: str
    task: str
    action: str
    node: str | None
    result: ActionResult
    t_wall: float = field(default_factory=_now)
    forced: bool = False


@dataclass(frozen=True, slots=True)
class ActionFeedback:
    """A running primitive action sent feedback (progress, an estimate) through its node.

    Journaled as sampled (:mod:`coordinator.feedback`: at most a few a second per call, always the
    last one before the result), and shown on the consoles (paper section 5).

    Attributes:
        instance, task, action: the running call (``instance`` is the call id).
        data: the feedback as the action sent it (msgpack-decoded: maps, lists, numbers, strings).
    """

    run: str
    instance: str
    task: str
    action: str
    data: Any
    t_wall: float = field(default_factory=_now)


@dataclass(frozen=True, slots=True)
class CallReconciled:
    """A node told, afterwards, the fate of a call the runtime had given up on (already journaled).

    Attributes:
        instance, task, action, node: the call (``instance`` is the call id).
        assumed: the status the net went on with, or ``None`` if no result was journaled.
        result: the node's final result, or ``None`` if the node does not know the call (it never
            ran, or its result is no longer kept).
        lost: why the runtime had given up on the call, in words (``"heartbeat timeout"``), or ``""``.
    """

    run: str
    instance: str
    task: str
    action: str
    node: str | None
    assumed: Status | None
    result: ActionResult | None
    lost: str = ""
    t_wall: float = field(default_factory=_now)

    @property
    def differs(self) -> bool:
        """True when the node's final status is not the one the net went on with
        (:func:`coordinator.reconcile.differs`)."""
        return differs(self.assumed, None if self.result is None else self.result.status)


@dataclass(frozen=True, slots=True)
class PulseDelivered:
    """An external event arrived as a pulse; ``fired`` transitions fired on it; ``operator``: the
    operator raised it (``inject``), not its publisher; ``payload``: what the event carried (the
    publisher's event data, msgpack-decoded; a ROS 2 topic's message fields; the operator's JSON),
    or ``None``."""

    run: str
    event: str
    fired: int
    t_wall: float = field(default_factory=_now)
    operator: bool = False
    payload: Any = None


@dataclass(frozen=True, slots=True)
class BreakpointHit:
    """A breakpoint paused the run (journaled as a ``pause`` with the breakpoint as its detail).

    Attributes:
        breakpoint: the breakpoint (:mod:`coordinator.breakpoints`).
        why: what made it true, in words (``"ball_caught fired"``).
    """

    run: str
    breakpoint: Breakpoint
    why: str
    t_wall: float = field(default_factory=_now)


@dataclass(frozen=True, slots=True)
class OperatorApplied:
    """An operator command was journaled and applied."""

    run: str
    command: OperatorCommand
    t_wall: float = field(default_factory=_now)


@dataclass(frozen=True, slots=True)
class OperatorRefused:
    """An operator command was refused (journaled with the reason); the run is unchanged.

    Attributes:
        command: the command, or the typed line when it was no command.
        reason: why it was refused.
    """

    run: str
    command: OperatorCommand | str
    reason: str
    t_wall: float = field(default_factory=_now)


@dataclass(frozen=True, slots=True)
class LearnerUpdated:
    """A primitive task's learning automaton took in a result (section 4).

    Attributes:
        task: primitive task.
        state: the automaton's state dict (probabilities, estimates; see coordinator.learning).
    """

    run: str
    task: str
    state: Mapping[str, Any]
    t_wall: float = field(default_factory=_now)


RunEvent = (RunStateChanged | TransitionFired | ActionStarted | ActionFeedback | ActionEnded | CallReconciled
            | PulseDelivered | OperatorApplied | OperatorRefused | LearnerUpdated | BreakpointHit)
"""Any event of a run."""

Observer = Callable[[RunEvent], None]
"""Called with each event; must not block (a display that fails is logged, never stops the run)."""
