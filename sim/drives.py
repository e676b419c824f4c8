"""What every simulated CiA 402 drive on a :class:`sim.canbus.SimBus` does, whatever it drives.

Both testbeds put their drives on a simulated CAN bus: the PUMA's six joint drives in cyclic
synchronous position mode (:class:`sim.catching.drives.SimDrives`) and the mobile robot's two wheel
drives in profile velocity mode (:class:`sim.mobile.candrives.SimWheelCan`). What they share is
here, in :class:`SimCanDrives`, a base they fill in with what moves (their targets, their PDOs,
their fault reaction):

* boot-up: a BOOT_UP heartbeat of every node at the first step, then a heartbeat every
  :data:`services.devices.cia402.HEARTBEAT_PERIOD_S` of bus time;
* NMT: start, stop, pre-operational and reset commands, for one node or all (0); a drive leaving
  OPERATIONAL is disabled (its power stage off);
* SYNC every ``cycle_s`` of bus time (the sim is the SYNC producer), with the RPDO-timeout
  watchdog: an enabled drive without a new target for more than ``target_timeout_cycles`` cycles
  faults (EMCY 0x8250);
* the consumer-heartbeat watchdog: once the master's heartbeat (node
  :data:`services.devices.cia402.MASTER_ID`) has been seen, none for ``consumer_heartbeat_s`` of bus
  time faults every enabled drive (EMCY 0x8130);
* faults: the fault reaction starts (the subclass brings its axis to rest), the EMCY frame says
  why, :attr:`SimCanDrives.faults` keeps a :class:`FaultRecord` (with the time the axis was at rest
  again, once it is);
* pacing to the master (``master_wait_s`` > 0): the sim's own stepping is bursty (a camera frame
  takes tens of milliseconds to render, then the physics catches up) while a real bus's SYNC is
  strictly periodic; so that a master in another process is not charged with the sim's bursts,
  at each SYNC at which an enabled drive has no target yet the sim waits for the master's targets,
  up to ``master_wait_s`` of wall time if the master answered the previous SYNC. Once a wait has
  run out the master is not waited for again until it answers; a subclass may ask (``silent_pace_s``)
  that the bus then still run no faster than real time, so that its RPDO timeout is as long in wall
  time as in bus time.

Threads: the world calls :meth:`SimCanDrives.step` from its simulation thread before every
physics step; frames from other ports reach the drives through the bus's inbound queue.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from services.devices import cia402 as cf
from sim.canbus import SimBus

__all__ = ["FaultRecord", "SimCanDrives", "SimDrive"]

log = logging.getLogger(__name__)

_NMT_STATES = {
    cf.NmtCommand.START: cf.NmtState.OPERATIONAL,
    cf.NmtCommand.STOP: cf.NmtState.STOPPED,
    cf.NmtCommand.PRE_OPERATIONAL: cf.NmtState.PRE_OPERATIONAL,
    cf.NmtCommand.RESET_NODE: cf.NmtState.PRE_OPERATIONAL,
}


@dataclass(frozen=True, slots=True)
class FaultRecord:
    """One fault of a simulated drive, as its EMCY frame announced it.

    Attributes:
        t: bus time of the fault, s.
        node: drive node id.
        code: the EMCY error code.
        reason: what happened, with numbers.
        speed: the axis's speed when the fault reaction started, rad/s.
        t_stopped: bus time at which the axis was at rest again (NaN while stopping), s.
    """

    t: float
    node: int
    code: cf.EmcyCode
    reason: str
    speed: float = 0.0
    t_stopped: float = math.nan


@dataclass
class SimDrive:
    """The state every simulated drive has: its node id, CiA 402 power state machine, NMT state and
    the SYNC cycles in a row it got no target."""

    node: int
    sm: cf.Cia402StateMachine = field(default_factory=cf.Cia402StateMachine)
    nmt: cf.NmtState = cf.NmtState.PRE_OPERATIONAL
    missed: int = 0


D = TypeVar("D", bound=SimDrive)


class SimCanDrives(Generic[D]):
    """Simulated CiA 402 drives on a :class:`~sim.canbus.SimBus` (see the module docstring).

    A subclass sets ``_drives`` (its drives, node ids 1..n in order) and fills in:
    :meth:`decode_target` (its RPDO1 layout), :meth:`take_target` (what a received target does),
    :meth:`has_target` (a target for the coming SYNC arrived), :meth:`on_sync` (its TPDOs),
    :meth:`start_fault_reaction` (bring the axis to rest; returns its speed) and :meth:`tick` (its
    work at every step). It may add other bus nodes (:meth:`other_nodes`, :meth:`other_nmt`).

    Args:
        bus: the bus (a new one if ``None``); serve it to other processes with
            :class:`sim.socketcand.CanGateway`.
        cycle_s: SYNC period, s of bus time.
        target_timeout_cycles: missing targets in a row before an RPDO-timeout fault.
        consumer_heartbeat_s: heartbeat consumer time for the master, s of bus time.
        master_wait_s: wall time waited at a SYNC for the master's targets (0: never wait).
        silent_pace_s: while the master does not answer, wait at each SYNC until this much wall
            time has passed since the previous one (``None``: do not pace).
        kind: what the drives are, in log lines ("drive", "wheel drive").

    Attributes:
        faults: every fault so far.
        master_waits: SYNCs at which the sim waited for the master's targets.
        master_misses: waits that ran out (the master did not answer within ``master_wait_s``).
    """

    def __init__(self, bus: SimBus | None, *, cycle_s: float, target_timeout_cycles: int,
                 consumer_heartbeat_s: float, master_wait_s: float, silent_pace_s: float | None = None,
                 kind: str = "drive") -> None:
        self.bus = bus if bus is not None else SimBus()
        self.cycle_s = float(cycle_s)
        self.target_timeout_cycles = int(target_timeout_cycles)
        self.consumer_heartbeat_s = float(consumer_heartbeat_s)
        self.master_wait_s = float(master_wait_s)
        self.silent_pace_s = silent_pace_s
        self.kind = kind
        self._drives: list[D] = []
        self.faults: list[FaultRecord] = []
        self.master_waits = 0
        self.master_misses = 0
        self._master_in_step = False
        self._master_heartbeat: float | None = None
        self._last_sync_wall: float | None = None
        self._booted = False
        self._next_sync = 0.0
        self._next_heartbeat = 0.0

    # --- what a subclass fills in ------------------------------------------------------------------

    def decode_target(self, data: bytes) -> tuple[int, float]:
        """(controlword, target) of an RPDO1's data.

        Raises:
            services.devices.cia402.FrameError: not this drive's RPDO1 layout.
        """
        raise NotImplementedError

    def take_target(self, d: D, before: cf.DriveState, after: cf.DriveState, target: float, t: float) -> None:
        """A valid RPDO1 reached drive ``d``, whose state went from ``before`` to ``after``."""
        raise NotImplementedError

    def has_target(self, d: D) -> bool:
        """Drive ``d`` has a new target for the coming SYNC."""
        raise NotImplementedError

    def on_sync(self, t: float) -> None:
        """The SYNC at bus time ``t`` went out: latch the targets, send the TPDOs."""
        raise NotImplementedError

    def start_fault_reaction(self, d: D, t: float) -> float:
        """Drive ``d`` faults at ``t``: start bringing its axis to rest; returns the axis's speed, rad/s."""
        raise NotImplementedError

    def tick(self, t: float) -> None:
        """Every step, after the bus's work: move the axes."""
        raise NotImplementedError

    def other_nodes(self) -> list[tuple[int, cf.NmtState]]:
        """Other nodes of the bus this object stands for, with their NMT state (none here)."""
        return []

    def other_nmt(self, node: int, state: cf.NmtState, t: float) -> None:
        """An NMT command addressed to ``node`` (0: all) put the other nodes in ``state``."""

    # --- the bus's work ----------------------------------------------------------------------------

    def states(self) -> list[cf.DriveState]:
        """CiA 402 state of each drive, in node order."""
        return [d.sm.state for d in self._drives]

    def step(self, t: float) -> None:
        """Advance the drives to bus time ``t`` (s): received frames, SYNC and PDOs, heartbeats,
        the watchdogs; then :meth:`tick`."""
        if not self._booted:
            self._booted = True
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, cf.NmtState.BOOT_UP, t))
            for node, _ in self.other_nodes():
                self.bus.transmit(cf.encode_heartbeat(node, cf.NmtState.BOOT_UP, t))
            self._next_sync = t
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
        for frame in self.bus.take_inbound():
            self.receive(frame, t)
        if t >= self._next_sync - 1e-9:
            self._next_sync += self.cycle_s
            if t > self._next_sync:  # the caller skipped cycles: resynchronise
                self._next_sync = t + self.cycle_s
            if self.master_wait_s > 0:
                self._await_master(t)
            self.bus.transmit(cf.CanFrame(cf.SYNC_ID, b"", t))
            self.on_sync(t)
        if t >= self._next_heartbeat - 1e-9:
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, d.nmt, t))
            for node, state in self.other_nodes():
                self.bus.transmit(cf.encode_heartbeat(node, state, t))
        if self._master_heartbeat is not None and t - self._master_heartbeat > self.consumer_heartbeat_s:
            silent = t - self._master_heartbeat
            self._master_heartbeat = None  # monitoring starts again with the next heartbeat
            for d in self._drives:
                if self.enabled(d):
                    self.fault(d, t, cf.EmcyCode.HEARTBEAT_LOST, f"no heartbeat from the master for {silent:.3f} s")
        self.tick(t)

    @staticmethod
    def enabled(d: SimDrive) -> bool:
        """The drive is OPERATIONAL and its power stage OPERATION_ENABLED."""
        return d.nmt is cf.NmtState.OPERATIONAL and d.sm.state is cf.DriveState.OPERATION_ENABLED

    def master_answered(self) -> None:
        """The master is in step again (a subclass calls it when a target arrives)."""
        self._master_in_step = True

    def count_target(self, d: D, got: bool, t: float) -> None:
        """At a SYNC: drive ``d`` got a target (``got``) or missed one; too many missed in a row
        is an RPDO-timeout fault."""
        if got:
            d.missed = 0
            return
        d.missed += 1
        if d.missed > self.target_timeout_cycles:
            self.fault(d, t, cf.EmcyCode.RPDO_TIMEOUT,
                       f"no target from the master for {d.missed} cycles ({d.missed * self.cycle_s * 1000:.0f} ms)")

    def fault(self, d: D, t: float, code: cf.EmcyCode, reason: str) -> None:
        """Start drive ``d``'s fault reaction at bus time ``t`` for ``reason``: EMCY, record, log."""
        if d.sm.faulted:
            return
        speed = self.start_fault_reaction(d, t)
        text = f"{code.text}: {reason} at t={t:.3f} s"
        d.sm.start_fault_reaction(text, code)
        self.faults.append(FaultRecord(t, d.node, code, text, speed))
        log.warning("%s %d: %s", self.kind, d.node, text)
        self.bus.transmit(cf.encode_emcy(d.node, code, 0x01, t))

    def at_rest(self, d: D, t: float) -> None:
        """Drive ``d``'s fault reaction is over at bus time ``t``: FAULT, and the record says when."""
        d.sm.reaction_done()
        for k in range(len(self.faults) - 1, -1, -1):
            f = self.faults[k]
            if f.node == d.node and math.isnan(f.t_stopped):
                self.faults[k] = FaultRecord(f.t, f.node, f.code, f.reason, f.speed, t)
                break

    def receive(self, frame: cf.CanFrame, t: float) -> None:
        """Handle one frame a port sent: NMT, the master's heartbeat, a drive's RPDO1."""
        if frame.can_id == cf.NMT_ID and len(frame.data) == 2:
            try:
                new = _NMT_STATES[cf.NmtCommand(frame.data[0])]
            except ValueError:
                return
            node = frame.data[1]
            for d in self._drives:
                if node in (0, d.node):
                    d.nmt = new
                    if new is not cf.NmtState.OPERATIONAL and not d.sm.faulted:
                        d.sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
            self.other_nmt(node, new, t)
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
            cw, target = self.decode_target(frame.data)
        except cf.FrameError:
            log.warning("%s %d: bad RPDO1 %s", self.kind, node, frame.data.hex())
            return
        before = d.sm.state
        after = d.sm.on_controlword(cw)
        if before is cf.DriveState.FAULT and after is not before:
            self.bus.transmit(cf.encode_emcy(d.node, cf.EmcyCode.NO_ERROR, 0, t))
        self.take_target(d, before, after, target, t)

    def _await_master(self, t: float) -> None:
        """Wait (wall clock, bounded) for the master's targets (see the module docstring)."""
        now = time.monotonic()
        last, self._last_sync_wall = self._last_sync_wall, now
        waiting = [d for d in self._drives if self.enabled(d) and not self.has_target(d)]
        if not waiting:
            return
        if self._master_in_step:
            self.master_waits += 1
            deadline = now + self.master_wait_s
        elif self.silent_pace_s is not None and last is not None:
            deadline = last + self.silent_pace_s  # real-time pace while the master is silent
        else:
            return
        while any(self.enabled(d) and not self.has_target(d) for d in waiting):
            left = deadline - time.monotonic()
            if left <= 0:
                if self._master_in_step:
                    self._master_in_step = False
                    self.master_misses += 1
                break
            frame = self.bus.wait_inbound(left)
            if frame is not None:
                self.receive(frame, t)
        self._last_sync_wall = time.monotonic()
