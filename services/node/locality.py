"""Whether a peer is on the node's own host, for ``local_only`` actions (docs/protocol.md §7).

A peer is local when its source address is one of this host's own addresses: a loopback address
(``127.0.0.0/8``, ``::1``), the address the connection was accepted on, or any other address of
the host's interfaces (a node bound to the alias ``127.0.0.5``, called from ``127.0.0.1``, is
called from its own host). "Is this address mine?" is asked of the kernel: binding a socket to an
address succeeds only for an address of this host (``EADDRNOTAVAIL`` otherwise). The answer is
cached per address. Where the host allows binding to foreign addresses
(``net.ipv4.ip_nonlocal_bind = 1``) the kernel's answer means nothing; then only loopback and the
accepting address count as local.
"""

from __future__ import annotations

import collections
import ipaddress
import socket
from collections.abc import Callable
from pathlib import Path

__all__ = ["Locality", "bindable"]

_NONLOCAL_BIND = Path("/proc/sys/net/ipv4/ip_nonlocal_bind")


def _nonlocal_bind_allowed() -> bool:
    try:
        return _NONLOCAL_BIND.read_text().strip() != "0"
    except OSError:
        return False


def bindable(ip: str) -> bool:
    """Whether a socket can be bound to ``ip`` (an address of this host), without listening."""
    try:
        addr = ipaddress.ip_address(ip.split("%", 1)[0])
    except ValueError:
        return False
    family = socket.AF_INET6 if addr.version == 6 else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.bind((ip, 0))
    except OSError:
        return False
    return True


class Locality:
    """Decides and caches whether peer addresses are this host's (see the module docstring).

    Args:
        own_address: "is this IP one of this host's?" (default: :func:`bindable`, unless the host
            allows binding foreign addresses).
        max_cached: addresses whose answer is kept.
    """

    def __init__(self, own_address: Callable[[str], bool] | None = None, max_cached: int = 1024) -> None:
        if own_address is None:
            own_address = (lambda ip: False) if _nonlocal_bind_allowed() else bindable
        self._own = own_address
        self._max = max_cached
        self._cache: collections.OrderedDict[str, bool] = collections.OrderedDict()

    def is_local(self, peer_ip: str, accepted_on: str) -> bool:
        """Whether a peer at ``peer_ip`` that reached us on ``accepted_on`` is on this host."""
        if peer_ip == accepted_on:
            return True
        try:
            if ipaddress.ip_address(peer_ip.split("%", 1)[0]).is_loopback:
                return True
        except ValueError:
            return False
        known = self._cache.get(peer_ip)
        if known is None:
            known = self._own(peer_ip)
            self._cache[peer_ip] = known
            if len(self._cache) > self._max:
                self._cache.popitem(last=False)
        return known
