"""Waiting on events in integration tests: poll a condition or a node's log, fail only after a
generous timeout (the machine is shared: never assert how fast something happened)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

from conftest import Cluster


async def eventually(what: str, cond: Callable[[], bool], timeout_s: float = 20.0) -> None:
    """Wait until ``cond()`` holds; fail naming ``what`` after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"not true after {timeout_s} s: {what}")
        await asyncio.sleep(0.02)


async def log_says(cluster: Cluster, name: str, text: str, timeout_s: float = 20.0) -> None:
    """Wait until node ``name``'s log contains ``text``."""
    try:
        await eventually(f"{text!r} in the log of {name}", lambda: text in cluster.log(name), timeout_s)
    except AssertionError as exc:
        raise AssertionError(f"{exc}\n{cluster.log(name)[-3000:]}") from None
