"""Catching benchmark: seeded throws in lock-step time, then set-point latency across processes.

Usage::

    python bench/catching.py --throws 200 --seed 1 [--json] [--plot FILE.png] [--latency-seconds 8]
        [--fps 50] [--noise-px 0.5] [--locator threshold|bgdiff] [--model-error 0.0]

Phase 1 (one process, lock-step simulated time, 1 kHz): for every throw of a seeded thrower the
pybullet world rolls the ball; the analytic camera renders it at ``--fps`` twice, without noise and
with 0.5 px position noise plus grey-level noise; each image goes through the locator, the
calibrated pixel → table map and the rolling-ball predictor (services.catching.vision); the noisy
pipeline's set points (in the robot base frame) drive services.catching.robot.motion_control's servo, whose joint
targets go as CiA 402 RPDOs over the simulated CAN bus to the simulated drives (sim.catching.drives), stepped
in-process every 1 ms.

Measured per throw: the lateral prediction error at the catch line of the last prediction made at
least 0.3 s before the ball crossed it (noiseless and noisy), the lead (how long before the crossing
the prediction came and stayed within 5 mm), the geometric catch (last set point within the cup's
capture radius of the true crossing, and the cup's rim within that radius of the ideal catch point
when the ball reaches the rim height), the physical catch (the ball ends in the cup, crossfire beam
cut), and the frames that yielded a set point (counted from the frame where the predictor has its
minimum number of observations until the crossing).

Baselines in the same run: a constant-velocity predictor (no deceleration model) on the same
detections, and a cup that stays at the home pose.

``--model-error E`` scales the predictor's deceleration model by 1 + E (robustness to a
mis-calibrated model; the simulated ball keeps the true one).

Phase 2 (real time, three processes on 127.0.0.1): the sim (``coordinator.commands.sim catching``,
world paced to the wall clock, analytic camera at the demo's 320×240 and 25 frames/s by default), a
vision node (``services.node``: camera driver and ``predict``, which publishes each set point as an
event of the node) and this process as the motion side (a :class:`services.catching.setpoints.SetPointSubscription`
on an authenticated node link, as the motion node has; it calls ``predict`` once per throw).
Latency = receive time of a set point minus the capture time of its frame (same host clock), split
into capture → sent (frame transfer and image processing) and sent → received (the node protocol).
``--latency-seconds`` is wall time. ``--throws 0`` runs phase 2 alone.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from services.devices import cia402 as cf
from services.catching.robot import motion_control, puma560
from services.catching.vision import (
    BallTracker,
    RollingModel,
    RollingPredictor,
    calibration_points,
    locate_bgdiff,
    locate_threshold,
)
from sim.catching.camera import (
    AnalyticRenderer,
    calibrate,
    overhead_camera,
)
from sim.catching.drives import SimDrives
from sim.drives import POSITION_UNIT
from sim.catching.world import CatchingWorld, Thrower
from sim.world import World

LEAD_TOLERANCE_M = 0.005
AHEAD_S = 0.3


@dataclass
class ThrowResult:
    speed: float
    y_true: float
    t_cross: float
    y_pred_ahead: dict[str, float | None]
    t_pred_ahead: dict[str, float | None]
    y_last_setpoint: float | None
    lead_s: float
    geometric: bool
    physical: bool
    static_cup: bool
    frames_counted: int
    frames_with_setpoint: int
    unreachable: int


# --------------------------------------------------------------------------------------------------
# in-process drives (deterministic in lock-step: no sockets)
# --------------------------------------------------------------------------------------------------
class InProcessDrives:
    """The motion side of the CAN bus without sockets: frames go straight onto the SimBus."""

    def __init__(self, drives: SimDrives, world: World) -> None:
        self.drives = drives
        self.world = world
        self.port = drives.bus.connect()
        self.layouts: dict[int, Any] = {}

    def rpdo(self, node: int, cw: int, q: float) -> cf.CanFrame:
        """RPDO1 of drive ``node`` with the mapping of its EDS: controlword and target, rad."""
        if node not in self.layouts:
            self.layouts[node] = self.drives.rpdo_layout(node)
        return cf.CanFrame(0x200 + node, self.layouts[node].pack([cw, round(q / POSITION_UNIT)]))

    def enable(self) -> None:
        self.port.send(cf.nmt_frame(cf.NmtCommand.START, 0))
        self.world.step(10)
        q = self.drives.positions()
        for cw in (cf.Controlword.FAULT_RESET, cf.Controlword.SHUTDOWN, cf.Controlword.SWITCH_ON,
                   cf.Controlword.ENABLE_OPERATION):
            for node, qi in zip(cf.DRIVE_IDS, q):
                self.port.send(self.rpdo(node, cw, qi))
            self.world.step(6)
        self.port.recv_all()
        states = self.drives.states()
        if any(s is not cf.DriveState.OPERATION_ENABLED for s in states):
            raise RuntimeError(f"drives not enabled: {states}")

    def send_targets(self, q: np.ndarray) -> None:
        for node, qi in zip(cf.DRIVE_IDS, q):
            self.port.send(self.rpdo(node, cf.Controlword.ENABLE_OPERATION, float(qi)))
        self.port.recv_all()


def _render_on_table(renderer: AnalyticRenderer, z: float, x: float, y: float) -> np.ndarray:
    return renderer.render((x, y, z))


def rim_position(world_pose_flange: np.ndarray) -> np.ndarray:
    return world_pose_flange[:3, 3] + puma560.CUP_RIM_OFFSET * world_pose_flange[:3, 2]


# --------------------------------------------------------------------------------------------------
# phase 1: lock-step throws
# --------------------------------------------------------------------------------------------------
def run_throws(
    n: int, seed: int, fps: float, noise_px: float, locator: str, model_error: float = 0.0
) -> tuple[list[ThrowResult], dict[str, Any]]:
    world = World()
    cw = CatchingWorld(world, robot=True)
    geo = motion_control.CatchGeometry()
    tf = cw.table_to_base()
    cam = overhead_camera()
    renderers = {
        "noiseless": AnalyticRenderer(cam, intensity_sigma=0.0, seed=seed),
        "noisy": AnalyticRenderer(cam, intensity_sigma=2.0, position_sigma_px=noise_px, seed=seed + 1),
    }
    z = cw.ball_plane_z
    homs = {
        k: calibrate(functools.partial(_render_on_table, r, z), calibration_points(1.5, 0.76), 16)
        for k, r in renderers.items()
    }
    a, b = cw.ball.rolling_decel_params()
    model = RollingModel(a * (1.0 + model_error), b * (1.0 + model_error))
    pipelines = {
        k: BallTracker(homs[k], RollingPredictor(model, position_sigma=0.001)) for k in renderers
    }
    baseline = BallTracker(homs["noisy"], RollingPredictor(RollingModel(0.0, 0.0), position_sigma=0.001))
    backgrounds = {k: r.noiseless_background() for k, r in renderers.items()}

    q_home = motion_control.home_pose(geo)
    cw.set_joint_positions(q_home)
    drives = SimDrives()
    assert cw.robot_id is not None
    drives.attach(world.client, cw.robot_id, cw.joint_indices, crossfire=cw.crossfire)
    world.add_step_hook(drives.step)
    bus = InProcessDrives(drives, world)
    bus.enable()
    servo = motion_control.CatchServo(q_home, geo)
    home_rim = rim_position(puma560.fk(q_home))

    thrower = Thrower(seed)
    frame_steps = max(1, round(1.0 / fps / world.dt))
    cycle_steps = round(motion_control.CYCLE_S / world.dt)
    capture = puma560.CUP_INNER_RADIUS - cw.ball.radius
    t_fall = math.sqrt(2.0 * (cw.ball.radius + geo.rim_drop) / motion_control.G)
    results: list[ThrowResult] = []
    time_err_model: list[float] = []
    time_err_baseline: list[float] = []
    lat_err_baseline: list[float] = []
    wall0 = time.perf_counter()
    for i in range(n):
        if i and i % 25 == 0:
            print(f"... {i}/{n} throws, {time.perf_counter() - wall0:.0f} s", file=sys.stderr, flush=True)
        spec = thrower.next()
        cw.park()
        for p in (*pipelines.values(), baseline):
            p.predictor.reset()
        world.step(5)
        cw.launch(spec)
        t0 = world.t
        preds: dict[str, list[tuple[float, float, float]]] = {k: [] for k in pipelines}
        base_preds: list[tuple[float, float, float]] = []
        last_sp: tuple[float, float, float] | None = None
        frames_counted = frames_with_sp = unreachable = 0
        rim_at_catch: np.ndarray | None = None
        t_end = t0 + 6.0
        k = 0
        while world.t < t_end:
            if k % cycle_steps == 0:
                bus.send_targets(servo.step())
            if k % frame_steps == 0:
                pos, _ = cw.ball_state()
                on_table = cw.ball_on_table()
                visible = on_table
                for name, r in renderers.items():
                    img = r.render(pos if visible else None)
                    det = (
                        locate_threshold(img, world.t) if locator == "threshold"
                        else locate_bgdiff(img, backgrounds[name], world.t)
                    )
                    pred = pipelines[name].observe(det, world.t)
                    if name == "noisy":
                        if visible and pipelines[name].predictor.count >= pipelines[name].predictor.min_points:
                            frames_counted += 1
                            frames_with_sp += pred is not None
                        bpred = baseline.observe(det, world.t)
                        if bpred is not None:
                            base_preds.append((world.t, bpred.y, bpred.t))
                        if pred is not None:
                            x_b, y_b, _ = tf.point(pred.x, pred.y)
                            vx_b, vy_b = tf.vector(pred.vx, pred.vy)
                            try:
                                servo.aim(x_b, y_b, pred.t, vx_b, vy_b)
                            except puma560.UnreachableError:
                                unreachable += 1
                            last_sp = (world.t, pred.y, pred.t)
                    if pred is not None:
                        preds[name].append((world.t, pred.y, pred.t))
            world.step()
            k += 1
            cr = cw.crossing
            if cr is not None:
                if rim_at_catch is None and world.t >= cr.t + t_fall:
                    rim_at_catch = rim_position(puma560.fk(cw.joint_positions()))
                if world.t > cr.t + 0.6:
                    break
        cr = cw.crossing
        if cr is None:
            raise RuntimeError(f"throw {spec} never crossed the catch line")
        physical = cw.crossfire()
        x_b, y_b, _ = tf.point(0.0, cr.y)
        vx_b, vy_b = tf.vector(cr.vx, cr.vy)
        ideal = np.array([x_b + vx_b * t_fall, y_b + vy_b * t_fall, geo.table_z - geo.rim_drop])
        ahead_y: dict[str, float | None] = {}
        ahead_t: dict[str, float | None] = {}
        for name, lst in preds.items():
            early = [p for p in lst if p[0] <= cr.t - AHEAD_S]
            ahead_y[name] = early[-1][1] if early else None
            ahead_t[name] = early[-1][2] if early else None
        early_b = [p for p in base_preds if p[0] <= cr.t - AHEAD_S]
        if early_b and ahead_t["noisy"] is not None:
            time_err_baseline.append(early_b[-1][2] - cr.t)
            lat_err_baseline.append(early_b[-1][1] - cr.y)
            time_err_model.append(ahead_t["noisy"] - cr.t)
        lead = 0.0
        for t_p, y_p, _ in reversed([p for p in preds["noisy"] if p[0] <= cr.t]):
            if abs(y_p - cr.y) > LEAD_TOLERANCE_M:
                break
            lead = cr.t - t_p
        geometric = (
            last_sp is not None
            and abs(last_sp[1] - cr.y) <= capture
            and rim_at_catch is not None
            and float(np.linalg.norm(rim_at_catch - ideal)) <= capture
        )
        static = float(np.linalg.norm(home_rim - ideal)) <= capture
        results.append(
            ThrowResult(
                speed=spec.speed, y_true=cr.y, t_cross=cr.t - t0, y_pred_ahead=ahead_y,
                t_pred_ahead=ahead_t, y_last_setpoint=last_sp[1] if last_sp else None, lead_s=lead,
                geometric=bool(geometric), physical=bool(physical), static_cup=static,
                frames_counted=frames_counted, frames_with_setpoint=frames_with_sp,
                unreachable=unreachable,
            )
        )
    extra = {
        "wall_s": time.perf_counter() - wall0,
        "calibration_rms_m": {k: h.rms_m for k, h in homs.items()},
        "time_err_model": time_err_model,
        "time_err_baseline": time_err_baseline,
        "lat_err_baseline": lat_err_baseline,
        "drive_states": [s.value for s in drives.states()],
    }
    world.close()
    return results, extra


# --------------------------------------------------------------------------------------------------
# phase 2: real-time latency across processes
# --------------------------------------------------------------------------------------------------
VISION_SERVICES = """
[nodes.vision]
host = "127.0.0.1"
port = {node_port}

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = {{ port = {camera_port} }}

