"""The simulated mobile-robot testbed (paper section 6, Figs. 2-3): a chessboard floor with a track,
courses, a differential-drive robot with wheel drives, its downward camera and beacon sensor
(docs/mobile.md).

Modules: :mod:`sim.mobile.course` and :mod:`sim.mobile.coursefile` (tiles, geometry, course files,
the seeded generator), :mod:`sim.mobile.floor` (analytic colour and texture from one geometry),
:mod:`sim.mobile.robot` (URDF, wheel drives, encoders), :mod:`sim.mobile.sensors` (cameras, beacon
sensor), :mod:`sim.mobile.world` (the pybullet world) and :mod:`sim.mobile.harness` (closed-loop
runs of a course in lock-step time).
"""

__all__: list[str] = []
