"""The mobile-robot testbed's physical world: floor, beacons and robot in a :class:`sim.world.World`.

Paper section 6 ("Mobile Robot Task", Fig. 2). The world frame is the floor's: x, y on the floor
(square (i, j) covers [2i, 2i+2] × [2j, 2j+2] m), z up. :class:`MobileWorld` builds

* the floor (:class:`sim.mobile.floor.PybulletFloor`) and the :class:`sim.mobile.floor.FloorMap`
  the analytic camera warps; for a TinyRenderer camera, the textured floor is built in a second,
  render-only pybullet client (:attr:`MobileWorld.render_client`) holding nothing but the floor.
  TinyRenderer does not clip triangles that cross the camera's plane, and everything taller than
  the 0.2 m high downward camera (beacons, posts, the robot's own mast and camera housing) lies
  behind that plane: in one client some frames took seconds. The downward camera sees only the
  floor, so the floor-only scene renders the same image;
* one retroreflector per interruption, its centre ``beacon.height`` above the resume point
  (:class:`sim.mobile.course.BeaconSpec`): a static cylinder, and unless hung, a post beside the
  resume point on the exit edge's line with an arm over it; the post stands on the side away from
  the next tile's turn (right of the resumed track when it goes straight on);
* the robot (:class:`sim.mobile.robot.MobileRobot`) at the start of the track, its wheel drives
  registered as a step hook.

It also gives the ground truth the benchmarks score against: the robot's pose, and where it is on
the course (tile, path length, signed cross-track offset).

Physics step: 250 Hz (dt = 4 ms) by default. A wheeled robot on a flat floor has no stiff contact
chain; the step is small enough for the 50 Hz control loop (five steps per set point) and the
drive ramp, and odometry against ground truth stays within 1 % of the distance run (see the
tests). 1 kHz would cost four times as much for no visible change.
"""

from __future__ import annotations

import math
from typing import Any

import pybullet
from pybullet_utils import bullet_client

from services.mobile.camera import GroundCamera

from ..world import World
from .course import Course, Tile
from .floor import FloorMap, FloorStyle, PybulletFloor
from .robot import MobileRobot, RobotSpec
from .sensors import (
    AnalyticCamera,
    BeaconSensor,
    BeaconSensorSpec,
    ImageNoise,
    TinyCamera,
    robot_camera,
)

__all__ = ["Beacon", "MobileWorld"]

DEFAULT_DT = 0.004
"""Physics step of the mobile world, s (250 Hz)."""


class Beacon:
    """One retroreflector as built.

    Attributes:
        tile: index of the blank tile whose resume point it marks.
        centre: (x, y, z) of the reflector's centre, m.
        resume: (x, y, heading) of the resume point and the resumed track's direction.
        body: pybullet body id of the reflector.
        post: pybullet body id of the post and arm, or None when hung.
    """

    def __init__(self, tile: int, centre: tuple[float, float, float], resume: tuple[float, float, float], body: int, post: int | None) -> None:
        self.tile = tile
        self.centre = centre
        self.resume = resume
        self.body = body
        self.post = post


