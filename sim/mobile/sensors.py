"""The mobile robot's sensors in simulation: two downward-camera back ends and the beacon sensor.

Paper section 6 ("Mobile Robot Task"): the robot follows the track by vision and finds where the
track resumes by "following a cylindrical retroreflector".

Cameras — one model (:class:`services.mobile.camera.GroundCamera`), two renderers delivering the
same timestamped :class:`services.devices.framegrabber.Frame` with an (H, W) uint8 grey image:

* :class:`AnalyticCamera` — warps the :class:`sim.mobile.floor.FloorMap` with the camera's
  pixel → floor affine map composed with the robot's pose (one ``cv2.warpAffine``, bilinear), then
  adds optics blur (Gaussian), vignetting (a radial gain falling to ``1 - vignetting`` in the
  corners), a per-frame illumination gain and Gaussian grey-level noise: tens of microseconds a
  frame, for benchmarks;
* :class:`TinyCamera` — pybullet's TinyRenderer on the textured floor (``PybulletFloor(...,
  textured=True)``), with the same noise: a few milliseconds a frame at 80×60, for the demo.

Beacon sensor (:class:`BeaconSensor`): a scanning retroreflector sensor on a mast reports the
azimuth and elevation of every reflector within its field of view and range whose centre it can
see — line of sight checked with pybullet ``rayTestBatch`` (the first body hit must be the
reflector) — with Gaussian angular noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from services.devices.framegrabber import Frame
from services.mobile.beacon import BeaconObservation
from services.mobile.camera import GroundCamera

from .floor import FloorMap
from .robot import RobotSpec

__all__ = [
    "AnalyticCamera",
    "BeaconSensor",
    "BeaconSensorSpec",
    "ImageNoise",
    "TinyCamera",
    "robot_camera",
]

Pose = tuple[float, float, float]


def robot_camera(spec: RobotSpec | None = None, *, width: int = 80, height: int = 60, metres_per_px: float = 0.004) -> GroundCamera:
    """The camera model of a robot: view centred below the camera's centre of projection."""
    s = spec or RobotSpec()
    return GroundCamera(
        width=width, height=height, metres_per_px=metres_per_px, x_centre=s.camera_x,
        mount_height=s.camera_height,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class ImageNoise:
    """Image degradations added by both camera back ends.

    Attributes:
        sigma: 1-σ Gaussian grey-level noise per pixel.
        blur_px: 1-σ of a Gaussian optics blur, pixels (0 = none).
        vignetting: relative brightness loss in the image corners (0 = none).
        gain_sigma: 1-σ of a per-frame illumination gain around 1 (0 = none).
        spots: mean number of scuffs per frame (Poisson): ellipses of 2–8 px half-axes in a random
            grey, drawn before the blur (dust, tyre marks, worn paint; 0 = clean floor).
    """

    sigma: float = 5.0
    blur_px: float = 0.6
    vignetting: float = 0.15
    gain_sigma: float = 0.05
    spots: float = 0.0


class _Degrade:
    def __init__(self, shape: tuple[int, int], noise: ImageNoise, rng: np.random.Generator) -> None:
        self.noise = noise
        self.rng = rng
        h, w = shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((u - (w - 1) / 2) / ((w - 1) / 2)) ** 2 + ((v - (h - 1) / 2) / ((h - 1) / 2)) ** 2
        self.vignette = (1.0 - noise.vignetting * r2 / 2.0).astype(np.float32)
        # pre-drawn noise fields; a frame takes one at a random row offset (no per-pixel draws)
        self.bank = (
            rng.normal(0.0, noise.sigma, (8, 2 * h, w)).astype(np.float32) if noise.sigma > 0 else None
        )

    def apply(self, img: np.ndarray) -> np.ndarray:
        n = self.noise
        if n.spots > 0:
            k = int(self.rng.poisson(n.spots))
            if k:
                img = img.copy()
                h, w = img.shape
                for _ in range(k):
                    c = (int(self.rng.integers(w)), int(self.rng.integers(h)))
                    axes = (int(self.rng.integers(2, 9)), int(self.rng.integers(2, 9)))
                    cv2.ellipse(img, c, axes, float(self.rng.uniform(0, 180)), 0, 360, int(self.rng.integers(0, 256)), -1)
        f: np.ndarray = img.astype(np.float32)
        if n.blur_px > 0:
            f = cv2.GaussianBlur(f, (0, 0), n.blur_px)
        gain = 1.0 + (float(self.rng.normal(0.0, n.gain_sigma)) if n.gain_sigma > 0 else 0.0)
        f = f * (self.vignette * np.float32(gain))
        if self.bank is not None:
            h = img.shape[0]
            k = int(self.rng.integers(self.bank.shape[0]))
            off = int(self.rng.integers(h))
            f += self.bank[k, off : off + h]
        return np.clip(f, 0.0, 255.0).astype(np.uint8)


class AnalyticCamera:
    """The downward camera rendered by warping the floor map (see the module docstring).

    Args:
        camera: the camera model.
        floor: the floor map of the course.
        noise: image degradations.
        seed: seed of the noise generator.

    Attributes:
        seq: number of the next frame.
    """

    def __init__(self, camera: GroundCamera, floor: FloorMap, *, noise: ImageNoise | None = None, seed: int = 0) -> None:
        self.camera = camera
        self.floor = floor
        self.seq = 0
        self._degrade = _Degrade((camera.height, camera.width), noise or ImageNoise(), np.random.default_rng(seed))
        a = np.vstack([camera.pixel_to_robot_affine(), [0.0, 0.0, 1.0]])
        self._pixel_to_robot = a
        self._world_to_map = np.vstack([floor.world_to_pixel(), [0.0, 0.0, 1.0]])

    def render(self, pose: Pose, *, clean: bool = False) -> np.ndarray:
        """(H, W) uint8 grey image seen from robot pose (x, y, heading) (m, rad); ``clean`` skips
        the degradations."""
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        robot_to_world = np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])
        m = (self._world_to_map @ robot_to_world @ self._pixel_to_robot)[:2]
        img = cv2.warpAffine(
            self.floor.image, m, (self.camera.width, self.camera.height),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT, borderValue=128,
        )
        return img if clean else self._degrade.apply(img)

    def grab(self, pose: Pose, t: float) -> Frame:
        """The next frame, exposed at simulated time ``t`` (s) from ``pose``."""
        f = Frame(self.seq, t, self.render(pose))
        self.seq += 1
        return f


