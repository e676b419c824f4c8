"""Every row read back from the journal is checked here before it becomes a record.

A journal is a file on a disk: a bit flipped by the disk, a row edited by hand, a copy cut short or a
write of another program can leave a field that petrobot never wrote — text where a number was,
JSON that does not parse, a status that does not exist, a byte sequence that is not UTF-8. Each
function below turns one row of one table into its typed record
(:mod:`coordinator.journal.records`), checking every field it reads; a field that is not what the
journal writes raises :class:`~coordinator.errors.DamagedJournal` naming the table, the row (its
``entry``; the ``rowid`` for ``run`` and ``learner_state``) and the field. The reader decides what
to do with it: skip the record and say so (``petrobot show``, ``runs``, ``perf``...) or refuse the
whole journal (``petrobot run --resume``). Pure: no I/O.

The connection reading the rows decodes text with :func:`decode_text`, which never fails: text that
is not UTF-8 reaches the checks below with its bad bytes escaped, and is reported as damaged there
rather than failing the whole query.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, NoReturn

from coordinator.errors import DamagedJournal
from coordinator.journal.records import (
    FeedbackRow,
    FiringRow,
    LearnerState,
    OperatorRow,
    ReconciliationRow,
    ResultRow,
    RunRow,
    StartRow,
)
from services.errors import ActionError
from services.results import ActionResult, Status

__all__ = [
    "STATUSES",
    "Fields",
    "decode_text",
    "feedback_row",
    "firing_row",
    "learner_row",
    "operator_row",
    "reconciliation_row",
    "result_row",
    "run_row",
    "start_row",
]

STATUSES = frozenset(s.value for s in Status)
"""The statuses a result row may hold."""
_MAX_INT = 2**63


def decode_text(data: bytes) -> str:
    """SQLite text as ``str`` without ever failing: bytes that are not UTF-8 are kept as lone
    surrogates (``surrogateescape``), which :meth:`Fields.text` reports as damage."""
    return data.decode("utf-8", "surrogateescape")


class Fields:
    """The checks of one row's fields; each failing check raises :class:`DamagedJournal` naming
    the table, the row and the field.

    Args:
        path: the journal, for the message.
        table: the row's table.
        row: the row's ``entry`` (or ``rowid``).
    """

    __slots__ = ("path", "row", "table")

    def __init__(self, path: str, table: str, row: object) -> None:
        self.path = path
        self.table = table
        self.row = row

    def fail(self, field: str, problem: str) -> NoReturn:
        """Raise the damage of ``field``."""
        raise DamagedJournal(self.path, problem, table=self.table, row=self.row, field=field)

    def text(self, field: str, value: object, *, optional: bool = False) -> Any:
        """``value`` as text (``None`` allowed when ``optional``)."""
        if value is None and optional:
            return None
        if not isinstance(value, str):
            self.fail(field, f"not text but {_kind(value)}")
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            self.fail(field, "text that is not UTF-8")
        return value

    def name(self, field: str, value: object, *, optional: bool = False) -> Any:
        """``value`` as a non-empty text (an id, a name)."""
        text = self.text(field, value, optional=optional)
        if text == "":
            self.fail(field, "empty")
        return text

    def integer(self, field: str, value: object, *, optional: bool = False, minimum: int = -_MAX_INT) -> Any:
        """``value`` as an integer at least ``minimum``."""
        if value is None and optional:
            return None
        if type(value) is not int:
            self.fail(field, f"not an integer but {_kind(value)}")
        if not minimum <= value < _MAX_INT:
            self.fail(field, f"integer {value} out of range")
        return value

    def flag(self, field: str, value: object) -> bool:
        """``value`` as a 0/1 flag."""
        if type(value) is not int or value not in (0, 1):
            self.fail(field, f"not 0 or 1 but {_kind(value)}")
        return bool(value)

    def number(self, field: str, value: object, *, optional: bool = False, non_negative: bool = False) -> Any:
        """``value`` as a finite float (non-negative when asked)."""
        if value is None and optional:
            return None
        if type(value) not in (int, float):
            self.fail(field, f"not a number but {_kind(value)}")
        x = float(value)  # type: ignore[arg-type]
        if not math.isfinite(x):
            self.fail(field, f"not a finite number: {x}")
        if non_negative and x < 0:
            self.fail(field, f"negative: {x}")
        return x

    def json(self, field: str, value: object, *, optional: bool = False) -> Any:
        """``value`` parsed as JSON text (``None`` for SQL NULL when ``optional``)."""
        text = self.text(field, value, optional=optional)
        if text is None:
            return None
        try:
            return json.loads(text)
        except (ValueError, RecursionError) as exc:
            self.fail(field, f"not JSON: {str(exc)[:80]}")

    def counts(self, field: str, value: object) -> dict[str, int]:
        """``value`` as the JSON object of a firing's consumed or produced tokens (place → count ≥ 0)."""
        got = self.json(field, value)
        if not isinstance(got, dict):
            self.fail(field, f"not a JSON object of place → tokens but {_kind(got)}")
        for place, n in got.items():
            if type(n) is not int or not 0 <= n < _MAX_INT:
                self.fail(field, f"place {place[:40]!r}: {n!r:.40} is not a token count")
        return got

    def status(self, field: str, value: object, *, optional: bool = False) -> Any:
        """``value`` as a result status (``success``, ``failure``, ``error``)."""
        text = self.text(field, value, optional=optional)
        if text is not None and text not in STATUSES:
            self.fail(field, f"status {text[:40]!r} is none of {', '.join(sorted(STATUSES))}")
        return None if text is None else Status(text)

    def result(self, status: Status, outcome: object, cost: object, wall_s: object, cpu_s: object,
               reason: object, value: object) -> ActionResult:
        """An action's result from its fields, each checked, then the result's own rules."""
        parts = {
            "outcome": self.text("outcome", outcome, optional=True),
            "cost": self.number("cost", cost, optional=True),
            "wall_s": self.number("wall_s", wall_s, optional=True, non_negative=True) or 0.0,
            "cpu_s": self.number("cpu_s", cpu_s, optional=True, non_negative=True) or 0.0,
            "reason": self.text("reason", reason, optional=True),
            "value": self.json("value", value, optional=True),
        }
        try:
            return ActionResult(status=status, **parts)
        except ActionError as exc:
            self.fail("outcome" if "outcome" in str(exc) else "status", str(exc))


