"""One endpoint of a node-protocol connection: a state machine fed with bytes (sans-IO).

:class:`Connection` turns received bytes into message objects (:meth:`Connection.receive_data`,
:meth:`Connection.next_message`) and message objects into bytes (:meth:`Connection.send`,
:meth:`Connection.data_to_send`), as h11 and websockets do; it opens no socket and reads no clock.
The asyncio shell is :mod:`services.wire`.

Rules of this file:

* Nothing but the handshake (and ``bye``) may pass before the connection is OPEN. The handshake's
  legal moves are the table :data:`HANDSHAKE`: ``(state, message received) → next state``; any
  other message before OPEN is a :class:`~services.errors.RemoteProtocolError`.
* Once OPEN, each message type may travel in one direction only
  (:data:`~services.protocol.messages.CLIENT_SENDS`, :data:`~services.protocol.messages.SERVER_SENDS`).
* ``bye`` may be sent once in any state and moves the connection to CLOSED; so does receiving it,
  the end of the stream, or any protocol error.
* Before OPEN a frame may be at most ``handshake_max_frame`` bytes (a node: :data:`MAX_AUTH_FRAME`,
  4 KiB, what an ``auth`` needs; a client: :data:`MAX_WELCOME_FRAME`, 1 MiB, for a ``welcome``
  listing many actions); ``max_frame`` applies once OPEN. An unauthenticated peer cannot make
  this endpoint buffer more than that.
"""

from __future__ import annotations

import enum
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Final

import msgpack

from services.errors import AuthenticationError, LocalProtocolError, RemoteProtocolError
from services.protocol.framing import FrameReader, pack_map, unpack_map
from services.protocol.handshake import (
    PROTOCOL_VERSION,
    Role,
    handshake_mac,
    macs_equal,
)
from services.protocol.messages import (
    CLIENT_SENDS,
    NONCE_BYTES,
    SERVER_SENDS,
    Auth,
    Bye,
    Hello,
    Message,
    Welcome,
    from_map,
    to_map,
)
from services.protocol.untrusted import shown

__all__ = ["DEFAULT_MAX_FRAME", "HANDSHAKE", "MAX_AUTH_FRAME", "MAX_WELCOME_FRAME", "Connection", "Offer", "State"]

DEFAULT_MAX_FRAME: Final = 16 * 1024 * 1024
"""Default cap on a frame body, in bytes (16 MiB)."""
MAX_AUTH_FRAME: Final = 4096
"""A node's cap on a frame body before the connection is OPEN, bytes: an ``auth`` (or ``bye``)."""
MAX_WELCOME_FRAME: Final = 1024 * 1024
"""A client's cap on a frame body before the connection is OPEN, bytes: a ``welcome`` with its
list of actions."""


@dataclass(frozen=True, slots=True)
class Offer:
    """What a node tells an authenticated client in ``welcome`` besides its MAC (docs/protocol.md §3).

    Attributes:
        actions: the primitive actions the node offers, sorted.
        location: hex SHA-256 of the services.toml bytes the node loaded, or ``None``.
        location_changed: the node's services.toml on disk differs from what it loaded.
    """

    actions: tuple[str, ...] | None = None
    location: str | None = None
    location_changed: bool = False


class State(enum.Enum):
    """Connection states (docs/protocol.md, "States")."""

    AWAIT_HELLO = "await_hello"
    """Client: connected, waiting for the server's ``hello``."""
    AWAIT_AUTH = "await_auth"
    """Server: ``hello`` sent, waiting for the client's ``auth``."""
    AWAIT_WELCOME = "await_welcome"
    """Client: ``auth`` sent, waiting for the server's ``welcome``."""
    OPEN = "open"
    """Both sides authenticated; calls, events and heartbeats may flow."""
    CLOSED = "closed"
    """``bye`` sent or received, end of stream seen, or a protocol error happened."""


HANDSHAKE: Final[dict[tuple[State, type[Message]], State]] = {
    (State.AWAIT_HELLO, Hello): State.AWAIT_WELCOME,  # client: verify version, answer with auth
    (State.AWAIT_AUTH, Auth): State.OPEN,  # server: verify the client's MAC, answer with welcome
    (State.AWAIT_WELCOME, Welcome): State.OPEN,  # client: verify the server's MAC
}
"""The handshake: ``(state, message received) → next state``; anything else before OPEN is illegal."""


