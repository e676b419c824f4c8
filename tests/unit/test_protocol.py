"""The sans-IO protocol, tested with two endpoints wired through in-memory bytes (no sockets)."""

from __future__ import annotations

import dataclasses
import struct

import msgpack
import pytest

from services import protocol
from services.errors import AuthenticationError, LocalProtocolError, RemoteProtocolError
from services.protocol import (
    PROTOCOL_VERSION,
    Accepted,
    Auth,
    Bye,
    Call,
    Cancel,
    Connection,
    Event,
    Feedback,
    Hello,
    Message,
    Ping,
    Pong,
    Rejected,
    Result,
    Role,
    State,
    Subscribe,
    Unsubscribe,
    Welcome,
    encode_frame,
    handshake_mac,
)
from services.results import ActionResult, Status

KEY = b"k" * 32
CLIENT_NONCE = bytes(range(16))
SERVER_NONCE = bytes(range(16, 32))


class ConnectionPair:
    """A client and a server Connection whose bytes are carried by hand."""

    def __init__(self, client_key: bytes = KEY, server_key: bytes = KEY, max_frame: int = 1 << 20) -> None:
        self.client = Connection(Role.CLIENT, client_key, name="coord", node="alpha", nonce=CLIENT_NONCE,
                                 max_frame=max_frame)
        self.server = Connection(Role.SERVER, server_key, name="alpha", nonce=SERVER_NONCE, max_frame=max_frame)

    def to_client(self, byte_at_a_time: bool = False) -> list[Message]:
        return self._carry(self.server, self.client, byte_at_a_time)

    def to_server(self, byte_at_a_time: bool = False) -> list[Message]:
        return self._carry(self.client, self.server, byte_at_a_time)

    @staticmethod
    def _carry(src: Connection, dst: Connection, byte_at_a_time: bool) -> list[Message]:
        data = src.data_to_send()
        out: list[Message] = []
        if byte_at_a_time:
            for i in range(len(data)):
                dst.receive_data(data[i:i + 1])
                out.extend(dst.messages())
        else:
            dst.receive_data(data)
            out.extend(dst.messages())
        return out

    def handshake(self, byte_at_a_time: bool = False) -> None:
        assert [type(m) for m in self.to_client(byte_at_a_time)] == [Hello]
        assert [type(m) for m in self.to_server(byte_at_a_time)] == [Auth]
        assert [type(m) for m in self.to_client(byte_at_a_time)] == [Welcome]


def test_handshake_opens_both_sides_and_names_the_peers() -> None:
    pair = ConnectionPair()
    pair.handshake()
    assert pair.client.state is State.OPEN and pair.server.state is State.OPEN
    assert pair.client.peer == "alpha" and pair.server.peer == "coord"


def test_handshake_works_when_bytes_arrive_one_at_a_time() -> None:
    pair = ConnectionPair()
    pair.handshake(byte_at_a_time=True)
    assert pair.client.state is State.OPEN


def test_wrong_key_raises_authentication_error_on_the_server() -> None:
    pair = ConnectionPair(client_key=b"x" * 32)
    pair.to_client()
    with pytest.raises(AuthenticationError):
        pair.to_server()
    assert pair.server.state is State.CLOSED


def test_a_server_without_the_key_is_caught_by_the_client() -> None:
    client = Connection(Role.CLIENT, KEY, name="coord", node="alpha", nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Hello(node="alpha", version=PROTOCOL_VERSION, nonce=SERVER_NONCE)))
    assert isinstance(client.next_message(), Hello)
    client.data_to_send()
    client.receive_data(encode_frame(Welcome(mac=b"\0" * 32)))
    with pytest.raises(AuthenticationError):
        client.next_message()


def test_a_reflected_client_mac_does_not_pass_as_the_server_mac() -> None:
    client = Connection(Role.CLIENT, KEY, name="coord", node="mirror", nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Hello(node="mirror", version=PROTOCOL_VERSION, nonce=SERVER_NONCE)))
    client.next_message()
    client.data_to_send()
    # a peer without the key bounces the client's own MAC back as its welcome
    reflected = handshake_mac(KEY, Role.CLIENT, client="coord", server="mirror", server_nonce=SERVER_NONCE,
                              client_nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Welcome(mac=reflected)))
    with pytest.raises(AuthenticationError):
        client.next_message()


