"""The PUMA 560's driver on the catching testbed's motion node (paper section 6, Fig. 1).

services.toml (example)::

    [drivers.puma]
    node = "motion"
    impl = "services.catching.arm:PumaDriver"
    params = { can_host = "127.0.0.1", can_port = 7211, bus = "devices/puma.toml" }

:class:`PumaDriver` params (all optional):

* ``bus`` (the project's ``devices/puma.toml``; a relative path is taken from the directory of
  services.toml): the device file of the PUMA's CAN bus (:mod:`services.devices.devicefile`: the
  interface and channel, each joint drive's node id, EDS file, mode, unit scaling, heartbeat and
  deadline times and PDO mappings, the crossfire module);
* ``can_host`` ("127.0.0.1"), ``can_port`` (7211): the socketcand server (the sim's gateway) when the
  device file's interface is socketcand;
* ``setpoints_from`` (default: the node services.toml places the action ``predict`` on) and
  ``setpoint_topic`` ("setpoints"): where the set points come from, as events of that node
  (:mod:`services.catching.setpoints`); ``setpoint_max_age_s`` (0.2): a set point older than this (wall
  clock) means a lost stream;
* ``robot_base`` ([0.75, 0.0, 0.46, pi]): x, y, z (m), yaw (rad) of the robot base frame in the
  table frame of the set points;
* ``edge_x``, ``table_z``, ``rim_drop``, ``tilt_deg``, ``y_min``, ``y_max``: override
  :class:`services.catching.robot.motion_control.CatchGeometry` (base frame);
* ``switch_interval_s`` (0.001): the node process's thread switch interval (see :meth:`PumaDriver.setup`);
* ``heartbeat_timeout_s`` (0.5, bus time: a CAN node silent that long is lost), ``bus_silence_s``
  (2.0, wall time: nothing at all on the bus that long and it is lost), ``connect_timeout_s`` (5.0).

The driver owns a control thread that runs once per CAN SYNC (2 ms of simulated time): one
:meth:`services.catching.robot.motion_control.CatchServo.step` per cycle elapsed on the bus (at most
:data:`services.devices.cia402.TARGET_TIMEOUT_CYCLES`, the cycles a drive extrapolates a missing
target, so that a late thread's next target continues where the drives' extrapolation went) and
one set of RPDO targets. The crossfire sensor's rising edge publishes the external event
``ball_caught`` with ``{"t": bus time}``.

Faults: before every action the driver makes sure the drives are usable, the way a CiA 402 master
does: a drive in FAULT (following error, RPDO timeout, lost master heartbeat; the drive's EMCY says
which) or one that left OPERATIONAL (an NMT command of another station) is started, reset and
enabled again (:meth:`services.devices.drives.CanDrives.enable`) and the servo restarts where the arm
is; a lost bus is reconnected (and the drives configured again over SDO). ``move_home`` reports a
recovery in its value (``recovered``). Drives that another master is commanding (its RPDOs seen on
the bus within the last second) are not recovered: the action ends ``error`` saying so.
"""

from __future__ import annotations

import asyncio
import logging
import math
import sys
import threading
import time
from typing import Any

import numpy as np

from services.action import Driver, NodeContext
from services.catching.robot import motion_control as mc
from services.catching.setpoints import SETPOINT_TOPIC, SetPointSubscription
from services.catching.drives import PumaDrives
from services.devices import cia402 as cf
from services.devices.devicefile import BusSpec, DeviceFileError, load_bus, resolve_device_file
from services.devices.drives import BusError
from services.devices.endpoint import DeviceEndpoint
from services.errors import ActionError, LocationError

__all__ = ["DEFAULT_ROBOT_BASE", "STOP_TOLERANCE_RAD", "PumaDriver", "table_to_base"]

log = logging.getLogger(__name__)

