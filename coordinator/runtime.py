"""The coordinator's asyncio shell around the engine (DESIGN.md §2–3, paper section 5).

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

from coordinator.engine import CancelAction, Effect, Engine, EngineState, Firing, StartAction
from coordinator.errors import EngineError, LocationError
from coordinator.journal import Journal, Recovered
from coordinator.net import PetriNet

__all__ = ["Runtime", "RunSummary", "ActionStats", "Learner", "OperatorCommand", "parse_operator_command"]

log = logging.getLogger("petrobot.runtime")


class Learner(Protocol):
    """What the runtime needs from a learner (coordinator.learning, section 4)."""

    def choose(self, task: str) -> str: ...

    def update(self, task: str, action: str, status: str, cost: float | None) -> Any:
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


@dataclass(frozen=True)
class OperatorCommand:
    """An operator command (section 5): ``insert``/``remove`` tokens, ``pause``, ``step``,
    ``resume``, ``abort``."""

    command: str
    place: str | None = None
    count: int = 1


def parse_operator_command(text: str) -> OperatorCommand:
    """Parse a typed command: ``+ PLACE [N]``, ``- PLACE [N]``, ``insert PLACE [N]``,
    ``remove PLACE [N]``, ``pause``, ``step``, ``resume``, ``abort``.

    Raises:
        ValueError: with a usage hint, on anything else.
    """
    words = text.split()
    if not words:
        raise ValueError("empty command")
    head = {"+": "insert", "-": "remove", "p": "pause", "s": "step", "r": "resume", "q": "abort"}.get(
        words[0], words[0])
    if head in ("insert", "remove"):
        if len(words) not in (2, 3):
            raise ValueError(f"usage: {head} PLACE [COUNT]")
        try:
            count = int(words[2]) if len(words) == 3 else 1
        except ValueError:
            raise ValueError(f"count must be an integer, got {words[2]!r}") from None
        return OperatorCommand(head, words[1], count)
    if head in ("pause", "step", "resume", "abort") and len(words) == 1:
        return OperatorCommand(head)
    raise ValueError("commands: + PLACE [N] | - PLACE [N] | pause | step | resume | abort")


Observer = Callable[[str, dict[str, Any]], None]


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
        observer: called as ``observer(kind, info)`` for ``fire``, ``start``, ``result``, ``pulse``,
            ``operator`` and ``state`` (for displays); must not block.
        max_firings_per_tick: firings between two visits of the event loop.
    """

    def __init__(
        self,
        net: PetriNet,
        client: Any,
        journal: Journal,
        *,
        seed: int = 0,
        learner: Learner | None = None,
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
        self._queue: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
        self._calls: dict[str, asyncio.Task[None]] = {}
        self._nodes: dict[str, str] = {}
        self._starts: dict[str, StartAction] = {}
        self._started_at: dict[str, float] = {}
        self.stats: dict[tuple[str, str], ActionStats] = {}
        self.errors: list[str] = []
        self._t0 = time.monotonic()

    # ------------------------------------------------------------------ public controls
    def command(self, cmd: OperatorCommand) -> None:
        """Queue an operator command (safe from any coroutine of the loop)."""
        self._queue.put_nowait(("operator", cmd))

    def running(self) -> list[dict[str, Any]]:
        """Running primitive actions: instance, task, action, node, elapsed seconds."""
        now = time.monotonic()
        return [{"instance": i.id, "task": i.task, "action": i.action, "node": self._nodes.get(i.id, "?"),
                 "elapsed_s": now - self._started_at.get(i.id, now)} for i in self.engine.running_instances()]

    # ------------------------------------------------------------------ main loop
    async def run(self, *, max_seconds: float | None = None) -> RunSummary:
        """Execute the net until it is dead (nothing more can happen) or aborted.

        Args:
            max_seconds: abort the run after this many seconds (a safety net for unattended use).

        Returns:
            The run summary; the journal holds every detail.
        """
        self._subscribe()
        self._emit("state", {"state": "started", "run": self.run_id})
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
                if state is EngineState.ABORTED and not self._calls:
                    end_state = "aborted"
                    break
                if state is EngineState.DEAD and not self._calls and self._queue.empty():
                    end_state = "dead"
                    break
                if self.engine.next_firing() is not None:
                    await asyncio.sleep(0)  # a net cycling without events: let I/O in
                    continue
                timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
                try:
                    item = await asyncio.wait_for(self._queue.get(), timeout)
                except TimeoutError:
                    self._apply_operator(OperatorCommand("abort"), reason="max_seconds reached")
                    deadline = None
                    continue
                self._process(item)
        except (asyncio.CancelledError, KeyboardInterrupt):
            end_state = "interrupted"
            for cid in list(self._calls):
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(self.client.cancel(cid), 1.0)
            raise
        finally:
            for task in list(self._calls.values()):
                task.cancel()
            note = "; ".join(self.errors[-3:])
            self.journal.end_run(self.run_id, end_state, note)
            self._emit("state", {"state": end_state, "run": self.run_id})
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
            self._queue.put_nowait(("pulse", topic))
        return deliver

    def _process(self, item: tuple[str, Any]) -> None:
        kind, payload = item
        if kind == "result":
            self._on_result(*payload)
        elif kind == "pulse":
            self._emit("pulse", {"event": f"ext:{payload}"})
            self.engine.pulse(payload, self._journal_firing, max_firings=self._max_firings,
                              after_fire=self._handle)
        elif kind == "operator":
            try:
                self._apply_operator(payload)
            except EngineError as exc:
                self._emit("operator", {"command": payload.command, "error": str(exc)})

    def _apply_operator(self, cmd: OperatorCommand, reason: str = "aborted by the operator") -> None:
        engine = self.engine
        if cmd.command in ("insert", "remove"):
            place = cmd.place or ""
            engine.check_tokens(cmd.command, place, cmd.count)  # validate, journal, then apply
            self.journal.operator(self.run_id, cmd.command, place, cmd.count)
            if cmd.command == "insert":
                engine.insert_tokens(place, cmd.count)
            else:
                engine.remove_tokens(place, cmd.count)
        elif cmd.command == "pause":
            self.journal.operator(self.run_id, "pause")
            engine.pause()
        elif cmd.command == "resume":
            self.journal.operator(self.run_id, "resume")
            engine.resume()
        elif cmd.command == "step":
            self.journal.operator(self.run_id, "step")
            engine.step(self._journal_firing, self._handle)
        elif cmd.command == "abort":
            self.journal.operator(self.run_id, "abort")
            if reason != "aborted by the operator":
                self.errors.append(reason)
            self._handle(engine.abort(reason))
        else:
            raise EngineError(f"unknown operator command {cmd.command!r}")
        self._emit("operator", {"command": cmd.command, "place": cmd.place, "count": cmd.count})

    def _advance(self) -> None:
        """Fire what can fire now: decide, journal, apply, act — one firing at a time."""
        self.engine.advance(self._journal_firing, max_firings=self._max_firings, after_fire=self._handle)

    def _journal_firing(self, firing: Firing) -> None:
        self.journal.firing(self.run_id, firing)

    def _handle(self, effects: list[Effect]) -> None:
        for effect in effects:
            if isinstance(effect, Firing):
                self._emit("fire", {"transition": effect.transition, "seq": effect.seq, "pulse": effect.pulse})
            elif isinstance(effect, StartAction):
                self._dispatch(effect)
            elif isinstance(effect, CancelAction):
                cid = effect.instance
                if cid in self._calls:
                    asyncio.get_running_loop().create_task(self._cancel(cid))

    async def _cancel(self, cid: str) -> None:
        with contextlib.suppress(Exception):
            await self.client.cancel(cid)

    def _dispatch(self, start: StartAction, *, journal: bool = True) -> None:
        try:
            node = self.client.location.node_of(start.action)
        except LocationError:
            node = None
        if journal:
            self.journal.action_start(self.run_id, start.instance, start.task, start.place, start.action,
                                      node, start.params)
        self._nodes[start.instance] = node or "?"
        self._starts[start.instance] = start
        self._started_at[start.instance] = time.monotonic()
        self._emit("start", {"instance": start.instance, "task": start.task, "action": start.action,
                             "node": node or "?"})
        self._calls[start.instance] = asyncio.get_running_loop().create_task(self._call(start))

    async def _call(self, start: StartAction) -> None:
        try:
            result = await self.client.call(start.action, dict(start.params), call_id=start.instance,
                                            deadline_s=start.deadline_s)
            payload: Any = (start, result.status, result.outcome, result.cost, result.wall_s, result.cpu_s,
                            result.reason, result.value, result.node)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # a configuration error (action not placed): an error status
            payload = (start, "error", None, None, 0.0, 0.0, f"{type(exc).__name__}: {exc}", None, None)
        self._queue.put_nowait(("result", payload))

    def _on_result(self, start: StartAction, status: str, outcome: str | None, cost: float | None,
                   wall_s: float, cpu_s: float, reason: str | None, value: Any, node: str | None) -> None:
        self._calls.pop(start.instance, None)
        node = node or self._nodes.get(start.instance)
        self.journal.action_result(self.run_id, start.instance, start.task, start.action, node, status,
                                   outcome=outcome, cost=cost, wall_s=wall_s, cpu_s=cpu_s, reason=reason,
                                   value=value)
        key = (start.task, start.action)
        st = self.stats.setdefault(key, ActionStats(start.task, start.action, node or "?"))
        st.calls += 1
        if status in ("success", "failure", "error"):
            setattr(st, status, getattr(st, status) + 1)
        st.wall_s.append(wall_s)
        if status == "error":
            self.errors.append(f"{start.task}/{start.action} on {node}: {reason or 'error status'}")
        if self.learner is not None:
            try:
                state = self.learner.update(start.task, start.action, status,
                                            cost if cost is not None else wall_s)
            except (KeyError, ValueError) as exc:
                self.errors.append(f"learner: {exc}")
            else:
                if isinstance(state, dict):
                    self.journal.save_learner(start.task, str(state.get("scheme", "")), state)
        self._emit("result", {"instance": start.instance, "task": start.task, "action": start.action,
                              "node": node, "status": status, "outcome": outcome, "wall_s": wall_s,
                              "reason": reason, "value": value})
        if self.engine.state is EngineState.ABORTED:
            return
        try:
            self.engine.complete(start.instance, status if status in ("success", "failure", "error") else "error",
                                 outcome if outcome and outcome.isidentifier() else None)
        except EngineError as exc:
            self.errors.append(str(exc))

    def _emit(self, kind: str, info: dict[str, Any]) -> None:
        if self.observer is not None:
            try:
                self.observer(kind, info)
            except Exception:  # a display must never stop the run
                log.exception("observer failed on %s", kind)
