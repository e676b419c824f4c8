"""Publish/subscribe fan-out of a node, sans-IO: topics, subscribers, sequence numbers, backlogs.

Pure logic: no asyncio, no sockets, no clock (the publisher's time is passed in). The node's asyncio
shell (:mod:`services.node.server`) tells a :class:`Fanout` when a connection subscribes,
unsubscribes, goes away, or has its writes paused and resumed by the transport; :meth:`Fanout.publish`
numbers each event of a topic and says which subscribers to send it to now. docs/protocol.md §9:

* a subscription lasts until ``unsubscribe`` or until the subscriber goes away
  (:meth:`Fanout.remove` unsubscribes it from everything);
* ``seq`` counts the events of each topic from 1, published to anyone or not, so a gap means the
  subscriber missed events;
* a node never waits for a slow subscriber: while its writes are paused its events wait in a
  backlog of at most ``backlog`` events (256 by default); when full the oldest is dropped and
  counted (:meth:`Fanout.dropped`); :meth:`Fanout.resume` hands back what waited, in order;
* a subscriber may hold at most ``max_topics`` topics (256 by default) and a topic name is at most
  ``max_topic_bytes`` bytes of UTF-8 (256 by default); :meth:`Fanout.subscribe` refuses more with
  a :class:`Refusal`.
"""

from __future__ import annotations

import collections
import enum
from collections.abc import Hashable
from typing import Any, Final, Generic, TypeVar

from services.protocol import Event

__all__ = [
    "DEFAULT_BACKLOG",
    "DEFAULT_MAX_TOPICS",
    "DEFAULT_MAX_TOPIC_BYTES",
    "Fanout",
    "Refusal",
]

S = TypeVar("S", bound=Hashable)
"""A subscriber (the node's shell uses its connection objects)."""

DEFAULT_BACKLOG: Final = 256
"""Default number of events held for a subscriber whose writes are paused."""
DEFAULT_MAX_TOPICS: Final = 256
"""Default cap on the topics one subscriber holds."""
DEFAULT_MAX_TOPIC_BYTES: Final = 256
"""Default cap on the length of a topic name, bytes of UTF-8."""


class Refusal(enum.StrEnum):
    """Why a subscription was refused."""

    TOO_MANY_TOPICS = "too_many_topics"
    """The subscriber already holds ``max_topics`` topics."""
    TOPIC_TOO_LONG = "topic_too_long"
    """The topic name is longer than ``max_topic_bytes`` bytes of UTF-8."""


class _Subscriber:
    """One subscriber's state: its topics, and its backlog while paused."""

    __slots__ = ("backlog", "dropped", "paused", "topics")

    def __init__(self, backlog: int) -> None:
        self.topics: set[str] = set()
        self.paused = False
        self.backlog: collections.deque[Event] = collections.deque(maxlen=backlog)
        self.dropped = 0


