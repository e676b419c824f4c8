"""The journal's SQLite schema: the one definition of its tables (paper sections 3 to 5).

Tables (one row per record; ``entry`` orders records of all tables within the journal)::

    run(id, net_name, net_text, seed, started_wall, ended_wall, end_state, note)
    firing(entry, run, seq, transition, consumed, produced, instances, pulse, t_wall)
    action_start(entry, run, instance, task, place, action, node, params, t_wall)
    action_result(entry, run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s,
                  t_wall, reason, value)
    operator(entry, run, command, place, count, t_wall)
    learner_state(task, scheme, state, updated_wall)

JSON columns: ``consumed``/``produced`` (place → tokens), ``instances`` (list of ids), ``params``
and ``value`` (JSON of the call's parameters and returned value, when JSON can hold them),
``state`` (the learner's state dict, :mod:`coordinator.learning.state`). Times: ``t_wall``,
``started_wall``, ``ended_wall`` and ``updated_wall`` are Unix times in seconds; ``wall_s`` and
``cpu_s`` are durations in seconds measured on the node. ``learner_state`` holds the latest state
of each primitive task's automaton, across runs.

Only :mod:`coordinator.journal` reads and writes these tables; every other module goes through
:class:`~coordinator.journal.reader.JournalReader` and :class:`~coordinator.journal.writer.Journal`.
"""

from __future__ import annotations

import sqlite3

from coordinator.errors import JournalError

__all__ = ["COLUMNS", "DDL", "check_schema"]

DDL = """
CREATE TABLE IF NOT EXISTS run (
    id TEXT PRIMARY KEY, net_name TEXT NOT NULL, net_text TEXT, seed INTEGER,
    started_wall REAL NOT NULL, ended_wall REAL, end_state TEXT, note TEXT
);
CREATE TABLE IF NOT EXISTS firing (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, seq INTEGER NOT NULL, transition TEXT NOT NULL,
    consumed TEXT NOT NULL, produced TEXT NOT NULL, instances TEXT NOT NULL, pulse TEXT,
    t_wall REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS action_start (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    place TEXT NOT NULL, action TEXT NOT NULL, node TEXT, params TEXT, t_wall REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS action_result (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    action TEXT NOT NULL, node TEXT, status TEXT NOT NULL, outcome TEXT, cost REAL, wall_s REAL,
    cpu_s REAL, t_wall REAL NOT NULL, reason TEXT, value TEXT
);
CREATE TABLE IF NOT EXISTS operator (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, command TEXT NOT NULL, place TEXT, count INTEGER,
    t_wall REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS learner_state (
    task TEXT PRIMARY KEY, scheme TEXT, state TEXT NOT NULL, updated_wall REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS firing_run ON firing(run, seq);
CREATE INDEX IF NOT EXISTS start_run ON action_start(run);
CREATE INDEX IF NOT EXISTS result_run ON action_result(run);
CREATE INDEX IF NOT EXISTS result_action ON action_result(task, action);
"""
"""The tables and their indexes (idempotent: ``IF NOT EXISTS``)."""

COLUMNS: dict[str, tuple[str, ...]] = {
    "run": ("id", "net_name", "net_text", "seed", "started_wall", "ended_wall", "end_state", "note"),
    "firing": ("entry", "run", "seq", "transition", "consumed", "produced", "instances", "pulse", "t_wall"),
    "action_start": ("entry", "run", "instance", "task", "place", "action", "node", "params", "t_wall"),
    "action_result": ("entry", "run", "instance", "task", "action", "node", "status", "outcome", "cost",
                      "wall_s", "cpu_s", "t_wall", "reason", "value"),
    "operator": ("entry", "run", "command", "place", "count", "t_wall"),
    "learner_state": ("task", "scheme", "state", "updated_wall"),
}
"""Table → its columns, as :data:`DDL` creates them."""


def check_schema(db: sqlite3.Connection, path: str) -> None:
    """Check that an open database has every journal table with (at least) its columns.

    Raises:
        JournalError: naming ``path``, if a table or a column is missing, or the file cannot be
            read as SQLite.
    """
    try:
        for table, columns in COLUMNS.items():
            have = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
            if not have:
                raise JournalError(f"{path}: not a petrobot journal (no table {table!r})")
            missing = [c for c in columns if c not in have]
            if missing:
                raise JournalError(f"{path}: not a petrobot journal (table {table!r} lacks "
                                   f"{', '.join(missing)})")
    except sqlite3.DatabaseError as exc:
        raise JournalError(f"{path}: cannot read the journal: {exc}") from exc
