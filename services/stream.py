"""Set-point stream from the vision node to the motion node (paper section 6).

"The image processing PC sends set points periodically to the motion control PC using TCP/IP
sockets. The set points represent the predicted catching points." Here: one TCP connection of its own
(not the coordinator's), one set point per camera frame, each with a sequence number and timestamps;
the receiver keeps only the latest (latest wins) and reports a lost stream when set points stop coming
or the connection drops.

Wire format: each set point is one write of a 4-byte big-endian length followed by a msgpack map
with the fields of :class:`SetPoint` (``{"seq", "t_frame", "t_capture", "t_sent", "x", "y", "t",
"vx", "vy", "sigma_y", "sigma_t"}``). Maps larger than :data:`MAX_MESSAGE` are refused before their
body is read.

Layers, sans-IO style: :func:`encode` / :class:`SetPointDecoder` turn set points into bytes and
bytes into set points; :class:`LatestSetPoint` keeps the latest and judges staleness with a time
passed in; :class:`SetPointSender` (blocking socket) and :class:`SetPointReceiver` (asyncio server)
are the thin I/O shells.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any


from services.errors import ActionError, RemoteProtocolError
from services.protocol.framing import FrameReader, pack_map, unpack_map

__all__ = [
    "MAX_MESSAGE",
    "LatestSetPoint",
    "SetPoint",
    "SetPointDecoder",
    "SetPointReceiver",
    "SetPointSender",
    "StreamLostError",
    "encode",
]

MAX_MESSAGE = 4096
"""Largest accepted set-point message body, bytes."""



class StreamLostError(ActionError):
    """No fresh set point: the stream never started, went stale, or its connection dropped."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SetPoint:
    """A predicted catching point, as streamed from vision to motion.

    Coordinates are in the table frame of :mod:`sim.catching` (x towards the robot, catch line at
    x = 0); times ``t_frame`` and ``t`` are on the camera's clock (simulated time in the sim),
    ``t_capture`` and ``t_sent`` on the host's wall clock (:func:`time.time`, for latency).

    Attributes:
        seq: sequence number, increasing by one per set point of the stream.
        t_frame: timestamp of the camera frame the prediction used, s.
        t_capture: wall-clock time the frame was captured, s.
        t_sent: wall-clock time the set point was sent, s.
        x, y: predicted point where the ball crosses the catch line, m.
        t: predicted time of the crossing, s (camera clock).
        vx, vy: predicted ball velocity at the crossing, m/s.
        sigma_y: 1-σ uncertainty of y, m.
        sigma_t: 1-σ uncertainty of t, s.
    """

    seq: int
    t_frame: float
    t_capture: float
    t_sent: float
    x: float
    y: float
    t: float
    vx: float
    vy: float
    sigma_y: float = 0.0
    sigma_t: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """The set point as a plain dict (msgpack-able)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SetPoint:
        """Build from a dict; raises RemoteProtocolError on missing or mistyped fields."""
        try:
            kw: dict[str, Any] = {}
            for f in fields(cls):
                if f.name not in d:
                    if f.name in ("sigma_y", "sigma_t"):
                        continue
                    raise KeyError(f.name)
                kw[f.name] = int(d[f.name]) if f.name == "seq" else float(d[f.name])
            return cls(**kw)
        except (KeyError, TypeError, ValueError) as exc:
            raise RemoteProtocolError(f"malformed set point: {exc!r}") from exc


def encode(sp: SetPoint) -> bytes:
    """Bytes of one set-point message (length prefix + msgpack map)."""
    return pack_map(sp.to_dict(), MAX_MESSAGE)


class SetPointDecoder:
    """Turns received bytes into set points (sans-IO).

    Feed whatever the socket gave with :meth:`feed`; it returns the complete set points found.

    Raises:
        RemoteProtocolError: (from :meth:`feed`) on an oversize or malformed message; the stream
            is then unusable.
    """

    def __init__(self, max_message: int = MAX_MESSAGE) -> None:
        self.max_message = max_message
        self._reader = FrameReader(max_message)

    def feed(self, data: bytes) -> list[SetPoint]:
        """Add received bytes; return the set points completed by them, in order."""
        self._reader.feed(data)
        out: list[SetPoint] = []
        while (body := self._reader.next_body()) is not None:
            out.append(SetPoint.from_dict(unpack_map(body)))
        return out


class LatestSetPoint:
    """Holds the latest set point of a stream (latest wins) and judges its freshness (sans-IO).

    Args:
        max_age: a set point older than this (s, by its receive time) is stale.
    """

    def __init__(self, max_age: float = 0.2) -> None:
        self.max_age = max_age
        self.latest: SetPoint | None = None
        self.received_at: float | None = None
        self.received = 0
        self.dropped = 0
        self.closed_reason: str | None = None

    def offer(self, sp: SetPoint, now: float) -> bool:
        """Offer a received set point at time ``now`` (s); True if it became the latest.

        A set point whose seq is not newer than the latest one's is dropped (counted in
        :attr:`dropped`).
        """
        self.received += 1
        if self.latest is not None and sp.seq <= self.latest.seq:
            self.dropped += 1
            return False
        self.latest = sp
        self.received_at = now
        return True

    def close(self, reason: str) -> None:
        """Mark the stream as lost (connection dropped, protocol error)."""
        if self.closed_reason is None:
            self.closed_reason = reason

    def get(self, now: float) -> SetPoint:
        """The latest set point, if fresh at time ``now`` (s, same clock as :meth:`offer`).

        Raises:
            StreamLostError: if the stream is closed, never delivered, or the latest set point is
                older than ``max_age``.
        """
        if self.closed_reason is not None:
            raise StreamLostError(f"set-point stream lost: {self.closed_reason}")
        if self.latest is None or self.received_at is None:
            raise StreamLostError("no set point received yet")
        age = now - self.received_at
        if age > self.max_age:
            raise StreamLostError(f"set-point stream stale: last set point {age:.3f} s old")
        return self.latest


class SetPointSender:
    """Sends set points over a TCP connection (blocking socket, TCP_NODELAY, one write each).

    Args:
        host, port: address of the :class:`SetPointReceiver`.
        timeout: connect and send timeout, s.

    Raises:
        OSError: if the connection cannot be made.
    """

    def __init__(self, host: str, port: int, *, timeout: float = 2.0) -> None:
        self._sock = socket.create_connection((host, port), timeout=timeout)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.seq = 0

    def send(
        self, *, t_frame: float, t_capture: float, x: float, y: float, t: float, vx: float,
        vy: float, sigma_y: float = 0.0, sigma_t: float = 0.0,
    ) -> SetPoint:
        """Stamp a set point with the next sequence number and the send time, and send it.

        Raises:
            OSError: if the connection is broken.
        """
        sp = SetPoint(
            seq=self.seq, t_frame=t_frame, t_capture=t_capture, t_sent=time.time(), x=x, y=y,
            t=t, vx=vx, vy=vy, sigma_y=sigma_y, sigma_t=sigma_t,
        )
        self._sock.sendall(encode(sp))
        self.seq += 1
        return sp

    def close(self) -> None:
        """Close the connection (the receiver then reports the stream lost)."""
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()


class SetPointReceiver:
    """asyncio TCP server receiving one set-point stream at a time (the motion node side).

    Args:
        host: address to listen on.
        port: TCP port, 0 for any free one (see :attr:`port` after :meth:`start`).
        max_age: staleness limit, s (see :class:`LatestSetPoint`).
        clock: wall clock used for receive times (default :func:`time.time`).
        on_set_point: optional callback run for each set point that becomes the latest, with the
            set point and its receive time.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        max_age: float = 0.2,
        clock: Callable[[], float] = time.time,
        on_set_point: Callable[[SetPoint, float], None] | None = None,
    ) -> None:
        self.host = host
        self.port = port
        self.clock = clock
        self.state = LatestSetPoint(max_age)
        self.on_set_point = on_set_point
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._new = asyncio.Event()
        self.connected = False

    async def start(self) -> int:
        """Start listening; returns the port."""
        self._server = await asyncio.start_server(self._handle, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    def latest(self) -> SetPoint:
        """The latest fresh set point; raises StreamLostError (see :meth:`LatestSetPoint.get`)."""
        return self.state.get(self.clock())

    async def wait_newer(self, seq: int, timeout: float) -> SetPoint:
        """Wait up to ``timeout`` s for a set point with sequence number above ``seq``.

        Raises:
            StreamLostError: if none arrives in time or the stream is lost.
        """
        try:
            async with asyncio.timeout(timeout):
                while True:
                    sp = self.state.latest
                    if sp is not None and sp.seq > seq and self.state.closed_reason is None:
                        return sp
                    if self.state.closed_reason is not None:
                        raise StreamLostError(f"set-point stream lost: {self.state.closed_reason}")
                    self._new.clear()
                    await self._new.wait()
        except TimeoutError:
            raise StreamLostError(f"no set point newer than {seq} within {timeout} s") from None

    async def close(self) -> None:
        """Close the server and every connection."""
        for w in list(self._writers):
            w.close()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await self._server.wait_closed()

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._writers.add(writer)
        self.state = _carry_over(self.state)
        self.connected = True
        decoder = SetPointDecoder()
        reason = "sender closed the connection"
        try:
            while True:
                data = await reader.read(65536)
                if not data:
                    break
                now = self.clock()
                for sp in decoder.feed(data):
                    if self.state.offer(sp, now) and self.on_set_point is not None:
                        self.on_set_point(sp, now)
                self._new.set()
        except RemoteProtocolError as exc:
            reason = str(exc)
        except (ConnectionError, OSError) as exc:
            reason = f"connection error: {exc!r}"
        finally:
            self.connected = False
            self.state.close(reason)
            self._new.set()
            self._writers.discard(writer)
            writer.close()


def _carry_over(old: LatestSetPoint) -> LatestSetPoint:
    """A fresh holder for a new connection (new sender, sequence numbers start again)."""
    return LatestSetPoint(old.max_age)
