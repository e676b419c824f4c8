"""Motion node actions (services/catching/motion_node.py) against the simulated PUMA over the CAN gateway,
with set points published by a real vision node on 127.0.0.1 and received through the motion
node's authenticated link (services/catching/setpoints.py). The ball is not simulated here: the crossfire
sensor reports a catch when the cup's rim sits where the set point said the ball would fall."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
import struct
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from puma_rig import SimRig

from services.action import CallContext, NodeContext
from services.catching.arm import PumaDriver, table_to_base
from services.catching.motion_node import Catch, MoveHome
from services.client import NodeLink
from services.devices import cia402 as cf
from services.location import parse_location
from services.node.server import Node
from services.catching.robot import motion_control as mc
from services.catching.robot import puma560 as P
from services.catching.setpoints import CatchSetPoint
from services.results import ActionResult
from sim.socketcand import CanGateway
from tests.ports import free_port

ROBOT_BASE = (0.75, 0.0, 0.46, math.pi)
KEY = bytes.fromhex("9c41e7d02b5f86a3147ed9c2058bf36e71a4d80c95e32fb6486a1dd7c0935e2b")
LOCATION = """
[nodes.vision]
host = "127.0.0.1"
port = {vision}

[nodes.motion]
host = "127.0.0.1"
port = {motion}
"""


def test_table_frame_set_points_map_into_the_robot_base_frame():
    xb, yb, vxb, vyb = table_to_base(0.0, 0.1, 0.9, 0.05, ROBOT_BASE)
    assert (xb, yb) == pytest.approx((0.75, -0.1))
    assert (vxb, vyb) == pytest.approx((-0.9, -0.05))


class Bench:
    """Sim rig + gateway + PumaDriver on a NodeContext, and a vision node publishing set points."""

    def __init__(self, tmp_path):
        self.rim_goal: np.ndarray | None = None
        self.t_rim = math.inf
        self.catchable = True
        self.rig = SimRig(tmp_path, crossfire=self._crossfire)  # paced to the master as the world is
        self.gw = CanGateway(self.rig.drives.bus)
        self.can_port = self.gw.start()
        self.rig.start()
        self.events: list[tuple[str, object]] = []
        self.location = parse_location(LOCATION.format(vision=free_port(), motion=free_port()))
        self.vision = Node("vision", self.location, KEY)
        self._links: dict[str, NodeLink] = {}
        self.driver = PumaDriver("puma", {"can_port": self.can_port, "robot_base": list(ROBOT_BASE),
                                          "heartbeat_timeout_s": 0.8, "setpoints_from": "vision"})
        self.ctx = NodeContext(
            name="motion",
            location=self.location,
            drivers={"puma": self.driver},
            memory=None,  # type: ignore[arg-type]
            publish=lambda topic, data: self.events.append((topic, data)),
            link=self._link,
        )
        self.driver.bind(self.ctx)
        self._sender: asyncio.Task[None] | None = None
        self.log_records: list[logging.LogRecord] = []
        self._handler = _Records(self.log_records)
        logging.getLogger("services").addHandler(self._handler)

    def _link(self, name: str) -> NodeLink:
        if name not in self._links:
            self._links[name] = NodeLink(name, self.location.address(name), KEY, name="node:motion")
        return self._links[name]

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

    def stream(self, y: float, lead_s: float, stop_after_s: float | None = None,
               bad: dict[str, Any] | None = None) -> None:
        """Publish set points at 100 Hz (wall) for a ball crossing the catch line lead_s from now (bus
        time), until stop_after_s of bus time has passed (the camera's clock: on a loaded machine the
        simulation, and with it the ball, runs slower than the wall clock); with ``bad``, every third
        set point has these fields replaced (malformed)."""
        t_cross = self.rig.t + lead_s
        vx = 0.9
        xb, yb, vxb, vyb = table_to_base(0.0, y, vx, 0.0, ROBOT_BASE)
        target = mc.catch_target(xb, yb, t_cross, vxb, vyb, P.Q_HOME, self.driver.geometry)
        self.rim_goal, self.t_rim = target.rim, target.t_rim

        async def run() -> None:
            t0 = self.rig.t  # bus time, as the ball's: a predictor stops when the ball reaches the line
            seq = 0
            while stop_after_s is None or self.rig.t - t0 <= stop_after_s:
                sp = CatchSetPoint(seq=seq, t_frame=self.rig.t, t_capture=time.time(), t_sent=time.time(),
                              x=0.0, y=y, t=t_cross, vx=vx, vy=0.0).to_dict()
                if bad is not None and seq % 3 == 2:
                    sp.update(bad)
                self.vision.publish("setpoints", sp)
                seq += 1
                await asyncio.sleep(0.01)

        self._sender = asyncio.get_running_loop().create_task(run())

    async def stop_stream(self) -> None:
        if self._sender is not None:
            self._sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._sender
            self._sender = None

    async def start(self) -> None:
        await self.vision.start()
        await self.driver.setup(self.ctx)
        self.driver.subscription()  # subscribe now: the first set points are not lost to the handshake
        link = self._link("vision")
        end = time.monotonic() + 10
        while not link.connected:
            assert time.monotonic() < end, "the motion side did not connect to the vision node"
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.1)

    async def close(self) -> None:
        logging.getLogger("services").removeHandler(self._handler)
        await self.stop_stream()
        await self.driver.teardown()
        for link in self._links.values():
            await link.close()
        await self.vision.stop()
        self.gw.stop()
        self.rig.close()


class _Records(logging.Handler):
    def __init__(self, records: list[logging.LogRecord]) -> None:
        super().__init__(logging.WARNING)
        self.records = records

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture
async def bench(tmp_path):
    b = Bench(tmp_path)
    await b.start()
    yield b
    await b.close()


async def _until(pred, what: str, timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, f"no {what} within {timeout} s"
        await asyncio.sleep(0.01)


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
async def test_a_ball_predicted_too_late_for_the_arm_is_a_miss_and_faults_no_drive(bench):
    bench.catchable = False
    bench.stream(y=0.34, lead_s=0.12)  # the far end of the catch line, 0.12 s ahead: out of reach in time
    out = await Catch().run({"timeout_s": 5.0, "miss_grace_s": 0.2}, bench.call("catch"))
    assert out.status == "failure" and out.outcome == "missed", out
    assert out.value["reach_s"] > out.value["lead_s"], out.value
    assert "too late" in (out.reason or "")
    await bench.stop_stream()
    home = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert home.status == "success" and home.value["recovered"] is None, home
    assert bench.rig.drives.faults == []
    assert bench.rig.drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6


@pytest.mark.timeout(60)
async def test_set_points_that_stop_mid_catch_make_the_watchdog_stop_the_arm_and_the_catch_an_error(bench):
    bench.stream(y=0.3, lead_s=3.0, stop_after_s=0.3)
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "error" and out.outcome == "stream_lost", out
    dog = out.value["watchdog"]
    assert dog is not None and dog["stale_s"] > 0.2 and dog["stop_s"] >= 0.0, out.value
    assert "watchdog stopped the arm" in (out.reason or "")
    # at rest where it stopped, not at the goal it was heading for
    q = np.asarray(bench.rig.drives.positions())
    await asyncio.sleep(0.2)
    assert np.allclose(bench.rig.drives.positions(), q, atol=5e-3)
    assert bench.rig.drives.faults == []


@pytest.mark.timeout(60)
async def test_malformed_set_points_are_dropped_and_counted_without_ending_the_catch(bench):
    bench.stream(y=0.1, lead_s=0.9, bad={"seq": float("inf"), "y": float("nan")})
    out = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert out.status == "success" and out.outcome == "caught", out
    assert out.value["malformed"] >= 3 and out.value["y_pred"] == pytest.approx(0.1)


@pytest.mark.timeout(60)
async def test_strangers_connecting_to_the_vision_node_during_a_catch_change_nothing(bench):
    from services.errors import AuthenticationError

    bench.stream(y=-0.15, lead_s=1.2)
    catch = asyncio.create_task(Catch().run({"timeout_s": 5.0}, bench.call("catch")))
    await asyncio.sleep(0.3)
    host, port = bench.location.address("vision")
    for _ in range(10):  # connect, then close at once (this ended a catch when set points had their own port)
        with socket.create_connection((host, port), timeout=2.0):
            pass
    intruder = NodeLink("vision", (host, port), bytes(32), name="intruder", connect_timeout_s=1.0)
    with pytest.raises(AuthenticationError):  # no key, no connection: nothing can be injected
        await intruder.connect()
    await intruder.close()
    out = await catch
    assert out.status == "success" and out.value["y_pred"] == pytest.approx(-0.15), out
    assert out.value["malformed"] == 0


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
async def test_move_home_resets_drives_that_faulted_when_the_master_went_silent(bench):
    drives = bench.driver.drives
    assert drives is not None
    drives.send_targets = lambda q: None  # the master stops commanding (its thread keeps running)
    await _until(lambda: all(s is cf.DriveState.FAULT for s in bench.rig.drives.states()), "drive faults")
    assert {f.code for f in bench.rig.drives.faults} == {cf.EmcyCode.RPDO_TIMEOUT}
    del drives.send_targets
    out = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert out.status == "success", out
    assert "fault reset" in out.value["recovered"] and "RPDO timeout" in out.value["recovered"]
    assert bench.rig.drives.states() == [cf.DriveState.OPERATION_ENABLED] * 6
    assert bench.driver.recoveries == 1
    again = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert again.status == "success" and again.value["recovered"] is None, again


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
async def test_a_new_catch_waits_for_the_next_stream_after_the_last_one_ended(bench):
    bench.stream(y=0.1, lead_s=0.6, stop_after_s=0.55)
    first = await Catch().run({"timeout_s": 5.0}, bench.call("catch"))
    assert first.status == "success", first
    await bench.stop_stream()
    second = asyncio.create_task(Catch().run({"timeout_s": 5.0}, bench.call("catch")))
    await asyncio.sleep(0.3)
    assert not second.done()
    bench.stream(y=-0.2, lead_s=0.7)
    out = await second
    assert out.status == "success" and out.value["y_pred"] == pytest.approx(-0.2), out


# --- devices taken over on the bus (a CAN bus has no keys: the master detects, it cannot prevent) ----------


def _rpdo1(node: int, controlword: int, target_counts: int) -> cf.CanFrame:
    """RPDO1 of the drives' default mapping (controlword, target position), as a second master sends it."""
    return cf.CanFrame(0x200 + node, struct.pack("<Hi", controlword, target_counts))


