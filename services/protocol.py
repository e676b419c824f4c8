"""The coordinator↔node wire protocol, sans-IO (no sockets, files or clocks inside).

docs/protocol.md is the normative specification; this module implements it. The design follows
h11 and websockets: a :class:`Connection` turns received bytes into message objects
(:meth:`Connection.receive_data`, :meth:`Connection.next_event`) and message objects into bytes
(:meth:`Connection.send`, :meth:`Connection.data_to_send`). The asyncio shells live in
``services.node`` and ``services.client``.

Rules of this file:

* A frame is a 4-byte big-endian unsigned length followed by that many bytes of one msgpack map.
  The length is checked against ``max_frame`` as soon as the 4 header bytes are in, before any of
  the body is buffered: an oversize header raises :class:`RemoteProtocolError` at once.
* Every map has a ``"type"`` key naming the message; the other keys are the fields of the message
  class registered for that name. Unknown extra keys are ignored (forward compatibility); a missing
  field, a field of the wrong type or an unknown type raises :class:`RemoteProtocolError`.
* Nothing but the handshake (and ``bye``) may pass before the connection is OPEN. The handshake is
  server ``hello`` → client ``auth`` → server ``welcome``; both MACs are HMAC-SHA256 with the shared
  key over a role label and both nonces (see :func:`handshake_mac`), so a MAC reflected back to its
  sender does not verify. MACs are compared with :func:`hmac.compare_digest`.
* Each message type may travel in one direction only (:data:`CLIENT_SENDS`, :data:`SERVER_SENDS`).
"""

from __future__ import annotations

import enum
import hmac
import os
from collections.abc import Iterator
from dataclasses import dataclass, field, fields
from hashlib import sha256
from operator import attrgetter
from struct import Struct
from typing import Any, ClassVar, Final

import msgpack

from coordinator.errors import (
    AuthenticationError,
    LocalProtocolError,
    RemoteProtocolError,
)

__all__ = [
    "CLIENT_SENDS",
    "DEFAULT_MAX_FRAME",
    "NONCE_BYTES",
    "PROTOCOL_VERSION",
    "SERVER_SENDS",
    "STATUSES",
    "Accepted",
    "Auth",
    "Bye",
    "Call",
    "Cancel",
    "Connection",
    "Event",
    "Feedback",
    "Hello",
    "Message",
    "Ping",
    "Pong",
    "Rejected",
    "Result",
    "Role",
    "State",
    "Subscribe",
    "Unsubscribe",
    "Welcome",
    "encode_frame",
    "handshake_mac",
]

PROTOCOL_VERSION: Final = 1
"""Version announced in ``hello``; a client refuses a server with a different version."""

DEFAULT_MAX_FRAME: Final = 16 * 1024 * 1024
"""Default cap on a frame body, in bytes (16 MiB)."""

NONCE_BYTES: Final = 16
"""Length of handshake nonces, in bytes."""

STATUSES: Final = frozenset({"success", "failure", "error"})
"""Statuses a result may carry (DESIGN.md §3)."""

_HEADER: Final = 4
_LEN: Final = Struct(">I")
_MAC_LABEL: Final = b"petrobot-auth-v1"


class Role(enum.Enum):
    """Which end of the TCP connection this endpoint is."""

    CLIENT = "client"
    """The side that connected (the coordinator, or a node reaching another node)."""
    SERVER = "server"
    """The node that accepted the connection."""


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


# --------------------------------------------------------------------------- messages


_NUMBER: Final = frozenset({int, float})


def _need(cond: bool, what: str) -> None:
    if not cond:
        raise RemoteProtocolError(what)


@dataclass(frozen=True, slots=True, kw_only=True)
class Message:
    """Base of every wire message. ``TYPE`` is the value of the ``"type"`` key on the wire."""

    TYPE: ClassVar[str] = ""

    def check(self) -> None:
        """Validate field types.

        Raises:
            RemoteProtocolError: a field has the wrong type or value.
        """


@dataclass(frozen=True, slots=True, kw_only=True)
class Hello(Message):
    """Server → client, first frame: the node's name, protocol version and a fresh nonce."""

    TYPE: ClassVar[str] = "hello"
    node: str
    version: int
    nonce: bytes

    def check(self) -> None:
        _need(isinstance(self.node, str), "hello.node must be a string")
        _need(type(self.version) is int, "hello.version must be an integer")
        _need(isinstance(self.nonce, bytes) and len(self.nonce) == NONCE_BYTES, "hello.nonce must be 16 bytes")


