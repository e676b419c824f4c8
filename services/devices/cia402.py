"""CAN frames of the robot drives (CiA 301/402 style): identifiers, payloads, the drive state machine.

Pure (no sockets, no clocks): the motion node's CAN master (:mod:`services.devices.drives`) encodes and
decodes these frames on a real or simulated bus; the simulated drives (:mod:`sim.drives`) use the
same codec and state machine, so the two can never disagree. Tested without I/O.

Bus layout (11-bit identifiers, CANopen pre-defined connection set):

=========  ==============  ===============================================================
COB-ID     direction       payload
=========  ==============  ===============================================================
0x000      master -> all   NMT: ``[command, node]`` (0x01 start, 0x80 pre-operational,
                           0x81 reset node; node 0 = all)
0x080      sim -> all      SYNC, no data, every 2 ms of simulated time (the sim is the
                           SYNC producer so that its clock paces the bus in both lock-step
                           and real-time modes)
0x200+id   master -> id    RPDO1: controlword uint16 LE, target position int32 LE
0x180+id   id -> master    TPDO1: statusword uint16 LE, actual position int32 LE; sent by
                           each drive right after every SYNC while operational
0x190      crossfire       TPDO1 of the crossfire I/O module (node 0x10): 1 byte, bit 0 =
                           beam interrupted; sent on change and on NMT start
0x700+id   id -> master    heartbeat: 1 byte NMT state (0x00 boot-up, 0x05 operational,
                           0x7F pre-operational), every 100 ms of simulated time
0x77F      master -> all   the master's own heartbeat (node :data:`MASTER_ID`), every 100 ms of
                           bus time while it commands the drives; the drives consume it
0x080+id   id -> master    EMCY (CiA 301 emergency): error code uint16 LE, error register
                           uint8, 5 bytes zero; sent when a drive faults (code 0x0000 when
                           a fault reset clears it)
=========  ==============  ===============================================================

Drive node ids 1..6 are joints 1..6. Positions on the bus are int32 in units of 1e-5 rad
(:data:`POSITION_UNIT`; range +-21474 rad), the drive's user-unit scaling. A target received in an
RPDO is latched at the next SYNC and interpolated linearly over the following 2 ms cycle.

CiA 402 power state machine (minimal subset, statusword values with the "remote" bit clear):
``SWITCH_ON_DISABLED (0x0040) -shutdown 0x06-> READY_TO_SWITCH_ON (0x0021) -switch on 0x07->
SWITCHED_ON (0x0023) -enable operation 0x0F-> OPERATION_ENABLED (0x0027)``; ``disable voltage
(0x00)`` returns to SWITCH_ON_DISABLED. A fault (following error, no target from the master for
:data:`TARGET_TIMEOUT_CYCLES` cycles, the master's heartbeat lost) starts the fault reaction: FAULT
REACTION ACTIVE (0x000F) while the drive brings its joint to rest on a quick-stop ramp, then FAULT
(0x0008), where it holds; the EMCY frame says why (:class:`EmcyCode`). A rising edge of controlword
bit 7 (fault reset, 0x80) leaves FAULT for SWITCH_ON_DISABLED; a reset during the fault reaction is
ignored. A CiA 402 master therefore recovers a faulted drive by waiting for FAULT, then sending
``0x00`` (bit 7 low), ``0x80`` (the edge), and the enable sequence again.

Profile velocity mode (modes of operation 0x6060 = 3; the mobile robot's wheel drives, node ids
1 = left, 2 = right): RPDO1 maps the controlword and the **target velocity** (0x60FF) instead of
a target position, int32 LE in units of :data:`VELOCITY_UNIT` (1e-4 rad/s); TPDO1 keeps the
statusword and the **position actual value** (0x6064, 1e-5 rad); **TPDO2** (0x280+id) carries the
**velocity actual value** (0x606C, int32 LE, 1e-4 rad/s) and the torque actual value (0x6077,
int16 LE, mN m), after every SYNC while operational. A target velocity holds until the next one
(no interpolation); a drive that gets no RPDO for its RPDO timeout faults and brakes the wheel to
rest on its quick-stop ramp (:mod:`sim.mobile.candrives`).

Cyclic synchronous position (CSP) targets: a drive that gets no new target at a SYNC keeps moving
at its last demand velocity (extrapolation), for at most :data:`TARGET_TIMEOUT_CYCLES` cycles in a
row; then it faults with :attr:`EmcyCode.RPDO_TIMEOUT` and stops on the ramp. A master that falls
behind therefore steps its trajectory by the number of cycles that passed (at most that many), so
that its next target continues where the drive's extrapolation has taken the joint.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, field

from services.errors import PetrobotError

__all__ = [
    "CONSUMER_HEARTBEAT_S",
    "CROSSFIRE_ID",
    "CYCLE_S",
    "DRIVE_IDS",
    "EMCY_BASE",
    "HEARTBEAT_BASE",
    "HEARTBEAT_PERIOD_S",
    "MASTER_ID",
    "NMT_ID",
    "POSITION_UNIT",
    "RPDO1_BASE",
    "SYNC_ID",
    "TARGET_TIMEOUT_CYCLES",
    "TPDO1_BASE",
    "TPDO2_BASE",
    "VELOCITY_UNIT",
    "WHEEL_IDS",
    "CanFrame",
    "Cia402StateMachine",
    "Controlword",
    "DriveState",
    "EmcyCode",
    "FrameError",
    "NmtCommand",
    "NmtState",
    "decode_crossfire",
    "decode_emcy",
    "decode_heartbeat",
    "decode_rpdo1",
    "decode_tpdo1",
    "decode_tpdo2",
    "decode_velocity_rpdo1",
    "encode_crossfire",
    "encode_emcy",
    "encode_heartbeat",
    "encode_rpdo1",
    "encode_tpdo1",
    "encode_tpdo2",
    "encode_velocity_rpdo1",
    "nmt_frame",
    "rad_to_units",
    "state_from_statusword",
    "statusword",
    "units_to_rad",
]

NMT_ID = 0x000
SYNC_ID = 0x080
RPDO1_BASE = 0x200
TPDO1_BASE = 0x180
TPDO2_BASE = 0x280
HEARTBEAT_BASE = 0x700
EMCY_BASE = 0x080  # + node id (1..127); 0x080 itself is SYNC
DRIVE_IDS = (1, 2, 3, 4, 5, 6)
CROSSFIRE_ID = 0x10
MASTER_ID = 0x7F
"""Node id of the motion node's CAN master (its heartbeat is 0x77F)."""
POSITION_UNIT = 1e-5  # rad per bus unit
VELOCITY_UNIT = 1e-4  # rad/s per bus unit (profile velocity mode: 0x60FF, 0x606C)
WHEEL_IDS = (1, 2)
"""Node ids of the mobile robot's wheel drives: 1 = left, 2 = right."""
CYCLE_S = 0.002
HEARTBEAT_PERIOD_S = 0.1
TARGET_TIMEOUT_CYCLES = 25
"""SYNC cycles in a row a drive extrapolates a missing target before it faults (50 ms)."""
CONSUMER_HEARTBEAT_S = 0.35
"""Heartbeat consumer time of the drives for the master's heartbeat, s of bus time (CiA 301
object 0x1016: 3.5 periods of the master's 100 ms heartbeat)."""

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


