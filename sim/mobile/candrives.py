"""The mobile robot's wheel drives on the simulated CAN bus: two CiA 402 drives in profile
velocity mode in front of :class:`sim.mobile.robot.WheelDrives`.

Each wheel drive is a CANopen slave made from ``devices/wheel_drive.eds`` (node 1 left, node 2
right): what every simulated device does (boot-up, NMT, SDO, PDOs from its object dictionary, SYNC,
heartbeats, the watchdogs and the waits for the master) is :class:`sim.drives.SimCanDrives`'s, shared
with the PUMA's drives. Default PDOs: RPDO1 = controlword + target velocity 0x60FF, TPDO1 =
statusword + position actual 0x6064, TPDO2 = velocity actual 0x606C + torque actual 0x6077. The bus
itself and its in-process ports are :mod:`sim.canbus`'s, the socketcand gateway
:class:`sim.socketcand.CanGateway`.

Drive model: the target velocity of the latest RPDO is handed to ``WheelDrives.set_velocity`` (which
ramps the demand at the drive's acceleration ramp and applies the torque limit); a drive that is
not operation enabled holds its wheel at rest (target 0, holding torque: a drive with a holding
brake). Watchdogs, as the PUMA's drives: an enabled drive that gets no RPDO within its RPDO deadline
(0x1400:05, 200 ms by default: 25 SYNC cycles) faults (EMCY 0x8250), and once the master's heartbeat
has been seen, none for its consumer heartbeat time (0x1016) faults every enabled drive (EMCY
0x8130). The fault reaction is a quick stop: target 0 on the drive's ramp until the wheel is at
rest, then FAULT.

The world calls :meth:`SimWheelCan.step` from its step hook before every physics step; SYNC goes
out every :data:`CYCLE_S` of simulated time (the sim is the SYNC producer, as on the PUMA's bus).
With ``master_wait_s`` > 0 (the world process in real time) the world waits at each SYNC, bounded,
for the targets of a master that answered the previous one, as the PUMA's bus does: a drive node
starved for a moment by a loaded machine then slows the world instead of faulting its drives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from services.devices import cia402 as cf
from services.devices.devicefile import PROJECT_DEVICES
from sim.canbus import SimBus
from sim.drives import POSITION_UNIT, VELOCITY_UNIT, SimCanDrives, SimDrive

__all__ = ["CYCLE_S", "REST_SPEED", "TARGET_TIMEOUT_CYCLES", "WHEEL_EDS", "SimWheelCan", "WheelActuator"]

CYCLE_S = 0.008
"""SYNC period of the mobile robot's bus, s (125 Hz: two physics steps of 4 ms)."""
TARGET_TIMEOUT_CYCLES = 25
"""SYNC cycles without an RPDO before an enabled wheel drive faults (its EDS's RPDO deadline, 200 ms)."""
REST_SPEED = 0.05
"""A wheel turning slower than this is at rest (end of the fault reaction), rad/s."""
WHEEL_EDS = PROJECT_DEVICES / "wheel_drive.eds"
"""The object dictionary of the simulated wheel drives."""
RATED_TORQUE = 1.0
"""N m: the wheel drives' rated torque 0x6076 (torque actual 0x6077 is in per mille of it)."""


class WheelActuator(Protocol):
    """What the CAN drives need of the wheels (:class:`sim.mobile.robot.WheelDrives` has it)."""

    def set_velocity(self, left: float, right: float) -> None: ...
    def encoders(self) -> tuple[float, float]: ...
    def velocities(self) -> tuple[float, float]: ...
    def torques(self) -> tuple[float, float]: ...


@dataclass(kw_only=True, eq=False)
class _Wheel(SimDrive):
    target: float = 0.0
    got_target: bool = False


class SimWheelCan(SimCanDrives[_Wheel]):
    """Two velocity-mode CiA 402 drives (node 1 left, node 2 right) on a :class:`SimBus`.

    Args:
        wheels: the wheel actuator (``MobileWorld.robot.drives``).
        bus: the bus (a new one if ``None``); serve it with :class:`sim.socketcand.CanGateway`.
        cycle_s: SYNC period, s of simulated time.
        master_wait_s: wall time waited at a SYNC for the targets of a master that answered the
            previous one (0: never wait); a master that missed a wait is not waited for again until
            it answers, but the bus then runs no faster than real time (one SYNC per ``cycle_s`` of
            wall time at most), so that its drives' RPDO deadline (200 ms of bus time) is 200 ms of
            wall time too and not a burst of SYNCs in which the world catches up after a stall.
        sync_producer: the world produces SYNC (default); ``False``: the master does.

    Attributes:
        faults: every fault (bus time, node, code, reason, speed, when the wheel was at rest).
    """

    def __init__(self, wheels: WheelActuator, bus: SimBus | None = None, *, cycle_s: float = CYCLE_S,
                 master_wait_s: float = 0.0, sync_producer: bool = True) -> None:
        super().__init__(bus, cycle_s=cycle_s, master_wait_s=master_wait_s, silent_pace_s=cycle_s,
                         kind="wheel drive", sync_producer=sync_producer)
        self.wheels = wheels
        for node in cf.WHEEL_IDS:
            self.add_drive(_Wheel(node=node), WHEEL_EDS)

    def take_target(self, d: _Wheel, before: cf.DriveState, after: cf.DriveState, values: dict[int, int],
                    t: float) -> None:
        if after is cf.DriveState.OPERATION_ENABLED:
            target = values.get(0x60FF, round(d.target / VELOCITY_UNIT)) * VELOCITY_UNIT
            d.target = target if before is cf.DriveState.OPERATION_ENABLED else 0.0
            d.got_target = True
            self.master_answered()
        else:
            d.target = 0.0

    def has_target(self, d: _Wheel) -> bool:
        return d.got_target

    def on_sync(self, t: float) -> None:
        for d in self._drives:
            if d.sm.state is cf.DriveState.OPERATION_ENABLED:
                got, d.got_target = d.got_target, False
                self.count_target(d, got, t)

    def actual_values(self) -> list[dict[int, int]]:
        positions = self.wheels.encoders()
        speeds = self.wheels.velocities()
        torques = self.wheels.torques()
        out = []
        for d, q, v, tau in zip(self._drives, positions, speeds, torques):
            torque = round(1000.0 * tau / RATED_TORQUE) if tau == tau else 0
            out.append({0x6064: round(q / POSITION_UNIT), 0x606C: round(v / VELOCITY_UNIT),
                        0x606B: round(d.target / VELOCITY_UNIT), 0x6077: max(-32768, min(32767, torque))})
        return out

    def start_fault_reaction(self, d: _Wheel, t: float) -> float:
        """Quick stop: target 0 on the drive's ramp."""
        d.target = 0.0
        return abs(self.wheels.velocities()[d.node - 1])

    def tick(self, t: float) -> None:
        """Hand the wheel targets to the actuator (0 unless operation enabled); a faulted wheel at
        rest ends its fault reaction."""
        speeds = self.wheels.velocities()
        targets = []
        for d, v in zip(self._drives, speeds):
            if d.sm.state is cf.DriveState.FAULT_REACTION_ACTIVE and abs(v) < REST_SPEED:
                self.at_rest(d, t)
            targets.append(d.target if d.sm.state is cf.DriveState.OPERATION_ENABLED else 0.0)
        self.wheels.set_velocity(targets[0], targets[1])
