"""The vision node against a real `sim catching` process: locate, predict, set points published as
node events, tick events, and a lost camera turning predict into an error (all on 127.0.0.1)."""

from __future__ import annotations

import asyncio
import json
import queue
import subprocess
import sys
import threading
import time
from typing import Any

import pytest
from tests.integration.cluster import ROOT, Cluster

from services.catching.setpoints import SETPOINT_TOPIC, LatestSetPoint

pytestmark = [pytest.mark.integration, pytest.mark.slow]

VISION_SERVICES = """
[nodes.vision]
host = "127.0.0.1"
port = {port[vision]}

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = {{ port = {port[camera]} }}

[actions.locate_threshold]
node = "vision"
impl = "services.catching.vision_node:LocateThreshold"

[actions.locate_bgdiff]
node = "vision"
impl = "services.catching.vision_node:LocateBgdiff"

[actions.locate_average]
node = "vision"
impl = "services.catching.vision_node:LocateAverage"

[actions.predict]
node = "vision"
impl = "services.catching.vision_node:Predict"

[events.image_sampling_tick]
node = "vision"
"""


class SimProcess:
    """`python -m coordinator.commands.sim catching` with its JSON event lines read by a thread."""

    def __init__(self, cluster: Cluster, *extra: str) -> None:
        cmd = [sys.executable, "-m", "coordinator.commands.sim", "catching", "--renderer", "analytic",
               "--camera-port", str(cluster.ports["camera"]), "--can-port", str(cluster.ports["can"]),
               "--throws", "1", "--interval", "100", *extra]
        self.proc = subprocess.Popen(cmd, cwd=ROOT, env=cluster.env(), stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                self.events.put(json.loads(line))

    def wait_event(self, name: str, timeout: float) -> dict[str, Any]:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                ev = self.events.get(timeout=max(0.01, end - time.monotonic()))
            except queue.Empty:
                break
            if ev["event"] == name:
                return ev
        raise AssertionError(f"sim sent no {name!r} event within {timeout} s")

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)


@pytest.fixture
def sim_factory(cluster: Cluster):
    sims: list[SimProcess] = []

    def make(*extra: str) -> SimProcess:
        s = SimProcess(cluster, *extra)
        sims.append(s)
        return s

    yield make
    for s in sims:
        s.kill()


def _holder(client: Any, node: str) -> LatestSetPoint:
    """Set points published by ``node`` (topic "setpoints"), kept latest-wins in a holder."""
    holder = LatestSetPoint(max_age=1e9)
    client.link(node).subscribe(SETPOINT_TOPIC, lambda ev: holder.offer_data(ev.data, time.time()))
    return holder


async def test_vision_node_locates_the_ball_and_publishes_its_predicted_crossing_as_set_points(
    cluster: Cluster, sim_factory
) -> None:
    cluster.write_services(VISION_SERVICES)
    sim = sim_factory("--first-throw", "2.5")
    await asyncio.to_thread(sim.wait_event, "ready", 60.0)
    cluster.start("vision", timeout=30.0)
    ticks: list[Any] = []
    async with cluster.client() as client:
        recv = _holder(client, "vision")
        client.subscribe("image_sampling_tick", lambda *a: ticks.append(a))
        loc = await client.call("locate_threshold", {"timeout_s": 15.0})
        assert loc.status == "success", loc
        assert -1.5 < loc.value["x"] < 0.0 and abs(loc.value["y"]) < 0.38
        assert loc.cost is not None and loc.cost > 0
        for action in ("locate_bgdiff", "locate_average"):
            res = await client.call(action, {"timeout_s": 5.0})
            assert res.status == "success", res
        avg = await client.call("locate_average", {"timeout_s": 5.0, "k": 3})
        assert avg.value["frames"] >= 3
        pred = await client.call("predict", {"timeout_s": 15.0})
        assert pred.status == "success", pred
    crossing = await asyncio.to_thread(sim.wait_event, "crossing", 10.0)
    assert abs(pred.value["y"] - crossing["y"]) < 0.01
    assert abs(pred.value["t"] - crossing["t"]) < 0.03
    assert pred.value["setpoints"] >= 10
    sp = recv.latest
    assert sp is not None and sp.seq == pred.value["setpoints"] - 1, (recv.received, recv.last_malformed)
    assert recv.malformed == 0
    assert abs(sp.y - crossing["y"]) < 0.01  # set points are in the table frame
    assert len(ticks) > 10


