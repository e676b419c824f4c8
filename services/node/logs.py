"""Log lines a peer can provoke, rate-limited per kind and address, and in total.

A peer can make a node log: each refused login, bad frame, rejected call or dropped handshake is
worth a line. Two limits hold:

* per *key* (a kind of event and the peer's address): at most ``burst`` lines per ``interval_s``;
  the ones held back are counted and reported in one line when the key next logs in a later
  interval;
* in total, over every key: at most ``total`` lines per ``interval_s`` (those per-key reports
  included), so that peers spread over many addresses — a fuzz from a thousand addresses, a
  misconfigured fleet — cannot grow the log faster than that whatever their number. Lines held back
  by this limit are summed per kind, and one summary line per interval says how many of each kind
  were dropped and from how many keys.

The node's log therefore grows by at most ``total + 1`` such lines per ``interval_s`` (56 lines per
10 s by default, each line bounded by :func:`services.protocol.shown`), plus the lines of
authenticated peers' own calls. Text received from peers is shown through
:func:`services.protocol.shown` (escaped, one line, bounded) by the callers.
"""

from __future__ import annotations

import collections
import logging
import time
from collections.abc import Callable, Hashable
from typing import Any

__all__ = ["LogLimiter"]


class LogLimiter:
    """At most ``burst`` lines per key and ``total`` lines in all per ``interval_s`` seconds (see
    the module docstring).

    Args:
        logger: where lines go.
        burst: lines written per key and interval.
        interval_s: the interval, seconds.
        max_keys: keys remembered (the oldest are forgotten beyond it, with their counts).
        total: lines written per interval over every key.
        clock: monotonic clock, seconds (:func:`time.monotonic` by default; pass one in tests).
    """

    __slots__ = ("_clock", "_dropped", "_keys", "_window", "_written", "burst", "interval_s", "logger", "max_keys",
                 "total")

    def __init__(self, logger: logging.Logger, *, burst: int = 5, interval_s: float = 10.0,
                 max_keys: int = 1024, total: int = 50, clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.burst = burst
        self.interval_s = interval_s
        self.max_keys = max_keys
        self.total = total
        self._clock = clock
        # key -> [interval start, lines written in it, lines held back in it]
        self._keys: collections.OrderedDict[Hashable, list[float]] = collections.OrderedDict()
        self._window = clock()  # start of the interval of the total limit
        self._written = 0  # lines written in it
        # lines dropped in it by the total limit: kind -> [lines, keys]
        self._dropped: dict[str, tuple[int, set[Hashable]]] = {}

    def log(self, level: int, key: Hashable, msg: str, *args: Any) -> bool:
        """Log ``msg % args`` at ``level`` unless ``key`` or the total used up its lines; return
        whether it was written."""
        if not self.logger.isEnabledFor(level):
            return False
        now = self._clock()
        if now - self._window >= self.interval_s:
            self._summarise(now)
        state = self._keys.get(key)
        if state is None or now - state[0] >= self.interval_s:
            if state is not None and state[2]:
                self._write(level, key, "%d similar line(s) suppressed in %.0f s (%s)", int(state[2]),
                            now - state[0], _kind(key))
            state = [now, 0, 0]
            self._keys[key] = state
            self._keys.move_to_end(key)
            while len(self._keys) > self.max_keys:
                self._keys.popitem(last=False)
        if state[1] >= self.burst:
            state[2] += 1
            return False
        state[1] += 1
        return self._write(level, key, msg, *args)

    def flush(self) -> None:
        """Write the summary of the interval of the total limit once it is over (the node calls this
        periodically, so that the last interval of a flood is reported when the flood stops)."""
        now = self._clock()
        if now - self._window >= self.interval_s:
            self._summarise(now)

    def _write(self, level: int, key: Hashable, msg: str, *args: Any) -> bool:
        if self._written >= self.total:
            kind = _kind(key)
            lines, keys = self._dropped.get(kind, (0, set()))
            if len(keys) < 100_000:
                keys.add(key)
            self._dropped[kind] = (lines + 1, keys)
            return False
        self._written += 1
        self.logger.log(level, msg, *args)
        return True

    def _summarise(self, now: float) -> None:
        """Start a new interval of the total limit, first saying what the last one dropped."""
        if self._dropped:
            total = sum(lines for lines, _ in self._dropped.values())
            kinds = ", ".join(f"{kind} {lines} (from {len(keys)} source{'s' * (len(keys) != 1)})"
                              for kind, (lines, keys) in sorted(self._dropped.items(), key=lambda kv: -kv[1][0]))
            self.logger.warning("log limit: %d line(s) dropped in %.0f s (at most %d lines per %g s): %s", total,
                                now - self._window, self.total, self.interval_s, kinds)
        self._dropped = {}
        self._written = 0
        self._window = now


def _kind(key: Hashable) -> str:
    return str(key[0]) if isinstance(key, tuple) and key else str(key)
