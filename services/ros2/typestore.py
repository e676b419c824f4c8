"""ROS 2 interface types (pure): definitions → CDR codec, RIHS01 hashes and checked field values.

Types come from ``.msg``, ``.srv`` and ``.action`` definitions kept as files (petrobot ships the ones
it needs under ``services/ros2/definitions/<package>/<msg|srv|action>/``; ``[ros2] interfaces`` adds
a lab's own directories of the same layout); nothing is fetched at run time. rosbags
(``rosbags.typesys``) parses them and does the CDR encoding and the hashing; this module adds what a
ROS 2 client needs on top, as rosidl does:

* a service ``pkg/srv/S`` becomes the messages ``S_Request``, ``S_Response``, ``S_Event`` (``info:
  service_msgs/ServiceEventInfo``, ``request: S_Request[<=1]``, ``response: S_Response[<=1]``) and
  the service type ``S`` itself, a structure of ``request_message``, ``response_message`` and
  ``event_message`` whose RIHS01 hash is the one rmw_zenoh puts in keys (``rosidl_generator_type_
  description``: ``add_srv``);
* an action ``pkg/action/A`` becomes ``A_Goal``, ``A_Result``, ``A_Feedback``, the services
  ``A_SendGoal`` (``goal_id: unique_identifier_msgs/UUID, goal: A_Goal`` → ``accepted: bool, stamp:
  builtin_interfaces/Time``) and ``A_GetResult`` (``goal_id`` → ``status: int8, result: A_Result``),
  the message ``A_FeedbackMessage`` (``goal_id, feedback``) and the action type ``A`` (``add_action``);
* a ``char`` field is an ``uint8`` (rosidl maps the ``.msg`` ``char`` to IDL ``uint8``; the hashes
  differ otherwise), and a bare type name inside a definition is a message of the same package.

Checked against rmw_zenoh's design document: ``std_msgs/msg/String`` hashes to
``RIHS01_df668c74...1a18`` and the ``example_interfaces/srv/AddTwoInts`` service to
``RIHS01_e118de6b...c81a`` (tests/unit/test_ros2_types.py).

Values cross this module as plain Python: a message is a mapping of field name → value, nested
messages are mappings, arrays are lists (``bytes`` too for byte and ``uint8`` arrays). Encoding
checks every field against its type first and raises :class:`Ros2FieldError` naming the field
(``goal.pose.position.x``) rather than letting a CDR exception escape.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.interfaces import Nodetype

from services.ros2.errors import Ros2FieldError, Ros2TypeError, Ros2WireError
from services.ros2.names import action_type_names, split_type

__all__ = [
    "DEFINITIONS",
    "FieldType",
    "ServiceTypes",
    "TypeStore",
    "load_definitions",
]

DEFINITIONS = Path(__file__).resolve().parent / "definitions"
"""The interface definitions petrobot ships (``<package>/<msg|srv|action>/<Name>.<kind>``)."""

_SUFFIX = {"msg": ".msg", "srv": ".srv", "action": ".action"}
_MAX_FILE = 1 << 20
_SEPARATOR = re.compile(r"^---\s*$", re.MULTILINE)
_PRIMITIVES = frozenset({"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
                         "int32", "uint32", "int64", "uint64", "string", "wstring"})
_INTS = {"int8": (-(1 << 7), (1 << 7) - 1), "uint8": (0, 255), "int16": (-(1 << 15), (1 << 15) - 1),
         "uint16": (0, (1 << 16) - 1), "int32": (-(1 << 31), (1 << 31) - 1), "uint32": (0, (1 << 32) - 1),
         "int64": (-(1 << 63), (1 << 63) - 1), "uint64": (0, (1 << 64) - 1), "byte": (0, 255)}
_DTYPES = {"bool": np.bool_, "byte": np.uint8, "int8": np.int8, "uint8": np.uint8, "int16": np.int16,
           "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
           "float32": np.float32, "float64": np.float64}
_FLOAT32_MAX = 3.4028234663852886e38
_MAX_DEPTH = 32

#: The interfaces every service and action type needs besides its own definition.
_BASE_TYPES = ("builtin_interfaces/msg/Time", "service_msgs/msg/ServiceEventInfo", "unique_identifier_msgs/msg/UUID")


def load_definitions(directories: Iterable[str | os.PathLike[str]] = (DEFINITIONS,)) -> dict[str, str]:
    """Read every interface definition under ``directories`` (later directories win).

    Args:
        directories: trees laid out ``<package>/<msg|srv|action>/<Name>.<msg|srv|action>``.

    Returns:
        ``{"pkg/kind/Name": text}``.

    Raises:
        Ros2TypeError: a directory does not exist, or a file is not UTF-8 or is over 1 MiB.
    """
    found: dict[str, str] = {}
    for directory in directories:
        root = Path(directory)
        if not root.is_dir():
            raise Ros2TypeError(f"interface directory {root} does not exist")
        for kind, suffix in _SUFFIX.items():
            for path in sorted(root.glob(f"*/{kind}/*{suffix}")):
                if path.stat().st_size > _MAX_FILE:
                    raise Ros2TypeError(f"{path}: larger than {_MAX_FILE} bytes")
                try:
                    found[f"{path.parent.parent.name}/{kind}/{path.stem}"] = path.read_text(encoding="utf-8")
                except UnicodeDecodeError as exc:
                    raise Ros2TypeError(f"{path}: not UTF-8 ({exc})") from None
    return found


@dataclass(frozen=True, slots=True)
class FieldType:
    """The type of one field, for messages and checks.

    Attributes:
        base: ``int32``, ``string``, ``pkg/msg/Name``...
        string_bound: the bound of a bounded string (``string<=N``), else 0.
        array: ``""`` (a single value), ``"fixed"`` (``T[N]``), ``"bounded"`` (``T[<=N]``) or
            ``"unbounded"`` (``T[]``).
        size: ``N`` for fixed and bounded arrays, else 0.
    """

    base: str
    string_bound: int = 0
    array: str = ""
    size: int = 0

    def __str__(self) -> str:
        base = f"{self.base}<={self.string_bound}" if self.string_bound else self.base
        suffix = {"": "", "fixed": f"[{self.size}]", "bounded": f"[<={self.size}]", "unbounded": "[]"}[self.array]
        return base + suffix

    @property
    def nested(self) -> bool:
        """True for a message type (not a primitive)."""
        return "/" in self.base


@dataclass(frozen=True, slots=True)
class ServiceTypes:
    """The message types of a service.

    Attributes:
        service: ``pkg/srv/Name`` (or ``pkg/action/Name_SendGoal``...).
        request: its request message type.
        response: its response message type.
    """

    service: str
    request: str
    response: str


def _qualify_line(line: str, package: str, where: str) -> str:
    """One definition line (no comment) with its nested type qualified (rosidl's rule: a bare name is
    a message of the same package, ``pkg/Name`` is ``pkg/msg/Name``) and ``char`` read as ``uint8``."""
    words = line.split(None, 1)
    if len(words) < 2:
        return line
    base = re.split(r"[\[<]", words[0], maxsplit=1)[0]
    rest = words[0][len(base):]
    if base == "wstring":
        raise Ros2TypeError(f"{where}: wstring fields are not supported")
    if base == "char":
        base = "uint8"
    elif base.count("/") == 1:
        pkg, name = base.split("/")
        base = f"{pkg}/msg/{name}"
    elif base not in _PRIMITIVES and "/" not in base:
        base = f"{package}/msg/{base}"
    return f"{base}{rest} {words[1]}"


def _normalize(text: str, package: str, where: str) -> str:
    """A definition with comments dropped and nested type names qualified (:func:`_qualify_line`)."""
    out = []
    for line in text.splitlines():
        line = line.strip() if _string_constant(line) else line.split("#", 1)[0].strip()
        if line:
            out.append(_qualify_line(line, package, where))
    return "\n".join(out) + "\n"


def _string_constant(line: str) -> bool:
    """A ``string NAME="..."`` constant, whose value may hold ``#``."""
    words = line.split(None, 1)
    return bool(words) and words[0].startswith("string") and "=" in line.split("#", 1)[0]


