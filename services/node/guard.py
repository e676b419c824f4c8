"""Who may hold a connection to a node, sans-IO: caps, the handshake deadline, login throttling.

Pure logic, as :mod:`services.node.calls` is: no sockets, no clock (times are passed in). The
node's listener (:mod:`services.node.server`) tells a :class:`ConnectionGuard` about every accepted
connection, every handshake that succeeds and every connection that closes; the guard says which
connections to close. The rules (docs/protocol.md §6, "Connection limits"):

* A connection is *pending* from accept until its handshake succeeds, then *open*.
* Pending connections are capped in total (``max_pending``) and per peer address
  (``max_pending_per_host``). A new connection over a cap is not refused: the **oldest** pending
  connection of its address (per-address cap), or of the address holding the most pending
  connections (total cap), is closed to make room. A slow or stalled handshake is what an attacker
  holds on to; a real client finishes its handshake in one round trip, long before newer
  connections push it out, and a flood from other addresses takes room from itself first.
* Open (authenticated) connections are capped in total (``max_open``) and per address
  (``max_open_per_host``); a handshake that would exceed a cap is refused.
* Every pending connection must finish its handshake within ``handshake_timeout_s`` of being
  accepted, however many bytes it trickles in (:meth:`ConnectionGuard.overdue`).
* New connections are rate-limited per address (``accepts_per_s``, bursts of ``accept_burst``;
  :meth:`ConnectionGuard.may_accept`): over the rate, a connection is closed at once, before any
  work is done for it, so that an address reconnecting in a loop costs the node little. A client
  opens a handful of connections a minute.
* Failed logins are throttled per address (:class:`AuthThrottle`): each failure takes a token from
  the address's bucket; while the bucket is empty, new connections from that address are closed at
  once, before any work is done for them.

:func:`budget_caps` fits the caps under the process's file-descriptor limit, so that connections
alone never exhaust it.
"""

from __future__ import annotations

import collections
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, replace
from typing import Final, Generic, TypeVar

__all__ = [
    "DEFAULT_CAPS",
    "AuthThrottle",
    "Caps",
    "ConnectionGuard",
    "TokenBuckets",
    "budget_caps",
]

C = TypeVar("C", bound=Hashable)
"""A connection (the node's shell uses its connection records)."""


@dataclass(frozen=True, slots=True)
class Caps:
    """Connection caps of a node (see the module docstring).

    Attributes:
        max_open: authenticated connections, in total.
        max_open_per_host: authenticated connections from one address.
        max_pending: connections still in their handshake, in total.
        max_pending_per_host: connections still in their handshake from one address.
        handshake_timeout_s: time from accept to a finished handshake, seconds.
        accepts_per_s: new connections accepted per second from one address, in the long run.
        accept_burst: new connections one address may open at once.
    """

    max_open: int = 256
    max_open_per_host: int = 64
    max_pending: int = 128
    max_pending_per_host: int = 32
    handshake_timeout_s: float = 2.0
    accepts_per_s: float = 50.0
    accept_burst: int = 100

    def __post_init__(self) -> None:
        if min(self.max_open, self.max_open_per_host, self.max_pending, self.max_pending_per_host,
               self.accept_burst) < 1:
            raise ValueError("connection caps must be >= 1")
        if not (self.handshake_timeout_s > 0 and self.accepts_per_s > 0):
            raise ValueError("handshake_timeout_s and accepts_per_s must be positive")


DEFAULT_CAPS: Final = Caps()
"""The reference node's caps."""