class FrameError(PetrobotError, ValueError):
    """A CAN payload or socketcand message is malformed or out of range."""


class NmtState(enum.IntEnum):
    """NMT state of a node as reported in its heartbeat."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


class NmtCommand(enum.IntEnum):
    """NMT command specifiers (first byte of a frame on COB-ID 0x000)."""

    START = 0x01
    STOP = 0x02
    PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81


class Controlword(enum.IntEnum):
    """CiA 402 controlword commands used here."""

    DISABLE_VOLTAGE = 0x0000
    SHUTDOWN = 0x0006
    SWITCH_ON = 0x0007
    ENABLE_OPERATION = 0x000F
    FAULT_RESET = 0x0080


class DriveState(enum.Enum):
    """CiA 402 power states (minimal subset)."""

    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    FAULT_REACTION_ACTIVE = "fault reaction active"
    FAULT = "fault"


class EmcyCode(enum.IntEnum):
    """Emergency error codes (CiA 301 Table 21, CiA 402 for the drive-specific ones)."""

    NO_ERROR = 0x0000
    """Error reset or no error (sent when a fault reset clears the fault)."""
    HEARTBEAT_LOST = 0x8130
    """Life guard or heartbeat error: the master's heartbeat stopped."""
    RPDO_TIMEOUT = 0x8250
    """RPDO timeout: no target from the master for :data:`TARGET_TIMEOUT_CYCLES` cycles."""
    FOLLOWING_ERROR = 0x8611
    """Following error: the joint is further from the demand than the drive allows."""

    @property
    def text(self) -> str:
        """What the code means, in a few words."""
        return _EMCY_TEXT[self]


