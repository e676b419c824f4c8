"""``petrobot sim mobile``: the mobile robot's world as a process (paper section 6, Figs. 2-3).

Builds the course's floor, beacons and robot (:class:`sim.mobile.world.MobileWorld`, 250 Hz
physics) and serves the robot's hardware on ``--host`` (127.0.0.1):

* **camera and beacon sensor** — :class:`sim.frameserver.FrameServer` (``--camera-port``, 7220): the
  downward camera's grey frames at ``--fps`` (50/s; TinyRenderer or the analytic floor-map warp),
  each header carrying the latest beacon scan (``meta = {"beacon": {"seq", "t", "obs": [[azimuth,
  elevation], ...]}}``, 20 scans/s): one transport, the project's framing, grab-latest. The info
  map gives the camera model (``camera``: :class:`services.mobile.camera.GroundCamera`'s fields),
  the robot's dimensions (``robot``), ``beacon_height``, ``square``, ``track_width`` and ``course``;
* **wheel drives** — two CiA 402 drives in profile velocity mode on the simulated CAN bus
  (:class:`sim.mobile.candrives.SimWheelCan`), served by the socketcand gateway
  (:class:`sim.socketcand.CanGateway`, ``--can-port``, 7221).

Stdout gets one JSON line per event: ``ready`` (ports, course), ``pose`` (ground truth every
``--pose-every`` s: t, the wall clock it was taken at, x, y, heading, speed over the last period,
tile, path length, cross-track offset), ``drive_fault``,
``stopped`` (frames, real-time lag, camera waits). Clock: ``--realtime`` (default) paces simulated
time to the wall clock, but waits after each frame, up to ``--camera-wait-ms`` (100) of wall time,
until a connected camera client has taken it (as the catching world does: a perception node slowed
down by a loaded machine then sees every frame and the world waits for it instead of driving on
under stale set points); once a wait has run out it waits again only after the client has taken
a frame (a frozen client costs one wait, then the world runs in real time); ``--lockstep`` waits after each frame until a connected camera client took
it.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, TextIO

__all__ = ["CONDITIONS", "DEFAULT_CAMERA_PORT", "DEFAULT_CAN_PORT", "DEFAULT_COURSE", "add_arguments", "run"]

DEFAULT_CAMERA_PORT = 7220
DEFAULT_CAN_PORT = 7221
DEFAULT_COURSE = Path(__file__).resolve().parents[2] / "nets" / "courses" / "fig2.toml"
CONDITIONS = ("default", "noisy", "scuffed", "harsh", "clean")


def add_arguments(c: argparse.ArgumentParser) -> None:
    """Options of ``petrobot sim mobile``."""
    mode = c.add_mutually_exclusive_group()
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="pace simulated time to the wall clock (default; for the demo)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="no wall-clock pacing: after each frame, wait until a connected camera client took it")
    c.set_defaults(mode="realtime")
    c.add_argument("--course", default=str(DEFAULT_COURSE), help="course file (default nets/courses/fig2.toml)")
    c.add_argument("--seed", type=int, default=1, help="seed of the image and beacon noise")
    c.add_argument("--renderer", choices=("tiny", "analytic"), default="tiny",
                   help="camera back end: pybullet TinyRenderer (default) or the analytic floor-map warp")
    c.add_argument("--noise", choices=CONDITIONS, default="default", help="image condition (default: default)")
    c.add_argument("--fps", type=float, default=50.0, help="camera frame rate, 1/s (default 50)")
    c.add_argument("--duration", type=float, default=0.0, help="stop after this many simulated seconds (0: never)")
    c.add_argument("--pose-every", type=float, default=0.1, help="ground-truth pose line period, s of sim time")
    c.add_argument("--camera-port", type=int, default=None,
                   help=f"frame server port (default: the perception driver's in services.toml, else "
                        f"{DEFAULT_CAMERA_PORT}; 0: any)")
    c.add_argument("--can-port", type=int, default=None,
                   help=f"CAN gateway port (default: the wheel drives' driver's in services.toml, else "
                        f"{DEFAULT_CAN_PORT}; 0: any)")
    c.add_argument("--host", default="127.0.0.1", help="address the servers listen on (default 127.0.0.1)")
    c.add_argument("--master-wait-ms", type=float, default=100.0, metavar="MS",
                   help="wall time waited at each SYNC for the targets of a CAN master that answered "
                        "the previous one (default 100; 0: never wait)")
    c.add_argument("--camera-wait-ms", type=float, default=100.0, metavar="MS",
                   help="--realtime: wall time waited after each frame for a connected camera client to take "
                        "it (default 100; 0: never wait), so that a perception node slowed down by a loaded "
                        "machine sees every frame instead of the world running away from it")


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run the mobile world until stopped (or ``--duration``); its event lines go to ``out``
    (default: stdout). Returns the exit code."""
    from services.devices.framegrabber import Frame
    from sim.process import WorldProcess
    from sim.world import ClockMode, World

    from .candrives import SimWheelCan
    from .course import CourseError
    from .coursefile import load_course
    from .sensors import ImageNoise
    from .world import DEFAULT_DT, MobileWorld

    try:
        course = load_course(args.course)
    except (CourseError, OSError) as exc:
        print(f"petrobot sim mobile: {exc}", file=sys.stderr)
        return 2
    noise = {
        "default": ImageNoise(), "clean": ImageNoise(sigma=0.0, blur_px=0.0, gain_sigma=0.0, vignetting=0.0),
        "noisy": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15), "scuffed": ImageNoise(spots=3.0),
        "harsh": ImageNoise(sigma=25.0, blur_px=1.0, gain_sigma=0.15, spots=3.0),
    }[args.noise]
    world = World(dt=DEFAULT_DT, mode=ClockMode.REALTIME if args.mode == "realtime" else ClockMode.LOCKSTEP,
                  solver_iterations=10)
    with WorldProcess(world, out, camera_wait_s=args.camera_wait_ms / 1000.0, lockstep=args.mode == "lockstep",
                      skip_frozen_client=True) as proc:
        mw = MobileWorld(world, course, textured=args.renderer == "tiny")
        proc.on_close(mw.close)
        spec = mw.robot.spec
        cam_model = mw.camera_model()
        cam = (mw.tiny_camera if args.renderer == "tiny" else mw.analytic_camera)(cam_model, noise=noise, seed=args.seed)
        sensor = mw.beacon_sensor(seed=args.seed + 1)
        can = SimWheelCan(mw.robot.drives, master_wait_s=args.master_wait_ms / 1000.0)
        world.add_step_hook(can.step)
        info = {
            "camera": asdict(cam_model),
            "robot": {"wheel_radius": spec.wheel_radius, "track_width": spec.track_width,
                      "sensor_height": spec.sensor_height, "sensor_x": spec.sensor_x},
            "beacon_height": course.beacon.height, "square": course.square, "track_width": course.track_width,
            "course": course.name, "fps": args.fps,
        }
        camera_port, can_port = proc.serve(
            args.host, DEFAULT_CAMERA_PORT if args.camera_port is None else args.camera_port, info, can.bus,
            DEFAULT_CAN_PORT if args.can_port is None else args.can_port)
        world.step(25)  # let the robot settle on its wheels
        ex, ey = course.end_point()
        proc.emit("ready", mode=args.mode, host=args.host, camera_port=camera_port, can_port=can_port,
                  course=course.name, length=course.length, renderer=args.renderer, noise=args.noise,
                  end_point=[ex, ey], start=list(course.start_pose()))
        period = 1.0 / args.fps
        scan_every = 1.0 / 20.0
        next_scan = world.t
        next_pose = world.t
        scan_seq = 0
        scan: dict[str, Any] | None = None
        seq = 0
        last_xy: tuple[float, float] | None = None
        last_t = world.t
        proc.begin()
        while not proc.stopping and (args.duration <= 0 or world.t < args.duration):
            world.advance(period)
            t = world.t
            pose = mw.pose()
            if t >= next_scan - 1e-9:
                next_scan += scan_every
                obs = sensor.observe(pose, t)
                scan = {"seq": scan_seq, "t": t, "obs": [[o.azimuth, o.elevation] for o in obs]}
                scan_seq += 1
            frame = cam.grab(pose, t)
            proc.publish(Frame(seq, t, frame.image, time.time(), {"beacon": scan} if scan else None))
            seq += 1
            if t >= next_pose - 1e-9:
                next_pose += args.pose_every
                here = mw.where(pose[0], pose[1])
                speed = 0.0 if last_xy is None else math.hypot(pose[0] - last_xy[0], pose[1] - last_xy[1]) / (t - last_t)
                last_xy, last_t = (pose[0], pose[1]), t
                proc.emit("pose", t=round(t, 4), wall=time.time(), x=pose[0], y=pose[1], heading=pose[2], v=speed,
                          tile=None if here is None else here[0].index, blank=None if here is None else here[0].blank,
                          s=None if here is None else here[1], offset=None if here is None else here[2])
            proc.report_faults(can)
        proc.stopped(can)
        return 0
