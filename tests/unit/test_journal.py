"""The SQLite journal: write-ahead records and recovery of an interrupted run (no sockets)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from coordinator.engine import Engine, Firing, StartAction
from coordinator.errors import JournalError
from coordinator.journal import Journal, JournalReader
from coordinator.journal.schema import SCHEMA_VERSION
from coordinator.netfile import loads_net
from services.results import ActionResult, Status

NET = """
[net]
name = "j"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "work"
kind = "primitive_task"
task = "w"

[[place]]
id = "done"

[task.w]
actions = ["a", "b"]

[[transition]]
id = "go"
inputs = { runs = 1 }
outputs = { work = 1 }

[[transition]]
id = "ok"
events = ["int:w.ok"]
inputs = { work = 1 }
outputs = { done = 1 }

[[transition]]
id = "err"
events = ["int:w.error"]
inputs = { work = 1 }
outputs = { runs = 1 }
"""


def journaled_engine(journal: Journal, net, run: str) -> tuple[Engine, list[StartAction]]:
    engine = Engine(net, instance_prefix=f"{run}-")
    starts: list[StartAction] = []

    def act(effects) -> None:
        for e in effects:
            if isinstance(e, StartAction):
                journal.action_start(run, e.instance, e.task, e.place, e.action, "alpha", e.params)
                starts.append(e)

    act(engine.start())
    engine.advance(lambda f: journal.firing(run, f), after_fire=act)
    return engine, starts


def test_recovery_rebuilds_marking_and_running_instances(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net, seed=4)
        engine, starts = journaled_engine(journal, net, run)
        assert len(starts) == 2
        first, second = starts
        journal.action_result(run, first.instance, "w", first.action, "alpha", ActionResult(status=Status.SUCCESS, wall_s=0.1))
        engine.complete(first.instance, ActionResult(status=Status.SUCCESS, wall_s=0.1))
        journal.operator(run, "insert", "runs", 1)
        engine.insert_tokens("runs", 1)
        # crash here: 'second' is still running; the operator's token is not yet used
    with Journal(tmp_path / "j.sqlite") as journal:
        assert journal.last_unfinished_run("j") == run
        rec = journal.recover(net, run)
    assert rec.seed == 4
    assert rec.marking == engine.marking == {"work": 2, "runs": 1}
    assert [(i.id, i.running) for i in rec.instances] == [(first.instance, False), (second.instance, True)]
    assert rec.nodes[second.instance] == "alpha"
    assert rec.next_instance == 3
    again = Engine(net, instance_prefix=f"{run}-")
    again.restore(rec.marking, rec.instances, fired=rec.fired, next_instance=rec.next_instance)
    assert again.start() == []  # every token in a task place already has its instance
    effects = again.advance()
    assert sorted(e.transition for e in effects if isinstance(e, Firing)) == ["go", "ok"]
    assert [e.instance for e in effects if isinstance(e, StartAction)] == [f"{run}-3"]


def test_firings_are_journaled_before_they_are_applied(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net)
        engine = Engine(net)
        seen = []

        def before(firing: Firing) -> None:
            seen.append((journal.firings(run)[-1].seq if journal.firings(run) else 0, dict(engine.marking)))
            journal.firing(run, firing)

        engine.advance(before)
        assert [m for _, m in seen] == [{"runs": 2}, {"runs": 1, "work": 1}]
        rows = journal.firings(run)
        assert [r.transition for r in rows] == ["go", "go"]


def test_learner_state_is_replaced_not_appended(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        journal.save_learner("w", "pursuit", {"p": [0.5, 0.5]})
        journal.save_learner("w", "pursuit", {"p": [0.9, 0.1]})
        saved = journal.learner_states()
    assert list(saved) == ["w"]
    assert (saved["w"].scheme, saved["w"].state) == ("pursuit", {"p": [0.9, 0.1]})


def test_values_that_json_cannot_hold_are_not_a_crash(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        journal.action_result("r", "i", "w", "a", None, ActionResult.success(object()))
        journal.action_result("r", "i2", "w", "a", None, ActionResult.success({"img": b"\x00" * 10}))
        rows = list(journal.results("r"))
    assert [r.instance for r in rows] == ["i", "i2"]


def test_a_file_that_is_not_a_journal_is_refused(tmp_path: Path):
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(JournalError, match="bad.sqlite"):
        Journal(bad)


def test_recovering_an_unknown_run_is_an_error(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal, pytest.raises(JournalError, match="no run"):
        journal.recover(loads_net(NET), "nope")


def test_the_read_api_gives_typed_records_of_one_run_or_of_all(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        first = journal.begin_run(net, seed=1)
        _, starts = journaled_engine(journal, net, first)
        journal.action_result(first, starts[0].instance, "w", starts[0].action, "alpha",
                              ActionResult.failure({"seen": 2}, outcome="nothing"))
        journal.operator(first, "remove", "runs", 1)
        journal.end_run(first, "aborted", "by hand")
        second = journal.begin_run(net, seed=2)
        journal.action_result(second, "x-1", "w", "b", None, ActionResult.error("deadline"))
    with JournalReader.open(tmp_path / "j.sqlite") as reader:
        runs = reader.runs()
        assert [(r.id, r.seed, r.end_state, r.finished) for r in runs] == [
            (first, 1, "aborted", True), (second, 2, None, False)]
        assert reader.run(first).note == "by hand"
        (result,) = reader.results(first)
        assert result.status is Status.FAILURE and result.outcome == "nothing"
        assert result.value == {"seen": 2} and result.node == "alpha" and result.run == first
        assert [r.status for r in reader.results()] == [Status.FAILURE, Status.ERROR]
        assert reader.results(second)[0].reason == "deadline"
        assert [s.instance for s in reader.starts(first)] == [s.instance for s in starts]
        assert [f.transition for f in reader.firings(first)] == ["go", "go"]
        assert reader.firings(first)[0].produced == {"work": 1}
        assert [(c.command, c.place, c.count) for c in reader.operator_commands()] == [("remove", "runs", 1)]
        assert reader.firings(second) == []
        with pytest.raises(JournalError, match="no run 'nope'"):
            reader.run("nope")


def test_a_journal_opened_for_reading_cannot_be_written(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        journal.begin_run(loads_net(NET))
    with JournalReader.open(tmp_path / "j.sqlite") as reader:
        with pytest.raises(sqlite3.OperationalError, match="readonly"):
            reader._db.execute("DELETE FROM run")
        assert len(reader.runs()) == 1


def test_reading_a_missing_or_foreign_file_names_it(tmp_path: Path):
    with pytest.raises(JournalError, match="none.sqlite: no such journal file"):
        JournalReader.open(tmp_path / "none.sqlite")
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE run (id TEXT)")
    with pytest.raises(JournalError, match="other.sqlite: not a petrobot journal"):
        JournalReader.open(other)
    with pytest.raises(JournalError, match="other.sqlite: not a petrobot journal"):
        Journal(other)
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(JournalError, match="bad.sqlite"):
        JournalReader.open(bad)


# ---------------------------------------------------------------------- order, versions, resumable runs
def test_recovery_replays_records_in_the_order_they_were_written_across_tables(tmp_path: Path):
    """Two instances run at once and the second ends first: its result is the journal's first result
    but comes after its start; a replay that ordered each table on its own would see the result
    before the start and think the instance still runs."""
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net)
        engine, starts = journaled_engine(journal, net, run)
        first, second = starts
        journal.action_result(run, second.instance, "w", second.action, "alpha", ActionResult.success())
        engine.complete(second.instance, ActionResult.success())
    with Journal(tmp_path / "j.sqlite") as journal:
        rec = journal.recover(net, run)
        assert [(i.id, i.running) for i in rec.instances] == [(first.instance, True), (second.instance, False)]
        order = [type(r).__name__ for r in journal.timeline(run)]
    assert order == ["FiringRow", "StartRow", "FiringRow", "StartRow", "ResultRow"]


OLD_SCHEMA = """
CREATE TABLE run (id TEXT PRIMARY KEY, net_name TEXT NOT NULL, net_text TEXT, seed INTEGER,
    started_wall REAL NOT NULL, ended_wall REAL, end_state TEXT, note TEXT);
