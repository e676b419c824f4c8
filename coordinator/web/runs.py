"""Live runs in the console: the runs a console follows, and the runs it starts or resumes for the page.

A console follows any number of runs side by side (Groot2 shows one tree per port; here one page
per run, or one page switching between them): :class:`LiveRun` is one of them — its runtime, the
:class:`~coordinator.web.frames.LiveFeed` that turns its events into frames, and the drawing of its
net. ``petrobot run NET --console`` attaches the run it executes; the page may start more.

:class:`RunStarter` starts (and resumes) a run of a net file for the page exactly as ``petrobot run``
does (:func:`coordinator.session.execute`): the same preflight of every primitive action on the
nodes of services.toml (a run that would not start on the command line does not start from the
page: the reply names each problem, unless the page asked for a degraded start), the learners
restored from the journal, the same journal (the console's ``--journal``, else
``ROOT/runs/journal.sqlite``), the same end states. The page picks the net, the tokens of its
control places (the number of runs, e.g. ``runs_remaining``), the seed and the deadline
(``max_seconds``). A run started from the page has the page as its operator: it waits for the
operator at rest, until ``end``, ``abort`` or its deadline, and goes on when the page is closed
(any page with the token may steer it); stopping the console interrupts it (resumable).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coordinator.console import Console
from coordinator.web.frames import LiveFeed

__all__ = ["LiveRun", "RunRefused", "RunStarter", "StartRequest"]

log = logging.getLogger("petrobot.web")

#: Most runs the console starts from the page that may run at the same time.
MAX_STARTED = 8
#: Longest a start waits for the preflight and the run's first event, seconds.
START_TIMEOUT_S = 60.0


class RunRefused(Exception):
    """A run the page asked for does not start: why, in words (the preflight's problems, a net
    that does not load, nothing to resume...)."""


@dataclass
class LiveRun:
    """A run the console follows.

    Attributes:
        runtime: the run (a :class:`coordinator.runtime.Runtime`).
        feed: its frames.
        net: ``{"path", "name", "draft", "validation", "laid_out"}``, the drawing of its net.
        feed_task: the task building its frames.
        origin: ``"attached"`` (``petrobot run --console``) or ``"page"`` (started from the page).
        task: the run itself, when the console started it.
    """

    runtime: Any
    feed: LiveFeed
    net: dict[str, Any]
    feed_task: asyncio.Task[None]
    origin: str = "attached"
    task: asyncio.Task[Any] | None = None

    @property
    def run_id(self) -> str:
        return str(self.runtime.run_id)

    def summary(self) -> dict[str, Any]:
        """One line of the page's list of live runs."""
        state = self.feed.state
        engine = self.runtime.engine
        return {"run": self.run_id, "net": self.runtime.net.name, "path": self.net.get("path"),
                "state": state.get("state"), "reason": state.get("reason", ""), "firings": engine.fired,
                "paused": engine.paused, "origin": self.origin, "ended": self.feed.ended}


@dataclass
class StartRequest:
    """What the page asked for (checked by :mod:`coordinator.web.protocol`).

    Attributes:
        path: the net file (under the console's root).
        marking: control place → its initial tokens, instead of the file's.
        seed: the seed of the engine's random switches and the learners.
        max_seconds: the run's deadline, or ``None``.
        degraded: start even when the preflight finds problems.
        resume: continue the last unfinished or interrupted run of the net instead.
    """

    path: Path
    marking: dict[str, int] = field(default_factory=dict)
    seed: int = 0
    max_seconds: float | None = None
    degraded: bool = False
    resume: bool = False


class _PageConsole(Console):
    """The terminal console of a run the page started: quiet lines on the console's standard error
    (errors, state changes, operator commands), and the run handed to the web console when it exists."""

    def __init__(self, net: Any, on_runtime: Callable[[Any], None]) -> None:
        super().__init__(net, stream=sys.stderr, live=False, quiet=True)
        self._on_runtime = on_runtime

    def attach(self, runtime: Any) -> None:
        super().attach(runtime)
        self._on_runtime(runtime)


