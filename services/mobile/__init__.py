"""Pure perception and control algorithms of the mobile-robot testbed (paper section 6, "Mobile
Robot Task", Figs. 2–3).

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
"""

__all__: list[str] = []
