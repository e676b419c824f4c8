"""The journal's SQLite schema: the one definition of its tables (paper sections 3 to 5).

Tables (one row per record; ``entry`` numbers the records of all tables in one sequence, the order
in which they were written, so a run can be replayed in order)::

    run(id, net_name, net_text, seed, started_wall, ended_wall, end_state, note)
    firing(entry, run, seq, transition, consumed, produced, instances, pulse, t_wall)
    action_start(entry, run, instance, task, place, action, node, params, t_wall)
    action_result(entry, run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s,
                  t_wall, reason, value, forced)
    operator(entry, run, command, place, count, t_wall, accepted, reason, detail)
    reconciliation(entry, run, instance, task, action, node, assumed, status, outcome, reason, cost,
                   wall_s, cpu_s, value, t_wall)
    feedback(entry, run, instance, task, action, data, t_wall)
    learner_state(task, scheme, state, updated_wall)

JSON columns: ``consumed``/``produced`` (place → tokens), ``instances`` (list of ids), ``params``,
``value`` and ``feedback.data`` (JSON of the call's parameters and returned value, when JSON can hold them),
``state`` (the learner's state dict, :mod:`coordinator.learning.state`), ``operator.detail`` (what a
command carries besides a place and a count: a breakpoint, an injected event, a forced outcome). Times: ``t_wall``,
``started_wall``, ``ended_wall`` and ``updated_wall`` are Unix times in seconds; ``wall_s`` and
``cpu_s`` are durations in seconds measured on the node. ``learner_state`` holds the latest state
of each primitive task's automaton, across runs. ``operator.accepted`` is 1 for a command that was
applied, 0 for one that was refused, with the refusal in ``reason``. A ``reconciliation`` row is
what a node said, when asked afterwards, about a call the coordinator had given up on (node trouble):
``assumed`` is the status the net went on with (NULL if no result was journaled), ``status`` the
node's final status (NULL if the node does not know the call: it never ran, or its result expired).
``action_result.forced`` is 1 for an outcome the operator forced (a drill, ``[operator]`` of the net):
never a measured result. A ``feedback`` row is one feedback message of a running primitive action, as
the runtime sampled it (at most :data:`coordinator.feedback.FEEDBACK_PER_S` a second per call,
plus always the last one before the result; docs/journal.md).

Schema versions (``PRAGMA user_version``): 1 (no version set) had one ``entry`` sequence per table
and no ``accepted``/``reason``; 2 added them; 3 added ``reconciliation``; 4 added ``operator.detail``
and ``action_result.forced``; 5 (:data:`SCHEMA_VERSION`) added ``feedback``. :func:`migrate` brings an
older journal to version 5 when it is opened for writing (a version-1 journal's entries renumbered in
the order of their times); a read-only reader reads every version (a journal without
``reconciliation`` has no reconciliations, one without ``feedback`` no feedback, one without
``forced`` no forced outcome, one without ``detail`` no details). The user-facing description:
``docs/journal.md``.

Only :mod:`coordinator.journal` reads and writes these tables; every other module goes through
:class:`~coordinator.journal.reader.JournalReader` and :class:`~coordinator.journal.writer.Journal`.
"""

from __future__ import annotations

import sqlite3

from coordinator.errors import DamagedJournal, JournalError, JournalTooNew

__all__ = ["ADDED_IN_3", "ADDED_IN_4", "ADDED_IN_5", "COLUMNS", "DDL", "RECORD_TABLES", "SCHEMA_VERSION", "check_schema",
           "check_tables", "check_version", "migrate", "schema_version"]