class MobileWorld:
    """Floor, beacons and robot of one course (see the module docstring).

    Args:
        world: the world to build in (use ``World(dt=DEFAULT_DT)`` for 250 Hz).
        course: the course.
        robot: the robot's parameter table.
        style: floor paint and texel size.
        textured: build the textured floor for :class:`sim.mobile.sensors.TinyCamera`.
        start: robot pose (x, y, heading) to start from; default the track's start.

    Attributes:
        pb: the pybullet client.
        floor: the pybullet floor (collision plane) in the physics client.
        render_client: the floor-only client the TinyRenderer camera renders (None unless
            ``textured``); closed by :meth:`close`.
        render_floor: the textured floor in it (None unless ``textured``).
        floor_map: the floor map (for the analytic camera).
        beacons: one per interruption, in course order.
        robot: the robot.
    """

    def __init__(
        self, world: World, course: Course, *, robot: RobotSpec | None = None, style: FloorStyle | None = None,
        textured: bool = False, start: tuple[float, float, float] | None = None,
    ) -> None:
        self.world = world
        self.course = course
        self.style = style or FloorStyle()
        self.pb: Any = world.client
        self.floor = PybulletFloor(self.pb, course, self.style)
        self.render_client: Any = None
        self.render_floor: PybulletFloor | None = None
        if textured:
            self.render_client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
            self.render_floor = PybulletFloor(self.render_client, course, self.style, textured=True)
        self.floor_map = FloorMap(course, self.style)
        self.beacons = [self._build_beacon(t) for t in course.tiles if t.blank]
        self.robot = MobileRobot(self.pb, robot, start or course.start_pose(), dt=world.dt)
        world.add_step_hook(self.robot.drives.step)
        self._tile_start = []
        acc = 0.0
        for t in course.tiles:
            self._tile_start.append(acc)
            acc += course.tile_length(t)

    # --- beacons ----------------------------------------------------------------------------
    def _build_beacon(self, tile: Tile) -> Beacon:
        c, spec, pb = self.course, self.course.beacon, self.pb
        rx, ry = c.tile_exit(tile)
        th = tile.exit_heading * math.pi / 2.0
        centre = (rx, ry, spec.height)
        col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=spec.radius, height=spec.length)
        vis = pb.createVisualShape(pb.GEOM_CYLINDER, radius=spec.radius, length=spec.length, rgbaColor=[0.9, 0.9, 0.95, 1])
        body = int(pb.createMultiBody(0, col, vis, list(centre)))
        post = None
        if spec.post:
            nxt = c.tiles[tile.index + 1]
            side = -1.0 if nxt.shape != "R" else 1.0  # +1: left of the resumed track
            nx, ny = -math.sin(th) * side, math.cos(th) * side
            px, py = rx + nx * spec.post_offset, ry + ny * spec.post_offset
            top = spec.height + spec.length / 2.0
            pr = 0.02
            post_col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=pr, height=top + 0.03)
            post_vis = pb.createVisualShape(pb.GEOM_CYLINDER, radius=pr, length=top + 0.03, rgbaColor=[0.3, 0.3, 0.3, 1])
            arm_len = spec.post_offset
            arm_half = [arm_len / 2.0, 0.01, 0.01]
            arm_col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=arm_half)
            arm_vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=arm_half, rgbaColor=[0.3, 0.3, 0.3, 1])
            yaw = math.atan2(ry - py, rx - px)
            post = int(
                pb.createMultiBody(
                    0, post_col, post_vis, [px, py, (top + 0.03) / 2.0],
                    linkMasses=[0.0], linkCollisionShapeIndices=[arm_col], linkVisualShapeIndices=[arm_vis],
                    linkPositions=[[arm_len / 2.0 * math.cos(yaw), arm_len / 2.0 * math.sin(yaw), (top - 0.01) / 2.0]],
                    linkOrientations=[pb.getQuaternionFromEuler([0.0, 0.0, yaw])],
                    linkInertialFramePositions=[[0, 0, 0]], linkInertialFrameOrientations=[[0, 0, 0, 1]],
                    linkParentIndices=[0], linkJointTypes=[pb.JOINT_FIXED], linkJointAxis=[[0, 0, 1]],
                )
            )
        return Beacon(tile.index, centre, (rx, ry, th), body, post)

    # --- robot ------------------------------------------------------------------------------
    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the robot frame, m and rad."""
        return self.robot.pose()

    def set_wheel_velocities(self, left: float, right: float) -> None:
        """Velocity set points of the wheel drives, rad/s (applied from the next physics step)."""
        self.robot.drives.set_velocity(left, right)

    def encoders(self) -> tuple[float, float]:
        """(left, right) wheel encoder angles, rad."""
        return self.robot.drives.encoders()

    # --- sensors ----------------------------------------------------------------------------
    def camera_model(self, **kw: Any) -> GroundCamera:
        """The robot's downward camera model (keyword arguments of :func:`robot_camera`)."""
        return robot_camera(self.robot.spec, **kw)

    def analytic_camera(self, camera: GroundCamera | None = None, *, noise: ImageNoise | None = None, seed: int = 0) -> AnalyticCamera:
        """An analytic camera on the robot."""
        return AnalyticCamera(camera or self.camera_model(), self.floor_map, noise=noise, seed=seed)

    def tiny_camera(self, camera: GroundCamera | None = None, *, noise: ImageNoise | None = None, seed: int = 0) -> TinyCamera:
        """A TinyRenderer camera on the robot (build the world with ``textured=True``)."""
        if self.render_client is None:
            raise RuntimeError("the TinyRenderer camera needs a world built with textured=True")
        return TinyCamera(camera or self.camera_model(), self.render_client, noise=noise, seed=seed)

    def beacon_sensor(self, spec: BeaconSensorSpec | None = None, *, seed: int = 0) -> BeaconSensor:
        """The beacon sensor on the robot, seeing this world's reflectors."""
        return BeaconSensor(self.pb, [(b.body, b.centre) for b in self.beacons], self.robot.spec, spec, seed=seed)

    # --- ground truth -----------------------------------------------------------------------
    def where(self, x: float | None = None, y: float | None = None) -> tuple[Tile, float, float] | None:
        """(tile, path length from the start, signed cross-track offset + left) of a floor point
        (default: the robot's axle midpoint), or None off the course's squares."""
        if x is None or y is None:
            x, y, _ = self.pose()
        tile = self.course.tile_at(x, y)
        if tile is None:
            return None
        s, off = self.course.project(tile, x, y)
        return tile, self._tile_start[tile.index] + s, off

    def close(self) -> None:
        """Disconnect the render-only client (the physics world is closed by its owner)."""
        if self.render_client is not None:
            try:
                self.render_client.disconnect()
            except pybullet.error:
                pass
            self.render_client = None
