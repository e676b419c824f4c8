"""The two wire dialects of ROS 2 over Zenoh (pure): key expressions, liveliness tokens, attachments.

**rmw_zenoh** (ROS 2's Zenoh middleware; ``ros2/rmw_zenoh`` ``docs/design.md``):

* a topic or a service is the key ``<domain_id>/<fully qualified name without its leading />/<DDS type
  name>/<RIHS01 type hash>``, e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...1a18``; a
  service's type name and hash are those of the service type (``AddTwoInts_``), not of its request;
* every published message and every service request and reply carries an *attachment*: the sequence
  number (int64, little endian), the source timestamp (int64 ns since the Unix epoch, little endian),
  the GID's length in one byte (16) and the 16-byte GID of the publisher or client; a reply echoes
  the request's sequence number and client GID;
* discovery is by liveliness tokens ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/
  <enclave>/<namespace>/<node name>`` for a node (kind ``NN``, entity id = node id) and, for a
  publisher (``MP``), subscription (``MS``), service server (``SS``) or client (``SC``), the same
  followed by ``/<topic or service>/<DDS type name>/<type hash>/<QoS>`` (names mangled: ``/`` →
  ``%``, empty → ``%``; QoS as :mod:`services.ros2.qos`); its GID is a hash of that token.

**zenoh-bridge-ros2dds** (``eclipse-zenoh/zenoh-plugin-ros2dds``: the robot keeps DDS, a bridge
routes it to Zenoh):

* a topic, service or action service is the plain key ``<name without its leading />`` (the bridge's
  own namespace, if configured, is the first chunk); payloads are CDR with no attachment (a service
  query may carry one; the bridge makes up its own request id otherwise);
* the bridge announces what it routes with tokens ``@/<bridge zid>/@ros2_lv/<kind>/<key>/<type>``
  (``/`` in the key and the type replaced by ``§``), kinds ``MP``, ``MS``, ``SS``, ``SC`` and ``AS``
  / ``AC`` for action servers and clients; ``MP``/``MS`` tokens end with a QoS chunk.
"""

from __future__ import annotations

import enum
import hashlib
import struct
from dataclasses import dataclass

from services.ros2.errors import Ros2WireError
from services.ros2.names import demangle, mangle

__all__ = [
    "ADMIN_SPACE",
    "ATTACHMENT_SIZE",
    "Attachment",
    "BridgeToken",
    "Dialect",
    "Entity",
    "EntityKind",
    "bridge_graph_keyexpr",
    "data_keyexpr",
    "gid_of",
    "graph_keyexpr",
]

ADMIN_SPACE = "@ros2_lv"
"""The prefix of rmw_zenoh's liveliness tokens (a hermetic Zenoh namespace: ``**`` does not match it)."""
ATTACHMENT_SIZE = 33
"""Bytes of an rmw_zenoh attachment: 8 + 8 + 1 + 16."""
GID_SIZE = 16


class Dialect(enum.StrEnum):
    """How ROS 2 entities map onto Zenoh (see the module docstring)."""

    RMW_ZENOH = "rmw_zenoh"
    """ROS 2 nodes run rmw_zenoh (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``)."""
    BRIDGE = "bridge"
    """ROS 2 nodes run a DDS middleware; zenoh-bridge-ros2dds routes them to Zenoh."""


