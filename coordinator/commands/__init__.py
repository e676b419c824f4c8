"""The ``petrobot`` subcommands, one module each (registered in :mod:`coordinator.cli`).

A command module is cheap to import (argparse only); what it needs is imported inside its ``run``.
The command line is the top of every layer: ``petrobot sim`` imports :mod:`sim` to start a world.
"""

__all__: list[str] = []
