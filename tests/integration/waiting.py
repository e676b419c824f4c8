"""Waiting on events in integration tests: poll a condition or a node's log, fail only after a
generous timeout (the machine is shared: never assert how fast something happened)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path

from tests.integration.cluster import Cluster


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


def file_says(path: Path, text: str, timeout_s: float = 60.0) -> None:
    """Wait (blocking; for tests that drive processes synchronously) until the file at ``path``
    exists and contains ``text``; fail with the file's tail after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not (path.exists() and text in path.read_text(errors="replace")):
        if time.monotonic() > end:
            tail = path.read_text(errors="replace")[-3000:] if path.exists() else "(no such file)"
            raise AssertionError(f"{path.name} has no {text!r} after {timeout_s} s:\n{tail}")
        time.sleep(0.05)
