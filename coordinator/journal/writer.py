"""Writing the journal: an SQLite (WAL) log of every run of a task net (paper sections 3 to 5).

Every firing, action start, action result and operator command is written — and committed —
before it takes effect (and, later, what a node said about a call the coordinator had given up on:
a reconciliation), so that ``petrobot run --resume`` can rebuild the marking and the live
instances of an interrupted run (:meth:`JournalReader.recover`). The same tables feed the
quantitative analysis (reliability and durations per primitive action, section 3) and learning
(section 4). The tables: :mod:`coordinator.journal.schema`.

Durability: WAL with ``synchronous=NORMAL``: a committed record survives a crash of the
coordinator process (not a power loss of the host).

Order: every record takes the next number of one ``entry`` sequence shared by the record tables,
so a run replays in the order it was written (one writer at a time per journal; a second writer's
collision is retried with a fresh number). Opening a journal written by an older petrobot migrates
it (:func:`coordinator.journal.schema.migrate`).
"""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from coordinator.engine import Firing
from coordinator.errors import JournalError
from coordinator.journal.reader import JournalReader
from coordinator.journal.schema import DDL, RECORD_TABLES, check_schema, check_tables, check_version, migrate
from coordinator.net import PetriNet
from services.results import ActionResult, Status

__all__ = ["FEEDBACK_BYTES", "Journal"]

FEEDBACK_BYTES = 4096
"""The longest feedback (its JSON text, characters) the journal keeps whole."""


def _json(value: Any) -> str | None:
    try:
        return json.dumps(value, sort_keys=True, default=_jsonable)
    except (TypeError, ValueError):
        return None


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, (bytes, bytearray)):
        return f"<{len(value)} bytes>"
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(type(value).__name__)


