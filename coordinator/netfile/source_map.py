"""Where things are in a TOML net file: the line of each element and key (docs/netfile.md).

:mod:`tomllib` reports positions of syntax errors only, so :class:`SourceMap` reads the lines
:class:`services.tomllines.TomlLines` found for each table and key (the same scan ``services.toml``
uses) in terms of the net file: places, transitions, arcs by index, tasks by name, ids. The loader
uses it to name the line of every problem, and ``petrobot check`` the line of a placement problem.
A best effort on text that is not valid TOML.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from typing import Any

from services.textfile import TextProblem
from services.tomllines import TomlLines

__all__ = ["SourceMap"]

_ARRAYS = ("place", "transition", "arc")
_SIMPLE_STRING = re.compile(r'[ \t]*"([^"\\]*)"[ \t\r]*(?:#.*)?')


@dataclass
class SourceMap:
    """Lines of the elements and keys of a net file, found by scanning its text.

    Elements are ``("net", None)``, ``("operator", None)``, ``("place", i)``, ``("transition", i)``, ``("arc", i)`` (0-based
    index among the tables of that array) and ``("task", name)``. Lines are 1-based.
    """

    elements: dict[tuple[str, Any], int] = field(default_factory=dict)
    keys: dict[tuple[str, Any, str], int] = field(default_factory=dict)
    ids: dict[tuple[str, str], int] = field(default_factory=dict)
    last_line: int = 1

    @classmethod
    def scan(cls, text: str) -> SourceMap:
        """Build the map of ``text`` (a best effort: empty for text the scan refuses)."""
        try:
            lines = TomlLines.scan(text)
        except TextProblem:
            return cls()
        return cls.from_lines(lines)

    @classmethod
    def from_lines(cls, lines: TomlLines) -> SourceMap:
        """Read the tables and keys :class:`TomlLines` found as net-file elements."""
        smap = cls(last_line=lines.last_line)
        for path, number in lines.in_order():
            smap._record(path, number, lines.values.get(path))
        return smap

    def _record(self, path: tuple[str | int, ...], number: int, value_text: str | None) -> None:
        section = str(path[0])
        ident: Any
        if section in _ARRAYS:
            if len(path) < 2 or not isinstance(path[1], int):
                self.elements.setdefault((section, None), number)
                return
            ident, rest = path[1], path[2:]
        elif section == "task":
            if len(path) < 2:
                self.elements.setdefault((section, None), number)
                return
            ident, rest = path[1], path[2:]
        elif section in ("net", "operator"):
            ident, rest = None, path[1:]
        else:
            self.elements.setdefault((section, None), number)
            return
        self.elements.setdefault((section, ident), number)
        if section == "task":
            self.ids.setdefault(("task", ident), number)
        if rest:
            self.keys.setdefault((section, ident, str(rest[0])), number)
            if rest == ("id",) and section in _ARRAYS and value_text is not None and len(value_text) < 1024:
                simple = _SIMPLE_STRING.fullmatch(value_text)
                try:
                    value = simple.group(1) if simple else tomllib.loads("id = " + value_text)["id"]
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
