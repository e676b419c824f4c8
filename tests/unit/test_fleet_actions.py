"""The simulated fleet actions (services/actions/fleet.py): their exits, the failure probability,
the seeded draw and their params, called as a node calls them (no sockets)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from services.action import CallContext, NodeContext
from services.actions.fleet import FLEET_ACTIONS, simulated_task
from services.location import load_location
from services.results import Status

ROOT = Path(__file__).resolve().parents[2]


def context(call_id: str, feedback: list[Any], send: Callable[[Any], None] | None = None) -> CallContext:
    node = NodeContext(name="alpha", location=load_location(ROOT / "services.toml"), drivers={}, memory=None,  # type: ignore[arg-type]
                       publish=lambda topic, data: None, link=lambda name: None)  # type: ignore[arg-type,return-value]
    return CallContext(call_id=call_id, action="load_tote", deadline=None, peer="test", node=node,
                       feedback=send or feedback.append)


async def test_the_error_exit_comes_with_the_settable_probability_and_a_seed_repeats_the_draws() -> None:
    async def statuses(seed: int) -> list[Status]:
        out = []
        for k in range(200):
            res = await simulated_task({"seconds": 0, "p_error": 0.3, "seed": seed}, context(f"c{k}", []))
            out.append(res.status)
        return out

    first = await statuses(1)
    assert 30 < first.count(Status.ERROR) < 90 and set(first) == {Status.SUCCESS, Status.ERROR}
    assert await statuses(1) == first and await statuses(2) != first


async def test_a_task_takes_its_seconds_with_progress_and_ends_in_its_normal_or_its_error_exit() -> None:
    feedback: list[Any] = []
    ok = await simulated_task({"seconds": 0.05, "p_error": 0.0}, context("a", feedback))
    assert ok.status is Status.SUCCESS and ok.cost == 0.05 and "ok" in ok.events
    assert feedback and feedback[-1] == {"fraction": 1.0}
    err = await simulated_task({"seconds": 0, "p_error": 1.0}, context("b", []))
    assert err.status is Status.ERROR and err.events == {"error", "fault"} and "simulated fault" in (err.reason or "")


@pytest.mark.parametrize("params", [{"p_error": 1.5}, {"p_error": "x"}, {"seconds": -1}, {"seconds": True}])
async def test_params_out_of_range_are_a_clear_error(params: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match="must be a number between"):
        await simulated_task(params, context("c", []))


def test_services_toml_places_every_fleet_action_the_fleet_net_calls() -> None:
    from coordinator.netfile.fleet import fleet_toml
    from coordinator.netfile.loader import loads_net

    net = loads_net(fleet_toml(2, safe=True, missions=1))
    called = {a.name for task in net.tasks.values() for a in task.actions}
    assert called == set(FLEET_ACTIONS)
    location = load_location(ROOT / "services.toml")
    assert all(location.node_of(name) == "alpha" for name in FLEET_ACTIONS)


async def test_the_last_feedback_of_a_wait_is_one_on_a_coarse_clock_with_a_slow_feedback_send() -> None:
    """A loop woken by other work (here a timer every 0.2 ms, as a node's sockets wake it) runs timers
    up to its clock resolution early (5 ms here, as on a coarse clock), and a feedback send takes
    0.3 ms (a frame out on a busy host): the wait still ends on fraction 1.0."""
    from services.actions.demo import wait

    loop = asyncio.get_running_loop()
    loop._clock_resolution = 0.005  # type: ignore[attr-defined]  # the asyncio loop's own setting
    sent: list[Any] = []
    ticking = True

    def tick() -> None:
        if ticking:
            loop.call_later(0.0002, tick)

    def slow_send(data: Any) -> None:
        sent.append(data)
        time.sleep(0.0003)  # blocks the loop, as a slow send does

    tick()
    try:
        for k in range(20):
            sent.clear()
            await wait({"seconds": 0.03, "step": 0.01}, context(f"w{k}", [], slow_send))
            assert sent and sent[-1] == {"fraction": 1.0}, sent[-3:]
    finally:
        ticking = False
        loop._clock_resolution = time.get_clock_info("monotonic").resolution  # type: ignore[attr-defined]
