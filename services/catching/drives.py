"""The PUMA's CAN bus as the motion node sees it: six CiA 402 joint drives and the crossfire module.

The catching testbed's use of the framework's CANopen master (:class:`services.devices.drives.CanDrives`):
the device file (``devices/puma.toml``) names the joint drives (nodes 1..6 in the simulated world, in
cyclic synchronous position mode) and the cup's crossfire sensor, an I/O module (``[io.crossfire]``,
a CiA 401 digital input: bit 0 of its first input byte says whether the light beam is interrupted).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from services.devices.devicefile import BusSpec
from services.devices.drives import CanDrives

__all__ = ["CROSSFIRE", "CrossfireCallback", "PumaDrives"]

CROSSFIRE = "crossfire"
"""Name of the crossfire module's table in the device file (``[io.crossfire]``)."""

CrossfireCallback = Callable[[bool, float], None]
"""Called from the receive thread with the crossfire state (True: beam interrupted) and its bus time, s."""


class PumaDrives(CanDrives):
    """The PUMA's joint drives and crossfire module (arguments as :class:`CanDrives`'s; the device
    file must have an ``[io.crossfire]`` table).

    Raises:
        services.devices.devicefile.DeviceFileError: the device file names no crossfire module.
    """

    def __init__(self, host: str, port: int, heartbeat_timeout: float = 0.5, silence_timeout: float = 2.0,
                 clock: Callable[[], float] = time.monotonic, *, bus: BusSpec) -> None:
        super().__init__(host, port, heartbeat_timeout, silence_timeout, clock, bus=bus)
        self._crossfire: bool | None = None
        self._crossfire_callbacks: list[CrossfireCallback] = []
        self.on_io(bus.io_node(CROSSFIRE).node_id, self._crossfire_report)

    @property
    def crossfire(self) -> bool | None:
        """Latest crossfire state (True = beam interrupted), ``None`` before the first report."""
        return self._crossfire

    def on_crossfire(self, callback: CrossfireCallback) -> None:
        """Call ``callback(blocked, t)`` from the receive thread on every crossfire report."""
        self._crossfire_callbacks.append(callback)

    def _crossfire_report(self, data: bytes, t: float) -> None:
        if not data:
            return
        self._crossfire = bool(data[0] & 0x01)
        for cb in list(self._crossfire_callbacks):
            cb(self._crossfire, t)
