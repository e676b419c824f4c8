"""The coordinator's asyncio shell around the engine (paper sections 2 and 5).

:class:`Runtime` drives a :class:`~coordinator.engine.Engine`: it calls each primitive action on
the node that ``services.toml`` places it on (through :class:`services.client.ServiceClient`),
turns results into engine completions, subscribes to the external events the net uses and
delivers them as pulses, applies operator commands, and journals every firing, action start,
action result and operator command (refused ones too) *before* it takes effect.

The loop serves its inputs between every two firings: operator commands, the ``max_seconds``
deadline, results and pulses are looked at before each firing, and the event loop gets a turn
every ``max_firings_per_tick`` firings, so a net that cycles without events still obeys ``pause``,
``abort`` and the deadline at once. When nothing can fire the run either waits — for running
primitive actions, for an external event that would let a transition fire, or for the operator
(paused, or only a control place holds a transition back, or, with ``linger``, at home) — saying
what it waits for with a ``RunStateChanged("waiting", ...)`` event, or it ends in one of
:data:`~coordinator.runsummary.END_STATES` (at home: ``completed``; tokens left away from home:
``stuck``, naming the places; only an absent operator could help: ``waiting_for_operator``).

A call the runtime gives up on (node trouble ended it with an error no node sent) is reconciled
with its node (:mod:`coordinator.reconcile`): as soon as the node can be reached again, at the end
of the run, and when the run is resumed, the node is asked for the call's final result, which is
journaled (a ``reconciliation`` record) and reported (:class:`~coordinator.events.CallReconciled`).

Breakpoints (:mod:`coordinator.breakpoints`) are operator commands like the others: the runtime
looks at them after every firing, token change and result, and a breakpoint that becomes true
pauses the run (journaled as a ``pause`` with the breakpoint). Where the net's ``[operator]``
table allows it, an operator may raise an external event (``inject``: delivered as a pulse exactly
like its publisher's) or force the outcome of a running primitive action (``force``: the call is
cancelled on its node and the instance ends with the forced outcome, journaled ``forced``, never
fed to the learner or counted in the run's statistics).

The runtime owns no policy: which action translates a primitive task comes from the learner
(section 4) passed in, or the first action of the task.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from coordinator.breakpoints import BreakpointWatch, Hit
from coordinator.engine import (
    CancelAction,
    Effect,
    Engine,
    Firing,
    StartAction,
)
from coordinator.engine.rest import at_rest, home_marking, work_places
from coordinator.errors import EngineError
from coordinator.events import (
    ActionEnded,
    ActionFeedback,
    ActionStarted,
    BreakpointHit,
    CallReconciled,
    LearnerUpdated,
    Observer,
    OperatorApplied,
    OperatorRefused,
    PulseDelivered,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.feedback import FeedbackSampler
from coordinator.journal import Journal, Recovered
from coordinator.net import FORCE_STATUSES, PetriNet
from coordinator.operator import Command, OperatorCommand
from coordinator.reconcile import GivenUp, Reconciler, describe, given_up, never_sent
from coordinator.runsummary import END_STATES, EXIT_CODES, ActionStats, RunSummary
from services.errors import LocationError
from services.results import ActionResult, Status

__all__ = ["END_STATES", "EXIT_CODES", "ActionChooser", "ActionStats", "InFlight", "RunSummary", "Runtime"]

log = logging.getLogger("petrobot.runtime")


class ActionChooser(Protocol):
    """What the runtime needs to choose primitive actions and learn from their results (section 4).

    :class:`coordinator.learning.Learner` is one.
    """

    def choose(self, task: str) -> str:
        """The primitive action to run for a new instance of primitive task ``task``."""

    def update(self, task: str, action: str, result: ActionResult) -> Any:
        """Feed back a result; may return the task's new state dict, which is journaled."""


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
    operator: bool = False  # raised by the operator (inject), not by its publisher
    payload: Any = None  # what the event carried (the publisher's data, the operator's JSON)


@dataclass(frozen=True, slots=True)
class _Invalid:
    text: str
    reason: str


@dataclass(frozen=True, slots=True)
class _Wait:
    """The run waits: until a new input, or ``until`` (monotonic s); ``reason``/``detail`` say why."""

    reason: str = ""
    detail: tuple[str, ...] = ()
    home: bool = False  # at the home marking (waiting only because ``linger`` asks to)


