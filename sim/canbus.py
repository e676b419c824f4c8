"""The simulated CAN bus: ports that share every frame, and the inbound queue of the sim's devices.

Frames sent by one port (an in-process client, or one connection of the socketcand gateway,
:class:`sim.socketcand.CanGateway`) reach every other port and the devices of the sim (the
simulated drives, :mod:`sim.drives`), as on a real bus. Frame layout: :mod:`services.devices.cia402`.

Threads: any thread may send; the sim's devices drain their inbound queue from the simulation
thread (:meth:`SimBus.take_inbound`, :meth:`SimBus.wait_inbound`), except the frames a device asked
to take at once (:meth:`SimBus.take_at_once`: SDO requests, which a real device answers within a
millisecond whatever the simulation is busy with), handed to it in the sender's thread.
"""

from __future__ import annotations

import dataclasses
import queue
import threading

from collections.abc import Callable, Container

from services.devices import cia402 as cf

__all__ = ["BusPort", "SimBus"]


class BusPort:
    """One attachment to a :class:`SimBus` (an in-process client or a gateway connection).

    Frames sent by one port reach the bus devices and every other port (not the sender), as on a
    real bus. Received frames wait in a bounded queue; on overflow the newest is dropped and
    :attr:`overruns` counts it.
    """

    def __init__(self, bus: SimBus, maxsize: int = 20000) -> None:
        self._bus = bus
        self._queue: queue.Queue[cf.CanFrame] = queue.Queue(maxsize=maxsize)
        self.overruns = 0
        self.closed = False

    def send(self, frame: cf.CanFrame) -> None:
        """Put a frame on the bus."""
        self._bus.transmit(frame, origin=self)

    def recv(self, timeout: float | None = None) -> cf.CanFrame | None:
        """Next frame from the bus, or ``None`` after ``timeout`` seconds (``None``: wait)."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def recv_all(self) -> list[cf.CanFrame]:
        """Every frame waiting now (non-blocking)."""
        out = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out

    def _deliver(self, frame: cf.CanFrame) -> None:
        try:
            self._queue.put_nowait(frame)
        except queue.Full:
            self.overruns += 1

    def close(self) -> None:
        """Detach from the bus."""
        self.closed = True
        self._bus.detach(self)


class SimBus:
    """A simulated CAN bus: fan-out between ports plus an inbound queue for the sim's devices.

    Every frame a port receives carries the bus's time (the simulated time of the latest frame a sim
    device sent), as every station of a real bus sees one gateway's receive clock: a frame that a
    port sent is stamped with it on the way to the other ports, whatever clock its sender used.
    """

    def __init__(self) -> None:
        self._ports: list[BusPort] = []
        self._lock = threading.Lock()
        self._inbound: queue.SimpleQueue[cf.CanFrame] = queue.SimpleQueue()
        self._at_once: tuple[Container[int], Callable[[cf.CanFrame], None]] | None = None
        self._now = 0.0  # bus time: the latest sim device frame's

    def take_at_once(self, ids: Container[int], handler: Callable[[cf.CanFrame], None]) -> None:
        """Hand frames with these identifiers that ports send to ``handler`` in the sender's thread,
        instead of queueing them for the simulation thread (the handler must be thread-safe)."""
        self._at_once = (ids, handler)

    def connect(self) -> BusPort:
        """A new port on the bus."""
        port = BusPort(self)
        with self._lock:
            self._ports.append(port)
        return port

    def detach(self, port: BusPort) -> None:
        """Remove a port (idempotent)."""
        with self._lock:
            if port in self._ports:
                self._ports.remove(port)

    def transmit(self, frame: cf.CanFrame, origin: BusPort | None = None) -> None:
        """Put a frame on the bus from a port (``origin``) or from a sim device (``None``)."""
        with self._lock:
            ports = list(self._ports)
            if origin is None:
                self._now = frame.t
            now = self._now
        seen = frame
        for port in ports:
            if port is not origin:
                if seen.t != now:  # restamped once, and only when another port takes it
                    seen = dataclasses.replace(frame, t=now)
                port._deliver(seen)
        if origin is not None:
            at_once = self._at_once
            if at_once is not None and frame.can_id in at_once[0]:
                at_once[1](frame)
            else:
                self._inbound.put(frame)

    def wait_inbound(self, timeout: float) -> cf.CanFrame | None:
        """The next frame sent by a port, waiting up to ``timeout`` s; ``None`` if none came."""
        try:
            return self._inbound.get(timeout=max(timeout, 0.0))
        except queue.Empty:
            return None

    def take_inbound(self) -> list[cf.CanFrame]:
        """Frames sent by ports since the last call (for the sim's devices)."""
        out = []
        while True:
            try:
                out.append(self._inbound.get_nowait())
            except queue.Empty:
                return out
