"""Where a net's places and transitions are drawn: positions kept in the net file (docs/netfile.md).

The drawing of a task net (paper section 5: a task is designed by drawing its net) is part of
the file, not of the model: a :class:`~coordinator.net.PetriNet` compares equal whatever its
drawing, and the engine and analyses never see positions. A TOML net file gives a place or a
transition ``pos = [x, y]``; a PNML file gives it ``<graphics><position x= y=/></graphics>``
(the standard's own element). Coordinates are drawing units (pixels at zoom 1), x to the right,
y downwards, finite and within ``±MAX_COORD``.

* :func:`position_problem` — the check the TOML loader applies to a ``pos`` value;
* :func:`layout_of_doc` — the positions of a parsed TOML document;
* :func:`loads_layout`, :func:`pnml_layout`, :func:`load_layout` — of TOML text, PNML text, a file.

Reading positions is tolerant: a value that is not a valid position is left out (the loader has
already reported it), so a drawing opens even from a file with problems. Pure apart from
:func:`load_layout`, which reads a file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from services.textfile import TextProblem, decode_utf8, read_capped
from services.tomllines import parse_toml

__all__ = ["MAX_COORD", "Layout", "layout_of_doc", "load_layout", "loads_layout", "pnml_layout",
           "position_problem"]

Layout = dict[str, tuple[float, float]]
"""Place or transition id → (x, y) in drawing units."""

#: Largest absolute coordinate accepted.
MAX_COORD = 1e6


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def position_problem(value: Any, what: str) -> str | None:
    """The problem with a ``pos`` value, or ``None`` when it is ``[x, y]`` with finite coordinates
    of at most :data:`MAX_COORD` in absolute value."""
    if not isinstance(value, list) or len(value) != 2 or not all(_number(v) for v in value):
        return f"pos of {what} must be [x, y], two numbers"
    if not all(math.isfinite(v) and abs(v) <= MAX_COORD for v in value):
        return f"pos of {what} must be finite coordinates within ±{MAX_COORD:g}"
    return None


def layout_of_doc(doc: Mapping[str, Any]) -> Layout:
    """Positions of the ``[[place]]`` and ``[[transition]]`` tables of a parsed TOML net file."""
    layout: Layout = {}
    for section in ("place", "transition"):
        tables = doc.get(section)
        if not isinstance(tables, list):
            continue
        for table in tables:
            if not isinstance(table, dict) or not isinstance(table.get("id"), str):
                continue
            pos = table.get("pos")
            if pos is not None and position_problem(pos, "") is None:
                layout[table["id"]] = (float(pos[0]), float(pos[1]))
    return layout


def loads_layout(text: str) -> Layout:
    """Positions in the text of a TOML net file; empty when the text is not TOML."""
    try:
        doc, _ = parse_toml(text)
    except TextProblem:
        return {}
    return layout_of_doc(doc)


def pnml_layout(data: str | bytes) -> Layout:
    """Positions of the places and transitions of a PNML document (``<graphics><position>``).

    The document is parsed as :mod:`coordinator.netfile.pnml` parses it (no DOCTYPE, bounded
    depth); a document it refuses has no positions.
    """
    from coordinator.errors import NetError
    from coordinator.netfile.pnml import _parse_xml

    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        root, _ = _parse_xml(raw, "<pnml>")
    except NetError:
        return {}
    layout: Layout = {}
    for elem in root.iter():
        if elem.tag not in ("place", "transition") or "id" not in elem.attrib:
            continue
        position = elem.find("graphics/position")
        if position is None:
            continue
        try:
            xy = [float(position.attrib["x"]), float(position.attrib["y"])]
        except (KeyError, ValueError):
            continue
        if position_problem(xy, "") is None:
            layout[elem.attrib["id"]] = (xy[0], xy[1])
    return layout


def load_layout(path: str | Path) -> Layout:
    """Positions in a net file (``.toml``, ``.pnml``, ``.xml``); empty if it cannot be read."""
    try:
        data = read_capped(path, what="net file")
    except TextProblem:
        return {}
    if Path(path).suffix.lower() == ".toml":
        try:
            return loads_layout(decode_utf8(data))
        except TextProblem:
            return {}
    return pnml_layout(data)
