"""Catching motion control for the PUMA 560: set point -> cup pose -> IK -> limited joint steps.

Pure: no I/O, no clocks (times are passed in). Used by the motion node (over the CAN drives, one
step per 2 ms SYNC cycle) and by the in-process catching bench.

Geometry (all in the robot base frame = DH frame 0 of :mod:`services.catching.robot.puma560`, metres):

* The table lies along +x; its near edge (the *catch line*) is the line ``x = edge_x`` at surface
  height ``table_z``. Balls roll toward -x and leave the table there.
* Decision on the cup orientation: the cup axis is **tilted** from vertical by a fixed ``tilt``
  (45 degrees) toward +x, i.e. the opening faces the oncoming ball. A ball leaving the edge at
  0.5–1.5 m/s meets the rim plane 0.05 m below the surface moving about 23–52 degrees off vertical, so a
  45-degree cup nearly faces it, the lower lip is on the table side and the far wall stops the ball.
  It also keeps the wrist further from the joint 5 limit than a vertical cup (22 vs 16 degrees of
  margin along the catch line; see docs/catching.md, "Robot").
* The cup's rim centre is aimed at the point where the ball centre, falling ballistically from the
  edge, crosses the height ``table_z - rim_drop`` (air drag over < 0.15 s is neglected).

Motion: each control cycle moves every joint toward its goal with a per-joint time-optimal law
under the speed limit ``QD_MAX`` and acceleration limit ``QDD_MAX`` (a braking-distance law:
``|v| <= sqrt(2 a |e|)``), see :func:`step_toward`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from services.catching.robot import puma560

__all__ = [
    "CYCLE_S",
    "CatchGeometry",
    "CatchServo",
    "CatchTarget",
    "G",
    "catch_target",
    "cup_pose",
    "flange_pose",
    "home_pose",
    "reach_time",
    "step_toward",
]

Array = NDArray[np.float64]
Vector = puma560.Vector

G = 9.81  # m/s^2
CYCLE_S = 0.002  # s, the CAN SYNC cycle


@dataclass(frozen=True, kw_only=True)
class CatchGeometry:
    """Where the table is in the robot base frame, and how the cup meets the ball.

    Attributes:
        edge_x: x of the catch line (the table's near edge), m.
        table_z: z of the table surface, m (the default puts the shoulder 0.30 m below it).
        ball_radius: m.
        rim_drop: how far below the table surface the rim centre is aimed, m.
        tilt: cup axis angle from vertical toward +x, rad.
        y_min, y_max: lateral span of the catch line the robot covers, m.
    """

    edge_x: float = 0.75
    table_z: float = 0.30
    ball_radius: float = 0.02
    rim_drop: float = 0.05
    tilt: float = math.radians(45.0)
    y_min: float = -0.35
    y_max: float = 0.35


@dataclass(frozen=True)
class CatchTarget:
    """A catching goal computed from a set point.

    Attributes:
        rim: rim centre position in the base frame, shape (3,), m.
        t_rim: time at which the ball centre reaches the rim plane height, s (same clock as the
            set point's time of arrival).
        q: joint goal, shape (6,), rad.
    """

    rim: Array
    t_rim: float
    q: Array = field(repr=False)


def cup_pose(rim: Vector, geometry: CatchGeometry) -> Array:
    """Pose of the cup frame whose origin is the rim centre and z axis the cup axis.

    Args:
        rim: rim centre in the base frame, shape (3,), m.
        geometry: gives the tilt.

    Returns:
        (4, 4) homogeneous transform; x axis in the tilt plane (pointing down toward +x, the
        direction of the crossfire beam), y axis = base y.
    """
    s, c = math.sin(geometry.tilt), math.cos(geometry.tilt)
    pose = np.eye(4)
    pose[:3, 0] = (c, 0.0, -s)
    pose[:3, 1] = (0.0, 1.0, 0.0)
    pose[:3, 2] = (s, 0.0, c)
    pose[:3, 3] = rim
    return pose


def flange_pose(cup: Array) -> Array:
    """Flange pose (DH frame 6) that puts the rim centre frame at ``cup``, shape (4, 4)."""
    out = np.array(cup, dtype=float, copy=True)
    out[:3, 3] = cup[:3, 3] - puma560.CUP_RIM_OFFSET * cup[:3, 2]
    return out


def catch_target(
    x: float,
    y: float,
    t_arrival: float,
    vx: float,
    vy: float,
    q_near: Vector,
    geometry: CatchGeometry = CatchGeometry(),
) -> CatchTarget:
    """Joint goal that puts the cup where a ball leaving the table at ``(x, y)`` will fall.

    Args:
        x, y: predicted point where the ball centre crosses the catch line, base frame, m.
        t_arrival: predicted time of that crossing, s.
        vx, vy: predicted ball velocity there, m/s (``vx < 0``: toward the robot). If the
            prediction has no velocity, pass the expected speed along -x.
        q_near: current joint configuration, shape (6,), rad (picks the IK branch).
        geometry: table and cup geometry.

    Returns:
        The target (rim position, time the ball reaches it, joint goal).

    Raises:
        services.catching.robot.puma560.UnreachableError: the cup pose is out of reach within the joint limits.
    """
    z0 = geometry.table_z + geometry.ball_radius
    z_rim = geometry.table_z - geometry.rim_drop
    t_fall = math.sqrt(2.0 * (z0 - z_rim) / G)
    y_c = min(max(y + vy * t_fall, geometry.y_min), geometry.y_max)
    rim = np.array([x + vx * t_fall, y_c, z_rim])
    q = puma560.ik(flange_pose(cup_pose(rim, geometry)), q_near)
    return CatchTarget(rim=rim, t_rim=t_arrival + t_fall, q=q)


def home_pose(geometry: CatchGeometry = CatchGeometry()) -> Array:
    """Joint angles of the home pose: the cup at the middle of the catch line, shape (6,), rad.

    Raises:
        services.catching.robot.puma560.UnreachableError: the geometry puts the middle of the catch line out of reach.
    """
    y_mid = 0.5 * (geometry.y_min + geometry.y_max)
    return catch_target(geometry.edge_x, y_mid, 0.0, -0.8, 0.0, puma560.Q_HOME, geometry).q


def step_toward(
    q: Vector,
    qd: Vector,
    q_goal: Vector,
    dt: float = CYCLE_S,
    qd_max: Vector = puma560.QD_MAX,
    qdd_max: Vector = puma560.QDD_MAX,
) -> tuple[Array, Array]:
    """One control cycle of a per-joint time-optimal move under speed and acceleration limits.

    The commanded velocity tends to ``sign(e) * min(qd_max, sqrt(2 qdd_max |e|), |e| / dt)``
    (``e = q_goal - q``), changing by at most ``qdd_max * dt`` per cycle, so a joint brakes in
    time and lands on the goal without overshoot beyond one cycle's worth of acceleration.

    Args:
        q, qd: commanded position (rad) and velocity (rad/s), shape (6,).
        q_goal: goal, shape (6,), rad.
        dt: cycle time, s.
        qd_max, qdd_max: limits, shape (6,), rad/s and rad/s^2.

    Returns:
        ``(q_next, qd_next)``, each shape (6,).
    """
    qa = np.asarray(q, dtype=float)
    va = np.asarray(qd, dtype=float)
    e = np.asarray(q_goal, dtype=float) - qa
    vmax = np.asarray(qd_max, dtype=float)
    amax = np.asarray(qdd_max, dtype=float)
    # Braking law evaluated on the remaining error after this cycle's own motion.
    brake = np.sqrt(2.0 * amax * np.maximum(np.abs(e) - np.abs(va) * dt, 0.0))
    v_des = np.sign(e) * np.minimum(np.minimum(vmax, brake), np.abs(e) / dt)
    v_next = np.clip(v_des, va - amax * dt, va + amax * dt)
    return qa + v_next * dt, v_next


def reach_time(
    q: Vector,
    qd: Vector,
    q_goal: Vector,
    qd_max: Vector = puma560.QD_MAX,
    qdd_max: Vector = puma560.QDD_MAX,
) -> float:
    """Lower bound on the time to reach ``q_goal`` at rest, the slowest joint's trapezoidal time.

    Each joint first stops or keeps its current velocity component toward the goal, then follows a
    trapezoidal (or triangular) profile. Shapes (6,), SI units; returns seconds.
    """
    worst = 0.0
    for qi, vi, gi, vm, am in zip(q, qd, q_goal, qd_max, qdd_max):
        e = float(gi) - float(qi)
        v = float(vi) * (1.0 if e >= 0 else -1.0)  # velocity component toward the goal
        d = abs(e)
        if v < 0.0:  # moving away: stop first
            t_stop = -v / am
            d += v * v / (2.0 * am)
            v = 0.0
        else:
            t_stop = 0.0
        # accelerate from v to vpeak, cruise, decelerate to 0
        d_acc_full = (vm * vm - v * v) / (2.0 * am) + vm * vm / (2.0 * am)
        if d >= d_acc_full:
            t = (vm - v) / am + vm / am + (d - d_acc_full) / vm
        else:
            vpeak2 = am * d + 0.5 * v * v
            vpeak = math.sqrt(max(vpeak2, v * v))
            t = (vpeak - v) / am + vpeak / am
        worst = max(worst, t_stop + t)
    return worst


class CatchServo:
    """Joint-space servo: holds the commanded state and moves it toward the latest goal.

    Lifecycle: construct at the current joint positions; :meth:`set_goal` (or
    :meth:`aim` from a set point) whenever a new set point arrives (latest wins); :meth:`step`
    once per control cycle, sending the returned positions to the drives.

    Args:
        q: initial joint positions, shape (6,), rad.
        geometry: table and cup geometry.
        dt: control cycle, s.
    """

    def __init__(self, q: Vector, geometry: CatchGeometry = CatchGeometry(), dt: float = CYCLE_S) -> None:
        self.geometry = geometry
        self.dt = dt
        self.q = np.asarray(q, dtype=float).copy()
        self.qd = np.zeros(6)
        self.goal = self.q.copy()
        self.target: CatchTarget | None = None

    def set_goal(self, q_goal: Vector) -> None:
        """Move toward a joint goal, shape (6,), rad (must be within the joint limits)."""
        goal = np.asarray(q_goal, dtype=float)
        if not puma560.within_limits(goal):
            raise puma560.UnreachableError("joint goal outside the PUMA 560 joint limits")
        self.goal = goal.copy()

    def aim(self, x: float, y: float, t_arrival: float, vx: float, vy: float) -> CatchTarget:
        """Aim the cup at a predicted catch-line crossing (see :func:`catch_target`).

        Raises:
            services.catching.robot.puma560.UnreachableError: the catch pose is out of reach; the goal is unchanged.
        """
        target = catch_target(x, y, t_arrival, vx, vy, self.goal, self.geometry)
        self.target = target
        self.goal = target.q.copy()
        return target

    def stop(self) -> Array:
        """Controlled stop: the new goal is where each joint comes to rest braking at ``QDD_MAX``
        from its commanded velocity (within the joint limits); returns that goal, shape (6,), rad.

        :meth:`step` then decelerates every joint at most at its acceleration limit, without
        overshoot, so the stop takes at most max(|qd| / QDD_MAX) plus a few cycles.
        """
        brake = self.qd * np.abs(self.qd) / (2.0 * np.asarray(puma560.QDD_MAX))
        self.goal = np.clip(self.q + brake, puma560.Q_MIN, puma560.Q_MAX)
        self.target = None
        return self.goal.copy()

    def step(self) -> Array:
        """Advance one cycle; returns the commanded joint positions, shape (6,), rad."""
        self.q, self.qd = step_toward(self.q, self.qd, self.goal, self.dt)
        return self.q.copy()

    def time_to_goal(self) -> float:
        """Lower bound on the time until the commanded state reaches the goal at rest, s."""
        return reach_time(self.q, self.qd, self.goal)

    def at_goal(self, tol: float = 1e-3) -> bool:
        """True when every joint is within ``tol`` rad of the goal and (nearly) at rest."""
        return bool(np.all(np.abs(self.goal - self.q) <= tol) and np.all(np.abs(self.qd) <= 10 * tol))
