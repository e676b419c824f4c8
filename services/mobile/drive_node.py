"""The mobile robot's drive node: the wheel drives on the CAN bus, odometry, the steering set points
with the watchdog, and ``stop_robot`` (paper section 6; overview in :mod:`services.mobile`)."""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from typing import Any

from services.action import CallContext, Driver, NodeContext, PrimitiveAction
from services.devices.devicefile import BusSpec, DeviceFileError, load_bus, resolve_device_file
from services.devices.drives import BusError, VelocityCanDrives
from services.devices.endpoint import DeviceEndpoint
from services.errors import ActionError, LocationError
from services.mobile.odometry import DriveGeometry, Odometry, Pose2D
from services.mobile.setpoints import ODOMETRY_TOPIC, STEERING_TOPIC, SteeringInput
from services.node.logs import LogLimiter
from services.results import ActionResult

__all__ = ["DEFAULT_CAN_PORT", "DriveDriver", "StopRobot"]

log = logging.getLogger(__name__)

DEFAULT_CAN_PORT = 7221


# --------------------------------------------------------------------------------------------------
# drive node
# --------------------------------------------------------------------------------------------------
class DriveDriver(Driver):
    """The wheel drives, odometry, the steering set points and the watchdog (module docstring).

    Params: ``bus`` (the project's ``devices/wheels.toml``; relative to services.toml's directory): the
    device file of the wheels' CAN bus (:mod:`services.devices.devicefile`: interface, channel, each
    drive's node id, EDS file, mode, unit scaling, times, PDO mappings; left wheel first);
    ``can_host`` ("127.0.0.1"), ``can_port`` (7221): the socketcand server; ``steering_from``
    (default: the node of ``follow_ransac``); ``stale_s`` (0.25); ``wheel_radius`` (0.05 m),
    ``track_width`` (0.30 m): the odometry's drive geometry; ``heartbeat_timeout_s`` (0.5),
    ``bus_silence_s`` (2.0), ``connect_timeout_s`` (10.0).

    A drive that faults, leaves OPERATIONAL (another station's NMT command) or is commanded by a
    second master (its RPDOs on the bus) puts ``fault: <cause>`` in the odometry's state at once,
    which ends the running primitive action of the perception node with ``error``; the cause is
    logged. Faulted or stopped drives are reset, started and enabled again in the background
    (every 0.5 s), drives another master commands only once its RPDOs stopped for a second; never
    before the fault was published (the perception node counts the fault messages, so one cleared
    before an action read the latest odometry still ends it).
    """

    def __init__(self, name: str, params: dict[str, Any]) -> None:
        super().__init__(name, params)
        p = self.params
        self.can_host = str(p.get("can_host", "127.0.0.1"))
        self.can_port = int(p.get("can_port", DEFAULT_CAN_PORT))
        self.bus_file = str(p["bus"]) if "bus" in p else None
        self.bus: BusSpec | None = None
        self._reported: str | None = None
        self.enabled = False
        """The wheel drives were enabled on this connection (odometry says ``enabling`` before)."""
        self.connect_timeout = float(p.get("connect_timeout_s", 10.0))
        self.heartbeat_timeout = float(p.get("heartbeat_timeout_s", 0.5))
        self.bus_silence = float(p.get("bus_silence_s", 2.0))
        self.geometry = DriveGeometry(wheel_radius=float(p.get("wheel_radius", 0.05)),
                                      track_width=float(p.get("track_width", 0.30)))
        self.input = SteeringInput(float(p.get("stale_s", 0.25)))
        self._limited = LogLimiter(log)
        self.latencies: list[float] = []
        """Frame capture → set point received, s (wall clocks of one host), logged every
        ``latency_every`` (param, 500) set points."""
        self.latency_every = int(p.get("latency_every", 500))
        self.odometry = Odometry(self.geometry)
        self.drives: VelocityCanDrives | None = None
        self.fault: str | None = None
        self.lock = threading.Lock()
        self.pose = Pose2D()
        self.speeds = (0.0, 0.0)
        self._odo_started = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._link: Any = None
        self._connecting: asyncio.Task[None] | None = None

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint:
        """The CAN gateway this driver connects to."""
        return DeviceEndpoint("mobile CAN gateway", str(params.get("can_host", "127.0.0.1")),
                              int(params.get("can_port", DEFAULT_CAN_PORT)), "petrobot sim mobile", "socketcand")

    async def setup(self, node: NodeContext) -> None:
        """Read the device file, subscribe to the steering set points; connect to the drives in the
        background.

        Raises:
            BusError: the device file cannot be read or is wrong (``FILE:LINE: problem``).
        """
        self._loop = asyncio.get_running_loop()
        try:
            self.bus = load_bus(resolve_device_file(self.bus_file, node.location.path, "wheels.toml"))
        except DeviceFileError as exc:
            raise BusError(str(exc)) from exc
        source = self.params.get("steering_from")
        if source is None:
            try:
                source = node.location.node_of("follow_ransac")
            except LocationError:
                source = None
        if source is not None:
            self._link = node.link(str(source))
            self._link.subscribe(STEERING_TOPIC, self._on_setpoint)
        self._connecting = asyncio.create_task(self._connect_forever())

    async def teardown(self) -> None:
        """Stop the control thread and disconnect."""
        if self._connecting is not None:
            self._connecting.cancel()
        if self._link is not None:
            self._link.unsubscribe(STEERING_TOPIC, self._on_setpoint)
        await asyncio.to_thread(self._shutdown)

    async def _connect_forever(self) -> None:
        while True:
            troubled = self.drives is not None and bool(self.drives.faults() or self.drives.trouble()) and (
                not self.drives.taken_over())
            if (self.fault is not None or troubled) and self._reported is None:
                # the fault is published before the drives are restarted, so that the running action
                # ends in error: a stopped SYNC or a busy node may have published nothing since
                self._publish_odometry(self.pose.t, self.speeds)
            elif self.drives is None or self.fault is not None or (self.drives.lost() is not None):
                try:
                    await asyncio.to_thread(self._shutdown)
                    await asyncio.to_thread(self._start)
                    log.info("wheel drives enabled")
                except BusError as exc:
                    log.warning("wheel drives not ready (%s); retrying", exc)
            elif troubled:
                why = "; ".join(f"drive {k}: {c}" for k, c in self.drives.faults().items()) or self.drives.trouble()
                try:
                    await asyncio.to_thread(self.drives.enable, self.connect_timeout)
                    log.warning("wheel drives started, reset and enabled again (%s)", why)
                except BusError as exc:
                    log.warning("wheel drive recovery failed: %s", exc)
            await asyncio.sleep(0.5)

    def _start(self) -> None:
        if self.bus is None:
            self.bus = load_bus(resolve_device_file(self.bus_file, None, "wheels.toml"))
        drives = VelocityCanDrives(self.can_host, self.can_port, heartbeat_timeout=self.heartbeat_timeout,
                                   silence_timeout=self.bus_silence, bus=self.bus)
        drives.open(timeout=self.connect_timeout)
        try:
            drives.start(timeout=self.connect_timeout)
            with self.lock:
                self.drives = drives
                self.fault = None
                self.input.hold()
            self._stop.clear()
            self._thread = threading.Thread(target=self._control_loop, name="wheel-control", daemon=True)
            self._thread.start()
            drives.enable(timeout=self.connect_timeout)
            self.enabled = True
        except BusError:
            self._stop.set()
            self.drives = None
            drives.close()
            raise

    def _shutdown(self) -> None:
        self.enabled = False
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
        n = 0
        while not self._stop.is_set():
            try:
                t = drives.wait_sync(timeout=self.bus_silence)
                q = drives.positions()
                if not (math.isfinite(q[0]) and math.isfinite(q[1])):
                    continue
                with self.lock:
                    if not self._odo_started:
                        self.odometry.reset(Pose2D(t=t))
                        self._odo_started = True
                    self.pose = self.odometry.update(float(q[0]), float(q[1]), t)
                    stops = self.input.watchdog_stops
                    left, right = self.input.wheels(time.monotonic(), t)
                    if self.input.watchdog_stops != stops:
                        wall_age, bus_age = self.input.age(time.monotonic(), t)
                        log.warning("watchdog: no steering set point for %.3f s (wall) / %.3f s (bus time): "
                                    "stopping the wheels (stop %d)", wall_age, bus_age, self.input.watchdog_stops)
                drives.send_velocities(left, right)
                n += 1
                if n % 2 == 0 and self._loop is not None:
                    self._loop.call_soon_threadsafe(self._publish_odometry, t, drives.velocities())
            except BusError as exc:
                self.fault = str(exc)
                drives.mark_lost(str(exc))
                log.error("wheel control loop stopped: %s", exc)
                return

    def _publish_odometry(self, t: float, speeds: Any) -> None:
        with self.lock:
            pose, inp = self.pose, self.input
            wl, wr = (float(speeds[0]), float(speeds[1])) if len(speeds) == 2 else (0.0, 0.0)
            if not (math.isfinite(wl) and math.isfinite(wr)):
                wl = wr = 0.0
            self.speeds = (wl, wr)
            v, w = self.geometry.twist(wl, wr)
            state = "ok"
            trouble = self.drives.trouble() if self.drives is not None else None
            if self.fault is not None:
                state = f"fault: {self.fault}"
            elif self.drives is not None and self.drives.faults():
                state = "fault: " + "; ".join(f"drive {k}: {c}" for k, c in self.drives.faults().items())
            elif trouble is not None:
                state = f"fault: {trouble}"
            elif not self.enabled:
                state = "enabling"
            elif inp.stopped:
                state = "watchdog"
            if state.startswith("fault") and state != self._reported:
                log.error("wheel drives: %s", state)
            self._reported = state if state.startswith("fault") else None
            data = {"t": t, "x": pose.x, "y": pose.y, "theta": pose.theta, "s": pose.s, "v": v, "w": w,
                    "seq": inp.latest.seq if inp.latest is not None else -1, "stops": inp.watchdog_stops,
                    "state": state}
        self.publish(ODOMETRY_TOPIC, data)

    def _on_setpoint(self, event: Any) -> None:
        with self.lock:
            bus = self.drives.sim_time if self.drives is not None else math.nan
            sp = self.input.offer(event.data, time.monotonic(), bus)
            note = self.input.note
        if note is not None:
            self._limited.log(logging.WARNING if sp is None else logging.INFO, ("steering", sp is None), "%s", note)
        if sp is None:
            return
        t_capture = event.data.get("t_capture") if isinstance(event.data, dict) else None
        if isinstance(t_capture, float) and math.isfinite(t_capture):
            self.latencies.append(time.time() - t_capture)
            if len(self.latencies) >= self.latency_every:
                lat = sorted(self.latencies)
                log.info("steering latency, frame capture -> drive node, over %d set points: p50 %.1f ms, "
                         "p99 %.1f ms, max %.1f ms", len(lat), 1000 * lat[len(lat) // 2],
                         1000 * lat[min(len(lat) - 1, int(0.99 * len(lat)))], 1000 * lat[-1])
                self.latencies.clear()

    def check(self) -> None:
        """Raise :class:`BusError` when the drives are not usable."""
        if self.fault is not None:
            raise BusError(self.fault)
        if self.drives is None:
            raise BusError("wheel drives are not connected")
        self.drives.check()


def _drive(ctx: CallContext) -> DriveDriver:
    drv = ctx.find_driver(DriveDriver)
    if drv is not None:
        return drv
    raise ActionError("this node hosts no wheel drive driver (services.mobile.drive_node:DriveDriver)")


class StopRobot(PrimitiveAction):
    """``stop_robot``: brake to rest (the latest set point is forgotten); success once both wheels
    turn slower than ``rest_speed`` (0.05 rad/s), with ``{t, watchdog_stops, dropped, faults}`` in the
    value. A faulted drive holds its wheel at rest too: the robot is stopped, the value names the
    fault, and the driver resets it in the background (``recovered`` in a later call's value). Error
    when the bus is lost (no wheel speed known) or the wheels do not come to rest within ``timeout_s``
    (5 s, wall clock)."""

    unattended = True

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        drv = _drive(ctx)
        rest = float(params.get("rest_speed", 0.05))
        timeout = float(params.get("timeout_s", 5.0))
        end = time.monotonic() + timeout
        while True:
            with drv.lock:
                drv.input.hold()
            drives = drv.drives
            lost = "wheel drives are not connected" if drives is None else (drv.fault or drives.lost())
            if lost is None and drives is not None:
                speeds = drives.velocities()
                if all(math.isfinite(float(s)) and abs(float(s)) < rest for s in speeds):
                    inp = drv.input
                    return ActionResult.success({
                        "t": drives.sim_time, "watchdog_stops": inp.watchdog_stops,
                        "dropped": inp.malformed + inp.stale + inp.out_of_order + inp.jumps,
                        "faults": {str(k): v for k, v in drives.faults().items()}})
            if time.monotonic() > end:
                return ActionResult.error(f"bus: {lost}" if lost else
                                          f"the wheels did not come to rest within {timeout} s")
            await asyncio.sleep(0.01)
