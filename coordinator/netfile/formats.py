"""Loading a net file of any supported format, chosen by its suffix.

``.toml`` is the petrobot net file (:mod:`~coordinator.netfile.loader`); ``.pnml`` and ``.xml``
are PNML (:mod:`~coordinator.netfile.pnml`).
"""

from __future__ import annotations

from pathlib import Path

from coordinator.errors import NetFileError
from coordinator.net import PetriNet
from coordinator.netfile.loader import load_net
from coordinator.netfile.pnml import load_pnml
from services.textfile import MAX_FILE_BYTES

__all__ = ["SUFFIXES", "load_any"]

#: Net-file suffixes :func:`load_any` reads.
SUFFIXES = (".toml", ".pnml", ".xml")


def load_any(path: str | Path, *, interpreted: bool = True, max_pnml_bytes: int | None = None) -> PetriNet:
    """Load a net file of any supported format, chosen by suffix: ``.toml``, ``.pnml`` or ``.xml``.
    ``max_pnml_bytes``: the largest PNML file read (default 16 MiB, :func:`.load_pnml`).

    Raises:
        NetFileError: unknown suffix, unreadable file, syntax error.
        NetError: as :func:`load_net` and :func:`coordinator.netfile.pnml.load_pnml`.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".toml":
        return load_net(path, interpreted=interpreted)
    if suffix in (".pnml", ".xml"):
        return load_pnml(path, interpreted=interpreted,
                         max_bytes=MAX_FILE_BYTES if max_pnml_bytes is None else max_pnml_bytes)
    raise NetFileError(f"unknown net file type {suffix or '(no suffix)'!r}: use .toml, .pnml or .xml", path=str(path))
