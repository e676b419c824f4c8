"""The ``ros2`` tables of services.toml (pure): the Zenoh session of a node, ROS 2 actions and events.

A primitive action becomes a ROS 2 action, service, publication or wait by a ``ros2`` table in its
``[actions.NAME]`` section (then ``impl`` may be left out); an external event comes from a ROS 2
topic by a ``ros2`` table in its ``[events.TOPIC]`` section; ``[ros2]`` sets up the Zenoh session of
every node that hosts them, overridden per node by ``[nodes.NAME.ros2]``. docs/ros2.md is the guide;
this module parses and checks the tables (:class:`Ros2ConfigError` with what is wrong; the location
file's loader adds the file and line) and builds the Zenoh configuration of a session.

``[ros2]`` / ``[nodes.NAME.ros2]`` (every key optional)::

    dialect = "rmw_zenoh"            # or "bridge" (zenoh-bridge-ros2dds)
    domain_id = 0                    # ROS_DOMAIN_ID
    namespace = "/"                  # relative names of actions, services and topics live here
    node_name = "petrobot_NODE"      # the ROS 2 node petrobot's node shows up as (ros2 node list)
    mode = "peer"                    # or "client" (everything through the router)
    connect = ["tcp/127.0.0.1:7447"] # the Zenoh router(s) (rmw_zenoh's default)
    listen = ["tcp/127.0.0.1:0"]     # peer mode: where other peers reach this one
    interfaces = ["interfaces"]      # more .msg/.srv/.action directories (pkg/msg/Name.msg...)
    tls = { root_ca = "ca.pem", cert = "host.pem", key = "host.key" }   # for tls/ endpoints
    user = "petrobot"                # Zenoh user/password authentication, with
    password_file = "zenoh.pass"     #   the password in this file (or PETROBOT_ZENOH_PASSWORD)
    allow_plaintext = false          # true: accept tcp/udp endpoints off the loopback (loudly)

An action's ``ros2`` table: exactly one of ``action``, ``service`` and ``publish`` (or only
``until``), with ``type``::

    [actions.fibonacci.ros2]
    action = "/fibonacci"
    type = "example_interfaces/action/Fibonacci"
    success = "len(sequence) > 0"   # a condition on the result (default: SUCCEEDED is success)
    aborted = "failure"             # what ABORTED is: failure (default) or error
    rejected = "failure"            # what a rejected goal is: failure (default) or error
    fill = false                    # true: missing goal fields take their defaults
    cancel_wait_s = 1.0             # after cancel_goal, how long to wait for the result
    qos = { depth = 10 }

    [actions.add.ros2]
    service = "/add_two_ints"
    type = "example_interfaces/srv/AddTwoInts"
    success = "sum > 0"

    [actions.drive.ros2]
    publish = "/cmd_vel"
    type = "geometry_msgs/msg/Twist"
    rate_hz = 10.0                  # else published once
    duration_s = 2.0                # or until the condition below, the deadline or a cancel
    until = { topic = "/arrived", type = "std_msgs/msg/Bool", when = "data" }

An event's ``ros2`` table::

    ros2 = { topic = "/crossfire", type = "std_msgs/msg/Bool", when = "data == true", edge = "rising",
             fields = ["data"], qos = { reliability = "best_effort" } }
"""

from __future__ import annotations

import enum
import ipaddress
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from services.results import Status
from services.ros2.condition import Condition, Edge
from services.ros2.errors import ConditionError, Ros2ConfigError, Ros2Error
from services.ros2.graph import Dialect
from services.ros2.names import action_type_names, check_name, split_type
from services.ros2.qos import DEFAULT_QOS, Qos, parse_qos

if TYPE_CHECKING:
    from services.ros2.typestore import TypeStore

__all__ = [
    "ACTION_IMPL",
    "DRIVER_IMPL",
    "DRIVER_NAME",
    "MAX_MESSAGE_BYTES",
    "PASSWORD_ENV",
    "ActionKind",
    "Ros2ActionSpec",
    "Ros2EventSpec",
    "SessionSettings",
    "TopicCondition",
    "check_action_types",
    "check_event_types",
    "endpoint_problems",
    "parse_action_spec",
    "parse_event_spec",
    "parse_session",
    "zenoh_config",
]

