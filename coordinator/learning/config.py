"""Building a primitive task's learning automaton from its net-file configuration (paper section 4).

:func:`make_learner` checks the ``learner`` table (:func:`~coordinator.learning.validation.learner_spec`)
and builds the automaton of the chosen scheme. Pure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from coordinator.learning.base import LearningAutomaton
from coordinator.learning.fixed import FixedChoice
from coordinator.learning.lri import LinearRewardInaction
from coordinator.learning.pursuit import PursuitAutomaton
from coordinator.learning.validation import (
    LearnerConfigError,
    LearnerSpec,
    learner_spec,
)

__all__ = ["LearnerConfigError", "automaton_for", "make_learner"]


def make_learner(
    config: Mapping[str, Any],
    actions: Sequence[str],
    costs: Mapping[str, float] | None = None,
    seed: int = 0,
    cost_budget: float | None = None,
) -> LearningAutomaton:
    """Build the learning automaton of one primitive task from its net-file configuration.

    Accepted keys of ``config`` (all optional):

    * ``scheme`` (alias ``learner``): ``"pursuit"``, ``"lri"`` or ``"fixed"``. When absent:
      ``"fixed"`` if ``config`` is empty (a net-file task without a ``learner`` table always runs
      its first action, see :class:`coordinator.net.PrimitiveTask`), ``"pursuit"`` otherwise.
    * ``rate`` (alias ``learning_rate``): λ ∈ (0, 1]; default :data:`DEFAULT_RATES`.
    * ``warmup``: trials of every action before learning moves ``p``; default
      :data:`DEFAULT_WARMUP`.
    * ``cost_source``: ``"apriori"`` or ``"measured"`` (see :class:`LearningAutomaton`).
    * ``estimator``: for ``"pursuit"``, ``"optimistic"`` (default) or ``"mean"``.
    * ``action``: for ``"fixed"``, the action to run (default the first).
    * ``rho``: ρ ≥ 0 of J = 1 − R + ρC (default 1 / max C(a), paper section 3).

    Args:
        config: the keys above.
        actions: the primitive task's primitive actions, in order.
        costs: a-priori costs {action: C ≥ 0} (net file ``costs = {action = value}``), or ``None``.
        seed: seed of the automaton's random generator (see :func:`coordinator.learning.state.task_seed`).
        cost_budget: a single-action task's deadline (s), ρ = 1 / it when its costs are measured
            (see :class:`~coordinator.learning.base.LearningAutomaton`), or ``None``.

    Returns:
        A fresh automaton with a uniform probability vector (or the fixed choice).

    Raises:
        LearnerConfigError: naming the offending key and value, for an unknown key, scheme, a rate
            outside (0, 1], a bad warmup, costs that do not match ``actions``, or keys that do not
            apply to the scheme.
    """
    return automaton_for(learner_spec(config, actions, costs, seed), seed, cost_budget)


def automaton_for(spec: LearnerSpec, seed: int = 0, cost_budget: float | None = None) -> LearningAutomaton:
    """A fresh automaton of a checked configuration, seeded with ``seed`` (``cost_budget``: see
    :func:`make_learner`)."""
    if spec.scheme == "fixed":
        return FixedChoice(spec.actions, action=spec.action, costs=spec.costs, cost_source=spec.cost_source,
                           rho=spec.rho, seed=seed, cost_budget=cost_budget)
    assert spec.rate is not None and spec.warmup is not None
    if spec.scheme == "pursuit":
        assert spec.estimator is not None
        return PursuitAutomaton(spec.actions, rate=spec.rate, warmup=spec.warmup, estimator=spec.estimator,
                                costs=spec.costs, cost_source=spec.cost_source, rho=spec.rho, seed=seed,
                                cost_budget=cost_budget)
    return LinearRewardInaction(spec.actions, rate=spec.rate, warmup=spec.warmup, costs=spec.costs,
                                cost_source=spec.cost_source, rho=spec.rho, seed=seed, cost_budget=cost_budget)
