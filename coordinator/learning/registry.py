"""The learners of one task net: one automaton per primitive task (paper section 4).

:class:`Learner` is what the runtime talks to: it chooses the primitive action of each new
instance of a primitive task (it is the engine's chooser) and takes in each result, returning the
task's new state for the journal. On a restart of the coordinator, :meth:`Learner.restore` takes
the saved states back. Pure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from coordinator.errors import JournalError
from coordinator.learning.base import LearningAutomaton
from coordinator.learning.config import make_learner
from coordinator.learning.state import automaton_from_state, task_seed
from coordinator.learning.validation import LearnerConfigError
from coordinator.net import PetriNet
from coordinator.performance import result_cost
from services.results import ActionResult

__all__ = ["Learner"]


class Learner:
    """One learning automaton per primitive task: the runtime's single entry point (section 4).

    Args:
        seed: run seed; task ``t``'s automaton is seeded with ``task_seed(seed, t)``.
    """

    def __init__(self, seed: int = 0) -> None:
        self._seed = int(seed)
        self._automata: dict[str, LearningAutomaton] = {}
        self._configs: dict[str, tuple[dict[str, Any], dict[str, float] | None, float | None]] = {}

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
        cost_budget: float | None = None,
    ) -> LearningAutomaton:
        """Create the automaton of ``task`` with :func:`make_learner` and register it (``cost_budget``:
        a single-action task's deadline, see :func:`make_learner`).

        Raises:
            LearnerConfigError: on a bad configuration, or if the task is already registered.
        """
        if task in self._automata:
            raise LearnerConfigError(f"primitive task {task!r} already has a learner")
        auto = make_learner(config or {}, actions, costs, task_seed(self._seed, task), cost_budget)
        self._automata[task] = auto
        self._configs[task] = (dict(config or {}), None if costs is None else dict(costs), cost_budget)
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
    def from_net(cls, net: PetriNet, seed: int = 0) -> Learner:
        """One automaton per primitive task of a :class:`coordinator.net.PetriNet`.

        Uses each task's ``learner`` table as the configuration (:func:`make_learner`), the
        actions' a-priori ``cost`` values as costs (none given: measured costs) and, for a task of a
        single action, its ``deadline_s`` as the cost budget of ρ
        (:func:`coordinator.performance.task_rho`).

        Raises:
            LearnerConfigError: naming the primitive task, on a bad ``learner`` table or on costs
                given for some of a task's actions only.
        """
        learner = cls(seed)
        for name, task in net.tasks.items():
            names = [spec.name for spec in task.actions]
            given = {spec.name: spec.cost for spec in task.actions if spec.cost is not None}
            try:
                learner.add_task(name, names, dict(task.learner), given or None,
                                 task.deadline_s if len(names) == 1 else None)
            except LearnerConfigError as exc:
                raise LearnerConfigError(f"primitive task {name!r}: {exc.problem}") from None
        return learner

    def update(self, task: str, action: str, result: ActionResult) -> dict[str, Any]:
        """Feed back one result and return the task's new state dict (to persist at once).

        The cost of the run is :func:`coordinator.performance.result_cost`: the action's own cost
        figure, else its measured duration on the node (``wall_s``).

        Raises:
            KeyError: if the task has no automaton.
            ValueError: on an unknown action.
        """
        auto = self._automata[task]
        auto.update(action, result.status, result_cost(result.cost, result.wall_s))
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
            config, costs, budget = self._configs[task]
            fresh = make_learner(config, current.actions, costs, task_seed(self._seed, task), budget)
            try:
                fresh.restore_counts(state)
            except (KeyError, TypeError, ValueError) as exc:
                raise JournalError(f"malformed learner state of {task!r}: {exc}") from exc
            self._automata[task] = fresh
        return skipped
