"""The PUMA's CAN bus in the sim process: simulated CiA 402 drives, a crossfire I/O module, and
a socketcand-protocol gateway on loopback so that another process can use the bus with
python-can (``can.Bus(interface="socketcand", host=..., port=..., channel="can0")``).

Frame layout, units and state machine: :mod:`services.devices.cia402`.

Threads: the world calls :meth:`SimDrives.step` from its own (simulation) thread every 1 ms of
simulated time; only that thread touches pybullet. Frames from clients reach the devices through
a thread-safe queue drained at the start of each step. The gateway runs one accept thread and,
per connection, a reader and a writer thread.

Drive model (per joint): a target received in RPDO1 is latched at the next SYNC (every 2 ms of
simulated time) and interpolated linearly over the cycle; the demand goes to pybullet's position
motor with the joint's speed and torque limits. A missing target is extrapolated at the last demand
velocity for a bounded number of cycles (the RPDO-timeout watchdog), and the master's heartbeat is
watched (the consumer-heartbeat watchdog). If ``|demand - actual|`` exceeds
:data:`FOLLOWING_ERROR_LIMIT`, or a watchdog runs out, the drive faults: it brings the joint to rest
on a quick-stop ramp (FAULT REACTION ACTIVE), then holds in FAULT, and says why in an EMCY frame
(:class:`SimDrives`). A drive that is not enabled holds its position (the PUMA's brakes).
"""

from __future__ import annotations

import logging
import math
import queue
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Self

from services.devices import cia402 as cf
from services.catching.robot import puma560
from sim import socketcand

__all__ = [
    "FOLLOWING_ERROR_LIMIT",
    "BusPort",
    "CanGateway",
    "FaultRecord",
    "SimBus",
    "SimDrives",
]

log = logging.getLogger(__name__)

FOLLOWING_ERROR_LIMIT = 0.1  # rad
_RAW_SETTLE_S = 0.2  # gateway: forward bus frames this long after "< ok >" to rawmode at the latest


class BusPort:
    """One attachment to a :class:`SimBus` (an in-process client or a gateway connection).

    Frames sent by one port reach the bus devices and every other port (not the sender), as on a
    real bus. Received frames wait in a bounded queue; on overflow the newest is dropped and
    :attr:`overruns` counts it.
    """

    def __init__(self, bus: SimBus, maxsize: int = 20000) -> None:
        self._bus = bus
        self._queue: queue.Queue[cf.CanFrame] = queue.Queue(maxsize=maxsize)
        self.overruns = 0
        self.closed = False

    def send(self, frame: cf.CanFrame) -> None:
        """Put a frame on the bus."""
        self._bus.transmit(frame, origin=self)

    def recv(self, timeout: float | None = None) -> cf.CanFrame | None:
        """Next frame from the bus, or ``None`` after ``timeout`` seconds (``None``: wait)."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def recv_all(self) -> list[cf.CanFrame]:
        """Every frame waiting now (non-blocking)."""
        out = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out

    def _deliver(self, frame: cf.CanFrame) -> None:
        try:
            self._queue.put_nowait(frame)
        except queue.Full:
            self.overruns += 1

    def close(self) -> None:
        """Detach from the bus."""
        self.closed = True
        self._bus.detach(self)


class SimBus:
    """A simulated CAN bus: fan-out between ports plus an inbound queue for the sim's devices."""

    def __init__(self) -> None:
        self._ports: list[BusPort] = []
        self._lock = threading.Lock()
        self._inbound: queue.SimpleQueue[cf.CanFrame] = queue.SimpleQueue()

    def connect(self) -> BusPort:
        """A new port on the bus."""
        port = BusPort(self)
        with self._lock:
            self._ports.append(port)
        return port

    def detach(self, port: BusPort) -> None:
        """Remove a port (idempotent)."""
        with self._lock:
            if port in self._ports:
                self._ports.remove(port)

    def transmit(self, frame: cf.CanFrame, origin: BusPort | None = None) -> None:
        """Put a frame on the bus from a port (``origin``) or from a sim device (``None``)."""
        with self._lock:
            ports = list(self._ports)
        for port in ports:
            if port is not origin:
                port._deliver(frame)
        if origin is not None:
            self._inbound.put(frame)

    def wait_inbound(self, timeout: float) -> cf.CanFrame | None:
        """The next frame sent by a port, waiting up to ``timeout`` s; ``None`` if none came."""
        try:
            return self._inbound.get(timeout=max(timeout, 0.0))
        except queue.Empty:
            return None

    def take_inbound(self) -> list[cf.CanFrame]:
        """Frames sent by ports since the last call (for the sim's devices)."""
        out = []
        while True:
            try:
                out.append(self._inbound.get_nowait())
            except queue.Empty:
                return out


