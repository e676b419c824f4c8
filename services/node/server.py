"""The node's asyncio shell: the :class:`Node` server and its actions' lifecycle.

A node hosts the primitive actions services.toml places on it (docs/protocol.md, "Calls"). This
module does the I/O only; the decisions are made by the sans-IO cores beside it:

* :class:`services.node.calls.CallTable` admits or rejects each call, joins repeats, answers
  queries, tracks orphaned calls and keeps results (bounded by bytes and by age; in an SQLite file
  that survives restarts when the node runs from the command line, :mod:`services.node.store`);
* :class:`services.node.fanout.Fanout` numbers published events and fans them out, holding a
  bounded backlog for a subscriber whose writes are paused;
* :class:`services.node.guard.ConnectionGuard` and :class:`~services.node.guard.AuthThrottle`
  decide which connections may stay (caps, handshake deadline, failed logins);
* :class:`services.protocol.Connection` parses and encodes the frames of each connection
  (:class:`services.node.peer.Peer` is one connection, which reaches the node only through the
  :class:`services.node.peer.PeerHost` methods the node implements; :class:`services.node.listener.Listener`
  accepts them).

What the shell adds:

* each admitted call runs as its own task; the deadline (``deadline_ms``) cuts it off with status
  ``error`` and reason ``"deadline"``; a ``cancel`` cuts it off with reason ``"cancelled"``; a call
  nobody has waited for during ``peer_timeout_s`` with ``"caller_gone"`` (unless its action is
  unattended) — a call of a ``motion`` action as soon as nobody waits for it, its caller's
  connection closed or silent for ``motion_silence_s`` (three heartbeat periods); stopping the node
  with ``"node shutdown"``;
* with a durable store, a call's start is committed before its action runs (at the end of the read
  that brought the call: its task starts on the next loop iteration) and its result before it is
  sent (at once when no other call runs, else once per loop iteration for all the calls that
  finished in it);
* a peer is local when its address is one of this host's own addresses
  (:mod:`services.node.locality`);
* an action that raises gives status ``error`` with the exception text; the node keeps running;
  a result that cannot be encoded (not msgpack-able, over the frame cap) becomes an ``error``
  result saying so;
* a peer silent for ``peer_timeout_s`` (default 2 s; clients ping every 0.25 s) is dropped; a
  connection that has not finished its handshake ``caps.handshake_timeout_s`` after it was
  accepted is dropped, however many bytes it trickles in; kept results past their age are dropped
  by the same periodic task;
* a bad frame closes that one connection with ``bye``; the node goes on.

Logs (stderr): one INFO line per authenticated connection, call and result; text from peers is
escaped and shortened (:func:`services.protocol.shown`) and lines a peer can provoke at will
(refused logins, bad frames, rejected calls, dropped handshakes) are rate-limited per address
(:class:`services.node.logs.LogLimiter`).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import os
import resource
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import replace
from typing import Any

from services.action import (
    CallContext,
    Driver,
    FunctionAction,
    MemoryAPI,
    NodeContext,
    PrimitiveAction,
    import_impl,
    make_action,
)
from services.actions.memory import MemoryStore, NoMemory, RemoteMemory, memory_actions
from services.client import NodeLink
from services.errors import PetrobotError, ProtocolError
from services.keys import check_key
from services.location import MEMORY_ACTIONS, Location
from services.node.calls import (
    DEFAULT_MAX_AGE_S,
    DEFAULT_MAX_BYTES,
    Answer,
    CallTable,
    Join,
    KeptResult,
    MemoryResultCache,
    Reject,
    ResultCache,
    RunningCall,
    Start,
)
from services.node.fanout import (
    DEFAULT_BACKLOG,
    DEFAULT_MAX_TOPIC_BYTES,
    DEFAULT_MAX_TOPICS,
    Fanout,
)
from services.node.guard import (
    DEFAULT_CAPS,
    AuthThrottle,
    Caps,
    ConnectionGuard,
    budget_caps,
)
from services.node.listener import Listener
from services.node.locality import Locality
from services.node.logs import LogLimiter
from services.node.peer import Peer, PeerHost
from services.node.watch import LocationWatch, digest_of
from services.protocol import (
    DEFAULT_MAX_FRAME,
    Accepted,
    Call,
    Connection,
    Event,
    Feedback,
    Offer,
    Query,
    Rejected,
    Result,
    Role,
    encode_frame,
    shown,
)
from services.results import ActionResult, Status
from services.wire import server_context

__all__ = ["DEFAULT_MAX_OUTPUT", "MOTION_SILENCE_S", "Node"]

log = logging.getLogger("petrobot.node")

ActionRun = Callable[[dict[str, Any], CallContext], Awaitable[Any]]

DEFAULT_MAX_OUTPUT = 1024 * 1024
"""Bytes that may wait to go out to one peer before the node stops reading from it."""
MOTION_SILENCE_S = 0.75
"""Silence after which a peer waiting for a motion call counts as lost, seconds."""
_MOTION_CHECK_S = 0.05
"""How often the reaper looks at the peers of motion calls while any runs, seconds."""


class Node(PeerHost):
    """A node process's server (see the module docstring); the host of its connections
    (:class:`~services.node.peer.PeerHost`).

    Args:
        name: node name in services.toml.
        location: the parsed services.toml.
        key: shared key (at least 16 bytes).
        previous_keys: older keys still accepted while a new one is rolled out.
        peer_timeout_s: drop a peer silent for this long, seconds; also the grace period of an
            orphaned call before it is cancelled.
        result_bytes: cap on the bytes of kept results (frames plus bookkeeping), bytes.
        result_ttl_s: how long a result is kept, seconds.
        results: where results are kept; a :class:`~services.node.calls.MemoryResultCache` with
            ``result_bytes`` and ``result_ttl_s`` if ``None`` (else the two are ignored). A store
            other than the in-memory one is flushed before each action starts and each result is
            sent, and closed when the node stops.
        event_backlog: events held for a subscriber whose writes are paused (older ones dropped).
        max_topics: topics one connection may subscribe to.
        max_topic_bytes: longest topic name a connection may subscribe to, bytes of UTF-8.
        max_frame: frame size cap once authenticated, bytes.
        caps: connection caps (fitted under the file-descriptor limit at start).
        max_output: bytes waiting to go out to one peer before the node stops reading from it.
        location_digest: hex SHA-256 of the services.toml bytes ``location`` was parsed from
            (default: the digest of the file at ``location.path`` now, if it exists).
        locality: decides which peers are on this host (default: :class:`Locality`).
        motion_silence_s: a peer waiting for a call of a ``motion`` action is dropped when silent
            this long, seconds (three of a client's 0.25 s heartbeats; the protocol has it send a
            frame every 0.5 s at least); its motion calls are then cancelled at once.

    Raises:
        LocationError: ``name`` is not a node of ``location``.
        SharedKeyError: a key is shorter than 16 bytes.
    """

    def __init__(
        self,
        name: str,
        location: Location,
        key: bytes,
        *,
        previous_keys: Sequence[bytes] = (),
        peer_timeout_s: float = 2.0,
        result_bytes: int = DEFAULT_MAX_BYTES,
        result_ttl_s: float = DEFAULT_MAX_AGE_S,
        results: ResultCache | None = None,
        event_backlog: int = DEFAULT_BACKLOG,
        max_topics: int = DEFAULT_MAX_TOPICS,
        max_topic_bytes: int = DEFAULT_MAX_TOPIC_BYTES,
        max_frame: int = DEFAULT_MAX_FRAME,
        caps: Caps = DEFAULT_CAPS,
        max_output: int = DEFAULT_MAX_OUTPUT,
        location_digest: str | None = None,
        locality: Locality | None = None,
        motion_silence_s: float = MOTION_SILENCE_S,
    ) -> None:
        self.name = name
        self.motion_silence_s = motion_silence_s
        self.location = location
        location.address(name)  # raises LocationError naming the file if the node is unknown
        self.spec = location.nodes[name]
        self.host, self.port = self.spec.host, self.spec.port
        self.max_in_flight = self.spec.max_in_flight
        self.peer_timeout_s = peer_timeout_s
        self.max_frame = max_frame
        self.max_output = max_output
        self._key = check_key(key)
        self._previous_keys = tuple(check_key(k, "a previous key") for k in previous_keys)
        self.tls_binding = self.spec.tls.mode == "psk"
        self._loop: asyncio.AbstractEventLoop = None  # type: ignore[assignment]
        self._listener: Listener | None = None
        self._peers: set[Peer] = set()
        self._actions: dict[str, PrimitiveAction] = {}
        self._placements = {a.name: a for a in location.actions_on(name)}
        self._drivers: dict[str, Driver] = {}
        if results is None:
            results = MemoryResultCache(max_bytes=result_bytes, max_age_s=result_ttl_s)
        self._durable = not isinstance(results, MemoryResultCache)
        self._calls: CallTable[Peer] = CallTable(
            self._placements, local_only=[a for a, p in self._placements.items() if p.local_only],
            unattended=[a for a, p in self._placements.items() if p.unattended],
            motion=[a for a, p in self._placements.items() if p.motion],
            max_in_flight=self.max_in_flight, cache=results,
        )
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._unsent: list[tuple[RunningCall[Peer], bytes]] = []  # results waiting for the next commit
        self._commit_scheduled = False
        self._fanout: Fanout[Peer] = Fanout(backlog=event_backlog, max_topics=max_topics,
                                            max_topic_bytes=max_topic_bytes)
        self._guard: ConnectionGuard[Peer] = ConnectionGuard(caps)
        self._throttle = AuthThrottle()
        self._limited = LogLimiter(log)
        self._locality = locality if locality is not None else Locality()
        if location_digest is None and os.path.isfile(location.path):
            with open(location.path, "rb") as fh:
                location_digest = digest_of(fh.read())
        self.watch = LocationWatch(location.path, location_digest)
        self._links: dict[str, NodeLink] = {}
        self._reaper: asyncio.Task[None] | None = None
        self._checkpointing: asyncio.Task[None] | None = None  # the store's checkpoint, in a thread
        self._stopping = False
        self.context: NodeContext | None = None

    @property
    def caps(self) -> Caps:
        """The connection caps in force (after :meth:`start`, fitted under the descriptor limit)."""
        return self._guard.caps

    @property
    def results(self) -> ResultCache:
        """Where results are kept."""
        return self._calls.cache

    # ---- lifecycle

    async def start(self) -> None:
        """Set up drivers and actions, then listen (``port`` is updated if it was 0).

        Raises:
            ActionError: an impl cannot be imported or built.
            OSError: the address is in use, or a TLS file cannot be read.
        """
        self._loop = asyncio.get_running_loop()
        memory: MemoryAPI
        store: MemoryStore | None = None
        if self.location.memory_node == self.name:
            store = MemoryStore()
            memory = store
        elif self.location.memory_node is not None:
            memory = RemoteMemory(self.link(self.location.memory_node))
        else:
            memory = NoMemory()
        self.context = NodeContext(
            name=self.name, location=self.location, drivers=self._drivers,
            memory=memory, publish=self.publish, link=self.link,
        )
        for dspec in self.location.drivers_on(self.name):
            cls = import_impl(dspec.impl)
            if not (isinstance(cls, type) and issubclass(cls, Driver)):
                raise PetrobotError(f"driver {dspec.name}: {dspec.impl} is not a Driver subclass")
            drv = cls(dspec.name, dspec.params)
            drv.bind(self.context)
            await drv.setup(self.context)
            self._drivers[dspec.name] = drv
        for aname in self._placements:
            if aname in MEMORY_ACTIONS:
                assert store is not None
                self._actions[aname] = memory_actions(store)[aname]
            else:
                self._actions[aname] = make_action(self._placements[aname].impl, aname)
        self._calls.unattended |= {a for a, action in self._actions.items() if action.unattended}
        self._calls.motion |= {a for a, action in self._actions.items() if action.motion}
        for action in self._actions.values():
            await action.setup(self.context)
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        self._guard.caps = budget_caps(self._guard.caps, soft, _open_fds())
        self._listener = Listener(
            self._loop, self.host, self.port, self._new_peer, self._guard,
            self._throttle, self._limited, server_context(self.spec.tls),
        )
        self.port = self._listener.port
        self._reaper = self._loop.create_task(self._reap())
        caps = self._guard.caps
        log.info("node %s hosts actions: %s; drivers: %s; caps: %d open (%d per address), %d in handshake "
                 "(%d per address)%s", self.name, ", ".join(sorted(self._actions)) or "none",
                 ", ".join(sorted(self._drivers)) or "none", caps.max_open, caps.max_open_per_host,
                 caps.max_pending, caps.max_pending_per_host,
                 f"; TLS {self.spec.tls.mode}" if self.spec.tls.mode != "off" else "")

    async def stop(self) -> None:
        """Stop: refuse new connections, cancel running calls, say bye, tear down actions and drivers."""
        if self._stopping:
            return
        self._stopping = True
        self._calls.stop()
        if self._listener is not None:
            self._listener.close()
        if self._reaper is not None:
            self._reaper.cancel()
        tasks = list(self._tasks.values())
        for t in tasks:
            t.cancel("node shutdown")
        if tasks:
            await asyncio.wait(tasks, timeout=2.0)
        if self._durable:
            self.commit()  # the results of the calls just cancelled, before the peers go
        for peer in list(self._peers):
            peer.close("shutdown")
        for link in self._links.values():
            await link.close()
        for action in self._actions.values():
            try:
                await action.teardown()
            except Exception:
                log.exception("teardown of action %s failed", action.name)
        for drv in self._drivers.values():
            try:
                await drv.teardown()
            except Exception:
                log.exception("teardown of driver %s failed", drv.name)
        if self._checkpointing is not None:
            await asyncio.wait([self._checkpointing])  # its thread uses the store's file
        close = getattr(self._calls.cache, "close", None)
        if close is not None:
            try:
                close()
            except Exception:
                log.exception("closing the result store failed")
        log.info("node %s stopped", self.name)

    # ---- node services for actions and drivers

    def publish(self, topic: str, data: Any = None) -> None:
        """Publish external event ``topic`` to every subscriber (never waits for a slow one)."""
        delivery = self._fanout.publish(topic, data, time.time())
        if delivery is None:
            return
        ev, ready = delivery
        for peer in ready:
            if not peer.open:
                continue
            try:
                peer.send(ev)
            except ProtocolError as exc:
                self._limited.log(logging.WARNING, ("event", topic), "cannot send event %s to %r: %s",
                                  shown(topic), peer, exc)

    def link(self, node: str) -> NodeLink:
        """Shared link from this node to ``node``."""
        link = self._links.get(node)
        if link is None:
            link = NodeLink(node, self.location.address(node), self._key, name=f"node:{self.name}",
                            tls=self.location.nodes[node].tls)
            self._links[node] = link
        return link

    # ---- connections (the PeerHost interface)

    def _new_peer(self, host: str, accepted_at: float) -> Peer:
        conn = Connection(Role.SERVER, self._key, name=self.name, max_frame=self.max_frame,
                          previous_keys=self._previous_keys, offer=self._offer)
        return Peer(self, conn, self._loop, host, accepted_at, self._limited, tls_binding=self.tls_binding)

    def _offer(self) -> Offer:
        return Offer(actions=self._calls.actions, location=self.watch.digest,
                     location_changed=self.watch.changed())

    def peer_connected(self, peer: Peer) -> None:
        """A connection's transport is up (:class:`~services.node.peer.PeerHost`)."""
        self._peers.add(peer)

    def peer_authenticated(self, peer: Peer) -> None:
        """A connection's handshake succeeded: keep it, unless over the caps."""
        if not self._guard.authenticate(peer):
            self._limited.log(logging.WARNING, ("open cap", peer.peer_host),
                              "refused %r: too many connections (%d open)", peer, self._guard.open)
            peer.conn.data_to_send()  # the welcome the connection queued is not sent: only the bye
            peer.close("overloaded")
            return
        peer.authenticated = True
        transport = peer.transport
        here = transport.get_extra_info("sockname") if transport is not None else None
        peer.local = self._locality.is_local(peer.peer_host, here[0] if here else "")
        if peer.conn.key_index:
            self._limited.log(logging.WARNING, "previous key", "%r authenticated with a previous key: "
                              "finish the key rotation", peer)
        log.info("connection from %r authenticated", peer)

    def login_failed(self, peer: Peer, exc: Exception) -> None:
        """A connection's handshake failed: count it against its address."""
        self._throttle.failed(peer.peer_host, self._loop.time())
        self._limited.log(logging.WARNING, ("auth", peer.peer_host), "refused %s: %s", peer.peer_host, exc)

    def peer_gone(self, peer: Peer) -> None:
        """``peer`` closed or went away: forget it (once), and orphan the calls it alone waited for."""
        if peer.forgotten:
            return
        peer.forgotten = True
        self._guard.close(peer)
        self._peers.discard(peer)
        self._fanout.remove(peer)
        if not peer.authenticated:
            return
        now = self._loop.time()
        for rec in self._calls.detach(peer, now):
            log.info("call %s %s lost its last caller: %s", shown(rec.call.id, 64), shown(rec.call.action, 64),
                     "it may finish unattended" if rec.unattended
                     else "a motion: cancelled now, the robot brought to rest" if rec.motion
                     else f"cancelled in {self.peer_timeout_s:g} s unless it is asked for again")
        self._cancel_orphans(now)

    def subscribe(self, peer: Peer, topic: str) -> None:
        """Send ``peer`` the events of ``topic``, unless over its subscription caps (logged)."""
        refusal = self._fanout.subscribe(peer, topic)
        if refusal is not None:
            self._limited.log(logging.WARNING, ("subscription refused", peer.peer_host),
                              "subscription of %r to %s refused: %s", peer, shown(topic, 64), refusal.value)

    def unsubscribe(self, peer: Peer, topic: str) -> None:
        """Stop sending ``peer`` the events of ``topic``."""
        self._fanout.unsubscribe(peer, topic)

    def writing_paused(self, peer: Peer) -> None:
        """Hold ``peer``'s events back (in the fan-out's bounded backlog)."""
        self._fanout.pause(peer)

    def writing_resumed(self, peer: Peer) -> list[Event]:
        """The events held back for ``peer``."""
        return self._fanout.resume(peer)

    def read_done(self) -> None:
        """A read from a peer is handled: with a durable store, commit the calls it started."""
        if self._durable:
            self.commit()

    # ---- calls

    def admit_call(self, peer: Peer, call: Call) -> None:
        """Admit, join, answer or reject ``call`` from ``peer`` (:class:`~services.node.calls.CallTable`)."""
        cid = call.id
        verdict = self._calls.admit(call, peer, local=peer.local, now=time.time())
        if type(verdict) is Start:
            action = self._actions[call.action]
            run = action.fn if type(action) is FunctionAction else action.run
            defaults = self._placements[call.action].params
            task = self._loop.create_task(self._run(verdict.running, run, defaults, peer))
            task.add_done_callback(functools.partial(self._cancelled_unstarted, verdict.running, time.perf_counter()))
            self._tasks[cid] = task
            peer.send(Accepted(id=cid))
        elif type(verdict) is Reject:
            reason = verdict.reason.value
            self._limited.log(logging.INFO, ("rejected", peer.peer_host), "call %s (%s) from %r rejected: %s",
                              shown(cid, 64), shown(call.action, 64), peer, reason)
            peer.send(Rejected(id=cid, reason=reason))
        elif type(verdict) is Answer:
            peer.send(Accepted(id=cid))
            self._send_kept(peer, verdict.kept)
            log.info("call %s (%s) from %r: repeated, answered with the first result", shown(cid, 64),
                     shown(call.action, 64), peer)
        else:  # Join: the peer now waits for the running call's result too
            peer.send(Accepted(id=cid))
            log.info("call %s (%s) from %r: repeated while running, joined", shown(cid, 64),
                     shown(call.action, 64), peer)

    def answer_query(self, peer: Peer, query: Query) -> None:
        """Answer ``query`` from ``peer``: the call's result, a join, or a rejection."""
        cid = query.id
        verdict = self._calls.query(cid, peer)
        if type(verdict) is Answer:
            peer.send(Accepted(id=cid))
            self._send_kept(peer, verdict.kept)
            log.info("query %s from %r: answered with its result", shown(cid, 64), peer)
        elif type(verdict) is Join:
            peer.send(Accepted(id=cid))
            log.info("query %s from %r: still running, joined", shown(cid, 64), peer)
        else:
            assert type(verdict) is Reject
            peer.send(Rejected(id=cid, reason=verdict.reason.value))
            self._limited.log(logging.INFO, ("query", peer.peer_host), "query %s from %r: %s", shown(cid, 64),
                              peer, verdict.reason.value)

    @staticmethod
    def _send_kept(peer: Peer, kept: KeptResult) -> None:
        """Send a kept result: its frame as first sent, when the cache gives it."""
        if kept.frame is not None:
            peer.send_frame(kept.frame)
        else:
            peer.send(kept.result)

    def cancel_call(self, cid: str, reason: str = "cancelled") -> None:
        """Cancel call ``cid`` with ``reason`` if it runs."""
        task = self._tasks.get(cid)
        if task is not None and not task.done() and self._calls.cancel(cid, reason) is not None:
            task.cancel(reason)
            log.info("call %s: %s", shown(cid, 64), "cancel requested" if reason == "cancelled" else reason)

    def commit(self) -> None:
        """Make every start and result so far durable, then send the results that waited for it.

        Called at the end of each read from a peer (the calls it started begin on the next loop
        iteration, after this), and once per loop iteration in which calls finished.
        """
        self._commit_scheduled = False
        try:
            self._calls.cache.flush()
        except Exception as exc:  # noqa: BLE001 - a failing disk must not stop the calls
            self._limited.log(logging.ERROR, "store", "cannot write the result store: %s", exc)
        unsent, self._unsent = self._unsent, []
        for rec, frame in unsent:
            for peer in rec.waiters:
                if peer.open:
                    peer.send_frame(frame)

    async def _run(self, rec: RunningCall[Peer], run: ActionRun, defaults: Any, peer: Peer) -> None:
        call = rec.call
        loop = self._loop
        info = log.isEnabledFor(logging.INFO)
        if info:
            log.info("call %s %s from %r", shown(call.id, 64), shown(call.action, 64), peer)
        params = {**defaults, **call.params} if defaults else call.params
        deadline = None if call.deadline_ms is None else loop.time() + call.deadline_ms / 1000.0
        assert self.context is not None
        ctx = CallContext(
            call_id=call.id, action=call.action, deadline=deadline, peer=peer.conn.peer or "?",
            node=self.context, feedback=lambda data: self._feedback(rec, data),
        )
        ctx._task = self._tasks.get(call.id)
        t0 = time.perf_counter()
        c0 = time.process_time()
        try:
            if deadline is None:
                out = await run(params, ctx)
            else:
                cm = asyncio.timeout_at(deadline)
                try:
                    async with cm:
                        out = await run(params, ctx)
                except TimeoutError:
                    if not cm.expired():
                        raise
                    out = ActionResult.error("deadline")
            record = out if isinstance(out, ActionResult) else ActionResult.success(out)
        except asyncio.CancelledError:
            record = ActionResult.error(rec.cancel_reason or "node shutdown")
        except Exception as exc:  # noqa: BLE001 - any action failure becomes an error result
            record = ActionResult.error(f"{exc.__class__.__name__}: {exc}")
            log.warning("call %s %s raised %s", shown(call.id, 64), call.action, shown(record.reason, 200))
        record = replace(record, wall_s=time.perf_counter() - t0, cpu_s=max(0.0, time.process_time() - c0))
        self._finish(rec, Result(id=call.id, result=record), info)

    def _cancelled_unstarted(self, rec: RunningCall[Peer], admitted: float, task: asyncio.Task[None]) -> None:
        """End the call of a task cancelled before its first step, whose :meth:`_run` never ran: a
        cancel read with its call (one write), or the node stopping. Without this the call stayed
        running for ever, its slot of ``max_in_flight`` taken and a repeat of its id joined to a
        result that never came (a coordinator interrupted by Ctrl-C right after a call, resumed,
        waited for it until the call's deadline). Its ``wall_s`` is the time since it was admitted
        (``admitted``, ``time.perf_counter()`` seconds): a node times every call it ends, and a
        coordinator tells the node's word from its own by that (``coordinator.reconcile.given_up``)."""
        cid = rec.call.id
        if task.cancelled() and self._tasks.get(cid) is task:  # _run ends every call it starts
            error = replace(ActionResult.error(rec.cancel_reason or "node shutdown"),
                            wall_s=time.perf_counter() - admitted)
            self._finish(rec, Result(id=cid, result=error), log.isEnabledFor(logging.INFO))

    def _finish(self, rec: RunningCall[Peer], result: Result, info: bool) -> None:
        """Keep ``result`` (charged its frame length) and send it to every waiter still connected,
        after the next commit if results are durable."""
        cid = result.id
        self._tasks.pop(cid, None)
        try:
            frame = encode_frame(result, self.max_frame)
        except ProtocolError as exc:  # value not msgpack-able, too big...
            result = _unsendable(result, exc)
            frame = encode_frame(result, self.max_frame)
        durable = self._durable
        self._calls.finish(result, size=len(frame), now=time.time(), frame=frame)
        if durable:
            self._unsent.append((rec, frame))
            if not self._tasks:  # no other call runs: nothing to wait for to share the commit
                self.commit()
            elif not self._commit_scheduled:
                self._commit_scheduled = True
                self._loop.call_soon(self.commit)
        else:
            for peer in rec.waiters:
                if peer.open:
                    peer.send_frame(frame)
        if info:
            r = result.result
            log.info("result %s %s: %s%s (%.3f s)", shown(cid, 64), shown(rec.call.action, 64), r.status.value,
                     f" ({shown(r.reason, 200)})" if r.reason else "", r.wall_s)

    def _feedback(self, rec: RunningCall[Peer], data: Any) -> None:
        msg = Feedback(id=rec.call.id, data=data)
        for peer in rec.waiters:
            if not peer.open:
                continue
            if peer.reading:
                peer.send(msg)
            else:
                peer.dropped_feedback += 1

    # ---- periodic work

    async def _reap(self) -> None:
        """Every ``peer_timeout_s / 4`` (at most 0.5 s): drop silent peers and overdue handshakes,
        cancel orphaned calls past their grace period, expire kept results. While a motion call
        runs, every 50 ms: drop its callers once silent for ``motion_silence_s`` (their motion calls
        are then cancelled at once)."""
        period = min(0.5, self.peer_timeout_s / 4)
        checkpoint: Callable[[], None] | None = getattr(self._calls.cache, "checkpoint", None)
        loop = self._loop
        slow_due = loop.time() + period
        while True:
            before = loop.time()
            watched = self._calls.motion_waiters()
            await asyncio.sleep(min(_MOTION_CHECK_S, period) if watched else max(0.0, slow_due - before))
            now = loop.time()
            blocked = now - before > 2 * (min(_MOTION_CHECK_S, period) if watched else period)
            if watched and not blocked:  # our own loop was blocked: peers' frames may be waiting unread
                cutoff = now - self.motion_silence_s
                for peer in watched:
                    if peer.last_rx < cutoff and not peer.closed:
                        log.info("dropping %r: silent for %.2f s while a motion call waits for it", peer,
                                 now - peer.last_rx)
                        peer.close("heartbeat_timeout")
            if now < slow_due:
                continue
            slow_due = now + period
            self._limited.flush()
            try:
                self._calls.expire(time.time())
            except Exception as exc:  # noqa: BLE001 - keep reaping whatever the store does
                self._limited.log(logging.ERROR, "store", "cannot expire results: %s", exc)
            previous = self._checkpointing
            if checkpoint is not None and (previous is None or previous.done()):
                if previous is not None and not previous.cancelled() and previous.exception():
                    self._limited.log(logging.ERROR, "store", "checkpoint failed: %s", previous.exception())
                self._checkpointing = loop.create_task(asyncio.to_thread(checkpoint))
            if blocked:
                continue  # our loop was blocked: peers' frames may be waiting unread
            for peer in list(self._guard.overdue(now)):
                self._limited.log(logging.INFO, ("handshake timeout", peer.peer_host),
                                  "dropping %s: no handshake within %g s", peer.peer_host,
                                  self._guard.caps.handshake_timeout_s)
                peer.evict("handshake_timeout")
            cutoff = now - self.peer_timeout_s
            for peer in list(self._peers):
                if peer.authenticated and peer.last_rx < cutoff and not peer.closed:
                    log.info("dropping %r: silent for %.1f s", peer, self.peer_timeout_s)
                    peer.close("heartbeat_timeout")
            self._cancel_orphans(now)

    def _cancel_orphans(self, now: float) -> None:
        """Cancel the orphaned calls that are due (:meth:`CallTable.orphans`)."""
        for rec in self._calls.orphans(now, self.peer_timeout_s):
            task = self._tasks.get(rec.call.id)
            if task is not None and not task.done():
                log.info("call %s %s: nobody waits for it%s: cancelling it (%s)", shown(rec.call.id, 64),
                         shown(rec.call.action, 64), "" if rec.motion else f" since {self.peer_timeout_s:g} s",
                         rec.cancel_reason)
                task.cancel(rec.cancel_reason)


def _open_fds() -> int:
    try:
        return len(os.listdir("/proc/self/fd"))
    except OSError:
        return 16


def _unsendable(result: Result, exc: Exception) -> Result:
    """The error result that replaces ``result`` when it cannot be encoded."""
    return Result(id=result.id, result=replace(result.result, status=Status.ERROR, outcome=None, value=None,
                                               reason=f"result not sendable: {shown(str(exc), 200)}"))