class TinyCamera:
    """The downward camera rendered by pybullet's TinyRenderer (see the module docstring).

    Renders a client holding the textured floor (:attr:`sim.mobile.world.MobileWorld.render_client`,
    floor only: TinyRenderer does not clip geometry behind the camera's plane).

    Args:
        camera: the camera model.
        client: the pybullet client to render.
        noise: image degradations (blur, vignetting, gain, noise).
        seed: seed of the noise generator.
        light: (ambient, diffuse) coefficients of pybullet's light.
    """

    def __init__(
        self, camera: GroundCamera, client: Any, *, noise: ImageNoise | None = None, seed: int = 0,
        light: tuple[float, float] = (0.9, 0.1),
    ) -> None:
        self.camera = camera
        self.client = client
        self.seq = 0
        self.light = light
        self._degrade = _Degrade((camera.height, camera.width), noise or ImageNoise(), np.random.default_rng(seed))
        self._proj = client.computeProjectionMatrixFOV(
            camera.fov_y, camera.width / camera.height, 0.02, camera.mount_height + 0.1
        )

    def render(self, pose: Pose, *, clean: bool = False) -> np.ndarray:
        """(H, W) uint8 grey image of the world seen from robot pose (x, y, heading)."""
        cam = self.camera
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        ex = x + c * cam.x_centre - s * cam.y_centre
        ey = y + s * cam.x_centre + c * cam.y_centre
        view = self.client.computeViewMatrix([ex, ey, cam.mount_height], [ex, ey, 0.0], [c, s, 0.0])
        _, _, rgba, _, _ = self.client.getCameraImage(
            cam.width, cam.height, view, self._proj, shadow=0, renderer=self.client.ER_TINY_RENDERER,
            flags=self.client.ER_NO_SEGMENTATION_MASK, lightDirection=[0.0, 0.0, 1.0],
            lightAmbientCoeff=self.light[0], lightDiffuseCoeff=self.light[1], lightSpecularCoeff=0.0,
        )
        img = np.asarray(rgba, dtype=np.uint8).reshape(cam.height, cam.width, 4)
        grey = cv2.cvtColor(img, cv2.COLOR_RGBA2GRAY)
        return grey if clean else self._degrade.apply(grey)

    def grab(self, pose: Pose, t: float) -> Frame:
        """The next frame, exposed at simulated time ``t`` (s) from ``pose``."""
        f = Frame(self.seq, t, self.render(pose))
        self.seq += 1
        return f