_EMCY_TEXT = {
    EmcyCode.NO_ERROR: "no error",
    EmcyCode.HEARTBEAT_LOST: "the master's heartbeat was lost",
    EmcyCode.RPDO_TIMEOUT: "no target from the master (RPDO timeout)",
    EmcyCode.FOLLOWING_ERROR: "following error",
}

_STATUSWORDS = {
    DriveState.SWITCH_ON_DISABLED: 0x0040,
    DriveState.READY_TO_SWITCH_ON: 0x0021,
    DriveState.SWITCHED_ON: 0x0023,
    DriveState.OPERATION_ENABLED: 0x0027,
    DriveState.FAULT_REACTION_ACTIVE: 0x000F,
    DriveState.FAULT: 0x0008,
}
# Masks as in CiA 402: bits 0-3, 5, 6 identify the state.
_STATE_MASK = 0x006F
_FOLLOWING_ERROR_BIT = 0x2000  # statusword bit 13 (in position modes: following error)


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One classic CAN frame.

    Attributes:
        can_id: 11-bit identifier.
        data: 0..8 payload bytes.
        t: timestamp, s (simulated time on the sim side).
    """

    can_id: int
    data: bytes = b""
    t: float = 0.0

    def __post_init__(self) -> None:
        if not 0 <= self.can_id <= 0x7FF:
            raise FrameError(f"CAN id {self.can_id:#x} is not an 11-bit identifier")
        if len(self.data) > 8:
            raise FrameError(f"CAN frame with {len(self.data)} data bytes (max 8)")


def rad_to_units(q: float) -> int:
    """Radians to bus position units (1e-5 rad), rounded.

    Raises:
        FrameError: the value does not fit an int32.
    """
    units = round(q / POSITION_UNIT)
    if not _INT32_MIN <= units <= _INT32_MAX:
        raise FrameError(f"position {q} rad does not fit an int32 of 1e-5 rad")
    return int(units)


def units_to_rad(units: int) -> float:
    """Bus position units (1e-5 rad) to radians."""
    return units * POSITION_UNIT


def encode_rpdo1(node: int, controlword: int, target_rad: float) -> CanFrame:
    """RPDO1 to a drive: controlword (uint16 LE) and target position (int32 LE, 1e-5 rad)."""
    return CanFrame(RPDO1_BASE + node, struct.pack("<Hi", controlword & 0xFFFF, rad_to_units(target_rad)))


def decode_rpdo1(data: bytes) -> tuple[int, float]:
    """Inverse of :func:`encode_rpdo1`: ``(controlword, target_rad)``.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 6:
        raise FrameError(f"RPDO1 needs 6 bytes, got {len(data)}")
    cw, units = struct.unpack("<Hi", data)
    return int(cw), units_to_rad(units)


def encode_tpdo1(node: int, status: int, actual_rad: float, t: float = 0.0) -> CanFrame:
    """TPDO1 from a drive: statusword (uint16 LE) and actual position (int32 LE, 1e-5 rad)."""
    return CanFrame(TPDO1_BASE + node, struct.pack("<Hi", status & 0xFFFF, rad_to_units(actual_rad)), t)