CREATE TABLE firing (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, seq INTEGER NOT NULL, transition TEXT NOT NULL,
    consumed TEXT NOT NULL, produced TEXT NOT NULL, instances TEXT NOT NULL, pulse TEXT, t_wall REAL NOT NULL);
CREATE TABLE action_start (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    place TEXT NOT NULL, action TEXT NOT NULL, node TEXT, params TEXT, t_wall REAL NOT NULL);
CREATE TABLE action_result (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, instance TEXT NOT NULL, task TEXT NOT NULL,
    action TEXT NOT NULL, node TEXT, status TEXT NOT NULL, outcome TEXT, cost REAL, wall_s REAL,
    cpu_s REAL, t_wall REAL NOT NULL, reason TEXT, value TEXT);
CREATE TABLE operator (entry INTEGER PRIMARY KEY, run TEXT NOT NULL, command TEXT NOT NULL, place TEXT,
    count INTEGER, t_wall REAL NOT NULL);
CREATE TABLE learner_state (task TEXT PRIMARY KEY, scheme TEXT, state TEXT NOT NULL, updated_wall REAL NOT NULL);
INSERT INTO run VALUES ('r1', 'j', NULL, 0, 100.0, NULL, NULL, NULL);
INSERT INTO firing VALUES (1, 'r1', 1, 'go', '{"runs": 1}', '{"work": 1}', '[]', NULL, 101.0);
INSERT INTO firing VALUES (2, 'r1', 2, 'go', '{"runs": 1}', '{"work": 1}', '[]', NULL, 103.0);
INSERT INTO action_start VALUES (1, 'r1', 'r1-1', 'w', 'work', 'a', 'alpha', '{}', 102.0);
INSERT INTO action_start VALUES (2, 'r1', 'r1-2', 'w', 'work', 'a', 'alpha', '{}', 104.0);
INSERT INTO action_result VALUES (1, 'r1', 'r1-2', 'w', 'a', 'alpha', 'success', NULL, NULL, 0.1, NULL, 105.0,
    NULL, NULL);
