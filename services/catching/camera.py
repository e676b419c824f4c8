"""The vision node's camera: the frame-grabber driver and its link to the camera server (paper §6).

:class:`CameraDriver` (services.toml ``[drivers.camera]``, ``impl =
"services.catching.camera:CameraDriver"``, params ``host``, ``port``, ``tick_every``,
``connect_timeout_s``) is the frame-grabber card. A thread (:class:`CameraLink`) grabs every frame
from the camera server (:mod:`services.devices.framegrabber`; the simulated one is
``sim.frameserver.FrameServer``) or, when the params name a ``source``, from any OpenCV
``VideoCapture`` source (a V4L2 device, a video file, an RTSP/HTTP/GStreamer URL, with the calibration
from the ``calibration`` JSON file: :mod:`services.devices.capture`, which says where frame times come
from), keeps the last few and a background image (per-pixel median of frames
at least 0.3 s apart), and the driver publishes the external event ``image_sampling_tick``
(``{"seq", "t"}``) for every ``tick_every``-th frame. After a lost camera the next action call
reconnects (:meth:`CameraDriver.reconnect_if_lost`), so a restarted camera server is picked up.

The camera server's info map carries the calibration (:class:`VisionConfig`): the homography, the
table's size, the robot base pose and the rolling model. The actions that use the camera live in
:mod:`services.catching.vision_node`.
"""

from __future__ import annotations

import asyncio
import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.action import CallContext, Driver, NodeContext
from services.devices.capture import CaptureClient, CaptureSpec, open_grabber
from services.devices.endpoint import DeviceEndpoint
from services.devices.framegrabber import Frame, FrameClient
from services.errors import ActionError
from services.catching.vision import Homography, PlanarTransform, Roi, RollingModel, table_roi

__all__ = [
    "DEFAULT_CAMERA_PORT",
    "CameraDriver",
    "CameraLink",
    "CameraLostError",
    "VisionConfig",
    "camera_of",
]

DEFAULT_CAMERA_PORT = 7210
"""TCP port of the camera server when the driver's params name none."""


class CameraLostError(ActionError):
    """The camera server stopped delivering frames (connection lost or no frame in time)."""


@dataclass(frozen=True, slots=True)
class VisionConfig:
    """Calibration and models the vision node gets from the camera server's info map.

    Attributes:
        homography: pixel → table map.
        base: table frame → robot base frame.
        model: rolling-ball deceleration model.
        catch_x: x of the catch line in the table frame, m.
        fps: nominal frame rate, 1/s.
        roi: the table's region in the image (pixels), searched by the locators.
    """

    homography: Homography
    base: PlanarTransform
    model: RollingModel
    catch_x: float
    fps: float
    roi: Roi | None = None

    @classmethod
    def from_info(cls, info: dict[str, Any]) -> VisionConfig:
        """Parse the camera server's ``info`` (``sim.catching.camera.camera_info`` in the simulation)'s map.

        Raises:
            ActionError: if fields are missing or malformed.
        """
        try:
            hom = Homography(np.asarray(info["homography"], dtype=float).reshape(3, 3),
                             float(info.get("calibration_rms_m", 0.0)))
            x, y, z, yaw = (float(v) for v in info["robot_base"])
            a, b = (float(v) for v in info["rolling_model"])
            catch_x = float(info.get("catch_x", 0.0))
            roi = None
            if "table_size" in info:
                length, width = (float(v) for v in info["table_size"])
                size = (int(info["width"]), int(info["height"])) if "width" in info else None
                roi = table_roi(hom, length, width, catch_x=catch_x, image_size=size)
            return cls(hom, PlanarTransform(x, y, z, yaw), RollingModel(a, b), catch_x,
                       float(info.get("fps", 25.0)), roi)
        except (KeyError, TypeError, ValueError) as exc:
            raise ActionError(f"camera info is malformed: {exc!r}") from exc


