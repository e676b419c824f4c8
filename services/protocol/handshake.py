"""The mutual HMAC handshake of the node protocol (docs/protocol.md §3).

Server ``hello{node, version, nonce}`` → client ``auth{client, nonce, mac}`` → server
``welcome{mac, ...}``. Each side proves it holds the shared key with :func:`handshake_mac` over a
role label and both nonces, so a MAC reflected back to its sender does not verify; MACs are
compared with :func:`hmac.compare_digest`. Over TLS in ``psk`` mode the MACs also cover the TLS
channel binding, so that a relay between two TLS sessions cannot pass them on (docs/protocol.md §3).
"""

from __future__ import annotations

import enum
import hmac
from hashlib import sha256
from typing import Final

__all__ = ["MAC_BYTES", "PROTOCOL_VERSION", "Role", "handshake_mac", "macs_equal"]

PROTOCOL_VERSION: Final = 1
"""Version announced in ``hello``; a client refuses a server with a different version."""

MAC_BYTES: Final = 32
"""Length of a handshake MAC (HMAC-SHA256), bytes."""

_MAC_LABEL: Final = b"petrobot-auth-v1"


class Role(enum.Enum):
    """Which end of the TCP connection this endpoint is."""

    CLIENT = "client"
    """The side that connected (the coordinator, or a node reaching another node)."""
    SERVER = "server"
    """The node that accepted the connection."""


def handshake_mac(key: bytes, role: Role, server_nonce: bytes, client_nonce: bytes, binding: bytes = b"") -> bytes:
    """The MAC one side proves itself with.

    ``HMAC-SHA256(key, b"petrobot-auth-v1" || 0x00 || role || 0x00 || server_nonce || client_nonce
    || binding)`` with ``role`` the ASCII label of the *sender* (``b"client"`` or ``b"server"``).

    Args:
        key: the shared key.
        role: the side that sends this MAC.
        server_nonce: 16 bytes from ``hello``.
        client_nonce: 16 bytes from ``auth``.
        binding: the TLS channel binding (``tls-unique``, RFC 5929) in TLS ``psk`` mode; empty
            otherwise, which gives the MAC of a plain TCP connection.

    Returns:
        The 32-byte MAC.
    """
    msg = b"".join((_MAC_LABEL, b"\x00", role.value.encode(), b"\x00", server_nonce, client_nonce, binding))
    return hmac.new(key, msg, sha256).digest()


def macs_equal(expected: bytes, received: bytes) -> bool:
    """Constant-time comparison of a MAC received with the one expected."""
    return hmac.compare_digest(expected, received)
