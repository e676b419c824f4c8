"""petrobot's ROS 2 clients against hand-made Zenoh peers in one process, on loopback: what a
misbehaving or vanishing server does to a call (never a hang), the graph it follows, and the
zenoh-bridge-ros2dds dialect (plain keys, no attachment, as the bridge's own tests query it)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest
import zenoh

from services.ros2.config import SessionSettings
from services.ros2.endpoints import CallFailed, ServiceClient, Subscription
from services.ros2.errors import Ros2ConfigError, Ros2Error, Ros2FieldError
from services.ros2.graph import Attachment, Dialect, Entity, EntityKind
from services.ros2.qos import encode_qos, Qos
from services.ros2.session import Ros2Session
from services.ros2.typestore import TypeStore, load_definitions
from tests.ports import free_port

pytestmark = pytest.mark.timeout(60)

STORE = TypeStore(load_definitions())
ADD = "example_interfaces/srv/AddTwoInts"


def _config(mode: str, **values: Any) -> zenoh.Config:
    config = zenoh.Config()
    for key, value in {"mode": mode, "scouting/multicast/enabled": False, **values}.items():
        config.insert_json5(key, json.dumps(value))
    return config


class Peer:
    """A Zenoh router and a raw peer session playing the ROS 2 side."""

    def __init__(self) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.router = zenoh.open(_config("router", **{"listen/endpoints": [self.endpoint]}))
        # client mode on both sides: every message through the router, no peer-to-peer links being
        # set up while a test runs (which can briefly route a query nowhere)
        self.session = zenoh.open(_config("client", **{"connect/endpoints": [self.endpoint]}))
        self.undeclare: list[Any] = []

    def serve(self, key: str, answer: Callable[[Any], None]) -> Any:
        def answer_or_probe(query: Any) -> None:
            if query.payload is not None and query.payload.to_bytes() == PROBE:
                query.reply_err(PROBE)  # _routed's question: the route to this queryable works
            else:
                answer(query)

        queryable = self.session.declare_queryable(key, answer_or_probe, complete=True)
        self.undeclare.append(queryable)
        return queryable

    def token(self, key: str) -> Any:
        token = self.session.liveliness().declare_token(key)
        self.undeclare.append(token)
        return token

    def close(self) -> None:
        for thing in self.undeclare:
            try:
                thing.undeclare()
            except Exception:  # noqa: BLE001
                pass
        self.session.close()
        if not self.router.is_closed():
            self.router.close()


@pytest.fixture
async def peer() -> AsyncIterator[Peer]:
    p = Peer()
    try:
        yield p
    finally:
        p.close()


PROBE = b"probe"


async def _routed(session: Ros2Session, key: str) -> None:
    """Wait until a query from ``session`` on ``key`` reaches the peer's queryable (declarations and
    routes travel): ask with a probe the peer answers at once, until it does."""
    while True:
        replies = await asyncio.to_thread(
            lambda: list(session.zenoh.get(key, payload=PROBE, target=zenoh.QueryTarget.ALL_COMPLETE, timeout=2)))
        if any(r.err is not None and r.err.payload.to_bytes() == PROBE for r in replies):
            return
        await asyncio.sleep(0.01)


async def _tokens(peer: Peer, count: int) -> list[str]:
    """The rmw_zenoh tokens of domain 0 the peer sees, once there are ``count`` of them."""
    while True:
        seen = [str(r.ok.key_expr) for r in peer.session.liveliness().get("@ros2_lv/0/**", timeout=5) if r.ok]
        if len(seen) >= count:
            return seen
        await asyncio.sleep(0.01)


async def _session(peer: Peer, **settings: Any) -> Ros2Session:
    session = Ros2Session(SessionSettings(connect=(peer.endpoint,), mode="client", **settings), "tester", STORE)
    await session.open()
    return session


def _server_token(name: str, session_id: str = "abcd") -> str:
    return Entity(domain_id=0, session_id=session_id, node_id=0, entity_id=1, kind=EntityKind.SERVICE,
                  namespace="/", node_name="server", name=name, dds_type="example_interfaces::srv::dds_::AddTwoInts_",
                  type_hash=STORE.hash(ADD), qos=encode_qos(Qos())).token


def _adder(reply_attachment: Callable[[Attachment], bytes | None] = lambda a: a.encode()) -> Callable[[Any], None]:
    def answer(query: Any) -> None:
        request = STORE.decode(f"{ADD}_Request", query.payload.to_bytes())
        asked = Attachment.decode(query.attachment.to_bytes())
        echoed = Attachment(asked.sequence_number, 1, asked.gid)
        query.reply(query.key_expr, STORE.encode(f"{ADD}_Response", {"sum": request["a"] + request["b"]}),
                    attachment=reply_attachment(echoed))
    return answer


async def test_a_call_is_answered_by_an_rmw_zenoh_style_server(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    peer.serve(client.key, _adder())
    await _routed(session, client.key)
    assert await client.call({"a": 2, "b": 40}, timeout_s=10) == {"sum": 42}
    await session.close()


async def test_a_reply_to_someone_elses_request_is_not_taken_for_the_answer(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    peer.serve(client.key, _adder(lambda a: Attachment(a.sequence_number + 7, 1, a.gid).encode()))
    await _routed(session, client.key)
    with pytest.raises(CallFailed, match="only a reply for another request"):
        await client.call({"a": 1, "b": 1}, timeout_s=5)
    await session.close()


async def test_a_server_that_never_answers_is_cut_off_by_the_timeout(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    held: list[Any] = []
    peer.serve(client.key, held.append)
    await _routed(session, client.key)
    with pytest.raises(CallFailed, match="no answer within 0.5 s"):
        await client.call({"a": 1, "b": 1}, timeout_s=0.5)
    await session.close()


@pytest.mark.parametrize("answer, words", [
    (lambda q: q.reply_err(b"service callback exploded"), "error reply: service callback exploded"),
    (lambda q: q.reply(q.key_expr, b"\x00\x01\x00\x00\x01",
                       attachment=Attachment.decode(q.attachment.to_bytes()).encode()), "malformed response"),
    (lambda q: q.reply(q.key_expr, b"\x00\x01\x00\x00" + bytes(8), attachment=b"short"), "without a valid attachment"),
])
async def test_a_misbehaving_server_ends_the_call_with_a_reason(peer: Peer, answer: Any, words: str):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    peer.serve(client.key, answer)
    await _routed(session, client.key)
    with pytest.raises(CallFailed, match=words):
        await client.call({"a": 1, "b": 1}, timeout_s=5)
    await session.close()


async def test_no_server_at_all_is_said_at_once(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    with pytest.raises(CallFailed, match="no service server answered"):
        await client.call({"a": 1, "b": 1}, timeout_s=30)
    await session.close()


async def test_a_query_no_one_answers_after_the_server_took_part_says_it_went_away(peer: Peer):
    # an action server that accepted a goal and was killed before the get_result query went out:
    # its token left the graph before the query did, yet "no server" would misname what happened
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    with pytest.raises(CallFailed, match="the server went away before answering"):
        await client.call({"a": 1, "b": 1}, timeout_s=30, served=True)
    await session.close()


async def test_a_server_whose_token_leaves_the_graph_ends_the_call_it_never_answers(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    asked = asyncio.Event()
    loop = asyncio.get_running_loop()
    held: list[Any] = []
    peer.serve(client.key, lambda q: (held.append(q), loop.call_soon_threadsafe(asked.set)))
    token = peer.token(_server_token("/add_two_ints"))
    await _routed(session, client.key)
    while not session.servers("/add_two_ints"):
        await asyncio.sleep(0.01)
    call = asyncio.create_task(client.call({"a": 1, "b": 1}))
    await asyncio.wait_for(asked.wait(), 10)
    token.undeclare()
    with pytest.raises(CallFailed, match="left the ROS 2 graph"):
        await call
    await session.close()


async def test_losing_the_router_ends_a_pending_call_at_once_and_says_why(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    held: list[Any] = []
    asked = asyncio.Event()
    loop = asyncio.get_running_loop()
    peer.serve(client.key, lambda q: (held.append(q), loop.call_soon_threadsafe(asked.set)))
    await _routed(session, client.key)
    call = asyncio.create_task(client.call({"a": 1, "b": 1}))
    await asyncio.wait_for(asked.wait(), 10)
    peer.router.close()  # the session's only router goes away
    with pytest.raises(CallFailed, match="reaches no router or peer"):
        await call
    await session.close()


async def test_a_bad_request_is_refused_before_anything_is_sent(peer: Peer):
    session = await _session(peer)
    client = ServiceClient(session, "/add_two_ints", ADD)
    asked: list[Any] = []
    peer.serve(client.key, asked.append)
    with pytest.raises(Ros2FieldError, match="'request.b': missing"):
        await client.call({"a": 1})
    assert asked == []
    await session.close()


async def test_petrobots_node_and_client_appear_in_the_graph(peer: Peer):
    session = await _session(peer, node_name="petrobot_alpha", namespace="/lab")
    ServiceClient(session, "add_two_ints", ADD)
    seen = await _tokens(peer, 2)
    entities = sorted((e.kind.value, e.namespace, e.node_name, e.name) for e in map(Entity.parse, seen))
    assert entities == [("NN", "/lab", "petrobot_alpha", ""), ("SC", "/lab", "petrobot_alpha", "/lab/add_two_ints")]
    await session.close()


async def test_the_bridge_dialect_queries_the_plain_key_with_cdr_and_no_attachment(peer: Peer):
    attachments: list[Any] = []

    def bridge(query: Any) -> None:  # what zenoh-bridge-ros2dds does with a query from Zenoh
        attachments.append(query.attachment)
        request = STORE.decode(f"{ADD}_Request", query.payload.to_bytes())
        query.reply(query.key_expr, STORE.encode(f"{ADD}_Response", {"sum": request["a"] * 0 + request["b"]}))

    peer.serve("bot1/add_two_ints", bridge)
    peer.token("@/b41d6e/@ros2_lv/SS/bot1§add_two_ints/example_interfaces§srv§AddTwoInts")
    session = await _session(peer, dialect=Dialect.BRIDGE, namespace="/bot1")
    assert session.dialect is Dialect.BRIDGE
    client = ServiceClient(session, "add_two_ints", ADD)
    assert client.key == "bot1/add_two_ints"
    await _routed(session, client.key)
    assert await client.call({"a": 5, "b": 6}, timeout_s=10) == {"sum": 6}
    assert attachments == [None]
    assert session.servers("/bot1/add_two_ints") != []
    await session.close()


async def test_topic_messages_reach_a_subscription_and_garbage_is_skipped(peer: Peer):
    session = await _session(peer)
    got: list[dict[str, Any]] = []
    arrived = asyncio.Event()
    sub = Subscription(session, "/crossfire", "std_msgs/msg/Bool", lambda m: (got.append(m), arrived.set()))
    publisher = peer.session.declare_publisher(sub.key)
    for _ in range(2000):  # until the subscription's route exists (a loaded machine takes its time)
        publisher.put(b"\x00\x01")  # too short for a Bool
        publisher.put(STORE.encode("std_msgs/msg/Bool", {"data": True}),
                      attachment=Attachment(1, 2, bytes(16)).encode())
        if arrived.is_set():
            break
        await asyncio.sleep(0.01)
    await asyncio.wait_for(arrived.wait(), 10)
    assert got and all(m == {"data": True} for m in got), got  # every garbage message skipped
    publisher.undeclare()
    await session.close()


# --------------------------------------------------------------------------- TLS and user/password


# the node's TLS tests make the certificates (a CA, a host, a rogue CA and its host): the same here
from test_node_tls import certs  # noqa: E402,F401


class SecurePeer(Peer):
    """A router on a TLS endpoint (mutual TLS) and, optionally, a user/password dictionary."""

    def __init__(self, certs: Any, dictionary: Any = None) -> None:
        self.endpoint = f"tls/127.0.0.1:{free_port()}"
        tls = {"transport/link/tls/root_ca_certificate": str(certs / "ca.pem"),
               "transport/link/tls/listen_certificate": str(certs / "host.pem"),
               "transport/link/tls/listen_private_key": str(certs / "host.key"),
               "transport/link/tls/connect_certificate": str(certs / "host.pem"),
               "transport/link/tls/connect_private_key": str(certs / "host.key"),
               "transport/link/tls/enable_mtls": True}
        auth = {"transport/auth/usrpwd/dictionary_file": str(dictionary),
                "transport/auth/usrpwd/user": "robot", "transport/auth/usrpwd/password": "robot-secret"} \
            if dictionary else {}
        self.router = zenoh.open(_config("router", **{"listen/endpoints": [self.endpoint], **tls, **auth}))
        self.session = zenoh.open(_config("client", **{"connect/endpoints": [self.endpoint], **tls, **auth}))
        self.undeclare = []


async def test_a_session_over_mutual_tls_calls_the_service(certs: Any):
    peer = SecurePeer(certs)
    try:
        session = await _session(peer, tls_root_ca=str(certs / "ca.pem"), tls_cert=str(certs / "host.pem"),
                                 tls_key=str(certs / "host.key"))
        client = ServiceClient(session, "/add_two_ints", ADD)
        peer.serve(client.key, _adder())
        await _routed(session, client.key)
        assert await client.call({"a": 20, "b": 22}, timeout_s=10) == {"sum": 42}
        await session.close()
    finally:
        peer.close()


async def test_a_certificate_from_another_ca_cannot_even_open_the_session(certs: Any):
    peer = SecurePeer(certs)
    try:
        session = Ros2Session(SessionSettings(connect=(peer.endpoint,), mode="client",
                                              tls_root_ca=str(certs / "ca.pem"), tls_cert=str(certs / "rogue.pem"),
                                              tls_key=str(certs / "rogue.key")), "tester", STORE)
        with pytest.raises(Ros2Error, match="cannot open the Zenoh session"):
            await session.open()
    finally:
        peer.close()


async def test_user_and_password_from_the_password_file_are_checked_by_the_router(certs: Any, tmp_path: Any):
    dictionary = tmp_path / "users.txt"
    dictionary.write_text("robot:robot-secret\npetrobot:lab-secret\n")
    peer = SecurePeer(certs, dictionary)
    tls = {"tls_root_ca": str(certs / "ca.pem"), "tls_cert": str(certs / "host.pem"), "tls_key": str(certs / "host.key")}
    try:
        (tmp_path / "good").write_text("lab-secret\n")
        (tmp_path / "bad").write_text("guess\n")
        session = await _session(peer, user="petrobot", password_file=str(tmp_path / "good"), **tls)
        client = ServiceClient(session, "/add_two_ints", ADD)
        peer.serve(client.key, _adder())
        await _routed(session, client.key)
        assert await client.call({"a": 1, "b": 2}, timeout_s=10) == {"sum": 3}
        await session.close()
        wrong = Ros2Session(SessionSettings(connect=(peer.endpoint,), mode="client", user="petrobot",
                                            password_file=str(tmp_path / "bad"), **tls), "tester", STORE)
        with pytest.raises(Ros2Error, match="cannot open the Zenoh session"):
            await wrong.open()
        missing = Ros2Session(SessionSettings(connect=(peer.endpoint,), mode="client", user="petrobot",
                                              password_file=str(tmp_path / "absent"), **tls), "tester", STORE)
        with pytest.raises(Ros2ConfigError, match="cannot read the Zenoh password file"):
            await missing.open()
    finally:
        peer.close()


async def test_petrobot_up_finds_a_running_zenoh_router_by_connecting_only_and_a_stopped_one_missing(peer: Peer):
    from services.devices.probe import probe
    from services.ros2.driver import Ros2Driver

    router = Ros2Driver.device({"router": peer.endpoint})
    assert router.protocol == "zenoh"
    assert probe(router) is None  # connected and left: asked for camera info, a router is "not a camera server"
    session = await _session(peer)  # the probe left the router serving
    await session.close()
    peer.close()
    assert probe(router) == "Connection refused"