def test_mac_covers_role_both_names_and_both_nonces() -> None:
    def mac(key: bytes = KEY, role: Role = Role.CLIENT, client: str = "coord", server: str = "alpha",
            ns: bytes = SERVER_NONCE, nc: bytes = CLIENT_NONCE) -> bytes:
        return handshake_mac(key, role, client=client, server=server, server_nonce=ns, client_nonce=nc)

    base = mac()
    others = [mac(role=Role.SERVER), mac(ns=CLIENT_NONCE, nc=SERVER_NONCE), mac(key=b"other"),
              mac(client="node:alpha"), mac(server="beta"), mac(client="alpha", server="coord"),
              mac(client="coorda", server="lpha")]  # the names are length-prefixed: no shifting of bytes
    assert len(base) == 32 and base not in others and len(set(others)) == len(others)


def test_a_hello_naming_another_node_than_the_one_meant_is_refused_by_the_client() -> None:
    client = Connection(Role.CLIENT, KEY, name="node:drive", node="perception", nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Hello(node="drive", version=PROTOCOL_VERSION, nonce=SERVER_NONCE)))
    with pytest.raises(AuthenticationError, match="says it is drive, not 'perception'"):
        client.next_message()
    assert client.data_to_send() == b"" and client.state is State.CLOSED  # no auth went out


def test_a_nodes_own_handshake_relayed_to_its_own_server_opens_neither_side() -> None:
    """The reflection of issue 22: a process squatting perception's port relays the drive node's
    outgoing handshake (meant for perception) to the drive node's own server, renaming the hello."""
    drive_server = Connection(Role.SERVER, KEY, name="drive", nonce=SERVER_NONCE)
    drive_link = Connection(Role.CLIENT, KEY, name="node:drive", node="perception", nonce=CLIENT_NONCE)
    hello = drive_server.data_to_send()
    drive_server_hello = protocol.from_map(protocol.unpack_map(hello[4:]))
    assert isinstance(drive_server_hello, Hello)
    renamed = dataclasses.replace(drive_server_hello, node="perception")
    drive_link.receive_data(encode_frame(renamed))
    assert isinstance(drive_link.next_message(), Hello)
    drive_server.receive_data(drive_link.data_to_send())  # the drive node's auth, meant for perception
    with pytest.raises(AuthenticationError):
        drive_server.next_message()
    assert drive_server.state is State.CLOSED and drive_link.state is not State.OPEN


def test_a_servers_mac_replayed_as_a_clients_auth_does_not_verify() -> None:
    pair = ConnectionPair()
    pair.handshake()
    welcome = pair.client.welcome
    assert welcome is not None
    server = Connection(Role.SERVER, KEY, name="alpha", nonce=SERVER_NONCE)
    server.data_to_send()
    server.receive_data(encode_frame(Auth(client="coord", nonce=CLIENT_NONCE, mac=welcome.mac)))
    with pytest.raises(AuthenticationError):
        server.next_message()


def test_a_client_connection_must_name_the_node_it_means_to_reach() -> None:
    with pytest.raises(LocalProtocolError, match="name of the node"):
        Connection(Role.CLIENT, KEY, name="coord")


def test_a_call_before_authentication_is_refused() -> None:
    server = Connection(Role.SERVER, KEY, name="alpha")
    server.receive_data(encode_frame(Call(id="1", action="echo")))
    with pytest.raises(RemoteProtocolError, match="unexpected call"):
        server.next_message()


def test_sending_a_call_before_the_handshake_is_a_local_error() -> None:
    client = Connection(Role.CLIENT, KEY, name="c", node="alpha")
    with pytest.raises(LocalProtocolError):
        client.send(Call(id="1", action="echo"))


def test_full_call_exchange_survives_byte_at_a_time_delivery() -> None:
    pair = ConnectionPair()
    pair.handshake()
    pair.client.send(Call(id="c1", action="wait", params={"seconds": 1.5, "xs": [1, 2]}, deadline_ms=2000))
    pair.client.send(Ping(seq=7))
    got = pair.to_server(byte_at_a_time=True)
    assert got == [Call(id="c1", action="wait", params={"seconds": 1.5, "xs": [1, 2]}, deadline_ms=2000), Ping(seq=7)]
    pair.server.send(Accepted(id="c1"))
    pair.server.send(Pong(seq=7))
    pair.server.send(Feedback(id="c1", data={"fraction": 0.5}))
    pair.server.send(Result(id="c1", result=ActionResult(status=Status.FAILURE, outcome="missed", value=b"\x01", cost=2.0, wall_s=1.0, cpu_s=0.1)))
    got = pair.to_client(byte_at_a_time=True)
    assert [type(m) for m in got] == [Accepted, Pong, Feedback, Result]
    res = got[-1]
    assert isinstance(res, Result)
    r = res.result
    assert (r.status, r.outcome, r.value, r.cost, r.reason) == ("failure", "missed", b"\x01", 2.0, None)


