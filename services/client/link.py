"""One authenticated, self-healing connection to one node: :class:`NodeLink`.

A thin asyncio shell around :class:`services.protocol.Connection` (docs/protocol.md), over TCP or
TLS (:mod:`services.wire`).

Failure model: :meth:`NodeLink.call` never raises for node trouble. A node that cannot be reached,
dies during a call, rejects the call or stops answering heartbeats turns the call into a
:class:`~services.results.ActionResult` with status ``error`` and a ``reason``. A silent node is declared dead after
three heartbeat periods without any frame (0.75 s with the default 0.25 s), so every running call on
it ends within about 1 s. The next call reconnects, retrying with exponential backoff
(50 ms doubling to 0.5 s) for at most ``connect_timeout_s``.

A call given up on that way may still be running on the node: the node cancels it (reason
``"caller_gone"``) once nobody has asked for it during its heartbeat window, unless its action is
unattended. :meth:`NodeLink.query` asks the node what became of it, without running anything.

Each TCP connection of a link (its wire) hands what it receives to the link through
:class:`WireHost`, given at construction: a call accepted, ended (with its result, or rejected),
its feedback, an event, a pong, the welcome, the connection lost. :class:`NodeLink` is that host.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import ssl
import uuid
from collections.abc import Callable
from typing import Any, Protocol

from services.errors import AuthenticationError, ProtocolError, RemoteProtocolError
from services.location import TlsSettings
from services.protocol import (
    DEFAULT_MAX_FRAME,
    Accepted,
    Bye,
    Call,
    Cancel,
    Connection,
    Event,
    Feedback,
    Message,
    Ping,
    Pong,
    Query,
    Rejected,
    Result,
    Role,
    State,
    Subscribe,
    Unsubscribe,
    Welcome,
    shown,
)
from services.results import ActionResult
from services.wire import FramedConnection, client_context

__all__ = ["UNKNOWN_CALL", "EventCallback", "FeedbackCallback", "NodeBusy", "NodeLink", "WireHost", "describe"]

log = logging.getLogger("petrobot.client")

EventCallback = Callable[[Event], None]
"""Called with each :class:`Event` of a subscribed topic; must not block."""
FeedbackCallback = Callable[[Any], None]
"""Called with the ``data`` of each feedback message of a call; must not block."""

_DEADLINE_GRACE_S = 1.0
_BUSY_REASONS = ("overloaded", "auth_throttled", "handshake_timeout")


class NodeBusy(ConnectionError):
    """The node closed our connection before the handshake ended because it is at a limit
    (``bye`` ``overloaded``, ``auth_throttled`` or ``handshake_timeout``, docs/protocol.md §6): it
    is running, and a later try may get in."""
UNKNOWN_CALL = "unknown_call"
"""The node's answer to a query for an id it never saw or no longer keeps."""


class _Pending:
    __slots__ = ("accepted", "action", "future", "on_feedback")

    def __init__(self, future: asyncio.Future[ActionResult], action: str, on_feedback: FeedbackCallback | None) -> None:
        self.future = future
        self.action = action
        self.on_feedback = on_feedback
        self.accepted = False


class WireHost(Protocol):
    """What one connection of a link needs of the link (every method is called on the loop).

    Attributes:
        node: the node's name (for log lines).
    """

    node: str

    def call_accepted(self, call_id: str) -> None:
        """The node accepted call ``call_id``."""

    def call_ended(self, call_id: str, result: ActionResult) -> None:
        """Call ``call_id`` ended with ``result`` (a rejection is an error result with its reason)."""

    def call_feedback(self, call_id: str, data: Any) -> None:
        """Feedback ``data`` of running call ``call_id``."""

    def event_received(self, event: Event) -> None:
        """An event of a subscribed topic."""

    def pong_received(self, seq: int, now: float) -> None:
        """The answer to ping ``seq``, at loop time ``now``."""

    def welcomed(self, welcome: Welcome) -> None:
        """The handshake succeeded: what the node offers."""

    def wire_lost(self, wire: _Wire, exc: Exception) -> None:
        """Connection ``wire`` is gone (``exc`` says why): its calls fail."""


