"""Actions of the vision node of the catching testbed: locate the ball, predict the catch (paper §6).

The actions read frames from the node's camera driver, :class:`services.catching.camera.CameraDriver`
(``services.catching.vision_node:CameraDriver`` still names it, for services files written before the
driver had its own module).

* Three alternative primitive actions of the *locate ball* primitive task, with different cost and
  reliability (paper §2 and §4): :class:`LocateThreshold`, :class:`LocateBgdiff`,
  :class:`LocateAverage` (k frames). Each waits for the ball on the table (params ``timeout_s``,
  default 10, seconds of camera time) and returns ``success`` with ``{"x", "y", "t", "u", "v", "seq", "frames"}`` (table
  frame, m) once found and inside the table, ``failure`` when no ball was seen in time (``reason``
  in the value says so), ``error`` when the camera is lost. Cost = measured processing time, s (CPU time of the image processing,
  ``frames`` in the value). With param ``spec_m`` the result is judged against a specification
  (see *Location within specification* below); without it any detection on the table is a success.
* :class:`Predict` (primitive task *predict*): tracks the ball frame by frame, predicts where and
  when it crosses the catch line, and publishes each prediction as a set point (table frame, as
  :class:`services.catching.setpoints.CatchSetPoint` specifies; the motion node turns it into its base frame) on
  the node's event topic ``setpoints`` (param ``topic``), to which the motion node subscribes
  through its authenticated node link (:mod:`services.catching.setpoints`); each prediction is also the
  call's feedback (``y`` m and ``t`` s where and when the ball crosses the catch line, their standard
  deviations ``sigma_y``, ``sigma_t``, set points sent and frames seen). ``success`` once the ball has
  crossed, with the last prediction; ``failure`` when the ball stops or vanishes before the line;
  ``error`` when the camera is lost. If the node hosts no camera driver (the action was moved to
  another node in services.toml), it opens its own connection to the camera server (params
  ``camera_host``, ``camera_port``).

Location within specification. The node has no ground truth, so a location is judged by its
consistency with the ball's track over the next frames: after a detection at time t, the action
locates the ball in the next ``verify_frames`` frames (param, default 10) with the threshold locator,
fits x(t) and y(t) each by a least-squares straight line (constant velocity: over 0.2 s at 50
frames/s the ball's deceleration moves it by under 1 mm) and evaluates the fit at t
(:func:`track_residual`). The location is within specification when this residual is at most
``spec_m`` (param, m). Otherwise, or when the ball is seen in fewer than 3 of those frames, the action
returns ``failure`` with the outcome ``no_ball`` (the name the catching net's *no ball seen* transition
expects) and ``{"reason": "out_of_spec" | "track_lost", "residual_m"}`` in the value; a success carries
``residual_m`` too. The verification's own processing time is not part of the cost (it judges the
locator, it is not the locator).

The calibration (homography, robot base pose, rolling model) comes from the camera server's info
map (:class:`services.catching.camera.VisionConfig`).
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Any

import numpy as np

from services.action import CallContext, PrimitiveAction
from services.catching.camera import (
    DEFAULT_CAMERA_PORT,
    CameraDriver,
    CameraLink,
    CameraLostError,
    VisionConfig,
    camera_of,
)
from services.devices.framegrabber import Frame
from services.errors import ActionError
from services.results import ActionResult, Status
from services.catching.setpoints import SETPOINT_TOPIC, CatchSetPoint
from services.catching.vision import (
    BallTracker,
    Detection,
    RollingPredictor,
    locate_average,
    locate_bgdiff,
    locate_threshold,
)

__all__ = [
    "VERIFY_FRAMES",
    "CameraDriver",
    "LocateAverage",
    "LocateBgdiff",
    "LocateThreshold",
    "Predict",
    "track_residual",
]

VERIFY_FRAMES = 10
"""Default number of frames after a detection used to judge it against ``spec_m``."""

WALL_BACKSTOP = 3.0
"""Timeouts (``timeout_s``) run on the camera clock (simulated time in the simulation, which a
loaded machine slows down, so that a demo's outcome does not depend on the machine's load); this
many times as much wall time ends the wait anyway."""


def track_residual(location: tuple[float, float, float],
                   track: list[tuple[float, float, float]]) -> float:
    """Distance between a located ball position and the ball's track fitted over other frames.

    The track's x(t) and y(t) are each fitted by a least-squares straight line and evaluated at the
    location's time (linear regression; over a few tenths of a second a rolling ball's path is a
    constant-velocity line to well under a millimetre, see :mod:`sim.catching.world`). Pure.

    Args:
        location: (t, x, y) of the located ball: s, and table-frame m.
        track: (N, 3) list of (t, x, y) detections of the ball in other frames, N >= 3, with at
            least two distinct times.

    Returns:
        The residual, m (Euclidean, in the table plane).

    Raises:
        ValueError: with fewer than 3 track points or a single distinct time.
    """
    pts = np.asarray(track, dtype=float).reshape(-1, 3)
    if len(pts) < 3:
        raise ValueError(f"track_residual needs >= 3 track points, got {len(pts)}")
    t = pts[:, 0]
    if float(np.ptp(t)) <= 0.0:
        raise ValueError("track_residual needs track points at two different times at least")
    t0, x0, y0 = (float(v) for v in location)
    tm = float(t.mean())
    design = np.column_stack([np.ones_like(t), t - tm])
    coef, *_ = np.linalg.lstsq(design, pts[:, 1:], rcond=None)
    fit = coef[0] + coef[1] * (t0 - tm)
    return float(math.hypot(x0 - float(fit[0]), y0 - float(fit[1])))


# --------------------------------------------------------------------------------------------------
# locate
# --------------------------------------------------------------------------------------------------
class _Locate(PrimitiveAction):
    """Common loop of the locate actions: wait for frames until the ball is found on the table."""

    frames_needed = 1

    def locate(self, frames: list[Frame], cam: CameraDriver) -> Detection | None:
        raise NotImplementedError

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        cam = camera_of(ctx)
        try:
            await cam.reconnect_if_lost()
        except CameraLostError as exc:
            return ActionResult.error(str(exc), outcome="camera_lost")
        assert cam.link is not None and cam.config is not None
        timeout = float(params.get("timeout_s", 10.0))
        k = max(1, int(params.get("k", self.frames_needed)))
        loop = asyncio.get_running_loop()
        wall_end = loop.time() + WALL_BACKSTOP * timeout
        t_end: float | None = None  # on the camera clock
        seq = cam.link.frames[-1].seq if cam.link.frames else -1
        cpu = 0.0
        frames_used = 0
        try:
            while loop.time() < wall_end:
                batch: list[Frame] = []
                while len(batch) < k:
                    f = await cam.link.next_frame(seq)
                    seq = f.seq
                    batch.append(f)
                frames_used += len(batch)
                if t_end is None:
                    t_end = batch[0].t + timeout
                elif batch[-1].t > t_end:
                    break
                c0 = time.thread_time()
                det = self.locate(batch, cam)
                cpu += time.thread_time() - c0
                if det is None:
                    continue
                x, y = (float(v) for v in cam.config.homography.to_table([det.u, det.v]))
                if x >= cam.config.catch_x:
                    continue
                value: dict[str, Any] = {"x": x, "y": y, "t": det.t, "u": det.u, "v": det.v,
                                         "seq": seq, "frames": frames_used, "cpu_s": cpu}
                spec = params.get("spec_m")
                if spec is not None:
                    n_verify = max(3, int(params.get("verify_frames", VERIFY_FRAMES)))
                    track: list[tuple[float, float, float]] = []
                    for _ in range(n_verify):
                        f = await cam.link.next_frame(seq)
                        seq = f.seq
                        d = locate_threshold(f.image, f.t, roi=cam.config.roi)
                        if d is not None:
                            xv, yv = cam.config.homography.to_table([d.u, d.v])
                            if float(xv) < cam.config.catch_x:
                                track.append((f.t, float(xv), float(yv)))
                    if len(track) < 3:
                        value.update(reason="track_lost", residual_m=None)
                        return ActionResult(status=Status.FAILURE, outcome="no_ball", value=value, cost=cpu)
                    residual = track_residual((det.t, x, y), track)
                    value["residual_m"] = residual
                    if residual > float(spec):
                        value["reason"] = "out_of_spec"
                        return ActionResult(status=Status.FAILURE, outcome="no_ball", value=value, cost=cpu)
                return ActionResult(status=Status.SUCCESS, value=value, cost=cpu)
        except CameraLostError as exc:
            return ActionResult.error(str(exc), outcome="camera_lost", cost=cpu)
        return ActionResult(status=Status.FAILURE, outcome="no_ball", cost=cpu,
                            value={"frames": frames_used, "reason": f"no ball on the table within {timeout:g} s"})


class LocateThreshold(_Locate):
    """Locate the ball by HSV threshold + contour centroid in one frame (cheap, ~1–3 mm)."""

    def locate(self, frames: list[Frame], cam: CameraDriver) -> Detection | None:
        assert cam.config is not None
        return locate_threshold(frames[-1].image, frames[-1].t, roi=cam.config.roi)


class LocateBgdiff(_Locate):
    """Locate the ball by difference to the background image (cheapest; needs a background)."""

    def locate(self, frames: list[Frame], cam: CameraDriver) -> Detection | None:
        assert cam.link is not None
        bg = cam.link.background
        if bg is None or bg.shape != frames[-1].image.shape:
            return None
        assert cam.config is not None
        return locate_bgdiff(frames[-1].image, bg, frames[-1].t, roi=cam.config.roi)


class LocateAverage(_Locate):
    """Locate the ball in k frames (param ``k``, default 4) and average (costlier, less noisy)."""

    frames_needed = 4

    def locate(self, frames: list[Frame], cam: CameraDriver) -> Detection | None:
        assert cam.config is not None
        return locate_average([(f.image, f.t) for f in frames], roi=cam.config.roi)


# --------------------------------------------------------------------------------------------------
# predict
# --------------------------------------------------------------------------------------------------
class Predict(PrimitiveAction):
    """Track the ball, predict its catch-line crossing, stream set points to motion (see module)."""

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        own_link: CameraLink | None = None
        try:
            cam = camera_of(ctx)
            try:
                await cam.reconnect_if_lost()
            except CameraLostError as exc:
                return ActionResult.error(str(exc), outcome="camera_lost")
            link, config = cam.link, cam.config
            assert link is not None and config is not None
        except ActionError:
            own_link = CameraLink(str(params.get("camera_host", "127.0.0.1")),
                                  int(params.get("camera_port", DEFAULT_CAMERA_PORT)))
            try:
                await own_link.start(float(params.get("connect_timeout_s", 5.0)))
            except CameraLostError as exc:
                return ActionResult.error(str(exc), outcome="camera_lost")
            link, config = own_link, VisionConfig.from_info(own_link.info)
        try:
            return await self._track(params, ctx, link, config)
        finally:
            if own_link is not None:
                await own_link.close()

    async def _track(
        self, params: dict[str, Any], ctx: CallContext, link: CameraLink, config: VisionConfig
    ) -> ActionResult:
        topic = str(params.get("topic", SETPOINT_TOPIC))
        tracker = BallTracker(config.homography, RollingPredictor(config.model, catch_x=config.catch_x))
        timeout = float(params.get("timeout_s", 10.0))
        loop = asyncio.get_running_loop()
        start = loop.time()
        t_first: float | None = None  # camera clock
        seq = link.frames[-1].seq if link.frames else -1
        frames = sent = 0
        first: float | None = None
        last = None
        cpu = 0.0
        try:
            while True:
                frame = await link.next_frame(seq)
                seq = frame.seq
                frames += 1
                if t_first is None:
                    t_first = frame.t
                c0 = time.thread_time()
                det = locate_threshold(frame.image, frame.t, roi=config.roi)
                pred = tracker.observe(det, frame.t)
                cpu += time.thread_time() - c0
                if pred is not None:
                    sp = CatchSetPoint(seq=sent, t_frame=frame.t, t_capture=frame.t_wall, t_sent=time.time(),
                                  x=pred.x, y=pred.y, t=pred.t, vx=pred.vx, vy=pred.vy,
                                  sigma_y=pred.sigma_y, sigma_t=pred.sigma_t)
                    ctx.publish(topic, sp.to_dict())
                    sent += 1
                    last = pred
                    # the predicted catching point, for the operator's consoles and the journal
                    ctx.feedback({"y": pred.y, "t": pred.t, "sigma_y": pred.sigma_y, "sigma_t": pred.sigma_t,
                                  "setpoints": sent, "frames": frames})
                    if first is None:
                        first = frame.t
                seen = tracker.last_position
                past = det is None or (seen is not None and seen[1] >= config.catch_x - 0.01)
                if last is not None and past and frame.t >= last.t - 0.05:
                    xb, yb, _ = config.base.point(last.x, last.y)
                    return ActionResult(status=Status.SUCCESS, value={"y": last.y, "t": last.t, "x_base": xb, "y_base": yb,
                               "sigma_y": last.sigma_y, "sigma_t": last.sigma_t,
                               "setpoints": sent, "frames": frames,
                               "lead_s": last.t - first if first is not None else 0.0,
                               "cpu_s": cpu},
                        cost=cpu,
                    )
                if last is not None and det is None and tracker.last_position is None:
                    return ActionResult(status=Status.FAILURE, outcome="ball_lost",
                                         value={"setpoints": sent, "frames": frames}, cost=cpu)
                if frame.t - t_first > timeout or loop.time() - start > WALL_BACKSTOP * timeout:
                    return ActionResult(status=Status.FAILURE, outcome="no_crossing",
                                         value={"setpoints": sent, "frames": frames}, cost=cpu)
        except CameraLostError as exc:
            return ActionResult.error(str(exc), outcome="camera_lost", cost=cpu)
