"""Performance function of a robotic task (paper section 3, equation 1).

J = 1 − R + ρ·C, where R is the reliability of a primitive action (probability that it meets its
specifications), C its cost (CPU time, actual execution time or any a-priori unit), and ρ a weight
such that ρ·C ∈ [0, 1]; the paper's typical choice is ρ = 1 / max_{a ∈ A} C(a) over the primitive
actions A of a primitive task.

This module is pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["cost_function", "rho_for"]


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
