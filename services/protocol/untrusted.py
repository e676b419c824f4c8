"""Text from the wire made safe to log: escaped, on one line, and short.

Everything a peer sends is untrusted: a ``bye`` reason, a client name, a call id or an action name
may hold newlines (forged log lines), ANSI escape sequences (a terminal rewritten), NUL bytes, or
16 MiB of text (a flooded log). :func:`shown` turns any such value into a printable, single-line
string of bounded length before it is logged or put in an error message.
"""

from __future__ import annotations

import reprlib
from typing import Any, Final

__all__ = ["DEFAULT_LIMIT", "shown"]

DEFAULT_LIMIT: Final = 80
"""Characters of untrusted text kept by default (before escaping)."""

_ESCAPES: Final = {"\\": "\\\\", "\n": "\\n", "\r": "\\r", "\t": "\\t"}
_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = DEFAULT_LIMIT
_REPR.maxlevel = 3


def _escape(text: str) -> str:
    if text.isprintable() and "\\" not in text:
        return text
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append(_ESCAPES[c])
        elif c.isprintable():
            out.append(c)
        else:
            code = ord(c)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}")
    return "".join(out)


def shown(value: Any, limit: int = DEFAULT_LIMIT) -> str:
    """A printable one-line rendering of ``value`` of at most about ``limit`` characters.

    Strings keep their text with control and other non-printable characters (newline, ESC, NUL,
    U+2028...) and backslashes escaped as ``\\n``, ``\\x1b``...; past ``limit`` characters the rest
    is replaced by ``…(+N chars)``. Bytes are shown as their ``repr`` prefix the same way, and any
    other value through :mod:`reprlib` (bounded however large the value is).

    Args:
        value: anything, usually received from a peer.
        limit: characters of the value kept (escaping may make the line up to 10 times longer).

    Returns:
        The rendering (never contains a newline or a non-printable character).
    """
    if type(value) is str:
        extra = len(value) - limit
        text = _escape(value[:limit]) if extra > 0 else _escape(value)
        return f"{text}…(+{extra} chars)" if extra > 0 else text
    if type(value) in (bytes, bytearray):
        extra = len(value) - limit
        text = repr(bytes(value[:limit]))  # printable ASCII on one line already
        return f"{text}…(+{extra} bytes)" if extra > 0 else text
    text = _REPR.repr(value)[: 4 * limit]
    return text if text.isprintable() else _escape(text)
