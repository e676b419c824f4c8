"""The ROS 2 driver of a node: its Zenoh session, the endpoints of its ROS 2 actions, its topic events.

services.toml places this driver (``ros2.NODE``) on every node that hosts a primitive action with a
``ros2`` table or publishes an event with one (:mod:`services.location`); nothing else starts it.
At node start it builds the interface types (the definitions petrobot ships plus ``[ros2]
interfaces``), checks every ROS 2 action and event of the node against them (an unknown type or
field stops the node with the services.toml section at fault), opens the session
(:class:`~services.ros2.session.Ros2Session`) and declares the endpoints, so that the ROS 2 tools
on the other side list petrobot's node with its clients and subscriptions before the first call.

Goals outlive a crash of the node: the robot keeps executing a goal whose node died, while the
restarted node answers the call ``node_restarted`` (its result store) and the net takes its error
branch. So that the robot agrees with the journal, the driver keeps the goals in flight in
``ros2-goals.json`` in the node's state directory (written before each goal is sent, rewritten when
it ends) and, at start, sends ``cancel_goal`` for every goal a previous process left there.

An event from a topic (``[events.T] ros2 = { topic, type, when, edge, fields }``) is raised by this
driver: each message is decoded, the condition evaluated, the edge detector fed, and on an edge the
node publishes external event ``T`` with the message's fields (or the listed ones) as its data.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from services.action import Driver, NodeContext
from services.devices.endpoint import DeviceEndpoint
from services.node.store import default_state_dir
from services.ros2.condition import EdgeDetector
from services.ros2.config import ActionKind, Ros2ActionSpec, Ros2EventSpec, check_action_types, check_event_types
from services.ros2.endpoints import ActionClient, Publication, ServiceClient, Subscription
from services.ros2.errors import ConditionError, Ros2Error
from services.ros2.session import Ros2Session
from services.ros2.typestore import DEFINITIONS, TypeStore, load_definitions
from services.textfile import write_atomically

__all__ = ["GoalLedger", "Ros2Driver", "UntilWatch"]

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


class GoalLedger:
    """The goals a node has in flight, in a JSON file that survives the process (see the module docstring).

    Args:
        path: the file (``STATE_DIR/ros2-goals.json``).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.goals: dict[str, str] = {}

    def left_over(self) -> dict[str, str]:
        """The goals a previous process left in flight: goal id (hex) → action name; ``{}`` if none
        or if the file is unreadable (said in the log)."""
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            log.warning("cannot read %s (%s): goals left running by a previous process are not cancelled",
                        self.path, exc)
            return {}
        goals = data.get("goals", {}) if isinstance(data, dict) else {}
        return {str(k): str(v) for k, v in goals.items()} if isinstance(goals, dict) else {}

    def add(self, goal_id: str, action: str) -> None:
        """Record a goal about to be sent."""
        self.goals[goal_id] = action
        self._write()

    def remove(self, goal_id: str) -> None:
        """Forget a goal that ended."""
        if self.goals.pop(goal_id, None) is not None:
            self._write()

    def clear(self) -> None:
        """Forget every goal."""
        self.goals.clear()
        self._write()

    def _write(self) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            write_atomically(self.path, json.dumps({"goals": self.goals}))
        except OSError as exc:
            log.warning("cannot write %s: %s", self.path, exc)


class Ros2Driver(Driver):
    """The node's ROS 2 session and endpoints (see the module docstring)."""

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint:
        """The Zenoh router the node connects to first (``params["router"]``, from services.toml's
        ``connect``), which ``petrobot up`` checks before starting the node."""
        address = str(params.get("router", "")).split("/", 1)[-1].split("#", 1)[0]
        host, _, port = address.rpartition(":")
        return DeviceEndpoint("Zenoh router", host.strip("[]") or "127.0.0.1", int(port) if port.isdigit() else 0,
                              "petrobot sim zenoh (or rmw_zenohd on the ROS 2 machine)", "zenoh")

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        super().__init__(name, params)
        self.session: Ros2Session | None = None
        self.endpoints: dict[str, Any] = {}
        self.until: dict[str, UntilWatch] = {}
        self._subscriptions: list[Subscription] = []
        self._bad_events = 0
        self.ledger: GoalLedger | None = None

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
            state_dir = location.nodes[node.name].state_dir
            directory = Path(state_dir) if state_dir else default_state_dir(node.name)
            self.ledger = GoalLedger(directory / "ros2-goals.json")
            await self._cancel_left_over()
        except BaseException:
            await self.teardown()
            raise

    async def _cancel_left_over(self) -> None:
        """Cancel the goals a previous process of this node left running (see the module docstring)."""
        assert self.ledger is not None
        left = self.ledger.left_over()
        clients = {c.name: c for c in self.endpoints.values() if isinstance(c, ActionClient)}
        for goal_hex, action in left.items():
            client = clients.get(action)
            if client is None:
                log.warning("goal %s of %s was left running by the previous node process, and %s is no action of "
                            "this node any more: not cancelled", goal_hex, action, action)
                continue
            try:
                code = await client.cancel(bytes.fromhex(goal_hex), timeout_s=2.0)
                log.warning("goal %s of %s was left running by the previous node process: cancel requested, "
                            "return code %d", goal_hex, action, code)
            except (Ros2Error, ValueError) as exc:
                log.warning("goal %s of %s was left running by the previous node process; cancelling it failed: %s",
                            goal_hex, action, exc)
        self.ledger.clear()

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

    def goal_started(self, goal_id: bytes, client: ActionClient) -> None:
        """Record a goal about to be sent (before ``send_goal``)."""
        if self.ledger is not None:
            self.ledger.add(goal_id.hex(), client.name)

    def goal_ended(self, goal_id: bytes) -> None:
        """Forget a goal whose result is known (or that was never accepted)."""
        if self.ledger is not None:
            self.ledger.remove(goal_id.hex())

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