@dataclass
class _Drive:
    node: int
    joint: int
    sm: cf.Cia402StateMachine = field(default_factory=cf.Cia402StateMachine)
    nmt: cf.NmtState = cf.NmtState.PRE_OPERATIONAL
    pending: float | None = None
    start: float = 0.0
    end: float = 0.0
    t_latch: float = 0.0
    hold: float = 0.0
    commanded: tuple[float, float] | None = None
    missed: int = 0  # SYNC cycles in a row without a new target (extrapolated)
    ramp_q: float = 0.0  # fault reaction: demand position, rad
    ramp_v: float = 0.0  # fault reaction: demand velocity, rad/s
    t_tick: float = 0.0  # time of the previous tick, s


@dataclass(frozen=True, slots=True)
class FaultRecord:
    """One fault of a simulated drive, as its EMCY frame announced it.

    Attributes:
        t: bus time of the fault, s.
        node: drive node id (1..6).
        code: the EMCY error code.
        reason: what happened, with numbers.
        speed: the joint's speed when the fault reaction started, rad/s.
        t_stopped: bus time at which the joint was at rest again (NaN while stopping), s.
    """

    t: float
    node: int
    code: cf.EmcyCode
    reason: str
    speed: float = 0.0
    t_stopped: float = math.nan


class SimDrives:
    """Six simulated CiA 402 joint drives and the crossfire I/O module on a :class:`SimBus`.

    Lifecycle: construct; :meth:`attach` to the robot body in a pybullet client; give the crossfire
    sensor with :meth:`set_crossfire` (or to ``attach``); serve the bus to other processes with a
    :class:`CanGateway` (or use :meth:`SimBus.connect` in process); call :meth:`step` every 1 ms of
    simulated time from the simulation thread.

    Watchdogs (the CiA 301/402 behaviour of a drive whose master goes silent): an enabled drive
    that gets no target at a SYNC keeps its last demand velocity for at most
    ``target_timeout_cycles`` cycles, then faults (EMCY 0x8250, RPDO timeout); once the master's
    heartbeat (node :data:`services.devices.cia402.MASTER_ID`) has been seen, an enabled drive
    that hears none for ``consumer_heartbeat_s`` of bus time faults too (EMCY 0x8130). A fault,
    including a following error, starts the fault reaction: the joint's demand goes from where the
    joint is, at its speed, to rest at the quick-stop deceleration ``qdd_max``; then the drive is
    in FAULT and holds. Every fault is kept in :attr:`faults` (bus time, node, code, reason, when
    the joint was at rest again).

    Pacing (``master_wait_s`` > 0): the sim's own stepping is bursty (a camera frame takes tens of
    milliseconds to render, then the physics catches up), while a real bus's SYNC is strictly
    periodic. So that the master is not charged with the sim's bursts, at each SYNC at which an
    enabled drive has no target yet the sim waits for the master's targets: up to
    ``master_wait_s`` of wall time if the master answered the previous SYNC; once a wait has run
    out, only until one cycle (2 ms) of wall time has passed since the previous SYNC, so that the
    bus runs no faster than real time while the master is silent and the RPDO timeout (50 ms of
    bus time) is at least 50 ms of wall time too. A master that answers is in step again.

    Args:
        bus: the bus to sit on (a new one if ``None``).
        qd_max, tau_max: per-joint speed (rad/s) and torque (N m) limits of the motors, shape (6,).
        q_min, q_max: joint limits (rad) targets are clamped to, shape (6,).
        qdd_max: quick-stop deceleration of the fault reaction, rad/s², shape (6,).
        target_timeout_cycles: missing targets in a row before an RPDO-timeout fault.
        consumer_heartbeat_s: heartbeat consumer time for the master, s of bus time.
        master_wait_s: wall time waited at a SYNC for the master's targets (0: never wait).
    """

    def __init__(
        self,
        bus: SimBus | None = None,
        qd_max: Sequence[float] = tuple(puma560.QD_MAX),
        tau_max: Sequence[float] = tuple(puma560.TAU_MAX),
        q_min: Sequence[float] = tuple(puma560.Q_MIN),
        q_max: Sequence[float] = tuple(puma560.Q_MAX),
        qdd_max: Sequence[float] = tuple(puma560.QDD_MAX),
        *,
        target_timeout_cycles: int = cf.TARGET_TIMEOUT_CYCLES,
        consumer_heartbeat_s: float = cf.CONSUMER_HEARTBEAT_S,
        master_wait_s: float = 0.0,
    ) -> None:
        self.bus = bus if bus is not None else SimBus()
        self.qd_max = [float(v) for v in qd_max]
        self.tau_max = [float(v) for v in tau_max]
        self.q_min = [float(v) for v in q_min]
        self.q_max = [float(v) for v in q_max]
        self.qdd_max = [float(v) for v in qdd_max]
        self.target_timeout_cycles = int(target_timeout_cycles)
        self.consumer_heartbeat_s = float(consumer_heartbeat_s)
        self.master_wait_s = float(master_wait_s)
        self.faults: list[FaultRecord] = []
        self.master_waits = 0
        """SYNCs at which the sim waited for the master's targets."""
        self.master_misses = 0
        """Waits that ran out (the master did not answer within ``master_wait_s``)."""
        self._master_in_step = False
        self._master_heartbeat: float | None = None
        self._last_sync_wall: float | None = None
        self._client: Any = None
        self._body = -1
        self._drives: list[_Drive] = []
        self._crossfire: Callable[[], bool] | None = None
        self._crossfire_nmt = cf.NmtState.PRE_OPERATIONAL
        self._crossfire_state: bool | None = None
        self._next_sync: float | None = None
        self._next_heartbeat = 0.0
        self._booted = False

    # --- set-up ----------------------------------------------------------------------------------

    def attach(
        self,
        client: Any,
        body_id: int,
        joint_indices: Sequence[int],
        crossfire: Callable[[], bool] | None = None,
    ) -> None:
        """Bind drives 1..6 to the joints of a pybullet body.

        Args:
            client: the ``pybullet`` module or a ``BulletClient`` (``getJointState``,
                ``setJointMotorControl2``, ``POSITION_CONTROL`` are used).
            body_id: the robot body.
            joint_indices: pybullet joint indices of joints 1..6, length 6.
            crossfire: optional function returning True while the cup's light beam is interrupted.

        Raises:
            ValueError: not six joints.
        """
        if len(joint_indices) != 6:
            raise ValueError(f"expected 6 joint indices, got {len(joint_indices)}")
        self._client = client
        self._body = body_id
        self._drives = []
        for node, joint in zip(cf.DRIVE_IDS, joint_indices):
            q = float(client.getJointState(body_id, joint)[0])
            self._drives.append(_Drive(node=node, joint=joint, start=q, end=q, hold=q))
        if crossfire is not None:
            self._crossfire = crossfire
        for d in self._drives:
            self._command(d, d.hold, 0.0)

    def reset_hold(self) -> None:
        """Take the joints' present positions as where every drive holds or starts interpolating
        (call after teleporting the robot with ``resetJointState``)."""
        for d, q in zip(self._drives, self.positions()):
            d.hold = d.start = d.end = q
            d.pending = None
            d.commanded = None
            if d.sm.state is not cf.DriveState.OPERATION_ENABLED:
                self._command(d, q, 0.0)

    def set_crossfire(self, crossfire: Callable[[], bool]) -> None:
        """Give the function that reads the crossfire sensor (True = beam interrupted)."""
        self._crossfire = crossfire

    # --- inspection (for tests and the world) ----------------------------------------------------

    def states(self) -> list[cf.DriveState]:
        """CiA 402 state of drives 1..6."""
        return [d.sm.state for d in self._drives]

    def fault_reasons(self) -> list[str]:
        """Fault reason of drives 1..6 (empty strings when not faulted)."""
        return [d.sm.fault_reason for d in self._drives]

    def positions(self) -> list[float]:
        """Actual joint positions, rad."""
        states = self._client.getJointStates(self._body, [d.joint for d in self._drives])
        return [float(s[0]) for s in states]

    def velocities(self) -> list[float]:
        """Actual joint velocities, rad/s."""
        states = self._client.getJointStates(self._body, [d.joint for d in self._drives])
        return [float(s[1]) for s in states]

    # --- the 1 ms tick ---------------------------------------------------------------------------

    def step(self, t: float) -> None:
        """Advance the bus devices to simulated time ``t`` (s); call every 1 ms, before stepping
        the physics. Handles received frames, SYNC (every 2 ms), PDOs, heartbeats, interpolation,
        the watchdogs, following-error supervision, fault reactions and the crossfire module."""
        if self._client is None:
            return
        if not self._booted:
            self._booted = True
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, cf.NmtState.BOOT_UP, t))
            self.bus.transmit(cf.encode_heartbeat(cf.CROSSFIRE_ID, cf.NmtState.BOOT_UP, t))
            self._next_sync = t
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
        for frame in self.bus.take_inbound():
            self._receive(frame, t)
        assert self._next_sync is not None
        if t >= self._next_sync - 1e-9:
            self._next_sync += cf.CYCLE_S
            if t > self._next_sync:  # the caller skipped cycles: resynchronise
                self._next_sync = t + cf.CYCLE_S
            if self.master_wait_s > 0:
                self._await_master(t)
            self._sync(t, self.positions())
        if t >= self._next_heartbeat - 1e-9:
            self._next_heartbeat = t + cf.HEARTBEAT_PERIOD_S
            for d in self._drives:
                self.bus.transmit(cf.encode_heartbeat(d.node, d.nmt, t))
            self.bus.transmit(cf.encode_heartbeat(cf.CROSSFIRE_ID, self._crossfire_nmt, t))
        if self._master_heartbeat is not None and t - self._master_heartbeat > self.consumer_heartbeat_s:
            silent = t - self._master_heartbeat
            self._master_heartbeat = None  # monitoring starts again with the next heartbeat
            for d in self._drives:
                if self._enabled(d):
                    self._fault(d, t, cf.EmcyCode.HEARTBEAT_LOST,
                                f"no heartbeat from the master for {silent:.3f} s")
        states = self._client.getJointStates(self._body, [d.joint for d in self._drives])
        for d, st in zip(self._drives, states):
            self._drive_tick(d, float(st[0]), float(st[1]), t)
        if self._crossfire is not None and self._crossfire_nmt is cf.NmtState.OPERATIONAL:
            blocked = bool(self._crossfire())
            if blocked != self._crossfire_state:
                self._crossfire_state = blocked
                self.bus.transmit(cf.encode_crossfire(blocked, t))

    @staticmethod
    def _enabled(d: _Drive) -> bool:
        return d.nmt is cf.NmtState.OPERATIONAL and d.sm.state is cf.DriveState.OPERATION_ENABLED

    def _await_master(self, t: float) -> None:
        """Wait (wall clock, bounded) for the master's targets (see the class docstring)."""
        now = time.monotonic()
        last, self._last_sync_wall = self._last_sync_wall, now
        waiting = [d for d in self._drives if self._enabled(d) and d.pending is None]
        if not waiting:
            return
        if self._master_in_step:
            self.master_waits += 1
            deadline = now + self.master_wait_s
        elif last is not None:
            deadline = last + cf.CYCLE_S  # real-time pace while the master is silent
        else:
            return
        while any(d.pending is None and self._enabled(d) for d in waiting):
            left = deadline - time.monotonic()
            if left <= 0:
                if self._master_in_step:
                    self._master_in_step = False
                    self.master_misses += 1
                break
            frame = self.bus.wait_inbound(left)
            if frame is not None:
                self._receive(frame, t)
        self._last_sync_wall = time.monotonic()

    def _receive(self, frame: cf.CanFrame, t: float) -> None:
        if frame.can_id == cf.NMT_ID and len(frame.data) == 2:
            try:
                cmd = cf.NmtCommand(frame.data[0])
            except ValueError:
                return
            node = frame.data[1]
            new = {
                cf.NmtCommand.START: cf.NmtState.OPERATIONAL,
                cf.NmtCommand.STOP: cf.NmtState.STOPPED,
                cf.NmtCommand.PRE_OPERATIONAL: cf.NmtState.PRE_OPERATIONAL,
                cf.NmtCommand.RESET_NODE: cf.NmtState.PRE_OPERATIONAL,
            }[cmd]
            for d in self._drives:
                if node in (0, d.node):
                    d.nmt = new
                    if new is not cf.NmtState.OPERATIONAL and not d.sm.faulted:
                        d.sm.on_controlword(cf.Controlword.DISABLE_VOLTAGE)
            if node in (0, cf.CROSSFIRE_ID):
                self._crossfire_nmt = new
                if new is cf.NmtState.OPERATIONAL and self._crossfire is not None:
                    self._crossfire_state = bool(self._crossfire())
                    self.bus.transmit(cf.encode_crossfire(self._crossfire_state, t))
            return
        if frame.can_id == cf.HEARTBEAT_BASE + cf.MASTER_ID:
            self._master_heartbeat = t
            return
        node = frame.can_id - cf.RPDO1_BASE
        if 1 <= node <= len(self._drives):
            d = self._drives[node - 1]
            if d.nmt is not cf.NmtState.OPERATIONAL:
                return
            try:
                cw, target = cf.decode_rpdo1(frame.data)
            except cf.FrameError:
                log.warning("drive %d: bad RPDO1 %s", node, frame.data.hex())
                return
            self._master_in_step = True
            before = d.sm.state
            after = d.sm.on_controlword(cw)
            if before is cf.DriveState.FAULT and after is not before:
                self.bus.transmit(cf.encode_emcy(d.node, cf.EmcyCode.NO_ERROR, 0, t))
            if after is cf.DriveState.OPERATION_ENABLED and before is not after:
                # Bumpless start: interpolate from where the joint is.
                q = float(self._client.getJointState(self._body, d.joint)[0])
                d.start = d.end = q
                d.missed = 0
            if after is cf.DriveState.OPERATION_ENABLED:
                j = node - 1
                d.pending = min(max(target, self.q_min[j]), self.q_max[j])

    def _sync(self, t: float, actual: list[float]) -> None:
        self.bus.transmit(cf.CanFrame(cf.SYNC_ID, b"", t))
        for d, q in zip(self._drives, actual):
            if d.sm.state is cf.DriveState.OPERATION_ENABLED:
                start = self._demand(d, t)
                if d.pending is not None:
                    end = d.pending
                    d.pending = None
                    d.missed = 0
                else:
                    d.missed += 1
                    if d.missed > self.target_timeout_cycles:
                        self._fault(d, t, cf.EmcyCode.RPDO_TIMEOUT,
                                    f"no target from the master for {d.missed} cycles "
                                    f"({d.missed * cf.CYCLE_S * 1000:.0f} ms)")
                    j = d.node - 1
                    # CSP extrapolation: keep the last demand velocity, within the joint limits
                    end = min(max(start + (d.end - d.start), self.q_min[j]), self.q_max[j])
                d.start, d.end, d.t_latch = start, end, t
            if d.nmt is cf.NmtState.OPERATIONAL:
                self.bus.transmit(cf.encode_tpdo1(d.node, d.sm.statusword, q, t))

    @staticmethod
    def _demand(d: _Drive, t: float) -> float:
        s = min(max((t - d.t_latch) / cf.CYCLE_S, 0.0), 1.0)
        return d.start + (d.end - d.start) * s

    def _fault(self, d: _Drive, t: float, code: cf.EmcyCode, reason: str) -> None:
        """Start the fault reaction of drive ``d``: quick-stop ramp from the joint's present state."""
        if d.sm.faulted:
            return
        q, v = self._client.getJointState(self._body, d.joint)[:2]
        d.ramp_q, d.ramp_v, d.t_tick = float(q), float(v), t
        d.pending = None
        text = f"{code.text}: {reason} at t={t:.3f} s"
        d.sm.start_fault_reaction(text, code)
        self.faults.append(FaultRecord(t, d.node, code, text, abs(float(v))))
        log.warning("drive %d: %s", d.node, text)
        self.bus.transmit(cf.encode_emcy(d.node, code, 0x01, t))

    def _drive_tick(self, d: _Drive, q: float, qd: float, t: float) -> None:
        if d.sm.state is cf.DriveState.OPERATION_ENABLED:
            demand = self._demand(d, t)
            if abs(demand - q) > FOLLOWING_ERROR_LIMIT:
                self._fault(d, t, cf.EmcyCode.FOLLOWING_ERROR, f"{demand - q:+.3f} rad")
                self._ramp(d, t)
                return
            d.hold = demand
            self._command(d, demand, (d.end - d.start) / cf.CYCLE_S)
        elif d.sm.state is cf.DriveState.FAULT_REACTION_ACTIVE:
            self._ramp(d, t)
        else:
            self._command(d, d.hold, 0.0)

    def _ramp(self, d: _Drive, t: float) -> None:
        """One tick of the quick-stop ramp; at rest the drive enters FAULT and holds there."""
        j = d.node - 1
        dt = max(t - d.t_tick, 0.0)
        d.t_tick = t
        v = d.ramp_v
        v -= math.copysign(min(abs(v), self.qdd_max[j] * dt), v)
        d.ramp_q = min(max(d.ramp_q + v * dt, self.q_min[j]), self.q_max[j])
        d.ramp_v = v
        if v == 0.0:
            d.sm.reaction_done()
            d.hold = d.ramp_q
            for k in range(len(self.faults) - 1, -1, -1):
                f = self.faults[k]
                if f.node == d.node and math.isnan(f.t_stopped):
                    self.faults[k] = FaultRecord(f.t, f.node, f.code, f.reason, f.speed, t)
                    break
            self._command(d, d.hold, 0.0)
            return
        self._command(d, d.ramp_q, v)

    def _command(self, d: _Drive, position: float, velocity: float) -> None:
        if d.commanded == (position, velocity):
            return  # the motor keeps its last set point
        d.commanded = (position, velocity)
        j = d.node - 1
        self._client.setJointMotorControl2(
            self._body,
            d.joint,
            self._client.POSITION_CONTROL,
            targetPosition=position,
            targetVelocity=velocity,
            positionGain=0.5,
            velocityGain=1.0,
            maxVelocity=self.qd_max[j] * 1.2,
            force=self.tau_max[j],
        )