DEFAULT_ROBOT_BASE = (0.75, 0.0, 0.46, math.pi)
MAX_CYCLES_PER_SYNC = cf.TARGET_TIMEOUT_CYCLES
"""At most this many 2 ms servo steps per received SYNC: a late thread catches up with the cycles
the drives extrapolated, never further (a longer gap has faulted the drives anyway)."""
STOP_TOLERANCE_RAD = 0.01
"""The arm counts as stopped when every joint is within this of the commanded rest pose."""


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
    """The PUMA on its CAN bus, the servo's control thread and the set-point subscription."""

    def __init__(self, name: str, params: dict[str, Any]) -> None:
        super().__init__(name, params)
        p = self.params
        self.can_host = str(p.get("can_host", "127.0.0.1"))
        self.can_port = int(p.get("can_port", 7211))
        self.bus_file = str(p["bus"]) if "bus" in p else None
        self.bus: BusSpec | None = None
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
        self.bus_silence = float(p.get("bus_silence_s", 2.0))
        self.connect_timeout = float(p.get("connect_timeout_s", 5.0))
        self.setpoints_from: str | None = str(p["setpoints_from"]) if "setpoints_from" in p else None
        self.setpoint_topic = str(p.get("setpoint_topic", SETPOINT_TOPIC))
        self.setpoint_max_age = float(p.get("setpoint_max_age_s", 0.2))
        self._subscription: SetPointSubscription | None = None
        self.recoveries = 0
        """Drive fault recoveries (fault reset and enable) since the node started."""
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

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint:
        """The CAN gateway this driver connects to (params ``can_host``, ``can_port``)."""
        return DeviceEndpoint("CAN gateway", str(params.get("can_host", "127.0.0.1")),
                              int(params.get("can_port", 7211)),
                              "petrobot sim catching", "socketcand")

    # --- lifecycle -------------------------------------------------------------------------------

    async def setup(self, node: NodeContext) -> None:
        """Try to connect to the drives (actions retry); set points are subscribed at the first catch.

        Also shortens the interpreter's thread switch interval of the node process to
        ``switch_interval_s`` (param, default 0.001 s; Python's is 0.005 s): the control thread
        answers a SYNC every 2 ms and shares the interpreter with the CAN receive thread and the
        node's event loop, so a 5 ms slice could make it miss cycles on its own.
        """
        self._loop = asyncio.get_running_loop()
        self.bus = self.load_bus(node.location.path)
        switch = float(self.params.get("switch_interval_s", 0.001))
        if 0 < switch < sys.getswitchinterval():
            sys.setswitchinterval(switch)
        try:
            await self.ensure_ready()
        except BusError as exc:
            log.warning("PUMA drives not ready yet (%s); actions will retry", exc)

    def load_bus(self, services_path: str | None = None) -> BusSpec:
        """Read the device file (param ``bus``; relative to services.toml's directory).

        Raises:
            BusError: the file cannot be read or is wrong (``FILE:LINE: problem``).
        """
        try:
            return load_bus(resolve_device_file(self.bus_file, services_path, "puma.toml"))
        except DeviceFileError as exc:
            raise BusError(str(exc)) from exc

    async def teardown(self) -> None:
        """Stop the control thread, disable and disconnect the drives, unsubscribe the set points."""
        if self._subscription is not None:
            self._subscription.close()
        await asyncio.to_thread(self._shutdown_drives)

    def subscription(self) -> SetPointSubscription:
        """The set-point subscription on the publishing node (made and started on first use).

        Raises:
            ActionError: the driver runs on no node, or no node to take set points from is known.
        """
        if self._subscription is None:
            if self.node is None:
                raise ActionError("the PUMA driver is not running on a node")
            source = self.setpoints_from
            if source is None:
                try:
                    source = self.node.location.node_of("predict")
                except LocationError as exc:
                    raise ActionError(f"no set-point source: give the driver param setpoints_from ({exc})") from exc
            self._subscription = SetPointSubscription(self.node.link(source), self.setpoint_topic,
                                                      max_age=self.setpoint_max_age)
        self._subscription.start()
        return self._subscription

    async def ensure_ready(self) -> str | None:
        """Make the drives usable, as a CiA 402 master does, before an action moves the arm.

        Connected with the control thread running and every drive operation enabled: nothing to
        do. A drive faulted, not enabled or no longer operational (another station's NMT command):
        restart the drives, reset the fault and enable them again (:meth:`PumaDrives.enable`, which
        NMT-starts them), restart the servo where the arm is. No bus, a lost one (a heartbeat
        missing) or no control thread: reconnect (waiting up to ``connect_timeout_s`` for the
        gateway), configure and enable, which resets faults too.

        Returns:
            What was recovered, in words (``None`` if nothing was wrong).

        Raises:
            BusError: the bus cannot be opened, the drives cannot be enabled (the message names
                each drive's state and fault cause), or another master is commanding them.
        """
        drives = self.drives
        if drives is not None and drives.lost() is None:
            await asyncio.to_thread(drives.refresh, 0.5)  # judge the drives as they are now
        lost = drives.lost() if drives is not None else "not connected"
        if drives is not None and lost is None and self.fault is None and self._thread is not None \
                and self._thread.is_alive():
            if drives.taken_over():
                raise BusError(drives.trouble() or "another master is commanding the drives")
            trouble = drives.trouble()
            faults = drives.faults()
            if not faults and trouble is None and drives.all_enabled():
                return None
            what = ("; ".join(f"drive {n}: {c}" for n, c in sorted(faults.items())) or trouble
                    or "drives not enabled")
            log.warning("recovering the PUMA drives (%s): fault reset and enable", what)
            await asyncio.to_thread(self._recover_drives)
            return f"fault reset and enable ({what})"
        why = self.fault or lost
        if drives is not None:
            drives.mark_lost(why or "reconnecting")
            log.warning("reconnecting the PUMA drives (%s)", why)
        await asyncio.to_thread(self._shutdown_drives)
        await asyncio.to_thread(self._start_drives)
        return f"bus reconnected ({why})" if drives is not None else None

    def _start_drives(self) -> None:
        if self.bus is None:
            self.bus = self.load_bus()
        drives = PumaDrives(self.can_host, self.can_port, heartbeat_timeout=self.heartbeat_timeout,
                            silence_timeout=self.bus_silence, bus=self.bus)
        drives.open(timeout=self.connect_timeout)
        try:
            drives.start(timeout=self.connect_timeout)
            drives.on_crossfire(self._on_crossfire)
            with self.lock:
                self.drives = drives
                self.servo = mc.CatchServo(drives.positions(), self.geometry)
                self.fault = None
            self._start_thread()  # targets flow from the first enabled cycle on
            drives.enable(timeout=self.connect_timeout)
        except BusError:
            self._stop_thread()
            self.drives = None
            drives.close()
            raise

    def _recover_drives(self) -> None:
        """Fault reset and enable while the control loop keeps sending targets: the servo restarts
        at the resting positions first, so the targets hold the arm still and flow from the first
        enabled cycle on (a gap between enabling and the first target would be an RPDO timeout)."""
        drives = self.drives
        assert drives is not None
        try:
            drives.start(timeout=self.connect_timeout)
            with self.lock:
                self.servo = mc.CatchServo(drives.positions(), self.geometry)
            drives.enable(timeout=self.connect_timeout)
        except BusError as exc:
            self.fault = f"fault recovery failed: {exc}"
            raise BusError(self.fault) from exc
        self.recoveries += 1

    def _start_thread(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._control_loop, name="puma-control", daemon=True)
        self._thread.start()

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _shutdown_drives(self) -> None:
        self._stop_thread()
        if self.drives is not None:
            self.drives.close()
            self.drives = None

    def _control_loop(self) -> None:
        drives = self.drives
        assert drives is not None
        t_prev: float | None = None
        while not self._stop.is_set():
            try:
                t = drives.wait_sync(timeout=self.bus_silence)
                # One servo step per SYNC cycle elapsed on the bus, so that the next target continues
                # where the drives' extrapolation of the missing ones took the joints (bounded by
                # the cycles a drive extrapolates before it faults).
                cycles = 1 if t_prev is None else round((t - t_prev) / mc.CYCLE_S)
                t_prev = t
                with self.lock:
                    assert self.servo is not None
                    for _ in range(min(max(cycles, 1), MAX_CYCLES_PER_SYNC)):
                        q = self.servo.step()
                drives.send_targets(q)
            except BusError as exc:
                self.fault = str(exc)
                drives.mark_lost(str(exc))
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

    def stop_motion(self) -> None:
        """Controlled stop: brake every joint to rest at its acceleration limit (from any thread)."""
        with self.lock:
            if self.servo is not None:
                self.servo.stop()

    async def wait_stopped(self, timeout: float) -> float:
        """Wait until the commanded motion is at rest and the arm within
        :data:`STOP_TOLERANCE_RAD` of it; returns the bus time (s) at that moment.

        Raises:
            BusError: the bus or a drive is lost meanwhile, or the arm is not at rest within
                ``timeout`` s (wall clock).
        """
        end = time.monotonic() + timeout
        while True:
            self.check()
            assert self.drives is not None
            actual = self.drives.positions()
            with self.lock:
                assert self.servo is not None
                rest = self.servo.at_goal() and bool(np.all(np.abs(actual - self.servo.q) <= STOP_TOLERANCE_RAD))
            if rest:
                return self.bus_time()
            if time.monotonic() > end:
                raise BusError(f"the arm did not come to rest within {timeout} s")
            await asyncio.sleep(0.004)

    def arm_catch(self) -> None:
        """Forget earlier crossfire events (called at the start of a catch)."""
        self._caught.clear()
        self._caught_t = math.nan

    @property
    def caught(self) -> bool:
        """True once the crossfire sensor fired since :meth:`arm_catch`."""
        return self._caught.is_set()

    @property
    def caught_t(self) -> float:
        """Bus time of the crossfire sensor's rising edge since :meth:`arm_catch`, s (NaN before)."""
        return self._caught_t

    def bus_time(self) -> float:
        """Simulated time of the latest SYNC, s (NaN before the first)."""
        return self.drives.sim_time if self.drives is not None else math.nan