class CameraLink:
    """A frame-grabbing thread on a :class:`services.devices.framegrabber.FrameClient`, awaitable from asyncio.

    Args:
        host, port: the camera server.
        on_frame: optional callback run in the event loop for each frame.
        history: frames kept for multi-frame locators.
        frame_timeout: s without a frame after which the camera counts as lost.
        capture: an OpenCV source to read instead of the camera server at ``host:port``.
    """

    def __init__(
        self, host: str, port: int, *, on_frame: Callable[[Frame], None] | None = None,
        history: int = 16, frame_timeout: float = 2.0, capture: CaptureSpec | None = None,
    ) -> None:
        self.host = host
        self.port = port
        self.capture = capture
        self.on_frame = on_frame
        self.frame_timeout = frame_timeout
        self.frames: collections.deque[Frame] = collections.deque(maxlen=history)
        self._background: np.ndarray | None = None
        self._bg_stale = False
        self._bg_samples: collections.deque[np.ndarray] = collections.deque(maxlen=5)
        self._bg_last_t = -math.inf
        self.lost: str | None = None
        self.info: dict[str, Any] = {}
        self._client: FrameClient | CaptureClient | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._new = asyncio.Event()

    async def start(self, connect_timeout: float = 10.0) -> None:
        """Connect (retrying until ``connect_timeout`` s), read the info map, start grabbing.

        Raises:
            CameraLostError: if the camera server cannot be reached.
        """
        self._loop = asyncio.get_running_loop()
        deadline = time.monotonic() + connect_timeout
        while True:
            try:
                self._client = await asyncio.to_thread(open_grabber, self.capture, self.host, self.port)
                self.info = await asyncio.to_thread(self._client.info)
                break
            except (OSError, ConnectionError) as exc:
                if time.monotonic() > deadline:
                    where = (f"camera source {self.capture.source}" if self.capture is not None
                             else f"camera server {self.host}:{self.port}")
                    raise CameraLostError(f"{where} unreachable: {exc}") from exc
                await asyncio.sleep(0.2)
        self._thread = threading.Thread(target=self._grab_loop, name="camera-grab", daemon=True)
        self._thread.start()

    def _grab_loop(self) -> None:
        assert self._client is not None and self._loop is not None
        seq = -1
        last = time.monotonic()
        try:
            while not self._stop.is_set():
                frame = self._client.grab(after=seq, timeout=0.5)
                if frame is None:
                    if time.monotonic() - last > self.frame_timeout:
                        raise ConnectionError(f"no frame for {self.frame_timeout} s")
                    continue
                last = time.monotonic()
                seq = frame.seq
                if frame.t - self._bg_last_t >= 0.3:
                    self._bg_last_t = frame.t
                    self._bg_samples.append(frame.image)
                    self._bg_stale = True
                self._loop.call_soon_threadsafe(self._deliver, frame)
        except (ConnectionError, OSError, ValueError) as exc:
            if not self._stop.is_set():
                self._loop.call_soon_threadsafe(self._mark_lost, f"camera lost: {exc}")

    @property
    def background(self) -> np.ndarray | None:
        """Per-pixel median of the last frames taken at least 0.3 s apart (at least 3), or ``None``.

        Computed when asked (by the background-difference locator) and kept until a new sample
        comes, not in the grabbing thread: a median of five frames takes milliseconds that would
        otherwise delay every frame's delivery, and with it the set points.
        """
        if self._bg_stale and len(self._bg_samples) >= 3:
            self._background = np.median(np.stack(list(self._bg_samples)), axis=0).astype(np.uint8)
            self._bg_stale = False
        return self._background

    def _deliver(self, frame: Frame) -> None:
        self.frames.append(frame)
        self._new.set()
        if self.on_frame is not None:
            self.on_frame(frame)

    def _mark_lost(self, reason: str) -> None:
        self.lost = reason
        self._new.set()

    async def next_frame(self, after: int, timeout: float | None = None) -> Frame:
        """The oldest kept frame with seq > ``after`` (waiting for one if needed).

        Raises:
            CameraLostError: if the camera is lost or no frame comes within ``timeout`` s
                (default: the link's ``frame_timeout``).
        """
        limit = self.frame_timeout if timeout is None else timeout
        try:
            async with asyncio.timeout(limit):
                while True:
                    if self.lost is not None:
                        raise CameraLostError(self.lost)
                    for f in self.frames:
                        if f.seq > after:
                            return f
                    self._new.clear()
                    await self._new.wait()
        except TimeoutError:
            raise CameraLostError(f"no camera frame within {limit} s") from None

    async def close(self) -> None:
        """Stop the grabbing thread and close the connection."""
        self._stop.set()
        if self._client is not None:
            self._client.close()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)


class CameraDriver(Driver):
    """The vision node's frame grabber (see module docstring); publishes ``image_sampling_tick``."""

    def __init__(self, name: str, params: dict[str, Any]) -> None:
        super().__init__(name, params)
        self.link: CameraLink | None = None
        self.capture: CaptureSpec | None = None
        self.config: VisionConfig | None = None
        self.tick_every = max(1, int(self.params.get("tick_every", 1)))

    @classmethod
    def device(cls, params: dict[str, Any]) -> DeviceEndpoint | None:
        """The camera server this driver connects to (params ``host``, ``port``); ``None`` with an
        OpenCV ``source`` (no server to probe)."""
        if "source" in params:
            return None
        return DeviceEndpoint("camera server", str(params.get("host", "127.0.0.1")),
                              int(params.get("port", DEFAULT_CAMERA_PORT)),
                              "petrobot sim catching", "frames")

    async def setup(self, node: NodeContext) -> None:
        try:
            self.capture = CaptureSpec.from_params(self.params, node.location.path)
        except ValueError as exc:
            raise ActionError(f"driver {self.name}: {exc}") from exc
        self.link = CameraLink(
            str(self.params.get("host", "127.0.0.1")),
            int(self.params.get("port", DEFAULT_CAMERA_PORT)),
            on_frame=self._tick, capture=self.capture,
        )
        await self.link.start(float(self.params.get("connect_timeout_s", 10.0)))
        self.config = VisionConfig.from_info(self.link.info)

    def _tick(self, frame: Frame) -> None:
        if frame.seq % self.tick_every == 0 and self.node is not None:
            self.publish("image_sampling_tick", {"seq": frame.seq, "t": frame.t})

    async def reconnect_if_lost(self, timeout: float = 2.0) -> None:
        """Reconnect to the camera server if the link was lost (e.g. the sim restarted).

        Raises:
            CameraLostError: if the server cannot be reached within ``timeout`` s.
        """
        if self.link is None or self.link.lost is None:
            return
        await self.link.close()
        link = CameraLink(self.link.host, self.link.port, on_frame=self._tick, capture=self.capture)
        self.link = link
        await link.start(timeout)
        self.config = VisionConfig.from_info(link.info)

    async def teardown(self) -> None:
        if self.link is not None:
            await self.link.close()


def camera_of(ctx: CallContext) -> CameraDriver:
    """The connected camera driver among the calling node's drivers.

    Raises:
        ActionError: the node hosts no camera driver, or it is not set up.
    """
    for d in ctx.drivers.values():
        if isinstance(d, CameraDriver) and d.link is not None and d.config is not None:
            return d
    raise ActionError("no camera driver on this node")
