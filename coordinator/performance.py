"""Performance function of a robotic task (paper section 3, equation 1); pure, no I/O.

J = 1 − R + ρ·C (eq. 1), where R is the reliability of a primitive action (probability that it
meets its specifications), C its cost (CPU time, actual execution time or any a-priori unit), and ρ
a weight such that ρ·C ∈ [0, 1]; the paper's typical choice is ρ = 1 / max_{a ∈ A} C(a) over the
primitive actions A of a primitive task, which also makes costs of different units comparable
across primitive tasks. J lies in [0, 2] and **lower is better**: 0 for an action that always meets
its specifications at no cost. The function comes from P. U. Lima and G. N. Saridis, *Design of
Intelligent Control Systems Based on Hierarchical Stochastic Automata*, World Scientific, 1996
(reference [3] of the paper).

**One definition of C and ρ**, used by the learning automata (section 4, :mod:`coordinator.learning`),
``petrobot learn`` and ``petrobot perf`` alike:

* C of one result (:func:`result_cost`): the cost figure the action reported, else its wall-clock
  time on the node (s). C(a) of an action: the mean over its results; but when the net file gives
  every action of the task an a-priori ``cost`` (and its learner does not say ``cost_source =
  "measured"``), C(a) is that a-priori cost, as the paper computes it.
* ρ of a primitive task (:func:`task_rho`): the ``rho`` its learner declares; else 1 / max_a C(a) over
  its actions (the paper's typical ρ); but for a task of a single action, whose 1 / C(a) would make
  ρC = 1 whatever the action costs (J = 2 − R, blind to cost), ρ = 1 / its ``deadline_s`` when its
  costs are measured times (ρC: the share of its time budget the action uses; :func:`cost_budget`),
  else 0 (no deadline, or a-priori costs a deadline does not bound: J = 1 − R, nothing to weigh the
  cost against).

``perf --cost wall|cpu|cost|apriori`` replaces the first rule by one measure for every action.

Formulas used here, each with its source:

* primitive action (paper section 3): ``R(a) = n_success(a) / n(a)`` over the journal's results
  (``failure`` and ``error`` both fail the specifications, section 4); C(a) and ρ as above;
  ``J(a) = 1 − R(a) + ρ C(a)``.
* primitive task: with a probability ``p(a)`` of choosing each action, ``R = Σ p(a) R(a)``,
  ``C = Σ p(a) C(a)`` and ``J = 1 − R + ρ C = Σ p(a) J(a)`` (J is linear in R and C). By default
  ``p`` puts all its mass on the action of least J: the estimator automaton of section 4 converges
  to that action with probability one, so this is the task's performance once learning is done.
  A learner's current probabilities (or the journal's frequencies of use) can be passed instead.
* task (paper section 2, through the GSPN view): R = probability of reaching the goal marking
  (absorption probability), C = mean time to absorption (task execution time), computed by
  :mod:`coordinator.analysis.gspn` on the P-timed net of :mod:`coordinator.analysis.ptimed`
  (M. Ajmone Marsan et al., *Modelling with Generalized Stochastic Petri Nets*, Wiley, 1995);
  ρ = 1 / C_max with C_max the mean time to absorption when every primitive task uses its costliest
  action — the same normalisation as for a primitive task, one level up. That propagation is an
  analysis: :func:`coordinator.analysis.gspn_performance.gspn_task_performance` (the analysis
  imports this module, never the other way).

Records: :class:`ActionRecord` is one result of a primitive action, what these formulas need; the
journal gives each of its results as one (:attr:`coordinator.journal.ResultRow.record`,
:func:`coordinator.journal.read_results`). This module opens no file.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from coordinator.net import PetriNet
from services.results import Status

__all__ = [
    "COST_MEASURES",
    "MEASURED_TIMES",
    "ActionPerformance",
    "ActionRecord",
    "TaskPerformance",
    "action_performance",
    "cost_budget",
    "cost_function",
    "error_sink_places",
    "is_goal",
    "result_cost",
    "rho_for",
    "task_performance",
    "task_rho",
    "usage_frequencies",
]

#: Cost measures: ``learner`` (C as the learning automata take it: see the module docstring),
#: ``wall`` (``wall_s``), ``cpu`` (``cpu_s``), ``cost`` (the action's reported cost), ``apriori``
#: (the net file's ``cost`` of each action).
COST_MEASURES = ("learner", "wall", "cpu", "cost", "apriori")
#: The measures that are times in seconds, which a primitive task's deadline bounds.
MEASURED_TIMES = frozenset({"learner", "wall", "cpu"})


def result_cost(cost: float | None, wall_s: float | None) -> float | None:
    """C of one result of a primitive action (section 3): the cost figure the action reported, else
    its wall-clock time on the node in seconds; ``None`` when it has neither.

    This is what the learning automata are fed (:meth:`coordinator.learning.Learner.update`) and what
    ``petrobot learn`` and ``petrobot perf`` read back from the journal.
    """
    return cost if cost is not None else wall_s


def cost_budget(deadline_s: float | None, actions: int, *, measured_time: bool) -> float | None:
    """The cost a single-action primitive task weighs its action's cost against: its deadline (s).

    Args:
        deadline_s: the primitive task's deadline in seconds, or ``None``.
        actions: how many primitive actions translate the task.
        measured_time: whether C is a measured time in seconds (not an a-priori or reported figure
            of another unit, which a deadline does not bound).

    Returns:
        ``deadline_s`` for a task of one action whose costs are measured times, else ``None``.
    """
    return deadline_s if actions == 1 and measured_time else None


def task_rho(costs: Iterable[float], *, actions: int, declared: float | None = None,
             budget: float | None = None) -> float:
    """ρ of a primitive task in J = 1 − R + ρC (paper section 3, eq. 1; the module docstring).

    Args:
        costs: the known costs C(a) ≥ 0 of the task's actions (those not known yet left out).
        actions: how many primitive actions translate the task.
        declared: the ``rho`` the task's learner declares, or ``None``.
        budget: :func:`cost_budget` (a single action's deadline, s), or ``None``.

    Returns:
        ρ in 1/cost-unit: ``declared``; else with one action ``1 / budget`` (0 without a budget);
        else :func:`rho_for` of ``costs`` (0 when no cost is known yet).

    Raises:
        ValueError: a negative cost or ρ, or a budget that is not > 0.
    """
    if declared is not None:
        if declared < 0:
            raise ValueError(f"rho must be >= 0, got {declared}")
        return float(declared)
    if actions == 1:
        if budget is None:
            return 0.0
        if not budget > 0:
            raise ValueError(f"a cost budget must be > 0, got {budget}")
        return 1.0 / budget
    known = list(costs)
    return rho_for(known) if known else 0.0


def cost_function(reliability: float, cost: float, rho: float) -> float:
    """Return J = 1 − R + ρ·C (paper section 3, eq. 1).

    Args:
        reliability: R ∈ [0, 1], probability that the primitive action meets its specifications.
        cost: C ≥ 0, in the primitive task's cost unit (seconds of CPU or wall time, frames...).
        rho: ρ ≥ 0, weight in 1/cost-unit, usually :func:`rho_for` of the task's actions.

    Returns:
        J, dimensionless; lower is better.

    Raises:
        ValueError: if R is outside [0, 1], or C or ρ is negative.
    """
    if not 0.0 <= reliability <= 1.0:
        raise ValueError(f"reliability must lie in [0, 1], got {reliability}")
    if cost < 0.0 or rho < 0.0:
        raise ValueError(f"cost and rho must be non-negative, got C={cost}, rho={rho}")
    return 1.0 - reliability + rho * cost


def rho_for(costs: Iterable[float]) -> float:
    """Return ρ = 1 / max C(a) over a primitive task's actions (paper section 3).

    Args:
        costs: the costs C(a) ≥ 0 of the primitive actions of one primitive task.

    Returns:
        ρ in 1/cost-unit; 0.0 when every cost is 0 (cost then plays no part in J).

    Raises:
        ValueError: if ``costs`` is empty or holds a negative value.
    """
    values = list(costs)
    if not values:
        raise ValueError("rho_for needs at least one cost")
    if min(values) < 0.0:
        raise ValueError(f"costs must be non-negative, got {min(values)}")
    top = max(values)
    return 0.0 if top == 0.0 else 1.0 / top


@dataclass(frozen=True, slots=True, kw_only=True)
class ActionRecord:
    """One result of a primitive action: what the performance function needs of it.

    Attributes:
        task: primitive task name.
        action: primitive action name.
        status: success, failure or error (a string is converted to :class:`Status`).
        outcome: the named outcome the action reported, or None.
        cost: cost reported by the action, or None.
        wall_s: actual execution time in s, or None.
        cpu_s: CPU time in s, or None.

    Raises:
        ValueError: a status that is not success, failure or error.
    """

    task: str
    action: str
    status: Status
    outcome: str | None = None
    cost: float | None = None
    wall_s: float | None = None
    cpu_s: float | None = None

    def __post_init__(self) -> None:
        if type(self.status) is not Status:
            object.__setattr__(self, "status", Status(self.status))

    def measure(self, which: str) -> float | None:
        """The cost measure ``which`` (``learner``, ``wall``, ``cpu`` or ``cost``) of this result, or None."""
        if which == "learner":
            return result_cost(self.cost, self.wall_s)
        return {"wall": self.wall_s, "cpu": self.cpu_s, "cost": self.cost}.get(which)


def _mean(values: Sequence[float]) -> float:
    """Arithmetic mean of a non-empty sequence, as ``numpy.mean`` computes it (pairwise sums).

    ``numpy`` is imported on the first call: loading a net for ``petrobot check`` or building the
    command line's parser does not pay for it.
    """
    import numpy as np

    return float(np.mean(values))


@dataclass(frozen=True, slots=True)
class ActionPerformance:
    """R, C, ρ and J of one primitive action (paper section 3).

    Attributes:
        task, action: names.
        runs: results in the journal; successes, failures, errors: their split by status.
        reliability: R, or None when there is neither a result nor an a-priori value.
        cost: C in the task's cost unit, or None when unknown.
        rho: ρ of the primitive task (1/cost-unit).
        j: J = 1 − R + ρC, or None when R or C is unknown.
        source: where R and C come from (``journal``, ``apriori``).
    """

    task: str
    action: str
    runs: int
    successes: int
    failures: int
    errors: int
    reliability: float | None
    cost: float | None
    rho: float
    j: float | None
    source: str


@dataclass(frozen=True, slots=True)
class TaskPerformance:
    """R, C, ρ and J of a primitive task or a task.

    Attributes:
        name: primitive task name, or the net's name for the task.
        reliability: R; cost: C; rho: ρ; j: J (None when unknown).
        basis: how it was propagated (``best action a``, ``mixture``, ``gspn``).
    """

    name: str
    reliability: float | None
    cost: float | None
    rho: float
    j: float | None
    basis: str


def action_performance(
    net: PetriNet, records: Iterable[ActionRecord], *, measure: str = "learner"
) -> dict[str, dict[str, ActionPerformance]]:
    """R, C, ρ, J of every primitive action of ``net`` from journal results.

    C is the mean of ``measure`` over the action's results when it has some, else the a-priori
    ``cost`` of the action (always with ``measure="apriori"``; with ``"learner"`` whenever the task
    gives every action an a-priori cost and its learner does not say ``cost_source = "measured"``).
    ρ is :func:`task_rho`. R is the relative frequency of success; without results it falls back
    on the primitive task's a-priori ``reliability``.

    Args:
        net: the task net (its primitive tasks and their actions).
        records: the journal's results; results of unknown tasks or actions are ignored.
        measure: one of :data:`COST_MEASURES` (default: as the learners take it).

    Returns:
        ``{task: {action: ActionPerformance}}``.

    Raises:
        ValueError: on an unknown measure.
    """
    if measure not in COST_MEASURES:
        raise ValueError(f"unknown cost measure {measure!r}: use one of {', '.join(COST_MEASURES)}")
    grouped: dict[tuple[str, str], list[ActionRecord]] = {}
    for rec in records:
        grouped.setdefault((rec.task, rec.action), []).append(rec)
    out: dict[str, dict[str, ActionPerformance]] = {}
    for name, task in net.tasks.items():
        apriori = measure == "apriori" or (
            measure == "learner" and all(spec.cost is not None for spec in task.actions)
            and task.learner.get("cost_source") != "measured")
        rows = []
        for spec in task.actions:
            recs = grouped.get((name, spec.name), [])
            counts = {s: sum(1 for r in recs if r.status == s) for s in ("success", "failure", "error")}
            values = [v for r in recs if (v := r.measure(measure)) is not None] if not apriori else []
            cost = _mean(values) if values else spec.cost
            rel = counts["success"] / len(recs) if recs else task.reliability
            source = ("journal" if recs else "apriori") + "/" + ("journal" if values else "apriori")
            rows.append((spec.name, len(recs), counts, rel, cost, source))
        known = [c for *_, c, _ in rows if c is not None]
        declared = task.learner.get("rho")
        budget = cost_budget(task.deadline_s, len(task.actions), measured_time=measure in MEASURED_TIMES
                             and not apriori)
        rho = task_rho(known, actions=len(task.actions), declared=None if declared is None else float(declared),
                       budget=budget)
        out[name] = {
            a: ActionPerformance(
                task=name, action=a, runs=n, successes=c["success"], failures=c["failure"],
                errors=c["error"], reliability=r, cost=cost, rho=rho,
                j=cost_function(r, cost, rho) if r is not None and cost is not None else None, source=src,
            )
            for a, n, c, r, cost, src in rows
        }
    return out


def usage_frequencies(records: Iterable[ActionRecord]) -> dict[str, dict[str, float]]:
    """Relative frequency with which each action of each primitive task was run: ``{task: {action: p}}``."""
    counts: dict[str, dict[str, int]] = {}
    for rec in records:
        counts.setdefault(rec.task, {}).setdefault(rec.action, 0)
        counts[rec.task][rec.action] += 1
    return {t: {a: n / sum(c.values()) for a, n in c.items()} for t, c in counts.items()}


def task_performance(
    actions: Mapping[str, ActionPerformance], *, probabilities: Mapping[str, float] | None = None
) -> TaskPerformance:
    """Propagate the actions' R, C, J to their primitive task (see the module docstring).

    Args:
        actions: ``{action: ActionPerformance}`` of one primitive task.
        probabilities: probability of choosing each action (e.g. the learner's current ones);
            None picks the action of least J (where the learning automaton converges).

    Returns:
        :class:`TaskPerformance` (R, C, J None when no action has them).

    Raises:
        ValueError: if no action is given or the probabilities do not sum to 1.
    """
    if not actions:
        raise ValueError("task_performance needs at least one action")
    first = next(iter(actions.values()))
    rho = first.rho
    if probabilities is None:
        scored = [a for a in actions.values() if a.j is not None]
        if not scored:
            return TaskPerformance(first.task, None, None, rho, None, "no action has both R and C")
        best = min(scored, key=lambda a: (a.j, a.action))
        return TaskPerformance(first.task, best.reliability, best.cost, rho, best.j, f"best action {best.action}")
    total = sum(probabilities.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"action probabilities must sum to 1, got {total}")
    used = [(p, actions[a]) for a, p in probabilities.items() if p > 0 and a in actions]
    if any(a.reliability is None or a.cost is None for _, a in used):
        return TaskPerformance(first.task, None, None, rho, None, "mixture with an unknown R or C")
    rel = sum(p * (a.reliability or 0.0) for p, a in used)
    cost = sum(p * (a.cost or 0.0) for p, a in used)
    return TaskPerformance(first.task, rel, cost, rho, cost_function(min(max(rel, 0.0), 1.0), cost, rho), "mixture")


def error_sink_places(net: PetriNet) -> set[str]:
    """Places whose only input transitions are error exits (``int:<task>.error``), e.g. a count of
    aborted runs: a dead marking that marks one is not the task's goal."""
    feeders: dict[str, list[bool]] = {}
    for t in net.transitions:
        is_error = any(e.endswith(".error") for e in t.internal_events)
        for pid in net.output_places[t.id]:
            feeders.setdefault(pid, []).append(is_error)
    return {p for p, flags in feeders.items() if flags and all(flags)}


def is_goal(marking: Mapping[str, int], goal: Mapping[str, int] | None, sinks: set[str]) -> bool:
    """Tell whether a dead marking is a goal: it holds at least ``goal[p]`` tokens in each place of
    ``goal`` when given, else it marks no error-sink place (:func:`error_sink_places`)."""
    if goal:
        return all(marking.get(p, 0) >= n for p, n in goal.items())
    return not any(marking.get(p, 0) for p in sinks)