def test_every_message_type_round_trips_in_its_direction() -> None:
    pair = ConnectionPair()
    pair.handshake()
    from_client: list[Message] = [
        Call(id="a", action="x"), Cancel(id="a"), Ping(seq=1), Pong(seq=2),
        Subscribe(topic="tick"), Unsubscribe(topic="tick"),
    ]
    from_server: list[Message] = [
        Accepted(id="a"), Rejected(id="b", reason="busy"), Feedback(id="a", data=None),
        Result(id="a", result=ActionResult(status=Status.ERROR, reason="deadline")), Ping(seq=3), Pong(seq=4),
        Event(topic="tick", t=1.5, seq=9, data={"frame": 3}),
    ]
    for m in from_client:
        pair.client.send(m)
    assert pair.to_server() == from_client
    for m in from_server:
        pair.server.send(m)
    assert pair.to_client() == from_server


def test_messages_are_frozen_slotted_and_keyword_only() -> None:
    msg = Call(id="1", action="echo")
    with pytest.raises(dataclasses.FrozenInstanceError):
        msg.id = "2"  # type: ignore[misc]
    assert not hasattr(msg, "__dict__")
    with pytest.raises(TypeError):
        Call("1", "echo")  # type: ignore[misc]


def test_a_server_may_not_send_a_call_and_a_client_may_not_send_a_result() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(LocalProtocolError):
        pair.server.send(Call(id="1", action="x"))
    with pytest.raises(LocalProtocolError):
        pair.client.send(Result(id="1", result=ActionResult(status=Status.SUCCESS)))
    pair.client.receive_data(encode_frame(Call(id="1", action="x")))
    with pytest.raises(RemoteProtocolError, match="may not send call"):
        pair.client.next_message()


def test_oversize_header_is_rejected_before_the_body_arrives() -> None:
    pair = ConnectionPair(max_frame=1000)
    pair.handshake()
    pair.server.receive_data(struct.pack(">I", 1001))  # header only: no body bytes at all
    with pytest.raises(RemoteProtocolError, match="oversize"):
        pair.server.next_message()


def test_a_frame_at_the_cap_is_accepted() -> None:
    pair = ConnectionPair(max_frame=200)
    pair.handshake()
    body = msgpack.packb({"type": "ping", "seq": 1, "pad": "x" * 150})
    pair.server.receive_data(struct.pack(">I", len(body)) + body)
    assert pair.server.next_message() == Ping(seq=1)


def test_sending_an_oversize_frame_is_a_local_error() -> None:
    pair = ConnectionPair(max_frame=100)
    pair.handshake()
    with pytest.raises(LocalProtocolError, match="exceeds"):
        pair.client.send(Call(id="1", action="x", params={"blob": "y" * 200}))


def test_bad_msgpack_is_a_remote_protocol_error() -> None:
    pair = ConnectionPair()
    pair.handshake()
    pair.server.receive_data(struct.pack(">I", 3) + b"\xc1\xc1\xc1")
    with pytest.raises(RemoteProtocolError, match="bad msgpack"):
        pair.server.next_message()


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ([1, 2, 3], "not a msgpack map"),
        ({"type": "teleport"}, "unknown message type"),
        ({"type": "call", "action": "x"}, "lacks field"),
        ({"type": "call", "id": 5, "action": "x"}, "call.id"),
        ({"type": "call", "id": "1", "action": "x", "deadline_ms": -1}, "deadline_ms"),
        ({"type": "result", "id": "1", "status": "great"}, "status"),
    ],
)
def test_malformed_messages_name_the_problem(body: object, match: str) -> None:
    pair = ConnectionPair()
    pair.handshake()
    data = msgpack.packb(body)
    pair.server.receive_data(struct.pack(">I", len(data)) + data)
    with pytest.raises(RemoteProtocolError, match=match):
        pair.server.next_message()


