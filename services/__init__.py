"""What runs on a node: the protocol, the node server and client, primitive actions and devices.

The base layer of the project (:mod:`services.errors`, :mod:`services.results`) lives here too; a
node process imports nothing from :mod:`coordinator` or :mod:`sim` (docs/architecture.md).
"""

__all__: list[str] = []
