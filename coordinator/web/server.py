"""The web console's server: aiohttp on the coordinator's own event loop (paper section 5).

:class:`ConsoleServer` serves the page (HTML, CSS, its scripts and the vendored libraries, all from
the package: nothing comes from another site), a small JSON API (open a net file, list the runs of
the journal, a run's timeline, export a drawing, the documentation the page links its numbers to)
and one WebSocket per page (:mod:`.protocol`): live frames of the run the page watches
(:class:`~coordinator.web.frames.LiveFeed`; the console follows any number of runs,
:mod:`.runs`), operator commands, a place's blackboard, runs started and resumed from the page,
validation, saving and analyses.

Security (docs/console.md, "Security"):

* control needs the per-server secret token (in the URL the server prints, like a notebook
  server's); a page without it is read-only: it follows the run but its commands and saves are
  refused, and it opens only the nets the console was started with;
* every request's ``Host`` must name this server (127.0.0.1, localhost or [::1] with its port,
  unless bound to another address with ``bind_any``): a DNS-rebinding page is refused;
* a WebSocket's ``Origin``, when the client sends one (browsers always do), must be this page's;
* every response carries a Content-Security-Policy allowing scripts from this server only, and
  refuses framing, sniffing and referrers;
* a malformed or hostile WebSocket message closes that socket with a reason; the run is not
  touched;
* what a page without the token may cost the run is bounded (:mod:`.limits`): at most 32 such pages,
  drawings of at most 512 KiB, their validations, exports and replays rate-limited and queued at
  most one deep, wrong tokens rate-limited per address; checking and converting drawings runs in
  the console's worker process (:mod:`.worker`), at a lower priority than the run, never on its
  event loop, and so does reading any page's replays from the journal. Each page has a bounded
  outbound queue: a page that cannot keep up gets a fresh snapshot instead of an ever-growing
  backlog.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import hmac
import ipaddress
import json
import logging
import os
import secrets
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiohttp import WSCloseCode, WSMsgType, web

from coordinator.errors import JournalError
from coordinator.operator import Command, OperatorCommand
from coordinator.web.analysis import run_analysis
from coordinator.web.draft import UNSAVED, validate_draft
from coordinator.web.files import (
    FileRefused,
    inside,
    list_nets,
    open_net,
    save_draft,
)
from coordinator.web.frames import DEFAULT_PERIOD_S, LiveFeed
from coordinator.web.limits import ConsoleGuard, ConsoleLimits
from coordinator.web.runs import LiveRun, RunRefused, RunStarter, StartRequest
from coordinator.web.protocol import (
    CLOSE_POLICY,
    MAX_MESSAGE_BYTES,
    PROTOCOL_VERSION,
    ClientMessage,
    ProtocolViolation,
    parse_client_message,
)
from coordinator.web.worker import Worker, WorkFailed

__all__ = ["STATIC", "ConsoleConfig", "ConsoleServer", "is_loopback"]

log = logging.getLogger("petrobot.web")

#: The page's files (package data).
STATIC = Path(__file__).resolve().parent / "static"

CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
       "connect-src 'self'; font-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
"""Content-Security-Policy of every response: scripts, styles and connections from this server only."""

#: Frames and messages waiting for one page before it is resynchronised with a snapshot instead.
MAX_QUEUE = 64
#: Most messages a page may send in :data:`RATE_WINDOW_S` seconds.
MAX_MESSAGES = 600
#: Most ``painted`` messages (one per frame painted) a page may send in :data:`RATE_WINDOW_S` seconds.
MAX_PAINTED = 3000
RATE_WINDOW_S = 10.0
#: Longest a closing console waits for a page to take what is queued for it (the run's last frame), s.
BYE_S = 2.0
#: How often the pages' list of live runs is brought up to date, seconds.
RUNS_PERIOD_S = 1.0
#: Live runs kept in the list once ended (the oldest ended ones are dropped beyond).
KEPT_ENDED = 8


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is a loopback address."""
    if host in ("localhost", ""):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass
