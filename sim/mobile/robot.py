"""The differential-drive robot: parameter table, URDF, wheel drives in velocity mode, encoders.

A competition-size line follower (paper section 6, "Mobile Robot Task"): two driven wheels on a
common axle and a ball caster at the rear, a downward camera on a boom ahead of the wheels, and a
beacon sensor on a mast. Every mass and inertia of the URDF comes from :class:`RobotSpec` through
the formulas for homogeneous solids:

* box of sides a, b, c: I_xx = m (b² + c²)/12, I_yy = m (a² + c²)/12, I_zz = m (a² + b²)/12;
* solid cylinder of radius r, length l about its own axis: m r²/2, about a diameter:
  m (3 r² + l²)/12;
* solid sphere: 2 m r²/5.

Frames: the URDF base link's frame is the *robot frame* lifted to the wheel axle: origin on the
axle midpoint at wheel-centre height, x forward, y left, z up. pybullet reports a base's pose at
its centre of mass; :meth:`MobileRobot.pose` converts back to the robot frame's floor point.

Drives (:class:`WheelDrives`): each wheel's drive takes a **velocity set point** in rad/s, as a
CiA 402 drive in velocity mode does; the demand follows the set point within the drive's
acceleration ramp and is clamped to the motor's speed limit, and pybullet's velocity motor applies
it with the motor's torque limit. A step hook (:meth:`WheelDrives.step`, registered with
:meth:`sim.world.World.add_step_hook`) applies the demand before every physics step, so that a CAN
layer can later sit in front of :meth:`WheelDrives.set_velocity` as :mod:`sim.catching.drives` does for the
PUMA's position-mode drives. Encoders report the wheel angles quantised to their counts.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "MobileRobot",
    "RobotSpec",
    "WheelDrives",
    "box_inertia",
    "cylinder_inertia",
    "sphere_inertia",
    "urdf",
]


def box_inertia(m: float, a: float, b: float, c: float) -> tuple[float, float, float]:
    """Principal moments (kg m²) of a homogeneous box of mass m (kg), sides a, b, c (m) along x, y, z."""
    return m * (b * b + c * c) / 12.0, m * (a * a + c * c) / 12.0, m * (a * a + b * b) / 12.0


def cylinder_inertia(m: float, r: float, length: float) -> tuple[float, float]:
    """(about the axis, about a diameter through the centre), kg m², of a solid cylinder."""
    return m * r * r / 2.0, m * (3.0 * r * r + length * length) / 12.0


def sphere_inertia(m: float, r: float) -> float:
    """Moment of inertia (kg m²) of a solid sphere about a diameter."""
    return 0.4 * m * r * r


@dataclass(frozen=True, slots=True, kw_only=True)
class RobotSpec:
    """The robot's parameter table (SI units). Sources and reasons in ``docs/mobile.md``.

    Attributes:
        wheel_radius: driven wheel radius, m (100 mm wheels, a common size in the competitions).
        wheel_width: tyre width, m.
        wheel_mass: one wheel (aluminium hub, rubber tyre), kg.
        track_width: distance between the wheels' mid-planes, m.
        chassis_size: (length, width, height) of the chassis box, m.
        chassis_mass: chassis with motors, gearboxes, battery and electronics, kg.
        chassis_x: forward position of the chassis box's centre from the axle, m.
        chassis_z: height of the chassis box's centre above the floor, m.
        caster_radius: ball caster radius, m.
        caster_mass: kg.
        caster_x: forward position of the caster ball's centre, m (negative: behind the axle).
        camera_x, camera_height: downward camera's centre of projection: forward from the axle and
            above the floor, m (a boom carries it ahead of the chassis).
        sensor_x, sensor_height: beacon sensor's position (forward, above the floor), m.
        max_wheel_speed: motor speed limit at the wheel, rad/s.
        max_torque: motor torque limit at the wheel, N m.
        ramp: drive acceleration ramp, rad/s².
        encoder_counts: encoder counts per wheel revolution.
        tyre_friction: lateral friction coefficient of the tyres on the floor.
    """

    wheel_radius: float = 0.05
    wheel_width: float = 0.025
    wheel_mass: float = 0.20
    track_width: float = 0.30
    chassis_size: tuple[float, float, float] = (0.34, 0.22, 0.08)
    chassis_mass: float = 4.6
    chassis_x: float = -0.06
    chassis_z: float = 0.075
    caster_radius: float = 0.025
    caster_mass: float = 0.08
    caster_x: float = -0.20
    camera_x: float = 0.20
    camera_height: float = 0.20
    sensor_x: float = -0.05
    sensor_height: float = 0.30
    max_wheel_speed: float = 25.0
    max_torque: float = 1.2
    ramp: float = 40.0
    encoder_counts: int = 16384
    tyre_friction: float = 0.9

    def __post_init__(self) -> None:
        if self.chassis_size[1] / 2.0 >= self.track_width / 2.0 - self.wheel_width / 2.0:
            raise ValueError("the chassis is wider than the space between the wheels")
        bottom = self.chassis_z - self.chassis_size[2] / 2.0
        if bottom <= 0.0:
            raise ValueError("the chassis touches the floor")
        if self.caster_radius * 2.0 >= self.chassis_z + self.chassis_size[2] / 2.0:
            raise ValueError("the caster ball does not fit under the chassis")

    @property
    def mass(self) -> float:
        """Total mass, kg."""
        return self.chassis_mass + 2.0 * self.wheel_mass + self.caster_mass

    @property
    def max_speed(self) -> float:
        """Top forward speed at the motors' speed limit, m/s."""
        return self.max_wheel_speed * self.wheel_radius