class Journal(JournalReader):
    """An open journal database, for writing (and reading: see :class:`JournalReader`).

    Args:
        path: SQLite file (created with its tables if missing), or ``":memory:"``.

    Raises:
        JournalError: if the file cannot be opened.
        DamagedJournal: it is not a petrobot journal, or a table of it is missing
            (:func:`~coordinator.journal.schema.check_tables`: never re-created under records).
        JournalTooNew: it was written by a newer petrobot.
    """

    def __init__(self, path: str | Path) -> None:
        name = str(path)
        try:
            db = sqlite3.connect(name, isolation_level=None, check_same_thread=False)
        except sqlite3.Error as exc:
            raise JournalError(f"{name}: cannot open the journal: {exc}") from exc
        try:
            check_version(db, name)
            check_tables(db, name)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.executescript(f"BEGIN;{DDL}COMMIT;")  # all the tables, or none
            check_schema(db, name)
            migrate(db, name)
        except sqlite3.DatabaseError as exc:
            db.close()
            raise JournalError(f"{name}: cannot open the journal: {exc}") from exc
        except JournalError:
            db.close()
            raise
        super().__init__(db, name)
        self._entry = self._last_entry()
        # JSON of the engine's per-transition consumed/produced maps (the same objects at every
        # firing of a transition), by id; each entry holds its map, so that id cannot be reused
        self._map_json: dict[int, tuple[Mapping[str, int], str | None]] = {}

    def _mapping_json(self, mapping: Mapping[str, int]) -> str | None:
        hit = self._map_json.get(id(mapping))
        if hit is not None and hit[0] is mapping:
            return hit[1]
        text = _json(dict(mapping))
        if len(self._map_json) >= 65_536:
            self._map_json.clear()
        self._map_json[id(mapping)] = (mapping, text)
        return text

    def _last_entry(self) -> int:
        union = " UNION ALL ".join(f"SELECT MAX(entry) FROM {t}" for t in RECORD_TABLES)
        return max((int(v) for (v,) in self._query(union) if v is not None), default=0)

    def _write(self, sql: str, args: tuple[Any, ...]) -> None:
        try:
            self._db.execute(sql, args)
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{self.path}: write failed: {exc}") from exc

    def _record(self, table: str, columns: str, values: tuple[Any, ...]) -> None:
        """Insert a record with the next ``entry`` of the journal's one sequence."""
        sql = f"INSERT INTO {table}(entry, {columns}) VALUES (?{',?' * len(values)})"
        for attempt in range(2):
            self._entry += 1
            try:
                self._db.execute(sql, (self._entry, *values))
                return
            except sqlite3.IntegrityError as exc:  # another writer took the number: catch up once
                if attempt:
                    raise JournalError(f"{self.path}: write failed: {exc}") from exc
                self._entry = self._last_entry()
            except sqlite3.DatabaseError as exc:
                raise JournalError(f"{self.path}: write failed: {exc}") from exc

    # ------------------------------------------------------------------ writing
    def begin_run(self, net: PetriNet, *, net_text: str | None = None, seed: int = 0,
                  run_id: str | None = None) -> str:
        """Record the start of a run and return its id (a short UUID unless given)."""
        rid = run_id or uuid.uuid4().hex[:12]
        self._write("INSERT INTO run(id, net_name, net_text, seed, started_wall) VALUES (?,?,?,?,?)",
                    (rid, net.name, net_text, seed, time.time()))
        return rid

    def end_run(self, run: str, end_state: str, note: str = "") -> None:
        """Record how a run ended (``completed``, ``stuck``, ``aborted``, ``interrupted``...) and why."""
        self._write("UPDATE run SET ended_wall=?, end_state=?, note=? WHERE id=?",
                    (time.time(), end_state, note, run))

    def reopen_run(self, run: str) -> None:
        """Mark a resumed run unfinished again (its end is recorded anew when it ends).

        Raises:
            JournalError: if the journal has no run ``run``.
        """
        self.run(run)
        self._write("UPDATE run SET ended_wall=NULL, end_state=NULL WHERE id=?", (run,))

    def firing(self, run: str, firing: Firing) -> None:
        """Record a firing. Call before :meth:`coordinator.engine.Engine.apply` (write-ahead)."""
        self._record(
            "firing", "run, seq, transition, consumed, produced, instances, pulse, t_wall",
            (run, firing.seq, firing.transition, self._mapping_json(firing.consumed),
             self._mapping_json(firing.produced), _json(list(firing.instances)) if firing.instances else "[]",
             firing.pulse, time.time()),
        )

    def action_start(self, run: str, instance: str, task: str, place: str, action: str,
                     node: str | None, params: Mapping[str, Any]) -> None:
        """Record that an action is being sent to a node, before the call leaves."""
        self._record(
            "action_start", "run, instance, task, place, action, node, params, t_wall",
            (run, instance, task, place, action, node, _json(dict(params)), time.time()),
        )

    def action_result(self, run: str, instance: str, task: str, action: str, node: str | None,
                      result: ActionResult, *, forced: bool = False) -> None:
        """Record the result of a primitive action, before the engine latches it; ``forced``: an
        outcome the operator forced (a drill), never a measured result."""
        self._record(
            "action_result", "run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s, t_wall, "
            "reason, value, forced",
            (run, instance, task, action, node, result.status.value, result.outcome, result.cost, result.wall_s,
             result.cpu_s, time.time(), result.reason, _json(result.value), int(forced)),
        )

    def reconciliation(self, run: str, instance: str, task: str, action: str, node: str | None,
                       assumed: Status | None, result: ActionResult | None) -> None:
        """Record what node ``node`` said about a call the coordinator had given up on: its final
        ``result``, or ``None`` when the node does not know the call (never ran, or no longer kept);
        ``assumed`` is the status the net went on with (``None`` if no result was journaled)."""
        if result is None:
            values: tuple[Any, ...] = (None,) * 7
        else:
            values = (result.status.value, result.outcome, result.reason, result.cost, result.wall_s, result.cpu_s,
                      _json(result.value))
        self._record(
            "reconciliation", "run, instance, task, action, node, assumed, status, outcome, reason, cost, wall_s, "
            "cpu_s, value, t_wall",
            (run, instance, task, action, node, None if assumed is None else assumed.value, *values, time.time()),
        )

    def feedback(self, run: str, instance: str, task: str, action: str, data: Any, t_wall: float) -> None:
        """Record one feedback message of a running action, received at ``t_wall`` (Unix s); the
        runtime samples which (:class:`coordinator.feedback.FeedbackSampler`). A feedback whose JSON
        is longer than :data:`FEEDBACK_BYTES` is kept as ``{"truncated": true, "bytes": N, "head":
        its first characters}``, one that JSON cannot hold as ``{"unjsonable": type name}``."""
        text = _json(data)
        if text is None:
            text = _json({"unjsonable": type(data).__name__})
        elif len(text) > FEEDBACK_BYTES:
            text = _json({"truncated": True, "bytes": len(text), "head": text[:FEEDBACK_BYTES // 2]})
        self._record("feedback", "run, instance, task, action, data, t_wall", (run, instance, task, action, text, t_wall))

    def operator(self, run: str, command: str, place: str | None = None, count: int | None = None, *,
                 accepted: bool = True, reason: str | None = None, detail: Mapping[str, Any] | None = None) -> None:
        """Record an operator command (insert, remove, pause, step, resume, abort, end, break, clear,
        inject, force): before it is applied, or with ``accepted=False`` and the ``reason`` when it is
        refused; ``detail`` is what it carries besides a place and a count (a breakpoint, an event, a
        forced outcome; a pause a breakpoint made has the breakpoint)."""
        self._record("operator", "run, command, place, count, t_wall, accepted, reason, detail",
                     (run, command, place, count, time.time(), int(accepted), reason,
                      None if detail is None else _json(dict(detail))))

    def save_learner(self, task: str, scheme: str, state: Mapping[str, Any]) -> None:
        """Store the learner state of a primitive task (replaces the previous one)."""
        self._write(
            "INSERT INTO learner_state(task, scheme, state, updated_wall) VALUES (?,?,?,?) "
            "ON CONFLICT(task) DO UPDATE SET scheme=excluded.scheme, state=excluded.state, "
            "updated_wall=excluded.updated_wall",
            (task, scheme, json.dumps(dict(state), sort_keys=True), time.time()),
        )