def _kind(value: object) -> str:
    if value is None:
        return "NULL"
    if isinstance(value, (bytes, bytearray)):
        return f"a {len(value)}-byte blob"
    if isinstance(value, str):
        return f"text {value[:30]!r}"
    return f"{type(value).__name__} {value!r:.30}"


def run_row(path: str, values: tuple[Any, ...]) -> RunRow:
    """``(rowid, id, net_name, net_text, seed, started_wall, ended_wall, end_state, note)``."""
    rowid, rid, net_name, net_text, seed, started, ended, end_state, note = values
    f = Fields(path, "run", rowid)
    return RunRow(f.name("id", rid), f.text("net_name", net_name), f.text("net_text", net_text, optional=True),
                  f.integer("seed", seed, optional=True) or 0, f.number("started_wall", started),
                  f.number("ended_wall", ended, optional=True), f.text("end_state", end_state, optional=True),
                  f.text("note", note, optional=True))


def firing_row(path: str, values: tuple[Any, ...]) -> FiringRow:
    """``(entry, run, seq, transition, consumed, produced, instances, pulse, t_wall)``."""
    entry, run, seq, transition, consumed, produced, instances, pulse, t_wall = values
    f = Fields(path, "firing", entry)
    ids = f.json("instances", instances)
    if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
        f.fail("instances", "not a JSON list of instance ids")
    return FiringRow(f.name("run", run), f.integer("seq", seq, minimum=0), f.name("transition", transition),
                     f.counts("consumed", consumed), f.counts("produced", produced), tuple(ids),
                     f.text("pulse", pulse, optional=True), f.number("t_wall", t_wall), int(entry))


