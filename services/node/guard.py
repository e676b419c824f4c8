"""Who may hold a connection to a node, sans-IO: caps, the handshake deadline, login throttling.

Pure logic, as :mod:`services.node.calls` is: no sockets, no clock (times are passed in). The
node's listener (:mod:`services.node.server`) tells a :class:`ConnectionGuard` about every accepted
connection, every handshake that succeeds and every connection that closes; the guard says which
connections to close. The rules (docs/protocol.md §6, "Connection limits"):

* A connection is *pending* from accept until its handshake succeeds, then *open*.
* An address is *known* for ``trust_s`` after a connection from it authenticated.
* Pending connections are capped in total (``max_pending``) and per peer address
  (``max_pending_per_host``). A new connection over a cap is not refused: the **oldest** pending
  connection of its address (per-address cap), or of the address holding the most pending
  connections (total cap), is closed to make room. A slow or stalled handshake is what an attacker
  holds on to; a real client finishes its handshake in one round trip, long before newer
  connections push it out, and a flood from other addresses takes room from itself first.
* ``reserved_pending`` of the pending slots are kept for known addresses: connections from unknown
  addresses make room among themselves once they hold the rest, so that a flood from many new
  addresses never takes the last slot from a client that has logged in before.
* New connections from unknown addresses are rate-limited **in total** too (``new_per_s``, bursts of
  ``new_burst``): a flood spread over many addresses, each within its own rate, is cut down to
  what the node can answer, before any work is done for it; known addresses are not counted.
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
  once, before any work is done for them — unless the address is known: one process with a wrong
  key must not lock out the rest of its host (the coordinator beside it), so a known address
  keeps its handshakes, each failure still costing it a token of its accept rate.

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

_MAX_KNOWN: Final = 4096
"""Known addresses remembered (the least recently authenticated are forgotten beyond it)."""


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
        reserved_pending: pending slots only known addresses may take (at most a quarter of
            ``max_pending`` is reserved, whatever this says).
        new_per_s: new connections accepted per second from all unknown addresses together.
        new_burst: new connections unknown addresses may open at once, together.
        trust_s: how long an address stays known after a connection from it authenticated, seconds.
    """

    max_open: int = 256
    max_open_per_host: int = 64
    max_pending: int = 128
    max_pending_per_host: int = 32
    handshake_timeout_s: float = 2.0
    accepts_per_s: float = 50.0
    accept_burst: int = 100
    reserved_pending: int = 32
    new_per_s: float = 200.0
    new_burst: int = 200
    trust_s: float = 3600.0

    def __post_init__(self) -> None:
        if min(self.max_open, self.max_open_per_host, self.max_pending, self.max_pending_per_host,
               self.accept_burst, self.new_burst) < 1:
            raise ValueError("connection caps must be >= 1")
        if self.reserved_pending < 0:
            raise ValueError("reserved_pending must be >= 0")
        if not (self.handshake_timeout_s > 0 and self.accepts_per_s > 0 and self.new_per_s > 0 and self.trust_s > 0):
            raise ValueError("handshake_timeout_s, accepts_per_s, new_per_s and trust_s must be positive")

    @property
    def reserved(self) -> int:
        """Pending slots kept for known addresses: ``reserved_pending``, at most a quarter of ``max_pending``."""
        return min(self.reserved_pending, self.max_pending // 4)


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
    )  # the reserve of known addresses shrinks with max_pending (Caps.reserved)


