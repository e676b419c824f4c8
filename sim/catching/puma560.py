"""The simulated PUMA 560: URDF written from the DH table, dynamics, cup and crossfire sensor.

Kinematics, limits and the cup's geometry are the robot's data sheet and live in
:mod:`services.catching.robot.puma560` (the motion node uses them on a real robot too); this module adds
what only the simulation needs. Everything here is pure (numpy only) except :func:`write_urdf`
and :func:`load`.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from services.catching.robot.puma560 import (
    CUP_DEPTH,
    CUP_INNER_RADIUS,
    CUP_MASS,
    CUP_MOUNT,
    CUP_RESTITUTION,
    CUP_WALL,
    DH_A,
    DH_ALPHA,
    DH_D,
    QD_MAX,
    Q_MAX,
    Q_MIN,
    TAU_MAX,
    Array,
    Vector,
)

__all__ = [
    "CROSSFIRE_HEIGHT",
    "CROSSFIRE_LINK",
    "LINK_COMS",
    "LINK_INERTIAS",
    "LINK_MASSES",
    "PUBLISHED_INERTIAS",
    "beam_blocked",
    "crossfire_beam",
    "fix_triangle_inequality",
    "load",
    "urdf",
    "write_urdf",
]

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

# --- Crossfire sensor ------------------------------------------------------------------------------
CROSSFIRE_LINK = "crossfire"
CROSSFIRE_HEIGHT = 0.02  # m, beam height above the inside bottom (a resting 40 mm ball cuts it)


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
