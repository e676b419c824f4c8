"""The simulated CAN-Ethernet gateway: the socketcand ASCII protocol, server side.

A real lab puts a CAN-Ethernet gateway (or the socketcand daemon) between the bus and the motion
node; the motion node's master talks to it with python-can's ``socketcand`` client
(``can.Bus(interface="socketcand", host=..., port=..., channel="can0")``). The simulated bus
(:mod:`sim.canbus`) is served with the same protocol, so the node cannot tell the two apart. Both
worlds serve their bus with it.

Two layers: :class:`SocketcandServerProtocol`, the sans-IO core of one connection (bytes in,
frames and bytes out), and :class:`CanGateway`, the TCP server around it: one accept thread and,
per connection, a reader and a writer thread. A peer may connect and leave at any moment (a port
probe, a scanner, a killed client): that ends its connection only.

socketcand ASCII (linux-can/socketcand doc/protocol.md): server greets ``< hi >``; ``< open can0 >``
and ``< rawmode >`` are answered ``< ok >``; in raw mode the server sends
``< frame ID SECS.USECS DATA >`` and the client sends ``< send ID LEN B0 B1 ... >``. ``DATA`` is
written as contiguous hex bytes (as the socketcand daemon does and python-can's client parses);
an empty frame has an empty data field.
"""

from __future__ import annotations

import enum
import logging
import socket
import threading
import time
from collections.abc import Sequence
from typing import Self

from services.devices.cia402 import CanFrame, FrameError
from sim.canbus import SimBus

__all__ = ["CanGateway", "ServerMode", "SocketcandServerProtocol", "format_frame", "format_send",
           "parse_message"]

log = logging.getLogger(__name__)

_RAW_SETTLE_S = 0.2  # gateway: forward bus frames this long after "< ok >" to rawmode at the latest


def format_frame(frame: CanFrame) -> bytes:
    """Server -> client raw-mode frame: ``< frame ID SECS.USECS DATA >``."""
    secs = max(frame.t, 0.0)
    whole = int(secs)
    usecs = round((secs - whole) * 1e6)
    if usecs >= 1_000_000:
        whole, usecs = whole + 1, usecs - 1_000_000
    return f"< frame {frame.can_id:03X} {whole}.{usecs:06d} {frame.data.hex().upper()} >".encode("ascii")


def format_send(frame: CanFrame) -> bytes:
    """Client -> server send command: ``< send ID LEN B0 B1 ... >``."""
    body = "".join(f" {b:02X}" for b in frame.data)
    return f"< send {frame.can_id:03X} {len(frame.data)}{body} >".encode("ascii")


def parse_message(text: str) -> tuple[str, list[str]]:
    """Split one ``< ... >`` message into its command word and arguments.

    Raises:
        FrameError: not delimited by ``<`` and ``>`` or empty.
    """
    text = text.strip()
    if not (text.startswith("<") and text.endswith(">")):
        raise FrameError(f"socketcand message not in angle brackets: {text!r}")
    words = text[1:-1].split()
    if not words:
        raise FrameError("empty socketcand message")
    return words[0], words[1:]


def _parse_send(args: list[str], t: float) -> CanFrame:
    if len(args) < 2:
        raise FrameError("send needs an id and a length")
    try:
        can_id = int(args[0], 16)
        length = int(args[1], 16)
        data = bytes(int(b, 16) for b in args[2:])
    except ValueError as exc:
        raise FrameError(f"bad number in send command: {' '.join(args)}") from exc
    if length != len(data):
        raise FrameError(f"send says {length} bytes but carries {len(data)}")
    if can_id > 0x7FF:
        raise FrameError("extended identifiers are not supported on this bus")
    return CanFrame(can_id, data, t)


class ServerMode(enum.Enum):
    """Modes of a socketcand connection, server side."""

    NO_BUS = "no bus"
    BCM = "bcm"
    RAW = "raw"
    CLOSED = "closed"


