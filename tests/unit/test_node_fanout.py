"""The node's event fan-out (services.node.fanout), driven as pure logic: no sockets, no event loop."""

from __future__ import annotations

import pytest

from services.node.fanout import Fanout, Refusal


def test_a_slow_subscriber_loses_its_oldest_events_and_never_blocks_the_node() -> None:
    fan: Fanout[str] = Fanout(backlog=256)
    fan.subscribe("slow", "tick")
    fan.pause("slow")  # the kernel buffer is full: the subscriber is not reading
    for i in range(1000):
        delivery = fan.publish("tick", {"i": i}, t=float(i))
        assert delivery is not None and delivery[1] == []  # nothing to send now, nothing to wait for
    held = fan.resume("slow")
    assert [e.seq for e in held] == list(range(1000 - 256 + 1, 1001))  # the newest 256, in order
    assert held[-1].data == {"i": 999} and held[-1].t == 999.0
    assert fan.dropped("slow") == 1000 - 256
    assert fan.resume("slow") == []  # handed over once


def test_events_flow_straight_through_to_a_subscriber_that_keeps_up() -> None:
    fan: Fanout[str] = Fanout()
    fan.subscribe("fast", "tick")
    first = fan.publish("tick", 1, t=10.0)
    assert fan.publish("other", 2, t=11.0) is None  # nobody subscribed: dropped at the source
    second = fan.publish("tick", 3, t=12.0)
    assert first is not None and second is not None
    assert [(e.topic, e.seq, e.data, e.t, to) for e, to in (first, second)] == [
        ("tick", 1, 1, 10.0, ["fast"]), ("tick", 2, 3, 12.0, ["fast"])]
    assert fan.dropped("fast") == 0


def test_each_topic_is_numbered_from_one_whether_or_not_anyone_listens() -> None:
    fan: Fanout[str] = Fanout()
    fan.publish("a", None, t=0.0)
    fan.publish("a", None, t=0.0)
    fan.publish("b", None, t=0.0)
    assert (fan.last_seq("a"), fan.last_seq("b"), fan.last_seq("c")) == (2, 1, 0)
    fan.subscribe("s", "a")
    delivery = fan.publish("a", None, t=0.0)
    assert delivery is not None and delivery[0].seq == 3  # the gap shows the events it missed


def test_only_the_paused_subscriber_holds_events() -> None:
    fan: Fanout[str] = Fanout()
    fan.subscribe("slow", "tick")
    fan.subscribe("fast", "tick")
    fan.pause("slow")
    delivery = fan.publish("tick", "x", t=0.0)
    assert delivery is not None and delivery[1] == ["fast"]
    assert fan.paused("slow") and not fan.paused("fast")
    assert [e.data for e in fan.resume("slow")] == ["x"] and not fan.paused("slow")


def test_a_subscriber_that_goes_away_is_unsubscribed_from_every_topic() -> None:
    fan: Fanout[str] = Fanout()
    for topic in ("a", "b"):
        fan.subscribe("gone", topic)
        fan.subscribe("stays", topic)
    fan.pause("gone")
    fan.remove("gone")
    assert fan.topics("gone") == frozenset() and fan.subscribers("a") == {"stays"}
    delivery = fan.publish("b", None, t=0.0)
    assert delivery is not None and delivery[1] == ["stays"]
    assert fan.resume("gone") == [] and fan.dropped("gone") == 0
    fan.remove("never-seen")  # harmless


def test_unsubscribe_stops_one_topic_only() -> None:
    fan: Fanout[str] = Fanout()
    fan.subscribe("s", "a")
    fan.subscribe("s", "b")
    fan.unsubscribe("s", "a")
    fan.unsubscribe("s", "never")  # harmless
    assert fan.publish("a", None, t=0.0) is None
    assert fan.topics("s") == {"b"} and fan.subscribers("b") == {"s"}


def test_subscribing_twice_to_a_topic_counts_once() -> None:
    fan: Fanout[str] = Fanout(max_topics=1)
    assert fan.subscribe("s", "a") is None
    assert fan.subscribe("s", "a") is None
    delivery = fan.publish("a", None, t=0.0)
    assert delivery is not None and delivery[1] == ["s"]


def test_a_subscriber_past_its_topic_cap_is_refused_too_many_topics() -> None:
    fan: Fanout[str] = Fanout(max_topics=2)
    assert fan.subscribe("s", "a") is None and fan.subscribe("s", "b") is None
    assert fan.subscribe("s", "c") is Refusal.TOO_MANY_TOPICS
    assert fan.topics("s") == {"a", "b"} and fan.subscribers("c") == frozenset()
    assert fan.subscribe("other", "c") is None  # the cap is per subscriber
    fan.unsubscribe("s", "a")
    assert fan.subscribe("s", "c") is None


def test_a_topic_name_longer_than_the_byte_cap_is_refused_topic_too_long() -> None:
    fan: Fanout[str] = Fanout(max_topic_bytes=8)
    assert fan.subscribe("s", "x" * 8) is None
    assert fan.subscribe("s", "x" * 9) is Refusal.TOPIC_TOO_LONG
    assert fan.subscribe("s", "é" * 5) is Refusal.TOPIC_TOO_LONG  # 10 bytes of UTF-8
    assert fan.topics("s") == {"x" * 8}
    assert Refusal.TOPIC_TOO_LONG == "topic_too_long" and Refusal.TOO_MANY_TOPICS == "too_many_topics"


def test_fanout_bounds_below_one_are_a_value_error() -> None:
    for bounds in ({"backlog": 0}, {"max_topics": 0}, {"max_topic_bytes": 0}):
        with pytest.raises(ValueError):
            Fanout(**bounds)
