"""ROS 2 endpoints over a :class:`~services.ros2.session.Ros2Session` (asyncio shells).

* :class:`ServiceClient` — a service call is a Zenoh query (target ALL_COMPLETE, no
  consolidation) carrying the CDR request and, in the rmw_zenoh dialect, the attachment (sequence
  number, time, client GID); the reply with the same sequence number and GID is the response. No
  reply at all means no server; a server whose token leaves the graph during the call ends it at once.
* :class:`Subscription` — a Zenoh subscriber on the topic's key (an advanced subscriber asking for
  history when the QoS is transient local); messages are decoded on the event loop.
* :class:`Publication` — a Zenoh publisher (with a cache of ``depth`` samples when transient local),
  each message with its attachment.
* :class:`ActionClient` — an action as rcl_action composes it: ``send_goal``, then ``get_result``
  (which the server answers when the goal ends), feedback and status on their topics, ``cancel_goal``
  on request.

Each declares its liveliness token (SC, MS, MP) so that the ROS 2 tools on the other side see it.
Failures the ROS 2 side causes (no server, server gone, an error reply, a malformed reply) raise
:class:`CallFailed` with a reason fit for a primitive action's ``error`` result.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, TypeVar

from services.ros2.errors import Ros2Error, Ros2WireError
from services.ros2.graph import Attachment, Dialect, EntityKind
from services.ros2.names import action_names, action_type_names
from services.ros2.qos import DEFAULT_QOS, SERVICES_QOS, STATUS_QOS, Durability, Qos, Reliability, encode_qos
from services.ros2.session import Ros2Session, import_zenoh

__all__ = ["LONG_WAIT_S", "REJECTED", "ActionClient", "CallFailed", "Publication", "ServiceClient", "Subscription"]

log = logging.getLogger("petrobot.ros2")

_T = TypeVar("_T")

LONG_WAIT_S = 7 * 24 * 3600.0
"""The Zenoh timeout of a query with no deadline (a week: a goal may take long)."""
REJECTED = -1
"""The status :meth:`ActionClient.run` returns for a goal the server refused."""
LINK_SETTLE_S = 0.3
"""After a query ended with no reply, how long to look for the session losing its link, seconds."""
MAX_STATUS_GOALS = 10_000
"""Goals of one status message kept (a server lists its recent goals; a hostile one cannot flood)."""


class CallFailed(Ros2Error):
    """A ROS 2 call did not come back with a response (the message says why)."""


class _ServerWatch:
    """Sets :attr:`gone` when every server of a service that was in the graph has left it."""

    def __init__(self, session: Ros2Session, name: str, *, action: bool = False) -> None:
        self._session = session
        self._name = name
        self._action = action
        self.present = bool(session.servers(name, action=action))
        self.gone = asyncio.Event()
        self._stop = session.watch(self._check)

    def _check(self) -> None:
        if self._session.servers(self._name, action=self._action):
            self.present = True
        elif self.present:
            self.gone.set()

    def close(self) -> None:
        self._stop()


async def _unless_gone(work: Awaitable[_T], watch: _ServerWatch, what: str) -> _T:
    """Await ``work`` unless the watched server leaves the graph first (then :class:`CallFailed`)."""
    task = asyncio.ensure_future(work)
    gone = asyncio.ensure_future(watch.gone.wait())
    try:
        await asyncio.wait({task, gone}, return_when=asyncio.FIRST_COMPLETED)
    except BaseException:
        task.cancel()
        gone.cancel()
        raise
    if task.done():
        gone.cancel()
        return task.result()
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError, Exception):
        await task
    raise CallFailed(f"{what}: the server left the ROS 2 graph (its liveliness token was withdrawn: the "
                     f"process ended or its Zenoh session was lost)")


class ServiceClient:
    """A client of one ROS 2 service.

    Args:
        session: the node's session.
        name: the service (absolute, or relative to the session's namespace).
        service_type: ``pkg/srv/Name`` (or an action's ``pkg/action/Name_SendGoal``...).
        qos: the QoS its token announces.

    Raises:
        Ros2TypeError: the service type is not defined.
    """

    def __init__(self, session: Ros2Session, name: str, service_type: str, qos: Qos = SERVICES_QOS) -> None:
        self.session = session
        self.name = session.qualify(name)
        self.types = session.store.service(service_type)
        self.key = session.key(self.name, service_type)
        self.entity = session.entity(EntityKind.CLIENT, self.name, service_type, encode_qos(qos))
        self.gid = self.entity.gid
        self._seq = 0
        session.announce(self.entity)

    def encode(self, request: Mapping[str, Any], *, fill: bool = False, what: str = "request") -> bytes:
        """The CDR bytes of ``request``, checked against the request type.

        Raises:
            Ros2FieldError: a field is missing, unknown or of the wrong type (named).
        """
        return self.session.store.encode(self.types.request, request, fill=fill, what=what)

    def decode(self, payload: bytes) -> dict[str, Any]:
        """The fields of a response.

        Raises:
            CallFailed: the payload is not a valid response.
        """
        try:
            return self.session.store.decode(self.types.response, payload)
        except Ros2WireError as exc:
            raise CallFailed(f"{self.name}: malformed response: {exc}") from None

    async def call_raw(self, payload: bytes, *, timeout_s: float | None = None, watch: bool = True,
                       action: bool = False, served: bool = False) -> bytes:
        """Send one request and return the response's CDR bytes.

        Args:
            payload: the CDR request.
            timeout_s: give up after this long (``None``: :data:`LONG_WAIT_S`).
            watch: end the call as soon as the server's token leaves the graph.
            action: the service is part of an action (the bridge announces the action instead).
            served: the server answered an earlier part of this exchange (an action's goal it
                accepted): a query no one answers means it went away, even when its token had
                already left the graph before this request was sent.

        Raises:
            CallFailed: no server answered, the server left, it replied with an error, the
                reply's attachment does not match, or the time ran out.
        """
        zenoh = import_zenoh()
        session = self.session
        loop = asyncio.get_running_loop()
        self._seq += 1
        seq = self._seq
        rmw = session.dialect is Dialect.RMW_ZENOH
        attachment = Attachment(seq, time.time_ns(), self.gid).encode() if rmw else None
        done: asyncio.Future[bytes] = loop.create_future()
        errors: list[str] = []
        limit = timeout_s or LONG_WAIT_S
        started = loop.time()
        explaining: list[asyncio.Task[None]] = []

        def deliver(ok: bytes | None, att: bytes | None, err: str | None) -> None:
            if done.done():
                return
            if err is not None:
                errors.append(err)
                return
            if rmw:
                try:
                    echoed = Attachment.decode(att or b"")
                except Ros2WireError as exc:
                    errors.append(f"reply without a valid attachment ({exc})")
                    return
                if echoed.sequence_number != seq or echoed.gid != self.gid:
                    errors.append(f"only a reply for another request (sequence number {echoed.sequence_number}, "
                                  f"ours {seq})")
                    return
            done.set_result(ok or b"")

        def finished() -> None:
            if done.done():
                return
            if loop.time() - started >= limit * 0.99:
                done.set_exception(CallFailed(f"{self.name}: no answer within {limit:g} s"))
            elif errors:
                done.set_exception(CallFailed(f"{self.name}: {'; '.join(errors)}"))
            else:
                explaining.append(loop.create_task(explain()))

        async def explain() -> None:
            """The query ended with no reply: say why. A lost router ends the query a moment before
            the session notices it has lost its link: look for that a short while first."""
            end = loop.time() + LINK_SETTLE_S
            while session.connected() and loop.time() < end:
                await asyncio.sleep(0.02)
            if not session.connected():
                why = "the Zenoh session reaches no router or peer (the router is down or the network cut)"
            elif served or (server is not None and server.present):
                why = "the server went away before answering (its process ended or its Zenoh session was lost)"
            else:
                why = "no service server answered (none in the ROS 2 graph, or its type hash differs)"
            if not done.done():
                done.set_exception(CallFailed(f"{self.name}: {why}"))

        # Replies and the end of the query come from Zenoh's threads, not necessarily the same one:
        # they are queued under a lock and handed to the loop in one drain, so that the end of the
        # query is never seen before a reply that came first.
        arrived: list[tuple[bytes | None, bytes | None, str | None]] = []
        ended = [False]
        lock = threading.Lock()

        def drain() -> None:
            with lock:
                batch = arrived[:]
                arrived.clear()
                over = ended[0]
            for item in batch:
                deliver(*item)
            if over:
                finished()

        def on_reply(reply: Any) -> None:  # Zenoh thread
            ok = reply.ok
            if ok is not None:
                att = ok.attachment
                item = (ok.payload.to_bytes(), att.to_bytes() if att is not None else None, None)
            else:
                item = (None, None, f"error reply: {_text(reply.err.payload.to_bytes())}")
            with lock:
                arrived.append(item)
            session.soon(drain)

        def on_end() -> None:  # Zenoh thread, after the last reply's callback returned
            with lock:
                ended[0] = True
            session.soon(drain)

        cancel = zenoh.CancellationToken()
        server = _ServerWatch(session, self.name, action=action) if watch else None
        try:
            session.zenoh.get(
                self.key, zenoh.handlers.Callback(on_reply, on_end, indirect=False),
                payload=payload, attachment=attachment, target=zenoh.QueryTarget.ALL_COMPLETE,
                consolidation=zenoh.ConsolidationMode.NONE, timeout=limit,
                cancellation_token=cancel,
            )
            if server is None:
                return await done
            return await _unless_gone(done, server, self.name)
        finally:
            if server is not None:
                server.close()
            if not done.done():
                cancel.cancel()
            for task in explaining:
                task.cancel()

    async def call(self, request: Mapping[str, Any], *, timeout_s: float | None = None, fill: bool = False,
                   action: bool = False, served: bool = False) -> dict[str, Any]:
        """Call the service with ``request`` (checked first) and return the response's fields.

        Raises:
            Ros2FieldError: ``request`` does not fit the request type (nothing was sent).
            CallFailed: as :meth:`call_raw`, or a malformed response.
        """
        payload = self.encode(request, fill=fill)
        return self.decode(await self.call_raw(payload, timeout_s=timeout_s, action=action, served=served))

    def close(self) -> None:
        """Withdraw the client's token."""
        self.session.withdraw(self.entity)


class Subscription:
    """A subscription to one topic; ``on_message(fields)`` runs on the event loop for each message.

    Args:
        session: the node's session.
        topic: the topic (absolute, or relative to the namespace).
        msg_type: its message type.
        on_message: called with each message's fields (malformed messages are logged and skipped).
        qos: reliability is the publisher's business; transient local asks for the publishers' cached
            samples (history of ``depth``).
    """

    def __init__(self, session: Ros2Session, topic: str, msg_type: str, on_message: Callable[[dict[str, Any]], None],
                 qos: Qos = DEFAULT_QOS) -> None:
        zenoh = import_zenoh()
        self.session = session
        self.topic = session.qualify(topic)
        self.msg_type = msg_type
        self.key = session.key(self.topic, msg_type)
        self._on_message = on_message
        self._bad = 0
        self.entity = session.entity(EntityKind.SUBSCRIPTION, self.topic, msg_type, encode_qos(qos))
        handler = zenoh.handlers.Callback(self._sample, indirect=False)
        if qos.durability is Durability.TRANSIENT_LOCAL:
            import zenoh.ext

            self._sub = zenoh.ext.declare_advanced_subscriber(
                session.zenoh, self.key, handler,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=qos.depth))
        else:
            self._sub = session.zenoh.declare_subscriber(self.key, handler)
        session.announce(self.entity)

    def _sample(self, sample: Any) -> None:  # Zenoh thread
        self.session.soon(self._deliver, sample.payload.to_bytes())

    def _deliver(self, payload: bytes) -> None:
        try:
            fields = self.session.store.decode(self.msg_type, payload)
        except Ros2WireError as exc:
            self._bad += 1
            if self._bad <= 5:
                log.warning("topic %s: skipping a malformed message: %s", self.topic, exc)
            return
        self._on_message(fields)

    def close(self) -> None:
        """Stop receiving and withdraw the token."""
        self.session.withdraw(self.entity)
        with contextlib.suppress(Exception):
            self._sub.undeclare()


class Publication:
    """A publisher on one topic.

    Args:
        session: the node's session.
        topic: the topic.
        msg_type: its message type.
        qos: best effort drops under congestion; transient local keeps the last ``depth`` messages
            for late subscribers.
    """

    def __init__(self, session: Ros2Session, topic: str, msg_type: str, qos: Qos = DEFAULT_QOS) -> None:
        zenoh = import_zenoh()
        self.session = session
        self.topic = session.qualify(topic)
        self.msg_type = msg_type
        self.key = session.key(self.topic, msg_type)
        self.entity = session.entity(EntityKind.PUBLISHER, self.topic, msg_type, encode_qos(qos))
        self.gid = self.entity.gid
        self._seq = 0
        congestion = (zenoh.CongestionControl.DROP if qos.reliability is Reliability.BEST_EFFORT
                      else zenoh.CongestionControl.BLOCK)
        if qos.durability is Durability.TRANSIENT_LOCAL:
            import zenoh.ext

            self._pub = zenoh.ext.declare_advanced_publisher(
                session.zenoh, self.key, congestion_control=congestion,
                cache=zenoh.ext.CacheConfig(max_samples=qos.depth), publisher_detection=True)
        else:
            self._pub = session.zenoh.declare_publisher(self.key, congestion_control=congestion)
        session.announce(self.entity)

    def publish(self, message: Mapping[str, Any], *, fill: bool = False) -> None:
        """Publish one message (checked against the type first).

        Raises:
            Ros2FieldError: a field is missing, unknown or of the wrong type (nothing is sent).
        """
        payload = self.session.store.encode(self.msg_type, message, fill=fill, what="message")
        self._seq += 1
        attachment = (Attachment(self._seq, time.time_ns(), self.gid).encode()
                      if self.session.dialect is Dialect.RMW_ZENOH else None)
        self._pub.put(payload, attachment=attachment)

    def close(self) -> None:
        """Stop publishing and withdraw the token."""
        self.session.withdraw(self.entity)
        with contextlib.suppress(Exception):
            self._pub.undeclare()


def _text(data: bytes) -> str:
    text = data.decode("utf-8", "replace").strip()
    return text if len(text) <= 200 else text[:197] + "..."


class ActionClient:
    """A client of one ROS 2 action (rcl_action's composition; see the module docstring).

    Args:
        session: the node's session.
        name: the action (absolute, or relative to the namespace).
        action_type: ``pkg/action/Name``.
        feedback_qos: the QoS of the feedback subscription.

    Raises:
        Ros2TypeError: the action type is not defined.
    """

    def __init__(self, session: Ros2Session, name: str, action_type: str, feedback_qos: Qos = DEFAULT_QOS) -> None:
        self.session = session
        self.name = session.qualify(name)
        self.names = action_names(self.name)
        self.types = action_type_names(action_type)
        self.send_goal = ServiceClient(session, self.names.send_goal, self.types.send_goal)
        self.cancel_goal = ServiceClient(session, self.names.cancel_goal, self.types.cancel_goal)
        self.get_result = ServiceClient(session, self.names.get_result, self.types.get_result)
        self._feedback_to: dict[bytes, Callable[[dict[str, Any]], None]] = {}
        self._status_to: dict[bytes, Callable[[int], None]] = {}
        self.known: dict[bytes, int] = {}
        """The goals the server's status topic lists, with their status (its latest message)."""
        self.feedback = Subscription(session, self.names.feedback, self.types.feedback_message, self._on_feedback,
                                     feedback_qos)
        self.status = Subscription(session, self.names.status, self.types.status, self._on_status, STATUS_QOS)

    def _on_feedback(self, fields: dict[str, Any]) -> None:
        route = self._feedback_to.get(bytes(fields["goal_id"]["uuid"]))
        if route is not None:
            route(fields["feedback"])

    def _on_status(self, fields: dict[str, Any]) -> None:
        known = {}
        for entry in fields["status_list"][:MAX_STATUS_GOALS]:
            goal_id = bytes(entry["goal_info"]["goal_id"]["uuid"])
            known[goal_id] = int(entry["status"])
            route = self._status_to.get(goal_id)
            if route is not None:
                route(int(entry["status"]))
        self.known = known

    def check_goal(self, goal: Mapping[str, Any], *, fill: bool = False) -> None:
        """Check ``goal`` against the goal type.

        Raises:
            Ros2FieldError: naming the field.
        """
        self.session.store.check(self.types.goal, goal, fill=fill, what="goal")

    async def run(self, goal_id: bytes, goal: Mapping[str, Any], *, fill: bool = False,
                  on_feedback: Callable[[dict[str, Any]], None] | None = None,
                  on_accepted: Callable[[], None] | None = None,
                  on_status: Callable[[int], None] | None = None) -> tuple[int, dict[str, Any]]:
        """Send goal ``goal`` under ``goal_id`` and wait for its end.

        Args:
            goal_id: the goal's 16-byte UUID.
            goal: the goal's fields.
            fill: missing goal fields take their defaults.
            on_feedback: called with each feedback message's fields for this goal.
            on_accepted: called once the server accepted the goal.
            on_status: called with each status the status topic reports for this goal.

        Returns:
            ``(status, result fields)``; status :data:`REJECTED` (-1) with no result when the server
            refused the goal. A goal the server refuses because it already has it (its status topic
            lists ``goal_id``: the same call sent before this node restarted) is waited for instead.

        Raises:
            Ros2FieldError: ``goal`` does not fit the goal type (nothing was sent).
            CallFailed: no server, the server left, or a malformed reply.
        """
        request = self.send_goal.encode({"goal_id": {"uuid": goal_id}, "goal": goal}, fill=fill, what="goal")
        if on_feedback is not None:
            self._feedback_to[goal_id] = on_feedback
        if on_status is not None:
            self._status_to[goal_id] = on_status
        try:
            reply = self.send_goal.decode(await self.send_goal.call_raw(request, action=True))
            if not reply["accepted"]:
                if goal_id not in self.known:
                    return REJECTED, {}
                # the server already has this goal: sent under the same id before this node restarted
                log.info("goal %s of %s was sent before (the server lists it): waiting for its result", goal_id.hex(),
                         self.name)
            if on_accepted is not None:
                on_accepted()
            # the server accepted the goal: if it is gone by the time this query goes out, say so
            result = await self.get_result.call({"goal_id": {"uuid": goal_id}}, action=True, served=True)
            return int(result["status"]), result["result"]
        finally:
            self._feedback_to.pop(goal_id, None)
            self._status_to.pop(goal_id, None)

    async def cancel(self, goal_id: bytes, *, timeout_s: float) -> int:
        """Ask the server to cancel goal ``goal_id``; its ``return_code`` (0: accepted).

        Raises:
            CallFailed: no answer within ``timeout_s``.
        """
        reply = await self.cancel_goal.call({"goal_info": {"goal_id": {"uuid": goal_id},
                                                           "stamp": {"sec": 0, "nanosec": 0}}},
                                            timeout_s=timeout_s, action=True)
        return int(reply["return_code"])

    async def result_of(self, goal_id: bytes, *, timeout_s: float) -> tuple[int, dict[str, Any]]:
        """Ask again for the result of goal ``goal_id`` (after a cancel), within ``timeout_s``.

        Raises:
            CallFailed: no answer in time.
        """
        result = await self.get_result.call({"goal_id": {"uuid": goal_id}}, timeout_s=timeout_s, action=True)
        return int(result["status"]), result["result"]

    def close(self) -> None:
        """Withdraw every token, stop the subscriptions."""
        for part in (self.send_goal, self.cancel_goal, self.get_result, self.feedback, self.status):
            part.close()

