"""The global memory of the system (paper §5): a key/value service hosted by one node.

The node named in services.toml's ``[memory]`` section keeps a :class:`MemoryStore` and serves it
as three ordinary primitive actions, so any client reaches it with a plain ``call``:

========== ============================== ==========================================
action     params                         result value
========== ============================== ==========================================
memory.get ``{"key": str, "default": x}`` the stored value, else ``default`` (nil)
memory.set ``{"key": str, "value": x}``   nil
memory.keys ``{}``                        sorted list of keys
========== ============================== ==========================================

Values are any msgpack value. Actions on other nodes use :class:`RemoteMemory`, which calls these
actions over a :class:`services.client.NodeLink`; actions on the memory node itself use the store
directly. Both satisfy :class:`services.action.MemoryAPI`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from services.errors import ActionError
from services.action import CallContext, PrimitiveAction
from services.results import ActionResult, Status

if TYPE_CHECKING:
    from services.client import NodeLink

__all__ = ["MemoryAction", "MemoryStore", "NoMemory", "RemoteMemory", "memory_actions"]


class MemoryStore:
    """The in-process store of the memory node (a dict; every operation is atomic on the loop)."""

    def __init__(self) -> None:
        self._data: dict[str, Any] = {}

    async def get(self, key: str, default: Any = None) -> Any:
        """Value under ``key``, or ``default``."""
        return self._data.get(key, default)

    async def set(self, key: str, value: Any) -> None:
        """Store ``value`` under ``key``."""
        self._data[key] = value

    async def keys(self) -> list[str]:
        """Sorted keys."""
        return sorted(self._data)


class MemoryAction(PrimitiveAction):
    """One of ``memory.get`` / ``memory.set`` / ``memory.keys`` bound to a store."""

    def __init__(self, op: str, store: MemoryStore) -> None:
        if op not in ("get", "set", "keys"):
            raise ActionError(f"unknown memory operation {op!r}")
        self.op = op
        self.store = store
        self.name = f"memory.{op}"

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        if self.op == "keys":
            return ActionResult(status=Status.SUCCESS, value=await self.store.keys())
        key = params.get("key")
        if not isinstance(key, str):
            raise ActionError(f"{self.name} needs a string 'key' parameter")
        if self.op == "get":
            return ActionResult(status=Status.SUCCESS, value=await self.store.get(key, params.get("default")))
        if "value" not in params:
            raise ActionError("memory.set needs a 'value' parameter")
        await self.store.set(key, params["value"])
        return ActionResult(status=Status.SUCCESS)


def memory_actions(store: MemoryStore) -> dict[str, MemoryAction]:
    """The three memory actions over ``store``, by action name."""
    return {f"memory.{op}": MemoryAction(op, store) for op in ("get", "set", "keys")}


class RemoteMemory:
    """Global memory reached over the network from a node that does not host it.

    Raises (from every method):
        ActionError: the memory node answered with an error or could not be reached.
    """

    def __init__(self, link: NodeLink, deadline_s: float = 5.0) -> None:
        self._link = link
        self._deadline_s = deadline_s

    async def _call(self, action: str, params: dict[str, Any]) -> Any:
        res = await self._link.call(action, params, deadline_s=self._deadline_s)
        if res.status is not Status.SUCCESS:
            raise ActionError(f"{action} failed on node {self._link.node!r}: {res.reason}")
        return res.value

    async def get(self, key: str, default: Any = None) -> Any:
        """Value under ``key``, or ``default``."""
        return await self._call("memory.get", {"key": key, "default": default})

    async def set(self, key: str, value: Any) -> None:
        """Store ``value`` under ``key``."""
        await self._call("memory.set", {"key": key, "value": value})

    async def keys(self) -> list[str]:
        """Sorted keys."""
        value = await self._call("memory.keys", {})
        return list(value)


class NoMemory:
    """Stand-in when services.toml has no ``[memory]`` section: every use raises ActionError."""

    async def get(self, key: str, default: Any = None) -> Any:
        raise ActionError("no global memory: services.toml has no [memory] section")

    async def set(self, key: str, value: Any) -> None:
        raise ActionError("no global memory: services.toml has no [memory] section")

    async def keys(self) -> list[str]:
        raise ActionError("no global memory: services.toml has no [memory] section")
