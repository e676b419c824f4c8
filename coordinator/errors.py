"""The coordinator's exceptions: net files, the engine, the journal and the analyses.

They derive from the project's root :class:`services.errors.PetrobotError`; the module docstring
of :mod:`services.errors` draws the whole tree. Errors a node can raise (protocol, actions,
services.toml) are defined there, in the base layer.
"""

from __future__ import annotations

from services.errors import PetrobotError

__all__ = [
    "AnalysisError",
    "DamagedJournal",
    "EngineError",
    "JournalError",
    "JournalTooNew",
    "NetError",
    "NetFileError",
    "NotEnabledError",
]


class NetError(PetrobotError):
    """A Petri net is malformed.

    Attributes:
        path: file the net came from, or ``None`` for a net built in code.
        line: 1-based line of the offending element, or ``None`` if unknown.
        problem: the problem in words.
    """

    def __init__(self, problem: str, *, path: str | None = None, line: int | None = None) -> None:
        self.problem = problem
        self.path = path
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(f"{where}{problem}")


class NetFileError(NetError):
    """A net file cannot be read or parsed (syntax error, unknown format)."""


class NotEnabledError(PetrobotError):
    """A transition was asked to fire in a marking that does not enable it."""


class EngineError(PetrobotError):
    """An engine input is illegal in the engine's current state (e.g. unknown instance)."""


class JournalError(PetrobotError):
    """The SQLite journal cannot be opened, or its contents are inconsistent.

    Attributes:
        exit_status: the status a command exits with on it (1; 2 for a damaged journal or one of
            a newer schema).
    """

    exit_status = 1


class DamagedJournal(JournalError):
    """The journal is damaged: a record that cannot be what petrobot wrote (a field of the wrong type,
    JSON that does not parse, a status that does not exist), records that disagree with each other,
    a table missing, SQLite's own integrity check failing, or a schema newer than this petrobot's.
    Commands that meet one exit with status 2.

    Attributes:
        table: the table of the damaged record, or ``None`` when the damage is not one record's.
        row: the record's ``entry`` (``rowid`` for ``run`` and ``learner_state``), or ``None``.
        field: the damaged column, or ``None``.
        problem: what is wrong, in words.
    """

    exit_status = 2

    def __init__(self, path: str, problem: str, *, table: str | None = None, row: object = None,
                 field: str | None = None) -> None:
        where = "".join((f"table {table}" if table else "", f", row {row}" if row is not None else "",
                         f", field {field}" if field else ""))
        super().__init__(f"{path}: {where + ': ' if where else ''}{problem}")
        self.path = path
        self.table = table
        self.row = row
        self.field = field
        self.problem = problem


class JournalTooNew(JournalError):
    """The journal was written by a newer petrobot, with a schema this one does not know; every
    command refuses it (exit status 2), naming the schema it needs.

    Attributes:
        version: the journal's schema version.
        supported: the newest schema this petrobot reads and writes.
    """

    exit_status = 2

    def __init__(self, path: str, version: int, supported: int) -> None:
        super().__init__(f"{path}: journal schema {version} was written by a newer petrobot; this one reads "
                         f"schemas up to {supported}: read it with a petrobot whose journal schema is {version} "
                         "or later")
        self.version = version
        self.supported = supported


class AnalysisError(PetrobotError):
    """An analysis cannot be carried out (state limit reached, vanishing loop, bad input)."""
