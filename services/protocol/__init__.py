"""The coordinator↔node wire protocol, sans-IO (no sockets, files or clocks inside).

docs/protocol.md is the normative specification; this package implements it, in four modules:

* :mod:`~services.protocol.framing` — length-prefixed msgpack frames (shared with the set-point
  stream and the frame grabber);
* :mod:`~services.protocol.messages` — the message dataclasses and their validated map codec;
* :mod:`~services.protocol.handshake` — the mutual HMAC handshake;
* :mod:`~services.protocol.connection` — the connection state machine fed with bytes;

and :mod:`~services.protocol.untrusted`, which makes text received from a peer safe to log.

The design follows h11 and websockets: a :class:`Connection` turns received bytes into message
objects and message objects into bytes; the asyncio shells live in :mod:`services.wire`,
:mod:`services.node` and :mod:`services.client`.
"""

from __future__ import annotations

from services.protocol.connection import (
    DEFAULT_MAX_FRAME,
    HANDSHAKE,
    MAX_AUTH_FRAME,
    MAX_WELCOME_FRAME,
    Connection,
    Offer,
    State,
)
from services.protocol.framing import FrameReader, frame, pack_map, unpack_map
from services.protocol.handshake import MAC_BYTES, PROTOCOL_VERSION, Role, handshake_mac
from services.protocol.messages import (
    CLIENT_SENDS,
    NONCE_BYTES,
    SERVER_SENDS,
    Accepted,
    Auth,
    Bye,
    Call,
    Cancel,
    Event,
    Feedback,
    Hello,
    Message,
    Ping,
    Pong,
    Query,
    Rejected,
    Result,
    Subscribe,
    Unsubscribe,
    Welcome,
    from_map,
    to_map,
)
from services.protocol.untrusted import shown

__all__ = [
    "CLIENT_SENDS",
    "DEFAULT_MAX_FRAME",
    "HANDSHAKE",
    "MAC_BYTES",
    "MAX_AUTH_FRAME",
    "MAX_WELCOME_FRAME",
    "NONCE_BYTES",
    "PROTOCOL_VERSION",
    "SERVER_SENDS",
    "Accepted",
    "Auth",
    "Bye",
    "Call",
    "Cancel",
    "Connection",
    "Event",
    "Feedback",
    "FrameReader",
    "Hello",
    "Message",
    "Offer",
    "Ping",
    "Pong",
    "Query",
    "Rejected",
    "Result",
    "Role",
    "State",
    "Subscribe",
    "Unsubscribe",
    "Welcome",
    "encode_frame",
    "frame",
    "from_map",
    "handshake_mac",
    "pack_map",
    "shown",
    "to_map",
    "unpack_map",
]


def encode_frame(msg: Message, max_frame: int = DEFAULT_MAX_FRAME) -> bytes:
    """Encode one message as a frame (4-byte big-endian length + msgpack map).

    Raises:
        LocalProtocolError: the encoded body exceeds ``max_frame`` or a value is not msgpack-able.
    """
    return pack_map(to_map(msg), max_frame)
