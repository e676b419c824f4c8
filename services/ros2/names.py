"""ROS 2 names (pure): validation, namespaces, mangling, DDS type names, rcl_action's composed names.

Sources:

* ROS 2 topic and service names (design.ros2.org, "Topic and Service name mapping"): a name is
  tokens of letters, digits and ``_`` separated by ``/``, not starting with a digit, with no empty
  token; a name starting with ``/`` is absolute, otherwise it is relative to the node's namespace.
  Private names (``~``) and substitutions (``{node}``) are not supported here.
* rmw_zenoh ``docs/design.md`` ("Graph Cache"): a *mangled* name has each ``/`` replaced by ``%``;
  an empty namespace or enclave is written ``%``.
* rosidl: the DDS type name of ``pkg/msg/Name`` is ``pkg::msg::dds_::Name_`` (also for ``srv`` and
  ``action``), the name rmw_zenoh puts in key expressions.
* ``ros2/rcl`` ``rcl_action/src/rcl_action/names.c``: an action ``A`` is the services
  ``A/_action/send_goal``, ``A/_action/cancel_goal``, ``A/_action/get_result`` and the topics
  ``A/_action/feedback`` and ``A/_action/status``; rosidl gives their types
  ``pkg/action/Name_SendGoal``, ``action_msgs/srv/CancelGoal``, ``pkg/action/Name_GetResult``,
  ``pkg/action/Name_FeedbackMessage`` and ``action_msgs/msg/GoalStatusArray``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from services.ros2.errors import Ros2ConfigError, Ros2TypeError

__all__ = [
    "ActionNames",
    "ActionTypeNames",
    "action_names",
    "action_type_names",
    "check_name",
    "dds_type_name",
    "demangle",
    "mangle",
    "qualify",
    "split_type",
]

_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_PACKAGE = re.compile(r"[a-z][a-z0-9_]*")
_TYPE = re.compile(r"[A-Z][A-Za-z0-9_]*")
_MAX_NAME = 255
_KINDS = ("msg", "srv", "action")


def check_name(name: str, what: str = "name", *, relative: bool = True) -> str:
    """Check a ROS 2 topic, service, action or namespace name and return it.

    Args:
        name: the name (``/fibonacci``, ``robot1/cmd_vel``; ``/`` alone is the root namespace).
        what: what the name is, for the error message.
        relative: whether a name without a leading ``/`` is accepted.

    Raises:
        Ros2ConfigError: an empty token, a token that starts with a digit or holds a character
            other than letters, digits and ``_``, ``~`` or ``{}``, a trailing ``/``, or a relative name
            where an absolute one is needed.
    """
    if not isinstance(name, str) or not name:
        raise Ros2ConfigError(f"{what} must be a non-empty string")
    if len(name) > _MAX_NAME:
        raise Ros2ConfigError(f"{what} {name!r} is longer than {_MAX_NAME} characters")
    if name == "/":
        return name
    if not relative and not name.startswith("/"):
        raise Ros2ConfigError(f"{what} {name!r} must be absolute (start with '/')")
    body = name[1:] if name.startswith("/") else name
    for token in body.split("/"):
        if not _TOKEN.fullmatch(token):
            raise Ros2ConfigError(
                f"{what} {name!r} is not a ROS 2 name (tokens of letters, digits and '_', not starting with a "
                f"digit, separated by single '/'; no trailing '/', no '~' or substitutions)")
    return name


def qualify(name: str, namespace: str = "/") -> str:
    """The fully qualified name of ``name`` in ``namespace``.

    ``qualify("fibonacci", "/robot1") == "/robot1/fibonacci"``; an absolute name is unchanged.

    Raises:
        Ros2ConfigError: either is not a valid name (:func:`check_name`).
    """
    check_name(name)
    check_name(namespace, "namespace", relative=False)
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def mangle(name: str) -> str:
    """rmw_zenoh's mangled form of a name: each ``/`` replaced by ``%``; empty becomes ``%``."""
    return name.replace("/", "%") if name else "%"


def demangle(name: str) -> str:
    """The inverse of :func:`mangle` (``%`` back to ``/``)."""
    return name.replace("%", "/")


