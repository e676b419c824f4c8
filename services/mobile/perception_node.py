"""The mobile robot's perception node: the camera/beacon/odometry driver and the course's primitive
actions, streaming steering set points (paper section 6, Fig. 3; overview and outcomes in
:mod:`services.mobile`)."""

from __future__ import annotations

import asyncio
import math
import threading
import time
from typing import Any

from services.action import CallContext, Driver, NodeContext, PrimitiveAction
from services.devices.endpoint import DeviceEndpoint
from services.devices.capture import CaptureClient, CaptureSpec, open_grabber
from services.devices.framegrabber import Frame, FrameClient
from services.errors import ActionError, LocationError
from services.mobile.beacon import BeaconModel, BeaconObservation
from services.mobile.camera import GroundCamera
from services.mobile.odometry import DriveGeometry, Pose2D
from services.mobile.setpoints import (
    ODOMETRY_TOPIC,
    STEERING_TOPIC,
    MalformedSetPoint,
    parse_odometry,
    setpoint_to_dict,
)
from services.mobile.setpoints import Odometry as OdometryMessage
from services.mobile.tasks import (
    CourseMemory,
    FindBeacon,
    FollowTrack,
    GotoBeacon,
    ReacquireTrack,
    Step,
    StopAtT,
    TaskParams,
)
from services.results import ActionResult

__all__ = [
    "DEFAULT_CAMERA_PORT",
    "FindBeaconAction",
    "FollowCentroid",
    "FollowRansac",
    "FollowScanline",
    "GotoBeaconAction",
    "PerceptionDriver",
    "ReacquireTrackAction",
    "StopAtTAction",
]

DEFAULT_CAMERA_PORT = 7220


