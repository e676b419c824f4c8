"""The messages of the coordinator↔node protocol (docs/protocol.md §4–6) and their map codec.

Every message is a small frozen, slotted dataclass with keyword-only fields; ``TYPE`` is the value of
the ``"type"`` key on the wire, the other keys are the fields. :func:`to_map` and :func:`from_map`
turn messages into msgpack maps and back; :func:`from_map` validates every field (the one place a
received message is checked) and raises :class:`~services.errors.RemoteProtocolError` on a missing
field, a field of the wrong type or an unknown type. Unknown extra keys are ignored (forward
compatibility). Each message type may travel in one direction only (:data:`CLIENT_SENDS`,
:data:`SERVER_SENDS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from operator import attrgetter
from typing import Any, ClassVar, Final

from services.errors import ActionError, RemoteProtocolError
from services.protocol.handshake import MAC_BYTES
from services.protocol.untrusted import shown
from services.results import ActionResult

__all__ = [
    "CLIENT_SENDS",
    "NONCE_BYTES",
    "SERVER_SENDS",
    "Accepted",
    "Auth",
    "Bye",
    "Call",
    "Cancel",
    "Event",
    "Feedback",
    "Hello",
    "Message",
    "Ping",
    "Pong",
    "Query",
    "Rejected",
    "Result",
    "Subscribe",
    "Unsubscribe",
    "Welcome",
    "from_map",
    "to_map",
]

NONCE_BYTES: Final = 16
"""Length of handshake nonces, in bytes."""


def _int(value: Any) -> bool:
    """An integer and not a boolean (msgpack ``true`` decodes as a Python ``bool``, a subclass of ``int``)."""
    return type(value) is int


def _number(value: Any) -> bool:
    """An integer or a float, not a boolean."""
    return type(value) is int or type(value) is float


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
        _need(type(self.node) is str, "hello.node must be a string")
        _need(_int(self.version), "hello.version must be an integer")
        _need(type(self.nonce) is bytes and len(self.nonce) == NONCE_BYTES, "hello.nonce must be 16 bytes")


@dataclass(frozen=True, slots=True, kw_only=True)
class Auth(Message):
    """Client → server: the client's name, its nonce and its MAC (:func:`handshake_mac`)."""

    TYPE: ClassVar[str] = "auth"
    client: str
    nonce: bytes
    mac: bytes

    def check(self) -> None:
        _need(type(self.client) is str, "auth.client must be a string")
        _need(type(self.nonce) is bytes and len(self.nonce) == NONCE_BYTES, "auth.nonce must be 16 bytes")
        _need(type(self.mac) is bytes and len(self.mac) == MAC_BYTES, "auth.mac must be 32 bytes")


@dataclass(frozen=True, slots=True, kw_only=True)
class Welcome(Message):
    """Server → client: the server's MAC, proving it holds the key too, and what the node serves.

    Attributes:
        mac: the server's MAC (:func:`~services.protocol.handshake.handshake_mac`).
        actions: the primitive actions this node offers, sorted; ``None`` if the node does not say.
        location: hex SHA-256 of the services.toml bytes the node loaded, or ``None``.
        location_changed: the node's services.toml on disk differs from what it loaded.
    """

    TYPE: ClassVar[str] = "welcome"
    mac: bytes
    actions: list[str] | None = None
    location: str | None = None
    location_changed: bool = False

    def check(self) -> None:
        _need(type(self.mac) is bytes and len(self.mac) == MAC_BYTES, "welcome.mac must be 32 bytes")
        acts = self.actions
        _need(acts is None or (type(acts) is list and all(type(a) is str for a in acts)),
              "welcome.actions must be a list of strings or nil")
        _need(self.location is None or type(self.location) is str, "welcome.location must be a string or nil")
        _need(type(self.location_changed) is bool, "welcome.location_changed must be a boolean")


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
        _need(type(self.id) is str and self.id != "", "call.id must be a non-empty string")
        _need(type(self.action) is str, "call.action must be a string")
        _need(type(self.params) is dict, "call.params must be a map")
        _need(d is None or (_int(d) and d >= 0), "call.deadline_ms must be a non-negative integer or nil")


