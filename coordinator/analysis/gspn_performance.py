"""R, C, ρ and J of a whole task through its GSPN view (paper sections 2 and 3); pure.

The task's reliability R is the probability that the P-timed GSPN of the task
(:mod:`coordinator.analysis.ptimed`) is absorbed in a goal marking, its cost C the mean time to
absorption (:mod:`coordinator.analysis.gspn`), and ρ = 1 / C_max with C_max the mean time to
absorption when every primitive task takes the mean time of its slowest action: the
normalisation of :mod:`coordinator.performance` one level up. The records are the journal's
results (:class:`coordinator.performance.ActionRecord`); this module opens no file.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from coordinator.analysis.gspn import analyse
from coordinator.analysis.ptimed import task_stats, to_gspn
from coordinator.net import PetriNet
from coordinator.performance import (
    ActionRecord,
    TaskPerformance,
    error_sink_places,
    is_goal,
)

__all__ = ["gspn_task_performance"]


def gspn_task_performance(
    net: PetriNet,
    records: Iterable[ActionRecord] = (),
    *,
    ext_rates: Mapping[str, float] | None = None,
    goal: Mapping[str, int] | None = None,
) -> tuple[TaskPerformance, dict[str, object]]:
    """R, C, ρ, J of the whole task through its P-timed GSPN (see the module docstring).

    Args:
        net: the interpreted task net; it must terminate (e.g. a finite number of runs).
        records: journal results (times and reliabilities; a-priori values otherwise).
        ext_rates: rate in 1/s per external topic.
        goal: minimum tokens per place of a goal marking; default: a dead marking that marks no
            place fed only by error exits.

    Returns:
        ``(TaskPerformance, details)`` with ``details`` holding ``goal_markings`` (each with its
        probability), ``c_max`` (s) and the P-timed model's ``warnings``. R, C and J are None when
        the GSPN does not terminate.

    Raises:
        AnalysisError: as :func:`coordinator.analysis.gspn.analyse`.
    """
    recs = list(records)
    stats = task_stats(recs)
    model = to_gspn(net, stats=stats, ext_rates=ext_rates)
    result = analyse(model.net)
    details: dict[str, object] = {"warnings": model.warnings, "means_s": model.means, "normal": model.normal}
    if not result.terminates or result.mean_time_to_absorption is None:
        return TaskPerformance(net.name, None, None, 0.0, None, "gspn does not terminate"), details
    sinks = error_sink_places(net)
    goals = [a for a in result.absorption if is_goal(a["marking"], goal, sinks)]
    rel = min(1.0, sum(float(a["probability"]) for a in goals))
    cost = float(result.mean_time_to_absorption)
    # Worst case: each primitive task at the mean time of its slowest action.
    worst: dict[str, float] = {}
    for name in net.tasks:
        per_action: dict[str, list[float]] = {}
        for r in recs:
            if r.task == name and r.wall_s is not None:
                per_action.setdefault(r.action, []).append(r.wall_s)
        means = [float(np.mean(v)) for v in per_action.values()]
        worst[name] = max(means) if means else model.means[name]
    c_max = float(analyse(to_gspn(net, stats=stats, ext_rates=ext_rates, means=worst).net).mean_time_to_absorption
                  or cost)
    rho = 1.0 / c_max if c_max > 0 else 0.0
    details.update(goal_markings=goals, c_max=c_max)
    return TaskPerformance(net.name, rel, cost, rho, 1.0 - rel + rho * cost, "gspn"), details
