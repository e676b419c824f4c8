"""A node: the asyncio server that hosts the primitive actions services.toml places on it.

Run as ``python -m services.node NAME [--services services.toml] [--key-file F] [--log-level L]``
(or ``petrobot node NAME``). The protocol itself lives in :mod:`services.protocol`; this module is
the thin I/O shell around it plus the call machinery (docs/protocol.md, "Node behaviour"):

* each call runs as its own task; the deadline (``deadline_ms``) cuts it off with status ``error``
  and reason ``"deadline"``; a ``cancel`` cuts it off with reason ``"cancelled"``;
* at most ``max_in_flight`` calls run at once, more are rejected with ``"busy"``;
* a ``local_only`` action is rejected with ``"local_only"`` unless the peer is local. Rule: a peer is
  local when its IP address equals the IP address on which this node accepted the connection (a
  process on the same host connecting to that address gets it as its source address);
* a repeated call id gets the first result (kept in a bounded LRU: 10,000 results, 10 minutes)
  without running again; while the first is still running, the repeat joins it;
* an action that raises gives status ``error`` with the exception text; the node keeps running;
* a peer silent for ``peer_timeout_s`` (default 2 s; clients ping every 0.25 s) is dropped;
* events published by drivers and actions go to every subscriber; a subscriber that cannot keep up
  loses its oldest pending events, the node never waits for it;
* a bad frame closes that one connection with ``bye``; the node goes on.

Logs (stderr): one INFO line per connection, call and result; "node NAME listening on HOST:PORT"
when ready.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import gc
import logging
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import replace
from typing import Any

from services.errors import AuthenticationError, PetrobotError, ProtocolError
from services.action import (
    CallContext,
    Driver,
    FunctionAction,
    MemoryAPI,
    NodeContext,
    PrimitiveAction,
    import_impl,
    make_action,
)
from services.results import ActionResult, Status
from services.actions.memory import MemoryStore, NoMemory, RemoteMemory, memory_actions
from services.client import NodeLink
from services.keys import load_key
from services.location import MEMORY_ACTIONS, Location, load_location
from services.protocol import (
    DEFAULT_MAX_FRAME,
    Accepted,
    Auth,
    Bye,
    Call,
    Cancel,
    Connection,
    Event,
    Feedback,
    Message,
    Ping,
    Pong,
    Rejected,
    Result,
    Role,
    State,
    Subscribe,
    Unsubscribe,
)
from services.wire import FramedConnection

__all__ = ["Node", "build_parser", "main"]

log = logging.getLogger("petrobot.node")

ActionRun = Callable[[dict[str, Any], CallContext], Awaitable[Any]]

_EVENT_BACKLOG = 256
_WRITE_HIGH_WATER = 256 * 1024


class _Running:
    """A call in flight."""

    __slots__ = ("call", "cancel_requested", "ctx", "task", "waiters")

    def __init__(self, call: Call) -> None:
        self.call = call
        self.task: asyncio.Task[None] | None = None
        self.waiters: list[_Peer] = []
        self.cancel_requested = False
        self.ctx: CallContext | None = None


class _Peer(FramedConnection):
    """One accepted connection."""

    def __init__(self, node: Node) -> None:
        super().__init__(Connection(Role.SERVER, node._key, name=node.name, max_frame=node.max_frame), node._loop)
        self.node = node
        self.peer_host = "?"
        self.local = False
        self.topics: set[str] = set()
        self.paused = False
        self.backlog: collections.deque[Event] = collections.deque(maxlen=_EVENT_BACKLOG)
        self.dropped = 0
        self.closed = False

    def __repr__(self) -> str:
        return f"{self.conn.peer or '?'}@{self.peer_host}"

    # ---- asyncio callbacks

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        assert isinstance(transport, asyncio.Transport)
        transport.set_write_buffer_limits(high=_WRITE_HIGH_WATER)
        peer = transport.get_extra_info("peername")
        here = transport.get_extra_info("sockname")
        self.peer_host = peer[0] if peer else "?"
        self.local = bool(peer and here and peer[0] == here[0])
        self.node._peers.add(self)
        self._flush()  # hello

    def data_received(self, data: bytes) -> None:
        if self.closed:
            return  # bye sent: whatever follows is ignored
        self.last_rx = self.loop.time()
        conn = self.conn
        conn.receive_data(data)
        try:
            while (msg := conn.next_message()) is not None:
                self._handle(msg)
        except ProtocolError as exc:
            if isinstance(exc, AuthenticationError):
                log.warning("refused %s: %s", self.peer_host, exc)
                self.close("auth_failed")
            else:
                log.warning("bad frame from %r: %s", self, exc)
                self.close(f"protocol_error: {exc}")
            return
        self._schedule_flush()

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed:
            self.closed = True
            log.info("connection from %r closed%s", self, f": {exc}" if exc else "")
        self.node._peers.discard(self)
        for topic in self.topics:
            self.node._subscribers[topic].discard(self)
        self.topics.clear()
        self.backlog.clear()

    def pause_writing(self) -> None:
        self.paused = True

    def resume_writing(self) -> None:
        self.paused = False
        backlog, self.backlog = self.backlog, collections.deque(maxlen=_EVENT_BACKLOG)
        for ev in backlog:
            self.send(ev)

    # ---- output

    def send(self, msg: Message) -> None:
        if self.closed:
            return
        super().send(msg)

    def send_event(self, ev: Event) -> None:
        if self.closed or self.conn.state is not State.OPEN:
            return
        if self.paused:
            if len(self.backlog) == self.backlog.maxlen:
                self.dropped += 1
            self.backlog.append(ev)
            return
        self.send(ev)

    def close(self, reason: str) -> None:
        """Send ``bye`` with ``reason`` and close this connection only."""
        if self.closed:
            return
        try:
            self.conn.send(Bye(reason=reason))
        except ProtocolError:
            pass
        self._flush()
        self.closed = True
        log.info("closing connection from %r: %s", self, reason)
        if self.transport is not None:
            self.transport.close()

    # ---- input

    def _handle(self, msg: Message) -> None:
        kind = type(msg)
        if kind is Call:
            self.node._on_call(self, msg)  # type: ignore[arg-type]
        elif kind is Cancel:
            self.node._on_cancel(msg.id)  # type: ignore[attr-defined]
        elif kind is Ping:
            self.send(Pong(seq=msg.seq))  # type: ignore[attr-defined]
        elif kind is Subscribe:
            self.topics.add(msg.topic)  # type: ignore[attr-defined]
            self.node._subscribers[msg.topic].add(self)  # type: ignore[attr-defined]
        elif kind is Unsubscribe:
            self.topics.discard(msg.topic)  # type: ignore[attr-defined]
            self.node._subscribers[msg.topic].discard(self)  # type: ignore[attr-defined]
        elif kind is Bye:
            log.info("%r said bye: %s", self, msg.reason)  # type: ignore[attr-defined]
            self.closed = True
            if self.transport is not None:
                self.transport.close()
        elif kind is Auth:
            log.info("connection from %r authenticated", self)


class Node:
    """A node process's server (see the module docstring).

    Args:
        name: node name in services.toml.
        location: the parsed services.toml.
        key: shared key.
        peer_timeout_s: drop a peer silent for this long, seconds.
        result_cache: number of recent results kept for repeated call ids.
        result_ttl_s: how long a result is kept, seconds.
        max_frame: frame size cap, bytes.

    Raises:
        LocationError: ``name`` is not a node of ``location``.
    """

    def __init__(
        self,
        name: str,
        location: Location,
        key: bytes,
        *,
        peer_timeout_s: float = 2.0,
        result_cache: int = 10_000,
        result_ttl_s: float = 600.0,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        self.name = name
        self.location = location
        location.address(name)  # raises LocationError naming the file if the node is unknown
        self.spec = location.nodes[name]
        self.host, self.port = self.spec.host, self.spec.port
        self.max_in_flight = self.spec.max_in_flight
        self.peer_timeout_s = peer_timeout_s
        self.result_cache = result_cache
        self.result_ttl_s = result_ttl_s
        self.max_frame = max_frame
        self._key = key
        self._loop: asyncio.AbstractEventLoop = None  # type: ignore[assignment]
        self._server: asyncio.Server | None = None
        self._peers: set[_Peer] = set()
        self._actions: dict[str, PrimitiveAction] = {}
        self._specs = {a.name: a for a in location.actions_on(name)}
        self._drivers: dict[str, Driver] = {}
        self._running: dict[str, _Running] = {}
        self._results: collections.OrderedDict[str, tuple[Result, float, str]] = collections.OrderedDict()
        self._subscribers: collections.defaultdict[str, set[_Peer]] = collections.defaultdict(set)
        self._seq: dict[str, int] = {}
        self._links: dict[str, NodeLink] = {}
        self._reaper: asyncio.Task[None] | None = None
        self._stopping = False
        self.context: NodeContext | None = None

    # ---- lifecycle

    async def start(self) -> None:
        """Set up drivers and actions, then listen (``port`` is updated if it was 0).

        Raises:
            ActionError: an impl cannot be imported or built.
            OSError: the address is in use.
        """
        self._loop = asyncio.get_running_loop()
        memory: MemoryAPI
        store: MemoryStore | None = None
        if self.location.memory_node == self.name:
            store = MemoryStore()
            memory = store
        elif self.location.memory_node is not None:
            memory = RemoteMemory(self.link(self.location.memory_node))
        else:
            memory = NoMemory()
        self.context = NodeContext(
            name=self.name, location=self.location, drivers=self._drivers,
            memory=memory, publish=self.publish, link=self.link,
        )
        for dspec in self.location.drivers_on(self.name):
            cls = import_impl(dspec.impl)
            if not (isinstance(cls, type) and issubclass(cls, Driver)):
                raise PetrobotError(f"driver {dspec.name}: {dspec.impl} is not a Driver subclass")
            drv = cls(dspec.name, dspec.params)
            drv.bind(self.context)
            await drv.setup(self.context)
            self._drivers[dspec.name] = drv
        for aname in self._specs:
            if aname in MEMORY_ACTIONS:
                assert store is not None
                self._actions[aname] = memory_actions(store)[aname]
            else:
                self._actions[aname] = make_action(self._specs[aname].impl, aname)
        for action in self._actions.values():
            await action.setup(self.context)
        self._server = await self._loop.create_server(lambda: _Peer(self), self.host, self.port, reuse_address=True)
        sock = self._server.sockets[0]
        self.port = sock.getsockname()[1]
        self._reaper = self._loop.create_task(self._reap_silent_peers())
        log.info("node %s hosts actions: %s; drivers: %s", self.name,
                 ", ".join(sorted(self._actions)) or "none", ", ".join(sorted(self._drivers)) or "none")

    async def stop(self) -> None:
        """Stop: refuse new connections, cancel running calls, say bye, tear down actions and drivers."""
        if self._stopping:
            return
        self._stopping = True
        if self._server is not None:
            self._server.close()
        if self._reaper is not None:
            self._reaper.cancel()
        tasks = [r.task for r in self._running.values() if r.task is not None]
        for t in tasks:
            t.cancel("node shutdown")
        if tasks:
            await asyncio.wait(tasks, timeout=2.0)
        for peer in list(self._peers):
            peer.close("shutdown")
        for link in self._links.values():
            await link.close()
        for action in self._actions.values():
            try:
                await action.teardown()
            except Exception:
                log.exception("teardown of action %s failed", action.name)
        for drv in self._drivers.values():
            try:
                await drv.teardown()
            except Exception:
                log.exception("teardown of driver %s failed", drv.name)
        if self._server is not None:
            await self._server.wait_closed()
        log.info("node %s stopped", self.name)

    # ---- node services for actions and drivers

    def publish(self, topic: str, data: Any = None) -> None:
        """Publish external event ``topic`` to every subscriber (drops the oldest for slow ones)."""
        seq = self._seq.get(topic, 0) + 1
        self._seq[topic] = seq
        subs = self._subscribers.get(topic)
        if not subs:
            return
        ev = Event(topic=topic, t=time.time(), seq=seq, data=data)
        for peer in list(subs):
            try:
                peer.send_event(ev)
            except ProtocolError as exc:
                log.warning("cannot send event %s to %r: %s", topic, peer, exc)

    def link(self, node: str) -> NodeLink:
        """Shared link from this node to ``node``."""
        link = self._links.get(node)
        if link is None:
            link = NodeLink(node, self.location.address(node), self._key, name=f"node:{self.name}")
            self._links[node] = link
        return link

    # ---- calls

    def _on_call(self, peer: _Peer, call: Call) -> None:
        cid = call.id
        action = self._actions.get(call.action)
        if action is None:
            self._reject(peer, call, "unknown_action")
            return
        spec = self._specs[call.action]
        if spec.local_only and not peer.local:
            self._reject(peer, call, "local_only")
            return
        cached = self._results.get(cid)
        if cached is not None:
            result, _, cached_action = cached
            if cached_action != call.action:
                self._reject(peer, call, "duplicate_id")
                return
            peer.send(Accepted(id=cid))
            peer.send(result)
            log.info("call %s (%s) from %r: repeated, answered with the first result", cid, call.action, peer)
            return
        running = self._running.get(cid)
        if running is not None:
            if running.call.action != call.action:
                self._reject(peer, call, "duplicate_id")
                return
            running.waiters.append(peer)
            peer.send(Accepted(id=cid))
            log.info("call %s (%s) from %r: repeated while running, joined", cid, call.action, peer)
            return
        if len(self._running) >= self.max_in_flight:
            self._reject(peer, call, "busy")
            return
        if self._stopping:
            self._reject(peer, call, "shutdown")
            return
        rec = _Running(call)
        rec.waiters.append(peer)
        self._running[cid] = rec
        run = action.fn if type(action) is FunctionAction else action.run
        rec.task = self._loop.create_task(self._run(rec, run, spec.params, peer))
        peer.send(Accepted(id=cid))

    def _reject(self, peer: _Peer, call: Call, reason: str) -> None:
        log.info("call %s (%s) from %r rejected: %s", call.id, call.action, peer, reason)
        peer.send(Rejected(id=call.id, reason=reason))

    def _on_cancel(self, cid: str) -> None:
        rec = self._running.get(cid)
        if rec is not None and rec.task is not None and not rec.task.done():
            rec.cancel_requested = True
            rec.task.cancel("cancelled")
            log.info("call %s: cancel requested", cid)

    async def _run(self, rec: _Running, run: ActionRun, defaults: Any, peer: _Peer) -> None:
        call = rec.call
        loop = self._loop
        info = log.isEnabledFor(logging.INFO)
        if info:
            log.info("call %s %s from %r", call.id, call.action, peer)
        params = {**defaults, **call.params} if defaults else call.params
        deadline = None if call.deadline_ms is None else loop.time() + call.deadline_ms / 1000.0
        assert self.context is not None
        ctx = CallContext(
            call_id=call.id, action=call.action, deadline=deadline, peer=peer.conn.peer or "?",
            node=self.context, feedback=lambda data: self._feedback(rec, data),
        )
        ctx._task = rec.task
        rec.ctx = ctx
        t0 = time.perf_counter()
        c0 = time.process_time()
        try:
            if deadline is None:
                out = await run(params, ctx)
            else:
                cm = asyncio.timeout_at(deadline)
                try:
                    async with cm:
                        out = await run(params, ctx)
                except TimeoutError:
                    if not cm.expired():
                        raise
                    out = ActionResult.error("deadline")
            record = out if isinstance(out, ActionResult) else ActionResult.success(out)
        except asyncio.CancelledError:
            record = ActionResult.error("cancelled" if rec.cancel_requested else "node shutdown")
        except Exception as exc:  # noqa: BLE001 - any action failure becomes an error result
            record = ActionResult.error(f"{exc.__class__.__name__}: {exc}")
            log.warning("call %s %s raised %s", call.id, call.action, record.reason)
        record = replace(record, wall_s=time.perf_counter() - t0, cpu_s=max(0.0, time.process_time() - c0))
        result = Result(id=call.id, result=record)
        self._finish(rec, result, info)

    def _finish(self, rec: _Running, result: Result, info: bool) -> None:
        cid = result.id
        self._running.pop(cid, None)
        now = self._loop.time()
        results = self._results
        results[cid] = (result, now, rec.call.action)
        if len(results) > self.result_cache:  # expired ones are dropped by the reaper
            results.popitem(last=False)
        for peer in rec.waiters:
            if peer.closed:
                continue
            try:
                peer.send(result)
            except ProtocolError as exc:  # value not msgpack-able, too big...
                err = Result(id=cid, result=replace(result.result, status=Status.ERROR, outcome=None, value=None,
                                                    reason=f"result not sendable: {exc}"))
                results[cid] = (err, now, rec.call.action)
                peer.send(err)
        if info:
            r = result.result
            log.info("result %s %s: %s%s (%.3f s)", cid, rec.call.action, r.status.value,
                     f" ({r.reason})" if r.reason else "", r.wall_s)

    def _feedback(self, rec: _Running, data: Any) -> None:
        msg = Feedback(id=rec.call.id, data=data)
        for peer in rec.waiters:
            if not peer.closed and peer.conn.state is State.OPEN:
                peer.send(msg)

    def _expire_results(self) -> None:
        results = self._results
        too_old = self._loop.time() - self.result_ttl_s
        while results and next(iter(results.values()))[1] < too_old:
            results.popitem(last=False)

    # ---- peers

    async def _reap_silent_peers(self) -> None:
        period = min(0.5, self.peer_timeout_s / 4)
        while True:
            before = self._loop.time()
            await asyncio.sleep(period)
            self._expire_results()
            now = self._loop.time()
            if now - before > 2 * period:
                continue  # our loop was blocked: peers' frames may be waiting unread
            cutoff = now - self.peer_timeout_s
            for peer in list(self._peers):
                if peer.last_rx < cutoff and not peer.closed:
                    log.info("dropping %r: silent for %.1f s", peer, self.peer_timeout_s)
                    peer.close("heartbeat_timeout")
                    self._peers.discard(peer)


# --------------------------------------------------------------------------- command line


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """Options of ``python -m services.node`` / ``petrobot node``."""
    p = parser or argparse.ArgumentParser(
        prog="python -m services.node", description="Run one petrobot node: host the primitive actions "
        "services.toml places on it and serve them over TCP (docs/protocol.md).")
    p.add_argument("name", help="node name, a [nodes.NAME] table of the services file")
    p.add_argument("--services", default="services.toml", metavar="FILE",
                   help="location file naming nodes, actions, drivers and events (default: services.toml)")
    p.add_argument("--key-file", default=None, metavar="FILE",
                   help="shared key file (default: $PETROBOT_KEY, else $PETROBOT_KEY_FILE, "
                        "else ~/.config/petrobot/key, created if missing)")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level of the stderr log (default: INFO: one line per connection, call, result)")
    return p


async def _serve(node: Node) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await node.start()
    # Long-lived objects made during start-up need no more collection; and a larger first-generation
    # threshold spares the per-call allocations most collector runs (fewer multi-ms pauses at p99).
    gc.freeze()
    gc.set_threshold(20_000, 50, 100)
    print(f"node {node.name} listening on {node.host}:{node.port}", file=sys.stderr, flush=True)
    try:
        await stop.wait()
    finally:
        await node.stop()


def run_node(args: argparse.Namespace) -> int:
    """Run a node from parsed arguments until SIGTERM/SIGINT; return the exit code."""
    logging.basicConfig(level=args.log_level, stream=sys.stderr, force=True,
                        format=f"%(asctime)s {args.name} %(levelname)s %(message)s")
    try:
        location = load_location(args.services)
        key = load_key(args.key_file)
        node = Node(args.name, location, key)
    except PetrobotError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        asyncio.run(_serve(node))
    except OSError as exc:
        print(f"error: node {args.name}: {exc}", file=sys.stderr)
        return 1
    except PetrobotError as exc:
        print(f"error: node {args.name}: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m services.node``."""
    return run_node(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