def decode_tpdo1(data: bytes) -> tuple[int, float]:
    """Inverse of :func:`encode_tpdo1`: ``(statusword, actual_rad)``.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 6:
        raise FrameError(f"TPDO1 needs 6 bytes, got {len(data)}")
    sw, units = struct.unpack("<Hi", data)
    return int(sw), units_to_rad(units)


def _velocity_units(v: float) -> int:
    if not math.isfinite(v):
        raise FrameError(f"velocity {v} is not a finite number")
    units = round(v / VELOCITY_UNIT)
    if not _INT32_MIN <= units <= _INT32_MAX:
        raise FrameError(f"velocity {v} rad/s does not fit an int32 of 1e-4 rad/s")
    return int(units)


def encode_velocity_rpdo1(node: int, controlword: int, target_velocity: float) -> CanFrame:
    """RPDO1 of a drive in profile velocity mode: controlword (uint16 LE) and target velocity
    0x60FF (int32 LE, 1e-4 rad/s).

    Raises:
        FrameError: the velocity is not finite or does not fit.
    """
    return CanFrame(RPDO1_BASE + node, struct.pack("<Hi", controlword & 0xFFFF, _velocity_units(target_velocity)))


def decode_velocity_rpdo1(data: bytes) -> tuple[int, float]:
    """Inverse of :func:`encode_velocity_rpdo1`: ``(controlword, target velocity rad/s)``.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 6:
        raise FrameError(f"RPDO1 needs 6 bytes, got {len(data)}")
    cw, units = struct.unpack("<Hi", data)
    return int(cw), units * VELOCITY_UNIT


def encode_tpdo2(node: int, velocity: float, torque: float, t: float = 0.0) -> CanFrame:
    """TPDO2 of a velocity-mode drive: velocity actual 0x606C (int32 LE, 1e-4 rad/s) and torque
    actual 0x6077 (int16 LE, mN m, saturated)."""
    mnm = max(-32768, min(32767, round(torque * 1000.0))) if math.isfinite(torque) else 0
    return CanFrame(TPDO2_BASE + node, struct.pack("<ih", _velocity_units(velocity), mnm), t)


def decode_tpdo2(data: bytes) -> tuple[float, float]:
    """Inverse of :func:`encode_tpdo2`: ``(velocity rad/s, torque N m)``.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 6:
        raise FrameError(f"TPDO2 needs 6 bytes, got {len(data)}")
    units, mnm = struct.unpack("<ih", data)
    return units * VELOCITY_UNIT, mnm / 1000.0


def encode_heartbeat(node: int, state: NmtState, t: float = 0.0) -> CanFrame:
    """Heartbeat (0x700 + node) carrying the NMT state."""
    return CanFrame(HEARTBEAT_BASE + node, bytes([int(state)]), t)


def decode_heartbeat(data: bytes) -> NmtState:
    """NMT state from a heartbeat payload.

    Raises:
        FrameError: wrong length or unknown state.
    """
    if len(data) != 1:
        raise FrameError(f"heartbeat needs 1 byte, got {len(data)}")
    try:
        return NmtState(data[0] & 0x7F)  # bit 7 is the node-guarding toggle bit
    except ValueError as exc:
        raise FrameError(f"unknown NMT state {data[0]:#x}") from exc


def encode_crossfire(blocked: bool, t: float = 0.0) -> CanFrame:
    """TPDO1 of the crossfire I/O module: bit 0 set when the light beam is interrupted."""
    return CanFrame(TPDO1_BASE + CROSSFIRE_ID, bytes([1 if blocked else 0]), t)


def decode_crossfire(data: bytes) -> bool:
    """Beam state from a crossfire TPDO payload.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 1:
        raise FrameError(f"crossfire TPDO needs 1 byte, got {len(data)}")
    return bool(data[0] & 0x01)


def encode_emcy(node: int, code: int, register: int = 0, t: float = 0.0) -> CanFrame:
    """EMCY (0x080 + node): error code uint16 LE, error register uint8, 5 zero bytes (CiA 301)."""
    if not 1 <= node <= 0x7F:
        raise FrameError(f"EMCY from node {node}: node ids are 1..127")
    return CanFrame(EMCY_BASE + node, struct.pack("<HB5x", code & 0xFFFF, register & 0xFF), t)


def decode_emcy(data: bytes) -> tuple[int, int]:
    """Inverse of :func:`encode_emcy`: ``(error code, error register)``.

    Raises:
        FrameError: wrong length.
    """
    if len(data) != 8:
        raise FrameError(f"EMCY needs 8 bytes, got {len(data)}")
    code, register = struct.unpack("<HB5x", data)
    return int(code), int(register)