def _fmt(*v: float) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def _inertial(m: float, xyz: tuple[float, float, float], moments: tuple[float, float, float]) -> str:
    return (
        f'<inertial><origin xyz="{_fmt(*xyz)}" rpy="0 0 0"/><mass value="{m:.9g}"/>'
        f'<inertia ixx="{moments[0]:.9g}" iyy="{moments[1]:.9g}" izz="{moments[2]:.9g}" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )


def _material(name: str, rgba: str) -> str:
    return f'<material name="{name}"><color rgba="{rgba}"/></material>'


def urdf(spec: RobotSpec | None = None) -> str:
    """The robot as a URDF document (links ``base_link``, ``left_wheel``, ``right_wheel``,
    ``caster``; continuous joints ``left_wheel_joint``, ``right_wheel_joint`` about +y)."""
    s = spec or RobotSpec()
    r = s.wheel_radius
    lx, ly, lz = s.chassis_size
    cz = s.chassis_z - r  # chassis centre in the base frame (base origin at axle height)
    body = box_inertia(s.chassis_mass, lx, ly, lz)
    ax, dia = cylinder_inertia(s.wheel_mass, r, s.wheel_width)
    ball = sphere_inertia(s.caster_mass, s.caster_radius)
    cam_z = s.camera_height - r
    sen_z = s.sensor_height - r
    grey, dark, blue = _material("grey", "0.55 0.57 0.6 1"), _material("dark", "0.1 0.1 0.1 1"), _material("blue", "0.2 0.35 0.8 1")
    boom_len = s.camera_x - (s.chassis_x + lx / 2.0) + 0.02
    boom_x = s.camera_x - boom_len / 2.0 + 0.01
    visuals = [
        f'<visual><origin xyz="{_fmt(s.chassis_x, 0, cz)}" rpy="0 0 0"/><geometry><box size="{_fmt(lx, ly, lz)}"/></geometry>{blue}</visual>',
        # camera boom and housing (above the centre of projection: out of the camera's view)
        f'<visual><origin xyz="{_fmt(boom_x, 0, cam_z + 0.035)}" rpy="0 0 0"/><geometry><box size="{_fmt(boom_len, 0.03, 0.01)}"/></geometry>{grey}</visual>',
        f'<visual><origin xyz="{_fmt(s.camera_x, 0, cam_z + 0.015)}" rpy="0 0 0"/><geometry><box size="0.03 0.03 0.03"/></geometry>{dark}</visual>',
        # beacon sensor mast and head
        f'<visual><origin xyz="{_fmt(s.sensor_x, 0, (cz + lz / 2.0 + sen_z) / 2.0)}" rpy="0 0 0"/><geometry><cylinder radius="0.008" length="{sen_z - cz - lz / 2.0:.9g}"/></geometry>{grey}</visual>',
        f'<visual><origin xyz="{_fmt(s.sensor_x, 0, sen_z + 0.015)}" rpy="0 0 0"/><geometry><cylinder radius="0.025" length="0.03"/></geometry>{dark}</visual>',
    ]
    out = [
        '<?xml version="1.0"?>',
        '<robot name="petrobot_mobile">',
        f'<link name="base_link">{_inertial(s.chassis_mass, (s.chassis_x, 0.0, cz), body)}'
        + "".join(visuals)
        + f'<collision><origin xyz="{_fmt(s.chassis_x, 0, cz)}" rpy="0 0 0"/><geometry><box size="{_fmt(lx, ly, lz)}"/></geometry></collision>'
        "</link>",
    ]
    for side, y in (("left", s.track_width / 2.0), ("right", -s.track_width / 2.0)):
        geo = f'<origin xyz="0 0 0" rpy="{math.pi / 2:.9g} 0 0"/><geometry><cylinder radius="{r:.9g}" length="{s.wheel_width:.9g}"/></geometry>'
        # collision: a sphere of the wheel's radius touches the floor in the wheel's mid-plane, as
        # a crowned tyre does; Bullet's cylinder-plane contact jumps between the two rim edges and
        # made a straight run turn by about 1 degree per metre
        tyre = f'<geometry><sphere radius="{r:.9g}"/></geometry>'
        out.append(
            f'<joint name="{side}_wheel_joint" type="continuous"><parent link="base_link"/><child link="{side}_wheel"/>'
            f'<origin xyz="0 {y:.9g} 0" rpy="0 0 0"/><axis xyz="0 1 0"/>'
            f'<limit effort="{s.max_torque:.9g}" velocity="{s.max_wheel_speed:.9g}"/><dynamics damping="0" friction="0"/></joint>'
        )
        out.append(
            f'<link name="{side}_wheel">{_inertial(s.wheel_mass, (0, 0, 0), (dia, ax, dia))}'
            f"<visual>{geo}{dark}</visual><collision>{tyre}</collision>"
            f'<contact><lateral_friction value="{s.tyre_friction:.9g}"/><rolling_friction value="0.0"/>'
            '<spinning_friction value="0.001"/></contact></link>'
        )
    caster_z = s.caster_radius - r
    out.append(
        '<joint name="caster_mount" type="fixed"><parent link="base_link"/><child link="caster"/>'
        f'<origin xyz="{_fmt(s.caster_x, 0, caster_z)}" rpy="0 0 0"/></joint>'
    )
    sphere = f'<geometry><sphere radius="{s.caster_radius:.9g}"/></geometry>'
    out.append(
        f'<link name="caster">{_inertial(s.caster_mass, (0, 0, 0), (ball, ball, ball))}'
        f"<visual>{sphere}{grey}</visual><collision>{sphere}</collision>"
        # a ball transfer unit: the ball turns freely in every direction, modelled as no friction
        '<contact><lateral_friction value="0.0"/><rolling_friction value="0.0"/><spinning_friction value="0.0"/></contact></link>'
    )
    out.append("</robot>")
    return "\n".join(out) + "\n"


class WheelDrives:
    """The two wheel drives in velocity mode (see the module docstring).

    Args:
        client: the pybullet client.
        body: the robot's body id.
        joints: (left, right) wheel joint indices.
        spec: motor limits, ramp and encoder resolution.
        dt: physics step, s (the ramp's increment per step is ``spec.ramp · dt``).

    Attributes:
        target: (left, right) velocity set points, rad/s.
        demand: (left, right) ramped demand applied at the last step, rad/s.
        enabled: False lets the wheels turn freely (no torque), as a drive without power.
    """

    def __init__(self, client: Any, body: int, joints: tuple[int, int], spec: RobotSpec, dt: float) -> None:
        self.client = client
        self.body = body
        self.joints = list(joints)
        self.spec = spec
        self.dt = dt
        self.target = [0.0, 0.0]
        self.demand = [0.0, 0.0]
        self.enabled = True
        self._applied: tuple[float, float, bool] | None = None

    def set_velocity(self, left: float, right: float) -> None:
        """Velocity set points (rad/s, positive drives forward), clamped to the speed limit."""
        lim = self.spec.max_wheel_speed
        self.target = [max(-lim, min(lim, float(left))), max(-lim, min(lim, float(right)))]

    def step(self, t: float) -> None:
        """Step hook: ramp the demand toward the set points and command pybullet's motors."""
        del t
        inc = self.spec.ramp * self.dt
        for k in (0, 1):
            err = self.target[k] - self.demand[k]
            self.demand[k] += max(-inc, min(inc, err))
        key = (self.demand[0], self.demand[1], self.enabled)
        if key == self._applied:
            return
        self._applied = key
        force = self.spec.max_torque if self.enabled else 0.0
        self.client.setJointMotorControlArray(
            self.body, self.joints, self.client.VELOCITY_CONTROL,
            targetVelocities=list(self.demand), forces=[force, force],
        )

    def encoders(self) -> tuple[float, float]:
        """(left, right) wheel angles, rad, quantised to the encoder's counts."""
        q = 2.0 * math.pi / self.spec.encoder_counts
        states = self.client.getJointStates(self.body, self.joints)
        return (math.floor(states[0][0] / q) * q, math.floor(states[1][0] / q) * q)

    def velocities(self) -> tuple[float, float]:
        """(left, right) actual wheel speeds, rad/s."""
        states = self.client.getJointStates(self.body, self.joints)
        return float(states[0][1]), float(states[1][1])

    def torques(self) -> tuple[float, float]:
        """(left, right) motor torques applied at the last step, N m."""
        states = self.client.getJointStates(self.body, self.joints)
        return float(states[0][3]), float(states[1][3])


class MobileRobot:
    """The robot loaded into a pybullet world, with its drives.

    Args:
        client: the pybullet client.
        spec: the parameter table.
        pose: (x, y, heading) of the robot frame on the floor, m and rad.
        dt: physics step of the world, s.

    Attributes:
        body: pybullet body id.
        drives: the wheel drives (register :meth:`WheelDrives.step` as a step hook).
        link_index: pybullet link index by link name.
    """

    def __init__(self, client: Any, spec: RobotSpec | None = None, pose: tuple[float, float, float] = (0.0, 0.0, 0.0), *, dt: float = 0.004) -> None:
        self.client = client
        self.spec = s = spec or RobotSpec()
        fd, path = tempfile.mkstemp(suffix=".urdf", prefix="petrobot_mobile_")
        os.close(fd)
        try:
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(urdf(s))
            self.body = int(client.loadURDF(path, [0, 0, s.wheel_radius], flags=client.URDF_USE_INERTIA_FROM_FILE))
        finally:
            os.unlink(path)
        self.link_index: dict[str, int] = {}
        joints: dict[str, int] = {}
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            joints[info[1].decode()] = j
            self.link_index[info[12].decode()] = j
        wheels = (joints["left_wheel_joint"], joints["right_wheel_joint"])
        for j in range(-1, client.getNumJoints(self.body)):
            client.changeDynamics(self.body, j, linearDamping=0.0, angularDamping=0.0)
        info = client.getDynamicsInfo(self.body, -1)
        self._com_offset = np.asarray(info[3], dtype=float)  # link frame → inertial frame
        self.drives = WheelDrives(client, self.body, wheels, s, dt)
        self.place(*pose)

    def place(self, x: float, y: float, heading: float) -> None:
        """Teleport the robot at rest to pose (x, y, heading) on the floor, wheels at angle 0."""
        c, s = math.cos(heading), math.sin(heading)
        o = self._com_offset
        com = [x + c * o[0] - s * o[1], y + s * o[0] + c * o[1], self.spec.wheel_radius + o[2]]
        orn = self.client.getQuaternionFromEuler([0.0, 0.0, heading])
        self.client.resetBasePositionAndOrientation(self.body, com, orn)
        self.client.resetBaseVelocity(self.body, [0, 0, 0], [0, 0, 0])
        for j in self.drives.joints:
            self.client.resetJointState(self.body, j, 0.0, 0.0)
        self.drives.target = [0.0, 0.0]
        self.drives.demand = [0.0, 0.0]
        self.drives._applied = None

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the robot frame (axle midpoint on the floor), m and rad."""
        pos, orn = self.client.getBasePositionAndOrientation(self.body)
        m = self.client.getMatrixFromQuaternion(orn)
        o = self._com_offset
        x = pos[0] - (m[0] * o[0] + m[1] * o[1] + m[2] * o[2])
        y = pos[1] - (m[3] * o[0] + m[4] * o[1] + m[5] * o[2])
        return x, y, math.atan2(m[3], m[0])

    def twist(self) -> tuple[float, float]:
        """Ground truth (forward speed m/s, yaw rate rad/s) of the robot frame."""
        lin, ang = self.client.getBaseVelocity(self.body)
        _, _, th = self.pose()
        # the COM's velocity differs from the axle's by ω × offset; the forward component of that
        # difference is -ω·o_y = 0 for a centred chassis
        return lin[0] * math.cos(th) + lin[1] * math.sin(th), float(ang[2])
