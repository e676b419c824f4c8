"""The simulated worlds of the testbeds (pybullet) and their hardware-like servers (camera, CAN gateway).

The simulation stands in for the hardware: it serves the same protocols a real camera and CAN
gateway would, so the nodes cannot tell the difference. It imports :mod:`services` (robot data
sheets, codecs, vision geometry), never :mod:`coordinator`.
"""

__all__: list[str] = []
