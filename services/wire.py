"""The asyncio shell around one sans-IO protocol connection (docs/protocol.md §1).

:class:`FramedConnection` is what the node's accepted connections and the client's node links have
in common: ``TCP_NODELAY`` on the socket, and every frame produced during one event-loop iteration
written in a single ``transport.write`` (a call's ``accepted`` and ``result`` usually travel
together; a header and its body never go out as two writes, which with Nagle's algorithm costs a
40 ms stall).
"""

from __future__ import annotations

import asyncio
import socket

from services.protocol import Connection, Message

__all__ = ["FramedConnection"]


class FramedConnection(asyncio.Protocol):
    """Feeds a :class:`~services.protocol.Connection` and flushes its output, coalesced per loop tick.

    Args:
        conn: the sans-IO connection (client or server role).
        loop: the running event loop.

    Attributes:
        transport: the TCP transport once connected, else ``None``.
        last_rx: loop time of the last bytes received, seconds (for heartbeats).
    """

    def __init__(self, conn: Connection, loop: asyncio.AbstractEventLoop) -> None:
        self.conn = conn
        self.loop = loop
        self.transport: asyncio.Transport | None = None
        self.last_rx = loop.time()
        self._flush_scheduled = False
        self._held: list[bytes] = []

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def send(self, msg: Message) -> None:
        """Queue ``msg``; it is written with everything else queued in this loop iteration."""
        self.conn.send(msg)
        self._schedule_flush()

    def send_counted(self, msg: Message) -> int:
        """Queue ``msg`` like :meth:`send` and return the length of its frame, bytes.

        Raises:
            LocalProtocolError: as :meth:`services.protocol.Connection.send` (the state or
                direction forbids ``msg``, or it cannot be encoded); nothing is queued then.
        """
        conn = self.conn
        before = conn.data_to_send()
        if before:
            self._held.append(before)
        conn.send(msg)
        data = conn.data_to_send()
        self._held.append(data)
        self._schedule_flush()
        return len(data)

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
        if data and self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)