@dataclass(frozen=True, slots=True, kw_only=True)
class Auth(Message):
    """Client → server: the client's name, its nonce and its MAC (:func:`handshake_mac`)."""

    TYPE: ClassVar[str] = "auth"
    client: str
    nonce: bytes
    mac: bytes

    def check(self) -> None:
        _need(isinstance(self.client, str), "auth.client must be a string")
        _need(isinstance(self.nonce, bytes) and len(self.nonce) == NONCE_BYTES, "auth.nonce must be 16 bytes")
        _need(isinstance(self.mac, bytes), "auth.mac must be bytes")


@dataclass(frozen=True, slots=True, kw_only=True)
class Welcome(Message):
    """Server → client: the server's MAC, proving it holds the key too."""

    TYPE: ClassVar[str] = "welcome"
    mac: bytes

    def check(self) -> None:
        _need(isinstance(self.mac, bytes), "welcome.mac must be bytes")


@dataclass(frozen=True, slots=True, kw_only=True)
class Call(Message):
    """Client → server: run primitive action ``action`` with ``params``.

    ``id`` is made by the client (unique, e.g. a UUID); a repeated id is answered with the first
    result. ``deadline_ms`` is relative to the node receiving the call, ``None`` for no deadline.
    """

    TYPE: ClassVar[str] = "call"
    id: str
    action: str
    params: dict[str, Any] = field(default_factory=dict)
    deadline_ms: int | None = None

    def check(self) -> None:
        d = self.deadline_ms
        if (type(self.id) is str and self.id and type(self.action) is str and type(self.params) is dict
                and (d is None or (type(d) is int and d >= 0))):
            return  # the common case, in one test
        _need(isinstance(self.id, str) and self.id != "", "call.id must be a non-empty string")
        _need(isinstance(self.action, str), "call.action must be a string")
        _need(isinstance(self.params, dict), "call.params must be a map")
        _need(d is None or (isinstance(d, int) and d >= 0), "call.deadline_ms must be a non-negative integer or nil")