class ConsoleConfig:
    """What a console serves.

    Attributes:
        root: folder the page may open and save net files in.
        nets: net files opened at the start (any reader may view these).
        journal: the journal replays and ``perf``/``learn`` read, or ``None``.
        location: the parsed ``services.toml`` placement is checked against, or ``None``.
        host, port: where to listen (port 0: any free port).
        bind_any: allow a host that is not a loopback address.
        token: the secret that gives control; a fresh random one when ``None``.
        period_s: shortest time between two live frames, seconds.
        key_file: the shared key runs started from the page connect to the nodes with (``None``:
            the default key, as ``petrobot run``).
        run_journal: the journal runs started from the page write to when ``journal`` is not
            given (``ROOT/runs/journal.sqlite``).
        limits: what pages without the token may cost (:mod:`.limits`).
    """

    root: Path = field(default_factory=Path.cwd)
    nets: list[Path] = field(default_factory=list)
    journal: Path | None = None
    location: Any = None
    host: str = "127.0.0.1"
    port: int = 0
    bind_any: bool = False
    token: str | None = None
    period_s: float = DEFAULT_PERIOD_S
    key_file: str | None = None
    run_journal: Path | None = None
    limits: ConsoleLimits = field(default_factory=ConsoleLimits)


class ConsoleServer:
    """The console: start it, print :attr:`url`, attach a run, close it.

    Raises:
        ValueError: the host is not a loopback address and ``bind_any`` is not set.
    """

    def __init__(self, config: ConsoleConfig) -> None:
        if not config.bind_any and not is_loopback(config.host):
            raise ValueError(f"{config.host} is not a loopback address: binding to it exposes the console "
                             "to the network; pass --bind-any to do so anyway")
        self.config = config
        self.token = config.token or secrets.token_urlsafe(24)
        self.root = config.root.resolve()
        self.pages: set[_Page] = set()
        self.guard = ConsoleGuard(config.limits)
        self.worker = Worker()
        #: the runs this console follows, by run id, oldest first (:mod:`.runs`)
        self.runs: dict[str, LiveRun] = {}
        self._runner: web.AppRunner | None = None
        self._runs_task: asyncio.Task[None] | None = None
        self._runs_sent: list[dict[str, Any]] = []
        self.starter = RunStarter(journal=self.run_journal(), location=config.location, key_file=config.key_file,
                                  attach=lambda runtime, path, task, origin: self._follow(runtime, path, task, origin))
        self.port = 0
        self._preloaded = {self._shown(p): p for p in config.nets}
        self.app = self._make_app()

    # ------------------------------------------------------------------ life cycle
    def _shown(self, path: Path) -> str:
        try:
            return str(path.resolve().relative_to(self.root))
        except ValueError:
            return str(path)

    @property
    def url(self) -> str:
        """The address to open, with the control token."""
        host = self.config.host
        shown = "127.0.0.1" if host in ("", "0.0.0.0") else f"[{host}]" if ":" in host and not host.startswith("[") \
            else host
        return f"http://{shown}:{self.port}/?token={self.token}"

    async def start(self) -> str:
        """Listen; return :attr:`url`.

        Raises:
            OSError: the address cannot be bound.
        """
        self._runner = web.AppRunner(self.app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.config.host, self.config.port)
        await site.start()
        addresses = self._runner.addresses  # the bound socket tells the port chosen for port 0
        self.port = int(addresses[0][1]) if addresses else self.config.port
        self._runs_task = asyncio.get_running_loop().create_task(self._tell_runs(), name="console-runs")
        return self.url

    async def close(self, reason: str = "the console is closing") -> None:
        """Say goodbye to every page, close their sockets and stop listening; the runs started from
        the page are interrupted (resumable)."""
        for live in self.runs.values():
            with contextlib.suppress(Exception):
                live.feed.flush()
        for page in list(self.pages):
            await page.close(WSCloseCode.GOING_AWAY, reason, bye=True)
        await self.starter.stop()
        for task in (self._runs_task, *(live.feed_task for live in self.runs.values())):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        for live in self.runs.values():
            live.runtime.remove_observer(live.feed)
        if self._runner is not None:
            await self._runner.cleanup()
        await self.worker.close()

    # ------------------------------------------------------------------ the runs it follows
    def run_journal(self) -> Path:
        """The journal runs started from the page write to."""
        if self.config.journal is not None:
            return self.config.journal
        return self.config.run_journal or self.root / "runs" / "journal.sqlite"

    @property
    def live(self) -> LiveRun | None:
        """The run a page watches unless it chose another: the newest one still going, else the newest."""
        going = [live for live in self.runs.values() if not live.feed.ended]
        return (going or list(self.runs.values()) or [None])[-1]

    @property
    def feed(self) -> LiveFeed | None:
        """The frames of :attr:`live` (``None`` without a run)."""
        return self.live.feed if self.live is not None else None

    @property
    def runtime(self) -> Any:
        """The runtime of :attr:`live` (``None`` without a run)."""
        return self.live.runtime if self.live is not None else None

    @property
    def live_net(self) -> dict[str, Any] | None:
        """The drawing of :attr:`live`'s net."""
        return self.live.net if self.live is not None else None

    def attach_run(self, runtime: Any, net_path: Path | None = None) -> LiveFeed:
        """Follow a run (a :class:`coordinator.runtime.Runtime`, before or after it starts): its events
        go to the pages watching it as frames, and pages with the token steer it."""
        return self._follow(runtime, net_path, None).feed

    def _follow(self, runtime: Any, net_path: Path | None, task: asyncio.Task[Any] | None,
                origin: str = "attached") -> LiveRun:
        feed = LiveFeed(runtime, period_s=self.config.period_s)
        runtime.add_observer(feed)
        feed_task = asyncio.get_running_loop().create_task(feed.run(), name=f"console-frames-{runtime.run_id}")
        net = None
        if net_path is not None:
            with contextlib.suppress(FileRefused):
                net = open_net(net_path, self.config.location, shown_as=self._shown(net_path))
        if net is None:
            from coordinator.web.draft import draft_of_net
            from coordinator.web.files import with_layout

            draft = with_layout(draft_of_net(runtime.net))
            net = {"path": runtime.net.name, "name": runtime.net.name, "draft": draft,
                   "validation": validate_draft(draft, runtime.net.name, self.config.location).to_json(),
                   "laid_out": True}
        live = LiveRun(runtime, feed, net, feed_task, origin=origin, task=task)
        self.runs[live.run_id] = live
        ended = [rid for rid, other in self.runs.items() if other.feed.ended]
        for rid in ended[:max(0, len(ended) - KEPT_ENDED)]:
            self.runs.pop(rid).feed_task.cancel()
        for page in list(self.pages):
            if page.watching is None or page.watching not in self.runs or self.runs[page.watching].feed.ended:
                page.watch(live)
        self._send_runs()
        return live

    def runs_json(self) -> list[dict[str, Any]]:
        """The live runs for the pages' list, oldest first."""
        return [live.summary() for live in self.runs.values()]

    def _send_runs(self) -> None:
        runs = self.runs_json()
        if runs != self._runs_sent:
            self._runs_sent = runs
            for page in list(self.pages):
                if page.greeted:
                    page.send({"type": "runs", "runs": runs})

    async def _tell_runs(self) -> None:
        """Keep the pages' list of live runs up to date (their state and firings, once a second)."""
        while True:
            await asyncio.sleep(RUNS_PERIOD_S)
            with contextlib.suppress(Exception):
                self._send_runs()

    # ------------------------------------------------------------------ the app
    def _make_app(self) -> web.Application:
        app = web.Application(middlewares=[self._guard], client_max_size=MAX_MESSAGE_BYTES)
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/api/nets", self._api_nets)
        app.router.add_get("/api/net", self._api_net)
        app.router.add_get("/api/runs", self._api_runs)
        app.router.add_get("/api/replay", self._api_replay)
        app.router.add_post("/api/export", self._api_export)
        app.router.add_get("/docs/{name}", self._docs)
        app.router.add_static("/static/", STATIC, follow_symlinks=False, show_index=False)
        return app

    def allowed_hosts(self) -> set[str]:
        """``Host`` header values naming this server."""
        port = self.port
        hosts = {f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}"}
        host = self.config.host
        if host not in ("", "0.0.0.0", "::"):
            hosts.add(f"[{host}]:{port}" if ":" in host and not host.startswith("[") else f"{host}:{port}")
        return hosts

    def has_token(self, given: str | None) -> bool:
        """Whether ``given`` is the control token (compared in constant time)."""
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())

    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                     ) -> web.StreamResponse:
        host = request.headers.get("Host", "")
        if not self.config.bind_any and host not in self.allowed_hosts():
            return self._secure(web.Response(status=421, text="this console answers to its own address only"))
        try:
            response = await handler(request)
        except web.HTTPException as exc:  # 404s and the like carry the headers too
            self._secure(exc)
            raise
        return self._secure(response)

    @staticmethod
    def _secure(response: web.StreamResponse) -> web.StreamResponse:
        if not response.prepared:
            headers = response.headers
            headers["Content-Security-Policy"] = CSP
            headers["X-Content-Type-Options"] = "nosniff"
            headers["Referrer-Policy"] = "no-referrer"
            headers["X-Frame-Options"] = "DENY"
            headers["Cache-Control"] = "no-store"
        return response

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    def _error(self, status: int, text: str) -> web.Response:
        return web.json_response({"error": text}, status=status)

    def _control(self, request: web.Request) -> bool:
        """Whether the request carries the token; a wrong one costs its address (:mod:`.limits`).

        Raises:
            web.HTTPTooManyRequests: the address gave too many wrong tokens lately.
        """
        given = request.headers.get("X-Petrobot-Token")
        if given is None:
            return False
        if self.has_token(given):
            return True
        if not self.guard.wrong_token(request.remote or ""):
            raise web.HTTPTooManyRequests(text="too many wrong tokens from this address: wait")
        return False

    async def _work(self, control: bool, size: int, kind: str, message: str, **fields: Any) -> Any:
        """One job of the worker process within the guard's bounds.

        Raises:
            WorkFailed: refused by a bound, or failed in the worker.
        """
        refused = self.guard.may_work(control, size)
        if refused is not None:
            raise WorkFailed(refused)
        try:
            return await self.worker.run(kind, message, **fields)
        finally:
            self.guard.work_done(control)

    async def _api_nets(self, request: web.Request) -> web.StreamResponse:
        opened = list(self._preloaded)
        files = await asyncio.to_thread(list_nets, self.root) if self._control(request) else []
        return web.json_response({"opened": opened, "files": files, "root": str(self.root),
                                  "journal": self._shown(self.config.journal) if self.config.journal else None})

    async def _api_net(self, request: web.Request) -> web.StreamResponse:
        path = request.query.get("path", "")
        target = self._preloaded.get(path)
        if target is None:
            if not self._control(request):
                return self._error(403, "read-only console: only the nets it was started with can be opened "
                                        "(open the URL with its token)")
            try:
                target = inside(self.root, path)
            except FileRefused as exc:
                return self._error(400, str(exc))
        try:
            net = await asyncio.to_thread(open_net, target, self.config.location, shown_as=self._shown(target))
        except FileRefused as exc:
            return self._error(400, str(exc))
        return web.json_response(net)

    def _journal(self) -> Path | None:
        if self.config.journal is not None:
            return self.config.journal
        journal = getattr(self.runtime, "journal", None)
        path = getattr(journal, "path", None)
        if path and path != ":memory:":
            return Path(path)
        started = self.run_journal()
        return started if started.is_file() else None

    async def _docs(self, request: web.Request) -> web.StreamResponse:
        from coordinator.web.docs import DocMissing, render_doc

        try:
            html = await asyncio.to_thread(render_doc, request.match_info["name"])
        except DocMissing as exc:
            return web.Response(status=404, text=str(exc))
        return web.Response(text=html, content_type="text/html", charset="utf-8")

    async def _api_runs(self, request: web.Request) -> web.StreamResponse:
        from coordinator.journal import JournalReader
        from coordinator.web.replay import runs_json

        path = self._journal()
        if path is None:
            return web.json_response({"journal": None, "runs": []})

        def read() -> list[dict[str, Any]]:
            with JournalReader.open(path) as reader:
                return runs_json(reader)
        try:
            runs = await asyncio.to_thread(read)
        except JournalError as exc:
            return self._error(400, str(exc))
        live = getattr(self.runtime, "run_id", None)
        return web.json_response({"journal": self._shown(path), "runs": runs, "live": live,
                                  "following": list(self.runs)})

    async def _api_replay(self, request: web.Request) -> web.StreamResponse:
        path = self._journal()
        run = request.query.get("run", "")
        if path is None:
            return self._error(404, "no journal: start the console with --journal FILE")
        run_id = request.query.get("run", "")
        following = self.runs.get(run_id)
        fallback = following.net["draft"] if following is not None else self.live_net["draft"] if self.live_net else None
        control = self._control(request)
        refused = self.guard.may_work(control, 0)
        if refused is not None:
            return self._error(429, refused)
        try:
            return await self._replay(path, run, following, fallback)
        finally:
            self.guard.work_done(control)

    async def _replay(self, path: Path, run: str, following: LiveRun | None, fallback: dict[str, Any] | None
                      ) -> web.StreamResponse:
        """A run's replay, read from the journal and laid out in the worker process (:mod:`.worker`):
        its body is sent on as the worker wrote it."""
        shown = following.net if following is not None else self.live_net
        try:
            body = await self.worker.run("replay", "", journal=str(path), run=run, fallback=fallback,
                                         preloaded=[[name, str(p)] for name, p in self._preloaded.items()],
                                         shown=shown["draft"] if shown is not None else None)
        except WorkFailed as exc:
            return self._error(404 if exc.journal else 503, str(exc))
        return web.Response(body=body, content_type="application/json")

    async def _api_export(self, request: web.Request) -> web.StreamResponse:
        fmt = request.query.get("format", "toml")
        control = self._control(request)
        limit = self.config.limits.viewer_bytes
        if not control and (request.content_length or 0) > limit:
            self.guard.refused += 1
            return self._error(413, f"a read-only page may send drawings of at most {limit >> 10} KiB: open the URL "
                                    "with its token")
        body = await request.text()
        hidden = request.query.get("hidden", "1") != "0"
        # the drawing goes to the worker as the text it came in, inside a message the worker checks
        message = '{"type":"validate","id":0,"draft":' + body + "}"
        try:
            text, media = await self._work(control, len(body), "export", message, format=fmt, hidden=hidden)
        except WorkFailed as exc:
            status = 429 if "busy" in str(exc) else 413 if "at most" in str(exc) else 400
            return self._error(status, f"not exported: {exc}")
        return web.Response(text=text, content_type=media, charset="utf-8")

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin != f"http://{request.headers.get('Host', '')}":
            return web.Response(status=403, text="cross-origin WebSocket refused")
        # aiohttp's own limit sits above the protocol's, so that an oversized message is closed here, with a
        # reason; beyond aiohttp's limit it closes the socket itself (code 1009)
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES + (1 << 20), compress=False, heartbeat=30.0)
        await ws.prepare(request)
        page = _Page(self, ws, request.remote or "")
        self.pages.add(page)
        try:
            await page.serve()
        finally:
            self.pages.discard(page)
            page.stop()
        return ws

    # ------------------------------------------------------------------ what a page learns first
    def welcome(self, control: bool, live: LiveRun | None) -> dict[str, Any]:
        from coordinator.web.docs import DEFINITIONS

        return {"type": "welcome", "v": PROTOCOL_VERSION, "control": control, "server_time": time.time(),
                "nets": list(self._preloaded), "journal": self._shown(self._journal()) if self._journal() else None,
                "services": self.config.location is not None,
                "live": live.feed.snapshot() if live is not None else None,
                "net": live.net if live is not None else None, "runs": self.runs_json(),
                "definitions": DEFINITIONS}


