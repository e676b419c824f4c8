"""The location file ``services.toml``: which node hosts which primitive action (paper §5).

"The designer must initially define in a file the location of the different primitive actions and
then the software will know where to direct a request for such a service" (Lima et al., §5). This
module parses that file (:func:`services.tomllines.parse_toml`: bounded nesting, no NUL, the line of
every key) into a frozen :class:`Location`; it reads the file and does no other I/O. Every problem is
a :class:`~services.errors.LocationError` reading ``FILE:LINE: problem``. Whether each ``impl``
imports and each host resolves is checked by :mod:`services.location_check` (``petrobot check``).

Format (every section optional except ``[nodes.*]``)::

    [nodes.alpha]                 # one node per host
    host = "127.0.0.1"
    port = 7101
    max_in_flight = 16            # optional cap on concurrently running calls
    state_dir = "/var/lib/petrobot/alpha"  # optional: where the node keeps results across restarts

    [tls]                         # optional: TLS on node connections (docs/protocol.md §3)
    mode = "certificate"          # "off" (default), "certificate" or "psk"
    ca = "ca.pem"                 # certificate mode: CA of every host's certificate
    cert = "host.pem"             # certificate mode: this host's certificate and key (PEM)
    key = "host.key"

    [nodes.alpha.tls]             # optional per-node overrides of [tls]
    server_name = "alpha.lab"     # name its certificate holds (default: its host)

    [actions.echo]
    node = "alpha"
    impl = "services.actions.demo:echo"   # importable "module:attr"
    local_only = false            # optional: refuse callers not on the node's own host
    deadline_s = 5.0              # optional default deadline, seconds
    params = { k = 1 }            # optional default params, merged under the call's params
    unattended = false            # optional: may finish when its caller is gone (else cancelled)
    motion = false                # optional: moves the robot: cancelled at once when its caller is gone

    [drivers.camera]              # optional background components started with the node
    node = "alpha"
    impl = "services.catching.camera:CameraDriver"
    params = {}

    [events.image_sampling_tick]  # which node publishes each external event topic
    node = "alpha"

    [memory]                      # which node hosts the global memory service
    node = "alpha"

    [ros2]                        # optional: how nodes reach ROS 2 over Zenoh (docs/ros2.md)
    [actions.fibonacci]           # a primitive action that is a ROS 2 action (no impl needed)
    node = "alpha"
    ros2 = { action = "/fibonacci", type = "example_interfaces/action/Fibonacci" }
    [events.crossfire]            # an external event from a ROS 2 topic
    node = "alpha"
    ros2 = { topic = "/crossfire", type = "std_msgs/msg/Bool", when = "data" }

The global memory actions ``memory.get``, ``memory.set`` and ``memory.keys`` are placed on the
``[memory]`` node implicitly; so is the driver ``ros2.NODE`` (the node's Zenoh session,
:mod:`services.ros2.driver`) on every node hosting a ROS 2 action or event. The ``ros2`` tables are
parsed by :mod:`services.ros2.config`.
"""

from __future__ import annotations

import ipaddress
import math
import os
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from services.errors import LocationError
from services.ros2.config import (
    ACTION_IMPL,
    DRIVER_IMPL,
    DRIVER_NAME,
    Ros2ActionSpec,
    Ros2EventSpec,
    SessionSettings,
    parse_action_spec,
    parse_event_spec,
    parse_session,
)
from services.textfile import TextProblem, decode_utf8, read_capped
from services.tomllines import parse_toml

__all__ = [
    "ACTION_KEYS",
    "DRIVER_KEYS",
    "EVENT_KEYS",
    "MEMORY_ACTIONS",
    "NODE_KEYS",
    "TOP_KEYS",
    "ActionPlacement",
    "DriverSpec",
    "Location",
    "NodeSpec",
    "TlsSettings",
    "load_location",
    "parse_location",
    "parse_tls",
]

MEMORY_ACTIONS = ("memory.get", "memory.set", "memory.keys")
"""Actions of the global memory service, hosted by the ``[memory]`` node."""

MEMORY_IMPL = "services.actions.memory:memory_actions"
_IMPL_RE = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_][\w.]*", re.ASCII)
_NAME_RE = re.compile(r"[A-Za-z_][\w.\-]*", re.ASCII)  # nodes
_ACTION_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")  # actions and drivers: the net's action ids
_TOPIC_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # event topics: 'ext:<topic>' in a net
_NAME_CHARS = {_NAME_RE: ", '.', '-'", _ACTION_RE: ", '.', '-'", _TOPIC_RE: ""}
_MAX_NAME = 256
_NUMERIC_HOST = re.compile(r"[0-9.]+")
_HOST_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9\-]{0,61}[A-Za-z0-9])?")
_DEFAULT_MAX_IN_FLIGHT = 16


