"""The TOML net-file format: its version, sections and keys (docs/netfile.md).

The loader (:mod:`~coordinator.netfile.loader`) accepts these keys and refuses others with a
suggestion; the writer (:mod:`~coordinator.netfile.writer`) writes the version.
"""

from __future__ import annotations

__all__ = [
    "ACTION_KEYS",
    "ARC_KEYS",
    "FORMAT_VERSION",
    "NET_KEYS",
    "OPERATOR_KEYS",
    "PLACE_KEYS",
    "TASK_KEYS",
    "TOP_KEYS",
    "TRANSITION_KEYS",
]

#: Version written in ``[net] format``; files of a higher version are refused.
FORMAT_VERSION = 1

#: Top-level sections.
TOP_KEYS = ("net", "place", "task", "transition", "arc", "operator")
#: Keys of ``[net]``.
NET_KEYS = ("name", "description", "format", "home")
#: Keys of ``[operator]``: what an operator may force from a console.
OPERATOR_KEYS = ("inject", "force")
#: Keys of a ``[[place]]``.
PLACE_KEYS = ("id", "kind", "tokens", "label", "capacity", "task", "pos")
#: Keys of a ``[task.<name>]``.
TASK_KEYS = ("actions", "deadline_s", "learner", "mean_time_s", "reliability", "params")
#: Keys of an action table in ``actions``.
ACTION_KEYS = ("name", "params", "cost")
#: Keys of a ``[[transition]]``.
TRANSITION_KEYS = ("id", "label", "events", "priority", "weight", "kind", "rate", "servers", "hidden",
                   "inputs", "outputs", "inhibitors", "pos")
#: Keys of an ``[[arc]]``.
ARC_KEYS = ("from", "to", "weight", "inhibitor", "reset")
