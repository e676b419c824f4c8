"""What every world process does around its simulation loop (``petrobot sim catching|mobile``; the
ROS 2 demo's processes, ``petrobot sim zenoh|ros2``, share its stop signals and its errors).

A world process serves the robot's hardware as a lab would have it (the camera behind a frame
server, the drives behind a socketcand CAN gateway) and prints one JSON line per event on stdout
(``ready``, the world's own events, ``drive_fault``, ``stopped``). :class:`WorldProcess` holds what
the two worlds share: stopping on SIGINT or SIGTERM, starting the two servers (a port that cannot
be bound is a :class:`ServeError` saying which server, where and why, e.g. "Address already in
use"), publishing camera frames with the wait for the camera client, announcing each drive fault
once its axis is at rest, the closing ``stopped`` line, and closing everything on the way out.
"""

from __future__ import annotations

import json
import math
import signal
import sys
import time
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any, Self, TextIO

from services.devices.framegrabber import Frame
from services.errors import PetrobotError
from sim.canbus import SimBus
from sim.drives import SimCanDrives
from sim.frameserver import FrameServer
from sim.socketcand import CanGateway

if TYPE_CHECKING:  # for annotations only: the ROS 2 processes use this module without pybullet
    from sim.world import World

__all__ = ["ServeError", "WorldProcess", "stop_on_signals"]


class ServeError(PetrobotError):
    """A world process cannot serve its camera, its CAN bus or its Zenoh router (the port is in use,
    the address is not one of this host's)."""


def stop_on_signals(stop: Callable[[], None]) -> Callable[[], None]:
    """Call ``stop`` (from the main thread) when SIGINT or SIGTERM arrives, instead of dying.

    Returns:
        A function that puts the previous handlers back.
    """

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for s, handler in old.items():
            signal.signal(s, handler)

    return restore


class WorldProcess:
    """Signals, servers and event lines of one world process; use it as a context manager.

    Args:
        world: the simulated world (closed on exit).
        out: where the JSON event lines go (default: stdout).
        camera_wait_s: in real time, wall time waited after each frame for a connected camera
            client to take it (0: never wait).
        lockstep: wait after each frame until a connected camera client took it (up to 1 s).
        skip_frozen_client: once a wait has run out, wait again only after the client took a frame
            (a frozen client costs one wait, then the world runs in real time).

    Attributes:
        stopping: SIGINT or SIGTERM arrived: the loop should end.
        server, gateway: the frame server and the CAN gateway, once :meth:`serve` started them.
        frames: frames published so far.
        camera_waits, camera_misses: waits for the camera client, and those that ran out.
    """

    def __init__(self, world: World, out: TextIO | None = None, *, camera_wait_s: float = 0.0,
                 lockstep: bool = False, skip_frozen_client: bool = False) -> None:
        self.world = world
        self.out = out if out is not None else sys.stdout
        self.camera_wait_s = camera_wait_s
        self.lockstep = lockstep
        self.skip_frozen_client = skip_frozen_client
        self.stopping = False
        self.server: FrameServer | None = None
        self.gateway: CanGateway | None = None
        self.frames = 0
        self.camera_waits = 0
        self.camera_misses = 0
        self._camera_in_step = True
        self._reported = 0
        self._closers: list[Callable[[], None]] = []
        self._restore_signals: Callable[[], None] = lambda: None
        self._t_wall0 = time.monotonic()

    def __enter__(self) -> Self:
        self._restore_signals = stop_on_signals(self._on_signal)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self.gateway is not None:
            self.gateway.stop()
        if self.server is not None:
            self.server.close()
        for close in reversed(self._closers):
            close()
        self.world.close()
        self._restore_signals()

    def _on_signal(self) -> None:
        self.stopping = True

    def on_close(self, close: Callable[[], None]) -> None:
        """Call ``close`` on the way out (before the world is closed)."""
        self._closers.append(close)

    def emit(self, event: str, **data: Any) -> None:
        """One JSON line ``{"event": event, ...data}`` on :attr:`out`, flushed."""
        self.out.write(json.dumps({"event": event, **data}) + "\n")
        self.out.flush()

    def serve(self, host: str, camera_port: int, info: dict[str, Any], bus: SimBus, can_port: int) -> tuple[int, int]:
        """Start the frame server (serving ``info``) and the CAN gateway of ``bus`` on ``host``.

        Returns:
            The camera and CAN ports (the ones chosen when given 0).

        Raises:
            ServeError: a server cannot listen there, naming it, the address and the reason.
        """
        self.server = FrameServer(host=host, port=camera_port, info=info)
        try:
            camera_port = self.server.start()
        except OSError as exc:
            self.server = None
            raise ServeError(f"cannot serve the camera on {host}:{camera_port}: {_why(exc)}") from exc
        self.gateway = CanGateway(bus, host=host, port=can_port)
        try:
            can_port = self.gateway.start()
        except OSError as exc:
            self.gateway = None
            raise ServeError(f"cannot serve the CAN bus on {host}:{can_port}: {_why(exc)}") from exc
        return camera_port, can_port

    def begin(self) -> None:
        """The loop starts: wall time counts from now, and the world's clock from here."""
        self._t_wall0 = time.monotonic()
        self.world.resync()

    def publish(self, frame: Frame) -> None:
        """Make ``frame`` the camera's latest, then wait for a connected camera client to take it
        (in lock-step, or up to ``camera_wait_s`` in real time)."""
        server = self.server
        assert server is not None
        server.publish(frame)
        self.frames += 1
        if not server.client_count:
            return
        if self.lockstep:
            server.wait_sent(frame.seq, timeout=1.0)
        elif self.camera_wait_s > 0 and (not self.skip_frozen_client or self._camera_in_step
                                         or server.wait_sent(frame.seq - 1, timeout=0.0)):
            self.camera_waits += 1
            self._camera_in_step = server.wait_sent(frame.seq, timeout=self.camera_wait_s)
            self.camera_misses += not self._camera_in_step

    def report_faults(self, drives: SimCanDrives[Any]) -> None:
        """A ``drive_fault`` line for each fault of ``drives`` whose axis came to rest since the last call."""
        faults = drives.faults
        while self._reported < len(faults) and not math.isnan(faults[self._reported].t_stopped):
            f = faults[self._reported]
            self.emit("drive_fault", t=f.t, node=f.node, code=f"{int(f.code):#06x}", reason=f.reason,
                      speed=f.speed, stop_s=f.t_stopped - f.t)
            self._reported += 1

    def stopped(self, drives: SimCanDrives[Any], **data: Any) -> None:
        """The closing ``stopped`` line: simulated and wall time, frames, the world's lag, the waits
        for the camera client and for the CAN master, the drive faults, and ``data``."""
        w = self.world
        self.emit("stopped", t=w.t, wall_s=time.monotonic() - self._t_wall0, frames=self.frames, **data,
                  max_lag_s=w.lag, slipped_s=w.slipped, camera_waits=self.camera_waits,
                  camera_misses=self.camera_misses, master_waits=drives.master_waits,
                  master_misses=drives.master_misses, drive_faults=len(drives.faults))


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc)