class CanGateway:
    """socketcand-protocol TCP server bridging a :class:`SimBus` to other processes.

    Implements the subset python-can's ``socketcand`` client uses (``open``, ``rawmode``,
    ``send``, plus ``echo``). Bus frames are forwarded once the connection is in raw mode and the
    client has sent its first frame, or :data:`_RAW_SETTLE_S` after raw mode at the latest
    (python-can reads the ``< ok >`` of ``rawmode`` with a single ``recv`` and compares it exactly,
    so nothing may follow it in the same segment).

    Args:
        bus: the simulated bus.
        host: listen address (loopback only by default).
        port: TCP port, 0 for any free port.
        channels: bus names served.
    """

    def __init__(
        self, bus: SimBus, host: str = "127.0.0.1", port: int = 0, channels: Sequence[str] = ("can0",)
    ) -> None:
        self.bus = bus
        self.host = host
        self.port = port
        self.channels = tuple(channels)
        self._server: socket.socket | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: list[socket.socket] = []
        self._lock = threading.Lock()

    def start(self) -> int:
        """Start listening; returns the TCP port."""
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((self.host, self.port))
        srv.listen(8)
        srv.settimeout(0.1)
        self._server = srv
        self.port = srv.getsockname()[1]
        th = threading.Thread(target=self._accept_loop, name="can-gateway-accept", daemon=True)
        th.start()
        self._threads.append(th)
        return self.port

    def stop(self) -> None:
        """Close the server and every connection; join the threads (bounded)."""
        self._stop.set()
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        if self._server is not None:
            self._server.close()
        for th in self._threads:
            th.join(timeout=2.0)

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _accept_loop(self) -> None:
        assert self._server is not None
        while not self._stop.is_set():
            try:
                conn, addr = self._server.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                if self._stop.is_set() or self._server.fileno() < 0:
                    return  # closed by stop()
                log.warning("CAN gateway: accept failed: %s", exc)  # out of descriptors...: try again
                self._stop.wait(0.1)
                continue
            try:
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                conn.settimeout(None)
            except OSError:  # the peer is already gone
                conn.close()
                continue
            with self._lock:
                self._conns.append(conn)
            _Connection(self, conn, f"{addr[0]}:{addr[1]}").start()