def test_unknown_extra_fields_are_ignored() -> None:
    pair = ConnectionPair()
    pair.handshake()
    data = msgpack.packb({"type": "cancel", "id": "9", "future_field": True})
    pair.server.receive_data(struct.pack(">I", len(data)) + data)
    assert pair.server.next_message() == Cancel(id="9")


def test_end_of_stream_inside_a_frame_is_an_error_and_between_frames_is_not() -> None:
    pair = ConnectionPair()
    pair.handshake()
    pair.server.receive_data(b"")
    assert pair.server.next_message() is None
    assert pair.server.state is State.CLOSED
    other = ConnectionPair()
    other.handshake()
    other.server.receive_data(b"\x00\x00\x00\x09abc")
    other.server.receive_data(b"")
    with pytest.raises(RemoteProtocolError, match="inside a frame"):
        other.server.next_message()


def test_bye_closes_and_may_be_sent_after_a_protocol_error() -> None:
    pair = ConnectionPair()
    pair.handshake()
    pair.server.receive_data(struct.pack(">I", 1) + b"\xc1")
    with pytest.raises(RemoteProtocolError):
        pair.server.next_message()
    pair.server.send(Bye(reason="protocol_error: bad msgpack"))
    assert pair.to_client() == [Bye(reason="protocol_error: bad msgpack")]
    assert pair.client.state is State.CLOSED
    with pytest.raises(LocalProtocolError):
        pair.server.send(Bye(reason="again"))


def test_a_version_mismatch_is_refused_by_the_client() -> None:
    client = Connection(Role.CLIENT, KEY, name="c", node="n")
    client.receive_data(encode_frame(Hello(node="n", version=PROTOCOL_VERSION + 1, nonce=SERVER_NONCE)))
    with pytest.raises(RemoteProtocolError, match="version"):
        client.next_message()


def test_many_frames_in_one_chunk_are_all_returned_in_order() -> None:
    pair = ConnectionPair()
    pair.handshake()
    for i in range(5000):
        pair.client.send(Ping(seq=i))
    assert [m.seq for m in pair.to_server()] == list(range(5000))  # type: ignore[attr-defined]


def test_public_names_are_exported() -> None:
    for name in protocol.__all__:
        assert hasattr(protocol, name)


def test_an_unencodable_value_is_a_local_error_and_the_connection_goes_on() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(LocalProtocolError, match="result: cannot encode"):
        pair.server.send(Result(id="1", result=ActionResult(status=Status.SUCCESS, value={1, 2})))
    pair.server.send(Result(id="1", result=ActionResult(status=Status.ERROR, reason="result not sendable")))
    assert pair.to_client() == [Result(id="1", result=ActionResult(status=Status.ERROR, reason="result not sendable"))]


# --------------------------------------------------------------------------- hostile bytes


def received(conn: Connection, body: object) -> Message | None:
    data = msgpack.packb(body, use_bin_type=True)
    conn.receive_data(struct.pack(">I", len(data)) + data)
    return conn.next_message()


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ({"type": "call", "id": "1", "action": "x", "deadline_ms": True}, "deadline_ms"),
        ({"type": "call", "id": "1", "action": "x", "deadline_ms": 1.5}, "deadline_ms"),
        ({"type": "ping", "seq": False}, "ping.seq"),
        ({"type": "pong", "seq": 1.0}, "pong.seq"),
        ({"type": "call", "id": "1", "action": "x", "params": []}, "params"),
        ({"type": "query", "id": ""}, "query.id"),
        ({"type": "cancel", "id": None}, "cancel.id"),
        ({"type": "subscribe", "topic": b"tick"}, "topic"),
    ],
)
def test_booleans_floats_and_bytes_are_not_taken_for_integers_or_strings(body: object, match: str) -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(RemoteProtocolError, match=match):
        received(pair.server, body)


def test_a_result_with_boolean_durations_is_refused_and_absent_fields_take_their_defaults() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(RemoteProtocolError, match="durations"):
        received(pair.client, {"type": "result", "id": "1", "status": "success", "wall_s": True})
    pair = ConnectionPair()
    pair.handshake()
    got = received(pair.client, {"type": "result", "id": "2", "status": "failure"})
    assert got == Result(id="2", result=ActionResult(status=Status.FAILURE, value=None, wall_s=0.0, cpu_s=0.0))


