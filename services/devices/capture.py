"""Cameras through OpenCV's ``VideoCapture``: a V4L2 device, a video file, an RTSP/HTTP/GStreamer URL.

A lab's camera is rarely our frame server: it is a V4L2 device (``/dev/video0``, a USB or a
GigE/USB3 camera with a V4L2 driver), a network stream (``rtsp://...``, ``http://...``), a
GStreamer pipeline (``... ! appsink``), or a recording of one (a video file). :class:`CaptureClient`
reads any source OpenCV's ``cv2.VideoCapture`` opens and hands frames on with the frame server's
grabber interface (:class:`services.devices.framegrabber.FrameClient`: :meth:`CaptureClient.grab`,
:meth:`CaptureClient.info`, :meth:`CaptureClient.close`), so that the nodes' camera drivers take
either. A driver chooses it in services.toml with the params of :class:`CaptureSpec` (``source``,
``calibration``, ``api``, ``timestamps``, ``pace``, ``loop``); without ``source`` it reads the
frame server at ``host:port`` as before.

Timestamps (each :class:`~services.devices.framegrabber.Frame`'s ``t``, what prediction fits the
ball's track on):

* ``timestamps = "source"`` (the default for files and streams): the time the source gives for the
  frame (``CAP_PROP_POS_MSEC``): a file's presentation time (0 at its first frame, exactly
  ``k / fps`` for a constant-rate recording), a V4L2 device's buffer time stamp (taken by the
  driver when the frame was captured, on the kernel's monotonic clock), an RTSP stream's
  presentation time. A source that gives none (0, or a time that does not increase) falls back to
  the capture clock for that frame.
* ``timestamps = "capture"``: :func:`time.monotonic` when ``read()`` returned the frame. It lags
  the exposure by the exposure itself, the transfer and any buffering (a V4L2 queue of 4 buffers at
  30 fps can be 130 ms behind; a network stream, more), and the lag varies from frame to frame:
  a prediction from capture times is late by the mean lag and noisier by its jitter. Use it only
  for sources whose own times are wrong.

``t_wall`` is always :func:`time.time` at capture (the latency measurements' clock). A file is read at
its frame rate by default (``pace``), as a live camera would deliver it, so a node runs on a recording
as on the camera; without pacing it is read as fast as the node takes frames (tests, offline
analysis). At the end of a file the camera is lost (``ConnectionError``), unless ``loop``.

The calibration (the info map a frame server serves: image size, homography, robot base pose...)
comes from a JSON file (``calibration``); :func:`record` writes one beside each recording (lossless
FFV1 in Matroska: the recording gives the frames it was made from, bit for bit). The catching
camera's recorder is ``python -m services.catching.recording``.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from services.devices.framegrabber import Frame, FrameClient

__all__ = ["APIS", "CaptureClient", "CaptureSpec", "open_grabber", "record"]

APIS: dict[str, int] = {
    "any": cv2.CAP_ANY,
    "v4l2": cv2.CAP_V4L2,
    "ffmpeg": cv2.CAP_FFMPEG,
    "gstreamer": cv2.CAP_GSTREAMER,
}
"""OpenCV capture back ends a driver's ``api`` param may name."""

_URL_SCHEMES = ("rtsp://", "rtsps://", "http://", "https://", "udp://", "tcp://", "rtmp://")


@dataclass(frozen=True)
class CaptureSpec:
    """A camera driver's OpenCV source, from its services.toml params.

    Attributes:
        source: what ``cv2.VideoCapture`` opens: a device index (``"0"``), a device path
            (``"/dev/video0"``), a file (relative to services.toml's directory), a URL, or a
            GStreamer pipeline (with ``api = "gstreamer"``).
        calibration: the info map's JSON file (relative to services.toml's directory), or ``None``:
            the info map has only the source's size and frame rate.
        api: OpenCV back end, a key of :data:`APIS`.
        timestamps: ``"source"`` or ``"capture"`` (module docstring).
        pace: read a file at its frame rate (``None``: yes for files, no for live sources).
        loop: start a file again at its end instead of losing the camera.
    """

    source: str
    calibration: str | None = None
    api: str = "any"
    timestamps: str = "source"
    pace: bool | None = None
    loop: bool = False

    @classmethod
    def from_params(cls, params: Mapping[str, Any], services_path: str | None = None) -> CaptureSpec | None:
        """The spec of a driver's params (``None`` when they name no ``source``: the frame server).

        Raises:
            ValueError: an unknown ``api`` or ``timestamps``.
        """
        if "source" not in params:
            return None
        source = str(params["source"])
        base = os.path.dirname(services_path) if services_path and not services_path.startswith("<") else ""
        if _is_file(source) and not os.path.isabs(source):
            source = os.path.join(base, source)
        calibration = params.get("calibration")
        if calibration is not None and not os.path.isabs(str(calibration)):
            calibration = os.path.join(base, str(calibration))
        api = str(params.get("api", "any"))
        if api not in APIS:
            raise ValueError(f"camera api {api!r} is none of {', '.join(APIS)}")
        stamps = str(params.get("timestamps", "source"))
        if stamps not in ("source", "capture"):
            raise ValueError(f"camera timestamps {stamps!r} is neither 'source' nor 'capture'")
        pace = params.get("pace")
        return cls(source, None if calibration is None else str(calibration), api, stamps,
                   None if pace is None else bool(pace), bool(params.get("loop", False)))

    @property
    def is_file(self) -> bool:
        """True for a video file (paced, lost at its end unless looped)."""
        return self.api != "gstreamer" and _is_file(self.source)

    def open(self) -> CaptureClient:
        """Open the source (see :class:`CaptureClient`)."""
        return CaptureClient(self)


