"""Primitive actions and drivers: the lifecycle a node gives the code it hosts.

A primitive action (paper §2: one of the ways a primitive task can be carried out) is hosted by a
node and called over the network. Its lifecycle follows py_trees' behaviours:

* ``__init__`` only configures (no hardware, no sockets);
* ``async setup(node)`` once when the node starts: connect to drivers, load models;
* ``async run(params, ctx)`` once per call, returning an :class:`ActionResult`. The node runs it as
  its own task and *cancels* that task on a cancel request or at the deadline: ``run`` must let
  :class:`asyncio.CancelledError` propagate (clean up in ``finally``);
* ``async teardown()`` once when the node stops.

A plain ``async def f(params, ctx)`` is an action too (wrapped by :func:`as_action`); it may return an
:class:`ActionResult` or any msgpack value (then the status is ``"success"``).

A :class:`Driver` is a background component (a camera card, a CAN bus) started with the node before
the actions; actions reach it as ``ctx.drivers[name]`` and it may :meth:`Driver.publish` external
events.
"""

from __future__ import annotations

import asyncio
import importlib
import inspect
from collections.abc import Awaitable, Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from services.errors import ActionError
from services.results import ActionResult

if TYPE_CHECKING:
    from services.client import NodeLink
    from services.location import Location

__all__ = [
    "CallContext",
    "Driver",
    "FunctionAction",
    "MemoryAPI",
    "NodeContext",
    "PrimitiveAction",
    "as_action",
    "import_impl",
    "make_action",
]

_D = TypeVar("_D", bound="Driver")


class MemoryAPI(Protocol):
    """The global memory of the system (paper §5): a key/value store hosted by one node."""

    async def get(self, key: str, default: Any = None) -> Any:
        """Value stored under ``key``, or ``default``."""
        ...

    async def set(self, key: str, value: Any) -> None:
        """Store ``value`` (any msgpack value) under ``key``."""
        ...

    async def keys(self) -> list[str]:
        """Every key, sorted."""
        ...


class NodeContext:
    """What a node offers the actions and drivers it hosts (built by ``services.node``).

    Attributes:
        name: this node's name.
        location: the parsed services.toml.
        drivers: driver objects by name.
        memory: the global memory client.
    """

    def __init__(
        self,
        *,
        name: str,
        location: Location,
        drivers: Mapping[str, Driver],
        memory: MemoryAPI,
        publish: Callable[[str, Any], None],
        link: Callable[[str], NodeLink],
    ) -> None:
        self.name = name
        self.location = location
        self.drivers = drivers
        self.memory = memory
        self._publish = publish
        self._link = link

    def publish(self, topic: str, data: Any = None) -> None:
        """Publish external event ``topic`` to every subscriber of this node (never blocks)."""
        self._publish(topic, data)

    def link(self, node: str) -> NodeLink:
        """A shared, lazily connected link from this node to ``node`` (e.g. to stream set points)."""
        return self._link(node)


class CallContext:
    """Per-call context handed to :meth:`PrimitiveAction.run`.

    Attributes:
        call_id: the client-made call id.
        action: the action name.
        deadline: ``loop.time()`` at which the call is cut off, or ``None``.
        peer: name of the calling client.
        node: the hosting node's context.
    """

    __slots__ = ("_feedback", "_task", "action", "call_id", "deadline", "node", "peer")

    def __init__(
        self,
        *,
        call_id: str,
        action: str,
        deadline: float | None,
        peer: str,
        node: NodeContext,
        feedback: Callable[[Any], None],
    ) -> None:
        self.call_id = call_id
        self.action = action
        self.deadline = deadline
        self.peer = peer
        self.node = node
        self._feedback = feedback
        self._task: asyncio.Task[Any] | None = None

    def feedback(self, data: Any) -> None:
        """Send progress ``data`` (msgpack value) to the caller(s); never blocks."""
        self._feedback(data)

    @property
    def cancelled(self) -> bool:
        """True once a cancel request or the deadline has cut this call off."""
        return self._task is not None and self._task.cancelling() > 0

    def remaining(self) -> float | None:
        """Seconds left before the deadline, or ``None`` without a deadline."""
        if self.deadline is None:
            return None
        return max(0.0, self.deadline - asyncio.get_running_loop().time())

    @property
    def memory(self) -> MemoryAPI:
        """The global memory client."""
        return self.node.memory

    @property
    def drivers(self) -> Mapping[str, Driver]:
        """The node's drivers by name."""
        return self.node.drivers

    def find_driver(self, kind: type[_D]) -> _D | None:
        """The node's first driver of class ``kind`` (in services.toml order), or ``None``."""
        for driver in self.node.drivers.values():
            if isinstance(driver, kind):
                return driver
        return None

    def publish(self, topic: str, data: Any = None) -> None:
        """Publish external event ``topic`` from this node."""
        self.node.publish(topic, data)


