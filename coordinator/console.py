"""Following the token flow live in a terminal (paper section 5).

:class:`Console` is a runtime observer. On a terminal it redraws, a few times a second, the
marking (places with tokens, by kind), the running primitive actions with their node and elapsed
time, and the last firings; elsewhere (a pipe, CI, a log file) it prints one line per firing,
action start and result. :func:`read_operator_commands` turns lines typed on standard input into
operator commands (insert/remove tokens in control places, pause, step, resume, abort).
"""

from __future__ import annotations

import asyncio
import collections
import sys
import threading
import time
from typing import TextIO

from coordinator.net import PetriNet, PlaceKind
from coordinator.events import (
    ActionEnded,
    ActionStarted,
    OperatorApplied,
    OperatorRefused,
    PulseDelivered,
    RunEvent,
    RunStateChanged,
    TransitionFired,
)
from coordinator.operator import USAGE, parse_operator_command
from coordinator.runtime import Runtime
from services.results import Status

__all__ = ["Console", "read_operator_commands", "HELP"]

HELP = f"operator: {USAGE}   (then Enter)"

_KIND_MARK = {PlaceKind.RESOURCE: "R", PlaceKind.PRIMITIVE_TASK: "T", PlaceKind.CONTROL: "C", PlaceKind.PLAIN: " "}


class Console:
    """Shows a run as it goes.

    Args:
        net: the net being run.
        stream: where to write (default standard error, so standard output keeps results).
        live: redraw a screen (``True``), print line by line (``False``), or decide from
            ``stream.isatty()`` (``None``).
        quiet: print nothing but errors and the end.
    """

    def __init__(self, net: PetriNet, *, stream: TextIO | None = None, live: bool | None = None,
                 quiet: bool = False) -> None:
        self.net = net
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.quiet = quiet
        self.runtime: Runtime | None = None
        self._recent: collections.deque[str] = collections.deque(maxlen=8)
        self._t0 = time.monotonic()
        self._last_draw = 0.0

    def attach(self, runtime: Runtime) -> None:
        """Follow ``runtime`` (set it as its observer)."""
        self.runtime = runtime
        runtime.observer = self

    def __call__(self, event: RunEvent) -> None:
        t = time.monotonic() - self._t0
        line = self._describe(event)
        if line is None:
            return
        stamped = f"{t:8.3f}s  {line}"
        self._recent.append(stamped)
        urgent = isinstance(event, (RunStateChanged, OperatorApplied, OperatorRefused))
        if self.live:
            if time.monotonic() - self._last_draw > 0.1 or urgent:
                self.draw()
        elif (not self.quiet or urgent
              or (isinstance(event, ActionEnded) and event.result.status is Status.ERROR)):
            print(stamped, file=self.stream, flush=True)

    def _describe(self, event: RunEvent) -> str | None:
        if isinstance(event, TransitionFired):
            f = event.firing
            via = f" on {f.pulse}" if f.pulse else ""
            return f"fire  #{f.seq:<5} {f.transition}{via}   {self._marking_text()}"
        if isinstance(event, ActionStarted):
            return f"start {event.task} -> {event.action} on {event.node or '?'} [{event.instance}]"
        if isinstance(event, ActionEnded):
            r = event.result
            extra = f" ({r.outcome})" if r.outcome else ""
            why = f": {r.reason}" if r.reason and r.status is Status.ERROR else ""
            return (f"done  {event.task}/{event.action} on {event.node or '?'}: {r.status.value}{extra}"
                    f" in {r.wall_s:.3f} s{why}")
        if isinstance(event, OperatorRefused):
            return f"operator {event.command} refused: {event.reason}"
        if isinstance(event, OperatorApplied):
            return f"operator {event.command}"
        if isinstance(event, RunStateChanged):
            return f"run {event.run} {event.state}"
        if isinstance(event, PulseDelivered):
            return None if self.live else f"pulse {event.event}"
        return None

    def _marking_text(self) -> str:
        if self.runtime is None:
            return ""
        marking = self.runtime.engine.marking
        return "{" + ", ".join(f"{p}: {n}" for p, n in marking.items()) + "}"

    def draw(self) -> None:
        """Redraw the live screen (marking, running actions, recent events)."""
        if self.runtime is None:
            return
        self._last_draw = time.monotonic()
        engine = self.runtime.engine
        marking = engine.marking
        out = ["\x1b[H\x1b[2J", f"petrobot  net {self.net.name}  run {self.runtime.run_id}  "
               f"state {engine.state.value}  firings {engine.fired}", "", "marking (R resource, T primitive task, "
               "C control):"]
        for place in self.net.places:
            n = marking[place.id]
            if n or place.kind is PlaceKind.CONTROL:
                out.append(f"  {_KIND_MARK[place.kind]} {place.id:<24} {'●' * min(n, 20)} {n}")
        out.append("")
        out.append("running primitive actions:")
        running = self.runtime.running()
        for r in running:
            s = r.start
            out.append(f"  {s.task:<14} {s.action:<22} on {r.node or '?':<10} {r.elapsed_s:7.2f} s")
        if not running:
            out.append("  (none)")
        waiting = engine.waiting_for()
        if waiting:
            out.append(f"waiting for: {', '.join(waiting)}")
        out.append("")
        out.extend(self._recent)
        out.append("")
        out.append(HELP)
        self.stream.write("\n".join(out) + "\n")
        self.stream.flush()


def read_operator_commands(runtime: Runtime, stream: TextIO | None = None,
                           echo: TextIO | None = None) -> threading.Thread:
    """Read operator commands, one per line, from ``stream`` (standard input) until EOF.

    Reading happens in a daemon thread (a blocked read must not keep the program alive at the
    end of the run); each command is handed to the runtime's event loop. Bad lines are reported
    on ``echo`` and ignored; the run goes on.

    Returns:
        The started reader thread.
    """
    src = stream or sys.stdin
    out = echo or sys.stderr
    loop = asyncio.get_running_loop()

    def reader() -> None:
        for line in src:
            if not line.strip():
                continue
            try:
                cmd = parse_operator_command(line)
            except ValueError as exc:
                print(f"? {exc}", file=out, flush=True)
                continue
            try:
                loop.call_soon_threadsafe(runtime.command, cmd)
            except RuntimeError:  # the loop has closed: the run is over
                return

    thread = threading.Thread(target=reader, name="operator-input", daemon=True)
    thread.start()
    return thread
