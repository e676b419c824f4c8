"""Ports for the servers the tests start, picked outside the kernel's ephemeral port range.

A port found free by binding port 0 and closing the socket lies in the ephemeral range
(``/proc/sys/net/ipv4/ip_local_port_range``, 32768–60999 by default). Before the server the test
starts binds it, the kernel may give that same port to anything else: a simulator's own server on
port 0, or the local end of any outgoing connection. The server then fails with "Address already in
use". A port outside that range is never handed out by the kernel, so only an explicit bind can
take it, and :func:`free_port` never gives the same port twice in one process.
"""

from __future__ import annotations

import functools
import random
import socket
from pathlib import Path

__all__ = ["free_port"]

_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
_LOWEST = 10_000
"""No port below this is picked (well-known and registered services crowd the low ports)."""
_TRIES = 200

_given: set[int] = set()
_rng = random.Random()


@functools.cache
def _outside_ephemeral() -> tuple[range, ...]:
    """The port ranges at or above :data:`_LOWEST` outside the ephemeral range; empty when it has none."""
    try:
        low, high = (int(v) for v in _RANGE_FILE.read_text().split())
    except (OSError, ValueError):
        low, high = 32768, 60999  # Linux's default
    return tuple(r for r in (range(_LOWEST, low), range(high + 1, 65536)) if len(r) > 0)


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` now, outside the ephemeral range, and not given before in this process.

    Raises:
        OSError: no free port found in :data:`_TRIES` draws, nor from the kernel.
    """
    ranges = _outside_ephemeral()
    for _ in range(_TRIES if ranges else 0):
        r = _rng.choice(ranges)
        port = _rng.randrange(r.start, r.stop)
        if port in _given:
            continue
        with socket.socket() as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
        _given.add(port)
        return port
    with socket.socket() as s:  # no range outside the ephemeral one: the kernel's pick, as a last resort
        s.bind((host, 0))
        port = int(s.getsockname()[1])
    _given.add(port)
    return port
