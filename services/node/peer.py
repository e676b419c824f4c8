"""One accepted connection of a node: :class:`Peer`, the asyncio protocol that feeds its messages to the node.

A peer is *pending* from accept until its handshake succeeds, then *open*. Before that it gets
nothing but the handshake (the sans-IO :class:`~services.protocol.Connection` enforces it, with a
4 KiB frame cap), and its connection counts against the pending caps of
:class:`~services.node.guard.ConnectionGuard`, which may close it to make room or at its handshake
deadline (:meth:`Peer.evict`).

Back-pressure: a peer that does not read what it is sent cannot make the node hold more than about
``max_output`` bytes for it (plus one frame). Once that much waits to go out, the node stops
reading from the peer (messages already received wait too) until the backlog has drained; events
for it go to the fan-out's bounded backlog and feedback for it is dropped (counted), while results
are always sent.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from services.errors import AuthenticationError, ProtocolError
from services.protocol import (
    Auth,
    Bye,
    Call,
    Cancel,
    Connection,
    Message,
    Ping,
    Pong,
    Query,
    Role,
    State,
    Subscribe,
    Unsubscribe,
    shown,
)
from services.wire import FramedConnection

if TYPE_CHECKING:
    from services.node.server import Node

__all__ = ["Peer"]

log = logging.getLogger("petrobot.node")

_WRITE_HIGH_WATER = 256 * 1024
_ABORT_AFTER_S = 1.0  # a closed connection whose output the peer does not read is cut after this


class Peer(FramedConnection):
    """One accepted connection (see the module docstring).

    Args:
        node: the node.
        host: the peer's IP address.
        accepted_at: loop time of the accept, seconds.

    Attributes:
        local: whether the peer is on this host (decided at authentication).
        authenticated: the handshake succeeded.
        closed: ``bye`` was sent or received, or the connection is gone.
        dropped_feedback: feedback messages not sent because the peer was not reading.
        forgotten: the node has let go of this connection (its caps, subscriptions and calls).
        connecting: the task setting up the transport (TLS handshake), until it is done.
    """

    def __init__(self, node: Node, host: str, accepted_at: float) -> None:
        conn = Connection(Role.SERVER, node._key, name=node.name, max_frame=node.max_frame,
                          previous_keys=node._previous_keys, offer=node._offer)
        super().__init__(conn, node._loop, tls_binding=node.tls_binding)
        self.node = node
        self.peer_host = host
        self.accepted_at = accepted_at
        self.local = False
        self.authenticated = False
        self.closed = False
        self.dropped_feedback = 0
        self.connecting: asyncio.Task[object] | None = None
        self._writing_paused = False
        self._reading_blocked = False
        self.forgotten = False

    def __repr__(self) -> str:
        return f"{shown(self.conn.peer, 40) if self.conn.peer is not None else '?'}@{self.peer_host}"

    # ---- asyncio callbacks

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        try:
            super().connection_made(transport)
        except ProtocolError as exc:
            log.warning("connection from %s refused: %s", self.peer_host, exc)
            transport.abort()
            return
        transport.set_write_buffer_limits(high=_WRITE_HIGH_WATER)
        if self.closed:  # evicted while its TLS handshake ran
            transport.abort()
            return
        self.node._peers.add(self)
        log.debug("connection from %s", self.peer_host)
        self._flush()  # hello

    def data_received(self, data: bytes) -> None:
        if self.closed:
            return  # bye sent: whatever follows is ignored
        self.last_rx = self.loop.time()
        self.conn.receive_data(data)
        self._process()

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed:
            self.closed = True
            if self.authenticated:
                log.info("connection from %r closed%s", self, f": {shown(str(exc))}" if exc else "")
        self.node._gone(self)

    def pause_writing(self) -> None:
        self._writing_paused = True
        self.node._fanout.pause(self)

    def resume_writing(self) -> None:
        self._writing_paused = False
        for ev in self.node._fanout.resume(self):
            self.send(ev)
        self._unblock()

    # ---- input

    def _process(self) -> None:
        conn = self.conn
        limit = self.node.max_output
        try:
            while not self.closed:
                if self.authenticated and self.output_backlog > limit:
                    self._block()
                    break
                msg = conn.next_message()
                if msg is None:
                    break
                self._handle(msg)
        except ProtocolError as exc:
            if isinstance(exc, AuthenticationError):
                self.node._login_failed(self, exc)
                self.close("auth_failed")
            else:
                self.node._limited.log(logging.WARNING, ("bad frame", self.peer_host),
                                       "bad frame from %r: %s", self, shown(str(exc), 200))
                self.close(f"protocol_error: {shown(str(exc), 200)}")
            return
        finally:
            if self.node._durable:
                self.node.commit()  # the calls started by this read are on disk before they run
        self._schedule_flush()

    def _block(self) -> None:
        """Stop reading: too much output waits for this peer."""
        if not self._reading_blocked and self.transport is not None:
            self._reading_blocked = True
            self.transport.pause_reading()

    def _unblock(self) -> None:
        if self._reading_blocked and not self._writing_paused and not self.closed \
                and self.output_backlog <= self.node.max_output and self.transport is not None:
            self._reading_blocked = False
            self.transport.resume_reading()
            self.loop.call_soon(self._process)  # messages received before we stopped

    def flushed(self) -> None:
        if self._reading_blocked:
            self._unblock()

    @property
    def reading(self) -> bool:
        """The peer reads what it is sent (its writes are not paused, nothing is held back)."""
        return not self._writing_paused and not self._reading_blocked

    def _handle(self, msg: Message) -> None:
        node = self.node
        kind = type(msg)
        if kind is Call:
            node._on_call(self, msg)  # type: ignore[arg-type]
        elif kind is Ping:
            self.send(Pong(seq=msg.seq))  # type: ignore[attr-defined]
        elif kind is Query:
            node._on_query(self, msg)  # type: ignore[arg-type]
        elif kind is Cancel:
            node._on_cancel(msg.id)  # type: ignore[attr-defined]
        elif kind is Subscribe:
            topic = msg.topic  # type: ignore[attr-defined]
            refusal = node._fanout.subscribe(self, topic)
            if refusal is not None:
                node._limited.log(logging.WARNING, ("subscription refused", self.peer_host),
                                  "subscription of %r to %s refused: %s", self, shown(topic, 64), refusal.value)
        elif kind is Unsubscribe:
            node._fanout.unsubscribe(self, msg.topic)  # type: ignore[attr-defined]
        elif kind is Bye:
            reason = shown(msg.reason, 120)  # type: ignore[attr-defined]
            if self.authenticated:
                log.info("%r said bye: %s", self, reason)
            else:
                node._limited.log(logging.INFO, ("bye before login", self.peer_host),
                                  "unauthenticated %s said bye: %s", self.peer_host, reason)
            self._close_transport()
        elif kind is Auth:
            node._authenticated(self)

    # ---- output and closing

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
        if self.authenticated:
            log.info("closing connection from %r: %s", self, reason)
        self._close_transport()

    def evict(self, reason: str) -> None:
        """Close a pending connection now (over a cap, or past its handshake deadline)."""
        if self.transport is None:  # its TLS handshake is still running
            self.closed = True
            if self.connecting is not None:
                self.connecting.cancel()
            self.node._gone(self)
            return
        self.close(reason)

    def _close_transport(self) -> None:
        self.closed = True
        t = self.transport
        if t is not None:
            if not self.authenticated:
                t.abort()  # the bye went out with the write; nothing else is owed
            else:
                t.close()  # let the results and the bye go out, but not forever
                if t.get_write_buffer_size():
                    self.loop.call_later(_ABORT_AFTER_S, t.abort)
        self.node._gone(self)