def test_an_event_time_must_be_a_number_not_a_boolean() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(RemoteProtocolError, match="event.t"):
        received(pair.client, {"type": "event", "topic": "a", "t": True, "seq": 1})


@pytest.mark.parametrize("mac", [b"", b"\0" * 31, b"\0" * 33, "x" * 32])
def test_an_auth_mac_that_is_not_32_bytes_is_a_protocol_error_not_a_failed_login(mac: object) -> None:
    server = Connection(Role.SERVER, KEY, name="alpha", nonce=SERVER_NONCE)
    with pytest.raises(RemoteProtocolError, match="auth.mac must be 32 bytes") as err:
        received(server, {"type": "auth", "client": "c", "nonce": CLIENT_NONCE, "mac": mac})
    assert not isinstance(err.value, AuthenticationError)


def test_extension_types_and_timestamps_are_refused() -> None:
    pair = ConnectionPair()
    pair.handshake()
    for value in (msgpack.ExtType(5, b"ab"), msgpack.Timestamp(1, 0)):
        data = msgpack.packb({"type": "call", "id": "1", "action": "x", "params": {"v": value}}, use_bin_type=True)
        pair.server.receive_data(struct.pack(">I", len(data)) + data)
        with pytest.raises(RemoteProtocolError, match="extension type"):
            pair.server.next_message()
        pair = ConnectionPair()
        pair.handshake()
    # the timestamp's marker bytes inside binary data are data, not a timestamp
    assert received(pair.server, {"type": "call", "id": "1", "action": "x", "params": {"b": b"\xd6\xff\0\0\0\1"}}) \
        == Call(id="1", action="x", params={"b": b"\xd6\xff\0\0\0\1"})


def test_map_keys_other_than_strings_and_bytes_are_refused_anywhere_in_the_frame() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(RemoteProtocolError, match="map key"):
        received(pair.server, {"type": "call", "id": "1", "action": "x", "params": {1: 2}})
    other = ConnectionPair()
    other.handshake()
    assert received(other.server, {"type": "call", "id": "1", "action": "x", "params": {b"k": 2}}) \
        == Call(id="1", action="x", params={b"k": 2})


def test_a_deeply_nested_value_is_a_protocol_error_not_a_crash() -> None:
    pair = ConnectionPair()
    pair.handshake()
    inner = b"\x91" * 100_000 + b"\xc0"
    head = msgpack.packb({"type": "call", "id": "1", "action": "x"}, use_bin_type=True)
    body = b"\x84" + head[1:] + msgpack.packb("params") + inner
    pair.server.receive_data(struct.pack(">I", len(body)) + body)
    with pytest.raises(RemoteProtocolError, match="bad msgpack"):
        pair.server.next_message()


def test_before_authentication_a_node_buffers_at_most_4_kib_of_a_frame() -> None:
    server = Connection(Role.SERVER, KEY, name="alpha", max_frame=16 << 20)
    server.receive_data(struct.pack(">I", protocol.MAX_AUTH_FRAME + 1))
    with pytest.raises(RemoteProtocolError, match="oversize frame: 4097 bytes announced, cap is 4096"):
        server.next_message()


def test_after_authentication_the_full_frame_cap_applies() -> None:
    pair = ConnectionPair(max_frame=1 << 20)
    pair.handshake()
    pair.client.send(Call(id="1", action="x", params={"blob": b"x" * 100_000}))
    assert [type(m) for m in pair.to_server()] == [Call]


def test_a_client_accepts_a_welcome_larger_than_a_node_accepts_an_auth() -> None:
    offer = protocol.Offer(actions=tuple(f"action_{i:05d}" for i in range(2000)), location="ab" * 32)
    client = Connection(Role.CLIENT, KEY, name="coord", node="alpha", nonce=CLIENT_NONCE)
    server = Connection(Role.SERVER, KEY, name="alpha", nonce=SERVER_NONCE, offer=lambda: offer)
    client.receive_data(server.data_to_send())
    client.next_message()
    server.receive_data(client.data_to_send())
    server.next_message()
    welcome_frame = server.data_to_send()
    assert len(welcome_frame) > protocol.MAX_AUTH_FRAME
    client.receive_data(welcome_frame)
    welcome = client.next_message()
    assert isinstance(welcome, Welcome) and client.state is State.OPEN
    assert client.welcome == welcome and welcome.actions == list(offer.actions)
    assert (welcome.location, welcome.location_changed) == ("ab" * 32, False)


