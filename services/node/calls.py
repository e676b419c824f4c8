"""The call table of a node, sans-IO: which calls run, which results are kept, who waits for what.

Pure logic, as :mod:`services.protocol` is: no asyncio, no sockets, no clock (the caller passes the
time in). The node's asyncio shell (:mod:`services.node.server`) asks :meth:`CallTable.admit` what
to do with each ``call`` message, runs the action when told to :class:`Start` it, and hands the
ending to :meth:`CallTable.finish`. The rules are those of docs/protocol.md §5 ("Calls") and §7:

* an action not hosted here → :class:`Reject` ``unknown_action``;
* a ``local_only`` action from a peer that is not local → ``local_only``;
* an id with a kept result → :class:`Answer` with that result, if the action is the same, else
  ``duplicate_id``;
* an id still running → :class:`Join` it (the caller is one more waiter for its result), if the
  action is the same, else ``duplicate_id``;
* ``max_in_flight`` calls already running → ``busy``; the node stopping → ``shutdown``;
* otherwise → :class:`Start`.

The checks run in that order (a repeat is answered even when the node is busy or stopping).

A ``query`` (:meth:`CallTable.query`) is answered the same way for a kept or running id, and with
``unknown_call`` otherwise; it never starts anything.

**Orphaned calls** (docs/protocol.md §5): a running call's waiters are the connections that sent
its id (once each). When the last one goes (:meth:`CallTable.detach`) the call is *orphaned*; a
repeated ``call`` or a ``query`` of its id adopts it again. :meth:`CallTable.orphans` names the
calls orphaned for longer than a grace period so that the shell cancels them with reason
``"caller_gone"``, except calls of ``unattended`` actions, which run to the end. Calls of ``motion``
actions (those that move the robot) have no grace period: they are due as soon as they are
orphaned, so that a robot whose coordinator died comes to rest within its own watchdog's bound.
Their results are kept either way.

Kept results live behind the small :class:`ResultCache` interface (``get``, ``put``, ``expire``,
``begin``, ``flush``) so that a store which survives node restarts
(:class:`services.node.store.SqliteResultCache`) can replace the in-memory :class:`MemoryResultCache`.
The in-memory cache is bounded by **bytes** and by **age**, not by count: it keeps each result as
its encoded ``result`` frame (the bytes sent to the callers, decoded again only when a repeated id
asks for it), so that what it is charged — the frame's length plus :data:`ENTRY_OVERHEAD`, the
objects that hold it — is the memory it holds, whatever the value (a list of a million small
numbers is 9 MB as a frame, 36 MB as Python objects); the oldest results are dropped when the
charge exceeds ``max_bytes`` (default 64 MiB), and results older than ``max_age_s`` (default
600 s) when :meth:`CallTable.expire` runs.
There is no count cap: the per-entry overhead makes the byte cap bound the count too (at most
``max_bytes / ENTRY_OVERHEAD`` results, about 131,000 with the defaults).
"""

from __future__ import annotations

import collections
import enum
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from typing import Final, Generic, NamedTuple, Protocol, TypeAlias, TypeVar

from services.protocol import Call, Result, encode_frame, from_map, unpack_map
from services.protocol.framing import HEADER_BYTES

__all__ = [
    "CALLER_GONE",
    "DEFAULT_MAX_AGE_S",
    "DEFAULT_MAX_BYTES",
    "ENTRY_OVERHEAD",
    "Admission",
    "Answer",
    "CallTable",
    "Join",
    "KeptResult",
    "MemoryResultCache",
    "Reject",
    "RejectReason",
    "ResultCache",
    "RunningCall",
    "Start",
]

W = TypeVar("W")
"""Whoever waits for a call's result (the node's shell uses its connection objects)."""

