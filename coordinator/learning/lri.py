"""The linear reward–inaction automaton, S-model, rewarding low J (paper section 4).

Narendra & Thathachar, *Learning Automata: An Introduction*, 1989, in the S-model form of
Viswanathan & Narendra (IEEE Trans. SMC 3(1), 1973), where the environment's response is a reward
strength in [0, 1] rather than a binary signal. The strength of one trial is
``j = [status is not success] + min(1, ρ·c)``, an unbiased sample of J, mapped affinely and
decreasingly onto [0, 1]: the action with the highest mean reward is exactly the J-optimal one,
and cost takes part in learning, not only reliability. Pure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from coordinator.learning.base import RateAutomaton
from coordinator.learning.validation import DEFAULT_RATES, DEFAULT_WARMUP

__all__ = ["LinearRewardInaction"]


class LinearRewardInaction(RateAutomaton):
    """Linear reward–inaction automaton, S-model (Narendra & Thathachar 1989; Viswanathan &
    Narendra 1973), rewarding low J rather than success alone.

    A result of action i with success indicator s and cost c gives the J sample
    ``j = (1 − s) + min(1, ρ·c)`` (c is the a-priori cost, or the measured one), normalised into a
    reward strength ``r = 1 − (j − j_lo) / (j_hi − j_lo) ∈ [0, 1]`` as the S-model prescribes for
    a response in a known interval [j_lo, j_hi] (Narendra & Thathachar 1989). With
    a-priori costs j_lo = ρ·min C and j_hi = 1 + ρ·max C, so that equal costs give r = s exactly;
    with measured costs j_lo = 0 and j_hi = 2. Then ``p ← (1 − λ·r)·p + λ·r·e_i`` (a reward moves
    probability toward i; nothing else ever moves it: "inaction" on penalty). Since r is an affine,
    decreasing function of j, E[r] is decreasing in J: the action with the highest expected reward
    is the J-optimal one, and the S-model L_R-I is ε-optimal in a stationary environment. It needs
    a smaller λ than pursuit for the same accuracy and is much slower, because each step is
    informed only by the drawn action's own result (bench/learning.py).

    Args:
        actions: see :class:`LearningAutomaton`.
        rate: learning rate λ ∈ (0, 1].
        warmup: trials of every action (round robin) before ``p`` moves; useful with measured
            costs so that ρ is known before rewards are scaled by it.
        costs, cost_source, seed: see :class:`LearningAutomaton`.

    Raises:
        LearnerConfigError: on a bad rate, warmup, or any argument of the base class.
    """

    scheme: ClassVar[str] = "lri"

    def __init__(
        self,
        actions: Sequence[str],
        *,
        rate: float = DEFAULT_RATES["lri"],
        warmup: int = DEFAULT_WARMUP["lri"],
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        rho: float | None = None,
        seed: int = 0,
        cost_budget: float | None = None,
    ) -> None:
        super().__init__(actions, rate=rate, warmup=warmup, costs=costs, cost_source=cost_source,
                         rho=rho, seed=seed, cost_budget=cost_budget)

    def reward(self, i: int, success: bool, cost: float | None) -> float:
        """Reward strength r = 1 − (j − j_lo)/(j_hi − j_lo) ∈ [0, 1] of one result of action ``i``.

        ``j = [not success] + min(1, ρ·c)`` is one sample of J; ``j_lo`` and ``j_hi`` are the
        smallest and largest values it can take (see the class docstring).
        """
        rho = self.rho
        if self._cost_source == "apriori":
            assert self._costs is not None
            c: float = self._costs[self._actions[i]]
            lo = rho * min(self._costs.values())
            hi = 1.0 + rho * max(self._costs.values())
        else:
            measured = cost if cost is not None else self._cost(i)
            c = 0.0 if measured is None else measured
            lo, hi = 0.0, 2.0 if rho > 0.0 else 1.0
        j = (0.0 if success else 1.0) + min(1.0, rho * c)
        return min(1.0, max(0.0, 1.0 - (j - lo) / (hi - lo)))

    def _reinforce(self, i: int, success: bool, cost: float | None) -> None:
        if self._warming() is not None:
            return
        r = self.reward(i, success, cost)
        if r > 0.0:
            self._pull_toward(i, self._rate * r)

    def _config(self) -> dict[str, Any]:
        return {"rate": self._rate, "warmup": self._warmup, "cost_source": self._cost_source}