TLS_MODES = ("off", "certificate", "psk")
"""Values of ``mode`` in ``[tls]``: plain TCP, TLS with certificates, TLS keyed by the shared key."""


@dataclass(frozen=True, slots=True, kw_only=True)
class TlsSettings:
    """TLS on the connections to and from one node (``[tls]``, overridden by ``[nodes.NAME.tls]``).

    Attributes:
        mode: ``"off"``, ``"certificate"`` (mutual TLS: every host presents ``cert``, checked
            against ``ca``) or ``"psk"`` (TLS keyed by the shared key, no certificates).
        ca: PEM file of the certificate authority (certificate mode).
        cert: PEM file of this host's certificate chain (certificate mode).
        key: PEM file of this host's private key (certificate mode).
        server_name: name the node's certificate must hold (default: the node's ``host``).

    Relative paths are taken from the directory of services.toml.
    """

    mode: str = "off"
    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    server_name: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class NodeSpec:
    """One node (one per host).

    Attributes:
        name: node name (table key).
        host: address the node listens on and clients connect to.
        port: TCP port.
        max_in_flight: cap on concurrently running calls; more are rejected with ``"busy"``.
        state_dir: directory where the node keeps call results across restarts, or ``None`` for
            the default (``$XDG_STATE_HOME/petrobot/NAME``, i.e. ``~/.local/state/petrobot/NAME``).
        tls: TLS settings of the connections to and from this node.
        ros2: how this node reaches ROS 2 (``[ros2]`` overridden by ``[nodes.NAME.ros2]``).
    """

    name: str
    host: str
    port: int
    max_in_flight: int = _DEFAULT_MAX_IN_FLIGHT
    state_dir: str | None = None
    tls: TlsSettings = field(default_factory=TlsSettings)
    ros2: SessionSettings = field(default_factory=SessionSettings)


@dataclass(frozen=True, slots=True, kw_only=True)
class ActionPlacement:
    """Where and how a primitive action runs: its node, its implementation and its call defaults.

    Not to be confused with the net's own ``coordinator.net.ActionSpec`` (an action of a primitive
    task, with its parameters and cost): a placement says where that action is served.

    Attributes:
        name: action name, as called.
        node: hosting node.
        impl: ``"module:attr"`` of a PrimitiveAction class/instance or an async function.
        local_only: refuse callers that are not on the node's own host.
        deadline_s: default deadline in seconds, or ``None``.
        params: default parameters, merged under each call's params.
        unattended: the call may finish when its caller is gone; otherwise the node cancels a
            call nobody waits for (docs/protocol.md §5, "Orphaned calls").
        motion: the action moves the robot: a call that loses its caller is cancelled at once
            (the action brings the robot to rest), not after the grace period, unless
            ``unattended``.
        ros2: the ROS 2 action, service or topic this action is (its ``ros2`` table), or ``None``.
    """

    name: str
    node: str
    impl: str
    local_only: bool = False
    deadline_s: float | None = None
    params: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    unattended: bool = False
    motion: bool = False
    ros2: Ros2ActionSpec | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class DriverSpec:
    """A background component (a hardware card) started with its node.

    Attributes:
        name: driver name, the key under which actions find it (``ctx.drivers[name]``).
        node: hosting node.
        impl: ``"module:attr"`` of a Driver subclass.
        params: constructor parameters.
    """

    name: str
    node: str
    impl: str
    params: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True, slots=True, kw_only=True)
