"""The mutual HMAC handshake of the node protocol (docs/protocol.md §3).

Server ``hello{node, version, nonce}`` → client ``auth{client, nonce, mac}`` → server
``welcome{mac, ...}``. Each side proves it holds the shared key with :func:`handshake_mac` over a
role label, the names of both ends and both nonces; MACs are compared with
:func:`hmac.compare_digest`.

What the MAC binds, and the attack each part stops (docs/protocol.md §3, "Threat model"):

* the **role** of its sender (``client`` or ``server``): a MAC reflected back to its sender, or a
  server's MAC replayed as a client's, does not verify;
* the **names of both ends**, the client's own name and the node the client means to reach (from
  its services.toml, never from the ``hello`` it received): every node shares one key and is both
  a server and, through its links, a client, so without the names a process squatting one node's
  port could relay a node's own outgoing handshake to that node's server and open both
  connections without the key; with them, the MAC a client made for node A never verifies at
  node B, nor at its own server;
* both **nonces**, fresh per connection: no MAC verifies twice;
* over TLS in ``psk`` mode, the TLS **channel binding**, so that a relay between two TLS sessions
  cannot pass the MACs on.
"""

from __future__ import annotations

import enum
import hmac
from hashlib import sha256
from typing import Final

__all__ = ["MAC_BYTES", "PROTOCOL_VERSION", "Role", "handshake_mac", "macs_equal"]

PROTOCOL_VERSION: Final = 2
"""Version announced in ``hello``; a client refuses a server with a different version (2: the MACs
bind the names of both ends; 1 did not)."""

MAC_BYTES: Final = 32
"""Length of a handshake MAC (HMAC-SHA256), bytes."""

_MAC_LABEL: Final = b"petrobot-auth-v2"


class Role(enum.Enum):
    """Which end of the TCP connection this endpoint is."""

    CLIENT = "client"
    """The side that connected (the coordinator, or a node reaching another node)."""
    SERVER = "server"
    """The node that accepted the connection."""


def _named(name: str) -> bytes:
    data = name.encode("utf-8", "surrogatepass")
    return len(data).to_bytes(4, "big") + data


def handshake_mac(key: bytes, role: Role, *, client: str, server: str, server_nonce: bytes,
                  client_nonce: bytes, binding: bytes = b"") -> bytes:
    """The MAC one side proves itself with.

    ``HMAC-SHA256(key, b"petrobot-auth-v2" || 0x00 || role || 0x00 || len(client) || client ||
    len(server) || server || server_nonce || client_nonce || binding)``, with ``role`` the ASCII
    label of the *sender* (``b"client"`` or ``b"server"``), each name its UTF-8 bytes after their
    length as a 4-byte big-endian integer.

    Args:
        key: the shared key.
        role: the side that sends this MAC.
        client: the client's name, as sent in ``auth.client``.
        server: the node's name: the node a client means to reach (its services.toml name), which
            the node's ``hello.node`` must equal; a node uses its own name.
        server_nonce: 16 bytes from ``hello``.
        client_nonce: 16 bytes from ``auth``.
        binding: the TLS channel binding (``tls-unique``, RFC 5929) in TLS ``psk`` mode; empty
            otherwise.

    Returns:
        The 32-byte MAC.
    """
    msg = b"".join((_MAC_LABEL, b"\x00", role.value.encode(), b"\x00", _named(client), _named(server),
                    server_nonce, client_nonce, binding))
    return hmac.new(key, msg, sha256).digest()


def macs_equal(expected: bytes, received: bytes) -> bool:
    """Constant-time comparison of a MAC received with the one expected."""
    return hmac.compare_digest(expected, received)
