"""CiA 301/402 vocabulary of the robot drives: identifiers, objects, NMT, EMCY, the drive state machine.

Pure (no sockets, no clocks). The CAN master of the motion and drive nodes
(:mod:`services.devices.drives`, on the ``canopen`` library) and the simulated drives
(:mod:`sim.drives`, ``canopen`` local nodes) share these names and, on the drive side, the power state
machine; what each PDO carries is not fixed here but read from the object dictionaries (EDS files in
``devices/``) and the device files (:mod:`services.devices.devicefile`), and packed by
:mod:`services.devices.pdo`. Tested without I/O.

Bus layout (11-bit identifiers, CANopen pre-defined connection set):

=========  ==============  ===============================================================
COB-ID     direction       payload
=========  ==============  ===============================================================
0x000      master -> all   NMT: ``[command, node]`` (0x01 start, 0x02 stop, 0x80 pre-operational,
                           0x81 reset node, 0x82 reset communication; node 0 = all)
0x080      producer        SYNC, no data (the simulated world produces it, every 2 ms of simulated
                           time on the PUMA's bus and 8 ms on the wheels': its clock paces the bus
                           in both lock-step and real-time modes; a device file may make the master
                           the producer)
0x080+id   id -> master    EMCY (CiA 301 emergency): error code uint16 LE, error register uint8, 5
                           bytes zero; sent when a drive faults (code 0x0000 when a fault reset
                           clears it)
0x180+id   id -> master    TPDO1 (0x280+id TPDO2, ...): what the drive's mapping (0x1A00..) says,
0x200+id   master -> id    RPDO1 (0x300+id RPDO2, ...): what its mapping (0x1600..) says
0x580+id   id -> master    SDO responses (canopen's SDO server on the simulated drives)
0x600+id   master -> id    SDO requests: the master configures each drive at start-up
0x700+id   id -> master    heartbeat: 1 byte NMT state (0x00 boot-up, 0x04 stopped, 0x05 operational,
                           0x7F pre-operational), every 0x1017 ms of bus time
0x77F      master -> all   the master's own heartbeat (node :data:`MASTER_ID`), watched by the drives
                           through their consumer heartbeat time 0x1016
=========  ==============  ===============================================================

Default PDOs of the drives' EDS files: RPDO1 = controlword 0x6040 + target position 0x607A (the
PUMA's joints, cyclic synchronous position) or target velocity 0x60FF (the wheels, profile
velocity); TPDO1 = statusword 0x6041 + position actual value 0x6064; the wheels' TPDO2 = velocity
actual value 0x606C + torque actual value 0x6077; the crossfire module's TPDO1 = digital inputs
0x6000:01, on change. A device file may map them otherwise (the master writes the mappings over SDO
at start-up).

CiA 402 power state machine (statusword values with the "remote" bit clear):
``SWITCH_ON_DISABLED (0x0040) -shutdown 0x06-> READY_TO_SWITCH_ON (0x0021) -switch on 0x07->
SWITCHED_ON (0x0023) -enable operation 0x0F-> OPERATION_ENABLED (0x0027)``; ``disable voltage
(0x00)`` returns to SWITCH_ON_DISABLED. A fault (following error, no target from the master within
the RPDO deadline, the master's heartbeat lost) starts the fault reaction: FAULT REACTION ACTIVE
(0x000F) while the drive brings its axis to rest on a quick-stop ramp, then FAULT (0x0008), where it
holds; the EMCY frame says why (:class:`EmcyCode`). A rising edge of controlword bit 7 (fault reset,
0x80) leaves FAULT for SWITCH_ON_DISABLED; a reset during the fault reaction is ignored. A CiA 402
master therefore recovers a faulted drive by waiting for FAULT, then sending ``0x00`` (bit 7 low),
``0x80`` (the edge), and the enable sequence again.

Cyclic synchronous position (CSP) targets: a target received in an RPDO is latched at the next SYNC
and interpolated linearly over the following cycle. A drive that gets no new target at a SYNC keeps
moving at its last demand velocity (extrapolation), for at most its RPDO deadline; then it faults
with :attr:`EmcyCode.RPDO_TIMEOUT` and stops on the ramp. A master that falls behind therefore steps
its trajectory by the number of cycles that passed, so that its next target continues where the
drive's extrapolation has taken the joint. In profile velocity mode a target velocity holds until
the next one.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, field

from services.errors import PetrobotError

__all__ = [
    "CROSSFIRE_ID",
    "CYCLE_S",
    "DRIVE_IDS",
    "EMCY_BASE",
    "HEARTBEAT_BASE",
    "MASTER_ID",
    "NMT_ID",
    "OBJECTS",
    "RPDO1_BASE",
    "SYNC_ID",
    "TARGET_TIMEOUT_CYCLES",
    "TPDO1_BASE",
    "WHEEL_IDS",
    "CanFrame",
    "Cia402StateMachine",
    "Controlword",
    "DriveState",
    "EmcyCode",
    "FrameError",
    "NmtCommand",
    "NmtState",
    "decode_emcy",
    "decode_heartbeat",
    "encode_emcy",
    "encode_heartbeat",
    "nmt_frame",
    "state_from_statusword",
    "statusword",
]

NMT_ID = 0x000
SYNC_ID = 0x080
RPDO1_BASE = 0x200  # + node id; RPDO2 0x300, RPDO3 0x400, RPDO4 0x500
TPDO1_BASE = 0x180  # + node id; TPDO2 0x280, TPDO3 0x380, TPDO4 0x480
HEARTBEAT_BASE = 0x700
EMCY_BASE = 0x080  # + node id (1..127); 0x080 itself is SYNC
DRIVE_IDS = (1, 2, 3, 4, 5, 6)
"""Node ids of the PUMA's joint drives (joints 1..6) in the simulated world."""
CROSSFIRE_ID = 0x10
"""Node id of the PUMA's crossfire I/O module in the simulated world."""
MASTER_ID = 0x7F
"""Node id of the motion and drive nodes' CAN master (its heartbeat is 0x77F) in the project's device files."""
WHEEL_IDS = (1, 2)
"""Node ids of the mobile robot's wheel drives: 1 = left, 2 = right."""
CYCLE_S = 0.002
"""SYNC period of the PUMA's bus, s of simulated time."""
TARGET_TIMEOUT_CYCLES = 25
"""SYNC cycles in a row a PUMA joint drive extrapolates a missing target before it faults (its RPDO
deadline, 50 ms, over the 2 ms cycle)."""