class Location:
    """The parsed location file.

    Attributes:
        path: file it came from (``"<string>"`` when parsed from text).
        nodes: node specs by name.
        actions: action placements by name (memory actions included when ``[memory]`` is set).
        drivers: driver specs by name.
        events: publishing node by event topic.
        memory_node: node hosting the global memory, or ``None``.
        ros2_events: the events that come from ROS 2 topics, by event topic.
    """

    path: str
    nodes: Mapping[str, NodeSpec]
    actions: Mapping[str, ActionPlacement]
    drivers: Mapping[str, DriverSpec]
    events: Mapping[str, str]
    memory_node: str | None = None
    ros2_events: Mapping[str, Ros2EventSpec] = field(default_factory=lambda: MappingProxyType({}))

    def node_of(self, action: str) -> str:
        """Name of the node hosting ``action``.

        Raises:
            LocationError: unknown action.
        """
        spec = self.actions.get(action)
        if spec is None:
            raise LocationError(f"{self.path}: no action named {action!r}")
        return spec.node

    def action(self, action: str) -> ActionPlacement:
        """The placement of ``action``.

        Raises:
            LocationError: unknown action.
        """
        spec = self.actions.get(action)
        if spec is None:
            raise LocationError(f"{self.path}: no action named {action!r}")
        return spec

    def address(self, node: str) -> tuple[str, int]:
        """``(host, port)`` of ``node``.

        Raises:
            LocationError: unknown node.
        """
        spec = self.nodes.get(node)
        if spec is None:
            raise LocationError(f"{self.path}: no node named {node!r}")
        return spec.host, spec.port

    def actions_on(self, node: str) -> tuple[ActionPlacement, ...]:
        """Placements of every action hosted by ``node``, in file order."""
        return tuple(a for a in self.actions.values() if a.node == node)

    def drivers_on(self, node: str) -> tuple[DriverSpec, ...]:
        """Specs of every driver started with ``node``, in file order."""
        return tuple(d for d in self.drivers.values() if d.node == node)

    def publisher_of(self, topic: str) -> str:
        """Name of the node that publishes external event ``topic`` (``ext:`` prefix allowed).

        Raises:
            LocationError: no node publishes ``topic``.
        """
        topic = topic.removeprefix("ext:")
        node = self.events.get(topic)
        if node is None:
            raise LocationError(f"{self.path}: no node publishes event {topic!r} (add [events.{topic}])")
        return node


def load_location(path: str | os.PathLike[str]) -> Location:
    """Read and parse a location file (a regular UTF-8 file of at most 16 MiB).

    Raises:
        LocationError: the file cannot be read, is not TOML, or is inconsistent; the message is
            ``FILE:LINE: problem``.
    """
    p = os.fspath(path)
    try:
        text = decode_utf8(read_capped(p, what="location file"))
    except TextProblem as exc:
        raise _error(p, exc.line, exc.problem) from None
    return parse_location(text, path=p)


def _error(path: str, line: int | None, problem: str) -> LocationError:
    """A :class:`LocationError` whose message is ``FILE:LINE: problem`` (``FILE: problem`` without a line)."""
    return LocationError(f"{path}:{line}: {problem}" if line is not None else f"{path}: {problem}")


def _host_problem(host: str) -> str | None:
    """Why ``host`` is not an IP address or a host name (RFC 1123), or ``None``. No lookup."""
    try:
        ipaddress.ip_address(host)
        return None
    except ValueError:
        pass
    name = host.removesuffix(".")
    if _NUMERIC_HOST.fullmatch(name):
        return f"host {host!r} is not a valid IP address"
    if len(name) > 253 or not all(_HOST_LABEL.fullmatch(label) for label in name.split(".")):
        return f"host {host!r} is neither an IP address nor a host name (letters, digits, '-', dots)"
    return None


def parse_tls(entry: Any, where: str, base: TlsSettings, directory: str) -> TlsSettings:
    """Parse a ``[tls]`` or ``[nodes.NAME.tls]`` table over ``base`` (its keys override base's).

    Args:
        entry: the table.
        where: its place in the file, for error messages.
        base: the settings it overrides (the defaults, or ``[tls]`` for a node's table).
        directory: directory relative paths are taken from.

    Raises:
        LocationError: not a table, an unknown key or mode, a value that is not a string, or
            certificate mode without ``ca``, ``cert`` and ``key``.
    """
    if not isinstance(entry, dict):
        raise LocationError(f"{where} must be a table")
    extra = sorted(set(entry) - {"mode", "ca", "cert", "key", "server_name"})
    if extra:
        raise LocationError(f"{where}: unknown key(s) {', '.join(extra)}")
    values: dict[str, Any] = {}
    for name, value in entry.items():
        if not isinstance(value, str) or not value:
            raise LocationError(f"{where}: {name} must be a non-empty string")
        if name in ("ca", "cert", "key"):
            value = os.path.join(directory, os.path.expanduser(value))
        values[name] = value
    tls = TlsSettings(**{**{f: getattr(base, f) for f in TlsSettings.__slots__}, **values})
    if tls.mode not in TLS_MODES:
        raise LocationError(f"{where}: mode must be one of {', '.join(TLS_MODES)}, got {tls.mode!r}")
    if tls.mode == "certificate" and None in (tls.ca, tls.cert, tls.key):
        raise LocationError(f"{where}: certificate mode needs ca, cert and key")
    return tls


