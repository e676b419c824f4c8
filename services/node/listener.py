"""The node's listening socket and its accept loop, with connection caps and no file-descriptor exhaustion.

asyncio's own server accepts every connection and, when the process runs out of file descriptors,
logs an error and stops accepting for a second, for everyone. This listener accepts by itself so
that each connection passes the node's :class:`~services.node.guard.ConnectionGuard` and
:class:`~services.node.guard.AuthThrottle` first, and so that running out of descriptors hurts
only unauthenticated peers:

* an address throttled for failed logins has its new connections closed at once (a ``bye`` with
  reason ``auth_throttled`` on plain TCP), before any handshake work, unless a connection from it
  logged in recently (another process of that host has the key); so has an address opening
  connections faster than its rate, and any connection from an address that never logged in past
  the total rate of those (``bye{"overloaded"}``);
* an accepted connection may push out the oldest pending ones (the guard's caps);
* if ``accept`` fails for want of descriptors (``EMFILE``, ``ENFILE``, ``ENOBUFS``, ``ENOMEM``),
  the oldest pending connection is closed to make room; if none is pending, a spare descriptor
  held for the purpose is released, the waiting connection accepted and closed at once, and the
  spare taken again, so that the listening socket does not stay readable and spin. Authenticated
  connections are never closed for this.

Lines about refused and dropped connections go through the node's rate-limited log.
"""

from __future__ import annotations

import asyncio
import errno
import functools
import logging
import os
import socket
import ssl
from collections.abc import Callable
from typing import Final

from services.node.guard import AuthThrottle, ConnectionGuard
from services.node.logs import LogLimiter
from services.node.peer import Peer
from services.protocol import Bye, encode_frame

__all__ = ["Listener"]

log = logging.getLogger("petrobot.node")

_OUT_OF_FDS: Final = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
_ACCEPTS_PER_WAKEUP: Final = 128  # refusals are cheap; admissions are rate-limited per address
_BACKLOG: Final = 1024
_THROTTLED_BYE: Final = encode_frame(Bye(reason="auth_throttled"))
_OVERLOADED_BYE: Final = encode_frame(Bye(reason="overloaded"))


def _same(peer: Peer) -> Peer:
    return peer


class Listener:
    """Accepts connections for a node (see the module docstring).

    Args:
        loop: the running loop.
        host: address to listen on.
        port: TCP port (0: any free port; :attr:`port` says which).
        make_peer: builds the protocol object of an accepted connection from ``(host, loop time)``.
        guard: the connection caps.
        throttle: failed logins per address.
        limited: the rate-limited log.
        ssl_context: TLS context, or ``None`` for plain TCP.

    Raises:
        OSError: the address cannot be bound (in use, not an address of this host).
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        host: str,
        port: int,
        make_peer: Callable[[str, float], Peer],
        guard: ConnectionGuard[Peer],
        throttle: AuthThrottle,
        limited: LogLimiter,
        ssl_context: ssl.SSLContext | None = None,
    ) -> None:
        self._loop = loop
        self._make_peer = make_peer
        self.guard = guard
        self.throttle = throttle
        self._limited = limited
        self._ssl = ssl_context
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, kind, proto, _, addr = infos[0]
        sock = socket.socket(family, kind, proto)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(addr)
            sock.listen(_BACKLOG)
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        self._sock = sock
        self.port: int = sock.getsockname()[1]
        self._spare: int | None = os.open(os.devnull, os.O_RDONLY)
        self._paused = False
        loop.add_reader(sock.fileno(), self._accept_ready)

    def close(self) -> None:
        """Stop accepting and close the listening socket (idempotent)."""
        if self._sock.fileno() >= 0:
            if not self._paused:
                self._loop.remove_reader(self._sock.fileno())
            self._sock.close()
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None

    def _accept_ready(self) -> None:
        loop = self._loop
        for _ in range(_ACCEPTS_PER_WAKEUP):
            try:
                sock, addr = self._sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if exc.errno in _OUT_OF_FDS:
                    self._out_of_fds(exc)
                else:
                    self._limited.log(logging.WARNING, "accept", "accept failed: %s", exc)
                return
            host = addr[0]
            now = loop.time()
            guard = self.guard
            if self.throttle.throttled(host, now) and not guard.known(host, now):
                self._limited.log(logging.WARNING, ("throttled", host), "refused a connection from %s: "
                                  "too many failed logins from that address", host)
                self._refuse(sock, _THROTTLED_BYE)
                continue
            if not guard.may_accept(host, now):
                self._limited.log(logging.WARNING, ("accept rate", host), "refused a connection from %s: "
                                  "more than %g new connections a second from that address", host,
                                  guard.caps.accepts_per_s)
                self._refuse(sock, _OVERLOADED_BYE)
                continue
            if not guard.within_total(host, now):
                self._limited.log(logging.WARNING, "new connections", "refused a connection from %s: more than %g "
                                  "new connections a second from addresses that never logged in", host,
                                  guard.caps.new_per_s)
                self._refuse(sock, _OVERLOADED_BYE)
                continue
            peer = self._make_peer(host, now)
            for old in self.guard.accept(peer, host, now):
                self._limited.log(logging.WARNING, ("pending cap", old.peer_host),
                                  "too many unauthenticated connections: closed the oldest, from %s",
                                  old.peer_host)
                old.evict("overloaded")
            sock.setblocking(False)
            task: asyncio.Task[object] = loop.create_task(loop.connect_accepted_socket(
                functools.partial(_same, peer), sock, ssl=self._ssl,
                ssl_handshake_timeout=self.guard.caps.handshake_timeout_s if self._ssl else None))
            peer.connecting = task
            task.add_done_callback(functools.partial(self._connected, peer=peer))

    def _connected(self, task: asyncio.Task[object], *, peer: Peer) -> None:
        peer.connecting = None
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:  # the TLS handshake failed or the peer went away first
            self._limited.log(logging.INFO, ("tls", peer.peer_host), "connection from %s failed: %s",
                              peer.peer_host, exc)
            peer.connect_failed()

    def _refuse(self, sock: socket.socket, bye: bytes) -> None:
        if self._ssl is None:
            sock.setblocking(False)
            try:
                sock.send(bye)
            except OSError:
                pass
        sock.close()

    def _out_of_fds(self, exc: OSError) -> None:
        pending = self.guard.oldest_pending()
        if pending is not None:
            self._limited.log(logging.WARNING, "fds", "out of file descriptors (%s): closed the oldest "
                              "unauthenticated connection, from %s", exc.strerror, pending.peer_host)
            pending.evict("overloaded")
            return
        self._limited.log(logging.WARNING, "fds", "out of file descriptors (%s): refusing new connections "
                          "while they last; authenticated connections are kept", exc.strerror)
        if self._spare is not None:
            os.close(self._spare)
            self._spare = None
            try:
                sock, _ = self._sock.accept()
                sock.close()
            except OSError:
                pass
            try:
                self._spare = os.open(os.devnull, os.O_RDONLY)
            except OSError:
                self._spare = None
        if self._spare is None and not self._paused:  # nothing to give back: listen again shortly
            self._paused = True
            self._loop.remove_reader(self._sock.fileno())
            self._loop.call_later(0.1, self._resume)

    def _resume(self) -> None:
        self._paused = False
        if self._sock.fileno() >= 0:
            if self._spare is None:
                try:
                    self._spare = os.open(os.devnull, os.O_RDONLY)
                except OSError:
                    pass
            self._loop.add_reader(self._sock.fileno(), self._accept_ready)
