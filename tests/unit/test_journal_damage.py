"""A damaged journal never crashes a reader (issue 22, section 5): real journals (the catching demo's,
tests/data/catching_demo.sqlite) damaged on purpose — a firing's JSON replaced by garbage, a result
whose status does not exist, a dropped table, a schema from the future — and 200 copies with bits
flipped at random. Every command names the damaged record (table, row, field) and skips it or refuses
the journal with exit status 2; ``--resume`` runs SQLite's integrity check and refuses records that
disagree; nothing ends in a traceback."""

from __future__ import annotations

import contextlib
import io
import random
import shutil
import sqlite3
from pathlib import Path

import pytest

from coordinator.cli import main
from coordinator.engine import Engine
from coordinator.errors import DamagedJournal, JournalError, JournalTooNew
from coordinator.journal import Journal, JournalReader
from coordinator.journal.schema import SCHEMA_VERSION
from coordinator.netfile import load_any

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "catching_demo.sqlite"
NET = ROOT / "nets" / "catch.toml"


def copy_of(tmp_path: Path, name: str = "j.sqlite", *, unfinished: bool = False) -> Path:
    """A copy of the demo's journal; ``unfinished``: its run as a killed coordinator leaves it."""
    path = tmp_path / name
    shutil.copyfile(DATA, path)
    if unfinished:
        with sqlite3.connect(path) as db:
            db.execute("UPDATE run SET ended_wall=NULL, end_state=NULL")
        sqlite3.connect(path).execute("PRAGMA wal_checkpoint(TRUNCATE)").close()
    return path