[actions.predict]
node = "vision"
impl = "services.catching.vision_node:Predict"
"""


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _subscribe_and_predict(port: int, key: bytes, seconds: float, on_sp: Any) -> None:
    """Subscribe to the vision node's set points and call ``predict`` for ``seconds`` (wall)."""
    from services.client import NodeLink
    from services.catching.setpoints import SetPointSubscription

    link = NodeLink("vision", ("127.0.0.1", port), key, name="node:motion", connect_timeout_s=30.0)
    try:
        sub = SetPointSubscription(link, on_set_point=on_sp)
        sub.start()
        await link.connect()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            sub.restart()
            await link.call("predict", {"timeout_s": 10.0}, deadline_s=20.0)
        sub.close()
    finally:
        await link.close()


def _latency_phase(seconds: float, seed: int, fps: float, size: tuple[int, int]) -> dict[str, Any]:
    """The sim (``coordinator.commands.sim catching``, analytic camera), a vision node process
    (camera driver + ``predict``), and this process as the motion side: it subscribes to the vision
    node's set points through an authenticated node link, as the motion node does, and calls
    ``predict`` once per throw for ``seconds`` of wall time."""
    import secrets
    import subprocess
    import tempfile

    latencies: list[float] = []
    vision_part: list[float] = []
    stream_part: list[float] = []

    def on_sp(sp: Any, now: float) -> None:
        latencies.append(now - sp.t_capture)
        vision_part.append(sp.t_sent - sp.t_capture)
        stream_part.append(now - sp.t_sent)

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    key = secrets.token_bytes(32)
    with tempfile.TemporaryDirectory() as tmp:
        key_file = os.path.join(tmp, "key")
        with open(key_file, "w") as fh:
            fh.write(key.hex() + "\n")
        sim = subprocess.Popen(
            [sys.executable, "-m", "coordinator.commands.sim", "catching", "--realtime", "--renderer", "analytic",
             "--width", str(size[0]), "--height", str(size[1]), "--fps", str(fps), "--seed", str(seed),
             "--throws", "0", "--interval", "0.5", "--first-throw", "1", "--after-camera-client",
             "--camera-port", "0", "--can-port", "0"],
            cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        procs = [sim]
        try:
            assert sim.stdout is not None
            while not (line := sim.stdout.readline()).startswith('{"event": "ready"'):
                if not line:
                    raise RuntimeError("the simulator exited before it was ready")
            camera_port = int(json.loads(line)["camera_port"])
            node_port = _free_port()
            services = os.path.join(tmp, "services.toml")
            with open(services, "w") as fh:
                fh.write(VISION_SERVICES.format(node_port=node_port, camera_port=camera_port))
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "services.node", "vision", "--services", services, "--key-file", key_file,
                 "--log-level", "WARNING"], cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            asyncio.run(_subscribe_and_predict(node_port, key, seconds, on_sp))
        finally:
            for p in reversed(procs):
                if p.poll() is None:
                    p.terminate()
                    try:
                        p.wait(timeout=10)
                    except subprocess.TimeoutExpired:
                        p.kill()
    arr = np.asarray(latencies)
    return {
        "setpoints": int(arr.size),
        "p50": float(np.percentile(arr, 50)) if arr.size else float("nan"),
        "p99": float(np.percentile(arr, 99)) if arr.size else float("nan"),
        "max": float(arr.max()) if arr.size else float("nan"),
        "capture_to_sent_p50": float(np.percentile(vision_part, 50)) if vision_part else float("nan"),
        "capture_to_sent_p99": float(np.percentile(vision_part, 99)) if vision_part else float("nan"),
        "sent_to_received_p50": float(np.percentile(stream_part, 50)) if stream_part else float("nan"),
        "sent_to_received_p99": float(np.percentile(stream_part, 99)) if stream_part else float("nan"),
        "image_size": list(size),
    }


