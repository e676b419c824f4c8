"""The CANopen master of CiA 402 drives on a CAN bus, as a node's driver sees them (position or velocity mode).

The framework's generic device link to drives, on the ``canopen`` library (over python-can): a
testbed's driver gives the bus's device file (:mod:`services.devices.devicefile`: per drive its node
id, EDS or DCF file, mode of operation, unit scaling, heartbeat and deadline times, PDO mappings) and
the master does the rest. Each drive and I/O module is a :class:`canopen.RemoteNode` made from its
EDS file on a :class:`canopen.Network`, and the master uses canopen for

* NMT (pre-operational for the configuration, start, and the state each node's heartbeat reports:
  canopen's NMT master per node, its heartbeat consumer);
* SDO: at start-up it configures every drive as a real one is configured: heartbeat producer time
  0x1017, consumer heartbeat time 0x1016 (the drive watches the master's heartbeat), mode of
  operation 0x6060 (checked against 0x6502 and read back from 0x6061), the PDO mappings of the
  device file (or of the EDS file, or read from the drive) written with canopen's PDO objects, the
  RPDO deadline (event timer 0x1400:05), and the mappings read back over SDO;
* PDOs: canopen's PDO maps receive the drives' TPDOs (their callbacks hand the data on); the
  cyclic RPDOs are sent through canopen's network;
* EMCY: canopen's EMCY consumer per node, whose codes say why a drive faulted;
* SYNC: the consumer of another station's SYNC (the simulated world's), or its producer
  (canopen's SYNC producer, once per cycle of :meth:`CanDrives.wait_sync`), as the device file says.

The CiA 402 power state machine is ours over those objects (the statusword decoded by
:func:`services.devices.cia402.state_from_statusword`, the controlword sent in the same RPDO as the
cyclic target), not canopen's :class:`canopen.profiles.p402.BaseNode402`, whose ``state`` setter
walks one drive at a time with fixed wall-clock timeouts (0.4-0.8 s, more than a loaded machine's
simulation may take), sends the controlword alone (a CSP drive needs a target in every cycle's RPDO,
and a synchronous RPDO it does not send at all), whose fault reset waits for a fault to clear before
the rising edge of bit 7 that clears it has been sent (its own FIXME: it always runs into its
timeout), and whose TPDO cache decodes every object of every TPDO through the object dictionary (about
10 µs per PDO, 60 ms of CPU per second with six drives at 500 SYNCs/s). The PDO data of the cyclic
path are packed and read with layouts compiled from canopen's PDO maps
(:class:`services.devices.pdo.PdoLayout`, one struct call per PDO).

Talks to the bus through python-can: ``interface = "socketcand"`` (the simulated world's gateway,
:class:`sim.socketcand.CanGateway`, or a socketcand daemon beside a real bus) at ``host:port``, or any
other python-can interface the device file names (``"socketcan"`` on a host with a CAN interface).

Supervision, on two clocks: a node whose latest heartbeat is older than ``heartbeat_timeout`` seconds
of *bus* time (the time the frames carry: a node gone silent on a live bus), a bus on which nothing
at all arrived for ``silence_timeout`` seconds of *wall* time (the bus, or the simulation behind it,
stopped), or a closed connection, makes :meth:`CanDrives.check` raise :class:`BusError` (and
:meth:`CanDrives.lost` say why); so does a drive in FAULT, naming the cause its EMCY gave. (A
simulation slowed down by a loaded machine delivers its heartbeats further apart in wall time without
anything being lost; judged on the wall clock alone, 0.5 s, that stall failed catches of the demo.)

A CAN bus has no keys: any station may send anything. The master cannot prevent another station from
taking its drives over, but it sees it, and :meth:`CanDrives.trouble` (and so :meth:`CanDrives.check`)
says so at once: an NMT command on the bus (the master never receives its own frames, so any NMT frame
it sees is another station's), an RPDO to one of its drives that it did not send (a second master),
a drive whose heartbeat reports it left OPERATIONAL (stopped, pre-operational, reset), a drive whose
TPDOs stopped while SYNCs go on, and, where a drive's TPDO echoes its target (0x607A or 0x60FF
mapped), a target the master did not send. The master produces its own heartbeat (every
``master_heartbeat_ms`` of bus time while it sends targets), which the drives consume.
:meth:`CanDrives.enable` is also the CiA 402 fault recovery: it waits out a running fault reaction,
resets the fault (controlword 0x00, then the rising edge 0x80) and walks every drive to
OPERATION_ENABLED again.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import functools
import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Self

import can
import canopen
import numpy as np
from canopen.sdo import SdoAbortedError, SdoCommunicationError
from numpy.typing import NDArray

from services.devices import cia402 as cf
from services.devices.devicefile import MODES, BusSpec, DriveSpec, IoSpec
from services.devices.pdo import PdoLayout, PdoLayoutError
from services.errors import ActionError

__all__ = ["BusError", "CanDrives", "IoCallback", "VelocityCanDrives"]

log = logging.getLogger(__name__)

# python-can's socketcand client logs every TCP read that splits a frame message as a warning;
# that is ordinary stream fragmentation, not a fault.
logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)
# canopen logs every SDO transfer and every PDO map entry at INFO: the configuration of six drives would be
# hundreds of lines in a node's log; this module says what matters itself.
logging.getLogger("canopen").setLevel(logging.WARNING)

_SUPPORTED_MODE_BITS = {1: 0x01, 3: 0x04, 8: 0x80, 9: 0x100, 10: 0x200}
_POSITION_MODES = ("csp", "pp")
_NMT_NAMES = {0x01: "start", 0x02: "stop", 0x80: "enter pre-operational", 0x81: "reset node",
              0x82: "reset communication"}
_TPDO_STALE_CYCLES = 10
"""SYNCs in a row without a drive's TPDO after which it counts as silent (its synchronous TPDOs stopped)."""
_FOREIGN_HOLD_S = 1.0
"""A second master's RPDOs keep the drives in trouble until none came for this long, s (wall)."""