def budget_caps(caps: Caps, fd_limit: int, fds_in_use: int, reserve: int = 64) -> Caps:
    """``caps`` shrunk so that connections use at most ``fd_limit - fds_in_use - reserve`` descriptors.

    The reserve is for what else the node opens (links to other nodes, its state store, drivers,
    a spare descriptor for accepting when the limit is reached). Pending connections get a quarter
    of the budget at most, open ones the rest.

    Args:
        caps: the wanted caps.
        fd_limit: the soft ``RLIMIT_NOFILE`` of the process.
        fds_in_use: descriptors open now (before listening).
        reserve: descriptors kept free.

    Returns:
        ``caps`` if it fits, else smaller caps (each at least 1).
    """
    budget = max(2, fd_limit - fds_in_use - reserve)
    if caps.max_open + caps.max_pending <= budget:
        return caps
    pending = max(1, min(caps.max_pending, budget // 4))
    open_ = max(1, min(caps.max_open, budget - pending))
    return replace(
        caps, max_open=open_, max_open_per_host=min(caps.max_open_per_host, open_),
        max_pending=pending, max_pending_per_host=min(caps.max_pending_per_host, pending),
    )


class ConnectionGuard(Generic[C]):
    """Tracks pending and open connections per address and enforces :class:`Caps`.

    Args:
        caps: the caps.
    """

    __slots__ = ("_accepts", "_caps", "_open", "_open_by_host", "_pending", "_pending_by_host")

    def __init__(self, caps: Caps = DEFAULT_CAPS) -> None:
        self._caps = caps
        self._accepts = TokenBuckets(burst=caps.accept_burst, per_s=caps.accepts_per_s)
        # pending connections in order of acceptance, with (host, accepted_at)
        self._pending: collections.OrderedDict[C, tuple[str, float]] = collections.OrderedDict()
        self._pending_by_host: dict[str, collections.OrderedDict[C, None]] = {}
        self._open: dict[C, str] = {}
        self._open_by_host: collections.Counter[str] = collections.Counter()

    @property
    def caps(self) -> Caps:
        """The caps in force."""
        return self._caps

    @caps.setter
    def caps(self, caps: Caps) -> None:
        self._caps = caps
        self._accepts = TokenBuckets(burst=caps.accept_burst, per_s=caps.accepts_per_s)

    @property
    def pending(self) -> int:
        """Connections in their handshake now."""
        return len(self._pending)

    def may_accept(self, host: str, now: float) -> bool:
        """Whether a new connection from ``host`` is within its address's rate at ``now`` (s); if it
        is, it uses up its share of the rate."""
        return self._accepts.take(host, now)

    @property
    def open(self) -> int:
        """Authenticated connections now."""
        return len(self._open)

    def accept(self, conn: C, host: str, now: float) -> list[C]:
        """A connection from ``host`` was accepted at ``now`` (s): it is pending.

        Returns:
            The pending connections to close to make room for it (oldest first; never ``conn``).
        """
        evict: list[C] = []
        same = self._pending_by_host.get(host)
        if same is not None and len(same) >= self.caps.max_pending_per_host:
            evict.append(next(iter(same)))
            self._drop_pending(evict[-1])
        if len(self._pending) >= self._caps.max_pending:
            # the busiest address gives way (the one whose oldest connection is oldest among equals)
            busiest = max(self._pending_by_host.values(), key=len)
            evict.append(next(iter(busiest)))
            self._drop_pending(evict[-1])
        self._pending[conn] = (host, now)
        self._pending_by_host.setdefault(host, collections.OrderedDict())[conn] = None
        return evict

    def authenticate(self, conn: C) -> bool:
        """``conn`` finished its handshake. Returns False if an open-connection cap refuses it
        (the caller closes it; it no longer counts as pending either way)."""
        entry = self._pending.get(conn)
        if entry is None:
            return False
        host = entry[0]
        self._drop_pending(conn)
        if len(self._open) >= self.caps.max_open or self._open_by_host[host] >= self.caps.max_open_per_host:
            return False
        self._open[conn] = host
        self._open_by_host[host] += 1
        return True

    def close(self, conn: C) -> None:
        """``conn`` closed (pending or open; unknown is harmless)."""
        if conn in self._pending:
            self._drop_pending(conn)
            return
        host = self._open.pop(conn, None)
        if host is not None:
            self._open_by_host[host] -= 1
            if not self._open_by_host[host]:
                del self._open_by_host[host]

    def oldest_pending(self) -> C | None:
        """The pending connection accepted first, or ``None``."""
        return next(iter(self._pending), None)

    def overdue(self, now: float) -> Iterator[C]:
        """The pending connections accepted more than ``handshake_timeout_s`` before ``now``,
        oldest first (they stay pending until :meth:`close`)."""
        cutoff = now - self.caps.handshake_timeout_s
        for conn, (_, accepted_at) in self._pending.items():
            if accepted_at > cutoff:
                break
            yield conn

    def _drop_pending(self, conn: C) -> None:
        host, _ = self._pending.pop(conn)
        same = self._pending_by_host[host]
        del same[conn]
        if not same:
            del self._pending_by_host[host]


class TokenBuckets:
    """A token bucket per key (an address): ``burst`` tokens, earned back at ``per_s`` a second.

    Args:
        burst: tokens a full bucket holds.
        per_s: tokens earned back per second.
        max_hosts: buckets remembered; the least recently used are forgotten (refilled) beyond it.
    """

    __slots__ = ("_buckets", "burst", "max_hosts", "per_s")

    def __init__(self, *, burst: int, per_s: float, max_hosts: int = 4096) -> None:
        if burst < 1 or per_s <= 0 or max_hosts < 1:
            raise ValueError("burst and max_hosts must be >= 1, per_s positive")
        self.burst = burst
        self.per_s = per_s
        self.max_hosts = max_hosts
        self._buckets: collections.OrderedDict[str, tuple[float, float]] = collections.OrderedDict()

    def tokens(self, key: str, now: float) -> float:
        """Tokens in ``key``'s bucket at ``now`` (s)."""
        entry = self._buckets.get(key)
        if entry is None:
            return float(self.burst)
        tokens, at = entry
        return min(float(self.burst), tokens + (now - at) * self.per_s)

    def spend(self, key: str, now: float) -> None:
        """Take a token from ``key``'s bucket (none left: it stays empty)."""
        self._buckets[key] = (max(0.0, self.tokens(key, now) - 1.0), now)
        self._buckets.move_to_end(key)
        while len(self._buckets) > self.max_hosts:
            self._buckets.popitem(last=False)

    def take(self, key: str, now: float) -> bool:
        """Take a token if there is one; return whether there was."""
        if key in self._buckets and self.tokens(key, now) < 1.0:
            return False
        self.spend(key, now)
        return True


class AuthThrottle(TokenBuckets):
    """Failed logins per address (see the module docstring): each failure spends a token; an
    address whose bucket is empty is throttled.

    Args:
        burst: failures an address may have in a row before it is throttled.
        per_s: failures per second an address earns back.
        max_hosts: addresses remembered; the least recently failing are forgotten beyond it.
    """

    __slots__ = ()

    def __init__(self, *, burst: int = 20, per_s: float = 5.0, max_hosts: int = 4096) -> None:
        super().__init__(burst=burst, per_s=per_s, max_hosts=max_hosts)

    def throttled(self, host: str, now: float) -> bool:
        """Whether a new connection from ``host`` should be refused at ``now`` (s)."""
        return host in self._buckets and self.tokens(host, now) < 1.0

    def failed(self, host: str, now: float) -> None:
        """A login from ``host`` failed at ``now`` (s)."""
        self.spend(host, now)