SCHEMA_VERSION = 5
"""The version this code writes (``PRAGMA user_version``)."""

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
    cpu_s REAL, t_wall REAL NOT NULL, reason TEXT, value TEXT, forced INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS operator (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, command TEXT NOT NULL, place TEXT, count INTEGER,
    t_wall REAL NOT NULL, accepted INTEGER NOT NULL DEFAULT 1, reason TEXT, detail TEXT
);
CREATE TABLE IF NOT EXISTS reconciliation (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    action TEXT NOT NULL, node TEXT, assumed TEXT, status TEXT, outcome TEXT, reason TEXT, cost REAL,
    wall_s REAL, cpu_s REAL, value TEXT, t_wall REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS feedback (
    entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    action TEXT NOT NULL, data TEXT NOT NULL, t_wall REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS learner_state (
    task TEXT PRIMARY KEY, scheme TEXT, state TEXT NOT NULL, updated_wall REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS firing_run ON firing(run, seq);
CREATE INDEX IF NOT EXISTS start_run ON action_start(run);
CREATE INDEX IF NOT EXISTS result_run ON action_result(run);
CREATE INDEX IF NOT EXISTS result_action ON action_result(task, action);
CREATE INDEX IF NOT EXISTS operator_run ON operator(run);
CREATE INDEX IF NOT EXISTS reconciliation_run ON reconciliation(run, instance);
CREATE INDEX IF NOT EXISTS feedback_run ON feedback(run, instance);
"""
"""The tables and their indexes (idempotent: ``IF NOT EXISTS``)."""

COLUMNS: dict[str, tuple[str, ...]] = {
    "run": ("id", "net_name", "net_text", "seed", "started_wall", "ended_wall", "end_state", "note"),
    "firing": ("entry", "run", "seq", "transition", "consumed", "produced", "instances", "pulse", "t_wall"),
    "action_start": ("entry", "run", "instance", "task", "place", "action", "node", "params", "t_wall"),
    "action_result": ("entry", "run", "instance", "task", "action", "node", "status", "outcome", "cost",
                      "wall_s", "cpu_s", "t_wall", "reason", "value", "forced"),
    "operator": ("entry", "run", "command", "place", "count", "t_wall", "accepted", "reason", "detail"),
    "reconciliation": ("entry", "run", "instance", "task", "action", "node", "assumed", "status", "outcome",
                       "reason", "cost", "wall_s", "cpu_s", "value", "t_wall"),
    "feedback": ("entry", "run", "instance", "task", "action", "data", "t_wall"),
    "learner_state": ("task", "scheme", "state", "updated_wall"),
}
"""Table → its columns, as :data:`DDL` creates them."""

ADDED_IN_2: dict[str, tuple[str, ...]] = {"operator": ("accepted", "reason")}
"""Columns a version-1 journal lacks (a reader of such a journal supplies their defaults)."""

ADDED_IN_3 = ("reconciliation",)
"""Tables a journal of version 1 or 2 lacks (a reader of such a journal finds no rows in them)."""

ADDED_IN_4: dict[str, tuple[str, ...]] = {"operator": ("detail",), "action_result": ("forced",)}
"""Columns a journal of version 1 to 3 lacks (a reader supplies NULL and 0)."""

ADDED_IN_5 = ("feedback",)
"""Tables a journal of version 1 to 4 lacks (a reader of such a journal finds no rows in them)."""

RECORD_TABLES = ("firing", "action_start", "action_result", "operator", "reconciliation", "feedback")
"""The tables whose rows share the ``entry`` sequence."""


def schema_version(db: sqlite3.Connection) -> int:
    """The journal's schema version: ``PRAGMA user_version``, 1 when it was never set."""
    return int(db.execute("PRAGMA user_version").fetchone()[0]) or 1


def migrate(db: sqlite3.Connection, path: str) -> int:
    """Bring an open, writable journal to :data:`SCHEMA_VERSION` (call after running :data:`DDL`).

    Version 1 → 2: adds ``operator.accepted`` (1 for every old command: only applied commands were
    journaled) and ``operator.reason``, and renumbers ``entry`` in one sequence over the record
    tables, ordered by ``t_wall`` (then firing, start, result, operator, then the old entry), which
    is the order the records were written in. Version 2 → 3: adds the (empty) ``reconciliation``
    table. Version 3 → 4: adds ``operator.detail`` (NULL) and ``action_result.forced`` (0: every
    older result was measured). Version 4 → 5: adds the (empty) ``feedback`` table. A fresh journal
    only gets its version set.

    Returns:
        The version the journal had.

    Raises:
        JournalTooNew: the journal was written by a newer petrobot.
        JournalError: naming ``path``, on an SQLite error (the journal is then unchanged: the
            migration is one transaction).
    """
    try:
        version = schema_version(db)
        if version > SCHEMA_VERSION:
            raise JournalTooNew(path, version, SCHEMA_VERSION)
        if version == SCHEMA_VERSION:
            return version
        db.execute("BEGIN IMMEDIATE")
        try:
            if version < 2:
                have = {row[1] for row in db.execute("PRAGMA table_info(operator)")}
                if "accepted" not in have:
                    db.execute("ALTER TABLE operator ADD COLUMN accepted INTEGER NOT NULL DEFAULT 1")
                if "reason" not in have:
                    db.execute("ALTER TABLE operator ADD COLUMN reason TEXT")
            for statement in _table_ddl("reconciliation"):  # version 3 (also made by DDL: idempotent)
                db.execute(statement)
            for table, columns in ADDED_IN_4.items():  # version 4
                have = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
                for column in columns:
                    if column not in have:
                        db.execute(f"ALTER TABLE {table} ADD COLUMN {_ADDED_DDL[column]}")
            for statement in _table_ddl("feedback"):  # version 5 (likewise)
                db.execute(statement)
            if version < 2:
                _renumber(db)
            db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        return version
    except sqlite3.DatabaseError as exc:
        raise JournalError(f"{path}: cannot migrate the journal: {exc}") from exc


_ADDED_DDL = {"detail": "detail TEXT", "forced": "forced INTEGER NOT NULL DEFAULT 0"}



def _table_ddl(table: str) -> tuple[str, ...]:
    """The statements of :data:`DDL` that create ``table`` and its indexes."""
    return tuple(part.strip() for part in DDL.split(";")
                 if part.strip().startswith(f"CREATE TABLE IF NOT EXISTS {table} (") or f" ON {table}(" in part)


def _renumber(db: sqlite3.Connection) -> None:
    """One ``entry`` sequence over the record tables, in the order of the records' times."""
    union = " UNION ALL ".join(f"SELECT '{t}' AS tbl, {rank} AS rank, entry, t_wall FROM {t}"
                               for rank, t in enumerate(RECORD_TABLES))
    db.execute("CREATE TEMP TABLE renumber AS SELECT tbl, entry AS old, "
               f"ROW_NUMBER() OVER (ORDER BY t_wall, rank, entry) AS new FROM ({union})")
    try:
        db.execute("CREATE INDEX temp.renumber_key ON renumber(tbl, old)")
        top = db.execute("SELECT COALESCE(MAX(old), 0) + COALESCE(MAX(new), 0) + 1 FROM renumber").fetchone()[0]
        for table in RECORD_TABLES:  # two steps, so that no new number collides with an old one
            db.execute(f"UPDATE {table} SET entry = ? + (SELECT new FROM renumber "
                       f"WHERE tbl='{table}' AND old={table}.entry)", (top,))
            db.execute(f"UPDATE {table} SET entry = entry - ?", (top,))
    finally:
        db.execute("DROP TABLE temp.renumber")


def check_version(db: sqlite3.Connection, path: str) -> None:
    """Refuse a journal written by a newer petrobot.

    Raises:
        JournalTooNew: its schema is newer than :data:`SCHEMA_VERSION`.
        DamagedJournal: the file is not an SQLite database.
    """
    try:
        version = schema_version(db)
    except sqlite3.DatabaseError as exc:
        raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc
    if version > SCHEMA_VERSION:
        raise JournalTooNew(path, version, SCHEMA_VERSION)


def check_schema(db: sqlite3.Connection, path: str) -> None:
    """Check that an open database has every journal table with (at least) its columns (those of
    version 1 suffice: a reader reads every version; the tables added since may be missing).

    Raises:
        DamagedJournal: naming ``path``, if a table or a column is missing, or the file cannot be
            read as SQLite.
    """
    try:
        for table, columns in COLUMNS.items():
            have = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
            if not have and (table in ADDED_IN_3 or table in ADDED_IN_5):
                continue
            if not have:
                raise DamagedJournal(path, f"not a petrobot journal, or a damaged one (no table {table!r})")
            missing = [c for c in columns if c not in have and c not in ADDED_IN_2.get(table, ())
                       and c not in ADDED_IN_4.get(table, ())]
            if missing:
                raise DamagedJournal(path, f"not a petrobot journal, or a damaged one (table {table!r} lacks "
                                     f"{', '.join(missing)})")
    except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:  # a name in the schema that is not UTF-8
        raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc


def check_tables(db: sqlite3.Connection, path: str) -> bool:
    """Before a journal is opened for writing: whether the file is new (no table at all), after
    checking that an existing one has every table of its version.

    A table missing from a journal that holds records is never created afresh (the ``IF NOT
    EXISTS`` of :data:`DDL` would do it silently, and a resume would then replay a run without its
    firings): the journal is refused instead.

    Returns:
        True for a file without tables (a new journal), False for an existing journal.

    Raises:
        DamagedJournal: a table of its version is missing while another holds records, or the file
            has tables but none of a journal's, or it cannot be read.
    """
    try:
        tables = {str(r[0]) for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not tables:
            return True
        version = schema_version(db)
        wanted = [t for t in COLUMNS if not (version < 3 and t in ADDED_IN_3) and not (version < 5 and t in ADDED_IN_5)]
        missing = [t for t in wanted if t not in tables]
        present = [t for t in wanted if t in tables]
        if not present:
            raise DamagedJournal(path, f"not a petrobot journal (an SQLite file with the tables "
                                 f"{', '.join(sorted(tables)[:5])}); give a new file or an existing journal")
        if missing:
            held = sum(int(db.execute(f"SELECT COUNT(*) FROM {t}").fetchone()[0]) for t in present)
            if held:
                raise DamagedJournal(path, "the table is missing from this journal, whose other tables hold "
                                     f"{held} record(s): it is not created afresh (a resume would replay the runs "
                                     "without it); restore the journal from a copy, or give a new journal file",
                                     table=missing[0])
        return False
    except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:  # a name in the schema that is not UTF-8
        raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc
