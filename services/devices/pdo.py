"""PDO layouts: a PDO mapping compiled into a fixed binary layout (CiA 301 section 7.4.8).

A PDO mapping parameter (objects 0x1600.., 0x1A00..) lists the application objects a PDO carries,
each as ``index << 16 | subindex << 8 | bits``, packed one after the other, little-endian, from bit 0.
:class:`PdoLayout` compiles such a list, with the data type of each object from the object
dictionary, into one :class:`struct.Struct`, so that packing a PDO's data or reading one is one
struct call: the simulated drives do it for every TPDO they send after a SYNC and every RPDO they
receive, the CAN master (:mod:`services.devices.drives`) for the targets it sends each cycle and the
reports it receives. Pure: no I/O.

Only byte-aligned entries of 8, 16, 32 or 64 bits are supported (every object a CiA 402 drive maps
in practice); a mapping with bit-granular entries is refused with :class:`PdoLayoutError`.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from services.errors import PetrobotError

__all__ = [
    "DATA_TYPE_FORMATS",
    "PdoEntry",
    "PdoLayout",
    "PdoLayoutError",
    "decode_mapping_entry",
    "encode_mapping_entry",
]

DATA_TYPE_FORMATS: Mapping[int, str] = {
    0x01: "B",  # BOOLEAN (mapped as 8 bits)
    0x02: "b",  # INTEGER8
    0x03: "h",  # INTEGER16
    0x04: "i",  # INTEGER32
    0x05: "B",  # UNSIGNED8
    0x06: "H",  # UNSIGNED16
    0x07: "I",  # UNSIGNED32
    0x15: "q",  # INTEGER64
    0x1B: "Q",  # UNSIGNED64
}
"""struct format of each CiA 301 data type a PDO may map (data type code → format)."""

_BITS = {"b": 8, "B": 8, "h": 16, "H": 16, "i": 32, "I": 32, "q": 64, "Q": 64}


class PdoLayoutError(PetrobotError, ValueError):
    """A PDO mapping cannot be compiled (too long, bit-granular, an unmappable data type) or a PDO's
    data does not fit its layout."""


def encode_mapping_entry(index: int, subindex: int, bits: int) -> int:
    """The UNSIGNED32 value of one entry of a mapping parameter (``index << 16 | subindex << 8 | bits``)."""
    return (index & 0xFFFF) << 16 | (subindex & 0xFF) << 8 | (bits & 0xFF)


def decode_mapping_entry(value: int) -> tuple[int, int, int]:
    """Inverse of :func:`encode_mapping_entry`: ``(index, subindex, bits)``."""
    return (value >> 16) & 0xFFFF, (value >> 8) & 0xFF, value & 0xFF


@dataclass(frozen=True, slots=True)
class PdoEntry:
    """One mapped object.

    Attributes:
        index, subindex: the object.
        bits: its length in the PDO.
        fmt: its struct format character.
    """

    index: int
    subindex: int
    bits: int
    fmt: str


class PdoLayout:
    """The binary layout of one PDO (see the module docstring).

    Args:
        entries: the mapped objects, in PDO order.

    Raises:
        PdoLayoutError: more than 64 bits, or an entry whose format does not match its length.
    """

    def __init__(self, entries: Sequence[PdoEntry]) -> None:
        self.entries = tuple(entries)
        for e in self.entries:
            if _BITS.get(e.fmt) != e.bits:
                raise PdoLayoutError(f"object {e.index:#06x}:{e.subindex:02x} is mapped with {e.bits} bits, "
                                     f"its type has {_BITS.get(e.fmt, '?')}")
        self._struct = struct.Struct("<" + "".join(e.fmt for e in self.entries))
        if self._struct.size > 8:
            raise PdoLayoutError(f"a PDO carries at most 8 bytes; this mapping has {self._struct.size}")
        self._position = {e.index: k for k, e in enumerate(self.entries)}

    @classmethod
    def compile(cls, mapping: Iterable[tuple[int, int, int]], data_type: Mapping[tuple[int, int], int]) -> PdoLayout:
        """A layout from mapping entries ``(index, subindex, bits)`` and the data type code of each object.

        Raises:
            PdoLayoutError: an object without a known data type, a type that cannot be mapped,
                a bit-granular entry, or more than 64 bits.
        """
        entries = []
        for index, subindex, bits in mapping:
            code = data_type.get((index, subindex))
            if code is None:
                raise PdoLayoutError(f"object {index:#06x}:{subindex:02x} is not in the object dictionary")
            fmt = DATA_TYPE_FORMATS.get(code)
            if fmt is None:
                raise PdoLayoutError(f"object {index:#06x}:{subindex:02x} has data type {code:#04x}, "
                                     "which a PDO cannot carry")
            if code == 0x01 and bits == 8:
                pass
            elif bits != _BITS[fmt]:
                raise PdoLayoutError(f"object {index:#06x}:{subindex:02x} mapped with {bits} bits: only whole "
                                     "objects of 8, 16, 32 or 64 bits are supported")
            entries.append(PdoEntry(index, subindex, bits, fmt))
        return cls(entries)

    @property
    def size(self) -> int:
        """Length of the PDO's data, bytes."""
        return self._struct.size

    @property
    def indices(self) -> tuple[int, ...]:
        """The mapped objects' indices, in PDO order."""
        return tuple(e.index for e in self.entries)

    def __contains__(self, index: object) -> bool:
        return index in self._position

    def position(self, index: int) -> int:
        """Place of object ``index`` among the values of :meth:`pack` and :meth:`unpack`.

        Raises:
            KeyError: the object is not mapped.
        """
        return self._position[index]

    def pack(self, values: Sequence[int]) -> bytes:
        """The PDO's data from one integer per entry, in PDO order.

        Raises:
            PdoLayoutError: not one value per entry, or a value out of its type's range.
        """
        try:
            return self._struct.pack(*values)
        except struct.error as exc:
            raise PdoLayoutError(f"values {list(values)} do not fit the PDO layout {self.describe()}: {exc}") from None

    def pack_objects(self, values: Mapping[int, int]) -> bytes:
        """The PDO's data from a value per mapped object index (objects not given are 0).

        Raises:
            PdoLayoutError: a value out of its type's range.
        """
        return self.pack([int(values.get(e.index, 0)) for e in self.entries])

    def unpack(self, data: bytes | bytearray) -> tuple[int, ...]:
        """One integer per entry, in PDO order.

        Raises:
            PdoLayoutError: the data is not exactly :attr:`size` bytes long.
        """
        if len(data) != self._struct.size:
            raise PdoLayoutError(f"PDO of {len(data)} bytes, its layout {self.describe()} has {self._struct.size}")
        return self._struct.unpack(data)

    def unpack_objects(self, data: bytes | bytearray) -> dict[int, int]:
        """The mapped objects' values by index.

        Raises:
            PdoLayoutError: the data is not exactly :attr:`size` bytes long.
        """
        return dict(zip(self.indices, self.unpack(data), strict=True))

    def describe(self) -> str:
        """``"0x6041:00 (16 bits), 0x6064:00 (32 bits)"``."""
        return ", ".join(f"{e.index:#06x}:{e.subindex:02x} ({e.bits} bits)" for e in self.entries) or "(empty)"
