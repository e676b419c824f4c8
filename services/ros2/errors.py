"""Exceptions of the ROS 2 reach (docs/ros2.md), all under :class:`services.errors.PetrobotError`::

    ActionError                   (services.errors)
    └── Ros2Error                 something about a ROS 2 interface went wrong
        ├── Ros2TypeError         an interface type is unknown or its definition is malformed
        ├── Ros2FieldError        a value does not fit its message type (names the field)
        ├── Ros2WireError         bytes from the ROS 2 side are malformed (key, token, attachment, CDR)
        └── ConditionError        a condition on message fields is malformed or cannot be evaluated
    LocationError                 (services.errors)
    └── Ros2ConfigError           a ``ros2`` table of services.toml is malformed

A ROS 2 call that fails at run time (no server, server gone, goal rejected) is not an exception: the
primitive action ends with an ``error`` or ``failure`` result that says why.
"""

from __future__ import annotations

from services.errors import ActionError, LocationError

__all__ = ["ConditionError", "Ros2ConfigError", "Ros2Error", "Ros2FieldError", "Ros2TypeError", "Ros2WireError"]


class Ros2Error(ActionError):
    """Root of the ROS 2 reach's errors."""


class Ros2TypeError(Ros2Error):
    """An interface type is unknown, or its ``.msg``/``.srv``/``.action`` definition is malformed."""


class Ros2FieldError(Ros2Error):
    """A value does not fit its message type.

    Attributes:
        path: the field, dotted from the message (``goal.pose.position.x``, ``sequence[3]``).
        problem: what is wrong with it.
    """

    def __init__(self, path: str, problem: str) -> None:
        self.path = path
        self.problem = problem
        super().__init__(f"field {path!r}: {problem}" if path else problem)


class Ros2WireError(Ros2Error):
    """Bytes received from the ROS 2 side are malformed (a key expression, a liveliness token, an
    attachment or a CDR payload)."""


class ConditionError(Ros2Error):
    """A condition on message fields is malformed, names an unknown field, or cannot be evaluated.

    Attributes:
        message: what is wrong.
        column: 1-based column of the problem in ``text`` (0 when it concerns the whole text).
        text: the condition.
    """

    def __init__(self, message: str, column: int, text: str) -> None:
        self.message = message
        self.column = column
        self.text = text
        where = f" at column {column}" if column else ""
        super().__init__(f"condition {text!r}{where}: {message}")


class Ros2ConfigError(LocationError):
    """A ``ros2`` table of services.toml (``[ros2]``, ``[nodes.N.ros2]``, an action's or an event's
    ``ros2 = {...}``) is malformed; :mod:`services.location` adds the file and line."""
