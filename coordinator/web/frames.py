"""Following a run in the browser: the runtime's events coalesced into frames (paper section 5).

:class:`LiveFeed` is a runtime observer (:meth:`coordinator.runtime.Runtime.add_observer`). Being
called costs the run a counter increment per firing (no event object is kept until the frame) and
a list append for any other event: nothing is serialised while the engine fires. A coalescing task
(:meth:`LiveFeed.run`) wakes at most every ``period_s`` (10 ms), takes what piled up, and builds
one *frame*: the marking's changes (the latest marking wins), the transitions fired since the last
frame with their counts, the primitive actions started and ended, the primitive tasks whose
results changed their record (errors in a row, the last error's whole reason), the learners that
changed (probabilities, R̂, C, J per action), the run's state when it changed (with the run's
summary once it has ended) and the operator commands applied or refused. One JSON text per frame goes to every page. A run firing thousands of
transitions a second thus sends ≤ 100 small frames a second; the page draws at most once per screen
frame (60 Hz), so the oldest firing a repaint shows is at most one screen frame and one period old
when the page receives it (bench/console.py measures the rest).

Frames are sized to what the pages can paint: a page that says when it has painted a frame
(:meth:`LiveFeed.painted`, the ``painted`` message) is *pacing*, and the next frame waits until
every pacing page has painted the previous one (at most :data:`PACE_MAX_S`), piling up what
happens meanwhile into that one frame. And frames are sized to the CPU the machine can spare: the
feed looks at the machine's idle CPU twice a second (:class:`IdleCpu`, ``/proc/stat``) and, when
no core is idle — the browser's work would be taken from the run — spaces its frames up to
:data:`BUSY_PERIOD_S` (:func:`frame_period`): a browser on the run's own cores then paints a few
larger frames a second instead of a hundred, and the run keeps its rate; with a core to spare,
frames come every ``period_s`` as before.

:func:`learner_view` is the learner panel's row data; :func:`result_json` one ended action;
:func:`used_nodes` the nodes a net calls or hears from (the page marks the others "not used").

The *blackboard* of a primitive-task place (:meth:`LiveFeed.blackboard`, asked for by the page when
the operator opens a place, as Groot2's blackboard view): its running actions with their
parameters and their latest feedback in full, and the results latched on its tokens with their
returned values (payloads), status, outcome, reason and whether the operator forced them; and the
external events delivered lately with the time, their payload and whether the operator raised them. The feed
keeps these as the events pass (bounded: :data:`BLACKBOARD_BYTES` per value, the latest
:data:`KEPT_RESULTS` results), never by asking the engine or the journal.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import logging
import os
import time
from collections.abc import Callable, Mapping
from typing import Any

from coordinator.events import (
    ActionEnded,
    ActionFeedback,
    ActionStarted,
    BreakpointHit,
    LearnerUpdated,
    OperatorApplied,
    OperatorRefused,
    PulseDelivered,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.operator import OperatorCommand

__all__ = ["BLACKBOARD_BYTES", "DEFAULT_PERIOD_S", "FEEDBACK_CHARS", "IdleCpu", "LiveFeed", "feedback_text",
           "frame_period", "json_value", "learner_view", "result_json", "used_nodes"]

log = logging.getLogger("petrobot.web")

#: Shortest time between two frames, seconds: under a 60 Hz screen frame, so that a repaint shows
#: firings at most one screen frame and this much old; 20 ms frames gave 7-8 ms more firing-to-screen
#: latency at the median (docs/BENCHMARKS.md, web console).
DEFAULT_PERIOD_S = 0.01
#: Shortest time between two looks at the nodes' health, seconds.
HEALTH_PERIOD_S = 1.0
#: Longest the next frame waits for a page to say it has painted the previous one, seconds (a page
#: that paints slower than this gets its frames anyway, as a page that never says).
PACE_MAX_S = 0.25
#: Shortest time between two frames when no core of the machine is idle, seconds.
BUSY_PERIOD_S = 0.2
#: Idle CPU (in cores) from which frames come at the full rate again.
SPARE_CORES = 0.5
#: How often the machine's idle CPU is looked at, seconds.
IDLE_PERIOD_S = 0.5


def frame_period(base_s: float, idle_cores: float | None) -> float:
    """The time between two frames given the machine's idle CPU: ``base_s`` with at least
    :data:`SPARE_CORES` idle, :data:`BUSY_PERIOD_S` with none, linear in between; ``base_s`` when
    the idle CPU is not known."""
    if idle_cores is None or base_s >= BUSY_PERIOD_S:
        return base_s
    busy = min(1.0, max(0.0, 1.0 - idle_cores / SPARE_CORES))
    return base_s + (BUSY_PERIOD_S - base_s) * busy


class IdleCpu:
    """The machine's idle CPU since the last look, in cores, from ``/proc/stat`` (``None`` where there
    is none: the frames then keep their period)."""

    def __init__(self, path: str = "/proc/stat") -> None:
        self.path = path
        self._last: tuple[int, int] | None = self._read()

    def _read(self) -> tuple[int, int] | None:
        try:
            with open(self.path, encoding="ascii") as f:
                fields = [int(x) for x in f.readline().split()[1:]]
        except (OSError, ValueError):
            return None
        if len(fields) < 5:
            return None
        return sum(fields), fields[3] + fields[4]  # total, idle + iowait (jiffies)

    def sample(self) -> float | None:
        """Idle cores since the previous sample (``None`` before there are two, or without /proc)."""
        now = self._read()
        last, self._last = self._last, now
        if now is None or last is None or now[0] <= last[0]:
            return None
        return (now[1] - last[1]) / (now[0] - last[0]) * (os.cpu_count() or 1)
#: Most action starts/ends, operator notes or pulses one frame lists (a burst beyond is counted).
MAX_LISTED = 200
#: Feedback shown per running action: its JSON text, cut to this many characters.
FEEDBACK_CHARS = 160
#: Largest value (parameters, feedback, a result's payload) a blackboard shows, bytes of JSON.
BLACKBOARD_BYTES = 64 * 1024
#: Results kept for the blackboard (those latched on tokens are looked up among them).
KEPT_RESULTS = 512
#: External events remembered for the blackboard, per topic the latest.
KEPT_TOPICS = 64


def _plain(value: Any) -> Any:
    """What ``json`` cannot write itself: a read-only mapping as an object, a set as an array, else its repr."""
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, (set, frozenset)):
        return sorted(value, key=repr)
    return repr(value)


def json_value(data: Any, limit: int = BLACKBOARD_BYTES) -> Any:
    """``data`` as JSON-ready values for the page, or its JSON text cut to ``limit`` bytes (with a
    note) when it is larger; anything JSON cannot hold is shown by its ``repr``."""
    try:
        text = json.dumps(data, default=_plain, separators=(",", ":"))
    except (TypeError, ValueError):
        text = json.dumps(repr(data))
    if len(text) <= limit:
        return json.loads(text)
    return {"cut": f"{len(text)} bytes of JSON; the first {limit} shown", "text": text[:limit]}


def feedback_text(data: Any) -> str:
    """A running action's feedback as short text for the page (JSON, cut to :data:`FEEDBACK_CHARS`)."""
    try:
        text = data if isinstance(data, str) else json.dumps(data, default=repr, separators=(", ", ": "))
    except (TypeError, ValueError):
        text = repr(data)
    return text if len(text) <= FEEDBACK_CHARS else text[:FEEDBACK_CHARS - 1] + "\u2026"


