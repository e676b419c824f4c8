"""Where a driver's device is served: what ``petrobot up`` checks before starting a node, and where
``petrobot sim`` serves it.

A driver whose device sits behind a TCP server (the camera server, the CAN gateway; in the
simulation both are served by ``petrobot sim catching`` or ``petrobot sim mobile``) says so with a
class method ``device(params) -> DeviceEndpoint``. Pure: no sockets here (the probe is
:mod:`services.devices.probe`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PROTOCOLS", "DeviceEndpoint"]

PROTOCOLS = ("frames", "socketcand", "zenoh")
"""What a device server speaks: the frame grabber's protocol (:mod:`services.devices.framegrabber`),
socketcand's ASCII protocol (a CAN gateway) or Zenoh's (a Zenoh router, :mod:`services.ros2`)."""


@dataclass(frozen=True, slots=True)
class DeviceEndpoint:
    """The TCP server a driver needs.

    Attributes:
        what: what it is, in a few words ("camera server").
        host: its address.
        port: its TCP port.
        served_by: what serves it when the hardware is simulated: the command
            (``"petrobot sim catching"``), maybe followed by what else does in parentheses.
        protocol: what the server speaks, one of :data:`PROTOCOLS`.
    """

    what: str
    host: str
    port: int
    served_by: str
    protocol: str = "frames"

    def describe(self) -> str:
        """``"camera server 127.0.0.1:7210"``."""
        return f"{self.what} {self.host}:{self.port}"