ACTION_IMPL = "services.ros2.actions:Ros2Primitive"
"""The ``impl`` of an action with a ``ros2`` table (and no ``impl`` of its own)."""
DRIVER_IMPL = "services.ros2.driver:Ros2Driver"
"""The driver started with every node that hosts a ROS 2 action or event (the node's Zenoh session)."""
DRIVER_NAME = "ros2"
"""The name of that driver (reserved in ``[drivers]``)."""
PASSWORD_ENV = "PETROBOT_ZENOH_PASSWORD"
"""Environment variable holding the Zenoh password when ``password_file`` is not set."""

MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""The largest message a node's Zenoh session takes in, bytes."""

_PLAINTEXT = frozenset({"tcp", "udp", "ws"})
_SECURE = frozenset({"tls", "quic"})
_LOCAL = frozenset({"unixsock-stream", "unixpipe", "vsock"})
_MAX_ENDPOINTS = 16


def _table(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise Ros2ConfigError(f"{where} must be a table")
    return value


def _keys(table: Mapping[str, Any], allowed: set[str], where: str) -> None:
    extra = sorted(set(table) - allowed)
    if extra:
        raise Ros2ConfigError(f"{where}: unknown key(s) {', '.join(extra)} (known: {', '.join(sorted(allowed))})")


def _string(table: Mapping[str, Any], key: str, where: str, default: str | None = None) -> str | None:
    value = table.get(key, default)
    if value is not None and (not isinstance(value, str) or not value):
        raise Ros2ConfigError(f"{where}: {key} must be a non-empty string")
    return value


def _number(table: Mapping[str, Any], key: str, where: str, *, low: float = 0.0, high: float = math.inf,
            default: float | None = None) -> float | None:
    value = table.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low < value < high:
        raise Ros2ConfigError(f"{where}: {key} must be a number above {low:g}"
                              + (f" and below {high:g}" if high < math.inf else "") + f", got {value!r}")
    return float(value)


def _flag(table: Mapping[str, Any], key: str, where: str, default: bool = False) -> bool:
    value = table.get(key, default)
    if not isinstance(value, bool):
        raise Ros2ConfigError(f"{where}: {key} must be true or false")
    return value


def _type(table: Mapping[str, Any], where: str, kind: str) -> str:
    value = table.get("type")
    if not isinstance(value, str):
        raise Ros2ConfigError(f"{where}: type must be a ROS 2 interface type such as "
                              + {"msg": "std_msgs/msg/Bool", "srv": "example_interfaces/srv/AddTwoInts",
                                 "action": "example_interfaces/action/Fibonacci"}[kind])
    try:
        pkg, got, name = split_type(value)
    except Ros2Error as exc:
        raise Ros2ConfigError(f"{where}: {exc}") from None
    if got != kind:
        raise Ros2ConfigError(f"{where}: type {value!r} is a {got} type, a {kind} type is needed here")
    return f"{pkg}/{got}/{name}"


def _condition(table: Mapping[str, Any], key: str, where: str) -> Condition | None:
    text = table.get(key)
    if text is None:
        return None
    if not isinstance(text, str):
        raise Ros2ConfigError(f"{where}: {key} must be a condition in a string, e.g. \"data == true\"")
    try:
        return Condition(text)
    except ConditionError as exc:
        raise Ros2ConfigError(f"{where}: {key}: {exc}") from None


def _name(table: Mapping[str, Any], key: str, where: str) -> str:
    value = table.get(key)
    if not isinstance(value, str):
        raise Ros2ConfigError(f"{where}: {key} must be a ROS 2 name such as \"/fibonacci\", got {value!r}")
    try:
        return check_name(value, f"{key} name")
    except Ros2ConfigError as exc:
        raise Ros2ConfigError(f"{where}: {exc}") from None


def _status(table: Mapping[str, Any], key: str, where: str) -> Status:
    value = table.get(key, "failure")
    if value not in ("failure", "error"):
        raise Ros2ConfigError(f"{where}: {key} must be \"failure\" or \"error\", got {value!r}")
    return Status(value)


# ------------------------------------------------------------------------------------------ session


@dataclass(frozen=True, slots=True, kw_only=True)
class SessionSettings:
    """How one node reaches ROS 2: its Zenoh session and its place in the ROS 2 graph.

    Attributes:
        dialect: rmw_zenoh or the zenoh-bridge-ros2dds.
        domain_id: ``ROS_DOMAIN_ID`` (0..232, rmw_zenoh's key prefix).
        namespace: the namespace of relative names and of petrobot's ROS 2 node.
        node_name: the ROS 2 node name petrobot's node takes (``None``: ``petrobot_<node>``).
        mode: ``"peer"`` or ``"client"``.
        connect: Zenoh endpoints to connect to (routers, peers).
        listen: Zenoh endpoints to listen on (peer mode).
        interfaces: more directories of interface definitions (absolute paths).
        tls_root_ca, tls_cert, tls_key: PEM files for ``tls/`` and ``quic/`` endpoints (absolute
            paths); with ``tls_cert`` and ``tls_key`` the session also presents its own certificate.
        user: Zenoh user name (user/password authentication), or ``None``.
        password_file: file holding the password (absolute path), or ``None`` (then the
            environment variable :data:`PASSWORD_ENV`).
        allow_plaintext: accept ``tcp``/``udp``/``ws`` endpoints off the loopback.
    """

    dialect: Dialect = Dialect.RMW_ZENOH
    domain_id: int = 0
    namespace: str = "/"
    node_name: str | None = None
    mode: str = "peer"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    interfaces: tuple[str, ...] = ()
    tls_root_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None
    user: str | None = None
    password_file: str | None = None
    allow_plaintext: bool = False

    def ros_node_name(self, node: str) -> str:
        """The ROS 2 node name of petrobot node ``node``."""
        if self.node_name:
            return self.node_name
        return "petrobot_" + "".join(c if c.isalnum() or c == "_" else "_" for c in node)


_SESSION_KEYS = {"dialect", "domain_id", "namespace", "node_name", "mode", "connect", "listen", "interfaces", "tls",
                 "user", "password_file", "allow_plaintext"}


def parse_session(table: Any, *, base: SessionSettings = SessionSettings(), where: str = "[ros2]",
                  directory: str = "") -> SessionSettings:
    """Parse ``[ros2]`` (or ``[nodes.NAME.ros2]`` over the ``[ros2]`` settings ``base``).

    Args:
        table: the table.
        base: the settings its keys override.
        where: its place, for error messages.
        directory: the directory relative paths are taken from (that of services.toml).

    Raises:
        Ros2ConfigError: an unknown key, a value of the wrong type or range, a malformed endpoint,
            a plaintext endpoint off the loopback without ``allow_plaintext``, ``tls`` without
            ``root_ca``, or ``password_file`` without ``user``.
    """
    t = _table(table, where)
    _keys(t, _SESSION_KEYS, where)
    values: dict[str, Any] = {}

    def path(value: str) -> str:
        return os.path.join(directory, os.path.expanduser(value))

    if "dialect" in t:
        if t["dialect"] not in tuple(Dialect):
            raise Ros2ConfigError(f"{where}: dialect must be one of {', '.join(Dialect)}, got {t['dialect']!r}")
        values["dialect"] = Dialect(t["dialect"])
    if "domain_id" in t:
        if type(t["domain_id"]) is not int or not 0 <= t["domain_id"] <= 232:
            raise Ros2ConfigError(f"{where}: domain_id must be an integer in 0..232, got {t['domain_id']!r}")
        values["domain_id"] = t["domain_id"]
    if "namespace" in t:
        try:
            values["namespace"] = check_name(t["namespace"], "namespace", relative=False)
        except Ros2ConfigError as exc:
            raise Ros2ConfigError(f"{where}: {exc}") from None
    if "node_name" in t:
        name = t["node_name"]
        if not isinstance(name, str) or not name or not (name[0].isalpha() or name[0] == "_") or not all(
                c.isalnum() or c == "_" for c in name):
            raise Ros2ConfigError(f"{where}: node_name must be letters, digits and '_', got {name!r}")
        values["node_name"] = name
    if "mode" in t:
        if t["mode"] not in ("peer", "client"):
            raise Ros2ConfigError(f"{where}: mode must be \"peer\" or \"client\", got {t['mode']!r}")
        values["mode"] = t["mode"]
    for key in ("connect", "listen"):
        if key in t:
            values[key] = _endpoints(t[key], f"{where}: {key}")
    if "interfaces" in t:
        dirs = t["interfaces"]
        if not isinstance(dirs, list) or not all(isinstance(d, str) and d for d in dirs):
            raise Ros2ConfigError(f"{where}: interfaces must be a list of directories")
        values["interfaces"] = tuple(path(d) for d in dirs)
    if "tls" in t:
        tls = _table(t["tls"], f"{where}: tls")
        _keys(tls, {"root_ca", "cert", "key"}, f"{where}: tls")
        for key in ("root_ca", "cert", "key"):
            value = _string(tls, key, f"{where}: tls")
            values[f"tls_{key}"] = path(value) if value else None
        if not values["tls_root_ca"]:
            raise Ros2ConfigError(f"{where}: tls needs root_ca (the CA that signed the router's certificate)")
        if (values["tls_cert"] is None) != (values["tls_key"] is None):
            raise Ros2ConfigError(f"{where}: tls needs both cert and key, or neither")
    if "user" in t:
        values["user"] = _string(t, "user", where)
    if "password_file" in t:
        values["password_file"] = path(str(_string(t, "password_file", where)))
    if "allow_plaintext" in t:
        values["allow_plaintext"] = _flag(t, "allow_plaintext", where)
    settings = SessionSettings(**{**{f: getattr(base, f) for f in SessionSettings.__slots__}, **values})
    if settings.password_file and not settings.user:
        raise Ros2ConfigError(f"{where}: password_file needs user")
    problems = endpoint_problems(settings)
    if problems and not settings.allow_plaintext:
        raise Ros2ConfigError(f"{where}: {problems[0]}; use tls/ endpoints (with tls = {{ root_ca = ... }}), or "
                              f"set allow_plaintext = true to accept it on a trusted network")
    return settings


def _endpoints(value: Any, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or len(value) > _MAX_ENDPOINTS:
        raise Ros2ConfigError(f"{where} must be a list of at most {_MAX_ENDPOINTS} Zenoh endpoints "
                              f"such as \"tcp/127.0.0.1:7447\"")
    for endpoint in value:
        if not isinstance(endpoint, str) or "/" not in endpoint or not endpoint.split("/", 1)[1]:
            raise Ros2ConfigError(f"{where}: {endpoint!r} is not a Zenoh endpoint (protocol/address, "
                                  f"e.g. tcp/127.0.0.1:7447 or tls/router.lab:7447)")
        proto = endpoint.split("/", 1)[0]
        if proto not in _PLAINTEXT | _SECURE | _LOCAL:
            raise Ros2ConfigError(f"{where}: {endpoint!r}: unknown protocol {proto!r} (known: "
                                  f"{', '.join(sorted(_PLAINTEXT | _SECURE | _LOCAL))})")
    return tuple(value)


def _host_of(endpoint: str) -> str:
    address = endpoint.split("/", 1)[1].split("#", 1)[0]
    if address.startswith("["):
        return address[1:].split("]", 1)[0]
    return address.rsplit(":", 1)[0] if ":" in address else address


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def endpoint_problems(settings: SessionSettings) -> list[str]:
    """The plaintext endpoints off the loopback in ``settings`` (what ``allow_plaintext`` accepts).

    A ``tcp``, ``udp`` or ``ws`` endpoint carries every message, goal and result readable and
    alterable by any host on the path, and Zenoh's user/password exchange too; petrobot treats its
    own ports the same way (docs/protocol.md, TLS). Loopback addresses stay on the machine.
    """
    out = []
    for key, endpoints in (("connect", settings.connect), ("listen", settings.listen if settings.mode == "peer" else ())):
        for endpoint in endpoints:
            if endpoint.split("/", 1)[0] in _PLAINTEXT and not _loopback(_host_of(endpoint)):
                out.append(f"{key} endpoint {endpoint!r} is plaintext and not on the loopback")
    return out


def zenoh_config(settings: SessionSettings, password: str | None = None) -> dict[str, Any]:
    """The Zenoh configuration of a session, as ``{"path/of/key": JSON value}`` (for
    ``zenoh.Config.insert_json5``), following rmw_zenoh's session defaults: multicast scouting off,
    gossip on, timestamps on; and messages of at most :data:`MAX_MESSAGE_BYTES` taken in.

    Args:
        settings: the node's settings.
        password: the Zenoh password (read from ``password_file`` or the environment by the caller).
    """
    config: dict[str, Any] = {
        "mode": settings.mode,
        "connect/endpoints": list(settings.connect),
        "listen/endpoints": list(settings.listen) if settings.mode == "peer" else [],
        "scouting/multicast/enabled": False,
        "scouting/gossip/enabled": True,
        "timestamping/enabled": {"router": True, "peer": True, "client": True},
        # a client needs its router at start: it tries for 5 s (a TLS handshake on a loaded machine takes
        # a while), then the node does not start; a peer opens at once and keeps trying in the background
        "connect/timeout_ms": {"router": -1, "peer": -1, "client": 5000},
        "connect/exit_on_failure": {"router": False, "peer": False, "client": True},
        "queries_default_timeout": 600000,
        # a hostile peer cannot make this node receive one message larger than this (Zenoh's default is
        # 1 GiB); a camera image of a few MB passes
        "transport/link/rx/max_message_size": MAX_MESSAGE_BYTES,
    }
    if settings.tls_root_ca:
        config["transport/link/tls/root_ca_certificate"] = settings.tls_root_ca
        if settings.tls_cert and settings.tls_key:
            config["transport/link/tls/connect_certificate"] = settings.tls_cert
            config["transport/link/tls/connect_private_key"] = settings.tls_key
            config["transport/link/tls/listen_certificate"] = settings.tls_cert
            config["transport/link/tls/listen_private_key"] = settings.tls_key
            config["transport/link/tls/enable_mtls"] = True
    if settings.user:
        config["transport/auth/usrpwd/user"] = settings.user
        config["transport/auth/usrpwd/password"] = password or ""
    return config


# ------------------------------------------------------------------------------------------ actions


class ActionKind(enum.StrEnum):
    """What a ROS 2 primitive action does (the key of its ``ros2`` table)."""

    ACTION = "action"
    """Send a goal to an action server; feedback; the result decides the status."""
    SERVICE = "service"
    """Call a service; the response decides the status."""
    PUBLISH = "publish"
    """Publish a message once, or at ``rate_hz`` while the action runs."""
    WAIT = "wait"
    """Wait for a condition on a topic (only ``until``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicCondition:
    """A condition on the messages of a topic.

    Attributes:
        topic: the topic (relative to the node's namespace unless absolute).
        type: its message type.
        when: the condition (``None``: any message).
        qos: the subscription's QoS.
    """

    topic: str
    type: str
    when: Condition | None
    qos: Qos = DEFAULT_QOS


@dataclass(frozen=True, slots=True, kw_only=True)
class Ros2ActionSpec:
    """A primitive action that is a ROS 2 action, service, publication or wait.

    Attributes:
        kind: :class:`ActionKind`.
        name: the action, service or topic (``""`` for a wait).
        type: its interface type (``""`` for a wait).
        success: a condition on the result or response that success needs, or ``None``.
        aborted: the status of an ABORTED goal (failure or error).
        rejected: the status of a rejected goal (failure or error).
        fill: missing goal, request or message fields take their default values.
        cancel_wait_s: after a cancel request, seconds to wait for the server's final result.
        qos: the QoS of the publisher (publish) or of the feedback subscription (action).
        rate_hz: publish: messages per second while the action runs (``None``: once).
        duration_s: publish at a rate: success after this long (``None``: until ``until`` holds,
            the deadline or a cancel).
        until: publish or wait: success when this topic condition holds.
    """

    kind: str
    name: str
    type: str
    success: Condition | None = None
    aborted: Status = Status.FAILURE
    rejected: Status = Status.FAILURE
    fill: bool = False
    cancel_wait_s: float = 1.0
    qos: Qos = DEFAULT_QOS
    rate_hz: float | None = None
    duration_s: float | None = None
    until: TopicCondition | None = field(default=None)


_ACTION_KEYS = {"action", "service", "publish", "type", "success", "aborted", "rejected", "fill", "cancel_wait_s",
                "qos", "rate_hz", "duration_s", "until"}
_ONLY = {ActionKind.ACTION: {"aborted", "rejected", "cancel_wait_s"},
         ActionKind.PUBLISH: {"rate_hz", "duration_s"}}


def _topic_condition(value: Any, where: str) -> TopicCondition:
    t = _table(value, where)
    _keys(t, {"topic", "type", "when", "qos"}, where)
    return TopicCondition(topic=_name(t, "topic", where), type=_type(t, where, "msg"), when=_condition(t, "when", where),
                          qos=parse_qos(t["qos"], where=f"{where}: qos") if "qos" in t else DEFAULT_QOS)


def parse_action_spec(table: Any, where: str) -> Ros2ActionSpec:
    """Parse an action's ``ros2`` table (see the module docstring).

    Raises:
        Ros2ConfigError: not exactly one of ``action``, ``service``, ``publish`` (or ``until`` alone),
            an unknown key or one that does not apply to the kind, a malformed name, type or
            condition, or a bad number.
    """
    t = _table(table, where)
    _keys(t, _ACTION_KEYS, where)
    kinds = [k for k in (ActionKind.ACTION, ActionKind.SERVICE, ActionKind.PUBLISH) if k in t]
    if len(kinds) > 1:
        raise Ros2ConfigError(f"{where}: give one of action, service and publish, not {' and '.join(kinds)}")
    kind = kinds[0] if kinds else ActionKind.WAIT
    if kind == ActionKind.WAIT and "until" not in t:
        raise Ros2ConfigError(f"{where}: needs action = \"/name\", service = \"/name\", publish = \"/topic\" "
                              f"or until = {{ topic = ..., type = ..., when = ... }}")
    for other, keys in _ONLY.items():
        wrong = sorted(keys & set(t)) if kind != other else []
        if wrong:
            raise Ros2ConfigError(f"{where}: {', '.join(wrong)} only apply to ros2 = {{ {other} = ... }}")
    if "success" in t and kind not in (ActionKind.ACTION, ActionKind.SERVICE):
        raise Ros2ConfigError(f"{where}: success only applies to actions and services (a publication succeeds "
                              f"when until holds)")
    if "until" in t and kind not in (ActionKind.PUBLISH, ActionKind.WAIT):
        raise Ros2ConfigError(f"{where}: until only applies to publish (or alone)")
    if kind == ActionKind.WAIT and "type" in t:
        raise Ros2ConfigError(f"{where}: type goes inside until = {{ ... }} for a wait")
    type_kind = {ActionKind.ACTION: "action", ActionKind.SERVICE: "srv"}.get(kind, "msg")
    spec = Ros2ActionSpec(
        kind=kind,
        name=_name(t, kind, where) if kind != ActionKind.WAIT else "",
        type=_type(t, where, type_kind) if kind != ActionKind.WAIT else "",
        success=_condition(t, "success", where),
        aborted=_status(t, "aborted", where),
        rejected=_status(t, "rejected", where),
        fill=_flag(t, "fill", where),
        cancel_wait_s=_number(t, "cancel_wait_s", where, high=60.0, default=1.0) or 1.0,
        qos=parse_qos(t["qos"], where=f"{where}: qos") if "qos" in t else DEFAULT_QOS,
        rate_hz=_number(t, "rate_hz", where, high=1000.0),
        duration_s=_number(t, "duration_s", where),
        until=_topic_condition(t["until"], f"{where}: until") if "until" in t else None,
    )
    if spec.duration_s is not None and spec.rate_hz is None:
        raise Ros2ConfigError(f"{where}: duration_s needs rate_hz (a single message takes no time)")
    return spec


# ------------------------------------------------------------------------------------------- events


@dataclass(frozen=True, slots=True, kw_only=True)
class Ros2EventSpec:
    """An external event raised by the messages of a ROS 2 topic.

    Attributes:
        topic: the topic.
        type: its message type.
        when: the condition (``None``: every message is an event).
        edge: rising (default) or every.
        fields: the message fields put in the event's payload (``None``: all of them).
        qos: the subscription's QoS.
    """

    topic: str
    type: str
    when: Condition | None = None
    edge: Edge = Edge.RISING
    fields: tuple[str, ...] | None = None
    qos: Qos = DEFAULT_QOS


def parse_event_spec(table: Any, where: str) -> Ros2EventSpec:
    """Parse an event's ``ros2`` table (see the module docstring).

    Raises:
        Ros2ConfigError: an unknown key, a malformed topic, type, condition or edge, or ``fields``
            that is not a list of field names.
    """
    t = _table(table, where)
    _keys(t, {"topic", "type", "when", "edge", "fields", "qos"}, where)
    edge = t.get("edge", "rising")
    if edge not in tuple(Edge):
        raise Ros2ConfigError(f"{where}: edge must be one of {', '.join(Edge)}, got {edge!r}")
    fields = t.get("fields")
    if fields is not None and (not isinstance(fields, list) or not all(isinstance(f, str) and f for f in fields)):
        raise Ros2ConfigError(f"{where}: fields must be a list of field names")
    return Ros2EventSpec(
        topic=_name(t, "topic", where), type=_type(t, where, "msg"), when=_condition(t, "when", where),
        edge=Edge(edge), fields=tuple(fields) if fields is not None else None,
        qos=parse_qos(t["qos"], where=f"{where}: qos") if "qos" in t else DEFAULT_QOS,
    )


def _resolve(store: TypeStore, msgtype: str, path: tuple[str, ...], where: str, what: str) -> None:
    """Check that the field path ``path`` exists in ``msgtype`` (through nested messages)."""
    current = msgtype
    for i, part in enumerate(path):
        fields = store.fields(current)
        if part not in fields:
            raise Ros2ConfigError(f"{where}: {what} reads {'.'.join(path[:i + 1])!r}, but {current} has no field "
                                  f"{part!r} (its fields: {', '.join(fields) or 'none'})")
        ftype = fields[part]
        if i + 1 < len(path) and (not ftype.nested or ftype.array):
            raise Ros2ConfigError(f"{where}: {what} reads {'.'.join(path[:i + 2])!r}, but {part!r} is a {ftype}")
        current = ftype.base


def _check_condition(store: TypeStore, condition: Condition | None, msgtype: str, where: str, what: str) -> None:
    if condition is not None:
        for path in condition.paths():
            _resolve(store, msgtype, path, where, what)


def check_action_types(spec: Ros2ActionSpec, store: TypeStore, where: str) -> None:
    """Check an action spec against the interface types: its type is defined, and its conditions
    read fields that exist.

    Raises:
        Ros2ConfigError: naming the unknown type or field.
    """
    try:
        if spec.kind == ActionKind.ACTION:
            if store.kind(spec.type) != "action":
                raise Ros2ConfigError(f"{where}: {spec.type} is not an action type")
            _check_condition(store, spec.success, action_type_names(spec.type).result, where, "success")
        elif spec.kind == ActionKind.SERVICE:
            _check_condition(store, spec.success, store.service(spec.type).response, where, "success")
        elif spec.kind == ActionKind.PUBLISH:
            store.fields(spec.type)
        if spec.until is not None:
            store.fields(spec.until.type)
            _check_condition(store, spec.until.when, spec.until.type, where, "until.when")
    except Ros2ConfigError:
        raise
    except Ros2Error as exc:
        raise Ros2ConfigError(f"{where}: {exc}") from None


def check_event_types(spec: Ros2EventSpec, store: TypeStore, where: str) -> None:
    """Check an event spec against the interface types (type, condition fields, payload fields).

    Raises:
        Ros2ConfigError: naming the unknown type or field.
    """
    try:
        store.fields(spec.type)
        _check_condition(store, spec.when, spec.type, where, "when")
        for name in spec.fields or ():
            _resolve(store, spec.type, (name,), where, "fields")
    except Ros2ConfigError:
        raise
    except Ros2Error as exc:
        raise Ros2ConfigError(f"{where}: {exc}") from None