DEFAULT_MAX_BYTES: Final = 64 * 1024 * 1024
"""Default cap on the bytes charged for kept results (64 MiB)."""
DEFAULT_MAX_AGE_S: Final = 600.0
"""Default age after which a kept result expires, seconds (10 minutes)."""
ENTRY_OVERHEAD: Final = 512
"""Bytes charged per kept result on top of its frame: the Python objects and the map slot that hold
it (a small result held about 520 bytes beyond its frame length, measured on CPython 3.11)."""
CALLER_GONE: Final = "caller_gone"
"""The ``reason`` of a call cancelled because nobody waited for it any more."""


class RejectReason(enum.StrEnum):
    """Why a call was not started: the ``reason`` of ``rejected{id, reason}`` (docs/protocol.md §5)."""

    UNKNOWN_ACTION = "unknown_action"
    """The action is not hosted by this node."""
    LOCAL_ONLY = "local_only"
    """The action serves callers on the node's own host only (docs/protocol.md §7)."""
    DUPLICATE_ID = "duplicate_id"
    """The id is kept or running for a different action."""
    BUSY = "busy"
    """``max_in_flight`` calls are running."""
    SHUTDOWN = "shutdown"
    """The node is stopping."""
    UNKNOWN_CALL = "unknown_call"
    """Answer to a ``query``: the node never saw the id, or no longer keeps its result."""


# --------------------------------------------------------------------------- kept results


class KeptResult(NamedTuple):
    """A finished call's result, kept to answer a repeat of its id (an immutable record).

    Attributes:
        call_id: the call's id.
        action: the action that ran (a repeat naming another action is a ``duplicate_id``).
        result: the ``result`` message sent to the callers.
        size: length of its encoded frame, bytes.
        stored_at: when it was kept, seconds on the clock the caller passes to the cache.
        frame: the encoded frame, when the caller has it (the caches keep it instead of the
            :class:`Result` and give it back with it, so that a repeat is answered with the very
            bytes first sent).
    """

    call_id: str
    action: str
    result: Result
    size: int
    stored_at: float
    frame: bytes | None = None


class ResultCache(Protocol):
    """Where a node keeps finished calls' results (docs/protocol.md §5, "Idempotency").

    Implementations decide their own bounds; :meth:`put` may drop older results to stay within
    them and :meth:`expire` drops results too old to keep. Times are seconds on one clock the
    caller chooses and keeps (the node passes its event loop's monotonic clock; a store that
    outlives the process needs a clock that does too).
    """

    def get(self, call_id: str) -> KeptResult | None:
        """The kept result of ``call_id``, or ``None``."""
        ...

    def put(self, kept: KeptResult) -> None:
        """Keep ``kept`` (replacing a result kept under the same id)."""
        ...

    def expire(self, now: float) -> int:
        """Drop the results too old at time ``now`` (s); return how many were dropped."""
        ...

    def begin(self, call_id: str, action: str, now: float) -> None:
        """Note that ``call_id`` starts running ``action`` (a durable store journals it, so that
        after a crash the id is answered ``node_restarted`` instead of running again)."""
        ...

    def flush(self) -> None:
        """Make every :meth:`put` and :meth:`begin` so far durable. The node calls it before it
        sends a result or starts an action (a no-op for a store that does not outlive the process)."""
        ...


class _Stored(NamedTuple):
    action: str
    frame: bytes
    stored_at: float


