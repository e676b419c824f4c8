"""The master of CiA 402 drives on a CAN bus, as a node's driver sees them (position or velocity mode).

The framework's generic device link to drives: a testbed's driver says which node ids its drives
and I/O modules have (the PUMA's six joint drives and its crossfire module:
:class:`services.catching.drives.PumaDrives`; the mobile robot's two wheel drives in profile
velocity mode: :class:`VelocityCanDrives` with the wheels' ids), and the master does the rest. A
real bus or another CAN stack replaces this module, not the testbeds' drivers.

Talks to the bus through python-can's ``socketcand`` interface (the sim's gateway in
:class:`sim.socketcand.CanGateway`, or any socketcand server); on real hardware the same frames would go through
``interface="socketcan"``. Frame layout and units: :mod:`services.devices.cia402`.

A receive thread keeps the latest actual positions and statuswords (TPDO1), heartbeat times,
the drives' emergency messages (EMCY), the I/O modules' reports (handed to :meth:`CanDrives.on_io`
callbacks) and the latest SYNC; :meth:`CanDrives.wait_sync` lets a control loop run once per bus
cycle. Supervision, on
two clocks: a node whose latest heartbeat is older than ``heartbeat_timeout`` seconds of *bus* time
(the time the SYNCs carry: a node gone silent on a live bus), a bus on which nothing at all arrived
for ``silence_timeout`` seconds of *wall* time (the bus, or the simulation behind it, stopped), or a
closed connection, makes :meth:`CanDrives.check` raise :class:`BusError`; so does a drive in
FAULT, naming the cause its EMCY gave. (A simulation slowed down by a loaded machine delivers its
heartbeats further apart in wall time without anything being lost; judged on the wall clock alone,
0.5 s, that stall failed catches of the demo.) The master produces its own heartbeat (node
:data:`services.devices.cia402.MASTER_ID`, every 100 ms of bus time while it sends targets), which
the drives consume. :meth:`CanDrives.enable` is also the CiA 402 fault recovery: it waits out a
running fault reaction, resets the fault (controlword 0x00, then the rising edge 0x80) and walks
every drive to OPERATION_ENABLED again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Self

import can
import numpy as np
from numpy.typing import NDArray

from services.devices import cia402 as cf
from services.errors import ActionError

__all__ = ["BusError", "CanDrives", "IoCallback", "VelocityCanDrives"]

# python-can's socketcand client logs every TCP read that splits a frame message as a warning;
# that is ordinary stream fragmentation, not a fault.
logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)


class BusError(ActionError):
    """The CAN bus or a drive is unusable: connection lost, heartbeat missing, drive fault."""


IoCallback = Callable[[bytes, float], None]
"""Called from the receive thread with an I/O module's TPDO1 data and its bus time, s."""


