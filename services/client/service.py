"""Call primitive actions by name: :class:`ServiceClient`, which routes each call by services.toml.

"The designer must initially define in a file the location of the different primitive actions and
then the software will know where to direct a request for such a service" (Lima et al., §5): the
client keeps one :class:`~services.client.link.NodeLink` per node and sends each call to the node
services.toml places its action on. :meth:`ServiceClient.preflight` checks, before a run, that
every action of a net is placed, and offered by a reachable node that loaded the same services.toml.
"""

from __future__ import annotations

import asyncio
import hashlib
from collections.abc import Iterable
from typing import Any, Self

from services.client.link import EventCallback, FeedbackCallback, NodeBusy, NodeLink, describe
from services.errors import AuthenticationError, LocationError, ProtocolError
from services.location import Location
from services.results import ActionResult

__all__ = ["PREFLIGHT_S", "ServiceClient"]

PREFLIGHT_S = 10.0
"""How long :meth:`ServiceClient.preflight` keeps trying a node that is up but busy (it refuses
connections at a limit, or does not answer within ``connect_timeout_s``), seconds."""


def _file_digest(path: str) -> str | None:
    try:
        with open(path, "rb") as fh:
            return hashlib.sha256(fh.read()).hexdigest()
    except OSError:
        return None


class ServiceClient:
    """Call primitive actions by name; services.toml says where each runs.

    Use as an async context manager::

        async with ServiceClient(load_location("services.toml"), load_key()) as client:
            res = await client.call("echo", {"x": 1})

    Args:
        location: the parsed services.toml.
        key: the shared key.
        name: client name sent to nodes.
        heartbeat_s: ping period per node connection.
        connect_timeout_s: reconnect budget at the start of a call.
        local_addr: optional ``(host, port)`` to bind client sockets to.
        location_digest: hex SHA-256 of the services.toml bytes ``location`` came from, which
            :meth:`preflight` compares with each node's (default: the digest of the file at
            ``location.path`` when the client is made, if it can be read).
    """

    def __init__(
        self,
        location: Location,
        key: bytes,
        *,
        name: str = "coordinator",
        heartbeat_s: float = 0.25,
        connect_timeout_s: float = 1.0,
        local_addr: tuple[str, int] | None = None,
        location_digest: str | None = None,
    ) -> None:
        self.location = location
        self.name = name
        self.heartbeat_s = heartbeat_s
        self.connect_timeout_s = connect_timeout_s
        self.local_addr = local_addr
        self.location_digest = location_digest if location_digest is not None else _file_digest(location.path)
        self._key = key
        self._links: dict[str, NodeLink] = {}
        self._call_node: dict[str, str] = {}

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def link(self, node: str) -> NodeLink:
        """The (lazily created) link to ``node``.

        Raises:
            LocationError: unknown node.
        """
        link = self._links.get(node)
        if link is None:
            link = NodeLink(
                node, self.location.address(node), self._key, name=self.name,
                heartbeat_s=self.heartbeat_s, connect_timeout_s=self.connect_timeout_s,
                local_addr=self.local_addr, tls=self.location.nodes[node].tls,
            )
            self._links[node] = link
        return link

    def health(self) -> dict[str, dict[str, Any]]:
        """Each node of services.toml as an operator's view shows it (read-only; no I/O).

        Returns:
            node name → :meth:`NodeLink.health` (a node never called yet: not connected, no
            round trip, no call in flight).
        """
        out: dict[str, dict[str, Any]] = {}
        for node in self.location.nodes:
            link = self._links.get(node)
            out[node] = link.health() if link is not None else {"connected": False, "heartbeat_rtt_s": None,
                                                                "in_flight": 0}
        return out

    async def call(
        self,
        action: str,
        params: dict[str, Any] | None = None,
        *,
        call_id: str | None = None,
        deadline_s: float | None = None,
        on_feedback: FeedbackCallback | None = None,
    ) -> ActionResult:
        """Call ``action`` on the node services.toml places it on (see :meth:`NodeLink.call`).

        ``deadline_s`` defaults to the action's ``deadline_s`` in services.toml.

        Raises:
            LocationError: ``action`` is not in services.toml (a configuration error, not node trouble).
        """
        spec = self.location.action(action)
        if deadline_s is None:
            deadline_s = spec.deadline_s
        link = self.link(spec.node)
        cid = call_id if call_id is not None else link.new_call_id()
        self._call_node[cid] = spec.node
        try:
            return await link.call(action, params, call_id=cid, deadline_s=deadline_s, on_feedback=on_feedback)
        finally:
            self._call_node.pop(cid, None)

    async def query(self, action: str, call_id: str, *, cancel: bool = False) -> ActionResult | None:
        """What became of call ``call_id`` of ``action``, asked of the node that hosts ``action``
        (see :meth:`NodeLink.query`: ``None`` if that node never saw the id or no longer keeps it).

        Raises:
            LocationError: ``action`` is not in services.toml.
        """
        return await self.link(self.location.node_of(action)).query(call_id, cancel=cancel)

    async def cancel(self, call_id: str) -> bool:
        """Cancel a running call by id (the call then returns ``error`` with reason ``"cancelled"``).

        Returns:
            True if the call was running and a cancel was sent.
        """
        node = self._call_node.get(call_id)
        if node is None:
            return False
        return await self._links[node].cancel(call_id)

    async def preflight(self, actions: Iterable[str], *, deadline_s: float = PREFLIGHT_S) -> list[str]:
        """Check that ``actions`` can be served before a run starts.

        Connects to every node that hosts one of them (at once, each within
        ``connect_timeout_s``) and reports, in plain words: an action not placed in services.toml;
        a node that cannot be reached (its address and the error); an action its node does not
        offer (the node was started from another services.toml); a node whose services.toml
        differs from this client's, or changed on disk since the node started. A node that is up
        but busy — it closes the connection at a limit (``overloaded``, ``auth_throttled``) or does
        not answer in time, as under a flood of connections — is tried again with backoff until
        ``deadline_s`` has passed; a node that refuses the connection (nothing listens) or our key
        is reported at once.

        Returns:
            The problems found, one sentence each; empty when every action is ready.
        """
        problems: list[str] = []
        by_node: dict[str, list[str]] = {}
        for action in dict.fromkeys(actions):
            try:
                by_node.setdefault(self.location.node_of(action), []).append(action)
            except LocationError:
                problems.append(f"action {action!r} is not placed in {self.location.path} (add [actions.{action}])")
        names = sorted(by_node)
        end = asyncio.get_running_loop().time() + deadline_s
        outcomes = await asyncio.gather(*(self._check_node(n, by_node[n], end) for n in names))
        for found in outcomes:
            problems.extend(found)
        return problems

    async def _check_node(self, node: str, actions: list[str], end: float) -> list[str]:
        link = self.link(node)
        host, port = link.address
        loop = asyncio.get_running_loop()
        delay = 0.1
        while True:
            try:
                await link.connect()
                break
            except AuthenticationError as exc:
                return [f"node {node} at {host}:{port} refused our key: {exc}"]
            except (NodeBusy, TimeoutError) as exc:  # up, but at a limit: try again until the deadline
                if loop.time() + delay >= end:
                    return [f"node {node} at {host}:{port} is unreachable: {describe(exc)} (busy: tried until "
                            "the preflight's deadline)"]
                await asyncio.sleep(delay)
                delay = min(2 * delay, 1.0)
            except (OSError, ProtocolError) as exc:
                return [f"node {node} at {host}:{port} is unreachable: {describe(exc)}"]
        problems = []
        offered = link.offered_actions
        if offered is not None:
            for action in actions:
                if action not in offered:
                    problems.append(
                        f"node {node} does not offer {action!r} (it offers {', '.join(offered) or 'nothing'}): "
                        f"its services.toml differs: restart it")
        if link.location_digest is not None and self.location_digest is not None \
                and link.location_digest != self.location_digest:
            problems.append(f"node {node} loaded a services.toml that differs from ours ({self.location.path}): "
                            f"restart it with the same file")
        if link.location_changed:
            problems.append(f"node {node}'s services.toml changed on disk since it started: restart it")
        return problems

    def subscribe(self, topic: str, callback: EventCallback) -> None:
        """Deliver external event ``topic`` to ``callback``, from the node services.toml names.

        Raises:
            LocationError: no node publishes ``topic``.
        """
        self.link(self.location.publisher_of(topic)).subscribe(topic, callback)

    def unsubscribe(self, topic: str, callback: EventCallback | None = None) -> None:
        """Stop delivering ``topic`` to ``callback`` (or to all callbacks)."""
        self.link(self.location.publisher_of(topic)).unsubscribe(topic, callback)

    async def close(self) -> None:
        """Close every node link."""
        links = list(self._links.values())
        self._links.clear()
        for link in links:
            await link.close()
