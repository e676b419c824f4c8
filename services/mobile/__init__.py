"""The mobile-robot testbed's node side (paper section 6, "Mobile Robot Task", Figs. 2–3): its pure
perception and control algorithms, and the perception and drive nodes around them.

The robot follows a 5 cm track painted on a chessboard of 2 m squares, the track always in the
colour opposite to the square it crosses; it detects interruptions (squares without track), goes
to a cylindrical retroreflector that marks where the track resumes, picks the track up again and
stops on the T-shaped mark that ends it.

Modules (no I/O, no clocks, no simulator: numpy, OpenCV and the standard library only, so that the
same code runs on the robot's perception and drive nodes):

* :mod:`services.mobile.camera` — the downward camera's pixel ↔ floor mapping (robot frame);
* :mod:`services.mobile.lines` — three track detectors of different cost and reliability, and the
  thin-structure (contrast) feature they share with the end-mark detector;
* :mod:`services.mobile.marks` — T end-mark detection and the interruption (gap) monitor;
* :mod:`services.mobile.odometry` — differential-drive kinematics and wheel odometry;
* :mod:`services.mobile.steering` — set points, speed profile and the pure-pursuit steering law;
* :mod:`services.mobile.beacon` — retroreflector observations, resume-point estimation, the
  beacon approach and track reacquisition.

Frames and units: the *robot frame* has its origin on the floor below the midpoint of the driven
wheels' axle, x forward, y to the left, z up; angles are counter-clockwise positive (rad); lengths
in metres, times in seconds, wheel speeds in rad/s.

The nodes' shells around these algorithms, the only modules of the package that do I/O:
:mod:`services.mobile.perception_node` and :mod:`services.mobile.drive_node` (their drivers and
primitive actions, placed by services.toml; neither imports anything of the simulator: the camera
model, the robot's dimensions and the beacon height come from the frame server's info map).

**Perception node** — driver :class:`~services.mobile.perception_node.PerceptionDriver` (the downward camera and the beacon sensor,
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

**Drive node** — driver :class:`~services.mobile.drive_node.DriveDriver` (the wheel drives on the CAN bus, CiA 402 profile
velocity mode, :class:`services.devices.drives.VelocityCanDrives`): a control thread runs once per
SYNC, integrates the wheel encoders into odometry (:class:`services.mobile.odometry.Odometry`),
commands the latest valid steering set point's wheel speeds (:class:`~services.mobile.setpoints.SteeringInput`: validation,
latest wins, the **watchdog**: none for ``stale_s`` = 0.25 s → zero speed, a controlled stop on the
drives' ramp) and publishes the odometry (topic ``odometry``, every other SYNC). Action
``stop_robot``: brake to rest (the latest set point is forgotten), success once both wheels turn
slower than 0.05 rad/s; error when the bus is lost.
"""

__all__: list[str] = []
