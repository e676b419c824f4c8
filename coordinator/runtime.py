"""The coordinator's asyncio shell around the engine (paper sections 2 and 5).

:class:`Runtime` drives a :class:`~coordinator.engine.Engine`: it calls each primitive action on
the node that ``services.toml`` places it on (through :class:`services.client.ServiceClient`),
turns results into engine completions, subscribes to the external events the net uses and
delivers them as pulses, applies operator commands, and journals every firing, action start,
action result and operator command *before* it takes effect.

The runtime owns no policy: which action translates a primitive task comes from the learner
(section 4) passed in, or the first action of the task.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from coordinator.engine import (
    CancelAction,
    Effect,
    Engine,
    EngineState,
    Firing,
    StartAction,
)
from coordinator.errors import EngineError
from coordinator.events import (
    ActionEnded,
    ActionStarted,
    LearnerUpdated,
    Observer,
    OperatorApplied,
    OperatorRefused,
    PulseDelivered,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.journal import Journal, Recovered
from coordinator.net import PetriNet
from coordinator.operator import Command, OperatorCommand
from services.errors import LocationError
from services.results import ActionResult, Status

__all__ = ["ActionChooser", "ActionStats", "InFlight", "RunSummary", "Runtime"]

log = logging.getLogger("petrobot.runtime")


class ActionChooser(Protocol):
    """What the runtime needs to choose primitive actions and learn from their results (section 4).

    :class:`coordinator.learning.Learner` is one.
    """

    def choose(self, task: str) -> str:
        """The primitive action to run for a new instance of primitive task ``task``."""

    def update(self, task: str, action: str, result: ActionResult) -> Any:
        """Feed back a result; may return the task's new state dict, which is journaled."""


@dataclass
class ActionStats:
    """Results of one primitive action in a run (durations in seconds)."""

    task: str
    action: str
    node: str
    calls: int = 0
    success: int = 0
    failure: int = 0
    error: int = 0
    wall_s: list[float] = field(default_factory=list)

    def record(self, result: ActionResult) -> None:
        """Count one result."""
        self.calls += 1
        setattr(self, result.status.value, getattr(self, result.status.value) + 1)
        self.wall_s.append(result.wall_s)

    @property
    def mean_wall_s(self) -> float:
        """Mean wall-clock duration on the node, seconds (0 when no call returned)."""
        return sum(self.wall_s) / len(self.wall_s) if self.wall_s else 0.0


@dataclass
class RunSummary:
    """How a run went."""

    run_id: str
    end_state: str
    final_marking: dict[str, int]
    firings: int
    duration_s: float
    actions: dict[tuple[str, str], ActionStats]
    errors: list[str]

    def format(self) -> str:
        """A human-readable multi-line summary."""
        lines = [f"run {self.run_id}: {self.end_state} after {self.firings} firings in {self.duration_s:.2f} s",
                 f"final marking: {self.final_marking or '{}'}"]
        if self.actions:
            lines.append(f"{'task':<14}{'action':<22}{'node':<10}{'calls':>6}{'ok':>5}{'fail':>5}{'err':>5}"
                         f"{'mean s':>9}")
            for st in self.actions.values():
                lines.append(f"{st.task:<14}{st.action:<22}{st.node:<10}{st.calls:>6}{st.success:>5}"
                             f"{st.failure:>5}{st.error:>5}{st.mean_wall_s:>9.3f}")
        for err in self.errors[:10]:
            lines.append(f"error: {err}")
        return "\n".join(lines)


@dataclass(slots=True)
class InFlight:
    """One running primitive action (one per running instance).

    Attributes:
        start: the engine's request that started it.
        node: the node the call went to (``None`` if the action is not placed).
        started: :func:`time.monotonic` when the call left, seconds.
        call: the task awaiting the node's result.
    """

    start: StartAction
    node: str | None
    started: float
    call: asyncio.Task[None] | None = None

    @property
    def elapsed_s(self) -> float:
        """Seconds since the call left."""
        return time.monotonic() - self.started


@dataclass(frozen=True, slots=True)
class _Completed:
    instance: str
    result: ActionResult


@dataclass(frozen=True, slots=True)
class _Pulse:
    topic: str


