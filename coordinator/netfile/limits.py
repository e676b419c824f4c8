"""Limits on what a net file may hold, shared by the TOML and PNML readers (docs/netfile.md, "Limits").

The net model (:mod:`coordinator.net`) checks structure; these checks bound sizes and values so that
a hostile file cannot smuggle a NUL or a line break into an id (``re.match`` with ``$`` accepts a
trailing newline), a 10^6-character name into every log line, or a token count that overflows the
analyses' 64-bit markings. Each function returns the problem in words, or ``None`` when the value
is acceptable; the readers add the file and line. Pure: no I/O.
"""

from __future__ import annotations

import math
import re
import unicodedata

__all__ = [
    "MAX_COUNT",
    "MAX_DESCRIPTION",
    "MAX_LABEL",
    "MAX_NAME",
    "MAX_PRIORITY",
    "count_problem",
    "event_problem",
    "finite_problem",
    "id_problem",
    "priority_problem",
    "task_name_problem",
    "text_problem",
]

#: Largest token count, capacity, arc weight, inhibitor threshold, server count or home-marking
#: count (2**31 - 1): the analyses hold markings in 64-bit integers and add weights to them, so
#: every sum of a few thousand such numbers stays exact.
MAX_COUNT = 2**31 - 1
#: Priorities lie in [-MAX_PRIORITY - 1, MAX_PRIORITY].
MAX_PRIORITY = 2**31 - 1
#: Longest id, task name, action name, event name or net name, in characters.
MAX_NAME = 256
#: Longest label, in characters.
MAX_LABEL = 1024
#: Longest description, in characters.
MAX_DESCRIPTION = 65536

_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
_TASK = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_EVENT = re.compile(r"int:[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*|ext:[A-Za-z_][A-Za-z0-9_]*")


def _shown(value: str) -> str:
    return repr(value if len(value) <= 60 else value[:57] + "...")


def id_problem(value: str, what: str) -> str | None:
    """Problem with the id of a place, transition or action (``[A-Za-z_][A-Za-z0-9_.-]*``, ≤ 256)."""
    if len(value) > MAX_NAME:
        return f"{what} id {_shown(value)} is {len(value)} characters long; the limit is {MAX_NAME}"
    if not _ID.fullmatch(value):
        return (f"bad {what} id {_shown(value)}: use letters, digits, '_', '.', '-', starting with a "
                "letter or '_'")
    return None


def task_name_problem(value: str) -> str | None:
    """Problem with a primitive task name (``[A-Za-z_][A-Za-z0-9_]*``, ≤ 256 characters)."""
    if len(value) > MAX_NAME:
        return f"task name {_shown(value)} is {len(value)} characters long; the limit is {MAX_NAME}"
    if not _TASK.fullmatch(value):
        return (f"bad primitive task name {_shown(value)}: it appears in 'int:<task>.<outcome>' events, "
                "so use letters, digits and '_', starting with a letter or '_'")
    return None


def event_problem(value: str) -> str | None:
    """Problem with an event name (``int:<task>.<outcome>`` or ``ext:<topic>``, ≤ 256 characters)."""
    if len(value) > MAX_NAME or not _EVENT.fullmatch(value):
        return (f"bad event name {_shown(value)}: use 'int:<task>.<outcome>' or 'ext:<topic>' "
                f"(identifiers of letters, digits and '_'; at most {MAX_NAME} characters)")
    return None


def text_problem(value: str, what: str, limit: int, *, lines: bool = False) -> str | None:
    """Problem with free text (a name, label or description): length, control characters.

    Args:
        value: the text.
        what: what it is, for the message.
        limit: longest accepted length in characters.
        lines: allow line breaks and tabs (descriptions).
    """
    if len(value) > limit:
        return f"{what} is {len(value)} characters long; the limit is {limit}"
    allowed = "\t\n\r" if lines else ""
    for ch in value:
        if ch not in allowed and unicodedata.category(ch) in ("Cc", "Cs"):
            return f"{what} holds the control character {ch!r}"
    return None


def count_problem(value: int, what: str, minimum: int) -> str | None:
    """Problem with a count: below ``minimum`` or above :data:`MAX_COUNT`."""
    if value < minimum:
        return f"{what} is {value}; it must be >= {minimum}"
    if value > MAX_COUNT:
        return f"{what} is {value}; the limit is {MAX_COUNT} (2**31 - 1)"
    return None


def priority_problem(value: int, what: str) -> str | None:
    """Problem with a priority: outside [-2**31, 2**31 - 1]."""
    if not -MAX_PRIORITY - 1 <= value <= MAX_PRIORITY:
        return f"{what} is {value}; priorities lie in [-2**31, 2**31 - 1]"
    return None


def finite_problem(value: float, what: str) -> str | None:
    """Problem with a real number: NaN or infinite."""
    if not math.isfinite(value):
        return f"{what} is {value}; it must be a finite number"
    return None
