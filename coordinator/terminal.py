"""The live view of a run on a terminal, with the operator's input line (paper section 5).

:class:`LiveScreen` shows what a :class:`coordinator.console.Console` knows of the run (its
:meth:`~coordinator.console.Console.screen_lines`: state, marking, running primitive actions, what
the run waits for, the last error, the last events) on the terminal's alternate screen, above an
input line where operator commands are typed. It is a ``prompt_toolkit`` full-screen application
on the run's own event loop:

* the view is redrawn when the run's events change it (and twice a second while primitive actions
  run, for their elapsed times), and prompt_toolkit writes only the cells that changed: a run at
  rest writes nothing, and the terminal's scrollback is left alone (the alternate screen);
* the input line keeps what is typed while the view changes above it, and takes the terminal's
  keys as a line editor does: arrows, Home, End, Delete, history (Up, Down), Tab completes the
  commands and the net's control places; no escape sequence ever reaches the command parser;
* Enter hands the line to the runtime (a line that is no command is journaled as refused, and the
  view says why until the next command); Ctrl-D on an empty line is ``end``; Ctrl-C interrupts the
  run as it does elsewhere (resumable with ``--resume``);
* log records written while the view is up go into the view's event list instead of onto the
  screen (where they would be overwritten).

Without an operator reading (``--no-input``, standard input not a terminal) the view has no input
line. The view stops when :meth:`LiveScreen.stop` is called; the terminal is then as it was.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import sys
from typing import Any

from coordinator.console import HELP, CommandSink, Console
from coordinator.net import PlaceKind
from coordinator.operator import Command, OperatorCommand, parse_operator_command

__all__ = ["TICK_S", "LiveScreen"]

#: Seconds between two redraws while primitive actions run (their elapsed times advance).
TICK_S = 0.5
#: Shortest time between two redraws, seconds (a burst of events is drawn once).
MIN_REDRAW_S = 0.1


class _ToScreen(logging.Handler):
    """Log records while the view is up: one line each in the console's event list."""

    def __init__(self, console: Console) -> None:
        super().__init__(logging.WARNING)
        self.console = console

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.console.note(f"log {record.levelname.lower()} {record.name}: {record.getMessage()}")
        except Exception:  # a log record must never break the view
            self.handleError(record)