class PrimitiveAction:
    """Base class of primitive actions; see the module docstring for the lifecycle."""

    name: str = ""
    unattended: bool = False
    """True if a call may finish when its caller is gone (a motion that must not stop halfway);
    otherwise the node cancels a call nobody has waited for during the heartbeat window, with reason
    ``"caller_gone"`` (docs/protocol.md §5). ``unattended = true`` in services.toml sets it too."""
    motion: bool = False
    """True if the action moves the robot: a call that loses its caller is cancelled at once, not
    after the heartbeat window, and the action brings the robot to rest when cancelled (it handles
    :class:`asyncio.CancelledError`); a caller silent for three heartbeat periods counts as lost
    (docs/protocol.md §5). Unless ``unattended``. ``motion = true`` in services.toml sets it too."""

    async def setup(self, node: NodeContext) -> None:
        """Prepare once at node start (drivers are already set up)."""

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        """Carry out one call.

        Args:
            params: the action's default params from services.toml, overridden by the call's.
            ctx: call context (feedback, cancellation, memory, drivers, publish).

        Returns:
            The outcome. Raising an exception makes the result ``error`` with the exception text.
        """
        raise NotImplementedError

    async def teardown(self) -> None:
        """Release resources once at node stop."""


ActionFunction = Callable[[dict[str, Any], CallContext], Awaitable[Any]]


class FunctionAction(PrimitiveAction):
    """Adapter: a plain ``async def f(params, ctx)`` as a :class:`PrimitiveAction`."""

    def __init__(self, fn: ActionFunction) -> None:
        if not inspect.iscoroutinefunction(fn):
            raise ActionError(f"{fn!r} is not an async function")
        self.fn = fn
        self.name = getattr(fn, "__name__", "")
        self.unattended = bool(getattr(fn, "unattended", False))
        self.motion = bool(getattr(fn, "motion", False))

    async def run(self, params: dict[str, Any], ctx: CallContext) -> ActionResult:
        out = await self.fn(params, ctx)
        return out if isinstance(out, ActionResult) else ActionResult.success(out)


def as_action(fn: ActionFunction) -> FunctionAction:
    """Decorator: turn ``async def f(params, ctx)`` into a primitive action object."""
    return FunctionAction(fn)


class Driver:
    """Base class of background components started with a node (hardware cards).

    Args:
        name: the name in services.toml (``[drivers.NAME]``).
        params: the ``params`` table of that section.
    """

    def __init__(self, name: str, params: Mapping[str, Any]) -> None:
        self.name = name
        self.params = dict(params)
        self.node: NodeContext | None = None

    def bind(self, node: NodeContext) -> None:
        """Attach the node context (called by the node before :meth:`setup`)."""
        self.node = node

    async def setup(self, node: NodeContext) -> None:
        """Start the component (open devices, start background tasks)."""

    async def teardown(self) -> None:
        """Stop the component."""

    def publish(self, topic: str, data: Any = None) -> None:
        """Publish external event ``topic`` from the hosting node.

        Raises:
            ActionError: the driver is not bound to a node yet.
        """
        if self.node is None:
            raise ActionError(f"driver {self.name!r} is not running on a node")
        self.node.publish(topic, data)


def import_impl(impl: str) -> Any:
    """Import the object named by ``"module:attr"`` (``attr`` may be dotted).

    Raises:
        ActionError: the module or attribute cannot be imported.
    """
    module_name, _, attr = impl.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ActionError(f"cannot import {impl!r}: {exc}") from exc
    return obj


def make_action(impl: str, name: str) -> PrimitiveAction:
    """Build the action object for services.toml's ``impl`` string.

    Accepts a :class:`PrimitiveAction` subclass (instantiated without arguments), an instance, or an
    async function.

    Raises:
        ActionError: the object is none of these.
    """
    obj = import_impl(impl)
    if isinstance(obj, type) and issubclass(obj, PrimitiveAction):
        action = obj()
    elif isinstance(obj, PrimitiveAction):
        action = obj
    elif inspect.iscoroutinefunction(obj):
        action = FunctionAction(obj)
    else:
        raise ActionError(f"{impl!r} is neither a PrimitiveAction nor an async function")
    if not action.name:
        action.name = name
    return action
