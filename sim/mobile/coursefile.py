"""Course files of the mobile-robot testbed (TOML, read with :mod:`tomllib`).

Format (see ``nets/courses/fig2.toml``)::

    [course]
    name = "fig2"
    start = [0, 0]            # square of the first tile
    heading = "east"          # direction of travel into it
    tiles = ["S", "L", "B", "S", "R", "E"]

    [floor]                   # optional
    square = 2.0              # m
    track_width = 0.05        # m
    end_bar_length = 0.40     # m, the T mark's cross bar
    first_square = "black"    # colour of square (0, 0)

    [beacon]                  # optional, see BeaconSpec
    height = 1.0
    post = true
    post_offset = 0.5

Tile codes may also be written as words: ``straight``, ``left``, ``right``, ``blank``,
``blank-left``, ``blank-right``, ``end``. Unknown sections and keys are errors (a typo must not
pass silently). Every problem is a :class:`sim.mobile.course.CourseError` whose text is
``FILE:LINE: problem``; lines come from a small scan of the text (:class:`_Lines`) since
:mod:`tomllib` keeps none.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .course import (
    HEADINGS,
    BeaconSpec,
    Course,
    CourseError,
    build_tiles,
    check,
)

__all__ = ["load_course", "parse_course"]

_LONG_NAMES = {
    "straight": "S", "left": "L", "right": "R", "end": "E", "blank": "B",
    "blank-left": "BL", "blank-right": "BR",
}

_HEAD = re.compile(r"^\s*\[\s*([A-Za-z0-9_-]+)\s*\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_-]+)\s*=")
_DECODE_LINE = re.compile(r"\s*\(at line (\d+), column \d+\)\s*$")


@dataclass
class _Lines:
    """Lines of the sections, keys and tile strings of a course file (scanned from its text)."""

    keys: dict[tuple[str, str], int] = field(default_factory=dict)
    sections: dict[str, int] = field(default_factory=dict)
    tiles: list[int] = field(default_factory=list)

    @classmethod
    def scan(cls, text: str) -> _Lines:
        out = cls()
        section = ""
        lines = text.splitlines()
        n = 0
        while n < len(lines):
            line = lines[n]
            head = _HEAD.match(line)
            key = _KEY.match(line)
            if head:
                section = head.group(1)
                out.sections.setdefault(section, n + 1)
            elif key:
                out.keys.setdefault((section, key.group(1)), n + 1)
                if (section, key.group(1)) == ("course", "tiles"):
                    n = out._scan_array(lines, n, key.end())
                    continue
            n += 1
        return out

    def _scan_array(self, lines: list[str], n: int, col: int) -> int:
        """Record the line of each string literal of the array starting on line n; returns the
        index of the line after the array."""
        depth, quote = 0, ""
        while n < len(lines):
            text = lines[n]
            i = col
            while i < len(text):
                ch = text[i]
                if quote:
                    if ch == "\\" and quote == '"':
                        i += 2
                        continue
                    if ch == quote:
                        quote = ""
                elif ch == "#":
                    break
                elif ch in "\"'":
                    quote = ch
                    self.tiles.append(n + 1)
                elif ch == "[":
                    depth += 1
                elif ch == "]":
                    depth -= 1
                    if depth <= 0:
                        return n + 1
                i += 1
            n, col = n + 1, 0
        return n


_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "course": {"name": str, "start": list, "heading": str, "tiles": list},
    "floor": {"square": (int, float), "track_width": (int, float), "end_bar_length": (int, float),
              "first_square": str},
    "beacon": {"height": (int, float), "radius": (int, float), "length": (int, float), "post": bool,
               "post_offset": (int, float)},
}


def parse_course(text: str, file: str = "<course>") -> Course:
    """Parse and check a course file's text (format in the module docstring).

    Args:
        text: TOML text.
        file: name used in error messages.

    Raises:
        CourseError: ``FILE:LINE: problem`` on a TOML syntax error, an unknown section or key, a
            value of the wrong type or range, or a broken course rule.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _DECODE_LINE.search(msg)
        raise CourseError(_DECODE_LINE.sub("", msg) if m else msg, file, int(m.group(1)) if m else None) from None
    where = _Lines.scan(text)

    def err(problem: str, section: str, key: str | None = None) -> CourseError:
        line = where.keys.get((section, key)) if key else None
        return CourseError(problem, file, line or where.sections.get(section))

    for section, table in data.items():
        if section not in _SCHEMA or not isinstance(table, dict):
            raise CourseError(
                f"unknown section [{section}] (expected {', '.join('[' + s + ']' for s in _SCHEMA)})",
                file, where.sections.get(section) or where.keys.get(("", section)),
            )
        for key, value in table.items():
            kinds = _SCHEMA[section]
            if key not in kinds:
                raise err(f"[{section}] has no key {key!r} (expected {', '.join(kinds)})", section, key)
            want = kinds[key]
            if not isinstance(value, want) or (isinstance(value, bool) and want != bool):
                raise err(f"[{section}] {key} has the wrong type {type(value).__name__}", section, key)
    if "course" not in data:
        raise CourseError("missing section [course]", file, 1)
    c = data["course"]
    if "tiles" not in c:
        raise err("[course] needs a tiles array", "course")
    raw = c["tiles"]
    codes = []
    for k, v in enumerate(raw):
        line = where.tiles[k] if k < len(where.tiles) else where.keys.get(("course", "tiles"))
        if not isinstance(v, str):
            raise CourseError(f"tile {k + 1} must be a string code, got {v!r}", file, line)
        codes.append(_LONG_NAMES.get(v.strip().lower(), v.strip().upper()))
    start = c.get("start", [0, 0])
    if len(start) != 2 or not all(isinstance(v, int) and not isinstance(v, bool) for v in start):
        raise err(f"[course] start must be two integers [i, j], got {start!r}", "course", "start")
    heading = c.get("heading", "east")
    if heading not in HEADINGS:
        raise err(f"[course] heading {heading!r} must be one of {', '.join(HEADINGS)}", "course", "heading")
    fl = data.get("floor", {})
    first = fl.get("first_square", "black")
    if first not in ("black", "white"):
        raise err(f"[floor] first_square must be \"black\" or \"white\", got {first!r}", "floor", "first_square")
    square = float(fl.get("square", 2.0))
    if not square > 0:
        raise err(f"[floor] square must be positive, got {square}", "floor", "square")
    bc = data.get("beacon", {})
    try:
        values: dict[str, Any] = {k: (float(v) if k != "post" else v) for k, v in bc.items()}
        beacon = BeaconSpec(**values)
    except ValueError as exc:
        raise err(str(exc), "beacon", next(iter(bc), None)) from None
    lines = [where.tiles[k] if k < len(where.tiles) else None for k in range(len(codes))]
    tiles = build_tiles(codes, (int(start[0]), int(start[1])), HEADINGS.index(heading), lines, file)
    if not tiles:
        raise err("[course] tiles is empty", "course", "tiles")
    course = Course(
        tiles,
        square=square,
        track_width=float(fl.get("track_width", 0.05)),
        end_bar_length=float(fl.get("end_bar_length", 0.40)),
        first_black=first == "black",
        beacon=beacon,
        name=str(c.get("name", Path(file).stem)),
        file=file,
    )
    try:
        check(course)
    except CourseError as exc:
        if exc.line is None and "track_width" in exc.problem:
            raise err(exc.problem, "floor", "track_width") from None
        if exc.line is None and "end_bar_length" in exc.problem:
            raise err(exc.problem, "floor", "end_bar_length") from None
        raise
    return course


def load_course(path: str | Path) -> Course:
    """Read and check a course file.

    Raises:
        CourseError: ``FILE:LINE: problem`` (also ``FILE: cannot read ...`` when unreadable).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CourseError(f"cannot read the course file: {exc}", str(p)) from None
    return parse_course(text, str(p))
