"""Set-point stream: codec and latest-wins holder without sockets, then over 127.0.0.1."""

from __future__ import annotations

import asyncio
import struct

import msgpack
import pytest

from services.errors import RemoteProtocolError
from services.stream import (
    LatestSetPoint,
    SetPoint,
    SetPointDecoder,
    SetPointReceiver,
    SetPointSender,
    StreamLostError,
    encode,
)


def _sp(seq: int, y: float = 0.1) -> SetPoint:
    return SetPoint(seq=seq, t_frame=0.5, t_capture=10.0, t_sent=10.001, x=0.75, y=y, t=1.2,
                    vx=-0.9, vy=0.05, sigma_y=0.001, sigma_t=0.002)


def test_set_points_survive_encoding_split_into_arbitrary_chunks():
    data = b"".join(encode(_sp(i, 0.01 * i)) for i in range(5))
    dec = SetPointDecoder()
    got = []
    for k in range(0, len(data), 7):
        got += dec.feed(data[k : k + 7])
    assert got == [_sp(i, 0.01 * i) for i in range(5)]


def test_an_oversize_message_is_refused_before_its_body_arrives():
    dec = SetPointDecoder(max_message=100)
    with pytest.raises(RemoteProtocolError):
        dec.feed(struct.pack(">I", 101))


def test_a_message_that_is_not_a_set_point_is_a_remote_protocol_error():
    body = msgpack.packb({"seq": 1, "x": "far"})
    with pytest.raises(RemoteProtocolError):
        SetPointDecoder().feed(struct.pack(">I", len(body)) + body)
    body = msgpack.packb([1, 2, 3])
    with pytest.raises(RemoteProtocolError):
        SetPointDecoder().feed(struct.pack(">I", len(body)) + body)


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


async def test_set_points_stream_over_tcp_and_a_closed_sender_loses_the_stream():
    recv = SetPointReceiver(max_age=0.5)
    port = await recv.start()
    try:
        sender = await asyncio.to_thread(SetPointSender, "127.0.0.1", port)
        for i in range(10):
            sender.send(t_frame=0.02 * i, t_capture=0.0, x=0.75, y=0.01 * i, t=1.0, vx=-1.0, vy=0.0)
        sp = await recv.wait_newer(8, timeout=2.0)
        assert sp.seq == 9 and sp.y == pytest.approx(0.09)
        assert recv.latest().seq == 9
        sender.close()
        async with asyncio.timeout(2.0):
            while recv.connected:
                await asyncio.sleep(0.01)
        with pytest.raises(StreamLostError, match="closed"):
            recv.latest()
        with pytest.raises(StreamLostError):
            await recv.wait_newer(9, timeout=0.5)
    finally:
        await recv.close()


async def test_waiting_for_a_set_point_that_never_comes_times_out():
    recv = SetPointReceiver()
    await recv.start()
    try:
        with pytest.raises(StreamLostError, match="within"):
            await recv.wait_newer(-1, timeout=0.1)
    finally:
        await recv.close()
