"""The simulated catching testbed (paper section 6, Fig. 1; docs/catching.md).

Modules: :mod:`sim.catching.world` (the table, the thrower, the ball, the PUMA with its cup and
crossfire sensor in pybullet), :mod:`sim.catching.puma560` (the PUMA's URDF and dynamics),
:mod:`sim.catching.camera` (the overhead camera: model, renderers, calibration),
:mod:`sim.catching.process` (``petrobot sim catching``: the world as a process serving the camera
and the CAN bus).
"""

__all__: list[str] = []
