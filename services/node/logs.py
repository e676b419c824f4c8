"""Log lines a peer can provoke, rate-limited per kind and address.

A peer can make a node log: each refused login, bad frame, rejected call or dropped handshake is
worth a line. Lines about one *key* (a kind of event and the peer's address) are written at most
``burst`` times per ``interval_s``; the ones held back are counted and reported in one line when
the next interval begins. Text received from peers is shown through
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
    """At most ``burst`` lines per key per ``interval_s`` seconds (see the module docstring).

    Args:
        logger: where lines go.
        burst: lines written per key and interval.
        interval_s: the interval, seconds.
        max_keys: keys remembered (the oldest are forgotten beyond it, with their counts).
        clock: monotonic clock, seconds (:func:`time.monotonic` by default; pass one in tests).
    """

    __slots__ = ("_clock", "_keys", "burst", "interval_s", "logger", "max_keys")

    def __init__(self, logger: logging.Logger, *, burst: int = 5, interval_s: float = 10.0,
                 max_keys: int = 1024, clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.burst = burst
        self.interval_s = interval_s
        self.max_keys = max_keys
        self._clock = clock
        # key -> [interval start, lines written in it, lines held back in it]
        self._keys: collections.OrderedDict[Hashable, list[float]] = collections.OrderedDict()

    def log(self, level: int, key: Hashable, msg: str, *args: Any) -> bool:
        """Log ``msg % args`` at ``level`` unless ``key`` used up its lines; return whether it was written."""
        if not self.logger.isEnabledFor(level):
            return False
        now = self._clock()
        state = self._keys.get(key)
        if state is None or now - state[0] >= self.interval_s:
            if state is not None and state[2]:
                self.logger.log(level, "%d similar line(s) suppressed in %.0f s (%s)", int(state[2]),
                                now - state[0], key[0] if isinstance(key, tuple) else key)
            state = [now, 0, 0]
            self._keys[key] = state
            self._keys.move_to_end(key)
            while len(self._keys) > self.max_keys:
                self._keys.popitem(last=False)
        if state[1] >= self.burst:
            state[2] += 1
            return False
        state[1] += 1
        self.logger.log(level, msg, *args)
        return True
