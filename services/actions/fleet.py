"""Simulated primitive actions of the fleet net (``petrobot example fleet``, coordinator.netfile.fleet).

The fleet's primitive tasks (load, drive, ride the lift, unload, charge, recover) are carried out by
``load_tote``, ``drive_aisle``, ``ride_lift``, ``unload_tote``, ``charge_battery`` and
``manual_recovery``. No robot stands behind them here: each is :func:`simulated_task`, placed under
its own name in services.toml, which takes the time its params say, sends progress feedback, and
ends in its normal exit (status success: ``int:<task>.ok``) or, with the probability its params
say, in its error exit (status error: ``int:<task>.error``, the net's way into recovery).

Params (services.toml's ``params`` of the action, overridden by the net's per-action ``params``):

* ``seconds``: how long the task takes, s (default 0.1; 0 ≤ seconds ≤ 3600);
* ``p_error``: probability of the error exit, 0 ≤ p ≤ 1 (default 0.0);
* ``seed``: makes the draw reproducible for a given call id (default: drawn from the OS).
"""

from __future__ import annotations

import random
from typing import Any

from services.action import CallContext
from services.actions.demo import wait
from services.results import ActionResult

__all__ = ["FLEET_ACTIONS", "simulated_task"]

#: The primitive actions of the fleet net, one per primitive task (coordinator.netfile.fleet).
FLEET_ACTIONS = ("load_tote", "drive_aisle", "ride_lift", "unload_tote", "charge_battery", "manual_recovery")

_MAX_SECONDS = 3600.0


def _number(params: dict[str, Any], key: str, default: float, low: float, high: float) -> float:
    value = params.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise ValueError(f"param {key} must be a number between {low:g} and {high:g}, not {value!r}")
    return float(value)


async def simulated_task(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Take ``params["seconds"]``, then end in the error exit with ``params["p_error"]``, else succeed.

    Feedback ``{"fraction": f}`` (0 < f ≤ 1) every tenth of the duration (the ``wait`` action of
    :mod:`services.actions.demo`). Cost = the duration, s.
    Cancellation and the deadline cut the task short (the CancelledError propagates).

    Returns:
        Success with value ``{"seconds": s}``, or error with reason ``"simulated fault (p_error=p)"``
        and outcome ``fault`` (``int:<task>.fault`` as well as ``int:<task>.error``).

    Raises:
        ValueError: ``seconds`` or ``p_error`` outside its range (the node turns it into status error).
    """
    seconds = _number(params, "seconds", 0.1, 0.0, _MAX_SECONDS)
    p_error = _number(params, "p_error", 0.0, 0.0, 1.0)
    seed = params.get("seed")
    rng = random.Random(f"{seed}:{ctx.call_id}") if seed is not None else random.SystemRandom()
    faulty = rng.random() < p_error
    await wait({"seconds": seconds, "step": max(0.01, seconds / 10)}, ctx)
    if faulty:
        return ActionResult.error(f"simulated fault (p_error={p_error:g})", outcome="fault", cost=seconds)
    return ActionResult.success({"seconds": seconds}, cost=seconds)
