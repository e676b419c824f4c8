"""The frame grabber: the vision node's link to its camera (paper section 6).

"A CCD camera above the table feeds the image-processing PC through a frame-grabber card." Here the
camera is a TCP frame server with grab-latest semantics (the simulated one is
:class:`sim.frameserver.FrameServer`; a GigE camera behind a small bridge serves the same protocol), and
:class:`FrameClient` is the grabber. Blocking sockets: the vision node runs it in a thread.

Wire format: every message is one frame of :mod:`services.protocol.framing` (4-byte big-endian
length, then a msgpack map of at most :data:`MAX_HEADER` bytes); a frame reply is followed by the
raw image bytes. Requests: ``{"op": "grab", "after": seq, "timeout": s}`` (the latest frame newer
than ``seq``, waiting up to ``timeout`` seconds) and ``{"op": "info"}`` (answered
``{"info": {...}}`` with the camera's data sheet and calibration). A frame reply is the header
``{"seq", "t", "t_wall", "width", "height", "channels", "nbytes"}`` (and ``"meta"``, a map, when the
server attaches one) followed by ``nbytes`` of BGR
uint8 (row-major); ``{"error": "timeout"}`` says no newer frame arrived in time.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from services.errors import ProtocolError
from services.protocol.framing import pack_map, recv_frame, unpack_map

__all__ = ["MAX_HEADER", "MAX_IMAGE_BYTES", "Frame", "FrameClient"]

MAX_HEADER: Final = 64 * 1024
"""Cap on a request or reply header, bytes."""

MAX_IMAGE_BYTES: Final = 64 * 1024 * 1024
"""Cap on one image, bytes."""


@dataclass(frozen=True, slots=True)
class Frame:
    """A camera frame.

    Attributes:
        seq: frame number, from 0.
        t: simulated time of the exposure, s.
        image: (H, W, 3) uint8 BGR.
        t_wall: wall-clock time (:func:`time.time`) the frame was captured, s (0 if not stamped);
            used to measure frame-to-set-point latency across processes.
        meta: optional msgpack-able map the server sends in the frame's header (``"meta"``), e.g.
            the mobile robot's latest beacon scan travelling with its camera frames.
    """

    seq: int
    t: float
    image: np.ndarray
    t_wall: float = 0.0
    meta: dict[str, Any] | None = None


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("camera connection closed")
        buf += chunk
    return bytes(buf)


def _recv_header(sock: socket.socket) -> dict[str, Any]:
    try:
        return unpack_map(recv_frame(sock, MAX_HEADER))
    except ProtocolError as exc:
        raise ConnectionError(f"camera server: {exc}") from None


class FrameClient:
    """Grabs the latest frame from a camera's frame server.

    Args:
        host, port: address of the frame server.
        connect_timeout: s.
    """

    def __init__(self, host: str, port: int, *, connect_timeout: float = 2.0) -> None:
        self._sock = socket.create_connection((host, port), timeout=connect_timeout)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def grab(self, after: int = -1, timeout: float = 1.0) -> Frame | None:
        """Return the latest frame newer than seq ``after``, waiting up to ``timeout`` s.

        Returns:
            The frame, or None if none newer arrived in time.

        Raises:
            ConnectionError: if the server closed the connection or sent something malformed.
        """
        self._sock.settimeout(timeout + 2.0)
        self._sock.sendall(pack_map({"op": "grab", "after": after, "timeout": timeout}, MAX_HEADER))
        hdr = _recv_header(self._sock)
        if "error" in hdr:
            if hdr["error"] == "timeout":
                return None
            raise ConnectionError(f"camera server: {hdr['error']}")
        h, w, ch, n = int(hdr["height"]), int(hdr["width"]), int(hdr["channels"]), int(hdr["nbytes"])
        if n != h * w * ch or n > MAX_IMAGE_BYTES:
            raise ConnectionError(f"camera frame of {n} bytes does not match {w}x{h}x{ch}")
        data = _recv_exact(self._sock, n)
        img = np.frombuffer(data, dtype=np.uint8).reshape(h, w, ch)
        meta = hdr.get("meta")
        return Frame(
            seq=int(hdr["seq"]), t=float(hdr["t"]), image=img, t_wall=float(hdr.get("t_wall", 0.0)),
            meta=meta if isinstance(meta, dict) else None,
        )

    def info(self, timeout: float = 2.0) -> dict[str, Any]:
        """The server's info map (camera data sheet and calibration).

        Raises:
            ConnectionError: if the server closed the connection or sent something malformed.
        """
        self._sock.settimeout(timeout)
        self._sock.sendall(pack_map({"op": "info"}, MAX_HEADER))
        msg = _recv_header(self._sock)
        info = msg.get("info")
        if not isinstance(info, dict):
            raise ConnectionError(f"camera server: no info in {msg!r}")
        return info

    def close(self) -> None:
        """Close the connection."""
        self._sock.close()
