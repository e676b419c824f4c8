"""``petrobot sim catching``: the catching testbed's physical world as a process (paper section 6, Fig. 1).

Runs the pybullet world at 1 kHz with the table, the thrower, the ball, the PUMA 560 with its cup and
crossfire sensor, and serves the hardware-like back ends on 127.0.0.1 (``--host`` to serve another
address, e.g. in a network namespace of its own):

* the overhead camera: :class:`sim.frameserver.FrameServer` (grab-latest frames; its info map carries
  the calibration, made at start-up by imaging the ball at known table points);
* the CAN bus with the six joint drives and the crossfire I/O module: a socketcand-protocol
  gateway (:class:`sim.socketcand.CanGateway`) for python-can's ``socketcand`` interface.

Clock modes: ``--realtime`` (default) paces simulated time to the wall clock, but waits after each
camera frame, up to ``--camera-wait-ms`` of wall time, until a connected camera client has taken it
(so that a vision node on a loaded machine sees every frame and a throw looks the same each time);
``--lockstep`` runs without wall-clock pacing and waits, after each camera frame, until a connected
camera client has taken it (so a slow vision node slows the world down instead of missing frames).
The pixel noise restarts from (``--seed``, throw number) at each throw.

The CAN bus is paced to the motion node's CAN master: at each SYNC the sim waits up to
``--master-wait-ms`` of wall time for the targets of a master that answered the previous SYNC
(:class:`sim.catching.drives.SimDrives`), so that the sim's own bursts of stepping after rendering a camera
frame are not charged to the master; a silent master is not waited for (the drives' watchdogs act).

The thrower rolls a ball every ``--interval`` seconds of simulated time. Stdout gets one JSON line
per event: ``ready`` (ports), ``throw``, ``crossing`` (ground truth of the catch-line crossing, table
and robot base frames), ``result`` (``caught``: the ball ended in the cup), ``arm`` (ground truth of
the arm every ``--arm-every`` s of simulated time, when asked: bus time, the wall clock it was taken
at, each joint's speed over the last camera period in rad/s), ``drive_fault`` (a
drive's fault: bus time, node, EMCY code, reason, the joint's speed, and ``stop_s``, how long its
quick stop took, once at rest) and ``stopped`` (frames, throws, the worst real-time lag, the
master waits that ran out).
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any, TextIO

__all__ = ["DEFAULT_CAMERA_PORT", "DEFAULT_CAN_PORT", "add_arguments", "run"]

DEFAULT_CAMERA_PORT = 7210
DEFAULT_CAN_PORT = 7211
#: a joint within this of its home angle counts as home for --throw-when-home, rad
HOME_TOLERANCE_RAD = 0.02


def add_arguments(c: argparse.ArgumentParser) -> None:
    """Options of ``petrobot sim catching``."""
    mode = c.add_mutually_exclusive_group()
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="pace simulated time to the wall clock (default; for the demo)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="no wall-clock pacing: after each camera frame, wait until a connected "
                           "camera client has taken it")
    c.set_defaults(mode="realtime")
    c.add_argument("--seed", type=int, default=1, help="seed of the thrower and of the pixel noise")
    c.add_argument("--throws", type=int, default=0,
                   help="number of balls to throw, then keep running idle (0: throw forever)")
    c.add_argument("--interval", type=float, default=6.0,
                   help="simulated seconds between throws (default 6)")
    c.add_argument("--throw-when-home", type=float, default=0.0, metavar="S",
                   help="throw only once the PUMA has rested at its home pose for S simulated seconds, "
                        "as a person waits for the robot to be ready (default 0: do not wait)")
    c.add_argument("--first-throw", type=float, default=3.0,
                   help="simulated time of the first throw, s (default 3)")
    c.add_argument("--after-camera-client", action="store_true",
                   help="count --first-throw from the moment the first camera client connects "
                        "(so that the first ball is not thrown before anyone looks)")
    c.add_argument("--duration", type=float, default=0.0,
                   help="stop after this many simulated seconds (0: run until stopped)")
    c.add_argument("--renderer", choices=("tiny", "analytic"), default="tiny",
                   help="camera back end: pybullet TinyRenderer (default) or the fast analytic one")
    c.add_argument("--width", type=int, default=320, help="image width, pixels (default 320)")
    c.add_argument("--height", type=int, default=240, help="image height, pixels (default 240)")
    c.add_argument("--fps", type=float, default=25.0, help="camera frame rate, 1/s (default 25)")
    c.add_argument("--noise", type=float, default=2.0,
                   help="grey-level pixel noise sigma (default 2)")
    c.add_argument("--camera-port", type=int, default=None,
                   help=f"TCP port of the camera frame server (default: the camera driver's in services.toml, "
                        f"else {DEFAULT_CAMERA_PORT}; 0: any)")
    c.add_argument("--can-port", type=int, default=None,
                   help=f"TCP port of the socketcand CAN gateway (default: the PUMA driver's in services.toml, "
                        f"else {DEFAULT_CAN_PORT}; 0: any)")
    c.add_argument("--host", default="127.0.0.1",
                   help="address the camera server and the CAN gateway listen on (default 127.0.0.1)")
    c.add_argument("--arm-every", type=float, default=0.0, metavar="S",
                   help="ground-truth arm line period (joint speeds), s of simulated time (default 0: none)")
    c.add_argument("--camera-wait-ms", type=float, default=100.0, metavar="MS",
                   help="--realtime: wall time waited after each frame for a connected camera client "
                        "to take it (default 100; 0: never wait)")
    c.add_argument("--master-wait-ms", type=float, default=100.0, metavar="MS",
                   help="wall time waited at each SYNC for the targets of a CAN master that answered "
                        "the previous one (default 100; 0: never wait)")



def _port(given: int | None, default: int) -> int:
    return default if given is None else given


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run the catching world until stopped (or ``--duration``); its event lines go to ``out``
    (default: stdout). Returns the exit code."""
    import numpy as np

    from services.catching.robot import motion_control
    from services.catching.vision import calibration_points
    from sim.catching.camera import (
        AnalyticRenderer,
        TinyRenderer,
        calibrate,
        camera_info,
        overhead_camera,
    )
    from services.devices.framegrabber import Frame
    from sim.catching.drives import SimDrives
    from sim.catching.world import CatchingWorld, Thrower
    from sim.process import WorldProcess
    from sim.world import ClockMode, World

    world = World(mode=ClockMode.REALTIME if args.mode == "realtime" else ClockMode.LOCKSTEP)
    with WorldProcess(world, out, camera_wait_s=args.camera_wait_ms / 1000.0,
                      lockstep=args.mode == "lockstep") as proc:
        cw = CatchingWorld(world, robot=True)
        geo = motion_control.CatchGeometry()
        q_home = motion_control.home_pose(geo)
        cw.set_joint_positions(q_home)
        drives = SimDrives(master_wait_s=args.master_wait_ms / 1000.0)
        assert cw.robot_id is not None
        drives.attach(world.client, cw.robot_id, cw.joint_indices, crossfire=cw.crossfire)
        world.add_step_hook(drives.step)
        cam = overhead_camera(cw.table.length, cw.table.height, width=args.width, height=args.height)
        render: Any
        renderer: TinyRenderer | AnalyticRenderer
        if args.renderer == "tiny":
            tiny = TinyRenderer(cam, world.client, intensity_sigma=args.noise, seed=args.seed)
            renderer = tiny

            def render() -> np.ndarray:
                return tiny.render()

            def render_at(x: float, y: float) -> np.ndarray:
                cw.pb.resetBasePositionAndOrientation(cw.ball_id, [x, y, cw.ball_plane_z], [0, 0, 0, 1])
                return tiny.render()
        else:
            ana = AnalyticRenderer(cam, table_length=cw.table.length, table_width=cw.table.width,
                                   table_height=cw.table.height, ball_radius=cw.ball.radius,
                                   intensity_sigma=args.noise, seed=args.seed)
            renderer = ana

            def render() -> np.ndarray:
                pos, _ = cw.ball_state()
                return ana.render(pos if cw.ball_on_table() else None)

            def render_at(x: float, y: float) -> np.ndarray:
                return ana.render((x, y, cw.ball_plane_z))

        roi = cam.table_roi(cw.table.length, cw.table.width, cw.ball_plane_z)
        hom = calibrate(render_at, calibration_points(cw.table.length, cw.table.width), 4, roi=roi)
        cw.park()
        info = camera_info(cam, hom, robot_base=cw.robot_base,
                           rolling_model=cw.ball.rolling_decel_params(), fps=args.fps,
                           table_size=(cw.table.length, cw.table.width))
        camera_port, can_port = proc.serve(args.host, _port(args.camera_port, DEFAULT_CAMERA_PORT), info,
                                           drives.bus, _port(args.can_port, DEFAULT_CAN_PORT))
        server = proc.server
        assert server is not None
        proc.emit("ready", mode=args.mode, host=args.host, camera_port=camera_port, can_port=can_port,
                  calibration_rms_m=hom.rms_m, renderer=args.renderer, width=args.width,
                  height=args.height, fps=args.fps)
        tf = cw.table_to_base()
        thrower = Thrower(args.seed)
        period = 1.0 / args.fps
        seq = 0
        thrown = 0
        next_throw = math.inf if args.after_camera_client else args.first_throw
        active: dict[str, Any] | None = None
        home_since: float | None = 0.0
        q_last, t_last = cw.joint_positions(), world.t
        next_arm = 0.0
        proc.begin()
        while not proc.stopping and (args.duration <= 0 or world.t < args.duration):
            world.advance(period)
            proc.report_faults(drives)
            t_wall = time.time()
            if args.arm_every > 0:
                q = cw.joint_positions()
                if world.t >= next_arm and world.t > t_last:
                    next_arm = world.t + args.arm_every
                    qd = np.abs(q - q_last) / (world.t - t_last)
                    proc.emit("arm", t=round(world.t, 4), wall=t_wall, qd=[round(float(v), 4) for v in qd])
                q_last, t_last = q, world.t
            proc.publish(Frame(seq, world.t, render(), t_wall))
            seq += 1
            if math.isinf(next_throw) and thrown == 0 and server.client_count:
                next_throw = world.t + args.first_throw
            if args.throw_when_home > 0:
                at_home = bool(np.max(np.abs(cw.joint_positions() - q_home)) < HOME_TOLERANCE_RAD)
                if not at_home:
                    home_since = None
                elif home_since is None:
                    home_since = world.t
            robot_ready = args.throw_when_home <= 0 or (
                home_since is not None and world.t - home_since >= args.throw_when_home)
            if (active is None and robot_ready and world.t >= next_throw
                    and (args.throws <= 0 or thrown < args.throws)):
                spec = thrower.next()
                cw.launch(spec)
                thrown += 1
                renderer.reseed([args.seed, thrown])
                active = {"n": thrown, "crossed": False}
                proc.emit("throw", n=thrown, t=world.t, speed=spec.speed, heading=spec.heading,
                          x0=spec.x0, y0=spec.y0)
                next_throw = world.t + args.interval
            if active is not None:
                cr = cw.crossing
                if cr is not None and not active["crossed"]:
                    active["crossed"] = True
                    active["t_cross"] = cr.t
                    xb, yb, _ = tf.point(0.0, cr.y)
                    vxb, vyb = tf.vector(cr.vx, cr.vy)
                    proc.emit("crossing", n=active["n"], t=cr.t, y=cr.y, x_base=xb, y_base=yb,
                              vx_base=vxb, vy_base=vyb)
                done_after = active.get("t_cross", math.inf) + 1.0
                stalled = cr is None and world.t - (cw.t_launch or 0.0) > 8.0
                if world.t >= done_after or stalled:
                    proc.emit("result", n=active["n"], t=world.t, caught=bool(cw.crossfire()),
                              crossed=cr is not None)
                    cw.park()
                    active = None
        proc.stopped(drives, throws=thrown)
        return 0