async def test_a_camera_lost_mid_prediction_makes_predict_an_error_until_it_comes_back(
    cluster: Cluster, sim_factory
) -> None:
    cluster.write_services(VISION_SERVICES)
    sim = sim_factory("--first-throw", "100")
    await asyncio.to_thread(sim.wait_event, "ready", 60.0)
    cluster.start("vision", timeout=30.0)
    async with cluster.client() as client:
        call = asyncio.create_task(client.call("predict", {"timeout_s": 30.0}))
        await asyncio.sleep(1.0)
        sim.kill()
        res = await asyncio.wait_for(call, 20.0)  # well before the call's own 30 s timeout
        assert (res.status, res.outcome) == ("error", "camera_lost"), res
        # the sim comes back on the same port: the next call reconnects the camera
        sim2 = sim_factory("--first-throw", "0.5")
        await asyncio.to_thread(sim2.wait_event, "ready", 60.0)
        again = await client.call("locate_threshold", {"timeout_s": 10.0})
        assert again.status == "success", again


async def test_predict_moved_to_a_node_without_the_camera_driver_still_publishes_set_points(
    cluster: Cluster, sim_factory
) -> None:
    moved = VISION_SERVICES.replace(
        '''[actions.predict]
node = "vision"
impl = "services.catching.vision_node:Predict"''',
        '''[nodes.motion]
host = "127.0.0.1"
port = {port[motion]}

[actions.predict]
node = "motion"
impl = "services.catching.vision_node:Predict"
params = {{ camera_port = {port[camera]} }}''',
    )
    assert moved != VISION_SERVICES
    cluster.write_services(moved)
    sim = sim_factory("--first-throw", "2.0")
    await asyncio.to_thread(sim.wait_event, "ready", 60.0)
    cluster.start("vision", "motion", timeout=30.0)
    async with cluster.client() as client:
        recv = _holder(client, "motion")  # the set points come from the node that hosts predict
        pred = await client.call("predict", {"timeout_s": 15.0})
    assert pred.status == "success", pred
    assert " predict from " in cluster.log("motion") and " predict from " not in cluster.log("vision")
    crossing = await asyncio.to_thread(sim.wait_event, "crossing", 10.0)
    assert abs(pred.value["y"] - crossing["y"]) < 0.01
    assert recv.received >= 10 and recv.malformed == 0


async def test_the_vision_node_reads_a_recorded_video_through_videocapture_as_it_reads_the_live_camera(
        cluster: Cluster) -> None:
    """Issue 24: a camera driver with an OpenCV source (here the catching camera's recording, played at
    its frame rate and looped, as a lab tests its own camera's recordings offline): the node locates
    the ball where the live frames had it and predicts the crossing the world recorded."""
    video = ROOT / "tests" / "data" / "catching_camera.mkv"
    recorded = json.loads(video.with_suffix(".json").read_text())
    cluster.write_services(VISION_SERVICES.replace(
        "params = {{ port = {port[camera]} }}",
        f'params = {{{{ source = "{video}", calibration = "{video.with_suffix(".json")}", loop = true }}}}'))
    cluster.start("vision", timeout=30.0)
    async with cluster.client() as client:
        loc = await client.call("locate_threshold", {"timeout_s": 10.0})
        pred = await client.call("predict", {"timeout_s": 10.0})
    assert loc.status == "success", loc
    seen = [f["detection"] for f in recorded["frames"] if f["detection"] is not None]
    assert [loc.value["u"], loc.value["v"]] in seen, loc.value  # a live frame's detection, to the bit
    assert pred.status == "success", pred
    truth = recorded["ground_truth"]
    assert abs(pred.value["y"] - truth["crossing_y"]) < 0.01, (pred.value, truth)
