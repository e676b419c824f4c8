"""The coordinator's exceptions: net files, the engine, the journal and the analyses.

They derive from the project's root :class:`services.errors.PetrobotError`; the module docstring
of :mod:`services.errors` draws the whole tree. Errors a node can raise (protocol, actions,
services.toml) are defined there, in the base layer.
"""

from __future__ import annotations

from services.errors import PetrobotError

__all__ = [
    "AnalysisError",
    "EngineError",
    "JournalError",
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
    """The SQLite journal cannot be opened, or its contents are inconsistent."""


class AnalysisError(PetrobotError):
    """An analysis cannot be carried out (state limit reached, vanishing loop, bad input)."""
