"""The asyncio shell around one sans-IO protocol connection, over TCP or TLS (docs/protocol.md §1, §3).

:class:`FramedConnection` is what the node's accepted connections and the client's node links have
in common: ``TCP_NODELAY`` on the socket, and every frame produced during one event-loop iteration
written in a single ``transport.write`` (a call's ``accepted`` and ``result`` usually travel
together; a header and its body never go out as two writes, which with Nagle's algorithm costs a
40 ms stall). It also counts the bytes waiting to go out (:attr:`FramedConnection.output_backlog`),
so that a node can stop reading from a peer that does not read what it is sent.

TLS (stdlib :mod:`ssl`), configured per node by :class:`services.location.TlsSettings`:

* ``certificate`` — mutual TLS 1.2+ with the standard verification: each side presents its host's
  certificate and checks the other's against the ``ca``; the client checks that the node's
  certificate names ``server_name`` (default: the node's host).
* ``psk`` — TLS keyed by the shared key, with no certificate at all: TLS 1.2 with an anonymous
  ephemeral elliptic-curve key exchange (``AECDH`` cipher suites, which OpenSSL allows only at
  security level 0), and the protocol's HMAC handshake covering the TLS channel binding
  (``tls-unique``, RFC 5929) on both sides. The key exchange alone authenticates nobody; the MACs
  do, and since they cover the binding, a relay that runs one TLS session with the client and
  another with the node cannot pass them on: its two sessions have different bindings. Session
  tickets and renegotiation are off; OpenSSL negotiates encrypt-then-MAC (RFC 7366) and the
  extended master secret (RFC 7627), which keeps ``tls-unique`` unique to one session.

:func:`server_context` and :func:`client_context` build the contexts; ``None`` means plain TCP.
"""

from __future__ import annotations

import asyncio
import socket
import ssl
from typing import Final

from services.errors import ProtocolError
from services.location import TlsSettings
from services.protocol import Connection, Message

__all__ = ["PSK_CIPHERS", "FramedConnection", "client_context", "server_context"]

PSK_CIPHERS: Final = "AECDH-AES256-SHA:AECDH-AES128-SHA:@SECLEVEL=0"
"""OpenSSL cipher list of ``psk`` mode: anonymous ECDHE, AES, TLS 1.2."""


def _psk_context(purpose: int) -> ssl.SSLContext:
    ctx = ssl.SSLContext(purpose)
    ctx.minimum_version = ctx.maximum_version = ssl.TLSVersion.TLSv1_2
    if purpose == ssl.PROTOCOL_TLS_CLIENT:
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_NONE
    ctx.set_ciphers(PSK_CIPHERS)
    ctx.options |= ssl.OP_NO_TICKET | ssl.OP_NO_RENEGOTIATION
    return ctx


def server_context(tls: TlsSettings) -> ssl.SSLContext | None:
    """The SSL context a node serves with, or ``None`` for plain TCP.

    Raises:
        ssl.SSLError, OSError: a certificate, key or CA file cannot be read or does not match.
    """
    if tls.mode == "psk":
        return _psk_context(ssl.PROTOCOL_TLS_SERVER)
    if tls.mode != "certificate":
        return None
    assert tls.cert and tls.key and tls.ca
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_cert_chain(tls.cert, tls.key)
    ctx.load_verify_locations(tls.ca)
    ctx.verify_mode = ssl.CERT_REQUIRED
    ctx.options |= ssl.OP_NO_RENEGOTIATION
    return ctx


def client_context(tls: TlsSettings) -> ssl.SSLContext | None:
    """The SSL context a client connects to a node with, or ``None`` for plain TCP.

    Raises:
        ssl.SSLError, OSError: a certificate, key or CA file cannot be read or does not match.
    """
    if tls.mode == "psk":
        return _psk_context(ssl.PROTOCOL_TLS_CLIENT)
    if tls.mode != "certificate":
        return None
    assert tls.cert and tls.key and tls.ca
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)  # verifies the node's certificate and its name
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_verify_locations(tls.ca)
    ctx.load_cert_chain(tls.cert, tls.key)
    return ctx


class FramedConnection(asyncio.Protocol):
    """Feeds a :class:`~services.protocol.Connection` and flushes its output, coalesced per loop tick.

    Args:
        conn: the sans-IO connection (client or server role).
        loop: the running event loop.
        tls_binding: the connection runs over TLS in ``psk`` mode: the handshake MACs cover the
            TLS channel binding (taken when the TLS session is up).

    Attributes:
        transport: the transport once connected, else ``None``.
        last_rx: loop time of the last bytes received, seconds (for heartbeats).
    """

    def __init__(self, conn: Connection, loop: asyncio.AbstractEventLoop, *, tls_binding: bool = False) -> None:
        self.conn = conn
        self.loop = loop
        self.transport: asyncio.Transport | None = None
        self.last_rx = loop.time()
        self.tls_binding = tls_binding
        self._flush_scheduled = False
        self._held: list[bytes] = []
        self._held_bytes = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self.tls_binding:
            ssl_object = transport.get_extra_info("ssl_object")
            binding = ssl_object.get_channel_binding("tls-unique") if ssl_object is not None else None
            if not binding:
                raise ProtocolError("TLS psk mode needs the tls-unique channel binding (TLS 1.2)")
            self.conn.binding = binding

    def send(self, msg: Message) -> None:
        """Queue ``msg``; it is written with everything else queued in this loop iteration."""
        self.conn.send(msg)
        self._schedule_flush()

    def send_frame(self, data: bytes) -> None:
        """Queue an already encoded frame (the same ``result`` sent to several peers is encoded
        once); the caller checks that the connection may send it."""
        pending = self.conn.data_to_send()
        if pending:
            self._held.append(pending)
            self._held_bytes += len(pending)
        self._held.append(data)
        self._held_bytes += len(data)
        self._schedule_flush()

    @property
    def output_backlog(self) -> int:
        """Bytes waiting to go out: queued in this loop iteration plus the transport's buffer."""
        t = self.transport
        return self.conn.bytes_to_send + self._held_bytes + (t.get_write_buffer_size() if t is not None else 0)

    def _schedule_flush(self) -> None:
        if not self._flush_scheduled:
            self._flush_scheduled = True
            self.loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        data = self.conn.data_to_send()
        if self._held:
            self._held.append(data)
            data = b"".join(self._held)
            self._held.clear()
            self._held_bytes = 0
        if data and self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)
        self.flushed()

    def flushed(self) -> None:
        """Called after each flush (subclasses resume reading here once the backlog is gone)."""
