"""The ROS 2 reach: primitive actions that are ROS 2 actions, services and publications, events
from ROS 2 topics, over Zenoh, with no ROS installed (docs/ros2.md).

The pure core (no I/O, checked by ``mypy --strict``): :mod:`~services.ros2.names` (ROS names,
mangling, DDS type names, rcl_action's composed names), :mod:`~services.ros2.qos`,
:mod:`~services.ros2.graph` (key expressions, liveliness tokens and attachments of the rmw_zenoh and
zenoh-bridge-ros2dds dialects), :mod:`~services.ros2.typestore` (interface types from ``.msg``,
``.srv`` and ``.action`` definitions: CDR codec, RIHS01 hashes, checked field values),
:mod:`~services.ros2.condition` (conditions on message fields), :mod:`~services.ros2.outcome`
(ROS statuses → petrobot results) and :mod:`~services.ros2.config` (the ``ros2`` tables of
services.toml).

The asyncio shells over eclipse-zenoh: :mod:`~services.ros2.session` (one Zenoh session per node),
:mod:`~services.ros2.endpoints` (service and action clients, subscriptions, publications),
:mod:`~services.ros2.driver` (the node's ROS 2 driver, which also raises topic events) and
:mod:`~services.ros2.actions` (the primitive action).
"""

__all__: list[str] = []
