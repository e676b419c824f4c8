"""A primitive task's learner configuration and its checks (paper section 4); pure Python.

A net file gives each primitive task an optional ``learner`` table (docs/netfile.md).
:func:`learner_spec` checks it against the task's actions and a-priori costs and returns a
:class:`LearnerSpec`, from which :func:`coordinator.learning.config.make_learner` builds the
automaton. The checks live here, without ``numpy``, so that loading a net file
(:mod:`coordinator.netfile`) validates a configuration without importing the automata; the
automata's constructors call the same checks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from coordinator.errors import NetError

__all__ = [
    "CONFIG_KEYS",
    "DEFAULT_RATES",
    "DEFAULT_WARMUP",
    "ESTIMATORS",
    "SCHEMES",
    "LearnerConfigError",
    "LearnerSpec",
    "check_actions",
    "check_budget",
    "check_cost_source",
    "check_costs",
    "check_estimator",
    "check_fixed_action",
    "check_rate",
    "check_rho",
    "check_warmup",
    "learner_spec",
]

#: Learning schemes accepted in a net file's ``learner`` key.
SCHEMES: tuple[str, ...] = ("pursuit", "lri", "fixed")

#: Default learning rate λ per scheme (chosen with ``bench/learning.py``, see docs/learning.md).
DEFAULT_RATES: Mapping[str, float] = {"pursuit": 0.01, "lri": 0.01}

#: Default number of trials of every action before the probability vector moves.
DEFAULT_WARMUP: Mapping[str, int] = {"pursuit": 10, "lri": 0}

#: Reliability estimators of the pursuit scheme.
ESTIMATORS: tuple[str, ...] = ("optimistic", "mean")

#: Keys a ``learner`` table may hold (``learner`` and ``learning_rate`` are aliases).
CONFIG_KEYS: tuple[str, ...] = ("scheme", "learner", "rate", "learning_rate", "warmup", "cost_source",
                                "action", "estimator", "rho")


class LearnerConfigError(NetError, ValueError):
    """A primitive task's learner configuration is invalid.

    It is a :class:`~coordinator.errors.NetError` (the configuration comes from a net file, whose
    loader may add the file and line) and a :class:`ValueError`.
    """


def check_actions(actions: Sequence[str]) -> tuple[str, ...]:
    """The action names as a tuple.

    Raises:
        LearnerConfigError: no action, a name that is not a non-empty string, or a name twice.
    """
    names = tuple(actions)
    if not names:
        raise LearnerConfigError("a learner needs at least one primitive action")
    for name in names:
        if not isinstance(name, str) or not name:
            raise LearnerConfigError(f"primitive action names must be non-empty strings, got {name!r}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise LearnerConfigError(f"primitive actions listed twice: {', '.join(dup)}")
    return names


def check_costs(costs: Mapping[str, float] | None, actions: tuple[str, ...]) -> dict[str, float] | None:
    """A-priori costs as ``{action: float}`` in action order, or ``None`` when none are given.

    Raises:
        LearnerConfigError: not a table, unknown or missing actions, or a cost that is not a
            finite number ≥ 0.
    """
    if costs is None:
        return None
    if not isinstance(costs, Mapping):
        raise LearnerConfigError(f"costs must be a table {{action = value}}, got {type(costs).__name__}")
    unknown = sorted(set(costs) - set(actions))
    if unknown:
        raise LearnerConfigError(f"costs name unknown primitive actions: {', '.join(map(str, unknown))}"
                                 f" (actions: {', '.join(actions)})")
    missing = [a for a in actions if a not in costs]
    if missing:
        raise LearnerConfigError(f"costs are given for some actions but not for: {', '.join(missing)}")
    out: dict[str, float] = {}
    for name in actions:
        value = costs[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise LearnerConfigError(f"cost of {name!r} must be a number, got {value!r}")
        if not math.isfinite(value) or value < 0:
            raise LearnerConfigError(f"cost of {name!r} must be finite and >= 0, got {value!r}")
        out[name] = float(value)
    return out


def check_cost_source(cost_source: str | None, costs: Mapping[str, float] | None) -> str:
    """Where the C of J comes from: ``"apriori"`` or ``"measured"``.

    Args:
        cost_source: as configured, or ``None`` for the default (``"apriori"`` when ``costs`` is
            given, else ``"measured"``).
        costs: the checked a-priori costs, or ``None``.

    Raises:
        LearnerConfigError: another value, or ``"apriori"`` without costs.
    """
    if cost_source is None:
        cost_source = "apriori" if costs is not None else "measured"
    if cost_source not in ("apriori", "measured"):
        raise LearnerConfigError(f"cost_source must be 'apriori' or 'measured', got {cost_source!r}")
    if cost_source == "apriori" and costs is None:
        raise LearnerConfigError("cost_source 'apriori' needs costs = {action = value} for every action")
    return cost_source


def check_rho(rho: Any) -> float:
    """The weight ρ ≥ 0 of cost in J = 1 − R + ρC (paper section 3), as a float.

    Raises:
        LearnerConfigError: not a finite number ≥ 0.
    """
    if isinstance(rho, bool) or not isinstance(rho, (int, float)) or not math.isfinite(rho) or rho < 0:
        raise LearnerConfigError(f"rho must be a finite number >= 0 (1/cost-unit), got {rho!r}")
    return float(rho)


def check_budget(budget: Any) -> float:
    """A cost budget (a single-action task's deadline, s) as a float > 0.

    Raises:
        LearnerConfigError: not a finite number > 0.
    """
    if isinstance(budget, bool) or not isinstance(budget, (int, float)) or not math.isfinite(budget) or budget <= 0:
        raise LearnerConfigError(f"a cost budget must be a finite number > 0 (s), got {budget!r}")
    return float(budget)


def check_rate(rate: Any) -> float:
    """A learning rate λ ∈ (0, 1] as a float.

    Raises:
        LearnerConfigError: not a number, or outside (0, 1].
    """
    if isinstance(rate, bool) or not isinstance(rate, (int, float)):
        raise LearnerConfigError(f"learning rate must be a number in (0, 1], got {rate!r}")
    if not (0.0 < float(rate) <= 1.0):
        raise LearnerConfigError(f"learning rate must lie in (0, 1], got {rate!r}")
    return float(rate)


def check_warmup(warmup: Any) -> int:
    """A number of warm-up trials per action (≥ 0).

    Raises:
        LearnerConfigError: not a whole number ≥ 0.
    """
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise LearnerConfigError(f"warmup must be a whole number of trials >= 0, got {warmup!r}")
    return warmup


def check_estimator(estimator: Any) -> str:
    """A reliability estimator of the pursuit scheme (one of :data:`ESTIMATORS`).

    Raises:
        LearnerConfigError: any other value.
    """
    if estimator not in ESTIMATORS:
        raise LearnerConfigError(f"estimator must be one of {', '.join(ESTIMATORS)}, got {estimator!r}")
    return str(estimator)


def check_fixed_action(action: str | None, actions: tuple[str, ...]) -> str:
    """The action a fixed choice runs: ``action``, or the first one when ``None``.

    Raises:
        LearnerConfigError: ``action`` is not one of ``actions``.
    """
    if action is None:
        return actions[0]
    if action not in actions:
        raise LearnerConfigError(f"fixed learner names action {action!r}, which is not one of "
                                 f"{', '.join(actions)}")
    return action


@dataclass(frozen=True, slots=True)
class LearnerSpec:
    """A checked learner configuration of one primitive task.

    Attributes:
        scheme: ``"pursuit"``, ``"lri"`` or ``"fixed"``.
        actions: the task's primitive actions, in order.
        costs: checked a-priori costs, or ``None``.
        cost_source: as configured (``None``: the automaton's default, see
            :func:`check_cost_source`).
        rate: learning rate λ (``None`` for ``"fixed"``).
        warmup: warm-up trials per action (``None`` for ``"fixed"``).
        estimator: reliability estimator (``"pursuit"`` only, else ``None``).
        action: the action of a ``"fixed"`` learner, else ``None``.
        rho: the configured ρ of J, or ``None`` for 1 / max C(a).
    """

    scheme: str
    actions: tuple[str, ...]
    costs: dict[str, float] | None
    cost_source: str | None
    rate: float | None = None
    warmup: int | None = None
    estimator: str | None = None
    action: str | None = None
    rho: float | None = None


def learner_spec(
    config: Mapping[str, Any],
    actions: Sequence[str],
    costs: Mapping[str, float] | None = None,
    seed: int = 0,
) -> LearnerSpec:
    """Check a ``learner`` table (the keys of :func:`coordinator.learning.config.make_learner`).

    Args:
        config: the ``learner`` table.
        actions: the primitive task's primitive actions, in order.
        costs: a-priori costs {action: C ≥ 0}, or ``None``.
        seed: the seed the automaton will get (checked to be an integer).

    Returns:
        The checked configuration.

    Raises:
        LearnerConfigError: naming the offending key and value, for an unknown key, scheme, a rate
            outside (0, 1], a bad warmup or estimator, costs that do not match ``actions``, or keys
            that do not apply to the scheme. The first problem is reported, in the order an
            automaton's construction would find it.
    """
    if not isinstance(config, Mapping):
        raise LearnerConfigError(f"learner configuration must be a table, got {type(config).__name__}")
    unknown = sorted(set(config) - set(CONFIG_KEYS))
    if unknown:
        raise LearnerConfigError(f"unknown learner key(s) {', '.join(map(repr, unknown))}; "
                                 f"accepted: {', '.join(CONFIG_KEYS)}")
    for key, alias in (("scheme", "learner"), ("rate", "learning_rate")):
        if key in config and alias in config:
            raise LearnerConfigError(f"give either {key!r} or {alias!r}, not both")
    names = check_actions(actions)
    scheme = config.get("scheme", config.get("learner"))
    if scheme is None:
        scheme = "pursuit" if config else "fixed"
    if scheme not in SCHEMES:
        raise LearnerConfigError(f"unknown learner {scheme!r}; choose one of {', '.join(SCHEMES)}")
    rate = config.get("rate", config.get("learning_rate"))
    cost_source = config.get("cost_source")
    rho = check_rho(config["rho"]) if "rho" in config else None
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise LearnerConfigError(f"seed must be an integer, got {seed!r}")
    if scheme == "fixed":
        for key in ("rate", "learning_rate", "warmup", "estimator"):
            if key in config:
                raise LearnerConfigError(f"learner 'fixed' does not learn: remove {key!r}")
        checked = check_costs(costs, names)
        check_cost_source(cost_source, checked)
        action = check_fixed_action(config.get("action"), names)
        return LearnerSpec("fixed", names, checked, cost_source, action=action, rho=rho)
    if "action" in config:
        raise LearnerConfigError(f"'action' applies only to learner 'fixed', not {scheme!r}")
    rate = DEFAULT_RATES[scheme] if rate is None else check_rate(rate)
    warmup = check_warmup(config.get("warmup", DEFAULT_WARMUP[scheme]))
    if scheme == "lri" and "estimator" in config:
        raise LearnerConfigError("'estimator' applies only to learner 'pursuit', not 'lri'")
    checked = check_costs(costs, names)
    check_cost_source(cost_source, checked)
    estimator = check_estimator(config.get("estimator", "optimistic")) if scheme == "pursuit" else None
    return LearnerSpec(scheme, names, checked, cost_source, rate=rate, warmup=warmup, estimator=estimator,
                       rho=rho)
