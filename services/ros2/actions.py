"""The primitive action that is a ROS 2 action, service, publication or wait (docs/ros2.md).

services.toml gives an action a ``ros2`` table and no ``impl``; the node then hosts a
:class:`Ros2Primitive`, which takes the call's parameters (services.toml's ``params`` under the
call's) as the goal, request or message, checks them against the type before anything is sent
(a missing or mistyped field is an ``error`` naming it), and maps what the ROS 2 side does onto the
call's lifecycle:

* **action** — the goal is sent under a UUID made from the call id (:func:`goal_uuid`: a call
  re-issued after the node restarted finds its goal on the server rather than starting another);
  each feedback message of that goal is sent to
  the caller as the call's feedback; the result and the goal status give the call's status
  (:mod:`services.ros2.outcome`). A cancel (petrobot ``abort``), the deadline or the caller's loss
  sends ``cancel_goal`` and waits up to ``cancel_wait_s`` for the server's final result, which the
  call then returns (an ``error`` whose reason is ``cancelled``, ``deadline`` or ``caller_gone``,
  with the ROS status in its value). The server leaving the ROS 2 graph during the goal, or the
  session losing it, ends the call at once with ``error``.
* **service** — the request is sent; the response's fields are the call's value; ``success``, if
  given, decides success or failure. A service cannot be cancelled on the ROS 2 side: a cancel only
  stops waiting.
* **publish** — the message is published once, or every ``1/rate_hz`` s while the call runs; the
  call succeeds after one message, after ``duration_s``, or when ``until`` holds.
* **wait** — the call succeeds when a message of the ``until`` topic meets its condition.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from typing import Any

from services.action import CallContext, NodeContext, PrimitiveAction
from services.errors import ActionError
from services.results import ActionResult
from services.ros2.config import ActionKind, Ros2ActionSpec
from services.ros2.driver import Ros2Driver, UntilWatch
from services.ros2.endpoints import REJECTED, ActionClient, CallFailed, Publication, ServiceClient
from services.ros2.errors import Ros2FieldError
from services.ros2.outcome import GoalStatus, action_result, rejected_result, service_result

__all__ = ["GOAL_NAMESPACE", "Ros2Primitive", "goal_uuid"]

log = logging.getLogger("petrobot.ros2")


GOAL_NAMESPACE = uuid.UUID("6c1b3f64-77a5-5d7e-9a61-1d0f5e2c9b40")
"""The namespace of the goal ids petrobot makes (RFC 4122 name-based, SHA-1)."""


def goal_uuid(node: str, action: str, call_id: str) -> bytes:
    """The goal id of call ``call_id`` of ``action`` on ``node``: the same call always sends the same
    goal id, so that a call re-issued after the node restarted (``petrobot run --resume``) meets the
    goal it sent before instead of starting a second one."""
    return uuid.uuid5(GOAL_NAMESPACE, f"{node}/{action}/{call_id}").bytes


def _cancel_reason(exc: asyncio.CancelledError, ctx: CallContext) -> str:
    """Why the node cut the call off: its reason (``cancelled``, ``caller_gone``, ``node shutdown``),
    or ``deadline`` when it was the deadline's timeout (which gives none)."""
    if exc.args and isinstance(exc.args[0], str):
        return exc.args[0]
    remaining = ctx.remaining()
    if remaining is not None and remaining <= 0.001:
        return "deadline"
    return "cancelled"


