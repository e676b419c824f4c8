"""The sans-IO protocol, tested with two endpoints wired through in-memory bytes (no sockets)."""

from __future__ import annotations

import dataclasses
import struct

import msgpack
import pytest

from services.errors import AuthenticationError, LocalProtocolError, RemoteProtocolError
from services import protocol
from services.results import ActionResult, Status
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

KEY = b"k" * 32
CLIENT_NONCE = bytes(range(16))
SERVER_NONCE = bytes(range(16, 32))


class ConnectionPair:
    """A client and a server Connection whose bytes are carried by hand."""

    def __init__(self, client_key: bytes = KEY, server_key: bytes = KEY, max_frame: int = 1 << 20) -> None:
        self.client = Connection(Role.CLIENT, client_key, name="coord", nonce=CLIENT_NONCE, max_frame=max_frame)
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
    client = Connection(Role.CLIENT, KEY, name="coord", nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Hello(node="evil", version=PROTOCOL_VERSION, nonce=SERVER_NONCE)))
    assert isinstance(client.next_message(), Hello)
    client.data_to_send()
    client.receive_data(encode_frame(Welcome(mac=b"\0" * 32)))
    with pytest.raises(AuthenticationError):
        client.next_message()


def test_a_reflected_client_mac_does_not_pass_as_the_server_mac() -> None:
    client = Connection(Role.CLIENT, KEY, name="coord", nonce=CLIENT_NONCE)
    client.receive_data(encode_frame(Hello(node="mirror", version=PROTOCOL_VERSION, nonce=SERVER_NONCE)))
    client.next_message()
    client.data_to_send()
    # a peer without the key bounces the client's own MAC back as its welcome
    reflected = handshake_mac(KEY, Role.CLIENT, SERVER_NONCE, CLIENT_NONCE)
    client.receive_data(encode_frame(Welcome(mac=reflected)))
    with pytest.raises(AuthenticationError):
        client.next_message()


def test_mac_covers_role_and_both_nonces() -> None:
    base = handshake_mac(KEY, Role.CLIENT, SERVER_NONCE, CLIENT_NONCE)
    assert base != handshake_mac(KEY, Role.SERVER, SERVER_NONCE, CLIENT_NONCE)
    assert base != handshake_mac(KEY, Role.CLIENT, CLIENT_NONCE, SERVER_NONCE)
    assert base != handshake_mac(b"other", Role.CLIENT, SERVER_NONCE, CLIENT_NONCE)
    assert len(base) == 32


def test_a_call_before_authentication_is_refused() -> None:
    server = Connection(Role.SERVER, KEY, name="alpha")
    server.receive_data(encode_frame(Call(id="1", action="echo")))
    with pytest.raises(RemoteProtocolError, match="unexpected call"):
        server.next_message()


def test_sending_a_call_before_the_handshake_is_a_local_error() -> None:
    client = Connection(Role.CLIENT, KEY, name="c")
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
    client = Connection(Role.CLIENT, KEY, name="c")
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