class CanDrives:
    """CiA 402 drives in cyclic synchronous position mode as seen from a node (the master).

    Lifecycle: ``CanDrives(host, port, nodes=...)`` only configures; :meth:`open` connects (or use it
    as a context manager); :meth:`enable` brings every drive to OPERATION_ENABLED;
    :meth:`send_targets` once per cycle; :meth:`close` disables and disconnects.

    Args:
        host, port: the socketcand server (the sim's CAN gateway).
        channel: bus name on the server.
        heartbeat_timeout: seconds of bus time without a heartbeat after which a node counts as lost.
        silence_timeout: seconds of wall time without any frame after which the bus counts as lost.
        clock: monotonic clock for supervision (seconds).
        nodes: node ids of the drives, 1..n in order.
        io_nodes: node ids of the other modules on the bus (I/O), whose heartbeats are supervised
            too and whose TPDO1 reports go to :meth:`on_io` callbacks.
    """

    def __init__(
        self,
        host: str,
        port: int,
        channel: str = "can0",
        heartbeat_timeout: float = 0.5,
        silence_timeout: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
        *,
        nodes: tuple[int, ...],
        io_nodes: tuple[int, ...] = (),
    ) -> None:
        self.nodes = tuple(nodes)
        self.io_nodes = tuple(io_nodes)
        self.host = host
        self.port = port
        self.channel = channel
        self.heartbeat_timeout = heartbeat_timeout
        self.silence_timeout = silence_timeout
        self._last_rx = 0.0
        self._clock = clock
        self._bus: can.BusABC | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._cond = threading.Condition()
        n = len(self.nodes)
        self._positions = np.full(n, np.nan)
        self._velocities = np.full(n, np.nan)
        self._statuswords = [0] * n
        self._tpdo_seen = [False] * n
        self._heartbeats: dict[int, tuple[float, cf.NmtState]] = {}  # node -> (bus time, state)
        self._sync_count = 0
        self._sync_returned = 0
        self._sync_t = float("nan")
        self._io: dict[int, list[IoCallback]] = {node: [] for node in self.io_nodes}
        self._emcy: dict[int, tuple[int, float]] = {}
        self._expect_enabled = False
        self._heartbeat_sent_t = -float("inf")
        self._dead: str | None = None
        self._opened_at = 0.0
        self._send_lock = threading.Lock()

    # --- connection ------------------------------------------------------------------------------

    def open(self, timeout: float = 5.0) -> Self:
        """Connect to the bus and start the receive thread.

        Raises:
            BusError: the server cannot be reached or refuses the bus within ``timeout``.
        """
        try:
            self._bus = _connect(self.host, self.port, self.channel, timeout)
        except (OSError, can.CanError, TimeoutError, BusError) as exc:
            raise BusError(f"cannot open CAN bus {self.channel} at {self.host}:{self.port}: {exc}") from exc
        self._opened_at = self._last_rx = self._clock()
        self._stop.clear()
        self._thread = threading.Thread(target=self._rx_loop, name="puma-drives-rx", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Disable the drives (best effort) and disconnect."""
        if self._bus is None:
            return
        self._expect_enabled = False
        try:
            if self._dead is None:
                for node in self.nodes:
                    self._send(self._hold_rpdo(node, cf.Controlword.DISABLE_VOLTAGE))
        except BusError:
            pass
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._bus.shutdown()
        self._bus = None

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- state -----------------------------------------------------------------------------------

    def positions(self) -> NDArray[np.float64]:
        """Latest actual positions of the drives, shape (n,), rad (NaN until a drive reported)."""
        with self._cond:
            return self._positions.copy()

    def states(self) -> list[cf.DriveState | None]:
        """Latest CiA 402 state of drives 1..n (``None`` until reported or not understood)."""
        with self._cond:
            return self._states_locked()

    @property
    def sim_time(self) -> float:
        """Bus time (s) stamped on the latest SYNC."""
        return self._sync_t

    def on_io(self, node: int, callback: IoCallback) -> None:
        """Call ``callback(data, t)`` from the receive thread on every TPDO1 of I/O module ``node``.

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
            beats = dict(self._heartbeats)
            bus_now = self._sync_t
            silent = now - self._last_rx
        if silent > self.silence_timeout:
            return f"nothing on the CAN bus for {silent:.2f} s (no SYNC, no heartbeats): bus lost"
        for node in (*self.nodes, *self.io_nodes):
            seen = beats.get(node)
            if seen is None:
                if now - self._opened_at > self.silence_timeout:
                    return f"no heartbeat from CAN node {node} since the bus was opened: node lost"
            elif bus_now - seen[0] > self.heartbeat_timeout:
                return (f"no heartbeat from CAN node {node} for {bus_now - seen[0]:.2f} s of bus time: "
                        "node lost")
        return None

    def check(self) -> None:
        """Raise :class:`BusError` if the bus is lost, a heartbeat is missing, a drive faulted, or
        (after :meth:`enable`) a drive is no longer operation enabled; the message says which."""
        lost = self.lost()
        if lost is not None:
            raise BusError(lost)
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

    # --- commands --------------------------------------------------------------------------------

    def start(self, timeout: float = 3.0) -> None:
        """NMT-start every node, send the master's heartbeat, and wait until every drive has
        reported (TPDO1: its position and state) and no fault reaction is running any more.

        After it, :meth:`positions` are the joints' resting positions: a control loop can start
        from them (and send targets) before :meth:`enable`.

        Raises:
            BusError: not within ``timeout`` s, or the bus is lost.
        """
        self._send(cf.nmt_frame(cf.NmtCommand.START, 0))
        deadline = self._clock() + timeout
        self._wait(lambda: all(self._tpdo_seen), deadline, "no TPDO1 from every drive after NMT start")
        self._send_heartbeat()
        self._wait(lambda: not any(s is cf.DriveState.FAULT_REACTION_ACTIVE for s in self._states_locked()),
                   deadline, "a drive's fault reaction did not end")

    def enable(self, timeout: float = 3.0) -> None:
        """:meth:`start`, then recover faulted drives and walk every drive to OPERATION_ENABLED.

        The CiA 402 recovery of a faulted drive: wait until its fault reaction has brought the
        joint to rest (FAULT), send controlword 0x00 so that bit 7 is low, then the fault reset
        0x80 (the rising edge), then shutdown, switch on, enable operation, each checked on the
        statuswords. Each RPDO carries the drive's own actual position as target, so enabling
        does not move the arm. A control loop may run meanwhile, sending enable-operation RPDOs
        with targets at the resting positions (the motion node's does, so that cyclic targets flow
        from the first enabled cycle on): a drive it enables from SWITCHED_ON counts as switched on.

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
            for node in self.nodes:
                self._send(self._hold_rpdo(node, cw))
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
        for node in self.nodes:
            self._send(self._hold_rpdo(node, cf.Controlword.DISABLE_VOLTAGE))

    def send_targets(self, q: Sequence[float] | NDArray[np.float64]) -> None:
        """Send one RPDO1 per drive: enable-operation controlword and target, rad, shape (n,).

        Raises:
            BusError: the connection is lost.
            ValueError: not one target per drive.
        """
        if len(q) != len(self.nodes):
            raise ValueError(f"expected {len(self.nodes)} joint targets, got {len(q)}")
        for node, target in zip(self.nodes, q):
            self._send(cf.encode_rpdo1(node, cf.Controlword.ENABLE_OPERATION, float(target)))
        if self._sync_t - self._heartbeat_sent_t >= cf.HEARTBEAT_PERIOD_S - 1e-9:
            self._send_heartbeat()

    def wait_sync(self, timeout: float = 0.1) -> float:
        """Block until a SYNC newer than the one the previous call returned; returns its bus time, s.

        A SYNC that arrived since the previous call is returned at once (a control loop answers
        every SYNC, never skips one it has not answered yet); several that arrived meanwhile count
        as one, the latest.

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

    def _send_heartbeat(self) -> None:
        """The master's heartbeat (NMT state operational), stamped with the bus time."""
        t = self._sync_t
        self._heartbeat_sent_t = -float("inf") if np.isnan(t) else t
        self._send(cf.encode_heartbeat(cf.MASTER_ID, cf.NmtState.OPERATIONAL))

    def _states_locked(self) -> list[cf.DriveState | None]:
        out: list[cf.DriveState | None] = []
        for seen, sw in zip(self._tpdo_seen, self._statuswords):
            try:
                out.append(cf.state_from_statusword(sw) if seen else None)
            except cf.FrameError:
                out.append(None)
        return out

    def _hold_rpdo(self, node: int, cw: int) -> cf.CanFrame:
        """An RPDO1 carrying controlword ``cw`` and a target that does not move the drive (its own
        actual position; a velocity-mode master sends zero velocity)."""
        return cf.encode_rpdo1(node, cw, self._pos_or0(node))

    def _pos_or0(self, node: int) -> float:
        q = float(self._positions[node - 1])
        return 0.0 if np.isnan(q) else q

    def _send(self, frame: cf.CanFrame) -> None:
        if self._bus is None:
            raise BusError("CAN bus not open")
        if self._dead is not None:
            raise BusError(self._dead)
        msg = can.Message(arbitration_id=frame.can_id, data=frame.data, is_extended_id=False)
        try:
            with self._send_lock:
                self._bus.send(msg)
        except (OSError, can.CanError) as exc:
            self._dead = f"CAN bus connection lost while sending: {exc}"
            raise BusError(self._dead) from exc

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
        emcy = self._emcy.get(node)
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

    def _rx_loop(self) -> None:
        assert self._bus is not None
        bus = self._bus
        while not self._stop.is_set():
            try:
                msg = bus.recv(timeout=0.05)
            except (OSError, can.CanError, ValueError) as exc:
                self._mark_dead(f"CAN bus connection lost: {exc}")
                return
            if msg is None or msg.is_error_frame:
                continue
            try:
                self._handle(cf.CanFrame(msg.arbitration_id, bytes(msg.data), float(msg.timestamp)))
            except cf.FrameError:
                continue

    def _mark_dead(self, reason: str) -> None:
        with self._cond:
            if self._dead is None:
                self._dead = reason
            self._cond.notify_all()

    def _handle(self, frame: cf.CanFrame) -> None:
        cid = frame.can_id
        callbacks: list[IoCallback] = []
        self._last_rx = self._clock()
        with self._cond:
            if cid == cf.SYNC_ID:
                self._sync_count += 1
                self._sync_t = frame.t
            elif cf.TPDO1_BASE + 1 <= cid <= cf.TPDO1_BASE + len(self.nodes):
                i = cid - cf.TPDO1_BASE - 1
                sw, q = cf.decode_tpdo1(frame.data)
                self._statuswords[i] = sw
                self._positions[i] = q
                self._tpdo_seen[i] = True
            elif cf.TPDO2_BASE + 1 <= cid <= cf.TPDO2_BASE + len(self.nodes):
                self._velocities[cid - cf.TPDO2_BASE - 1] = cf.decode_tpdo2(frame.data)[0]
            elif cid - cf.TPDO1_BASE in self._io:
                callbacks = list(self._io[cid - cf.TPDO1_BASE])
            elif cf.EMCY_BASE + 1 <= cid <= cf.EMCY_BASE + 0x7F:
                code, _register = cf.decode_emcy(frame.data)
                self._emcy[cid - cf.EMCY_BASE] = (code, frame.t)
            elif cf.HEARTBEAT_BASE <= cid <= cf.HEARTBEAT_BASE + 0x7F:
                self._heartbeats[cid - cf.HEARTBEAT_BASE] = (frame.t, cf.decode_heartbeat(frame.data))
            else:
                return
            self._cond.notify_all()
        for cb in callbacks:
            cb(frame.data, frame.t)


def _connect(host: str, port: int, channel: str, timeout: float) -> can.BusABC:
    """Open python-can's socketcand bus, failing fast when nothing listens.

    python-can retries a refused connection for 10 s; probe the port first so that a missing
    gateway is reported within ``timeout``.
    """
    import socket

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
    return can.Bus(interface="socketcand", host=host, port=port, channel=channel, tcp_tune=True)


class VelocityCanDrives(CanDrives):
    """CiA 402 drives in profile velocity mode (the mobile robot's wheels, node 1 left, node 2
    right): the same master (connection, supervision, NMT start, fault recovery by :meth:`enable`,
    the master's heartbeat, :meth:`wait_sync`) with velocity RPDOs.

    Frames: :mod:`services.devices.cia402` (RPDO1 = controlword + target velocity 0x60FF; TPDO1 =
    statusword + position actual 0x6064; TPDO2 = velocity actual 0x606C).
    """

    def _hold_rpdo(self, node: int, cw: int) -> cf.CanFrame:
        return cf.encode_velocity_rpdo1(node, cw, 0.0)

    def send_velocities(self, *velocities: float) -> None:
        """One RPDO1 per drive, in node order: enable-operation controlword and target velocity,
        rad/s (also the master's heartbeat every 100 ms of bus time).

        Raises:
            BusError: the connection is lost.
            FrameError: a velocity is not finite.
        """
        for node, velocity in zip(self.nodes, velocities, strict=True):
            self._send(cf.encode_velocity_rpdo1(node, cf.Controlword.ENABLE_OPERATION, float(velocity)))
        if self._sync_t - self._heartbeat_sent_t >= cf.HEARTBEAT_PERIOD_S - 1e-9:
            self._send_heartbeat()

    def velocities(self) -> NDArray[np.float64]:
        """Latest velocity actual values (TPDO2) of the drives, in node order, rad/s (NaN before)."""
        with self._cond:
            return self._velocities.copy()
