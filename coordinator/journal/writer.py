"""Writing the journal: an SQLite (WAL) log of every run of a task net (paper sections 3 to 5).

Every firing, action start, action result and operator command is written — and committed —
before it takes effect, so that ``petrobot run --resume`` can rebuild the marking and the live
instances of an interrupted run (:meth:`JournalReader.recover`). The same tables feed the
quantitative analysis (reliability and durations per primitive action, section 3) and learning
(section 4). The tables: :mod:`coordinator.journal.schema`.

Durability: WAL with ``synchronous=NORMAL``: a committed record survives a crash of the
coordinator process (not a power loss of the host).
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
from coordinator.journal.schema import DDL, check_schema
from coordinator.net import PetriNet
from services.results import ActionResult

__all__ = ["Journal"]


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
        JournalError: if the file cannot be opened or is not a petrobot journal.
    """

    def __init__(self, path: str | Path) -> None:
        name = str(path)
        try:
            db = sqlite3.connect(name, isolation_level=None, check_same_thread=False)
        except sqlite3.Error as exc:
            raise JournalError(f"{name}: cannot open the journal: {exc}") from exc
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.executescript(DDL)
            check_schema(db, name)
        except sqlite3.DatabaseError as exc:
            db.close()
            raise JournalError(f"{name}: cannot open the journal: {exc}") from exc
        except JournalError:
            db.close()
            raise
        super().__init__(db, name)

    def _write(self, sql: str, args: tuple[Any, ...]) -> None:
        try:
            self._db.execute(sql, args)
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
        """Record how a run ended (``dead``, ``aborted``, ``interrupted``...)."""
        self._write("UPDATE run SET ended_wall=?, end_state=?, note=? WHERE id=?",
                    (time.time(), end_state, note, run))

    def firing(self, run: str, firing: Firing) -> None:
        """Record a firing. Call before :meth:`coordinator.engine.Engine.apply` (write-ahead)."""
        self._write(
            "INSERT INTO firing(run, seq, transition, consumed, produced, instances, pulse, t_wall) "
            "VALUES (?,?,?,?,?,?,?,?)",
            (run, firing.seq, firing.transition, _json(dict(firing.consumed)), _json(dict(firing.produced)),
             _json(list(firing.instances)), firing.pulse, time.time()),
        )

    def action_start(self, run: str, instance: str, task: str, place: str, action: str,
                     node: str | None, params: Mapping[str, Any]) -> None:
        """Record that an action is being sent to a node, before the call leaves."""
        self._write(
            "INSERT INTO action_start(run, instance, task, place, action, node, params, t_wall) "
            "VALUES (?,?,?,?,?,?,?,?)",
            (run, instance, task, place, action, node, _json(dict(params)), time.time()),
        )

    def action_result(self, run: str, instance: str, task: str, action: str, node: str | None,
                      result: ActionResult) -> None:
        """Record the result of a primitive action, before the engine latches it."""
        self._write(
            "INSERT INTO action_result(run, instance, task, action, node, status, outcome, cost, wall_s, "
            "cpu_s, t_wall, reason, value) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (run, instance, task, action, node, result.status.value, result.outcome, result.cost, result.wall_s,
             result.cpu_s, time.time(), result.reason, _json(result.value)),
        )

    def operator(self, run: str, command: str, place: str | None = None, count: int | None = None) -> None:
        """Record an operator command (insert, remove, pause, step, resume, abort)."""
        self._write("INSERT INTO operator(run, command, place, count, t_wall) VALUES (?,?,?,?,?)",
                    (run, command, place, count, time.time()))

    def save_learner(self, task: str, scheme: str, state: Mapping[str, Any]) -> None:
        """Store the learner state of a primitive task (replaces the previous one)."""
        self._write(
            "INSERT INTO learner_state(task, scheme, state, updated_wall) VALUES (?,?,?,?) "
            "ON CONFLICT(task) DO UPDATE SET scheme=excluded.scheme, state=excluded.state, "
            "updated_wall=excluded.updated_wall",
            (task, scheme, json.dumps(dict(state), sort_keys=True), time.time()),
        )
