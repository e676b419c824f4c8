"""Steering and speed: set points for the wheel drives.

The drive node takes a stream of :class:`SteeringSetPoint` s — a forward speed and a path curvature, turned
into a velocity set point per wheel (rad/s) with the drive's geometry — each numbered and stamped
so that the receiver can drop stale or out-of-order ones.

Steering law: **pure pursuit** (Coulter, "Implementation of the pure pursuit path tracking
algorithm", CMU-RI-TR-92-01, 1992). A goal point (x_g, y_g) on the path, about ``look_ahead``
ahead, is reached by the circle tangent to the robot's heading through it:

    κ = 2 y_g / (x_g² + y_g²).

On a path of constant curvature (the track's straights and 1 m arcs) the law has no steady-state
cross-track error: the circle it commands *is* the path when the robot is on it. The camera
supplies the goal point directly: the fitted centre line evaluated at the look-ahead distance.
Crossing an interruption, the goal point is the estimated resume point (:mod:`services.mobile.
beacon`), which makes the robot retrace a straight or a 1 m arc through the blank square.

Speed profile (:class:`SpeedLimits`): cruise speed, lowered on curves so that the lateral
acceleration v²|κ| stays within bounds, lowered when the track detection is weak; changes limited
to the acceleration and deceleration bounds; a stop at a given distance d uses v ≤ √(2 a_dec d).
Pure module (no I/O).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .lines import LineEstimate
from .odometry import DriveGeometry

__all__ = ["PurePursuit", "SpeedLimits", "SteeringController", "SteeringSetPoint", "pursuit_curvature"]


@dataclass(frozen=True, slots=True)
class SteeringSetPoint:
    """A steering set point for the drive node (the catching testbed's is
    :class:`services.catching.setpoints.CatchSetPoint`).

    Attributes:
        seq: sequence number, from 0, increasing by one per set point of a stream.
        t: time the set point was computed for, s (the time stamp of the frame it came from).
        v: forward speed, m/s.
        curvature: path curvature, 1/m (+ turning left).
        left, right: wheel velocity set points, rad/s (positive drives forward).
    """

    seq: int
    t: float
    v: float
    curvature: float
    left: float
    right: float


def pursuit_curvature(x: float, y: float, max_curvature: float = 4.0) -> float:
    """Curvature (1/m) of the circle tangent to the robot's x axis at the origin through (x, y).

    Args:
        x, y: goal point in the robot frame, m.
        max_curvature: the result is clamped to ±this (a point beside or behind the robot).
    """
    d2 = x * x + y * y
    if d2 < 1e-9:
        return 0.0
    k = 2.0 * y / d2
    return max(-max_curvature, min(max_curvature, k))


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedLimits:
    """Speed profile bounds.

    Attributes:
        cruise: speed on a well-seen track, m/s.
        min_speed: speed floor while the track is weak or being searched, m/s.
        accel: acceleration bound, m/s².
        decel: deceleration bound (also used to stop at a distance), m/s².
        lateral: bound on lateral acceleration v²·|κ|, m/s².
    """

    cruise: float = 0.8
    min_speed: float = 0.25
    accel: float = 1.0
    decel: float = 1.5
    lateral: float = 1.2

    def curve_speed(self, curvature: float) -> float:
        """Highest speed (m/s) on a path of this curvature within the lateral bound."""
        k = abs(curvature)
        return self.cruise if k < 1e-6 else min(self.cruise, math.sqrt(self.lateral / k))

    def stop_speed(self, distance: float) -> float:
        """Highest speed (m/s) from which the robot still stops within ``distance`` m."""
        return math.sqrt(2.0 * self.decel * max(0.0, distance))


@dataclass(frozen=True, slots=True, kw_only=True)
class PurePursuit:
    """Pure pursuit on the camera's centre-line estimate.

    Attributes:
        look_ahead: forward distance of the goal point on the track, m (inside the camera's view).
        max_curvature: bound on the commanded curvature, 1/m.
    """

    look_ahead: float = 0.26
    max_curvature: float = 4.0

    def curvature(self, line: LineEstimate) -> float:
        """Commanded curvature (1/m) toward the track point ``look_ahead`` ahead.

        The goal is the fitted centre line at x = look_ahead (extrapolated when the rows found do
        not reach so far).
        """
        xg = self.look_ahead
        yg = line.lateral_at(xg)
        return pursuit_curvature(xg, yg, self.max_curvature)


class SteeringController:
    """Turns (speed wish, curvature) into numbered, stamped, rate-limited set points.

    Args:
        geometry: the drive geometry the wheel speeds are computed with.
        limits: the speed profile bounds.

    Attributes:
        seq: sequence number of the next set point.
        v: the last commanded speed, m/s.
    """

    def __init__(self, geometry: DriveGeometry, limits: SpeedLimits | None = None) -> None:
        self.geometry = geometry
        self.limits = limits or SpeedLimits()
        self.seq = 0
        self.v = 0.0
        self._t: float | None = None

    def command(self, t: float, v_wish: float, curvature: float) -> SteeringSetPoint:
        """The set point for time ``t`` (s): speed toward ``v_wish`` within the acceleration bounds
        and the curve bound, along ``curvature`` (1/m).

        Raises:
            ValueError: if t goes backwards.
        """
        if self._t is not None and t < self._t:
            raise ValueError(f"set point time went backwards: {t} < {self._t}")
        dt = 0.0 if self._t is None else t - self._t
        self._t = t
        lim = self.limits
        target = max(0.0, min(v_wish, lim.curve_speed(curvature)))
        if target > self.v:
            self.v = min(target, self.v + lim.accel * dt) if dt > 0 else self.v
        else:
            # braking is never limited below a requested stop (the stop profile already is)
            self.v = target
        left, right = self.geometry.wheel_speeds(self.v, curvature)
        sp = SteeringSetPoint(self.seq, t, self.v, curvature, left, right)
        self.seq += 1
        return sp

    def stop(self, t: float) -> SteeringSetPoint:
        """A zero-speed set point at time ``t``."""
        self.v = 0.0
        self._t = t if self._t is None else max(self._t, t)
        sp = SteeringSetPoint(self.seq, t, 0.0, 0.0, 0.0, 0.0)
        self.seq += 1
        return sp
