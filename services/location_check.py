"""Checks of a location file that need more than its text: do the impls import, do the hosts resolve?

:func:`services.location.parse_location` checks what the text of ``services.toml`` can tell (types,
names, known nodes, the syntax of hosts and ``impl`` strings). A node would still fail at start on
an ``impl`` whose module does not import or names neither a primitive action nor an async function,
on a driver that is no :class:`~services.action.Driver`, on a host name that does not resolve, or on
a ROS 2 action or event whose type or fields are unknown (:mod:`services.ros2.preflight`).
:func:`check_location_file` finds those ahead of time, for ``petrobot check`` (paper §5: the location
file says where each primitive action runs).

It imports every ``impl`` module into the calling process (as a node would) and looks host names up
with the system resolver; it constructs nothing and connects nowhere.
"""

from __future__ import annotations

import importlib
import inspect
import ipaddress
import os
import socket
from collections.abc import Collection
from typing import Any

from services.errors import LocationError
from services.location import MEMORY_ACTIONS, Location, load_location
from services.textfile import TextProblem, decode_utf8, read_capped
from services.tomllines import TomlLines

__all__ = ["action_impl_problem", "check_location", "check_location_file", "driver_impl_problem", "host_problem"]


def _brief(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 200 else text[:197] + "..."


def _import(impl: str) -> tuple[Any, str | None]:
    """The object named by ``"module:attr"``, or ``(None, why not)``."""
    module_name, _, attr = impl.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
    except (Exception, SystemExit) as exc:  # noqa: BLE001 (any failure of a module's top level is a problem to report)
        return None, f"module {module_name!r} cannot be imported ({_brief(exc)})"
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            return None, f"module {module_name!r} has no attribute {attr!r}"
    return obj, None


def action_impl_problem(impl: str) -> str | None:
    """Why ``impl`` cannot serve as a primitive action, or ``None``.

    An action's ``impl`` names a :class:`~services.action.PrimitiveAction` subclass or instance,
    or an ``async def f(params, ctx)`` (:func:`services.action.make_action`).
    """
    from services.action import PrimitiveAction

    obj, problem = _import(impl)
    if problem is not None:
        return problem
    if isinstance(obj, type) and issubclass(obj, PrimitiveAction):
        return None
    if isinstance(obj, PrimitiveAction) or inspect.iscoroutinefunction(obj):
        return None
    kind = "a class" if isinstance(obj, type) else f"a {type(obj).__name__}"
    return f"{impl!r} is {kind}, neither a PrimitiveAction (subclass or instance) nor an async function"


def driver_impl_problem(impl: str) -> str | None:
    """Why ``impl`` cannot serve as a driver (a :class:`~services.action.Driver` subclass), or ``None``."""
    from services.action import Driver

    obj, problem = _import(impl)
    if problem is not None:
        return problem
    if isinstance(obj, type) and issubclass(obj, Driver):
        return None
    kind = "a class that is not a Driver" if isinstance(obj, type) else f"a {type(obj).__name__}"
    return f"{impl!r} is {kind}; a driver's impl names a Driver subclass"


def host_problem(host: str, port: int) -> str | None:
    """Why ``host`` cannot be connected to (it does not resolve), or ``None``. IP addresses pass."""
    try:
        ipaddress.ip_address(host)
        return None
    except ValueError:
        pass
    try:
        socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        return f"host {host!r} does not resolve ({reason})"
    return None


def check_location(location: Location, lines: TomlLines,
                   actions: Collection[str] | None = None) -> list[LocationError]:
    """Check that every impl of ``location`` imports and is of the right kind, and every host resolves.

    With ``actions``, only the impls of those actions and of the drivers on the nodes that host them
    are imported (``petrobot check NET`` checks what the net needs, without importing the device
    stacks of every other testbed); hosts are all checked.

    Args:
        location: a parsed location file.
        lines: the lines of its text (:meth:`TomlLines.scan`), for the messages.
        actions: names of the actions to check, or ``None`` for all of them.

    Returns:
        Every problem, sorted by line, each a :class:`LocationError` reading ``FILE:LINE: problem``.
    """
    found: list[tuple[int, str]] = []

    def report(problem: str | None, where: str, *key: str) -> None:
        if problem is not None:
            line = lines.line(*key)
            found.append((line or 0, f"{location.path}:{line}: {where}: {problem}" if line
                          else f"{location.path}: {where}: {problem}"))

    for name, node in location.nodes.items():
        report(host_problem(node.host, node.port), f"[nodes.{name}]", "nodes", name, "host")
    wanted = set(location.actions) if actions is None else set(actions) & set(location.actions)
    nodes = {location.actions[name].node for name in wanted}
    for name, action in location.actions.items():
        if name not in MEMORY_ACTIONS and name in wanted:
            report(action_impl_problem(action.impl), f"[actions.{name}]", "actions", name, "impl")
    for name, driver in location.drivers.items():
        if actions is None or driver.node in nodes:
            report(driver_impl_problem(driver.impl), f"[drivers.{name}]", "drivers", name, "impl")
    if any(a.ros2 is not None for a in location.actions.values()) or location.ros2_events:
        from services.ros2.preflight import location_problems

        for key, problem in location_problems(location, None if actions is None else wanted):
            report(problem, f"[{key[0]}.{key[1]}]", *key)
    return [LocationError(message) for _, message in sorted(found, key=lambda item: item[0])]


def check_location_file(path: str | os.PathLike[str],
                        actions: Collection[str] | None = None) -> tuple[Location | None, list[LocationError]]:
    """Load a location file and run :func:`check_location` on it (for ``actions``, or all).

    Returns:
        ``(location, problems)``: ``(None, [the parse error])`` when the file does not load, else
        the location and the problems of :func:`check_location` (empty when it can run).
    """
    try:
        location = load_location(path)
        lines = TomlLines.scan(decode_utf8(read_capped(path, what="location file")))
    except LocationError as exc:
        return None, [exc]
    except TextProblem as exc:  # the file changed between the two reads
        return None, [LocationError(f"{os.fspath(path)}: {exc.problem}")]
    return location, check_location(location, lines, actions)