@dataclass(frozen=True, slots=True, kw_only=True)
class BeaconSensorSpec:
    """The beacon sensor's data sheet.

    Attributes:
        half_fov: half of the horizontal field of view about the robot's x axis, rad.
        max_elevation: steepest elevation seen, rad (the sensor's vertical window).
        max_range: farthest reflector seen (floor distance), m.
        azimuth_sigma, elevation_sigma: 1-σ Gaussian angular noise, rad.
        rate: scans per second (the caller decides when to scan; informative).
    """

    half_fov: float = math.radians(70.0)
    max_elevation: float = math.radians(65.0)
    max_range: float = 6.0
    azimuth_sigma: float = math.radians(0.3)
    elevation_sigma: float = math.radians(0.3)
    rate: float = 20.0


class BeaconSensor:
    """Simulated retroreflector sensor (see the module docstring).

    Args:
        client: the pybullet client.
        beacons: (body id, (x, y, z) centre) of each reflector.
        robot: the robot's parameter table (sensor position).
        spec: the sensor's data sheet.
        seed: seed of the noise generator.
    """

    def __init__(
        self, client: Any, beacons: list[tuple[int, tuple[float, float, float]]], robot: RobotSpec | None = None,
        spec: BeaconSensorSpec | None = None, *, seed: int = 0,
    ) -> None:
        self.client = client
        self.beacons = list(beacons)
        self.robot = robot or RobotSpec()
        self.spec = spec or BeaconSensorSpec()
        self.rng = np.random.default_rng(seed)

    def origin(self, pose: Pose) -> tuple[float, float, float]:
        """World position of the sensor for robot pose (x, y, heading), m."""
        x, y, th = pose
        return (x + math.cos(th) * self.robot.sensor_x, y + math.sin(th) * self.robot.sensor_x, self.robot.sensor_height)

    def observe(self, pose: Pose, t: float) -> list[BeaconObservation]:
        """The reflectors seen from robot pose (x, y, heading) at time t (s), noisy."""
        sp = self.spec
        o = self.origin(pose)
        cands = []
        for body, (bx, by, bz) in self.beacons:
            dx, dy, dz = bx - o[0], by - o[1], bz - o[2]
            rho = math.hypot(dx, dy)
            az = (math.atan2(dy, dx) - pose[2] + math.pi) % (2 * math.pi) - math.pi
            el = math.atan2(dz, rho)
            if rho <= sp.max_range and abs(az) <= sp.half_fov and 0.0 < el <= sp.max_elevation:
                cands.append((body, (bx, by, bz), az, el))
        if not cands:
            return []
        hits = self.client.rayTestBatch([o] * len(cands), [c[1] for c in cands])
        out = []
        for (body, _, az, el), hit in zip(cands, hits):
            if hit[0] != body:
                continue
            out.append(
                BeaconObservation(
                    az + float(self.rng.normal(0.0, sp.azimuth_sigma)),
                    el + float(self.rng.normal(0.0, sp.elevation_sigma)),
                    t,
                )
            )
        return out