@dataclass(frozen=True, slots=True)
class _End:
    state: str
    note: str
    detail: tuple[str, ...] = ()


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
            More observers (the web console next to the terminal one) join with :meth:`add_observer`.
        max_firings_per_tick: firings between two turns of the event loop (inputs already queued
            are served between every two firings regardless).
        operator: an operator can send commands (:meth:`command`): a run that only an operator
            command could move on waits for one instead of ending ``waiting_for_operator``.
        linger: with an operator, a run that has come home waits too while a control place could
            let a transition fire (to add runs), until ``end``, ``abort`` or the deadline.
        cancel_grace_s: after an abort or the deadline, how long to wait for the cancelled
            primitive actions' results before ending anyway, seconds.
        goal: place → tokens: a run at rest whose marking holds at least these tokens has reached
            the net's goal and ends ``completed`` like one at home (a net that does not come back
            to its home marking, e.g. one that runs once).
        reconcile_s: at the end of the run, how long to wait for the nodes of calls given up on
            (and not reconciled yet) to tell their fate, seconds; those still unknown then are
            named in the run's note and summary.

    Raises:
        EngineError: ``goal`` names a place the net does not have.
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
        max_firings_per_tick: int = 1,
        operator: bool = False,
        linger: bool = False,
        cancel_grace_s: float = 3.0,
        goal: Mapping[str, int] | None = None,
        reconcile_s: float = 5.0,
    ) -> None:
        self.net = net
        self.client = client
        self.journal = journal
        self.learner = learner
        self.observer = observer
        self._observers: tuple[Observer, ...] = ()  # replaced, never changed in place: safe to emit
        self.operator = operator
        self.linger = linger
        self._per_tick = max(1, max_firings_per_tick)
        self._grace_s = cancel_grace_s
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
        self._work = work_places(net)
        self._home = home_marking(net)
        self._goal = dict(goal or {})
        unknown = [pid for pid in self._goal if pid not in net.place_index]
        if unknown:  # an error now, not a run that never completes
            raise EngineError(f"the goal names places that net {net.name!r} does not have: {', '.join(unknown)}")
        self._inbox: collections.deque[_Completed | _Pulse] = collections.deque()
        self._commands: collections.deque[OperatorCommand | _Invalid] = collections.deque()
        self._wake = asyncio.Event()
        self._inflight: dict[str, InFlight] = {}
        self._feedback: FeedbackSampler[ActionFeedback] = FeedbackSampler()
        self._dead_topics: set[str] = set()
        self._deadline: float | None = None
        self._ending: _End | None = None
        self._ending_until = 0.0
        self._end_requested = False
        self._last_wait: _Wait | None = None
        self.stats: dict[tuple[str, str], ActionStats] = {}
        if recovered is not None:  # a resumed run counts the results before its interruption too
            for row in journal.results(self.run_id):
                self.stats.setdefault((row.task, row.action), ActionStats(row.task, row.action, row.node or "?")).record(
                    row.result)
        self.errors: list[str] = []
        #: the operator's breakpoints (:mod:`coordinator.breakpoints`); a resumed run re-arms those
        #: its journal says were set at the interruption
        self.breakpoints = BreakpointWatch(net)
        for bp in () if recovered is None else recovered.breakpoints:
            self.breakpoints.add(bp, self.engine)
        self._reconciler = Reconciler(client, self._reconciled)
        self._reconcile_s = reconcile_s
        self._reissued: set[str] = set()
        #: what nodes said about the calls given up on, in the order they said it
        self.reconciled: list[CallReconciled] = []
        self._t0 = time.monotonic()

    # ------------------------------------------------------------------ public controls
    def add_observer(self, observer: Observer) -> None:
        """Also call ``observer`` with each event, after :attr:`observer` and the observers added
        before it (each must not block; one that raises is logged and the others still run)."""
        self._observers = (*self._observers, observer)

    def remove_observer(self, observer: Observer) -> None:
        """Stop calling an observer added with :meth:`add_observer` (no error if it is not there)."""
        self._observers = tuple(o for o in self._observers if o != observer)

    def command(self, cmd: OperatorCommand) -> None:
        """Queue an operator command; it is served before the next firing (call it from the loop's
        thread: another thread uses ``loop.call_soon_threadsafe(runtime.command, cmd)``)."""
        self._commands.append(cmd)
        self._wake.set()

    def refuse_input(self, text: str, reason: str) -> None:
        """Queue a typed line that is no command: it is journaled as refused, with ``reason``."""
        self._commands.append(_Invalid(text, reason))
        self._wake.set()

    def running(self) -> list[InFlight]:
        """The running primitive actions, in start order."""
        return list(self._inflight.values())

    @property
    def waiting(self) -> tuple[str, tuple[str, ...]] | None:
        """What the run waits for now (reason, detail), or ``None`` while it does not wait."""
        w = self._last_wait
        return None if w is None else (w.reason, w.detail)

    # ------------------------------------------------------------------ main loop
    async def run(self, *, max_seconds: float | None = None) -> RunSummary:
        """Execute the net until it comes to rest, is aborted, runs out of time or is interrupted.

        Args:
            max_seconds: end the run after this many seconds (``deadline``; a run waiting at home
                with ``linger`` ends ``completed``).

        Returns:
            The run summary (its :attr:`~RunSummary.end_state` is one of :data:`END_STATES`); the
            journal holds every detail.

        Raises:
            asyncio.CancelledError: when cancelled (Ctrl-C); the run is journaled ``interrupted``
                and stays resumable.
        """
        self._subscribe()
        if self._recovered is not None:
            self.journal.reopen_run(self.run_id)
            armed = self.breakpoints.breakpoints
            self._emit(RunStateChanged(self.run_id, "resumed", f"breakpoints re-armed from the journal: "
                                       f"{', '.join(map(str, armed))}" if armed else ""))
            for inst in self.engine.running_instances():
                task = self.net.tasks[inst.task]
                params = dict(self._recovered.params.get(inst.id, task.action(inst.action).params))
                self._dispatch(StartAction(inst.id, inst.task, inst.place, inst.action, params, task.deadline_s),
                               journal=False)
            self._reconcile_journaled()
        else:
            self._emit(RunStateChanged(self.run_id, "started"))
        self._handle(self.engine.start())
        self._deadline = None if max_seconds is None else time.monotonic() + max_seconds
        end = _End("interrupted", "the coordinator stopped; petrobot run --resume continues the run")
        try:
            end = await self._loop(max_seconds)
            await self._settle_calls()
        except (asyncio.CancelledError, KeyboardInterrupt):
            end = _End("interrupted", "interrupted; petrobot run --resume continues the run")
            await self._cancel_on_nodes(1.0)
            raise
        finally:
            for flight in list(self._inflight.values()):
                if flight.call is not None:
                    flight.call.cancel()
            note = end.note
            calls = sum(st.calls for st in self.stats.values())
            if calls and all(st.error == st.calls for st in self.stats.values()):
                note += f" | every one of the {calls} primitive-action calls ended in error"
            if self.errors:
                note += f" | last errors: {'; '.join(self.errors[-3:])}"
            unreconciled = self._unreconciled()
            self._reconciler.abandon()
            differed = [describe(e.node, e.action, e.assumed, e.result, e.lost) for e in self.reconciled if e.differs]
            if differed:
                note += f" | reconciled differently: {'; '.join(differed[-3:])}"
            if unreconciled:
                note += f" | not reconciled: {'; '.join(unreconciled[-3:])}"
            self.journal.end_run(self.run_id, end.state, note)
            self._emit(RunStateChanged(self.run_id, end.state, end.note, detail=end.detail))
        return RunSummary(self.run_id, end.state, self.engine.marking.to_dict(), self.engine.fired,
                          time.monotonic() - self._t0, self.stats, self.errors, end.note, end.detail,
                          reconciled=len(self.reconciled), differed=tuple(differed),
                          unreconciled=tuple(unreconciled))

    # ------------------------------------------------------------------ reconciliation
    def _follow_up(self, instance: str, start: StartAction, node: str | None, result: ActionResult | None) -> None:
        """After a call ended (``result``), or was left running at the end of the run (``None``): if
        its fate on its node is unknown, have the node asked (reconciliation); if the node answered,
        its other calls given up on can be asked now."""
        reissued = instance in self._reissued
        self._reissued.discard(instance)
        if node is None:
            return
        if result is not None:
            if not given_up(result):
                self._reconciler.node_answered(node)
                return
            if never_sent(result, node) and not reissued:
                return
        self._reconciler.add(GivenUp(instance, start.task, start.action, node,
                                     None if result is None else result.status,
                                     "" if result is None else result.reason or ""))

    def _reconcile_journaled(self) -> None:
        """On resume: reconcile the calls of this run given up on before (by an earlier coordinator
        too) that no node has told the fate of yet."""
        done = {r.instance for r in self.journal.reconciliations(self.run_id)}
        for row in self.journal.results(self.run_id):
            if row.instance in done or row.node is None or row.status is not Status.ERROR:
                continue
            if given_up(row.result):
                self._reconciler.add(GivenUp(row.instance, row.task, row.action, row.node, row.status,
                                             row.reason or ""))

    def _reconciled(self, call: GivenUp, truth: ActionResult | None) -> None:
        self.journal.reconciliation(self.run_id, call.instance, call.task, call.action, call.node, call.assumed,
                                    truth)
        event = CallReconciled(self.run_id, call.instance, call.task, call.action, call.node, call.assumed, truth,
                               call.lost)
        self.reconciled.append(event)
        if event.differs:
            log.info("%s [%s]", describe(call.node, call.action, call.assumed, truth, call.lost), call.instance)
        self._emit(event)

    async def _settle_calls(self) -> None:
        """At the end of the run: give up on the calls still running (an abort or the deadline did
        not see their results in time), then let the nodes tell the fate of every call given up on."""
        for instance, flight in list(self._inflight.items()):
            if flight.call is not None:
                flight.call.cancel()  # the client sends the node a cancel
            del self._inflight[instance]
            self._feedback_ended(instance)
            self._follow_up(instance, flight.start, flight.node, None)
        if self._reconciler.pending:
            await self._reconciler.settle(self._reconcile_s)

    def _unreconciled(self) -> list[str]:
        trouble = self._reconciler.trouble
        return [f"{c.action} on {c.node} [{c.instance}]" + (f": {trouble[c.instance]}" if c.instance in trouble else "")
                for c in self._reconciler.pending]

    async def _loop(self, max_seconds: float | None) -> _End:
        engine = self.engine
        while True:
            self._serve_commands()
            if self._ending is not None:
                if not self._inflight or time.monotonic() >= self._ending_until:
                    return self._ending
                self._drain_results()
                await self._wait_input(self._ending_until)
                continue
            if self._deadline is not None and time.monotonic() >= self._deadline:
                if not self._inflight and not self._inbox and not engine.firing_possible():
                    verdict = self._at_rest()
                    if isinstance(verdict, _End):
                        return verdict
                    if verdict.home:  # waiting only for more runs the operator might start
                        where = verdict.reason.split(";")[0].removeprefix("completed: ")
                        return _End("completed", f"{where} when --max-seconds {max_seconds:g} ran out")
                self._begin_ending("deadline", f"--max-seconds {max_seconds:g} ran out")
                continue
            if self._inbox:
                item = self._inbox.popleft()
                if isinstance(item, _Completed):
                    self._on_result(item.instance, item.result)
                else:
                    await self._pulse(item)
                continue
            if await self._fire():
                continue
            if self._commands or self._inbox:
                continue
            verdict = self._at_rest()
            if isinstance(verdict, _End):
                return verdict
            if verdict != self._last_wait and verdict.reason:
                self._emit(RunStateChanged(self.run_id, "waiting", verdict.reason, detail=verdict.detail))
            self._last_wait = verdict if verdict.reason else self._last_wait
            await self._wait_input(self._deadline)

    async def _fire(self, *, pulse: bool = False) -> int:
        """Fire while something can, serving operator commands and checking the deadline before
        each firing; stop at a result or pulse to serve (outside a pulse window). Returns the count."""
        engine, n = self.engine, 0
        while True:
            if self._commands:
                self._serve_commands()
            if self._ending is not None or (self._deadline is not None and time.monotonic() >= self._deadline):
                return n
            if self._inbox and not pulse:
                return n
            firing = engine.next_firing()
            if firing is None:
                return n
            self.journal.firing(self.run_id, firing)
            self._handle(engine.apply(firing))
            self._last_wait = None
            if self.breakpoints:
                self._break(self.breakpoints.after_firing(firing.transition, engine))
            n += 1
            if n % self._per_tick == 0:
                await asyncio.sleep(0)  # let results, pulses and typed commands in

    async def _pulse(self, pulse: _Pulse) -> None:
        before = self.engine.fired
        self.engine.begin_pulse(pulse.topic)
        try:
            await self._fire(pulse=True)
        finally:
            self.engine.end_pulse()
        self._emit(PulseDelivered(self.run_id, f"ext:{pulse.topic}", self.engine.fired - before,
                                  operator=pulse.operator, payload=pulse.payload))

    def _break(self, hit: Hit | None) -> None:
        """Pause the run at a breakpoint that has just become true (journaled as the operator's pause)."""
        if hit is None or self.engine.paused or self._ending is not None:
            return
        self.journal.operator(self.run_id, "pause", detail={"breakpoint": hit.breakpoint.to_json(), "why": hit.why})
        self.engine.pause()
        self._emit(BreakpointHit(self.run_id, hit.breakpoint, hit.why))
        self._emit(RunStateChanged(self.run_id, "paused", f"breakpoint {hit.breakpoint}: {hit.why}"))

    async def _wait_input(self, until: float | None) -> None:
        if self._inbox or self._commands:
            return
        self._wake.clear()
        timeout = None if until is None else max(0.0, until - time.monotonic())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), timeout)

    def _drain_results(self) -> None:
        """While ending: journal the results that came back, drop pulses."""
        while self._inbox:
            item = self._inbox.popleft()
            if isinstance(item, _Completed):
                self._on_result(item.instance, item.result)

    # ------------------------------------------------------------------ coming to rest
    def _at_rest(self) -> _Wait | _End:
        """Nothing can fire now and no input is queued: wait (and for what), or end (and how)."""
        engine = self.engine
        if self._inflight:
            return _Wait()  # results will come (a dead node's call ends in an error result)
        if engine.paused and not self._end_requested:
            if engine.firing_possible(ignore_pause=True) or self._events_awaited():
                if self.operator:
                    return _Wait("paused: resume, or step to fire one transition")
                return _End("waiting_for_operator", "paused, and no operator can resume the run")
        awaited = self._events_awaited()
        if awaited and not self._end_requested and not engine.paused:
            return _Wait(f"waiting for {', '.join(awaited)}", awaited)
        rest = at_rest(engine, self._work, self._home)
        options = tuple(str(o) for o in rest.options if o.event is None or o.event[4:] not in self._dead_topics)
        marking = engine.marking
        if self._goal and all(marking[p] >= n for p, n in self._goal.items()):
            if options and self.operator and self.linger and not self._end_requested:
                return _Wait(f"completed: the goal is reached; waiting for the operator: {'; '.join(options)}; "
                             "or end to finish", options, home=True)
            return _End("completed", "the goal marking is reached" + ("" if rest.at_home else
                        f" ({len(rest.stuck)} place{'' if len(rest.stuck) == 1 else 's'} away from home)"),
                        rest.stuck)
        if rest.at_home:
            if options and self.operator and self.linger and not self._end_requested:
                return _Wait(f"completed: at the home marking; waiting for the operator: {'; '.join(options)}; "
                             "or end to finish", options, home=True)
            return _End("completed", "at the home marking")
        if options and not self._end_requested:
            if self.operator:
                return _Wait("waiting for the operator: " + "; ".join(options), rest.stuck + options)
            return _End("waiting_for_operator", "only the operator could move the run on, and no operator "
                        "is reading (run it on a terminal, or with --wait): " + "; ".join(options),
                        rest.stuck + options)
        return _End("stuck", f"tokens stuck away from home in {len(rest.stuck)} place"
                    f"{'' if len(rest.stuck) == 1 else 's'}: " + "; ".join(rest.stuck), rest.stuck)

    def _events_awaited(self) -> tuple[str, ...]:
        return tuple(e for e in self.engine.waiting_for() if e[4:] not in self._dead_topics)

    def _begin_ending(self, state: str, note: str) -> None:
        """Abort (operator) or deadline: cancel the running actions, await their results a while."""
        self._ending = _End(state, note)
        self._ending_until = time.monotonic() + self._grace_s
        self._handle(self.engine.abort(note))

    async def _cancel_on_nodes(self, timeout_s: float) -> None:
        calls = [self.client.cancel(cid) for cid in self._inflight]
        if calls:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(asyncio.gather(*calls, return_exceptions=True), timeout_s)

    # ------------------------------------------------------------------ operator commands
    def _serve_commands(self) -> None:
        while self._commands:
            cmd = self._commands.popleft()
            if isinstance(cmd, _Invalid):
                self.journal.operator(self.run_id, "invalid", accepted=False, reason=f"{cmd.text!r}: {cmd.reason}")
                self._emit(OperatorRefused(self.run_id, cmd.text, cmd.reason))
                continue
            try:
                self._apply_operator(cmd)
            except EngineError as exc:
                counted = cmd.command in (Command.INSERT, Command.REMOVE)
                self.journal.operator(self.run_id, cmd.command.value, cmd.place, cmd.count if counted else None,
                                      accepted=False, reason=str(exc))
                self._emit(OperatorRefused(self.run_id, cmd, str(exc)))

    def _apply_operator(self, cmd: OperatorCommand) -> None:
        """Check, journal, then apply one command (section 5); raise EngineError to refuse it."""
        engine, run, command = self.engine, self.run_id, cmd.command
        if self._ending is not None:
            raise EngineError(f"the run is ending ({self._ending.state})")
        if command in (Command.INSERT, Command.REMOVE):
            place = cmd.place or ""
            engine.check_tokens(command.value, place, cmd.count)
            self.journal.operator(run, command.value, place, cmd.count)
            if command is Command.INSERT:
                engine.insert_tokens(place, cmd.count)
            else:
                engine.remove_tokens(place, cmd.count)
        elif command in (Command.BREAK, Command.CLEAR):
            if cmd.breakpoint is None:
                raise EngineError(f"{command.value} needs a breakpoint")
            try:
                if command is Command.BREAK:
                    self.breakpoints.add(cmd.breakpoint, engine)
                else:
                    self.breakpoints.remove(cmd.breakpoint)
            except ValueError as exc:
                raise EngineError(str(exc)) from None
            self.journal.operator(run, command.value, detail=cmd.detail())
        elif command is Command.INJECT:
            self._inject(cmd)
        elif command is Command.FORCE:
            self._force(cmd)
        elif command is Command.PAUSE:
            if engine.paused:
                raise EngineError("the run is already paused")
            self.journal.operator(run, "pause")
            engine.pause()
            self._emit(RunStateChanged(run, "paused", "paused by the operator"))
        elif command is Command.RESUME:
            if not engine.paused:
                raise EngineError("the run is not paused")
            self.journal.operator(run, "resume")
            engine.resume()
            self._emit(RunStateChanged(run, "running", "resumed by the operator"))
        elif command is Command.STEP:
            if not engine.firing_possible(ignore_pause=True):
                raise EngineError("no transition can fire now")
            self.journal.operator(run, "step")
            stepped: list[str] = []

            def journal_firing(firing: Firing) -> None:
                stepped.append(firing.transition)
                self._journal_firing(firing)
            engine.step(journal_firing, self._handle)
            if self.breakpoints and stepped:
                self._break(self.breakpoints.after_firing(stepped[0], engine))
        elif command is Command.ABORT:
            self.journal.operator(run, "abort")
            self._begin_ending("aborted", "aborted by the operator")
        elif command is Command.END:
            self.journal.operator(run, "end")
            self._end_requested = True
        else:
            raise EngineError(f"unknown operator command {command!r}")
        self._last_wait = None
        self._emit(OperatorApplied(run, cmd))
        if command in (Command.INSERT, Command.REMOVE) and self.breakpoints:
            self._break(self.breakpoints.after_change(engine))

    def _inject(self, cmd: OperatorCommand) -> None:
        """Raise an external event for the operator: journaled, then delivered as a pulse."""
        event = cmd.event or ""
        if not self.net.operator.may_inject(event):
            allowed = ", ".join(self.net.operator.inject) or "none"
            raise EngineError(f"net {self.net.name!r} does not let the operator raise {event!r} (its [operator] "
                              f"inject allows: {allowed})")
        self.journal.operator(self.run_id, "inject", detail=cmd.detail())
        self._inbox.append(_Pulse(event[4:], operator=True, payload=cmd.payload))
        self._wake.set()

    def _force(self, cmd: OperatorCommand) -> None:
        """End a running primitive action with the outcome the operator forces (a drill)."""
        flight = self._inflight.get(cmd.instance or "")
        if flight is None:
            raise EngineError(f"no primitive action is running as instance {cmd.instance!r}")
        task, outcome = flight.start.task, cmd.outcome or ""
        if not self.net.operator.may_force(task, outcome):
            allowed = ", ".join(self.net.operator.force.get(task, ())) or "nothing"
            raise EngineError(f"net {self.net.name!r} does not let the operator force {outcome!r} on task {task!r} "
                              f"(its [operator] force allows: {allowed})")
        status, _, named = outcome.partition(".")
        assert status in FORCE_STATUSES  # OperatorRights checked it
        reason = "forced by the operator" + (f": {cmd.reason}" if cmd.reason else "")
        result = ActionResult(status=Status(status), outcome=named or None, reason=reason)
        self.journal.operator(self.run_id, "force", detail=cmd.detail())
        del self._inflight[flight.start.instance]
        # ask the node to stop the real action, then stop waiting for its result (which would come
        # back as "cancelled" and must not end the instance a second time)
        asyncio.get_running_loop().create_task(self._cancel(flight.start.instance))
        if flight.call is not None:
            flight.call.cancel()
        start, node = flight.start, flight.node
        self._feedback_ended(start.instance)
        self.journal.action_result(self.run_id, start.instance, start.task, start.action, node, result, forced=True)
        self._emit(ActionEnded(self.run_id, start.instance, start.task, start.action, node, result, forced=True))
        self.engine.complete(start.instance, result)
        if self.breakpoints:
            self._break(self.breakpoints.after_result(start.task, status, self.engine))

    # ------------------------------------------------------------------ actions and events
    def _subscribe(self) -> None:
        topics = sorted({e[4:] for t in self.net.transitions for e in t.external_events})
        for topic in topics:
            try:
                self.client.subscribe(topic, self._on_event(topic))
            except LocationError as exc:
                self._dead_topics.add(topic)
                self.errors.append(str(exc))
                log.warning("%s: transitions linked to ext:%s will never fire", exc, topic)

    def _on_event(self, topic: str) -> Callable[..., None]:
        def deliver(event: Any = None, *_: Any) -> None:
            # the node's Event (services.protocol.messages): its data is the event's payload
            self._inbox.append(_Pulse(topic, payload=getattr(event, "data", None)))
            self._wake.set()
        return deliver

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
        if not journal:
            self._reissued.add(start.instance)  # an earlier coordinator may have sent it
        self._emit(ActionStarted(self.run_id, start.instance, start.task, start.place, start.action, node,
                                 params=start.params))
        flight.call = asyncio.get_running_loop().create_task(self._call(start))

    async def _call(self, start: StartAction) -> None:
        try:
            result: ActionResult = await self.client.call(start.action, dict(start.params), call_id=start.instance,
                                                          deadline_s=start.deadline_s,
                                                          on_feedback=self._feedback_to_observers(start))
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # a configuration error (action not placed): an error status
            result = ActionResult.error(f"{type(exc).__name__}: {exc}")
        self._inbox.append(_Completed(start.instance, result))
        self._wake.set()

    def _feedback_to_observers(self, start: StartAction) -> Callable[[Any], None]:
        """The call's feedback callback: each feedback becomes an :class:`ActionFeedback` event, and
        is journaled as :class:`FeedbackSampler` samples it (the last one before the result always)."""
        def feedback(data: Any) -> None:
            if start.instance in self._inflight:
                event = ActionFeedback(self.run_id, start.instance, start.task, start.action, data)
                if self._feedback.offer(start.instance, time.monotonic(), event) is not None:
                    self._journal_feedback(event)
                self._emit(event)
        return feedback

    def _journal_feedback(self, event: ActionFeedback) -> None:
        self.journal.feedback(self.run_id, event.instance, event.task, event.action, event.data, event.t_wall)

    def _feedback_ended(self, instance: str) -> None:
        """A call ended: journal the feedback held back since its last journaled one, before its result."""
        held = self._feedback.finish(instance)
        if held is not None:
            self._journal_feedback(held)

    def _on_result(self, instance: str, result: ActionResult) -> None:
        flight = self._inflight.pop(instance, None)
        if flight is None:
            return
        start, node = flight.start, flight.node
        self._feedback_ended(instance)
        self.journal.action_result(self.run_id, instance, start.task, start.action, node, result)
        self._follow_up(instance, start, node, result)
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
        self._last_wait = None
        if self._ending is not None:
            return
        try:
            self.engine.complete(instance, result)
        except EngineError as exc:
            self.errors.append(str(exc))
            return
        if self.breakpoints:
            self._break(self.breakpoints.after_result(start.task, result.status.value, self.engine))

    def _emit(self, event: RunEvent) -> None:
        if self.observer is not None:
            try:
                self.observer(event)
            except Exception:  # a display must never stop the run
                log.exception("observer failed on %s", type(event).__name__)
        for observer in self._observers:
            try:
                observer(event)
            except Exception:
                log.exception("observer failed on %s", type(event).__name__)
