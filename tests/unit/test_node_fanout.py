"""Event fan-out of a node to a slow subscriber, driven in-process through a fake transport."""

from __future__ import annotations

import asyncio
from typing import Any

from services.location import parse_location
from services.node import Node, _Peer
from services.protocol import Connection, Event, Role, Subscribe

TOML = '[nodes.n]\nhost = "127.0.0.1"\nport = 7999\n'
KEY = b"fanout-key"


class FakeTransport(asyncio.Transport):
    """Collects written bytes; the test decides when it is 'full'."""

    def __init__(self) -> None:
        super().__init__()
        self.data = bytearray()

    def write(self, data: Any) -> None:
        self.data += data

    def is_closing(self) -> bool:
        return False

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return {"peername": ("127.0.0.1", 5000), "sockname": ("127.0.0.1", 7999)}.get(name, default)

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        pass

    def close(self) -> None:
        pass


async def _subscribed_peer(node: Node, topic: str) -> tuple[_Peer, FakeTransport, Connection]:
    node._loop = asyncio.get_running_loop()
    peer = _Peer(node)
    transport = FakeTransport()
    peer.connection_made(transport)
    client = Connection(Role.CLIENT, KEY, name="slow")
    client.receive_data(bytes(transport.data))
    transport.data.clear()
    list(client.messages())
    peer.data_received(client.data_to_send())
    await asyncio.sleep(0)
    client.receive_data(bytes(transport.data))
    transport.data.clear()
    list(client.messages())
    client.send(Subscribe(topic=topic))
    peer.data_received(client.data_to_send())
    await asyncio.sleep(0)
    return peer, transport, client


async def test_a_slow_subscriber_loses_its_oldest_events_and_never_blocks_the_node() -> None:
    node = Node("n", parse_location(TOML), KEY)
    peer, transport, client = await _subscribed_peer(node, "tick")
    peer.pause_writing()  # the kernel buffer is full: the subscriber is not reading
    for i in range(1000):
        node.publish("tick", {"i": i})  # returns at once every time
    await asyncio.sleep(0)
    assert transport.data == b""
    peer.resume_writing()
    await asyncio.sleep(0)
    client.receive_data(bytes(transport.data))
    got = [m for m in client.messages() if isinstance(m, Event)]
    assert [e.seq for e in got] == list(range(1000 - 256 + 1, 1001))  # the newest 256, in order
    assert peer.dropped == 1000 - 256


async def test_events_flow_straight_through_to_a_subscriber_that_keeps_up() -> None:
    node = Node("n", parse_location(TOML), KEY)
    _peer, transport, client = await _subscribed_peer(node, "tick")
    node.publish("tick", 1)
    node.publish("other", 2)  # nobody subscribed: dropped at the source
    node.publish("tick", 3)
    await asyncio.sleep(0)
    client.receive_data(bytes(transport.data))
    got = [(m.topic, m.seq, m.data) for m in client.messages() if isinstance(m, Event)]
    assert got == [("tick", 1, 1), ("tick", 2, 3)]
