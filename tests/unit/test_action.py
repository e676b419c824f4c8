"""The primitive-action lifecycle helpers (services.action) and the memory store."""

from __future__ import annotations

import pytest

from services.errors import ActionError
from services.action import (
    FunctionAction,
    PrimitiveAction,
    import_impl,
    make_action,
)
from services.results import ActionResult, Status
from services.actions.demo import ComputePrimes, count_primes_below
from services.actions.memory import MemoryStore, memory_actions


def test_a_result_refuses_an_unknown_status_a_bad_outcome_and_a_negative_duration() -> None:
    assert ActionResult.failure(outcome="missed").status is Status.FAILURE
    assert ActionResult(status="success").status is Status.SUCCESS  # type: ignore[arg-type]
    with pytest.raises(ActionError, match="status"):
        ActionResult(status="maybe")  # type: ignore[arg-type]
    with pytest.raises(ActionError, match="identifier"):
        ActionResult.success(outcome="not an identifier")
    with pytest.raises(ActionError, match="durations"):
        ActionResult(status=Status.SUCCESS, wall_s=-1.0)
    with pytest.raises(ActionError, match="cost"):
        ActionResult.success(cost=float("nan"))


def test_a_result_latches_ok_and_its_status_and_its_named_outcome() -> None:
    assert ActionResult.success().events == {"ok", "success"}
    assert ActionResult.failure(outcome="tails").events == {"ok", "failure", "tails"}
    assert ActionResult.error("node lost").events == {"error"}
    assert not ActionResult.error("x").ok and ActionResult.failure().ok


def test_make_action_accepts_a_class_an_instance_and_an_async_function() -> None:
    assert isinstance(make_action("services.actions.demo:ComputePrimes", "primes"), ComputePrimes)
    fn = make_action("services.actions.demo:echo", "echo")
    assert isinstance(fn, FunctionAction) and fn.name == "echo"
    assert isinstance(make_action("services.actions.demo:ComputePrimes", "x"), PrimitiveAction)


def test_make_action_names_what_cannot_be_imported() -> None:
    with pytest.raises(ActionError, match="cannot import"):
        import_impl("services.actions.demo:nope")
    with pytest.raises(ActionError, match="cannot import"):
        import_impl("no_such_module_anywhere:thing")
    with pytest.raises(ActionError, match="neither"):
        make_action("services.actions.demo:count_primes_below", "x")


def test_the_prime_sieve_counts_correctly() -> None:
    assert [count_primes_below(n) for n in (0, 2, 3, 10, 100, 1000)] == [0, 0, 1, 4, 25, 168]


async def test_the_memory_store_serves_get_set_and_keys() -> None:
    store = MemoryStore()
    acts = memory_actions(store)
    await acts["memory.set"].run({"key": "b", "value": [1]}, None)  # type: ignore[arg-type]
    await acts["memory.set"].run({"key": "a", "value": 2}, None)  # type: ignore[arg-type]
    got = await acts["memory.get"].run({"key": "b"}, None)  # type: ignore[arg-type]
    missing = await acts["memory.get"].run({"key": "z", "default": 0}, None)  # type: ignore[arg-type]
    keys = await acts["memory.keys"].run({}, None)  # type: ignore[arg-type]
    assert (got.value, missing.value, keys.value) == ([1], 0, ["a", "b"])
    with pytest.raises(ActionError):
        await acts["memory.set"].run({"key": "c"}, None)  # type: ignore[arg-type]
