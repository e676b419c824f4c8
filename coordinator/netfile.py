"""The TOML net file format: load, validate with file:line errors, save (docs/netfile.md).

A net file describes an interpreted Petri net of a robotic task (paper section 2): ``[net]``,
``[[place]]`` tables, ``[task.<name>]`` tables mapping each primitive task to its alternative
primitive actions, ``[[transition]]`` tables whose ``inputs``/``outputs``/``inhibitors`` tables
give the arcs, and optionally ``[[arc]]`` tables (``from``/``to``/``weight``/``inhibitor``).
:func:`dump_net` writes one canonical form (arcs inside the transitions) that
:func:`loads_net` reads back equal.

Every problem is a :class:`~coordinator.errors.NetError` naming the file, the 1-based line and the
problem. :mod:`tomllib` reports positions of syntax errors only, so :class:`SourceMap` scans the
source text for table headers and keys to find the line of each element and key.

:func:`check_net` validates a net against the location file (``services.toml``): every primitive
action is placed on a node, every external event has a publisher.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import math
import re
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Protocol, TypeVar

from coordinator.errors import NetError, NetFileError
from coordinator.learning.validation import learner_spec
from services.errors import LocationError
from coordinator.net import (
    EVENT_RE,
    ActionSpec,
    Arc,
    Marking,
    PetriNet,
    Place,
    PlaceKind,
    PrimitiveTask,
    Transition,
    TransitionKind,
)

__all__ = [
    "FORMAT_VERSION",
    "SourceMap",
    "check_net",
    "dump_net",
    "format_key",
    "format_value",
    "lint_net",
    "load_any",
    "load_net",
    "loads_net",
    "save_net",
]

#: Version written in ``[net] format``; files of a higher version are refused.
FORMAT_VERSION = 1

_TOP_KEYS = ("net", "place", "task", "transition", "arc")
_NET_KEYS = ("name", "description", "format", "home")
_PLACE_KEYS = ("id", "kind", "tokens", "label", "capacity", "task")
_TASK_KEYS = ("actions", "deadline_s", "learner", "mean_time_s", "reliability", "params")
_ACTION_KEYS = ("name", "params", "cost")
_TRANSITION_KEYS = ("id", "label", "events", "priority", "weight", "kind", "rate", "servers", "hidden",
                    "inputs", "outputs", "inhibitors")
_ARC_KEYS = ("from", "to", "weight", "inhibitor")
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_T = TypeVar("_T")


# ============================================================================ TOML writing
def format_key(key: str) -> str:
    """Write a TOML key: bare when it may be, else a quoted basic string."""
    return key if _BARE_KEY.match(key) else _format_string(key)


def _format_string(text: str) -> str:
    out = ['"']
    for ch in text:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ch == "\r":
            out.append("\\r")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _format_float(value: float) -> str:
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return repr(float(value))


def format_value(value: Any) -> str:
    """Write a value as one-line TOML (strings, booleans, integers, floats, dates, arrays, tables).

    Tables become inline tables; ``tomllib.loads("v = " + format_value(x))["v"] == x``.

    Raises:
        NetError: on a value TOML cannot hold (``None``, an object).
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _format_float(value)
    if isinstance(value, str):
        return _format_string(value)
    if isinstance(value, (_dt.datetime, _dt.date, _dt.time)):
        return value.isoformat()
    if isinstance(value, Mapping):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{format_key(str(k))} = {format_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    raise NetError(f"cannot write {value!r} ({type(value).__name__}) in TOML")


# ============================================================================ source positions
def _split_key(text: str) -> list[str]:
    """Split a dotted TOML key (``a."b.c".d``) into its parts."""
    parts: list[str] = []
    i, n = 0, len(text)
    while i < n:
        while i < n and text[i] in " \t":
            i += 1
        if i >= n:
            break
        if text[i] in "\"'":
            quote = text[i]
            j = i + 1
            buf: list[str] = []
            while j < n and text[j] != quote:
                if quote == '"' and text[j] == "\\" and j + 1 < n:
                    buf.append(text[j + 1])
                    j += 2
                    continue
                buf.append(text[j])
                j += 1
            parts.append("".join(buf))
            i = j + 1
        else:
            j = i
            while j < n and text[j] not in ". \t":
                j += 1
            parts.append(text[i:j])
            i = j
        while i < n and text[i] in " \t":
            i += 1
        if i < n and text[i] == ".":
            i += 1
    return parts


def _scan_line(line: str, state: dict[str, Any]) -> None:
    """Update bracket depth and multi-line string state over one source line."""
    i, n = 0, len(line)
    while i < n:
        ml = state["ml"]
        if ml:
            end = line.find(ml, i)
            if end < 0:
                return
            i = end + 3
            state["ml"] = None
            continue
        ch = line[i]
        if ch == "#":
            return
        if line.startswith('"""', i) or line.startswith("'''", i):
            state["ml"] = line[i:i + 3]
            i += 3
            continue
        if ch in "\"'":
            j = i + 1
            while j < n and line[j] != ch:
                j += 2 if ch == '"' and line[j] == "\\" else 1
            i = j + 1
            continue
        if ch in "[{":
            state["depth"] += 1
        elif ch in "]}":
            state["depth"] = max(0, state["depth"] - 1)
        i += 1


_HEADER = re.compile(r"^\s*(\[\[?)\s*(.*?)\s*\]\]?\s*(?:#.*)?$")
_KEY = re.compile(r"^\s*((?:[A-Za-z0-9_-]+|\"(?:[^\"\\]|\\.)*\"|'[^']*')"
                  r"(?:\s*\.\s*(?:[A-Za-z0-9_-]+|\"(?:[^\"\\]|\\.)*\"|'[^']*'))*)\s*=")


@dataclass
class SourceMap:
    """Lines of the elements and keys of a net file, found by scanning its text.

    Elements are ``("net", None)``, ``("place", i)``, ``("transition", i)``, ``("arc", i)`` (0-based
    index among the tables of that array) and ``("task", name)``. Lines are 1-based.
    """

    elements: dict[tuple[str, Any], int] = field(default_factory=dict)
    keys: dict[tuple[str, Any, str], int] = field(default_factory=dict)
    ids: dict[tuple[str, str], int] = field(default_factory=dict)
    last_line: int = 1

    @classmethod
    def scan(cls, text: str) -> SourceMap:
        """Build the map of ``text`` (a best effort on text that is not valid TOML)."""
        smap = cls()
        counters = {"place": -1, "transition": -1, "arc": -1}
        header: list[str] = []
        state: dict[str, Any] = {"ml": None, "depth": 0}
        lines = text.splitlines()
        smap.last_line = max(1, len(lines))
        for number, line in enumerate(lines, start=1):
            if state["ml"] is None and state["depth"] == 0:
                head = _HEADER.match(line)
                if head and not _KEY.match(line):
                    header = _split_key(head.group(2))
                    if head.group(1) == "[[" and len(header) == 1 and header[0] in counters:
                        counters[header[0]] += 1
                    smap._record(header, number, counters)
                    continue
                key = _KEY.match(line)
                if key:
                    smap._record(header + _split_key(key.group(1)), number, counters, line[key.end():])
            _scan_line(line, state)
        return smap

    def _record(self, path: list[str], number: int, counters: dict[str, int],
                value_text: str | None = None) -> None:
        if not path:
            return
        section = path[0]
        ident: Any
        if section in counters:
            ident, rest = counters[section], path[1:]
            if ident < 0:
                return
        elif section == "task":
            if len(path) < 2:
                return
            ident, rest = path[1], path[2:]
        elif section == "net":
            ident, rest = None, path[1:]
        else:
            self.elements.setdefault((section, None), number)
            return
        self.elements.setdefault((section, ident), number)
        if section == "task":
            self.ids.setdefault(("task", ident), number)
        if rest:
            self.keys.setdefault((section, ident, rest[0]), number)
            if rest == ["id"] and section in counters and value_text is not None:
                try:
                    value = tomllib.loads("id = " + value_text)["id"]
                except tomllib.TOMLDecodeError:
                    return
                if isinstance(value, str):
                    self.ids.setdefault((section, value), number)

    def element(self, section: str, ident: Any) -> int | None:
        """Line of an element: its ``id`` key if present, else its header, else ``None``."""
        line = self.keys.get((section, ident, "id"))
        return line if line is not None else self.elements.get((section, ident))

    def key(self, section: str, ident: Any, key: str) -> int | None:
        """Line of a key of an element, falling back to :meth:`element`."""
        line = self.keys.get((section, ident, key))
        return line if line is not None else self.element(section, ident)

    def of_id(self, ident: str) -> int | None:
        """Line of the place, transition or task with this id or name, or ``None``."""
        for section in ("place", "transition", "task"):
            if (section, ident) in self.ids:
                return self.ids[(section, ident)]
        return None


# ============================================================================ loading
def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_num(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _type_name(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a float", str: "a string", list: "an array",
            dict: "a table"}.get(type(value), type(value).__name__)


class _Skip(Exception):
    """The current element is unusable; its problem is already recorded."""


class _Loader:
    """Turns a parsed TOML document into a net, collecting every problem with its line."""

    def __init__(self, doc: dict[str, Any], smap: SourceMap, path: str) -> None:
        self.doc = doc
        self.smap = smap
        self.path = path
        self.problems: list[NetError] = []

    # ---------------------------------------------------------------- reporting
    def report(self, problem: str, line: int | None) -> None:
        self.problems.append(NetError(problem, path=self.path, line=line))

    def fail(self, problem: str, line: int | None) -> _Skip:
        self.report(problem, line)
        return _Skip()

    def check_keys(self, table: Mapping[str, Any], allowed: tuple[str, ...], what: str,
                   section: str, ident: Any) -> None:
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f" (known keys: {', '.join(allowed)})"
                self.report(f"unknown key {key!r} in {what}{hint}", self.smap.key(section, ident, key))

    def get(self, table: Mapping[str, Any], key: str, kind: str, what: str, section: str, ident: Any,
            default: Any = None) -> Any:
        """Fetch ``table[key]`` checking its type; ``kind`` is str|int|num|bool|table|array."""
        if key not in table:
            return default
        value = table[key]
        ok = {"str": isinstance(value, str), "int": _is_int(value), "num": _is_num(value),
              "bool": isinstance(value, bool), "table": isinstance(value, dict),
              "array": isinstance(value, list)}[kind]
        if not ok:
            wanted = {"str": "a string", "int": "an integer", "num": "a number", "bool": "true or false",
                      "table": "a table", "array": "an array"}[kind]
            raise self.fail(f"{key} of {what} must be {wanted}, not {_type_name(value)} ({value!r})",
                            self.smap.key(section, ident, key))
        return value

    def build(self, line: int | None, make: Callable[[], _T]) -> _T:
        """Call a model constructor; turn its NetError into a problem at ``line``."""
        try:
            return make()
        except NetError as exc:
            raise self.fail(exc.problem, line) from None

    # ---------------------------------------------------------------- top level
    def load(self, default_name: str, interpreted: bool) -> PetriNet | None:
        doc = self.doc
        for key in doc:
            if key not in _TOP_KEYS:
                close = difflib.get_close_matches(key, _TOP_KEYS, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(_TOP_KEYS)})"
                line = self.smap.elements.get((key, None))
                self.report(f"unknown section {key!r}{hint}", line or self._find_header(key))
        for key, kind in (("net", dict), ("task", dict), ("place", list), ("transition", list), ("arc", list)):
            if key in doc and not isinstance(doc[key], kind):
                form = f"[{key}]" if kind is dict else f"[[{key}]]"
                self.report(f"{key} must be written as {form} table(s)", self._find_header(key))
                return None
        name, description, home = self.load_header(default_name)
        tasks = self.load_tasks()
        places, marking = self.load_places()
        transitions = self.load_transitions()
        for tid in transitions:
            if tid in places:
                self.report(f"id {tid!r} is both a place and a transition; ids must be unique across both",
                            self.smap.ids.get(("transition", tid)))
        arcs = self.load_arcs(places, transitions)
        self.check_places(places, tasks)
        if home is not None:
            for pid in home:
                if pid not in places:
                    self.report(f"home marking of [net] puts tokens in unknown place {pid!r}",
                                self.smap.key("net", None, "home"))
        if self.problems:
            return None
        try:
            net = PetriNet(name=name, places=tuple(places.values()), transitions=tuple(transitions.values()),
                           arcs=tuple(arcs), initial_marking=marking, tasks=tasks, description=description,
                           home_marking=home)
        except NetError as exc:
            self.report(exc.problem, None)
            return None
        if interpreted:
            for ident, problem in net.interpretation_problems():
                self.report(problem, self.smap.of_id(ident))
        return None if self.problems else net

    def _find_header(self, key: str) -> int | None:
        for (section, _), line in sorted(self.smap.elements.items(), key=lambda kv: kv[1]):
            if section == key:
                return line
        return None

    def load_header(self, default_name: str) -> tuple[str, str, Marking | None]:
        table = self.doc.get("net", {})
        self.check_keys(table, _NET_KEYS, "[net]", "net", None)
        name, description, home = default_name, "", None
        try:
            name = self.get(table, "name", "str", "[net]", "net", None, default_name)
            description = self.get(table, "description", "str", "[net]", "net", None, "")
            version = self.get(table, "format", "int", "[net]", "net", None, FORMAT_VERSION)
            if version != FORMAT_VERSION:
                self.report(f"net file format {version} is not supported (this reader knows format "
                            f"{FORMAT_VERSION})", self.smap.key("net", None, "format"))
            home_table = self.get(table, "home", "table", "[net]", "net", None)
            if home_table is not None:
                home = self.marking_table(home_table, "home of [net]", "net", None, "home")
        except _Skip:
            pass
        return name, description, home

    def marking_table(self, table: Mapping[str, Any], what: str, section: str, ident: Any, key: str) -> Marking:
        line = self.smap.key(section, ident, key)
        for place, count in table.items():
            if not _is_int(count) or count < 0:
                raise self.fail(f"{what}: token count of {place!r} must be an integer >= 0, not {count!r}", line)
        return Marking(table)

    # ---------------------------------------------------------------- tasks
    def load_tasks(self) -> dict[str, PrimitiveTask]:
        tasks: dict[str, PrimitiveTask] = {}
        for name, table in self.doc.get("task", {}).items():
            try:
                tasks[name] = self.load_task(name, table)
            except _Skip:
                continue
        return tasks

    def load_task(self, name: str, table: Any) -> PrimitiveTask:
        what = f"[task.{name}]"
        line = self.smap.elements.get(("task", name))
        if not isinstance(table, dict):
            raise self.fail(f"{what} must be a table", line)
        self.check_keys(table, _TASK_KEYS, what, "task", name)
        if "actions" not in table:
            raise self.fail(f"{what} has no actions: list its alternative primitive actions", line)
        actions_value = self.get(table, "actions", "array", what, "task", name)
        common = self.get(table, "params", "table", what, "task", name, {})
        actions_line = self.smap.key("task", name, "actions")
        actions: list[ActionSpec] = []
        for item in actions_value:
            if isinstance(item, str):
                spec: dict[str, Any] = {"name": item}
            elif isinstance(item, dict):
                spec = item
                for key in item:
                    if key not in _ACTION_KEYS:
                        close = difflib.get_close_matches(key, _ACTION_KEYS, n=1)
                        hint = f"; did you mean {close[0]!r}?" if close else ""
                        raise self.fail(f"unknown key {key!r} in an action of {what}{hint}", actions_line)
            else:
                raise self.fail(f"actions of {what} must be names or tables {{ name = ..., params = ..., "
                                f"cost = ... }}, not {_type_name(item)}", actions_line)
            action_name = spec.get("name")
            params = spec.get("params", {})
            cost = spec.get("cost")
            if not isinstance(action_name, str):
                raise self.fail(f"an action of {what} has no name (a string)", actions_line)
            if not isinstance(params, dict):
                raise self.fail(f"params of action {action_name!r} in {what} must be a table", actions_line)
            if cost is not None and (not _is_num(cost) or cost < 0):
                raise self.fail(f"cost of action {action_name!r} in {what} must be a number >= 0", actions_line)
            merged = {**common, **params}
            actions.append(self.build(actions_line, partial(
                ActionSpec, name=action_name, params=merged, cost=None if cost is None else float(cost))))
        values: dict[str, float | None] = {}
        for key in ("deadline_s", "mean_time_s", "reliability"):
            value = self.get(table, key, "num", what, "task", name)
            if value is not None and not (0 <= value <= 1 if key == "reliability" else value > 0):
                wanted = "in [0, 1]" if key == "reliability" else "> 0"
                raise self.fail(f"{key} of {what} is {value}; it must be {wanted}", self.smap.key("task", name, key))
            values[key] = None if value is None else float(value)
        learner = self.get(table, "learner", "table", what, "task", name, {})
        if learner:  # section 4: reject a bad learner configuration here, with its line
            costs = {a.name: a.cost for a in actions if a.cost is not None}
            self.build(self.smap.key("task", name, "learner") or line,
                       lambda: learner_spec(learner, [a.name for a in actions], costs or None))
        return self.build(line, lambda: PrimitiveTask(name=name, actions=tuple(actions), learner=learner, **values))

    # ---------------------------------------------------------------- places
    def load_places(self) -> tuple[dict[str, Place], Marking]:
        places: dict[str, Place] = {}
        marking: dict[str, int] = {}
        for index, table in enumerate(self.doc.get("place", [])):
            try:
                place, tokens = self.load_place(index, table, places)
            except _Skip:
                continue
            places[place.id] = place
            if tokens:
                marking[place.id] = tokens
        return places, Marking(marking)

    def element_id(self, section: str, index: int, table: Mapping[str, Any], taken: Mapping[str, Any]) -> str:
        header = self.smap.elements.get((section, index))
        if "id" not in table:
            raise self.fail(f"a [[{section}]] has no id", header)
        ident = table["id"]
        line = self.smap.element(section, index)
        if not isinstance(ident, str):
            raise self.fail(f"id of a [[{section}]] must be a string, not {_type_name(ident)}", line)
        if ident in taken:
            raise self.fail(f"duplicate {section} id {ident!r}", line)
        return ident

    def load_place(self, index: int, table: Any, places: Mapping[str, Place]) -> tuple[Place, int]:
        if not isinstance(table, dict):
            raise self.fail("a [[place]] must be a table", self.smap.elements.get(("place", index)))
        pid = self.element_id("place", index, table, places)
        what = f"place {pid!r}"
        self.check_keys(table, _PLACE_KEYS, what, "place", index)
        task = self.get(table, "task", "str", what, "place", index)
        kind_text = self.get(table, "kind", "str", what, "place", index,
                             "primitive_task" if task is not None else "plain")
        try:
            kind = PlaceKind(kind_text)
        except ValueError:
            kinds = ", ".join(k.value for k in PlaceKind)
            raise self.fail(f"{what} has unknown kind {kind_text!r} (use one of {kinds})",
                            self.smap.key("place", index, "kind")) from None
        if kind is PlaceKind.PRIMITIVE_TASK and task is None:
            raise self.fail(f"{what} is a primitive_task place but names no task (add task = \"...\")",
                            self.smap.key("place", index, "kind"))
        if kind is not PlaceKind.PRIMITIVE_TASK and task is not None:
            raise self.fail(f"{what} of kind {kind.value} cannot name a task", self.smap.key("place", index, "task"))
        tokens = self.get(table, "tokens", "int", what, "place", index, 0)
        if tokens < 0:
            raise self.fail(f"{what} has a negative initial marking ({tokens})", self.smap.key("place", index, "tokens"))
        label = self.get(table, "label", "str", what, "place", index, "")
        capacity = self.get(table, "capacity", "int", what, "place", index)
        if capacity is not None and capacity < 0:
            raise self.fail(f"{what} has a negative capacity ({capacity})", self.smap.key("place", index, "capacity"))
        return self.build(self.smap.element("place", index), lambda: Place(
            id=pid, kind=kind, task=task, label=label, capacity=capacity)), tokens

    def check_places(self, places: Mapping[str, Place], tasks: Mapping[str, PrimitiveTask]) -> None:
        for index, table in enumerate(self.doc.get("place", [])):
            if not isinstance(table, dict):
                continue
            ident = table.get("id")
            place = places.get(ident) if isinstance(ident, str) else None
            if place is None or place.task is None or place.task in tasks:
                continue
            if place.task in self.doc.get("task", {}):
                continue  # the task itself is broken, already reported
            known = ", ".join(sorted(tasks)) or "none defined"
            self.report(f"place {place.id!r} names unknown task {place.task!r} (tasks: {known}); "
                        f"add a [task.{place.task}] table", self.smap.key("place", index, "task"))

    # ---------------------------------------------------------------- transitions
    def load_transitions(self) -> dict[str, Transition]:
        transitions: dict[str, Transition] = {}
        self.transition_arcs: list[tuple[int, str, str, Mapping[str, Any]]] = []
        for index, table in enumerate(self.doc.get("transition", [])):
            try:
                t = self.load_transition(index, table, transitions)
            except _Skip:
                continue
            transitions[t.id] = t
        return transitions

    def load_transition(self, index: int, table: Any, transitions: Mapping[str, Transition]) -> Transition:
        if not isinstance(table, dict):
            raise self.fail("a [[transition]] must be a table", self.smap.elements.get(("transition", index)))
        tid = self.element_id("transition", index, table, transitions)
        what = f"transition {tid!r}"
        sec = "transition"
        self.check_keys(table, _TRANSITION_KEYS, what, sec, index)
        events = self.get(table, "events", "array", what, sec, index, [])
        for event in events:
            if not isinstance(event, str) or not EVENT_RE.match(event):
                raise self.fail(f"{what} links bad event name {event!r}: use 'int:<task>.<outcome>' or "
                                "'ext:<topic>' (identifiers of letters, digits and '_')",
                                self.smap.key(sec, index, "events"))
        priority = self.get(table, "priority", "int", what, sec, index, 0)
        weight = self.get(table, "weight", "num", what, sec, index, 1.0)
        if not weight > 0:
            raise self.fail(f"{what} has weight {weight}; weights must be > 0", self.smap.key(sec, index, "weight"))
        kind_text = self.get(table, "kind", "str", what, sec, index, "immediate")
        try:
            kind = TransitionKind(kind_text)
        except ValueError:
            raise self.fail(f"{what} has unknown kind {kind_text!r} (use immediate or exponential)",
                            self.smap.key(sec, index, "kind")) from None
        rate = self.get(table, "rate", "num", what, sec, index)
        if rate is not None and kind is TransitionKind.IMMEDIATE:
            raise self.fail(f"immediate {what} cannot have a rate (add kind = \"exponential\")",
                            self.smap.key(sec, index, "rate"))
        if rate is not None and not rate > 0:
            raise self.fail(f"rate of {what} is {rate}; it must be > 0 (1/s)", self.smap.key(sec, index, "rate"))
        servers_value = table.get("servers", 1)
        if servers_value == "infinite":
            servers: int | None = None
        elif _is_int(servers_value) and servers_value >= 1:
            servers = servers_value
        else:
            raise self.fail(f"servers of {what} must be an integer >= 1 or \"infinite\", not {servers_value!r}",
                            self.smap.key(sec, index, "servers"))
        hidden = self.get(table, "hidden", "bool", what, sec, index, False)
        label = self.get(table, "label", "str", what, sec, index, "")
        for key in ("inputs", "outputs", "inhibitors"):
            arcs = self.get(table, key, "table", what, sec, index, {})
            self.transition_arcs.append((index, tid, key, arcs))
        return self.build(self.smap.element(sec, index), lambda: Transition(
            id=tid, events=tuple(events), priority=priority, weight=float(weight), kind=kind,
            rate=None if rate is None else float(rate), servers=servers, hidden=hidden, label=label))

    # ---------------------------------------------------------------- arcs
    def arc_weight(self, weight: Any, what: str, line: int | None) -> int:
        if not _is_int(weight) or weight < 1:
            raise self.fail(f"{what} has weight {weight!r}; arc weights are integers >= 1", line)
        return int(weight)

    def load_arcs(self, places: Mapping[str, Place], transitions: Mapping[str, Transition]) -> list[Arc]:
        arcs: list[Arc] = []
        seen: dict[tuple[str, str, bool], int | None] = {}

        def add(source: str, target: str, weight: int, inhibitor: bool, line: int | None) -> None:
            key = (source, target, inhibitor)
            if key in seen:
                kind = "inhibitor arc" if inhibitor else "arc"
                first = f" (first at line {seen[key]})" if seen[key] else ""
                self.report(f"{kind} {source} -> {target} is given twice{first}; use one arc with a weight", line)
                return
            seen[key] = line
            arcs.append(Arc(source=source, target=target, weight=weight, inhibitor=inhibitor))

        for index, tid, key, table in self.transition_arcs:
            line = self.smap.key("transition", index, key)
            for pid, weight in table.items():
                what = f"{key[:-1]} arc {pid} -> {tid}" if key != "outputs" else f"output arc {tid} -> {pid}"
                try:
                    w = self.arc_weight(weight, what, line)
                except _Skip:
                    continue
                if pid not in places:
                    if pid in transitions:
                        self.report(f"{key} of transition {tid!r} names transition {pid!r}; arcs join a place "
                                    "and a transition", line)
                    elif pid in self.smap_place_ids():
                        pass  # the place is broken, already reported
                    else:
                        self.report(f"{key} of transition {tid!r} names unknown place {pid!r}", line)
                    continue
                if key == "outputs":
                    add(tid, pid, w, False, line)
                else:
                    add(pid, tid, w, key == "inhibitors", line)
        for index, table in enumerate(self.doc.get("arc", [])):
            try:
                self.load_arc(index, table, places, transitions, add)
            except _Skip:
                continue
        return arcs

    def smap_place_ids(self) -> set[str]:
        ids = {ident for (section, ident) in self.smap.ids if section == "place"}
        for table in self.doc.get("place", []):
            if isinstance(table, dict) and isinstance(table.get("id"), str):
                ids.add(table["id"])
        return ids

    def load_arc(self, index: int, table: Any, places: Mapping[str, Place],
                 transitions: Mapping[str, Transition], add: Any) -> None:
        header = self.smap.elements.get(("arc", index))
        if not isinstance(table, dict):
            raise self.fail("an [[arc]] must be a table", header)
        self.check_keys(table, _ARC_KEYS, "an [[arc]]", "arc", index)
        ends = []
        for key in ("from", "to"):
            if key not in table:
                raise self.fail(f"an [[arc]] has no {key!r}", header)
            end = self.get(table, key, "str", "an [[arc]]", "arc", index)
            if end not in places and end not in transitions:
                raise self.fail(f"arc {table.get('from')} -> {table.get('to')}: unknown place or transition "
                                f"{end!r}", self.smap.key("arc", index, key))
            ends.append(end)
        source, target = ends
        line = self.smap.key("arc", index, "from")
        if (source in places) == (target in places):
            what = "two places" if source in places else "two transitions"
            raise self.fail(f"arc {source} -> {target} joins {what}; arcs join a place and a transition", line)
        weight = self.arc_weight(table.get("weight", 1), f"arc {source} -> {target}",
                                 self.smap.key("arc", index, "weight"))
        inhibitor = self.get(table, "inhibitor", "bool", "an [[arc]]", "arc", index, False)
        if inhibitor and source not in places:
            raise self.fail(f"inhibitor arc {source} -> {target} must go from a place to a transition",
                            self.smap.key("arc", index, "inhibitor"))
        add(source, target, weight, inhibitor, line)


def _syntax_error(exc: tomllib.TOMLDecodeError, path: str, smap_last: int) -> NetFileError:
    message = str(exc)
    match = re.search(r"\s*\(at line (\d+), column (\d+)\)\s*$", message)
    if match:
        line = int(match.group(1))
        problem = f"TOML syntax error: {message[:match.start()]} (column {match.group(2)})"
        return NetFileError(problem, path=path, line=line)
    match = re.search(r"\s*\(at end of document\)\s*$", message)
    if match:
        return NetFileError(f"TOML syntax error: {message[:match.start()]} (at end of file)",
                            path=path, line=smap_last)
    return NetFileError(f"TOML syntax error: {message}", path=path)


def _default_name(path: str) -> str:
    stem = Path(path).stem if not path.startswith("<") else "net"
    return stem or "net"


def lint_net(text: str, path: str = "<string>", *, interpreted: bool = True) -> tuple[PetriNet | None, list[NetError]]:
    """Load a net from TOML text, collecting every problem instead of stopping at the first.

    Args:
        text: the TOML source.
        path: file name for error messages.
        interpreted: also apply :meth:`PetriNet.interpretation_problems` (exits of primitive tasks,
            ``int:`` events naming tasks of input places).

    Returns:
        ``(net, [])`` for a valid file, else ``(None, problems)`` sorted by line; each problem is a
        :class:`NetError` (:class:`NetFileError` for a syntax error) with ``path`` and ``line``.
    """
    smap = SourceMap.scan(text)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        return None, [_syntax_error(exc, path, smap.last_line)]
    loader = _Loader(doc, smap, path)
    net = loader.load(_default_name(path), interpreted)
    problems = sorted(loader.problems, key=lambda e: (e.line is None, e.line or 0))
    return (net, []) if net is not None and not problems else (None, problems)


def loads_net(text: str, path: str = "<string>", *, interpreted: bool = True) -> PetriNet:
    """Load a net from the text of a TOML net file (format: docs/netfile.md).

    Args:
        text: the TOML source.
        path: file name for error messages.
        interpreted: also check the interpreted-net rules (see :func:`lint_net`).

    Returns:
        The net.

    Raises:
        NetFileError: on a TOML syntax error (line from :mod:`tomllib`).
        NetError: on the first problem found (by line), with ``path`` and ``line`` set.
    """
    net, problems = lint_net(text, path, interpreted=interpreted)
    if problems:
        raise problems[0]
    assert net is not None
    return net


def _read_text(path: str | Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise NetFileError(f"cannot read net file: {reason}", path=str(path)) from None


def load_net(path: str | Path, *, interpreted: bool = True) -> PetriNet:
    """Load a TOML net file; see :func:`loads_net`.

    Raises:
        NetFileError: if the file cannot be read, or on a syntax error.
        NetError: as :func:`loads_net`.
    """
    return loads_net(_read_text(path), str(path), interpreted=interpreted)


def load_any(path: str | Path, *, interpreted: bool = True) -> PetriNet:
    """Load a net file of any supported format, chosen by suffix: ``.toml``, ``.pnml`` or ``.xml``.

    Raises:
        NetFileError: unknown suffix, unreadable file, syntax error.
        NetError: as :func:`load_net` and :func:`coordinator.pnml.load_pnml`.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".toml":
        return load_net(path, interpreted=interpreted)
    if suffix in (".pnml", ".xml"):
        from coordinator.pnml import load_pnml

        net = load_pnml(path)
        if interpreted:
            problems = net.interpretation_problems()
            if problems:
                raise NetError(problems[0][1], path=str(path))
        return net
    raise NetFileError(f"unknown net file type {suffix or '(no suffix)'!r}: use .toml, .pnml or .xml", path=str(path))


# ============================================================================ saving
def _place_order(net: PetriNet, table: Mapping[str, int]) -> list[tuple[str, int]]:
    return sorted(table.items(), key=lambda kv: net.place_index[kv[0]])


def _inline(items: Iterable[tuple[str, Any]]) -> str:
    pairs = [f"{format_key(k)} = {format_value(v)}" for k, v in items]
    return "{ " + ", ".join(pairs) + " }" if pairs else "{}"


def dump_net(net: PetriNet) -> str:
    """Write a net as canonical TOML (docs/netfile.md, "Canonical form").

    Sections in the order ``[net]``, ``[[place]]`` (net order), ``[task.*]`` (definition order),
    ``[[transition]]`` (net order) with their arcs as ``inputs``/``outputs``/``inhibitors`` tables
    (keys in place order); keys equal to their default are left out. ``loads_net(dump_net(n)) == n``.

    Raises:
        NetError: if a parameter value cannot be written in TOML.
    """
    out: list[str] = [f"# petrobot net file, format {FORMAT_VERSION} (see docs/netfile.md)", "", "[net]",
                      f"name = {format_value(net.name)}"]
    if net.description:
        out.append(f"description = {format_value(net.description)}")
    out.append(f"format = {FORMAT_VERSION}")
    if net.home_marking is not None:
        out.append(f"home = {_inline(net.home_marking.items())}")
    for place in net.places:
        out += ["", "[[place]]", f"id = {format_value(place.id)}"]
        if place.kind is not PlaceKind.PLAIN:
            out.append(f"kind = {format_value(place.kind.value)}")
        if place.task is not None:
            out.append(f"task = {format_value(place.task)}")
        tokens = net.initial_marking[place.id]
        if tokens:
            out.append(f"tokens = {tokens}")
        if place.label:
            out.append(f"label = {format_value(place.label)}")
        if place.capacity is not None:
            out.append(f"capacity = {place.capacity}")
    for task in net.tasks.values():
        out += ["", f"[task.{format_key(task.name)}]"]
        if all(not a.params and a.cost is None for a in task.actions):
            out.append("actions = " + format_value([a.name for a in task.actions]))
        else:
            out.append("actions = [")
            for action in task.actions:
                items: list[tuple[str, Any]] = [("name", action.name)]
                if action.params:
                    items.append(("params", dict(action.params)))
                if action.cost is not None:
                    items.append(("cost", float(action.cost)))
                out.append(f"    {_inline(items)},")
            out.append("]")
        for key in ("deadline_s", "mean_time_s", "reliability"):
            value = getattr(task, key)
            if value is not None:
                out.append(f"{key} = {format_value(float(value))}")
        if task.learner:
            out.append(f"learner = {format_value(dict(task.learner))}")
    inputs, outputs, inhibitors = net.input_places, net.output_places, net.inhibitor_places
    for t in net.transitions:
        out += ["", "[[transition]]", f"id = {format_value(t.id)}"]
        if t.label:
            out.append(f"label = {format_value(t.label)}")
        if t.events:
            out.append(f"events = {format_value(list(t.events))}")
        if t.priority:
            out.append(f"priority = {t.priority}")
        if t.weight != 1.0:
            out.append(f"weight = {format_value(float(t.weight))}")
        if t.kind is not TransitionKind.IMMEDIATE:
            out.append(f"kind = {format_value(t.kind.value)}")
        if t.rate is not None:
            out.append(f"rate = {format_value(float(t.rate))}")
        if t.servers != 1:
            out.append("servers = " + ('"infinite"' if t.servers is None else str(t.servers)))
        if t.hidden:
            out.append("hidden = true")
        for key, table in (("inputs", inputs), ("outputs", outputs), ("inhibitors", inhibitors)):
            if table[t.id] or key != "inhibitors":
                out.append(f"{key} = {_inline(_place_order(net, table[t.id]))}")
    return "\n".join(out) + "\n"


def save_net(net: PetriNet, path: str | Path) -> None:
    """Write :func:`dump_net` of ``net`` to ``path`` (UTF-8).

    Raises:
        NetFileError: if the file cannot be written.
        NetError: as :func:`dump_net`.
    """
    text = dump_net(net)
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise NetFileError(f"cannot write net file: {exc.strerror or exc}", path=str(path)) from None


# ============================================================================ against services.toml
class _Placement(Protocol):
    def node_of(self, action: str) -> str: ...

    def publisher_of(self, topic: str) -> str: ...


def check_net(net: PetriNet, location: _Placement) -> list[tuple[str, str]]:
    """Check that a net can run with a location file (paper section 5).

    Every primitive action of every primitive task must be placed on a node, and every ``ext:``
    event linked to a transition must have a publishing node.

    Args:
        net: the task net.
        location: a :class:`services.location.Location` (anything with ``node_of(action)`` and
            ``publisher_of(topic)`` raising :class:`LocationError`).

    Returns:
        ``(element, problem)`` pairs, empty when the net can run; ``element`` is a task name or a
        transition id.
    """
    problems: list[tuple[str, str]] = []
    for task in net.tasks.values():
        for action in task.actions:
            try:
                location.node_of(action.name)
            except LocationError:
                problem = (f"primitive action {action.name!r} of task {task.name!r} is not placed on "
                           f"any node (add [actions.{action.name}] to services.toml)")
                problems.append((task.name, problem))
    reported: set[str] = set()
    for t in net.transitions:
        for event in t.external_events:
            topic = event.removeprefix("ext:")
            try:
                location.publisher_of(topic)
            except LocationError:
                if topic not in reported:
                    reported.add(topic)
                    problem = (f"external event {event!r} of transition {t.id!r} has no publisher "
                               f"(add [events.{topic}] to services.toml)")
                    problems.append((t.id, problem))
    return problems