class Ros2Primitive(PrimitiveAction):
    """A primitive action whose work is done on the ROS 2 side (see the module docstring)."""

    def __init__(self) -> None:
        self.spec: Ros2ActionSpec | None = None
        self.driver: Ros2Driver | None = None

    async def setup(self, node: NodeContext) -> None:
        """Find this action's ``ros2`` table and the node's ROS 2 driver.

        Raises:
            ActionError: the action has no ``ros2`` table, or the node no ROS 2 driver.
        """
        spec = node.location.action(self.name).ros2
        if spec is None:
            raise ActionError(f"action {self.name}: {type(self).__name__} needs a ros2 table in services.toml")
        driver = next((d for d in node.drivers.values() if isinstance(d, Ros2Driver)), None)
        if driver is None:
            raise ActionError(f"action {self.name}: node {node.name} has no ROS 2 driver")
        self.spec = spec
        self.driver = driver

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        """Carry out one call (see the module docstring)."""
        assert self.spec is not None and self.driver is not None
        kind = self.spec.kind
        if kind == ActionKind.ACTION:
            return await self._goal(self.driver.endpoint(self.name), params, ctx)
        if kind == ActionKind.SERVICE:
            return await self._service(self.driver.endpoint(self.name), params, ctx)
        return await self._publish(self.driver.endpoints.get(self.name), self.driver.until.get(self.name), params, ctx)

    async def _goal(self, client: ActionClient, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        spec = self.spec
        assert spec is not None
        goal_id = goal_uuid(ctx.node.name, self.name, ctx.call_id)
        hex_id = goal_id.hex()
        seen: list[int] = []
        try:
            client.check_goal(params, fill=spec.fill)
        except Ros2FieldError as exc:
            return ActionResult.error(f"goal {exc} (type {client.types.goal}); nothing was sent")
        driver = self.driver
        assert driver is not None
        driver.goal_started(goal_id, client)
        try:
            status, result = await client.run(
                goal_id, params, fill=spec.fill, on_feedback=ctx.feedback, on_status=seen.append,
                on_accepted=lambda: log.info("call %s: goal %s accepted by %s", ctx.call_id, hex_id, client.name))
        except CallFailed as exc:
            last = GoalStatus(seen[-1]).name if seen and seen[-1] in tuple(GoalStatus) else None
            return ActionResult.error(str(exc), value={"status": last, "goal_id": hex_id, "result": None})
        except asyncio.CancelledError as exc:
            return await self._cancelled(client, goal_id, _cancel_reason(exc, ctx))
        finally:
            driver.goal_ended(goal_id)
        if status == REJECTED:
            return rejected_result(hex_id, spec.rejected)
        return action_result(status, result, goal_id=hex_id, success=spec.success, aborted=spec.aborted)

    async def _cancelled(self, client: ActionClient, goal_id: bytes, reason: str) -> ActionResult:
        """Cancel the goal on the server, wait (bounded) for its final result and return it."""
        spec = self.spec
        assert spec is not None
        hex_id = goal_id.hex()
        loop = asyncio.get_running_loop()
        end = loop.time() + spec.cancel_wait_s
        try:
            code = await client.cancel(goal_id, timeout_s=spec.cancel_wait_s)
            log.info("goal %s of %s: cancel requested (%s), return code %d", hex_id, client.name, reason, code)
            status, result = await client.result_of(goal_id, timeout_s=max(0.05, end - loop.time()))
        except CallFailed as exc:
            return ActionResult.error(reason, value={"status": None, "goal_id": hex_id, "result": None,
                                                     "cancel": f"not confirmed: {exc}"})
        if status == GoalStatus.CANCELED:
            return action_result(status, result, goal_id=hex_id, cancel_reason=reason)
        out = action_result(status, result, goal_id=hex_id, success=spec.success, aborted=spec.aborted)
        log.info("goal %s of %s ended %s although cancelled (%s)", hex_id, client.name,
                 GoalStatus(status).name if status in tuple(GoalStatus) else status, reason)
        return out

    async def _service(self, client: ServiceClient, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        spec = self.spec
        assert spec is not None
        try:
            payload = client.encode(params, fill=spec.fill)
        except Ros2FieldError as exc:
            return ActionResult.error(f"request {exc} (type {client.types.request}); nothing was sent")
        try:
            response = client.decode(await client.call_raw(payload, timeout_s=ctx.remaining()))
        except CallFailed as exc:
            return ActionResult.error(str(exc))
        return service_result(response, spec.success)

    async def _publish(self, publication: Publication | None, until: UntilWatch | None, params: dict[str, Any],
                       ctx: CallContext) -> ActionResult:
        spec = self.spec
        assert spec is not None
        if until is not None:
            until.reset()
        sent = 0
        loop = asyncio.get_running_loop()
        start = loop.time()
        try:
            if publication is not None:
                publication.publish(params, fill=spec.fill)
                sent = 1
            if publication is not None and spec.rate_hz is not None:
                period = 1.0 / spec.rate_hz
                while until is None or not until.met.is_set():
                    if spec.duration_s is not None and loop.time() - start >= spec.duration_s:
                        break
                    if until is not None:
                        try:
                            async with asyncio.timeout(period):
                                await until.met.wait()
                            break
                        except TimeoutError:
                            pass
                    else:
                        await asyncio.sleep(period)
                    publication.publish(params, fill=spec.fill)
                    sent += 1
            elif until is not None:
                await until.met.wait()
        except Ros2FieldError as exc:
            return ActionResult.error(f"message {exc}; nothing was sent")
        value: dict[str, Any] = {"published": sent}
        if until is not None:
            value["until"] = until.message
        return ActionResult.success(value)
