"""A node: the process that hosts the primitive actions services.toml places on it (paper §5).

Run as ``python -m services.node NAME`` (or ``petrobot node NAME``). The package is a sans-IO core
in a thin asyncio shell, as :mod:`services.protocol` is:

* :mod:`~services.node.calls` — the call table: admit, reject or join calls, answer queries,
  cancel orphaned calls, keep their results (bounded by bytes and by age) behind a small cache
  interface;
* :mod:`~services.node.fanout` — publish/subscribe fan-out: topics, sequence numbers, bounded
  backlogs for slow subscribers, caps on topics;
* :mod:`~services.node.guard` — connection caps, the handshake deadline, failed-login throttling;
* :mod:`~services.node.store` — the result cache in an SQLite file, which survives restarts;
* :mod:`~services.node.server` — the asyncio server (:class:`Node`): action and driver lifecycle,
  deadlines, cancels, heartbeats; with :mod:`~services.node.peer` (one connection, with
  back-pressure), :mod:`~services.node.listener` (the accept loop), :mod:`~services.node.locality`
  (which peers are on this host), :mod:`~services.node.watch` (the services.toml loaded) and
  :mod:`~services.node.logs` (rate-limited log lines);
* :mod:`~services.node.cli` — the command line.

A node process imports nothing from ``sim`` or ``coordinator``.
"""

from services.node.cli import build_parser, main, run_node
from services.node.server import Node

__all__ = ["Node", "build_parser", "main", "run_node"]