class SocketcandServerProtocol:
    """Sans-IO server side of one socketcand connection (subset: open, rawmode, send, echo).

    Feed received bytes with :meth:`receive_data`; it returns the CAN frames the client sent.
    Bytes to write back accumulate in :meth:`data_to_send`. :attr:`mode` tells whether bus frames
    may be forwarded to the client (only in raw mode). A malformed message is answered with
    ``< error ... >`` and otherwise ignored; an unknown bus closes the connection.

    Args:
        channels: bus names this server offers (e.g. ``("can0",)``).
    """

    MAX_MESSAGE = 256

    def __init__(self, channels: Sequence[str] = ("can0",)) -> None:
        self.channels = tuple(channels)
        self.mode = ServerMode.NO_BUS
        self.channel: str | None = None
        self._in = bytearray()
        self._out = bytearray(b"< hi >")

    def receive_data(self, data: bytes, t: float = 0.0) -> list[CanFrame]:
        """Consume bytes from the client; returns the frames it asked to send (stamped ``t``)."""
        self._in += data
        frames: list[CanFrame] = []
        while self.mode is not ServerMode.CLOSED:
            start = self._in.find(b"<")
            if start < 0:
                self._in.clear()
                break
            end = self._in.find(b">", start)
            if end < 0:
                del self._in[:start]
                if len(self._in) > self.MAX_MESSAGE:
                    self._error("message too long")
                    self._in.clear()
                break
            raw = bytes(self._in[start : end + 1])
            del self._in[: end + 1]
            try:
                cmd, args = parse_message(raw.decode("ascii"))
            except (FrameError, UnicodeDecodeError) as exc:
                self._error(str(exc))
                continue
            frame = self._command(cmd, args, t)
            if frame is not None:
                frames.append(frame)
        return frames

    def _command(self, cmd: str, args: list[str], t: float) -> CanFrame | None:
        if cmd == "echo":
            self._out += b"< echo >"
        elif cmd == "open" and self.mode is ServerMode.NO_BUS:
            if len(args) == 1 and args[0] in self.channels:
                self.channel = args[0]
                self.mode = ServerMode.BCM
                self._out += b"< ok >"
            else:
                self._error(f"could not open bus {' '.join(args)}")
                self.mode = ServerMode.CLOSED
        elif cmd == "rawmode" and self.mode in (ServerMode.BCM, ServerMode.RAW):
            self.mode = ServerMode.RAW
            self._out += b"< ok >"
        elif cmd == "bcmmode" and self.mode in (ServerMode.BCM, ServerMode.RAW):
            self.mode = ServerMode.BCM
            self._out += b"< ok >"
        elif cmd == "send" and self.mode in (ServerMode.BCM, ServerMode.RAW):
            try:
                return _parse_send(args, t)
            except FrameError as exc:
                self._error(str(exc))
        else:
            self._error(f"command {cmd} not supported in mode {self.mode.value}")
        return None

    def _error(self, text: str) -> None:
        safe = text.replace("<", "(").replace(">", ")")
        self._out += f"< error {safe} >".encode("ascii", "replace")

    def frame_out(self, frame: CanFrame) -> None:
        """Queue a bus frame for the client (dropped unless in raw mode)."""
        if self.mode is ServerMode.RAW:
            self._out += format_frame(frame)

    def data_to_send(self) -> bytes:
        """Bytes to write to the client now (and forget)."""
        out = bytes(self._out)
        self._out.clear()
        return out


class CanGateway:
    """socketcand-protocol TCP server bridging a :class:`SimBus` to other processes.

    Implements the subset python-can's ``socketcand`` client uses (``open``, ``rawmode``,
    ``send``, plus ``echo``). Bus frames are forwarded once the connection is in raw mode and the
    client has sent its first frame, or :data:`_RAW_SETTLE_S` after raw mode at the latest
    (python-can reads the ``< ok >`` of ``rawmode`` with a single ``recv`` and compares it exactly,
    so nothing may follow it in the same segment).

    Args:
        bus: the simulated bus.
        host: listen address (loopback only by default).
        port: TCP port, 0 for any free port.
        channels: bus names served.
        max_connections: connections at most (each costs two threads and a port whose queue holds every
            bus frame). A connection beyond it closes the one that has sent nothing for the longest
            (a master sends every SYNC cycle: idle strangers go first). The port has no key (a CAN bus
            has none), so this bounds what 500 idle connections cost, not who may send.
    """

    def __init__(
        self, bus: SimBus, host: str = "127.0.0.1", port: int = 0, channels: Sequence[str] = ("can0",),
        *, max_connections: int = 16,
    ) -> None:
        if max_connections < 1:
            raise ValueError(f"max_connections must be at least 1, not {max_connections}")
        self.bus = bus
        self.host = host
        self.port = port
        self.channels = tuple(channels)
        self.max_connections = max_connections
        self._server: socket.socket | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: list[socket.socket] = []
        self._live: dict[socket.socket, _Connection] = {}
        self._lock = threading.Lock()
        self._evicted = 0

    def start(self) -> int:
        """Start listening; returns the TCP port."""
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((self.host, self.port))
        srv.listen(64)  # a burst of connections waits in the backlog instead of a 1 s SYN retry
        srv.settimeout(0.1)
        self._server = srv
        self.port = srv.getsockname()[1]
        th = threading.Thread(target=self._accept_loop, name="can-gateway-accept", daemon=True)
        th.start()
        self._threads.append(th)
        return self.port

    def stop(self) -> None:
        """Close the server and every connection; join the threads (bounded)."""
        self._stop.set()
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        if self._server is not None:
            self._server.close()
        for th in self._threads:
            th.join(timeout=2.0)

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _accept_loop(self) -> None:
        assert self._server is not None
        while not self._stop.is_set():
            try:
                conn, addr = self._server.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                if self._stop.is_set() or self._server.fileno() < 0:
                    return  # closed by stop()
                log.warning("CAN gateway: accept failed: %s", exc)  # out of descriptors...: try again
                self._stop.wait(0.1)
                continue
            try:
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                conn.settimeout(None)
            except OSError:  # the peer is already gone
                conn.close()
                continue
            peer = f"{addr[0]}:{addr[1]}"
            self._make_room(peer)
            connection = _Connection(self, conn, peer)
            with self._lock:
                self._conns.append(conn)
                self._live[conn] = connection
                self._threads = [th for th in self._threads if th.is_alive()]
            connection.start()

    def _make_room(self, peer: str) -> None:
        """At ``max_connections``, close the connection that has sent nothing for the longest."""
        with self._lock:
            if len(self._live) < self.max_connections:
                return
            victim = min(self._live.values(), key=lambda c: c.last_heard)
            self._evicted += 1
            if self._evicted == 1 or self._evicted % 100 == 0:
                log.warning("CAN gateway: %d connections, closed %s (silent longest) for %s (%d so far)",
                            len(self._live), victim.peer, peer, self._evicted)
        victim.close()
        for th in victim.threads:  # its threads gone before a new pair starts: bounded under any churn
            th.join(timeout=1.0)


