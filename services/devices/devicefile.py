"""Device files: what is on a CAN bus, for its CANopen master (``devices/puma.toml``, ``devices/wheels.toml``).

services.toml names a node's device file (the ``bus`` param of the PUMA's and the wheels' drivers); the
file says, per CiA 402 drive, its node id, its EDS or DCF file, its mode of operation, its unit
scaling, its heartbeat and deadline times and its PDO mappings, and per other CANopen device (an I/O
module) its node id and EDS, so that putting a real drive on the bus is an edit of this file and a
copy of the drive's EDS, not of code. A table ``[defaults]`` gives what every drive has unless its own
table says otherwise. Example (the PUMA's, abridged)::

    [bus]
    interface = "socketcand"     # python-can interface; "socketcan" for a CAN interface of this host
    channel = "can0"
    sync = "consumer"            # another station produces SYNC; "producer": the master, every sync_period_ms
    master_node_id = 0x7F        # the master's heartbeat is 0x77F
    master_heartbeat_ms = 100

    [defaults]
    eds = "puma_joint_drive.eds" # relative to this file
    mode = "csp"                 # csp (8), csv (9), pv (3), pp (1)
    position_unit = 1e-5         # rad per count (0x607A, 0x6064)
    velocity_unit = 1e-4         # rad/s per count (0x60FF, 0x606C)
    heartbeat_ms = 100           # 0x1017
    master_heartbeat_timeout_ms = 350   # 0x1016: the drive faults when the master is silent that long
    rpdo_timeout_ms = 50         # 0x1400:05 (RPDO deadline): the drive faults without targets that long
    rpdo = [["controlword", "target_position"]]          # RPDO1, RPDO2, ...
    tpdo = [["statusword", "position_actual_value"]]     # TPDO1, TPDO2, ...

    [drives.joint1]
    node_id = 1

    [io.crossfire]
    node_id = 0x10
    eds = "crossfire_io.eds"

Drives are in file order (the PUMA's joints 1..6, the wheels left then right). ``rpdo`` and ``tpdo``
are written over SDO at start-up (each inner list a PDO, in order; the drive's other PDOs are
switched off); without them, the mapping of the EDS (or DCF) file is written; ``pdo_mapping =
"read"`` instead reads the drive's own mapping and writes none. Objects are named by the
snake-case names of :data:`services.devices.cia402.OBJECTS` or as ``"0x6041"`` / ``"0x6041:00"``.
Pure apart from reading the file: errors are :class:`DeviceFileError` with ``FILE:LINE: problem``.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from services.devices.cia402 import OBJECTS
from services.errors import PetrobotError
from services.textfile import TextProblem, decode_utf8, read_capped
from services.tomllines import TomlLines, parse_toml

__all__ = ["MODES", "PROJECT_DEVICES", "BusSpec", "DeviceFileError", "DriveSpec", "IoSpec", "load_bus",
           "object_ref", "parse_bus", "resolve_device_file"]

PROJECT_DEVICES: Final = Path(__file__).resolve().parents[2] / "devices"
"""The project's device and EDS files (``devices/`` beside services.toml)."""

MODES: Final = {"pp": 1, "pv": 3, "csp": 8, "csv": 9}
"""Modes of operation a device file may name, with their 0x6060 value (CiA 402)."""

_BUS_KEYS = {"interface", "channel", "sync", "sync_period_ms", "master_node_id", "master_heartbeat_ms",
             "sdo_timeout_s"}
_DRIVE_KEYS = {"node_id", "eds", "mode", "position_unit", "velocity_unit", "heartbeat_ms",
               "master_heartbeat_timeout_ms", "rpdo_timeout_ms", "rpdo", "tpdo", "pdo_mapping"}
_IO_KEYS = {"node_id", "eds", "heartbeat_ms"}
_HEX_OBJECT = re.compile(r"0[xX]([0-9A-Fa-f]{4})(?::([0-9A-Fa-f]{1,2}))?")

ObjectRef = tuple[int, int]
PdoMapping = tuple[ObjectRef, ...]


class DeviceFileError(PetrobotError):
    """A device file cannot be read or says something impossible (``FILE:LINE: problem``)."""