def _defaults_of(text: str, where: str) -> dict[str, Any]:
    """The default values a definition gives its primitive fields (``float64 w 1``, ``string s "x"``,
    ``int32[] a [1, 2]``); constants (``NAME=value``) are not defaults.

    Raises:
        Ros2TypeError: a default that is not a literal of its field's type.
    """
    out: dict[str, Any] = {}
    for line in text.splitlines():
        line = line.strip() if _string_constant(line) else line.split("#", 1)[0].strip()
        words = line.split(None, 2)
        if len(words) < 3 or "=" in words[1] or words[2].startswith("="):
            continue
        base = re.split(r"[\[<]", words[0], maxsplit=1)[0]
        if base not in _PRIMITIVES:
            continue
        literal = words[2].strip()
        try:
            if "[" in words[0]:
                inner = literal.strip()
                if not (inner.startswith("[") and inner.endswith("]")):
                    raise ValueError("an array default is written [a, b, ...]")
                items = [i.strip() for i in inner[1:-1].split(",") if i.strip()]
                out[words[1]] = [_literal(base, i) for i in items]
            else:
                out[words[1]] = _literal(base, literal)
        except ValueError as exc:
            raise Ros2TypeError(f"{where}: default of field {words[1]!r}: {exc}") from None
    return out