# --------------------------------------------------------------------------------------------------
# perception node
# --------------------------------------------------------------------------------------------------
class PerceptionDriver(Driver):
    """Camera and beacon sensor of the mobile robot, and the drive node's odometry.

    Params: ``host`` ("127.0.0.1"), ``port`` (7220): the world's frame server, or ``source`` (with
    ``calibration``, ``api``, ``timestamps``, ``pace``, ``loop``): any OpenCV ``VideoCapture`` source
    instead (:mod:`services.devices.capture`; its frames carry no beacon scans); ``drive_node``
    (default: the node services.toml places ``stop_robot`` on): whose odometry to follow;
    ``connect_timeout_s`` (10); ``consume_wait_s`` (0.05): after handing a frame to the actions the
    grabbing thread waits up to this long for an action to take it before it grabs the next, so that
    the world (which waits for its camera client after each frame) slows down with a node slowed down
    by load instead of running away from it.
    """

    def __init__(self, name: str, params: dict[str, Any]) -> None:
        super().__init__(name, params)
        self.host = str(self.params.get("host", "127.0.0.1"))
        self.port = int(self.params.get("port", DEFAULT_CAMERA_PORT))
        self.connect_timeout = float(self.params.get("connect_timeout_s", 10.0))
        self.capture: CaptureSpec | None = None
        self.info: dict[str, Any] | None = None
        self.memory: CourseMemory | None = None
        self.frame: Frame | None = None
        self.lost: str | None = None
        self.odometry: OdometryMessage | None = None
        self.odometry_wall = -math.inf
        self.odometry_bad = 0
        self.faults = 0
        """Odometry messages that said ``fault: ...`` so far: an action compares it with its value at
        its start, so that a fault the drive node cleared (it restarts the drives) before an action
        read the latest odometry still ends the action."""
        self.last_fault: str | None = None
        self._scan_seq = -1
        self._scans: list[list[BeaconObservation]] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._new_frame = asyncio.Event()
        self._new_odometry = asyncio.Event()
        self._stop = threading.Event()
        self._consumed = threading.Event()
        self.consume_wait = float(self.params.get("consume_wait_s", 0.05))
        self._thread: threading.Thread | None = None
        self._link: Any = None

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint | None:
        """The frame server this driver connects to (``None`` with an OpenCV ``source``)."""
        if "source" in params:
            return None
        return DeviceEndpoint("mobile camera server", str(params.get("host", "127.0.0.1")),
                              int(params.get("port", DEFAULT_CAMERA_PORT)), "petrobot sim mobile", "frames")

    async def setup(self, node: NodeContext) -> None:
        """Start the grabbing thread and subscribe to the drive node's odometry.

        Raises:
            ActionError: the params' OpenCV source options are wrong.
        """
        try:
            self.capture = CaptureSpec.from_params(self.params, node.location.path)
        except ValueError as exc:
            raise ActionError(f"driver {self.name}: {exc}") from exc
        self._loop = asyncio.get_running_loop()
        self._new_frame = asyncio.Event()
        self._new_odometry = asyncio.Event()
        self._thread = threading.Thread(target=self._grab_loop, name="mobile-camera", daemon=True)
        self._thread.start()
        drive = self.params.get("drive_node")
        if drive is None:
            try:
                drive = node.location.node_of("stop_robot")
            except LocationError:
                drive = None
        if drive is not None:
            self._link = node.link(str(drive))
            self._link.subscribe(ODOMETRY_TOPIC, self._on_odometry)

    async def teardown(self) -> None:
        """Stop grabbing, unsubscribe."""
        self._stop.set()
        if self._link is not None:
            self._link.unsubscribe(ODOMETRY_TOPIC, self._on_odometry)
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 3.0)

    # --- threads and callbacks -------------------------------------------------------------------
    def _grab_loop(self) -> None:
        client: FrameClient | CaptureClient | None = None
        seq = -1
        while not self._stop.is_set():
            try:
                if client is None:
                    client = open_grabber(self.capture, self.host, self.port, connect_timeout=2.0)
                    info = client.info()
                    self.info = info
                    self.lost = None
                frame = client.grab(after=seq, timeout=0.5)
            except (OSError, ConnectionError) as exc:
                self.lost = f"camera server {self.host}:{self.port}: {exc}"
                if client is not None:
                    client.close()
                    client = None
                self._stop.wait(0.2)
                continue
            if frame is None:
                continue
            seq = frame.seq
            if self._loop is not None:
                self._consumed.clear()
                self._loop.call_soon_threadsafe(self._deliver, frame)
                # grab the next frame once an action took this one (at most consume_wait_s later):
                # the world waits for its camera client, so a node slowed down by load slows the
                # world instead of falling behind it
                self._consumed.wait(self.consume_wait)
        if client is not None:
            client.close()

    def _deliver(self, frame: Frame) -> None:
        self.frame = frame
        scan = (frame.meta or {}).get("beacon")
        if isinstance(scan, dict) and isinstance(scan.get("seq"), int) and scan["seq"] > self._scan_seq:
            self._scan_seq = scan["seq"]
            obs = []
            for item in scan.get("obs", [])[:16]:
                try:
                    az, el = float(item[0]), float(item[1])
                except (TypeError, ValueError, IndexError):
                    continue
                if math.isfinite(az) and math.isfinite(el):
                    obs.append(BeaconObservation(az, el, float(scan.get("t", frame.t))))
            self._scans.append(obs)
            del self._scans[:-4]
        self._new_frame.set()

    def _on_odometry(self, event: Any) -> None:
        try:
            self.odometry = parse_odometry(event.data)
        except MalformedSetPoint:
            self.odometry_bad += 1
            return
        if self.odometry.state.startswith("fault"):
            self.faults += 1
            self.last_fault = self.odometry.state
        self.odometry_wall = time.monotonic()
        self._new_odometry.set()

    # --- for actions -----------------------------------------------------------------------------
    def course_memory(self, params: dict[str, Any]) -> CourseMemory:
        """The course memory shared by the actions (made from the camera server's info map once).

        Raises:
            ActionError: no info yet (the camera server has not answered).
        """
        if self.memory is None:
            info = self.info
            if info is None:
                raise ActionError(f"no camera info from {self.host}:{self.port} yet ({self.lost or 'connecting'})")
            try:
                cam = GroundCamera(**info["camera"])
                robot = info["robot"]
                geo = DriveGeometry(wheel_radius=float(robot["wheel_radius"]), track_width=float(robot["track_width"]))
                beacon = BeaconModel(height_above_sensor=float(info["beacon_height"]) - float(robot["sensor_height"]),
                                     sensor_x=float(robot["sensor_x"]))
                tp = TaskParams.from_params({**params, "square": float(info.get("square", 2.0)),
                                             "track_width": float(info.get("track_width", 0.05))})
            except (KeyError, TypeError, ValueError) as exc:
                raise ActionError(f"camera info unusable: {exc}") from exc
            self.memory = CourseMemory(cam, geo, beacon, tp, seq0=time.time_ns() // 1000)
        return self.memory

    async def wait_ready(self, timeout: float) -> None:
        """Wait for camera info, a frame, fresh odometry and wheel drives that are enabled (the drive
        node's odometry says ``enabling`` while it configures and enables them).

        Raises:
            ActionError: not within ``timeout`` s (wall clock), saying what is missing.
        """
        end = time.monotonic() + timeout
        while (self.info is None or self.frame is None or time.monotonic() - self.odometry_wall > 1.0
               or self.odometry is None or self.odometry.state == "enabling"):
            if time.monotonic() > end:
                if self.info is None or self.frame is None:
                    what = "camera"
                elif self.odometry is not None and self.odometry.state == "enabling":
                    what = "enabled wheel drives (the drive node is still enabling them)"
                else:
                    what = "odometry from the drive node"
                raise ActionError(f"no {what} after {timeout:.0f} s ({self.lost or 'waiting'})")
            await asyncio.sleep(0.02)

    async def next_frame(self, after: int, timeout: float) -> Frame | None:
        """The latest frame newer than seq ``after``, waiting up to ``timeout`` s (None then)."""
        end = time.monotonic() + timeout
        while self.frame is None or self.frame.seq <= after:
            left = end - time.monotonic()
            if left <= 0:
                return None
            self._new_frame.clear()
            try:
                # asyncio.timeout, not wait_for: on Python 3.11 wait_for loses a cancel that comes as the
                # frame arrives, and a cancelled motion would drive on (issue 22: 1 round in 3)
                async with asyncio.timeout(left):
                    await self._new_frame.wait()
            except TimeoutError:
                return None
        self._consumed.set()
        return self.frame

    def take_scans(self) -> list[BeaconObservation] | None:
        """Beacon observations of the scans that arrived since the last call (None: no new scan)."""
        if not self._scans:
            return None
        out = [o for scan in self._scans for o in scan]
        self._scans.clear()
        return out


def _perception(ctx: CallContext) -> PerceptionDriver:
    drv = ctx.find_driver(PerceptionDriver)
    if drv is not None:
        return drv
    raise ActionError("this node hosts no mobile camera driver (services.mobile: PerceptionDriver)")


class _Streaming(PrimitiveAction):
    """A loop over camera frames around one task controller, streaming its set points.

    A motion (:attr:`PrimitiveAction.motion`): cancelled — by the caller, its deadline, or at once
    when its caller is gone (a coordinator killed mid-course) — it sends a zero-speed set point
    before it ends, so the drive node brakes on its ramp at once instead of waiting for its
    watchdog."""

    task = ""
    uses_image = True
    uses_beacons = False
    motion = True

    def make(self, memory: CourseMemory) -> Any:
        """The task controller of one call (each subclass builds its own from :mod:`services.mobile.tasks`)."""
        raise NotImplementedError(f"{type(self).__name__} defines no task controller")

    def value(self, task: Any) -> dict[str, Any]:
        return {}

    def judge(self, task: Any, step: Step, params: dict[str, Any]) -> tuple[bool, str]:
        """Whether the ended task met its specification (default: its outcome says so)."""
        return step.success, step.note

    def step(self, task: Any, frame: Frame, pose: Pose2D, beacons: list[BeaconObservation] | None) -> Step:
        """Advance the controller by one camera frame (each subclass feeds its controller what it needs)."""
        raise NotImplementedError(f"{type(self).__name__} defines no step")

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        drv = _perception(ctx)
        try:
            await drv.wait_ready(float(params.get("ready_timeout_s", 15.0)))
            memory = drv.course_memory(params)
        except ActionError as exc:
            return ActionResult.error(str(exc), outcome=None)
        task = self.make(memory)
        frame_timeout = float(params.get("frame_timeout_s", 1.0))
        odo_timeout = float(params.get("odometry_timeout_s", 1.0))
        timeout = float(params.get("timeout_s", 60.0))
        topic = str(params.get("topic", STEERING_TOPIC))
        cpu = 0.0
        sent = 0
        first_seq: int | None = None
        stops_base: int | None = None
        faults_base = drv.faults
        seq = drv.frame.seq if drv.frame is not None else -1
        t0: float | None = None
        t_last: float | None = None
        lateral: list[float] = []
        drv.take_scans()  # the scans of earlier actions are in the memory already

        def result_value(note: str) -> dict[str, Any]:
            out = {"task": self.task, "frames": sent, "setpoints": sent, "note": note, "cpu_s": cpu,
                   "t0": t0, "t": t_last}
            out.update(self.value(task))
            if lateral:
                out["cross_track_proxy_m"] = math.sqrt(sum(x * x for x in lateral) / len(lateral))
            return out

        try:
            while True:
                frame = await drv.next_frame(seq, frame_timeout)
                if frame is None:
                    return ActionResult.error(f"camera lost: no frame for {frame_timeout} s ({drv.lost or 'no reason'})",
                                              value=result_value("camera lost"), cost=cpu)
                seq = frame.seq
                t0 = frame.t if t0 is None else t0
                t_last = frame.t
                odo = drv.odometry
                if odo is None or time.monotonic() - drv.odometry_wall > odo_timeout:
                    memory.stop(frame.t)
                    return ActionResult.error(f"drive node silent: no odometry for {odo_timeout} s",
                                              value=result_value("drive lost"), cost=cpu)
                if first_seq is not None and odo.seq >= first_seq:
                    if stops_base is None:
                        stops_base = odo.stops
                    elif odo.stops > stops_base:
                        return ActionResult.error("drive watchdog stopped the wheels: set points stopped reaching "
                                                  "the drive node", value=result_value("watchdog"), cost=cpu)
                fault = odo.state if odo.state.startswith("fault") else (
                    drv.last_fault if drv.faults > faults_base else None)
                if fault is not None:
                    return ActionResult.error(f"drive {fault}", value=result_value("drive fault"), cost=cpu)
                if frame.t - t0 > timeout:
                    ctx.publish(topic, setpoint_to_dict(memory.stop(frame.t), time.time()))
                    return ActionResult.error(f"timeout: {timeout} s of camera time", value=result_value("timeout"),
                                              cost=cpu)
                pose = Pose2D(odo.pose.x, odo.pose.y, odo.pose.theta, odo.pose.s, frame.t)
                beacons = drv.take_scans()
                c0 = time.thread_time()
                step = self.step(task, frame, pose, beacons)
                cpu += time.thread_time() - c0
                line = memory.last_line
                if self.uses_image and line is not None and line[0] is not None and line[0].t == frame.t:
                    lateral.append(line[1].lateral_at(memory.camera.x_centre))
                ctx.publish(topic, setpoint_to_dict(step.setpoint, time.time(), frame.t_wall or None))
                if first_seq is None:
                    first_seq = step.setpoint.seq
                sent += 1
                if step.outcome is not None:
                    named = None if step.outcome == "ok" else step.outcome
                    value = result_value(step.note)
                    ok, why = self.judge(task, step, params)
                    if ok:
                        return ActionResult.success(value, outcome=named, cost=cpu)
                    return ActionResult.failure(value, outcome=named, cost=cpu, reason=why or step.note)
        except asyncio.CancelledError:  # brake now rather than on the drive's watchdog
            t_now = drv.frame.t if drv.frame is not None else t_last  # the newest frame: not stale at the drive
            if t_now is not None:
                ctx.publish(topic, setpoint_to_dict(memory.stop(t_now), time.time()))
            raise


class _Follow(_Streaming):
    task = "follow_track"
    detector = ""

    def make(self, memory: CourseMemory) -> FollowTrack:
        return FollowTrack(memory, self.detector)

    def value(self, task: FollowTrack) -> dict[str, Any]:
        return {"detector": self.detector, "seen": task.seen, "dropouts": task.dropouts, "distance_m": task.distance}

    def judge(self, task: FollowTrack, step: Step, params: dict[str, Any]) -> tuple[bool, str]:
        assert step.outcome is not None
        return task.judge(step.outcome, int(params.get("max_dropouts", 0)))

    def step(self, task: FollowTrack, frame: Frame, pose: Pose2D, beacons: list[BeaconObservation] | None) -> Step:
        if beacons is not None:
            task.m.observe_beacons(pose, beacons)
        return task.step(frame.t, pose, _grey(frame))


class FollowCentroid(_Follow):
    """``follow_track`` with the contrast-centroid detector (cheap, pulled by scuffs)."""

    detector = "centroid"


class FollowRansac(_Follow):
    """``follow_track`` with the RANSAC line fit on edge pairs (the most reliable)."""

    detector = "ransac"


class FollowScanline(_Follow):
    """``follow_track`` with five scan lines (the cheapest; loses the track under scuffs)."""

    detector = "scanline"


class FindBeaconAction(_Streaming):
    """``find_beacon``: a reflector at one of the blank square's exits (success ``found``)."""

    task = "find_beacon"
    uses_image = False

    def make(self, memory: CourseMemory) -> FindBeacon:
        return FindBeacon(memory)

    def step(self, task: FindBeacon, frame: Frame, pose: Pose2D, beacons: list[BeaconObservation] | None) -> Step:
        return task.step(frame.t, pose, beacons)


class GotoBeaconAction(_Streaming):
    """``goto_beacon``: pure pursuit across the blank square toward the resume point."""

    task = "goto_beacon"
    uses_image = False

    def make(self, memory: CourseMemory) -> GotoBeacon:
        return GotoBeacon(memory)

    def step(self, task: GotoBeacon, frame: Frame, pose: Pose2D, beacons: list[BeaconObservation] | None) -> Step:
        if beacons is not None:
            task.m.observe_beacons(pose, beacons)
        return task.step(frame.t, pose, beacons)


class ReacquireTrackAction(_Streaming):
    """``reacquire_track``: the track again near the resume point (failure ``lost`` past it)."""

    task = "reacquire_track"

    def make(self, memory: CourseMemory) -> ReacquireTrack:
        return ReacquireTrack(memory)

    def step(self, task: ReacquireTrack, frame: Frame, pose: Pose2D,
             beacons: list[BeaconObservation] | None) -> Step:
        if beacons is not None:
            task.m.observe_beacons(pose, beacons)
        return task.step(frame.t, pose, _grey(frame), beacons)


class StopAtTAction(_Streaming):
    """``stop_at_t``: brake to a stop on the T bar."""

    task = "stop_at_t"

    def make(self, memory: CourseMemory) -> StopAtT:
        return StopAtT(memory)

    def value(self, task: StopAtT) -> dict[str, Any]:
        return {"remaining_m": task.remaining if math.isfinite(task.remaining) else None}

    def step(self, task: StopAtT, frame: Frame, pose: Pose2D, beacons: list[BeaconObservation] | None) -> Step:
        return task.step(frame.t, pose, _grey(frame))


def _grey(frame: Frame) -> Any:
    img = frame.image
    return img[:, :, 0] if img.ndim == 3 else img
