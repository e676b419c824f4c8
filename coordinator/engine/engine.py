"""Execution semantics of an interpreted Petri net (paper section 2), sans-IO.

The engine holds the marking of a task net and the instances of its primitive tasks. It does no
I/O and never looks at a clock: inputs are method calls, outputs are effect records that the
asyncio runtime (:mod:`coordinator.runtime`) journals and carries out.

Rules of this module:

* A transition is *enabled* when every input place holds at least the arc weight in available
  tokens and no inhibitor place reaches its threshold. A token in a primitive-task place is
  available only once its instance has ended: while the primitive action runs, the token is busy.
* It *fires* when enabled and every linked event has occurred. ``int:<task>.<outcome>`` events are
  latched on the token of an ended instance until a firing consumes that token: an instance that
  ended with **success** carries ``ok`` and ``success``, **failure** carries ``ok`` and ``failure``,
  **error** carries ``error``; a named outcome reported by the action is added. ``ext:<topic>``
  events are pulses: during :meth:`Engine.pulse` each transition linked to the topic may fire once;
  afterwards the pulse is gone.
* Among transitions that can fire at the same instant, the highest priority wins; ties are broken
  by a random switch on the weights, drawn from a generator seeded at construction, so a run is
  reproducible. A weight that is a marking expression is evaluated in the current marking (tokens
  of running instances included) when a switch needs it; it must be finite and > 0 there, or the
  engine raises :class:`~coordinator.errors.EngineError` naming the transition and the marking.
* A transition with reset arcs empties their places when it fires, after its input arcs have
  consumed and before its output arcs produce; the :class:`Firing` it decides records in
  ``consumed`` every token it removes (input arcs and resets), so the journal replays it as is. A
  reset arc may not empty a primitive-task place (its tokens are running instances).
* A token entering a primitive-task place starts one instance: the engine asks its chooser (the
  learner of section 4) which primitive action to run and emits :class:`StartAction`.
* Operator commands (section 5): insert/remove tokens in control places, pause, step (fire exactly
  one transition), resume, abort (cancel every running instance).

Write-ahead use (the journal is written before a firing is applied)::

    firing = engine.next_firing()      # decide, without changing the marking
    journal.write(firing)
    effects = engine.apply(firing)     # change the marking, start instances

:meth:`Engine.advance` runs that loop with a ``before_fire`` hook.

The module is longer than most: :class:`Engine` is one state machine (marking, instances, the
incremental fireable set) whose firing loop reads its own attributes directly; its vocabulary and
its compiled tables live in :mod:`~coordinator.engine.effects` and :mod:`~coordinator.engine.tables`.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Iterable, Mapping
from types import MappingProxyType

from coordinator.engine.effects import (
    CancelAction,
    Chooser,
    Effect,
    EngineState,
    Firing,
    Instance,
    OperatorOption,
    StartAction,
)
from coordinator.engine.tables import EngineTables
from coordinator.errors import EngineError, NetError, NotEnabledError
from coordinator.net import Marking, PetriNet, parse_event
from services.results import ActionResult

__all__ = ["Engine"]


def _first(task: str, actions: tuple[str, ...]) -> str:
    return actions[0]


class Engine:
    """Executor of an interpreted Petri net, without I/O.

    Args:
        net: the task net (validate it first: see :meth:`PetriNet.interpretation_problems`).
        seed: seed of the random switch between fireable transitions of equal priority.
        chooser: picks the primitive action of each new instance; defaults to the first action.
        instance_prefix: prefix of instance ids (e.g. the run id), so ids are unique across runs.
        marking: start from this marking instead of the net's initial marking.

    Raises:
        EngineError: if ``marking`` names an unknown place, or a reset arc empties a primitive-task
            place.
    """

    def __init__(
        self,
        net: PetriNet,
        *,
        seed: int = 0,
        chooser: Chooser | None = None,
        instance_prefix: str = "i",
        marking: Mapping[str, int] | None = None,
    ) -> None:
        self.net = net
        self._rng = random.Random(seed)
        self._seed = seed
        self._chooser: Chooser = chooser or _first
        self._prefix = instance_prefix
        self._next_instance = 1
        self._fired = 0
        self._state = EngineState.RUNNING
        self._pulse: str | None = None
        self._pulse_fired: set[str] = set()
        start = net.initial_marking if marking is None else Marking(marking)
        for pid in start:
            if pid not in net.place_index:
                raise EngineError(f"marking names unknown place {pid!r}")
        self._counts: dict[str, int] = {p.id: start[p.id] for p in net.places}
        self._instances: dict[str, Instance] = {}
        tables = EngineTables.compile(net)
        self.tables = tables
        # the tables, as attributes: the firing loop reads them without one more indirection
        self._inputs = tables.inputs
        self._outputs = tables.outputs
        self._inhib = tables.inhib
        self._priority = tables.priority
        self._weight = tables.weight
        self._ext = tables.ext
        self._needs = tables.needs
        self._task_of = tables.task_of
        self._control = tables.control
        self._order = tables.order
        self._tids = tables.tids
        self._dependents = tables.dependents
        self._by_topic = tables.by_topic
        self._touch = tables.touch
        self._task_outputs = tables.task_outputs
        self._consumed_map = tables.consumed_map
        self._produced_map = tables.produced_map
        self._resets = tables.resets
        self._weight_fn = tables.weight_fn
        for tid, pids in tables.resets.items():
            for pid in pids:
                if pid in tables.task_of:
                    raise EngineError(f"transition {tid!r} has a reset arc from primitive-task place {pid!r}: "
                                      "a reset cannot take away running primitive actions")
        self._task_inputs = tables.task_inputs
        self._pulse_of = tables.pulse_of
        #: every transition has the same priority and weight: a conflict is a uniform draw
        self._uniform = tables.uniform
        self._ended: dict[str, list[Instance]] = {pid: [] for pid in tables.task_place_ids}
        self._started = False
        # incremental set of transitions without external event that can fire now: a list for O(1)
        # uniform draws plus the position of each member
        self._fireable: list[str] = []
        self._fpos: dict[str, int] = {}
        self._dirty: set[int] = set(range(len(self._tids)))
        self._decided: Firing | None = None

    # ------------------------------------------------------------------ views
    @property
    def state(self) -> EngineState:
        """Where the run stands (recomputed: DEAD once nothing can happen)."""
        if self._state in (EngineState.PAUSED, EngineState.ABORTED):
            return self._state
        if self._refresh() or self.running_instances() or self.waiting_for():
            return EngineState.RUNNING
        return EngineState.DEAD

    @property
    def marking(self) -> Marking:
        """Current marking (tokens of running instances included): a snapshot, cheap enough for a
        reader that looks at it many times a second (the web console's frames)."""
        return Marking.from_counts(self._counts)

    @property
    def fired(self) -> int:
        """Number of firings applied so far."""
        return self._fired

    def running_instances(self) -> list[Instance]:
        """Instances whose primitive action has not returned, in start order."""
        return [i for i in self._instances.values() if i.running]

    def ended_instances(self) -> list[Instance]:
        """Ended instances whose token is still in its place (events latched), in end order."""
        return [i for lst in self._ended.values() for i in lst]

    def instance(self, instance_id: str) -> Instance:
        """Return a live (running or ended, unconsumed) instance.

        Raises:
            EngineError: if there is no such instance.
        """
        try:
            return self._instances[instance_id]
        except KeyError:
            raise EngineError(f"no instance {instance_id!r} in this run") from None

    def waiting_for(self) -> tuple[str, ...]:
        """External events (``ext:<topic>``) that would let some transition fire now."""
        topics = []
        for topic, tids in self._by_topic.items():
            if any(self._can_fire(t) for t in tids):
                topics.append(f"ext:{topic}")
        return tuple(topics)

    def operator_options(self) -> tuple[OperatorOption, ...]:
        """Transitions that an operator command on control places would let fire (section 5).

        A transition qualifies when every condition on its other places holds now (available
        tokens, latched internal events, inhibitors) and only control places hold it back: an
        input control place with too few tokens, or an inhibitor control place with too many. Its
        external event, if any, is not required (it is named in :attr:`OperatorOption.event`).
        Transitions that can fire now are not listed. O(|T|); meant for a run that has come to rest.

        Returns:
            One :class:`OperatorOption` per such transition, in net order.
        """
        control, counts = self._control, self._counts
        out: list[OperatorOption] = []
        for tid in self._tids:
            insert: dict[str, int] = {}
            remove: dict[str, int] = {}
            blocked = False
            needs = self._needs[tid]
            for pid, w in self._inputs[tid]:
                if pid in control:
                    if counts[pid] < w:
                        insert[pid] = w - counts[pid]
                elif self._available(pid, needs.get(self._task_of[pid]) if pid in self._task_of else None) < w:
                    blocked = True
                    break
            if blocked or (needs and not set(needs) <= {self._task_of.get(p) for p, _ in self._inputs[tid]}):
                continue
            for pid, w in self._inhib[tid]:
                if counts[pid] >= w:
                    if pid not in control:
                        blocked = True
                        break
                    remove[pid] = counts[pid] - w + 1
            if not blocked and (insert or remove):
                out.append(OperatorOption(tid, insert, remove, self._pulse_of[tid]))
        return tuple(out)

    # ------------------------------------------------------------------ enabling
    def _available(self, pid: str, need: frozenset[str] | None) -> int:
        if pid not in self._task_of:
            return self._counts[pid]
        ended = self._ended[pid]
        if not need:
            return len(ended)
        return sum(1 for inst in ended if need <= inst.outcomes)

    def _can_fire(self, tid: str) -> bool:
        """Enabled, with internal events latched (external event not checked)."""
        counts = self._counts
        if not self._task_inputs[tid]:
            for pid, w in self._inputs[tid]:
                if counts[pid] < w:
                    return False
            for pid, w in self._inhib[tid]:
                if counts[pid] >= w:
                    return False
            return not self._needs[tid]
        needs = self._needs[tid]
        for pid, w in self._inputs[tid]:
            task = self._task_of.get(pid)
            if task is None:
                if counts[pid] < w:
                    return False
            elif self._available(pid, needs.get(task)) < w:
                return False
        for pid, w in self._inhib[tid]:
            if counts[pid] >= w:
                return False
        if needs:
            in_tasks = {self._task_of.get(pid) for pid, _ in self._inputs[tid]}
            if not set(needs) <= in_tasks:
                return False
        return True

    def ready(self, transition: str) -> bool:
        """Whether ``transition`` is ready to fire: enabled by the marking, its input tokens available
        (not busy with running primitive actions) and its internal events latched; its external
        event, if any, is not required (a breakpoint's "enabled", :mod:`coordinator.breakpoints`).

        Raises:
            EngineError: the net has no such transition.
        """
        if transition not in self._inputs:
            raise EngineError(f"no transition {transition!r} in this net")
        return self._can_fire(transition)

    def _refresh(self) -> bool:
        """Bring the fireable set up to date; return True if it is not empty."""
        if self._dirty:
            fireable, fpos, ext, can_fire = self._fireable, self._fpos, self._ext, self._can_fire
            tids = self._tids
            for j in self._dirty:
                tid = tids[j]
                if ext[tid] is not None:
                    continue
                if can_fire(tid):
                    if tid not in fpos:
                        fpos[tid] = len(fireable)
                        fireable.append(tid)
                elif tid in fpos:
                    i = fpos.pop(tid)
                    last = fireable.pop()
                    if last != tid:
                        fireable[i] = last
                        fpos[last] = i
            self._dirty.clear()
        return bool(self._fireable)

    def fireable(self) -> tuple[str, ...]:
        """Transitions that can fire now, in net order, ignoring pause.

        Fireable is more than enabled (:meth:`PetriNet.enabled`): the input tokens must be
        available (not busy with a running instance) and every linked ``int:`` event latched; a
        transition linked to ``ext:<topic>`` is fireable only during a pulse of that topic.
        """
        self._refresh()
        cands = set(self._fireable)
        if self._pulse is not None:
            cands.update(t for t in self._by_topic.get(self._pulse, ())
                         if t not in self._pulse_fired and self._can_fire(t))
        return tuple(sorted(cands, key=self._order.__getitem__))

    # ------------------------------------------------------------------ deciding and firing
    def firing_possible(self, *, ignore_pause: bool = False) -> bool:
        """True if :meth:`next_firing` would decide a firing now; draws no random number, so asking
        does not change the run's sequence of firings."""
        if self._state is EngineState.ABORTED:
            return False
        if self._state is EngineState.PAUSED and not ignore_pause:
            return False
        if self._refresh():
            return True
        if self._pulse is None:
            return False
        return any(t not in self._pulse_fired and self._can_fire(t) for t in self._by_topic.get(self._pulse, ()))

    def next_firing(self, *, ignore_pause: bool = False) -> Firing | None:
        """Decide the next firing without applying it.

        Returns:
            The firing (priority first, then a seeded random switch on weights), or ``None`` if
            nothing can fire now, the run is paused (unless ``ignore_pause``) or aborted.
        """
        if self._state is EngineState.ABORTED:
            return None
        if self._state is EngineState.PAUSED and not ignore_pause:
            return None
        self._refresh()
        if self._pulse is None:
            cands = self._fireable
            if not cands:
                return None
            if len(cands) == 1:
                tid = cands[0]
            elif self._uniform:
                tid = cands[int(self._rng.random() * len(cands))]
            else:
                tid = self._pick(list(cands))
        else:
            cands = list(self._fireable)
            for tid in self._by_topic.get(self._pulse, ()):
                if tid not in self._pulse_fired and self._can_fire(tid):
                    cands.append(tid)
            if not cands:
                return None
            tid = self._pick(cands)
        firing = self._decide(tid)
        self._decided = firing
        return firing

    def _pick(self, cands: list[str]) -> str:
        if len(cands) == 1:
            return cands[0]
        prio = self._priority
        top = max(prio[t] for t in cands)
        best = [t for t in cands if prio[t] == top]
        if len(best) == 1:
            return best[0]
        best.sort(key=self._order.__getitem__)
        weights = [self._weight_now(t) for t in best] if self._weight_fn else [self._weight[t] for t in best]
        if min(weights) == max(weights):
            return best[self._rng.randrange(len(best))]
        return self._rng.choices(best, weights=weights)[0]

    def _weight_now(self, tid: str) -> float:
        """The weight of ``tid`` in the current marking (its expression's value, if it has one)."""
        fn = self._weight_fn.get(tid)
        if fn is None:
            return self._weight[tid]
        value = float(fn(self._counts))
        if not (value > 0 and value != float("inf")):
            raise EngineError(f"the weight of transition {tid!r} is {value:g} in marking {self.marking.to_dict()}; "
                              "a weight expression must be finite and > 0 where its transition takes part in a "
                              "random switch")
        return value

    def _decide(self, tid: str) -> Firing:
        instances: list[str] = []
        if self._task_inputs[tid]:
            needs = self._needs[tid]
            for pid, w in self._inputs[tid]:
                task = self._task_of.get(pid)
                if task is not None:
                    need = needs.get(task)
                    instances.extend([i.id for i in self._ended[pid] if not need or need <= i.outcomes][:w])
        return Firing(self._fired + 1, tid, self._consumed_now(tid), self._produced_map[tid],
                      tuple(instances), self._pulse_of[tid])

    def _consumed_now(self, tid: str) -> Mapping[str, int]:
        """What firing ``tid`` removes in the current marking: its input arcs, plus what is left in
        the places of its reset arcs."""
        consumed = self._consumed_map[tid]
        if not self._resets[tid]:
            return consumed
        removed = dict(consumed)
        for pid in self._resets[tid]:
            left = self._counts[pid] - removed.get(pid, 0)
            if left:
                removed[pid] = removed.get(pid, 0) + left
        return MappingProxyType(removed)

    def apply(self, firing: Firing) -> list[Effect]:
        """Apply a firing decided by :meth:`next_firing` (or read back from the journal).

        Returns:
            ``[firing]`` followed by a :class:`StartAction` for every token entering a
            primitive-task place.

        Raises:
            NotEnabledError: if the firing is not possible in the current state (stale decision).
        """
        tid = firing.transition
        if firing is not self._decided:  # a decision from elsewhere (journal replay, stale): check it
            if tid not in self._inputs:
                raise NotEnabledError(f"unknown transition {tid!r}")
            if not self._can_fire(tid) or (self._ext[tid] is not None and firing.pulse is None):
                raise NotEnabledError(f"transition {tid!r} cannot fire in {self.marking!r}")
            if self._resets[tid] and dict(firing.consumed) != dict(self._consumed_now(tid)):
                raise NotEnabledError(f"firing {tid!r} removes {dict(firing.consumed)}, but its reset arcs would "
                                      f"remove {dict(self._consumed_now(tid))} in {self.marking!r} (stale decision)")
            for iid in firing.instances:
                inst = self._instances.get(iid)
                if inst is None or inst.running:
                    raise NotEnabledError(f"firing {tid!r} consumes instance {iid!r}, which has not ended")
        self._decided = None
        for iid in firing.instances:
            inst = self._instances.pop(iid)
            self._ended[inst.place].remove(inst)
        counts = self._counts
        for pid, w in firing.consumed.items():
            counts[pid] -= w
        for pid, w in firing.produced.items():
            counts[pid] += w
        self._dirty |= self._touch[tid]
        effects: list[Effect] = [firing]
        for pid, w in self._task_outputs[tid]:
            effects.extend(self._start(pid) for _ in range(w))
        self._fired = max(self._fired, firing.seq)
        if firing.pulse is not None:
            self._pulse_fired.add(tid)
        return effects

    def _start(self, pid: str) -> StartAction:
        task_name = self._task_of[pid]
        assert task_name is not None
        task = self.net.tasks[task_name]
        names = tuple(a.name for a in task.actions)
        action = self._chooser(task_name, names)
        if action not in names:
            raise EngineError(f"chooser picked {action!r}, not an action of primitive task {task_name!r}")
        iid = f"{self._prefix}{self._next_instance}"
        self._next_instance += 1
        self._instances[iid] = Instance(iid, task_name, pid, action)
        spec = task.action(action)
        return StartAction(iid, task_name, pid, action, spec.params, task.deadline_s)

    def start(self) -> list[Effect]:
        """Start instances for tokens that sit in primitive-task places of the starting marking.

        Call once before the first :meth:`advance`. Returns the :class:`StartAction` effects.

        Raises:
            EngineError: if called twice.
        """
        if self._started:
            raise EngineError("the run has already started")
        self._started = True
        effects: list[Effect] = []
        held = {pid: len(lst) for pid, lst in self._ended.items()}
        running: dict[str, int] = {}
        for inst in self._instances.values():
            if inst.running:
                running[inst.place] = running.get(inst.place, 0) + 1
        for pid in self._task_of:
            free = self._counts[pid] - held.get(pid, 0) - running.get(pid, 0)
            effects.extend(self._start(pid) for _ in range(max(free, 0)))
        return effects

    def advance(
        self,
        before_fire: Callable[[Firing], None] | None = None,
        *,
        max_firings: int = 10_000,
        after_fire: Callable[[list[Effect]], None] | None = None,
    ) -> list[Effect]:
        """Fire until nothing can fire now, the run is paused, or ``max_firings`` is reached.

        Args:
            before_fire: called with each decided firing before it is applied (write-ahead journal).
            max_firings: bound on firings in this call, so a net that cycles without waiting for any
                event cannot starve the caller's event loop; call again to continue.
            after_fire: called with the effects of each firing right after it is applied (to act on
                them while the marking is the one they produced).

        Returns:
            The effects in order: each :class:`Firing` followed by the :class:`StartAction` it caused.
        """
        effects: list[Effect] = []
        for _ in range(max_firings):
            firing = self.next_firing()
            if firing is None:
                break
            if before_fire is not None:
                before_fire(firing)
            applied = self.apply(firing)
            if after_fire is not None:
                after_fire(applied)
            effects.extend(applied)
        return effects

    # ------------------------------------------------------------------ inputs
    def complete(self, instance_id: str, result: ActionResult) -> Instance:
        """Record that a primitive action returned; latch its events on the token.

        Args:
            instance_id: the instance (call id).
            result: how the action ended; its status and named outcome give the latched events
                (:attr:`ActionResult.events`).

        Returns:
            The ended instance.

        Raises:
            EngineError: unknown instance, or instance already ended.
        """
        inst = self.instance(instance_id)
        if inst.status is not None:
            raise EngineError(f"instance {instance_id!r} has already ended with {inst.status.value}")
        inst.status = result.status
        inst.outcomes = result.events
        self._decided = None
        self._ended[inst.place].append(inst)
        self._dirty.update(self._dependents[inst.place])
        return inst

    def pulse(
        self,
        event: str,
        before_fire: Callable[[Firing], None] | None = None,
        *,
        max_firings: int = 10_000,
        after_fire: Callable[[list[Effect]], None] | None = None,
    ) -> list[Effect]:
        """Deliver an external event as a pulse and fire what it allows (paper section 2).

        During the pulse each transition linked to ``event`` may fire once, interleaved with the
        other firings by priority; when no more can fire the pulse is dropped. A paused or aborted
        run ignores pulses (they are lost, as pulses are).

        Args:
            event: ``"ext:<topic>"`` or the bare topic.
            before_fire, max_firings, after_fire: as in :meth:`advance`.

        Returns:
            The effects, as in :meth:`advance`.

        Raises:
            EngineError: if the name is not an external event.
        """
        self.begin_pulse(event)
        try:
            return self.advance(before_fire, max_firings=max_firings, after_fire=after_fire)
        finally:
            self.end_pulse()

    def begin_pulse(self, event: str) -> None:
        """Open the window of a pulse of ``event``; fire with :meth:`next_firing`/:meth:`apply`
        (or :meth:`advance`) as usual, then close it with :meth:`end_pulse`. :meth:`pulse` does all
        three; a caller that must serve other inputs between the firings of a pulse (the runtime)
        uses these.

        Raises:
            EngineError: if the name is not an external event.
        """
        name = event if event.startswith("ext:") else f"ext:{event}"
        try:
            _, topic, _ = parse_event(name)
        except NetError:
            raise EngineError(f"{event!r} is not an external event name") from None
        self._pulse, self._pulse_fired, self._decided = topic, set(), None

    def end_pulse(self) -> None:
        """Close the window of the current pulse (the pulse is gone); harmless without one."""
        self._pulse, self._pulse_fired, self._decided = None, set(), None

    # ------------------------------------------------------------------ operator commands
    def insert_tokens(self, place: str, count: int = 1) -> None:
        """Put ``count`` tokens in a control place (section 5).

        Raises:
            EngineError: if the place is not a control place or ``count`` < 1.
        """
        self.check_tokens("insert", place, count)
        self._counts[place] += count
        self._dirty.update(self._dependents[place])
        self._decided = None

    def remove_tokens(self, place: str, count: int = 1) -> None:
        """Take ``count`` tokens from a control place (section 5).

        Raises:
            EngineError: if the place is not a control place, ``count`` < 1, or it holds fewer tokens.
        """
        self.check_tokens("remove", place, count)
        self._counts[place] -= count
        self._dirty.update(self._dependents[place])
        self._decided = None

    def check_tokens(self, command: str, place: str, count: int) -> None:
        """Check an ``insert``/``remove`` command without applying it (to journal it first).

        Raises:
            EngineError: unknown place, not a control place, count < 1, or removing more tokens
                than the place holds.
        """
        if place not in self._counts:
            raise EngineError(f"no place {place!r} in net {self.net.name!r}")
        if place not in self._control:
            raise EngineError(f"place {place!r} is not a control place; the operator edits control places only")
        if not isinstance(count, int) or count < 1:
            raise EngineError(f"token count must be a positive integer, got {count!r}")
        if command == "remove" and self._counts[place] < count:
            raise EngineError(f"control place {place!r} holds {self._counts[place]} tokens; cannot remove {count}")

    def pause(self) -> None:
        """Stop firing; running primitive actions go on and their results are latched.

        Raises:
            EngineError: if the run was aborted.
        """
        self._not_aborted()
        self._state = EngineState.PAUSED

    def resume(self) -> None:
        """Leave the paused state.

        Raises:
            EngineError: if the run was aborted.
        """
        self._not_aborted()
        self._state = EngineState.RUNNING

    @property
    def paused(self) -> bool:
        """True while paused."""
        return self._state is EngineState.PAUSED

    def step(self, before_fire: Callable[[Firing], None] | None = None,
             after_fire: Callable[[list[Effect]], None] | None = None) -> list[Effect]:
        """Fire exactly one transition, paused or not; return its effects (empty if none can fire).

        Raises:
            EngineError: if the run was aborted.
        """
        self._not_aborted()
        firing = self.next_firing(ignore_pause=True)
        if firing is None:
            return []
        if before_fire is not None:
            before_fire(firing)
        applied = self.apply(firing)
        if after_fire is not None:
            after_fire(applied)
        return applied

    def abort(self, reason: str = "aborted by the operator") -> list[Effect]:
        """Cancel every running instance and stop the run for good.

        Returns:
            A :class:`CancelAction` per running instance.
        """
        self._state = EngineState.ABORTED
        return [CancelAction(i.id, reason) for i in self.running_instances()]

    def _not_aborted(self) -> None:
        if self._state is EngineState.ABORTED:
            raise EngineError("the run was aborted")

    # ------------------------------------------------------------------ recovery
    def restore(self, marking: Mapping[str, int], instances: Iterable[Instance], *,
                fired: int, next_instance: int) -> None:
        """Rebuild the state of a run from its journal (``petrobot run --resume``).

        Args:
            marking: the marking after the last journaled firing and operator command.
            instances: live instances (running, or ended with their status and outcomes) in start order.
            fired: number of firings journaled.
            next_instance: the next instance number to use.

        Raises:
            EngineError: if an instance sits in a place that is not a primitive-task place of its task,
                or a place holds fewer tokens than its instances.
        """
        counts = {p.id: 0 for p in self.net.places}
        for pid, c in marking.items():
            if pid not in counts:
                raise EngineError(f"journal marking names unknown place {pid!r}")
            counts[pid] = c
        self._counts = counts
        self._instances = {}
        self._ended = {pid: [] for pid in self.tables.task_place_ids}
        per_place: dict[str, int] = {}
        for inst in instances:
            if self._task_of.get(inst.place) != inst.task:
                raise EngineError(f"instance {inst.id!r} of {inst.task!r} cannot sit in place {inst.place!r}")
            self._instances[inst.id] = inst
            if not inst.running:
                self._ended[inst.place].append(inst)
            per_place[inst.place] = per_place.get(inst.place, 0) + 1
        for pid, n in per_place.items():
            if counts[pid] < n:
                raise EngineError(f"place {pid!r} holds {counts[pid]} tokens but {n} instances")
        self._fired = fired
        self._next_instance = next_instance
        self._rng = random.Random(f"{self._seed}:{fired}")
        self._fireable, self._fpos, self._decided = [], {}, None
        self._dirty = set(range(len(self._tids)))