async def _catch_with(bench: Bench, inject: Callable[[Any], None]) -> tuple[ActionResult, float]:
    """Run a catch; 0.3 s into it ``inject(port)`` puts frames on the bus as another station would.
    Returns the result and the bus time of the injection."""
    bench.stream(y=0.2, lead_s=2.5)
    catch = asyncio.create_task(Catch().run({"timeout_s": 5.0}, bench.call("catch")))
    await asyncio.sleep(0.3)
    assert not catch.done(), catch.result()
    port = bench.rig.drives.bus.connect()
    t_inject = bench.rig.t
    inject(port)
    out = await catch
    port.close()
    return out, t_inject


@pytest.mark.timeout(60)
async def test_an_nmt_stop_from_another_station_mid_catch_is_an_error_within_a_heartbeat_period(bench):
    out, t_inject = await _catch_with(bench, lambda port: port.send(cf.nmt_frame(cf.NmtCommand.STOP, 0)))
    assert out.status == "error" and out.outcome == "bus", out
    assert "another station on the CAN bus sent NMT 'stop' to all nodes" in (out.reason or ""), out
    assert bench.driver.bus_time() - t_inject <= 0.1 + 0.01  # noticed within one heartbeat period of bus time
    logged = "\n".join(r.getMessage() for r in bench.log_records)
    assert "sent NMT 'stop'" in logged
    # the next action starts the drives again (a stop is no takeover): move_home succeeds
    home = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert home.status == "success" and "NMT 'stop'" in home.value["recovered"], home


@pytest.mark.timeout(60)
async def test_a_second_master_s_rpdos_mid_catch_are_an_error_and_block_recovery_while_they_come(bench):
    def second_master(port: Any) -> None:
        port.send(_rpdo1(4, 0x0F, 0))  # one frame is enough to be seen

    out, t_inject = await _catch_with(bench, second_master)
    assert out.status == "error" and out.outcome == "bus", out
    assert "sends RPDO 0x204 to drive 4: a second master" in (out.reason or ""), out
    assert bench.driver.bus_time() - t_inject <= 0.1 + 0.01
    home = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert home.status == "error" and "second master" in (home.reason or ""), home  # no fighting over the drives
    await asyncio.sleep(1.1)  # its RPDOs stopped a second ago: the master takes the drives back
    home = await MoveHome().run({"timeout_s": 5.0}, bench.call("move_home"))
    assert home.status == "success", home
