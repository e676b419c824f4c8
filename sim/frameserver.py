"""The camera frame server of the simulated worlds: grab-latest frames over TCP, like a GigE camera.

Both testbeds serve their camera this way (the catching world its overhead camera, the mobile
world its downward camera with the beacon scans in each frame's ``meta``); the nodes' frame grabber
(:class:`services.devices.framegrabber.FrameClient`) reads them. The wire format is documented there.
"""

from __future__ import annotations

import functools
import socket
import threading
from typing import Any

import numpy as np

from services.devices.framegrabber import MAX_HEADER, Frame
from services.errors import ProtocolError
from services.protocol.framing import pack_map, recv_frame, unpack_map

__all__ = ["Frame", "FrameServer"]


class FrameServer:
    """Serves the latest camera frame over TCP (grab-latest), one thread per client.

    Args:
        host: address to listen on (127.0.0.1).
        port: TCP port, 0 for any free one (see :attr:`port` after :meth:`start`).
        info: a msgpack-able map served on request ``{"op": "info"}`` (the camera's data sheet and
            calibration: image size, homography, robot base pose...).

    A connection counts as a camera client (:attr:`client_count`, what the world waits for) from
    its first grab on: one that only asks for the info map (a probe, a node reading the
    calibration) changes nothing in the world.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, info: dict[str, Any] | None = None) -> None:
        self.host = host
        self.info = dict(info or {})
        self._requested_port = port
        self.port = 0
        self._cond = threading.Condition()
        self._latest: Frame | None = None
        self._closed = False
        self._sock: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._clients: list[socket.socket] = []  # every connection
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
        self._threads.append(th)
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
        for c in list(self._clients):
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        if self._sock is not None:
            self._sock.close()
        for th in self._threads:
            th.join(timeout=2.0)

    def _accept_loop(self) -> None:
        assert self._sock is not None
        while not self._closed:
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._clients.append(conn)
            th = threading.Thread(target=self._serve, args=(conn,), daemon=True)
            th.start()
            self._threads.append(th)

    def _newer(self, after: int) -> bool:
        return self._closed or (self._latest is not None and self._latest.seq > after)

    def _serve(self, conn: socket.socket) -> None:
        try:
            while not self._closed:
                req = unpack_map(recv_frame(conn, MAX_HEADER))
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
            if conn in self._clients:
                self._clients.remove(conn)
