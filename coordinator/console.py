"""Following the token flow live in a terminal (paper section 5).

:class:`Console` is a runtime observer. On a terminal it keeps a live view
(:meth:`Console.screen_lines`, shown by :class:`coordinator.terminal.LiveScreen` above the
operator's input line): the run's state (``paused`` while paused), the marking (places with
tokens, by kind), the running primitive actions with their node and elapsed time, what the run
waits for, the last error with its reason, the last events, and the fate of the operator's last
command (a refusal stays on screen until the next command); elsewhere (a pipe, CI, a log file) it
prints one line per firing (the places it took tokens from and gave
tokens to), action start and result (with the action's reason), what a node said afterwards about
a call the run had given up on (printed even when quiet if it is not what the net assumed), state
change and operator command; the pulses of external events are not printed one by one: one that
fired something is named on its firing line (``fire #7 start_run on ext:image_sampling_tick``), and
those that fired nothing are counted and summed up in one line at most every
:data:`PULSE_REPORT_S` seconds, and at the end of the run.
:func:`read_operator_commands` turns lines typed on standard input into operator commands
(insert/remove tokens in control places, pause, step, resume, abort, end; end of input is end).
"""

from __future__ import annotations

import asyncio
import collections
import re
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol, TextIO

from coordinator.events import (
    ActionEnded,
    ActionFeedback,
    ActionStarted,
    BreakpointHit,
    CallReconciled,
    OperatorApplied,
    OperatorRefused,
    PulseDelivered,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.net import PetriNet, PlaceKind
from coordinator.operator import USAGE, Command, OperatorCommand, parse_operator_command
from coordinator.reconcile import describe as describe_reconciliation
from coordinator.runtime import Runtime
from coordinator.web.frames import feedback_text
from services.results import Status

__all__ = ["ESCAPES", "HELP", "CommandSink", "Console", "read_operator_commands"]

HELP = f"operator: {USAGE}   (then Enter; Ctrl-D = end)"

#: A terminal's escape sequence (cursor and editing keys: CSI ``ESC [ ... final``, SS3 ``ESC O x``,
#: or ESC and one character), as a terminal in line mode puts it into the line when such a key is
#: pressed.
ESCAPES = re.compile(r"\x1b(?:\[[0-9;?]*[ -/]*[@-~]|O.|.)?")

#: Shortest time between two summaries of the pulses that fired nothing (line by line), seconds.
PULSE_REPORT_S = 10.0

_KIND_MARK = {PlaceKind.RESOURCE: "R", PlaceKind.PRIMITIVE_TASK: "T", PlaceKind.CONTROL: "C", PlaceKind.PLAIN: " "}


def _places(arcs: Mapping[str, int]) -> str:
    return ", ".join(p if n == 1 else f"{p}x{n}" for p, n in arcs.items()) or "-"


class Console:
    """Shows a run as it goes.

    Args:
        net: the net being run.
        stream: where to write (default standard error, so standard output keeps results).
        live: redraw a screen (``True``), print line by line (``False``), or decide from
            ``stream.isatty()`` (``None``).
        quiet: print nothing but errors, state changes, operator commands and the end.
        clock: monotonic seconds (the pulse summaries' period).
    """

    def __init__(self, net: PetriNet, *, stream: TextIO | None = None, live: bool | None = None,
                 quiet: bool = False, clock: Callable[[], float] = time.monotonic) -> None:
        self.net = net
        self._clock = clock
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.quiet = quiet
        self.runtime: Runtime | None = None
        self._recent: collections.deque[str] = collections.deque(maxlen=8)
        self._t0 = clock()
        self._silent: collections.Counter[str] = collections.Counter()
        self._silent_since = 0.0
        #: the fate of the operator's last command (shown until the next one)
        self.operator_note = ""
        #: the last error reason of a primitive action
        self.last_error = ""
        #: what the run waits for (reason and detail), or ``None``
        self.waiting: tuple[str, tuple[str, ...]] | None = None
        #: the run's state as its events tell it (running, paused, waiting, or its end state)
        self.run_state = "running"
        #: lines shown under the live view's header (e.g. the web console's address)
        self.banner: list[str] = []
        #: the live view showing this console (a :class:`coordinator.terminal.LiveScreen`), if any
        self.screen: Any = None
        #: the latest feedback of each running primitive action (by instance), as short text
        self.feedback: dict[str, str] = {}

    def attach(self, runtime: Runtime) -> None:
        """Follow ``runtime`` (set it as its observer)."""
        self.runtime = runtime
        runtime.observer = self

    def __call__(self, event: RunEvent) -> None:
        self._track(event)
        if isinstance(event, PulseDelivered) and not event.operator:
            if not event.fired:  # a pulse that fired something is on its firing's line
                if not self._silent:
                    self._silent_since = self._clock()
                self._silent[event.event] += 1
            return
        line = self._describe(event)
        if line is None:
            return
        urgent = isinstance(event, (RunStateChanged, OperatorApplied, OperatorRefused)) or (
            isinstance(event, CallReconciled) and event.differs)
        error = isinstance(event, ActionEnded) and event.result.status is Status.ERROR
        ended = isinstance(event, RunStateChanged) and event.state not in ("started", "resumed", "paused", "running",
                                                                           "waiting")
        due = self._silent and self._clock() - self._silent_since >= PULSE_REPORT_S
        if not self.live and (ended or (due and (not self.quiet or urgent or error))):
            self._flush_pulses()
        stamped = self._stamp(line)
        self._recent.append(stamped)
        if self.live:
            self.draw()
        elif not self.quiet or urgent or error:
            print(stamped, file=self.stream, flush=True)

    def note(self, text: str) -> None:
        """Add a line to the recent events (live) or print it (line by line), time-stamped."""
        stamped = self._stamp(text)
        self._recent.append(stamped)
        if self.live:
            self.draw()
        else:
            print(stamped, file=self.stream, flush=True)

    def _stamp(self, line: str) -> str:
        return f"{self._clock() - self._t0:8.3f}s  {line}"

    def _flush_pulses(self) -> None:
        """One line summing up the pulses that fired nothing since the last summary."""
        if not self._silent:
            return
        counts = ", ".join(f"{event} x{n}" for event, n in self._silent.items())
        text = self._stamp(f"pulses that fired nothing in the last {self._clock() - self._silent_since:.1f} s: {counts}")
        self._recent.append(text)
        if not self.live:
            print(text, file=self.stream, flush=True)
        self._silent.clear()

    def _track(self, event: RunEvent) -> None:
        if isinstance(event, ActionFeedback):
            self.feedback[event.instance] = feedback_text(event.data)
        elif isinstance(event, ActionEnded):
            self.feedback.pop(event.instance, None)
        if isinstance(event, OperatorRefused):
            self.operator_note = f"refused: {event.command}: {event.reason}"
        elif isinstance(event, OperatorApplied):
            self.operator_note = f"applied: {event.command}"
        elif isinstance(event, ActionEnded) and event.result.status is Status.ERROR:
            self.last_error = f"{event.task}/{event.action} on {event.node or '?'}: {event.result.reason or 'error'}"
        elif isinstance(event, CallReconciled) and event.differs:
            self.last_error = describe_reconciliation(event.node, event.action, event.assumed, event.result,
                                                      event.lost)
        elif isinstance(event, RunStateChanged):
            self.waiting = (event.reason, event.detail) if event.state == "waiting" else None
            self.run_state = "running" if event.state in ("started", "resumed") else event.state
        elif isinstance(event, (TransitionFired, ActionStarted)) and self.run_state == "waiting":
            self.waiting, self.run_state = None, "running"

    def operator_message(self, text: str) -> None:
        """Show a message about the operator's input (kept on screen until the next command)."""
        self.operator_note = text
        if self.live:
            self.draw()
        else:
            print(self._stamp(text), file=self.stream, flush=True)

    def _describe(self, event: RunEvent) -> str | None:
        if isinstance(event, TransitionFired):
            f = event.firing
            via = f" on {f.pulse}" if f.pulse else ""
            return f"fire  #{f.seq:<5} {f.transition}{via}   {_places(f.consumed)} -> {_places(f.produced)}"
        if isinstance(event, ActionStarted):
            return f"start {event.task} -> {event.action} on {event.node or '?'} [{event.instance}]"
        if isinstance(event, ActionEnded):
            r = event.result
            extra = f" ({r.outcome})" if r.outcome else ""
            why = f": {r.reason}" if r.reason else ""
            if event.forced:
                return f"done  {event.task}/{event.action}: {r.status.value}{extra} FORCED ({r.reason})"
            return (f"done  {event.task}/{event.action} on {event.node or '?'}: {r.status.value}{extra}"
                    f" in {r.wall_s:.3f} s{why}")
        if isinstance(event, PulseDelivered):
            return f"operator raised {event.event}: {event.fired} transition{'' if event.fired == 1 else 's'} fired"
        if isinstance(event, BreakpointHit):
            return f"breakpoint {event.breakpoint}: {event.why}; paused (resume, or step)"
        if isinstance(event, CallReconciled):
            text = describe_reconciliation(event.node, event.action, event.assumed, event.result, event.lost)
            return f"reconciled {event.task}: {text} [{event.instance}]"
        if isinstance(event, OperatorRefused):
            return f"operator {event.command} refused: {event.reason}"
        if isinstance(event, OperatorApplied):
            return f"operator {event.command}"
        if isinstance(event, RunStateChanged):
            why = f": {event.reason}" if event.reason else ""
            more = "".join(f"\n            - {d}" for d in event.detail if d not in event.reason)
            return f"run {event.run} {event.state}{why}{more}"
        return None

    @property
    def shown_state(self) -> str:
        """The state the view shows: ``paused`` while the engine is paused and the run goes on (it
        may be waiting too: for the operator to resume), else :attr:`run_state`."""
        runtime = self.runtime
        if runtime is not None and runtime.engine.paused and self.run_state in ("running", "waiting", "paused"):
            return "paused"
        return self.run_state

    def draw(self) -> None:
        """Have the live view redrawn (it draws :meth:`screen_lines`; nothing without a view)."""
        if self.screen is not None:
            self.screen.invalidate()

    def screen_lines(self) -> list[str]:
        """The live view, one string per line: a header (net, run, state, firings), the banner,
        the marking, the running primitive actions (with their latest feedback), what the run waits for, the last error, the
        pulses that fired nothing and the recent events. The operator's last command is
        :attr:`operator_note`, shown by the view beside the input line."""
        if self.runtime is None:
            return [f"petrobot  net {self.net.name}  starting"]
        engine = self.runtime.engine
        marking = engine.marking
        out = [f"petrobot  net {self.net.name}  run {self.runtime.run_id}  state {self.shown_state}  "
               f"firings {engine.fired}", *self.banner, "", "marking (R resource, T primitive task, C control):"]
        for place in self.net.places:
            n = marking[place.id]
            if n or place.kind is PlaceKind.CONTROL:
                out.append(f"  {_KIND_MARK[place.kind]} {place.id:<24} {'●' * min(n, 20)} {n}")
        out.append("")
        out.append("running primitive actions:")
        running = self.runtime.running()
        for r in running:
            s = r.start
            shown = self.feedback.get(s.instance)
            out.append(f"  {s.task:<14} {s.action:<22} on {r.node or '?':<10} {r.elapsed_s:7.2f} s"
                       + (f"  {shown}" if shown else ""))
        if not running:
            out.append("  (none)")
        if self.waiting is not None:
            reason, detail = self.waiting
            out.append(f"waiting: {reason}")
            out.extend(f"  - {d}" for d in detail if d not in reason)
        if self.last_error:
            out.append(f"last error: {self.last_error}")
        if self._silent:
            out.append("pulses that fired nothing: " + ", ".join(f"{e} x{n}" for e, n in self._silent.items()))
        out.append("")
        out.extend(self._recent)
        return out


class CommandSink(Protocol):
    """What :func:`read_operator_commands` hands its input to (a :class:`Runtime` is one)."""

    def command(self, cmd: OperatorCommand) -> None:
        """Take a command."""

    def refuse_input(self, text: str, reason: str) -> None:
        """Take a line that is no command (journaled as refused)."""


def read_operator_commands(runtime: CommandSink, stream: TextIO | None = None, *,
                           end_on_eof: bool = True, on_error: Any = None) -> threading.Thread:
    """Read operator commands, one per line, from ``stream`` (standard input) until end of input.

    Reading happens in a daemon thread (a blocked read must not keep the program alive at the
    end of the run); each command is handed to the runtime's event loop. The escape sequences of
    cursor and editing keys (arrows, Home, End...) that a terminal in line mode leaves in a line are
    taken out first (:data:`ESCAPES`): a line of nothing else is ignored. A line that is no command
    goes to ``runtime.refuse_input`` (journaled as refused; the console shows why until the next
    command) and to ``on_error(text, reason)`` if given, in the reader thread; the run goes on.
    End of input (Ctrl-D) is the ``end`` command when ``end_on_eof``.

    Returns:
        The started reader thread.
    """
    src = stream or sys.stdin
    loop = asyncio.get_running_loop()

    def hand(fn: Any, *args: Any) -> bool:
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # the loop has closed: the run is over
            return False
        return True

    def reader() -> None:
        for raw in src:
            line = ESCAPES.sub("", raw)
            if not line.strip():
                continue
            try:
                cmd = parse_operator_command(line)
            except ValueError as exc:
                if on_error is not None:
                    on_error(line.strip(), str(exc))
                if not hand(runtime.refuse_input, line.strip(), str(exc)):
                    return
                continue
            if not hand(runtime.command, cmd):
                return
        if end_on_eof:
            hand(runtime.command, OperatorCommand(Command.END))

    thread = threading.Thread(target=reader, name="operator-input", daemon=True)
    thread.start()
    return thread
