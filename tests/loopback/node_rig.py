"""A node served inside the test process on 127.0.0.1, and helpers to wait on conditions.

:func:`running_node` writes a services.toml for one node ``alpha`` (with a free port), starts a
:class:`services.node.Node` on the test's event loop and stops it afterwards::

    async with running_node(ACTIONS, peer_timeout_s=0.5) as node:
        async with ServiceClient(node.location, KEY) as client: ...
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from services.location import load_location
from services.node import Node
from tests.ports import free_port

KEY = bytes.fromhex("9c41e7d02b5f86a3147ed9c2058bf36e71a4d80c95e32fb6486a1dd7c0935e2b")
"""The shared key of the rig's node."""

ACTIONS = """
[actions.echo]
node = "alpha"
impl = "services.actions.demo:echo"

[actions.wait]
node = "alpha"
impl = "services.actions.demo:wait"

[actions.announce]
node = "alpha"
impl = "services.actions.demo:announce"
"""
"""The demo actions the rig's node hosts by default."""


@contextlib.asynccontextmanager
async def running_node(actions: str = ACTIONS, *, directory: Path | None = None, host: str = "127.0.0.1",
                       node_table: str = "", header: str = "", **kwargs: Any) -> AsyncIterator[Node]:
    """A started node ``alpha`` hosting ``actions`` (services.toml text); stopped on exit.

    Args:
        actions: the ``[actions.*]`` (and other) tables.
        directory: where services.toml is written (a fresh temporary one if ``None``).
        host: the node's address.
        node_table: extra lines of ``[nodes.alpha]``.
        header: text before ``[nodes.alpha]`` (e.g. a ``[tls]`` table).
        kwargs: passed to :class:`Node`.
    """
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        where = directory if directory is not None else Path(tmp)
        path = where / "services.toml"
        path.write_text(f'{header}\n[nodes.alpha]\nhost = "{host}"\nport = {free_port(host)}\n'
                        f"max_in_flight = 4\n{node_table}\n{actions}")
        node = Node("alpha", load_location(path), kwargs.pop("key", KEY), **kwargs)
        await node.start()
        try:
            yield node
        finally:
            await node.stop()


async def eventually(what: str, cond: Callable[[], bool], timeout_s: float = 10.0) -> None:
    """Wait until ``cond()`` holds, polling; fail naming ``what`` after a generous ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"not true after {timeout_s} s: {what}")
        await asyncio.sleep(0.01)