def nmt_frame(command: NmtCommand, node: int = 0) -> CanFrame:
    """NMT command frame (node 0 addresses all nodes)."""
    return CanFrame(NMT_ID, bytes([int(command), node & 0x7F]))


def statusword(state: DriveState, following_error: bool = False) -> int:
    """Statusword for a power state (bit 13 flags a following error)."""
    return _STATUSWORDS[state] | (_FOLLOWING_ERROR_BIT if following_error else 0)


def state_from_statusword(sw: int) -> DriveState:
    """Power state from a statusword.

    Raises:
        FrameError: the statusword does not encode a state of the subset.
    """
    if sw & 0x004F == 0x0008:
        return DriveState.FAULT
    if sw & 0x004F == 0x000F:
        return DriveState.FAULT_REACTION_ACTIVE
    for state, value in _STATUSWORDS.items():
        if sw & _STATE_MASK == value:
            return state
    raise FrameError(f"statusword {sw:#06x} encodes no supported CiA 402 state")


@dataclass
class Cia402StateMachine:
    """Minimal CiA 402 power state machine of one drive (pure).

    Attributes:
        state: current power state.
        fault_reason: why the drive faulted (empty when not in FAULT or FAULT REACTION ACTIVE).
        fault_code: the EMCY code of the fault (:attr:`EmcyCode.NO_ERROR` when none).
    """

    state: DriveState = DriveState.SWITCH_ON_DISABLED
    fault_reason: str = ""
    fault_code: EmcyCode = EmcyCode.NO_ERROR
    _last_cw: int = field(default=0, repr=False)

    def on_controlword(self, cw: int) -> DriveState:
        """Apply a controlword; returns the new state. Unknown commands are ignored."""
        rising_reset = bool(cw & 0x80) and not bool(self._last_cw & 0x80)
        self._last_cw = cw
        if self.state is DriveState.FAULT_REACTION_ACTIVE:
            return self.state  # the drive is stopping; nothing interrupts the reaction
        if self.state is DriveState.FAULT:
            if rising_reset:
                self.state = DriveState.SWITCH_ON_DISABLED
                self.fault_reason = ""
                self.fault_code = EmcyCode.NO_ERROR
            return self.state
        cmd = cw & 0x008F
        if cmd & 0x0002 == 0:  # disable voltage (bit 1 clear)
            self.state = DriveState.SWITCH_ON_DISABLED
        elif cmd == Controlword.SHUTDOWN:
            self.state = DriveState.READY_TO_SWITCH_ON
        elif cmd == Controlword.SWITCH_ON and self.state in (
            DriveState.READY_TO_SWITCH_ON,
            DriveState.OPERATION_ENABLED,
        ):
            self.state = DriveState.SWITCHED_ON
        elif cmd == Controlword.ENABLE_OPERATION and self.state in (
            DriveState.SWITCHED_ON,
            DriveState.OPERATION_ENABLED,
        ):
            self.state = DriveState.OPERATION_ENABLED
        return self.state

    def fault(self, reason: str, code: EmcyCode = EmcyCode.FOLLOWING_ERROR) -> None:
        """Enter FAULT at once (no reaction ramp)."""
        self.state = DriveState.FAULT
        self.fault_reason = reason
        self.fault_code = code

    def start_fault_reaction(self, reason: str, code: EmcyCode) -> None:
        """Enter FAULT REACTION ACTIVE (the drive stops on its ramp, then :meth:`reaction_done`)."""
        self.state = DriveState.FAULT_REACTION_ACTIVE
        self.fault_reason = reason
        self.fault_code = code

    def reaction_done(self) -> None:
        """The joint is at rest: FAULT REACTION ACTIVE becomes FAULT."""
        if self.state is DriveState.FAULT_REACTION_ACTIVE:
            self.state = DriveState.FAULT

    @property
    def faulted(self) -> bool:
        """True in FAULT or FAULT REACTION ACTIVE."""
        return self.state in (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE)

    @property
    def statusword(self) -> int:
        """Statusword of the current state (bit 13 set for a following error)."""
        following = self.faulted and self.fault_code is EmcyCode.FOLLOWING_ERROR
        return statusword(self.state, following_error=following)
