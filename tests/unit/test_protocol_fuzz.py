"""Fuzzing the frame decoder, the message codec and the handshake with hypothesis (bounded in count).

Whatever bytes arrive, the sans-IO side may only hand out messages or raise
:class:`~services.errors.RemoteProtocolError` (an :class:`~services.errors.AuthenticationError` for a
bad MAC); it never opens without a valid MAC and never buffers more than one capped frame.
"""

from __future__ import annotations

import itertools
import math
import struct
from typing import Any

import msgpack
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from services.errors import RemoteProtocolError
from services.protocol import (
    MAX_AUTH_FRAME,
    Connection,
    FrameReader,
    Message,
    Role,
    State,
    from_map,
    to_map,
    unpack_map,
)
from services.protocol.framing import HEADER_BYTES

KEY = b"k" * 32
FUZZ = settings(max_examples=200, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])

TYPES = ["hello", "auth", "welcome", "call", "accepted", "rejected", "feedback", "result", "cancel", "query",
         "ping", "pong", "subscribe", "unsubscribe", "event", "bye", "teleport"]
FIELDS = ["id", "action", "params", "deadline_ms", "reason", "data", "status", "outcome", "value", "cost",
          "wall_s", "cpu_s", "seq", "topic", "t", "node", "version", "nonce", "mac", "client", "actions",
          "location", "location_changed"]

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(2**63), max_value=2**64 - 1),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=40), st.binary(max_size=40),
)
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)), max_leaves=12)
messages = st.builds(
    lambda t, fields: {"type": t, **fields},
    st.sampled_from(TYPES),
    st.dictionaries(st.sampled_from(FIELDS), values, max_size=8),
)


def frame(body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + body


def drain(conn: Connection) -> list[Message]:
    out: list[Message] = []
    try:
        while (msg := conn.next_message()) is not None:
            out.append(msg)
    except RemoteProtocolError:
        assert conn.state is State.CLOSED
    return out


@FUZZ
@given(data=st.binary(max_size=2000), cuts=st.lists(st.integers(min_value=0, max_value=2000), max_size=8))
def test_the_frame_reader_returns_bodies_or_a_remote_error_and_holds_at_most_one_frame(
        data: bytes, cuts: list[int]) -> None:
    reader = FrameReader(max_frame=256)
    points = sorted({0, len(data), *(c for c in cuts if c <= len(data))})
    try:
        for a, b in itertools.pairwise(points):
            reader.feed(data[a:b])
            while (body := reader.next_body()) is not None:
                assert len(body) <= 256
            assert reader.pending < HEADER_BYTES + 256
        reader.feed(b"")
        assert reader.next_body() is None
    except RemoteProtocolError:
        pass


@FUZZ
@given(data=st.binary(max_size=3000))
def test_random_bytes_never_open_a_node_connection(data: bytes) -> None:
    server = Connection(Role.SERVER, KEY, name="alpha")
    server.receive_data(data)
    drain(server)
    assert server.state is not State.OPEN


@FUZZ
@given(body=messages)
def test_any_map_becomes_a_valid_message_or_a_remote_error(body: dict[str, Any]) -> None:
    try:
        packed = msgpack.packb(body, use_bin_type=True)
    except (OverflowError, ValueError):
        return
    try:
        msg = from_map(unpack_map(packed))
    except RemoteProtocolError:
        return
    again = from_map(unpack_map(msgpack.packb(to_map(msg), use_bin_type=True)))
    assert type(again) is type(msg)


@FUZZ
@given(body=messages, chunk=st.integers(min_value=1, max_value=64))
def test_a_node_in_its_handshake_accepts_only_a_verified_auth(body: dict[str, Any], chunk: int) -> None:
    server = Connection(Role.SERVER, KEY, name="alpha")
    try:
        data = frame(msgpack.packb(body, use_bin_type=True))
    except (OverflowError, ValueError):
        return
    for i in range(0, len(data), chunk):
        server.receive_data(data[i:i + chunk])
    drain(server)
    assert server.state is not State.OPEN
    assert len(server.data_to_send()) < MAX_AUTH_FRAME  # hello, and perhaps nothing else


@FUZZ
@given(body=messages)
def test_an_open_connection_survives_any_map_or_closes_with_a_remote_error(body: dict[str, Any]) -> None:
    client = Connection(Role.CLIENT, KEY, name="c", node="alpha", nonce=bytes(16))
    server = Connection(Role.SERVER, KEY, name="alpha", nonce=bytes(range(16)))
    client.receive_data(server.data_to_send())
    client.next_message()
    server.receive_data(client.data_to_send())
    server.next_message()
    client.receive_data(server.data_to_send())
    client.next_message()
    try:
        data = frame(msgpack.packb(body, use_bin_type=True))
    except (OverflowError, ValueError):
        return
    for side in (server, client):
        side.receive_data(data)
        drain(side)


SETPOINT_FIELDS = ["seq", "t_frame", "t_capture", "t_sent", "x", "y", "t", "vx", "vy", "sigma_y", "sigma_t"]
setpoint_maps = st.one_of(
    values,
    st.dictionaries(st.sampled_from(SETPOINT_FIELDS + ["extra"]), scalars, max_size=12),
    st.fixed_dictionaries({f: st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                         st.integers(min_value=-(2**64), max_value=2**64))
                           for f in SETPOINT_FIELDS}),
)


@FUZZ
@given(maps=st.lists(setpoint_maps, min_size=1, max_size=6))
def test_any_received_set_point_map_is_taken_with_finite_fields_or_counted_as_malformed(maps: list[Any]) -> None:
    from services.catching.setpoints import LatestSetPoint

    latest = LatestSetPoint(max_age=0.2)
    for i, data in enumerate(maps):
        before = latest.latest
        sp = latest.offer_data(data, now=float(i))
        if sp is None:
            assert latest.latest is before
        else:
            assert latest.latest is sp and 0 <= sp.seq < 2**63
            assert all(math.isfinite(getattr(sp, f)) for f in SETPOINT_FIELDS[1:])
    assert latest.received == len(maps)
