"""The mobile robot's wheel drives on the simulated CAN bus: two CiA 402 drives in profile
velocity mode in front of :class:`sim.mobile.robot.WheelDrives`.

Frame layout and units: :mod:`services.devices.cia402` (velocity mode: RPDO1 = controlword + target
velocity 0x60FF, TPDO1 = statusword + position actual 0x6064, TPDO2 = velocity actual 0x606C +
torque actual 0x6077). The bus itself and its in-process ports are :mod:`sim.canbus`'s, the
socketcand gateway :class:`sim.socketcand.CanGateway`; boot-up, NMT, SYNC, heartbeats, the
watchdogs and the waits for the master are those of every simulated drive
(:class:`sim.drives.SimCanDrives`, shared with the PUMA's drives).

Drive model: the target velocity of the latest RPDO is handed to ``WheelDrives.set_velocity`` (which
ramps the demand at the drive's acceleration ramp and applies the torque limit); a drive that is
not operation enabled holds its wheel at rest (target 0, holding torque: a drive with a holding
brake). Watchdogs, as the PUMA's drives: an enabled drive that gets no RPDO for
``target_timeout_cycles`` SYNC cycles faults (EMCY 0x8250), and once the master's heartbeat has
been seen, none for ``consumer_heartbeat_s`` faults every enabled drive (EMCY 0x8130). The fault
reaction is a quick stop: target 0 on the drive's ramp until the wheel is at rest, then FAULT.

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
from sim.canbus import SimBus
from sim.drives import SimCanDrives, SimDrive

__all__ = ["CYCLE_S", "REST_SPEED", "TARGET_TIMEOUT_CYCLES", "SimWheelCan", "WheelActuator"]

CYCLE_S = 0.008
"""SYNC period of the mobile robot's bus, s (125 Hz: two physics steps of 4 ms)."""
TARGET_TIMEOUT_CYCLES = 25
"""SYNC cycles without an RPDO before an enabled wheel drive faults (200 ms)."""
REST_SPEED = 0.05
"""A wheel turning slower than this is at rest (end of the fault reaction), rad/s."""


class WheelActuator(Protocol):
    """What the CAN drives need of the wheels (:class:`sim.mobile.robot.WheelDrives` has it)."""

    def set_velocity(self, left: float, right: float) -> None: ...
    def encoders(self) -> tuple[float, float]: ...
    def velocities(self) -> tuple[float, float]: ...
    def torques(self) -> tuple[float, float]: ...


@dataclass(kw_only=True)
class _Wheel(SimDrive):
    target: float = 0.0
    got_target: bool = False


class SimWheelCan(SimCanDrives[_Wheel]):
    """Two velocity-mode CiA 402 drives (node 1 left, node 2 right) on a :class:`SimBus`.

    Args:
        wheels: the wheel actuator (``MobileWorld.robot.drives``).
        bus: the bus (a new one if ``None``); serve it with :class:`sim.socketcand.CanGateway`.
        cycle_s: SYNC period, s of simulated time.
        target_timeout_cycles: missing RPDOs in a row before an RPDO-timeout fault.
        consumer_heartbeat_s: heartbeat consumer time for the master, s of bus time.
        master_wait_s: wall time waited at a SYNC for the targets of a master that answered the
            previous one (0: never wait); a master that missed a wait is not waited for again until
            it answers (its drives' RPDO timeout then runs on real time).

    Attributes:
        faults: every fault (bus time, node, code, reason, speed, when the wheel was at rest).
    """

    def __init__(self, wheels: WheelActuator, bus: SimBus | None = None, *, cycle_s: float = CYCLE_S,
                 target_timeout_cycles: int = TARGET_TIMEOUT_CYCLES,
                 consumer_heartbeat_s: float = cf.CONSUMER_HEARTBEAT_S, master_wait_s: float = 0.0) -> None:
        super().__init__(bus, cycle_s=cycle_s, target_timeout_cycles=target_timeout_cycles,
                         consumer_heartbeat_s=consumer_heartbeat_s, master_wait_s=master_wait_s,
                         kind="wheel drive")
        self.wheels = wheels
        self._drives = [_Wheel(node=node) for node in cf.WHEEL_IDS]

    def decode_target(self, data: bytes) -> tuple[int, float]:
        return cf.decode_velocity_rpdo1(data)

    def take_target(self, d: _Wheel, before: cf.DriveState, after: cf.DriveState, target: float, t: float) -> None:
        if after is cf.DriveState.OPERATION_ENABLED:
            d.target = target if before is cf.DriveState.OPERATION_ENABLED else 0.0
            d.got_target = True
            self.master_answered()
        else:
            d.target = 0.0

    def has_target(self, d: _Wheel) -> bool:
        return d.got_target

    def on_sync(self, t: float) -> None:
        positions = self.wheels.encoders()
        speeds = self.wheels.velocities()
        torques = self.wheels.torques()
        for d, q, v, tau in zip(self._drives, positions, speeds, torques):
            if d.sm.state is cf.DriveState.OPERATION_ENABLED:
                got, d.got_target = d.got_target, False
                self.count_target(d, got, t)
            if d.nmt is cf.NmtState.OPERATIONAL:
                self.bus.transmit(cf.encode_tpdo1(d.node, d.sm.statusword, q, t))
                self.bus.transmit(cf.encode_tpdo2(d.node, v, tau, t))

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
