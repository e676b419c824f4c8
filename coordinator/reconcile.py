"""Reconciling the calls the runtime gave up on with what their nodes did (docs/protocol.md §5).

When node trouble ends a call — the connection lost, three heartbeats missed, a deadline the node
never answered — the service client turns it into an ``error`` result that no node sent, and the
net goes on along its error branch. The node may still have run the call to its end (an
``unattended`` action, or one that ended just before the link broke), or cancelled it when its
caller was gone (``caller_gone``). A :class:`Reconciler` remembers each such call and, as soon as
its node can be reached again, cancels the call if it still runs (not for an action placed
``unattended``: that one is waited for) and asks the node for its final result (``query``). The
runtime journals the answer (a ``reconciliation`` record) and tells its observers
(:class:`~coordinator.events.CallReconciled`), so that the journal and the nodes never disagree
about what ran.

Which results are given up on (:func:`given_up`): an ``error`` that no node measured (``wall_s``
and ``cpu_s`` both 0; a node times every call it runs) and that is not a node's own word: a
rejection (``unknown_action``, ``local_only``, ``busy``, ``shutdown``, ``duplicate_id``: the call
was not started) or ``node_restarted`` (the call died with its node, which says so for good). A
call that never left the coordinator (:func:`never_sent`: its node could not be reached, or
refused our key, before the call was sent) needs no reconciliation, unless it repeats the id of a
call an earlier coordinator may have sent (a call re-issued on ``--resume``).

The pure part (:func:`given_up`, :func:`never_sent`, :func:`describe`) decides and words; the
:class:`Reconciler` is the asyncio shell that asks the nodes.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from services.errors import LocationError
from services.results import ActionResult, Status

__all__ = ["NODE_WORDS", "GivenUp", "Reconciler", "describe", "differs", "given_up", "never_sent"]

log = logging.getLogger("petrobot.runtime")

NODE_WORDS = frozenset({"unknown_action", "local_only", "busy", "shutdown", "duplicate_id", "node_restarted"})
"""Error reasons that are a node's own final word though it measured no duration: the rejections of
a call it did not start, and ``node_restarted`` (docs/protocol.md §5)."""


def given_up(result: ActionResult) -> bool:
    """True when ``result`` is an error made on the coordinator's side, not by a node: the call's
    fate on its node is unknown (see the module docstring)."""
    return (result.status is Status.ERROR and result.wall_s == 0.0 and result.cpu_s == 0.0
            and (result.reason or "") not in NODE_WORDS)


def never_sent(result: ActionResult, node: str) -> bool:
    """True when the service client could not reach ``node`` (or was refused at login) before
    sending the call: the node never saw it from this coordinator."""
    reason = result.reason or ""
    return reason.startswith((f"node {node} unreachable", "authentication failed"))


def differs(assumed: Status | None, status: Status | None) -> bool:
    """True when a node's final status for a call (``None``: it does not know the call) is not what
    the net went on with (``assumed``; ``None``: the run ended before any result). A call that
    never ran, or ended in error, agrees with an error and with no result at all."""
    if status is None or (assumed is None and status is Status.ERROR):
        return assumed not in (None, Status.ERROR)
    return status != assumed


@dataclass(frozen=True, slots=True)
class GivenUp:
    """A call the runtime gave up on.

    Attributes:
        instance: the instance id, which is the call id on the node.
        task, action, node: the primitive task, its action and the node services.toml places it on.
        assumed: the status the net went on with (``error``), or ``None`` when no result was
            journaled (the run ended before one came).
        lost: why the runtime gave up, in words (the client's reason), or ``""``.
    """

    instance: str
    task: str
    action: str
    node: str
    assumed: Status | None
    lost: str = ""


def describe(node: str | None, action: str, assumed: Status | None, result: ActionResult | None,
             lost: str = "") -> str:
    """One line on what node ``node`` said about a call given up on: the node's final status, and
    whether it is the one the net went on with."""
    where = f"node {node or '?'}"
    if result is None:
        return f"{where} never ran {action} (or no longer keeps its result): nothing ran, as the net assumed"
    what = result.status.value + (f" ({result.outcome})" if result.outcome else "") + (
        f": {result.reason}" if result.reason else "")
    if assumed is None:
        return f"{where} ended {action} with {what} after the run had stopped waiting for it"
    if differs(assumed, result.status):
        why = f" ({lost})" if lost else ""
        return f"{where} finished {action} with {what} after the coordinator declared it lost{why}"
    return f"{where} ended {action} with {what}, as the net assumed"


class Reconciler:
    """Ask nodes, as soon as they can be reached, what became of the calls the runtime gave up on.

    Args:
        client: the service client (its ``query(action, call_id, cancel=...)`` asks the node; its
            ``location`` says whether an action is ``unattended``).
        on_truth: called (on the event loop) with each call and the node's final result, or
            ``None`` when the node does not know the call; it journals and reports.
        max_backoff_s: longest pause between two attempts on an unreachable node, seconds (the
            first retry comes after 0.1 s, doubling; a result from the node cuts a pause short).
    """

    def __init__(self, client: Any, on_truth: Callable[[GivenUp, ActionResult | None], None], *,
                 max_backoff_s: float = 2.0) -> None:
        self.client = client
        self.on_truth = on_truth
        self.max_backoff_s = max_backoff_s
        self._calls: dict[str, GivenUp] = {}
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._wake: dict[str, asyncio.Event] = {}
        #: call id → the last trouble that kept it from being reconciled, in words
        self.trouble: dict[str, str] = {}

    @property
    def enabled(self) -> bool:
        """False for a client that cannot ask nodes (a test double without ``query``)."""
        return callable(getattr(self.client, "query", None))

    @property
    def pending(self) -> list[GivenUp]:
        """The calls not reconciled yet, in the order they were given up on."""
        return list(self._calls.values())

    def add(self, call: GivenUp) -> None:
        """Reconcile ``call`` in the background (a call already pending is not added twice)."""
        if not self.enabled or call.instance in self._calls:
            return
        self._calls[call.instance] = call
        self._tasks[call.instance] = asyncio.get_running_loop().create_task(self._reconcile(call))

    def node_answered(self, node: str) -> None:
        """``node`` just sent a result: it is reachable, so retry its pending calls now."""
        wake = self._wake.get(node)
        if wake is not None:
            wake.set()

    async def settle(self, timeout_s: float) -> list[GivenUp]:
        """Wait up to ``timeout_s`` seconds for the pending calls; return those still pending."""
        tasks = list(self._tasks.values())
        if tasks and timeout_s > 0:
            await asyncio.wait(tasks, timeout=timeout_s)
        return self.pending

    def abandon(self) -> None:
        """Stop asking (the calls still pending stay unreconciled; their tasks are cancelled)."""
        for task in list(self._tasks.values()):
            task.cancel()

    def _unattended(self, action: str) -> bool:
        try:
            return bool(self.client.location.action(action).unattended)
        except (AttributeError, LocationError):
            return False

    async def _reconcile(self, call: GivenUp) -> None:
        cancel = not self._unattended(call.action)
        delay = 0.1
        try:
            while True:
                try:
                    truth: ActionResult | None = await self.client.query(call.action, call.instance, cancel=cancel)
                except LocationError as exc:  # the action is no longer placed: nobody to ask
                    self.trouble[call.instance] = str(exc)
                    return
                if truth is None or not given_up(truth):
                    del self._calls[call.instance]
                    self.trouble.pop(call.instance, None)
                    self.on_truth(call, truth)
                    return
                self.trouble[call.instance] = truth.reason or "error"
                wake = self._wake.setdefault(call.node, asyncio.Event())
                wake.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(wake.wait(), delay)
                delay = min(2 * delay, self.max_backoff_s)
        except asyncio.CancelledError:
            raise
        except Exception:  # a reconciliation must never stop the run
            log.exception("reconciling call %s of %s on %s failed", call.instance, call.action, call.node)
        finally:
            self._tasks.pop(call.instance, None)
