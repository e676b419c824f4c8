"""Reading the journal: runs, results, firings, operator commands, learner states (sections 3 to 5).

:meth:`JournalReader.open` opens a journal read-only, for the analysis commands (``petrobot perf``,
``gspn``, ``learn``): they can read a journal a coordinator is writing, and never change it.
:class:`~coordinator.journal.writer.Journal` is a reader too (the resume of an interrupted run
reads what it wrote). Every query returns the typed records of :mod:`coordinator.journal.records`,
in journal order; ``run=None`` means every run.

Damage (docs/journal.md, "A damaged journal"): every row is checked field by field as it is read
(:mod:`coordinator.journal.rows`). A reader opened with ``strict=False`` (the default) skips a
damaged record and keeps what is wrong with it in :attr:`JournalReader.damaged` (table, row and
field, for the command to print); with ``strict=True`` the first damage raises
:class:`~coordinator.errors.DamagedJournal`. :meth:`JournalReader.recover` is always strict: it
first runs SQLite's ``PRAGMA quick_check``, then refuses a run whose records disagree with each
other or with the net (a firing that takes tokens a place does not hold, a result for a call never
started...), saying which record and why. A journal of a newer schema than this petrobot's is
refused at opening (:class:`~coordinator.errors.JournalTooNew`).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Self, TypeVar

from coordinator.breakpoints import Breakpoint, breakpoint_problem
from coordinator.engine import Instance
from coordinator.errors import DamagedJournal, JournalError
from coordinator.journal.records import (
    FeedbackRow,
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
from coordinator.journal.rows import (
    decode_text,
    feedback_row,
    firing_row,
    learner_row,
    operator_row,
    reconciliation_row,
    result_row,
    run_row,
    start_row,
)
from coordinator.journal.schema import check_schema, check_version
from coordinator.net import Marking, PetriNet, PlaceKind
from coordinator.performance import ActionRecord
from services.results import latched_events

__all__ = ["JournalReader", "Record", "read_results"]

Record = FiringRow | StartRow | ResultRow | OperatorRow | ReconciliationRow
"""Any record of a run, as :meth:`JournalReader.timeline` gives them."""

R = TypeVar("R")

_MAX_DAMAGE = 1000  # damaged records kept for the report (the count goes on)


def _where_run(run: str | None) -> tuple[str, tuple[Any, ...]]:
    return ("", ()) if run is None else (" WHERE run=?", (run,))


class JournalReader:
    """Queries of an open journal.

    Open one with :meth:`open` (read-only) or use a :class:`~coordinator.journal.writer.Journal`.

    Args:
        db: the open database.
        path: the journal file, for messages.
        strict: raise :class:`DamagedJournal` on the first damaged record instead of skipping it.

    Attributes:
        path: the journal file, as given.
        strict: see above.
    """

    def __init__(self, db: sqlite3.Connection, path: str, *, strict: bool = False) -> None:
        self._db = db
        self.path = path
        self.strict = strict
        self._damaged: dict[str, DamagedJournal] = {}
        self.damage_count = 0
        """Damaged records met so far (each once), also beyond the ones :attr:`damaged` keeps."""
        db.text_factory = decode_text  # text that is not UTF-8 is damage of one field, not of the query
        try:
            have = {row[1] for row in db.execute("PRAGMA table_info(operator)")}
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc
        # a version-1 journal (read-only) has no accepted/reason: every command it holds was applied
        self._operator_cols = ("accepted, reason" if {"accepted", "reason"} <= have else "1, NULL")
        # a journal before version 4 (read-only) has no detail and no forced: no command carried one,
        # every result was measured
        self._detail_col = "detail" if "detail" in have else "NULL"
        try:
            results = {row[1] for row in db.execute("PRAGMA table_info(action_result)")}
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc
        self._forced_col = "forced" if "forced" in results else "0"
        try:  # a journal of version 1 or 2 (read-only) has no reconciliation table
            self._reconciliation = bool(db.execute("PRAGMA table_info(reconciliation)").fetchall())
            # one of version 1 to 4 (read-only) has no feedback table
            self._feedback = bool(db.execute("PRAGMA table_info(feedback)").fetchall())
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(path, f"cannot read the journal: {exc}") from exc

    @classmethod
    def open(cls, path: str | Path, *, strict: bool = False) -> JournalReader:
        """Open an existing journal read-only.

        Raises:
            JournalError: naming the file, if it does not exist or cannot be opened.
            DamagedJournal: it is not SQLite, or a table or column of a petrobot journal is missing.
            JournalTooNew: it was written by a newer petrobot.
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
            check_version(db, name)
            check_schema(db, name)
            return cls(db, name, strict=strict)
        except BaseException:
            db.close()
            raise

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ damage
    @property
    def damaged(self) -> list[DamagedJournal]:
        """The damaged records skipped so far, each once, in the order met (at most 1,000 kept;
        :attr:`damage_count` counts them all)."""
        return list(self._damaged.values())

    def damage_report(self) -> list[str]:
        """One line per damaged record skipped so far (``table T, row R, field F: problem``), and a
        last line counting those beyond the ones kept; empty when nothing was damaged."""
        lines = [str(exc) for exc in self._damaged.values()]
        if self.damage_count > len(lines):
            lines.append(f"{self.path}: ... and {self.damage_count - len(lines)} more damaged record(s)")
        return lines

    def _damage(self, exc: DamagedJournal) -> None:
        if self.strict:
            raise exc
        key = str(exc)
        if key not in self._damaged:
            self.damage_count += 1
            if len(self._damaged) < _MAX_DAMAGE:
                self._damaged[key] = exc

    def _query(self, sql: str, args: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(self.path, f"cannot read the journal: {exc}") from exc

    def _rows(self, table: str, sql: str, args: tuple[Any, ...], make: Callable[[str, tuple[Any, ...]], R]) -> list[R]:
        """Rows of ``table`` made into records; a damaged one is skipped (or raised when strict), a
        table SQLite cannot read counts as one damage of the table."""
        try:
            raw = self._db.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as exc:
            self._damage(DamagedJournal(self.path, f"unreadable: {exc}", table=table))
            return []
        out = []
        for values in raw:
            try:
                out.append(make(self.path, values))
            except DamagedJournal as exc:
                self._damage(exc)
        return out

    # ------------------------------------------------------------------ runs
    def runs(self) -> list[RunRow]:
        """Every run, oldest first, with its end state (``None`` while unfinished).

        Raises:
            DamagedJournal: the run table cannot be read.
        """
        try:
            raw = self._db.execute("SELECT rowid, id, net_name, net_text, seed, started_wall, ended_wall, end_state, "
                                   "note FROM run ORDER BY rowid").fetchall()
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(self.path, f"unreadable: {exc}", table="run") from exc
        out: list[tuple[int, RunRow]] = []
        for values in raw:
            try:
                out.append((int(values[0]), run_row(self.path, values)))
            except DamagedJournal as exc:
                self._damage(exc)
        out.sort(key=lambda x: (x[1].started_wall, x[0]))
        return [row for _, row in out]

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
        resumable = [r for r in self.runs() if r.net_name == net_name and r.resumable]
        return resumable[-1].id if resumable else None

    def run_stats(self) -> list[RunStats]:
        """Every run with its counts of firings, calls, errors and operator commands, oldest first
        (counted by SQLite, over the records whose time is a number).

        Raises:
            DamagedJournal: the database cannot be read.
        """
        number = "CASE WHEN typeof(t_wall) IN ('real', 'integer') THEN t_wall END"
        refused = "SUM(accepted=0)" if self._operator_cols.startswith("accepted") else "0"
        firings = {r: (n, t) for r, n, t in self._stats(f"SELECT run, COUNT(*), MAX({number}) FROM firing GROUP BY run")}
        calls = {r: (n, e, f, t) for r, n, e, f, t in self._stats(
            f"SELECT run, COUNT(*), SUM(status='error'), SUM(status='failure'), MAX({number}) "
            "FROM action_result GROUP BY run")}
        commands = {r: (n, x, t) for r, n, x, t in self._stats(
            f"SELECT run, COUNT(*), {refused}, MAX({number}) FROM operator GROUP BY run")}
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

    def _stats(self, sql: str) -> list[tuple[Any, ...]]:
        """Rows of a per-run aggregate whose run is text and whose other columns are numbers or NULL."""
        table = sql.rsplit(" FROM ", 1)[1].split()[0]
        rows = self._rows(table, sql, (), lambda _path, values: values)
        ok = []
        for values in rows:
            run, rest = values[0], values[1:]
            if isinstance(run, str) and all(v is None or type(v) in (int, float) for v in rest):
                ok.append(values)
        return ok

    # ------------------------------------------------------------------ records of runs
    def results(self, run: str | None = None, *, forced: bool = True) -> list[ResultRow]:
        """Primitive-action results in journal order, of one run or of all runs; the outcomes the
        operator forced are left out when ``forced`` is False (what measures an action's
        reliability and cost: ``perf``, ``learn``).

        Raises:
            DamagedJournal: strict, and a row is damaged.
        """
        where, args = _where_run(run)
        if not forced:
            where += f"{' AND' if where else ' WHERE'} {self._forced_col} = 0"
        return self._rows("action_result", "SELECT entry, run, instance, task, action, node, status, outcome, cost, "
                          f"wall_s, cpu_s, t_wall, reason, value, {self._forced_col} FROM action_result{where} "
                          "ORDER BY entry", args, result_row)

    def starts(self, run: str | None = None) -> list[StartRow]:
        """Primitive actions sent to their nodes, in journal order."""
        where, args = _where_run(run)
        return self._rows("action_start", "SELECT entry, run, instance, task, place, action, node, params, t_wall "
                          f"FROM action_start{where} ORDER BY entry", args, start_row)

    def firings(self, run: str | None = None) -> list[FiringRow]:
        """Firings in journal order (by ``seq`` within a run)."""
        where, args = _where_run(run)
        return self._rows("firing", "SELECT entry, run, seq, transition, consumed, produced, instances, pulse, t_wall "
                          f"FROM firing{where} ORDER BY entry", args, firing_row)

    def operator_commands(self, run: str | None = None) -> list[OperatorRow]:
        """Operator commands (section 5) in journal order, refused ones included (``accepted`` False)."""
        where, args = _where_run(run)
        return self._rows("operator", f"SELECT entry, run, command, place, count, t_wall, {self._operator_cols}, "
                          f"{self._detail_col} FROM operator{where} ORDER BY entry", args, operator_row)

    def reconciliations(self, run: str | None = None) -> list[ReconciliationRow]:
        """What nodes said afterwards about the calls the coordinator gave up on, in journal order
        (none in a journal written before reconciliation existed)."""
        if not self._reconciliation:
            return []
        where, args = _where_run(run)
        return self._rows("reconciliation", "SELECT entry, run, instance, task, action, node, assumed, status, "
                          "outcome, reason, cost, wall_s, cpu_s, value, t_wall "
                          f"FROM reconciliation{where} ORDER BY entry", args, reconciliation_row)

    def feedback_messages(self, run: str | None = None) -> list[FeedbackRow]:
        """The feedback the runtime kept of the running actions (sampled: docs/journal.md), in journal
        order (none in a journal written before feedback was kept)."""
        if not self._feedback:
            return []
        where, args = _where_run(run)
        return self._rows("feedback", "SELECT entry, run, instance, task, action, data, t_wall "
                          f"FROM feedback{where} ORDER BY entry", args, feedback_row)

    def final_words(self, run: str | None = None) -> dict[str, ResultRow | ReconciliationRow]:
        """The journal's last word on each call id (instance) that has one: its reconciliation if a
        node told its fate after the coordinator gave up on it, else its result."""
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
        """The latest saved state of each primitive task's learner, by task name (a damaged one is
        skipped, or raised when strict)."""
        rows = self._rows("learner_state", "SELECT rowid, task, scheme, state, updated_wall FROM learner_state "
                          "ORDER BY task", (), learner_row)
        return {row.task: row for row in rows}

    # ------------------------------------------------------------------ recovery
    def integrity(self) -> None:
        """SQLite's own check of the file's structure (``PRAGMA quick_check``: pages, records,
        indexes, without cross-checking index contents).

        Raises:
            DamagedJournal: the check finds problems (the first five are named).
        """
        try:
            problems = [str(r[0]) for r in self._db.execute("PRAGMA quick_check(6)").fetchall()]
        except sqlite3.DatabaseError as exc:
            raise DamagedJournal(self.path, f"SQLite's integrity check cannot run: {exc}") from exc
        if problems != ["ok"]:
            raise DamagedJournal(self.path, "SQLite's integrity check (PRAGMA quick_check) failed: "
                                 + "; ".join(problems[:5]) + (" ..." if len(problems) > 5 else ""))

    def recover(self, net: PetriNet, run: str) -> Recovered:
        """Rebuild the state of ``run`` by replaying its records in journal order.

        Runs :meth:`integrity` first, reads every record of the run strictly, and checks that they
        agree with each other and with ``net`` (:func:`_replay`).

        Raises:
            JournalError: if the run does not exist.
            DamagedJournal: the file, a record, or the agreement of the records is damaged; the
                message says which record and why.
        """
        self.integrity()
        strict, self.strict = self.strict, True
        try:
            row = self.run(run)
            records: list[Record] = [*self.firings(run), *self.starts(run), *self.results(run),
                                     *self.operator_commands(run)]
        finally:
            self.strict = strict
        records.sort(key=lambda r: r.entry)
        return _replay(self.path, net, row, records)


def read_results(path: str | Path, run: str | None = None, damaged: list[str] | None = None, *,
                 forced: bool = False) -> list[ActionRecord]:
    """Open a journal read-only and return its results as the performance functions take them
    (:attr:`ResultRow.record`), of run ``run`` or of every run: the measured ones only, unless
    ``forced`` asks for the outcomes the operator forced too. Damaged results are left out, and
    named in ``damaged`` when given (:meth:`JournalReader.damage_report`).

    Raises:
        JournalError: naming the file, if it is missing or not a journal, or has no run ``run``.
    """
    with JournalReader.open(path) as journal:
        if run is not None:
            journal.run(run)  # an unknown run is an error, not an empty report
        records = [row.record for row in journal.results(run, forced=forced)]
        if damaged is not None:
            damaged.extend(journal.damage_report())
        return records


class _Replay:
    """The state of a run rebuilt record by record, refusing records that disagree."""

    def __init__(self, path: str, net: PetriNet, run: RunRow) -> None:
        self.path = path
        self.net = net
        self.run = run
        self.counts: dict[str, int] = {p.id: 0 for p in net.places}
        self.counts.update(net.initial_marking.items())
        self.task_of = {p.id: p.task for p in net.places if p.kind is PlaceKind.PRIMITIVE_TASK}
        self.transitions = {t.id for t in net.transitions}
        self.live: dict[str, Instance] = {}
        self.started: set[str] = set()
        self.per_place: dict[str, int] = {}
        self.nodes: dict[str, str | None] = {}
        self.params: dict[str, Any] = {}
        self.fired = 0
        self.highest = 0
        self.seq = -1
        self.breakpoints: dict[Breakpoint, None] = {}  # set and not cleared, in the order set

    def refuse(self, table: str, entry: int, problem: str) -> DamagedJournal:
        return DamagedJournal(self.path, f"run {self.run.id} does not replay on net {self.net.name!r}: {problem}",
                              table=table, row=entry)

    def place(self, table: str, entry: int, pid: str) -> str:
        if pid not in self.counts:
            raise self.refuse(table, entry, f"names place {pid[:60]!r}, which the net does not have")
        return pid

    def firing(self, rec: FiringRow) -> None:
        if rec.transition not in self.transitions:
            raise self.refuse("firing", rec.entry, f"fires {rec.transition[:60]!r}, which the net does not have")
        if rec.seq <= self.seq:
            raise self.refuse("firing", rec.entry, f"firing #{rec.seq} comes after #{self.seq}")
        self.seq = rec.seq
        for pid, n in rec.consumed.items():
            held = self.counts[self.place("firing", rec.entry, pid)]
            if held < n:
                raise self.refuse("firing", rec.entry, f"#{rec.seq} {rec.transition} takes {n} token(s) from place "
                                  f"{pid!r}, which holds {held} after the records before it")
            self.counts[pid] = held - n
        for pid, n in rec.produced.items():
            self.counts[self.place("firing", rec.entry, pid)] += n
        for iid in rec.instances:
            inst = self.live.pop(iid, None)
            if inst is None:
                raise self.refuse("firing", rec.entry, f"#{rec.seq} {rec.transition} consumes instance {iid[:60]!r}, "
                                  "which is not live (never started, or consumed before)")
            self.per_place[inst.place] -= 1
        self.fired = rec.seq

    def start(self, rec: StartRow) -> None:
        if self.task_of.get(rec.place) != rec.task:
            raise self.refuse("action_start", rec.entry, f"instance {rec.instance[:60]!r} of task {rec.task[:60]!r} "
                              f"starts in place {rec.place[:60]!r}, which is not that task's place in the net")
        if rec.instance in self.started:
            raise self.refuse("action_start", rec.entry, f"instance {rec.instance[:60]!r} is started twice")
        n = self.per_place.get(rec.place, 0) + 1
        if n > self.counts[rec.place]:
            raise self.refuse("action_start", rec.entry, f"instance {rec.instance[:60]!r} would be instance {n} of "
                              f"place {rec.place!r}, which holds {self.counts[rec.place]} token(s)")
        self.per_place[rec.place] = n
        self.started.add(rec.instance)
        self.live[rec.instance] = Instance(rec.instance, rec.task, rec.place, rec.action)
        self.nodes[rec.instance] = rec.node
        self.params[rec.instance] = dict(rec.params)
        digits = "".join(ch for ch in rec.instance.rsplit("-", 1)[-1] if ch.isdigit())
        self.highest = max(self.highest, int(digits[:18]) if digits else 0)

    def result(self, rec: ResultRow) -> None:
        if rec.instance not in self.started:
            raise self.refuse("action_result", rec.entry, f"a result for instance {rec.instance[:60]!r}, which this "
                              "run never started")
        inst = self.live.get(rec.instance)
        if inst is not None and inst.running:
            inst.status = rec.result.status
            inst.outcomes = latched_events(inst.status, rec.result.outcome)

    def operator(self, rec: OperatorRow) -> None:
        if rec.accepted and rec.command in ("break", "clear"):
            self.breakpoint(rec)
        if not rec.accepted or rec.command not in ("insert", "remove"):
            return
        if rec.place is None or rec.count is None or rec.count < 1:
            raise self.refuse("operator", rec.entry, f"{rec.command} without a place and a positive count")
        held = self.counts[self.place("operator", rec.entry, rec.place)]
        if rec.command == "remove" and held < rec.count:
            raise self.refuse("operator", rec.entry, f"removes {rec.count} token(s) from place {rec.place!r}, "
                              f"which holds {held}")
        self.counts[rec.place] = held + (rec.count if rec.command == "insert" else -rec.count)

    def breakpoint(self, rec: OperatorRow) -> None:
        """A ``break`` sets its breakpoint, a ``clear`` clears it (what the resumed run re-arms)."""
        detail = rec.detail if isinstance(rec.detail, dict) else {}
        try:
            bp = Breakpoint.from_json(detail.get("breakpoint"))
        except ValueError as exc:
            raise self.refuse("operator", rec.entry,
                              f"{rec.command} without a breakpoint in its detail ({exc})") from None
        if rec.command == "break":
            problem = breakpoint_problem(self.net, bp)
            if problem is not None:
                raise self.refuse("operator", rec.entry, f"break {bp}: {problem}")
            self.breakpoints.setdefault(bp, None)
        else:
            self.breakpoints.pop(bp, None)


def _replay(path: str, net: PetriNet, run: RunRow, records: Iterable[Record]) -> Recovered:
    state = _Replay(path, net, run)
    for rec in records:
        if isinstance(rec, FiringRow):
            state.firing(rec)
        elif isinstance(rec, StartRow):
            state.start(rec)
        elif isinstance(rec, ResultRow):
            state.result(rec)
        elif isinstance(rec, OperatorRow):
            state.operator(rec)
    marking = Marking({p: n for p, n in state.counts.items() if n})
    return Recovered(run.id, run.seed, marking, tuple(state.live.values()), state.nodes, state.params, state.fired,
                     state.highest + 1, tuple(state.breakpoints))