OBJECTS: dict[str, tuple[int, int]] = {
    "error_code": (0x603F, 0),
    "controlword": (0x6040, 0),
    "statusword": (0x6041, 0),
    "modes_of_operation": (0x6060, 0),
    "modes_of_operation_display": (0x6061, 0),
    "position_demand_value": (0x6062, 0),
    "position_actual_value": (0x6064, 0),
    "velocity_demand_value": (0x606B, 0),
    "velocity_actual_value": (0x606C, 0),
    "torque_actual_value": (0x6077, 0),
    "target_position": (0x607A, 0),
    "target_velocity": (0x60FF, 0),
    "digital_inputs": (0x6000, 1),
}
"""CiA 402 (and CiA 401) objects by the names device files use: ``(index, subindex)``."""


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
    RESET_COMMUNICATION = 0x82


class Controlword(enum.IntEnum):
    """CiA 402 controlword commands used here."""

    DISABLE_VOLTAGE = 0x0000
    SHUTDOWN = 0x0006
    SWITCH_ON = 0x0007
    ENABLE_OPERATION = 0x000F
    FAULT_RESET = 0x0080


class DriveState(enum.Enum):
    """CiA 402 power states (the simulated drives use all but NOT READY TO SWITCH ON and QUICK STOP
    ACTIVE, which a real drive may report)."""

    NOT_READY_TO_SWITCH_ON = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP_ACTIVE = "quick stop active"
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
    DriveState.NOT_READY_TO_SWITCH_ON: 0x0000,
    DriveState.SWITCH_ON_DISABLED: 0x0040,
    DriveState.READY_TO_SWITCH_ON: 0x0021,
    DriveState.SWITCHED_ON: 0x0023,
    DriveState.OPERATION_ENABLED: 0x0027,
    DriveState.QUICK_STOP_ACTIVE: 0x0007,
    DriveState.FAULT_REACTION_ACTIVE: 0x000F,
    DriveState.FAULT: 0x0008,
}
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
    """Power state from a statusword (the masks of CiA 402's statusword table: bits 0-3 and 6, and
    bit 5 for the states where quick stop tells them apart).

    Raises:
        FrameError: the statusword encodes no CiA 402 state.
    """
    for state, (mask, value) in _STATE_BITS.items():
        if sw & mask == value:
            return state
    raise FrameError(f"statusword {sw:#06x} encodes no CiA 402 state")


_STATE_BITS = {
    DriveState.NOT_READY_TO_SWITCH_ON: (0x004F, 0x0000),
    DriveState.SWITCH_ON_DISABLED: (0x004F, 0x0040),
    DriveState.READY_TO_SWITCH_ON: (0x006F, 0x0021),
    DriveState.SWITCHED_ON: (0x006F, 0x0023),
    DriveState.OPERATION_ENABLED: (0x006F, 0x0027),
    DriveState.QUICK_STOP_ACTIVE: (0x006F, 0x0007),
    DriveState.FAULT_REACTION_ACTIVE: (0x004F, 0x000F),
    DriveState.FAULT: (0x004F, 0x0008),
}


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
