"""Writing TOML: values, and a net as a canonical net file (docs/netfile.md, "Canonical form").

:func:`dump_net` writes one canonical form (arcs inside the transitions) that
:func:`~coordinator.netfile.loader.loads_net` reads back equal. :func:`format_value` writes one
TOML value on one line; the PNML writer uses it for the tables it keeps as TOML text.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from coordinator.errors import NetError, NetFileError
from coordinator.net import PetriNet, PlaceKind, TransitionKind
from coordinator.netfile.schema import FORMAT_VERSION
from services.textfile import write_atomically

__all__ = ["dump_net", "format_key", "format_value", "save_net"]

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


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


def _place_order(net: PetriNet, table: Mapping[str, int]) -> list[tuple[str, int]]:
    return sorted(table.items(), key=lambda kv: net.place_index[kv[0]])


def _inline(items: Iterable[tuple[str, Any]]) -> str:
    pairs = [f"{format_key(k)} = {format_value(v)}" for k, v in items]
    return "{ " + ", ".join(pairs) + " }" if pairs else "{}"


def _pos(layout: Mapping[str, tuple[float, float]] | None, ident: str) -> list[str]:
    if layout is None or ident not in layout:
        return []
    x, y = layout[ident]
    return [f"pos = [{format_value(round(float(x), 1))}, {format_value(round(float(y), 1))}]"]


def dump_net(net: PetriNet, layout: Mapping[str, tuple[float, float]] | None = None) -> str:
    """Write a net as canonical TOML (docs/netfile.md, "Canonical form").

    Sections in the order ``[net]``, ``[operator]`` (when the net declares what an operator may
    force), ``[[place]]`` (net order), ``[task.*]`` (definition order),
    ``[[transition]]`` (net order) with their arcs as ``inputs``/``outputs``/``inhibitors`` tables
    (keys in place order), then one ``[[arc]]`` table per reset arc (transition order, then place
    order); keys equal to their default are left out; a rate or weight expression is written as a
    string. ``loads_net(dump_net(n)) == n``. ``layout`` (id → (x, y),
    :mod:`~coordinator.netfile.layout`) adds the drawing's ``pos = [x, y]`` to the places and
    transitions it names, rounded to 0.1 drawing unit.

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
    if net.operator:
        out += ["", "[operator]"]
        if net.operator.inject:
            out.append(f"inject = {format_value(list(net.operator.inject))}")
        if net.operator.force:
            out.append(f"force = {_inline((task, list(outcomes)) for task, outcomes in net.operator.force.items())}")
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
        out += _pos(layout, place.id)
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
        if t.weight_expr is not None:
            out.append(f"weight = {format_value(t.weight_expr)}")
        elif t.weight != 1.0:
            out.append(f"weight = {format_value(float(t.weight))}")
        if t.kind is not TransitionKind.IMMEDIATE:
            out.append(f"kind = {format_value(t.kind.value)}")
        if t.rate_expr is not None:
            out.append(f"rate = {format_value(t.rate_expr)}")
        elif t.rate is not None:
            out.append(f"rate = {format_value(float(t.rate))}")
        if t.servers != 1:
            out.append("servers = " + ('"infinite"' if t.servers is None else str(t.servers)))
        if t.hidden:
            out.append("hidden = true")
        out += _pos(layout, t.id)
        for key, table in (("inputs", inputs), ("outputs", outputs), ("inhibitors", inhibitors)):
            if table[t.id] or key != "inhibitors":
                out.append(f"{key} = {_inline(_place_order(net, table[t.id]))}")
    for t in net.transitions:
        for pid in sorted(net.reset_places[t.id], key=net.place_index.__getitem__):
            out += ["", "[[arc]]", f"from = {format_value(pid)}", f"to = {format_value(t.id)}", "reset = true"]
    return "\n".join(out) + "\n"


def save_net(net: PetriNet, path: str | Path, layout: Mapping[str, tuple[float, float]] | None = None) -> None:
    """Write :func:`dump_net` of ``net`` (with ``layout``'s positions) to ``path`` (UTF-8).

    Raises:
        NetFileError: if the file cannot be written.
        NetError: as :func:`dump_net`.
    """
    text = dump_net(net, layout)
    try:
        write_atomically(path, text)
    except OSError as exc:
        raise NetFileError(f"cannot write net file: {exc.strerror or exc}", path=str(path)) from None
