"""Motion node actions (services/actions/motion.py) against the simulated PUMA over the CAN gateway,
with a real set-point stream (services/stream.py). The ball is not simulated here: the crossfire
sensor reports a catch when the cup's rim sits where the set point said the ball would fall."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import numpy as np
import pytest
from puma_rig import SimRig

from services.robots import motion_control as mc
from services.action import CallContext, NodeContext
from services.actions.motion import Catch, MoveHome, PumaDriver, table_to_base
from services.location import parse_location
from services.stream import SetPointSender
from services.robots import puma560 as P
from sim.canbus import CanGateway

ROBOT_BASE = (0.75, 0.0, 0.46, math.pi)
LOCATION = """
[nodes.motion]
host = "127.0.0.1"
port = 7199
"""


def test_table_frame_set_points_map_into_the_robot_base_frame():
    xb, yb, vxb, vyb = table_to_base(0.0, 0.1, 0.9, 0.05, ROBOT_BASE)
    assert (xb, yb) == pytest.approx((0.75, -0.1))
    assert (vxb, vyb) == pytest.approx((-0.9, -0.05))


class Bench:
    """Sim rig + gateway + PumaDriver on a NodeContext, and a set-point sender thread."""

    def __init__(self, tmp_path):
        self.rim_goal: np.ndarray | None = None
        self.t_rim = math.inf
        self.catchable = True
        self.rig = SimRig(tmp_path, crossfire=self._crossfire)
        self.gw = CanGateway(self.rig.drives.bus)
        self.can_port = self.gw.start()
        self.rig.start()
        self.events: list[tuple[str, object]] = []
        self.driver = PumaDriver(
            "puma", {"can_port": self.can_port, "robot_base": list(ROBOT_BASE), "heartbeat_timeout_s": 0.8}
        )
        self.ctx = NodeContext(
            name="motion",
            location=parse_location(LOCATION),
            drivers={"puma": self.driver},
            memory=None,
            publish=lambda topic, data: self.events.append((topic, data)),
            link=None,
        )  # type: ignore[arg-type]
        self.driver.bind(self.ctx)
        self._stop = threading.Event()
        self._sender: threading.Thread | None = None

    def _crossfire(self) -> bool:
        if self.rim_goal is None or not self.catchable or self.rig.t < self.t_rim:
            return False
        t = P.fk(self.rig.drives.positions())
        rim = t[:3, 3] + P.CUP_RIM_OFFSET * t[:3, 2]
        return bool(np.linalg.norm(rim - self.rim_goal) < 0.01)

    def call(self, action: str) -> CallContext:
        return CallContext(
            call_id=f"{action}-{time.monotonic()}",
            action=action,
            deadline=None,
            peer="test",
            node=self.ctx,
            feedback=lambda data: None,
        )

    def stream(self, y: float, lead_s: float, stop_after_s: float | None = None) -> None:
        """Stream set points at 100 Hz for a ball crossing the catch line lead_s from now."""
        t_cross = self.rig.t + lead_s
        vx = 0.9
        xb, yb, vxb, vyb = table_to_base(0.0, y, vx, 0.0, ROBOT_BASE)
        target = mc.catch_target(xb, yb, t_cross, vxb, vyb, P.Q_HOME, self.driver.geometry)
        self.rim_goal, self.t_rim = target.rim, target.t_rim
        sender = SetPointSender("127.0.0.1", self.driver.receiver.port)

        def run() -> None:
            t0 = time.monotonic()
            try:
                while not self._stop.is_set():
                    if stop_after_s is not None and time.monotonic() - t0 > stop_after_s:
                        return
                    sender.send(
                        t_frame=self.rig.t, t_capture=time.time(), x=0.0, y=y, t=t_cross, vx=vx, vy=0.0
                    )
                    time.sleep(0.01)
            finally:
                sender.close()

        self._sender = threading.Thread(target=run, daemon=True)
        self._sender.start()

    async def close(self) -> None:
        self._stop.set()
        if self._sender is not None:
            self._sender.join(timeout=2)
        await self.driver.teardown()
        self.gw.stop()
        self.rig.close()


@pytest.fixture
async def bench(tmp_path):
    b = Bench(tmp_path)
    await b.driver.setup(b.ctx)
    yield b
    await b.close()


@pytest.mark.timeout(60)
async def test_catch_succeeds_when_the_crossfire_fires_and_publishes_ball_caught(bench):
    bench.stream(y=0.15, lead_s=0.8)
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "success" and out.outcome == "caught", out
    assert out.value["set_points"] >= 1 and out.value["y_pred"] == pytest.approx(0.15)
    assert out.value["t_caught"] >= bench.t_rim
    topics = [topic for topic, _ in bench.events]
    assert topics == ["ball_caught"]


@pytest.mark.timeout(60)
async def test_a_missed_ball_is_a_failure_once_it_has_passed(bench):
    bench.catchable = False
    bench.stream(y=-0.1, lead_s=0.6)
    out = await Catch().run({"timeout_s": 5.0, "miss_grace_s": 0.2}, bench.call("catch"))
    assert out.status == "failure" and out.outcome == "missed", out
    assert bench.rig.t >= bench.t_rim + 0.2


@pytest.mark.timeout(60)
async def test_a_stream_that_stops_before_the_ball_arrives_is_an_error(bench):
    bench.stream(y=0.0, lead_s=3.0, stop_after_s=0.3)
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "error" and out.outcome == "stream_lost", out


@pytest.mark.timeout(60)
async def test_catch_without_any_set_point_times_out_as_an_error(bench):
    out = await Catch().run({"timeout_s": 0.5}, bench.call("catch"))
    assert out.status == "error" and out.outcome == "stream_lost", out


@pytest.mark.timeout(60)
async def test_move_home_returns_the_cup_to_mid_catch_line(bench):
    bench.stream(y=0.3, lead_s=0.5)
    await Catch().run({"timeout_s": 3.0}, bench.call("catch"))
    out = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert out.status == "success", out
    assert np.allclose(bench.rig.drives.positions(), mc.home_pose(bench.driver.geometry), atol=0.01)


@pytest.mark.timeout(60)
async def test_a_stopped_simulation_turns_the_catch_into_a_bus_error(bench):
    bench.stream(y=0.0, lead_s=3.0)
    await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    bench.rig.running.clear()
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "error" and out.outcome == "bus", out


@pytest.mark.timeout(60)
async def test_a_stream_that_ends_as_the_ball_reaches_the_line_keeps_the_last_set_point(bench):
    bench.stream(y=0.1, lead_s=0.8, stop_after_s=0.72)
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "success" and out.outcome == "caught", out


@pytest.mark.timeout(60)
async def test_a_new_catch_waits_for_the_next_stream_after_the_last_one_closed(bench):
    bench.stream(y=0.1, lead_s=0.6, stop_after_s=0.55)
    first = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert first.status == "success", first
    bench._sender.join(timeout=2)
    second = asyncio.create_task(Catch().run({"timeout_s": 5.0}, bench.call("catch")))
    await asyncio.sleep(0.3)
    assert not second.done()
    bench.stream(y=-0.2, lead_s=0.7)
    out = await second
    assert out.status == "success" and out.value["y_pred"] == pytest.approx(-0.2), out