def _literal(base: str, text: str) -> Any:
    if base == "bool":
        if text.lower() not in ("true", "false", "1", "0"):
            raise ValueError(f"{text!r} is not a bool")
        return text.lower() in ("true", "1")
    if base == "string":
        if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
            return text[1:-1]
        return text
    if base.startswith("float"):
        return float(text)
    return int(text, 0)


def _split(text: str, parts: int, what: str) -> list[str]:
    chunks = _SEPARATOR.split(text)
    if len(chunks) != parts:
        raise Ros2TypeError(f"{what}: expected {parts} parts separated by lines '---', got {len(chunks)}")
    return chunks


class TypeStore:
    """Interface types built from definitions (see the module docstring); pure, no I/O.

    Args:
        definitions: ``{"pkg/kind/Name": text}`` (:func:`load_definitions`).

    Raises:
        Ros2TypeError: a name or a definition is malformed, or a field names a type that is not
            defined (the message names the type and the field).
    """

    def __init__(self, definitions: Mapping[str, str]) -> None:
        self._kinds: dict[str, str] = {}
        self._defaults: dict[str, dict[str, Any]] = {}
        raw: dict[str, Any] = {}

        def add(text: str, name: str) -> None:
            pkg = name.split("/", 1)[0]
            try:
                types = get_types_from_msg(_normalize(text, pkg, name), name)
            except Ros2TypeError:
                raise
            except Exception as exc:  # noqa: BLE001 - rosbags raises its own parse errors
                raise Ros2TypeError(f"{name}: cannot parse the definition: {exc}") from None
            for key, value in types.items():
                raw[_fixed_name(key)] = _fixed_desc(value)
            self._defaults[name] = _defaults_of(text, name)

        for name, text in definitions.items():
            pkg, kind, short = split_type(name)
            name = f"{pkg}/{kind}/{short}"
            self._kinds[name] = kind
            if kind == "msg":
                add(text, name)
            elif kind == "srv":
                request, response = _split(text, 2, name)
                self._add_service(add, name, request, response)
            else:
                goal, result, feedback = _split(text, 3, name)
                names = action_type_names(name)
                add(goal, names.goal)
                add(result, names.result)
                add(feedback, names.feedback)
                self._add_service(add, names.send_goal, f"unique_identifier_msgs/msg/UUID goal_id\n{names.goal} goal",
                                  "bool accepted\nbuiltin_interfaces/msg/Time stamp")
                self._add_service(add, names.get_result, "unique_identifier_msgs/msg/UUID goal_id",
                                  f"int8 status\n{names.result} result")
                add(f"unique_identifier_msgs/msg/UUID goal_id\n{names.feedback} feedback", names.feedback_message)
                add(f"{names.goal} goal\n{names.result} result\n{names.feedback} feedback\n"
                    f"{names.send_goal} send_goal_service\n{names.get_result} get_result_service\n"
                    f"{names.feedback_message} feedback_message", name)
        for typename, (_, fields) in raw.items():
            for fname, desc in fields:
                ref = _referenced(desc)
                if ref is not None and ref not in raw:
                    raise Ros2TypeError(f"{typename}: field {fname!r} has type {ref!r}, which is not defined "
                                        f"(add its definition file)")
        self._store = get_typestore(Stores.EMPTY)
        self._store.register(raw)
        self._defs: dict[str, Any] = raw
        self._hashes: dict[str, str] = {}

    def _add_service(self, add: Any, name: str, request: str, response: str) -> None:
        short = name.rsplit("/", 1)[1]
        prefix = name.rsplit("/", 1)[0]
        add(request, f"{name}_Request")
        add(response, f"{name}_Response")
        add(f"service_msgs/msg/ServiceEventInfo info\n{prefix}/{short}_Request[<=1] request\n"
            f"{prefix}/{short}_Response[<=1] response", f"{name}_Event")
        add(f"{prefix}/{short}_Request request_message\n{prefix}/{short}_Response response_message\n"
            f"{prefix}/{short}_Event event_message", name)
        self._kinds.setdefault(name, "srv")

    # ---- what is defined

    @property
    def rosbags(self) -> Any:
        """The rosbags ``Typestore`` holding every type (for rosbags' bag writer)."""
        return self._store

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._defs

    def names(self) -> list[str]:
        """Every defined type, sorted (messages, services' parts and the composed action types)."""
        return sorted(self._defs)

    def _fields_of(self, name: str) -> list[tuple[str, Any]]:
        try:
            fields: list[tuple[str, Any]] = self._defs[name][1]
            return fields
        except KeyError:
            raise Ros2TypeError(f"unknown interface type {name!r} (no definition file for it; known packages: "
                                f"{', '.join(sorted({n.split('/')[0] for n in self._defs}))})") from None

    def fields(self, name: str) -> dict[str, FieldType]:
        """The fields of message type ``name`` in order.

        Raises:
            Ros2TypeError: ``name`` is not defined.
        """
        return {fname: _field_type(desc) for fname, desc in self._fields_of(name)}

    def service(self, name: str) -> ServiceTypes:
        """The request and response types of service ``name`` (``pkg/srv/S`` or an action's part).

        Raises:
            Ros2TypeError: no such service.
        """
        if f"{name}_Request" not in self._defs or f"{name}_Response" not in self._defs:
            raise Ros2TypeError(f"unknown service type {name!r} (no .srv definition for it)")
        return ServiceTypes(service=name, request=f"{name}_Request", response=f"{name}_Response")

    def kind(self, name: str) -> str:
        """``"msg"``, ``"srv"`` or ``"action"`` for a type defined by a file (or a composed service).

        Raises:
            Ros2TypeError: ``name`` is not such a type.
        """
        kind = self._kinds.get(name)
        if kind is None:
            raise Ros2TypeError(f"unknown interface type {name!r} (no definition file for it)")
        return kind

    def hash(self, name: str) -> str:
        """The REP-2016 type hash of ``name`` (``RIHS01_<64 hex digits>``).

        Raises:
            Ros2TypeError: ``name`` is not defined.
        """
        if name not in self._hashes:
            self._fields_of(name)
            self._hashes[name] = str(self._store.hash_rihs01(name))
        return self._hashes[name]

    # ---- values

    def encode(self, name: str, value: Mapping[str, Any], *, fill: bool = False, what: str = "") -> bytes:
        """CDR bytes (with the 4-byte encapsulation header, little endian) of a message.

        Args:
            name: the message type.
            value: field name → value (nested messages as mappings, arrays as lists).
            fill: give missing fields their zero value (else a missing field is an error).
            what: a prefix for field paths in errors (``"goal"``).

        Raises:
            Ros2FieldError: a field is missing (unless ``fill``), unknown, of the wrong type or out of
                range, naming it.
            Ros2TypeError: ``name`` is not defined.
        """
        message = self._build(name, value, what, fill, 0)
        return bytes(self._store.serialize_cdr(message, name))

    def check(self, name: str, value: Mapping[str, Any], *, fill: bool = False, what: str = "") -> None:
        """Check ``value`` against message type ``name`` as :meth:`encode` does, without encoding."""
        self._build(name, value, what, fill, 0)

    def decode(self, name: str, data: bytes | bytearray | memoryview) -> dict[str, Any]:
        """The fields of a CDR-encoded message of type ``name``.

        Raises:
            Ros2WireError: the bytes are not a valid encoding of ``name``.
            Ros2TypeError: ``name`` is not defined.
        """
        self._fields_of(name)
        try:
            message = self._store.deserialize_cdr(bytes(data), name)
        except Exception as exc:  # noqa: BLE001 - any decoding failure is the sender's
            raise Ros2WireError(f"{len(data)} bytes are not a CDR {name}: {exc.__class__.__name__}: {exc}") from None
        out: dict[str, Any] = _plain(message)
        return out

    def zero(self, name: str) -> dict[str, Any]:
        """Every field of ``name`` at its default value: the one its definition gives
        (``float64 w 1``), else zero (false, 0, 0.0, "", empty or zeroed arrays)."""
        defaults = self._defaults.get(name, {})
        return {fname: defaults[fname] if fname in defaults else self._zero(desc)
                for fname, desc in self._fields_of(name)}

    def _zero(self, desc: Any) -> Any:
        kind, rest = desc
        if kind == Nodetype.BASE:
            return _zero_base(rest[0])
        if kind == Nodetype.NAME:
            return self.zero(rest)
        if kind == Nodetype.ARRAY:
            return [self._zero(rest[0]) for _ in range(rest[1])]
        return []

    def _build(self, name: str, value: Any, path: str, fill: bool, depth: int) -> Any:
        fields = self._fields_of(name)
        if not isinstance(value, Mapping):
            raise Ros2FieldError(path, f"expected a table of {name} fields, got {_shown(value)}")
        if depth > _MAX_DEPTH:
            raise Ros2FieldError(path, f"nested deeper than {_MAX_DEPTH}")
        known = [f for f, _ in fields]
        unknown = sorted(str(k) for k in value if k not in known)
        if unknown:
            raise Ros2FieldError(_join(path, unknown[0]), f"{name} has no such field (its fields: "
                                 f"{', '.join(known) or 'none'})")
        kwargs: dict[str, Any] = {}
        for fname, desc in fields:
            where = _join(path, fname)
            if fname in value:
                kwargs[fname] = self._value(desc, value[fname], where, fill, depth)
            elif fill:
                kwargs[fname] = self._value(desc, self._zero(desc), where, fill, depth)
            else:
                raise Ros2FieldError(where, f"missing ({_field_type(desc)})")
        return self._store.types[name](**kwargs)

    def _value(self, desc: Any, value: Any, path: str, fill: bool, depth: int) -> Any:
        kind, rest = desc
        if kind == Nodetype.BASE:
            return _base(rest[0], rest[1], value, path)
        if kind == Nodetype.NAME:
            return self._build(rest, value, path, fill, depth + 1)
        inner, size = rest
        typ = _field_type(desc)
        if isinstance(value, (bytes, bytearray)) and inner[0] == Nodetype.BASE and inner[1][0] in ("uint8", "byte"):
            value = list(value)
        if not isinstance(value, (list, tuple)):
            raise Ros2FieldError(path, f"expected a list ({typ}), got {_shown(value)}")
        if kind == Nodetype.ARRAY and len(value) != size:
            raise Ros2FieldError(path, f"expected exactly {size} elements ({typ}), got {len(value)}")
        if kind == Nodetype.SEQUENCE and size and len(value) > size:
            raise Ros2FieldError(path, f"at most {size} elements ({typ}), got {len(value)}")
        items = [self._value(inner, v, f"{path}[{i}]", fill, depth) for i, v in enumerate(value)]
        if inner[0] == Nodetype.BASE and inner[1][0] in _DTYPES:
            return np.array(items, dtype=_DTYPES[inner[1][0]])
        return items