@dataclass(frozen=True, slots=True)
class DriveSpec:
    """One CiA 402 drive on the bus.

    Attributes:
        name: its table's name (``joint1``).
        node_id: 1..127.
        eds: path of its EDS or DCF file.
        mode: mode of operation, a key of :data:`MODES`.
        position_unit: SI units (rad or m) per position count.
        velocity_unit: SI units per second per velocity count.
        heartbeat_ms: the drive's heartbeat period (0x1017), ms.
        master_heartbeat_timeout_ms: the drive's consumer heartbeat time for the master (0x1016), ms
            (0: the drive does not watch the master).
        rpdo_timeout_ms: the deadline of the RPDO carrying the target (0x1400:05 event timer), ms (0: none).
        rpdo, tpdo: the PDO mappings to write, one tuple of ``(index, subindex)`` per PDO, or
            ``None`` for the EDS's.
        pdo_mapping: ``"write"`` (the mappings above) or ``"read"`` (the drive's own).
    """

    name: str
    node_id: int
    eds: str
    mode: str = "csp"
    position_unit: float = 1e-5
    velocity_unit: float = 1e-4
    heartbeat_ms: int = 100
    master_heartbeat_timeout_ms: int = 350
    rpdo_timeout_ms: int = 50
    rpdo: tuple[PdoMapping, ...] | None = None
    tpdo: tuple[PdoMapping, ...] | None = None
    pdo_mapping: str = "write"


@dataclass(frozen=True, slots=True)
class IoSpec:
    """Another CANopen device on the bus (an I/O module): its TPDOs go to the driver's callbacks.

    Attributes:
        name: its table's name.
        node_id: 1..127.
        eds: path of its EDS or DCF file.
        heartbeat_ms: its heartbeat period (0x1017), ms.
    """

    name: str
    node_id: int
    eds: str
    heartbeat_ms: int = 100


@dataclass(frozen=True, slots=True)
class BusSpec:
    """A CAN bus and its devices, as a device file says.

    Attributes:
        path: the file.
        interface: python-can interface (``"socketcand"``, ``"socketcan"``, ``"virtual"``...).
        channel: the bus's name on that interface.
        sync: ``"consumer"`` (another station produces SYNC) or ``"producer"`` (the master does).
        sync_period_s: the SYNC period when the master produces it, s.
        master_node_id: the master's node id (its heartbeat 0x700 + id).
        master_heartbeat_ms: the master's heartbeat period, ms of bus time.
        sdo_timeout_s: how long an SDO request waits for the device's answer, s.
        drives: the CiA 402 drives, in file order.
        io: the other devices.
    """

    path: str
    drives: tuple[DriveSpec, ...]
    io: tuple[IoSpec, ...] = ()
    interface: str = "socketcand"
    channel: str = "can0"
    sync: str = "consumer"
    sync_period_s: float = 0.002
    master_node_id: int = 0x7F
    master_heartbeat_ms: int = 100
    sdo_timeout_s: float = 1.0

    @property
    def node_ids(self) -> tuple[int, ...]:
        """The drives' node ids, in order."""
        return tuple(d.node_id for d in self.drives)

    def io_node(self, name: str) -> IoSpec:
        """The I/O device named ``name``.

        Raises:
            DeviceFileError: none has that name.
        """
        for io in self.io:
            if io.name == name:
                return io
        raise DeviceFileError(f"{self.path}: no [io.{name}] table")


def object_ref(text: str) -> ObjectRef:
    """``(index, subindex)`` of an object named as in a device file (``"statusword"``, ``"0x6041"``,
    ``"0x6000:01"``).

    Raises:
        ValueError: neither a known name nor a hexadecimal index.
    """
    if text in OBJECTS:
        return OBJECTS[text]
    m = _HEX_OBJECT.fullmatch(text)
    if m is None:
        raise ValueError(f"unknown object {text!r}: a name ({', '.join(sorted(OBJECTS))}) or 0xIIII[:SS]")
    return int(m.group(1), 16), int(m.group(2) or "0", 16)


def resolve_device_file(given: str | None, services_path: str | None, default: str) -> str:
    """Where a driver's device file is: its ``bus`` param, relative to the directory of services.toml
    (``services_path``; the working directory when it was not read from a file), else the project's
    ``devices/DEFAULT``."""
    if given is None:
        return str(PROJECT_DEVICES / default)
    given = os.path.expanduser(given)
    if os.path.isabs(given) or not services_path or services_path.startswith("<"):
        return given
    return os.path.join(os.path.dirname(services_path), given)


