"""Call results that outlive the node process: an SQLite-backed :class:`~services.node.calls.ResultCache`.

"A node never runs one id twice" (docs/protocol.md §5) has to hold across a node restart and
however many other calls the node served. :class:`SqliteResultCache` keeps, in one SQLite file
(stdlib :mod:`sqlite3`, write-ahead log), the encoded ``result`` frame of every finished call,
bounded like :class:`~services.node.calls.MemoryResultCache`: by age (``max_age_s``) and by bytes
(each result charged its frame length plus ``entry_overhead``; the oldest are dropped first), never
by count. It also journals each call's *start*: a call found started but not finished when the
store is opened was running when the node died, and is answered ``error`` with reason
``"node_restarted"`` (:data:`NODE_RESTARTED`) instead of being run again.

Writes are grouped: :meth:`SqliteResultCache.begin` and :meth:`SqliteResultCache.put` queue rows
and :meth:`SqliteResultCache.flush` commits them in one transaction. The node flushes before it
starts an action and before it sends a result, once per event-loop iteration for all the calls of
that iteration, so a result a client saw is on disk, and so is the start of an action that ran.

Durability: with ``synchronous="NORMAL"`` (the default) a commit reaches the operating system but
is not forced to the disk: everything committed survives the node process crashing or being
killed, not a crash of the operating system or a power cut (the last commits may be lost then).
``synchronous="FULL"`` forces each commit to the disk (an ``fsync`` per group commit) and survives
those too.

Checkpoints (copying the write-ahead log into the database file, with an ``fsync``) are the one
slow write: :meth:`SqliteResultCache.checkpoint` does it on a connection of its own, and the node
calls it from a worker thread once a second, so that its event loop never waits for the disk.
SQLite's automatic checkpoint stays as a backstop, at 10,000 pages of log (40 MiB).

Times are wall-clock seconds (``time.time()``), the one clock that survives a restart.

One process at a time: the store holds an exclusive lock on ``DIR/lock`` while open; a second node
process with the same state directory fails to start (:class:`StateDirError`).
"""

from __future__ import annotations

import fcntl
import logging
import os
import sqlite3
from pathlib import Path
from typing import Final

from services.errors import PetrobotError
from services.node.calls import (
    DEFAULT_MAX_AGE_S,
    DEFAULT_MAX_BYTES,
    ENTRY_OVERHEAD,
    KeptResult,
)
from services.protocol import (
    DEFAULT_MAX_FRAME,
    Result,
    encode_frame,
    from_map,
    unpack_map,
)
from services.protocol.framing import HEADER_BYTES
from services.results import ActionResult

__all__ = ["DB_NAME", "NODE_RESTARTED", "SqliteResultCache", "StateDirError", "default_state_dir"]

log = logging.getLogger("petrobot.node")

NODE_RESTARTED: Final = "node_restarted"
"""The ``reason`` of the result kept for a call that was running when its node died."""
DB_NAME: Final = "results.sqlite3"
"""File name of the store in the state directory."""

# An ordinary (rowid) table, the call id in an index of its own: in a WITHOUT ROWID table the whole
# row is the b-tree's key, and SQLite reads a row's every overflow page to compare against it, so
# with results of megabytes kept each lookup and insert read megabytes (5.5 ms a call instead of
# 0.25 with 20 results of 1-16 MiB; a node under a connection flood answered in 80 ms instead of 4).
_TABLE: Final = """
CREATE TABLE IF NOT EXISTS {name} (
    call_id TEXT PRIMARY KEY,
    action  TEXT NOT NULL,
    frame   BLOB,               -- the encoded result frame; NULL while the call runs
    size    INTEGER NOT NULL,   -- length of frame, bytes (0 while running)
    at      REAL NOT NULL       -- wall-clock time the call started (running) or its result was kept
);
"""
_SCHEMA: Final = _TABLE.format(name="calls") + """
CREATE INDEX IF NOT EXISTS kept_by_age ON calls (at) WHERE frame IS NOT NULL;
"""


class StateDirError(PetrobotError):
    """The node's state directory cannot be used (not creatable, or in use by another process)."""


def default_state_dir(node: str) -> Path:
    """``$XDG_STATE_HOME/petrobot/NODE``, else ``~/.local/state/petrobot/NODE``."""
    base = os.environ.get("XDG_STATE_HOME") or os.path.expanduser("~/.local/state")
    return Path(base) / "petrobot" / node