def cli(*argv: str) -> tuple[int, str, str]:
    """Run ``petrobot ARGV`` in this process; (exit status, stdout, stderr). A traceback fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def edit(path: Path, sql: str, *args: object) -> None:
    with sqlite3.connect(path) as db:
        db.execute(sql, args)


def resume_check(path: Path) -> str:
    """What ``petrobot run --resume`` does with the journal before it calls any node: open it for
    writing, find the run, rebuild its state, restore the engine. '' when it can resume, else why not."""
    net = load_any(NET)
    try:
        with Journal(path) as journal:
            run = journal.last_unfinished_run(net.name)
            if run is None:
                return "nothing to resume"
            rec = journal.recover(net, run)
        Engine(net, seed=rec.seed).restore(rec.marking, rec.instances, fired=rec.fired,
                                           next_instance=rec.next_instance)
    except JournalError as exc:
        return str(exc)
    return ""


def test_the_undamaged_journal_reads_and_resumes(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    code, out, err = cli("show", "last", "--journal", str(path))
    assert code == 0 and "fire" in out and err == "", err
    assert resume_check(path) == ""


def test_a_firings_json_replaced_by_garbage_is_named_and_skipped_by_show_and_refused_by_resume(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    edit(path, "UPDATE firing SET consumed='{\"locating\": 1, garbage' WHERE entry=4")
    code, out, err = cli("show", "last", "--journal", str(path))
    assert code == 2, err
    assert "table firing, row 4, field consumed: not JSON" in err, err
    assert "#2     ball_located" not in out and "#8     ball_located" in out  # the rest is shown
    why = resume_check(path)
    assert "table firing, row 4, field consumed" in why, why
    code, _, err = cli("run", str(NET), "--resume", "--journal", str(path), "--no-input")
    assert code == 2 and "table firing, row 4, field consumed" in err, err  # refused before any node is called


def test_a_result_with_a_status_that_does_not_exist_is_named_by_every_reader(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    edit(path, "UPDATE action_result SET status='exploded' WHERE entry=3")
    for argv in (("show", "last"), ("perf", str(NET)), ("learn", str(NET)), ("runs",)):
        code, _, err = cli(*argv, "--journal", str(path))
        if argv == ("runs",):  # runs counts by SQL, reads no result row: nothing to skip
            assert code == 0, err
            continue
        assert code == 2 and "table action_result, row 3, field status: status 'exploded'" in err, (argv, err)
    assert "table action_result, row 3, field status" in resume_check(path)


def test_records_that_disagree_are_refused_by_resume_with_the_reason(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    edit(path, "UPDATE firing SET consumed='{\"locating\": 3}' WHERE entry=4")  # well-formed, but not held
    why = resume_check(path)
    assert "table firing, row 4" in why and "takes 3 token(s) from place 'locating', which holds 1" in why, why
    path = copy_of(tmp_path, "other.sqlite", unfinished=True)
    edit(path, "UPDATE action_result SET instance='nobody-7' WHERE entry=3")
    why = resume_check(path)
    assert "table action_result, row 3" in why and "never started" in why, why


def test_a_dropped_table_is_never_created_again_under_an_existing_journal(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    edit(path, "DROP TABLE firing")
    with pytest.raises(DamagedJournal, match="table firing: the table is missing from this journal"):
        Journal(path)
    with sqlite3.connect(path) as db:  # still not there: nothing was created
        assert not db.execute("SELECT name FROM sqlite_master WHERE name='firing'").fetchall()
    code, _, err = cli("run", str(NET), "--journal", str(path), "--no-input")
    assert code == 2 and "missing" in err, err
    code, _, err = cli("show", "last", "--journal", str(path))
    assert code == 2 and "no table 'firing'" in err, err


def test_a_journal_of_a_newer_schema_is_refused_by_every_command_with_the_version_it_needs(tmp_path: Path) -> None:
    path = copy_of(tmp_path)
    edit(path, "PRAGMA user_version=99")
    for argv in (("runs",), ("show", "last"), ("perf", str(NET)), ("learn", str(NET)), ("gspn", str(NET)),
                 ("run", str(NET), "--no-input")):
        code, _, err = cli(*argv, "--journal", str(path))
        assert code == 2 and "journal schema 99" in err and f"schemas up to {SCHEMA_VERSION}" in err, (argv, err)
    with pytest.raises(JournalTooNew):
        JournalReader.open(path)


def test_sqlite_integrity_check_runs_before_a_resume(tmp_path: Path) -> None:
    path = copy_of(tmp_path, unfinished=True)
    with sqlite3.connect(path) as db:  # an index that no longer matches its table
        db.execute("PRAGMA writable_schema=ON")
        page = db.execute("SELECT rootpage FROM sqlite_master WHERE name='firing_run'").fetchone()[0]
        size = db.execute("PRAGMA page_size").fetchone()[0]
    data = bytearray(path.read_bytes())
    offset = (page - 1) * size
    data[offset + 8 + 12:offset + 8 + 20] = b"\xff" * 8  # garble the index page's cells
    path.write_bytes(bytes(data))
    why = resume_check(path)
    assert "integrity check (PRAGMA quick_check) failed" in why, why


def _flip(path: Path, rng: random.Random, bits: int) -> None:
    data = bytearray(path.read_bytes())
    for _ in range(bits):
        i = rng.randrange(len(data))
        data[i] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))


def test_200_journals_with_bits_flipped_at_random_never_end_in_a_traceback(tmp_path: Path) -> None:
    """Each copy: 3 single-bit flips anywhere in the file. ``show``, ``runs`` and the resume path (and
    ``perf`` on every fifth) either read it (0), skip named damage, or refuse it (1 for an unknown
    run, 2 for damage); an exception escaping fails the test with its traceback."""
    rng = random.Random(22)
    outcomes: dict[str, int] = {}
    for i in range(200):
        path = copy_of(tmp_path, f"flipped-{i}.sqlite", unfinished=True)
        _flip(path, rng, 3)
        for argv in (("show", "last"), ("runs",)) + ((("perf", str(NET)),) if i % 5 == 0 else ()):
            code, _, err = cli(*argv, "--journal", str(path))
            assert code in (0, 1, 2), (i, argv, code, err)
            if code == 2:
                assert "damaged" in err or "cannot read" in err or "not a petrobot journal" in err \
                    or "schema" in err or "integrity" in err, (i, argv, err)
            outcomes[f"{argv[0]} {code}"] = outcomes.get(f"{argv[0]} {code}", 0) + 1
        why = resume_check(path)
        outcomes["resume " + ("refused" if why else "ok")] = outcomes.get("resume " + ("refused" if why else "ok"), 0) + 1
        path.unlink()
    print(sorted(outcomes.items()))
    assert outcomes.get("show 2", 0) > 0 and outcomes.get("show 0", 0) > 0  # both kinds of copies were met