def start_row(path: str, values: tuple[Any, ...]) -> StartRow:
    """``(entry, run, instance, task, place, action, node, params, t_wall)``."""
    entry, run, instance, task, place, action, node, params, t_wall = values
    f = Fields(path, "action_start", entry)
    got = f.json("params", params, optional=True)
    if got is not None and not isinstance(got, dict):
        f.fail("params", f"not a JSON object but {_kind(got)}")
    return StartRow(f.name("run", run), f.name("instance", instance), f.name("task", task), f.name("place", place),
                    f.name("action", action), f.text("node", node, optional=True), got or {},
                    f.number("t_wall", t_wall), int(entry))


def result_row(path: str, values: tuple[Any, ...]) -> ResultRow:
    """``(entry, run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s, t_wall, reason, value,
    forced)``."""
    entry, run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s, t_wall, reason, value, forced \
        = values
    f = Fields(path, "action_result", entry)
    result = f.result(f.status("status", status), outcome, cost, wall_s, cpu_s, reason, value)
    return ResultRow(run=f.name("run", run), instance=f.name("instance", instance), task=f.name("task", task),
                     action=f.name("action", action), node=f.text("node", node, optional=True), result=result,
                     t_wall=f.number("t_wall", t_wall), entry=int(entry), forced=f.flag("forced", forced))


def operator_row(path: str, values: tuple[Any, ...]) -> OperatorRow:
    """``(entry, run, command, place, count, t_wall, accepted, reason, detail)``."""
    entry, run, command, place, count, t_wall, accepted, reason, detail = values
    f = Fields(path, "operator", entry)
    return OperatorRow(f.name("run", run), f.name("command", command), f.text("place", place, optional=True),
                       f.integer("count", count, optional=True), f.number("t_wall", t_wall), f.flag("accepted", accepted),
                       f.text("reason", reason, optional=True), int(entry), f.json("detail", detail, optional=True))


def reconciliation_row(path: str, values: tuple[Any, ...]) -> ReconciliationRow:
    """``(entry, run, instance, task, action, node, assumed, status, outcome, reason, cost, wall_s, cpu_s,
    value, t_wall)``."""
    entry, run, instance, task, action, node, assumed, status, outcome, reason, cost, wall_s, cpu_s, value, t_wall \
        = values
    f = Fields(path, "reconciliation", entry)
    known = f.status("status", status, optional=True)
    truth = None if known is None else f.result(known, outcome, cost, wall_s, cpu_s, reason, value)
    return ReconciliationRow(f.name("run", run), f.name("instance", instance), f.name("task", task),
                             f.name("action", action), f.text("node", node, optional=True),
                             f.status("assumed", assumed, optional=True), truth, f.number("t_wall", t_wall),
                             int(entry))


def feedback_row(path: str, values: tuple[Any, ...]) -> FeedbackRow:
    """``(entry, run, instance, task, action, data, t_wall)``."""
    entry, run, instance, task, action, data, t_wall = values
    f = Fields(path, "feedback", entry)
    return FeedbackRow(f.name("run", run), f.name("instance", instance), f.name("task", task),
                       f.name("action", action), f.json("data", data), f.number("t_wall", t_wall), int(entry))


def learner_row(path: str, values: tuple[Any, ...]) -> LearnerState:
    """``(rowid, task, scheme, state, updated_wall)``."""
    rowid, task, scheme, state, updated = values
    f = Fields(path, "learner_state", rowid)
    got = f.json("state", state)
    if not isinstance(got, Mapping):
        f.fail("state", f"not a JSON object but {_kind(got)}")
    scheme = f.text("scheme", scheme, optional=True)
    if "scheme" in got and got["scheme"] != scheme:
        f.fail("scheme", f"{scheme!r} disagrees with the state's scheme ({str(got['scheme'])[:40]!r})")
    return LearnerState(f.name("task", task), scheme or "", got, f.number("updated_wall", updated))
