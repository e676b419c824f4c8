"""Learning automata that choose among a primitive task's primitive actions (paper section 4).

Each time a primitive task starts, one of its translating primitive actions must be chosen. A
*learning automaton* per primitive task holds a probability vector ``p`` over the task's actions,
draws the action to run from it, and is told the outcome: a status (``"success"``, ``"failure"``
or ``"error"``; an error counts as a failure for learning, section 4) and, optionally, a measured
cost. Over the trials it moves ``p`` toward the action that minimises the performance function
J = 1 − R + ρ·C (section 3, eq. 1, computed by :func:`coordinator.performance.cost_function`).

Schemes (chosen per primitive task in the net file, ``learner = "..."``):

* ``"pursuit"`` — :class:`PursuitAutomaton`, the estimator scheme of Thathachar & Sastry
  ("A new approach to the design of reinforcement schemes for learning automata", IEEE Trans.
  SMC 15(1), 1985; "Estimator algorithms for learning automata", 1986): keep running estimates
  R̂ and Ĉ of every action, and after each trial move ``p`` a step λ toward the unit vector of the
  action with the lowest estimated Ĵ = 1 − R̂ + ρ·Ĉ.
* ``"lri"`` — :class:`LinearRewardInaction`, linear reward–inaction (Narendra & Thathachar,
  *Learning Automata: An Introduction*, 1989) in its S-model form (Viswanathan & Narendra,
  IEEE Trans. SMC 3(1), 1973), where the environment's response is a reward strength in [0, 1]
  rather than a binary signal. The strength of one trial is ``j = [status is not success] +
  min(1, ρ·c)``, an unbiased sample of J, mapped affinely and decreasingly onto [0, 1]: the action
  with the highest mean reward is exactly the J-optimal one, and cost takes part in learning, not
  only reliability.
* ``"fixed"`` — :class:`FixedChoice`, always the same action (tasks with a single action).

Both learning updates are deterministic functions of (action, status, cost): the random generator is
used only to draw actions. Replaying a journal's results through a fresh automaton of the same
configuration therefore reproduces its probability vector exactly (``petrobot learn --plot`` relies
on this).

Persistence: :meth:`LearningAutomaton.state_dict` returns a JSON-serialisable dict holding the
configuration, the probabilities, the counts, the cost sums and the random generator's state;
:func:`automaton_from_state` rebuilds an automaton whose probabilities, estimates and future draws are
identical. :func:`state_to_json` / :func:`state_from_json` encode it for the journal's
``learner_state`` table (:data:`LEARNER_STATE_DDL`).

This module is pure: no I/O, no clocks; randomness comes only from seeded ``numpy`` generators.
"""

from __future__ import annotations

import json
import math
import zlib
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from scipy.special import betaincinv

from coordinator.errors import JournalError, NetError
from coordinator.performance import cost_function, rho_for
from services.results import ActionResult, Status

__all__ = [
    "DEFAULT_RATES",
    "DEFAULT_WARMUP",
    "ESTIMATORS",
    "LEARNER_STATE_DDL",
    "OPTIMISTIC_QUANTILE",
    "SCHEMES",
    "ActionEstimate",
    "FixedChoice",
    "Learner",
    "LearnerConfigError",
    "LearningAutomaton",
    "LinearRewardInaction",
    "PursuitAutomaton",
    "automaton_from_state",
    "make_learner",
    "state_from_json",
    "state_to_json",
    "task_seed",
]


#: Learning schemes accepted in a net file's ``learner`` key.
SCHEMES: tuple[str, ...] = ("pursuit", "lri", "fixed")

#: Default learning rate λ per scheme (chosen with ``bench/learning.py``, see docs/learning.md).
DEFAULT_RATES: Mapping[str, float] = {"pursuit": 0.01, "lri": 0.01}

#: Default number of trials of every action before the probability vector moves.
DEFAULT_WARMUP: Mapping[str, int] = {"pursuit": 10, "lri": 0}

#: SQLite table in which the runtime keeps one automaton state per primitive task.
LEARNER_STATE_DDL = (
    "CREATE TABLE IF NOT EXISTS learner_state ("
    "task TEXT PRIMARY KEY, scheme TEXT NOT NULL, state TEXT NOT NULL, updated_wall REAL)"
)

_STATE_FORMAT = 1
_CONFIG_KEYS = ("scheme", "learner", "rate", "learning_rate", "warmup", "cost_source", "action",
                "estimator")

