"""The learning automaton of one primitive task: what every scheme shares (paper section 4).

A *learning automaton* per primitive task holds a probability vector ``p`` over the task's
primitive actions, draws the action to run from it, and is told the outcome: a status
(``"success"``, ``"failure"`` or ``"error"``; an error counts as a failure for learning, section 4)
and, optionally, a measured cost. Over the trials it moves ``p`` toward the action that minimises
the performance function J = 1 − R + ρ·C (section 3, eq. 1, computed by
:func:`coordinator.performance.cost_function`).

:class:`LearningAutomaton` keeps the per-action estimates (trials, successes, measured costs),
computes R̂, C and Ĵ, draws actions and saves its whole state; a scheme
(:mod:`~coordinator.learning.pursuit`, :mod:`~coordinator.learning.lri`,
:mod:`~coordinator.learning.fixed`) says how an action is drawn and how ``p`` moves.
:class:`RateAutomaton` adds the learning rate λ and the round-robin warm-up that pursuit and L_R-I
share.

Persistence: :meth:`LearningAutomaton.state_dict` returns a JSON-serialisable dict holding the
configuration, the probabilities, the counts, the cost sums and the random generator's state
(:mod:`coordinator.learning.state` rebuilds an automaton from it).

Pure: no I/O, no clocks; randomness comes only from seeded ``numpy`` generators.
"""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from coordinator.errors import JournalError
from coordinator.learning.validation import (
    check_actions,
    check_budget,
    check_cost_source,
    check_rho,
    check_costs,
    check_rate,
    check_warmup,
)
from coordinator.performance import cost_function, task_rho
from services.results import Status

__all__ = ["STATE_FORMAT", "ActionEstimate", "LearningAutomaton", "RateAutomaton"]

#: Version of the :meth:`LearningAutomaton.state_dict` layout.
STATE_FORMAT = 1


@dataclass(frozen=True, slots=True)
class ActionEstimate:
    """What an automaton has learned about one primitive action.

    Attributes:
        trials: number of results received (success, failure or error).
        successes: number of ``"success"`` results.
        reliability: R̂ = successes / trials, or ``None`` before the first trial.
        cost: C used in J: the a-priori cost, or the mean measured cost (``None`` if unknown).
        measured_cost: mean of the measured costs reported so far, ``None`` if none was reported.
        j: Ĵ = 1 − R̂ + ρ·C (eq. 1), ``None`` while R̂ or C is unknown.
    """

    trials: int
    successes: int
    reliability: float | None
    cost: float | None
    measured_cost: float | None
    j: float | None


