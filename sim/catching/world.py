"""The catching testbed's physical world: table, ping-pong ball, thrower, PUMA 560 with cup.

Paper section 6 ("Visual Servoing and Catching", Fig. 1): balls are rolled across a table towards a
manipulator that catches them with a cup at its end of the table.

Frames and sizes (SI units). The *table frame* is the world frame: origin on the floor below the
middle of the table's near edge (the robot's end), x pointing from the thrower towards the robot,
z up. The table top spans x in [-length, 0], y in [-width/2, width/2] at height ``height``. The
**catch line** is the near edge, x = 0: ground truth records where (y) and when (t) the ball's centre
crosses it. The robot stands beyond the edge (x > 0), its base frame given by ``robot_base``.

Ball model (a 40 mm, 2.7 g ping-pong ball): thin spherical shell, I = 2/3 m r²; pybullet's linear and
angular damping set to 0 (the default 0.04 brakes a spinning ball hard); air drag
F = -½ ρ C_d π r² |v| v applied as an external force every step; rolling resistance as a torque
μ_r·N with μ_r a length. Bullet combines rolling friction of two bodies as
``rf_a·f_b + f_a·rf_b`` (not a product), so the table's rolling friction is 0 and the ball's is
μ_r / f_table, which makes the combined coefficient on the table exactly μ_r. A ball rolling without
slipping then decelerates at

    dv/dt = -(3/5) (g μ_r / r + k v²),   k = ½ ρ C_d π r² / m,

the model :mod:`services.catching.vision.rolling` predicts with (tests check pybullet against it).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.catching.vision import PlanarTransform

from sim.world import World

__all__ = [
    "AIR_DENSITY",
    "BallSpec",
    "CatchingWorld",
    "Crossing",
    "TableSpec",
    "ThrowSpec",
    "Thrower",
]

AIR_DENSITY = 1.2
"""Density of air at about 20 °C, kg/m³."""


@dataclass(frozen=True, slots=True, kw_only=True)
class BallSpec:
    """A ping-pong ball.

    Attributes:
        radius: m (40 mm ball).
        mass: kg (2.7 g).
        drag_coefficient: C_d of a smooth sphere at Re ~ 10³–10⁴.
        rolling_friction: μ_r, a length (m); torque of rolling resistance is μ_r·N.
        lateral_friction: Coulomb friction coefficient ball–table (combined, see module docstring).
        restitution: coefficient of restitution of the ball.
    """

    radius: float = 0.020
    mass: float = 0.0027
    drag_coefficient: float = 0.47
    rolling_friction: float = 1.0e-4
    lateral_friction: float = 0.55
    restitution: float = 0.6

    @property
    def inertia(self) -> float:
        """Moment of inertia of a thin spherical shell, 2/3 m r² (kg·m²)."""
        return 2.0 / 3.0 * self.mass * self.radius**2

    @property
    def drag_k(self) -> float:
        """k = ½ ρ C_d π r² / m (1/m): drag deceleration of a free ball is k·v²."""
        return 0.5 * AIR_DENSITY * self.drag_coefficient * math.pi * self.radius**2 / self.mass

    def rolling_decel_params(self, gravity: float = 9.81) -> tuple[float, float]:
        """(α, β) of the rolling model dv/dt = -(α + β v²) for a ball rolling without slipping.

        α = (3/5) g μ_r / r in m/s², β = (3/5) k in 1/m; the factor 3/5 = 1/(1 + I/(m r²)) is the
        share of a force that goes into translation when the ball rolls (thin shell).
        """
        share = 1.0 / (1.0 + self.inertia / (self.mass * self.radius**2))
        return share * gravity * self.rolling_friction / self.radius, share * self.drag_k


@dataclass(frozen=True, slots=True, kw_only=True)
class TableSpec:
    """The rolling table: a 1.5 m × 0.76 m top at 0.76 m (ping-pong table height, half its width).

    Attributes:
        length: along x, m; the thrower is at x = -length, the catch line at x = 0.
        width: along y, m.
        height: of the top surface above the floor, m.
        thickness: of the top, m.
        lateral_friction: friction coefficient of the top (combined with the ball's, see module).
        restitution: of the top.
    """

    length: float = 1.5
    width: float = 0.76
    height: float = 0.76
    thickness: float = 0.03
    lateral_friction: float = 0.55
    restitution: float = 0.6


@dataclass(frozen=True, slots=True, kw_only=True)
class ThrowSpec:
    """One throw: where the ball starts and how it is launched.

    Attributes:
        x0, y0: start of the ball's centre on the table, m (table frame).
        speed: launch speed, m/s.
        heading: direction of travel in the table plane, rad from +x.
        rolling: True launches the ball rolling without slipping (ω = v/r); False launches it
            sliding with no spin (it then slides until friction makes it roll).
        aim_y: the y at which a straight path crosses the catch line, m (informative).
    """

    x0: float
    y0: float
    speed: float
    heading: float
    rolling: bool = True
    aim_y: float = 0.0


class Thrower:
    """A seeded thrower at the far end of the table.

    Each throw starts at x = -length + margin with y0 ~ U(-start_half_width, start_half_width), aims
    at a point of the catch line y_aim ~ U(-aim_half_width, aim_half_width) (the robot's reach) and
    launches at a speed ~ U(speed_min, speed_max). Deceleration does not bend the path (all forces on
    a rolling ball act along its velocity), so the ball leaves the table close to y_aim.

    Args:
        seed: seed of the thrower's own random generator (numpy PCG64).
        table: the table thrown across.
        speed_range: (min, max) launch speed, m/s.
        aim_half_width: half-width of the aimed band on the catch line, m.
        start_half_width: half-width of the start band at the far end, m.
        rolling: launch rolling (True) or sliding without spin (False).
    """

    def __init__(
        self,
        seed: int,
        table: TableSpec | None = None,
        *,
        speed_range: tuple[float, float] = (0.5, 1.5),
        aim_half_width: float = 0.25,
        start_half_width: float = 0.15,
        margin: float = 0.05,
        rolling: bool = True,
    ) -> None:
        self.rng = np.random.default_rng(seed)
        self.table = table or TableSpec()
        self.speed_range = speed_range
        self.aim_half_width = aim_half_width
        self.start_half_width = start_half_width
        self.margin = margin
        self.rolling = rolling

    def next(self) -> ThrowSpec:
        """Draw the next throw."""
        x0 = -self.table.length + self.margin
        y0 = float(self.rng.uniform(-self.start_half_width, self.start_half_width))
        aim = float(self.rng.uniform(-self.aim_half_width, self.aim_half_width))
        speed = float(self.rng.uniform(*self.speed_range))
        heading = math.atan2(aim - y0, -x0)
        return ThrowSpec(x0=x0, y0=y0, speed=speed, heading=heading, rolling=self.rolling, aim_y=aim)


@dataclass(frozen=True, slots=True)
class Crossing:
    """Ground truth of the ball's centre crossing the catch line x = 0.

    Attributes:
        t: simulated time of the crossing, s (linear interpolation between steps).
        y: lateral coordinate of the crossing, m (table frame).
        z: height of the centre at the crossing, m.
        vx, vy: horizontal velocity at the crossing, m/s.
    """

    t: float
    y: float
    z: float
    vx: float
    vy: float


@dataclass(slots=True)
class _ThrowState:
    spec: ThrowSpec
    t_launch: float
    crossing: Crossing | None = None
    prev: tuple[float, np.ndarray, np.ndarray] | None = None
    history: list[tuple[float, float, float, float]] = field(default_factory=list)


class CatchingWorld:
    """Table, ball, thrower, floor and (optionally) the PUMA 560 with its cup, in a :class:`World`.

    Args:
        world: the pybullet world to build in (its step hooks are used for drag and ground truth).
        table: table geometry.
        ball: ball properties.
        drag: apply air drag (turn off only to test rolling friction alone).
        robot: load the PUMA 560 from :func:`sim.catching.puma560.write_urdf` (needs that module).
        robot_base: (x, y, z, yaw) of the robot base frame (DH frame 0, on the shoulder) in the table
            frame (m, rad). The default faces the robot towards the table, its catch line 0.75 m in
            front of the shoulder and the table top 0.30 m above it, as
            :class:`services.catching.robot.motion_control.CatchGeometry` assumes.
        record_history: keep (t, x, y, z) of the ball at every step of a throw.

    Attributes:
        ball_id, table_id, floor_id: pybullet body ids.
        robot_id: body id of the PUMA, or None without robot.
        joint_indices: pybullet joint indices of joints 1..6 (with robot).
        link_index: pybullet link index by URDF link name (with robot).
    """

    def __init__(
        self,
        world: World,
        *,
        table: TableSpec | None = None,
        ball: BallSpec | None = None,
        drag: bool = True,
        robot: bool = False,
        robot_base: tuple[float, float, float, float] = (0.75, 0.0, 0.46, math.pi),
        record_history: bool = False,
    ) -> None:
        self.world = world
        self.table = table or TableSpec()
        self.ball = ball or BallSpec()
        self.drag = drag
        self.robot_base = robot_base
        self.record_history = record_history
        pb = world.client
        self.pb: Any = pb
        tb = self.table
        half = [tb.length / 2, tb.width / 2, tb.thickness / 2]
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=[0.10, 0.30, 0.18, 1])
        self.table_id = pb.createMultiBody(
            0, col, vis, [-tb.length / 2, 0.0, tb.height - tb.thickness / 2]
        )
        pb.changeDynamics(
            self.table_id, -1, lateralFriction=tb.lateral_friction, rollingFriction=0.0,
            spinningFriction=0.0, restitution=tb.restitution,
        )
        fcol = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[3.0, 3.0, 0.05])
        self.floor_id = pb.createMultiBody(0, fcol, -1, [0.0, 0.0, -0.05])
        b = self.ball
        bcol = pb.createCollisionShape(pb.GEOM_SPHERE, radius=b.radius)
        bvis = pb.createVisualShape(pb.GEOM_SPHERE, radius=b.radius, rgbaColor=[1.0, 0.55, 0.0, 1])
        self.ball_id = pb.createMultiBody(b.mass, bcol, bvis, self.parking_position())
        inertia = b.inertia
        pb.changeDynamics(
            self.ball_id, -1, localInertiaDiagonal=[inertia] * 3, linearDamping=0.0,
            angularDamping=0.0, lateralFriction=b.lateral_friction,
            rollingFriction=b.rolling_friction / tb.lateral_friction, spinningFriction=0.0,
            restitution=b.restitution,
        )
        self._throw: _ThrowState | None = None
        self._parked = True
        self.robot_id: int | None = None
        self.crossfire_fn: Callable[[], bool] | None = None
        if robot:
            self._load_robot()
        world.add_step_hook(self._before_step)

    # --- geometry -------------------------------------------------------------------------------
    def parking_position(self) -> list[float]:
        """Where an idle ball waits: on the floor far behind the thrower (out of the camera's view)."""
        return [-self.table.length - 1.0, 0.0, self.ball.radius]

    @property
    def ball_plane_z(self) -> float:
        """Height of the ball's centre while it rolls on the table, m."""
        return self.table.height + self.ball.radius

    # --- robot ----------------------------------------------------------------------------------
    def _load_robot(self) -> None:
        from . import puma560  # the robot side's module, imported only when a robot is wanted

        fd, path = tempfile.mkstemp(suffix=".urdf", prefix="puma560_")
        os.close(fd)
        try:
            puma560.write_urdf(path)
            x, y, z, yaw = self.robot_base
            orn = self.pb.getQuaternionFromEuler([0.0, 0.0, yaw])
            body, joints, links = puma560.load(self.pb, path, (x, y, z), orn)
        finally:
            os.unlink(path)
        self.robot_id = body
        self.joint_indices = joints
        self.link_index = links
        crossfire_link = links[puma560.CROSSFIRE_LINK]
        # rolling ball on the cup: Bullet's rolling-friction combination (see module docstring)
        # with the cup's rolling friction would brake the ball; the cup's own contact data stay.

        def crossfire() -> bool:
            state = self.pb.getLinkState(body, crossfire_link, computeForwardKinematics=True)
            pose = np.eye(4)
            pose[:3, :3] = np.asarray(self.pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            pose[:3, 3] = state[4]
            emitter, receiver = puma560.crossfire_beam(pose)
            centre, _ = self.ball_state()
            return puma560.beam_blocked(centre, self.ball.radius, emitter, receiver)

        self.crossfire_fn = crossfire

    def set_joint_positions(self, q: Sequence[float] | np.ndarray) -> None:
        """Teleport the robot's six joints to ``q`` (rad), at rest (for set-up, not for motion)."""
        if self.robot_id is None:
            raise RuntimeError("this catching world has no robot")
        for j, qi in zip(self.joint_indices, q, strict=True):
            self.pb.resetJointState(self.robot_id, j, float(qi), 0.0)

    def joint_positions(self) -> np.ndarray:
        """Present joint positions of the robot, (6,) rad."""
        if self.robot_id is None:
            raise RuntimeError("this catching world has no robot")
        return np.array([s[0] for s in self.pb.getJointStates(self.robot_id, self.joint_indices)])

    def table_to_base(self) -> PlanarTransform:
        """The rigid transform from the table frame to the robot base frame (DH frame 0)."""
        x, y, z, yaw = self.robot_base
        return PlanarTransform.from_base_pose(x, y, z, yaw)

    # --- throws ---------------------------------------------------------------------------------
    def launch(self, spec: ThrowSpec) -> None:
        """Put the ball at the throw's start and launch it now (simulated time ``world.t``)."""
        r = self.ball.radius
        pos = [spec.x0, spec.y0, self.ball_plane_z]
        v = [spec.speed * math.cos(spec.heading), spec.speed * math.sin(spec.heading), 0.0]
        # rolling without slipping on a plane: ω = n × v / r with n = +z
        w = [-v[1] / r, v[0] / r, 0.0] if spec.rolling else [0.0, 0.0, 0.0]
        self.pb.resetBasePositionAndOrientation(self.ball_id, pos, [0, 0, 0, 1])
        self.pb.resetBaseVelocity(self.ball_id, v, w)
        self._throw = _ThrowState(spec=spec, t_launch=self.world.t)
        self._parked = False

    def park(self) -> None:
        """Take the ball out of play (to the parking position, at rest)."""
        self.pb.resetBasePositionAndOrientation(self.ball_id, self.parking_position(), [0, 0, 0, 1])
        self.pb.resetBaseVelocity(self.ball_id, [0, 0, 0], [0, 0, 0])
        self._parked = True

    @property
    def crossing(self) -> Crossing | None:
        """Ground truth of the present throw's catch-line crossing, once it has happened."""
        return self._throw.crossing if self._throw else None

    @property
    def t_launch(self) -> float | None:
        """Simulated time at which the present throw was launched."""
        return self._throw.t_launch if self._throw else None

    @property
    def history(self) -> list[tuple[float, float, float, float]]:
        """(t, x, y, z) of the ball at each step of the present throw (if recording)."""
        return self._throw.history if self._throw else []

    def ball_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) m and linear velocity (3,) m/s of the ball's centre in the table frame."""
        pos, _ = self.pb.getBasePositionAndOrientation(self.ball_id)
        vel, _ = self.pb.getBaseVelocity(self.ball_id)
        return np.asarray(pos, dtype=float), np.asarray(vel, dtype=float)

    def ball_on_table(self) -> bool:
        """True while the ball's centre is above the table top's footprint and resting on it."""
        p, _ = self.ball_state()
        tb = self.table
        return (
            -tb.length <= p[0] <= 0.0
            and abs(p[1]) <= tb.width / 2
            and abs(p[2] - self.ball_plane_z) < 0.005
        )

    def crossfire(self) -> bool:
        """State of the cup's crossfire (light-beam) sensor: True while it sees the ball.

        Raises:
            RuntimeError: if the world has no robot/cup.
        """
        if self.crossfire_fn is None:
            raise RuntimeError("this catching world has no cup with a crossfire sensor")
        return self.crossfire_fn()

    # --- step hook ------------------------------------------------------------------------------
    def _before_step(self, t: float) -> None:
        if self._parked:
            return
        pb = self.pb
        pos_t, _ = pb.getBasePositionAndOrientation(self.ball_id)
        vel_t, _ = pb.getBaseVelocity(self.ball_id)
        pos = np.asarray(pos_t)
        vel = np.asarray(vel_t)
        if self.drag:
            speed = float(np.linalg.norm(vel))
            if speed > 0.0:
                f = -self.ball.drag_k * self.ball.mass * speed * vel
                pb.applyExternalForce(self.ball_id, -1, f.tolist(), pos_t, pb.WORLD_FRAME)
        th = self._throw
        if th is None:
            return
        if self.record_history:
            th.history.append((t, float(pos[0]), float(pos[1]), float(pos[2])))
        if th.crossing is None and th.prev is not None:
            t0, p0, v0 = th.prev
            if p0[0] < 0.0 <= pos[0]:
                s = -p0[0] / (pos[0] - p0[0])
                p = p0 + s * (pos - p0)
                v = v0 + s * (vel - v0)
                th.crossing = Crossing(
                    t=t0 + s * (t - t0), y=float(p[1]), z=float(p[2]), vx=float(v[0]), vy=float(v[1])
                )
        th.prev = (t, pos, vel)