def _is_file(source: str) -> bool:
    return not (source.isdigit() or source.startswith("/dev/") or source.startswith(_URL_SCHEMES)
                or "!" in source)


class CaptureClient:
    """Frames from an OpenCV ``VideoCapture`` source, with the frame grabber's interface.

    Blocking, like :class:`~services.devices.framegrabber.FrameClient`: the nodes call it from a
    grabbing thread.

    Args:
        spec: the source and its options.

    Raises:
        ConnectionError: the source cannot be opened, or the calibration file cannot be read.
    """

    def __init__(self, spec: CaptureSpec) -> None:
        self.spec = spec
        self._lock = threading.Lock()
        calibration: dict[str, Any] = {}
        if spec.calibration is not None:
            try:
                calibration = json.loads(Path(spec.calibration).read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise ConnectionError(f"camera calibration {spec.calibration}: {exc}") from exc
            if not isinstance(calibration, dict):
                raise ConnectionError(f"camera calibration {spec.calibration}: not a JSON object")
            calibration = dict(calibration.get("info", calibration))
        source: str | int = int(spec.source) if spec.source.isdigit() else spec.source
        if spec.is_file and not os.path.exists(spec.source):
            raise ConnectionError(f"camera source {spec.source}: no such file")
        self._cap = cv2.VideoCapture(source, APIS[spec.api])
        if not self._cap.isOpened():
            raise ConnectionError(f"camera source {spec.source!r} cannot be opened (OpenCV back end {spec.api})")
        width = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self._info = {**calibration, "width": width or calibration.get("width"),
                      "height": height or calibration.get("height"),
                      "fps": fps if fps > 0 else calibration.get("fps", 25.0), "source": spec.source}
        self._pace = spec.is_file if spec.pace is None else spec.pace
        self._seq = -1
        self._last_t = -float("inf")
        self._t_base = 0.0  # added to a looped file's times, s
        self._clock0: tuple[float, float] | None = None  # (source t, monotonic) of the first paced frame

    def grab(self, after: int = -1, timeout: float = 1.0) -> Frame | None:
        """The next frame of the source (every frame in order: ``after`` only has it numbered after).

        Returns:
            The frame (seq counting from 0 over the connection; ``t`` as the module docstring says).

        Raises:
            ConnectionError: the source ended (a file without ``loop``) or failed.
        """
        with self._lock:
            ok, image = self._cap.read()
            if not ok and self.spec.is_file and self.spec.loop:
                self._t_base = self._last_t + 1.0 / float(self._info["fps"])
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                ok, image = self._cap.read()
            if not ok or image is None:
                raise ConnectionError(f"camera source {self.spec.source}: "
                                      + ("end of the video" if self.spec.is_file else "no frame (source lost)"))
            t_wall = time.time()
            captured = time.monotonic()
            t = captured
            if self.spec.timestamps == "source":
                ms = float(self._cap.get(cv2.CAP_PROP_POS_MSEC))
                src = self._t_base + ms / 1000.0
                if (ms > 0 or self._seq < 0 or self._t_base > 0) and src > self._last_t:
                    t = src
            self._seq = max(self._seq + 1, after + 1)
            self._last_t = t
            if self._pace:
                if self._clock0 is None:
                    self._clock0 = (t, captured)
                delay = self._clock0[1] + (t - self._clock0[0]) - time.monotonic()
                if delay > 0:
                    time.sleep(min(delay, 1.0))
            if image.ndim == 2:
                image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
            return Frame(seq=self._seq, t=float(t), image=np.ascontiguousarray(image), t_wall=t_wall)

    def info(self, timeout: float = 2.0) -> dict[str, Any]:
        """The calibration file's info map, with the source's ``width``, ``height``, ``fps`` and ``source``."""
        return dict(self._info)

    def close(self) -> None:
        """Release the source."""
        with self._lock:
            self._cap.release()


def open_grabber(spec: CaptureSpec | None, host: str, port: int,
                 connect_timeout: float = 2.0) -> FrameClient | CaptureClient:
    """The grabber a camera driver reads: its OpenCV source if it has one, else the frame server.

    Raises:
        ConnectionError, OSError: the source or the server cannot be reached.
    """
    if spec is not None:
        return spec.open()
    return FrameClient(host, port, connect_timeout=connect_timeout)


def record(frames: Iterable[Frame], path: str | os.PathLike[str], *, fps: float, info: Mapping[str, Any],
           detect: Callable[[Frame], Any] | None = None) -> int:
    """Write frames to a lossless video (FFV1 in Matroska) and its calibration JSON beside it.

    The JSON (``PATH`` with suffix ``.json``) holds ``{"info": info, "fps": fps, "frames": [{"seq",
    "t", "detection"}]}``: each frame's number and time as the source gave them, and what ``detect``
    (if given) returned for it, so that a recording carries what its live frames gave.

    Returns:
        The number of frames written.

    Raises:
        OSError: the video cannot be written.
    """
    out = Path(path)
    writer: cv2.VideoWriter | None = None
    rows: list[dict[str, Any]] = []
    try:
        for frame in frames:
            h, w = frame.image.shape[:2]
            if writer is None:
                writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h))
                if not writer.isOpened():
                    raise OSError(f"cannot write {out} (OpenCV's FFV1 writer)")
            writer.write(frame.image)
            rows.append({"seq": frame.seq, "t": frame.t, "detection": detect(frame) if detect else None})
    finally:
        if writer is not None:
            writer.release()
    out.with_suffix(".json").write_text(json.dumps({"info": dict(info), "fps": fps, "frames": rows}, indent=1)
                                        + "\n", encoding="utf-8")
    return len(rows)
