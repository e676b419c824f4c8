"""What the journal gives back: one frozen record per row, typed (paper sections 3 to 5).

The readers of the journal — ``petrobot perf``, ``gspn`` and ``learn``, the resume of an
interrupted run, a replay of a run — get these records from
:class:`~coordinator.journal.reader.JournalReader`, never SQL rows. Times are Unix times in seconds
(``*_wall``) and durations in seconds (``wall_s``, ``cpu_s``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from coordinator.breakpoints import Breakpoint
from coordinator.engine import Instance
from coordinator.net import Marking
from coordinator.performance import ActionRecord
from coordinator.reconcile import differs
from services.results import ActionResult, Status

__all__ = ["FeedbackRow", "FiringRow", "LearnerState", "OperatorRow", "ReconciliationRow", "Recovered", "ResultRow",
           "RunRow", "RunStats", "StartRow"]


@dataclass(frozen=True, slots=True)
class RunRow:
    """One run of a net.

    Attributes:
        id: run id.
        net_name: the net's name.
        net_text: source text of the net file, when the run stored it.
        seed: seed of the engine's random switches and of the learners.
        started_wall, ended_wall: when it started and ended (``None`` while unfinished).
        end_state: ``completed``, ``stuck``, ``waiting_for_operator``, ``aborted``, ``deadline``,
            ``interrupted`` (resumable), or ``None`` while unfinished (journals written before
            these states say ``dead`` for a run that came to rest); see docs/journal.md.
        note: why the run ended that way and its last errors, in words.
    """

    id: str
    net_name: str
    net_text: str | None
    seed: int
    started_wall: float
    ended_wall: float | None
    end_state: str | None
    note: str | None

    @property
    def finished(self) -> bool:
        """True once the run's end is recorded."""
        return self.ended_wall is not None

    @property
    def resumable(self) -> bool:
        """True while ``petrobot run --resume`` can continue it (unfinished, or interrupted)."""
        return self.ended_wall is None or self.end_state == "interrupted"


@dataclass(frozen=True, slots=True)
class RunStats:
    """A run and what it did, for ``petrobot runs``.

    Attributes:
        run: the run.
        firings: firings journaled.
        calls: primitive-action results journaled; errors, failures: those with that status.
        refused: operator commands refused.
        last_wall: time of its last record (the start when it has none), Unix s.
        reconciled: calls given up on whose fate a node told afterwards; differed: those whose
            final status on the node is not the one the net went on with.
    """

    run: RunRow
    firings: int
    calls: int
    errors: int
    failures: int
    operator_commands: int
    refused: int
    last_wall: float
    reconciled: int = 0
    differed: int = 0

    @property
    def duration_s(self) -> float:
        """From its start to its end, or to its last record while unfinished, seconds."""
        return (self.run.ended_wall or self.last_wall) - self.run.started_wall


class _ResultField:
    """One field of the :class:`~services.results.ActionResult` a row holds, read through the row
    (``row.status`` is ``row.result.status``; ``None`` when the row holds no result)."""

    name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, row: Any, owner: type | None = None) -> Any:
        if row is None:
            return self
        result = row.action_result()
        return None if result is None else getattr(result, self.name)


class _HoldsResult:
    """A row that holds an action's result: its fields read through the row."""

    __slots__ = ()

    status = _ResultField()
    outcome = _ResultField()
    cost = _ResultField()
    wall_s = _ResultField()
    cpu_s = _ResultField()
    reason = _ResultField()
    value = _ResultField()

    def action_result(self) -> ActionResult | None:
        """The result the row holds, or ``None``."""
        raise NotImplementedError


@dataclass(frozen=True, slots=True)
class FeedbackRow:
    """One feedback message of a running primitive action (progress, an estimate), as the runtime
    sampled it for the journal: at most a few a second per call, and always the last one before the
    call's result (docs/journal.md, "Feedback").

    Attributes:
        run: run id.
        instance: the call (its instance id).
        task, action: the primitive task and the primitive action that sent it.
        data: the feedback as the action sent it, through JSON (maps, lists, numbers, strings); a
            feedback too large to keep is ``{"truncated": true, "bytes": N, "head": "..."}``.
        t_wall: when the coordinator received it, Unix s.
        entry: order among every record of the journal.
    """

    run: str
    instance: str
    task: str
    action: str
    data: Any
    t_wall: float
    entry: int = 0


@dataclass(frozen=True, slots=True, kw_only=True)
class ResultRow(_HoldsResult):
    """One primitive-action result: the :class:`~services.results.ActionResult` the coordinator
    received, and where it came from.

    The result is the one record of how the call ended, as the node sent it and the engine took it
    (validated once, when the journal's row was read back); ``status``, ``outcome``, ``cost``,
    ``wall_s``, ``cpu_s``, ``reason`` and ``value`` read it. :attr:`record` is the same result as
    the performance functions take it.

    Attributes:
        run: run id.
        instance: instance id (the call id).
        task, action: the primitive task and the primitive action that ran.
        node: the node that ran the action, or ``None``.
        result: how the call ended (its ``value`` decoded from JSON, ``None`` when JSON could not
            hold it).
        t_wall: when the coordinator received the result.
        entry: order among every record of the journal.
        forced: the operator forced this outcome (a drill): not a measured result.
    """

    run: str
    instance: str
    task: str
    action: str
    node: str | None
    result: ActionResult
    t_wall: float = 0.0
    entry: int = 0
    forced: bool = False

    def action_result(self) -> ActionResult:
        """The result the row holds."""
        return self.result

    @property
    def record(self) -> ActionRecord:
        """The result as the performance functions take it (:mod:`coordinator.performance`)."""
        r = self.result
        return ActionRecord(task=self.task, action=self.action, status=r.status, outcome=r.outcome, cost=r.cost,
                            wall_s=r.wall_s, cpu_s=r.cpu_s)


