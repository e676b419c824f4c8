"""The PUMA's CAN bus as the motion node sees it: six CiA 402 joint drives and the crossfire module.

The catching testbed's use of the framework's CAN master (:class:`services.devices.drives.CanDrives`):
the joint drives are nodes 1..6 (:data:`services.devices.cia402.DRIVE_IDS`), in cyclic synchronous
position mode; the cup's crossfire sensor is an I/O module (node
:data:`services.devices.cia402.CROSSFIRE_ID`) whose TPDO1 says whether its light beam is
interrupted. Frame layout and units: :mod:`services.devices.cia402`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from services.devices import cia402 as cf
from services.devices.drives import CanDrives

__all__ = ["CrossfireCallback", "PumaDrives"]

CrossfireCallback = Callable[[bool, float], None]
"""Called from the receive thread with the crossfire state (True: beam interrupted) and its bus time, s."""


class PumaDrives(CanDrives):
    """The PUMA's joint drives and crossfire module (arguments as :class:`CanDrives`'s)."""

    def __init__(self, host: str, port: int, channel: str = "can0", heartbeat_timeout: float = 0.5,
                 silence_timeout: float = 2.0, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(host, port, channel, heartbeat_timeout, silence_timeout, clock,
                         nodes=cf.DRIVE_IDS, io_nodes=(cf.CROSSFIRE_ID,))
        self._crossfire: bool | None = None
        self._crossfire_callbacks: list[CrossfireCallback] = []
        self.on_io(cf.CROSSFIRE_ID, self._crossfire_report)

    @property
    def crossfire(self) -> bool | None:
        """Latest crossfire state (True = beam interrupted), ``None`` before the first report."""
        return self._crossfire

    def on_crossfire(self, callback: CrossfireCallback) -> None:
        """Call ``callback(blocked, t)`` from the receive thread on every crossfire report."""
        self._crossfire_callbacks.append(callback)

    def _crossfire_report(self, data: bytes, t: float) -> None:
        self._crossfire = cf.decode_crossfire(data)
        for cb in list(self._crossfire_callbacks):
            cb(self._crossfire, t)