class LiveScreen:
    """A full-screen view of a run with an input line for operator commands.

    Args:
        console: the console whose view is shown (its stream is the terminal written to).
        sink: where typed commands go (the runtime), or ``None`` to show the view without an input
            line.
        input, output: prompt_toolkit input and output (default: standard input and the console's
            stream); tests pass pipes.
    """

    def __init__(self, console: Console, sink: CommandSink | None, *, input: Any = None,
                 output: Any = None) -> None:
        self.console = console
        self.sink = sink
        self._input = input
        self._output = output
        self._app: Any = None
        self._task: asyncio.Task[Any] | None = None
        self._tick: asyncio.Task[None] | None = None
        self._pipe: Any = None
        self._handlers: list[tuple[logging.Handler, int]] = []
        self._to_screen: _ToScreen | None = None

    # ------------------------------------------------------------------ the application
    def _build(self) -> Any:
        from prompt_toolkit.application import Application
        from prompt_toolkit.buffer import Buffer
        from prompt_toolkit.completion import WordCompleter
        from prompt_toolkit.filters import Condition
        from prompt_toolkit.history import InMemoryHistory
        from prompt_toolkit.key_binding import KeyBindings
        from prompt_toolkit.layout import HSplit, Layout, Window
        from prompt_toolkit.layout.controls import BufferControl, FormattedTextControl
        from prompt_toolkit.layout.processors import BeforeInput
        from prompt_toolkit.output import create_output
        from prompt_toolkit.styles import Style

        console = self.console
        controls = [p.id for p in console.net.places if p.kind is PlaceKind.CONTROL]
        words = ["+", "-", "pause", "step", "resume", "abort", "end", "break", "clear", "enabled", "fires", "count",
                 "error", "inject", "force", *console.net.operator.inject, *controls]
        buffer = Buffer(multiline=False, history=InMemoryHistory(), accept_handler=self._accept,
                        completer=WordCompleter(words, sentence=False), complete_while_typing=False)
        reading = self.sink is not None

        def view() -> list[tuple[str, str]]:
            lines = console.screen_lines()
            out: list[tuple[str, str]] = []
            for i, line in enumerate(lines):
                style = "class:header" if i == 0 else "class:error" if line.startswith("last error:") else ""
                out.append((style, line + "\n"))
            return out

        def note() -> list[tuple[str, str]]:
            text = console.operator_note
            style = "class:error" if text.startswith("refused") else "class:note"
            return [(style, f"{text}")] if text else []

        bindings = KeyBindings()
        empty = Condition(lambda: not buffer.text)

        @bindings.add("c-d", filter=empty)
        def _end(event: Any) -> None:
            if self.sink is not None:
                self._hand(self.sink.command, OperatorCommand(Command.END))

        @bindings.add("c-c")
        def _interrupt(event: Any) -> None:
            signal.raise_signal(signal.SIGINT)  # as a Ctrl-C anywhere else: the run is interrupted

        @bindings.add("c-z")
        def _ignore(event: Any) -> None:
            """Suspending would stop the coordinator with the run's calls in flight."""

        body: list[Any] = [
            Window(FormattedTextControl(view), wrap_lines=False),
            Window(FormattedTextControl(note), height=1),
            Window(FormattedTextControl(HELP if reading else "(operator input is not read: --no-input or no "
                                        "terminal on standard input)"), height=1, style="class:help"),
        ]
        if reading:
            body.append(Window(BufferControl(buffer, input_processors=[BeforeInput("> ")]), height=1))
        style = Style.from_dict({"header": "reverse", "error": "ansired", "note": "bold", "help": "ansibrightblack"})
        output = self._output if self._output is not None else create_output(stdout=console.stream)
        if self._input is None and not reading:
            from prompt_toolkit.input import create_pipe_input

            self._pipe = create_pipe_input()
        return Application(layout=Layout(HSplit(body), focused_element=body[-1]), key_bindings=bindings,
                           style=style, full_screen=True, mouse_support=False,
                           min_redraw_interval=MIN_REDRAW_S, max_render_postpone_time=MIN_REDRAW_S,
                           input=self._input if self._input is not None else self._pipe, output=output)

    def _hand(self, fn: Any, *args: Any) -> None:
        asyncio.get_running_loop().call_soon(fn, *args)

    def _accept(self, buffer: Any) -> bool:
        text = buffer.text.strip()
        if not text or self.sink is None:
            return False
        try:
            cmd = parse_operator_command(text)
        except ValueError as exc:
            self._hand(self.sink.refuse_input, text, str(exc))
            return False
        self._hand(self.sink.command, cmd)
        return False  # the line is cleared (it stays in the history)

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Show the view (on the running event loop) until :meth:`stop`."""
        self._app = self._build()
        self.console.screen = self
        self._capture_logs()
        self._task = asyncio.get_running_loop().create_task(
            self._app.run_async(set_exception_handler=False, handle_sigint=False), name="live-screen")
        self._tick = asyncio.get_running_loop().create_task(self._ticker(), name="live-screen-tick")

    async def _ticker(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            runtime = self.console.runtime
            if runtime is not None and runtime.running():
                self.invalidate()

    def invalidate(self) -> None:
        """Redraw soon (at most every :data:`MIN_REDRAW_S`; only changed cells are written)."""
        if self._app is not None and self._app.is_running:
            self._app.invalidate()

    async def stop(self) -> None:
        """Leave the view: the terminal gets its normal screen and modes back."""
        if self._tick is not None:
            self._tick.cancel()
        app, task = self._app, self._task
        if app is not None and task is not None:
            if app.is_running and not app.future.done():
                app.exit()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self.console.screen = None
        self._release_logs()
        if self._pipe is not None:
            self._pipe.close()
            self._pipe = None

    def _capture_logs(self) -> None:
        root = logging.getLogger()
        for handler in root.handlers:
            if isinstance(handler, logging.StreamHandler) and getattr(handler, "stream", None) in (
                    sys.stderr, sys.stdout, self.console.stream):
                self._handlers.append((handler, handler.level))
                handler.setLevel(logging.CRITICAL + 1)
        self._to_screen = _ToScreen(self.console)
        root.addHandler(self._to_screen)

    def _release_logs(self) -> None:
        for handler, level in self._handlers:
            handler.setLevel(level)
        self._handlers.clear()
        if self._to_screen is not None:
            logging.getLogger().removeHandler(self._to_screen)
            self._to_screen = None