def test_welcome_tells_the_actions_and_the_services_digest_and_old_welcomes_still_parse() -> None:
    offer = protocol.Offer(actions=("echo", "wait"), location="d" * 64, location_changed=True)
    pair = ConnectionPair()
    pair.server = Connection(Role.SERVER, KEY, name="alpha", nonce=SERVER_NONCE, offer=lambda: offer)
    pair.handshake()
    assert pair.client.welcome == Welcome(mac=pair.client.welcome.mac, actions=["echo", "wait"],  # type: ignore[union-attr]
                                          location="d" * 64, location_changed=True)
    mac = handshake_mac(KEY, Role.SERVER, client="coord", server="alpha", server_nonce=SERVER_NONCE,
                       client_nonce=CLIENT_NONCE)
    v1 = msgpack.packb({"type": "welcome", "mac": mac}, use_bin_type=True)
    assert protocol.from_map(protocol.unpack_map(v1)) == Welcome(mac=mac, actions=None, location=None,
                                                                  location_changed=False)


def test_a_query_travels_from_client_to_node_only() -> None:
    pair = ConnectionPair()
    pair.handshake()
    pair.client.send(protocol.Query(id="c7"))
    assert pair.to_server() == [protocol.Query(id="c7")]
    with pytest.raises(LocalProtocolError):
        pair.server.send(protocol.Query(id="c7"))


def test_a_node_accepts_a_previous_key_during_rotation_and_answers_with_it() -> None:
    old, new = b"o" * 32, b"n" * 32
    client = Connection(Role.CLIENT, old, name="coord", node="alpha", nonce=CLIENT_NONCE)
    server = Connection(Role.SERVER, new, name="alpha", nonce=SERVER_NONCE, previous_keys=[old])
    client.receive_data(server.data_to_send())
    client.next_message()
    server.receive_data(client.data_to_send())
    assert isinstance(server.next_message(), Auth) and server.key_index == 1
    client.receive_data(server.data_to_send())
    assert isinstance(client.next_message(), Welcome) and client.state is State.OPEN
    stranger = Connection(Role.CLIENT, b"s" * 32, name="coord", node="alpha", nonce=CLIENT_NONCE)
    server = Connection(Role.SERVER, new, name="alpha", nonce=SERVER_NONCE, previous_keys=[old])
    stranger.receive_data(server.data_to_send())
    stranger.next_message()
    server.receive_data(stranger.data_to_send())
    with pytest.raises(AuthenticationError):
        server.next_message()


def test_macs_over_different_tls_channel_bindings_do_not_verify() -> None:
    pair = ConnectionPair()
    pair.client.binding = b"client side of a relay"
    pair.server.binding = b"node side of a relay"
    pair.to_client()
    with pytest.raises(AuthenticationError):
        pair.to_server()
    same = ConnectionPair()
    same.client.binding = same.server.binding = b"one TLS session"
    same.handshake()
    assert same.client.state is State.OPEN
    names = {"client": "coord", "server": "alpha", "server_nonce": SERVER_NONCE, "client_nonce": CLIENT_NONCE}
    assert handshake_mac(KEY, Role.CLIENT, **names, binding=b"") == handshake_mac(KEY, Role.CLIENT, **names)


def test_protocol_errors_show_untrusted_text_escaped_and_short() -> None:
    pair = ConnectionPair()
    pair.handshake()
    with pytest.raises(RemoteProtocolError) as err:
        received(pair.server, {"type": "x\n2026-01-01 forged line\x1b[2J" + "y" * 10_000})
    text = str(err.value)
    assert "\n" not in text and "\x1b" not in text and len(text) < 300
    assert "\\n2026-01-01 forged line\\x1b[2J" in text


def test_shown_escapes_control_characters_and_truncates() -> None:
    assert protocol.shown("ok") == "ok"
    assert protocol.shown("a\nb\r\t\x00\x1b\u2028\\") == "a\\nb\\r\\t\\x00\\x1b\\u2028\\\\"
    long = protocol.shown("z" * 1000, 10)
    assert long == "z" * 10 + "…(+990 chars)"
    assert protocol.shown(b"\n" * 100, 4) == "b'\\n\\n\\n\\n'…(+96 bytes)"
    assert len(protocol.shown(list(range(100_000)))) < 400