@dataclass(frozen=True, slots=True)
class StartRow:
    """A primitive action sent to its node for a new instance (before the call left); ``entry``
    orders it among every record of the journal."""

    run: str
    instance: str
    task: str
    place: str
    action: str
    node: str | None
    params: Mapping[str, Any]
    t_wall: float
    entry: int = 0


@dataclass(frozen=True, slots=True)
class FiringRow:
    """A firing, journaled before it was applied (the fields of :class:`coordinator.engine.Firing`)."""

    run: str
    seq: int
    transition: str
    consumed: Mapping[str, int]
    produced: Mapping[str, int]
    instances: tuple[str, ...]
    pulse: str | None
    t_wall: float
    entry: int = 0


@dataclass(frozen=True, slots=True)
class OperatorRow:
    """An operator command (section 5): ``insert``/``remove`` (with place and count), ``pause``,
    ``step``, ``resume``, ``abort``, ``end``, ``break``/``clear`` (a breakpoint), ``inject`` (an
    external event) or ``force`` (an outcome); ``accepted`` is False for a refused command (a line
    that is no command is journaled as ``invalid``), with the refusal in ``reason``. ``detail``
    holds what the command carries besides a place and a count: ``{"breakpoint": {...}}``,
    ``{"event": "ext:..."}``, ``{"instance", "outcome", "reason"}``; a ``pause`` with a
    ``breakpoint`` detail is the pause a breakpoint made."""

    run: str
    command: str
    place: str | None
    count: int | None
    t_wall: float
    accepted: bool = True
    reason: str | None = None
    entry: int = 0
    detail: Any = None


@dataclass(frozen=True, slots=True)
class ReconciliationRow(_HoldsResult):
    """What a node said, when asked afterwards, about a call the coordinator had given up on.

    The coordinator gives up on a call when node trouble (a lost connection, missed heartbeats, an
    unanswered deadline) ends it with an ``error`` result the node did not send; the net goes on
    with that error. When the node is reachable again the coordinator cancels the call if it still
    runs and asks the node for its final result (docs/protocol.md §5, ``query``).

    Attributes:
        run, instance, task, action, node: the call (``instance`` is the call id).
        assumed: the status the net went on with (the journaled result's), or ``None`` when no
            result was journaled (the run ended, on abort or deadline, before one came).
        truth: the node's final result, or ``None`` when the node does not know the call (it
            never ran, or its result is no longer kept); ``status``, ``outcome``, ``reason``,
            ``cost``, ``wall_s``, ``cpu_s`` and ``value`` read it (``None`` when unknown).
        t_wall: when the node's answer was journaled.
        entry: order among every record of the journal.
    """

    run: str
    instance: str
    task: str
    action: str
    node: str | None
    assumed: Status | None
    truth: ActionResult | None
    t_wall: float
    entry: int = 0

    def action_result(self) -> ActionResult | None:
        """The node's final result, or ``None``."""
        return self.truth

    @property
    def known(self) -> bool:
        """True when the node knew the call (it ran, or started and died with the node)."""
        return self.truth is not None

    @property
    def differs(self) -> bool:
        """True when the node's final status is not the one the net went on with
        (:func:`coordinator.reconcile.differs`: a call the node never ran, or ended in error,
        agrees with an ``error`` and with no result at all)."""
        return differs(self.assumed, self.status)


@dataclass(frozen=True, slots=True)
class LearnerState:
    """The latest saved state of one primitive task's learning automaton (section 4).

    Attributes:
        task: primitive task.
        scheme: its scheme (``pursuit``, ``lri``, ``fixed``).
        state: :meth:`coordinator.learning.LearningAutomaton.state_dict` output.
        updated_wall: when it was saved.
    """

    task: str
    scheme: str
    state: Mapping[str, Any]
    updated_wall: float


@dataclass(frozen=True, slots=True)
class Recovered:
    """What :meth:`JournalReader.recover` rebuilt for an interrupted run.

    Attributes:
        run: the run id.
        seed: the seed the run was started with.
        marking: marking after the last journaled record.
        instances: live instances (running, or ended but not consumed), in start order.
        nodes: instance id → node the action was sent to.
        params: instance id → parameters of the call (for re-issuing it with the same call id).
        fired: number of firings journaled.
        next_instance: next free instance number.
        breakpoints: the operator's breakpoints set at the interruption (their ``break`` commands
            not cleared since), in the order they were set: the resumed run re-arms them.
    """

    run: str
    seed: int
    marking: Marking
    instances: tuple[Instance, ...]
    nodes: Mapping[str, str | None]
    params: Mapping[str, Any]
    fired: int
    next_instance: int
    breakpoints: tuple[Breakpoint, ...] = ()