def _fixed_name(name: str) -> str:
    """rosbags files service and action parts under ``pkg/srv/msg/``; ROS names them ``pkg/srv/``."""
    return name.replace("/srv/msg/", "/srv/").replace("/action/msg/", "/action/")


def _fixed_desc(value: Any) -> Any:
    if isinstance(value, tuple):
        return tuple(_fixed_desc(v) for v in value)
    if isinstance(value, list):
        return [_fixed_desc(v) for v in value]
    if isinstance(value, str):
        return _fixed_name(value)
    return value


def _referenced(desc: Any) -> str | None:
    kind, rest = desc
    if kind == Nodetype.NAME:
        return str(rest)
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return _referenced(rest[0])
    return None


def _field_type(desc: Any) -> FieldType:
    kind, rest = desc
    if kind == Nodetype.BASE:
        return FieldType(rest[0], string_bound=rest[1] if rest[0] == "string" else 0)
    if kind == Nodetype.NAME:
        return FieldType(rest)
    inner = _field_type(rest[0])
    array = "fixed" if kind == Nodetype.ARRAY else ("bounded" if rest[1] else "unbounded")
    return FieldType(inner.base, inner.string_bound, array, rest[1])


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _shown(value: Any) -> str:
    text = repr(value)
    return f"{text[:60]}... ({type(value).__name__})" if len(text) > 60 else f"{text} ({type(value).__name__})"


