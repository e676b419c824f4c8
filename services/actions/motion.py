"""Motion node of the catching testbed (paper section 6, Fig. 1): the PUMA driver, ``move_home``
and ``catch``.

services.toml (example)::

    [drivers.puma]
    node = "motion"
    impl = "services.actions.motion:PumaDriver"
    params = { can_host = "127.0.0.1", can_port = 29536, setpoint_port = 7150 }

    [actions.move_home]
    node = "motion"
    impl = "services.actions.motion:MoveHome"

    [actions.catch]
    node = "motion"
    impl = "services.actions.motion:Catch"

    [events.ball_caught]
    node = "motion"

:class:`PumaDriver` params (all optional except the CAN address):

* ``can_host``, ``can_port``, ``channel`` ("can0"): the sim's socketcand gateway;
* ``setpoint_host`` ("127.0.0.1"), ``setpoint_port`` (0 = any): where the set-point stream from
  the vision node is received (:class:`services.stream.SetPointReceiver`);
* ``setpoint_max_age_s`` (0.2): a set point older than this means a lost stream;
* ``robot_base`` ([0.75, 0.0, 0.46, pi]): x, y, z (m), yaw (rad) of the robot base frame in the
  table frame of the set points;
* ``edge_x``, ``table_z``, ``rim_drop``, ``tilt_deg``, ``y_min``, ``y_max``: override
  :class:`services.robots.motion_control.CatchGeometry` (base frame);
* ``heartbeat_timeout_s`` (0.5), ``connect_timeout_s`` (5.0).

The driver owns a control thread that runs once per CAN SYNC (2 ms of simulated time): one
:meth:`services.robots.motion_control.CatchServo.step` and one set of RPDO targets. The crossfire sensor's
rising edge publishes the external event ``ball_caught`` with ``{"t": bus time}``.

Outcomes of ``catch``: success when the crossfire sensor fires; failure when the ball is missed
(the bus clock passed the predicted rim time by ``miss_grace_s`` without a catch); error on a
timeout, a lost set-point stream, or a lost bus. ``move_home``: success at the home pose, error on
timeout or a lost bus.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from typing import Any

import numpy as np

from services.robots import motion_control as mc
from services.action import (
    CallContext,
    Driver,
    NodeContext,
    PrimitiveAction,
)
from services.results import ActionResult, Status
from services.devices.drives import BusError, PumaDrives
from services.stream import SetPoint, SetPointReceiver, StreamLostError
from services.robots.puma560 import UnreachableError

__all__ = ["Catch", "MoveHome", "PumaDriver", "table_to_base"]

log = logging.getLogger(__name__)

DEFAULT_ROBOT_BASE = (0.75, 0.0, 0.46, math.pi)
MAX_CYCLES_PER_SYNC = 10
"""At most this many 2 ms servo steps per received SYNC (a late thread catches up, bounded)."""


def table_to_base(
    x: float, y: float, vx: float, vy: float, robot_base: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    """Planar point and velocity from the table frame to the robot base frame.

    Args:
        x, y: point in the table frame, m.
        vx, vy: velocity in the table frame, m/s.
        robot_base: (x, y, z, yaw) of the base frame in the table frame (m, rad).

    Returns:
        ``(x_b, y_b, vx_b, vy_b)`` in the base frame.
    """
    bx, by, _, yaw = robot_base
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = x - bx, y - by
    return c * dx + s * dy, -s * dx + c * dy, c * vx + s * vy, -s * vx + c * vy


class PumaDriver(Driver):
    """The PUMA on its CAN bus, the servo's control thread and the set-point receiver."""

    def __init__(self, name: str, params: dict[str, Any]) -> None:
        super().__init__(name, params)
        p = self.params
        self.can_host = str(p.get("can_host", "127.0.0.1"))
        self.can_port = int(p.get("can_port", 7211))
        self.channel = str(p.get("channel", "can0"))
        self.robot_base = tuple(float(v) for v in p.get("robot_base", DEFAULT_ROBOT_BASE))
        if len(self.robot_base) != 4:
            raise ValueError("robot_base needs x, y, z, yaw")
        g = mc.CatchGeometry()
        self.geometry = mc.CatchGeometry(
            edge_x=float(p.get("edge_x", g.edge_x)),
            table_z=float(p.get("table_z", g.table_z)),
            rim_drop=float(p.get("rim_drop", g.rim_drop)),
            tilt=math.radians(float(p.get("tilt_deg", math.degrees(g.tilt)))),
            y_min=float(p.get("y_min", g.y_min)),
            y_max=float(p.get("y_max", g.y_max)),
        )
        self.heartbeat_timeout = float(p.get("heartbeat_timeout_s", 0.5))
        self.connect_timeout = float(p.get("connect_timeout_s", 5.0))
        self.receiver = SetPointReceiver(
            str(p.get("setpoint_host", "127.0.0.1")),
            int(p.get("setpoint_port", 0)),
            max_age=float(p.get("setpoint_max_age_s", 0.2)),
        )
        self.drives: PumaDrives | None = None
        self.servo: mc.CatchServo | None = None
        self.lock = threading.Lock()
        self.fault: str | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._caught = asyncio.Event()
        self._caught_t = math.nan
        self._last_crossfire = False

    # --- lifecycle -------------------------------------------------------------------------------

    async def setup(self, node: NodeContext) -> None:
        """Start the set-point receiver and try to connect to the drives (retried by actions)."""
        self._loop = asyncio.get_running_loop()
        port = await self.receiver.start()
        log.info("set-point receiver on %s:%d", self.receiver.host, port)
        try:
            await self.ensure_ready()
        except BusError as exc:
            log.warning("PUMA drives not ready yet (%s); actions will retry", exc)

    async def teardown(self) -> None:
        """Stop the control thread, disable and disconnect the drives, close the receiver."""
        await asyncio.to_thread(self._shutdown_drives)
        await self.receiver.close()

    async def ensure_ready(self) -> None:
        """Connect and enable the drives and start the control thread if not running.

        Raises:
            BusError: the bus cannot be opened or the drives cannot be enabled.
        """
        if (
            self.drives is not None
            and self.fault is None
            and self._thread is not None
            and self._thread.is_alive()
        ):
            return
        await asyncio.to_thread(self._shutdown_drives)
        await asyncio.to_thread(self._start_drives)

    def _start_drives(self) -> None:
        drives = PumaDrives(
            self.can_host, self.can_port, self.channel, heartbeat_timeout=self.heartbeat_timeout
        )
        drives.open(timeout=self.connect_timeout)
        try:
            drives.enable(timeout=self.connect_timeout)
        except BusError:
            drives.close()
            raise
        drives.on_crossfire(self._on_crossfire)
        with self.lock:
            self.drives = drives
            self.servo = mc.CatchServo(drives.positions(), self.geometry)
            self.fault = None
        self._stop.clear()
        self._thread = threading.Thread(target=self._control_loop, name="puma-control", daemon=True)
        self._thread.start()

    def _shutdown_drives(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self.drives is not None:
            self.drives.close()
            self.drives = None

    def _control_loop(self) -> None:
        drives = self.drives
        assert drives is not None
        t_prev: float | None = None
        while not self._stop.is_set():
            try:
                t = drives.wait_sync(timeout=max(0.25, self.heartbeat_timeout))
                # One servo step per SYNC cycle elapsed on the bus, so the commanded motion keeps
                # pace with simulated time when this thread falls behind (bounded so that a
                # target never jumps further than the drives' following-error window allows).
                cycles = 1 if t_prev is None else round((t - t_prev) / mc.CYCLE_S)
                t_prev = t
                with self.lock:
                    assert self.servo is not None
                    for _ in range(min(max(cycles, 1), MAX_CYCLES_PER_SYNC)):
                        q = self.servo.step()
                drives.send_targets(q)
            except BusError as exc:
                self.fault = str(exc)
                log.error("PUMA control loop stopped: %s", exc)
                return

    def _on_crossfire(self, blocked: bool, t: float) -> None:
        rising = blocked and not self._last_crossfire
        self._last_crossfire = blocked
        if rising and self._loop is not None:
            self._loop.call_soon_threadsafe(self._caught_now, t)

    def _caught_now(self, t: float) -> None:
        self._caught_t = t
        self._caught.set()
        self.publish("ball_caught", {"t": t})

    # --- for actions -----------------------------------------------------------------------------

    def check(self) -> None:
        """Raise :class:`BusError` if the drives or the control loop are lost."""
        if self.fault is not None:
            raise BusError(self.fault)
        if self.drives is None:
            raise BusError("PUMA drives are not connected")
        self.drives.check()

    def arm_catch(self) -> None:
        """Forget earlier crossfire events (called at the start of a catch)."""
        self._caught.clear()
        self._caught_t = math.nan

    @property
    def caught(self) -> bool:
        """True once the crossfire sensor fired since :meth:`arm_catch`."""
        return self._caught.is_set()

    def bus_time(self) -> float:
        """Simulated time of the latest SYNC, s (NaN before the first)."""
        return self.drives.sim_time if self.drives is not None else math.nan


def _driver(ctx: CallContext) -> PumaDriver:
    for drv in ctx.drivers.values():
        if isinstance(drv, PumaDriver):
            return drv
    raise BusError("no PumaDriver on this node (services.toml [drivers.*])")


class MoveHome(PrimitiveAction):
    """Return the cup to the home pose (middle of the catch line).

    Params: ``timeout_s`` (5.0), ``tolerance_rad`` (0.01, on the actual joint positions).
    """

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        t0 = time.monotonic()
        drv = _driver(ctx)
        timeout = float(params.get("timeout_s", 5.0))
        tol = float(params.get("tolerance_rad", 0.01))
        try:
            await drv.ensure_ready()
            home = mc.home_pose(drv.geometry)
            with drv.lock:
                assert drv.servo is not None
                drv.servo.set_goal(home)
            deadline = t0 + timeout
            while True:
                drv.check()
                assert drv.drives is not None
                actual = drv.drives.positions()
                with drv.lock:
                    done = drv.servo.at_goal() and bool(np.all(np.abs(actual - home) <= tol))
                if done:
                    return ActionResult.success({"q": [float(v) for v in actual]}, cost=time.monotonic() - t0)
                if time.monotonic() > deadline:
                    return ActionResult.error(f"not home after {timeout} s", outcome="timeout",
                                              cost=time.monotonic() - t0)
                await asyncio.sleep(0.01)
        except BusError as exc:
            return ActionResult.error(str(exc), outcome="bus", cost=time.monotonic() - t0)


class Catch(PrimitiveAction):
    """Servo the cup to the latest set point until the crossfire sensor fires.

    Params: ``timeout_s`` (5.0; whole call), ``miss_grace_s`` (0.3; after the predicted rim time),
    ``first_setpoint_s`` (= ``timeout_s``; wait for the stream to start), ``stream_end_s`` (0.15).

    The set-point stream may end (closed or stale) once the bus time is within ``stream_end_s``
    of the predicted crossing: the predictor stops when the ball reaches the line, and the cup
    stays at the last set point. A stream that ends earlier is lost: error ``stream_lost``.

    Value: ``{"caught", "set_points", "unreachable", "y_pred", "t_pred", "t_caught"}`` (table
    frame, bus time). Cost: wall seconds.
    """

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        t0 = time.monotonic()
        drv = _driver(ctx)
        timeout = float(params.get("timeout_s", 5.0))
        grace = float(params.get("miss_grace_s", 0.3))
        first_wait = float(params.get("first_setpoint_s", timeout))
        stream_end = float(params.get("stream_end_s", 0.15))
        info: dict[str, Any] = {
            "caught": False,
            "set_points": 0,
            "unreachable": 0,
            "y_pred": None,
            "t_pred": None,
            "t_caught": None,
        }

        def done(status: Status, outcome: str | None = None, reason: str | None = None) -> ActionResult:
            return ActionResult(status=status, outcome=outcome, value=info, cost=time.monotonic() - t0,
                                reason=reason)

        try:
            await drv.ensure_ready()
            drv.arm_catch()
            sp = await self._first_set_point(drv, min(first_wait, timeout))
            used: SetPoint | None = None
            t_rim: float | None = None
            deadline = t0 + timeout
            while True:
                drv.check()
                if drv.caught:
                    info["caught"] = True
                    info["t_caught"] = drv._caught_t
                    return done(Status.SUCCESS, "caught")
                if sp is not used:  # a new set point (latest wins)
                    used = sp
                    info["set_points"] += 1
                    aimed = self._aim(drv, sp, info)
                    if aimed is not None:
                        t_rim = aimed
                now_bus = drv.bus_time()
                if t_rim is not None and now_bus > t_rim + grace:
                    return done(Status.FAILURE, "missed", f"ball passed at t={t_rim:.3f} s without a catch")
                if time.monotonic() > deadline:
                    return done(Status.ERROR, "timeout", f"no catch and no miss within {timeout} s")
                try:
                    sp = drv.receiver.latest()
                except StreamLostError:
                    t_pred = info["t_pred"]
                    if t_pred is not None and now_bus >= t_pred - stream_end:
                        # The ball is at the line: the vision side has stopped tracking. Keep
                        # the last set point and wait for the crossfire sensor or the miss.
                        await asyncio.sleep(0.002)
                        continue
                    raise
                await asyncio.sleep(0.002)
        except StreamLostError as exc:
            return done(Status.ERROR, "stream_lost", str(exc))
        except BusError as exc:
            return done(Status.ERROR, "bus", str(exc))

    @staticmethod
    async def _first_set_point(drv: PumaDriver, timeout: float) -> SetPoint:
        """The first set point received after the call started (on this or a new connection).

        Raises:
            StreamLostError: none within ``timeout`` s.
        """
        before = drv.receiver.state.latest
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            state = drv.receiver.state
            sp = state.latest
            if sp is not None and sp is not before and state.closed_reason is None:
                return sp
            await asyncio.sleep(0.002)
        raise StreamLostError(f"no set point within {timeout} s")

    @staticmethod
    def _aim(drv: PumaDriver, sp: SetPoint, info: dict[str, Any]) -> float | None:
        xb, yb, vxb, vyb = table_to_base(sp.x, sp.y, sp.vx, sp.vy, drv.robot_base)  # type: ignore[arg-type]
        try:
            with drv.lock:
                assert drv.servo is not None
                target = drv.servo.aim(xb, yb, sp.t, vxb, vyb)
        except UnreachableError:
            info["unreachable"] += 1
            return None
        info["y_pred"] = sp.y
        info["t_pred"] = sp.t
        return target.t_rim
