"""Can a net run with a location file? Placement of actions and events (paper section 5).

:func:`check_net` checks a net against ``services.toml``: every primitive action is placed on a
node, every external event has a publisher.
"""

from __future__ import annotations

from typing import Protocol

from coordinator.net import PetriNet
from services.errors import LocationError

__all__ = ["Placement", "check_net"]


class Placement(Protocol):
    """What :func:`check_net` needs of a location (a :class:`services.location.Location`)."""

    def node_of(self, action: str) -> str: ...

    def publisher_of(self, topic: str) -> str: ...


def check_net(net: PetriNet, location: Placement) -> list[tuple[str, str]]:
    """Check that a net can run with a location file (paper section 5).

    Every primitive action of every primitive task must be placed on a node, and every ``ext:``
    event linked to a transition must have a publishing node.

    Args:
        net: the task net.
        location: a :class:`services.location.Location` (anything with ``node_of(action)`` and
            ``publisher_of(topic)`` raising :class:`LocationError`).

    Returns:
        ``(element, problem)`` pairs, empty when the net can run; ``element`` is a task name or a
        transition id.
    """
    problems: list[tuple[str, str]] = []
    for task in net.tasks.values():
        for action in task.actions:
            try:
                location.node_of(action.name)
            except LocationError:
                problem = (f"primitive action {action.name!r} of task {task.name!r} is not placed on "
                           f"any node (add [actions.{action.name}] to services.toml)")
                problems.append((task.name, problem))
    reported: set[str] = set()
    for t in net.transitions:
        for event in t.external_events:
            topic = event.removeprefix("ext:")
            try:
                location.publisher_of(topic)
            except LocationError:
                if topic not in reported:
                    reported.add(topic)
                    problem = (f"external event {event!r} of transition {t.id!r} has no publisher "
                               f"(add [events.{topic}] to services.toml)")
                    problems.append((t.id, problem))
    return problems