class _Wire(FramedConnection):
    """One TCP connection of a NodeLink.

    Args:
        host: the link.
        conn: the sans-IO client connection.
        loop: the running loop.
        tls_binding: the connection runs over TLS in ``psk`` mode.
    """

    def __init__(self, host: WireHost, conn: Connection, loop: asyncio.AbstractEventLoop, *,
                 tls_binding: bool = False) -> None:
        super().__init__(conn, loop, tls_binding=tls_binding)
        self.host = host
        self.opened: asyncio.Future[None] = self.loop.create_future()
        self.closed = False

    # ---- asyncio callbacks

    def data_received(self, data: bytes) -> None:
        self.last_rx = self.loop.time()
        conn = self.conn
        conn.receive_data(data)
        try:
            while (msg := conn.next_message()) is not None:
                self._handle(msg)
        except ProtocolError as exc:
            reason = "auth_failed" if isinstance(exc, AuthenticationError) else f"protocol_error: {shown(str(exc), 200)}"
            log.warning("node %s: %s", self.host.node, shown(str(exc), 200))
            self.abort(exc, reason)
            return
        self._flush()

    def connection_lost(self, exc: Exception | None) -> None:
        self._dead(ConnectionError(f"connection lost{': ' + str(exc) if exc else ''}"))

    # ---- input

    def _handle(self, msg: Message) -> None:
        host = self.host
        if isinstance(msg, Result):
            host.call_ended(msg.id, msg.result)
        elif isinstance(msg, Accepted):
            host.call_accepted(msg.id)
        elif isinstance(msg, Feedback):
            host.call_feedback(msg.id, msg.data)
        elif isinstance(msg, Rejected):
            host.call_ended(msg.id, ActionResult.error(msg.reason))
        elif isinstance(msg, Event):
            host.event_received(msg)
        elif isinstance(msg, Ping):
            self.send(Pong(seq=msg.seq))
        elif isinstance(msg, Pong):
            host.pong_received(msg.seq, self.loop.time())
        elif isinstance(msg, Welcome):
            host.welcomed(msg)
            if not self.opened.done():
                self.opened.set_result(None)
        elif isinstance(msg, Bye):
            if msg.reason.startswith("auth_failed") and not self.opened.done():
                exc: Exception = AuthenticationError(f"node {host.node} refused our key (auth_failed)")
            elif msg.reason.startswith(_BUSY_REASONS) and not self.opened.done():
                exc = NodeBusy(f"node said bye: {shown(msg.reason, 200)}")
            else:
                exc = ConnectionError(f"node said bye: {shown(msg.reason, 200)}")
            self.abort(exc, None)
        # Hello: the connection answered with auth by itself

    # ---- teardown

    def abort(self, exc: Exception, reason: str | None) -> None:
        """Close this connection (sending ``bye`` with ``reason`` if given) and fail its calls."""
        if reason is not None and self.transport is not None and not self.transport.is_closing():
            try:
                self.conn.send(Bye(reason=reason))
                self._flush()
            except ProtocolError:
                pass
        if self.transport is not None:
            self.transport.close()
        self._dead(exc)

    def _dead(self, exc: Exception) -> None:
        if self.closed:
            return
        self.closed = True
        if not self.opened.done():
            self.opened.set_exception(exc)
            self.opened.exception()  # mark retrieved
        self.host.wire_lost(self, exc)