def split_type(ros_type: str) -> tuple[str, str, str]:
    """Split ``pkg/kind/Name`` into ``(pkg, kind, Name)``; ``pkg/Name`` is read as ``pkg/msg/Name``.

    Raises:
        Ros2TypeError: not of that form (package in lower case, kind ``msg``, ``srv`` or ``action``,
            name starting with a capital letter).
    """
    parts = ros_type.split("/") if isinstance(ros_type, str) else []
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if (len(parts) != 3 or not _PACKAGE.fullmatch(parts[0]) or parts[1] not in _KINDS
            or not _TYPE.fullmatch(parts[2])):
        raise Ros2TypeError(f"{ros_type!r} is not a ROS 2 interface type (expected package/msg|srv|action/Name, "
                            f"e.g. std_msgs/msg/Bool)")
    return parts[0], parts[1], parts[2]


def dds_type_name(ros_type: str) -> str:
    """The DDS type name rmw_zenoh uses in keys: ``std_msgs/msg/String`` → ``std_msgs::msg::dds_::String_``.

    Raises:
        Ros2TypeError: ``ros_type`` is malformed (:func:`split_type`).
    """
    pkg, kind, name = split_type(ros_type)
    return f"{pkg}::{kind}::dds_::{name}_"


@dataclass(frozen=True, slots=True)
class ActionNames:
    """The services and topics of one action (rcl_action ``names.c``), fully qualified.

    Attributes:
        send_goal: ``<action>/_action/send_goal`` (service).
        cancel_goal: ``<action>/_action/cancel_goal`` (service).
        get_result: ``<action>/_action/get_result`` (service).
        feedback: ``<action>/_action/feedback`` (topic).
        status: ``<action>/_action/status`` (topic, transient local).
    """

    send_goal: str
    cancel_goal: str
    get_result: str
    feedback: str
    status: str


def action_names(action: str) -> ActionNames:
    """rcl_action's composed names for the action ``action`` (a fully qualified name).

    Raises:
        Ros2ConfigError: ``action`` is not an absolute ROS 2 name.
    """
    check_name(action, "action name", relative=False)
    base = action.rstrip("/")
    return ActionNames(
        send_goal=f"{base}/_action/send_goal", cancel_goal=f"{base}/_action/cancel_goal",
        get_result=f"{base}/_action/get_result", feedback=f"{base}/_action/feedback",
        status=f"{base}/_action/status",
    )


@dataclass(frozen=True, slots=True)
class ActionTypeNames:
    """The interface types that make up one action type (rosidl).

    Attributes:
        goal, result, feedback: ``pkg/action/Name_Goal``, ``_Result``, ``_Feedback`` (messages).
        send_goal: ``pkg/action/Name_SendGoal`` (service: goal id and goal → accepted and stamp).
        get_result: ``pkg/action/Name_GetResult`` (service: goal id → status and result).
        feedback_message: ``pkg/action/Name_FeedbackMessage`` (goal id and feedback).
        cancel_goal: ``action_msgs/srv/CancelGoal``.
        status: ``action_msgs/msg/GoalStatusArray``.
    """

    goal: str
    result: str
    feedback: str
    send_goal: str
    get_result: str
    feedback_message: str
    cancel_goal: str = "action_msgs/srv/CancelGoal"
    status: str = "action_msgs/msg/GoalStatusArray"


def action_type_names(action_type: str) -> ActionTypeNames:
    """The composed type names of ``pkg/action/Name``.

    Raises:
        Ros2TypeError: ``action_type`` is not of the form ``pkg/action/Name``.
    """
    pkg, kind, name = split_type(action_type)
    if kind != "action":
        raise Ros2TypeError(f"{action_type!r} is not an action type (expected package/action/Name)")
    base = f"{pkg}/action/{name}"
    return ActionTypeNames(
        goal=f"{base}_Goal", result=f"{base}_Result", feedback=f"{base}_Feedback",
        send_goal=f"{base}_SendGoal", get_result=f"{base}_GetResult", feedback_message=f"{base}_FeedbackMessage",
    )