class SqliteResultCache:
    """Kept results and started calls in an SQLite file (see the module docstring).

    Args:
        directory: the node's state directory; created with mode 0700 if missing.
        max_bytes: cap on the bytes charged for kept results.
        max_age_s: results older than this (s) are dropped by :meth:`expire`.
        entry_overhead: bytes charged per result on top of its frame.
        synchronous: SQLite's ``synchronous`` setting, ``"NORMAL"`` or ``"FULL"``.
        now: wall-clock time at opening (s): results older than ``max_age_s`` are dropped then.
        max_frame: cap used to encode the frame of a ``node_restarted`` result.

    Attributes:
        nbytes: bytes charged for the results kept now.
        restarted: ids of the calls found running when the store was opened (answered
            ``node_restarted`` from now on).

    Raises:
        StateDirError: the directory or the file cannot be created or opened, or another process
            holds the store.
        ValueError: a bound is not positive, or ``synchronous`` is not NORMAL or FULL.
    """

    def __init__(
        self,
        directory: str | os.PathLike[str],
        *,
        max_bytes: int = DEFAULT_MAX_BYTES,
        max_age_s: float = DEFAULT_MAX_AGE_S,
        entry_overhead: int = ENTRY_OVERHEAD,
        synchronous: str = "NORMAL",
        now: float,
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        if max_bytes <= 0 or max_age_s <= 0 or entry_overhead < 0:
            raise ValueError("max_bytes and max_age_s must be positive, entry_overhead non-negative")
        if synchronous.upper() not in ("NORMAL", "FULL"):
            raise ValueError(f"synchronous must be NORMAL or FULL, got {synchronous!r}")
        self.max_bytes = max_bytes
        self.max_age_s = max_age_s
        self.entry_overhead = entry_overhead
        self.directory = Path(directory)
        self.path = self.directory / DB_NAME
        self._begun: list[tuple[str, str, float]] = []
        self._ckpt: sqlite3.Connection | None = None
        self._kept: dict[str, KeptResult] = {}  # put since the last flush, by id
        self._lock_fd = self._lock()
        try:
            self._db = self._open(synchronous.upper())
            self.restarted = self._close_interrupted(now, max_frame)
            count, total = self._db.execute(
                "SELECT COUNT(*), COALESCE(SUM(size), 0) FROM calls WHERE frame IS NOT NULL").fetchone()
            self.nbytes = total + count * entry_overhead
            self.expire(now)
            self._evict()
        except BaseException:
            os.close(self._lock_fd)
            raise

    # ---- opening

    def _lock(self) -> int:
        try:
            self.directory.mkdir(mode=0o700, parents=True, exist_ok=True)
            fd = os.open(self.directory / "lock", os.O_RDWR | os.O_CREAT, 0o600)
        except OSError as exc:
            raise StateDirError(f"{self.directory}: cannot use the state directory: {exc}") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise StateDirError(f"{self.directory}: the state directory is in use by another node process") from None
        return fd

    def _open(self, synchronous: str) -> sqlite3.Connection:
        try:
            if not self.path.exists():
                os.close(os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600))
            db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(f"PRAGMA synchronous={synchronous}")
            db.execute("PRAGMA wal_autocheckpoint=10000")  # a backstop: checkpoint() runs off the loop
            db.execute("PRAGMA journal_size_limit=8388608")  # a reset log is cut back to 8 MiB
            self._rebuild_without_rowid(db)
            db.executescript(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise StateDirError(f"{self.path}: cannot open the result store: {exc}") from exc
        return db

    def _rebuild_without_rowid(self, db: sqlite3.Connection) -> None:
        """A store written by an earlier version (a WITHOUT ROWID table, see ``_TABLE``) is copied
        into an ordinary table in one transaction: the old table is dropped only in the
        transaction that fills its successor."""
        row = db.execute("SELECT sql FROM sqlite_master WHERE type = 'table' AND name = 'calls'").fetchone()
        if row is None or "WITHOUT ROWID" not in str(row[0]).upper():
            return
        db.execute("BEGIN IMMEDIATE")
        try:
            db.execute("DROP TABLE IF EXISTS calls_rebuilt")
            db.execute(_TABLE.format(name="calls_rebuilt"))
            db.execute("INSERT INTO calls_rebuilt (call_id, action, frame, size, at) "
                       "SELECT call_id, action, frame, size, at FROM calls")
            db.execute("DROP TABLE calls")
            db.execute("ALTER TABLE calls_rebuilt RENAME TO calls")
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        log.info("%s: result store rebuilt as an ordinary table (lookups no longer read whole results)", self.path)

    def _close_interrupted(self, now: float, max_frame: int) -> frozenset[str]:
        rows = self._db.execute("SELECT call_id FROM calls WHERE frame IS NULL").fetchall()
        if not rows:
            return frozenset()
        updates = []
        for (cid,) in rows:
            frame = encode_frame(Result(id=cid, result=ActionResult.error(NODE_RESTARTED)), max_frame)
            updates.append((frame, len(frame), now, cid))
        with self._db:
            self._db.execute("BEGIN")
            self._db.executemany("UPDATE calls SET frame = ?, size = ?, at = ? WHERE call_id = ?", updates)
        log.warning("%d call(s) were running when this node last stopped: answered %r from now on",
                    len(rows), NODE_RESTARTED)
        return frozenset(cid for (cid,) in rows)

    # ---- the ResultCache interface

    def get(self, call_id: str) -> KeptResult | None:
        """The kept result of ``call_id``, or ``None``."""
        kept = self._kept.get(call_id)
        if kept is not None:
            return kept
        row = self._db.execute(
            "SELECT action, frame, size, at FROM calls WHERE call_id = ? AND frame IS NOT NULL", (call_id,)).fetchone()
        if row is None:
            return None
        action, frame, size, at = row
        msg = from_map(unpack_map(frame[HEADER_BYTES:]))
        assert isinstance(msg, Result)
        return KeptResult(call_id, action, msg, size, at, bytes(frame))

    def put(self, kept: KeptResult) -> None:
        """Keep ``kept``; written at the next :meth:`flush`.

        A result kept again under the same id replaces the first; its first charge is then only
        dropped when it was not yet flushed (a node never keeps an id twice: a repeated id is
        answered from the store), so the charge can only be too high, which drops old results a
        little early, never too late.
        """
        old = self._kept.get(kept.call_id)
        if old is not None:
            self.nbytes -= old.size + self.entry_overhead
        self._kept[kept.call_id] = kept
        self.nbytes += kept.size + self.entry_overhead

    def begin(self, call_id: str, action: str, now: float) -> None:
        """Journal that ``call_id`` starts running ``action`` (written at the next :meth:`flush`)."""
        self._begun.append((call_id, action, now))

    def flush(self) -> None:
        """Commit every :meth:`begin` and :meth:`put` so far in one transaction, then drop the
        oldest results while over ``max_bytes``.

        Raises:
            sqlite3.Error: the write failed (disk full, file removed...); the rows stay queued.
        """
        if not self._begun and not self._kept:
            return
        db = self._db
        rows = [(k.call_id, k.action, k.frame if k.frame is not None else encode_frame(k.result), k.size, k.stored_at)
                for k in self._kept.values()]
        db.execute("BEGIN")
        try:
            if self._begun:
                db.executemany("INSERT OR REPLACE INTO calls VALUES (?, ?, NULL, 0, ?)", self._begun)
            if rows:
                db.executemany("INSERT OR REPLACE INTO calls VALUES (?, ?, ?, ?, ?)", rows)
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        self._begun.clear()
        self._kept.clear()
        if self.nbytes > self.max_bytes:
            self._evict()

    def expire(self, now: float) -> int:
        """Drop the results kept before ``now - max_age_s`` (s); return how many were dropped."""
        self.flush()
        too_old = now - self.max_age_s
        db = self._db
        count, total = db.execute(
            "SELECT COUNT(*), COALESCE(SUM(size), 0) FROM calls WHERE frame IS NOT NULL AND at < ?",
            (too_old,)).fetchone()
        if count:
            db.execute("DELETE FROM calls WHERE frame IS NOT NULL AND at < ?", (too_old,))
            self.nbytes -= total + count * self.entry_overhead
        return int(count)

    def _evict(self) -> None:
        """Drop the oldest results until the charge is at most 90 % of ``max_bytes`` (fewer, larger
        deletes), keeping the newest result even if it alone exceeds the cap."""
        if self.nbytes <= self.max_bytes:
            return
        target = self.max_bytes * 9 // 10
        db = self._db
        (count,) = db.execute("SELECT COUNT(*) FROM calls WHERE frame IS NOT NULL").fetchone()
        doomed: list[tuple[str]] = []
        freed = 0
        for cid, size in db.execute("SELECT call_id, size FROM calls WHERE frame IS NOT NULL ORDER BY at"):
            if self.nbytes - freed <= target or len(doomed) >= count - 1:
                break
            doomed.append((cid,))
            freed += size + self.entry_overhead
        db.execute("BEGIN")
        db.executemany("DELETE FROM calls WHERE call_id = ?", doomed)
        db.execute("COMMIT")
        self.nbytes -= freed

    def checkpoint(self) -> None:
        """Copy the write-ahead log into the database without blocking writers (``PASSIVE``), on a
        connection of its own: safe to call from another thread while the node writes."""
        if self._ckpt is None:
            self._ckpt = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
        self._ckpt.execute("PRAGMA wal_checkpoint(PASSIVE)")

    # ---- the rest

    def __len__(self) -> int:
        self.flush()
        return int(self._db.execute("SELECT COUNT(*) FROM calls WHERE frame IS NOT NULL").fetchone()[0])

    def __contains__(self, call_id: object) -> bool:
        return isinstance(call_id, str) and self.get(call_id) is not None

    def close(self) -> None:
        """Flush, close the file and release the directory (idempotent)."""
        if self._lock_fd < 0:
            return
        try:
            self.flush()
        finally:
            if self._ckpt is not None:
                self._ckpt.close()
            self._db.close()
            os.close(self._lock_fd)
            self._lock_fd = -1