class BusError(ActionError):
    """The CAN bus or a drive is unusable: connection lost, heartbeat missing, drive fault, a drive
    taken over by another station."""


IoCallback = Callable[[bytes, float], None]
"""Called from the receive thread with an I/O module's TPDO data and its bus time, s."""


@dataclass(eq=False)
class _Drive:
    """What the master knows of one drive."""

    spec: DriveSpec
    node: Any  # canopen.RemoteNode
    rpdos: list[tuple[int, PdoLayout]] = field(default_factory=list)  # the cyclic RPDOs: (COB-ID, layout)
    target_index: int = 0x607A
    statusword: int = 0
    position: float = math.nan
    velocity: float = math.nan
    seen: bool = False  # a TPDO with the statusword arrived
    tpdo_sync: int = 0  # SYNC count at the latest TPDO
    nmt: cf.NmtState | None = None
    nmt_t: float = math.nan  # bus time of the latest heartbeat
    emcy: tuple[int, float] | None = None
    sent: collections.deque[int] = field(default_factory=lambda: collections.deque(maxlen=8))
    echoed: bool = False  # a TPDO echoed one of the targets sent since start (the echo is in step)
    wrong_target: str | None = None


class CanDrives:
    """CiA 402 drives as seen from a node (the CANopen master), in the modes their device file gives.

    Lifecycle: ``CanDrives(host, port, bus=spec)`` only configures; :meth:`open` connects (or use it as
    a context manager); :meth:`start` configures the drives over SDO (once per connection) and starts
    them; :meth:`enable` brings every drive to OPERATION_ENABLED; :meth:`send_targets` once per cycle;
    :meth:`close` disables and disconnects.

    Args:
        host, port: the socketcand server (the sim's CAN gateway), for ``interface = "socketcand"``.
        heartbeat_timeout: seconds of bus time without a heartbeat after which a node counts as lost.
        silence_timeout: seconds of wall time without any frame after which the bus counts as lost.
        clock: monotonic clock for supervision (seconds).
        bus: the device file's bus: drives (in order) and I/O modules (whose heartbeats are supervised
            too and whose TPDO reports go to :meth:`on_io` callbacks).
    """

    def __init__(
        self,
        host: str,
        port: int,
        heartbeat_timeout: float = 0.5,
        silence_timeout: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
        *,
        bus: BusSpec,
    ) -> None:
        self.spec = bus
        self.nodes = bus.node_ids
        self.io_nodes = tuple(io.node_id for io in bus.io)
        self.host = host
        self.port = port
        self.channel = bus.channel
        self.heartbeat_timeout = heartbeat_timeout
        self.silence_timeout = silence_timeout
        self._clock = clock
        self._network: canopen.Network | None = None
        self._drives: list[_Drive] = []
        self._io_specs: tuple[IoSpec, ...] = bus.io
        self._io_nodes: dict[int, Any] = {}
        self._io: dict[int, list[IoCallback]] = {node: [] for node in self.io_nodes}
        self._io_state: dict[int, tuple[float, cf.NmtState]] = {}
        self._cond = threading.Condition()
        self._last_rx = 0.0
        self._bus_now = math.nan  # bus time of the latest frame
        self._sync_count = 0
        self._sync_returned = 0
        self._sync_t = math.nan
        self.sync_arrived: float | None = None
        """Monotonic time at which the latest SYNC arrived (or was produced)."""
        self._stop_sync = threading.Event()
        self._sync_thread: threading.Thread | None = None
        self._expect_enabled = False
        self._expect_operational = False
        self._configured = False
        self._heartbeat_sent_t = -math.inf
        self._dead: str | None = None
        self._opened_at = 0.0
        self._foreign: str | None = None  # another station's NMT command or RPDOs, in words
        self._foreign_t = -math.inf  # wall time it was last seen
        self._foreign_rpdo = False

    # --- connection ------------------------------------------------------------------------------

    def open(self, timeout: float = 5.0) -> Self:
        """Connect to the bus, make the nodes from their EDS files and start receiving.

        Raises:
            BusError: the server cannot be reached or refuses the bus within ``timeout``, or an EDS
                file cannot be read.
        """
        try:
            raw = _connect(self.spec, self.host, self.port, timeout)
        except (OSError, can.CanError, TimeoutError, BusError) as exc:
            raise BusError(f"cannot open CAN bus {self.channel} at {self.host}:{self.port}: {exc}") from exc
        network = canopen.Network(raw)
        network.NOTIFIER_CYCLE = 0.05  # type: ignore[misc]  # close() waits at most this long for the receive thread
        network.listeners.append(_Watch(self))
        try:
            for spec in self.spec.drives:
                node = canopen.RemoteNode(spec.node_id, canopen.import_od(spec.eds, spec.node_id))
                network.add_node(node)
                node.sdo.RESPONSE_TIMEOUT = self.spec.sdo_timeout_s
                node.nmt.add_heartbeat_callback(functools.partial(self._on_heartbeat, len(self._drives)))
                node.emcy.add_callback(functools.partial(self._on_emcy, len(self._drives)))
                self._drives.append(_Drive(spec, node, target_index=0x607A if spec.mode in _POSITION_MODES else 0x60FF))
            for io in self._io_specs:
                node = canopen.RemoteNode(io.node_id, canopen.import_od(io.eds, io.node_id))
                network.add_node(node)
                node.sdo.RESPONSE_TIMEOUT = self.spec.sdo_timeout_s
                node.nmt.add_heartbeat_callback(functools.partial(self._on_io_heartbeat, io.node_id))
                self._io_nodes[io.node_id] = node
        except (OSError, ValueError, KeyError) as exc:
            raw.shutdown()
            raise BusError(f"cannot read an EDS file of {self.spec.path}: {exc}") from exc
        network.subscribe(cf.SYNC_ID, self._on_sync)
        network.subscribe(cf.NMT_ID, self._on_nmt_command)
        self._opened_at = self._last_rx = self._clock()
        network.connect()
        self._network = network
        if self.spec.sync == "producer":
            self._stop_sync.clear()
            self._sync_thread = threading.Thread(target=self._produce_syncs, name="can-sync-producer", daemon=True)
            self._sync_thread.start()
        return self

    def close(self) -> None:
        """Disable the drives (best effort) and disconnect."""
        network = self._network
        if network is None:
            return
        self._expect_enabled = False
        self._expect_operational = False
        try:
            if self._dead is None and self._configured:
                for d in self._drives:
                    self._send_hold(d, cf.Controlword.DISABLE_VOLTAGE)
        except BusError:
            pass
        self._stop_sync.set()
        if self._sync_thread is not None:
            self._sync_thread.join(timeout=2.0)
            self._sync_thread = None
        self._network = None
        if self._dead is not None:
            _abort(network.bus)
        try:
            network.disconnect()
        except (can.CanError, OSError, RuntimeError):
            pass

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- state -----------------------------------------------------------------------------------

    def positions(self) -> NDArray[np.float64]:
        """Latest actual positions of the drives, shape (n,), SI units (rad; NaN until a drive reported)."""
        with self._cond:
            return np.array([d.position for d in self._drives])

    def states(self) -> list[cf.DriveState | None]:
        """Latest CiA 402 state of the drives (``None`` until reported or not understood)."""
        with self._cond:
            return self._states_locked()

    @property
    def sim_time(self) -> float:
        """Bus time (s) of the latest SYNC."""
        return self._sync_t

    def on_io(self, node: int, callback: IoCallback) -> None:
        """Call ``callback(data, t)`` from the receive thread on every TPDO of I/O module ``node``.

        Raises:
            ValueError: ``node`` is not one of the ``io_nodes``.
        """
        if node not in self._io:
            raise ValueError(f"CAN node {node} is not an I/O module of this bus ({self.io_nodes})")
        self._io[node].append(callback)

    def lost(self) -> str | None:
        """Why the bus counts as lost (closed, marked lost, a node's heartbeat missing), or ``None``."""
        if self._dead is not None:
            return self._dead
        now = self._clock()
        with self._cond:
            silent = now - self._last_rx
            bus_now = self._bus_now
            beats = [(d.spec.node_id, d.nmt_t) for d in self._drives]
            beats += [(node, self._io_state.get(node, (math.nan, None))[0]) for node in self.io_nodes]
        if silent > self.silence_timeout:
            return f"nothing on the CAN bus for {silent:.2f} s (no SYNC, no heartbeats): bus lost"
        for node, seen in beats:
            if math.isnan(seen):
                if now - self._opened_at > self.silence_timeout:
                    return f"no heartbeat from CAN node {node} since the bus was opened: node lost"
            elif bus_now - seen > self.heartbeat_timeout:
                return f"no heartbeat from CAN node {node} for {bus_now - seen:.2f} s of bus time: node lost"
        return None

    def trouble(self) -> str | None:
        """Why the drives are not (or no longer) the master's alone, or ``None``: another station's NMT
        command or RPDOs, a drive whose heartbeat says it left OPERATIONAL, a drive whose TPDOs
        stopped, a drive reporting a target it was not sent (module docstring)."""
        with self._cond:
            if self._foreign is not None and (not self._foreign_rpdo
                                              or self._clock() - self._foreign_t < _FOREIGN_HOLD_S):
                return self._foreign
            if not self._expect_operational:
                return None
            for d in self._drives:
                if d.nmt is not None and d.nmt is not cf.NmtState.OPERATIONAL:
                    return (f"drive {d.spec.node_id} left operational: its heartbeat says NMT state "
                            f"{d.nmt.name.lower().replace('_', '-')}")
                if d.seen and self._sync_count - d.tpdo_sync > _TPDO_STALE_CYCLES:
                    return (f"drive {d.spec.node_id} sent no TPDO for {self._sync_count - d.tpdo_sync} SYNC "
                            "cycles: it left operational")
                if d.wrong_target is not None:
                    return d.wrong_target
        return None

    def taken_over(self) -> bool:
        """Another station is commanding the drives now (its RPDOs were seen within the last second):
        recovering them would fight it."""
        with self._cond:
            return self._foreign_rpdo and self._clock() - self._foreign_t < _FOREIGN_HOLD_S

    def check(self) -> None:
        """Raise :class:`BusError` if the bus is lost, a heartbeat is missing, a drive faulted or was
        taken over, or (after :meth:`enable`) a drive is no longer operation enabled; the message says
        which."""
        lost = self.lost()
        if lost is not None:
            raise BusError(lost)
        trouble = self.trouble()
        if trouble is not None:
            raise BusError(trouble)
        with self._cond:
            states = self._states_locked()
        for node, state in zip(self.nodes, states):
            if state in (cf.DriveState.FAULT, cf.DriveState.FAULT_REACTION_ACTIVE):
                raise BusError(f"drive {node} is in FAULT ({self.fault_cause(node)})")
            if self._expect_enabled and state is not cf.DriveState.OPERATION_ENABLED:
                raise BusError(f"drive {node} is '{state.value if state else 'silent'}', not operation enabled")

    def mark_lost(self, reason: str) -> None:
        """Declare the connection lost (e.g. the bus went silent): later sends and checks raise
        :class:`BusError` with ``reason``, and :meth:`close` sends nothing more on it (frames
        queued on a connection that comes back late could otherwise reach the drives after a
        new connection has enabled them)."""
        self._mark_dead(reason)

    def fault_cause(self, node: int) -> str:
        """What the latest EMCY of drive ``node`` said, in words ("unknown cause" without one)."""
        with self._cond:
            return self._cause_locked(node)

    def faults(self) -> dict[int, str]:
        """Drives in FAULT or FAULT REACTION ACTIVE by node id, each with its EMCY cause in words."""
        with self._cond:
            return {n: self._cause_locked(n) for n, s in zip(self.nodes, self._states_locked())
                    if s in (cf.DriveState.FAULT, cf.DriveState.FAULT_REACTION_ACTIVE)}

    def all_enabled(self) -> bool:
        """True when every drive reported OPERATION_ENABLED in its latest TPDO."""
        return all(s is cf.DriveState.OPERATION_ENABLED for s in self.states())

    def refresh(self, timeout: float = 0.5) -> bool:
        """Wait until every drive has reported (a TPDO) after the next SYNC, so that :meth:`states`,
        :meth:`faults` and :meth:`trouble` judge the drives as they are now and not as they were before
        a receive thread starved by a loaded machine caught up (at most ``timeout`` s, wall clock).

        Returns:
            True when every drive reported in time (False: some are silent; :meth:`trouble` or
            :meth:`lost` say why).
        """
        with self._cond:
            target = self._sync_count + 1
        try:
            self._wait(lambda: all(d.tpdo_sync >= target for d in self._drives), self._clock() + timeout, "")
        except BusError:
            return False
        return True

    def sdo_read(self, node: int, index: int, subindex: int = 0) -> int:
        """Read an integer object of drive or module ``node`` over SDO (a blocking request).

        Raises:
            BusError: the bus is not open, the node is unknown, or the SDO transfer failed (the
                abort code's text said).
        """
        for candidate in [d.node for d in self._drives] + list(self._io_nodes.values()):
            if candidate.id == node:
                try:
                    var = candidate.sdo[index]
                    return int(var.raw if subindex == 0 and not hasattr(var, "keys") else var[subindex].raw)
                except (SdoAbortedError, SdoCommunicationError, KeyError) as exc:
                    raise BusError(f"SDO read of {index:#06x}:{subindex:02x} from node {node} failed: {exc}") from exc
        raise BusError(f"node {node} is not on this bus")

    # --- commands --------------------------------------------------------------------------------

    def configure(self, timeout: float = 10.0) -> None:
        """Configure every drive over SDO as the device file says (module docstring); the drives are
        put in NMT pre-operational first. Done by :meth:`start` once per connection.

        Raises:
            BusError: a drive refused a value (the object and the abort code named), did not answer,
                does not support the mode, or its PDO mapping lacks what the master needs.
        """
        network = self._require_network()
        network.nmt.send_command(cf.NmtCommand.PRE_OPERATIONAL)
        # one thread per drive: each drive answers its own SDO channel, so N drives take the time of one
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, len(self._drives)),
                                                   thread_name_prefix="can-configure") as pool:
            futures = [(d, pool.submit(self._configure_drive, d)) for d in self._drives]
            done, pending = concurrent.futures.wait([f for _, f in futures], timeout=timeout)
            for d, f in futures:
                if f in pending:
                    raise BusError(f"configuring drive {d.spec.node_id} ({d.spec.name}) took longer than {timeout} s")
                try:
                    f.result()
                except (SdoAbortedError, SdoCommunicationError) as exc:
                    raise BusError(f"drive {d.spec.node_id} ({d.spec.name}): SDO configuration failed: {exc}") from exc
        for node in self._io_nodes.values():
            try:
                node.tpdo.read(from_od=True)
            except (KeyError, ValueError) as exc:
                raise BusError(f"I/O node {node.id}: its EDS's TPDOs are unusable: {exc}") from exc
            for m in node.tpdo.map.values():
                if m.enabled:
                    m.add_callback(functools.partial(self._on_io_tpdo, node.id))
        self._configured = True

    def _configure_drive(self, d: _Drive) -> None:
        node, spec = d.node, d.spec
        mode = MODES[spec.mode]
        if 0x6502 in node.object_dictionary:
            supported = int(node.sdo[0x6502].raw)
            if not supported & _SUPPORTED_MODE_BITS.get(mode, 0):
                raise BusError(f"drive {spec.node_id} does not support mode {spec.mode} "
                               f"(0x6502 = {supported:#06x})")
        node.sdo[0x6060].raw = mode
        shown = int(node.sdo[0x6061].raw)
        if shown != mode:
            raise BusError(f"drive {spec.node_id} shows mode {shown} in 0x6061 after 0x6060 = {mode}")
        node.sdo[0x1017].raw = spec.heartbeat_ms
        if 0x1016 in node.object_dictionary:
            node.sdo[0x1016][1].raw = ((self.spec.master_node_id << 16 | spec.master_heartbeat_timeout_ms)
                                       if spec.master_heartbeat_timeout_ms else 0)
        if spec.pdo_mapping == "write":
            node.rpdo.read(from_od=True)
            node.tpdo.read(from_od=True)
            self._remap(node.rpdo, spec.rpdo, spec.rpdo_timeout_ms, d.target_index)
            self._remap(node.tpdo, spec.tpdo, None, None)
            node.rpdo.save()
            node.tpdo.save()
        node.rpdo.read()  # what the drive holds now, over SDO
        node.tpdo.read()
        self._use_mappings(d)
        log.info("CAN drive %d (%s) configured over SDO: mode %s, heartbeat %d ms; read back: RPDO %s, TPDO %s",
                 spec.node_id, spec.name, spec.mode, spec.heartbeat_ms,
                 _mapped(node.rpdo), _mapped(node.tpdo))

    @staticmethod
    def _remap(pdos: Any, wanted: tuple[tuple[tuple[int, int], ...], ...] | None, deadline_ms: int | None,
               target_index: int | None) -> None:
        """Set canopen's PDO maps to the device file's mapping (``None``: keep the EDS's), synchronous."""
        for number, m in pdos.map.items():
            if wanted is not None:
                m.clear()
                if number <= len(wanted):
                    for index, subindex in wanted[number - 1]:
                        if m.add_variable(index, subindex) is None:
                            raise BusError(f"object {index:#06x}:{subindex:02x} is not in node "
                                           f"{pdos.node.id}'s EDS")
                m.enabled = number <= len(wanted) and bool(wanted[number - 1])
            if m.cob_id in (None, 0) and m.predefined_cob_id is not None:
                m.cob_id = m.predefined_cob_id
            if m.enabled:
                m.trans_type = 1
            if deadline_ms is not None and 5 in m.com_record.od:
                carries = target_index is not None and any(v.index == target_index for v in m.map)
                m.event_timer = deadline_ms if (m.enabled and carries) else 0

    def _use_mappings(self, d: _Drive) -> None:
        """Compile the layouts of the drive's enabled PDOs and hook its TPDOs; check that the RPDOs
        carry the controlword and the target and the TPDOs the statusword and the position."""
        rpdos: list[tuple[int, PdoLayout]] = []
        for m in d.node.rpdo.map.values():
            if m.enabled:
                layout = _layout(m)
                if 0x6040 in layout or d.target_index in layout:
                    rpdos.append((m.cob_id, layout))
                    self._require_network().subscribe(
                        m.cob_id, functools.partial(self._on_foreign_rpdo, d.spec.node_id))
        tpdo_objects: set[int] = set()
        for m in d.node.tpdo.map.values():
            if m.enabled:
                layout = _layout(m)
                tpdo_objects.update(layout.indices)
                m.add_callback(functools.partial(self._on_tpdo, d, layout))
        needed = {0x6040: rpdos and any(0x6040 in lay for _, lay in rpdos),
                  d.target_index: any(d.target_index in lay for _, lay in rpdos)}
        missing = [f"{i:#06x} in an RPDO" for i, ok in needed.items() if not ok]
        missing += [f"{i:#06x} in a TPDO" for i in (0x6041, 0x6064) if i not in tpdo_objects]
        if isinstance(self, VelocityCanDrives) and 0x606C not in tpdo_objects:
            missing.append("0x606c in a TPDO")
        if missing:
            raise BusError(f"drive {d.spec.node_id} ({d.spec.name}): its PDO mapping lacks {', '.join(missing)}")
        d.rpdos = rpdos

    def start(self, timeout: float = 3.0) -> None:
        """Configure the drives (first time on this connection), NMT-start every node, send the master's
        heartbeat, and wait until every drive has reported (its TPDOs: its position and state) and no
        fault reaction is running any more.

        After it, :meth:`positions` are the joints' resting positions: a control loop can start
        from them (and send targets) before :meth:`enable`.

        Raises:
            BusError: not within ``timeout`` s, a drive refused its configuration, or the bus is lost.
        """
        network = self._require_network()
        if not self._configured:
            self.configure(max(timeout, 10.0))
        with self._cond:
            if not self._foreign_rpdo:
                self._foreign = None  # a foreign NMT command is undone by this start
            for d in self._drives:
                d.wrong_target = None
                d.echoed = False
                d.sent.clear()
            started = self._sync_count
        self._send_message(cf.NMT_ID, bytes([cf.NmtCommand.START, 0]), network)
        deadline = self._clock() + timeout
        self._wait(lambda: all(d.seen and d.tpdo_sync > started for d in self._drives),
                   deadline, "no TPDO from every drive after NMT start")
        with self._cond:
            for d in self._drives:
                d.nmt = cf.NmtState.OPERATIONAL if d.nmt is not None else None
            self._expect_operational = True
        self._send_heartbeat()
        self._wait(lambda: not any(s is cf.DriveState.FAULT_REACTION_ACTIVE for s in self._states_locked()),
                   deadline, "a drive's fault reaction did not end")

    def enable(self, timeout: float = 3.0) -> None:
        """:meth:`start`, then recover faulted drives and walk every drive to OPERATION_ENABLED.

        The CiA 402 recovery of a faulted drive: wait until its fault reaction has brought the
        joint to rest (FAULT), send controlword 0x00 so that bit 7 is low, then the fault reset
        0x80 (the rising edge), then shutdown, switch on, enable operation, each checked on the
        statuswords. Each RPDO carries the drive's own actual position as target (a velocity drive
        zero velocity), so enabling does not move the axis. A control loop may run meanwhile,
        sending enable-operation RPDOs with targets at the resting positions (the motion node's does,
        so that cyclic targets flow from the first enabled cycle on): a drive it enables from
        SWITCHED_ON counts as switched on.

        Raises:
            BusError: a drive did not reach OPERATION_ENABLED within ``timeout`` s (its state and
                fault cause named), or the bus is lost.
        """
        deadline = self._clock() + timeout
        self.start(timeout)
        on = cf.DriveState.OPERATION_ENABLED
        steps: tuple[tuple[cf.Controlword, tuple[cf.DriveState, ...]], ...] = (
            (cf.Controlword.DISABLE_VOLTAGE, ()),
            (cf.Controlword.FAULT_RESET, (cf.DriveState.SWITCH_ON_DISABLED,)),
            (cf.Controlword.SHUTDOWN, (cf.DriveState.READY_TO_SWITCH_ON,)),
            (cf.Controlword.SWITCH_ON, (cf.DriveState.SWITCHED_ON, on)),
            (cf.Controlword.ENABLE_OPERATION, (on,)),
        )
        for cw, states in steps:
            for d in self._drives:
                self._send_hold(d, cw)
            if states:
                self._wait(
                    lambda ok=states: all(st in ok for st in self._states_locked()),  # type: ignore[misc]
                    deadline,
                    f"drives did not reach '{states[0].value}'",
                    describe=True,
                )
            else:
                self._wait_syncs(2, deadline)
        self._expect_enabled = True

    def disable(self) -> None:
        """Disable voltage on every drive (they hold position, brakes on)."""
        self._expect_enabled = False
        for d in self._drives:
            self._send_hold(d, cf.Controlword.DISABLE_VOLTAGE)

    def send_targets(self, q: Sequence[float] | NDArray[np.float64]) -> None:
        """Send each drive its RPDOs: enable-operation controlword and target position, SI units (rad),
        shape (n,); also the master's heartbeat every ``master_heartbeat_ms`` of bus time.

        Raises:
            BusError: the connection is lost.
            ValueError: not one target per drive.
        """
        if len(q) != len(self._drives):
            raise ValueError(f"expected {len(self._drives)} joint targets, got {len(q)}")
        for d, target in zip(self._drives, q):
            self._send_cycle(d, cf.Controlword.ENABLE_OPERATION, float(target) / d.spec.position_unit)
        if self._sync_t - self._heartbeat_sent_t >= self.spec.master_heartbeat_ms / 1000.0 - 1e-9:
            self._send_heartbeat()

    def wait_sync(self, timeout: float = 0.1) -> float:
        """Block until a SYNC newer than the one the previous call returned; returns its bus time, s.

        A SYNC that arrived since the previous call is returned at once (a control loop answers
        every SYNC, never skips one it has not answered yet); several that arrived meanwhile count
        as one, the latest. (When the device file makes the master the SYNC producer, a thread of its
        own sends SYNC every period of the wall clock.)

        Raises:
            BusError: no SYNC within ``timeout`` s (wall clock), or the bus is lost.
        """
        with self._cond:
            seen = self._sync_returned
            ok = self._cond.wait_for(lambda: self._sync_count != seen or self._dead is not None, timeout)
            if self._dead is not None:
                raise BusError(self._dead)
            if not ok:
                raise BusError(f"no SYNC on the CAN bus for {timeout:.3f} s")
            self._sync_returned = self._sync_count
            return self._sync_t

    # --- internals -------------------------------------------------------------------------------

    def _require_network(self) -> canopen.Network:
        if self._network is None:
            raise BusError("CAN bus not open")
        if self._dead is not None:
            raise BusError(self._dead)
        return self._network

    def _produce_syncs(self) -> None:
        """The SYNC producer's thread (device file ``sync = "producer"``): canopen's SYNC every period
        of the wall clock, each also counted as received (the master does not hear its own frames)."""
        period = self.spec.sync_period_s
        due = time.monotonic()
        while not self._stop_sync.is_set() and self._dead is None:
            network = self._network
            if network is None:
                return
            try:
                network.sync.transmit()
            except (can.CanError, OSError, RuntimeError) as exc:
                self._mark_dead(f"CAN bus connection lost while sending SYNC: {exc}")
                return
            self._on_sync(cf.SYNC_ID, bytearray(), time.monotonic())
            due = max(due + period, time.monotonic() - period)
            self._stop_sync.wait(max(0.0, due - time.monotonic()))

    def _send_heartbeat(self) -> None:
        """The master's heartbeat (NMT state operational), on the bus clock."""
        t = self._sync_t
        self._heartbeat_sent_t = -math.inf if math.isnan(t) else t
        self._send_message(cf.HEARTBEAT_BASE + self.spec.master_node_id, bytes([cf.NmtState.OPERATIONAL]))

    def _states_locked(self) -> list[cf.DriveState | None]:
        out: list[cf.DriveState | None] = []
        for d in self._drives:
            try:
                out.append(cf.state_from_statusword(d.statusword) if d.seen else None)
            except cf.FrameError:
                out.append(None)
        return out

    def _hold_value(self, d: _Drive) -> float:
        """A target that does not move the drive, in counts: its actual position (a velocity-mode
        drive: zero)."""
        if d.target_index == 0x60FF:
            return 0.0
        return 0.0 if math.isnan(d.position) else d.position / d.spec.position_unit

    def _send_hold(self, d: _Drive, cw: int) -> None:
        self._send_cycle(d, cw, self._hold_value(d))

    def _send_cycle(self, d: _Drive, cw: int, target_counts: float) -> None:
        """Send the drive's cyclic RPDOs with controlword ``cw`` and the target in counts."""
        if not d.rpdos:
            raise BusError(f"drive {d.spec.node_id} is not configured (no RPDO)")
        if not math.isfinite(target_counts):
            raise cf.FrameError(f"target of drive {d.spec.node_id} is not a finite number")
        units = round(target_counts)
        d.sent.append(units)
        for cob_id, layout in d.rpdos:
            values = [cw if e.index == 0x6040 else units if e.index == d.target_index else 0 for e in layout.entries]
            try:
                data = layout.pack(values)
            except PdoLayoutError as exc:
                raise cf.FrameError(f"target of drive {d.spec.node_id} does not fit its RPDO: {exc}") from exc
            self._send_message(cob_id, data)

    def _send_message(self, can_id: int, data: bytes, network: canopen.Network | None = None) -> None:
        net = network or self._require_network()
        if self._dead is not None:
            raise BusError(self._dead)
        try:
            net.send_message(can_id, data)
        except (OSError, can.CanError, RuntimeError) as exc:
            self._mark_dead(f"CAN bus connection lost while sending: {exc}")
            raise BusError(self._dead or "bus lost") from exc

    def _wait(self, pred: Callable[[], bool], deadline: float, what: str, describe: bool = False) -> None:
        with self._cond:
            while not pred():
                if self._dead is not None:
                    raise BusError(self._dead)
                left = deadline - self._clock()
                if left <= 0:
                    if describe:
                        what += ": " + ", ".join(
                            f"drive {n} {s.value if s else 'silent'}"
                            + (f" ({self._cause_locked(n)})" if s is cf.DriveState.FAULT else "")
                            for n, s in zip(self.nodes, self._states_locked()))
                    raise BusError(what)
                self._cond.wait(min(left, 0.05))

    def _cause_locked(self, node: int) -> str:
        emcy = next((d.emcy for d in self._drives if d.spec.node_id == node), None)
        if emcy is None or emcy[0] == cf.EmcyCode.NO_ERROR:
            return "unknown cause"
        try:
            return cf.EmcyCode(emcy[0]).text
        except ValueError:
            return f"EMCY error code {emcy[0]:#06x}"

    def _wait_syncs(self, n: int, deadline: float) -> None:
        with self._cond:
            target = self._sync_count + n
        self._wait(lambda: self._sync_count >= target, deadline, "no SYNC on the CAN bus")

    def _mark_dead(self, reason: str) -> None:
        with self._cond:
            if self._dead is None:
                self._dead = reason
            self._cond.notify_all()

    # --- receive callbacks (the notifier's thread) -----------------------------------------------

    def _received(self, timestamp: float) -> None:
        self._last_rx = self._clock()
        self._bus_now = timestamp

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._cond:
            self._sync_count += 1
            self._sync_t = timestamp
            self.sync_arrived = time.monotonic()
            self._cond.notify_all()

    def _on_tpdo(self, d: _Drive, layout: PdoLayout, pdo_map: Any) -> None:
        try:
            values = layout.unpack(pdo_map.data)
        except PdoLayoutError:
            return
        with self._cond:
            for e, v in zip(layout.entries, values):
                if e.index == 0x6041:
                    d.statusword = v
                    d.seen = True
                elif e.index == 0x6064:
                    d.position = v * d.spec.position_unit
                elif e.index == 0x606C:
                    d.velocity = v * d.spec.velocity_unit
                elif e.index == d.target_index and d.sent and self._expect_operational:
                    if v in d.sent:
                        d.echoed = True
                    elif d.echoed:  # not the target it held before this master's first one reached it
                        d.wrong_target = (f"drive {d.spec.node_id} reports target {v} (counts), which this "
                                          f"master did not send (its last: {d.sent[-1]}): another master?")
            d.tpdo_sync = self._sync_count
            self._cond.notify_all()

    def _on_heartbeat(self, k: int, state: int) -> None:
        d = self._drives[k]
        try:
            nmt = cf.NmtState(state & 0x7F)
        except ValueError:
            return
        with self._cond:
            if nmt is not d.nmt and self._expect_operational and nmt is not cf.NmtState.OPERATIONAL:
                log.warning("CAN drive %d reports NMT state %s in its heartbeat", d.spec.node_id, nmt.name)
            d.nmt = nmt
            d.nmt_t = float(d.node.nmt.timestamp or math.nan)
            self._cond.notify_all()

    def _on_io_heartbeat(self, node: int, state: int) -> None:
        try:
            nmt = cf.NmtState(state & 0x7F)
        except ValueError:
            return
        with self._cond:
            self._io_state[node] = (float(self._io_nodes[node].nmt.timestamp or math.nan), nmt)

    def _on_emcy(self, k: int, entry: Any) -> None:
        d = self._drives[k]
        with self._cond:
            d.emcy = (int(entry.code), float(entry.timestamp))
            self._cond.notify_all()
        if entry.code:
            log.warning("CAN drive %d: EMCY %#06x (%s)", d.spec.node_id, entry.code, self._cause_locked(d.spec.node_id))

    def _on_io_tpdo(self, node: int, pdo_map: Any) -> None:
        data, t = bytes(pdo_map.data), float(pdo_map.timestamp or 0.0)
        for cb in list(self._io.get(node, ())):
            cb(data, t)

    def _on_nmt_command(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """An NMT frame on the bus: the master never receives its own, so it is another station's."""
        if len(data) != 2:
            return
        command, node = data[0], data[1]
        mine = set(self.nodes) | set(self.io_nodes)
        if node != 0 and node not in mine:
            return
        what = _NMT_NAMES.get(command, f"command {command:#04x}")
        whom = "all nodes" if node == 0 else f"node {node}"
        reason = f"another station on the CAN bus sent NMT '{what}' to {whom}: the drives are not this master's alone"
        with self._cond:
            if self._foreign is None:
                log.error("%s", reason)
            self._foreign = reason
            self._foreign_t = self._clock()
            self._cond.notify_all()

    def _on_foreign_rpdo(self, node: int, can_id: int, data: bytearray, timestamp: float) -> None:
        """An RPDO to one of this master's drives that it did not send: a second master on the bus."""
        with self._cond:
            if not self._foreign_rpdo:
                reason = (f"another station on the CAN bus sends RPDO {can_id:#05x} to drive {node}: "
                          "a second master is commanding the drives")
                log.error("%s", reason)
                self._foreign = reason
            self._foreign_rpdo = True
            self._foreign_t = self._clock()
            self._cond.notify_all()


class _Watch(can.Listener):
    """Every received frame marks the bus alive (wall and bus clocks); a receive error marks it dead."""

    def __init__(self, owner: CanDrives) -> None:
        self.owner = owner

    def on_message_received(self, msg: can.Message) -> None:
        self.owner._received(float(msg.timestamp))

    def on_error(self, exc: Exception) -> bool:
        self.owner._mark_dead(f"CAN bus connection lost: {exc}")
        return False  # the notifier's thread ends


def _mapped(pdos: Any) -> str:
    """The enabled PDOs of one of canopen's PDO sets in words: ``0x201 [0x6040, 0x607a]; ...``."""
    return "; ".join(f"{m.cob_id:#05x} [{', '.join(f'{v.index:#06x}' for v in m.map)}]"
                     for m in pdos.map.values() if m.enabled) or "none"


def _layout(pdo_map: Any) -> PdoLayout:
    """The layout of one of canopen's PDO maps.

    Raises:
        BusError: it cannot be compiled (bit-granular entries, an unmappable type).
    """
    try:
        return PdoLayout.compile([(v.index, v.subindex, v.length) for v in pdo_map.map],
                                 {(v.index, v.subindex): v.od.data_type for v in pdo_map.map})
    except PdoLayoutError as exc:
        raise BusError(f"{pdo_map.name}: {exc}") from exc


def _abort(raw: can.BusABC | None) -> None:
    """Make closing a lost socketcand connection a reset (SO_LINGER 0) instead of an orderly close.

    Frames sent just before a link went down stay in the kernel's send queue, unacknowledged, and an
    orderly close leaves them there to be retransmitted, up to seconds after the link is back: old
    targets and controlwords of a motion that has ended would reach the drives after a new
    connection has enabled them. A reset drops them. Other buses (SocketCAN) hold no such queue."""
    sock = getattr(raw, "_SocketCanDaemonBus__socket", None)  # python-can's socketcand client
    if isinstance(sock, socket.socket):
        with contextlib.suppress(OSError):  # already closed by the lost link: nothing left to drop
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))


