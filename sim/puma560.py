"""PUMA 560 kinematics and URDF, written from its standard Denavit–Hartenberg table.

Everything here is pure (numpy only) except :func:`write_urdf` and :func:`load`.

Conventions (SI units: metres, radians, kilograms):

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

URDF (``urdf()``): one revolute joint per DH row. Because a URDF joint applies its fixed origin
*before* its rotation while standard DH rotates first, each row becomes two links: ``rotor{i}``
(massless, frame ``DH_{i-1} Rz(q_i)``) and ``link{i}`` (frame ``DH_i``, carrying the link's mass),
joined by a fixed joint with origin ``Tz(d_i) Tx(a_i) Rx(alpha_i)``. So the pybullet link frame of
``link{i}`` *is* DH frame i. Load with ``URDF_USE_INERTIA_FROM_FILE`` (see :func:`load`), otherwise
pybullet recomputes inertias from the collision shapes.

Inertias: the consensus masses and centre-of-mass positions (links 2–6) with these fixes, because a
rigid body's principal moments must satisfy the triangle inequality ``I_a + I_b >= I_c``:
link 1 has no published mass (only ``Iyy = 0.35`` about the joint 1 axis matters for a fixed base);
we choose 13 kg (a guess; with a fixed base and the centre of mass on the joint 1 axis the mass
itself does not act on any joint) and raise ``Ixx = Izz`` to 0.18 so that ``Ixx + Izz >= Iyy``. Link 3's published ``(0.066, 0.086, 0.0125)``
violates ``Ixx + Izz >= Iyy``; we raise its smallest moment ``Izz`` to 0.0225 (the deficit plus
a 0.0025 kg m^2 margin). :func:`fix_triangle_inequality` does this generically and the tests check
every link.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CROSSFIRE_HEIGHT",
    "CROSSFIRE_LINK",
    "CUP_DEPTH",
    "CUP_INNER_RADIUS",
    "CUP_RIM_OFFSET",
    "CUP_WALL",
    "DH_A",
    "DH_ALPHA",
    "DH_D",
    "LINK_COMS",
    "LINK_INERTIAS",
    "LINK_MASSES",
    "QDD_MAX",
    "QD_MAX",
    "Q_HOME",
    "Q_MAX",
    "Q_MIN",
    "TAU_MAX",
    "UnreachableError",
    "beam_blocked",
    "crossfire_beam",
    "dh_transform",
    "fix_triangle_inequality",
    "fk",
    "fk_all",
    "ik",
    "ik_all",
    "jacobian",
    "load",
    "urdf",
    "within_limits",
    "write_urdf",
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
# from vertical toward +x (services.motion_control's default catching pose, mid catch line).
Q_HOME: Array = np.array([0.2553, 1.1078, -3.1181, 0.1895, 1.2469, -0.2434])

# --- Dynamics (links 1..6, each in its own DH frame) -----------------------------------------------
LINK_MASSES: Array = np.array([13.0, 17.4, 4.8, 0.82, 0.34, 0.09])
LINK_COMS: Array = np.array(
    [
        [0.0, 0.0, 0.0],
        [-0.3638, 0.006, 0.2275],
        [-0.0203, -0.0141, 0.070],
        [0.0, 0.019, 0.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 0.032],
    ]
)
# Published principal moments (Ixx, Iyy, Izz) about the centre of mass, kg m^2.
PUBLISHED_INERTIAS: Array = np.array(
    [
        [0.0, 0.35, 0.0],
        [0.13, 0.524, 0.539],
        [0.066, 0.086, 0.0125],
        [1.8e-3, 1.3e-3, 1.8e-3],
        [0.3e-3, 0.4e-3, 0.3e-3],
        [0.15e-3, 0.15e-3, 0.04e-3],
    ]
)

# --- Cup and crossfire sensor ----------------------------------------------------------------------
CUP_INNER_RADIUS = 0.05  # m, inside radius of the cup wall
CUP_DEPTH = 0.06  # m, inside depth from rim to bottom
CUP_WALL = 0.003  # m, wall and bottom thickness
CUP_MOUNT = 0.03  # m, from flange to the outer face of the cup bottom (a short adapter)
CUP_RIM_OFFSET = CUP_MOUNT + CUP_WALL + CUP_DEPTH  # m along +z6, flange to rim centre
CUP_MASS = 0.08  # kg
CUP_RESTITUTION = 0.05
CROSSFIRE_LINK = "crossfire"
CROSSFIRE_HEIGHT = 0.02  # m, beam height above the inside bottom (a resting 40 mm ball cuts it)


class UnreachableError(ValueError):
    """No inverse-kinematics solution exists within the joint limits for the requested pose."""


def fix_triangle_inequality(moments: Vector, margin: float = 0.0025) -> Array:
    """Raise principal moments of inertia until every triangle inequality holds.

    While some ``I_a + I_b < I_c``, the smallest moment is raised by the deficit plus ``margin``.

    Args:
        moments: principal moments ``(I1, I2, I3)``, kg m^2, shape (3,).
        margin: extra kg m^2 added on each raise.

    Returns:
        The (possibly) corrected moments, shape (3,).
    """
    m = np.array(moments, dtype=float)
    for _ in range(6):
        deficits = [m[(k + 1) % 3] + m[(k + 2) % 3] - m[k] for k in range(3)]
        worst = int(np.argmin(deficits))
        if deficits[worst] >= 0.0:
            return m
        smallest = int(np.argmin(m))
        m[smallest] += -deficits[worst] + margin
    return m


LINK_INERTIAS: Array = np.array(
    [fix_triangle_inequality(i) if i.sum() > 0 else i for i in PUBLISHED_INERTIAS]
)
# Link 1: only Iyy (about the joint-1 axis) is published; the others are set so that Ixx+Izz >= Iyy.
LINK_INERTIAS[0] = np.array([0.18, 0.35, 0.18])


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


# --- Crossfire sensor geometry ---------------------------------------------------------------------


def crossfire_beam(link_pose: Array) -> tuple[Array, Array]:
    """World endpoints of the crossfire light beam from the pose of the :data:`CROSSFIRE_LINK` link.

    The beam runs along the link's x axis across the whole inside diameter of the cup, at
    :data:`CROSSFIRE_HEIGHT` above the inside bottom (the link origin is on the cup axis there).

    Args:
        link_pose: (4, 4) world pose of the crossfire link.

    Returns:
        Emitter and receiver points, each shape (3,), metres.
    """
    x = link_pose[:3, 0]
    o = link_pose[:3, 3]
    return o - CUP_INNER_RADIUS * x, o + CUP_INNER_RADIUS * x


def beam_blocked(ball_centre: Vector, ball_radius: float, emitter: Array, receiver: Array) -> bool:
    """True if a sphere cuts the segment between emitter and receiver (the beam is interrupted).

    Args:
        ball_centre: shape (3,), metres.
        ball_radius: metres.
        emitter, receiver: beam endpoints, shape (3,), metres.
    """
    c = np.asarray(ball_centre, dtype=float)
    seg = receiver - emitter
    t = float(np.clip(np.dot(c - emitter, seg) / float(np.dot(seg, seg)), 0.0, 1.0))
    return bool(np.linalg.norm(emitter + t * seg - c) < ball_radius)


# --- URDF ------------------------------------------------------------------------------------------

_LINK_RADII = [0.09, 0.06, 0.05, 0.04, 0.035, 0.03]


@dataclass(frozen=True)
class _Shape:
    kind: str  # "cylinder" | "box" | "sphere"
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    size: tuple[float, ...]


def _fmt(v: Vector) -> str:
    return " ".join(f"{x:.12g}" for x in v)


def _geometry(s: _Shape) -> str:
    if s.kind == "cylinder":
        return f'<cylinder radius="{s.size[0]:.12g}" length="{s.size[1]:.12g}"/>'
    if s.kind == "box":
        return f'<box size="{_fmt(s.size)}"/>'
    return f'<sphere radius="{s.size[0]:.12g}"/>'


def _segment(p0: Array, p1: Array, radius: float) -> _Shape | None:
    """A cylinder from p0 to p1 (link-frame points)."""
    v = p1 - p0
    length = float(np.linalg.norm(v))
    if length < 1e-6:
        return None
    z = v / length
    pitch = math.acos(max(-1.0, min(1.0, z[2])))
    yaw = math.atan2(z[1], z[0])
    mid = (p0 + p1) / 2.0
    return _Shape("cylinder", (mid[0], mid[1], mid[2]), (0.0, pitch, yaw), (radius, length))


def _link_shapes(i: int) -> list[_Shape]:
    """Simple visual/collision shapes of link i+1 in its own DH frame.

    A link carries its own ``a`` offset (from ``(-a, 0, 0)`` to the origin: points on the common
    normal move with this joint) and the next row's ``d`` offset along its z axis (points on the
    next joint axis do not move with the next joint).
    """
    r = _LINK_RADII[i]
    shapes: list[_Shape] = [_Shape("sphere", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (r,))]
    ends = [(np.array([-DH_A[i], 0.0, 0.0]), np.zeros(3))]
    if i < 5:
        ends.append((np.zeros(3), np.array([0.0, 0.0, DH_D[i + 1]])))
    for p0, p1 in ends:
        seg = _segment(p0, p1, r * 0.8)
        if seg is not None:
            shapes.append(seg)
    return shapes


def _inertial(mass: float, com: Vector, moments: Vector) -> str:
    return (
        f'<inertial><origin xyz="{_fmt(com)}" rpy="0 0 0"/><mass value="{mass:.12g}"/>'
        f'<inertia ixx="{moments[0]:.12g}" iyy="{moments[1]:.12g}" izz="{moments[2]:.12g}" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )


_MASSLESS = '<inertial><mass value="0"/><inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>'


def _visual_collision(shapes: list[_Shape], colour: str, collide: bool = True) -> str:
    parts = []
    for s in shapes:
        origin = f'<origin xyz="{_fmt(s.xyz)}" rpy="{_fmt(s.rpy)}"/>'
        parts.append(
            f"<visual>{origin}<geometry>{_geometry(s)}</geometry>"
            f'<material name="{colour}"><color rgba="{_material(colour)}"/></material></visual>'
        )
        if collide:
            parts.append(f"<collision>{origin}<geometry>{_geometry(s)}</geometry></collision>")
    return "".join(parts)


def _material(colour: str) -> str:
    return {"grey": "0.6 0.6 0.65 1", "orange": "0.95 0.5 0.1 1", "dark": "0.2 0.2 0.2 1"}[colour]


def _cup_shapes(n_staves: int = 20) -> list[_Shape]:
    """Cup in the cup link frame: origin at the outer face of the bottom, axis +z."""
    shapes = [
        _Shape(
            "cylinder",
            (0.0, 0.0, CUP_WALL / 2.0),
            (0.0, 0.0, 0.0),
            (CUP_INNER_RADIUS + CUP_WALL, CUP_WALL),
        )
    ]
    r_mid = CUP_INNER_RADIUS + CUP_WALL / 2.0
    stave = 2.0 * (CUP_INNER_RADIUS + CUP_WALL) * math.tan(math.pi / n_staves) + 0.002
    height = CUP_DEPTH + CUP_WALL
    for k in range(n_staves):
        ang = 2.0 * math.pi * k / n_staves
        shapes.append(
            _Shape(
                "box",
                (r_mid * math.cos(ang), r_mid * math.sin(ang), height / 2.0),
                (0.0, 0.0, ang),
                (CUP_WALL, stave, height),
            )
        )
    return shapes


def urdf(cup: bool = True) -> str:
    """The PUMA 560 as a URDF document.

    Links ``link1``..``link6`` have the DH frames 1..6 as link frames; ``base_link`` is DH frame 0.
    With ``cup``: a ``cup`` link on the flange (origin :data:`CUP_MOUNT` along +z6, opening along
    +z6) made of a disc and 20 box staves, restitution 0.05, and a massless ``crossfire`` link on
    the cup axis at :data:`CROSSFIRE_HEIGHT` above the inside bottom (see :func:`crossfire_beam`).

    Returns:
        URDF XML text.
    """
    out = ['<?xml version="1.0"?>', '<robot name="puma560">']
    base_shapes = [_Shape("cylinder", (0.0, 0.0, -0.25), (0.0, 0.0, 0.0), (0.1, 0.4))]
    out.append(
        f'<link name="base_link">{_inertial(30.0, (0.0, 0.0, -0.25), (1.0, 1.0, 0.2))}'
        f"{_visual_collision(base_shapes, 'dark')}</link>"
    )
    parent = "base_link"
    for i in range(6):
        n = i + 1
        out.append(
            f'<joint name="joint{n}" type="revolute"><parent link="{parent}"/><child link="rotor{n}"/>'
            f'<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>'
            f'<limit lower="{Q_MIN[i]:.12g}" upper="{Q_MAX[i]:.12g}" effort="{TAU_MAX[i]:.12g}" '
            f'velocity="{QD_MAX[i]:.12g}"/><dynamics damping="0.0" friction="0.0"/></joint>'
        )
        out.append(f'<link name="rotor{n}">{_MASSLESS}</link>')
        out.append(
            f'<joint name="dh{n}" type="fixed"><parent link="rotor{n}"/><child link="link{n}"/>'
            f'<origin xyz="{DH_A[i]:.12g} 0 {DH_D[i]:.12g}" rpy="{DH_ALPHA[i]:.12g} 0 0"/></joint>'
        )
        colour = "grey" if n % 2 else "orange"
        out.append(
            f'<link name="link{n}">{_inertial(LINK_MASSES[i], LINK_COMS[i], LINK_INERTIAS[i])}'
            f"{_visual_collision(_link_shapes(i), colour)}</link>"
        )
        parent = f"link{n}"
    if cup:
        r_out = CUP_INNER_RADIUS + CUP_WALL
        h = CUP_DEPTH + CUP_WALL
        # Thin-walled open cylinder, approximated: I_axis = m r^2, I_perp = m (6 r^2 + 4 h^2) / 12.
        i_axis = CUP_MASS * r_out**2
        i_perp = CUP_MASS * (6.0 * r_out**2 + 4.0 * h**2) / 12.0
        adapter = _Shape("cylinder", (0.0, 0.0, -CUP_MOUNT / 2.0), (0.0, 0.0, 0.0), (0.02, CUP_MOUNT))
        out.append(
            f'<joint name="cup_mount" type="fixed"><parent link="link6"/><child link="cup"/>'
            f'<origin xyz="0 0 {CUP_MOUNT:.12g}" rpy="0 0 0"/></joint>'
        )
        out.append(
            f'<link name="cup">{_inertial(CUP_MASS, (0.0, 0.0, h / 2.0), (i_perp, i_perp, i_axis))}'
            f"{_visual_collision([adapter] + _cup_shapes(), 'orange')}"
            f'<contact><restitution value="{CUP_RESTITUTION:.12g}"/><lateral_friction value="0.4"/>'
            f'<rolling_friction value="0.001"/></contact></link>'
        )
        out.append(
            f'<joint name="crossfire_mount" type="fixed"><parent link="cup"/>'
            f'<child link="{CROSSFIRE_LINK}"/>'
            f'<origin xyz="0 0 {CUP_WALL + CROSSFIRE_HEIGHT:.12g}" rpy="0 0 0"/></joint>'
        )
        out.append(f'<link name="{CROSSFIRE_LINK}">{_MASSLESS}</link>')
    out.append("</robot>")
    return "\n".join(out) + "\n"


def write_urdf(path: str | Path, cup: bool = True) -> Path:
    """Write :func:`urdf` to ``path`` and return the path."""
    target = Path(path)
    target.write_text(urdf(cup=cup), encoding="utf-8")
    return target


def load(
    client: Any,
    path: str | Path,
    base_position: Vector = (0.0, 0.0, 0.0),
    base_orientation: Vector = (0.0, 0.0, 0.0, 1.0),
) -> tuple[int, list[int], dict[str, int]]:
    """Load a written URDF into a pybullet client with the flags it needs.

    Args:
        client: the ``pybullet`` module or a ``bullet_client.BulletClient``; the functions used are
            ``loadURDF``, ``getNumJoints``, ``getJointInfo`` and ``URDF_USE_INERTIA_FROM_FILE``.
        path: URDF file from :func:`write_urdf`.
        base_position: world position of DH frame 0 (the shoulder), metres.
        base_orientation: world orientation of DH frame 0, quaternion (x, y, z, w).

    Returns:
        ``(body_id, joint_indices, link_index)``: the pybullet body, the indices of joint1..joint6
        (pass them to ``SimDrives.attach``) and a map from link name to pybullet link index.
    """
    body = int(
        client.loadURDF(
            str(path),
            basePosition=list(base_position),
            baseOrientation=list(base_orientation),
            useFixedBase=True,
            flags=client.URDF_USE_INERTIA_FROM_FILE,
        )
    )
    link_index: dict[str, int] = {}
    joints: dict[str, int] = {}
    for j in range(client.getNumJoints(body)):
        info = client.getJointInfo(body, j)
        joints[info[1].decode()] = j
        link_index[info[12].decode()] = j
    return body, [joints[f"joint{n}"] for n in range(1, 7)], link_index
