"""Where things are in a TOML net file: the line of each element and key (docs/netfile.md).

:mod:`tomllib` reports positions of syntax errors only, so :class:`SourceMap` scans the source text
for table headers and keys; the loader uses it to name the line of every problem, and ``petrobot
check`` the line of a placement problem. A best effort on text that is not valid TOML.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SourceMap"]


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