@dataclass(frozen=True, slots=True, kw_only=True)
class Accepted(Message):
    """Server → client: the call is running (or already ran: a result follows)."""

    TYPE: ClassVar[str] = "accepted"
    id: str

    def check(self) -> None:
        _need(type(self.id) is str, "accepted.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Rejected(Message):
    """Server → client: the call was not started; no result follows."""

    TYPE: ClassVar[str] = "rejected"
    id: str
    reason: str

    def check(self) -> None:
        _need(type(self.id) is str, "rejected.id must be a string")
        _need(type(self.reason) is str, "rejected.reason must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Feedback(Message):
    """Server → client: progress data from a running call."""

    TYPE: ClassVar[str] = "feedback"
    id: str
    data: Any = None

    def check(self) -> None:
        _need(type(self.id) is str, "feedback.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Result(Message):
    """Server → client: the end of a call, carrying its :class:`~services.results.ActionResult`.

    On the wire the record's fields sit beside ``id`` in one flat map (``status``, ``outcome``,
    ``value``, ``cost``, ``wall_s``, ``cpu_s``, ``reason``; docs/protocol.md §5).
    """

    TYPE: ClassVar[str] = "result"
    id: str
    result: ActionResult

    def check(self) -> None:
        _need(type(self.id) is str, "result.id must be a string")
        _need(type(self.result) is ActionResult, "result must carry an ActionResult")


@dataclass(frozen=True, slots=True, kw_only=True)
class Cancel(Message):
    """Client → server: cancel the running call ``id`` (ignored if unknown or finished)."""

    TYPE: ClassVar[str] = "cancel"
    id: str

    def check(self) -> None:
        _need(type(self.id) is str, "cancel.id must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Query(Message):
    """Client → server: what became of call ``id``? Never starts anything (docs/protocol.md §5).

    Answered like a repeated ``call``: ``accepted`` and the kept ``result``, or ``accepted`` and the
    result when the running call ends (the querier joins it), or ``rejected{reason: "unknown_call"}``.
    """

    TYPE: ClassVar[str] = "query"
    id: str

    def check(self) -> None:
        _need(type(self.id) is str and self.id != "", "query.id must be a non-empty string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Ping(Message):
    """Heartbeat request (either direction); answered by :class:`Pong` with the same ``seq``."""

    TYPE: ClassVar[str] = "ping"
    seq: int

    def check(self) -> None:
        _need(_int(self.seq), "ping.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Pong(Message):
    """Heartbeat answer."""

    TYPE: ClassVar[str] = "pong"
    seq: int

    def check(self) -> None:
        _need(_int(self.seq), "pong.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Subscribe(Message):
    """Client → server: send me every :class:`Event` published on ``topic``."""

    TYPE: ClassVar[str] = "subscribe"
    topic: str

    def check(self) -> None:
        _need(type(self.topic) is str, "subscribe.topic must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Unsubscribe(Message):
    """Client → server: stop sending ``topic``."""

    TYPE: ClassVar[str] = "unsubscribe"
    topic: str

    def check(self) -> None:
        _need(type(self.topic) is str, "unsubscribe.topic must be a string")


@dataclass(frozen=True, slots=True, kw_only=True)
class Event(Message):
    """Server → client: one external event (a pulse: docs/protocol.md §9; the paper's external events).

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
        _need(type(self.topic) is str, "event.topic must be a string")
        _need(_number(self.t), "event.t must be a number")
        _need(_int(self.seq), "event.seq must be an integer")


@dataclass(frozen=True, slots=True, kw_only=True)
class Bye(Message):
    """Either direction: the sender is closing the connection, with a reason."""

    TYPE: ClassVar[str] = "bye"
    reason: str

    def check(self) -> None:
        _need(type(self.reason) is str, "bye.reason must be a string")


_TYPES: Final[dict[str, type[Message]]] = {
    cls.TYPE: cls
    for cls in (
        Hello, Auth, Welcome, Call, Accepted, Rejected, Feedback, Result,
        Cancel, Query, Ping, Pong, Subscribe, Unsubscribe, Event, Bye,
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

CLIENT_SENDS: Final = frozenset({Call, Cancel, Query, Ping, Pong, Subscribe, Unsubscribe, Bye})
"""Message classes a client may send once OPEN."""
SERVER_SENDS: Final = frozenset({Accepted, Rejected, Feedback, Result, Ping, Pong, Event, Bye})
"""Message classes a server may send once OPEN."""


_RESULT_FIELDS: Final = ("status", "outcome", "value", "cost", "wall_s", "cpu_s", "reason")
_RESULT_GET: Final = attrgetter(*_RESULT_FIELDS)
_GETTERS: Final = {cls: (cls.TYPE, names, attrgetter(*names)) for cls, names in _FIELDS.items()
                   if names and cls is not Result}


def to_map(msg: Message) -> dict[str, Any]:
    """The wire map of ``msg`` (``{"type": TYPE, field: value...}``)."""
    if type(msg) is Result:
        r = msg.result
        out = dict(zip(_RESULT_FIELDS, _RESULT_GET(r)))
        out["status"] = r.status.value
        out["id"] = msg.id
        out["type"] = "result"
        return out
    tag, names, getter = _GETTERS[type(msg)]
    values = getter(msg)
    if len(names) == 1:
        return {"type": tag, names[0]: values}
    out = dict(zip(names, values))
    out["type"] = tag
    return out


def _result_from_map(obj: dict[str, Any]) -> Result:
    cid = obj.get("id")
    if type(cid) is not str:
        raise RemoteProtocolError("result.id must be a string")
    _need("status" in obj, "result lacks field(s) status")
    kw = {k: obj[k] for k in _RESULT_FIELDS if k in obj and obj[k] is not None}
    _need(type(kw.get("status")) is str, "result.status must be a string")
    try:
        record = ActionResult(**kw)
    except (ActionError, TypeError) as exc:
        raise RemoteProtocolError(f"bad result: {shown(str(exc))}") from None
    return Result(id=cid, result=record)


def from_map(obj: dict[str, Any]) -> Message:
    """Build and validate the message a received map describes.

    Raises:
        RemoteProtocolError: unknown ``type``, missing field, or a field of the wrong type/value.
    """
    tag = obj.pop("type", None)
    if tag == "result":
        return _result_from_map(obj)
    cls = _TYPES.get(tag) if isinstance(tag, str) else None
    if cls is None:
        raise RemoteProtocolError(f"unknown message type {shown(tag)}")
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