def load_bus(path: str | os.PathLike[str]) -> BusSpec:
    """Read and parse a device file.

    Raises:
        DeviceFileError: the file cannot be read or is wrong (``FILE:LINE: problem``).
    """
    p = os.fspath(path)
    try:
        text = decode_utf8(read_capped(p, what="device file", limit=1 << 20))
    except TextProblem as exc:
        raise _error(p, exc.line, exc.problem) from None
    return parse_bus(text, path=p)


def parse_bus(text: str, *, path: str = "<string>") -> BusSpec:
    """Parse the text of a device file; relative EDS paths are taken from the file's directory.

    Raises:
        DeviceFileError: (``FILE:LINE: problem``).
    """
    try:
        doc, lines = parse_toml(text)
    except TextProblem as exc:
        raise _error(path, exc.line, exc.problem) from None
    return _Reader(doc, lines, path).bus()


def _error(path: str, line: int | None, problem: str) -> DeviceFileError:
    return DeviceFileError(f"{path}:{line}: {problem}" if line is not None else f"{path}: {problem}")


class _Reader:
    def __init__(self, doc: dict[str, Any], lines: TomlLines, path: str) -> None:
        self.doc = doc
        self.lines = lines
        self.path = path
        self.directory = os.path.dirname(path) if path != "<string>" else ""

    def fail(self, problem: str, *where: str | int) -> DeviceFileError:
        return _error(self.path, self.lines.line(*where) if where else None, problem)

    def table(self, key: str) -> dict[str, Any]:
        value = self.doc.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(f"{key} must be a table", key)
        return value

    def bus(self) -> BusSpec:
        extra = sorted(set(self.doc) - {"bus", "defaults", "drives", "io"})
        if extra:
            raise self.fail(f"unknown table(s) {', '.join(extra)} (bus, defaults, drives, io)", extra[0])
        bus = self.table("bus")
        self.known(bus, _BUS_KEYS, "bus")
        defaults = self.table("defaults")
        self.known(defaults, _DRIVE_KEYS - {"node_id"}, "defaults")
        drives_table = self.table("drives")
        if not drives_table:
            raise self.fail("no [drives.NAME] table: a device file names at least one drive")
        drives = tuple(self.drive(name, entry, defaults) for name, entry in drives_table.items())
        io = tuple(self.io(name, entry) for name, entry in self.table("io").items())
        seen: dict[int, str] = {}
        for name, node, where in [*((d.name, d.node_id, "drives") for d in drives),
                                  *((i.name, i.node_id, "io") for i in io)]:
            if node in seen:
                raise self.fail(f"node id {node} of {name} is also {seen[node]}'s", where, name, "node_id")
            seen[node] = name
        master = self.integer(bus, "master_node_id", 0x7F, 1, 127, "bus")
        if master in seen:
            raise self.fail(f"master_node_id {master} is also {seen[master]}'s node id", "bus", "master_node_id")
        sync = bus.get("sync", "consumer")
        if sync not in ("consumer", "producer"):
            raise self.fail(f"sync must be \"consumer\" or \"producer\", got {sync!r}", "bus", "sync")
        period_ms = self.number(bus, "sync_period_ms", 2.0, "bus")
        return BusSpec(
            path=self.path, drives=drives, io=io,
            interface=self.string(bus, "interface", "socketcand", "bus"),
            channel=self.string(bus, "channel", "can0", "bus"), sync=sync, sync_period_s=period_ms / 1000.0,
            master_node_id=master,
            master_heartbeat_ms=self.integer(bus, "master_heartbeat_ms", 100, 1, 65535, "bus"),
            sdo_timeout_s=self.number(bus, "sdo_timeout_s", 1.0, "bus"))

    def known(self, table: dict[str, Any], keys: set[str], *where: str) -> None:
        extra = sorted(set(table) - keys)
        if extra:
            raise self.fail(f"unknown key(s) {', '.join(extra)} in [{'.'.join(where)}] "
                            f"(known: {', '.join(sorted(keys))})", *where, extra[0])

    def string(self, table: dict[str, Any], key: str, default: str, *where: str) -> str:
        value = table.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(f"{key} must be a non-empty string", *where, key)
        return value

    def integer(self, table: dict[str, Any], key: str, default: int | None, low: int, high: int, *where: str) -> int:
        value = table.get(key, default)
        if value is None:
            raise self.fail(f"{key} is missing", *where)
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise self.fail(f"{key} must be an integer in {low}..{high}, got {value!r}", *where, key)
        return value

    def number(self, table: dict[str, Any], key: str, default: float, *where: str) -> float:
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
            raise self.fail(f"{key} must be a positive number, got {value!r}", *where, key)
        return float(value)

    def eds(self, table: dict[str, Any], *where: str) -> str:
        name = self.string(table, "eds", "", *where) if "eds" in table else None
        if name is None:
            raise self.fail("eds is missing (the device's EDS or DCF file)", *where)
        path = os.path.join(self.directory, os.path.expanduser(name))
        if not os.path.isfile(path):
            raise self.fail(f"EDS file {name!r} not found (looked for {path})", *where, "eds")
        if os.path.splitext(path)[1].lower() not in (".eds", ".dcf"):
            raise self.fail(f"EDS file {name!r}: the name must end in .eds or .dcf", *where, "eds")
        return path

    def mappings(self, table: dict[str, Any], key: str, *where: str) -> tuple[PdoMapping, ...] | None:
        if key not in table:
            return None
        value = table[key]
        if not isinstance(value, list) or not all(isinstance(p, list) for p in value):
            raise self.fail(f"{key} must be a list of PDOs, each a list of objects", *where, key)
        out = []
        for pdo in value:
            refs = []
            for item in pdo:
                if not isinstance(item, str):
                    raise self.fail(f"{key}: objects are named by strings, got {item!r}", *where, key)
                try:
                    refs.append(object_ref(item))
                except ValueError as exc:
                    raise self.fail(f"{key}: {exc}", *where, key) from None
            out.append(tuple(refs))
        return tuple(out)

    def drive(self, name: str, entry: Any, defaults: dict[str, Any]) -> DriveSpec:
        if not isinstance(entry, dict):
            raise self.fail(f"drives.{name} must be a table", "drives", name)
        self.known(entry, _DRIVE_KEYS, "drives", name)
        where = ("drives", name)
        merged = {**defaults, **entry}
        mode = merged.get("mode", "csp")
        if mode not in MODES:
            raise self.fail(f"mode must be one of {', '.join(MODES)}, got {mode!r}", *where, "mode")
        pdo_mapping = merged.get("pdo_mapping", "write")
        if pdo_mapping not in ("write", "read"):
            raise self.fail(f"pdo_mapping must be \"write\" or \"read\", got {pdo_mapping!r}", *where, "pdo_mapping")
        eds_where = where if "eds" in entry else ("defaults",)
        return DriveSpec(
            name=name, node_id=self.integer(entry, "node_id", None, 1, 127, *where),
            eds=self.eds(merged, *eds_where), mode=mode,
            position_unit=self.number(merged, "position_unit", 1e-5, *where),
            velocity_unit=self.number(merged, "velocity_unit", 1e-4, *where),
            heartbeat_ms=self.integer(merged, "heartbeat_ms", 100, 1, 65535, *where),
            master_heartbeat_timeout_ms=self.integer(merged, "master_heartbeat_timeout_ms", 350, 0, 65535, *where),
            rpdo_timeout_ms=self.integer(merged, "rpdo_timeout_ms", 50, 0, 65535, *where),
            rpdo=self.mappings(merged, "rpdo", *where), tpdo=self.mappings(merged, "tpdo", *where),
            pdo_mapping=pdo_mapping)

    def io(self, name: str, entry: Any) -> IoSpec:
        if not isinstance(entry, dict):
            raise self.fail(f"io.{name} must be a table", "io", name)
        self.known(entry, _IO_KEYS, "io", name)
        return IoSpec(name=name, node_id=self.integer(entry, "node_id", None, 1, 127, "io", name),
                      eds=self.eds(entry, "io", name),
                      heartbeat_ms=self.integer(entry, "heartbeat_ms", 100, 1, 65535, "io", name))
