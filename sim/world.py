"""A pybullet world stepped at a fixed rate, with a lock-step or real-time clock.

The world owns one pybullet client in DIRECT mode (no GUI, no shared memory) and advances it in fixed
steps of ``dt`` seconds (1 kHz by default). Two clock modes:

* **lock-step** — simulated time advances only when the caller asks (:meth:`World.step`,
  :meth:`World.advance`); tests and benchmarks use it, so results do not depend on the machine's load.
* **real-time** — :meth:`World.advance` paces the steps to the wall clock (the demo), sleeping when the
  simulation is ahead and reporting how far it fell behind when the machine is too slow.

Other parts of the simulation hook into the step loop with :meth:`World.add_step_hook`: a hook is
called *before* every physics step with the simulated time of that step (the joint drives of the CAN
bus apply their torques there; air drag is applied there as an external force, since pybullet clears
external forces after each step).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from enum import Enum
from typing import Any, Self

import pybullet
from pybullet_utils import bullet_client

__all__ = ["ClockMode", "StepHook", "World"]

StepHook = Callable[[float], None]
"""A function called before each physics step with the simulated time t (s) of the step's start."""


class ClockMode(Enum):
    """How simulated time relates to the wall clock."""

    LOCKSTEP = "lockstep"
    """Time advances only when the caller steps the world; as fast as the machine allows."""
    REALTIME = "realtime"
    """:meth:`World.advance` sleeps so that simulated time keeps pace with the wall clock."""


class World:
    """A pybullet world (DIRECT mode) with a fixed step and a clock.

    Args:
        dt: physics step in seconds (default 0.001, i.e. 1 kHz).
        mode: lock-step or real-time pacing.
        gravity: gravitational acceleration along -z, m/s².
        solver_iterations: pybullet constraint-solver iterations per step.
        wall_clock: function returning wall time in seconds (default :func:`time.monotonic`);
            used only in real-time mode.
        sleep: function sleeping a number of seconds (default :func:`time.sleep`).
        max_lag: real-time mode: when simulated time falls further than this (s) behind the wall
            clock (an overloaded machine), the world gives up catching up and slips: it takes the
            present instant as the present simulated time (the slipped time is in :attr:`slipped`).

    Attributes:
        client: the :class:`pybullet_utils.bullet_client.BulletClient` of this world; pass it to the
            parts that build bodies in it.
        t: simulated time in seconds since the world was made.
        steps: number of physics steps taken.
        lag: in real-time mode, the largest amount (s) by which simulated time has fallen behind the
            wall clock; 0 in lock-step mode.
        slipped: in real-time mode, the total wall-clock time (s) given up by slips (see max_lag).
    """

    def __init__(
        self,
        dt: float = 0.001,
        mode: ClockMode = ClockMode.LOCKSTEP,
        *,
        gravity: float = 9.81,
        solver_iterations: int = 50,
        wall_clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        max_lag: float = 0.1,
    ) -> None:
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        self.dt = float(dt)
        self.mode = mode
        self.gravity = float(gravity)
        self.client: Any = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        self.client.setGravity(0.0, 0.0, -self.gravity)
        self.client.setPhysicsEngineParameter(
            fixedTimeStep=self.dt, numSubSteps=0, numSolverIterations=solver_iterations
        )
        self.steps = 0
        self.lag = 0.0
        self.slipped = 0.0
        self.max_lag = max_lag
        self._hooks: list[StepHook] = []
        self._wall_clock = wall_clock
        self._sleep = sleep
        self._wall_origin: float | None = None
        self._t_origin = 0.0

    @property
    def t(self) -> float:
        """Simulated time (s) since the world was made."""
        return self.steps * self.dt

    def add_step_hook(self, hook: StepHook) -> None:
        """Call ``hook(t)`` before every physics step, in the order hooks were added."""
        self._hooks.append(hook)

    def remove_step_hook(self, hook: StepHook) -> None:
        """Stop calling ``hook``; raises ValueError if it was never added."""
        self._hooks.remove(hook)

    def step(self, n: int = 1) -> None:
        """Take ``n`` physics steps at once, without pacing (any mode)."""
        for _ in range(n):
            t = self.t
            for hook in self._hooks:
                hook(t)
            self.client.stepSimulation()
            self.steps += 1

    def advance(self, duration: float) -> None:
        """Advance simulated time by ``duration`` seconds (rounded to whole steps).

        In lock-step mode this is :meth:`step` of the right count. In real-time mode the steps are
        paced so that simulated time never runs ahead of the wall clock measured since the first
        call to :meth:`advance` (or the last :meth:`resync`).
        """
        n = max(0, round(duration / self.dt))
        if self.mode is ClockMode.LOCKSTEP:
            self.step(n)
            return
        if self._wall_origin is None:
            self.resync()
        assert self._wall_origin is not None
        for _ in range(n):
            target = self._wall_origin + (self.t + self.dt - self._t_origin)
            now = self._wall_clock()
            if now < target:
                self._sleep(target - now)
            else:
                behind = now - target
                self.lag = max(self.lag, behind)
                if behind > self.max_lag:
                    self.slipped += behind
                    self._wall_origin = now
                    self._t_origin = self.t + self.dt
            self.step()

    def resync(self) -> None:
        """Real-time mode: take the present wall-clock instant as the present simulated time."""
        self._wall_origin = self._wall_clock()
        self._t_origin = self.t

    def close(self) -> None:
        """Disconnect the pybullet client; the world cannot be used afterwards."""
        try:
            self.client.disconnect()
        except pybullet.error:
            pass

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
