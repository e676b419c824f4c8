"""A service client without sockets, for tests of the runtime (coordinator.runtime.Runtime).

:class:`FakeClient` answers each primitive action with a scripted :class:`ActionResult`, holds
"blocking" actions until the test releases or the runtime cancels them, and lets the test
publish external events to the runtime's subscriptions.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any

from services.errors import LocationError
from services.protocol.messages import Event
from services.results import ActionResult


class FakeLocation:
    """Every action in ``actions`` is placed on node ``fake``."""

    def __init__(self, actions: set[str]) -> None:
        self.actions = actions

    def node_of(self, action: str) -> str:
        if action not in self.actions:
            raise LocationError(f"action {action!r} is not placed in services.toml")
        return "fake"


class FakeClient:
    """A client whose actions answer at once (``results``) or wait for the test (``blocking``).

    Args:
        results: action → its result, or a function of the call's params giving it.
        blocking: actions whose calls wait until :meth:`release` or a cancel.
        topics: external event topics that can be subscribed to (others raise LocationError).
        feedback: feedback data each action sends (in order) before its result.
    """

    def __init__(self, results: dict[str, ActionResult | Callable[[dict[str, Any]], ActionResult]] | None = None,
                 *, blocking: set[str] = frozenset(), topics: set[str] = frozenset(),
                 feedback: dict[str, list[Any]] | None = None) -> None:
        self.results = dict(results or {})
        self.feedback = dict(feedback or {})
        self.blocking = set(blocking)
        self.location = FakeLocation(set(self.results) | self.blocking)
        self.topics = set(topics)
        self.calls: list[tuple[str, str]] = []
        self.cancelled: list[str] = []
        self.subscribers: dict[str, list[Callable[..., None]]] = {}
        self._held: dict[str, asyncio.Future[ActionResult]] = {}
        self.started = asyncio.Event()
        self._seq = 0

    async def call(self, action: str, params: dict[str, Any], *, call_id: str, deadline_s: float | None = None,
                   on_feedback: Callable[[Any], None] | None = None) -> ActionResult:
        self.calls.append((action, call_id))
        if on_feedback is not None and action in self.feedback:
            for data in self.feedback[action]:
                on_feedback(data)
        self.started.set()
        if action in self.blocking:
            future: asyncio.Future[ActionResult] = asyncio.get_running_loop().create_future()
            self._held[call_id] = future
            return await future
        if action not in self.results:
            raise LocationError(f"action {action!r} is not placed in services.toml")
        result = self.results[action]
        return result(params) if callable(result) else result

    def release(self, call_id: str, result: ActionResult) -> None:
        self._held.pop(call_id).set_result(result)

    async def cancel(self, call_id: str) -> bool:
        self.cancelled.append(call_id)
        future = self._held.pop(call_id, None)
        if future is not None and not future.done():
            future.set_result(ActionResult.error("cancelled by the coordinator"))
        return True

    def subscribe(self, topic: str, callback: Callable[..., None]) -> None:
        if topic not in self.topics:
            raise LocationError(f"no node publishes event {topic!r}")
        self.subscribers.setdefault(topic, []).append(callback)

    def publish(self, topic: str, data: Any = None) -> None:
        """Deliver an event of ``topic`` as a node link does: the protocol's ``Event``, ``data`` its payload."""
        self._seq += 1
        for callback in self.subscribers.get(topic, []):
            callback(Event(topic=topic, t=time.time(), seq=self._seq, data=data))
