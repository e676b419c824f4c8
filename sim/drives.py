"""The simulated CANopen devices on a :class:`sim.canbus.SimBus`: CiA 402 drives and I/O modules as
CANopen slaves, each a :class:`canopen.LocalNode` made from its EDS file.

Both testbeds put their drives on a simulated CAN bus: the PUMA's six joint drives in cyclic
synchronous position mode (:class:`sim.catching.drives.SimDrives`, ``devices/puma_joint_drive.eds``)
and the mobile robot's two wheel drives in profile velocity mode (:class:`sim.mobile.candrives.SimWheelCan`,
``devices/wheel_drive.eds``). What they share is here, in :class:`SimCanDrives`, a base they fill in
with what moves (their targets, their actual values, their fault reaction). Each device is a
:class:`canopen.LocalNode` whose object dictionary is its EDS file, on a :class:`SimNetwork` (the
``canopen`` network of the simulated side, whose messages go onto the :class:`~sim.canbus.SimBus` and
whose periodic messages run on the bus clock), so that a master configures a simulated drive over SDO
exactly as it would a real one (canopen's SDO server answers, the values land in the node's object
dictionary) and the drive then does what its objects say:

* boot-up and NMT: canopen's NMT slave: a BOOT_UP heartbeat of every node at the first step, then
  its heartbeat every 0x1017 ms of bus time; start, stop, pre-operational and reset commands for
  one node or all (0). A drive leaving OPERATIONAL is disabled (its power stage off); a reset node
  forgets what was written over SDO (reset communication: its 0x1000-0x1FFF objects), says BOOT_UP
  and is pre-operational again;
* PDOs: the layouts of its RPDOs and TPDOs (0x1400.., 0x1600.., 0x1800.., 0x1A00..) are compiled
  (:class:`services.devices.pdo.PdoLayout`) from its object dictionary whenever they change: RPDOs
  are taken while operational (the controlword 0x6040 and the target, 0x607A or 0x60FF, wherever
  they are mapped), synchronous TPDOs (transmission type 1..240) go out after every n-th SYNC,
  event-driven ones (254, 255) when the device says so. Mapping parameters can be written only while
  their PDO is not valid (COB-ID bit 31 set), as CiA 301 requires; an object that cannot be mapped
  or a PDO longer than 8 bytes is refused with the SDO abort code CiA 301 gives;
* SYNC every ``cycle_s`` of bus time (the simulated world is the SYNC producer, so that its clock
  paces the bus in both lock-step and real-time modes; with ``sync_producer=False`` it takes the
  SYNCs another station sends instead), with the RPDO deadline monitoring of CiA 301: an enabled
  drive whose RPDO event timer (0x1400:05, ms) is set faults (EMCY 0x8250) after more than that many
  SYNC cycles without a new target;
* the consumer heartbeat (0x1016): once the heartbeat of a watched node (the master, 0x7F) has been
  seen, none for its time faults every enabled drive (EMCY 0x8130);
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

Units of the simulated drives (their EDS comments say the same): position 1e-5 rad per count
(:data:`POSITION_UNIT`), velocity 1e-4 rad/s (:data:`VELOCITY_UNIT`), torque per mille of the rated
torque 0x6076 (mN m).

Threads: the world calls :meth:`SimCanDrives.step` from its simulation thread before every physics
step; frames from other ports reach the devices through the bus's inbound queue, except SDO requests,
which the devices answer at once in the sender's thread (a real drive answers within a millisecond,
whatever the simulation is busy with: rendering a camera frame takes tens), under a lock that the
simulation thread holds while it does the bus's work. An SDO read of an actual value (0x6064, ...)
gives the value of the latest SYNC.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

import canopen
from canopen.sdo import SdoAbortedError

from services.devices import cia402 as cf
from services.devices.pdo import PdoLayout, PdoLayoutError, decode_mapping_entry
from sim.canbus import SimBus

__all__ = ["POSITION_UNIT", "VELOCITY_UNIT", "BusClockTask", "FaultRecord", "SimCanDrives", "SimDevice",
           "SimDrive", "SimIoModule", "SimNetwork"]

log = logging.getLogger(__name__)
# canopen's SDO server logs every transfer at INFO: a master's configuration would flood the world's log.
logging.getLogger("canopen").setLevel(logging.WARNING)

POSITION_UNIT = 1e-5
"""rad per position count of the simulated drives (0x607A, 0x6062, 0x6064)."""
VELOCITY_UNIT = 1e-4
"""rad/s per velocity count of the simulated drives (0x60FF, 0x606B, 0x606C)."""

_NMT_STATE = {"INITIALISING": cf.NmtState.BOOT_UP, "PRE-OPERATIONAL": cf.NmtState.PRE_OPERATIONAL,
              "OPERATIONAL": cf.NmtState.OPERATIONAL, "STOPPED": cf.NmtState.STOPPED}
_PDO_NOT_VALID = 1 << 31
# SDO abort codes (CiA 301 Table 22)
_ABORT_UNSUPPORTED_ACCESS = 0x06010000
_ABORT_NOT_MAPPABLE = 0x06040041
_ABORT_PDO_LENGTH = 0x06040042
_ABORT_VALUE_RANGE = 0x06090030


class BusClockTask:
    """A periodic message on the bus clock (what :meth:`SimNetwork.send_periodic` returns): the
    simulated heartbeat producers. The first message goes out one period after the start."""

    def __init__(self, network: SimNetwork, can_id: int, data: bytes, period: float) -> None:
        self.network = network
        self.can_id = can_id
        self.data = bytes(data)
        self.period = float(period)
        self.next = network.t + self.period

    def due(self, t: float) -> None:
        """Send the message if its time has come by bus time ``t``."""
        if t >= self.next - 1e-9:
            self.next = max(self.next + self.period, t)
            self.network.send_message(self.can_id, self.data)

    def stop(self) -> None:
        """No more messages."""
        self.network.stop_task(self)

    def update(self, data: bytes | Sequence[int]) -> None:
        """Send ``data`` from now on."""
        self.data = bytes(data)


class SimNetwork(canopen.Network):
    """The canopen network of the simulated devices: messages go onto a :class:`SimBus`, stamped
    with the bus time, and periodic messages (heartbeats) run on the bus clock, not on a thread's
    timer. Frames from the bus reach the devices through :meth:`canopen.Network.notify`."""

    def __init__(self, bus: SimBus) -> None:
        super().__init__(None)
        self.simbus = bus
        self.t = 0.0
        self._tasks: list[BusClockTask] = []

    def send_message(self, can_id: int, data: bytes | bytearray | Sequence[int], remote: bool = False) -> None:
        self.simbus.transmit(cf.CanFrame(can_id, bytes(data), self.t))

    def send_periodic(self, can_id: int, data: bytes | bytearray | Sequence[int], period: float,  # type: ignore[override]
                      remote: bool = False) -> BusClockTask:
        task = BusClockTask(self, can_id, bytes(data or b""), period)
        self._tasks.append(task)
        return task

    def stop_task(self, task: BusClockTask) -> None:
        """Forget a periodic message (idempotent)."""
        if task in self._tasks:
            self._tasks.remove(task)

    def advance(self, t: float) -> None:
        """Bus time is ``t``: send the periodic messages that are due."""
        self.t = t
        for task in list(self._tasks):
            task.due(t)


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


@dataclass(eq=False)
class SimDevice:
    """A simulated CANopen device: its node id, its :class:`canopen.LocalNode`, and its PDO layouts
    compiled from its object dictionary (``None`` until compiled)."""

    node: int
    local: Any = None
    rpdos: dict[int, tuple[PdoLayout, int]] | None = None  # COB-ID -> (layout, RPDO number)
    tpdos: list[tuple[int, PdoLayout, int]] | None = None  # (COB-ID, layout, transmission type)
    syncs: int = 0
    dirty: bool = True

    @property
    def nmt(self) -> cf.NmtState:
        """The node's NMT state (canopen's NMT slave keeps it)."""
        return _NMT_STATE.get(self.local.nmt.state, cf.NmtState.PRE_OPERATIONAL)

    def raw(self, index: int, subindex: int = 0) -> int:
        """An integer object's value as the object dictionary holds it (written over SDO, else the EDS's)."""
        obj = self.local.object_dictionary[index]
        if not isinstance(obj, canopen.objectdictionary.ODVariable):
            obj = obj[subindex]
        data = self.local.data_store.get(index, {}).get(subindex)
        if data is None:
            value = obj.value if obj.value is not None else obj.default
            return int(value or 0)
        return int(obj.decode_raw(data))

    def has(self, index: int, subindex: int = 0) -> bool:
        """The object exists in the device's object dictionary."""
        od = self.local.object_dictionary
        if index not in od:
            return False
        obj = od[index]
        return isinstance(obj, canopen.objectdictionary.ODVariable) or subindex in obj


