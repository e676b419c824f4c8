"""The simulated ROS 2 side (docs/ros2.md): a Zenoh router (:mod:`sim.ros2.process`, ``petrobot sim
zenoh``) and a stand-in ROS 2 robot built on zenoh-ros2-sdk (:mod:`sim.ros2.robot`, ``petrobot sim
ros2``) serving the ROS 2 tutorials' AddTwoInts service, Fibonacci action and a Bool topic."""

__all__: list[str] = []
