"""The journal: an SQLite log of every run of a task net, and the one owner of its schema.

* :mod:`~coordinator.journal.schema` — the tables (the only DDL of the project);
* :mod:`~coordinator.journal.records` — the typed records the journal gives back;
* :mod:`~coordinator.journal.reader` — :class:`JournalReader`, every query (read-only with
  :meth:`JournalReader.open`);
* :mod:`~coordinator.journal.writer` — :class:`Journal`, the write-ahead log the runtime writes.
"""

from coordinator.journal.reader import JournalReader, Record, read_results
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
from coordinator.journal.writer import Journal

__all__ = [
    "FeedbackRow",
    "FiringRow",
    "Journal",
    "JournalReader",
    "LearnerState",
    "OperatorRow",
    "ReconciliationRow",
    "Record",
    "Recovered",
    "ResultRow",
    "RunRow",
    "RunStats",
    "StartRow",
    "read_results",
]
