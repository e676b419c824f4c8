"""The web console's WebSocket protocol, version 1: every message the page may send, checked here.

Messages are JSON objects in text frames (docs/console.md, "Protocol"). The page sends ``hello``
first, then any of ``command``, ``validate``, ``save``, ``analyze``, ``ping``, ``watch`` (follow
another live run), ``blackboard`` (what a place's actions are doing), ``start`` and ``resume`` (a
run of a net file, on the nodes of services.toml) and ``painted`` (the page has drawn a frame: the
server sends the next one only then, so frames are sized to what the page can paint); the server
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

from coordinator.breakpoints import BreakKind, Breakpoint
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
    "MAX_PAYLOAD_BYTES",
    "MAX_REASON",
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
#: Longest reason an operator may give with a forced outcome, characters.
MAX_REASON = 512
#: Largest payload of an injected event, bytes of compact JSON (a publisher's event, not a file).
MAX_PAYLOAD_BYTES = 4096
#: Longest run of a live run started from the page, seconds (a day).
MAX_RUN_SECONDS = 86_400.0


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
        type: ``hello``, ``command``, ``validate``, ``save``, ``analyze``, ``ping``, ``watch``,
            ``blackboard``, ``start``, ``resume`` or ``painted``.
        id: the request id the answer carries (``None`` for ``hello`` and ``painted``).
        fields: the message's other keys, checked (``token``; ``command``, ``place``, ``count``,
            ``breakpoint`` (a :class:`~coordinator.breakpoints.Breakpoint`), ``event``, ``instance``,
            ``outcome``, ``reason``, ``run``; ``draft``; ``path``; ``kind``, ``run``, ``format``; ``net``,
            ``marking``, ``seed``, ``max_seconds``, ``degraded``; ``place``; ``seq``).
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
    if kind == "painted":
        _keys(msg, {"type", "seq"}, {"type", "seq"})
        return ClientMessage("painted", None, {"seq": _int(msg["seq"], "painted.seq", 0, 2**53)})
    if kind not in CLIENT_TYPES:
        raise ProtocolViolation(f"unknown message type {kind[:40]!r}")
    ident = _int(msg.get("id"), f"{kind}.id", 0, 2**53)
    fields: dict[str, Any] = {}
    if kind == "command":
        fields.update(_command(msg))
    elif kind == "watch":
        _keys(msg, {"type", "id", "run"}, {"type", "id", "run"})
        fields["run"] = _str(msg["run"], "watch.run", 64)
    elif kind == "blackboard":
        _keys(msg, {"type", "id", "place", "run"}, {"type", "id", "place"})
        fields["place"] = _str(msg["place"], "blackboard.place", MAX_NAME)
        fields["run"] = None if msg.get("run") is None else _str(msg["run"], "blackboard.run", 64)
    elif kind in ("start", "resume"):
        allowed = {"type", "id", "net", "degraded"} | ({"marking", "seed", "max_seconds"} if kind == "start" else set())
        _keys(msg, allowed, {"type", "id", "net"})
        fields["net"] = _str(msg["net"], f"{kind}.net", 1024)
        fields["degraded"] = msg.get("degraded", False)
        if not isinstance(fields["degraded"], bool):
            raise ProtocolViolation(f"{kind}.degraded must be true or false")
        if kind == "start":
            marking = msg.get("marking", {})
            if not isinstance(marking, dict) or len(marking) > MAX_ELEMENTS:
                raise ProtocolViolation("start.marking must be an object place -> tokens")
            fields["marking"] = {_str(p, "start.marking place", MAX_NAME): _int(n, "start.marking tokens", 0, MAX_COUNT)
                                 for p, n in marking.items()}
            fields["seed"] = _int(msg.get("seed", 0), "start.seed", 0, 2**31 - 1)
            limit = msg.get("max_seconds")
            if limit is not None and (not isinstance(limit, (int, float)) or isinstance(limit, bool)
                                      or not 0 < limit <= MAX_RUN_SECONDS):
                raise ProtocolViolation(f"start.max_seconds must be a number in (0, {MAX_RUN_SECONDS:g}] or null")
            fields["max_seconds"] = None if limit is None else float(limit)
    elif kind == "validate":
        _keys(msg, {"type", "id", "draft", "name"}, {"type", "id", "draft"})
        fields["draft"] = _draft(msg["draft"])
        fields["name"] = None if msg.get("name") is None else _str(msg["name"], "validate.name", 1024)
    elif kind == "save":
        _keys(msg, {"type", "id", "draft", "path"}, {"type", "id", "draft", "path"})
        fields["draft"] = _draft(msg["draft"])
        fields["path"] = _str(msg["path"], "save.path", 1024)
    elif kind == "analyze":
        _keys(msg, {"type", "id", "draft", "kind", "run", "format"}, {"type", "id", "draft", "kind"})
        fields["draft"] = _draft(msg["draft"])
        which = _str(msg["kind"], "analyze.kind", 16)
        if which not in _ANALYSES:
            raise ProtocolViolation(f"analyze.kind must be one of {', '.join(sorted(_ANALYSES))}")
        fields["kind"] = which
        fields["run"] = None if msg.get("run") is None else _str(msg["run"], "analyze.run", 64)
        fields["format"] = _str(msg.get("format", "text"), "analyze.format", 8)
        if fields["format"] not in ("text", "json"):
            raise ProtocolViolation("analyze.format must be text or json")
    elif kind == "ping":
        _keys(msg, {"type", "id", "t"}, {"type", "id"})
        t = msg.get("t", 0.0)
        if not isinstance(t, (int, float)) or isinstance(t, bool):
            raise ProtocolViolation("ping.t must be a number")
        fields["t"] = float(t)
    return ClientMessage(kind, ident, fields)


def _command(msg: dict[str, Any]) -> dict[str, Any]:
    """The keys of a ``command`` message, checked for its command."""
    _keys(msg, {"type", "id", "command", "place", "count", "breakpoint", "event", "payload", "instance", "outcome",
                "reason", "run"}, {"type", "id", "command"})
    try:
        command = Command(_str(msg["command"], "command.command", 16))
    except ValueError:
        raise ProtocolViolation(f"unknown operator command {str(msg['command'])[:16]!r}") from None
    fields: dict[str, Any] = {"command": command,
                              "run": None if msg.get("run") is None else _str(msg["run"], "command.run", 64)}
    wanted = {Command.INSERT: {"place", "count"}, Command.REMOVE: {"place", "count"},
              Command.BREAK: {"breakpoint"}, Command.CLEAR: {"breakpoint"}, Command.INJECT: {"event", "payload"},
              Command.FORCE: {"instance", "outcome", "reason"}}.get(command, set())
    extra = {"place", "count", "breakpoint", "event", "payload", "instance", "outcome", "reason"} - wanted
    if extra & set(msg):
        raise ProtocolViolation(f"command {command.value} takes no {min(extra & set(msg))}")
    if command in (Command.INSERT, Command.REMOVE):
        if "place" not in msg:
            raise ProtocolViolation(f"command {command.value} needs a place")
        fields["place"] = _str(msg["place"], "command.place", MAX_NAME)
        fields["count"] = _int(msg.get("count", 1), "command.count", 1, MAX_COUNT)
    elif command in (Command.BREAK, Command.CLEAR):
        bp = msg.get("breakpoint")
        if not isinstance(bp, dict) or not set(bp) <= {"kind", "target", "count"}:
            raise ProtocolViolation(f"command {command.value} needs a breakpoint {{kind, target, count}}")
        try:
            bkind = BreakKind(_str(bp.get("kind"), "breakpoint.kind", 16))
        except ValueError:
            raise ProtocolViolation("breakpoint.kind must be enabled, fires, count or error") from None
        count = None
        if bkind is BreakKind.COUNT:
            count = _int(bp.get("count"), "breakpoint.count", 0, MAX_COUNT)
        elif bp.get("count") is not None:
            raise ProtocolViolation(f"a {bkind.value} breakpoint takes no count")
        fields["breakpoint"] = Breakpoint(bkind, _str(bp.get("target"), "breakpoint.target", MAX_NAME), count)
    elif command is Command.INJECT:
        event = _str(msg.get("event"), "command.event", MAX_NAME + 4)
        if not event.startswith("ext:"):
            raise ProtocolViolation("command inject needs an external event ext:TOPIC")
        fields["event"] = event
        if msg.get("payload") is not None:
            size = len(json.dumps(msg["payload"], separators=(",", ":")))
            if size > MAX_PAYLOAD_BYTES:
                raise ProtocolViolation(f"command.payload is {size} bytes of JSON, more than {MAX_PAYLOAD_BYTES}")
            fields["payload"] = msg["payload"]
    elif command is Command.FORCE:
        fields["instance"] = _str(msg.get("instance"), "command.instance", MAX_NAME)
        fields["outcome"] = _str(msg.get("outcome"), "command.outcome", 2 * MAX_NAME + 1)
        fields["reason"] = _str(msg.get("reason", ""), "command.reason", MAX_REASON)
    return fields


#: Message types the page may send after ``hello`` (``painted`` carries no id).
CLIENT_TYPES = frozenset({"command", "validate", "save", "analyze", "ping", "watch", "blackboard", "start",
                          "resume"})