def parse_location(text: str, *, path: str = "<string>") -> Location:
    """Parse the text of a location file.

    Args:
        text: TOML text.
        path: file name used in error messages.

    Raises:
        LocationError: bad TOML (NUL characters, nesting deeper than 64, syntax), unknown node, bad
            name, bad host, bad impl string, duplicate address, bad types. The message is
            ``FILE:LINE: problem``, the line that of the key or table concerned.
    """
    try:
        doc, lines = parse_toml(text)
    except TextProblem as exc:
        raise _error(path, exc.line, exc.problem.replace("TOML syntax error", "not valid TOML", 1)) from None
    return _LocationLoader(doc, lines, path).load()


TOP_KEYS = frozenset({"nodes", "actions", "drivers", "events", "memory", "tls", "ros2"})
"""The tables a location file may have."""
NODE_KEYS = frozenset({"host", "port", "max_in_flight", "state_dir", "tls", "ros2"})
"""The keys of a ``[nodes.NAME]`` table."""
ACTION_KEYS = frozenset({"node", "impl", "local_only", "deadline_s", "params", "unattended", "motion", "ros2"})
"""The keys of an ``[actions.NAME]`` table."""
DRIVER_KEYS = frozenset({"node", "impl", "params"})
"""The keys of a ``[drivers.NAME]`` table."""
EVENT_KEYS = frozenset({"node", "ros2"})
"""The keys of an ``[events.TOPIC]`` table."""


