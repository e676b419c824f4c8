"""The socketcand ASCII protocol, server side: the simulated CAN-Ethernet gateway (sans-IO).

A real lab puts a CAN-Ethernet gateway (or the socketcand daemon) between the bus and the motion
node; the motion node's master talks to it with python-can's ``socketcand`` client. The simulated
bus (:mod:`sim.canbus`) serves the same protocol, so the node cannot tell the two apart.

socketcand ASCII (linux-can/socketcand doc/protocol.md): server greets ``< hi >``; ``< open can0 >``
and ``< rawmode >`` are answered ``< ok >``; in raw mode the server sends
``< frame ID SECS.USECS DATA >`` and the client sends ``< send ID LEN B0 B1 ... >``. ``DATA`` is
written as contiguous hex bytes (as the socketcand daemon does and python-can's client parses);
an empty frame has an empty data field.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from services.devices.cia402 import CanFrame, FrameError

__all__ = ["ServerMode", "SocketcandServerProtocol", "format_frame", "format_send", "parse_message"]


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
