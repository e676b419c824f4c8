"""ROS 2 quality of service (pure): the settings petrobot supports and rmw_zenoh's text form of them.

rmw_zenoh writes an entity's QoS in the last chunk of its liveliness token (``qos_to_keyexpr`` in
``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp``)::

    <reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>

each number being the ``rmw_qos_*`` enum value or count, left empty when it equals rmw_zenoh's own
default (``rmw_zenoh_cpp/src/detail/qos.cpp``: reliable, volatile, keep last, depth 42, infinite
deadline, lifespan and lease, automatic liveliness). So the default ROS 2 profile (depth 10) is
``::,10:,:,:,,``, the example of rmw_zenoh's design document. petrobot sets reliability,
durability, history and depth; deadline, lifespan and liveliness stay at their defaults (rmw_zenoh
does not implement the first two either).

Profiles of rclcpp/rcl_action that an action client matches: services use the default profile
(reliable, volatile, keep last 10); the feedback topic too; the status topic is transient local with
depth 1 (``rcl_action_qos_profile_status_default``), so a late subscriber still gets the last status.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from services.ros2.errors import Ros2ConfigError, Ros2WireError

__all__ = [
    "DEFAULT_QOS",
    "SERVICES_QOS",
    "STATUS_QOS",
    "Durability",
    "History",
    "Qos",
    "Reliability",
    "decode_qos",
    "encode_qos",
    "parse_qos",
]

RMW_ZENOH_DEFAULT_DEPTH = 42
"""The depth rmw_zenoh substitutes for depth 0, and the depth its QoS text leaves out."""


class Reliability(enum.IntEnum):
    """``rmw_qos_reliability_policy_e``."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    """Every sample delivered (TCP by default in Zenoh)."""
    BEST_EFFORT = 2
    """Samples may be dropped (Zenoh's drop congestion control)."""


class Durability(enum.IntEnum):
    """``rmw_qos_durability_policy_e``."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    """A late subscriber gets the last ``depth`` samples (a publication cache on the publisher)."""
    VOLATILE = 2
    """Only samples published while subscribed."""


class History(enum.IntEnum):
    """``rmw_qos_history_policy_e``."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True, slots=True)
class Qos:
    """The QoS of one publisher, subscription, service or client.

    Attributes:
        reliability: reliable or best effort.
        durability: volatile or transient local.
        history: keep last or keep all.
        depth: samples kept (keep last), at least 1.
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10


DEFAULT_QOS = Qos()
"""rclcpp's default profile: reliable, volatile, keep last 10 (topics, the action feedback topic)."""
SERVICES_QOS = Qos()
"""``rmw_qos_profile_services_default``: the same as the default profile."""
STATUS_QOS = Qos(durability=Durability.TRANSIENT_LOCAL, depth=1)
"""``rcl_action_qos_profile_status_default``: transient local, keep last 1."""

_ZENOH_DEFAULT = Qos(depth=RMW_ZENOH_DEFAULT_DEPTH)


def encode_qos(qos: Qos) -> str:
    """rmw_zenoh's text form of ``qos`` (see the module docstring): ``Qos()`` → ``"::,10:,:,:,,"``."""
    def part(value: int, default: int) -> str:
        return "" if value == default else str(int(value))

    return (f"{part(qos.reliability, _ZENOH_DEFAULT.reliability)}:"
            f"{part(qos.durability, _ZENOH_DEFAULT.durability)}:"
            f"{part(qos.history, _ZENOH_DEFAULT.history)},{part(qos.depth, _ZENOH_DEFAULT.depth)}:"
            ",:,:,,")


def decode_qos(text: str) -> Qos:
    """Read rmw_zenoh's text form of a QoS (from a liveliness token of the other side).

    Deadline, lifespan and liveliness are checked for form and otherwise ignored.

    Raises:
        Ros2WireError: not six ``:``-separated parts of the documented shape, or an unknown value.
    """
    parts = text.split(":")
    if len(parts) != 6:
        raise Ros2WireError(f"QoS {text!r}: expected 6 ':'-separated parts, got {len(parts)}")
    history, _, depth = parts[2].partition(",")
    shapes = [(parts[3], 2), (parts[4], 2), (parts[5], 3)]
    if "," not in parts[2] or any(len(p.split(",")) != n for p, n in shapes):
        raise Ros2WireError(f"QoS {text!r}: malformed history, deadline, lifespan or liveliness part")
    try:
        numbers = [n for chunk, _ in shapes for n in chunk.split(",")] + [depth]
        if not all(n.isdigit() for n in numbers if n):
            raise ValueError("a count that is not a non-negative integer")
        return Qos(
            reliability=Reliability(int(parts[0])) if parts[0] else _ZENOH_DEFAULT.reliability,
            durability=Durability(int(parts[1])) if parts[1] else _ZENOH_DEFAULT.durability,
            history=History(int(history)) if history else _ZENOH_DEFAULT.history,
            depth=int(depth) if depth else _ZENOH_DEFAULT.depth,
        )
    except ValueError as exc:
        raise Ros2WireError(f"QoS {text!r}: {exc}") from None


_NAMES: dict[str, dict[str, enum.IntEnum]] = {
    "reliability": {"reliable": Reliability.RELIABLE, "best_effort": Reliability.BEST_EFFORT},
    "durability": {"volatile": Durability.VOLATILE, "transient_local": Durability.TRANSIENT_LOCAL},
    "history": {"keep_last": History.KEEP_LAST, "keep_all": History.KEEP_ALL},
}


def parse_qos(table: Any, base: Qos = DEFAULT_QOS, where: str = "qos") -> Qos:
    """A :class:`Qos` from a services.toml table such as ``{ reliability = "best_effort", depth = 1 }``.

    Args:
        table: the table; keys ``reliability`` (``reliable``, ``best_effort``), ``durability``
            (``volatile``, ``transient_local``), ``history`` (``keep_last``, ``keep_all``), ``depth``
            (1..10000); missing keys keep ``base``'s values.
        base: the profile the table modifies.
        where: the table's place, for error messages.

    Raises:
        Ros2ConfigError: not a table, an unknown key or value, a bad depth.
    """
    if not isinstance(table, Mapping):
        raise Ros2ConfigError(f"{where} must be a table")
    extra = sorted(set(table) - {*_NAMES, "depth"})
    if extra:
        raise Ros2ConfigError(f"{where}: unknown key(s) {', '.join(extra)} (known: depth, {', '.join(_NAMES)})")
    values: dict[str, Any] = {}
    for key, names in _NAMES.items():
        if key in table:
            value = table[key]
            if value not in names:
                raise Ros2ConfigError(f"{where}: {key} must be one of {', '.join(names)}, got {value!r}")
            values[key] = names[value]
    if "depth" in table:
        depth = table["depth"]
        if type(depth) is not int or not 1 <= depth <= 10000:
            raise Ros2ConfigError(f"{where}: depth must be an integer in 1..10000, got {depth!r}")
        values["depth"] = depth
    return Qos(**{"reliability": base.reliability, "durability": base.durability, "history": base.history,
                  "depth": base.depth, **values})