class RunStarter:
    """Starts and resumes runs of net files for the page (module doc).

    Args:
        journal: the journal runs are written to.
        location: the parsed services.toml, or ``None`` (then nothing can start).
        key_file: the shared key file (``None``: the default, as ``petrobot run``).
        attach: called with ``(runtime, net_path, task, origin)`` once a run has passed its
            preflight and has a runtime; it returns the :class:`LiveRun` the console follows.
    """

    def __init__(self, *, journal: Path, location: Any, key_file: str | None,
                 attach: Callable[[Any, Path, asyncio.Task[Any], str], LiveRun]) -> None:
        self.journal = journal
        self.location = location
        self.key_file = key_file
        self._attach = attach
        self.tasks: set[asyncio.Task[Any]] = set()

    async def start(self, request: StartRequest) -> LiveRun:
        """Start (or resume) a run; return it once it has passed its preflight.

        Raises:
            RunRefused: the run does not start, and why.
        """
        from coordinator.errors import NetError
        from coordinator.journal import Journal
        from coordinator.net import PlaceKind
        from coordinator.netfile import load_any
        from coordinator.session import NodesNotReady, execute
        from services.errors import PetrobotError
        from services.keys import load_key

        if self.location is None:
            raise RunRefused("the console has no services.toml (start it with --services FILE, or from the folder "
                             "that has services.toml): a run needs the nodes")
        running = sum(1 for t in self.tasks if not t.done())
        if running >= MAX_STARTED:
            raise RunRefused(f"{running} runs started from the page are still going: end one first")
        path = request.path
        try:
            net = await asyncio.to_thread(load_any, path)
        except (NetError, OSError) as exc:
            raise RunRefused(f"{path.name}: {exc}") from None
        problems = net.interpretation_problems()
        if problems:
            raise RunRefused("; ".join(f"{path.name}: {element}: {problem}" for element, problem in problems))
        if request.marking and not request.resume:
            for place, tokens in request.marking.items():
                if place not in net.place_index or net.place(place).kind is not PlaceKind.CONTROL:
                    raise RunRefused(f"{place!r} is not a control place of net {net.name!r}: only control places "
                                     "take tokens from the operator")
            net = net.with_initial_marking({**net.initial_marking.to_dict(), **request.marking})
        try:
            key = await asyncio.to_thread(load_key, self.key_file)
        except PetrobotError as exc:
            raise RunRefused(str(exc)) from None
        text = path.read_text(encoding="utf-8") if path.suffix.lower() == ".toml" else None
        if request.marking and not request.resume:
            from coordinator.netfile import dump_net
            from coordinator.netfile.layout import load_layout

            # the journal keeps the net as it is run (the operator's tokens), with its drawing
            text = dump_net(net, await asyncio.to_thread(load_layout, path))
        loop = asyncio.get_running_loop()
        ready: asyncio.Future[LiveRun] = loop.create_future()
        holder: dict[str, asyncio.Task[Any]] = {}

        def on_runtime(runtime: Any) -> None:
            live = self._attach(runtime, path, holder["task"], "page")
            if not ready.done():
                ready.set_result(live)

        async def go() -> Any:
            self.journal.parent.mkdir(parents=True, exist_ok=True)
            with Journal(self.journal) as journal:
                return await execute(net, location=self.location, key=key, journal=journal, seed=request.seed,
                                     resume=request.resume, net_text=text, live=False, quiet=True,
                                     max_seconds=request.max_seconds, console=_PageConsole(net, on_runtime),
                                     wait=True, linger=True, degraded=request.degraded)

        task = loop.create_task(go(), name=f"console-run-{net.name}")
        holder["task"] = task
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)
        task.add_done_callback(lambda t: self._ended(t, ready))
        try:
            async with asyncio.timeout(START_TIMEOUT_S):
                return await asyncio.shield(ready)
        except TimeoutError:
            task.cancel()
            raise RunRefused(f"the run of {path.name} did not start within {START_TIMEOUT_S:g} s") from None
        except RunRefused:
            raise
        except NodesNotReady as exc:
            raise RunRefused(str(exc)) from None
        except PetrobotError as exc:
            raise RunRefused(str(exc)) from None

    @staticmethod
    def _ended(task: asyncio.Task[Any], ready: asyncio.Future[Any]) -> None:
        if task.cancelled():
            if not ready.done():
                ready.set_exception(RunRefused("the run was stopped before it started"))
            return
        exc = task.exception()
        if exc is not None:
            if not ready.done():
                ready.set_exception(exc)
            else:
                log.error("a run started from the console failed: %s", exc)

    async def stop(self) -> None:
        """Interrupt the runs still going (each is journaled interrupted, resumable)."""
        for task in list(self.tasks):
            task.cancel()
        for task in list(self.tasks):
            with contextlib.suppress(BaseException):
                await task