def _connect(spec: BusSpec, host: str, port: int, timeout: float) -> can.BusABC:
    """Open the python-can bus the device file names; for socketcand, fail fast when nothing listens.

    python-can retries a refused socketcand connection for 10 s; probe the port first so that a
    missing gateway is reported within ``timeout``.
    """
    if spec.interface != "socketcand":
        return can.Bus(interface=spec.interface, channel=spec.channel)
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host, port), timeout=0.5) as probe:
                probe.recv(16)  # the greeting; the server drops this connection
            break
        except OSError as exc:
            if time.monotonic() > deadline:
                raise BusError(f"no socketcand server at {host}:{port}: {exc}") from exc
            time.sleep(0.05)
    return can.Bus(interface="socketcand", host=host, port=port, channel=spec.channel, tcp_tune=True)


class VelocityCanDrives(CanDrives):
    """CiA 402 drives in profile velocity mode (the mobile robot's wheels, node 1 left, node 2
    right): the same master (connection, configuration, supervision, NMT start, fault recovery by
    :meth:`enable`, the master's heartbeat, :meth:`wait_sync`) with target velocities (0x60FF) in
    their RPDOs and velocity actual values (0x606C) from their TPDOs.
    """

    def send_velocities(self, *velocities: float) -> None:
        """The drives' RPDOs, in node order: enable-operation controlword and target velocity,
        SI units (rad/s) (also the master's heartbeat every ``master_heartbeat_ms`` of bus time).

        Raises:
            BusError: the connection is lost.
            FrameError: a velocity is not finite or does not fit.
        """
        for d, velocity in zip(self._drives, velocities, strict=True):
            self._send_cycle(d, cf.Controlword.ENABLE_OPERATION, float(velocity) / d.spec.velocity_unit)
        if self._sync_t - self._heartbeat_sent_t >= self.spec.master_heartbeat_ms / 1000.0 - 1e-9:
            self._send_heartbeat()

    def velocities(self) -> NDArray[np.float64]:
        """Latest velocity actual values of the drives, in node order, SI units (rad/s; NaN before)."""
        with self._cond:
            return np.array([d.velocity for d in self._drives])