#: Reliability estimators of the pursuit scheme.
ESTIMATORS: tuple[str, ...] = ("optimistic", "mean")

#: Posterior quantile used by the ``"optimistic"`` estimator (Zhang, Granmo & Oommen 2011).
OPTIMISTIC_QUANTILE = 0.95


class LearnerConfigError(NetError, ValueError):
    """A primitive task's learner configuration is invalid.

    It is a :class:`~coordinator.errors.NetError` (the configuration comes from a net file, whose
    loader may add the file and line) and a :class:`ValueError`.
    """


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


def _problem(text: str) -> LearnerConfigError:
    return LearnerConfigError(text)


def _check_actions(actions: Sequence[str]) -> tuple[str, ...]:
    names = tuple(actions)
    if not names:
        raise _problem("a learner needs at least one primitive action")
    for name in names:
        if not isinstance(name, str) or not name:
            raise _problem(f"primitive action names must be non-empty strings, got {name!r}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise _problem(f"primitive actions listed twice: {', '.join(dup)}")
    return names


def _check_costs(costs: Mapping[str, float] | None, actions: tuple[str, ...]) -> dict[str, float] | None:
    if costs is None:
        return None
    if not isinstance(costs, Mapping):
        raise _problem(f"costs must be a table {{action = value}}, got {type(costs).__name__}")
    unknown = sorted(set(costs) - set(actions))
    if unknown:
        raise _problem(f"costs name unknown primitive actions: {', '.join(map(str, unknown))}"
                       f" (actions: {', '.join(actions)})")
    missing = [a for a in actions if a not in costs]
    if missing:
        raise _problem(f"costs are given for some actions but not for: {', '.join(missing)}")
    out: dict[str, float] = {}
    for name in actions:
        value = costs[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _problem(f"cost of {name!r} must be a number, got {value!r}")
        if not math.isfinite(value) or value < 0:
            raise _problem(f"cost of {name!r} must be finite and >= 0, got {value!r}")
        out[name] = float(value)
    return out


def _check_rate(rate: Any) -> float:
    if isinstance(rate, bool) or not isinstance(rate, (int, float)):
        raise _problem(f"learning rate must be a number in (0, 1], got {rate!r}")
    if not (0.0 < float(rate) <= 1.0):
        raise _problem(f"learning rate must lie in (0, 1], got {rate!r}")
    return float(rate)


def _check_warmup(warmup: Any) -> int:
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise _problem(f"warmup must be a whole number of trials >= 0, got {warmup!r}")
    return warmup


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
        seed: seed of the automaton's own ``numpy`` generator (used when ``choose`` gets none).

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
        seed: int = 0,
    ) -> None:
        self._actions = _check_actions(actions)
        self._costs = _check_costs(costs, self._actions)
        if cost_source is None:
            cost_source = "apriori" if self._costs is not None else "measured"
        if cost_source not in ("apriori", "measured"):
            raise _problem(f"cost_source must be 'apriori' or 'measured', got {cost_source!r}")
        if cost_source == "apriori" and self._costs is None:
            raise _problem("cost_source 'apriori' needs costs = {action = value} for every action")
        self._cost_source = cost_source
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
        """ρ = 1 / max C(a) (section 3): from the a-priori costs, or from the measured means.

        0.0 while no cost is known or every cost is 0.
        """
        if self._cost_source == "apriori":
            assert self._costs is not None
            return rho_for(self._costs.values())
        means = [s / c for s, c in zip(self._cost_sums, self._cost_counts) if c > 0]
        return rho_for(means) if means else 0.0

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
        """Scheme parameters, as accepted by :func:`make_learner`."""

    # -- persistence -------------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Return the whole state as a JSON-serialisable dict (exact round trip via JSON)."""
        return {
            "format": _STATE_FORMAT,
            "scheme": self.scheme,
            "actions": list(self._actions),
            "costs": None if self._costs is None else dict(self._costs),
            "config": self._config(),
            "seed": self._seed,
            "probabilities": list(self._p),
            "trials": list(self._trials),
            "successes": list(self._successes),
            "cost_sums": list(self._cost_sums),
            "cost_counts": list(self._cost_counts),
            "steps": self._steps,
            "rng": _jsonable_rng_state(self._rng),
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> LearningAutomaton:
        """Rebuild an automaton from :meth:`state_dict` output (any scheme).

        Raises:
            JournalError: if the state is malformed or of another format.
        """
        auto = automaton_from_state(state)
        if cls is not LearningAutomaton and not isinstance(auto, cls):
            raise JournalError(f"state is of scheme {auto.scheme!r}, not {cls.scheme!r}")
        return auto

    def _load_counts(self, state: Mapping[str, Any]) -> None:
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


class _RateAutomaton(LearningAutomaton):
    """An automaton with a learning rate λ and a round-robin warm-up (shared by pursuit and L_R-I)."""

    def __init__(
        self,
        actions: Sequence[str],
        *,
        rate: float,
        warmup: int,
        costs: Mapping[str, float] | None = None,
        cost_source: str | None = None,
        seed: int = 0,
    ) -> None:
        super().__init__(actions, costs=costs, cost_source=cost_source, seed=seed)
        self._rate = _check_rate(rate)
        self._warmup = _check_warmup(warmup)

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


class PursuitAutomaton(_RateAutomaton):
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
        seed: int = 0,
    ) -> None:
        super().__init__(actions, rate=rate, warmup=warmup, costs=costs, cost_source=cost_source,
                         seed=seed)
        if estimator not in ESTIMATORS:
            raise _problem(f"estimator must be one of {', '.join(ESTIMATORS)}, got {estimator!r}")
        self._estimator = estimator
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

    def _load_counts(self, state: Mapping[str, Any]) -> None:
        super()._load_counts(state)
        self._r_tilde = [None] * len(self._actions)

    def _config(self) -> dict[str, Any]:
        return {"rate": self._rate, "warmup": self._warmup, "estimator": self._estimator,
                "cost_source": self._cost_source}


class LinearRewardInaction(_RateAutomaton):
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
        seed: int = 0,
    ) -> None:
        super().__init__(actions, rate=rate, warmup=warmup, costs=costs, cost_source=cost_source,
                         seed=seed)

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
        seed: int = 0,
    ) -> None:
        super().__init__(actions, costs=costs, cost_source=cost_source, seed=seed)
        if action is None:
            action = self._actions[0]
        if action not in self._actions:
            raise _problem(f"fixed learner names action {action!r}, which is not one of "
                           f"{', '.join(self._actions)}")
        self._index = self._actions.index(action)
        self._p = [0.0] * len(self._actions)
        self._p[self._index] = 1.0

    def _choose(self, rng: np.random.Generator) -> int:
        return self._index

    def _reinforce(self, i: int, success: bool, cost: float | None) -> None:
        return None

    def _config(self) -> dict[str, Any]:
        return {"action": self._actions[self._index], "cost_source": self._cost_source}


