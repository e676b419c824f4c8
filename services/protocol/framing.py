"""Length-prefixed msgpack framing, sans-IO: the one framing every petrobot stream uses.

A frame is a 4-byte big-endian unsigned length followed by that many bytes of body; in petrobot
the body is one msgpack map. The node protocol (:mod:`services.protocol.connection`), the
set-point stream (:mod:`services.catching.setpoints`) and the frame grabber's link to its camera
(:mod:`services.devices.framegrabber`) all use this module.

:class:`FrameReader` checks the announced length against its cap as soon as the 4 header bytes
are in, before any of the body is buffered: a peer cannot make the reader hold more than
``max_frame`` + 4 bytes of one frame.
"""

from __future__ import annotations

import re
import socket
from struct import Struct
from typing import Any, Final

import msgpack

from services.errors import LocalProtocolError, RemoteProtocolError

__all__ = ["HEADER_BYTES", "FrameReader", "frame", "pack_map", "recv_frame", "unpack_map"]

HEADER_BYTES: Final = 4
"""Length of the frame header (big-endian unsigned 32-bit body length), bytes."""

_LEN: Final = Struct(">I")
_COMPACT_AT: Final = 65536


def frame(body: bytes) -> bytes:
    """The frame carrying ``body``: its length (4 bytes, big-endian) followed by ``body``."""
    return _LEN.pack(len(body)) + body


def pack_map(obj: dict[str, Any], max_frame: int, packer: msgpack.Packer | None = None) -> bytes:
    """Encode ``obj`` as one frame (header + msgpack body).

    Args:
        obj: a map of msgpack-able values.
        max_frame: cap on the body, bytes.
        packer: a reusable ``msgpack.Packer(use_bin_type=True)`` (faster than a fresh one).

    Raises:
        LocalProtocolError: a value is not msgpack-able, or the body exceeds ``max_frame``.
    """
    try:
        body: bytes = (packer or msgpack.Packer(use_bin_type=True)).pack(obj)
    except (TypeError, ValueError, OverflowError) as exc:
        if packer is not None:
            packer.reset()
        raise LocalProtocolError(f"cannot encode: {exc}") from exc
    if len(body) > max_frame:
        raise LocalProtocolError(f"frame of {len(body)} bytes exceeds the cap of {max_frame}")
    return _LEN.pack(len(body)) + body


def _no_ext(code: int, data: bytes) -> Any:
    raise ValueError(f"extension type {code} is not used by the protocol")


# The timestamp extension (type -1) is decoded by msgpack itself, without the ext hook; its three
# encodings start with these bytes. They may also occur inside strings or binary data: only a body
# holding one is searched for a decoded Timestamp.
_TIMESTAMP_MARKS: Final = re.compile(b"\xd6\xff|\xd7\xff|\xc7\x0c\xff")


def _has_timestamp(obj: Any) -> bool:
    stack = [obj]
    while stack:
        item = stack.pop()
        kind = type(item)
        if kind is msgpack.Timestamp:
            return True
        if kind is dict:
            stack.extend(item.values())
        elif kind is list:
            stack.extend(item)
    return False


def unpack_map(body: bytes) -> dict[str, Any]:
    """Decode one frame body that must be a msgpack map.

    Map keys must be strings or byte strings (any other key type is refused by the decoder);
    extension types, the msgpack timestamp included, are refused.

    Raises:
        RemoteProtocolError: the body is not valid msgpack, not a map, or holds an extension type or
            a map key of another type.
    """
    try:
        obj = msgpack.unpackb(body, raw=False, ext_hook=_no_ext)
    except Exception as exc:  # noqa: BLE001 - msgpack raises several unrelated types for bad input
        raise RemoteProtocolError(f"bad msgpack body: {exc.__class__.__name__}: {str(exc)[:200]}") from None
    if type(obj) is not dict:
        raise RemoteProtocolError("frame body is not a msgpack map")
    if b"\xff" in body and _TIMESTAMP_MARKS.search(body) and _has_timestamp(obj):
        raise RemoteProtocolError("bad msgpack body: extension type -1 (timestamp) is not used by the protocol")
    return obj


class FrameReader:
    """Splits a received byte stream into frame bodies (sans-IO).

    Args:
        max_frame: cap on one body, bytes; a larger announced length is refused at once.

    Attributes:
        max_frame: the cap (may be raised after authentication).
    """

    __slots__ = ("_buf", "_eof", "_pos", "max_frame")

    def __init__(self, max_frame: int) -> None:
        self.max_frame = max_frame
        self._buf = bytearray()
        self._pos = 0
        self._eof = False

    @property
    def pending(self) -> int:
        """Bytes received but not yet returned as a body."""
        return len(self._buf) - self._pos

    @property
    def eof(self) -> bool:
        """True once the end of the stream was fed."""
        return self._eof

    def feed(self, data: bytes) -> None:
        """Add received bytes; ``b""`` means the peer closed its side."""
        if not data:
            self._eof = True
            return
        if self._pos and self._pos == len(self._buf):
            self._buf.clear()
            self._pos = 0
        self._buf += data

    def next_body(self) -> bytes | None:
        """Return the next complete body, or ``None`` if more bytes are needed.

        Raises:
            RemoteProtocolError: the announced length exceeds ``max_frame``, or the stream ended
                inside a frame.
        """
        buf = self._buf
        pos = self._pos
        avail = len(buf) - pos
        if avail < HEADER_BYTES:
            if self._eof and avail:
                raise RemoteProtocolError(f"connection closed inside a frame ({avail} bytes pending)")
            return None
        size = _LEN.unpack_from(buf, pos)[0]
        if size > self.max_frame:
            raise RemoteProtocolError(f"oversize frame: {size} bytes announced, cap is {self.max_frame}")
        end = pos + HEADER_BYTES + size
        if len(buf) < end:
            if self._eof:
                raise RemoteProtocolError(f"connection closed inside a frame ({avail} bytes pending)")
            return None
        body = bytes(buf[pos + HEADER_BYTES:end])
        if end == len(buf):
            buf.clear()
            self._pos = 0
        elif end > _COMPACT_AT:
            del buf[:end]
            self._pos = 0
        else:
            self._pos = end
        return body


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("connection closed by the peer")
        buf += chunk
    return bytes(buf)


def recv_frame(sock: socket.socket, max_frame: int) -> bytes:
    """Read one frame body from a blocking socket (for threads that own a plain socket).

    Raises:
        ConnectionError: the peer closed the connection.
        RemoteProtocolError: the announced length exceeds ``max_frame``.
        OSError: the socket failed or timed out.
    """
    (size,) = _LEN.unpack(_recv_exact(sock, HEADER_BYTES))
    if size > max_frame:
        raise RemoteProtocolError(f"oversize frame: {size} bytes announced, cap is {max_frame}")
    return _recv_exact(sock, size)
