"""Set points: validation and the latest-wins holder without sockets, then published as events of
a node on 127.0.0.1 and received through an authenticated node link (services/catching/setpoints.py)."""

from __future__ import annotations

import asyncio
import math
import socket
import time

import pytest

from services.client import NodeLink
from services.errors import AuthenticationError
from services.location import parse_location
from services.node.server import Node
from services.catching.setpoints import (
    MAX_SEQ,
    LatestSetPoint,
    MalformedSetPoint,
    CatchSetPoint,
    SetPointSubscription,
    StreamLostError,
)
from tests.ports import free_port

KEY = bytes.fromhex("9c41e7d02b5f86a3147ed9c2058bf36e71a4d80c95e32fb6486a1dd7c0935e2b")


def _sp(seq: int, y: float = 0.1, t_frame: float = 0.5) -> CatchSetPoint:
    return CatchSetPoint(seq=seq, t_frame=t_frame, t_capture=10.0, t_sent=10.001, x=0.75, y=y, t=1.2,
                    vx=-0.9, vy=0.05, sigma_y=0.001, sigma_t=0.002)


# --- validation (no sockets) --------------------------------------------------------------------


def test_a_set_point_survives_its_dict_form():
    assert CatchSetPoint.from_dict(_sp(7).to_dict()) == _sp(7)
    bare = {k: v for k, v in _sp(3).to_dict().items() if not k.startswith("sigma")}
    assert CatchSetPoint.from_dict(bare).sigma_y == 0.0


@pytest.mark.parametrize(("field", "value", "says"), [
    ("seq", float("inf"), "seq"),  # crashed the old receiver with OverflowError
    ("seq", -1, "seq"),
    ("seq", MAX_SEQ, "seq"),
    ("seq", True, "seq"),
    ("seq", 1.0, "seq"),
    ("y", float("nan"), "y"),
    ("t", float("inf"), "t"),
    ("x", 1e6, "x"),
    ("vx", "fast", "vx"),
    ("t_frame", None, "t_frame"),
    ("sigma_t", -0.1, "negative"),
])
def test_a_set_point_with_a_bad_field_is_refused_naming_it(field, value, says):
    data = _sp(1).to_dict()
    data[field] = value
    with pytest.raises(MalformedSetPoint, match=says):
        CatchSetPoint.from_dict(data)


def test_a_set_point_that_is_not_a_map_of_few_fields_is_refused():
    with pytest.raises(MalformedSetPoint, match="map"):
        CatchSetPoint.from_dict([1, 2, 3])
    huge = {**_sp(1).to_dict(), **{f"k{i}": 0 for i in range(40)}}
    with pytest.raises(MalformedSetPoint, match="at most"):
        CatchSetPoint.from_dict(huge)
    missing = _sp(1).to_dict()
    del missing["t"]
    with pytest.raises(MalformedSetPoint, match="without 't'"):
        CatchSetPoint.from_dict(missing)


def test_a_malformed_set_point_is_dropped_and_counted_and_the_latest_stays():
    h = LatestSetPoint(max_age=0.1)
    assert h.offer_data(_sp(2).to_dict(), now=1.0) == _sp(2)
    assert h.offer_data({**_sp(3).to_dict(), "seq": float("inf")}, now=1.01) is None
    assert h.offer_data("garbage", now=1.02) is None
    assert h.malformed == 2 and h.last_malformed is not None and "map" in h.last_malformed
    assert h.get(1.05) == _sp(2)
    assert h.offer_data(_sp(4).to_dict(), now=1.06) == _sp(4)


def test_the_latest_set_point_wins_and_older_ones_are_dropped():
    h = LatestSetPoint(max_age=0.1)
    assert h.offer(_sp(3), now=1.0)
    assert not h.offer(_sp(2), now=1.01)
    assert not h.offer(_sp(3), now=1.02)
    assert h.get(1.05).seq == 3
    assert h.dropped == 2 and h.received == 3


def test_a_stale_never_started_or_closed_stream_is_lost():
    h = LatestSetPoint(max_age=0.1)
    with pytest.raises(StreamLostError, match="no set point"):
        h.get(0.0)
    h.offer(_sp(0), now=1.0)
    with pytest.raises(StreamLostError, match="stale"):
        h.get(1.2)
    h.close("sender closed the connection")
    with pytest.raises(StreamLostError, match="lost"):
        h.get(1.0)


def test_a_slow_camera_clock_keeps_a_set_point_fresh_that_the_wall_clock_alone_would_call_stale():
    h = LatestSetPoint(max_age=0.2)
    h.offer(_sp(0, t_frame=5.0), now=100.0)
    # 0.5 s of wall time but only 0.1 s on the camera clock: a simulation running slowly
    assert h.get(100.5, camera_now=5.1).seq == 0
    with pytest.raises(StreamLostError, match="camera clock"):
        h.get(100.5, camera_now=5.3)
    assert h.age(100.5) == pytest.approx(0.5)


# --- over a node on 127.0.0.1 -------------------------------------------------------------------

@pytest.fixture
async def vision():
    node = Node("vision", parse_location(f'[nodes.vision]\nhost = "127.0.0.1"\nport = {free_port()}\n'), KEY)
    await node.start()
    yield node
    await node.stop()


