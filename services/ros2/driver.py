"""The ROS 2 driver of a node: its Zenoh session, the endpoints of its ROS 2 actions, its topic events.

services.toml places this driver (``ros2.NODE``) on every node that hosts a primitive action with a
``ros2`` table or publishes an event with one (:mod:`services.location`); nothing else starts it.
At node start it builds the interface types (the definitions petrobot ships plus ``[ros2]
interfaces``), checks every ROS 2 action and event of the node against them (an unknown type or
field stops the node with the services.toml section at fault), opens the session
(:class:`~services.ros2.session.Ros2Session`) and declares the endpoints, so that the ROS 2 tools
on the other side list petrobot's node with its clients and subscriptions before the first call.

An event from a topic (``[events.T] ros2 = { topic, type, when, edge, fields }``) is raised by this
driver: each message is decoded, the condition evaluated, the edge detector fed, and on an edge the
node publishes external event ``T`` with the message's fields (or the listed ones) as its data.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping
from typing import Any

from services.action import Driver, NodeContext
from services.devices.endpoint import DeviceEndpoint
from services.ros2.condition import EdgeDetector
from services.ros2.config import ActionKind, Ros2ActionSpec, Ros2EventSpec, check_action_types, check_event_types
from services.ros2.endpoints import ActionClient, Publication, ServiceClient, Subscription
from services.ros2.errors import ConditionError, Ros2Error
from services.ros2.session import Ros2Session
from services.ros2.typestore import DEFINITIONS, TypeStore, load_definitions

__all__ = ["Ros2Driver", "UntilWatch"]

log = logging.getLogger("petrobot.ros2")


class UntilWatch:
    """The latest message of an ``until`` topic and whether it met the condition (fed by a subscription)."""

    def __init__(self, spec: Ros2ActionSpec) -> None:
        assert spec.until is not None
        self.condition = spec.until.when
        self.met: asyncio.Event = asyncio.Event()
        self.message: dict[str, Any] | None = None
        self.problem: str | None = None

    def reset(self) -> None:
        """Forget what came before (a new run starts)."""
        self.met.clear()
        self.message = None
        self.problem = None

    def feed(self, fields: dict[str, Any]) -> None:
        """One message of the topic."""
        try:
            ok = self.condition is None or self.condition.evaluate(fields)
        except ConditionError as exc:
            self.problem = str(exc)
            ok = False
        if ok and not self.met.is_set():
            self.message = fields
            self.met.set()


class Ros2Driver(Driver):
    """The node's ROS 2 session and endpoints (see the module docstring)."""

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint:
        """The Zenoh router the node connects to first (``params["router"]``, from services.toml's
        ``connect``), which ``petrobot up`` checks before starting the node."""
        address = str(params.get("router", "")).split("/", 1)[-1].split("#", 1)[0]
        host, _, port = address.rpartition(":")
        return DeviceEndpoint("Zenoh router", host.strip("[]") or "127.0.0.1", int(port) if port.isdigit() else 0,
                              "petrobot sim zenoh (or rmw_zenohd on the ROS 2 machine)")

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        super().__init__(name, params)
        self.session: Ros2Session | None = None
        self.endpoints: dict[str, Any] = {}
        self.until: dict[str, UntilWatch] = {}
        self._subscriptions: list[Subscription] = []
        self._bad_events = 0

    async def setup(self, node: NodeContext) -> None:
        """Build the types, check the node's ROS 2 actions and events, open the session, declare
        the endpoints.

        Raises:
            Ros2ConfigError: an action or event names an unknown type or field.
            Ros2TypeError: a definition file is malformed.
            Ros2Error: the session cannot be opened.
        """
        location = node.location
        settings = location.nodes[node.name].ros2
        store = await asyncio.to_thread(lambda: TypeStore(load_definitions([DEFINITIONS, *settings.interfaces])))
        actions = {a.name: a.ros2 for a in location.actions_on(node.name) if a.ros2 is not None}
        events = {t: spec for t, spec in location.ros2_events.items() if location.events.get(t) == node.name}
        for name, spec in actions.items():
            check_action_types(spec, store, f"{location.path}: [actions.{name}] ros2")
        for topic, event in events.items():
            check_event_types(event, store, f"{location.path}: [events.{topic}] ros2")
        self.session = session = Ros2Session(settings, node.name, store)
        await session.open()
        try:
            for name, spec in actions.items():
                self._declare(name, spec)
            for topic, event in events.items():
                self._subscriptions.append(Subscription(session, event.topic, event.type, self._event(topic, event),
                                                        event.qos))
        except BaseException:
            await self.teardown()
            raise

    def _declare(self, name: str, spec: Ros2ActionSpec) -> None:
        session = self.session
        assert session is not None
        if spec.kind == ActionKind.ACTION:
            self.endpoints[name] = ActionClient(session, spec.name, spec.type, spec.qos)
        elif spec.kind == ActionKind.SERVICE:
            self.endpoints[name] = ServiceClient(session, spec.name, spec.type)
        elif spec.kind == ActionKind.PUBLISH:
            self.endpoints[name] = Publication(session, spec.name, spec.type, spec.qos)
        if spec.until is not None:
            watch = UntilWatch(spec)
            self.until[name] = watch
            self._subscriptions.append(Subscription(session, spec.until.topic, spec.until.type, watch.feed,
                                                    spec.until.qos))

    def _event(self, topic: str, spec: Ros2EventSpec) -> Any:
        edge = EdgeDetector(spec.edge)

        def on_message(fields: dict[str, Any]) -> None:
            try:
                value = spec.when is None or spec.when.evaluate(fields)
            except ConditionError as exc:
                self._bad_events += 1
                if self._bad_events <= 5:
                    log.warning("event %s from %s: %s", topic, spec.topic, exc)
                return
            if edge.update(value):
                data = {f: fields[f] for f in spec.fields} if spec.fields is not None else fields
                self.publish(topic, data)

        return on_message

    def endpoint(self, action: str) -> Any:
        """The client or publication of ROS 2 action ``action``.

        Raises:
            Ros2Error: ``action`` is no ROS 2 action of this node.
        """
        found = self.endpoints.get(action)
        if found is None:
            raise Ros2Error(f"{action} is not a ROS 2 action, service or publication of this node")
        return found

    async def teardown(self) -> None:
        """Withdraw every endpoint and close the session."""
        for sub in self._subscriptions:
            sub.close()
        self._subscriptions.clear()
        for endpoint in self.endpoints.values():
            endpoint.close()
        self.endpoints.clear()
        if self.session is not None:
            await self.session.close()