def _round(value: float | None, digits: int = 6) -> float | None:
    return None if value is None else round(float(value), digits)


def learner_view(automaton: Any) -> dict[str, Any]:
    """A learning automaton's state for the learner panel (section 4).

    Args:
        automaton: a :class:`coordinator.learning.LearningAutomaton` (``probabilities``,
            ``estimates``, ``rho``, ``steps``, ``scheme``).

    Returns:
        ``{"scheme", "steps", "rho", "actions": [{"name", "p", "trials", "successes", "R", "C",
        "J"}]}``: probability of choosing each action, its trials and successes, R̂ = successes /
        trials, C its cost (a-priori or mean measured), J = 1 − R̂ + ρC (section 3); ``None`` where
        nothing is known yet.
    """
    probabilities = automaton.probabilities
    estimates = automaton.estimates
    rows = []
    for name, est in estimates.items():
        rows.append({"name": name, "p": _round(probabilities.get(name)), "trials": est.trials,
                     "successes": est.successes, "R": _round(est.reliability), "C": _round(est.cost),
                     "J": _round(est.j)})
    return {"scheme": automaton.scheme, "steps": automaton.steps, "rho": _round(automaton.rho), "actions": rows}


def result_json(instance: str, task: str, action: str, node: str | None, result: Any, t_wall: float,
                forced: bool = False) -> dict[str, Any]:
    """One ended primitive action, as frames and replays list it (``forced``: by the operator)."""
    return {"i": instance, "task": task, "action": action, "node": node, "status": result.status.value,
            "outcome": result.outcome, "reason": result.reason, "wall_s": _round(result.wall_s), "t": t_wall,
            **({"forced": True} if forced else {})}