@dataclass(eq=False)
class SimDrive(SimDevice):
    """A simulated CiA 402 drive: a :class:`SimDevice` with its power state machine, the SYNC cycles
    in a row it got no target, and its deadline (RPDO timeout in cycles, 0: none)."""

    sm: cf.Cia402StateMachine = field(default_factory=cf.Cia402StateMachine)
    missed: int = 0
    timeout_cycles: int = 0
    controlword: int = 0
    mode: int = 0
    consumers: dict[int, float] = field(default_factory=dict)  # watched node -> consumer heartbeat time, s
    received: dict[int, int] = field(default_factory=dict)  # latest value of each object an RPDO or SDO set


D = TypeVar("D", bound=SimDrive)


def _data_types(local: Any) -> dict[tuple[int, int], int]:
    out: dict[tuple[int, int], int] = {}
    for obj in local.object_dictionary.values():
        members = [obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else list(obj.values())
        for var in members:
            out[(var.index, var.subindex)] = var.data_type
    return out


class SimCanDrives(Generic[D]):
    """Simulated CiA 402 drives and I/O modules on a :class:`~sim.canbus.SimBus` (see the module docstring).

    A subclass makes its drives with :meth:`add_drive` (node ids in axis order) and fills in:
    :meth:`take_target` (what a received target does), :meth:`has_target` (a target for the coming
    SYNC arrived), :meth:`on_sync` (latch targets; called before the TPDOs go out),
    :meth:`actual_values` (its axes' actual values, in counts, for TPDOs and SDO reads),
    :meth:`start_fault_reaction` (bring the axis to rest; returns its speed) and :meth:`tick` (its
    work at every step). It may add I/O modules (:meth:`add_module`).

    Args:
        bus: the bus (a new one if ``None``); serve it to other processes with
            :class:`sim.socketcand.CanGateway`.
        cycle_s: SYNC period, s of bus time.
        master_wait_s: wall time waited at a SYNC for the master's targets (0: never wait).
        silent_pace_s: while the master does not answer, wait at each SYNC until this much wall
            time has passed since the previous one (``None``: do not pace).
        kind: what the drives are, in log lines ("drive", "wheel drive").
        sync_producer: the world produces SYNC every ``cycle_s`` (default); ``False``: it takes the
            SYNCs another station (the master) sends.

    Attributes:
        faults: every fault so far.
        master_waits: SYNCs at which the sim waited for the master's targets.
        master_misses: waits that ran out (the master did not answer within ``master_wait_s``).
        network: the canopen network of the simulated devices.
    """

    def __init__(self, bus: SimBus | None, *, cycle_s: float, master_wait_s: float,
                 silent_pace_s: float | None = None, kind: str = "drive", sync_producer: bool = True) -> None:
        self.bus = bus if bus is not None else SimBus()
        self.network = SimNetwork(self.bus)
        self.cycle_s = float(cycle_s)
        self.master_wait_s = float(master_wait_s)
        self.silent_pace_s = silent_pace_s
        self.kind = kind
        self.sync_producer = sync_producer
        self._drives: list[D] = []
        self._modules: list[SimIoModule] = []
        self._by_node: dict[int, SimDevice] = {}
        self._rpdo_owner: dict[int, SimDrive] = {}
        self.faults: list[FaultRecord] = []
        self.master_waits = 0
        self.master_misses = 0
        self._master_in_step = False
        self._heard: dict[int, float] = {}  # watched node -> bus time of its latest heartbeat
        self._last_sync_wall: float | None = None
        self._booted = False
        self._next_sync = 0.0
        self._lock = threading.RLock()
        self._actuals: list[dict[int, int]] = []  # the actual values at the latest SYNC, per drive
        self.network.subscribe(cf.NMT_ID, self._after_nmt)
        self.bus.take_at_once(range(0x601, 0x680), self._sdo_request)

    # --- making the devices ------------------------------------------------------------------------

    def add_drive(self, drive: D, eds: str | Path) -> D:
        """Make ``drive`` a CANopen slave whose object dictionary is the EDS file ``eds``; returns it."""
        drive.local = self._local(drive, eds)
        self._drives.append(drive)
        return drive

    def add_module(self, module: SimIoModule, eds: str | Path) -> SimIoModule:
        """Add an I/O module (a CANopen slave made from ``eds``) to the bus."""
        module.local = self._local(module, eds)
        module.owner = self
        self._modules.append(module)
        return module

    def _local(self, device: SimDevice, eds: str | Path) -> Any:
        local = canopen.LocalNode(device.node, canopen.import_od(str(eds), device.node))
        self.network.add_node(local)
        local.add_read_callback(lambda index, subindex, od, _d=device: self._read_object(_d, index, subindex))
        local.add_write_callback(lambda index, subindex, od, data, _d=device: self._write_object(_d, index, subindex, data))
        self._by_node[device.node] = device
        return local

    # --- what a subclass fills in ------------------------------------------------------------------

    def take_target(self, d: D, before: cf.DriveState, after: cf.DriveState, values: dict[int, int], t: float) -> None:
        """A valid RPDO reached drive ``d`` (its mapped objects' ``values`` by index, counts), whose
        state went from ``before`` to ``after``."""
        raise NotImplementedError

    def has_target(self, d: D) -> bool:
        """Drive ``d`` has a new target for the coming SYNC."""
        raise NotImplementedError

    def on_sync(self, t: float) -> None:
        """The SYNC at bus time ``t`` went out: latch the targets (the TPDOs follow)."""
        raise NotImplementedError

    def actual_values(self) -> list[dict[int, int]]:
        """Per drive, in node order, the actual values its TPDOs and SDO reads report, by object index,
        in counts (0x6064 position, 0x606C velocity, 0x6062/0x606B demands, 0x6077 torque, ...)."""
        raise NotImplementedError

    def start_fault_reaction(self, d: D, t: float) -> float:
        """Drive ``d`` faults at ``t``: start bringing its axis to rest; returns the axis's speed, rad/s."""
        raise NotImplementedError

    def tick(self, t: float) -> None:
        """Every step, after the bus's work: move the axes."""
        raise NotImplementedError

    # --- inspection --------------------------------------------------------------------------------

    def states(self) -> list[cf.DriveState]:
        """CiA 402 state of each drive, in node order."""
        return [d.sm.state for d in self._drives]

    def device(self, node: int) -> SimDevice:
        """The simulated device with node id ``node``.

        Raises:
            KeyError: no such node on this bus.
        """
        return self._by_node[node]

    def rpdo_layout(self, node: int, number: int = 1) -> PdoLayout:
        """The layout RPDO ``number`` of drive ``node`` has now (what a master must send)."""
        return self._compile(self._by_node[node], 0x1600 + number - 1)

    def tpdo_layout(self, node: int, number: int = 1) -> PdoLayout:
        """The layout TPDO ``number`` of device ``node`` has now (what it sends)."""
        return self._compile(self._by_node[node], 0x1A00 + number - 1)

    # --- the bus's work ----------------------------------------------------------------------------

    def step(self, t: float) -> None:
        """Advance the devices to bus time ``t`` (s): received frames, SYNC and PDOs, heartbeats,
        the watchdogs; then :meth:`tick`."""
        with self._lock:
            self._step(t)

    def _sdo_request(self, frame: cf.CanFrame) -> None:
        """An SDO request from a port, in the sender's thread: answered at once (module docstring)."""
        with self._lock:
            if self._booted:
                self.receive(frame, self.network.t)

    def _step(self, t: float) -> None:
        self.network.t = t
        if not self._booted:
            self._booted = True
            for dev in self._devices():
                self._boot(dev)
            self._next_sync = t
        for frame in self.bus.take_inbound():
            self.receive(frame, t)
        if self.sync_producer and t >= self._next_sync - 1e-9:
            self._next_sync += self.cycle_s
            if t > self._next_sync:  # the caller skipped cycles: resynchronise
                self._next_sync = t + self.cycle_s
            if self.master_wait_s > 0:
                self._await_master(t)
            self.bus.transmit(cf.CanFrame(cf.SYNC_ID, b"", t))
            self._sync(t)
        self.network.advance(t)
        self._watch_heartbeats(t)
        self.tick(t)
        for module in self._modules:
            module.poll(t)

    def _devices(self) -> list[SimDevice]:
        return [*self._drives, *self._modules]

    def _boot(self, dev: SimDevice) -> None:
        """Power-on or reset: BOOT_UP, then pre-operational with the heartbeat of 0x1017."""
        dev.local.nmt.send_command(0x81)  # INITIALISING: the boot-up message
        dev.local.nmt.send_command(0x80)  # PRE-OPERATIONAL: canopen starts the heartbeat producer
        self._recompile(dev)

    def _sync(self, t: float) -> None:
        self.on_sync(t)
        actual = self._actuals = self.actual_values()
        for d, values in zip(self._drives, actual):
            if d.nmt is not cf.NmtState.OPERATIONAL:
                continue
            d.syncs += 1
            values = {**d.received, **values, 0x6041: d.sm.statusword, 0x6061: d.mode, 0x603F: int(d.sm.fault_code)}
            for cob_id, layout, trans in d.tpdos or ():
                if 1 <= trans <= 240 and d.syncs % trans == 0:
                    self.bus.transmit(cf.CanFrame(cob_id, layout.pack_objects(values), t))

    def _watch_heartbeats(self, t: float) -> None:
        """The consumer-heartbeat watchdog: a watched node silent longer than a drive's 0x1016 time."""
        for node, seen in list(self._heard.items()):
            silent = t - seen
            late = [d for d in self._drives if 0 < d.consumers.get(node, 0.0) < silent]
            if not late:
                continue
            self._heard.pop(node, None)  # monitoring starts again with the next heartbeat
            for d in late:
                if self.enabled(d):
                    self.fault(d, t, cf.EmcyCode.HEARTBEAT_LOST, f"no heartbeat from the master for {silent:.3f} s")

    @staticmethod
    def enabled(d: SimDrive) -> bool:
        """The drive is OPERATIONAL and its power stage OPERATION_ENABLED."""
        return d.nmt is cf.NmtState.OPERATIONAL and d.sm.state is cf.DriveState.OPERATION_ENABLED

    def master_answered(self) -> None:
        """The master is in step again (a subclass calls it when a target arrives)."""
        self._master_in_step = True

    def count_target(self, d: D, got: bool, t: float) -> None:
        """At a SYNC: drive ``d`` got a target (``got``) or missed one; more missed in a row than its
        RPDO deadline allows is an RPDO-timeout fault."""
        if got:
            d.missed = 0
            return
        d.missed += 1
        if d.timeout_cycles and d.missed > d.timeout_cycles:
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
        self.network.t = t
        d.local.emcy.send(int(code), 0x01)

    def at_rest(self, d: D, t: float) -> None:
        """Drive ``d``'s fault reaction is over at bus time ``t``: FAULT, and the record says when."""
        d.sm.reaction_done()
        for k in range(len(self.faults) - 1, -1, -1):
            f = self.faults[k]
            if f.node == d.node and math.isnan(f.t_stopped):
                self.faults[k] = FaultRecord(f.t, f.node, f.code, f.reason, f.speed, t)
                break

    def receive(self, frame: cf.CanFrame, t: float) -> None:
        """Handle one frame a port sent: a drive's RPDO, a watched heartbeat, a SYNC of another
        producer, or anything canopen's slaves answer (NMT, SDO)."""
        self.network.t = t
        cid = frame.can_id
        owner = self._rpdo_owner.get(cid)
        if owner is not None:
            self._rpdo(owner, cid, frame.data, t)  # type: ignore[arg-type]
        elif cf.HEARTBEAT_BASE < cid <= cf.HEARTBEAT_BASE + 0x7F and cid - cf.HEARTBEAT_BASE not in self._by_node:
            self._heard[cid - cf.HEARTBEAT_BASE] = t
        elif cid == cf.SYNC_ID and not self.sync_producer:
            self._sync(t)
        else:
            self.network.notify(cid, bytearray(frame.data), t)
            for dev in self._devices():
                if dev.dirty and dev.nmt is not cf.NmtState.BOOT_UP:
                    self._recompile(dev)

    def _rpdo(self, d: D, cob_id: int, data: bytes, t: float) -> None:
        if d.nmt is not cf.NmtState.OPERATIONAL or d.rpdos is None or cob_id not in d.rpdos:
            return
        layout = d.rpdos[cob_id][0]
        try:
            values = layout.unpack_objects(data)
        except PdoLayoutError:
            log.warning("%s %d: RPDO %#05x of %d bytes does not match its mapping (%s)", self.kind, d.node,
                        cob_id, len(data), layout.describe())
            return
        d.received.update(values)  # what a TPDO mapping these objects echoes (a real drive's 0x607A)
        before = d.sm.state
        if 0x6040 in values:
            d.controlword = values[0x6040]
        after = d.sm.on_controlword(d.controlword)
        if before is cf.DriveState.FAULT and after is not before:
            d.local.emcy.reset()
        self.take_target(d, before, after, values, t)

    def _after_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """After canopen's NMT slaves took an NMT command: what the new state means for each device."""
        if len(data) != 2:
            return
        command, node = data[0], data[1]
        for dev in self._devices():
            if node not in (0, dev.node):
                continue
            if command in (0x81, 0x82):  # reset node / communication: canopen set INITIALISING
                self._reset(dev, everything=command == 0x81)
                continue
            if isinstance(dev, SimDrive) and dev.nmt is not cf.NmtState.OPERATIONAL and not dev.sm.faulted:
                dev.sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
            if dev.nmt is cf.NmtState.OPERATIONAL:
                self._recompile(dev)
                if isinstance(dev, SimIoModule):
                    dev.started(self.network.t)

    def _reset(self, dev: SimDevice, everything: bool) -> None:
        if everything:
            dev.local.data_store.clear()
        else:
            for index in [i for i in dev.local.data_store if 0x1000 <= i <= 0x1FFF]:
                del dev.local.data_store[index]
        if isinstance(dev, SimDrive) and not dev.sm.faulted:
            dev.sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
        self._boot(dev)

    # --- the object dictionary ---------------------------------------------------------------------

    def _recompile(self, dev: SimDevice) -> None:
        """Make the device's caches from its object dictionary (after an SDO write, at boot and at NMT
        start): the PDO layouts (a mapping that cannot be compiled leaves its PDO out, with a log
        line), the RPDO deadline, the consumer heartbeat times, the mode of operation."""
        dev.dirty = False
        for cob in [c for c, owner in self._rpdo_owner.items() if owner is dev]:
            del self._rpdo_owner[cob]
        rpdos: dict[int, tuple[PdoLayout, int]] = {}
        tpdos: list[tuple[int, PdoLayout, int]] = []
        timeout = 0
        for n in range(512):
            if not dev.has(0x1400 + n, 1):
                break
            cob = dev.raw(0x1400 + n, 1)
            layout = None if cob & _PDO_NOT_VALID else self._layout_or_none(dev, 0x1600 + n)
            if layout is None:
                continue
            rpdos[cob & 0x7FF] = (layout, n + 1)
            if isinstance(dev, SimDrive):
                self._rpdo_owner[cob & 0x7FF] = dev
                event_ms = dev.raw(0x1400 + n, 5) if dev.has(0x1400 + n, 5) else 0
                if event_ms and (0x607A in layout or 0x60FF in layout):
                    timeout = max(1, round(event_ms / 1000.0 / self.cycle_s))
        for n in range(512):
            if not dev.has(0x1800 + n, 1):
                break
            cob = dev.raw(0x1800 + n, 1)
            layout = None if cob & _PDO_NOT_VALID else self._layout_or_none(dev, 0x1A00 + n)
            if layout is not None:
                tpdos.append((cob & 0x7FF, layout, dev.raw(0x1800 + n, 2)))
        dev.rpdos, dev.tpdos = rpdos, tpdos
        if isinstance(dev, SimDrive):
            dev.timeout_cycles = timeout
            dev.mode = dev.raw(0x6060) if dev.has(0x6060) else 0
            dev.consumers = {}
            if dev.has(0x1016, 0):
                for sub in range(1, dev.raw(0x1016, 0) + 1):
                    entry = dev.raw(0x1016, sub) if dev.has(0x1016, sub) else 0
                    if entry & 0xFFFF:
                        dev.consumers[(entry >> 16) & 0x7F] = (entry & 0xFFFF) / 1000.0
            self.configured(dev)  # type: ignore[arg-type]

    def configured(self, d: D) -> None:
        """Drive ``d``'s object dictionary changed (or it booted): a subclass takes what it needs from it."""

    def _layout_or_none(self, dev: SimDevice, mapping_index: int) -> PdoLayout | None:
        try:
            return self._compile(dev, mapping_index)
        except PdoLayoutError as exc:
            log.warning("%s %d: mapping %#06x unusable, its PDO is left out: %s", self.kind, dev.node,
                        mapping_index, exc)
            return None

    @staticmethod
    def _compile(dev: SimDevice, mapping_index: int) -> PdoLayout:
        count = dev.raw(mapping_index, 0)
        entries = [decode_mapping_entry(dev.raw(mapping_index, s)) for s in range(1, count + 1)]
        return PdoLayout.compile(entries, _data_types(dev.local))

    def _read_object(self, dev: SimDevice, index: int, subindex: int) -> int | None:
        """Live values for SDO reads (canopen's read callback): the state, the actual values."""
        if isinstance(dev, SimIoModule):
            return dev.read(index, subindex)
        if not isinstance(dev, SimDrive):
            return None
        if index == 0x6041:
            return dev.sm.statusword
        if index == 0x6061:
            return dev.mode
        if index == 0x603F:
            return int(dev.sm.fault_code)
        if index == 0x1001:
            return 0x01 if dev.sm.faulted else 0x00
        if 0x6062 <= index <= 0x6077 and subindex == 0 and self._actuals:
            return self._actuals[self._drives.index(dev)].get(index)  # type: ignore[arg-type]
        return None

    def _write_object(self, dev: SimDevice, index: int, subindex: int, data: bytes) -> None:
        """Checks and effects of an SDO write (canopen's write callback; raising
        :class:`SdoAbortedError` answers the master with that abort code)."""
        if 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF:
            com = index - 0x200
            if dev.has(com, 1) and not dev.raw(com, 1) & _PDO_NOT_VALID:
                raise SdoAbortedError(_ABORT_UNSUPPORTED_ACCESS)  # the PDO must be invalid first
            value = int.from_bytes(data, "little")
            if subindex == 0:
                entries = [decode_mapping_entry(dev.raw(index, s)) for s in range(1, value + 1)]
                if sum(bits for _, _, bits in entries) > 64:
                    raise SdoAbortedError(_ABORT_PDO_LENGTH)
                try:
                    PdoLayout.compile(entries, _data_types(dev.local))
                except PdoLayoutError:
                    raise SdoAbortedError(_ABORT_NOT_MAPPABLE) from None
            else:
                obj_index, obj_sub, bits = decode_mapping_entry(value)
                if value and not self._mappable(dev, obj_index, obj_sub, bits, receive=index < 0x1A00):
                    raise SdoAbortedError(_ABORT_NOT_MAPPABLE)
        elif isinstance(dev, SimDrive) and index == 0x6060:
            mode = struct.unpack("<b", data[:1])[0]
            bit = {1: 0x01, 3: 0x04, 8: 0x80, 9: 0x100, 10: 0x200}.get(mode, 0)
            if not bit or not dev.raw(0x6502) & bit:
                raise SdoAbortedError(_ABORT_VALUE_RANGE)
        elif isinstance(dev, SimDrive) and index == 0x6040:
            dev.controlword = int.from_bytes(data, "little")
            dev.sm.on_controlword(dev.controlword)
        elif isinstance(dev, SimDrive) and index in (0x607A, 0x60FF) and len(data) == 4:
            dev.received[index] = struct.unpack("<i", data)[0]  # echoed by a TPDO mapping it
        dev.dirty = True  # the caches are made again once the value has landed (canopen stores it after us)

    @staticmethod
    def _mappable(dev: SimDevice, index: int, subindex: int, bits: int, receive: bool) -> bool:
        if not dev.has(index, subindex):
            return False
        obj = dev.local.object_dictionary[index]
        if not isinstance(obj, canopen.objectdictionary.ODVariable):
            obj = obj[subindex]
        if not obj.pdo_mappable or len(obj) != bits:
            return False
        return obj.writable if receive else obj.readable

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
            self._lock.release()  # SDO requests are answered meanwhile
            try:
                frame = self.bus.wait_inbound(left)
            finally:
                self._lock.acquire()
            if frame is not None:
                self.receive(frame, t)
        self._last_sync_wall = time.monotonic()


class SimIoModule(SimDevice):
    """A simulated CiA 401 digital input module (the PUMA's crossfire sensor): 0x6000:01 is what
    ``read_input`` returns; its event-driven TPDOs go out on every change while operational and on
    NMT start.

    Args:
        node: node id.
        read_input: returns the 8 input bits.
    """

    def __init__(self, node: int, read_input: Callable[[], int]) -> None:
        super().__init__(node)
        self.read_input = read_input
        self.owner: SimCanDrives[Any] | None = None
        self._last: int | None = None
        self._inputs = 0

    def read(self, index: int, subindex: int) -> int | None:
        """Value of an object for SDO reads (``None``: the object dictionary's): the inputs as of the
        latest step (an SDO request is answered in another thread than the simulation's)."""
        if index == 0x6000 and subindex == 1:
            return self._inputs
        return None

    def started(self, t: float) -> None:
        """NMT start: report the inputs at once."""
        self._last = None
        self.poll(t)

    def poll(self, t: float) -> None:
        """Send the event-driven TPDOs if the inputs changed (call every step)."""
        value = self._inputs = int(self.read_input()) & 0xFF
        if self.nmt is not cf.NmtState.OPERATIONAL or self.owner is None:
            return
        if value == self._last:
            return
        self._last = value
        if self.tpdos is None:
            self.owner._recompile(self)
        for cob_id, layout, trans in self.tpdos or ():
            if trans >= 254:
                self.owner.bus.transmit(cf.CanFrame(cob_id, layout.pack_objects({0x6000: value}), t))
