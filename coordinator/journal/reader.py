"""Reading the journal: runs, results, firings, operator commands, learner states (sections 3 to 5).

:meth:`JournalReader.open` opens a journal read-only, for the analysis commands (``petrobot perf``,
``gspn``, ``learn``): they can read a journal a coordinator is writing, and never change it.
:class:`~coordinator.journal.writer.Journal` is a reader too (the resume of an interrupted run
reads what it wrote). Every query returns the typed records of :mod:`coordinator.journal.records`,
in journal order; ``run=None`` means every run.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Self

from coordinator.engine import Instance
from coordinator.errors import JournalError
from coordinator.journal.records import (
    FiringRow,
    LearnerState,
    OperatorRow,
    ReconciliationRow,
    Recovered,
    ResultRow,
    RunRow,
    RunStats,
    StartRow,
)
from coordinator.journal.schema import check_schema
from coordinator.net import Marking, PetriNet
from coordinator.performance import ActionRecord
from services.errors import ActionError
from services.results import ActionResult, Status, latched_events

__all__ = ["JournalReader", "Record", "read_results"]

Record = FiringRow | StartRow | ResultRow | OperatorRow | ReconciliationRow
"""Any record of a run, as :meth:`JournalReader.timeline` gives them."""

_STATUSES = frozenset(s.value for s in Status)


def _where_run(run: str | None) -> tuple[str, tuple[Any, ...]]:
    return ("", ()) if run is None else (" WHERE run=?", (run,))


def _loads(text: str | None) -> Any:
    return None if text is None else json.loads(text)


class JournalReader:
    """Queries of an open journal.

    Open one with :meth:`open` (read-only) or use a :class:`~coordinator.journal.writer.Journal`.

    Attributes:
        path: the journal file, as given.
    """

    def __init__(self, db: sqlite3.Connection, path: str) -> None:
        self._db = db
        self.path = path
        try:
            have = {row[1] for row in db.execute("PRAGMA table_info(operator)")}
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{path}: cannot read the journal: {exc}") from exc
        # a version-1 journal (read-only) has no accepted/reason: every command it holds was applied
        self._operator_cols = ("accepted, reason" if {"accepted", "reason"} <= have else "1, NULL")
        # a journal before version 4 (read-only) has no detail and no forced: no command carried one,
        # every result was measured
        self._detail_col = "detail" if "detail" in have else "NULL"
        try:
            results = {row[1] for row in db.execute("PRAGMA table_info(action_result)")}
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{path}: cannot read the journal: {exc}") from exc
        self._forced_col = "forced" if "forced" in results else "0"
        try:  # a journal of version 1 or 2 (read-only) has no reconciliation table
            self._reconciliation = bool(db.execute("PRAGMA table_info(reconciliation)").fetchall())
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{path}: cannot read the journal: {exc}") from exc

    @classmethod
    def open(cls, path: str | Path) -> JournalReader:
        """Open an existing journal read-only.

        Raises:
            JournalError: naming the file, if it does not exist, is not SQLite, or is not a
                petrobot journal (a table or column is missing).
        """
        name = str(path)
        file = Path(path)
        if not file.is_file():
            raise JournalError(f"{name}: no such journal file")
        try:
            db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro", uri=True, timeout=5.0,
                                 check_same_thread=False)
        except sqlite3.Error as exc:
            raise JournalError(f"{name}: cannot open the journal: {exc}") from exc
        try:
            check_schema(db, name)
        except JournalError:
            db.close()
            raise
        return cls(db, name)

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _query(self, sql: str, args: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"{self.path}: cannot read the journal: {exc}") from exc

    # ------------------------------------------------------------------ runs
    def runs(self) -> list[RunRow]:
        """Every run, oldest first, with its end state (``None`` while unfinished).

        Raises:
            JournalError: the database cannot be read.
        """
        rows = self._query("SELECT id, net_name, net_text, seed, started_wall, ended_wall, end_state, note "
                           "FROM run ORDER BY started_wall, rowid")
        return [RunRow(str(i), str(n), t, int(s or 0), float(b), e, st, note)
                for i, n, t, s, b, e, st, note in rows]

    def run(self, run: str) -> RunRow:
        """One run.

        Raises:
            JournalError: if the journal has no run ``run``.
        """
        for row in self.runs():
            if row.id == run:
                return row
        raise JournalError(f"{self.path}: no run {run!r}")

    def last_unfinished_run(self, net_name: str) -> str | None:
        """Id of the most recent resumable run of ``net_name`` — no end recorded (the coordinator
        died) or ended ``interrupted`` (Ctrl-C) — or ``None``."""
        rows = self._query("SELECT id FROM run WHERE net_name=? AND (ended_wall IS NULL OR end_state='interrupted') "
                           "ORDER BY started_wall DESC, rowid DESC LIMIT 1", (net_name,))
        return str(rows[0][0]) if rows else None

    def run_stats(self) -> list[RunStats]:
        """Every run with its counts of firings, calls, errors and operator commands, oldest first.

        Raises:
            JournalError: the database cannot be read.
        """
        refused = "SUM(accepted=0)" if self._operator_cols.startswith("accepted") else "0"
        firings = {r: (n, t) for r, n, t in self._query("SELECT run, COUNT(*), MAX(t_wall) FROM firing GROUP BY run")}
        calls = {r: (n, e, f, t) for r, n, e, f, t in self._query(
            "SELECT run, COUNT(*), SUM(status='error'), SUM(status='failure'), MAX(t_wall) "
            "FROM action_result GROUP BY run")}
        commands = {r: (n, x, t) for r, n, x, t in self._query(
            f"SELECT run, COUNT(*), {refused}, MAX(t_wall) FROM operator GROUP BY run")}
        reconciled: dict[str, tuple[int, int]] = {}
        for rec in self.reconciliations():
            n, d = reconciled.get(rec.run, (0, 0))
            reconciled[rec.run] = (n + 1, d + int(rec.differs))
        out = []
        for row in self.runs():
            nf, tf = firings.get(row.id, (0, None))
            nc, ne, nfail, tc = calls.get(row.id, (0, 0, 0, None))
            no, nx, to = commands.get(row.id, (0, 0, None))
            nr, nd = reconciled.get(row.id, (0, 0))
            last = max([row.started_wall] + [float(t) for t in (tf, tc, to) if t is not None])
            out.append(RunStats(row, firings=int(nf), calls=int(nc), errors=int(ne or 0), failures=int(nfail or 0),
                                operator_commands=int(no), refused=int(nx or 0), last_wall=last,
                                reconciled=nr, differed=nd))
        return out

    # ------------------------------------------------------------------ records of runs
    def results(self, run: str | None = None, *, forced: bool = True) -> list[ResultRow]:
        """Primitive-action results in journal order, of one run or of all runs.

        Rows whose status is not success, failure or error (no petrobot journal writes one) are
        left out; so are the outcomes the operator forced when ``forced`` is False (what measures
        an action's reliability and cost: ``perf``, ``learn``).

        Raises:
            JournalError: the database cannot be read.
        """
        where, args = _where_run(run)
        if not forced:
            where += f"{' AND' if where else ' WHERE'} {self._forced_col} = 0"
        rows = self._query("SELECT run, instance, task, action, node, status, outcome, cost, wall_s, cpu_s, "
                           f"t_wall, reason, value, entry, {self._forced_col} FROM action_result{where} ORDER BY entry",
                           args)
        return [ResultRow(run=r, instance=i, task=t, action=a, node=n, t_wall=float(tw), entry=int(e),
                          result=self._result(e, s, o, c, w, cpu, why, v), forced=bool(f))
                for r, i, t, a, n, s, o, c, w, cpu, tw, why, v, e, f in rows if s in _STATUSES]

    def _result(self, entry: int, status: str, outcome: str | None, cost: float | None, wall_s: float | None,
                cpu_s: float | None, reason: str | None, value: str | None) -> ActionResult:
        """The one place a journaled result becomes an :class:`ActionResult` again (validated).

        Raises:
            JournalError: the row is not a result the journal could have written.
        """
        try:
            return ActionResult(status=Status(status), outcome=outcome, cost=cost, wall_s=wall_s or 0.0,
                                cpu_s=cpu_s or 0.0, reason=reason, value=_loads(value))
        except ActionError as exc:
            raise JournalError(f"{self.path}: record {entry} is not a valid result: {exc}") from None

    def starts(self, run: str | None = None) -> list[StartRow]:
        """Primitive actions sent to their nodes, in journal order."""
        where, args = _where_run(run)
        rows = self._query("SELECT run, instance, task, place, action, node, params, t_wall, entry "
                           f"FROM action_start{where} ORDER BY entry", args)
        return [StartRow(r, i, t, p, a, n, _loads(params) or {}, float(tw), int(e))
                for r, i, t, p, a, n, params, tw, e in rows]

    def firings(self, run: str | None = None) -> list[FiringRow]:
        """Firings in journal order (by ``seq`` within a run)."""
        where, args = _where_run(run)
        rows = self._query("SELECT run, seq, transition, consumed, produced, instances, pulse, t_wall, entry "
                           f"FROM firing{where} ORDER BY entry", args)
        return [FiringRow(r, int(seq), str(t), json.loads(c), json.loads(p), tuple(json.loads(i)), pulse,
                          float(tw), int(e))
                for r, seq, t, c, p, i, pulse, tw, e in rows]

    def operator_commands(self, run: str | None = None) -> list[OperatorRow]:
        """Operator commands (section 5) in journal order, refused ones included (``accepted`` False)."""
        where, args = _where_run(run)
        rows = self._query(f"SELECT run, command, place, count, t_wall, {self._operator_cols}, entry, "
                           f"{self._detail_col} FROM operator{where} ORDER BY entry", args)
        return [OperatorRow(r, str(c), p, n, float(tw), bool(ok), why, int(e), _loads(d))
                for r, c, p, n, tw, ok, why, e, d in rows]

    def reconciliations(self, run: str | None = None) -> list[ReconciliationRow]:
        """What nodes said afterwards about the calls the coordinator gave up on, in journal order
        (none in a journal written before reconciliation existed).

        Raises:
            JournalError: the database cannot be read.
        """
        if not self._reconciliation:
            return []
        where, args = _where_run(run)
        rows = self._query("SELECT run, instance, task, action, node, assumed, status, outcome, reason, cost, wall_s, "
                           f"cpu_s, value, t_wall, entry FROM reconciliation{where} ORDER BY entry", args)
        return [ReconciliationRow(r, i, t, a, n, Status(was) if was in _STATUSES else None,
                                  self._result(e, st, o, c, w, cpu, why, v) if st in _STATUSES else None,
                                  float(tw), int(e))
                for r, i, t, a, n, was, st, o, why, c, w, cpu, v, tw, e in rows]

    def final_words(self, run: str | None = None) -> dict[str, ResultRow | ReconciliationRow]:
        """The journal's last word on each call id (instance) that has one: its reconciliation if a
        node told its fate after the coordinator gave up on it, else its result.

        Raises:
            JournalError: the database cannot be read.
        """
        words: dict[str, ResultRow | ReconciliationRow] = {r.instance: r for r in self.results(run)}
        words.update((r.instance, r) for r in self.reconciliations(run))
        return words

    def timeline(self, run: str) -> list[Record]:
        """Every record of ``run`` — firings, action starts, results, operator commands,
        reconciliations — in the order they were written (``entry``).

        Raises:
            JournalError: if the journal has no run ``run``.
        """
        self.run(run)
        records: list[Record] = [*self.firings(run), *self.starts(run), *self.results(run),
                                 *self.operator_commands(run), *self.reconciliations(run)]
        records.sort(key=lambda r: (r.entry, r.t_wall))
        return records

    # ------------------------------------------------------------------ learning
    def learner_states(self) -> dict[str, LearnerState]:
        """The latest saved state of each primitive task's learner, by task name.

        Raises:
            JournalError: a state is not a JSON object, or its scheme disagrees with its row.
        """
        out: dict[str, LearnerState] = {}
        for task, scheme, text, updated in self._query(
                "SELECT task, scheme, state, updated_wall FROM learner_state ORDER BY task"):
            try:
                state = json.loads(text)
            except (TypeError, ValueError) as exc:
                raise JournalError(f"{self.path}: learner state of {task!r} is not valid JSON: {exc}") from exc
            if not isinstance(state, dict):
                raise JournalError(f"{self.path}: learner state of {task!r} is not a JSON object")
            if "scheme" in state and state["scheme"] != scheme:
                raise JournalError(f"{self.path}: learner_state of {task!r}: scheme column {scheme!r} "
                                   f"disagrees with the state ({state['scheme']!r})")
            out[str(task)] = LearnerState(str(task), str(scheme or ""), state, float(updated))
        return out

    # ------------------------------------------------------------------ recovery
    def recover(self, net: PetriNet, run: str) -> Recovered:
        """Rebuild the state of ``run`` by replaying its records in journal order.

        Raises:
            JournalError: if the run does not exist, or its records do not fit the net.
        """
        head = self._query("SELECT seed FROM run WHERE id=?", (run,))
        if not head:
            raise JournalError(f"{self.path}: no run {run!r}")
        records = self._query(
            "SELECT entry, 'firing', consumed, produced, instances, seq, NULL, NULL FROM firing WHERE run=? "
            "UNION ALL SELECT entry, 'start', instance, task, place, action, node, params "
            "FROM action_start WHERE run=? "
            "UNION ALL SELECT entry, 'result', instance, status, outcome, NULL, NULL, NULL "
            "FROM action_result WHERE run=? "
            f"UNION ALL SELECT entry, 'operator', command, place, count, {self._operator_cols.split(',')[0]}, "
            "NULL, NULL FROM operator WHERE run=? ORDER BY entry",
            (run, run, run, run),
        )
        return _replay(self.path, net, run, int(head[0][0] or 0), records)


def read_results(path: str | Path, run: str | None = None, *, forced: bool = False) -> list[ActionRecord]:
    """Open a journal read-only and return its results as the performance functions take them
    (:attr:`ResultRow.record`), of run ``run`` or of every run: the measured ones only, unless
    ``forced`` asks for the outcomes the operator forced too.

    Raises:
        JournalError: naming the file, if it is missing or not a journal, or has no run ``run``.
    """
    with JournalReader.open(path) as journal:
        if run is not None:
            journal.run(run)  # an unknown run is an error, not an empty report
        return [row.record for row in journal.results(run, forced=forced)]


def _replay(path: str, net: PetriNet, run: str, seed: int, records: Iterable[tuple[Any, ...]]) -> Recovered:
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
        elif kind == "operator" and a in ("insert", "remove") and b is not None and d:
            counts[b] = counts.get(b, 0) + (c if a == "insert" else -c)
    try:
        marking = Marking(counts)
    except Exception as exc:
        raise JournalError(f"{path}: run {run!r} does not replay on net {net.name!r}: {exc}") from exc
    return Recovered(run, seed, marking, tuple(live.values()), nodes, params, fired, highest + 1)