def used_nodes(net: Any, location: Any) -> set[str] | None:
    """The nodes a net uses: those services.toml places its primitive actions on, and those that
    publish its external events; ``None`` when ``location`` cannot say (no ``node_of``)."""
    if location is None or not callable(getattr(location, "node_of", None)):
        return None
    used: set[str] = set()
    for task in net.tasks.values():
        for spec in task.actions:
            with contextlib.suppress(Exception):  # an unplaced action: the preflight said so already
                used.add(location.node_of(spec.name))
    publisher = getattr(location, "publisher_of", None)
    if callable(publisher):
        for transition in net.transitions:
            for event in transition.external_events:
                with contextlib.suppress(Exception):
                    used.add(publisher(event))
    return used


def _command_json(command: OperatorCommand | str) -> dict[str, Any]:
    if isinstance(command, str):
        return {"command": "invalid", "text": command}
    return {"command": command.command.value, "place": command.place,
            "count": command.count if command.place is not None else None, "text": str(command),
            **(command.detail() or {})}


class LiveFeed:
    """Coalesces one run's events into frames for the pages watching it.

    Args:
        runtime: the run (a :class:`coordinator.runtime.Runtime`): its engine's marking, running
            actions and learner are read when a frame is built.
        period_s: shortest time between two frames, seconds.
        clock: wall clock, Unix seconds (frames carry the server's time).

    Use: ``runtime.add_observer(feed)``, start ``feed.run()`` as a task, :meth:`subscribe` a sink
    per page (called with each frame's JSON text; it must not block).
    """

    def __init__(self, runtime: Any, *, period_s: float = DEFAULT_PERIOD_S,
                 clock: Callable[[], float] = time.time) -> None:
        self.runtime = runtime
        self.period_s = period_s
        self.clock = clock
        self._events: list[RunEvent] = []  # events other than firings, in order
        # firings since the last frame, counted as they come: a run firing thousands of
        # transitions a second keeps no event object alive for the console
        self._fired: dict[str, int] = {}
        self._t_first: float | None = None
        self._t_last: float | None = None
        self._fired_latched = False
        self._pending = False
        self._wake = asyncio.Event()
        self._sinks: list[Callable[[str], None]] = []
        self._awaiting: dict[Callable[[str], None], int] = {}  # pacing sink -> seq of the frame it has not painted
        self._pacing: set[Callable[[str], None]] = set()
        self._painted = asyncio.Event()
        self._sent_marking: dict[str, int] = runtime.engine.marking.to_dict()
        self._seq = 0
        self._replies: dict[int, tuple[OperatorCommand, Callable[[bool, str], None]]] = {}
        #: the run's state as its events tell it, with reason and detail
        self.state: dict[str, Any] = {"state": "starting", "reason": "", "detail": []}
        self.ended = False
        self._learner: dict[str, dict[str, Any]] = {}
        self._operator: collections.deque[dict[str, Any]] = collections.deque(maxlen=20)
        self._errors: collections.deque[dict[str, Any]] = collections.deque(maxlen=20)
        self._results: collections.deque[dict[str, Any]] = collections.deque(maxlen=40)
        self._last_frame = 0.0
        self._sent_nodes: dict[str, Any] = {}
        self._sent_state: dict[str, Any] = {}
        self._health_at = 0.0
        self._used = used_nodes(runtime.net, getattr(runtime.client, "location", None)) \
            if hasattr(runtime, "net") else None
        #: per primitive task: errors in a row, errors in all, the last error (whole reason)
        self._tasks: dict[str, dict[str, Any]] = {}
        self._summary: dict[str, Any] | None = None
        # the blackboard: parameters and latest feedback of running actions, the latest results
        # (their payloads), the external events delivered lately
        self._params: dict[str, Any] = {}
        self._feedback: dict[str, tuple[Any, int, float]] = {}  # instance -> (data, feedback count, time)
        self._ended_results: collections.OrderedDict[str, dict[str, Any]] = collections.OrderedDict()
        self._topics: collections.OrderedDict[str, dict[str, Any]] = collections.OrderedDict()
        self._hits: collections.deque[dict[str, Any]] = collections.deque(maxlen=20)
        #: the time between two frames now (``period_s``, longer while no core is idle)
        self.period_now = period_s
        #: space the frames while the machine has no idle core (False: always every ``period_s``)
        self.adaptive = True

    # ------------------------------------------------------------------ the observer
    def __call__(self, event: RunEvent) -> None:
        """Take one event (called by the runtime): a firing is counted, any other event appended;
        the first one after a frame wakes the coalescing task."""
        if type(event) is TransitionFired:
            firing = event.firing
            fired = self._fired
            fired[firing.transition] = fired.get(firing.transition, 0) + 1
            if self._t_first is None:
                self._t_first = event.t_wall
            self._t_last = event.t_wall
            if firing.instances:
                self._fired_latched = True
        else:
            self._events.append(event)
            if type(event) is ActionFeedback:  # the blackboard keeps the latest feedback in full
                seen = self._feedback.get(event.instance)
                self._feedback[event.instance] = (event.data, 1 + (seen[1] if seen else 0), event.t_wall)
            elif type(event) is ActionEnded:  # and the result latched on the token, at once
                result = event.result
                self._ended_results[event.instance] = {
                    "status": result.status.value, "outcome": result.outcome, "reason": result.reason,
                    "value": json_value(result.value), "forced": event.forced, "t": event.t_wall}
                while len(self._ended_results) > KEPT_RESULTS:
                    self._ended_results.popitem(last=False)
        if not self._pending:
            self._pending = True
            self._wake.set()

    # ------------------------------------------------------------------ pages
    def subscribe(self, sink: Callable[[str], None]) -> None:
        """Send every later frame's JSON text to ``sink``."""
        self._sinks.append(sink)

    def unsubscribe(self, sink: Callable[[str], None]) -> None:
        """Stop sending frames to ``sink``."""
        with contextlib.suppress(ValueError):
            self._sinks.remove(sink)
        self._pacing.discard(sink)
        self._awaiting.pop(sink, None)
        self._painted.set()

    def painted(self, sink: Callable[[str], None], seq: int) -> None:
        """The page behind ``sink`` has painted frame ``seq``: it paces the frames from now on (the
        next frame waits for it, module doc)."""
        if sink not in self._sinks:
            return
        self._pacing.add(sink)
        if self._awaiting.get(sink, -1) <= seq:
            self._awaiting.pop(sink, None)
            if not self._awaiting:
                self._painted.set()

    def expect_reply(self, command: OperatorCommand, reply: Callable[[bool, str], None]) -> None:
        """Call ``reply(accepted, reason)`` when the runtime applies or refuses ``command`` (the
        very object given to :meth:`Runtime.command`)."""
        self._replies[id(command)] = (command, reply)

    def nodes(self) -> dict[str, Any]:
        """The nodes' health as the run's client reports it (``ServiceClient.health``): node →
        ``{"connected", "heartbeat_rtt_s", "in_flight", "used"}``, the nodes this net uses first
        (``used`` False: services.toml has the node but the net calls nothing there and hears no
        event from it, so its link is never opened); ``{}`` for a client that cannot say."""
        health = getattr(self.runtime.client, "health", None)
        if not callable(health):
            return {}
        try:
            nodes = health()
        except Exception:
            log.exception("reading the nodes' health failed")
            return {}
        used = self._used
        order = sorted(nodes, key=lambda n: used is not None and n not in used)
        return {node: {**nodes[node], "heartbeat_rtt_s": _round(nodes[node].get("heartbeat_rtt_s"), 4),
                       "used": used is None or node in used} for node in order}

    def _task_result(self, task: str, item: dict[str, Any]) -> dict[str, Any]:
        """Count one result of ``task``: an error adds to its errors in a row, anything else ends them."""
        record = self._tasks.setdefault(task, {"task": task, "in_a_row": 0, "errors": 0, "results": 0,
                                               "last_error": None})
        record["results"] += 1
        if item["status"] == "error":
            record["in_a_row"] += 1
            record["errors"] += 1
            record["last_error"] = {k: item[k] for k in ("action", "node", "reason", "t", "i")}
        else:
            record["in_a_row"] = 0
        return record

    def summary(self) -> dict[str, Any]:
        """The run's summary for the page once it has ended: the end state and why, the firings,
        the final marking, each primitive action's calls and outcomes, and the last errors."""
        runtime = self.runtime
        stats = getattr(runtime, "stats", None) or {}
        errors = list(getattr(runtime, "errors", None) or [])
        calls = sum(st.calls for st in stats.values())
        return {**self.state, "run": runtime.run_id, "firings": runtime.engine.fired, "calls": calls,
                "all_calls_failed": calls > 0 and all(st.error == st.calls for st in stats.values()),
                "marking": runtime.engine.marking.to_dict(),
                "actions": [{"task": st.task, "action": st.action, "node": st.node, "calls": st.calls,
                             "success": st.success, "failure": st.failure, "error": st.error,
                             "mean_s": _round(st.mean_wall_s, 4)} for st in stats.values()],
                "errors": errors[-5:], "n_errors": len(errors)}

    def snapshot(self) -> dict[str, Any]:
        """The run as it stands, for a page that has just connected."""
        runtime = self.runtime
        engine = runtime.engine
        now = self.clock()
        running = [{"i": f.start.instance, "task": f.start.task, "place": f.start.place, "action": f.start.action,
                    "node": f.node, "t": now - f.elapsed_s} for f in runtime.running()]
        learner = runtime.learner
        views = dict(self._learner)
        if learner is not None:
            for task in getattr(learner, "tasks", ()):
                with contextlib.suppress(Exception):
                    views[task] = learner_view(learner.automaton(task))
        return {"run": runtime.run_id, "marking": engine.marking.to_dict(), "firings": engine.fired,
                "paused": engine.paused, "state": self.state, "running": running, "latched": self._latched(),
                "learner": views, "operator": list(self._operator), "errors": list(self._errors),
                "results": list(self._results), "nodes": self.nodes(), "tasks": dict(self._tasks),
                "summary": self._summary, "server_time": now, "breakpoints": self.breakpoints(),
                "hits": list(self._hits)}

    def breakpoints(self) -> list[dict[str, Any]]:
        """The run's breakpoints (:mod:`coordinator.breakpoints`) as the page draws them."""
        watch = getattr(self.runtime, "breakpoints", None)
        return [bp.to_json() for bp in getattr(watch, "breakpoints", ())]

    def blackboard(self, place: str) -> dict[str, Any]:
        """What the actions of primitive-task place ``place`` are doing, for the operator (module doc).

        Returns:
            ``{"place", "task", "running": [{"i", "action", "node", "t", "params", "feedback",
            "feedback_count", "feedback_t"}], "latched": [{"i", "action", "events", "status",
            "outcome", "reason", "value", "forced", "t"}], "events": [{"event", "t", "fired",
            "operator", "payload"}]}``; values (a payload too) as :func:`json_value` gives them.
        """
        runtime = self.runtime
        task = None
        with contextlib.suppress(Exception):
            task = runtime.net.place(place).task
        now = self.clock()
        running = []
        for flight in runtime.running():
            start = flight.start
            if start.place != place:
                continue
            data, count, t = self._feedback.get(start.instance, (None, 0, None))
            running.append({"i": start.instance, "action": start.action, "node": flight.node,
                            "t": now - flight.elapsed_s, "params": json_value(self._params.get(start.instance,
                                                                                               start.params)),
                            "feedback": json_value(data), "feedback_count": count, "feedback_t": t})
        latched = []
        for inst in runtime.engine.ended_instances():
            if inst.place != place:
                continue
            kept = self._ended_results.get(inst.id, {})
            latched.append({"i": inst.id, "action": inst.action,
                            "events": sorted(f"int:{inst.task}.{o}" for o in inst.outcomes), **kept})
        return {"place": place, "task": task, "running": running, "latched": latched,
                "events": list(reversed(self._topics.values()))}

    # ------------------------------------------------------------------ frames
    def _latched(self) -> dict[str, list[list[Any]]]:
        out: dict[str, list[list[Any]]] = {}
        for inst in self.runtime.engine.ended_instances():
            events = sorted(f"int:{inst.task}.{o}" for o in inst.outcomes)
            out.setdefault(inst.place, []).append([inst.id, inst.action, events])
        return out

    def build_frame(self) -> dict[str, Any] | None:
        """Take the events piled up since the last frame and return the next frame, or ``None``
        when nothing changed."""
        events, self._events = self._events, []
        fired, t_first, t_last, latched = self._fired, self._t_first, self._t_last, self._fired_latched
        self._fired, self._t_first, self._t_last, self._fired_latched = {}, None, None, False
        self._pending = False
        engine = self.runtime.engine
        marking = engine.marking
        changed = {p: n for p, n in marking.items() if self._sent_marking.get(p) != n}
        changed.update({p: 0 for p in self._sent_marking if p not in marking})
        nodes = None
        now_mono = time.monotonic()
        if now_mono - self._health_at >= HEALTH_PERIOD_S:
            self._health_at = now_mono
            looked = self.nodes()
            if looked != self._sent_nodes:
                nodes = self._sent_nodes = looked
        if not events and not fired and not changed and nodes is None:
            return None
        self._sent_marking = marking
        started: list[dict[str, Any]] = []
        ended: list[dict[str, Any]] = []
        feedback: dict[str, str] = {}
        operator: list[dict[str, Any]] = []
        pulses: collections.Counter[str] = collections.Counter()
        learner_tasks: dict[str, Mapping[str, Any]] = {}
        tasks: dict[str, dict[str, Any]] = {}
        injected: list[dict[str, Any]] = []
        hits: list[dict[str, Any]] = []
        breakpoints_changed = False
        state = None
        for event in events:
            if isinstance(event, ActionStarted):
                self._params[event.instance] = event.params
                if len(started) < MAX_LISTED:
                    started.append({"i": event.instance, "task": event.task, "place": event.place,
                                    "action": event.action, "node": event.node, "t": event.t_wall})
            elif isinstance(event, ActionFeedback):
                if event.instance in feedback or len(feedback) < MAX_LISTED:
                    feedback[event.instance] = feedback_text(event.data)  # the latest per action wins
            elif isinstance(event, ActionEnded):
                feedback.pop(event.instance, None)
                self._params.pop(event.instance, None)
                self._feedback.pop(event.instance, None)
                latched = True
                item = result_json(event.instance, event.task, event.action, event.node, event.result, event.t_wall,
                                   event.forced)
                if len(ended) < MAX_LISTED:
                    ended.append(item)
                self._results.append(item)
                if item["status"] == "error" and not event.forced:
                    self._errors.append(item)
                if not event.forced:  # a drill says nothing about how the task fares
                    tasks[event.task] = dict(self._task_result(event.task, item))
            elif isinstance(event, LearnerUpdated):
                learner_tasks[event.task] = event.state
            elif isinstance(event, (OperatorApplied, OperatorRefused)):
                ok = isinstance(event, OperatorApplied)
                reason = "" if ok else event.reason  # type: ignore[union-attr]
                note = {**_command_json(event.command), "ok": ok, "reason": reason, "t": event.t_wall}
                if ok and note["command"] in ("break", "clear"):
                    breakpoints_changed = True
                self._operator.append(note)
                if len(operator) < MAX_LISTED:
                    operator.append(note)
                pending = self._replies.pop(id(event.command), None)
                if pending is not None and pending[0] is event.command:
                    with contextlib.suppress(Exception):
                        pending[1](ok, reason)
            elif isinstance(event, RunStateChanged):
                state = {"state": event.state, "reason": event.reason, "detail": list(event.detail)}
            elif isinstance(event, PulseDelivered):
                pulses[event.event] += 1
                self._topics.pop(event.event, None)
                self._topics[event.event] = {"event": event.event, "t": event.t_wall, "fired": event.fired,
                                             "operator": event.operator, "payload": json_value(event.payload)}
                while len(self._topics) > KEPT_TOPICS:
                    self._topics.popitem(last=False)
                if event.operator:
                    injected.append({"event": event.event, "fired": event.fired, "t": event.t_wall})
            elif isinstance(event, BreakpointHit):
                hit = {**event.breakpoint.to_json(), "text": str(event.breakpoint), "why": event.why,
                       "t": event.t_wall}
                self._hits.append(hit)
                hits.append(hit)
        if state is not None:
            self.state = state
        elif fired and self.state["state"] == "waiting":
            self.state = {"state": "running", "reason": "", "detail": []}
        frame: dict[str, Any] = {"type": "frame", "seq": self._seq + 1, "t": self.clock(), "firings": engine.fired,
                                 "paused": engine.paused}
        self._seq += 1
        if changed:
            frame["marking"] = changed
        if fired:
            frame["fired"] = fired
            frame["t_fired"] = [t_first, t_last]
        if started:
            frame["started"] = started
        if ended:
            frame["ended"] = ended
        if feedback:
            frame["feedback"] = feedback
        if latched:
            frame["latched"] = self._latched()
        if learner_tasks:
            frame["learner"] = {task: self._learner_of(task, state_dict) for task, state_dict in learner_tasks.items()}
        if operator:
            frame["operator"] = operator
        if pulses:
            frame["pulses"] = dict(pulses)
        if injected:
            frame["injected"] = injected
        if hits:
            frame["hits"] = hits
        if breakpoints_changed:
            frame["breakpoints"] = self.breakpoints()
        if nodes is not None:
            frame["nodes"] = nodes
        if tasks:
            frame["tasks"] = tasks
        if self.state != self._sent_state:  # only when it changed: a page redraws its panels then
            frame["state"] = self._sent_state = self.state
            if self.state["state"] in _END_STATES:
                frame["summary"] = self._summary = self.summary()
        return frame

    def _learner_of(self, task: str, state: Mapping[str, Any]) -> dict[str, Any]:
        learner = self.runtime.learner
        try:
            view = learner_view(learner.automaton(task)) if learner is not None else None
        except Exception:
            view = None
        if view is None:
            from coordinator.learning.state import automaton_from_state

            try:
                view = learner_view(automaton_from_state(state))
            except Exception:
                view = {"scheme": state.get("scheme"), "steps": state.get("steps"), "rho": None, "actions": []}
        self._learner[task] = view
        return view

    def flush(self) -> None:
        """Build a frame now and send it to every page (when something changed)."""
        frame = self.build_frame()
        if frame is None:
            return
        self._last_frame = time.monotonic()
        text = json.dumps(frame, separators=(",", ":"), default=str)
        for sink in list(self._sinks):
            if sink in self._pacing:
                self._awaiting[sink] = frame["seq"]
            try:
                sink(text)
            except Exception:  # a page that fails is dropped by its own handler; never the run
                log.exception("a page's frame sink failed")
        if self.state["state"] in _END_STATES:
            self.ended = True

    async def run(self) -> None:
        """Coalesce and send frames until cancelled: a first event after a quiet spell goes out
        at once, later ones at most every ``period_s`` (longer while the machine has no idle core)."""
        idle = IdleCpu()
        looked = time.monotonic()
        period = self.period_s
        while True:
            if time.monotonic() - looked >= IDLE_PERIOD_S:
                looked = time.monotonic()
                period = frame_period(self.period_s, idle.sample() if self.adaptive else None)
                self.period_now = period
            # a quiet run still gets its nodes' health; asyncio.timeout, not wait_for, whose 3.11
            # version can swallow the cancellation that stops this task
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(HEALTH_PERIOD_S):
                    await self._wake.wait()
            self._wake.clear()
            wait = self._last_frame + period - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
            if self._awaiting:  # a pacing page has not painted the last frame yet: let it
                self._painted.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(max(0.0, self._last_frame + PACE_MAX_S - time.monotonic())):
                        await self._painted.wait()
                self._awaiting.clear()
            try:
                self.flush()
            except Exception:
                log.exception("building a frame failed")
            if self._pending:
                self._wake.set()


_END_STATES = frozenset({"completed", "stuck", "waiting_for_operator", "aborted", "deadline", "interrupted"})
