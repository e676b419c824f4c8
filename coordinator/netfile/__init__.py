"""Net files: the TOML net file (docs/netfile.md), PNML and Graphviz DOT (paper section 2).

* :mod:`~coordinator.netfile.schema` — the TOML format's version, sections and keys;
* :mod:`~coordinator.netfile.source_map` — :class:`SourceMap`, the line of each element and key
  (from :class:`services.tomllines.TomlLines`, shared with ``services.toml``);
* :mod:`~coordinator.netfile.limits` — the limits every reader applies (sizes, names, counts);
* :mod:`~coordinator.netfile.loader` — :func:`loads_net`, :func:`load_net`, :func:`lint_net`:
  TOML → :class:`~coordinator.net.PetriNet`, every problem at its file and line;
* :mod:`~coordinator.netfile.writer` — :func:`dump_net`, :func:`save_net` (canonical TOML),
  :func:`format_value`, :func:`format_key`;
* :mod:`~coordinator.netfile.placement` — :func:`check_net`, a net against ``services.toml``;
* :mod:`~coordinator.netfile.layout` — the drawing's positions kept in a net file (:func:`load_layout`);
* :mod:`~coordinator.netfile.pnml` — PNML import and export (ISO/IEC 15909-2);
* :mod:`~coordinator.netfile.dot` — a Graphviz picture of a net;
* :mod:`~coordinator.netfile.formats` — :func:`load_any`, any of them by suffix.

Imports point one way: ``formats`` → ``loader``, ``pnml`` → ``writer`` → ``schema``.
"""

from coordinator.netfile.formats import load_any
from coordinator.netfile.layout import Layout, load_layout, loads_layout
from coordinator.netfile.loader import lint_net, load_net, loads_net
from coordinator.netfile.placement import check_net
from coordinator.netfile.schema import FORMAT_VERSION
from coordinator.netfile.source_map import SourceMap
from coordinator.netfile.writer import dump_net, format_key, format_value, save_net

__all__ = [
    "FORMAT_VERSION",
    "Layout",
    "SourceMap",
    "check_net",
    "dump_net",
    "format_key",
    "format_value",
    "lint_net",
    "load_any",
    "load_layout",
    "load_net",
    "loads_layout",
    "loads_net",
    "save_net",
]
