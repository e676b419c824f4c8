"""The fixed choice: a primitive task that always runs the same action (paper section 4).

A net-file task without a ``learner`` table gets one: it runs its first action, and keeps the
estimates R̂, C and Ĵ of the results so that ``petrobot learn`` can report them. Pure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from coordinator.learning.base import LearningAutomaton
from coordinator.learning.validation import check_fixed_action

__all__ = ["FixedChoice"]


class FixedChoice(LearningAutomaton):
    """Always choose the same primitive action; keeps estimates but never learns.

    Args:
        actions: see :class:`LearningAutomaton`.
        action: the action to run; the first one when ``None``.
        costs, cost_source, seed: see :class:`LearningAutomaton`.

    Raises:
        LearnerConfigError: if ``action`` is not one of ``actions``.
    """

    scheme: ClassVar[str] = "fixed"

    def __init__(
        self,
        actions: Sequence[str],
        *,
        action: str | None = None,
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        rho: float | None = None,
        seed: int = 0,
        cost_budget: float | None = None,
    ) -> None:
        super().__init__(actions, costs=costs, cost_source=cost_source, rho=rho, seed=seed, cost_budget=cost_budget)
        self._index = self._actions.index(check_fixed_action(action, self._actions))
        self._p = [0.0] * len(self._actions)
        self._p[self._index] = 1.0

    def _choose(self, rng: np.random.Generator) -> int:
        return self._index

    def _reinforce(self, i: int, success: bool, cost: float | None) -> None:
        return None

    def _config(self) -> dict[str, Any]:
        return {"action": self._actions[self._index], "cost_source": self._cost_source}
