"""The node's durable result store (services.node.store), on a file in a temporary directory."""

from __future__ import annotations

import os
import sqlite3
import stat
from pathlib import Path

import pytest

from services.node.calls import Answer, CallTable, KeptResult, Start
from services.node.store import (
    DB_NAME,
    NODE_RESTARTED,
    SqliteResultCache,
    StateDirError,
    default_state_dir,
)
from services.protocol import Call, Result, encode_frame
from services.results import ActionResult


def result(cid: str, value: object = None) -> Result:
    return Result(id=cid, result=ActionResult.success(value, cost=1.5))


def kept(cid: str, at: float, value: object = None, action: str = "echo") -> KeptResult:
    res = result(cid, value)
    return KeptResult(cid, action, res, len(encode_frame(res)), at)


def crash(store: SqliteResultCache) -> None:
    """What the kernel does for a process killed with SIGKILL: close its files, flush nothing."""
    store._db.close()
    os.close(store._lock_fd)


@pytest.fixture
def state(tmp_path: Path) -> Path:
    return tmp_path / "state" / "alpha"


def test_results_survive_a_reopen_byte_for_byte(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0)
    store.put(kept("c1", 1.0, {"x": [1, 2.5, b"\x00"]}))
    store.flush()
    store.close()
    again = SqliteResultCache(state, now=2.0)
    got = again.get("c1")
    first = kept("c1", 1.0, {"x": [1, 2.5, b"\x00"]})
    assert got == first._replace(frame=encode_frame(first.result))  # with the very bytes of its frame
    assert again.get("c2") is None and len(again) == 1
    again.close()


def test_a_call_begun_and_not_finished_is_answered_node_restarted_after_a_crash(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0)
    table = CallTable[str](["wait"], cache=store)
    assert isinstance(table.admit(Call(id="w1", action="wait"), "p", local=True, now=1.0), Start)
    store.flush()  # the node commits the start before the action runs
    crash(store)
    reopened = SqliteResultCache(state, now=5.0)
    assert reopened.restarted == {"w1"}
    after = CallTable[str](["wait"], cache=reopened)
    verdict = after.admit(Call(id="w1", action="wait"), "p", local=True, now=6.0)
    assert isinstance(verdict, Answer)
    r = verdict.kept.result.result
    assert (r.status, r.reason) == ("error", NODE_RESTARTED)
    assert isinstance(after.admit(Call(id="w2", action="wait"), "p", local=True, now=6.0), Start)
    reopened.close()


def test_a_result_put_is_visible_before_the_flush_and_on_disk_after_it(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0)
    store.put(kept("c1", 1.0, 7))
    assert store.get("c1") is not None
    import sqlite3

    peek = sqlite3.connect(state / DB_NAME)  # a second reader of the same file
    assert peek.execute("SELECT COUNT(*) FROM calls").fetchone() == (0,)
    store.flush()
    assert peek.execute("SELECT COUNT(*) FROM calls WHERE frame IS NOT NULL").fetchone() == (1,)
    peek.close()
    store.close()


def test_results_are_bounded_by_bytes_oldest_first_not_by_count(state: Path) -> None:
    one = kept("c0", 0.0).size + 512
    store = SqliteResultCache(state, now=0.0, max_bytes=100 * one)
    for i in range(250):
        store.put(kept(f"c{i}", float(i)))
        store.flush()
    assert store.nbytes <= 100 * one
    assert store.get("c249") is not None and store.get("c0") is None
    assert 80 <= len(store) <= 100
    charged = store.nbytes
    store.close()
    reopened = SqliteResultCache(state, now=250.0, max_bytes=100 * one)
    assert reopened.nbytes == charged
    reopened.close()


def test_more_than_ten_thousand_small_results_are_all_kept_within_the_default_budget(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0)
    store.put(kept("first", 0.0, "the first result"))
    for i in range(12_000):
        store.put(kept(f"c{i}", 1.0))
        if i % 500 == 0:
            store.flush()
    store.flush()
    first = store.get("first")
    assert first is not None and first.result.result.value == "the first result"
    store.close()


def test_results_older_than_the_age_cap_expire_and_also_at_opening(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0, max_age_s=600.0)
    store.put(kept("old", 0.0))
    store.put(kept("new", 500.0))
    assert store.expire(650.0) == 1
    assert store.get("old") is None and store.get("new") is not None
    store.close()
    reopened = SqliteResultCache(state, now=2000.0, max_age_s=600.0)
    assert reopened.get("new") is None and reopened.nbytes == 0
    reopened.close()


def test_a_second_process_cannot_open_the_same_state_directory(state: Path) -> None:
    store = SqliteResultCache(state, now=0.0)
    with pytest.raises(StateDirError, match="in use by another node process"):
        SqliteResultCache(state, now=0.0)
    store.close()
    SqliteResultCache(state, now=0.0).close()


def test_the_state_directory_and_file_are_private(state: Path) -> None:
    SqliteResultCache(state, now=0.0).close()
    assert stat.S_IMODE(os.stat(state).st_mode) == 0o700
    assert stat.S_IMODE(os.stat(state / DB_NAME).st_mode) == 0o600


def test_an_unusable_state_directory_is_a_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(StateDirError, match="cannot use the state directory"):
        SqliteResultCache(blocker / "alpha", now=0.0)


def test_the_default_state_directory_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    assert default_state_dir("alpha") == tmp_path / "petrobot" / "alpha"
    monkeypatch.delenv("XDG_STATE_HOME")
    assert default_state_dir("beta") == Path(os.path.expanduser("~/.local/state/petrobot/beta"))


def test_bad_bounds_are_refused(state: Path) -> None:
    with pytest.raises(ValueError):
        SqliteResultCache(state, now=0.0, max_bytes=0)
    with pytest.raises(ValueError):
        SqliteResultCache(state, now=0.0, synchronous="OFF")


def test_a_store_of_a_without_rowid_table_is_rebuilt_keeping_its_results_and_its_running_calls(state: Path) -> None:
    # in a WITHOUT ROWID table the whole row is the key: every lookup read the overflow pages of
    # the results of megabytes it passed by; the call id now has an index of its own
    state.mkdir(parents=True)
    db = sqlite3.connect(state / DB_NAME)
    db.executescript("""
        CREATE TABLE calls (call_id TEXT PRIMARY KEY, action TEXT NOT NULL, frame BLOB, size INTEGER NOT NULL,
                            at REAL NOT NULL) WITHOUT ROWID;
        CREATE INDEX kept_by_age ON calls (at) WHERE frame IS NOT NULL;""")
    frame = encode_frame(result("c1", b"\x01" * 100_000))
    db.execute("INSERT INTO calls VALUES ('c1', 'echo', ?, ?, 1.0)", (frame, len(frame)))
    db.execute("INSERT INTO calls VALUES ('w1', 'wait', NULL, 0, 1.0)")
    db.commit()
    db.close()
    store = SqliteResultCache(state, now=2.0)
    got = store.get("c1")
    assert got is not None and got.frame == frame
    assert store.restarted == frozenset({"w1"}) and len(store) == 2
    (sql,) = store._db.execute("SELECT sql FROM sqlite_master WHERE name = 'calls'").fetchone()
    assert "WITHOUT ROWID" not in sql.upper()
    assert store._db.execute("SELECT name FROM sqlite_master WHERE name = 'kept_by_age'").fetchone() is not None
    store.close()