INSERT INTO operator VALUES (1, 'r1', 'insert', 'runs', 1, 106.0);
"""


def old_journal(path: Path) -> Path:
    with sqlite3.connect(path) as db:
        db.executescript(OLD_SCHEMA)
    return path


def test_a_journal_of_version_1_is_read_as_it_is_and_migrated_when_opened_for_writing(tmp_path: Path):
    path = old_journal(tmp_path / "old.sqlite")
    net = loads_net(NET)
    with JournalReader.open(path) as reader:  # read-only: nothing changes
        assert [(c.command, c.accepted, c.reason) for c in reader.operator_commands()] == [("insert", True, None)]
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == 0
    with Journal(path) as journal:
        assert [type(r).__name__ for r in journal.timeline("r1")] == [
            "FiringRow", "StartRow", "FiringRow", "StartRow", "ResultRow", "OperatorRow"]
        assert [r.entry for r in journal.timeline("r1")] == [1, 2, 3, 4, 5, 6]
        rec = journal.recover(net, "r1")
        assert [(i.id, i.running) for i in rec.instances] == [("r1-1", True), ("r1-2", False)]
        assert rec.marking == {"work": 2, "runs": 1}
        journal.operator("r1", "remove", "nope", 1, accepted=False, reason="no place 'nope'")
        assert journal.timeline("r1")[-1].entry == 7
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    with JournalReader.open(path) as reader:
        refused = reader.operator_commands()[-1]
        assert (refused.command, refused.accepted, refused.reason) == ("remove", False, "no place 'nope'")
        assert reader.recover(net, "r1").marking == {"work": 2, "runs": 1}  # a refused command changes nothing


def test_a_journal_of_a_newer_version_is_refused_for_writing(tmp_path: Path):
    path = tmp_path / "new.sqlite"
    with Journal(path):
        pass
    with sqlite3.connect(path) as db:
        db.execute("PRAGMA user_version=99")
    with pytest.raises(JournalError, match="newer petrobot"):
        Journal(path)


def test_an_interrupted_run_stays_resumable_until_it_ends_again(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        done = journal.begin_run(net)
        journal.end_run(done, "completed")
        run = journal.begin_run(net)
        journal.end_run(run, "interrupted", "Ctrl-C")
        assert journal.last_unfinished_run("j") == run
        assert journal.run(run).resumable and not journal.run(done).resumable
        journal.reopen_run(run)
        assert journal.run(run).end_state is None and not journal.run(run).finished
        journal.end_run(run, "completed")
        assert journal.last_unfinished_run("j") is None


def test_run_stats_count_what_each_run_did(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        first = journal.begin_run(net)
        _, starts = journaled_engine(journal, net, first)
        journal.action_result(first, starts[0].instance, "w", "a", "alpha", ActionResult.error("drive 1 is in FAULT"))
        journal.action_result(first, starts[1].instance, "w", "a", "alpha", ActionResult.failure())
        journal.operator(first, "pause")
        journal.operator(first, "insert", "work", 1, accepted=False, reason="not a control place")
        journal.end_run(first, "stuck", "work: 2 tokens")
        second = journal.begin_run(net)
    with JournalReader.open(tmp_path / "j.sqlite") as reader:
        stats = {s.run.id: s for s in reader.run_stats()}
    a, b = stats[first], stats[second]
    assert (a.firings, a.calls, a.errors, a.failures, a.operator_commands, a.refused) == (2, 2, 1, 1, 2, 1)
    assert a.duration_s >= 0 and a.run.end_state == "stuck"
    assert (b.firings, b.calls, b.errors, b.operator_commands) == (0, 0, 0, 0) and b.duration_s == 0


def version_2_journal(path: Path) -> Path:
    """A journal as petrobot wrote it before reconciliations: version 2, no reconciliation table."""
    net = loads_net(NET)
    with Journal(path) as journal:
        run = journal.begin_run(net, run_id="r2")
        _, starts = journaled_engine(journal, net, run)
        journal.action_result(run, starts[0].instance, "w", "a", "alpha", ActionResult.error("heartbeat timeout"))
    with sqlite3.connect(path) as db:
        db.execute("DROP TABLE reconciliation")
        db.execute("PRAGMA user_version=2")
    return path


def test_a_journal_of_version_2_is_read_without_reconciliations_and_migrated_when_opened_for_writing(
        tmp_path: Path):
    path = version_2_journal(tmp_path / "v2.sqlite")
    with JournalReader.open(path) as reader:
        assert reader.reconciliations() == []
        assert [type(r).__name__ for r in reader.timeline("r2")][-1] == "ResultRow"
        assert reader.run_stats()[0].reconciled == 0
    with sqlite3.connect(path) as db:  # reading changed nothing
        assert not db.execute("SELECT name FROM sqlite_master WHERE name='reconciliation'").fetchall()
    with Journal(path) as journal:
        journal.reconciliation("r2", "r2-1", "w", "a", "alpha", Status.ERROR, ActionResult.success(7))
        assert [r.entry for r in journal.timeline("r2")] == [1, 2, 3, 4, 5, 6]
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 5


def test_a_reconciliation_is_the_journals_last_word_on_a_call_and_says_whether_it_differs(tmp_path: Path):
    net = loads_net(NET)
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(net)
        _, (first, second) = journaled_engine(journal, net, run)
        lost = ActionResult.error("heartbeat timeout")
        journal.action_result(run, first.instance, "w", "a", "beta", lost)
        journal.action_result(run, second.instance, "w", "a", "beta", lost)
        journal.reconciliation(run, first.instance, "w", "a", "beta", Status.ERROR,
                               ActionResult(status=Status.SUCCESS, value={"waited_s": 2.0}, wall_s=2.0, cpu_s=0.01))
        journal.reconciliation(run, second.instance, "w", "a", "beta", Status.ERROR, None)
    with JournalReader.open(tmp_path / "j.sqlite") as reader:
        finished, never = reader.reconciliations(run)
        words = reader.final_words(run)
        (stats,) = reader.run_stats()
        kinds = [type(r).__name__ for r in reader.timeline(run)][-4:]
    assert (finished.assumed, finished.status, finished.value, finished.wall_s) == (
        Status.ERROR, Status.SUCCESS, {"waited_s": 2.0}, 2.0)
    assert finished.differs and finished.known
    assert (never.status, never.known, never.differs) == (None, False, False)  # never ran: agrees with error
    assert words[first.instance] == finished and words[second.instance] == never
    assert (stats.reconciled, stats.differed) == (2, 1)
    assert kinds == ["ResultRow", "ResultRow", "ReconciliationRow", "ReconciliationRow"]


def version_4_journal(path: Path) -> Path:
    """A journal as petrobot wrote it before it kept feedback: version 4, no feedback table."""
    net = loads_net(NET)
    with Journal(path) as journal:
        run = journal.begin_run(net, run_id="r4")
        _, starts = journaled_engine(journal, net, run)
        journal.action_result(run, starts[0].instance, "w", "a", "alpha", ActionResult.success(3))
    with sqlite3.connect(path) as db:
        db.execute("DROP TABLE feedback")
        db.execute("PRAGMA user_version=4")
    return path


def test_a_journal_of_version_4_is_read_without_feedback_and_migrated_when_opened_for_writing(tmp_path: Path):
    path = version_4_journal(tmp_path / "v4.sqlite")
    with JournalReader.open(path) as reader:
        assert reader.feedback_messages() == [] and reader.damage_report() == []
        kinds = [type(r).__name__ for r in reader.timeline("r4")]
    with sqlite3.connect(path) as db:  # reading changed nothing
        assert not db.execute("SELECT name FROM sqlite_master WHERE name='feedback'").fetchall()
    with Journal(path) as journal:
        assert [type(r).__name__ for r in journal.timeline("r4")] == kinds  # nothing lost
        journal.feedback("r4", "r4-2", "w", "a", {"progress": 0.5}, 1.0)
        (row,) = journal.feedback_messages("r4")
        assert (row.instance, row.data, row.entry) == ("r4-2", {"progress": 0.5}, len(kinds) + 1)
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 5


def test_a_feedback_too_large_or_not_json_is_kept_as_what_it_was(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        run = journal.begin_run(loads_net(NET))
        journal.feedback(run, "i-1", "w", "a", {"image": "x" * 100_000}, 1.0)
        journal.feedback(run, "i-1", "w", "a", object(), 2.0)
        big, odd = journal.feedback_messages(run)
    assert big.data["truncated"] is True and big.data["bytes"] > 100_000 and len(big.data["head"]) == 2048
    assert odd.data == {"unjsonable": "object"}


def test_a_damaged_feedback_row_is_skipped_and_named(tmp_path: Path):
    path = tmp_path / "j.sqlite"
    with Journal(path) as journal:
        run = journal.begin_run(loads_net(NET))
        journal.feedback(run, "i-1", "w", "a", {"progress": 1}, 1.0)
        journal.feedback(run, "i-1", "w", "a", {"progress": 2}, 2.0)
    with sqlite3.connect(path) as db:
        db.execute("UPDATE feedback SET data='{not json' WHERE entry=1")
    with JournalReader.open(path) as reader:
        assert [f.data for f in reader.feedback_messages(run)] == [{"progress": 2}]
        (line,) = reader.damage_report()
    assert "table feedback, row 1, field data" in line


def test_a_catching_demo_journal_of_schema_3_opens_and_migrates_keeping_every_record(tmp_path: Path):
    import shutil

    path = tmp_path / "catching.sqlite"
    shutil.copyfile(Path(__file__).resolve().parents[1] / "data" / "catching_demo_v3.sqlite", path)

    def kinds(reader: JournalReader) -> list[tuple[str, int]]:
        return [(type(r).__name__, r.entry) for run in reader.runs() for r in reader.timeline(run.id)]

    with JournalReader.open(path) as reader:
        before, learned = kinds(reader), reader.learner_states()
        assert reader.feedback_messages() == [] and len(before) > 20
    with Journal(path) as journal:
        assert kinds(journal) == before and journal.learner_states() == learned
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