class EntityKind(enum.StrEnum):
    """The kinds of rmw_zenoh liveliness tokens."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


def data_keyexpr(dialect: Dialect, domain_id: int, name: str, dds_type: str, type_hash: str) -> str:
    """The Zenoh key of a topic or service.

    Args:
        dialect: rmw_zenoh or the bridge.
        domain_id: ``ROS_DOMAIN_ID`` (rmw_zenoh only).
        name: the fully qualified topic or service name (``/chatter``).
        dds_type: the DDS type name (``std_msgs::msg::dds_::String_``; rmw_zenoh only).
        type_hash: the RIHS01 hash (rmw_zenoh only).
    """
    if dialect is Dialect.BRIDGE:
        return name.strip("/")
    return f"{domain_id}/{name.strip('/')}/{dds_type}/{type_hash}"


def graph_keyexpr(domain_id: int) -> str:
    """The key expression of every rmw_zenoh liveliness token of a domain."""
    return f"{ADMIN_SPACE}/{domain_id}/**"


def bridge_graph_keyexpr() -> str:
    """The key expression of every token the bridges announce."""
    return f"@/*/{ADMIN_SPACE}/**"


def gid_of(token: str) -> bytes:
    """A 16-byte GID for the entity of liveliness token ``token`` (the first bytes of its SHA-256;
    rmw_zenoh hashes the token too, with XXH3-128: any stable, unique 16 bytes serve)."""
    return hashlib.sha256(token.encode()).digest()[:GID_SIZE]


@dataclass(frozen=True, slots=True, kw_only=True)
class Entity:
    """One entity of the rmw_zenoh graph, as its liveliness token describes it.

    Attributes:
        domain_id: ``ROS_DOMAIN_ID``.
        session_id: the Zenoh session id (hex) of the process.
        node_id: the node's number within the session.
        entity_id: the entity's number (the node's own for a node).
        kind: NN, MP, MS, SS or SC.
        namespace: the node's namespace (``/`` for none).
        node_name: the node's name.
        enclave: the SROS enclave (``""`` for none).
        name: the topic or service, fully qualified (``""`` for a node).
        dds_type: the DDS type name (``""`` for a node).
        type_hash: the RIHS01 hash (``""`` for a node).
        qos: the QoS text (``""`` for a node).
    """

    domain_id: int
    session_id: str
    node_id: int
    entity_id: int
    kind: EntityKind
    namespace: str
    node_name: str
    enclave: str = ""
    name: str = ""
    dds_type: str = ""
    type_hash: str = ""
    qos: str = ""

    @property
    def token(self) -> str:
        """The liveliness token's key expression."""
        head = (f"{ADMIN_SPACE}/{self.domain_id}/{self.session_id}/{self.node_id}/{self.entity_id}/"
                f"{self.kind.value}/{mangle(self.enclave if self.enclave != '/' else '')}/"
                f"{mangle(self.namespace if self.namespace != '/' else '')}/{mangle(self.node_name)}")
        if self.kind is EntityKind.NODE:
            return head
        return f"{head}/{mangle(self.name)}/{self.dds_type}/{self.type_hash}/{self.qos}"

    @property
    def gid(self) -> bytes:
        """The entity's 16-byte GID (:func:`gid_of` its token)."""
        return gid_of(self.token)

    @classmethod
    def parse(cls, token: str) -> Entity:
        """Read a liveliness token of the rmw_zenoh graph.

        Raises:
            Ros2WireError: not ``@ros2_lv``, a wrong number of chunks for its kind, an empty chunk,
                an unknown kind or a non-numeric id.
        """
        parts = token.split("/")
        if len(parts) < 9 or parts[0] != ADMIN_SPACE:
            raise Ros2WireError(f"liveliness token {token!r}: not an rmw_zenoh token")
        if any(not p for p in parts):
            raise Ros2WireError(f"liveliness token {token!r}: empty chunk")
        try:
            kind = EntityKind(parts[5])
        except ValueError:
            raise Ros2WireError(f"liveliness token {token!r}: unknown entity kind {parts[5]!r}") from None
        expected = 9 if kind is EntityKind.NODE else 13
        if len(parts) != expected:
            raise Ros2WireError(f"liveliness token {token!r}: {len(parts)} chunks, a {kind.value} token has "
                                f"{expected}")
        if not (parts[1].isdigit() and parts[3].isdigit() and parts[4].isdigit()):
            raise Ros2WireError(f"liveliness token {token!r}: domain, node and entity ids must be numbers")

        def name(chunk: str) -> str:
            return "/" if chunk == "%" else demangle(chunk)

        return cls(
            domain_id=int(parts[1]), session_id=parts[2], node_id=int(parts[3]), entity_id=int(parts[4]),
            kind=kind, enclave="" if parts[6] == "%" else demangle(parts[6]), namespace=name(parts[7]),
            node_name=demangle(parts[8]),
            **({} if kind is EntityKind.NODE else {
                "name": demangle(parts[9]), "dds_type": parts[10], "type_hash": parts[11], "qos": parts[12]}),
        )


_BRIDGE_KINDS = frozenset({"MP", "MS", "SS", "SC", "AS", "AC"})


@dataclass(frozen=True, slots=True)
class BridgeToken:
    """One route announced by a zenoh-bridge-ros2dds.

    Attributes:
        bridge: the bridge's Zenoh id.
        kind: MP, MS, SS, SC, AS or AC.
        key: the Zenoh key it routes (``fibonacci``, ``robot1/cmd_vel``).
        ros_type: the ROS 2 type (``example_interfaces/action/Fibonacci``).
    """

    bridge: str
    kind: str
    key: str
    ros_type: str

    @classmethod
    def parse(cls, token: str) -> BridgeToken:
        """Read ``@/<zid>/@ros2_lv/<kind>/<key>/<type>[/<qos>]``.

        Raises:
            Ros2WireError: any other shape.
        """
        parts = token.split("/")
        if (len(parts) not in (6, 7) or parts[0] != "@" or parts[2] != ADMIN_SPACE or parts[3] not in _BRIDGE_KINDS
                or not all(parts[1:6])):
            raise Ros2WireError(f"bridge token {token!r}: not @/<zid>/@ros2_lv/<kind>/<key>/<type>")
        return cls(bridge=parts[1], kind=parts[3], key=parts[4].replace("§", "/"),
                   ros_type=parts[5].replace("§", "/"))


@dataclass(frozen=True, slots=True)
class Attachment:
    """The attachment rmw_zenoh puts on every message, request and reply.

    Attributes:
        sequence_number: the publisher's or client's counter (a reply echoes the request's).
        timestamp_ns: source time, ns since the Unix epoch.
        gid: the 16-byte GID of the publisher or client (a reply echoes the client's).
    """

    sequence_number: int
    timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        """The 33 bytes on the wire.

        Raises:
            Ros2WireError: a number outside int64 or a GID that is not 16 bytes.
        """
        if len(self.gid) != GID_SIZE:
            raise Ros2WireError(f"a GID is {GID_SIZE} bytes, got {len(self.gid)}")
        try:
            return struct.pack("<qqB", self.sequence_number, self.timestamp_ns, GID_SIZE) + bytes(self.gid)
        except struct.error as exc:
            raise Ros2WireError(f"attachment numbers must fit int64: {exc}") from None

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """Read an attachment.

        Raises:
            Ros2WireError: not 33 bytes, or a GID length byte other than 16.
        """
        if len(data) != ATTACHMENT_SIZE:
            raise Ros2WireError(f"an rmw_zenoh attachment is {ATTACHMENT_SIZE} bytes, got {len(data)}")
        seq, stamp, size = struct.unpack_from("<qqB", data)
        if size != GID_SIZE:
            raise Ros2WireError(f"attachment GID length byte is {size}, expected {GID_SIZE}")
        return cls(sequence_number=seq, timestamp_ns=stamp, gid=bytes(data[17:]))