class LearningAutomaton(ABC):
    """A learning automaton over the primitive actions of one primitive task (section 4).

    Subclasses define how an action is drawn and how the probability vector moves; this base keeps
    the per-action estimates (trials, successes, measured costs) and computes R̂, C and Ĵ.

    Args:
        actions: names of the task's primitive actions, in a fixed order (length r ≥ 1).
        costs: a-priori cost C(a) ≥ 0 of every action (any unit), or ``None``.
        cost_source: ``"apriori"`` (J uses ``costs``; ρ = 1 / max C(a)) or ``"measured"`` (J uses
            the mean measured cost of each action; ρ = 1 / max over actions of those means).
            Default: ``"apriori"`` when ``costs`` is given, else ``"measured"``.
        rho: ρ ≥ 0 in 1/cost-unit, the weight of cost against reliability; ``None`` (default) for
            :func:`coordinator.performance.task_rho`: the paper's typical ρ = 1 / max C(a), or for a
            single action 1 / ``cost_budget``. The paper asks that ρ keep the cost from
            overwhelming the reliability: a task whose failures cost much more than its actions'
            running costs (a failed segment ends a course) declares a smaller ρ.
        seed: seed of the automaton's own ``numpy`` generator (used when ``choose`` gets none).
        cost_budget: the deadline (s) of a single-action task whose costs are measured times:
            ρ = 1 / cost_budget (:func:`coordinator.performance.cost_budget`); ignored otherwise.

    Raises:
        LearnerConfigError: on an empty or duplicated action list, bad costs or cost source.
    """

    scheme: ClassVar[str] = ""

    def __init__(
        self,
        actions: Sequence[str],
        *,
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        rho: float | None = None,
        seed: int = 0,
        cost_budget: float | None = None,
    ) -> None:
        self._actions = check_actions(actions)
        self._costs = check_costs(costs, self._actions)
        self._cost_source = check_cost_source(cost_source, self._costs)
        self._rho = None if rho is None else check_rho(rho)
        self._cost_budget = None if cost_budget is None else check_budget(cost_budget)
        self._seed = int(seed)
        self._rng = np.random.default_rng(self._seed)
        n = len(self._actions)
        self._p = [1.0 / n] * n
        self._trials = [0] * n
        self._successes = [0] * n
        self._cost_sums = [0.0] * n
        self._cost_counts = [0] * n
        self._steps = 0

    # -- read-only views -------------------------------------------------------------------------

    @property
    def actions(self) -> tuple[str, ...]:
        """The primitive actions, in the automaton's order."""
        return self._actions

    @property
    def steps(self) -> int:
        """Number of results received so far."""
        return self._steps

    @property
    def cost_source(self) -> str:
        """``"apriori"`` or ``"measured"``: where the C of J comes from."""
        return self._cost_source

    @property
    def probabilities(self) -> dict[str, float]:
        """Probability of choosing each action next, {action: p}, summing to 1."""
        return dict(zip(self._actions, self._p))

    @property
    def rho(self) -> float:
        """ρ of J = 1 − R + ρC (section 3), :func:`coordinator.performance.task_rho`: as configured,
        else 1 / max C(a) of the a-priori costs or of the measured means; for a single action whose
        costs are measured times, 1 / its cost budget (0 without one).

        0.0 while no cost is known or every cost is 0 (and no ρ is configured).
        """
        if self._cost_source == "apriori":
            assert self._costs is not None
            return task_rho(self._costs.values(), actions=len(self._actions), declared=self._rho)
        means = [s / c for s, c in zip(self._cost_sums, self._cost_counts) if c > 0]
        return task_rho(means, actions=len(self._actions), declared=self._rho, budget=self._cost_budget)

    @property
    def cost_budget(self) -> float | None:
        """The cost budget (s) ρ is 1 / of for a single action with measured costs, or ``None``."""
        return self._cost_budget

    def _cost(self, i: int) -> float | None:
        if self._cost_source == "apriori":
            assert self._costs is not None
            return self._costs[self._actions[i]]
        if self._cost_counts[i] == 0:
            # An action that never reported a cost is treated as free (documented).
            return 0.0 if self._trials[i] > 0 else None
        return self._cost_sums[i] / self._cost_counts[i]

    def _j(self, i: int, rho: float) -> float | None:
        if self._trials[i] == 0:
            return None
        cost = self._cost(i)
        if cost is None:
            return None
        return cost_function(self._successes[i] / self._trials[i], cost, rho)

    @property
    def estimates(self) -> dict[str, ActionEstimate]:
        """Per action: trials, successes, R̂, C, mean measured cost and Ĵ (eq. 1)."""
        rho = self.rho
        out: dict[str, ActionEstimate] = {}
        for i, name in enumerate(self._actions):
            n = self._trials[i]
            out[name] = ActionEstimate(
                trials=n,
                successes=self._successes[i],
                reliability=self._successes[i] / n if n else None,
                cost=self._cost(i),
                measured_cost=(self._cost_sums[i] / self._cost_counts[i]
                               if self._cost_counts[i] else None),
                j=self._j(i, rho),
            )
        return out

    def converged(self, threshold: float = 0.95) -> str | None:
        """Return the action whose probability is at least ``threshold``, else ``None``.

        Raises:
            ValueError: if ``threshold`` is not in (0.5, 1].
        """
        if not 0.5 < threshold <= 1.0:
            raise ValueError(f"threshold must lie in (0.5, 1], got {threshold}")
        for name, p in zip(self._actions, self._p):
            if p >= threshold:
                return name
        return None

    # -- the learning loop -------------------------------------------------------------------------

    def choose(self, rng: np.random.Generator | None = None) -> str:
        """Return the primitive action to run next.

        Args:
            rng: generator to draw from; the automaton's own seeded generator when ``None``.
        """
        return self._actions[self._choose(self._rng if rng is None else rng)]

    def _sample(self, rng: np.random.Generator) -> int:
        u = float(rng.random())
        acc = 0.0
        last = 0
        for i, p in enumerate(self._p):
            if p > 0.0:
                last = i
                acc += p
                if u < acc:
                    return i
        return last  # rounding: the sum of p fell just short of u

    def update(self, action: str, status: Status, cost: float | None = None) -> None:
        """Feed back the result of one run of ``action``.

        Args:
            action: the primitive action that ran.
            status: how it ended (error counts as failure for learning).
            cost: measured cost of this run (≥ 0, the task's cost unit), or ``None`` if not measured.

        Raises:
            ValueError: on an unknown action, or a negative or non-finite cost.
        """
        try:
            i = self._actions.index(action)
        except ValueError:
            raise ValueError(f"unknown primitive action {action!r}; "
                             f"known: {', '.join(self._actions)}") from None
        if cost is not None:
            cost = float(cost)
            if not math.isfinite(cost) or cost < 0.0:
                raise ValueError(f"cost must be finite and >= 0, got {cost}")
        success = status == Status.SUCCESS
        self._trials[i] += 1
        self._successes[i] += int(success)
        if cost is not None:
            self._cost_sums[i] += cost
            self._cost_counts[i] += 1
        self._steps += 1
        self._reinforce(i, success, cost)

    def _pull_toward(self, i: int, step: float) -> None:
        """p ← (1 − step)·p + step·e_i."""
        keep = 1.0 - step
        self._p = [keep * p for p in self._p]
        self._p[i] += step

    @abstractmethod
    def _choose(self, rng: np.random.Generator) -> int:
        """Index of the action to run next."""

    @abstractmethod
    def _reinforce(self, i: int, success: bool, cost: float | None) -> None:
        """Move the probability vector after a result of action ``i``."""

    @abstractmethod
    def _config(self) -> dict[str, Any]:
        """Scheme parameters, as accepted by :func:`~coordinator.learning.config.make_learner`."""

    # -- persistence -------------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Return the whole state as a JSON-serialisable dict (exact round trip via JSON)."""
        return {
            "format": STATE_FORMAT,
            "scheme": self.scheme,
            "actions": list(self._actions),
            "costs": None if self._costs is None else dict(self._costs),
            "config": self._config() if self._rho is None else {**self._config(), "rho": self._rho},
            "seed": self._seed,
            "cost_budget": self._cost_budget,
            "probabilities": list(self._p),
            "trials": list(self._trials),
            "successes": list(self._successes),
            "cost_sums": list(self._cost_sums),
            "cost_counts": list(self._cost_counts),
            "steps": self._steps,
            "rng": _jsonable_rng_state(self._rng),
        }

    def restore_counts(self, state: Mapping[str, Any]) -> None:
        """Take the probabilities, counts, cost sums and generator state of a :meth:`state_dict`.

        The configuration (scheme, actions, rate...) is this automaton's own; the caller checks
        that the state belongs to the same scheme and actions.

        Raises:
            JournalError: vectors of the wrong length, probabilities that are not a distribution,
                more successes than trials.
            KeyError, TypeError, ValueError: a missing or malformed entry.
        """
        n = len(self._actions)
        p = [float(x) for x in state["probabilities"]]
        trials = [int(x) for x in state["trials"]]
        succ = [int(x) for x in state["successes"]]
        sums = [float(x) for x in state["cost_sums"]]
        counts = [int(x) for x in state["cost_counts"]]
        if any(len(v) != n for v in (p, trials, succ, sums, counts)):
            raise JournalError("learner state: vectors do not match the number of actions")
        if any(x < 0.0 for x in p) or abs(sum(p) - 1.0) > 1e-6:
            raise JournalError("learner state: probabilities are not a distribution")
        if any(s > t or s < 0 for s, t in zip(succ, trials)):
            raise JournalError("learner state: more successes than trials")
        self._p, self._trials, self._successes = p, trials, succ
        self._cost_sums, self._cost_counts = sums, counts
        self._steps = int(state["steps"])
        self._rng.bit_generator.state = dict(state["rng"])

    def __repr__(self) -> str:
        probs = ", ".join(f"{a}={p:.3f}" for a, p in zip(self._actions, self._p))
        return f"{type(self).__name__}({probs}; steps={self._steps})"


