"""The node's asyncio shell: the :class:`Node` server, its connections and its actions' lifecycle.

A node hosts the primitive actions services.toml places on it (docs/protocol.md, "Calls"). This
module does the I/O only; the decisions are made by the sans-IO cores beside it:

* :class:`services.node.calls.CallTable` admits or rejects each call, joins repeats and keeps
  results (bounded by bytes and by age);
* :class:`services.node.fanout.Fanout` numbers published events and fans them out, holding a
  bounded backlog for a subscriber whose writes are paused;
* :class:`services.protocol.Connection` parses and encodes the frames of each connection.

What the shell adds:

* each admitted call runs as its own task; the deadline (``deadline_ms``) cuts it off with status
  ``error`` and reason ``"deadline"``; a ``cancel`` cuts it off with reason ``"cancelled"``;
  stopping the node with ``"node shutdown"``;
* a peer is local when its IP address equals the IP address on which this node accepted the
  connection (a process on the same host connecting to that address gets it as its source address);
* an action that raises gives status ``error`` with the exception text; the node keeps running;
  a result that cannot be encoded (not msgpack-able, over the frame cap) becomes an ``error``
  result saying so;
* a peer silent for ``peer_timeout_s`` (default 2 s; clients ping every 0.25 s) is dropped; kept
  results past their age are dropped by the same periodic task;
* a bad frame closes that one connection with ``bye``; the node goes on.

Logs (stderr): one INFO line per connection, call and result.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import replace
from typing import Any

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
from services.actions.memory import MemoryStore, NoMemory, RemoteMemory, memory_actions
from services.client import NodeLink
from services.errors import AuthenticationError, PetrobotError, ProtocolError
from services.location import MEMORY_ACTIONS, Location
from services.node.calls import (
    DEFAULT_MAX_AGE_S,
    DEFAULT_MAX_BYTES,
    Answer,
    CallTable,
    MemoryResultCache,
    Reject,
    ResultCache,
    RunningCall,
    Start,
)
from services.node.fanout import (
    DEFAULT_BACKLOG,
    DEFAULT_MAX_TOPIC_BYTES,
    DEFAULT_MAX_TOPICS,
    Fanout,
)
from services.protocol import (
    DEFAULT_MAX_FRAME,
    Accepted,
    Auth,
    Bye,
    Call,
    Cancel,
    Connection,
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
    encode_frame,
)
from services.results import ActionResult, Status
from services.wire import FramedConnection

__all__ = ["Node"]

log = logging.getLogger("petrobot.node")

ActionRun = Callable[[dict[str, Any], CallContext], Awaitable[Any]]

_WRITE_HIGH_WATER = 256 * 1024


class _Peer(FramedConnection):
    """One accepted connection."""

    def __init__(self, node: Node) -> None:
        super().__init__(Connection(Role.SERVER, node._key, name=node.name, max_frame=node.max_frame), node._loop)
        self.node = node
        self.peer_host = "?"
        self.local = False
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
        self.node._fanout.remove(self)

    def pause_writing(self) -> None:
        self.node._fanout.pause(self)

    def resume_writing(self) -> None:
        for ev in self.node._fanout.resume(self):
            self.send(ev)

    # ---- output

    @property
    def open(self) -> bool:
        """Messages other than ``bye`` may be sent: not closed, handshake done."""
        return not self.closed and self.conn.state is State.OPEN

    def send(self, msg: Message) -> None:
        if self.closed:
            return
        super().send(msg)

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
        node = self.node
        if type(msg) is Call:
            node._on_call(self, msg)
        elif type(msg) is Cancel:
            node._on_cancel(msg.id)
        elif type(msg) is Ping:
            self.send(Pong(seq=msg.seq))
        elif type(msg) is Subscribe:
            refusal = node._fanout.subscribe(self, msg.topic)
            if refusal is not None:
                log.warning("subscription of %r to %.64r refused: %s", self, msg.topic, refusal.value)
        elif type(msg) is Unsubscribe:
            node._fanout.unsubscribe(self, msg.topic)
        elif type(msg) is Bye:
            log.info("%r said bye: %s", self, msg.reason)
            self.closed = True
            if self.transport is not None:
                self.transport.close()
        elif type(msg) is Auth:
            log.info("connection from %r authenticated", self)


class Node:
    """A node process's server (see the module docstring).

    Args:
        name: node name in services.toml.
        location: the parsed services.toml.
        key: shared key.
        peer_timeout_s: drop a peer silent for this long, seconds.
        result_bytes: cap on the bytes of kept results (frames plus bookkeeping), bytes.
        result_ttl_s: how long a result is kept, seconds.
        results: where results are kept; a :class:`~services.node.calls.MemoryResultCache` with
            ``result_bytes`` and ``result_ttl_s`` if ``None`` (else the two are ignored).
        event_backlog: events held for a subscriber whose writes are paused (older ones dropped).
        max_topics: topics one connection may subscribe to.
        max_topic_bytes: longest topic name a connection may subscribe to, bytes of UTF-8.
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
        result_bytes: int = DEFAULT_MAX_BYTES,
        result_ttl_s: float = DEFAULT_MAX_AGE_S,
        results: ResultCache | None = None,
        event_backlog: int = DEFAULT_BACKLOG,
        max_topics: int = DEFAULT_MAX_TOPICS,
        max_topic_bytes: int = DEFAULT_MAX_TOPIC_BYTES,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        self.name = name
        self.location = location
        location.address(name)  # raises LocationError naming the file if the node is unknown
        self.spec = location.nodes[name]
        self.host, self.port = self.spec.host, self.spec.port
        self.max_in_flight = self.spec.max_in_flight
        self.peer_timeout_s = peer_timeout_s
        self.max_frame = max_frame
        self._key = key
        self._loop: asyncio.AbstractEventLoop = None  # type: ignore[assignment]
        self._server: asyncio.Server | None = None
        self._peers: set[_Peer] = set()
        self._actions: dict[str, PrimitiveAction] = {}
        self._placements = {a.name: a for a in location.actions_on(name)}
        self._drivers: dict[str, Driver] = {}
        if results is None:
            results = MemoryResultCache(max_bytes=result_bytes, max_age_s=result_ttl_s)
        self._calls: CallTable[_Peer] = CallTable(
            self._placements, local_only=[a for a, p in self._placements.items() if p.local_only],
            max_in_flight=self.max_in_flight, cache=results,
        )
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._fanout: Fanout[_Peer] = Fanout(backlog=event_backlog, max_topics=max_topics,
                                             max_topic_bytes=max_topic_bytes)
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
        for aname in self._placements:
            if aname in MEMORY_ACTIONS:
                assert store is not None
                self._actions[aname] = memory_actions(store)[aname]
            else:
                self._actions[aname] = make_action(self._placements[aname].impl, aname)
        for action in self._actions.values():
            await action.setup(self.context)
        self._server = await self._loop.create_server(lambda: _Peer(self), self.host, self.port, reuse_address=True)
        sock = self._server.sockets[0]
        self.port = sock.getsockname()[1]
        self._reaper = self._loop.create_task(self._reap())
        log.info("node %s hosts actions: %s; drivers: %s", self.name,
                 ", ".join(sorted(self._actions)) or "none", ", ".join(sorted(self._drivers)) or "none")

    async def stop(self) -> None:
        """Stop: refuse new connections, cancel running calls, say bye, tear down actions and drivers."""
        if self._stopping:
            return
        self._stopping = True
        self._calls.stop()
        if self._server is not None:
            self._server.close()
        if self._reaper is not None:
            self._reaper.cancel()
        tasks = list(self._tasks.values())
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
        """Publish external event ``topic`` to every subscriber (never waits for a slow one)."""
        delivery = self._fanout.publish(topic, data, time.time())
        if delivery is None:
            return
        ev, ready = delivery
        for peer in ready:
            if not peer.open:
                continue
            try:
                peer.send(ev)
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
        verdict = self._calls.admit(call, peer, local=peer.local)
        if type(verdict) is Start:
            action = self._actions[call.action]
            run = action.fn if type(action) is FunctionAction else action.run
            defaults = self._placements[call.action].params
            self._tasks[cid] = self._loop.create_task(self._run(verdict.running, run, defaults, peer))
            peer.send(Accepted(id=cid))
        elif type(verdict) is Reject:
            reason = verdict.reason.value
            log.info("call %s (%s) from %r rejected: %s", cid, call.action, peer, reason)
            peer.send(Rejected(id=cid, reason=reason))
        elif type(verdict) is Answer:
            peer.send(Accepted(id=cid))
            peer.send(verdict.kept.result)
            log.info("call %s (%s) from %r: repeated, answered with the first result", cid, call.action, peer)
        else:  # Join: the peer now waits for the running call's result too
            peer.send(Accepted(id=cid))
            log.info("call %s (%s) from %r: repeated while running, joined", cid, call.action, peer)

    def _on_cancel(self, cid: str) -> None:
        task = self._tasks.get(cid)
        if task is not None and not task.done():
            self._calls.cancel(cid)
            task.cancel("cancelled")
            log.info("call %s: cancel requested", cid)

    async def _run(self, rec: RunningCall[_Peer], run: ActionRun, defaults: Any, peer: _Peer) -> None:
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
        ctx._task = self._tasks.get(call.id)
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
        self._finish(rec, Result(id=call.id, result=record), info)

    def _finish(self, rec: RunningCall[_Peer], result: Result, info: bool) -> None:
        """Send ``result`` to every waiter still connected, then keep it, charged its frame length."""
        cid = result.id
        self._tasks.pop(cid, None)
        size = 0
        for peer in rec.waiters:
            if not peer.open:
                continue
            try:
                n = peer.send_counted(result)
            except ProtocolError as exc:  # value not msgpack-able, too big...
                result = _unsendable(result, exc)
                n = peer.send_counted(result)
            size = size or n
        if not size:  # nobody left to tell: measure it for the cache all the same
            try:
                size = len(encode_frame(result, self.max_frame))
            except ProtocolError as exc:
                result = _unsendable(result, exc)
                size = len(encode_frame(result, self.max_frame))
        self._calls.finish(result, size=size, now=self._loop.time())
        if info:
            r = result.result
            log.info("result %s %s: %s%s (%.3f s)", cid, rec.call.action, r.status.value,
                     f" ({r.reason})" if r.reason else "", r.wall_s)

    def _feedback(self, rec: RunningCall[_Peer], data: Any) -> None:
        msg = Feedback(id=rec.call.id, data=data)
        for peer in rec.waiters:
            if peer.open:
                peer.send(msg)

    # ---- peers and kept results

    async def _reap(self) -> None:
        """Every ``peer_timeout_s / 4`` (at most 0.5 s): expire kept results, drop silent peers."""
        period = min(0.5, self.peer_timeout_s / 4)
        while True:
            before = self._loop.time()
            await asyncio.sleep(period)
            now = self._loop.time()
            self._calls.expire(now)
            if now - before > 2 * period:
                continue  # our loop was blocked: peers' frames may be waiting unread
            cutoff = now - self.peer_timeout_s
            for peer in list(self._peers):
                if peer.last_rx < cutoff and not peer.closed:
                    log.info("dropping %r: silent for %.1f s", peer, self.peer_timeout_s)
                    peer.close("heartbeat_timeout")
                    self._peers.discard(peer)


def _unsendable(result: Result, exc: Exception) -> Result:
    """The error result that replaces ``result`` when it cannot be encoded."""
    return Result(id=result.id, result=replace(result.result, status=Status.ERROR, outcome=None, value=None,
                                               reason=f"result not sendable: {exc}"))
