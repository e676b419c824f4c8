"""The coordinator: the task net, its three views and the runtime that executes it (docs/architecture.md).

The net model (:mod:`coordinator.net`), net files (:mod:`coordinator.netfile`), the sans-IO engine
(:mod:`coordinator.engine`), the runtime and journal, learning (section 4), the analyses (sections 2
and 3) and the ``petrobot`` command line. It calls primitive actions through :mod:`services`.
"""

__all__: list[str] = []