# --------------------------------------------------------------------------------------------------
def _rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values else float("nan")


def summarise(results: list[ThrowResult], extra: dict[str, Any], latency: dict[str, Any] | None) -> dict[str, Any]:
    n = len(results)
    err = {
        name: [y - r.y_true for r in results if (y := r.y_pred_ahead[name]) is not None]
        for name in ("noiseless", "noisy")
    }
    counted = sum(r.frames_counted for r in results)
    rms_t_model = _rms(extra["time_err_model"])
    rms_t_base = _rms(extra["time_err_baseline"])
    out = {
        "throws": n,
        "catch_rate": sum(r.geometric for r in results) / n,
        "physical_catch_rate": sum(r.physical for r in results) / n,
        "prediction_rmse_m": _rms(err["noisy"]),
        "prediction_rmse_noiseless_m": _rms(err["noiseless"]),
        "prediction_rmse_noise_0.5px_m": _rms(err["noisy"]),
        "predictions_300ms_ahead": len(err["noisy"]),
        "prediction_lead_s": float(np.median([r.lead_s for r in results])),
        "prediction_lead_min_s": float(np.min([r.lead_s for r in results])),
        "frames_with_setpoint": sum(r.frames_with_setpoint for r in results) / max(1, counted),
        "setpoint_latency_p50_s": latency["p50"] if latency else None,
        "setpoint_latency_p99_s": latency["p99"] if latency else None,
        "setpoint_latency_max_s": latency["max"] if latency else None,
        "latency_setpoints": latency["setpoints"] if latency else 0,
        "latency_detail": latency,
        "arrival_time_rmse_s": rms_t_model,
        "baseline_constant_velocity_arrival_time_rmse_s": rms_t_base,
        "baseline_constant_velocity_lateral_rmse_m": _rms(extra["lat_err_baseline"]),
        "ratio_arrival_time_rmse_baseline_over_model": rms_t_base / rms_t_model if rms_t_model else None,
        "baseline_static_cup_catch_rate": sum(r.static_cup for r in results) / n,
        "ratio_catch_rate_servo_over_static_cup": (
            sum(r.geometric for r in results) / sum(r.static_cup for r in results)
            if any(r.static_cup for r in results) else None
        ),
        "unreachable_setpoints": sum(r.unreachable for r in results),
        "calibration_rms_m": extra["calibration_rms_m"],
        "phase1_wall_s": extra["wall_s"],
    }
    return out