@dataclass(frozen=True, slots=True, kw_only=True)
class Accepted(Message):
    """Server → client: the call is running (or already ran: a result follows)."""

    TYPE: ClassVar[str] = "accepted"
    id: str

    def check(self) -> None:
        _need(isinstance(self.id, str), "accepted.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Rejected(Message):
    """Server → client: the call was not started; no result follows."""

    TYPE: ClassVar[str] = "rejected"
    id: str
    reason: str

    def check(self) -> None:
        _need(isinstance(self.id, str), "rejected.id must be a string")
        _need(isinstance(self.reason, str), "rejected.reason must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Feedback(Message):
    """Server → client: progress data from a running call."""

    TYPE: ClassVar[str] = "feedback"
    id: str
    data: Any = None

    def check(self) -> None:
        _need(isinstance(self.id, str), "feedback.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Result(Message):
    """Server → client: the end of a call.

    Attributes:
        status: ``"success"``, ``"failure"`` or ``"error"`` (DESIGN.md §3).
        outcome: optional named outcome, raised as the internal event ``int:<task>.<outcome>``.
        value: any msgpack value the action returns.
        cost: the action's own cost figure (paper §4, J = 1 - R + rho*C), or ``None``.
        wall_s: wall-clock duration on the node, seconds.
        cpu_s: CPU time spent by the node process during the call, seconds.
        reason: why an error happened (``"deadline"``, ``"cancelled"``, exception text), or ``None``.
    """

    TYPE: ClassVar[str] = "result"
    id: str
    status: str
    outcome: str | None = None
    value: Any = None
    cost: float | None = None
    wall_s: float = 0.0
    cpu_s: float = 0.0
    reason: str | None = None

    def check(self) -> None:
        if (type(self.id) is str and type(self.status) is str and self.status in STATUSES
                and (self.outcome is None or type(self.outcome) is str)
                and (self.cost is None or type(self.cost) in _NUMBER)
                and type(self.wall_s) in _NUMBER and type(self.cpu_s) in _NUMBER
                and (self.reason is None or type(self.reason) is str)):
            return  # the common case, in one test
        _need(isinstance(self.id, str), "result.id must be a string")
        _need(isinstance(self.status, str) and self.status in STATUSES,
              f"result.status must be one of {sorted(STATUSES)}")
        _need(self.outcome is None or isinstance(self.outcome, str), "result.outcome must be a string or nil")
        _need(self.cost is None or isinstance(self.cost, (int, float)), "result.cost must be a number or nil")
        _need(isinstance(self.wall_s, (int, float)), "result.wall_s must be a number")
        _need(isinstance(self.cpu_s, (int, float)), "result.cpu_s must be a number")
        _need(self.reason is None or isinstance(self.reason, str), "result.reason must be a string or nil")


@dataclass(frozen=True, slots=True, kw_only=True)
class Cancel(Message):
    """Client → server: cancel the running call ``id`` (ignored if unknown or finished)."""

    TYPE: ClassVar[str] = "cancel"
    id: str

    def check(self) -> None:
        _need(isinstance(self.id, str), "cancel.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Ping(Message):
    """Heartbeat request (either direction); answered by :class:`Pong` with the same ``seq``."""

    TYPE: ClassVar[str] = "ping"
    seq: int

    def check(self) -> None:
        _need(type(self.seq) is int, "ping.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Pong(Message):
    """Heartbeat answer."""

    TYPE: ClassVar[str] = "pong"
    seq: int

    def check(self) -> None:
        _need(type(self.seq) is int, "pong.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Subscribe(Message):
    """Client → server: send me every :class:`Event` published on ``topic``."""

    TYPE: ClassVar[str] = "subscribe"
    topic: str

    def check(self) -> None:
        _need(isinstance(self.topic, str), "subscribe.topic must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Unsubscribe(Message):
    """Client → server: stop sending ``topic``."""

    TYPE: ClassVar[str] = "unsubscribe"
    topic: str

    def check(self) -> None:
        _need(isinstance(self.topic, str), "unsubscribe.topic must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Event(Message):
    """Server → client: one external event (a pulse, DESIGN.md §3).

    Attributes:
        topic: event name without the ``ext:`` prefix.
        t: publisher's wall-clock time, seconds since the Unix epoch.
        seq: per-topic sequence number on the publishing node (gaps mean dropped events).
        data: any msgpack value.
    """

    TYPE: ClassVar[str] = "event"
    topic: str
    t: float
    seq: int
    data: Any = None

    def check(self) -> None:
        _need(isinstance(self.topic, str), "event.topic must be a string")
        _need(isinstance(self.t, (int, float)), "event.t must be a number")
        _need(type(self.seq) is int, "event.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Bye(Message):
    """Either direction: the sender is closing the connection, with a reason."""

    TYPE: ClassVar[str] = "bye"
    reason: str

    def check(self) -> None:
        _need(isinstance(self.reason, str), "bye.reason must be a string")


_TYPES: Final[dict[str, type[Message]]] = {
    cls.TYPE: cls
    for cls in (
        Hello, Auth, Welcome, Call, Accepted, Rejected, Feedback, Result,
        Cancel, Ping, Pong, Subscribe, Unsubscribe, Event, Bye,
    )
}
_FIELDS: Final[dict[type[Message], tuple[str, ...]]] = {
    cls: tuple(f.name for f in fields(cls)) for cls in _TYPES.values()
}
_REQUIRED: Final[dict[type[Message], frozenset[str]]] = {
    cls: frozenset(
        f.name for f in fields(cls)
        if f.default is f.default_factory  # both MISSING: no default at all
    )
    for cls in _TYPES.values()
}

CLIENT_SENDS: Final = frozenset({Call, Cancel, Ping, Pong, Subscribe, Unsubscribe, Bye})
"""Message classes a client may send once OPEN."""
SERVER_SENDS: Final = frozenset({Accepted, Rejected, Feedback, Result, Ping, Pong, Event, Bye})
"""Message classes a server may send once OPEN."""


# --------------------------------------------------------------------------- encoding


def handshake_mac(key: bytes, role: Role, server_nonce: bytes, client_nonce: bytes) -> bytes:
    """The MAC one side proves itself with.

    ``HMAC-SHA256(key, b"petrobot-auth-v1" || 0x00 || role || 0x00 || server_nonce || client_nonce)``
    with ``role`` the ASCII label of the *sender* (``b"client"`` or ``b"server"``).

    Args:
        key: the shared key.
        role: the side that sends this MAC.
        server_nonce: 16 bytes from ``hello``.
        client_nonce: 16 bytes from ``auth``.

    Returns:
        The 32-byte MAC.
    """
    msg = b"".join((_MAC_LABEL, b"\x00", role.value.encode(), b"\x00", server_nonce, client_nonce))
    return hmac.new(key, msg, sha256).digest()


_GETTERS: Final = {cls: (cls.TYPE, names, attrgetter(*names)) for cls, names in _FIELDS.items() if names}


def _to_map(msg: Message) -> dict[str, Any]:
    tag, names, getter = _GETTERS[type(msg)]
    values = getter(msg)
    if len(names) == 1:
        return {"type": tag, names[0]: values}
    out = dict(zip(names, values))
    out["type"] = tag
    return out


def encode_frame(msg: Message, max_frame: int = DEFAULT_MAX_FRAME, packer: msgpack.Packer | None = None) -> bytes:
    """Encode one message as a frame (4-byte big-endian length + msgpack map).

    Args:
        msg: the message.
        max_frame: cap on the body, bytes.
        packer: a reusable ``msgpack.Packer(use_bin_type=True)`` (faster than a fresh one per frame).

    Raises:
        LocalProtocolError: the encoded body exceeds ``max_frame`` or a value is not msgpack-able.
    """
    try:
        body: bytes = (packer or msgpack.Packer(use_bin_type=True)).pack(_to_map(msg))
    except (TypeError, ValueError, OverflowError) as exc:
        if packer is not None:
            packer.reset()
        raise LocalProtocolError(f"cannot encode {msg.TYPE}: {exc}") from exc
    if len(body) > max_frame:
        raise LocalProtocolError(f"{msg.TYPE} frame of {len(body)} bytes exceeds the cap of {max_frame}")
    return _LEN.pack(len(body)) + body


def _decode_body(body: bytes) -> Message:
    try:
        obj = msgpack.unpackb(body, raw=False)
    except Exception as exc:  # noqa: BLE001 - msgpack raises several unrelated types for bad input
        raise RemoteProtocolError(f"bad msgpack body: {exc.__class__.__name__}: {exc}") from None
    if type(obj) is not dict:
        raise RemoteProtocolError("frame body is not a msgpack map")
    tag = obj.pop("type", None)
    cls = _TYPES.get(tag) if isinstance(tag, str) else None
    if cls is None:
        raise RemoteProtocolError(f"unknown message type {tag!r}")
    try:
        msg = cls(**obj)
    except TypeError:
        # unknown extra keys (ignored) or missing fields (an error)
        missing = _REQUIRED[cls].difference(obj)
        if missing:
            raise RemoteProtocolError(f"{tag} lacks field(s) {', '.join(sorted(missing))}") from None
        names = _FIELDS[cls]
        msg = cls(**{k: v for k, v in obj.items() if k in names})
    msg.check()
    return msg


# --------------------------------------------------------------------------- connection


class Connection:
    """One endpoint of a connection: a state machine fed with bytes, producing messages.

    The server queues its ``hello`` at construction; the client answers ``hello`` with ``auth``
    and the server answers a valid ``auth`` with ``welcome`` by themselves (fetch these bytes with
    :meth:`data_to_send`). Handshake messages are still returned by :meth:`next_event`, after
    verification, so the shell learns the peer's name.

    Args:
        role: which end this is.
        key: the shared key (bytes, any length; 32 random bytes recommended).
        name: this endpoint's name (node name for a server, client name for a client).
        max_frame: cap on received and sent frame bodies, bytes.
        nonce: this side's 16-byte nonce; fresh random bytes when ``None`` (pass one in tests).
    """

    def __init__(
        self,
        role: Role,
        key: bytes,
        *,
        name: str,
        max_frame: int = DEFAULT_MAX_FRAME,
        nonce: bytes | None = None,
    ) -> None:
        self.role = role
        self.name = name
        self.max_frame = max_frame
        self.peer: str | None = None
        """The peer's name once known (from ``hello`` or ``auth``)."""
        self._key = key
        self._nonce = nonce if nonce is not None else os.urandom(NONCE_BYTES)
        if len(self._nonce) != NONCE_BYTES:
            raise LocalProtocolError(f"nonce must be {NONCE_BYTES} bytes")
        self._server_nonce = b""
        self._buf = bytearray()
        self._pos = 0
        self._out: list[bytes] = []
        self._packer = msgpack.Packer(use_bin_type=True)
        self._eof = False
        self._bye_sent = False
        self._may_send = CLIENT_SENDS if role is Role.CLIENT else SERVER_SENDS
        self._may_receive = SERVER_SENDS if role is Role.CLIENT else CLIENT_SENDS
        if role is Role.SERVER:
            self.state = State.AWAIT_AUTH
            self._server_nonce = self._nonce
            self._queue(Hello(node=name, version=PROTOCOL_VERSION, nonce=self._nonce))
        else:
            self.state = State.AWAIT_HELLO

    # ---- output

    def _queue(self, msg: Message) -> None:
        self._out.append(encode_frame(msg, self.max_frame, self._packer))

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
        self._out.append(encode_frame(msg, self.max_frame, self._packer))

    def data_to_send(self) -> bytes:
        """Return and forget all bytes queued for the peer (``b""`` if none)."""
        if not self._out:
            return b""
        out = self._out[0] if len(self._out) == 1 else b"".join(self._out)
        self._out.clear()
        return out

    # ---- input

    def receive_data(self, data: bytes) -> None:
        """Feed bytes received from the peer; ``b""`` means end of stream."""
        if not data:
            self._eof = True
            return
        if self._pos and self._pos == len(self._buf):
            self._buf.clear()
            self._pos = 0
        self._buf += data

    def next_event(self) -> Message | None:
        """Parse and return the next complete message, or ``None`` if more bytes are needed.

        Raises:
            RemoteProtocolError: oversize header, bad msgpack, unknown or misplaced message.
            AuthenticationError: the peer's MAC does not verify (wrong key).
        """
        buf = self._buf
        pos = self._pos
        avail = len(buf) - pos
        if avail < _HEADER:
            if self._eof:
                self._close_on_eof(avail)
            return None
        size = _LEN.unpack_from(buf, pos)[0]
        if size > self.max_frame:
            self.state = State.CLOSED
            raise RemoteProtocolError(f"oversize frame: {size} bytes announced, cap is {self.max_frame}")
        if avail < _HEADER + size:
            if self._eof:
                self._close_on_eof(avail)
            return None
        end = pos + _HEADER + size
        body = bytes(buf[pos + _HEADER:end])
        if end == len(buf):
            buf.clear()
            self._pos = 0
        elif end > 65536:
            del buf[:end]
            self._pos = 0
        else:
            self._pos = end
        try:
            msg = _decode_body(body)
            self._on_receive(msg)
        except RemoteProtocolError:
            self.state = State.CLOSED
            raise
        return msg

    def events(self) -> Iterator[Message]:
        """Iterate over every complete message buffered so far (see :meth:`next_event`)."""
        while (msg := self.next_event()) is not None:
            yield msg

    def _close_on_eof(self, avail: int) -> None:
        self.state = State.CLOSED
        if avail:
            raise RemoteProtocolError(f"connection closed inside a frame ({avail} bytes pending)")

    def _on_receive(self, msg: Message) -> None:
        kind = type(msg)
        state = self.state
        if state is State.OPEN:
            if kind not in self._may_receive:
                raise RemoteProtocolError(f"a {'server' if self.role is Role.CLIENT else 'client'} may not send {msg.TYPE}")
            if kind is Bye:
                self.state = State.CLOSED
            return
        if kind is Bye:
            self.state = State.CLOSED
            return
        if state is State.AWAIT_HELLO and isinstance(msg, Hello):
            if msg.version != PROTOCOL_VERSION:
                raise RemoteProtocolError(f"server speaks protocol version {msg.version}, we speak {PROTOCOL_VERSION}")
            self.peer = msg.node
            self._server_nonce = msg.nonce
            mac = handshake_mac(self._key, Role.CLIENT, msg.nonce, self._nonce)
            self._queue(Auth(client=self.name, nonce=self._nonce, mac=mac))
            self.state = State.AWAIT_WELCOME
            return
        if state is State.AWAIT_AUTH and isinstance(msg, Auth):
            expect = handshake_mac(self._key, Role.CLIENT, self._nonce, msg.nonce)
            if not hmac.compare_digest(expect, msg.mac):
                raise AuthenticationError(f"client {msg.client!r} failed authentication (wrong key?)")
            self.peer = msg.client
            self._queue(Welcome(mac=handshake_mac(self._key, Role.SERVER, self._nonce, msg.nonce)))
            self.state = State.OPEN
            return
        if state is State.AWAIT_WELCOME and isinstance(msg, Welcome):
            expect = handshake_mac(self._key, Role.SERVER, self._server_nonce, self._nonce)
            if not hmac.compare_digest(expect, msg.mac):
                raise AuthenticationError(f"node {self.peer!r} failed authentication (wrong key?)")
            self.state = State.OPEN
            return
        raise RemoteProtocolError(f"unexpected {msg.TYPE} in state {state.name}")
