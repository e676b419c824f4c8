"""Motion node of the catching testbed (paper section 6, Fig. 1): ``move_home`` and ``catch``,
over the PUMA's driver (:class:`services.catching.arm.PumaDriver`).

services.toml (example)::

    [drivers.puma]
    node = "motion"
    impl = "services.catching.arm:PumaDriver"
    params = { can_host = "127.0.0.1", can_port = 7211 }

    [actions.move_home]
    node = "motion"
    impl = "services.catching.motion_node:MoveHome"

    [actions.catch]
    node = "motion"
    impl = "services.catching.motion_node:Catch"

    [events.ball_caught]
    node = "motion"

Watchdog (node side): when set points stop coming during ``catch`` (none for
``setpoint_max_age_s``, on the wall clock and on the bus clock the frames are stamped with, before
the ball is due at the line: the vision node died, the link is cut, the publisher stopped), the servo brakes every joint to rest at its acceleration limit (a
controlled stop, :meth:`services.catching.robot.motion_control.CatchServo.stop`) and ``catch`` returns
``error`` with outcome ``stream_lost``, the reason, and the stop in its value (``watchdog``). The
drives have their own watchdog for a silent master (:mod:`sim.drives`).

Outcomes of ``catch``: success when the crossfire sensor fires; failure when the ball is missed
(the bus clock passed the predicted rim time by ``miss_grace_s`` without a catch), including a
ball predicted too late for the arm to get there; error on a timeout, a lost set-point stream, or
a lost bus. ``move_home``: success at the home pose, error on timeout or a lost bus.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from services.action import CallContext, PrimitiveAction
from services.catching.arm import PumaDriver, table_to_base
from services.catching.robot import motion_control as mc
from services.catching.robot.puma560 import UnreachableError
from services.catching.setpoints import CatchSetPoint, SetPointSubscription, StreamLostError
from services.devices.drives import BusError
from services.results import ActionResult, Status

__all__ = ["Catch", "MoveHome"]

log = logging.getLogger(__name__)

_WALL_BACKSTOP = 3.0
"""Catch timeouts are in bus time; wall time this many times longer ends the wait anyway."""


def _driver(ctx: CallContext) -> PumaDriver:
    drv = ctx.find_driver(PumaDriver)
    if drv is not None:
        return drv
    raise BusError("no PumaDriver on this node (services.toml [drivers.*])")


class MoveHome(PrimitiveAction):
    """Return the cup to the home pose (middle of the catch line).

    A motion: cancelled (by its caller, or at once when the caller is gone), it brakes the arm to
    rest (:meth:`PumaDriver.stop_motion`) before it ends.
    Before moving, faulted drives are reset and enabled again (:meth:`PumaDriver.ensure_ready`).
    Params: ``timeout_s`` (5.0, bus time, with three times as much wall time as a backstop),
    ``tolerance_rad`` (0.01, on the actual joint positions).
    Value: ``{"q": [6 joint angles, rad], "recovered": what was recovered or None}``.
    """

    motion = True

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        drv = _driver(ctx)
        try:
            return await self._home(params, drv)
        except asyncio.CancelledError:
            drv.stop_motion()
            raise

    @staticmethod
    async def _home(params: dict[str, Any], drv: PumaDriver) -> ActionResult:
        t0 = time.monotonic()
        timeout = float(params.get("timeout_s", 5.0))
        tol = float(params.get("tolerance_rad", 0.01))
        try:
            recovered = await drv.ensure_ready()
            home = mc.home_pose(drv.geometry)
            with drv.lock:
                assert drv.servo is not None
                drv.servo.set_goal(home)
            t_bus0 = drv.bus_time()
            wall_deadline = time.monotonic() + _WALL_BACKSTOP * timeout
            while True:
                drv.check()
                assert drv.drives is not None
                actual = drv.drives.positions()
                with drv.lock:
                    done = drv.servo.at_goal() and bool(np.all(np.abs(actual - home) <= tol))
                if done:
                    return ActionResult.success({"q": [float(v) for v in actual], "recovered": recovered},
                                                cost=time.monotonic() - t0)
                if drv.bus_time() - t_bus0 > timeout or time.monotonic() > wall_deadline:
                    return ActionResult.error(f"not home after {timeout} s", outcome="timeout",
                                              value={"recovered": recovered}, cost=time.monotonic() - t0)
                await asyncio.sleep(0.01)
        except BusError as exc:
            return ActionResult.error(str(exc), outcome="bus", cost=time.monotonic() - t0)


class Catch(PrimitiveAction):
    """Servo the cup to the latest set point until the crossfire sensor fires.

    Params: ``timeout_s`` (5.0; whole call), ``miss_grace_s`` (0.3; after the predicted rim time),
    ``first_setpoint_s`` (= ``timeout_s``; wait for the first set point), ``stream_end_s`` (0.15),
    ``stop_timeout_s`` (2.0; the watchdog's wait for the arm to be at rest). The timeouts are
    seconds of bus time (the simulated time the set points and the ball live in, which a loaded
    machine slows down), with three times as much wall time as a backstop.

    A motion: cancelled (by its caller, its deadline, or at once when the caller is gone: a
    coordinator killed mid-catch), it brakes the arm to rest before it ends, as the watchdog does.

    The set points may stop once the bus time is within ``stream_end_s`` of the predicted
    crossing: the predictor stops when the ball reaches the line, and the cup stays at the last
    set point. Set points that stop earlier (none for ``setpoint_max_age_s``) trigger the
    watchdog: a controlled stop, then error ``stream_lost``. A set point that fails validation is
    dropped and counted (``malformed``), never used, and does not end the catch.

    Value: ``{"caught", "set_points", "unreachable", "malformed", "y_pred", "t_pred",
    "t_caught", "reach_s", "lead_s", "watchdog"}`` (table frame, bus time; ``reach_s`` is the
    servo's lower bound on the time to the goal when the last set point was aimed, ``lead_s`` the
    time left until the rim then; ``watchdog`` is ``{"stale_s", "stale_bus_s", "stop_s", "t"}`` when
it acted: the set points' age on the wall and bus clocks, how long the controlled stop took and
when it started, bus time).
    Cost: wall seconds.
    """

    motion = True

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        drv = _driver(ctx)
        try:
            return await self._catch(params, drv)
        except asyncio.CancelledError:
            drv.stop_motion()
            raise

    async def _catch(self, params: dict[str, Any], drv: PumaDriver) -> ActionResult:
        t0 = time.monotonic()
        timeout = float(params.get("timeout_s", 5.0))
        grace = float(params.get("miss_grace_s", 0.3))
        first_wait = float(params.get("first_setpoint_s", timeout))
        stream_end = float(params.get("stream_end_s", 0.15))
        stop_timeout = float(params.get("stop_timeout_s", 2.0))
        info: dict[str, Any] = {
            "caught": False,
            "set_points": 0,
            "unreachable": 0,
            "malformed": 0,
            "y_pred": None,
            "t_pred": None,
            "t_caught": None,
            "reach_s": None,
            "lead_s": None,
            "watchdog": None,
        }
        sub: SetPointSubscription | None = None

        def done(status: Status, outcome: str | None = None, reason: str | None = None) -> ActionResult:
            if sub is not None:
                info["malformed"] = sub.state.malformed
            return ActionResult(status=status, outcome=outcome, value=info, cost=time.monotonic() - t0,
                                reason=reason)

        try:
            await drv.ensure_ready()
            sub = drv.subscription()
            sub.restart()
            drv.arm_catch()
            t_bus0 = drv.bus_time()
            sp = await self._first_set_point(sub, drv, min(first_wait, timeout))
            used: CatchSetPoint | None = None
            t_rim: float | None = None
            wall_deadline = t0 + _WALL_BACKSTOP * timeout
            while True:
                drv.check()
                if drv.caught:
                    info["caught"] = True
                    info["t_caught"] = drv.caught_t
                    return done(Status.SUCCESS, "caught")
                if sp is not used:  # a new set point (latest wins)
                    used = sp
                    info["set_points"] += 1
                    aimed = self._aim(drv, sp, info)
                    if aimed is not None:
                        t_rim = aimed
                now_bus = drv.bus_time()
                if t_rim is not None and now_bus > t_rim + grace:
                    late = info["reach_s"] is not None and info["lead_s"] is not None and info["reach_s"] > info["lead_s"]
                    why = " (predicted too late for the arm to get there)" if late else ""
                    return done(Status.FAILURE, "missed", f"ball passed at t={t_rim:.3f} s without a catch{why}")
                if now_bus - t_bus0 > timeout or time.monotonic() > wall_deadline:
                    return done(Status.ERROR, "timeout",
                                f"no catch and no miss within {timeout} s (bus time {now_bus - t_bus0:.2f} s, "
                                f"wall {time.monotonic() - t0:.2f} s)")
                try:
                    sp = sub.latest(camera_now=now_bus)
                except StreamLostError as exc:
                    t_pred = info["t_pred"]
                    if t_pred is not None and now_bus >= t_pred - stream_end:
                        # The ball is at the line: the vision side has stopped tracking. Keep
                        # the last set point and wait for the crossfire sensor or the miss.
                        await asyncio.sleep(0.002)
                        continue
                    return await self._watchdog_stop(drv, sub, exc, stop_timeout, info, done)
                await asyncio.sleep(0.002)
        except StreamLostError as exc:
            return done(Status.ERROR, "stream_lost", str(exc))
        except BusError as exc:
            return done(Status.ERROR, "bus", str(exc))

    @staticmethod
    async def _watchdog_stop(drv: PumaDriver, sub: SetPointSubscription, exc: StreamLostError,
                             stop_timeout: float, info: dict[str, Any],
                             done: Callable[..., ActionResult]) -> ActionResult:
        """Set points stopped mid-catch: controlled stop, then ``error`` ``stream_lost``."""
        t_trigger = drv.bus_time()
        stale = sub.state.age(sub.clock())
        last = sub.state.latest
        drv.stop_motion()
        t_rest = await drv.wait_stopped(stop_timeout)
        info["watchdog"] = {"stale_s": stale, "stale_bus_s": t_trigger - last.t_frame if last else None,
                            "stop_s": t_rest - t_trigger, "t": t_trigger}
        return done(Status.ERROR, "stream_lost",
                    f"{exc}; watchdog stopped the arm in {t_rest - t_trigger:.3f} s (bus time)")

    @staticmethod
    async def _first_set_point(sub: SetPointSubscription, drv: PumaDriver, timeout: float) -> CatchSetPoint:
        """The first set point received after :meth:`SetPointSubscription.restart`.

        Raises:
            StreamLostError: none within ``timeout`` s of bus time (or three times that of wall time).
            BusError: the bus is lost meanwhile.
        """
        t_bus0 = drv.bus_time()
        end = time.monotonic() + _WALL_BACKSTOP * timeout
        while drv.bus_time() - t_bus0 <= timeout and time.monotonic() < end:
            sp = sub.state.latest
            if sp is not None:
                log.info("catch: first set point after %.3f s of waiting (bus time); ball at the line at t=%.3f s",
                         drv.bus_time() - t_bus0, sp.t)
                return sp
            drv.check()
            await asyncio.sleep(0.002)
        where = "" if sub.link.connected else f" (link to node {sub.node} is down)"
        raise StreamLostError(f"no set point within {timeout} s{where}")

    @staticmethod
    def _aim(drv: PumaDriver, sp: CatchSetPoint, info: dict[str, Any]) -> float | None:
        xb, yb, vxb, vyb = table_to_base(sp.x, sp.y, sp.vx, sp.vy, drv.robot_base)  # type: ignore[arg-type]
        try:
            with drv.lock:
                assert drv.servo is not None
                target = drv.servo.aim(xb, yb, sp.t, vxb, vyb)
                reach = drv.servo.time_to_goal()
        except UnreachableError:
            info["unreachable"] += 1
            return None
        info["y_pred"] = sp.y
        info["t_pred"] = sp.t
        info["reach_s"] = reach
        info["lead_s"] = target.t_rim - drv.bus_time()
        return target.t_rim