def _zero_base(typ: str) -> Any:
    if typ == "bool":
        return False
    if typ == "string":
        return ""
    if typ.startswith("float"):
        return 0.0
    return 0


def _base(typ: str, bound: int, value: Any, path: str) -> Any:
    if typ == "bool":
        if type(value) is not bool:
            raise Ros2FieldError(path, f"expected true or false (bool), got {_shown(value)}")
        return value
    if typ == "string":
        if not isinstance(value, str):
            raise Ros2FieldError(path, f"expected a string, got {_shown(value)}")
        if "\x00" in value:
            raise Ros2FieldError(path, "a string may not hold a NUL character")
        if bound and len(value.encode()) > bound:
            raise Ros2FieldError(path, f"at most {bound} bytes (string<={bound}), got {len(value.encode())}")
        return value
    if typ in _INTS:
        low, high = _INTS[typ]
        if type(value) is not int:
            raise Ros2FieldError(path, f"expected an integer ({typ}), got {_shown(value)}")
        if not low <= value <= high:
            raise Ros2FieldError(path, f"{value} is out of range for {typ} ({low}..{high})")
        return value
    if typ in ("float32", "float64"):
        if type(value) not in (int, float):
            raise Ros2FieldError(path, f"expected a number ({typ}), got {_shown(value)}")
        if typ == "float32" and math.isfinite(value) and abs(value) > _FLOAT32_MAX:
            raise Ros2FieldError(path, f"{value} is out of range for float32")
        return float(value)
    raise Ros2FieldError(path, f"unsupported field type {typ!r}")


def _plain(value: Any) -> Any:
    """rosbags' message objects and numpy arrays as plain mappings, lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    fields = getattr(value, "__dataclass_fields__", None)
    if fields is not None:
        return {name: _plain(getattr(value, name)) for name in fields if name != "__msgtype__"}
    return value