def plot(results: list[ThrowResult], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for name, marker in (("noiseless", "o"), ("noisy", "x")):
        pts = [(r.y_true, r.y_pred_ahead[name]) for r in results if r.y_pred_ahead[name] is not None]
        if pts:
            a = np.asarray(pts)
            ax1.scatter(a[:, 0], a[:, 1], s=12, marker=marker, label=name)
            ax2.scatter(a[:, 0], 1000 * (a[:, 1] - a[:, 0]), s=12, marker=marker, label=name)
    lim = [-0.27, 0.27]
    ax1.plot(lim, lim, "k-", lw=0.5)
    ax1.set_xlabel("actual exit point y (m, table frame)")
    ax1.set_ylabel("predicted exit point y, >= 0.3 s ahead (m)")
    ax1.set_title("Predicted vs actual exit points")
    ax1.legend()
    ax2.axhline(0.0, color="k", lw=0.5)
    ax2.set_xlabel("actual exit point y (m)")
    ax2.set_ylabel("prediction error (mm)")
    ax2.set_title("Lateral error at the catch line")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--throws", type=int, default=200,
                    help="number of seeded throws of phase 1 (0 runs only the latency phase)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the thrower and of the noise")
    ap.add_argument("--fps", type=float, default=50.0, help="camera frame rate, frames per second")
    ap.add_argument("--noise-px", type=float, default=0.5, help="ball position noise, pixels (1-sigma)")
    ap.add_argument("--locator", choices=("threshold", "bgdiff"), default="threshold",
                    help="locator used by the pipelines of phase 1")
    ap.add_argument("--model-error", type=float, default=0.0,
                    help="relative error of the predictor's deceleration model (alpha and beta are "
                         "scaled by 1 + this), to test robustness to a mis-calibrated model")
    ap.add_argument("--latency-seconds", type=float, default=8.0,
                    help="seconds (wall) of the real-time latency phase (0 skips it)")
    ap.add_argument("--latency-width", type=int, default=320,
                    help="image width of the latency phase, pixels (default 320, as the demo)")
    ap.add_argument("--latency-height", type=int, default=240,
                    help="image height of the latency phase, pixels (default 240)")
    ap.add_argument("--latency-fps", type=float, default=25.0,
                    help="frame rate of the latency phase (default 25, as the demo)")
    ap.add_argument("--json", action="store_true", help="print the results as one JSON object")
    ap.add_argument("--plot", metavar="FILE.png", help="write a plot of predicted vs actual exit points")
    args = ap.parse_args(argv)
    results: list[ThrowResult] = []
    extra: dict[str, Any] = {}
    if args.throws > 0:
        results, extra = run_throws(args.throws, args.seed, args.fps, args.noise_px, args.locator,
                                    args.model_error)
    latency = None
    if args.latency_seconds > 0:
        size = (args.latency_width, args.latency_height)
        latency = _latency_phase(args.latency_seconds, args.seed, args.latency_fps, size)
    if args.throws <= 0:
        print(json.dumps({"latency": latency}, indent=2))
        return 0
    summary = summarise(results, extra, latency)
    if args.plot:
        plot(results, args.plot)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for k, v in summary.items():
            print(f"{k:55s} {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
