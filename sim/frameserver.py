"""The camera frame server of the simulated worlds: grab-latest frames over TCP, like a GigE camera.

Both testbeds serve their camera this way (the catching world its overhead camera, the mobile
world its downward camera with the beacon scans in each frame's ``meta``); the nodes' frame grabber
(:class:`services.devices.framegrabber.FrameClient`) reads them. The wire format is documented there.
"""

from __future__ import annotations

import functools
import logging
import socket
import threading
import time
from typing import Any

import numpy as np

from services.devices.framegrabber import MAX_HEADER, Frame
from services.errors import ProtocolError
from services.protocol.framing import pack_map, recv_frame, unpack_map

__all__ = ["Frame", "FrameServer"]

log = logging.getLogger(__name__)


class FrameServer:
    """Serves the latest camera frame over TCP (grab-latest), one thread per client, at most
    ``max_clients`` clients at once.

    Args:
        host: address to listen on (127.0.0.1).
        port: TCP port, 0 for any free one (see :attr:`port` after :meth:`start`).
        info: a msgpack-able map served on request ``{"op": "info"}`` (the camera's data sheet and
            calibration: image size, homography, robot base pose...).
        max_clients: connections (and so serving threads) at most. A connection beyond it closes the
            one that has waited longest for its next request (a camera client asks again within a
            frame period: the idle ones go first); when every connection is inside a request, the new
            one is closed instead. The port is unauthenticated (a camera's): 500 idle connections
            cost ``max_clients`` threads, not 500, and never lock the nodes' grabbers out.
        idle_timeout: a connection that sends no request for this long is closed, s.

    A connection counts as a camera client (:attr:`client_count`, what the world waits for) from
    its first grab on: one that only asks for the info map (a probe, a node reading the
    calibration) changes nothing in the world.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, info: dict[str, Any] | None = None, *,
                 max_clients: int = 16, idle_timeout: float = 30.0) -> None:
        if max_clients < 1:
            raise ValueError(f"max_clients must be at least 1, not {max_clients}")
        self.host = host
        self.info = dict(info or {})
        self.max_clients = max_clients
        self.idle_timeout = idle_timeout
        self._requested_port = port
        self.port = 0
        self._cond = threading.Condition()
        self._latest: Frame | None = None
        self._closed = False
        self._sock: socket.socket | None = None
        self._accept_thread: threading.Thread | None = None
        self._clients: dict[socket.socket, threading.Thread] = {}  # every connection and its thread
        self._waiting: dict[socket.socket, float] = {}  # those waiting for a request: since when (monotonic)
        self._evicted = 0
        self._grabbing: set[socket.socket] = set()  # those that asked for a frame
        self._last_sent = -1

    def start(self) -> int:
        """Listen and serve in background threads; returns the port."""
        s = socket.create_server((self.host, self._requested_port))
        s.settimeout(0.2)
        self._sock = s
        self.port = s.getsockname()[1]
        th = threading.Thread(target=self._accept_loop, name="frame-server", daemon=True)
        th.start()
        self._accept_thread = th
        return self.port

    def publish(self, frame: Frame) -> None:
        """Make ``frame`` the latest; wakes clients waiting for a newer frame."""
        with self._cond:
            self._latest = frame
            self._cond.notify_all()

    @property
    def client_count(self) -> int:
        """Number of connected clients that take frames."""
        return len(self._grabbing)

    @property
    def connection_count(self) -> int:
        """Number of open connections (each has a serving thread), at most ``max_clients``."""
        with self._cond:
            return len(self._clients)

    def wait_sent(self, seq: int, timeout: float) -> bool:
        """Wait until frame ``seq`` (or a later one) has been sent to some client (lock-step pacing).

        Returns:
            True if it was sent within ``timeout`` s.
        """
        with self._cond:
            return self._cond.wait_for(lambda: self._closed or self._last_sent >= seq, timeout)

    def close(self) -> None:
        """Stop serving and close every connection."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
            clients = dict(self._clients)
        for c in clients:
            _shut(c)
        if self._sock is not None:
            self._sock.close()
        if self._accept_thread is not None:
            self._accept_thread.join(timeout=2.0)
        for th in clients.values():
            th.join(timeout=2.0)

    def _accept_loop(self) -> None:
        assert self._sock is not None
        while not self._closed:
            try:
                conn, peer = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            if not self._make_room(peer):
                _shut(conn)
                conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(self.idle_timeout)
            th = threading.Thread(target=self._serve, args=(conn,), name="frame-server-client", daemon=True)
            with self._cond:
                self._clients[conn] = th
                self._waiting[conn] = time.monotonic()
            th.start()

    def _make_room(self, peer: Any) -> bool:
        """Below ``max_clients`` connections, or one closed to make room (the one idle longest, its
        thread joined); False when every connection is inside a request."""
        with self._cond:
            if len(self._clients) < self.max_clients:
                return True
            if not self._waiting:
                log.warning("camera server: %d connections all busy, refusing %s", len(self._clients), peer)
                return False
            victim = min(self._waiting, key=self._waiting.__getitem__)
            del self._waiting[victim]
            thread = self._clients.get(victim)
            self._evicted += 1
            if self._evicted == 1 or self._evicted % 100 == 0:
                log.warning("camera server: %d connections, closed the one idle longest for %s (%d so far)",
                            len(self._clients), peer, self._evicted)
        _shut(victim)
        if thread is not None:
            thread.join(timeout=1.0)
        return True

    def _newer(self, after: int) -> bool:
        return self._closed or (self._latest is not None and self._latest.seq > after)

    def _serve(self, conn: socket.socket) -> None:
        try:
            while not self._closed:
                with self._cond:
                    self._waiting[conn] = time.monotonic()
                req = unpack_map(recv_frame(conn, MAX_HEADER))
                with self._cond:
                    if self._waiting.pop(conn, None) is None:
                        return  # closed to make room meanwhile
                if req.get("op") == "info":
                    conn.sendall(pack_map({"info": self.info}, MAX_HEADER))
                    continue
                if req.get("op") != "grab":
                    conn.sendall(pack_map({"error": f"unknown op {req.get('op')!r}"}, MAX_HEADER))
                    continue
                self._grabbing.add(conn)
                after = int(req.get("after", -1))
                timeout = min(float(req.get("timeout", 1.0)), 10.0)
                with self._cond:
                    self._cond.wait_for(functools.partial(self._newer, after), timeout=timeout)
                    frame = self._latest
                if frame is None or frame.seq <= after:
                    conn.sendall(pack_map({"error": "timeout"}, MAX_HEADER))
                    continue
                img = np.ascontiguousarray(frame.image)
                h, w = img.shape[:2]
                ch = img.shape[2] if img.ndim == 3 else 1
                header: dict[str, Any] = {"seq": frame.seq, "t": frame.t, "t_wall": frame.t_wall, "width": w, "height": h,
                          "channels": ch, "nbytes": img.nbytes}
                if frame.meta:
                    header["meta"] = frame.meta
                conn.sendall(pack_map(header, MAX_HEADER) + img.tobytes())
                with self._cond:
                    self._last_sent = max(self._last_sent, frame.seq)
                    self._cond.notify_all()
        except (ConnectionError, OSError, ValueError, ProtocolError):
            pass
        finally:
            conn.close()
            self._grabbing.discard(conn)
            with self._cond:
                self._clients.pop(conn, None)
                self._waiting.pop(conn, None)


def _shut(conn: socket.socket) -> None:
    try:
        conn.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