class Fanout(Generic[S]):
    """Topics → subscribers, with per-topic sequence numbers and per-subscriber backlogs.

    Args:
        backlog: events held per paused subscriber (>= 1); older ones are dropped.
        max_topics: topics one subscriber may hold (>= 1).
        max_topic_bytes: longest topic name, bytes of UTF-8 (>= 1).

    Raises:
        ValueError: a bound is below 1.
    """

    __slots__ = ("_backlog", "_seq", "_subs", "_topics", "max_topic_bytes", "max_topics")

    def __init__(
        self,
        *,
        backlog: int = DEFAULT_BACKLOG,
        max_topics: int = DEFAULT_MAX_TOPICS,
        max_topic_bytes: int = DEFAULT_MAX_TOPIC_BYTES,
    ) -> None:
        if min(backlog, max_topics, max_topic_bytes) < 1:
            raise ValueError("backlog, max_topics and max_topic_bytes must be >= 1")
        self._backlog = backlog
        self.max_topics = max_topics
        self.max_topic_bytes = max_topic_bytes
        self._seq: dict[str, int] = {}
        self._topics: dict[str, set[S]] = {}
        self._subs: dict[S, _Subscriber] = {}

    def _state(self, sub: S) -> _Subscriber:
        state = self._subs.get(sub)
        if state is None:
            state = self._subs[sub] = _Subscriber(self._backlog)
        return state

    # ---- subscriptions

    def subscribe(self, sub: S, topic: str) -> Refusal | None:
        """Subscribe ``sub`` to ``topic`` (again is harmless); ``None``, or why it was refused."""
        cap = self.max_topic_bytes
        if len(topic) > cap or len(topic.encode("utf-8", "surrogatepass")) > cap:
            return Refusal.TOPIC_TOO_LONG
        state = self._state(sub)
        if topic in state.topics:
            return None
        if len(state.topics) >= self.max_topics:
            return Refusal.TOO_MANY_TOPICS
        state.topics.add(topic)
        self._topics.setdefault(topic, set()).add(sub)
        return None

    def unsubscribe(self, sub: S, topic: str) -> None:
        """Unsubscribe ``sub`` from ``topic`` (not subscribed is harmless)."""
        state = self._subs.get(sub)
        if state is None or topic not in state.topics:
            return
        state.topics.discard(topic)
        self._drop_from(topic, sub)

    def remove(self, sub: S) -> None:
        """``sub`` went away: unsubscribe it from every topic and forget its backlog."""
        state = self._subs.pop(sub, None)
        if state is None:
            return
        for topic in state.topics:
            self._drop_from(topic, sub)

    def _drop_from(self, topic: str, sub: S) -> None:
        subs = self._topics.get(topic)
        if subs is not None:
            subs.discard(sub)
            if not subs:
                del self._topics[topic]

    def topics(self, sub: S) -> frozenset[str]:
        """The topics ``sub`` is subscribed to."""
        state = self._subs.get(sub)
        return frozenset(state.topics) if state is not None else frozenset()

    def subscribers(self, topic: str) -> frozenset[S]:
        """Who is subscribed to ``topic``."""
        return frozenset(self._topics.get(topic, ()))

    # ---- publishing

    def publish(self, topic: str, data: Any, t: float) -> tuple[Event, list[S]] | None:
        """Number the next event of ``topic`` and fan it out.

        Args:
            topic: event name without the ``ext:`` prefix.
            data: any msgpack value.
            t: the publisher's time, seconds since the Unix epoch.

        Returns:
            ``None`` when nobody is subscribed (the number is used up all the same); else the
            event and the subscribers to send it to now. Paused subscribers are not in that list:
            the event went to their backlog.
        """
        seq = self._seq.get(topic, 0) + 1
        self._seq[topic] = seq
        subs = self._topics.get(topic)
        if not subs:
            return None
        event = Event(topic=topic, t=t, seq=seq, data=data)
        now: list[S] = []
        states = self._subs
        for sub in subs:
            state = states[sub]
            if state.paused:
                if len(state.backlog) == state.backlog.maxlen:
                    state.dropped += 1
                state.backlog.append(event)
            else:
                now.append(sub)
        return event, now

    def last_seq(self, topic: str) -> int:
        """The number of the last event published on ``topic`` (0 if none yet)."""
        return self._seq.get(topic, 0)

    # ---- flow control

    def pause(self, sub: S) -> None:
        """``sub``'s writes are paused: hold its events in its backlog from now on."""
        self._state(sub).paused = True

    def resume(self, sub: S) -> list[Event]:
        """``sub``'s writes resumed: return the events held for it, oldest first, and forget them."""
        state = self._subs.get(sub)
        if state is None:
            return []
        state.paused = False
        held = list(state.backlog)
        state.backlog.clear()
        return held

    def paused(self, sub: S) -> bool:
        """Whether ``sub``'s events are being held."""
        state = self._subs.get(sub)
        return state is not None and state.paused

    def dropped(self, sub: S) -> int:
        """Events dropped from ``sub``'s backlog so far (oldest first, while it was paused)."""
        state = self._subs.get(sub)
        return state.dropped if state is not None else 0
