"""Exceptions raised by petrobot.

Every error the project raises derives from :class:`PetrobotError`, so a caller
can catch the whole family at once::

    PetrobotError
    ├── NetError                  a net is malformed (file, line and problem named)
    │   └── NetFileError          a net file cannot be read or parsed
    ├── NotEnabledError           fire() on a transition that is not enabled
    ├── EngineError               an engine command is illegal in the current state
    ├── ProtocolError             the coordinator↔node protocol was broken
    │   ├── LocalProtocolError    we did something illegal (bug on our side)
    │   └── RemoteProtocolError   the peer sent something illegal
    │       └── AuthenticationError   the handshake failed (wrong shared key)
    ├── ActionError               a primitive action could not be called or failed
    ├── LocationError             services.toml is malformed or names an unknown action/node
    ├── JournalError              the SQLite journal is unusable or inconsistent
    └── AnalysisError             an analysis cannot be carried out (state limit, vanishing loop...)
"""

from __future__ import annotations

__all__ = [
    "PetrobotError",
    "NetError",
    "NetFileError",
    "NotEnabledError",
    "EngineError",
    "ProtocolError",
    "LocalProtocolError",
    "RemoteProtocolError",
    "AuthenticationError",
    "ActionError",
    "LocationError",
    "JournalError",
    "AnalysisError",
]


class PetrobotError(Exception):
    """Root of every exception petrobot raises."""


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


class ProtocolError(PetrobotError):
    """The coordinator↔node protocol (docs/protocol.md) was violated."""


class LocalProtocolError(ProtocolError):
    """This endpoint tried to do something the protocol forbids."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol forbids (bad frame, oversize, bad state)."""


class AuthenticationError(RemoteProtocolError):
    """The HMAC handshake failed: the peer does not hold the shared key."""


class ActionError(PetrobotError):
    """A primitive action could not be called, or failed in a way that is not a status."""


class LocationError(PetrobotError):
    """services.toml is malformed, or names an action or node that does not exist."""


class JournalError(PetrobotError):
    """The SQLite journal cannot be opened, or its contents are inconsistent."""


class AnalysisError(PetrobotError):
    """An analysis cannot be carried out (state limit reached, vanishing loop, bad input)."""