class _Connection:
    """One client of the gateway: a reader and a writer thread around the sans-IO protocol.

    A peer may leave at any moment (a port probe connects and closes at once): every send and
    receive error ends this connection only, never the gateway.
    """

    def __init__(self, gateway: CanGateway, sock: socket.socket, peer: str) -> None:
        self.gw = gateway
        self.sock = sock
        self.peer = peer
        self.proto = socketcand.SocketcandServerProtocol(gateway.channels)
        self.port = gateway.bus.connect()
        self.lock = threading.Lock()
        self.raw_since: float | None = None
        self.forwarding = False
        self.done = threading.Event()

    def start(self) -> None:
        if not self._flush():  # the greeting, before any thread may close the socket
            return
        for target, name in ((self._reader, "reader"), (self._writer, "writer")):
            th = threading.Thread(target=target, name=f"can-gateway-{name}", daemon=True)
            th.start()
            self.gw._threads.append(th)

    def _flush(self) -> bool:
        """Send what the protocol has queued; False (and the connection closed) if the peer is gone."""
        try:
            with self.lock:
                out = self.proto.data_to_send()
                if out:
                    self.sock.sendall(out)
            return True
        except OSError as exc:
            log.debug("CAN gateway: %s left: %s", self.peer, exc)
            self._close()
            return False

    def _reader(self) -> None:
        try:
            while not self.done.is_set():
                data = self.sock.recv(4096)
                if not data:
                    break
                with self.lock:
                    frames = self.proto.receive_data(data, time.monotonic())
                    if self.proto.mode is socketcand.ServerMode.RAW and self.raw_since is None:
                        self.raw_since = time.monotonic()
                if not self._flush():
                    return
                if frames:
                    self.forwarding = self.raw_since is not None
                for f in frames:
                    self.port.send(f)
                if self.proto.mode is socketcand.ServerMode.CLOSED:
                    break
        except OSError:
            pass
        finally:
            self._close()

    def _writer(self) -> None:
        while not self.done.is_set():
            first = self.port.recv(timeout=0.1)
            if first is None:
                continue
            frames = [first] + self.port.recv_all()
            if not self.forwarding:
                if self.raw_since is None or time.monotonic() - self.raw_since < _RAW_SETTLE_S:
                    continue
                self.forwarding = True
            with self.lock:
                for f in frames:
                    self.proto.frame_out(f)
            if not self._flush():
                return

    def _close(self) -> None:
        with self.lock:
            if self.done.is_set():
                return
            self.done.set()
        self.port.close()
        try:
            self.sock.close()
        except OSError:
            pass
        with self.gw._lock:
            if self.sock in self.gw._conns:
                self.gw._conns.remove(self.sock)
