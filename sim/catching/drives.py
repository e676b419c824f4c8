"""The PUMA's six joint drives and its crossfire I/O module on the simulated CAN bus (paper section 6).

Each joint drive is a CANopen slave made from ``devices/puma_joint_drive.eds`` (node ids 1..6), the
crossfire module one made from ``devices/crossfire_io.eds`` (node 0x10); what every simulated device
does (boot-up, NMT, SDO, PDOs from its object dictionary, SYNC, heartbeats, the watchdogs, waiting
for the master): :class:`sim.drives.SimCanDrives`. The bus and its ports are :mod:`sim.canbus`'s, the
gateway that serves it to the motion node is :class:`sim.socketcand.CanGateway`.

Threads: the world calls :meth:`SimDrives.step` from its own (simulation) thread every 1 ms of
simulated time; only that thread touches pybullet.

Drive model (per joint, cyclic synchronous position mode): a target received in an RPDO is latched at
the next SYNC (every 2 ms of simulated time) and interpolated linearly over the cycle; the demand
goes to pybullet's position motor with the joint's speed and torque limits. A missing target is
extrapolated at the last demand velocity for a bounded number of cycles (the RPDO deadline,
0x1400:05), and the master's heartbeat is watched (the consumer heartbeat, 0x1016). If
``|demand - actual|`` exceeds the following error window (0x6065, counts of 1e-5 rad: 0.1 rad by
default), or a watchdog runs out, the drive faults: it brings the joint to rest on a quick-stop ramp
(FAULT REACTION ACTIVE), then holds in FAULT, and says why in an EMCY frame. A drive that is not
enabled holds its position (the PUMA's brakes).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from services.catching.robot import puma560
from services.devices import cia402 as cf
from services.devices.devicefile import PROJECT_DEVICES
from sim.canbus import SimBus
from sim.drives import POSITION_UNIT, VELOCITY_UNIT, FaultRecord, SimCanDrives, SimDrive, SimIoModule

__all__ = ["FOLLOWING_ERROR_LIMIT", "JOINT_EDS", "CROSSFIRE_EDS", "FaultRecord", "SimDrives"]

FOLLOWING_ERROR_LIMIT = 0.1  # rad: the EDS's following error window 0x6065 (10000 counts)
JOINT_EDS = PROJECT_DEVICES / "puma_joint_drive.eds"
"""The object dictionary of the simulated joint drives."""
CROSSFIRE_EDS = PROJECT_DEVICES / "crossfire_io.eds"
"""The object dictionary of the simulated crossfire module."""


@dataclass(kw_only=True, eq=False)
class _Drive(SimDrive):
    joint: int
    pending: float | None = None
    start: float = 0.0
    end: float = 0.0
    t_latch: float = 0.0
    hold: float = 0.0
    commanded: tuple[float, float] | None = None
    ramp_q: float = 0.0  # fault reaction: demand position, rad
    ramp_v: float = 0.0  # fault reaction: demand velocity, rad/s
    t_tick: float = 0.0  # time of the previous tick, s
    following_limit: float = FOLLOWING_ERROR_LIMIT  # rad, from 0x6065


class SimDrives(SimCanDrives[_Drive]):
    """Six simulated CiA 402 joint drives and the crossfire I/O module on a :class:`SimBus`.

    Lifecycle: construct; :meth:`attach` to the robot body in a pybullet client; give the crossfire
    sensor with :meth:`set_crossfire` (or to ``attach``); serve the bus to other processes with a
    :class:`sim.socketcand.CanGateway` (or use :meth:`SimBus.connect` in process); call :meth:`step` every 1 ms of
    simulated time from the simulation thread.

    Watchdogs (the CiA 301/402 behaviour of a drive whose master goes silent): an enabled drive
    that gets no target at a SYNC keeps its last demand velocity for at most its RPDO deadline
    (0x1400:05 over the 2 ms cycle: 25 cycles by default), then faults (EMCY 0x8250, RPDO timeout);
    once the master's heartbeat has been seen, an enabled drive that hears none for its consumer
    heartbeat time (0x1016: 0.35 s by default) faults too (EMCY 0x8130). A fault, including a
    following error, starts the fault reaction: the joint's demand goes from where the joint is, at
    its speed, to rest at the quick-stop deceleration ``qdd_max``; then the drive is in FAULT and
    holds. Every fault is kept in :attr:`faults` (bus time, node, code, reason, when the joint was at
    rest again).

    Pacing (``master_wait_s`` > 0, :class:`sim.drives.SimCanDrives`): the sim waits at each SYNC for
    the targets of a master that answered the previous one; once a wait has run out, only until
    one cycle (2 ms) of wall time has passed since the previous SYNC, so that the bus runs no
    faster than real time while the master is silent and the RPDO timeout (50 ms of bus time) is
    at least 50 ms of wall time too. A master that answers is in step again.

    Args:
        bus: the bus to sit on (a new one if ``None``).
        qd_max, tau_max: per-joint speed (rad/s) and torque (N m) limits of the motors, shape (6,).
        q_min, q_max: joint limits (rad) targets are clamped to, shape (6,).
        qdd_max: quick-stop deceleration of the fault reaction, rad/s², shape (6,).
        master_wait_s: wall time waited at a SYNC for the master's targets (0: never wait).
        sync_producer: the world produces SYNC (default); ``False``: the master does.
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
        master_wait_s: float = 0.0,
        sync_producer: bool = True,
    ) -> None:
        super().__init__(bus, cycle_s=cf.CYCLE_S, master_wait_s=master_wait_s, silent_pace_s=cf.CYCLE_S,
                         kind="drive", sync_producer=sync_producer)
        self.qd_max = [float(v) for v in qd_max]
        self.tau_max = [float(v) for v in tau_max]
        self.q_min = [float(v) for v in q_min]
        self.q_max = [float(v) for v in q_max]
        self.qdd_max = [float(v) for v in qdd_max]
        self._client: Any = None
        self._body = -1
        self._crossfire: Callable[[], bool] | None = None
        self.add_module(SimIoModule(cf.CROSSFIRE_ID, self._read_crossfire), CROSSFIRE_EDS)

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
        if self._drives:
            raise ValueError("the drives are attached already")
        self._client = client
        self._body = body_id
        for node, joint in zip(cf.DRIVE_IDS, joint_indices):
            q = float(client.getJointState(body_id, joint)[0])
            self.add_drive(_Drive(node=node, joint=joint, start=q, end=q, hold=q), JOINT_EDS)
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
        super().step(t)

    def _read_crossfire(self) -> int:
        return 1 if self._crossfire is not None and self._crossfire() else 0

    def configured(self, d: _Drive) -> None:
        if d.has(0x6065):
            d.following_limit = d.raw(0x6065) * POSITION_UNIT

    def take_target(self, d: _Drive, before: cf.DriveState, after: cf.DriveState, values: dict[int, int],
                    t: float) -> None:
        self.master_answered()
        if after is cf.DriveState.OPERATION_ENABLED and before is not after:
            # Bumpless start: interpolate from where the joint is.
            q = float(self._client.getJointState(self._body, d.joint)[0])
            d.start = d.end = q
            d.missed = 0
        if after is cf.DriveState.OPERATION_ENABLED and 0x607A in values:
            j = d.node - 1
            d.pending = min(max(values[0x607A] * POSITION_UNIT, self.q_min[j]), self.q_max[j])

    def has_target(self, d: _Drive) -> bool:
        return d.pending is not None

    def on_sync(self, t: float) -> None:
        for d in self._drives:
            if d.sm.state is cf.DriveState.OPERATION_ENABLED:
                start = self._demand(d, t)
                if d.pending is not None:
                    end = d.pending
                    d.pending = None
                    self.count_target(d, True, t)
                else:
                    self.count_target(d, False, t)
                    j = d.node - 1
                    # CSP extrapolation: keep the last demand velocity, within the joint limits
                    end = min(max(start + (d.end - d.start), self.q_min[j]), self.q_max[j])
                d.start, d.end, d.t_latch = start, end, t

    def actual_values(self) -> list[dict[int, int]]:
        states = self._client.getJointStates(self._body, [d.joint for d in self._drives])
        out = []
        for d, st in zip(self._drives, states):
            q, qd = float(st[0]), float(st[1])
            tau = float(st[3])
            rated = 100.0  # N m: 0x6076 = 100000 mN m
            out.append({0x6064: round(q / POSITION_UNIT), 0x606C: round(qd / VELOCITY_UNIT),
                        0x6062: round(d.hold / POSITION_UNIT),
                        0x606B: round((d.end - d.start) / cf.CYCLE_S / VELOCITY_UNIT),
                        0x6077: max(-32768, min(32767, round(1000.0 * tau / rated)))})
        return out

    def tick(self, t: float) -> None:
        states = self._client.getJointStates(self._body, [d.joint for d in self._drives])
        for d, st in zip(self._drives, states):
            self._drive_tick(d, float(st[0]), float(st[1]), t)

    @staticmethod
    def _demand(d: _Drive, t: float) -> float:
        s = min(max((t - d.t_latch) / cf.CYCLE_S, 0.0), 1.0)
        return d.start + (d.end - d.start) * s

    def start_fault_reaction(self, d: _Drive, t: float) -> float:
        """Quick-stop ramp from the joint's present state."""
        q, v = self._client.getJointState(self._body, d.joint)[:2]
        d.ramp_q, d.ramp_v, d.t_tick = float(q), float(v), t
        d.pending = None
        return abs(float(v))

    def _drive_tick(self, d: _Drive, q: float, qd: float, t: float) -> None:
        if d.sm.state is cf.DriveState.OPERATION_ENABLED:
            demand = self._demand(d, t)
            if abs(demand - q) > d.following_limit:
                self.fault(d, t, cf.EmcyCode.FOLLOWING_ERROR, f"{demand - q:+.3f} rad")
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
            self.at_rest(d, t)
            d.hold = d.ramp_q
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