class _LocationLoader:
    """Turns a parsed location file into a :class:`Location`, one kind of table after the other
    (the ``[tls]`` and ``[ros2]`` defaults, then nodes: every other table names one). The first
    problem stops it, as a :class:`~services.errors.LocationError` at the line of its key
    (``FILE:LINE: problem``).

    A new key of a table goes in its ``*_KEYS`` set and in the method that reads one entry of that
    kind (:meth:`node`, :meth:`action`, :meth:`driver`, :meth:`event`); the ``ros2`` tables are read
    by :mod:`services.ros2.config` through :meth:`ros2_of`.
    """

    def __init__(self, doc: dict[str, Any], lines: Any, path: str) -> None:
        self.doc = doc
        self.lines = lines
        self.path = path
        self.directory = os.path.dirname(path) if path != "<string>" else ""
        self.tls = TlsSettings()
        self.ros2 = SessionSettings()
        self.nodes: dict[str, NodeSpec] = {}
        self.ros2_events: dict[str, Ros2EventSpec] = {}
        self._addresses: dict[tuple[str, int], str] = {}

    def load(self) -> Location:
        extra = sorted(set(self.doc) - TOP_KEYS)
        if extra:
            raise self.fail(f"unknown key(s) {', '.join(extra)}", extra[0])
        if "tls" in self.doc:
            self.tls = self.tls_of(self.doc["tls"], "[tls]", TlsSettings(), "tls")
        if "ros2" in self.doc:
            self.ros2 = self.ros2_of(parse_session, self.doc["ros2"], "[ros2]", "ros2", directory=self.directory)
        for name, entry in self.table("nodes").items():
            self.nodes[name] = self.node(name, entry)
        if not self.nodes:
            raise _error(self.path, 1, "no [nodes.*] table: a location file names at least one node")
        memory_node = self.memory()
        actions = {name: self.action(name, entry) for name, entry in self.table("actions").items()}
        if memory_node is not None:
            for name in MEMORY_ACTIONS:
                actions[name] = ActionPlacement(name=name, node=memory_node, impl=MEMORY_IMPL)
        drivers = {name: self.driver(name, entry) for name, entry in self.table("drivers").items()}
        events = {topic: self.event(topic, entry) for topic, entry in self.table("events").items()}
        self.ros2_drivers(actions, events, drivers)
        return Location(
            path=self.path,
            nodes=MappingProxyType(self.nodes),
            actions=MappingProxyType(actions),
            drivers=MappingProxyType(drivers),
            events=MappingProxyType(events),
            memory_node=memory_node,
            ros2_events=MappingProxyType(self.ros2_events),
        )

    # ---------------------------------------------------------------- one entry of each kind
    def node(self, name: str, entry: Any) -> NodeSpec:
        """A ``[nodes.NAME]`` table (its address must not be another node's)."""
        where = f"[nodes.{name}]"
        self.entry_table(entry, where, NODE_KEYS, "nodes", name)
        self.check_name(name, _NAME_RE, where, "nodes", name)
        host = entry.get("host")
        port = entry.get("port")
        cap = entry.get("max_in_flight", _DEFAULT_MAX_IN_FLIGHT)
        if not isinstance(host, str) or not host:
            raise self.fail(f"{where}: host must be a non-empty string", "nodes", name, "host")
        problem = _host_problem(host)
        if problem is not None:
            raise self.fail(f"{where}: {problem}", "nodes", name, "host")
        if type(port) is not int or not 0 < port < 65536:
            raise self.fail(f"{where}: port must be an integer in 1..65535", "nodes", name, "port")
        if type(cap) is not int or cap < 1:
            raise self.fail(f"{where}: max_in_flight must be a positive integer", "nodes", name, "max_in_flight")
        if (host, port) in self._addresses:
            raise self.fail(f"{where}: duplicate address {host}:{port} (also node {self._addresses[host, port]!r})",
                            "nodes", name, "port")
        self._addresses[host, port] = name
        state_dir = entry.get("state_dir")
        if state_dir is not None and (not isinstance(state_dir, str) or not state_dir):
            raise self.fail(f"{where}: state_dir must be a non-empty string", "nodes", name, "state_dir")
        tls = self.tls_of(entry["tls"], f"{where}.tls", self.tls, "nodes", name, "tls") if "tls" in entry else self.tls
        ros2 = (self.ros2_of(parse_session, entry["ros2"], f"{where}.ros2", "nodes", name, "ros2", base=self.ros2,
                             directory=self.directory) if "ros2" in entry else self.ros2)
        return NodeSpec(
            name=name, host=host, port=port, max_in_flight=cap, tls=tls, ros2=ros2,
            state_dir=os.path.join(self.directory, os.path.expanduser(state_dir)) if state_dir else None,
        )

    def memory(self) -> str | None:
        """The ``[memory]`` table: the node hosting the global memory, or ``None``."""
        mem = self.table("memory")
        if not mem:
            return None
        self.check_keys(mem, {"node"}, "[memory]", "memory")
        return self.node_ref(mem, "[memory]", "memory")

    def action(self, name: str, entry: Any) -> ActionPlacement:
        """An ``[actions.NAME]`` table (a ROS 2 action, service or topic by its ``ros2`` table, with
        no ``impl`` needed)."""
        where = f"[actions.{name}]"
        self.entry_table(entry, where, ACTION_KEYS, "actions", name)
        if name in MEMORY_ACTIONS:
            raise self.fail(f"{where}: {name} is reserved for the global memory service", "actions", name)
        self.check_name(name, _ACTION_RE, where, "actions", name)
        local_only = self.flag(entry, "local_only", where, "actions", name)
        unattended = self.flag(entry, "unattended", where, "actions", name)
        motion = self.flag(entry, "motion", where, "actions", name)
        deadline = entry.get("deadline_s")
        if deadline is not None and (isinstance(deadline, bool) or not isinstance(deadline, (int, float))
                                     or not 0 < deadline < math.inf):
            raise self.fail(f"{where}: deadline_s must be a positive finite number", "actions", name, "deadline_s")
        spec = (self.ros2_of(parse_action_spec, entry["ros2"], f"{where}: ros2", "actions", name, "ros2")
                if "ros2" in entry else None)
        return ActionPlacement(
            name=name,
            node=self.node_ref(entry, where, "actions", name),
            impl=self.impl_ref(entry, where, "actions", name) if spec is None or "impl" in entry else ACTION_IMPL,
            ros2=spec,
            local_only=local_only,
            deadline_s=float(deadline) if deadline is not None else None,
            params=self.params_of(entry, where, "actions", name),
            unattended=unattended,
            motion=motion,
        )

    def driver(self, name: str, entry: Any) -> DriverSpec:
        """A ``[drivers.NAME]`` table."""
        where = f"[drivers.{name}]"
        self.entry_table(entry, where, DRIVER_KEYS, "drivers", name)
        self.check_name(name, _ACTION_RE, where, "drivers", name)
        return DriverSpec(
            name=name, node=self.node_ref(entry, where, "drivers", name),
            impl=self.impl_ref(entry, where, "drivers", name), params=self.params_of(entry, where, "drivers", name),
        )

    def event(self, topic: str, entry: Any) -> str:
        """An ``[events.TOPIC]`` table: the node that publishes the topic (the ROS 2 topic it comes
        from, by its ``ros2`` table, goes to :attr:`ros2_events`)."""
        where = f"[events.{topic}]"
        self.entry_table(entry, where, EVENT_KEYS, "events", topic)
        self.check_name(topic, _TOPIC_RE, where, "events", topic)
        node = self.node_ref(entry, where, "events", topic)
        if "ros2" in entry:
            self.ros2_events[topic] = self.ros2_of(parse_event_spec, entry["ros2"], f"{where}: ros2", "events", topic,
                                                   "ros2")
        return node

    def ros2_drivers(self, actions: Mapping[str, ActionPlacement], events: Mapping[str, str],
                     drivers: dict[str, DriverSpec]) -> None:
        """Add the implicit driver ``ros2.NODE`` (the node's Zenoh session) of every node hosting a
        ROS 2 action or event to ``drivers``; a driver of the file may not take its name."""
        for node in sorted({a.node for a in actions.values() if a.ros2} | {events[t] for t in self.ros2_events}):
            name = f"{DRIVER_NAME}.{node}"
            if name in drivers:
                raise self.fail(f"[drivers.{name}]: the name {name} is reserved for the ROS 2 session of node {node}",
                                "drivers", name)
            connect = self.nodes[node].ros2.connect
            drivers[name] = DriverSpec(name=name, node=node, impl=DRIVER_IMPL,
                                       params=MappingProxyType({"router": connect[0]} if connect else {}))

    # ---------------------------------------------------------------- values
    def node_ref(self, entry: Mapping[str, Any], where: str, *key: str) -> str:
        node = entry.get("node")
        if not isinstance(node, str):
            raise self.fail(f"{where}: node must be a string", *key, "node")
        if node not in self.nodes:
            raise self.fail(f"{where}: unknown node {node!r} (known: {', '.join(sorted(self.nodes))})", *key, "node")
        return node

    def impl_ref(self, entry: Mapping[str, Any], where: str, *key: str) -> str:
        impl = entry.get("impl")
        if not isinstance(impl, str) or not _IMPL_RE.fullmatch(impl):
            raise self.fail(f"{where}: impl must be an importable \"module:attr\" string, got {impl!r}", *key, "impl")
        return impl

    def params_of(self, entry: Mapping[str, Any], where: str, *key: str) -> Mapping[str, Any]:
        params = entry.get("params", {})
        if not isinstance(params, dict):
            raise self.fail(f"{where}: params must be a table", *key, "params")
        return MappingProxyType(dict(params))

    def flag(self, entry: Mapping[str, Any], name: str, where: str, *key: str) -> bool:
        value = entry.get(name, False)
        if not isinstance(value, bool):
            raise self.fail(f"{where}: {name} must be true or false", *key, name)
        return value

    def tls_of(self, entry: Any, where: str, base: TlsSettings, *key: str) -> TlsSettings:
        try:
            return parse_tls(entry, where, base, self.directory)
        except LocationError as exc:
            raise self.fail(str(exc), *key) from None

    def ros2_of(self, parse: Any, value: Any, where: str, *key: str, **kwargs: Any) -> Any:
        """``parse(value, where=where, **kwargs)`` (a parser of :mod:`services.ros2.config`), its
        problem reported at the line of ``key``."""
        try:
            return parse(value, where=where, **kwargs)
        except LocationError as exc:
            raise self.fail(str(exc), *key) from None

    # ---------------------------------------------------------------- structure and reporting
    def fail(self, problem: str, *key: str) -> LocationError:
        return _error(self.path, self.lines.line(*key), problem)

    def table(self, key: str) -> Mapping[str, Any]:
        value = self.doc.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(f"[{key}] must be a table", key)
        return value

    def entry_table(self, entry: Any, where: str, allowed: frozenset[str], *key: str) -> None:
        if not isinstance(entry, dict):
            raise self.fail(f"{where} must be a table", *key)
        self.check_keys(entry, allowed, where, *key)

    def check_keys(self, entry: Mapping[str, Any], allowed: Collection[str], where: str, *key: str) -> None:
        extra = sorted(set(entry) - set(allowed))
        if extra:
            raise self.fail(f"{where}: unknown key(s) {', '.join(extra)}", *key, extra[0])

    def check_name(self, name: str, pattern: re.Pattern[str], where: str, *key: str) -> None:
        if len(name) > _MAX_NAME or not pattern.fullmatch(name):
            raise self.fail(f"{where}: bad name (use letters, digits, '_'{_NAME_CHARS[pattern]}, starting with a "
                            f"letter or '_'; at most {_MAX_NAME} characters)", *key)
