"""TOML with line numbers and limits: where each table and key is, and a parser that cannot recurse away.

:mod:`tomllib` reports the position of a syntax error only, so :class:`TomlLines` scans the source
text for table headers and keys and records the line of each; readers of TOML files (the net
loader, ``services.toml``) use it to put a line on every problem they find after parsing. The scan
also measures nesting (arrays, inline tables, dotted keys) and the length of bare values, so
:func:`parse_toml` refuses a 10^5-deep array or a 5,000-digit integer with its line *before*
:mod:`tomllib` would overflow the interpreter's stack or raise a bare ``ValueError``.

Paths name tables and keys as :mod:`tomllib` nests them, with the index of each element of an array
of tables: ``[[place]]`` twice then ``id = "p"`` gives ``("place", 1, "id")``. Pure: no I/O.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from services.textfile import TextProblem, screen_text

__all__ = ["MAX_BARE_VALUE", "MAX_DEPTH", "KeyPath", "TomlLines", "parse_toml"]

#: Deepest nesting of tables, arrays, inline tables and dotted-key parts accepted in a document.
#: Real files nest three or four levels; :mod:`tomllib` recurses once per level of arrays and
#: inline tables and would exhaust Python's stack at a few hundred.
MAX_DEPTH = 64
#: Longest bare value (number, date, boolean) in characters; a 5,000-digit integer is refused here
#: instead of inside :mod:`tomllib` (Python's integer-conversion limit).
MAX_BARE_VALUE = 256
#: Largest integer magnitude accepted anywhere: TOML integers are 64-bit signed.
INT64 = 2**63

KeyPath = tuple[str | int, ...]

_BARE_KEY = re.compile(r"[A-Za-z0-9_\-]+")
_DELIMITERS = frozenset(" \t\r,[]{}=#\"'")
#: A value that opens nothing: one plain basic string, or one short bare value; a comment may follow.
_BARE = r"[^\s\"'\[\]{}#,=.]{1,%d}" % MAX_BARE_VALUE  # noqa: UP031 (braces of the class)
_PLAIN_VALUE = re.compile(rf"[ \t]*(?:\"[^\"\\]*\"|{_BARE}(?:\.{_BARE})?)[ \t\r]*(?:#.*)?")


def _skip_ws(line: str, i: int) -> int:
    n = len(line)
    while i < n and line[i] in " \t":
        i += 1
    return i


class _TooManyParts(Exception):
    """A dotted key has more parts than the nesting limit allows."""


def _parse_key(line: str, i: int, max_parts: int) -> tuple[list[str], int] | None:
    """Parse a (dotted) key starting at ``line[i]``; return its parts and the index after it.

    Raises:
        _TooManyParts: more than ``max_parts`` parts, whether or not the key is well formed
            (:mod:`tomllib` takes time quadratic in the number of parts, even to refuse a key).
    """
    parts: list[str] = []
    n = len(line)
    while True:
        if len(parts) > max_parts:
            raise _TooManyParts
        i = _skip_ws(line, i)
        if i >= n:
            return None
        ch = line[i]
        if ch == '"':
            j = i + 1
            while j < n and line[j] != '"':
                j += 2 if line[j] == "\\" else 1
            if j >= n:
                return None
            raw = line[i:j + 1]
            try:
                parts.append(str(tomllib.loads(f"k = {raw}")["k"]) if "\\" in raw else raw[1:-1])
            except tomllib.TOMLDecodeError:
                parts.append(raw[1:-1])
            i = j + 1
        elif ch == "'":
            j = line.find("'", i + 1)
            if j < 0:
                return None
            parts.append(line[i + 1:j])
            i = j + 1
        else:
            match = _BARE_KEY.match(line, i)
            if match is None:
                return None
            parts.append(match.group())
            i = match.end()
        i = _skip_ws(line, i)
        if i < n and line[i] == ".":
            i += 1
            continue
        return parts, i


@dataclass
class _State:
    """Scanner state carried from line to line: an open multi-line string, open brackets."""

    ml: str | None = None
    depth: int = 0
    base: int = 0  # nesting of the key whose value is open


@dataclass
class TomlLines:
    """Lines of the tables and keys of a TOML document, found by scanning its text.

    Attributes:
        lines: first 1-based line of each table header or key, by :data:`KeyPath`.
        values: text after ``=`` on the line of each key (the start of its value).
        last_line: number of the last line (for problems "at end of file").
    """

    lines: dict[KeyPath, int] = field(default_factory=dict)
    values: dict[KeyPath, str] = field(default_factory=dict)
    last_line: int = 1

    @classmethod
    def scan(cls, text: str, *, max_depth: int = MAX_DEPTH) -> TomlLines:
        """Map ``text`` (best effort on text that is not valid TOML).

        Raises:
            TextProblem: nesting deeper than ``max_depth``, or a bare value longer than
                :data:`MAX_BARE_VALUE` characters, with its line.
        """
        out = cls()
        state = _State()
        header: KeyPath = ()
        counters: dict[KeyPath, int] = {}
        number = 0
        for number, line in enumerate(text.split("\n"), start=1):
            if state.ml is None and state.depth == 0:
                i = _skip_ws(line, 0)
                if i >= len(line) or line[i] == "#":
                    continue
                try:
                    if line[i] == "[":
                        head = out._header(line, i, counters, number, max_depth)
                        if head is not None:
                            header = head
                            continue
                    parsed = _parse_key(line, i, max_depth)
                except _TooManyParts:
                    raise TextProblem(f"nesting deeper than {max_depth} levels (a dotted key of more "
                                      f"than {max_depth} parts)", number) from None
                if parsed is None or parsed[1] >= len(line) or line[parsed[1]] != "=":
                    continue  # not a key: tomllib will say why
                parts, end = parsed
                path = header + tuple(parts)
                depth = len(path)
                if depth > max_depth:
                    raise TextProblem(f"nesting deeper than {max_depth} levels (a dotted key of "
                                      f"{len(parts)} parts)", number)
                out._record(path, number)
                value = line[end + 1:]
                out.values.setdefault(path, value)
                if not _PLAIN_VALUE.fullmatch(value):  # the common one-line value needs no scan
                    state.base = depth
                    _scan_value(line, end + 1, state, number, max_depth)
            else:
                _scan_value(line, 0, state, number, max_depth)
        out.last_line = max(1, number - 1 if text.endswith("\n") else number)
        return out

    def _header(self, line: str, i: int, counters: dict[KeyPath, int], number: int,
                max_depth: int) -> KeyPath | None:
        double = line.startswith("[[", i)
        parsed = _parse_key(line, i + (2 if double else 1), max_depth)
        if parsed is None:
            return None
        parts, end = parsed
        closing = "]]" if double else "]"
        if not line.startswith(closing, end):
            return None
        if len(parts) > max_depth:
            raise TextProblem(f"nesting deeper than {max_depth} levels (a table header of "
                              f"{len(parts)} parts)", number)
        path: KeyPath = ()
        for k, part in enumerate(parts):
            path = path + (part,)
            if path in counters and not (double and k == len(parts) - 1):
                path = path + (counters[path],)
        if double:
            counters[path] = counters.get(path, -1) + 1
            path = path + (counters[path],)
        if len(path) > max_depth:
            raise TextProblem(f"nesting deeper than {max_depth} levels (a table header)", number)
        self._record(path, number)
        return path

    def _record(self, path: KeyPath, number: int) -> None:
        """Record the line of ``path`` and of the tables it defines implicitly (``[a.b]`` defines ``a``)."""
        for end in range(1, len(path) + 1):
            self.lines.setdefault(path[:end], number)

    def exact(self, path: KeyPath) -> int | None:
        """Line of exactly this table or key, or ``None``."""
        return self.lines.get(path)

    def line(self, *path: str | int) -> int | None:
        """Line of a table or key, else of its nearest enclosing table or key found, else ``None``."""
        for end in range(len(path), 0, -1):
            found = self.lines.get(path[:end])
            if found is not None:
                return found
        return None

    def in_order(self) -> Iterator[tuple[KeyPath, int]]:
        """Every recorded path with its line, in the order of the file."""
        return iter(sorted(self.lines.items(), key=lambda kv: kv[1]))


def _scan_value(line: str, i: int, state: _State, number: int, max_depth: int) -> None:
    """Follow strings and brackets over one line of a value; check nesting and bare values."""
    n = len(line)
    bare = dots = 0
    while i < n:
        if state.ml is not None:
            end = line.find(state.ml, i)
            if end < 0:
                return
            i = end + 3
            while i < n and line[i] == state.ml[0]:  # up to two quotes may close with the delimiter
                i += 1
            state.ml = None
            continue
        ch = line[i]
        if ch in _DELIMITERS:
            bare = 0
            if ch in "=,[]{}":
                dots = 0
        else:
            bare += 1
            if ch == ".":  # dotted keys in inline tables: a float or a date has one dot
                dots += 1
                if dots > max_depth:
                    raise TextProblem(f"nesting deeper than {max_depth} levels (a dotted key of more "
                                      f"than {max_depth} parts)", number)
            if bare > MAX_BARE_VALUE:
                raise TextProblem(f"a bare value of more than {MAX_BARE_VALUE} characters (a number "
                                  "too long?)", number)
            i += 1
            continue
        if ch == "#":
            return
        if line.startswith('"""', i) or line.startswith("'''", i):
            state.ml = line[i:i + 3]
            i += 3
            continue
        if ch in "\"'":
            j = i + 1
            while j < n and line[j] != ch:
                j += 2 if ch == '"' and line[j] == "\\" else 1
            i = j + 1
            continue
        if ch in "[{":
            state.depth += 1
            if state.base + state.depth > max_depth:
                raise TextProblem(f"nesting deeper than {max_depth} levels of arrays and inline tables",
                                  number)
        elif ch in "]}":
            state.depth = max(0, state.depth - 1)
        i += 1


