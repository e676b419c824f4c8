"""The estimator ("pursuit") learning automaton (paper section 4).

Thathachar & Sastry, "A new approach to the design of reinforcement schemes for learning
automata", IEEE Trans. SMC 15(1), 1985, and "Estimator algorithms for learning automata", 1986:
keep running estimates R̂ and Ĉ of every action, and after each trial move ``p`` a step λ toward
the unit vector of the action with the lowest estimated Ĵ = 1 − R̂ + ρ·Ĉ. The default
``"optimistic"`` estimator pursues an upper posterior quantile of R instead of R̂ (Zhang, Granmo
& Oommen 2011). The update is a deterministic function of (action, status, cost). Pure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from scipy.special import betaincinv

from coordinator.learning.base import RateAutomaton
from coordinator.learning.validation import (
    DEFAULT_RATES,
    DEFAULT_WARMUP,
    check_estimator,
)

__all__ = ["OPTIMISTIC_QUANTILE", "PursuitAutomaton"]

#: Posterior quantile used by the ``"optimistic"`` estimator (Zhang, Granmo & Oommen 2011).
OPTIMISTIC_QUANTILE = 0.95


class PursuitAutomaton(RateAutomaton):
    """Estimator ("pursuit") learning automaton (Thathachar & Sastry 1985, 1986).

    After each result, with m = argmin_a J̃(a) (ties to the earlier action),
    ``p ← (1 − λ)·p + λ·e_m``. Before that, every action is run ``warmup`` times in turn (a
    deterministic round robin, the usual initialisation of estimator algorithms) and ``p`` stays
    uniform, so that no action is discarded on one unlucky trial. The scheme is ε-optimal: for any
    ε > 0 there is a λ small enough that it converges to the J-optimal action with probability at
    least 1 − ε; smaller λ is slower and more accurate (docs/learning.md).

    The pursued estimate J̃ = 1 − R̃ + ρ·C depends on ``estimator``:

    * ``"mean"``: R̃ = R̂ = successes / trials, the classic pursuit scheme.
    * ``"optimistic"`` (default): R̃ is the 95 % quantile of the Beta(successes + 1,
      failures + 1) posterior of R, as in the Bayesian pursuit algorithm (Zhang, Granmo & Oommen,
      "The Bayesian pursuit algorithm: a new family of estimator learning automata", IEA/AIE 2011,
      LNCS 6704). An action tried few times keeps an optimistic J̃ until enough trials show it is
      worse, so an unlucky start does not starve the optimal action of trials. At the same λ it
      converges correctly more often than ``"mean"`` for a few more trials (bench/learning.py).

    The reported estimates (:attr:`estimates`) are always the plain R̂ and Ĵ.

    Args:
        actions: see :class:`LearningAutomaton`.
        rate: learning rate λ ∈ (0, 1].
        warmup: trials of every action before ``p`` moves (≥ 0).
        estimator: ``"optimistic"`` or ``"mean"``.
        costs, cost_source, seed: see :class:`LearningAutomaton`.

    Raises:
        LearnerConfigError: on a bad rate, warmup, estimator, or any argument of the base class.
    """

    scheme: ClassVar[str] = "pursuit"

    def __init__(
        self,
        actions: Sequence[str],
        *,
        rate: float = DEFAULT_RATES["pursuit"],
        warmup: int = DEFAULT_WARMUP["pursuit"],
        estimator: str = "optimistic",
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        rho: float | None = None,
        seed: int = 0,
        cost_budget: float | None = None,
    ) -> None:
        super().__init__(actions, rate=rate, warmup=warmup, costs=costs, cost_source=cost_source,
                         rho=rho, seed=seed, cost_budget=cost_budget)
        self._estimator = check_estimator(estimator)
        self._r_tilde: list[float | None] = [None] * len(self._actions)

    @property
    def estimator(self) -> str:
        """``"optimistic"`` or ``"mean"``: the reliability estimate pursued."""
        return self._estimator

    def _pursued_reliability(self, k: int) -> float:
        """R̃ of action k (cached; recomputed only when its counts change)."""
        cached = self._r_tilde[k]
        if cached is not None:
            return cached
        n, s = self._trials[k], self._successes[k]
        if self._estimator == "mean":
            value = s / n
        else:
            value = float(betaincinv(s + 1.0, n - s + 1.0, OPTIMISTIC_QUANTILE))
        self._r_tilde[k] = value
        return value

    def _reinforce(self, i: int, success: bool, cost: float | None) -> None:
        self._r_tilde[i] = None
        if self._warming() is not None:
            return
        rho = self.rho
        best = -1
        best_j = math.inf
        for k in range(len(self._actions)):
            if self._trials[k] == 0:
                continue
            c = self._cost(k)
            j = 1.0 - self._pursued_reliability(k) + rho * (0.0 if c is None else c)
            if j < best_j:
                best, best_j = k, j
        if best >= 0:
            self._pull_toward(best, self._rate)

    def restore_counts(self, state: Mapping[str, Any]) -> None:
        super().restore_counts(state)
        self._r_tilde = [None] * len(self._actions)

    def _config(self) -> dict[str, Any]:
        return {"rate": self._rate, "warmup": self._warmup, "estimator": self._estimator,
                "cost_source": self._cost_source}
