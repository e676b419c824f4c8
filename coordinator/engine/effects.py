"""The engine's vocabulary: run states, instances, and the effect records it emits (paper section 2).

The engine (:mod:`coordinator.engine.engine`) takes method calls and returns these records; the
asyncio runtime (:mod:`coordinator.runtime`) journals them and carries them out. All are plain
data: a :class:`Firing` is what the journal writes before the engine applies it, a
:class:`StartAction` asks the runtime to call a primitive action on its node, a
:class:`CancelAction` asks it to cancel one.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from services.results import Status

__all__ = ["CancelAction", "Chooser", "Effect", "EngineState", "Firing", "Instance", "OperatorOption", "StartAction"]


class EngineState(enum.Enum):
    """Where a run stands."""

    #: Transitions can fire, instances are running, or the net waits for an external event.
    RUNNING = "running"
    #: The operator paused the run: nothing fires except by :meth:`Engine.step`.
    PAUSED = "paused"
    #: Nothing can ever happen again without an operator: no transition can fire, no instance
    #: runs and no transition waits for an external event.
    DEAD = "dead"
    #: The operator aborted the run.
    ABORTED = "aborted"


@dataclass(slots=True)
class Instance:
    """One running (or ended, not yet consumed) instance of a primitive task.

    Attributes:
        id: unique id within the run (also used as the call id towards the node).
        task: primitive task name.
        place: id of the primitive-task place holding its token.
        action: the primitive action chosen to translate the task.
        status: ``None`` while running, then the returned status.
        outcomes: outcome names latched on the token once ended (:attr:`ActionResult.events`).
    """

    id: str
    task: str
    place: str
    action: str
    status: Status | None = None
    outcomes: frozenset[str] = frozenset()

    @property
    def running(self) -> bool:
        """True while the primitive action has not returned."""
        return self.status is None


@dataclass(frozen=True, slots=True)
class Firing:
    """A decided firing, journaled before it is applied.

    Attributes:
        seq: 1-based firing number in the run.
        transition: id of the transition.
        consumed: place id → tokens removed.
        produced: place id → tokens added.
        instances: ids of the ended instances whose tokens are consumed.
        pulse: the external event that let it fire, or ``None``.
    """

    seq: int
    transition: str
    consumed: Mapping[str, int]
    produced: Mapping[str, int]
    instances: tuple[str, ...] = ()
    pulse: str | None = None


@dataclass(frozen=True, slots=True)
class StartAction:
    """Request to start a primitive action for a new instance.

    Attributes:
        instance: instance id (use it as the call id: nodes deduplicate repeated ids).
        task: primitive task name.
        place: primitive-task place id.
        action: primitive action name (placed on a node by ``services.toml``).
        params: parameters for the call.
        deadline_s: deadline in seconds, or ``None``.
    """

    instance: str
    task: str
    place: str
    action: str
    params: Mapping[str, Any] = field(default_factory=dict)
    deadline_s: float | None = None


@dataclass(frozen=True, slots=True)
class CancelAction:
    """Request to cancel a running primitive action.

    Attributes:
        instance: instance id.
        reason: why, in words.
    """

    instance: str
    reason: str


@dataclass(frozen=True, slots=True)
class OperatorOption:
    """What the operator could do to a control place to let a transition fire (section 5).

    Attributes:
        transition: the transition every other condition of which holds now.
        insert: control place → tokens to insert (an input arc lacks them).
        remove: control place → tokens to remove (an inhibitor arc holds the transition back).
        event: the external event the transition would then still wait for, or ``None``.
    """

    transition: str
    insert: Mapping[str, int] = field(default_factory=dict)
    remove: Mapping[str, int] = field(default_factory=dict)
    event: str | None = None

    @property
    def commands(self) -> tuple[str, ...]:
        """The operator commands, as typed: ``("+ runs_remaining 1", "- hold 1")``."""
        return (tuple(f"+ {p} {n}" for p, n in self.insert.items())
                + tuple(f"- {p} {n}" for p, n in self.remove.items()))

    def __str__(self) -> str:
        then = f" (then it waits for {self.event})" if self.event else ""
        return f"{', '.join(self.commands)} would enable {self.transition}{then}"


Effect = Firing | StartAction | CancelAction
"""Anything the engine asks its caller to record or do."""

Chooser = Callable[[str, tuple[str, ...]], str]
"""Chooses the primitive action of a primitive task: ``(task name, action names) -> action name``."""
