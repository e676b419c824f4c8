"""PUMA 560 kinematics from its standard Denavit–Hartenberg table: the robot's data sheet in code.

Pure (numpy only): the motion node plans with it on the real robot or in simulation; the
simulated world (:mod:`sim.catching.puma560`) writes its URDF from the same table.

Conventions (SI units: metres, radians):

* Standard (distal) DH parameters of the PUMA 560 as collected by Corke & Armstrong-Hélouvry,
  "A search for consensus among model parameters reported for the PUMA 560 robot", ICRA 1994:
  ``A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, ``T_0^6 = A_1 ... A_6``. Frame 0 is the base frame
  with its origin on the shoulder (joint 1 and 2 axes intersect there; the pedestal is below it).
  The flange frame is DH frame 6 (``d6 = 0``: the flange sits at the wrist centre).
* Joint limits as used by Corke's Robotics Toolbox model of the same robot.
* The tool is a cup fixed on the flange, its axis along the flange z axis, opening along +z6; the
  catch point :data:`CUP_RIM_OFFSET` (centre of the rim circle) lies on that axis.
* Closed-form inverse kinematics in the manner of Paul & Zhang, "Computationally efficient
  kinematics for manipulators with spherical wrists based on the homogeneous transformation
  representation", IJRR 5(2), 1986: arm (joints 1–3) from the wrist centre, wrist (joints 4–6) from
  ``R_3^6 = Rz(q4) Ry(-q5) Rz(q6)``; up to 8 solutions, each shifted by multiples of 2*pi into the
  joint limits, the one nearest to a given configuration wins.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from services.errors import PetrobotError

__all__ = [
    "CUP_DEPTH",
    "CUP_INNER_RADIUS",
    "CUP_MASS",
    "CUP_MOUNT",
    "CUP_RESTITUTION",
    "CUP_RIM_OFFSET",
    "CUP_WALL",
    "DH_A",
    "DH_ALPHA",
    "DH_D",
    "QDD_MAX",
    "QD_MAX",
    "Q_HOME",
    "Q_MAX",
    "Q_MIN",
    "TAU_MAX",
    "Array",
    "UnreachableError",
    "Vector",
    "dh_transform",
    "fk",
    "fk_all",
    "ik",
    "ik_all",
    "jacobian",
    "within_limits",
]

Array = NDArray[np.float64]
Vector = Sequence[float] | NDArray[np.float64]
"""A joint or Cartesian vector given as a sequence of floats or a numpy array."""

# --- Standard DH table (Corke & Armstrong-Helouvry 1994), metres / radians -------------------------
DH_A: Array = np.array([0.0, 0.4318, 0.0203, 0.0, 0.0, 0.0])
DH_D: Array = np.array([0.0, 0.0, 0.15005, 0.4318, 0.0, 0.0])
DH_ALPHA: Array = np.array([math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0.0])

# Joint limits (Robotics Toolbox PUMA 560 model), radians.
Q_MIN: Array = np.radians([-160.0, -45.0, -225.0, -110.0, -100.0, -266.0])
Q_MAX: Array = np.radians([160.0, 225.0, 45.0, 170.0, 100.0, 266.0])
# Joint speed / acceleration / torque limits of the simulated drives. Chosen, not published data:
# they give a tool speed of roughly 1 m/s near the catch region, the order of the Unimate
# specification, and torques that hold the arm against gravity with margin.
QD_MAX: Array = np.array([2.5, 2.5, 3.0, 5.0, 5.0, 5.0])
QDD_MAX: Array = np.array([10.0, 10.0, 12.0, 20.0, 20.0, 20.0])
TAU_MAX: Array = np.array([150.0, 250.0, 120.0, 30.0, 30.0, 30.0])

# Home pose: the cup rim centre at (0.66, 0, 0.25) m in the base frame, cup axis tilted 45 degrees
# from vertical toward +x (services.catching.robot.motion_control's default catching pose, mid catch line).
Q_HOME: Array = np.array([0.2553, 1.1078, -3.1181, 0.1895, 1.2469, -0.2434])

# --- Cup (the tool) ---------------------------------------------------------------------------------
CUP_INNER_RADIUS = 0.05  # m, inside radius of the cup wall
CUP_DEPTH = 0.06  # m, inside depth from rim to bottom
CUP_WALL = 0.003  # m, wall and bottom thickness
CUP_MOUNT = 0.03  # m, from flange to the outer face of the cup bottom (a short adapter)
CUP_RIM_OFFSET = CUP_MOUNT + CUP_WALL + CUP_DEPTH  # m along +z6, flange to rim centre
CUP_MASS = 0.08  # kg
CUP_RESTITUTION = 0.05


class UnreachableError(PetrobotError, ValueError):
    """No inverse-kinematics solution exists within the joint limits for the requested pose."""


def dh_transform(theta: float, d: float, a: float, alpha: float) -> Array:
    """Homogeneous transform of one standard DH row, ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``.

    Returns:
        (4, 4) array.
    """
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def fk_all(q: Vector) -> Array:
    """Poses of all DH frames 0..6 in the base frame.

    Args:
        q: joint angles, shape (6,), radians.

    Returns:
        (7, 4, 4) array; index i is DH frame i (0 = base, 6 = flange).
    """
    frames = np.empty((7, 4, 4))
    frames[0] = np.eye(4)
    for i in range(6):
        frames[i + 1] = frames[i] @ dh_transform(float(q[i]), DH_D[i], DH_A[i], DH_ALPHA[i])
    return frames


def fk(q: Vector) -> Array:
    """Flange pose (DH frame 6) in the base frame.

    Args:
        q: joint angles, shape (6,), radians.

    Returns:
        (4, 4) homogeneous transform.
    """
    out: Array = fk_all(q)[6]
    return out


def jacobian(q: Vector) -> Array:
    """Geometric Jacobian of the flange origin in the base frame.

    Args:
        q: joint angles, shape (6,), radians.

    Returns:
        (6, 6) array; rows 0–2 linear velocity (m/s per rad/s), rows 3–5 angular velocity.
    """
    frames = fk_all(q)
    p6 = frames[6][:3, 3]
    jac = np.empty((6, 6))
    for i in range(6):
        z = frames[i][:3, 2]
        jac[:3, i] = np.cross(z, p6 - frames[i][:3, 3])
        jac[3:, i] = z
    return jac


def within_limits(q: Vector, tol: float = 1e-9) -> bool:
    """True if every joint angle is inside :data:`Q_MIN`..:data:`Q_MAX` (with ``tol`` rad)."""
    qa = np.asarray(q, dtype=float)
    return bool(np.all(qa >= Q_MIN - tol) and np.all(qa <= Q_MAX + tol))


def _wrap(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def _raw_solutions(target: Array, q4_hint: float) -> list[Array]:
    """All (up to 8) closed-form solutions in (-pi, pi], ignoring limits."""
    rot = target[:3, :3]
    px, py, pz = target[:3, 3]
    a2, a3 = DH_A[1], DH_A[2]
    d3, d4 = DH_D[2], DH_D[3]
    r = math.hypot(px, py)
    if r < abs(d3):
        return []
    phi = math.atan2(py, px)
    ratio = d3 / r
    out: list[Array] = []
    for q1 in (phi + math.asin(ratio), phi + math.pi - math.asin(ratio)):
        c1, s1 = math.cos(q1), math.sin(q1)
        x = c1 * px + s1 * py  # wrist centre in frame 1 (x1, y1)
        y = pz
        k = (x * x + y * y - a2 * a2 - a3 * a3 - d4 * d4) / (2.0 * a2)
        rho = math.hypot(a3, d4)
        if abs(k) > rho:
            continue
        beta = math.atan2(d4, a3)
        gamma = math.acos(max(-1.0, min(1.0, k / rho)))
        for q3 in (-beta + gamma, -beta - gamma):
            c3, s3 = math.cos(q3), math.sin(q3)
            u = a2 + a3 * c3 - d4 * s3
            v = a3 * s3 + d4 * c3
            q2 = math.atan2(y, x) - math.atan2(v, u)
            c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
            # R_0^3 = R_0^1 Rz(q2 + q3) Rx(-pi/2)  (alpha_1 = pi/2, alpha_2 = 0, alpha_3 = -pi/2)
            r01 = np.array([[c1, 0.0, s1], [s1, 0.0, -c1], [0.0, 1.0, 0.0]])
            r13 = np.array([[c23, 0.0, -s23], [s23, 0.0, c23], [0.0, -1.0, 0.0]])
            r03 = r01 @ r13
            m = r03.T @ rot
            s5 = math.hypot(m[0, 2], m[1, 2])
            if s5 < 1e-9:
                # Wrist singularity: only q4 + q6 is defined; keep q4 at the hint.
                q5 = 0.0 if m[2, 2] > 0 else math.pi
                q4 = q4_hint
                total = math.atan2(m[1, 0], m[0, 0])
                q6 = total - q4 if m[2, 2] > 0 else -(total - q4)
                sols = [(q4, q5, q6)]
            else:
                q4 = math.atan2(-m[1, 2], -m[0, 2])
                q5 = math.atan2(s5, m[2, 2])
                q6 = math.atan2(-m[2, 1], m[2, 0])
                sols = [(q4, q5, q6), (q4 + math.pi, -q5, q6 + math.pi)]
            for q4s, q5s, q6s in sols:
                out.append(np.array([_wrap(q1), _wrap(q2), _wrap(q3), _wrap(q4s), q5s, _wrap(q6s)]))
    return out


_LIMITS = [(float(lo) - 1e-9, float(hi) + 1e-9) for lo, hi in zip(Q_MIN, Q_MAX)]
_TWO_PI = 2.0 * math.pi


def _nearest_in_limits(sol: Array, q_near: Array) -> Array | None:
    """Shift each joint of ``sol`` by multiples of 2*pi into the limits, nearest to ``q_near``."""
    out = []
    for x, near, (lo, hi) in zip(sol.tolist(), q_near.tolist(), _LIMITS):
        best: float | None = None
        for k in (-2, -1, 0, 1, 2):
            cand = x + _TWO_PI * k
            if lo <= cand <= hi and (best is None or abs(cand - near) < abs(best - near)):
                best = cand
        if best is None:
            return None
        out.append(best)
    return np.array(out)


def ik_all(target: Array, q_near: Vector | None = None) -> list[Array]:
    """All closed-form IK solutions within the joint limits (Paul & Zhang 1986 style).

    Args:
        target: desired flange pose (DH frame 6) in the base frame, shape (4, 4).
        q_near: configuration used to pick the 2*pi representative of each joint and the wrist
            angle at a wrist singularity, shape (6,); defaults to :data:`Q_HOME`.

    Returns:
        List of up to 8 configurations, each shape (6,), radians, sorted by distance to ``q_near``.
    """
    qn = np.asarray(Q_HOME if q_near is None else q_near, dtype=float)
    sols = []
    for raw in _raw_solutions(np.asarray(target, dtype=float), float(qn[3])):
        shifted = _nearest_in_limits(raw, qn)
        if shifted is not None:
            sols.append(shifted)
    sols.sort(key=lambda s: float(np.max(np.abs(s - qn) / QD_MAX)))
    return sols


def ik(target: Array, q_near: Vector | None = None) -> Array:
    """Inverse kinematics: the in-limits solution nearest to ``q_near``.

    "Nearest" is the least time to reach at the joint speed limits (max over joints of
    ``|q - q_near| / QD_MAX``).

    Args:
        target: desired flange pose (DH frame 6) in the base frame, shape (4, 4).
        q_near: current configuration, shape (6,), radians; defaults to :data:`Q_HOME`.

    Returns:
        Joint angles, shape (6,), radians.

    Raises:
        UnreachableError: the position is out of reach, or no solution respects the joint limits.
    """
    sols = ik_all(target, q_near)
    if not sols:
        p = np.asarray(target)[:3, 3]
        raise UnreachableError(
            f"flange pose at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is not reachable within the "
            "PUMA 560 joint limits"
        )
    return sols[0]
