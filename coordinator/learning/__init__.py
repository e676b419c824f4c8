"""Learning automata that choose among a primitive task's primitive actions (paper section 4).

Each time a primitive task starts, one of its translating primitive actions must be chosen. A
learning automaton per primitive task draws it and learns from the results to minimise
J = 1 − R + ρ·C (section 3, eq. 1). Schemes (chosen per primitive task in the net file,
``learner = { scheme = "..." }``):

* ``"pursuit"`` — :class:`PursuitAutomaton` (:mod:`~coordinator.learning.pursuit`), the estimator
  scheme; the default;
* ``"lri"`` — :class:`LinearRewardInaction` (:mod:`~coordinator.learning.lri`), S-model linear
  reward–inaction;
* ``"fixed"`` — :class:`FixedChoice` (:mod:`~coordinator.learning.fixed`), always the same action.

The package, one concept per module:

* :mod:`~coordinator.learning.validation` — the ``learner`` table's keys and checks,
  :class:`LearnerConfigError` (pure Python: the net-file loader uses it without ``numpy``);
* :mod:`~coordinator.learning.base` — :class:`LearningAutomaton`, what every scheme shares;
* :mod:`~coordinator.learning.config` — :func:`make_learner`, configuration → automaton;
* :mod:`~coordinator.learning.state` — saved states: JSON, :func:`automaton_from_state`,
  :func:`task_seed`;
* :mod:`~coordinator.learning.registry` — :class:`Learner`, one automaton per primitive task.

The names below are imported from their module on first use, so that importing
:mod:`coordinator.learning.validation` does not import ``numpy`` and ``scipy``. Pure: no I/O.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coordinator.learning.base import (
        STATE_FORMAT,
        ActionEstimate,
        LearningAutomaton,
        RateAutomaton,
    )
    from coordinator.learning.config import make_learner
    from coordinator.learning.fixed import FixedChoice
    from coordinator.learning.lri import LinearRewardInaction
    from coordinator.learning.pursuit import OPTIMISTIC_QUANTILE, PursuitAutomaton
    from coordinator.learning.registry import Learner
    from coordinator.learning.state import (
        automaton_from_state,
        state_from_json,
        state_to_json,
        task_seed,
    )
    from coordinator.learning.validation import (
        DEFAULT_RATES,
        DEFAULT_WARMUP,
        ESTIMATORS,
        SCHEMES,
        LearnerConfigError,
        LearnerSpec,
        learner_spec,
    )

_HOMES = {
    "STATE_FORMAT": "base",
    "ActionEstimate": "base",
    "LearningAutomaton": "base",
    "RateAutomaton": "base",
    "make_learner": "config",
    "FixedChoice": "fixed",
    "LinearRewardInaction": "lri",
    "OPTIMISTIC_QUANTILE": "pursuit",
    "PursuitAutomaton": "pursuit",
    "Learner": "registry",
    "automaton_from_state": "state",
    "state_from_json": "state",
    "state_to_json": "state",
    "task_seed": "state",
    "DEFAULT_RATES": "validation",
    "DEFAULT_WARMUP": "validation",
    "ESTIMATORS": "validation",
    "SCHEMES": "validation",
    "LearnerConfigError": "validation",
    "LearnerSpec": "validation",
    "learner_spec": "validation",
}

__all__ = [
    "DEFAULT_RATES",
    "DEFAULT_WARMUP",
    "ESTIMATORS",
    "OPTIMISTIC_QUANTILE",
    "SCHEMES",
    "STATE_FORMAT",
    "ActionEstimate",
    "FixedChoice",
    "Learner",
    "LearnerConfigError",
    "LearnerSpec",
    "LearningAutomaton",
    "LinearRewardInaction",
    "PursuitAutomaton",
    "RateAutomaton",
    "automaton_from_state",
    "learner_spec",
    "make_learner",
    "state_from_json",
    "state_to_json",
    "task_seed",
]


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))
