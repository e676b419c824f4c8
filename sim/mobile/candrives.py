"""The mobile robot's wheel drives on the simulated CAN bus: two CiA 402 drives in profile
velocity mode in front of :class:`sim.mobile.robot.WheelDrives`.

Frame layout and units: :mod:`services.devices.cia402` (velocity mode: RPDO1 = controlword + target
velocity 0x60FF, TPDO1 = statusword + position actual 0x6064, TPDO2 = velocity actual 0x606C +
torque actual 0x6077). The bus itself, its in-process ports and the socketcand gateway are
:mod:`sim.canbus`'s (:class:`sim.canbus.SimBus`, :class:`sim.canbus.CanGateway`); the power state
machine is :class:`services.devices.cia402.Cia402StateMachine`, shared with the PUMA's drives.

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

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Protocol

from services.devices import cia402 as cf
from sim.canbus import FaultRecord, SimBus

__all__ = ["CYCLE_S", "REST_SPEED", "TARGET_TIMEOUT_CYCLES", "SimWheelCan", "WheelActuator"]

log = logging.getLogger(__name__)

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


@dataclass
class _Wheel:
    node: int
    sm: cf.Cia402StateMachine = field(default_factory=cf.Cia402StateMachine)
    nmt: cf.NmtState = cf.NmtState.PRE_OPERATIONAL
    target: float = 0.0
    missed: int = 0
    got_target: bool = False


class SimWheelCan:
    """Two velocity-mode CiA 402 drives (node 1 left, node 2 right) on a :class:`SimBus`.

    Args:
        wheels: the wheel actuator (``MobileWorld.robot.drives``).
        bus: the bus (a new one if ``None``); serve it with :class:`sim.canbus.CanGateway`.
        cycle_s: SYNC period, s of simulated time.
        target_timeout_cycles: missing RPDOs in a row before an RPDO-timeout fault.
        consumer_heartbeat_s: heartbeat consumer time for the master, s of bus time.

    Attributes:
        faults: every fault (bus time, node, code, reason, speed, when the wheel was at rest).
    """

    def __init__(self, wheels: WheelActuator, bus: SimBus | None = None, *, cycle_s: float = CYCLE_S,
                 target_timeout_cycles: int = TARGET_TIMEOUT_CYCLES,
                 consumer_heartbeat_s: float = cf.CONSUMER_HEARTBEAT_S, master_wait_s: float = 0.0) -> None:
        self.wheels = wheels
        self.bus = bus if bus is not None else SimBus()
        self.cycle_s = float(cycle_s)
        self.target_timeout_cycles = int(target_timeout_cycles)
        self.consumer_heartbeat_s = float(consumer_heartbeat_s)
        self.master_wait_s = float(master_wait_s)
        self.faults: list[FaultRecord] = []
        self.master_waits = 0
        """SYNCs at which the world waited for the master's targets."""
        self.master_misses = 0
        """Waits that ran out."""
        self._master_in_step = False
        self._drives = [_Wheel(node) for node in cf.WHEEL_IDS]
        self._booted = False
        self._next_sync = 0.0
        self._next_heartbeat = 0.0
        self._master_heartbeat: float | None = None

    def states(self) -> list[cf.DriveState]:
        """CiA 402 state of the left and right drive."""
        return [d.sm.state for d in self._drives]

    def step(self, t: float) -> None:
        """Advance the drives to simulated time ``t`` (s): received frames, SYNC and PDOs,
        heartbeats, watchdogs, fault reactions; then hand the wheel targets to the actuator."""
        if not self._booted:
            self._booted = True
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, cf.NmtState.BOOT_UP, t))
            self._next_sync = t
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
        for frame in self.bus.take_inbound():
            self._receive(frame, t)
        if t >= self._next_sync - 1e-9:
            self._next_sync += self.cycle_s
            if t > self._next_sync:
                self._next_sync = t + self.cycle_s
            if self.master_wait_s > 0:
                self._await_master(t)
            self._sync(t)
        if t >= self._next_heartbeat - 1e-9:
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, d.nmt, t))
        if self._master_heartbeat is not None and t - self._master_heartbeat > self.consumer_heartbeat_s:
            silent = t - self._master_heartbeat
            self._master_heartbeat = None
            for d in self._drives:
                if self._enabled(d):
                    self._fault(d, t, cf.EmcyCode.HEARTBEAT_LOST, f"no heartbeat from the master for {silent:.3f} s")
        speeds = self.wheels.velocities()
        targets = []
        for d, v in zip(self._drives, speeds):
            if d.sm.state is cf.DriveState.FAULT_REACTION_ACTIVE and abs(v) < REST_SPEED:
                d.sm.reaction_done()
                for k in range(len(self.faults) - 1, -1, -1):
                    f = self.faults[k]
                    if f.node == d.node and math.isnan(f.t_stopped):
                        self.faults[k] = FaultRecord(f.t, f.node, f.code, f.reason, f.speed, t)
                        break
            targets.append(d.target if d.sm.state is cf.DriveState.OPERATION_ENABLED else 0.0)
        self.wheels.set_velocity(targets[0], targets[1])

    def _await_master(self, t: float) -> None:
        """At a SYNC, wait (wall clock, at most ``master_wait_s``) for the targets of a master that
        answered the previous SYNC, so that the world's bursts of stepping are not charged to a
        master in another process; a master that missed a wait is not waited for again until it
        answers (its drives' RPDO timeout then runs on real time)."""
        waiting = [d for d in self._drives if self._enabled(d) and not d.got_target]
        if not waiting or not self._master_in_step:
            return
        self.master_waits += 1
        deadline = time.monotonic() + self.master_wait_s
        while any(self._enabled(d) and not d.got_target for d in waiting):
            left = deadline - time.monotonic()
            if left <= 0:
                self._master_in_step = False
                self.master_misses += 1
                return
            frame = self.bus.wait_inbound(left)
            if frame is not None:
                self._receive(frame, t)

    @staticmethod
    def _enabled(d: _Wheel) -> bool:
        return d.nmt is cf.NmtState.OPERATIONAL and d.sm.state is cf.DriveState.OPERATION_ENABLED

    def _receive(self, frame: cf.CanFrame, t: float) -> None:
        if frame.can_id == cf.NMT_ID and len(frame.data) == 2:
            try:
                cmd = cf.NmtCommand(frame.data[0])
            except ValueError:
                return
            new = {
                cf.NmtCommand.START: cf.NmtState.OPERATIONAL,
                cf.NmtCommand.STOP: cf.NmtState.STOPPED,
                cf.NmtCommand.PRE_OPERATIONAL: cf.NmtState.PRE_OPERATIONAL,
                cf.NmtCommand.RESET_NODE: cf.NmtState.PRE_OPERATIONAL,
            }[cmd]
            for d in self._drives:
                if frame.data[1] in (0, d.node):
                    d.nmt = new
                    if new is not cf.NmtState.OPERATIONAL and not d.sm.faulted:
                        d.sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
            return
        if frame.can_id == cf.HEARTBEAT_BASE + cf.MASTER_ID:
            self._master_heartbeat = t
            return
        node = frame.can_id - cf.RPDO1_BASE
        if not 1 <= node <= len(self._drives):
            return
        d = self._drives[node - 1]
        if d.nmt is not cf.NmtState.OPERATIONAL:
            return
        try:
            cw, velocity = cf.decode_velocity_rpdo1(frame.data)
        except cf.FrameError:
            log.warning("wheel drive %d: bad RPDO1 %s", node, frame.data.hex())
            return
        before = d.sm.state
        after = d.sm.on_controlword(cw)
        if before is cf.DriveState.FAULT and after is not before:
            self.bus.transmit(cf.encode_emcy(d.node, cf.EmcyCode.NO_ERROR, 0, t))
        if after is cf.DriveState.OPERATION_ENABLED:
            d.target = velocity if before is cf.DriveState.OPERATION_ENABLED else 0.0
            d.got_target = True
            self._master_in_step = True
        else:
            d.target = 0.0

    def _sync(self, t: float) -> None:
        self.bus.transmit(cf.CanFrame(cf.SYNC_ID, b"", t))
        positions = self.wheels.encoders()
        speeds = self.wheels.velocities()
        torques = self.wheels.torques()
        for d, q, v, tau in zip(self._drives, positions, speeds, torques):
            if d.sm.state is cf.DriveState.OPERATION_ENABLED:
                if d.got_target:
                    d.got_target = False
                    d.missed = 0
                else:
                    d.missed += 1
                    if d.missed > self.target_timeout_cycles:
                        self._fault(d, t, cf.EmcyCode.RPDO_TIMEOUT,
                                    f"no target from the master for {d.missed} cycles "
                                    f"({d.missed * self.cycle_s * 1000:.0f} ms)")
            if d.nmt is cf.NmtState.OPERATIONAL:
                self.bus.transmit(cf.encode_tpdo1(d.node, d.sm.statusword, q, t))
                self.bus.transmit(cf.encode_tpdo2(d.node, v, tau, t))

    def _fault(self, d: _Wheel, t: float, code: cf.EmcyCode, reason: str) -> None:
        if d.sm.faulted:
            return
        speed = abs(self.wheels.velocities()[d.node - 1])
        text = f"{code.text}: {reason} at t={t:.3f} s"
        d.sm.start_fault_reaction(text, code)
        d.target = 0.0
        self.faults.append(FaultRecord(t, d.node, code, text, speed))
        log.warning("wheel drive %d: %s", d.node, text)
        self.bus.transmit(cf.encode_emcy(d.node, code, 0x01, t))