class _Connection:
    """One client of the gateway: a reader and a writer thread around the sans-IO protocol.

    A peer may leave at any moment (a port probe connects and closes at once): every send and
    receive error ends this connection only, never the gateway.
    """

    def __init__(self, gateway: CanGateway, sock: socket.socket, peer: str) -> None:
        self.gw = gateway
        self.sock = sock
        self.peer = peer
        self.proto = SocketcandServerProtocol(gateway.channels)
        self.port = gateway.bus.connect()
        self.lock = threading.Lock()
        self.raw_since: float | None = None
        self.forwarding = False
        self.done = threading.Event()
        self.last_heard = time.monotonic()  # when the peer last sent something
        self.threads: list[threading.Thread] = []  # its reader and writer, once started

    def start(self) -> None:
        if not self._flush():  # the greeting, before any thread may close the socket
            return
        for target, name in ((self._reader, "reader"), (self._writer, "writer")):
            th = threading.Thread(target=target, name=f"can-gateway-{name}", daemon=True)
            th.start()
            self.threads.append(th)
            self.gw._threads.append(th)

    def _flush(self) -> bool:
        """Send what the protocol has queued; False (and the connection closed) if the peer is gone."""
        try:
            with self.lock:
                out = self.proto.data_to_send()
                if out:
                    self.sock.sendall(out)
            return True
        except OSError as exc:
            log.debug("CAN gateway: %s left: %s", self.peer, exc)
            self._close()
            return False

    def _reader(self) -> None:
        try:
            while not self.done.is_set():
                data = self.sock.recv(4096)
                if not data:
                    break
                self.last_heard = time.monotonic()
                with self.lock:
                    frames = self.proto.receive_data(data, time.monotonic())
                    if self.proto.mode is ServerMode.RAW and self.raw_since is None:
                        self.raw_since = time.monotonic()
                if not self._flush():
                    return
                if frames:
                    self.forwarding = self.raw_since is not None
                for f in frames:
                    self.port.send(f)
                if self.proto.mode is ServerMode.CLOSED:
                    break
        except OSError:
            pass
        finally:
            self._close()

    def _writer(self) -> None:
        while not self.done.is_set():
            first = self.port.recv(timeout=0.1)
            if first is None:
                continue
            frames = [first] + self.port.recv_all()
            if not self.forwarding:
                if self.raw_since is None or time.monotonic() - self.raw_since < _RAW_SETTLE_S:
                    continue
                self.forwarding = True
            with self.lock:
                for f in frames:
                    self.proto.frame_out(f)
            if not self._flush():
                return

    def close(self) -> None:
        """End this connection (its threads end on their next wake-up)."""
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._close()

    def _close(self) -> None:
        with self.lock:
            if self.done.is_set():
                return
            self.done.set()
        self.port.close()
        try:
            self.sock.close()
        except OSError:
            pass
        with self.gw._lock:
            if self.sock in self.gw._conns:
                self.gw._conns.remove(self.sock)
            self.gw._live.pop(self.sock, None)