def _syntax_problem(exc: tomllib.TOMLDecodeError, last_line: int) -> TextProblem:
    message = str(exc)
    match = re.search(r"\s*\(at line (\d+), column (\d+)\)\s*$", message)
    if match:
        return TextProblem(f"TOML syntax error: {message[:match.start()]} (column {match.group(2)})",
                           int(match.group(1)))
    match = re.search(r"\s*\(at end of document\)\s*$", message)
    if match:
        return TextProblem(f"TOML syntax error: {message[:match.start()]} (at end of file)", last_line)
    return TextProblem(f"TOML syntax error: {message}")


def _check_values(doc: dict[str, Any], lines: TomlLines, max_depth: int) -> None:
    """Walk the parsed document without recursion: nesting, NUL in strings, 64-bit integers."""
    stack: list[tuple[KeyPath, Any]] = [((), doc)]
    while stack:
        path, value = stack.pop()
        if len(path) > max_depth:
            raise TextProblem(f"nesting deeper than {max_depth} levels", lines.line(*path))
        if isinstance(value, dict):
            for key, item in value.items():
                if "\0" in key:
                    raise TextProblem(f"NUL character in the key {key!r}", lines.line(*path))
                stack.append((path + (key,), item))
        elif isinstance(value, list):
            stack.extend((path + (k,), item) for k, item in enumerate(value))
        elif isinstance(value, str):
            if "\0" in value:
                raise TextProblem(f"NUL character in the string {_dotted(path)}", lines.line(*path))
        elif isinstance(value, int) and not isinstance(value, bool) and not -INT64 <= value < INT64:
            raise TextProblem(f"integer {_dotted(path)} is out of range: TOML integers are 64-bit",
                              lines.line(*path))


def _dotted(path: KeyPath) -> str:
    return ".".join(str(p) for p in path) or "value"


def parse_toml(text: str, *, max_depth: int = MAX_DEPTH) -> tuple[dict[str, Any], TomlLines]:
    """Parse TOML text within the limits, and map its lines.

    Refuses, each with the line where it can be found: NUL characters (raw or escaped), nesting
    deeper than ``max_depth``, bare values longer than :data:`MAX_BARE_VALUE`, integers beyond 64
    bits, and TOML syntax errors (line and column from :mod:`tomllib`).

    Returns:
        ``(document, lines)``.

    Raises:
        TextProblem: the text is refused.
    """
    screen_text(text)
    lines = TomlLines.scan(text, max_depth=max_depth)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_problem(exc, lines.last_line) from None
    except RecursionError:  # the scan missed a nesting (it follows strings on a best-effort basis)
        raise TextProblem(f"nesting deeper than {max_depth} levels of arrays and inline tables") from None
    except ValueError as exc:  # an over-long number the scan missed
        raise TextProblem(f"a value cannot be read: {exc}") from None
    _check_values(doc, lines, max_depth)
    return doc, lines
