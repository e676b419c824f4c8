"""Crossing an interruption: the retroreflector beacon, the resume point, and reacquisition.

Paper section 6 ("Mobile Robot Task"): at an interruption "the robot must detect the interruption,
and recover the track at the closest segment, for instance by following a cylindrical
retroreflector, located 1 meter above the point where the track resumes".

Beacon sensor model: a scanning sensor at a known height on the robot reports, for every
retroreflector it sees, the azimuth (bearing in the horizontal plane, + left) and the elevation
above the horizontal of the reflector's centre. The reflector's height above the sensor Δh being
known, the range in the floor plane follows from the elevation, ρ = Δh / tan(ε), and each
observation places the reflector's foot — the resume point — in the odometry frame. Range
uncertainty grows with range: σ_ρ = Δh · σ_ε / sin²ε.

Which beacon: on this floor (2 m squares, track through edge midpoints) a blank square's exit is
one of its three other edge midpoints: 2 m straight ahead of where the track ended, or √2 m away
at ±45° (the square's hidden path a straight or a 1 m arc). :class:`BeaconApproach` takes the
beacon observed nearest to one of these three *expected exits* (within ``gate``); given the
course rules (no blank next to a blank, each square used once) no other beacon can stand there.

Approach: pure pursuit (:func:`services.mobile.steering.pursuit_curvature`) toward the fused
resume-point estimate. Started where the track ended, with the track's heading, the pursuit circle
through a point 2 m ahead is the straight, through a point at (1, ±1) m the 1 m arc: the robot
retraces the hidden path and meets the resumed track along its tangent. Within ``hold_distance`` of
the resume point the curvature is held (pure pursuit is singular at the goal), and the track
detector takes over once it sees the track for a few frames (:class:`Reacquire`).

Pure module (no I/O).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from .lines import LineEstimate
from .odometry import Pose2D
from .steering import pursuit_curvature

__all__ = [
    "BeaconApproach",
    "BeaconModel",
    "BeaconObservation",
    "Reacquire",
    "expected_exits",
]


@dataclass(frozen=True, slots=True)
class BeaconObservation:
    """One retroreflector seen by the beacon sensor.

    Attributes:
        azimuth: bearing of the reflector's centre in the robot's horizontal plane, rad (+ left of
            the robot's x axis).
        elevation: angle of the reflector's centre above the sensor's horizontal plane, rad.
        t: time of the observation, s.
    """

    azimuth: float
    elevation: float
    t: float


@dataclass(frozen=True, slots=True, kw_only=True)
class BeaconModel:
    """What the robot knows of the beacon sensor and the beacons.

    Attributes:
        height_above_sensor: height of a reflector's centre above the sensor, m (1.0 m above the
            floor in the paper, sensor 0.3 m high: 0.7 m).
        sensor_x, sensor_y: sensor position in the robot frame, m.
        azimuth_sigma, elevation_sigma: 1-σ angular noise, rad (used to weight observations).
        min_elevation: observations flatter than this are ignored (range too uncertain), rad.

    Raises:
        ValueError: on a non-positive height.
    """

    height_above_sensor: float = 0.7
    sensor_x: float = 0.0
    sensor_y: float = 0.0
    azimuth_sigma: float = 0.01
    elevation_sigma: float = 0.01
    min_elevation: float = math.radians(8.0)

    def __post_init__(self) -> None:
        if not self.height_above_sensor > 0:
            raise ValueError("the beacon must be above the sensor (height_above_sensor > 0)")

    def locate(self, pose: Pose2D, obs: BeaconObservation) -> tuple[float, float, float] | None:
        """Foot of the observed reflector in the odometry frame.

        Args:
            pose: robot pose at the observation.
            obs: the observation.

        Returns:
            (x, y, σ) — position in m and its 1-σ uncertainty radius in m — or None when the
            elevation is below ``min_elevation``.
        """
        if obs.elevation < self.min_elevation:
            return None
        tan_e = math.tan(obs.elevation)
        rho = self.height_above_sensor / tan_e
        sin_e = math.sin(obs.elevation)
        s_rho = self.height_above_sensor * self.elevation_sigma / (sin_e * sin_e)
        sigma = math.hypot(s_rho, rho * self.azimuth_sigma)
        lx = self.sensor_x + rho * math.cos(obs.azimuth)
        ly = self.sensor_y + rho * math.sin(obs.azimuth)
        x, y = pose.to_world(lx, ly)
        return x, y, sigma


def expected_exits(
    end_x: float, end_y: float, heading: float, square: float = 2.0
) -> list[tuple[float, float]]:
    """The three possible resume points of a blank square entered at (end_x, end_y) along heading.

    Args:
        end_x, end_y: where the track ended (the blank square's entry edge midpoint), m.
        heading: direction of travel into the square, rad.
        square: side of the squares, m.

    Returns:
        [straight ahead, left-hand exit, right-hand exit] as (x, y) in the same frame, m.
    """
    h = square / 2.0
    c, s = math.cos(heading), math.sin(heading)
    fx, fy, lx, ly = c, s, -s, c
    return [
        (end_x + 2 * h * fx, end_y + 2 * h * fy),
        (end_x + h * fx + h * lx, end_y + h * fy + h * ly),
        (end_x + h * fx - h * lx, end_y + h * fy - h * ly),
    ]


class BeaconApproach:
    """Selects the beacon at the blank square's exit, fuses its observations, pursues it.

    Args:
        model: the beacon sensor model.
        square: side of the floor squares, m.
        gate: an observation is taken for the resume point if its foot lies within this distance of
            an expected exit (at the start) or of the present estimate (afterwards), m.
        hold_distance: within this distance of the resume point the curvature is held, m.

    Attributes:
        target: fused resume point (x, y) in the odometry frame, or None before :meth:`start`
            succeeded.
        exit_index: which expected exit the beacon matched (0 straight, 1 left, 2 right).
        observations_used: number of observations fused.
    """

    def __init__(
        self, model: BeaconModel, *, square: float = 2.0, gate: float = 0.5, hold_distance: float = 0.3
    ) -> None:
        self.model = model
        self.square = square
        self.gate = gate
        self.hold_distance = hold_distance
        self.target: tuple[float, float] | None = None
        self.exit_index = -1
        self.observations_used = 0
        self._weight = 0.0
        self._held: float | None = None

    def start(
        self,
        track_end: tuple[float, float, float],
        sightings: Iterable[tuple[Pose2D, Sequence[BeaconObservation]]],
    ) -> bool:
        """Choose the beacon marking the resume point.

        Args:
            track_end: (x, y, heading) where the track ended and its direction, odometry frame
                (m, m, rad).
            sightings: recent (pose, observations) pairs of the beacon sensor (any number; older
                ones are as good as new ones within odometry's drift).

        Returns:
            True if a beacon lies within ``gate`` of an expected exit (the estimate is then set).
        """
        exits = expected_exits(*track_end, square=self.square)
        best: tuple[float, int] | None = None
        feet: list[tuple[float, float, float]] = []
        for pose, observations in sightings:
            for obs in observations:
                foot = self.model.locate(pose, obs)
                if foot is None:
                    continue
                feet.append(foot)
                for k, (ex, ey) in enumerate(exits):
                    d = math.hypot(foot[0] - ex, foot[1] - ey)
                    if d < self.gate and (best is None or d < best[0]):
                        best = (d, k)
        self.target = None
        self._weight = 0.0
        self.observations_used = 0
        self._held = None
        if best is None:
            self.exit_index = -1
            return False
        self.exit_index = best[1]
        ex, ey = exits[best[1]]
        for foot in feet:
            if math.hypot(foot[0] - ex, foot[1] - ey) < self.gate:
                self._fuse(foot)
        return True

    def _fuse(self, foot: tuple[float, float, float]) -> None:
        w = 1.0 / max(foot[2], 1e-3) ** 2
        if self.target is None:
            self.target = (foot[0], foot[1])
        else:
            k = w / (self._weight + w)
            self.target = (
                self.target[0] + k * (foot[0] - self.target[0]),
                self.target[1] + k * (foot[1] - self.target[1]),
            )
        self._weight += w
        self.observations_used += 1

    def observe(self, pose: Pose2D, observations: Sequence[BeaconObservation]) -> None:
        """Fuse new observations that fall within ``gate`` of the present estimate."""
        if self.target is None:
            return
        for obs in observations:
            foot = self.model.locate(pose, obs)
            if foot is not None and math.hypot(foot[0] - self.target[0], foot[1] - self.target[1]) < self.gate:
                self._fuse(foot)

    def remaining(self, pose: Pose2D) -> float:
        """Distance (m) from the axle midpoint to the resume-point estimate (inf without one)."""
        if self.target is None:
            return math.inf
        return math.hypot(self.target[0] - pose.x, self.target[1] - pose.y)

    def curvature(self, pose: Pose2D) -> float:
        """Pure-pursuit curvature (1/m) toward the resume point; held within ``hold_distance``.

        Raises:
            RuntimeError: before a successful :meth:`start`.
        """
        if self.target is None:
            raise RuntimeError("no resume point: BeaconApproach.start() found no beacon")
        if self._held is not None:
            return self._held
        gx, gy = pose.to_local(*self.target)
        k = pursuit_curvature(gx, gy)
        if math.hypot(gx, gy) < self.hold_distance:
            self._held = k
        return k


class Reacquire:
    """Decides that the resumed track is found: confident detections in consecutive frames.

    Args:
        frames: consecutive frames needed.
        min_confidence: least :attr:`LineEstimate.confidence` of each (the share of the
            detector's rows or scan lines that found the track, discounted by the fit's residual:
            0.4 is 40 % of the view's length for the row-based detectors, 2 of 5 scan lines).
        max_offset: the track's lateral position at ``at_x`` must be within ±this, m.
        at_x: forward distance at which the offset is checked, m.
    """

    def __init__(
        self, *, frames: int = 2, min_confidence: float = 0.4, max_offset: float = 0.12, at_x: float = 0.26,
    ) -> None:
        self.frames = frames
        self.min_confidence = min_confidence
        self.max_offset = max_offset
        self.at_x = at_x
        self._run = 0

    def reset(self) -> None:
        """Forget the frames seen so far."""
        self._run = 0

    def update(self, line: LineEstimate | None) -> bool:
        """Feed one frame's estimate; True once ``frames`` good ones came in a row."""
        good = (
            line is not None
            and line.confidence >= self.min_confidence
            and abs(line.lateral_at(self.at_x)) <= self.max_offset
        )
        self._run = self._run + 1 if good else 0
        return self._run >= self.frames