class MemoryResultCache:
    """Kept results in memory as their frames, oldest first, bounded by bytes and by age (see the
    module docstring).

    Args:
        max_bytes: cap on the bytes charged (frame length + ``entry_overhead`` per result); the
            oldest results are dropped to stay under it, except the newest, which is kept even if
            it alone exceeds the cap.
        max_age_s: results older than this, seconds, are dropped by :meth:`expire`.
        entry_overhead: bytes charged per result on top of its frame.

    Raises:
        ValueError: a bound is not positive, or the overhead is negative.
    """

    __slots__ = ("_kept", "entry_overhead", "max_age_s", "max_bytes", "nbytes")

    def __init__(
        self,
        *,
        max_bytes: int = DEFAULT_MAX_BYTES,
        max_age_s: float = DEFAULT_MAX_AGE_S,
        entry_overhead: int = ENTRY_OVERHEAD,
    ) -> None:
        if max_bytes <= 0 or max_age_s <= 0 or entry_overhead < 0:
            raise ValueError("max_bytes and max_age_s must be positive, entry_overhead non-negative")
        self.max_bytes = max_bytes
        self.max_age_s = max_age_s
        self.entry_overhead = entry_overhead
        self.nbytes = 0
        """Bytes charged for the results kept now: their frames' lengths plus the overhead each."""
        self._kept: collections.OrderedDict[str, _Stored] = collections.OrderedDict()

    def __len__(self) -> int:
        return len(self._kept)

    def __contains__(self, call_id: object) -> bool:
        return call_id in self._kept

    def get(self, call_id: str) -> KeptResult | None:
        """The kept result of ``call_id`` (decoded from its frame, the frame given too), or ``None``."""
        stored = self._kept.get(call_id)
        if stored is None:
            return None
        msg = from_map(unpack_map(stored.frame[HEADER_BYTES:]))
        assert isinstance(msg, Result)
        return KeptResult(call_id, stored.action, msg, len(stored.frame), stored.stored_at, stored.frame)

    def put(self, kept: KeptResult) -> None:
        """Keep ``kept``'s frame (encoded here if it has none) as the newest result, then drop the
        oldest while over ``max_bytes``."""
        results = self._kept
        cid = kept.call_id
        frame = kept.frame if kept.frame is not None else encode_frame(kept.result)
        if cid in results:
            self.nbytes -= len(results.pop(cid).frame) + self.entry_overhead
        results[cid] = _Stored(kept.action, frame, kept.stored_at)
        self.nbytes += len(frame) + self.entry_overhead
        if self.nbytes > self.max_bytes:
            while self.nbytes > self.max_bytes and len(results) > 1:
                _, dropped = results.popitem(last=False)
                self.nbytes -= len(dropped.frame) + self.entry_overhead

    def expire(self, now: float) -> int:
        """Drop the results kept before ``now - max_age_s`` (s); return how many were dropped."""
        results = self._kept
        too_old = now - self.max_age_s
        n = 0
        while results:
            cid, first = next(iter(results.items()))
            if first.stored_at >= too_old:
                break
            del results[cid]
            self.nbytes -= len(first.frame) + self.entry_overhead
            n += 1
        return n

    def begin(self, call_id: str, action: str, now: float) -> None:
        """Nothing to do: a result kept in memory dies with the process anyway."""

    def flush(self) -> None:
        """Nothing to do (nothing outlives the process)."""


# --------------------------------------------------------------------------- the table


class RunningCall(Generic[W]):
    """A call in flight.

    Attributes:
        call: the ``call`` message that started it.
        waiters: who gets its result, each once, in the order they came: the first caller, then
            every caller that joined it (a dict used as an ordered set).
        unattended: its action may finish with nobody waiting.
        motion: its action moves the robot (no grace period once orphaned).
        cancel_reason: why it is being cancelled (``"cancelled"``, ``"caller_gone"``), else ``None``.
        orphaned_since: when its last waiter went (s, the shell's monotonic clock), else ``None``.
    """

    __slots__ = ("call", "cancel_reason", "motion", "orphaned_since", "unattended", "waiters")

    def __init__(self, call: Call, first: W, *, unattended: bool = False, motion: bool = False) -> None:
        self.call = call
        self.waiters: dict[W, None] = {first: None}
        self.unattended = unattended
        self.motion = motion
        self.cancel_reason: str | None = None
        self.orphaned_since: float | None = None

    @property
    def cancel_requested(self) -> bool:
        """A cancel (by a client, or for want of one) was asked for."""
        return self.cancel_reason is not None

    def adopt(self, waiter: W) -> None:
        """``waiter`` waits for this call too (no longer an orphan)."""
        self.waiters[waiter] = None
        self.orphaned_since = None

    def __repr__(self) -> str:
        return f"RunningCall({self.call.id!r}, {self.call.action!r}, waiters={len(self.waiters)})"


