"""From ROS 2 statuses and responses to petrobot results (pure; paper section 4's success /
failure / error).

An action goal ends with a ``action_msgs/msg/GoalStatus`` status; petrobot's result follows it:

==================  =====================================  ===========================
ROS 2               petrobot status                        outcome (``int:<task>.X``)
==================  =====================================  ===========================
SUCCEEDED           success, or failure if ``success``     —
                    (a condition on the result) is false
ABORTED             failure (``aborted = "error"``: error)  ``aborted``
CANCELED            error (reason: who canceled)           ``canceled``
goal rejected       failure (``rejected = "error"``: error) ``rejected``
no server, server   error (reason says which)              —
gone, no answer
==================  =====================================  ===========================

A service's response is a success unless a ``success`` condition on it is false (failure). The
result's ``value`` keeps what the ROS 2 side said: for an action ``{"status": "SUCCEEDED",
"goal_id": "<32 hex digits>", "result": {...}}``, for a service the response's fields.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Any

from services.results import ActionResult, Status
from services.ros2.condition import Condition
from services.ros2.errors import ConditionError

__all__ = ["GoalStatus", "action_result", "rejected_result", "service_result"]


class GoalStatus(enum.IntEnum):
    """``action_msgs/msg/GoalStatus`` status values."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    @property
    def terminal(self) -> bool:
        """True for SUCCEEDED, CANCELED and ABORTED."""
        return self in (GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED)


def _status_name(status: int) -> str:
    try:
        return GoalStatus(status).name
    except ValueError:
        return str(status)


def _judged(success: Condition | None, fields: Mapping[str, Any], value: Any, what: str) -> ActionResult:
    if success is None:
        return ActionResult.success(value)
    try:
        met = success.evaluate(fields)
    except ConditionError as exc:
        return ActionResult.error(f"success condition cannot be evaluated on the {what}: {exc}", value=value)
    if met:
        return ActionResult.success(value)
    return ActionResult.failure(value, reason=f"success condition {success.text!r} is false on the {what}")


def action_result(status: int, result: Mapping[str, Any], *, goal_id: str, success: Condition | None = None,
                  aborted: Status = Status.FAILURE, cancel_reason: str | None = None) -> ActionResult:
    """The petrobot result of a goal that ended with ``status`` (see the module docstring).

    Args:
        status: the GoalStatus value the get_result response carried.
        result: the result message's fields.
        goal_id: the goal's UUID in hex.
        success: a condition on the result that success needs, or ``None``.
        aborted: the status ABORTED maps to (failure or error).
        cancel_reason: why petrobot canceled the goal (``"cancelled"``, ``"deadline"``,
            ``"caller_gone"``), if it did.
    """
    value = {"status": _status_name(status), "goal_id": goal_id, "result": dict(result)}
    if status == GoalStatus.SUCCEEDED:
        return _judged(success, result, value, "result")
    if status == GoalStatus.ABORTED:
        reason = "the action server aborted the goal"
        if aborted is Status.ERROR:
            return ActionResult.error(reason, outcome="aborted", value=value)
        return ActionResult.failure(value, outcome="aborted", reason=reason)
    if status == GoalStatus.CANCELED:
        return ActionResult.error(cancel_reason or "the goal was canceled on the ROS 2 side", outcome="canceled",
                                  value=value)
    return ActionResult.error(f"the goal ended with status {_status_name(status)}, which is not terminal",
                              value=value)


def rejected_result(goal_id: str, rejected: Status = Status.FAILURE) -> ActionResult:
    """The petrobot result of a goal the action server refused."""
    value = {"status": "REJECTED", "goal_id": goal_id, "result": None}
    reason = "the action server rejected the goal"
    if rejected is Status.ERROR:
        return ActionResult.error(reason, outcome="rejected", value=value)
    return ActionResult.failure(value, outcome="rejected", reason=reason)


def service_result(response: Mapping[str, Any], success: Condition | None = None) -> ActionResult:
    """The petrobot result of a service response (success unless ``success`` is false on it)."""
    return _judged(success, response, dict(response), "response")
