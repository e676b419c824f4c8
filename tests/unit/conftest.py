"""Unit tests touch no network: an inet socket that binds or connects here fails the test.

The pure parts (net, engine, protocol, node core, learning, analyses, algorithms) are tested without
sockets; tests that need loopback TCP live in ``tests/loopback``, and tests that start real node
processes in ``tests/integration``. (An asyncio event loop's internal socket pair is a Unix socket
and stays allowed.)
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import pytest

_INET = (socket.AF_INET, socket.AF_INET6)


def _refuse(original: Any) -> Any:
    def guarded(self: socket.socket, *args: Any) -> Any:
        if self.family in _INET:
            raise AssertionError("a unit test opened a network connection; put it in tests/loopback")
        return original(self, *args)
    return guarded


@pytest.fixture(autouse=True)
def _no_network(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    for name in ("bind", "connect", "connect_ex"):
        monkeypatch.setattr(socket.socket, name, _refuse(getattr(socket.socket, name)))
    yield