async def _wait(pred, what: str, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, f"no {what} within {timeout} s"
        await asyncio.sleep(0.01)


async def _subscribed(node: Node, link: NodeLink) -> None:
    """Wait until ``link`` is connected and its subscription to set points is in place on ``node``
    (what is published before is not delivered to it)."""
    await _wait(lambda: link.connected, "connection")
    await _wait(lambda: bool(node._fanout.subscribers("setpoints")), "subscription on the node")


async def test_set_points_published_by_a_node_reach_the_subscription_and_a_bad_one_is_only_counted(vision):
    link = NodeLink("vision", ("127.0.0.1", vision.port), KEY, name="node:motion")
    sub = SetPointSubscription(link, max_age=5.0)
    sub.start()
    try:
        await _subscribed(vision, link)
        for i in range(5):
            vision.publish("setpoints", _sp(i, 0.01 * i).to_dict())
        vision.publish("setpoints", {**_sp(5).to_dict(), "seq": float("inf")})
        vision.publish("setpoints", {**_sp(6).to_dict(), "x": float("nan")})
        vision.publish("setpoints", _sp(7, 0.07).to_dict())
        await _wait(lambda: sub.state.latest is not None and sub.state.latest.seq == 7, "set point 7")
        assert sub.latest().y == pytest.approx(0.07)
        assert sub.state.malformed == 2 and sub.events == 8
        fresh = sub.restart()
        with pytest.raises(StreamLostError, match="no set point"):
            sub.latest()
        vision.publish("setpoints", _sp(0, -0.2).to_dict())  # a new predict call starts at seq 0
        await _wait(lambda: fresh.latest is not None, "set point of the new stream")
        assert sub.latest().y == pytest.approx(-0.2)
    finally:
        sub.close()
        await link.close()


async def test_a_peer_without_the_key_cannot_inject_and_a_connect_then_close_ends_nothing(vision):
    link = NodeLink("vision", ("127.0.0.1", vision.port), KEY, name="node:motion")
    sub = SetPointSubscription(link, max_age=5.0)
    sub.start()
    try:
        await _subscribed(vision, link)
        vision.publish("setpoints", _sp(1).to_dict())
        await _wait(lambda: sub.state.latest is not None, "the first set point")
        stranger = NodeLink("vision", ("127.0.0.1", vision.port), bytes(32), name="intruder", connect_timeout_s=2.0)
        with pytest.raises(AuthenticationError):
            await stranger.connect()
        await stranger.close()
        for _ in range(20):  # connect, then close at once
            with socket.create_connection(("127.0.0.1", vision.port), timeout=2.0):
                pass
        raw = socket.create_connection(("127.0.0.1", vision.port), timeout=2.0)
        raw.sendall(b"\x00\x00\x00\x10not a frame at all")  # garbage: that one connection is closed
        raw.close()
        vision.publish("setpoints", _sp(2, 0.3).to_dict())
        await _wait(lambda: sub.state.latest is not None and sub.state.latest.seq == 2, "set point 2")
        assert link.connected and sub.state.malformed == 0
        assert sub.latest().y == pytest.approx(0.3)
    finally:
        sub.close()
        await link.close()


async def test_a_subscription_says_so_when_its_link_is_down():
    link = NodeLink("vision", ("127.0.0.1", free_port()), KEY, name="node:motion", connect_timeout_s=0.2)
    sub = SetPointSubscription(link)
    sub.start()
    try:
        with pytest.raises(StreamLostError, match="link to node vision is down"):
            sub.latest()
        assert math.isinf(sub.state.age(time.time()))
    finally:
        sub.close()
        await link.close()


def test_a_sequence_number_far_ahead_is_refused_while_the_stream_is_live_and_restarts_it_after_silence():
    h = LatestSetPoint(max_age=0.1)
    assert h.offer(_sp(3), now=1.0)
    assert not h.offer(_sp(2**62), now=1.01)  # one forged number must not make the rest look old
    assert h.jumps == 1 and h.note is not None and "refused" in h.note
    assert h.offer(_sp(4), now=1.02) and h.get(1.03).seq == 4
    assert not h.offer(_sp(1), now=1.05)  # older, the stream live: dropped
    assert h.offer(_sp(1), now=1.2) and h.restarts == 1 and "restarted" in (h.note or "")


async def test_a_subscription_refused_by_a_stranger_on_the_port_retries_until_the_real_node_is_back():
    """Issue 22: a failed authentication towards a publisher (a stranger on a restarted node's port)
    made the subscriber give up for good; now it retries with backoff, as for a lost connection."""
    port = free_port()
    stranger = Node("vision", parse_location(f'[nodes.vision]\nhost = "127.0.0.1"\nport = {port}\n'),
                    bytes.fromhex("61f0c2b9e8d4a7135c9e0f27b86d4a1c3e5f70b2d9a8c6e41f3b57d09a2c8e61"))
    await stranger.start()
    link = NodeLink("vision", ("127.0.0.1", port), KEY, name="node:motion", connect_timeout_s=0.5)
    sub = SetPointSubscription(link, max_age=5.0)
    sub.start()
    real = None
    try:
        await asyncio.sleep(0.5)  # a few refused attempts
        assert not link.connected
        await stranger.stop()
        real = Node("vision", parse_location(f'[nodes.vision]\nhost = "127.0.0.1"\nport = {port}\n'), KEY)
        await real.start()
        await _subscribed(real, link)
        real.publish("setpoints", _sp(1, 0.2).to_dict())
        await _wait(lambda: sub.state.latest is not None, "a set point from the real node")
    finally:
        sub.close()
        await link.close()
        if real is not None:
            await real.stop()
