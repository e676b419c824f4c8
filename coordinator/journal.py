"""The journal: an SQLite (WAL) log of every run of a task net (DESIGN.md §3).

Every firing, action start, action result and operator command is written — and committed —
before it takes effect, so that ``petrobot run --resume`` can rebuild the marking and the live
instances of an interrupted run (:meth:`Journal.recover`). The same tables feed the quantitative
analysis (reliability and durations per primitive action, section 3) and learning (section 4).

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
``state`` (the learner's state dict). Times: ``t_wall`` is the Unix time in seconds; ``wall_s``
and ``cpu_s`` are durations in seconds measured on the node.

Durability: WAL with ``synchronous=NORMAL``: a committed record survives a crash of the
coordinator process (not a power loss of the host).
"""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coordinator.engine import Firing, Instance
from coordinator.errors import JournalError
from coordinator.net import Marking, PetriNet
from services.results import ActionResult, Status, latched_events

__all__ = ["Journal", "Recovered", "ResultRow"]

_SCHEMA = """
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


@dataclass(frozen=True, slots=True)
class ResultRow:
    """One primitive-action result read back from the journal (times in seconds)."""

    run: str
    instance: str
    task: str
    action: str
    node: str | None
    status: str
    outcome: str | None
    cost: float | None
    wall_s: float | None
    cpu_s: float | None
    t_wall: float


@dataclass(frozen=True, slots=True)
class Recovered:
    """What :meth:`Journal.recover` rebuilt for an interrupted run.

    Attributes:
        run: the run id.
        seed: the seed the run was started with.
        marking: marking after the last journaled record.
        instances: live instances (running, or ended but not consumed), in start order.
        nodes: instance id → node the action was sent to.
        params: instance id → parameters of the call (for re-issuing it with the same call id).
        fired: number of firings journaled.
        next_instance: next free instance number.
    """

    run: str
    seed: int
    marking: Marking
    instances: tuple[Instance, ...]
    nodes: Mapping[str, str | None]
    params: Mapping[str, Any]
    fired: int
    next_instance: int


class Journal:
    """An open journal database.

    Args:
        path: SQLite file (created with its tables if missing), or ``":memory:"``.

    Raises:
        JournalError: if the file cannot be opened or is not a petrobot journal.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{self.path}: cannot open the journal: {exc}") from exc

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

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
        """Record a firing. Call before :meth:`Engine.apply` (write-ahead)."""
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

    # ------------------------------------------------------------------ reading
    def load_learner(self) -> dict[str, tuple[str, dict[str, Any]]]:
        """Return task → (scheme, state dict) of every stored learner."""
        rows = self._db.execute("SELECT task, scheme, state FROM learner_state").fetchall()
        return {task: (scheme, json.loads(state)) for task, scheme, state in rows}

    def runs(self) -> list[dict[str, Any]]:
        """Every run, oldest first, as dicts of the ``run`` table's columns."""
        cur = self._db.execute("SELECT * FROM run ORDER BY started_wall")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, row)) for row in cur.fetchall()]

    def last_unfinished_run(self, net_name: str) -> str | None:
        """Id of the most recent run of ``net_name`` that has no end recorded, or ``None``."""
        row = self._db.execute(
            "SELECT id FROM run WHERE net_name=? AND ended_wall IS NULL ORDER BY started_wall DESC LIMIT 1",
            (net_name,),
        ).fetchone()
        return None if row is None else str(row[0])

    def results(self, run: str | None = None) -> Iterator[ResultRow]:
        """Action results in journal order, of one run or of all runs."""
        sql = ("SELECT run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s, t_wall "
               "FROM action_result")
        args: tuple[Any, ...] = ()
        if run is not None:
            sql += " WHERE run=?"
            args = (run,)
        for row in self._db.execute(sql + " ORDER BY entry", args):
            yield ResultRow(*row)

    def firings(self, run: str) -> list[tuple[int, str, str | None, float]]:
        """``(seq, transition, pulse, t_wall)`` of a run's firings in order."""
        rows = self._db.execute("SELECT seq, transition, pulse, t_wall FROM firing WHERE run=? ORDER BY seq", (run,))
        return [(int(a), str(b), c, float(d)) for a, b, c, d in rows]

    def recover(self, net: PetriNet, run: str) -> Recovered:
        """Rebuild the state of ``run`` by replaying its records in journal order.

        Raises:
            JournalError: if the run does not exist, or its records do not fit the net.
        """
        head = self._db.execute("SELECT seed FROM run WHERE id=?", (run,)).fetchone()
        if head is None:
            raise JournalError(f"{self.path}: no run {run!r}")
        records = self._db.execute(
            "SELECT entry, 'firing', consumed, produced, instances, seq, NULL, NULL FROM firing WHERE run=? "
            "UNION ALL SELECT entry, 'start', instance, task, place, action, node, params "
            "FROM action_start WHERE run=? "
            "UNION ALL SELECT entry, 'result', instance, status, outcome, NULL, NULL, NULL "
            "FROM action_result WHERE run=? "
            "UNION ALL SELECT entry, 'operator', command, place, count, NULL, NULL, NULL "
            "FROM operator WHERE run=? ORDER BY entry",
            (run, run, run, run),
        ).fetchall()
        counts: dict[str, int] = dict(net.initial_marking)
        live: dict[str, Instance] = {}
        nodes: dict[str, str | None] = {}
        params: dict[str, Any] = {}
        fired = 0
        highest = 0
        for _, kind, a, b, c, d, e, f in records:
            if kind == "firing":
                for pid, w in json.loads(a).items():
                    counts[pid] = counts.get(pid, 0) - w
                for pid, w in json.loads(b).items():
                    counts[pid] = counts.get(pid, 0) + w
                for iid in json.loads(c):
                    live.pop(iid, None)
                fired = max(fired, int(d))
            elif kind == "start":
                live[a] = Instance(a, b, c, d)
                nodes[a] = e
                params[a] = json.loads(f) if f else {}
                digits = "".join(ch for ch in a.rsplit("-", 1)[-1] if ch.isdigit())
                highest = max(highest, int(digits) if digits else 0)
            elif kind == "result":
                inst = live.get(a)
                if inst is not None and inst.running:
                    inst.status = Status(b)
                    inst.outcomes = latched_events(inst.status, c)
            elif kind == "operator" and a in ("insert", "remove") and b is not None:
                counts[b] = counts.get(b, 0) + (c if a == "insert" else -c)
        try:
            marking = Marking(counts)
        except Exception as exc:
            raise JournalError(f"{self.path}: run {run!r} does not replay on net {net.name!r}: {exc}") from exc
        return Recovered(run, int(head[0] or 0), marking, tuple(live.values()), nodes, params, fired, highest + 1)
