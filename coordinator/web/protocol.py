"""The web console's WebSocket protocol, version 1: every message the page may send, checked here.

Messages are JSON objects in text frames (docs/console.md, "Protocol"). The page sends ``hello``
first, then any of ``command``, ``validate``, ``save``, ``analyze`` and ``ping``; the server
answers each message that has an ``id`` with a message carrying the same ``id``. Everything the
server receives goes through :func:`parse_client_message`, the one place an inbound message is
checked: size, JSON syntax, nesting, the message type, its keys and the type and range of each
value. A message that fails is a :class:`ProtocolViolation`; the server closes that one socket
with the violation's reason (WebSocket close code 1008, or 1009 when too large) and the run goes
on. Pure: no I/O.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from coordinator.netfile.limits import MAX_COUNT, MAX_NAME
from coordinator.operator import Command
from services.errors import PetrobotError

__all__ = [
    "CLIENT_TYPES",
    "CLOSE_POLICY",
    "CLOSE_TOO_BIG",
    "MAX_DEPTH",
    "MAX_ELEMENTS",
    "MAX_MESSAGE_BYTES",
    "PROTOCOL_VERSION",
    "ClientMessage",
    "ProtocolViolation",
    "parse_client_message",
]

#: Version carried by ``hello`` and ``welcome``; a page speaking another version is refused.
PROTOCOL_VERSION = 1
#: Largest inbound message, bytes (a drawn net of 1,000 nodes is about 250 kB of JSON).
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
#: Deepest nesting of arrays and objects in an inbound message.
MAX_DEPTH = 24
#: Most places, transitions, arcs or tasks in a draft.
MAX_ELEMENTS = 50_000
#: Longest string value anywhere in an inbound message, characters (a net's description).
MAX_STRING = 65_536
#: WebSocket close codes: policy violation, message too big (RFC 6455, section 7.4.1).
CLOSE_POLICY = 1008
CLOSE_TOO_BIG = 1009

_DRAFT_KEYS = frozenset({"net", "places", "transitions", "arcs", "tasks", "operator"})
_ANALYSES = frozenset({"analyze", "gspn", "perf", "learn"})


class ProtocolViolation(PetrobotError):
    """An inbound message breaks the protocol; the socket is closed with ``reason``.

    Attributes:
        reason: why, in words (at most 120 bytes of UTF-8: a WebSocket close reason's room).
        code: the WebSocket close code (:data:`CLOSE_POLICY` or :data:`CLOSE_TOO_BIG`).
    """

    def __init__(self, reason: str, code: int = CLOSE_POLICY) -> None:
        data = reason.encode("utf-8")
        if len(data) > 120:
            reason = data[:117].decode("utf-8", "ignore") + "..."
        super().__init__(reason)
        self.reason = reason
        self.code = code


@dataclass(frozen=True, slots=True)
class ClientMessage:
    """One checked message from the page.

    Attributes:
        type: ``hello``, ``command``, ``validate``, ``save``, ``analyze`` or ``ping``.
        id: the request id the answer carries (``None`` for ``hello``).
        fields: the message's other keys, checked (``token``; ``command``, ``place``, ``count``;
            ``draft``; ``path``; ``kind``, ``journal``, ``run``).
    """

    type: str
    id: int | None = None
    fields: dict[str, Any] = field(default_factory=dict)


def _shape(value: Any, depth: int = 0) -> None:
    """Refuse nesting deeper than MAX_DEPTH, over-long strings and non-finite numbers."""
    if depth > MAX_DEPTH:
        raise ProtocolViolation(f"message nested deeper than {MAX_DEPTH} levels")
    if isinstance(value, str):
        if len(value) > MAX_STRING:
            raise ProtocolViolation(f"a string longer than {MAX_STRING} characters")
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise ProtocolViolation("a number that is not finite")
    elif isinstance(value, dict):
        for k, v in value.items():
            if len(k) > MAX_NAME:
                raise ProtocolViolation(f"a key longer than {MAX_NAME} characters")
            _shape(v, depth + 1)
    elif isinstance(value, list):
        for v in value:
            _shape(v, depth + 1)


def _int(value: Any, what: str, low: int, high: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise ProtocolViolation(f"{what} must be an integer in [{low}, {high}]")
    return value


def _str(value: Any, what: str, limit: int) -> str:
    if not isinstance(value, str) or len(value) > limit:
        raise ProtocolViolation(f"{what} must be a string of at most {limit} characters")
    if any(ord(ch) < 0x20 or ord(ch) == 0x7F for ch in value):
        raise ProtocolViolation(f"{what} holds a control character")
    return value


def _keys(msg: dict[str, Any], allowed: set[str], required: set[str]) -> None:
    extra = set(msg) - allowed
    if extra:
        raise ProtocolViolation(f"{msg['type']}: unknown key {min(extra)[:40]!r}")
    missing = required - set(msg)
    if missing:
        raise ProtocolViolation(f"{msg['type']}: missing key {min(missing)!r}")


def _draft(value: Any) -> dict[str, Any]:
    """A draft net: its containers must have the right shape; their content is the linter's."""
    if not isinstance(value, dict):
        raise ProtocolViolation("draft must be an object")
    extra = set(value) - _DRAFT_KEYS
    if extra:
        raise ProtocolViolation(f"draft: unknown key {min(extra)[:40]!r}")
    for key in ("places", "transitions", "arcs"):
        items = value.get(key, [])
        if not isinstance(items, list) or len(items) > MAX_ELEMENTS:
            raise ProtocolViolation(f"draft.{key} must be an array of at most {MAX_ELEMENTS} objects")
        if not all(isinstance(item, dict) for item in items):
            raise ProtocolViolation(f"draft.{key} must hold objects only")
    for key in ("net", "tasks", "operator"):
        table = value.get(key, {})
        if not isinstance(table, dict) or len(table) > MAX_ELEMENTS:
            raise ProtocolViolation(f"draft.{key} must be an object")
    if not all(isinstance(t, dict) for t in value.get("tasks", {}).values()):
        raise ProtocolViolation("draft.tasks must map names to objects")
    return value


def parse_client_message(data: str | bytes) -> ClientMessage:
    """Check one inbound WebSocket message and return it.

    Args:
        data: the frame's payload (text; a binary frame is refused).

    Returns:
        The checked message.

    Raises:
        ProtocolViolation: the message is too large, not JSON, too deep, not an object, of an
            unknown type, has unknown or missing keys, or a value of the wrong type or range.
    """
    if isinstance(data, (bytes, bytearray)):
        raise ProtocolViolation("binary frames are not part of the protocol")
    if len(data) > MAX_MESSAGE_BYTES:  # characters >= bytes / 4: checked again in bytes by the server
        raise ProtocolViolation(f"message larger than {MAX_MESSAGE_BYTES} bytes", CLOSE_TOO_BIG)
    try:
        msg = json.loads(data)
    except RecursionError:
        raise ProtocolViolation(f"message nested deeper than {MAX_DEPTH} levels") from None
    except ValueError as exc:
        raise ProtocolViolation(f"not JSON: {str(exc)[:60]}") from None
    if not isinstance(msg, dict):
        raise ProtocolViolation("a message must be a JSON object")
    _shape(msg)
    kind = msg.get("type")
    if not isinstance(kind, str):
        raise ProtocolViolation("a message needs a string 'type'")
    if kind == "hello":
        _keys(msg, {"type", "v", "token"}, {"type", "v"})
        version = _int(msg["v"], "hello.v", 0, 1_000_000)
        if version != PROTOCOL_VERSION:
            raise ProtocolViolation(f"protocol version {version} is not spoken here (this server speaks "
                                    f"{PROTOCOL_VERSION}); reload the page")
        token = msg.get("token")
        return ClientMessage("hello", None, {"token": None if token is None else _str(token, "token", 256)})
    if kind not in CLIENT_TYPES:
        raise ProtocolViolation(f"unknown message type {kind[:40]!r}")
    ident = _int(msg.get("id"), f"{kind}.id", 0, 2**53)
    fields: dict[str, Any] = {}
    if kind == "command":
        _keys(msg, {"type", "id", "command", "place", "count"}, {"type", "id", "command"})
        try:
            command = Command(_str(msg["command"], "command.command", 16))
        except ValueError:
            raise ProtocolViolation(f"unknown operator command {str(msg['command'])[:16]!r}") from None
        fields["command"] = command
        if command in (Command.INSERT, Command.REMOVE):
            if "place" not in msg:
                raise ProtocolViolation(f"command {command.value} needs a place")
            fields["place"] = _str(msg["place"], "command.place", MAX_NAME)
            fields["count"] = _int(msg.get("count", 1), "command.count", 1, MAX_COUNT)
        elif "place" in msg or "count" in msg:
            raise ProtocolViolation(f"command {command.value} takes no place or count")
    elif kind == "validate":
        _keys(msg, {"type", "id", "draft"}, {"type", "id", "draft"})
        fields["draft"] = _draft(msg["draft"])
    elif kind == "save":
        _keys(msg, {"type", "id", "draft", "path"}, {"type", "id", "draft", "path"})
        fields["draft"] = _draft(msg["draft"])
        fields["path"] = _str(msg["path"], "save.path", 1024)
    elif kind == "analyze":
        _keys(msg, {"type", "id", "draft", "kind", "run"}, {"type", "id", "draft", "kind"})
        fields["draft"] = _draft(msg["draft"])
        which = _str(msg["kind"], "analyze.kind", 16)
        if which not in _ANALYSES:
            raise ProtocolViolation(f"analyze.kind must be one of {', '.join(sorted(_ANALYSES))}")
        fields["kind"] = which
        fields["run"] = None if msg.get("run") is None else _str(msg["run"], "analyze.run", 64)
    elif kind == "ping":
        _keys(msg, {"type", "id", "t"}, {"type", "id"})
        t = msg.get("t", 0.0)
        if not isinstance(t, (int, float)) or isinstance(t, bool):
            raise ProtocolViolation("ping.t must be a number")
        fields["t"] = float(t)
    return ClientMessage(kind, ident, fields)


#: Message types the page may send after ``hello``.
CLIENT_TYPES = frozenset({"command", "validate", "save", "analyze", "ping"})
