"""Checks of the ROS 2 side of services.toml and of a net's parameters, ahead of a run (``petrobot check``).

A node checks its ROS 2 actions and events against the interface types when it starts
(:mod:`services.ros2.driver`); these functions let ``petrobot check`` say the same before anything
starts, and add what only the net knows: the parameters each primitive task gives a ROS 2 action
must fit its goal, request or message type (a missing or mistyped field is named). They read the
definition files (the shipped ones and each node's ``[ros2] interfaces``); they connect nowhere.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from services.location import Location
from services.ros2.config import ActionKind, check_action_types, check_event_types
from services.ros2.errors import Ros2ConfigError, Ros2Error, Ros2FieldError
from services.ros2.names import action_type_names
from services.ros2.typestore import DEFINITIONS, TypeStore, load_definitions

__all__ = ["location_problems", "params_problem"]

_STORES: dict[tuple[str, ...], TypeStore] = {}


def _store(location: Location, node: str) -> TypeStore:
    """The interface types of ``node`` (built once per set of definition directories)."""
    dirs = location.nodes[node].ros2.interfaces
    if dirs not in _STORES:
        _STORES[dirs] = TypeStore(load_definitions([DEFINITIONS, *dirs]))
    return _STORES[dirs]


def location_problems(location: Location, actions: Collection[str] | None = None) -> list[tuple[tuple[str, ...], str]]:
    """The ROS 2 actions (of ``actions``, or all) and events of ``location`` that name an unknown
    type or field, or whose definition directories do not load.

    Returns:
        ``(key path of the ros2 table, problem)`` pairs, e.g. ``(("actions", "fib", "ros2"), "...")``.
    """
    out: list[tuple[tuple[str, ...], str]] = []
    nodes = set()
    for name, placement in location.actions.items():
        if placement.ros2 is None or (actions is not None and name not in actions):
            continue
        nodes.add(placement.node)
        try:
            check_action_types(placement.ros2, _store(location, placement.node), "ros2")
        except (Ros2Error, Ros2ConfigError) as exc:
            out.append((("actions", name, "ros2"), str(exc)))
    for topic, spec in location.ros2_events.items():
        node = location.events[topic]
        if actions is not None and node not in nodes:
            continue
        try:
            check_event_types(spec, _store(location, node), "ros2")
        except (Ros2Error, Ros2ConfigError) as exc:
            out.append((("events", topic, "ros2"), str(exc)))
    return out


def params_problem(location: Location, action: str, params: Mapping[str, Any]) -> str | None:
    """Why ``params`` (a task's parameters for ROS 2 action ``action``, over services.toml's) do not
    fit its goal, request or message type, or ``None`` (also for an action that is not ROS 2)."""
    placement = location.actions.get(action)
    if placement is None or placement.ros2 is None:
        return None
    spec = placement.ros2
    merged = {**placement.params, **params}
    try:
        store = _store(location, placement.node)
        if spec.kind == ActionKind.ACTION:
            msgtype, what = action_type_names(spec.type).goal, "goal"
        elif spec.kind == ActionKind.SERVICE:
            msgtype, what = store.service(spec.type).request, "request"
        elif spec.kind == ActionKind.PUBLISH:
            msgtype, what = spec.type, "message"
        else:
            return None
        store.check(msgtype, merged, fill=spec.fill, what=what)
    except Ros2FieldError as exc:
        return f"the parameters of ROS 2 action {action!r} do not fit {msgtype}: {what} {exc}"
    except Ros2Error as exc:
        return f"ROS 2 action {action!r}: {exc}"
    return None
