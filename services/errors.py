"""Exceptions raised by petrobot: the root of the family and the errors a node can raise.

Every error the project raises derives from :class:`PetrobotError`, so a caller can catch the whole
family at once; those that callers also catch as a standard error keep it as a second base
(``ValueError``). The errors a node process can meet (protocol, actions, services.toml, keys) live
here, in the base layer every package may import; the coordinator's own errors (net files, engine,
journal, analyses) derive from the same root in :mod:`coordinator.errors`::

    PetrobotError                 (services.errors)
    ├── ProtocolError             the coordinator↔node protocol was broken
    │   ├── LocalProtocolError    we did something illegal (bug on our side)
    │   └── RemoteProtocolError   the peer sent something illegal
    │       ├── AuthenticationError   the handshake failed (wrong shared key)
    │       └── MalformedSetPoint, ValueError  a received set point (or odometry message) is malformed
    ├── ActionError               a primitive action could not be called or failed
    ├── LocationError             services.toml is malformed or names an unknown action/node
    ├── TextProblem               (services.textfile) an input text is unusable (file, line, problem)
    ├── FrameError, ValueError    (services.devices.cia402) a CAN frame or socketcand message is malformed
    ├── UnreachableError, ValueError  (services.catching.robot.puma560) a pose the PUMA cannot reach
    ├── CourseError, ValueError   (sim.mobile.course) a mobile-robot course is malformed
    ├── ExprError, ValueError     (coordinator.expr) a marking expression is malformed
    ├── FileRefused               (coordinator.web.files) a path the web console will not read or write
    ├── ProtocolViolation         (coordinator.web.protocol) a console message breaks its protocol
    ├── NetError                  (coordinator.errors) a net is malformed (file, line, problem)
    │   └── NetFileError          a net file cannot be read or parsed
    ├── NotEnabledError           (coordinator.errors) fire() on a transition that is not enabled
    ├── EngineError               (coordinator.errors) an engine command is illegal now
    ├── JournalError              (coordinator.errors) the SQLite journal is unusable
    │   ├── DamagedJournal        a record, a table or the file is damaged (commands exit 2)
    │   └── JournalTooNew         written by a newer petrobot (commands exit 2)
    └── AnalysisError             (coordinator.errors) an analysis cannot be carried out
"""

from __future__ import annotations

__all__ = [
    "ActionError",
    "AuthenticationError",
    "LocalProtocolError",
    "LocationError",
    "MalformedSetPoint",
    "PetrobotError",
    "ProtocolError",
    "RemoteProtocolError",
]


class PetrobotError(Exception):
    """Root of every exception petrobot raises."""


class ProtocolError(PetrobotError):
    """The coordinator↔node protocol (docs/protocol.md) was violated."""


class LocalProtocolError(ProtocolError):
    """This endpoint tried to do something the protocol forbids."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol forbids (bad frame, oversize, bad state)."""


class AuthenticationError(RemoteProtocolError):
    """The HMAC handshake failed: the peer does not hold the shared key."""


class MalformedSetPoint(RemoteProtocolError, ValueError):
    """A received set point (or a message of its stream: the mobile robot's odometry) is not a map
    of the expected, finite, bounded fields; the message names the first wrong field. Both
    testbeds' set-point streams raise it (:mod:`services.catching.setpoints`,
    :mod:`services.mobile.setpoints`)."""


class ActionError(PetrobotError):
    """A primitive action could not be called, or failed in a way that is not a status."""


class LocationError(PetrobotError):
    """services.toml is malformed, or names an action or node that does not exist."""
