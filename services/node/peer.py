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

A peer reaches its node only through :class:`PeerHost`, given at construction: the sans-IO
connection turns bytes into messages, the peer hands each message to its host (a call to admit, a
query to answer, a cancel, a subscription), reports authentication and departure, and asks the host
how much output it may hold. The node (:class:`services.node.server.Node`) is that host; this
module never imports it, as websockets' asyncio shell never imports what drives it.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Protocol

from services.errors import AuthenticationError, ProtocolError
from services.node.logs import LogLimiter
from services.protocol import (
    Auth,
    Bye,
    Call,
    Cancel,
    Connection,
    Event,
    Message,
    Ping,
    Pong,
    Query,
    State,
    Subscribe,
    Unsubscribe,
    shown,
)
from services.wire import FramedConnection

__all__ = ["Peer", "PeerHost"]

log = logging.getLogger("petrobot.node")

_WRITE_HIGH_WATER = 256 * 1024
_ABORT_AFTER_S = 1.0  # a closed connection whose output the peer does not read is cut after this


class PeerHost(Protocol):
    """What a connection needs of the node that accepted it; every method is called on the loop.

    Attributes:
        max_output: bytes that may wait to go out to one peer before the node stops reading from it.
    """

    max_output: int

    def peer_connected(self, peer: Peer) -> None:
        """The transport is up: the peer is one of the node's connections."""

    def peer_authenticated(self, peer: Peer) -> None:
        """The handshake succeeded (the host may still refuse the peer, over its caps)."""

    def login_failed(self, peer: Peer, exc: Exception) -> None:
        """The handshake failed with ``exc`` (the peer is closed next)."""

    def peer_gone(self, peer: Peer) -> None:
        """The connection closed or failed: forget the peer (may be called more than once)."""

    def admit_call(self, peer: Peer, call: Call) -> None:
        """Admit, join, answer or reject ``call``, and say so to the peer."""

    def answer_query(self, peer: Peer, query: Query) -> None:
        """Answer ``query`` (what became of a call), never running anything."""

    def cancel_call(self, call_id: str) -> None:
        """Cancel call ``call_id`` if it runs."""

    def subscribe(self, peer: Peer, topic: str) -> None:
        """Send the peer the events of ``topic`` (a refusal is the host's to log)."""

    def unsubscribe(self, peer: Peer, topic: str) -> None:
        """Stop sending the peer the events of ``topic``."""

    def writing_paused(self, peer: Peer) -> None:
        """The peer's transport buffer is full: hold its events back."""

    def writing_resumed(self, peer: Peer) -> list[Event]:
        """The buffer drained: the events held back for the peer, to send now."""
        ...

    def read_done(self) -> None:
        """One read from a peer has been handled (the calls it started are committed before they run)."""


class Peer(FramedConnection):
    """One accepted connection (see the module docstring).

    Args:
        host: the node, as the connection sees it.
        conn: the sans-IO server connection (its key, name, frame cap and offer are the node's).
        loop: the running loop.
        peer_host: the peer's IP address.
        accepted_at: loop time of the accept, seconds.
        limited: the node's rate-limited log, for lines a peer can provoke at will.
        tls_binding: the connection runs over TLS in ``psk`` mode.

    Attributes:
        local: whether the peer is on this host (decided at authentication).
        authenticated: the handshake succeeded.
        closed: ``bye`` was sent or received, or the connection is gone.
        dropped_feedback: feedback messages not sent because the peer was not reading.
        forgotten: the node has let go of this connection (its caps, subscriptions and calls).
        connecting: the task setting up the transport (TLS handshake), until it is done.
    """

    def __init__(self, host: PeerHost, conn: Connection, loop: asyncio.AbstractEventLoop, peer_host: str,
                 accepted_at: float, limited: LogLimiter, *, tls_binding: bool = False) -> None:
        super().__init__(conn, loop, tls_binding=tls_binding)
        self.host = host
        self.limited = limited
        self.peer_host = peer_host
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
        self.host.peer_connected(self)
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
        self.host.peer_gone(self)

    def pause_writing(self) -> None:
        self._writing_paused = True
        self.host.writing_paused(self)

    def resume_writing(self) -> None:
        self._writing_paused = False
        for ev in self.host.writing_resumed(self):
            self.send(ev)
        self._unblock()

    def connect_failed(self) -> None:
        """The transport never came up (TLS handshake failed, or the peer left first)."""
        self.closed = True
        self.host.peer_gone(self)

    # ---- input

    def _process(self) -> None:
        conn = self.conn
        limit = self.host.max_output
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
                self.host.login_failed(self, exc)
                self.close("auth_failed")
            else:
                self.limited.log(logging.WARNING, ("bad frame", self.peer_host),
                                 "bad frame from %r: %s", self, shown(str(exc), 200))
                self.close(f"protocol_error: {shown(str(exc), 200)}")
            return
        finally:
            self.host.read_done()  # the calls started by this read are on disk before they run
        self._schedule_flush()

    def _block(self) -> None:
        """Stop reading: too much output waits for this peer."""
        if not self._reading_blocked and self.transport is not None:
            self._reading_blocked = True
            self.transport.pause_reading()

    def _unblock(self) -> None:
        if self._reading_blocked and not self._writing_paused and not self.closed \
                and self.output_backlog <= self.host.max_output and self.transport is not None:
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
        host = self.host
        if isinstance(msg, Call):
            host.admit_call(self, msg)
        elif isinstance(msg, Ping):
            self.send(Pong(seq=msg.seq))
        elif isinstance(msg, Query):
            host.answer_query(self, msg)
        elif isinstance(msg, Cancel):
            host.cancel_call(msg.id)
        elif isinstance(msg, Subscribe):
            host.subscribe(self, msg.topic)
        elif isinstance(msg, Unsubscribe):
            host.unsubscribe(self, msg.topic)
        elif isinstance(msg, Bye):
            reason = shown(msg.reason, 120)
            if self.authenticated:
                log.info("%r said bye: %s", self, reason)
            else:
                self.limited.log(logging.INFO, ("bye before login", self.peer_host),
                                 "unauthenticated %s said bye: %s", self.peer_host, reason)
            self._close_transport()
        elif isinstance(msg, Auth):
            host.peer_authenticated(self)

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
            self.host.peer_gone(self)
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
        self.host.peer_gone(self)