def _jsonable_rng_state(rng: np.random.Generator) -> dict[str, Any]:
    state = rng.bit_generator.state
    # PCG64's state is plain ints and strings already; make a deep copy through JSON to be sure.
    out: dict[str, Any] = json.loads(json.dumps(state))
    return out


class RateAutomaton(LearningAutomaton):
    """An automaton with a learning rate λ and a round-robin warm-up (shared by pursuit and L_R-I)."""

    def __init__(
        self,
        actions: Sequence[str],
        *,
        rate: float,
        warmup: int,
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        rho: float | None = None,
        seed: int = 0,
        cost_budget: float | None = None,
    ) -> None:
        super().__init__(actions, costs=costs, cost_source=cost_source, rho=rho, seed=seed, cost_budget=cost_budget)
        self._rate = check_rate(rate)
        self._warmup = check_warmup(warmup)

    @property
    def rate(self) -> float:
        """Learning rate λ."""
        return self._rate

    @property
    def warmup(self) -> int:
        """Trials of every action before the probability vector moves."""
        return self._warmup

    def _warming(self) -> int | None:
        best: int | None = None
        for i, n in enumerate(self._trials):
            if n < self._warmup and (best is None or n < self._trials[best]):
                best = i
        return best

    def _choose(self, rng: np.random.Generator) -> int:
        pending = self._warming()
        return pending if pending is not None else self._sample(rng)