class NodeLink(WireHost):
    """An authenticated, self-healing connection to one node; the host of its wires
    (:class:`WireHost`).

    Used by :class:`ServiceClient` (one per node) and by nodes that reach other nodes (global
    memory, set-point streaming).

    Args:
        node: the node's name (for results and logs).
        address: ``(host, port)``.
        key: the shared key.
        name: this client's name, sent in ``auth``.
        heartbeat_s: ping period; the node is dead after 3 periods of silence.
        connect_timeout_s: budget for (re)connecting at the start of a call.
        local_addr: optional ``(host, port)`` to bind the client socket to (tests of local-only).
        max_frame: frame size cap, bytes.
        tls: TLS settings of the connection to this node (default: plain TCP).

    Attributes:
        offered_actions: the actions the node said it offers (sorted), once connected; ``None``
            before, or if the node does not say.
        location_digest: hex SHA-256 of the services.toml the node loaded, once connected.
        location_changed: the node's services.toml changed on disk since it loaded it.
    """

    def __init__(
        self,
        node: str,
        address: tuple[str, int],
        key: bytes,
        *,
        name: str = "coordinator",
        heartbeat_s: float = 0.25,
        connect_timeout_s: float = 1.0,
        local_addr: tuple[str, int] | None = None,
        max_frame: int = DEFAULT_MAX_FRAME,
        tls: TlsSettings | None = None,
    ) -> None:
        self.node = node
        self.address = address
        self.tls = tls if tls is not None else TlsSettings()
        self._ssl = client_context(self.tls)
        self.offered_actions: tuple[str, ...] | None = None
        self.location_digest: str | None = None
        self.location_changed = False
        self.name = name
        self.heartbeat_s = heartbeat_s
        self.connect_timeout_s = connect_timeout_s
        self.local_addr = local_addr
        self.max_frame = max_frame
        self._key = key
        self._wire: _Wire | None = None
        self._connecting: asyncio.Task[_Wire] | None = None
        self._pending: dict[str, _Pending] = {}
        self._topics: dict[str, list[EventCallback]] = {}
        self._heartbeat: asyncio.Task[None] | None = None
        self._keeper: asyncio.Task[None] | None = None
        self._closed = False
        self._ids = itertools.count(1)
        self._id_prefix = uuid.uuid4().hex[:16]
        self._ping_seq = itertools.count(1)
        self._ping_sent: tuple[int, float] | None = None  # the last ping: (seq, loop time)
        self._rtt_s: float | None = None

    # ---- public API

    @property
    def connected(self) -> bool:
        """True while an authenticated connection is open."""
        w = self._wire
        return w is not None and not w.closed and w.conn.state is State.OPEN

    def health(self) -> dict[str, Any]:
        """What an operator's view shows of this link (read-only; no I/O).

        Returns:
            ``{"connected": bool, "heartbeat_rtt_s": float | None, "in_flight": int}``: whether an
            authenticated connection is open, the round trip of the last answered heartbeat
            (seconds; ``None`` before one was answered) and the calls sent and not yet answered.
        """
        return {"connected": self.connected, "heartbeat_rtt_s": self._rtt_s, "in_flight": len(self._pending)}

    def new_call_id(self) -> str:
        """A fresh call id, unique across clients (random prefix + counter)."""
        return f"{self._id_prefix}-{next(self._ids)}"

    async def call(
        self,
        action: str,
        params: dict[str, Any] | None = None,
        *,
        call_id: str | None = None,
        deadline_s: float | None = None,
        on_feedback: FeedbackCallback | None = None,
    ) -> ActionResult:
        """Call ``action`` on this node and wait for its result.

        Args:
            action: action name.
            params: parameters (msgpack map), merged over the action's defaults on the node.
            call_id: client-made id; reuse an id to get the first result again without re-running.
            deadline_s: deadline in seconds from now, enforced by the node (``reason="deadline"``);
                the client gives up 1 s after it if the node says nothing.
            on_feedback: called with each feedback ``data``.

        Returns:
            The result; ``status="error"`` with a ``reason`` for every kind of node trouble.

        Raises:
            asyncio.CancelledError: the awaiting task was cancelled (a cancel is sent to the node).
        """
        cid = call_id if call_id is not None else self.new_call_id()
        wire = self._wire
        if wire is None or wire.closed or wire.conn.state is not State.OPEN:
            try:
                wire = await self._open_wire()
            except _Unreachable as exc:
                return exc.result
        if cid in self._pending:
            return ActionResult.error(f"call id {cid} is already waiting on this link")
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[ActionResult] = loop.create_future()
        self._pending[cid] = _Pending(fut, action, on_feedback)
        deadline_ms = None if deadline_s is None else max(0, int(deadline_s * 1000))
        try:
            wire.send(Call(id=cid, action=action, params=params or {}, deadline_ms=deadline_ms))
        except ProtocolError as exc:
            self._pending.pop(cid, None)
            return ActionResult.error(f"cannot send call: {exc}")
        try:
            if deadline_s is None:
                return await fut
            try:
                async with asyncio.timeout(deadline_s + _DEADLINE_GRACE_S):
                    return await fut
            except TimeoutError:
                self._pending.pop(cid, None)
                self._send_cancel(cid)
                return ActionResult.error("deadline (no answer from node)")
        except asyncio.CancelledError:
            if self._pending.pop(cid, None) is not None:
                self._send_cancel(cid)
            raise

    async def query(self, call_id: str, *, cancel: bool = False) -> ActionResult | None:
        """Ask the node what became of call ``call_id``; nothing is ever started (docs/protocol.md §5).

        Args:
            call_id: the id of a call made earlier, on this link or elsewhere.
            cancel: first ask the node to cancel the call if it still runs (for a call the caller
                gave up on: its result then says ``"cancelled"`` unless it had already ended).

        Returns:
            The call's result (waiting for it if the call still runs); ``None`` if the node never
            saw the id or no longer keeps its result; an ``error`` result for node trouble, as
            :meth:`call` gives.
        """
        try:
            wire = await self._open_wire()
        except _Unreachable as exc:
            return exc.result
        if self.offered_actions is None:  # a node that does not list its actions predates query
            return ActionResult.error(f"node {self.node} does not answer queries (an older node: restart it "
                                      "with this version)")
        if call_id in self._pending:
            return ActionResult.error(f"call id {call_id} is already waiting on this link")
        fut: asyncio.Future[ActionResult] = asyncio.get_running_loop().create_future()
        self._pending[call_id] = _Pending(fut, "", None)
        try:
            if cancel:
                wire.send(Cancel(id=call_id))
            wire.send(Query(id=call_id))
        except ProtocolError as exc:
            self._pending.pop(call_id, None)
            return ActionResult.error(f"cannot send query: {exc}")
        try:
            result = await fut
        except asyncio.CancelledError:
            self._pending.pop(call_id, None)
            raise
        if result.status == "error" and result.reason == UNKNOWN_CALL:
            return None
        return result

    async def cancel(self, call_id: str) -> bool:
        """Ask the node to cancel ``call_id``; its result then comes back with reason ``"cancelled"``.

        Returns:
            True if the call was waiting on this link and a cancel was sent.
        """
        if call_id not in self._pending:
            return False
        return self._send_cancel(call_id)

    def subscribe(self, topic: str, callback: EventCallback) -> None:
        """Receive every event of ``topic`` published by this node (resubscribes after reconnect)."""
        topic = topic.removeprefix("ext:")
        cbs = self._topics.setdefault(topic, [])
        cbs.append(callback)
        if len(cbs) == 1 and self.connected:
            assert self._wire is not None
            self._wire.send(Subscribe(topic=topic))
        if self._keeper is None or self._keeper.done():
            self._keeper = asyncio.get_running_loop().create_task(self._keep_connected())

    def unsubscribe(self, topic: str, callback: EventCallback | None = None) -> None:
        """Stop delivering ``topic`` to ``callback`` (or to every callback)."""
        topic = topic.removeprefix("ext:")
        cbs = self._topics.get(topic)
        if not cbs:
            return
        if callback is None:
            cbs.clear()
        elif callback in cbs:
            cbs.remove(callback)
        if not cbs:
            del self._topics[topic]
            if self.connected:
                assert self._wire is not None
                self._wire.send(Unsubscribe(topic=topic))

    async def connect(self) -> None:
        """Connect now (normally done by the first call).

        Raises:
            OSError: the node cannot be reached within ``connect_timeout_s``.
            AuthenticationError: the node does not hold our key.
        """
        await self._ensure_connected()

    async def close(self) -> None:
        """Say bye, close the connection and fail the calls still waiting (reason ``"client closed"``)."""
        self._closed = True
        for task in (self._keeper, self._heartbeat, self._connecting):
            if task is not None and not task.done():
                task.cancel()
        for task in (self._keeper, self._heartbeat, self._connecting):
            if task is not None:
                # their outcome no longer matters: we are closing
                with contextlib.suppress(asyncio.CancelledError, OSError, ProtocolError, TimeoutError):
                    await task
        if self._wire is not None:
            self._wire.abort(ConnectionError("client closed"), "client closed")
        self._fail_all("client closed")

    # ---- internals

    async def _open_wire(self) -> _Wire:
        wire = self._wire
        if wire is not None and not wire.closed and wire.conn.state is State.OPEN:
            return wire
        try:
            return await self._ensure_connected()
        except AuthenticationError as exc:
            raise _Unreachable(ActionResult.error(f"authentication failed: {exc}")) from None
        except (TimeoutError, OSError, ProtocolError) as exc:
            raise _Unreachable(ActionResult.error(f"node {self.node} unreachable: {describe(exc)}")) from None

    # ---- what its wires hand over (WireHost)

    def call_accepted(self, call_id: str) -> None:
        """The node accepted call ``call_id``."""
        p = self._pending.get(call_id)
        if p is not None:
            p.accepted = True

    def call_ended(self, call_id: str, result: ActionResult) -> None:
        """Call ``call_id`` ended: its waiter gets ``result``."""
        p = self._pending.pop(call_id, None)
        if p is not None and not p.future.done():
            p.future.set_result(result)

    def call_feedback(self, call_id: str, data: Any) -> None:
        """Pass feedback ``data`` to the callback of call ``call_id`` (its failure is logged)."""
        p = self._pending.get(call_id)
        if p is not None and p.on_feedback is not None:
            try:
                p.on_feedback(data)
            except Exception:
                log.exception("feedback callback of call %s failed", shown(call_id))

    def event_received(self, event: Event) -> None:
        """Pass ``event`` to the callbacks of its topic (a failing one is logged)."""
        for cb in list(self._topics.get(event.topic, ())):
            try:
                cb(event)
            except Exception:
                log.exception("event callback for %s failed", shown(event.topic))

    def pong_received(self, seq: int, now: float) -> None:
        """The answer to the last ping gives the round trip (:meth:`health`)."""
        sent = self._ping_sent
        if sent is not None and sent[0] == seq:
            self._rtt_s = now - sent[1]
            self._ping_sent = None

    def welcomed(self, welcome: Welcome) -> None:
        """Keep what the node says it offers."""
        self.offered_actions = tuple(welcome.actions) if welcome.actions is not None else None
        self.location_digest = welcome.location
        self.location_changed = welcome.location_changed

    def wire_lost(self, wire: _Wire, exc: Exception) -> None:
        """Connection ``wire`` is gone: the calls waiting on it end in error with the reason."""
        if wire is not self._wire:
            return
        self._wire = None
        if not self._closed:
            log.warning("lost node %s: %s", self.node, exc)
        self._fail_all(str(exc) or exc.__class__.__name__)

    def _send_cancel(self, cid: str) -> bool:
        w = self._wire
        if w is None or w.closed or w.conn.state is not State.OPEN:
            return False
        try:
            w.send(Cancel(id=cid))
        except ProtocolError:
            return False
        return True

    async def _ensure_connected(self) -> _Wire:
        if self._closed:
            raise ConnectionError("link closed")
        w = self._wire
        if w is not None and not w.closed and w.conn.state is State.OPEN:
            return w
        if self._connecting is None or self._connecting.done():
            self._connecting = asyncio.get_running_loop().create_task(self._connect_with_backoff())
        return await asyncio.shield(self._connecting)

    async def _connect_with_backoff(self) -> _Wire:
        loop = asyncio.get_running_loop()
        give_up = loop.time() + self.connect_timeout_s
        delay = 0.05
        while True:
            try:
                return await self._connect_once(max(0.05, give_up - loop.time()))
            except AuthenticationError:
                raise
            except (TimeoutError, OSError, RemoteProtocolError):
                if loop.time() + delay >= give_up:
                    raise
            await asyncio.sleep(delay)
            delay = min(delay * 2, 0.5)

    async def _connect_once(self, timeout: float) -> _Wire:
        loop = asyncio.get_running_loop()
        host, port = self.address
        tls_name = (self.tls.server_name or host) if self.tls.mode == "certificate" else None
        async with asyncio.timeout(timeout):
            _, wire = await loop.create_connection(self._new_wire, host, port, local_addr=self.local_addr,
                                                   ssl=self._ssl, server_hostname=tls_name)
            try:
                await wire.opened
            except BaseException:
                if wire.transport is not None:
                    wire.transport.abort()
                raise
        self._wire = wire
        log.info("connected to node %s at %s:%d", self.node, host, port)
        for topic in self._topics:
            wire.send(Subscribe(topic=topic))
        if self._heartbeat is None or self._heartbeat.done():
            self._heartbeat = loop.create_task(self._heartbeat_loop())
        return wire

    def _new_wire(self) -> _Wire:
        conn = Connection(Role.CLIENT, self._key, name=self.name, node=self.node, max_frame=self.max_frame)
        return _Wire(self, conn, asyncio.get_running_loop(), tls_binding=self.tls.mode == "psk")

    async def _heartbeat_loop(self) -> None:
        loop = asyncio.get_running_loop()
        period = self.heartbeat_s
        while True:
            before = loop.time()
            await asyncio.sleep(period)
            now = loop.time()
            w = self._wire
            if w is None or w.closed:
                continue
            if now - before > 2 * period:
                # our own loop was blocked: frames may be waiting unread, so judge next time
                continue
            if now - w.last_rx > 3 * period:
                log.warning("node %s missed 3 heartbeats: declaring it dead", self.node)
                w.abort(ConnectionError("heartbeat timeout"), "heartbeat_timeout")
                continue
            if w.conn.state is State.OPEN:
                seq = next(self._ping_seq)
                try:
                    w.send(Ping(seq=seq))
                    self._ping_sent = (seq, loop.time())
                except ProtocolError:
                    pass

    async def _keep_connected(self) -> None:
        """Keep a connection up while topics are subscribed: reconnect with backoff (50 ms doubling
        to 2 s) after a lost connection and after a failed authentication alike (a stranger on the
        port of a restarting node, a key being rotated: the real node may answer the next try); each
        streak of failures is logged once, as a warning, until a connection opens."""
        delay = 0.05
        failing = ""
        while self._topics and not self._closed:
            if self.connected:
                delay = 0.05
                failing = ""
                await asyncio.sleep(self.heartbeat_s)
                continue
            try:
                await self._ensure_connected()
            except (AuthenticationError, TimeoutError, OSError, ProtocolError) as exc:
                kind = "authentication" if isinstance(exc, AuthenticationError) else "connection"
                if kind != failing:
                    failing = kind
                    log.warning("cannot subscribe on node %s: %s; retrying with backoff up to 2 s", self.node,
                                describe(exc))
                await asyncio.sleep(delay)
                delay = min(delay * 2, 2.0)

    def _fail_all(self, reason: str) -> None:
        pending, self._pending = self._pending, {}
        for p in pending.values():
            if not p.future.done():
                p.future.set_result(ActionResult.error(reason))


class _Unreachable(Exception):
    """The link could not be opened; ``result`` says why, as an error result."""

    def __init__(self, result: ActionResult) -> None:
        super().__init__(result.reason)
        self.result = result


def describe(exc: BaseException) -> str:
    """A connection error in words: ``timed out``, the OS's text for its errno, or its message."""
    if isinstance(exc, asyncio.TimeoutError):
        return "timed out"
    if isinstance(exc, OSError) and exc.errno and not isinstance(exc, ssl.SSLError):
        return f"{os.strerror(exc.errno)} (errno {exc.errno})"
    return str(exc) or exc.__class__.__name__