class ConnectionGuard(Generic[C]):
    """Tracks pending and open connections per address and enforces :class:`Caps`.

    Args:
        caps: the caps.
    """

    __slots__ = ("_accepts", "_caps", "_known", "_new", "_open", "_open_by_host", "_pending", "_pending_by_host",
                 "_pending_unknown")

    def __init__(self, caps: Caps = DEFAULT_CAPS) -> None:
        self._caps = caps
        self._accepts = TokenBuckets(burst=caps.accept_burst, per_s=caps.accepts_per_s)
        self._new = TokenBuckets(burst=caps.new_burst, per_s=caps.new_per_s, max_hosts=1)
        # pending connections in order of acceptance, with (host, accepted_at, known host)
        self._pending: collections.OrderedDict[C, tuple[str, float, bool]] = collections.OrderedDict()
        self._pending_by_host: dict[str, collections.OrderedDict[C, None]] = {}
        self._pending_unknown = 0
        self._open: dict[C, str] = {}
        self._open_by_host: collections.Counter[str] = collections.Counter()
        # addresses a connection authenticated from, least recently first, with when
        self._known: collections.OrderedDict[str, float] = collections.OrderedDict()

    @property
    def caps(self) -> Caps:
        """The caps in force."""
        return self._caps

    @caps.setter
    def caps(self, caps: Caps) -> None:
        self._caps = caps
        self._accepts = TokenBuckets(burst=caps.accept_burst, per_s=caps.accepts_per_s)
        self._new = TokenBuckets(burst=caps.new_burst, per_s=caps.new_per_s, max_hosts=1)

    @property
    def pending(self) -> int:
        """Connections in their handshake now."""
        return len(self._pending)

    def may_accept(self, host: str, now: float) -> bool:
        """Whether a new connection from ``host`` is within its address's rate at ``now`` (s); if it
        is, it uses up its share of the rate."""
        return self._accepts.take(host, now)

    def within_total(self, host: str, now: float) -> bool:
        """Whether a new connection from ``host`` is within the total rate of unknown addresses at
        ``now`` (s): a known address always is; an unknown one uses up a share of it if it is."""
        return self.known(host, now) or self._new.take("*", now)

    def known(self, host: str, now: float) -> bool:
        """Whether a connection from ``host`` authenticated within ``trust_s`` before ``now`` (s)."""
        at = self._known.get(host)
        return at is not None and now - at <= self._caps.trust_s

    @property
    def open(self) -> int:
        """Authenticated connections now."""
        return len(self._open)

    def accept(self, conn: C, host: str, now: float) -> list[C]:
        """A connection from ``host`` was accepted at ``now`` (s): it is pending.

        Returns:
            The pending connections to close to make room for it (oldest first; never ``conn``).
        """
        caps = self._caps
        known = self.known(host, now)
        evict: list[C] = []
        same = self._pending_by_host.get(host)
        if same is not None and len(same) >= caps.max_pending_per_host:
            evict.append(next(iter(same)))
            self._drop_pending(evict[-1])
        if known:
            if len(self._pending) >= caps.max_pending:
                victim = self._oldest_of_busiest(unknown_only=self._pending_unknown > 0)
                evict.append(victim)
                self._drop_pending(victim)
        elif self._pending_unknown >= caps.max_pending - caps.reserved or len(self._pending) >= caps.max_pending:
            victim = self._oldest_of_busiest(unknown_only=self._pending_unknown > 0)
            evict.append(victim)
            self._drop_pending(victim)
        self._pending[conn] = (host, now, known)
        self._pending_unknown += not known
        self._pending_by_host.setdefault(host, collections.OrderedDict())[conn] = None
        return evict

    def _oldest_of_busiest(self, *, unknown_only: bool) -> C:
        """The oldest pending connection of the address holding the most (the first listed among
        equals), among the connections from unknown addresses when ``unknown_only``."""
        hosts = list(self._pending_by_host.values())
        if unknown_only and self._pending_unknown < len(self._pending):  # (all unknown: nothing to sift)
            hosts = [q for q in hosts if not self._pending[next(iter(q))][2]] or hosts
        busiest = max(hosts, key=len)
        return next(iter(busiest))

    def authenticate(self, conn: C) -> bool:
        """``conn`` finished its handshake: its address is known from now on. Returns False if an
        open-connection cap refuses it (the caller closes it; it no longer counts as pending
        either way)."""
        entry = self._pending.get(conn)
        if entry is None:
            return False
        host, accepted_at, _ = entry
        self._drop_pending(conn)
        self._known[host] = max(accepted_at, self._known.get(host, accepted_at))
        self._known.move_to_end(host)
        while len(self._known) > _MAX_KNOWN:
            self._known.popitem(last=False)
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
        for conn, (_, accepted_at, _) in self._pending.items():
            if accepted_at > cutoff:
                break
            yield conn

    def _drop_pending(self, conn: C) -> None:
        host, _, known = self._pending.pop(conn)
        self._pending_unknown -= not known
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
