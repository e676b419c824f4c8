"""Differential-drive kinematics and wheel odometry.

A differential-drive robot has two driven wheels of radius r on a common axle, a distance b apart
(the *track width*), and a passive caster. With wheel angular speeds ω_l, ω_r (rad/s, positive
driving forward) the body twist is

    v = r (ω_r + ω_l) / 2,       ω = r (ω_r - ω_l) / b,

and a path of curvature κ = ω / v at speed v needs ω_{l,r} = v (1 ∓ κ b / 2) / r (Siegwart,
Nourbakhsh & Scaramuzza, *Introduction to Autonomous Mobile Robots*, 2nd ed., §3.2).

Odometry integrates the wheel encoder increments Δφ_l, Δφ_r between two readings: each wheel
travels Δs = r Δφ, the axle midpoint travels Δs = (Δs_r + Δs_l)/2 and turns Δθ = (Δs_r - Δs_l)/b;
the motion between readings is taken as an arc of constant curvature (exact for constant wheel
speeds), so the pose is updated with the chord of that arc:

    x += Δs · sinc(Δθ/2) · cos(θ + Δθ/2),   y += Δs · sinc(Δθ/2) · sin(θ + Δθ/2),   θ += Δθ.

Wheel slip and a wrong wheel radius or track width are the usual errors; the model's parameters
may differ from the true robot's (see :class:`DriveGeometry`). Pure module (no I/O).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["DriveGeometry", "Odometry", "Pose2D", "wrap_angle"]


def wrap_angle(a: float) -> float:
    """The angle a (rad) wrapped into [-π, π)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A planar pose of the robot frame.

    Attributes:
        x, y: position of the axle midpoint, m.
        theta: heading (direction of the robot's x axis), rad, CCW from the frame's x axis.
        s: path length travelled by the axle midpoint since the odometry started, m (forward
            motion adds, backward motion subtracts).
        t: time of the reading the pose was computed from, s.
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    s: float = 0.0
    t: float = 0.0

    def to_local(self, px: float, py: float) -> tuple[float, float]:
        """A point (px, py) of the odometry frame expressed in this pose's robot frame, m."""
        dx, dy = px - self.x, py - self.y
        c, s = math.cos(self.theta), math.sin(self.theta)
        return c * dx + s * dy, -s * dx + c * dy

    def to_world(self, lx: float, ly: float) -> tuple[float, float]:
        """A point (lx, ly) of this pose's robot frame expressed in the odometry frame, m."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return self.x + c * lx - s * ly, self.y + s * lx + c * ly


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveGeometry:
    """Wheel radii and track width of a differential drive, as the controller believes them.

    Attributes:
        wheel_radius: nominal radius r of both driven wheels, m.
        track_width: distance b between the wheels' contact points, m.
        right_scale: ratio of the right wheel's radius to the nominal one (1 = equal wheels); an
            odometry calibration parameter.

    Raises:
        ValueError: on non-positive sizes.
    """

    wheel_radius: float = 0.05
    track_width: float = 0.30
    right_scale: float = 1.0

    def __post_init__(self) -> None:
        if not (self.wheel_radius > 0 and self.track_width > 0 and self.right_scale > 0):
            raise ValueError("wheel radius, track width and right_scale must be positive")

    def wheel_speeds(self, v: float, curvature: float) -> tuple[float, float]:
        """(ω_left, ω_right), rad/s, for forward speed v (m/s) along a path of curvature κ (1/m)."""
        half = curvature * self.track_width / 2.0
        r = self.wheel_radius
        return v * (1.0 - half) / r, v * (1.0 + half) / (r * self.right_scale)

    def twist(self, left: float, right: float) -> tuple[float, float]:
        """(v m/s, ω rad/s) of the body for wheel speeds ``left``, ``right`` in rad/s."""
        sl = self.wheel_radius * left
        sr = self.wheel_radius * self.right_scale * right
        return (sr + sl) / 2.0, (sr - sl) / self.track_width


class Odometry:
    """Dead reckoning from the two wheel encoders (see the module docstring).

    Args:
        geometry: the drive's believed wheel radii and track width.
        pose: the initial pose (default: origin, heading 0).

    Attributes:
        pose: the present pose estimate.
    """

    def __init__(self, geometry: DriveGeometry, pose: Pose2D | None = None) -> None:
        self.geometry = geometry
        self.pose = pose or Pose2D()
        self._last: tuple[float, float] | None = None

    def reset(self, pose: Pose2D | None = None) -> None:
        """Start again from ``pose``; the next reading only sets the encoder reference."""
        self.pose = pose or Pose2D()
        self._last = None

    def update(self, left: float, right: float, t: float) -> Pose2D:
        """Take an encoder reading and return the new pose.

        Args:
            left, right: absolute wheel angles, rad (any origin; only differences are used).
            t: time of the reading, s.

        Returns:
            The updated pose (the first reading only sets the reference and stamps the pose).
        """
        if self._last is None:
            self._last = (left, right)
            p = self.pose
            self.pose = Pose2D(p.x, p.y, p.theta, p.s, t)
            return self.pose
        g = self.geometry
        dl = (left - self._last[0]) * g.wheel_radius
        dr = (right - self._last[1]) * g.wheel_radius * g.right_scale
        self._last = (left, right)
        ds = (dr + dl) / 2.0
        dth = (dr - dl) / g.track_width
        half = dth / 2.0
        chord = ds * (math.sin(half) / half if abs(half) > 1e-9 else 1.0 - half * half / 6.0)
        p = self.pose
        mid = p.theta + half
        self.pose = Pose2D(
            p.x + chord * math.cos(mid),
            p.y + chord * math.sin(mid),
            wrap_angle(p.theta + dth),
            p.s + ds,
            t,
        )
        return self.pose