class Runtime:
    """Run one task net on the nodes of ``services.toml``.

    Args:
        net: the validated task net.
        client: an open service client (its location decides where each action runs).
        journal: the journal to write to.
        seed: seed of the engine's random switches.
        learner: chooses actions and learns from results; ``None`` means the first action.
        recovered: state rebuilt by :meth:`Journal.recover` to resume an interrupted run.
        net_text: source text of the net, stored in the journal with the run.
        observer: called with each :mod:`coordinator.events` record (for displays); must not block.
        max_firings_per_tick: firings between two visits of the event loop.
    """

    def __init__(
        self,
        net: PetriNet,
        client: Any,
        journal: Journal,
        *,
        seed: int = 0,
        learner: ActionChooser | None = None,
        recovered: Recovered | None = None,
        net_text: str | None = None,
        observer: Observer | None = None,
        max_firings_per_tick: int = 1000,
    ) -> None:
        self.net = net
        self.client = client
        self.journal = journal
        self.learner = learner
        self.observer = observer
        self._max_firings = max_firings_per_tick
        if recovered is not None:
            self.run_id = recovered.run
            seed = recovered.seed
        else:
            self.run_id = journal.begin_run(net, net_text=net_text, seed=seed)
        chooser = (lambda task, actions: learner.choose(task)) if learner is not None else None
        self.engine = Engine(net, seed=seed, chooser=chooser, instance_prefix=f"{self.run_id}-")
        self._recovered = recovered
        if recovered is not None:
            self.engine.restore(recovered.marking, recovered.instances, fired=recovered.fired,
                                next_instance=recovered.next_instance)
        self._queue: asyncio.Queue[_Completed | _Pulse | OperatorCommand] = asyncio.Queue()
        self._inflight: dict[str, InFlight] = {}
        self.stats: dict[tuple[str, str], ActionStats] = {}
        self.errors: list[str] = []
        self._t0 = time.monotonic()

    # ------------------------------------------------------------------ public controls
    def command(self, cmd: OperatorCommand) -> None:
        """Queue an operator command (safe from any coroutine of the loop)."""
        self._queue.put_nowait(cmd)

    def running(self) -> list[InFlight]:
        """The running primitive actions, in start order."""
        return list(self._inflight.values())

    # ------------------------------------------------------------------ main loop
    async def run(self, *, max_seconds: float | None = None) -> RunSummary:
        """Execute the net until it is dead (nothing more can happen) or aborted.

        Args:
            max_seconds: abort the run after this many seconds (a safety net for unattended use).

        Returns:
            The run summary; the journal holds every detail.
        """
        self._subscribe()
        self._emit(RunStateChanged(self.run_id, "resumed" if self._recovered is not None else "started"))
        if self._recovered is not None:
            for inst in self.engine.running_instances():
                task = self.net.tasks[inst.task]
                params = dict(self._recovered.params.get(inst.id, task.action(inst.action).params))
                self._dispatch(StartAction(inst.id, inst.task, inst.place, inst.action, params, task.deadline_s),
                               journal=False)
        self._handle(self.engine.start())
        deadline = None if max_seconds is None else time.monotonic() + max_seconds
        end_state = "dead"
        try:
            while True:
                self._advance()
                state = self.engine.state
                if state is EngineState.ABORTED and not self._inflight:
                    end_state = "aborted"
                    break
                if state is EngineState.DEAD and not self._inflight and self._queue.empty():
                    end_state = "dead"
                    break
                if self.engine.next_firing() is not None:
                    await asyncio.sleep(0)  # a net cycling without events: let I/O in
                    continue
                timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
                try:
                    item = await asyncio.wait_for(self._queue.get(), timeout)
                except TimeoutError:
                    self._apply_operator(OperatorCommand(Command.ABORT), reason="max_seconds reached")
                    deadline = None
                    continue
                self._process(item)
        except (asyncio.CancelledError, KeyboardInterrupt):
            end_state = "interrupted"
            for cid in list(self._inflight):
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(self.client.cancel(cid), 1.0)
            raise
        finally:
            for flight in list(self._inflight.values()):
                if flight.call is not None:
                    flight.call.cancel()
            note = "; ".join(self.errors[-3:])
            self.journal.end_run(self.run_id, end_state, note)
            self._emit(RunStateChanged(self.run_id, end_state, note))
        return RunSummary(self.run_id, end_state, self.engine.marking.to_dict(), self.engine.fired,
                          time.monotonic() - self._t0, self.stats, self.errors)

    # ------------------------------------------------------------------ event handling
    def _subscribe(self) -> None:
        topics = sorted({e[4:] for t in self.net.transitions for e in t.external_events})
        for topic in topics:
            try:
                self.client.subscribe(topic, self._on_event(topic))
            except LocationError as exc:
                self.errors.append(str(exc))
                log.warning("%s: transitions linked to ext:%s will never fire", exc, topic)

    def _on_event(self, topic: str) -> Callable[..., None]:
        def deliver(*_: Any) -> None:
            self._queue.put_nowait(_Pulse(topic))
        return deliver

    def _process(self, item: _Completed | _Pulse | OperatorCommand) -> None:
        if isinstance(item, _Completed):
            self._on_result(item.instance, item.result)
        elif isinstance(item, _Pulse):
            before = self.engine.fired
            self.engine.pulse(item.topic, self._journal_firing, max_firings=self._max_firings,
                              after_fire=self._handle)
            self._emit(PulseDelivered(self.run_id, f"ext:{item.topic}", self.engine.fired - before))
        else:
            try:
                self._apply_operator(item)
            except EngineError as exc:
                self._emit(OperatorRefused(self.run_id, item, str(exc)))

    def _apply_operator(self, cmd: OperatorCommand, reason: str = "aborted by the operator") -> None:
        engine = self.engine
        command = cmd.command
        if command in (Command.INSERT, Command.REMOVE):
            place = cmd.place or ""
            engine.check_tokens(command.value, place, cmd.count)  # validate, journal, then apply
            self.journal.operator(self.run_id, command.value, place, cmd.count)
            if command is Command.INSERT:
                engine.insert_tokens(place, cmd.count)
            else:
                engine.remove_tokens(place, cmd.count)
        elif command is Command.PAUSE:
            self.journal.operator(self.run_id, "pause")
            engine.pause()
        elif command is Command.RESUME:
            self.journal.operator(self.run_id, "resume")
            engine.resume()
        elif command is Command.STEP:
            self.journal.operator(self.run_id, "step")
            engine.step(self._journal_firing, self._handle)
        elif command is Command.ABORT:
            self.journal.operator(self.run_id, "abort")
            if reason != "aborted by the operator":
                self.errors.append(reason)
            self._handle(engine.abort(reason))
        else:
            raise EngineError(f"unknown operator command {command!r}")
        self._emit(OperatorApplied(self.run_id, cmd))

    def _advance(self) -> None:
        """Fire what can fire now: decide, journal, apply, act — one firing at a time."""
        self.engine.advance(self._journal_firing, max_firings=self._max_firings, after_fire=self._handle)

    def _journal_firing(self, firing: Firing) -> None:
        self.journal.firing(self.run_id, firing)

    def _handle(self, effects: list[Effect]) -> None:
        for effect in effects:
            if isinstance(effect, Firing):
                self._emit(TransitionFired(self.run_id, effect))
            elif isinstance(effect, StartAction):
                self._dispatch(effect)
            elif isinstance(effect, CancelAction):
                if effect.instance in self._inflight:
                    asyncio.get_running_loop().create_task(self._cancel(effect.instance))

    async def _cancel(self, cid: str) -> None:
        with contextlib.suppress(Exception):
            await self.client.cancel(cid)

    def _dispatch(self, start: StartAction, *, journal: bool = True) -> None:
        try:
            node: str | None = self.client.location.node_of(start.action)
        except LocationError:
            node = None
        if journal:
            self.journal.action_start(self.run_id, start.instance, start.task, start.place, start.action,
                                      node, start.params)
        flight = InFlight(start, node, time.monotonic())
        self._inflight[start.instance] = flight
        self._emit(ActionStarted(self.run_id, start.instance, start.task, start.place, start.action, node))
        flight.call = asyncio.get_running_loop().create_task(self._call(start))

    async def _call(self, start: StartAction) -> None:
        try:
            result: ActionResult = await self.client.call(start.action, dict(start.params), call_id=start.instance,
                                                          deadline_s=start.deadline_s)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # a configuration error (action not placed): an error status
            result = ActionResult.error(f"{type(exc).__name__}: {exc}")
        self._queue.put_nowait(_Completed(start.instance, result))

    def _on_result(self, instance: str, result: ActionResult) -> None:
        flight = self._inflight.pop(instance, None)
        if flight is None:
            return
        start, node = flight.start, flight.node
        self.journal.action_result(self.run_id, instance, start.task, start.action, node, result)
        key = (start.task, start.action)
        self.stats.setdefault(key, ActionStats(start.task, start.action, node or "?")).record(result)
        if result.status is Status.ERROR:
            self.errors.append(f"{start.task}/{start.action} on {node}: {result.reason or 'error status'}")
        if self.learner is not None:
            try:
                state = self.learner.update(start.task, start.action, result)
            except (KeyError, ValueError) as exc:
                self.errors.append(f"learner: {exc}")
            else:
                if isinstance(state, dict):
                    self.journal.save_learner(start.task, str(state.get("scheme", "")), state)
                    self._emit(LearnerUpdated(self.run_id, start.task, state))
        self._emit(ActionEnded(self.run_id, instance, start.task, start.action, node, result))
        if self.engine.state is EngineState.ABORTED:
            return
        try:
            self.engine.complete(instance, result)
        except EngineError as exc:
            self.errors.append(str(exc))

    def _emit(self, event: RunEvent) -> None:
        if self.observer is not None:
            try:
                self.observer(event)
            except Exception:  # a display must never stop the run
                log.exception("observer failed on %s", type(event).__name__)
