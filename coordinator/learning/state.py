"""Saved learner states (paper section 4): JSON text, rebuilding an automaton, per-task seeds.

The learning updates are deterministic functions of (action, status, cost): the random generator is
used only to draw actions. :func:`automaton_from_state` rebuilds an automaton whose probabilities,
estimates and future draws are those of the saved one, and replaying a journal's results through a
fresh automaton of the same configuration reproduces its probability vector exactly (``petrobot
learn`` relies on this). The journal stores one state per primitive task
(:meth:`coordinator.journal.Journal.save_learner`). Pure.
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from coordinator.errors import JournalError
from coordinator.learning.base import STATE_FORMAT, LearningAutomaton
from coordinator.learning.config import make_learner

__all__ = ["automaton_from_state", "state_from_json", "state_to_json", "task_seed"]


def automaton_from_state(state: Mapping[str, Any]) -> LearningAutomaton:
    """Rebuild an automaton from :meth:`LearningAutomaton.state_dict` output.

    The result has identical probabilities, counts, estimates, and random generator state (so its
    future draws are those the saved automaton would have made).

    Raises:
        JournalError: if the state is malformed, of an unknown scheme or format.
    """
    try:
        if state.get("format") != STATE_FORMAT:
            raise JournalError(f"learner state format {state.get('format')!r} is not supported")
        config = dict(state["config"])
        config["scheme"] = state["scheme"]
        auto = make_learner(config, list(state["actions"]), state["costs"], int(state["seed"]),
                            state.get("cost_budget"))
        auto.restore_counts(state)
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
    """Encode a state dict as JSON text (floats exact): the form the journal stores."""
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
