"""Test helpers: a pybullet PUMA 560 on its simulated CAN bus, stepped by hand or in real time; a
control loop answering every SYNC, as the PUMA driver's control thread does."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

import pybullet
from pybullet_utils import bullet_client

from services.catching.robot import puma560 as K
from sim.catching import puma560 as P
from sim.catching.drives import SimDrives


REALTIME_MASTER_WAIT_S = 0.1
"""In real time the rig waits this long (wall) at a SYNC for a master in step, as ``petrobot sim`` does
(``--master-wait-ms`` 100): without it a rig that fell behind the wall clock caught up in a burst of up
to 50 SYNCs that a master thread starved by a loaded machine could not answer, and its drives faulted on
their RPDO deadline (50 ms) although the master was alive (the world never charges a master with its
own bursts)."""


class SimRig:
    """A pybullet PUMA with SimDrives, stepped by hand or by a real-time thread (which paces the bus to
    the master as the world does, :data:`REALTIME_MASTER_WAIT_S`, unless ``master_wait_s`` is given)."""

    def __init__(self, tmp_path, q0=K.Q_HOME, crossfire: Callable[[], bool] | None = None, **drive_options):
        self.pb = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        self.pb.setGravity(0, 0, -9.81)
        self.pb.setPhysicsEngineParameter(fixedTimeStep=0.001)
        body, joints, _ = P.load(self.pb, P.write_urdf(tmp_path / "puma.urdf"))
        for j, q in zip(joints, q0):
            self.pb.resetJointState(body, j, float(q))
        self.crossfire_state = False
        self._paced = "master_wait_s" in drive_options
        self.drives = SimDrives(**drive_options)
        self.drives.attach(self.pb, body, joints, crossfire=crossfire or (lambda: self.crossfire_state))
        self.t = 0.0
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.running = threading.Event()

    def step(self, n=1):
        with self.lock:
            for _ in range(n):
                self.drives.step(self.t)
                self.pb.stepSimulation()
                self.t = round(self.t + 0.001, 9)

    def start(self):
        if not self._paced:
            self.drives.master_wait_s = REALTIME_MASTER_WAIT_S
        self.running.set()

        def loop():
            t0 = time.monotonic()
            sim0 = self.t
            while not self._stop.is_set():
                if not self.running.is_set():
                    time.sleep(0.005)
                    t0, sim0 = time.monotonic(), self.t
                    continue
                self.step(2)
                ahead = (self.t - sim0) - (time.monotonic() - t0)
                if ahead > 0:
                    time.sleep(ahead)
                elif ahead < -0.1:  # too far behind: slip instead of racing (as sim.world does)
                    t0, sim0 = time.monotonic(), self.t

        self._thread = threading.Thread(target=loop, daemon=True)
        self._thread.start()

    def close(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.pb.disconnect()


SWITCH_INTERVAL_S = 0.001
"""The interpreter's thread switch interval of the motion node (services.catching.arm, param
``switch_interval_s``): the control thread answers a SYNC every 2 ms beside the CAN receive thread."""


class ControlLoop:
    """A thread answering every SYNC with the targets :attr:`q` (at first the drives' resting positions),
    as the PUMA driver's control thread does; start it before :meth:`CanDrives.enable` (a drive enabled
    without targets flowing faults on its RPDO deadline). A context manager; a bus error in the thread
    is raised on exit and by :meth:`wait`."""

    def __init__(self, drives) -> None:
        self.drives = drives
        self.q = drives.positions()
        self.answered = 0
        self.error: Exception | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        from services.devices.drives import BusError

        try:
            while not self._stop.is_set():
                self.drives.wait_sync(timeout=5.0)
                self.drives.send_targets(self.q)
                self.answered += 1
        except BusError as exc:
            self.error = exc

    def wait(self, cycles: int, timeout: float = 20.0) -> None:
        """Until ``cycles`` more SYNCs were answered."""
        end = self.answered + cycles
        deadline = time.monotonic() + timeout
        while self.answered < end:
            if self.error is not None:
                raise self.error
            assert time.monotonic() < deadline, "the control loop stalled"
            time.sleep(0.005)

    def __enter__(self) -> ControlLoop:
        if sys.getswitchinterval() > SWITCH_INTERVAL_S:  # as the PUMA driver sets it in the motion node
            sys.setswitchinterval(SWITCH_INTERVAL_S)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        if self.error is not None:
            raise self.error
