"""Small real primitive actions for the foundation demo, the tests and the RPC benchmark.

* ``echo``: returns its params (the benchmark's action: the protocol's own cost);
* ``wait``: waits ``seconds`` on the event loop, sending progress feedback, honouring cancel;
* ``compute_primes``: counts primes below ``n`` with a sieve in a worker thread (real CPU work;
  cost = CPU seconds of that work);
* ``coin``: a seeded Bernoulli draw returning success / failure / error, to exercise net branches;
* ``fail``: raises, to exercise the node's exception path;
* ``remember``: writes a value to the global memory and reads it back (memory service demo);
* ``tally``: increments a counter in the global memory and returns it (shows a call ran once);
* ``announce``: publishes an external event from the node;
* :class:`Ticker`: a driver publishing a ``tick`` event every ``period_s`` seconds.
"""

from __future__ import annotations

import asyncio
import math
import random
import time
from typing import Any

from services.action import (
    CallContext,
    Driver,
    NodeContext,
    PrimitiveAction,
)
from services.results import ActionResult, Status

__all__ = [
    "ComputePrimes", "Ticker", "announce", "coin", "count_primes_below", "echo", "fail", "remember", "tally", "wait",
]


async def echo(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Return ``params`` unchanged as the value; status success."""
    return ActionResult(status=Status.SUCCESS, value=params)


async def wait(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Wait ``params["seconds"]`` (default 1.0 s), reporting progress ``{"fraction": f}`` every ``step`` s.

    The clock is read once per step, for both the feedback and the test for the end, so the last
    feedback of a wait that ran its course is exactly ``{"fraction": 1.0}``.
    Cancellation and the deadline cut the wait short (the CancelledError propagates).
    """
    seconds = float(params.get("seconds", 1.0))
    step = max(0.001, float(params.get("step", 0.1)))
    loop = asyncio.get_running_loop()
    start = now = loop.time()
    end = start + seconds
    while now < end:
        await asyncio.sleep(min(step, end - now))
        now = loop.time()
        ctx.feedback({"fraction": min(1.0, (now - start) / seconds)})
    return ActionResult(status=Status.SUCCESS, value={"waited_s": loop.time() - start}, cost=seconds)


def count_primes_below(n: int) -> int:
    """Number of primes p < n (sieve of Eratosthenes; O(n log log n) time, n bytes of memory)."""
    import numpy as np  # here, so that nodes not hosting this action start faster

    if n < 3:
        return 0
    sieve = np.ones(n, dtype=bool)
    sieve[:2] = False
    for p in range(2, math.isqrt(n - 1) + 1):
        if sieve[p]:
            sieve[p * p::p] = False
    return int(sieve.sum())


class ComputePrimes(PrimitiveAction):
    """Count primes below ``params["n"]`` (default 1,000,000) in a worker thread.

    The event loop stays free for heartbeats. Value ``{"n": n, "count": k}``; cost = CPU seconds of
    the sieve (thread CPU time).
    """

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        n = int(params.get("n", 1_000_000))
        if n < 0 or n > 200_000_000:
            return ActionResult(status=Status.FAILURE, outcome="bad_n", value={"n": n})

        def work() -> tuple[int, float]:
            c0 = time.thread_time()
            k = count_primes_below(n)
            return k, time.thread_time() - c0

        count, cpu = await asyncio.to_thread(work)
        return ActionResult(status=Status.SUCCESS, value={"n": n, "count": count}, cost=cpu)


async def coin(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """A seeded draw: success with ``p_success``, error with ``p_error``, else failure.

    Params: ``seed`` (int, default: the call id's hash), ``p_success`` (default 0.5), ``p_error``
    (default 0.0). Outcome ``"heads"`` on success and ``"tails"`` otherwise.
    """
    seed = params.get("seed")
    rng = random.Random(seed if seed is not None else ctx.call_id)
    u = rng.random()
    p_s = float(params.get("p_success", 0.5))
    p_e = float(params.get("p_error", 0.0))
    if u < p_s:
        return ActionResult(status=Status.SUCCESS, outcome="heads", value=u)
    if u < p_s + p_e:
        return ActionResult(status=Status.ERROR, outcome="tails", value=u)
    return ActionResult(status=Status.FAILURE, outcome="tails", value=u)


async def fail(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Raise RuntimeError(params["message"]) (the node turns it into status error)."""
    raise RuntimeError(str(params.get("message", "deliberate failure")))


async def remember(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Store ``params["value"]`` under ``params["key"]`` in the global memory and read it back."""
    key = str(params.get("key", "demo"))
    await ctx.memory.set(key, params.get("value"))
    return ActionResult(status=Status.SUCCESS, value=await ctx.memory.get(key))


async def tally(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Add 1 to the global-memory counter ``params["key"]`` (default ``"tally"``); value = new count."""
    key = str(params.get("key", "tally"))
    count = int(await ctx.memory.get(key, 0)) + 1
    await ctx.memory.set(key, count)
    return ActionResult(status=Status.SUCCESS, value=count)


async def announce(params: dict[str, Any], ctx: CallContext) -> ActionResult:
    """Publish external event ``params["topic"]`` with ``params.get("data")`` from this node."""
    ctx.publish(str(params["topic"]), params.get("data"))
    return ActionResult(status=Status.SUCCESS)


class Ticker(Driver):
    """Publishes ``params["topic"]`` (default ``"tick"``) every ``params["period_s"]`` (default 0.1 s).

    Event data: ``{"n": k}`` with k counting from 1.
    """

    def __init__(self, name: str, params: Any) -> None:
        super().__init__(name, params)
        self._task: asyncio.Task[None] | None = None

    async def setup(self, node: NodeContext) -> None:
        self._task = asyncio.get_running_loop().create_task(self._tick())

    async def _tick(self) -> None:
        topic = str(self.params.get("topic", "tick"))
        period = float(self.params.get("period_s", 0.1))
        n = 0
        while True:
            await asyncio.sleep(period)
            n += 1
            self.publish(topic, {"n": n})

    async def teardown(self) -> None:
        if self._task is not None:
            self._task.cancel()
