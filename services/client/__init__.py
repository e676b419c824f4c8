"""The calling side of the protocol (docs/protocol.md): the coordinator, or a node reaching another node.

* :mod:`~services.client.link` — :class:`NodeLink`, one authenticated, self-healing connection to
  one node: calls, queries, cancels, subscriptions, heartbeats;
* :mod:`~services.client.service` — :class:`ServiceClient`, which routes calls by action name
  through services.toml and checks a run's actions beforehand (:meth:`ServiceClient.preflight`).
"""

from services.client.link import UNKNOWN_CALL, EventCallback, FeedbackCallback, NodeBusy, NodeLink
from services.client.service import PREFLIGHT_S, ServiceClient

__all__ = ["PREFLIGHT_S", "UNKNOWN_CALL", "EventCallback", "FeedbackCallback", "NodeBusy", "NodeLink", "ServiceClient"]