_CLASSES: Mapping[str, type[LearningAutomaton]] = {
    "pursuit": PursuitAutomaton,
    "lri": LinearRewardInaction,
    "fixed": FixedChoice,
}


def make_learner(
    config: Mapping[str, Any],
    actions: Sequence[str],
    costs: Mapping[str, float] | None = None,
    seed: int = 0,
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

    Args:
        config: the keys above.
        actions: the primitive task's primitive actions, in order.
        costs: a-priori costs {action: C ≥ 0} (net file ``costs = {action = value}``), or ``None``.
        seed: seed of the automaton's random generator (see :func:`task_seed`).

    Returns:
        A fresh automaton with a uniform probability vector (or the fixed choice).

    Raises:
        LearnerConfigError: naming the offending key and value, for an unknown key, scheme, a rate
            outside (0, 1], a bad warmup, costs that do not match ``actions``, or keys that do not
            apply to the scheme.
    """
    if not isinstance(config, Mapping):
        raise _problem(f"learner configuration must be a table, got {type(config).__name__}")
    unknown = sorted(set(config) - set(_CONFIG_KEYS))
    if unknown:
        raise _problem(f"unknown learner key(s) {', '.join(map(repr, unknown))}; "
                       f"accepted: {', '.join(_CONFIG_KEYS)}")
    for key, alias in (("scheme", "learner"), ("rate", "learning_rate")):
        if key in config and alias in config:
            raise _problem(f"give either {key!r} or {alias!r}, not both")
    names = _check_actions(actions)
    scheme = config.get("scheme", config.get("learner"))
    if scheme is None:
        scheme = "pursuit" if config else "fixed"
    if scheme not in _CLASSES:
        raise _problem(f"unknown learner {scheme!r}; choose one of {', '.join(SCHEMES)}")
    rate = config.get("rate", config.get("learning_rate"))
    cost_source = config.get("cost_source")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise _problem(f"seed must be an integer, got {seed!r}")
    if scheme == "fixed":
        for key in ("rate", "learning_rate", "warmup", "estimator"):
            if key in config:
                raise _problem(f"learner 'fixed' does not learn: remove {key!r}")
        return FixedChoice(names, action=config.get("action"), costs=costs,
                           cost_source=cost_source, seed=seed)
    if "action" in config:
        raise _problem(f"'action' applies only to learner 'fixed', not {scheme!r}")
    rate = DEFAULT_RATES[scheme] if rate is None else _check_rate(rate)
    warmup = _check_warmup(config.get("warmup", DEFAULT_WARMUP[scheme]))
    if scheme == "pursuit":
        return PursuitAutomaton(names, rate=rate, warmup=warmup,
                                estimator=config.get("estimator", "optimistic"),
                                costs=costs, cost_source=cost_source, seed=seed)
    if "estimator" in config:
        raise _problem("'estimator' applies only to learner 'pursuit', not 'lri'")
    return LinearRewardInaction(names, rate=rate, warmup=warmup, costs=costs,
                                cost_source=cost_source, seed=seed)


def automaton_from_state(state: Mapping[str, Any]) -> LearningAutomaton:
    """Rebuild an automaton from :meth:`LearningAutomaton.state_dict` output.

    The result has identical probabilities, counts, estimates, and random generator state (so its
    future draws are those the saved automaton would have made).

    Raises:
        JournalError: if the state is malformed, of an unknown scheme or format.
    """
    try:
        if state.get("format") != _STATE_FORMAT:
            raise JournalError(f"learner state format {state.get('format')!r} is not supported")
        config = dict(state["config"])
        config["scheme"] = state["scheme"]
        auto = make_learner(config, list(state["actions"]), state["costs"], int(state["seed"]))
        auto._load_counts(state)
    except JournalError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise JournalError(f"malformed learner state: {exc}") from exc
    return auto


def task_seed(seed: int, task: str) -> int:
    """Seed of one primitive task's automaton, derived from the run's seed and the task's name.

    Stable across processes and Python versions (CRC-32 of the name, not ``hash``), so that
    every task draws from its own reproducible stream.
    """
    return int(np.random.SeedSequence([int(seed) & 0xFFFFFFFF,
                                       zlib.crc32(task.encode("utf-8"))]).generate_state(1)[0])


def state_to_json(state: Mapping[str, Any]) -> str:
    """Encode a state dict as JSON text for the ``learner_state.state`` column (floats exact)."""
    return json.dumps(state, sort_keys=True, separators=(",", ":"), allow_nan=False)


def state_from_json(text: str) -> dict[str, Any]:
    """Decode :func:`state_to_json` output.

    Raises:
        JournalError: if the text is not a JSON object.
    """
    try:
        value = json.loads(text)
    except (TypeError, ValueError) as exc:
        raise JournalError(f"learner state is not valid JSON: {exc}") from exc
    if not isinstance(value, dict):
        raise JournalError("learner state is not a JSON object")
    return value


class Learner:
    """One learning automaton per primitive task: the runtime's single entry point (section 4).

    Args:
        seed: run seed; task ``t``'s automaton is seeded with ``task_seed(seed, t)``.
    """

    def __init__(self, seed: int = 0) -> None:
        self._seed = int(seed)
        self._automata: dict[str, LearningAutomaton] = {}
        self._configs: dict[str, tuple[dict[str, Any], dict[str, float] | None]] = {}

    @property
    def seed(self) -> int:
        """The run seed."""
        return self._seed

    @property
    def tasks(self) -> tuple[str, ...]:
        """Primitive tasks with an automaton, in insertion order."""
        return tuple(self._automata)

    def add_task(
        self,
        task: str,
        actions: Sequence[str],
        config: Mapping[str, Any] | None = None,
        costs: Mapping[str, float] | None = None,
    ) -> LearningAutomaton:
        """Create the automaton of ``task`` with :func:`make_learner` and register it.

        Raises:
            LearnerConfigError: on a bad configuration, or if the task is already registered.
        """
        if task in self._automata:
            raise _problem(f"primitive task {task!r} already has a learner")
        auto = make_learner(config or {}, actions, costs, task_seed(self._seed, task))
        self._automata[task] = auto
        self._configs[task] = (dict(config or {}), None if costs is None else dict(costs))
        return auto

    def automaton(self, task: str) -> LearningAutomaton:
        """The automaton of ``task``.

        Raises:
            KeyError: if the task has none.
        """
        return self._automata[task]

    def choose(self, task: str) -> str:
        """Draw the primitive action to run for a new instance of ``task``."""
        return self._automata[task].choose()

    def __call__(self, task: str, actions: tuple[str, ...]) -> str:
        """Engine chooser (``coordinator.engine.Chooser``): draw the action of a new instance.

        Raises:
            KeyError: if ``task`` has no automaton, or ``actions`` differ from the automaton's.
        """
        auto = self._automata.get(task)
        if auto is None:
            raise KeyError(f"primitive task {task!r} has no learner")
        if tuple(actions) != auto.actions:
            raise KeyError(f"primitive task {task!r}: engine offers {actions}, learner has {auto.actions}")
        return auto.choose()

    @classmethod
    def from_net(cls, net: Any, seed: int = 0) -> Learner:
        """One automaton per primitive task of a :class:`coordinator.net.PetriNet`.

        Uses each task's ``learner`` table as the configuration (:func:`make_learner`) and the
        actions' a-priori ``cost`` values as costs (none given: measured costs).

        Raises:
            LearnerConfigError: naming the primitive task, on a bad ``learner`` table or on costs
                given for some of a task's actions only.
        """
        learner = cls(seed)
        for name, task in net.tasks.items():
            names = [spec.name for spec in task.actions]
            given = {spec.name: spec.cost for spec in task.actions if spec.cost is not None}
            try:
                learner.add_task(name, names, dict(task.learner), given or None)
            except LearnerConfigError as exc:
                raise LearnerConfigError(f"primitive task {name!r}: {exc.problem}") from None
        return learner

    def update(self, task: str, action: str, result: ActionResult) -> dict[str, Any]:
        """Feed back one result and return the task's new state dict (to persist at once).

        The cost of the run is the action's own cost figure, else its measured duration on the
        node (``wall_s``).

        Raises:
            KeyError: if the task has no automaton.
            ValueError: on an unknown action.
        """
        auto = self._automata[task]
        auto.update(action, result.status, result.cost if result.cost is not None else result.wall_s)
        return auto.state_dict()

    def state_dict(self) -> dict[str, dict[str, Any]]:
        """{task: automaton state dict} for every task."""
        return {task: auto.state_dict() for task, auto in self._automata.items()}

    @classmethod
    def from_state(cls, states: Mapping[str, Mapping[str, Any]], seed: int = 0) -> Learner:
        """Rebuild a learner from :meth:`state_dict` output.

        Raises:
            JournalError: if any task's state is malformed.
        """
        learner = cls(seed)
        for task, state in states.items():
            learner._automata[task] = automaton_from_state(state)
        return learner

    def restore(self, states: Mapping[str, Mapping[str, Any]], *, strict: bool = True) -> list[str]:
        """Replace registered automata by their saved states (restart of the coordinator).

        A saved state is used only if its scheme and actions equal those configured now; states
        of tasks not registered are ignored. The configuration given to :meth:`add_task` (rate,
        warmup, costs) stays in force; probabilities, counts and the generator state are the saved
        ones, so the probabilities after the reload are identical to those before the restart.

        Args:
            states: {task: state dict}, e.g. decoded from the journal's ``learner_state`` rows.
            strict: raise on a mismatch instead of keeping the fresh automaton.

        Returns:
            The tasks whose saved state was *not* used (mismatch or unknown task).

        Raises:
            JournalError: if a state is malformed, or (``strict``) if it does not match the net.
        """
        skipped: list[str] = []
        for task, state in states.items():
            current = self._automata.get(task)
            if current is None:
                skipped.append(task)
                continue
            saved = automaton_from_state(state)
            if saved.scheme != current.scheme or saved.actions != current.actions:
                if strict:
                    raise JournalError(
                        f"saved learner of {task!r} ({saved.scheme}: {', '.join(saved.actions)}) "
                        f"does not match the net ({current.scheme}: {', '.join(current.actions)})")
                skipped.append(task)
                continue
            config, costs = self._configs[task]
            fresh = make_learner(config, current.actions, costs, task_seed(self._seed, task))
            try:
                fresh._load_counts(state)
            except (KeyError, TypeError, ValueError) as exc:
                raise JournalError(f"malformed learner state of {task!r}: {exc}") from exc
            self._automata[task] = fresh
        return skipped
