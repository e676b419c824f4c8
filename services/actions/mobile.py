"""The mobile robot's nodes (paper section 6, "Mobile Robot Task", Fig. 3): perception and drive.

**Perception node** — driver :class:`PerceptionDriver` (the downward camera and the beacon sensor,
both from the world's frame server: each frame's header carries the latest beacon scan) and the
primitive actions, each a loop over camera frames around one controller of
:mod:`services.mobile.tasks`, streaming its steering set points to the drive node as events on
topic ``steering`` (:mod:`services.mobile.setpoints`):

====================  ===================  ========================================================
action                primitive task       outcomes (``int:<task>.<outcome>``)
====================  ===================  ========================================================
``follow_centroid``   ``follow_track``     success ``interruption`` / ``end``, failure ``lost``,
``follow_ransac``                          error; the three detectors are the learner's choice
``follow_scanline``
``find_beacon``       ``find_beacon``      success ``found``, failure ``not_found``, error
``goto_beacon``       ``goto_beacon``      success (``ok``), error
``reacquire_track``   ``reacquire_track``  success (``ok``), failure ``lost``, error
``stop_at_t``         ``stop_at_t``        success (``ok``), error
====================  ===================  ========================================================

Every streaming action's value has ``t0`` and ``t``, the simulated times of its first and last
frame. A follow action's value: ``{detector, frames, seen, dropouts, distance_m, cross_track_proxy_m, note,
setpoints}`` (``cross_track_proxy_m``: RMS of the detected line's lateral offset at the camera's view
centre, the node's own measure of how well it followed; the world's ground truth is the
simulator's); its cost is the CPU time of its image processing, s. **Specification**
(:meth:`services.mobile.tasks.FollowTrack.judge`): the segment ended with ``interruption`` or ``end``
and the detector lost the track at most ``max_dropouts`` times (param, default 0) on the way — a
loss shorter than the 6 cm gap after which the track was seen again, so it was there all along.
Within it the action is a success; otherwise a failure *with the same outcome* (the net branches on
the outcome, the learner counts the failure); ``lost`` is a failure.

Every action ends ``error`` when the camera is lost (no frame for ``frame_timeout_s``, 1 s), when the
drive node's odometry stops (none for ``odometry_timeout_s``, 1 s: node dead, link cut), when the
drive node reports that its **watchdog** stopped the wheels during the action (set points stopped
reaching it) or a drive fault, or on ``timeout_s`` (60 s of camera time).

**Drive node** — driver :class:`DriveDriver` (the wheel drives on the CAN bus, CiA 402 profile
velocity mode, :class:`services.devices.drives.WheelCanDrives`): a control thread runs once per
SYNC, integrates the wheel encoders into odometry (:class:`services.mobile.odometry.Odometry`),
commands the latest valid steering set point's wheel speeds (:class:`SteeringInput`: validation,
latest wins, the **watchdog**: none for ``stale_s`` = 0.25 s → zero speed, a controlled stop on the
drives' ramp) and publishes the odometry (topic ``odometry``, every other SYNC). Action
``stop_robot``: brake to rest (the latest set point is forgotten), success once both wheels turn
slower than 0.05 rad/s; error when the bus is lost.

Code: :mod:`services.actions.mobile_perception` and :mod:`services.actions.mobile_drive` (this module
re-exports both, the names services.toml uses). Neither node imports anything of the simulator: the camera model, the robot's dimensions and the
beacon height come from the frame server's info map.
"""

from __future__ import annotations

from services.actions.mobile_drive import DEFAULT_CAN_PORT, DriveDriver, StopRobot
from services.actions.mobile_perception import (
    DEFAULT_CAMERA_PORT,
    FindBeaconAction,
    FollowCentroid,
    FollowRansac,
    FollowScanline,
    GotoBeaconAction,
    PerceptionDriver,
    ReacquireTrackAction,
    StopAtTAction,
)

__all__ = [
    "DEFAULT_CAMERA_PORT",
    "DEFAULT_CAN_PORT",
    "DriveDriver",
    "FindBeaconAction",
    "FollowCentroid",
    "FollowRansac",
    "FollowScanline",
    "GotoBeaconAction",
    "PerceptionDriver",
    "ReacquireTrackAction",
    "StopAtTAction",
    "StopRobot",
]
