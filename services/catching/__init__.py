"""The catching testbed's node side (paper section 6, "Visual Servoing and Catching", Fig. 1).

A PUMA 560 with a cup catches ping-pong balls rolled across a table, guided by an overhead camera.
Everything a node of this testbed runs lives here; the simulated world that stands in for the
hardware is :mod:`sim.catching`.

Pure algorithms (no I/O, no clocks):

* :mod:`services.catching.vision` — ball vision: the three locators of the *locate* primitive task,
  the pixel → table homography, the rolling-ball model and the catch-line predictor, the per-frame
  tracker;
* :mod:`services.catching.robot` — the PUMA 560's kinematics and the catching motion control (set
  point → joint steps);
* :mod:`services.catching.setpoints` — the catching set points from the vision node to the motion
  node (validation, latest wins, staleness) and their subscription.

The nodes (drivers and primitive actions, placed by services.toml):

* vision node — :mod:`services.catching.camera` (the camera driver: frames, calibration, the
  ``image_sampling_tick`` events) and :mod:`services.catching.vision_node` (``locate_threshold``,
  ``locate_bgdiff``, ``locate_average``, ``predict``);
* motion node — :mod:`services.catching.arm` (the PUMA's driver: CAN drives, control thread,
  ``ball_caught`` events) and :mod:`services.catching.motion_node` (``move_home``, ``catch``).

Device links they use come from the framework (:mod:`services.devices`: the CiA 402 CAN master,
the frame grabber).
"""

__all__: list[str] = []