class _Page:
    """One page's WebSocket: its reading loop, its bounded outbound queue and sender task."""

    def __init__(self, server: ConsoleServer, ws: web.WebSocketResponse, host: str = "") -> None:
        self.server = server
        self.ws = ws
        self.host = host
        self.control = False
        self.greeted = False
        self.viewer = False  # counted among the read-only pages
        self._raw = ""  # the text of the message being handled
        self._frames: collections.deque[str] = collections.deque()
        self._replies: collections.deque[str] = collections.deque()
        self._resync = False
        self._ready = asyncio.Event()
        self._sender: asyncio.Task[None] | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self._recent: collections.deque[float] = collections.deque()
        self._closing = False
        #: the run whose frames this page gets (a run id of ``server.runs``), or ``None``
        self.watching: str | None = None
        self._analysis: asyncio.Future[Any] | None = None
        self._feed: LiveFeed | None = None
        self._painted: collections.deque[float] = collections.deque()
        self._drained = asyncio.Event()  # set whenever the sender has sent everything queued

    # ------------------------------------------------------------------ outbound
    def send(self, message: dict[str, Any]) -> None:
        """Queue a message (never dropped)."""
        self._replies.append(json.dumps(message, separators=(",", ":"), default=str))
        self._drained.clear()
        self._ready.set()

    def offer_frame(self, text: str) -> None:
        """Queue a live frame; past :data:`MAX_QUEUE` waiting, drop them all for one snapshot."""
        if len(self._frames) >= MAX_QUEUE:
            self._frames.clear()
            self._resync = True
        else:
            self._frames.append(text)
        self._drained.clear()
        self._ready.set()

    def watch(self, live: LiveRun | None, *, announce: bool = True) -> None:
        """Get the frames of ``live`` from now on (instead of another run's); with ``announce``, send
        the page its snapshot and net first (a ``run`` message)."""
        if self._feed is not None:
            self._feed.unsubscribe(self.offer_frame)
            self._feed = None
        self._frames.clear()
        self._resync = False
        self.watching = live.run_id if live is not None else None
        if live is None:
            return
        if announce:
            journal = self.server._journal()
            self.send({"type": "run", "live": live.feed.snapshot(), "net": live.net,
                       "journal": self.server._shown(journal) if journal else None})
        self._feed = live.feed
        live.feed.subscribe(self.offer_frame)

    async def _send_loop(self) -> None:
        ws = self.ws
        while not ws.closed:
            await self._ready.wait()
            self._ready.clear()
            while (self._replies or self._frames or self._resync) and not ws.closed:
                if self._replies:
                    text = self._replies.popleft()
                elif self._resync and self._feed is not None:
                    self._resync = False
                    self._frames.clear()
                    text = json.dumps({"type": "snapshot", **self._feed.snapshot()}, separators=(",", ":"),
                                      default=str)
                elif self._frames:
                    text = self._frames.popleft()
                else:
                    self._resync = False
                    continue
                try:
                    await ws.send_str(text)
                except (ConnectionError, RuntimeError):
                    return
            self._drained.set()

    # ------------------------------------------------------------------ inbound
    async def serve(self) -> None:
        self._sender = asyncio.get_running_loop().create_task(self._send_loop())
        async for msg in self.ws:
            if msg.type == WSMsgType.TEXT:
                data = msg.data
                limit = self.server.config.limits.viewer_bytes
                if not self.control and len(data) > limit:  # closed unread: not parsed on the run's loop
                    self.server.guard.refused += 1
                    self.server.guard.viewer_closed(self.host)
                    await self.close(1009, f"read-only page: message larger than {limit >> 10} KiB")
                    break
                if len(data.encode("utf-8")) > MAX_MESSAGE_BYTES:
                    await self.close(1009, f"message larger than {MAX_MESSAGE_BYTES} bytes")
                    break
                self._raw = data
                try:
                    if self.greeted and not self.control and len(data) > self.server.config.limits.small_bytes:
                        self._count()
                        await self._validate_unread(data)  # parsed in the worker, not on the run's loop
                        continue
                    msg = parse_client_message(data)
                    if msg.type == "painted":
                        self._count_painted()
                    else:
                        self._count()
                    await self.handle(msg)
                except ProtocolViolation as exc:
                    log.info("closing a console WebSocket: %s", exc.reason)
                    if self.viewer:  # a read-only page let in, now closed for what it sent
                        self.server.guard.viewer_closed(self.host)
                    await self.close(exc.code, exc.reason)
                    break
            elif msg.type == WSMsgType.BINARY:
                await self.close(CLOSE_POLICY, "binary frames are not part of the protocol")
                break
            elif msg.type == WSMsgType.ERROR:
                break

    def _count(self) -> None:
        now = time.monotonic()
        self._recent.append(now)
        while self._recent and self._recent[0] < now - RATE_WINDOW_S:
            self._recent.popleft()
        if len(self._recent) > MAX_MESSAGES:
            raise ProtocolViolation(f"more than {MAX_MESSAGES} messages in {RATE_WINDOW_S:g} s")

    def _count_painted(self) -> None:
        """``painted`` messages have their own bound: one per frame the page was sent, at most."""
        now = time.monotonic()
        self._painted.append(now)
        while self._painted and self._painted[0] < now - RATE_WINDOW_S:
            self._painted.popleft()
        if len(self._painted) > MAX_PAINTED:
            raise ProtocolViolation(f"more than {MAX_PAINTED} painted messages in {RATE_WINDOW_S:g} s")

    async def close(self, code: int, reason: str, *, bye: bool = False) -> None:
        if self._closing:
            return
        self._closing = True
        if bye and not self.ws.closed:
            if self._sender is not None and not self._sender.done():
                # after what is queued (the run's last frame, with its end and summary), not before it
                self.send({"type": "bye", "reason": reason})
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(BYE_S):
                        await self._drained.wait()
            else:
                with contextlib.suppress(Exception):
                    await self.ws.send_str(json.dumps({"type": "bye", "reason": reason}))
        with contextlib.suppress(Exception):
            await self.ws.close(code=code, message=reason.encode("utf-8")[:123])

    def stop(self) -> None:
        if self.viewer:
            self.viewer = False
            self.server.guard.viewer_leaves()
        if self._feed is not None:
            self._feed.unsubscribe(self.offer_frame)
        for task in (self._sender, *self._tasks):
            if task is not None:
                task.cancel()

    def _spawn(self, coro: Awaitable[Any]) -> asyncio.Future[Any]:
        task = asyncio.ensure_future(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    def reply(self, msg: ClientMessage, **fields: Any) -> None:
        self.send({"type": "reply", "id": msg.id, "to": msg.type, **fields})

    async def handle(self, msg: ClientMessage) -> None:
        server = self.server
        if msg.type == "hello":
            if self.greeted:
                raise ProtocolViolation("hello twice")
            self.greeted = True
            token = msg.fields["token"]
            self.control = server.has_token(token)
            if not self.control:
                if token and not server.guard.wrong_token(self.host):
                    raise ProtocolViolation("too many wrong tokens from this address: wait")
                refused = server.guard.viewer_joins(self.host)
                if refused is not None:
                    raise ProtocolViolation(refused, code=1013)
                self.viewer = True
            live = server.live
            self.send(server.welcome(self.control, live))
            self.watch(live, announce=False)
            return
        if not self.greeted:
            raise ProtocolViolation("the first message must be hello")
        if msg.type == "painted":
            if self._feed is not None:
                self._feed.painted(self.offer_frame, msg.fields["seq"])
        elif msg.type == "watch":
            live = server.runs.get(msg.fields["run"])
            if live is None:
                self.reply(msg, ok=False, reason=f"the console follows no run {msg.fields['run']!r}")
            else:
                self.watch(live)
                self.reply(msg, ok=True, run=live.run_id)
        elif msg.type == "blackboard":
            live = server.runs.get(msg.fields["run"] or self.watching or "")
            if live is None:
                self.reply(msg, ok=False, reason="no run is followed here")
            else:
                self.reply(msg, ok=True, blackboard=live.feed.blackboard(msg.fields["place"]))
        elif msg.type in ("start", "resume"):
            if not self.control:
                self.reply(msg, ok=False, reason=_READ_ONLY)
            else:
                self._spawn(self._start(msg))
        elif msg.type == "ping":
            self.reply(msg, ok=True, t=msg.fields["t"], server_time=time.time())
        elif msg.type == "command":
            self._command(msg)
        elif msg.type == "validate":
            await self._validate(msg)
        elif msg.type == "save":
            await self._save(msg)
        elif msg.type == "analyze":
            if not self.control:
                self.reply(msg, ok=False, reason=_READ_ONLY)
            elif self._analysis is not None and not self._analysis.done():
                self.reply(msg, ok=False, reason="an analysis is already running")
            else:
                self._analysis = self._spawn(self._analyze(msg))

    def _command(self, msg: ClientMessage) -> None:
        server = self.server
        if not self.control:
            self.reply(msg, ok=False, reason=_READ_ONLY)
            return
        f = msg.fields
        live = server.runs.get(f.get("run") or self.watching or "")
        if live is None:
            self.reply(msg, ok=False, reason="no run is followed by this console (petrobot run NET --console PORT, "
                                             "or start one from the page)")
            return
        if live.feed.ended:
            self.reply(msg, ok=False, reason=f"the run has ended ({live.feed.state['state']})")
            return
        if f["command"] in (Command.INSERT, Command.REMOVE):
            command = OperatorCommand(f["command"], f.get("place"), f.get("count", 1))
        else:
            command = OperatorCommand(f["command"], breakpoint=f.get("breakpoint"), event=f.get("event"),
                                      instance=f.get("instance"), outcome=f.get("outcome"), reason=f.get("reason", ""),
                                      payload=f.get("payload"))
        live.feed.expect_reply(command, lambda ok, reason: self.reply(msg, ok=ok, reason=reason,
                                                                     command=str(command)))
        live.runtime.command(command)

    async def _start(self, msg: ClientMessage) -> None:
        """Start or resume a run of a net file under the root, as ``petrobot run`` would (:mod:`.runs`)."""
        server = self.server
        f = msg.fields
        try:
            path = inside(server.root, f["net"])
        except FileRefused as exc:
            self.reply(msg, ok=False, reason=str(exc))
            return
        request = StartRequest(path, marking=f.get("marking", {}), seed=f.get("seed", 0),
                               max_seconds=f.get("max_seconds"), degraded=f["degraded"], resume=msg.type == "resume")
        try:
            live = await server.starter.start(request)
        except RunRefused as exc:
            self.reply(msg, ok=False, reason=str(exc))
            return
        self.watch(live)
        self.reply(msg, ok=True, run=live.run_id)

    async def _validate(self, msg: ClientMessage) -> None:
        """Check a drawing: a small one of a page with the token in a thread, as it is drawn; any
        other in the worker process, within the guard's bounds (:mod:`.limits`)."""
        server = self.server
        name = msg.fields.get("name") or UNSAVED
        if self.control and len(self._raw) <= server.config.limits.small_bytes:
            result = await asyncio.to_thread(validate_draft, msg.fields["draft"], name, server.config.location)
            self.reply(msg, ok=True, validation=result.to_json())
            return
        try:
            answer = await server._work(self.control, len(self._raw), "validate", self._raw, name=name,
                                        services=self._services())
        except WorkFailed as exc:
            self.reply(msg, ok=False, reason=str(exc))
            return
        self.reply(msg, ok=True, validation=answer["validation"])

    def _services(self) -> str | None:
        """The services.toml the worker checks placement against: the console's, if it came from a file."""
        location = self.server.config.location
        path = getattr(location, "path", None) if location is not None else None
        return str(path) if path and os.path.isfile(path) else None

    async def _validate_unread(self, data: str) -> None:
        """A read-only page's message too large to parse on the run's loop (over ``small_bytes``):
        it may only be a ``validate``, and it goes to the worker as text, within the guard's bounds.
        A page whose budget is spent is closed (code 1013, try again later): its message was not
        read, so there is no id to reply to.

        Raises:
            ProtocolViolation: the budget is spent, or the message breaks the protocol.
        """
        try:
            answer = await self.server._work(False, len(data), "validate", data, services=self._services())
        except WorkFailed as exc:
            if exc.violation is not None:
                raise ProtocolViolation(str(exc), exc.violation) from None
            raise ProtocolViolation(f"read-only page: {exc}", code=1013) from None
        self.send({"type": "reply", "id": answer["id"], "to": "validate", "ok": True,
                   "validation": answer["validation"]})

    async def _save(self, msg: ClientMessage) -> None:
        server = self.server
        if not self.control:
            self.reply(msg, ok=False, reason=_READ_ONLY)
            return
        try:
            target = inside(server.root, msg.fields["path"], suffixes=(".toml", ".pnml"))
            saved = await asyncio.to_thread(save_draft, msg.fields["draft"], target, server.config.location,
                                            shown_as=server._shown(target))
        except FileRefused as exc:
            self.reply(msg, ok=False, reason=str(exc))
            return
        saved["path"] = server._shown(Path(saved["path"]))
        self.reply(msg, ok=True, **saved)

    async def _analyze(self, msg: ClientMessage) -> None:
        server = self.server
        journal = server._journal()
        try:
            report = await run_analysis(msg.fields["kind"], msg.fields["draft"], journal=str(journal) if journal else None,
                                        run=msg.fields.get("run"), cwd=server.root,
                                        as_json=msg.fields.get("format") == "json")
        except Exception as exc:  # an analysis that cannot start is reported, never raised into the loop
            self.reply(msg, ok=False, reason=f"{type(exc).__name__}: {exc}")
            return
        self.reply(msg, ok=True, report=report)


_READ_ONLY = "read-only: this page was opened without the console's token (open the URL petrobot printed)"