@dataclass(slots=True)
class Start(Generic[W]):
    """Run the action: the call is now in the table (answer ``accepted``)."""

    running: RunningCall[W]


@dataclass(slots=True)
class Join(Generic[W]):
    """The id is running: the caller was added to its waiters (answer ``accepted``)."""

    running: RunningCall[W]


@dataclass(slots=True)
class Answer:
    """The id already ran: answer ``accepted`` and this kept result, without running it again."""

    kept: KeptResult


@dataclass(frozen=True, slots=True)
class Reject:
    """Do not start the call: answer ``rejected`` with this reason."""

    reason: RejectReason


Admission: TypeAlias = Start[W] | Join[W] | Answer | Reject
"""What :meth:`CallTable.admit` decides for one ``call``."""

_REJECT: Final = {reason: Reject(reason) for reason in RejectReason}


class CallTable(Generic[W]):
    """Admits calls, tracks the running ones and keeps their results (see the module docstring).

    Args:
        actions: names of the actions hosted here.
        local_only: those of them served only to local peers.
        unattended: those of them that may finish when nobody waits for them.
        motion: those of them that move the robot (cancelled at once when orphaned).
        max_in_flight: cap on calls running at once (>= 1).
        cache: where results are kept; a :class:`MemoryResultCache` with its defaults if ``None``.

    Attributes:
        cache: the result cache.
        max_in_flight: the cap on running calls.
        unattended: the actions whose calls may finish with nobody waiting (a node adds those whose
            implementation says so).
        motion: the actions that move the robot (likewise).
        stopping: set by :meth:`stop`; new calls are then rejected with ``shutdown``.

    Raises:
        ValueError: ``max_in_flight`` < 1, or a ``local_only`` or ``unattended`` action is not in
            ``actions``.
    """

    __slots__ = ("_actions", "_local_only", "_running", "cache", "max_in_flight", "motion", "stopping", "unattended")

    def __init__(
        self,
        actions: Iterable[str],
        *,
        local_only: Collection[str] = (),
        unattended: Collection[str] = (),
        motion: Collection[str] = (),
        max_in_flight: int = 16,
        cache: ResultCache | None = None,
    ) -> None:
        self._actions = frozenset(actions)
        self._local_only = frozenset(local_only)
        self.unattended = frozenset(unattended)
        self.motion = frozenset(motion)
        if max_in_flight < 1:
            raise ValueError("max_in_flight must be >= 1")
        if not self._local_only <= self._actions:
            raise ValueError(f"local_only names unknown actions: {sorted(self._local_only - self._actions)}")
        if not self.unattended <= self._actions:
            raise ValueError(f"unattended names unknown actions: {sorted(self.unattended - self._actions)}")
        self.max_in_flight = max_in_flight
        self.cache: ResultCache = cache if cache is not None else MemoryResultCache()
        self.stopping = False
        self._running: dict[str, RunningCall[W]] = {}

    @property
    def in_flight(self) -> int:
        """Calls running now."""
        return len(self._running)

    @property
    def actions(self) -> tuple[str, ...]:
        """The actions hosted here, sorted."""
        return tuple(sorted(self._actions))

    def admit(self, call: Call, waiter: W, *, local: bool, now: float = 0.0) -> Admission[W]:
        """Decide what to do with ``call`` from ``waiter`` (a local peer if ``local``).

        :class:`Start` and :class:`Join` change the table (the call runs, or ``waiter`` now waits
        for it); :class:`Answer` and :class:`Reject` do not. A start is noted in the cache
        (:meth:`ResultCache.begin`) at time ``now`` (s, the cache's clock).
        """
        action = call.action
        if action not in self._actions:
            return _REJECT[RejectReason.UNKNOWN_ACTION]
        if not local and action in self._local_only:
            return _REJECT[RejectReason.LOCAL_ONLY]
        cid = call.id
        kept = self.cache.get(cid)
        if kept is not None:
            return Answer(kept) if kept.action == action else _REJECT[RejectReason.DUPLICATE_ID]
        running = self._running.get(cid)
        if running is not None:
            if running.call.action != action:
                return _REJECT[RejectReason.DUPLICATE_ID]
            running.adopt(waiter)
            return Join(running)
        if len(self._running) >= self.max_in_flight:
            return _REJECT[RejectReason.BUSY]
        if self.stopping:
            return _REJECT[RejectReason.SHUTDOWN]
        running = RunningCall(call, waiter, unattended=action in self.unattended, motion=action in self.motion)
        self._running[cid] = running
        self.cache.begin(cid, action, now)
        return Start(running)

    def query(self, call_id: str, waiter: W) -> Answer | Join[W] | Reject:
        """What became of ``call_id``, for ``waiter``'s ``query``; never starts anything.

        Returns:
            :class:`Answer` with the kept result; :class:`Join` if it is running (``waiter`` now
            waits for it, which adopts an orphan); else ``Reject(UNKNOWN_CALL)``.
        """
        kept = self.cache.get(call_id)
        if kept is not None:
            return Answer(kept)
        running = self._running.get(call_id)
        if running is None:
            return _REJECT[RejectReason.UNKNOWN_CALL]
        running.adopt(waiter)
        return Join(running)

    def running(self, call_id: str) -> RunningCall[W] | None:
        """The running call ``call_id``, or ``None``."""
        return self._running.get(call_id)

    def cancel(self, call_id: str, reason: str = "cancelled") -> RunningCall[W] | None:
        """Mark the running call ``call_id`` as cancelled for ``reason`` and return it (``None`` if
        not running; the first reason given stays)."""
        running = self._running.get(call_id)
        if running is not None and running.cancel_reason is None:
            running.cancel_reason = reason
        return running

    def detach(self, waiter: W, now: float) -> list[RunningCall[W]]:
        """``waiter`` went away: it waits for nothing any more.

        Args:
            waiter: the connection that closed.
            now: the time, seconds on the shell's monotonic clock.

        Returns:
            The calls it left without any waiter (orphaned from ``now``).
        """
        orphaned = []
        for running in self._running.values():  # at most max_in_flight of them
            waiters = running.waiters
            if waiter in waiters:
                del waiters[waiter]
                if not waiters:
                    running.orphaned_since = now
                    orphaned.append(running)
        return orphaned

    def orphans(self, now: float, grace_s: float) -> list[RunningCall[W]]:
        """The calls to cancel now: orphaned for at least ``grace_s`` seconds (a ``motion`` call:
        orphaned at all), not yet cancelled, and not of an ``unattended`` action. Each is marked
        cancelled with reason ``"caller_gone"``.
        """
        due = []
        cutoff = now - grace_s
        for running in self._running.values():
            since = running.orphaned_since
            if since is not None and (running.motion or since <= cutoff) and not running.unattended \
                    and running.cancel_reason is None:
                running.cancel_reason = CALLER_GONE
                due.append(running)
        return due

    def motion_waiters(self) -> set[W]:
        """Whoever waits for a running call of a ``motion`` action that may not finish unattended
        (the shell watches their heartbeats more closely)."""
        return {w for running in self._running.values() if running.motion and not running.unattended
                for w in running.waiters}

    def finish(self, result: Result, *, size: int, now: float, frame: bytes | None = None) -> RunningCall[W]:
        """End the running call ``result.id``: keep ``result`` and return the call (its waiters).

        Args:
            result: the ``result`` message sent to the waiters.
            size: length of its encoded frame, bytes.
            now: the time, seconds on the cache's clock.
            frame: the encoded frame, if the caller has it.

        Raises:
            KeyError: ``result.id`` is not running.
        """
        running = self._running.pop(result.id)
        self.cache.put(KeptResult(result.id, running.call.action, result, size, now, frame))
        return running

    def expire(self, now: float) -> int:
        """Drop kept results too old at ``now`` (s, the cache's clock); return how many."""
        return self.cache.expire(now)

    def stop(self) -> list[RunningCall[W]]:
        """Refuse new calls from now on (``shutdown``); return the calls still running."""
        self.stopping = True
        return list(self._running.values())
