"""The asyncio shell around one Zenoh session: petrobot's node as a node of the ROS 2 graph.

:class:`Ros2Session` opens the session (:func:`services.ros2.config.zenoh_config`), declares the
node's liveliness token so that ``ros2 node list`` on the other side shows it (rmw_zenoh dialect),
follows the graph (every liveliness token of the domain, or the bridges' tokens) so that a client can
tell when its server disappears, and gives :mod:`services.ros2.endpoints` what it needs: key
expressions, entity tokens and GIDs, and a way back from Zenoh's threads into the event loop.

Zenoh calls back from its own threads; every callback here only hands its data to the event loop
(``call_soon_threadsafe``), so the rest of petrobot stays single-threaded. ``zenoh`` is imported
when a session opens, not before: commands that never open one do not pay for it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
from collections.abc import Callable
from typing import Any

from services.ros2.config import PASSWORD_ENV, SessionSettings, endpoint_problems, zenoh_config
from services.ros2.errors import Ros2ConfigError, Ros2Error, Ros2WireError
from services.ros2.graph import (
    BridgeToken,
    Dialect,
    Entity,
    EntityKind,
    bridge_graph_keyexpr,
    data_keyexpr,
    graph_keyexpr,
)
from services.ros2.names import dds_type_name, qualify
from services.ros2.typestore import TypeStore

__all__ = ["Ros2Session", "import_zenoh"]

log = logging.getLogger("petrobot.ros2")

_MAX_GRAPH = 100_000
"""Tokens kept in the graph cache; beyond, new ones are ignored (a hostile peer cannot exhaust memory)."""


def import_zenoh() -> Any:
    """The ``zenoh`` module (imported on first use)."""
    import zenoh

    return zenoh


def _password(settings: SessionSettings) -> str | None:
    if not settings.user:
        return None
    if settings.password_file:
        try:
            with open(settings.password_file, encoding="utf-8") as fh:
                return fh.read().strip()
        except OSError as exc:
            raise Ros2ConfigError(f"cannot read the Zenoh password file {settings.password_file}: "
                                  f"{exc.strerror or exc}") from None
    password = os.environ.get(PASSWORD_ENV)
    if password is None:
        raise Ros2ConfigError(f"user {settings.user!r} needs a password: set password_file in [ros2] or the "
                              f"environment variable {PASSWORD_ENV}")
    return password


class Ros2Session:
    """One node's Zenoh session and its place in the ROS 2 graph.

    Args:
        settings: the node's ``[ros2]`` settings.
        node: the petrobot node's name (its ROS 2 node is ``settings.ros_node_name(node)``).
        store: the interface types.

    Attributes:
        settings: as given.
        store: as given.
        node_name: the ROS 2 node name.
        zid: the Zenoh session id (hex), once open.
    """

    def __init__(self, settings: SessionSettings, node: str, store: TypeStore) -> None:
        self.settings = settings
        self.store = store
        self.node_name = settings.ros_node_name(node)
        self.zid = ""
        self._z: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tokens: dict[str, Any] = {}
        self._graph: dict[str, Entity | BridgeToken] = {}
        self._graph_sub: Any = None
        self._watchers: set[Callable[[], None]] = set()
        self._next_id = 1
        self._node_token: Any = None
        self._closed = False
        self._bad_tokens = 0

    # ---- lifecycle

    @property
    def zenoh(self) -> Any:
        """The open ``zenoh.Session``.

        Raises:
            Ros2Error: the session is not open.
        """
        if self._z is None or self._closed:
            raise Ros2Error("the Zenoh session is not open")
        return self._z

    @property
    def dialect(self) -> Dialect:
        """The wire dialect."""
        return self.settings.dialect

    async def open(self) -> None:
        """Open the session, follow the graph and declare the node's token.

        A session opens even when no router answers yet (Zenoh keeps trying to connect); calls
        made before it connects find no server and end in ``error``.

        Raises:
            Ros2ConfigError: the password cannot be read.
            Ros2Error: Zenoh refuses the configuration or cannot open the session.
        """
        zenoh = import_zenoh()
        self._loop = asyncio.get_running_loop()
        for problem in endpoint_problems(self.settings):
            log.warning("ROS 2 session of %s: %s: allowed by allow_plaintext, but anyone on the path can read and "
                        "alter every message, goal and result", self.node_name, problem)
        config = zenoh.Config()
        try:
            for key, value in zenoh_config(self.settings, _password(self.settings)).items():
                config.insert_json5(key, json.dumps(value))
            self._z = await asyncio.to_thread(zenoh.open, config)
        except zenoh.ZError as exc:
            raise Ros2Error(f"cannot open the Zenoh session: {exc}") from None
        self.zid = str(self._z.info.zid())
        if self.dialect is Dialect.RMW_ZENOH:
            key = graph_keyexpr(self.settings.domain_id)
        else:
            key = bridge_graph_keyexpr()
        self._graph_sub = self._z.liveliness().declare_subscriber(
            key, zenoh.handlers.Callback(self._on_token, indirect=False), history=True)
        if self.dialect is Dialect.RMW_ZENOH:
            node = Entity(domain_id=self.settings.domain_id, session_id=self.zid, node_id=0, entity_id=0,
                          kind=EntityKind.NODE, namespace=self.settings.namespace, node_name=self.node_name)
            self._node_token = self._z.liveliness().declare_token(node.token)
        if self.settings.connect and not list(self._z.info.routers_zid()):
            log.warning("ROS 2 session of %s: no Zenoh router answers at %s yet (down, refusing our TLS "
                        "certificate or password, or unreachable); Zenoh keeps trying, and calls find no server "
                        "meanwhile", self.node_name, ", ".join(self.settings.connect))
        log.info("ROS 2 session %s open (%s, %s mode, domain %d, connect %s): node %s%s", self.zid,
                 self.dialect.value, self.settings.mode, self.settings.domain_id, ", ".join(self.settings.connect),
                 qualify(self.node_name, self.settings.namespace), "" if self.settings.user is None
                 else f", user {self.settings.user}")

    async def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        if self._closed or self._z is None:
            self._closed = True
            return
        self._closed = True
        for token in [self._node_token, *self._tokens.values()]:
            if token is not None:
                try:
                    token.undeclare()
                except Exception:  # noqa: BLE001 - the session may already be gone
                    pass
        self._tokens.clear()
        try:
            await asyncio.to_thread(self._z.close)
        except Exception as exc:  # noqa: BLE001 - closing must not fail the node's stop
            log.warning("closing the Zenoh session failed: %s", exc)

    def connected(self) -> bool:
        """Whether the session reaches at least one Zenoh router or peer now."""
        if self._z is None or self._closed:
            return False
        try:
            info = self._z.info
            return bool(list(info.routers_zid()) or list(info.peers_zid()))
        except Exception:  # noqa: BLE001 - a session being torn down
            return False

    # ---- back into the event loop

    def soon(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` on the event loop (from any thread; dropped once the loop is closed)."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:
            pass  # the loop closed meanwhile

    # ---- entities

    def qualify(self, name: str) -> str:
        """``name`` made absolute in the node's namespace."""
        return qualify(name, self.settings.namespace)

    def key(self, name: str, ros_type: str) -> str:
        """The Zenoh key of topic or service ``name`` (absolute) of type ``ros_type``."""
        if self.dialect is Dialect.BRIDGE:
            return data_keyexpr(self.dialect, 0, name, "", "")
        return data_keyexpr(self.dialect, self.settings.domain_id, name, dds_type_name(ros_type),
                            self.store.hash(ros_type))

    def entity(self, kind: EntityKind, name: str, ros_type: str, qos: str) -> Entity:
        """A new entity of petrobot's ROS 2 node (a fresh entity id)."""
        entity_id, self._next_id = self._next_id, self._next_id + 1
        return Entity(domain_id=self.settings.domain_id, session_id=self.zid or "0", node_id=0, entity_id=entity_id,
                      kind=kind, namespace=self.settings.namespace, node_name=self.node_name, name=name,
                      dds_type=dds_type_name(ros_type), type_hash=self.store.hash(ros_type), qos=qos)

    def announce(self, entity: Entity) -> None:
        """Declare ``entity``'s liveliness token (rmw_zenoh dialect; the bridge has no such graph)."""
        if self.dialect is Dialect.RMW_ZENOH and entity.token not in self._tokens:
            self._tokens[entity.token] = self.zenoh.liveliness().declare_token(entity.token)

    def withdraw(self, entity: Entity) -> None:
        """Undeclare ``entity``'s token."""
        token = self._tokens.pop(entity.token, None)
        if token is not None:
            try:
                token.undeclare()
            except Exception:  # noqa: BLE001 - the session may be closing
                pass

    # ---- the graph

    def _on_token(self, sample: Any) -> None:
        """Zenoh thread: a token appeared or went."""
        put = str(sample.kind).endswith("PUT")
        self.soon(self._graph_changed, put, str(sample.key_expr))

    def _graph_changed(self, put: bool, token: str) -> None:
        if put:
            if len(self._graph) >= _MAX_GRAPH or token in self._graph:
                return
            try:
                self._graph[token] = (Entity.parse(token) if self.dialect is Dialect.RMW_ZENOH
                                      else BridgeToken.parse(token))
            except Ros2WireError as exc:
                self._bad_tokens += 1
                if self._bad_tokens <= 5:
                    log.warning("ignoring a malformed liveliness token: %s", exc)
                return
        elif self._graph.pop(token, None) is None:
            return
        for watcher in list(self._watchers):
            watcher()

    def servers(self, name: str, *, action: bool = False) -> list[str]:
        """The tokens of the servers of service ``name`` (absolute) now in the graph; with ``action``,
        also the bridges' action-server tokens of the action that ``name`` belongs to."""
        found = []
        for token, entry in self._graph.items():
            if isinstance(entry, Entity):
                if entry.kind is EntityKind.SERVICE and entry.name == name:
                    found.append(token)
            elif entry.kind == "SS" and entry.key == name.strip("/"):
                found.append(token)
            elif action and entry.kind == "AS" and name.strip("/").startswith(entry.key + "/_action/"):
                found.append(token)
        return found

    def publishers(self, name: str) -> list[str]:
        """The tokens of the publishers of topic ``name`` (absolute) now in the graph."""
        return [token for token, entry in self._graph.items()
                if (isinstance(entry, Entity) and entry.kind is EntityKind.PUBLISHER and entry.name == name)
                or (isinstance(entry, BridgeToken) and entry.kind == "MP" and entry.key == name.strip("/"))]

    def graph(self) -> list[Entity | BridgeToken]:
        """Every entity now in the graph."""
        return list(self._graph.values())

    def watch(self, fn: Callable[[], None]) -> Callable[[], None]:
        """Call ``fn()`` on the loop after every change of the graph; returns the function that stops it."""
        self._watchers.add(fn)
        return lambda: self._watchers.discard(fn)
