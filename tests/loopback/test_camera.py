"""Camera back ends (TinyRenderer, analytic) and the TCP frame server on 127.0.0.1."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from services.catching.vision import calibration_points, locate_threshold
from services.devices.endpoint import DeviceEndpoint
from services.devices.framegrabber import Frame, FrameClient
from services.devices.probe import probe
from sim.catching.camera import (
    AnalyticRenderer,
    TinyRenderer,
    calibrate,
    overhead_camera,
)
from sim.catching.world import CatchingWorld
from sim.frameserver import FrameServer
from sim.world import World


def test_tiny_renderer_sees_the_ball_where_the_calibrated_map_says_at_320_by_240():
    world = World()
    try:
        cw = CatchingWorld(world)
        cam = overhead_camera(width=320, height=240)
        tiny = TinyRenderer(cam, world.client, intensity_sigma=2.0)
        z = cw.ball_plane_z

        def render_at(x: float, y: float) -> np.ndarray:
            cw.pb.resetBasePositionAndOrientation(cw.ball_id, [x, y, z], [0, 0, 0, 1])
            return tiny.render()

        hom = calibrate(render_at, calibration_points(1.5, 0.76, nx=4, ny=3))
        assert hom.rms_m < 0.003
        img = render_at(-0.42, -0.17)
        assert img.shape == (240, 320, 3) and img.dtype == np.uint8
        d = locate_threshold(img, 0.0)
        assert d is not None
        assert np.hypot(*(hom.to_table([d.u, d.v]) - [-0.42, -0.17])) < 0.004
    finally:
        world.close()


def test_analytic_renderer_noise_has_the_configured_sigma():
    r = AnalyticRenderer(overhead_camera(width=320, height=240), intensity_sigma=3.0)
    diff = r.render(None).astype(float) - r.noiseless_background().astype(float)
    assert float(diff.std()) == pytest.approx(3.0, rel=0.15)


def test_frame_server_hands_out_the_latest_frame_and_waits_for_a_newer_one():
    server = FrameServer()
    port = server.start()
    client = FrameClient("127.0.0.1", port)
    try:
        assert client.grab(after=-1, timeout=0.05) is None
        img = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
        server.publish(Frame(0, 0.00, img))
        server.publish(Frame(1, 0.02, img + 1))
        f = client.grab(after=-1, timeout=30.0)
        assert f is not None and f.seq == 1 and f.t == 0.02
        np.testing.assert_array_equal(f.image, img + 1)
        timer = threading.Timer(0.05, server.publish, args=(Frame(2, 0.04, img),))
        timer.start()
        f2 = client.grab(after=1, timeout=30.0)  # returns as soon as frame 2 is published
        assert f2 is not None and f2.seq == 2
        timer.join()
    finally:
        client.close()
        server.close()


def test_a_probe_is_answered_and_is_no_camera_client_the_world_waits_for():
    server = FrameServer(info={"fps": 25.0})
    port = server.start()
    client = FrameClient("127.0.0.1", port)
    try:
        assert probe(DeviceEndpoint("camera server", "127.0.0.1", port, "petrobot sim catching", "frames")) is None
        assert client.info() == {"fps": 25.0}
        assert server.client_count == 0  # connected and asked its info: no frame taken yet
        server.publish(Frame(0, 0.0, np.zeros((2, 2, 3), dtype=np.uint8)))
        assert client.grab(after=-1, timeout=30.0) is not None
        assert server.client_count == 1
        closed = DeviceEndpoint("camera server", "127.0.0.1", 1, "petrobot sim catching", "frames")
        assert probe(closed) is not None
    finally:
        client.close()
        server.close()


def test_frame_client_sees_a_closed_server_as_a_connection_error():
    server = FrameServer()
    port = server.start()
    client = FrameClient("127.0.0.1", port)
    server.close()
    with pytest.raises((ConnectionError, OSError)):
        for _ in range(3):
            client.grab(timeout=0.1)
    client.close()


@pytest.mark.timeout(60)
def test_five_hundred_idle_connections_cost_a_bounded_number_of_threads_and_lock_no_grabber_out():
    server = FrameServer()  # as the worlds start it: at most 16 connections
    port = server.start()
    img = np.zeros((2, 2, 3), dtype=np.uint8)
    stop = threading.Event()
    grabbed: list[int] = []
    failed: list[BaseException] = []

    def camera() -> None:
        seq = 0
        while not stop.wait(0.005):
            server.publish(Frame(seq, seq * 0.005, img))
            seq += 1

    def grabber() -> None:  # a node's grabber, connected before the flood and grabbing through it
        client = FrameClient("127.0.0.1", port)
        try:
            seq = -1
            while not stop.is_set():
                f = client.grab(after=seq, timeout=1.0)
                if f is not None:
                    seq = f.seq
                    grabbed.append(f.seq)
        except (ConnectionError, OSError) as exc:
            failed.append(exc)
        finally:
            client.close()

    before = threading.active_count()
    workers = [threading.Thread(target=camera), threading.Thread(target=grabber)]
    for w in workers:
        w.start()
    idle: list[socket.socket] = []
    most = 0
    try:
        while len(grabbed) < 3:
            time.sleep(0.01)
        for _ in range(500):
            idle.append(socket.create_connection(("127.0.0.1", port), timeout=5.0))
            most = max(most, threading.active_count())
        n = len(grabbed)
        while len(grabbed) < n + 3:  # the grabber goes on taking frames after the flood
            time.sleep(0.01)
        late = FrameClient("127.0.0.1", port)  # and a client connecting after it gets in
        try:
            assert late.grab(after=-1, timeout=30.0) is not None
        finally:
            late.close()
    finally:
        stop.set()
        for w in workers:
            w.join(timeout=5.0)
        for s in idle:
            s.close()
        server.close()
    assert not failed, failed
    # the test's two threads, the accept loop and at most max_clients serving threads (+1 being joined)
    assert most <= before + 2 + 1 + 16 + 1, (most, before)
    assert server.connection_count == 0