class Connection:
    """One endpoint of a connection: a state machine fed with bytes, producing messages.

    The server queues its ``hello`` at construction; the client answers ``hello`` with ``auth``
    and the server answers a valid ``auth`` with ``welcome`` by themselves (fetch these bytes with
    :meth:`data_to_send`). Handshake messages are still returned by :meth:`next_message`, after
    verification, so the shell learns the peer's name.

    Args:
        role: which end this is.
        key: the shared key (bytes; 32 random bytes recommended).
        name: this endpoint's name (node name for a server, client name for a client).
        node: client only, required: the name of the node this client means to reach (its
            services.toml name). The server's ``hello`` must carry that name, and both MACs cover
            it: a client never talks to a node under another name, and its MAC verifies at no
            other node (docs/protocol.md §3, "Threat model").
        max_frame: cap on received and sent frame bodies once OPEN, bytes.
        nonce: this side's 16-byte nonce; fresh random bytes when ``None`` (pass one in tests).
        handshake_max_frame: cap on received frame bodies before OPEN, bytes (default
            :data:`MAX_AUTH_FRAME` for a server, :data:`MAX_WELCOME_FRAME` for a client).
        previous_keys: server only: older keys still accepted in ``auth`` while a new key is rolled
            out (docs/protocol.md §3, "Key rotation"); ``key`` is tried first.
        offer: server only: called once the client is authenticated, for the contents of ``welcome``.

    Attributes:
        binding: TLS channel binding covered by both MACs (set it before the handshake messages
            are processed; empty on plain TCP).
        welcome: client: the server's ``welcome`` once OPEN, else ``None``.
        key_index: server: which key verified the client (0 = ``key``, 1.. = ``previous_keys``).

    Raises:
        LocalProtocolError: the nonce is not 16 bytes, or a client is given no ``node``.
    """

    def __init__(
        self,
        role: Role,
        key: bytes,
        *,
        name: str,
        node: str | None = None,
        max_frame: int = DEFAULT_MAX_FRAME,
        nonce: bytes | None = None,
        handshake_max_frame: int | None = None,
        previous_keys: Sequence[bytes] = (),
        offer: Callable[[], Offer] | None = None,
    ) -> None:
        self.role = role
        self.name = name
        self.max_frame = max_frame
        self.peer: str | None = None
        """The peer's name once known (from ``hello`` or ``auth``)."""
        if role is Role.CLIENT and node is None:
            raise LocalProtocolError("a client connection needs the name of the node it means to reach")
        self._node: str = node if node is not None and role is Role.CLIENT else name
        self.binding = b""
        self.welcome: Welcome | None = None
        self.key_index = 0
        self._keys = (key, *previous_keys)
        self._key = key
        self._offer = offer
        self._nonce = nonce if nonce is not None else os.urandom(NONCE_BYTES)
        if len(self._nonce) != NONCE_BYTES:
            raise LocalProtocolError(f"nonce must be {NONCE_BYTES} bytes")
        self._server_nonce = b""
        if handshake_max_frame is None:
            handshake_max_frame = MAX_WELCOME_FRAME if role is Role.CLIENT else MAX_AUTH_FRAME
        self._reader = FrameReader(min(max_frame, handshake_max_frame))
        self._out: list[bytes] = []
        self._out_bytes = 0
        self._packer = msgpack.Packer(use_bin_type=True)
        self._bye_sent = False
        self._may_send = CLIENT_SENDS if role is Role.CLIENT else SERVER_SENDS
        self._may_receive = SERVER_SENDS if role is Role.CLIENT else CLIENT_SENDS
        self.state: State
        if role is Role.SERVER:
            self.state = State.AWAIT_AUTH
            self._server_nonce = self._nonce
            self._queue(Hello(node=name, version=PROTOCOL_VERSION, nonce=self._nonce))
        else:
            self.state = State.AWAIT_HELLO

    # ---- output

    def _queue(self, msg: Message) -> None:
        try:
            data = pack_map(to_map(msg), self.max_frame, self._packer)
        except LocalProtocolError as exc:
            raise LocalProtocolError(f"{msg.TYPE}: {exc}") from None
        self._out.append(data)
        self._out_bytes += len(data)

    @property
    def bytes_to_send(self) -> int:
        """Bytes queued for the peer and not yet collected by :meth:`data_to_send`."""
        return self._out_bytes

    def send(self, msg: Message) -> None:
        """Queue ``msg`` for sending; collect the bytes with :meth:`data_to_send`.

        A :class:`Bye` may be sent once in any state (also after a protocol error, to tell the
        peer why); it moves the connection to CLOSED.

        Raises:
            LocalProtocolError: the state or direction forbids ``msg``, or it cannot be encoded.
        """
        if type(msg) is Bye:
            if self._bye_sent:
                raise LocalProtocolError("bye already sent")
            self._bye_sent = True
            self._queue(msg)
            self.state = State.CLOSED
            return
        if self.state is not State.OPEN:
            raise LocalProtocolError(f"cannot send {msg.TYPE} in state {self.state.name}")
        if type(msg) not in self._may_send:
            raise LocalProtocolError(f"a {self.role.value} may not send {msg.TYPE}")
        self._queue(msg)

    def data_to_send(self) -> bytes:
        """Return and forget all bytes queued for the peer (``b""`` if none)."""
        if not self._out:
            return b""
        out = self._out[0] if len(self._out) == 1 else b"".join(self._out)
        self._out.clear()
        self._out_bytes = 0
        return out

    # ---- input

    def receive_data(self, data: bytes) -> None:
        """Feed bytes received from the peer; ``b""`` means end of stream."""
        self._reader.feed(data)

    def next_message(self) -> Message | None:
        """Parse and return the next complete message, or ``None`` if more bytes are needed.

        Raises:
            RemoteProtocolError: oversize header, bad msgpack, unknown or misplaced message, end
                of stream inside a frame.
            AuthenticationError: the peer's MAC does not verify (wrong key).
        """
        try:
            body = self._reader.next_body()
            if body is None:
                if self._reader.eof:
                    self.state = State.CLOSED
                return None
            msg = from_map(unpack_map(body))
            self._on_receive(msg)
        except RemoteProtocolError:
            self.state = State.CLOSED
            raise
        return msg

    def messages(self) -> Iterator[Message]:
        """Iterate over every complete message buffered so far (see :meth:`next_message`)."""
        while (msg := self.next_message()) is not None:
            yield msg

    def _on_receive(self, msg: Message) -> None:
        kind = type(msg)
        state = self.state
        if state is State.OPEN:
            if kind not in self._may_receive:
                sender = "server" if self.role is Role.CLIENT else "client"
                raise RemoteProtocolError(f"a {sender} may not send {msg.TYPE}")
            if kind is Bye:
                self.state = State.CLOSED
            return
        if kind is Bye:
            self.state = State.CLOSED
            return
        after = HANDSHAKE.get((state, kind))
        if after is None:
            raise RemoteProtocolError(f"unexpected {msg.TYPE} in state {state.name}")
        if isinstance(msg, Hello):
            if msg.version != PROTOCOL_VERSION:
                raise RemoteProtocolError(f"server speaks protocol version {shown(msg.version)}, "
                                          f"we speak {PROTOCOL_VERSION}")
            if msg.node != self._node:
                raise AuthenticationError(f"the node here says it is {shown(msg.node)}, not {self._node!r}: "
                                          "refusing it (another process on that node's port, or services.toml "
                                          "disagrees with the node)")
            self.peer = msg.node
            self._server_nonce = msg.nonce
            mac = handshake_mac(self._key, Role.CLIENT, client=self.name, server=self._node,
                                server_nonce=msg.nonce, client_nonce=self._nonce, binding=self.binding)
            self._queue(Auth(client=self.name, nonce=self._nonce, mac=mac))
        elif isinstance(msg, Auth):
            self._verify_auth(msg)
        elif isinstance(msg, Welcome):
            expect = handshake_mac(self._key, Role.SERVER, client=self.name, server=self._node,
                                   server_nonce=self._server_nonce, client_nonce=self._nonce, binding=self.binding)
            if not macs_equal(expect, msg.mac):
                raise AuthenticationError(f"node {shown(self.peer)} failed authentication (wrong key?)")
            self.welcome = msg
        self.state = after
        if after is State.OPEN:
            self._reader.max_frame = self.max_frame

    def _verify_auth(self, msg: Auth) -> None:
        # every key is tried (each comparison in constant time), so the time taken does not say which matched
        matched = -1
        for i, key in enumerate(self._keys):
            expect = handshake_mac(key, Role.CLIENT, client=msg.client, server=self.name, server_nonce=self._nonce,
                                   client_nonce=msg.nonce, binding=self.binding)
            if macs_equal(expect, msg.mac) and matched < 0:
                matched = i
        if matched < 0:
            raise AuthenticationError(f"client {shown(msg.client)} failed authentication (wrong key?)")
        self.peer = msg.client
        self.key_index = matched
        key = self._keys[matched]
        offer = self._offer() if self._offer is not None else Offer()
        self._queue(Welcome(
            mac=handshake_mac(key, Role.SERVER, client=msg.client, server=self.name, server_nonce=self._nonce,
                              client_nonce=msg.nonce, binding=self.binding),
            actions=list(offer.actions) if offer.actions is not None else None,
            location=offer.location, location_changed=offer.location_changed,
        ))
