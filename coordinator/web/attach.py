"""The web console next to the terminal one on a run started by ``petrobot run NET --console PORT``.

:func:`coordinator.session.execute` shows a run with a :class:`coordinator.console.Console` and
hands it the runtime it builds; :class:`WebAttachedConsole` is that terminal console which, when
it attaches, also attaches the web console's server (:meth:`ConsoleServer.attach_run`), so both
observe the same runtime side by side and commands from either take the same engine path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from coordinator.console import Console
from coordinator.net import PetriNet
from coordinator.runtime import Runtime

__all__ = ["WebAttachedConsole"]


class WebAttachedConsole(Console):
    """A terminal console that attaches ``server`` to the runtime it is given.

    Args:
        net: the net being run.
        server: a started :class:`coordinator.web.server.ConsoleServer`.
        net_path: the net file (its drawing is shown), or ``None``.
        **options: the :class:`~coordinator.console.Console` options (``live``, ``quiet``...).
    """

    def __init__(self, net: PetriNet, server: Any, net_path: Path | None = None, **options: Any) -> None:
        super().__init__(net, **options)
        self.server = server
        self.net_path = net_path

    def attach(self, runtime: Runtime) -> None:
        """Follow ``runtime`` on the terminal and in the browser."""
        super().attach(runtime)
        self.server.attach_run(runtime, self.net_path)
