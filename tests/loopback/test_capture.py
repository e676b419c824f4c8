"""Cameras through OpenCV's VideoCapture: the recorded catching camera gives the detections of the
live frames it was recorded from; sources from services.toml params; recordings bit for bit."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from services.catching.camera import VisionConfig
from services.catching.vision import locate_threshold
from services.devices.capture import CaptureClient, CaptureSpec, record
from services.devices.framegrabber import Frame
from services.devices.probe import device_endpoints
from services.location import parse_location

ROOT = Path(__file__).resolve().parents[2]
VIDEO = ROOT / "tests" / "data" / "catching_camera.mkv"
RECORDED = json.loads(VIDEO.with_suffix(".json").read_text())


def _play(**options: object) -> CaptureClient:
    return CaptureSpec(str(VIDEO), str(VIDEO.with_suffix(".json")), **options).open()  # type: ignore[arg-type]


def test_the_recorded_catching_camera_gives_through_videocapture_the_detections_of_its_live_frames():
    live = RECORDED["frames"]
    assert sum(f["detection"] is not None for f in live) >= 20  # the ball rolls through the recording
    cam = _play(pace=False)
    try:
        info = cam.info()
        assert (info["width"], info["height"], info["fps"]) == (320, 240, 25.0)
        roi = VisionConfig.from_info(info).roi
        played = []
        for _ in live:
            frame = cam.grab()
            assert frame is not None
            d = locate_threshold(frame.image, frame.t, roi=roi)
            played.append((frame.t, None if d is None else [d.u, d.v]))
        with pytest.raises(ConnectionError, match="end of the video"):
            cam.grab()
    finally:
        cam.close()
    assert [p[1] for p in played] == [f["detection"] for f in live]  # the same, to the bit
    t0, live_t0 = played[0][0], live[0]["t"]
    assert [round(t - t0, 6) for t, _ in played] == [round(f["t"] - live_t0, 6) for f in live]  # the file's times


def test_a_recording_reads_back_bit_for_bit_and_loops_on_request(tmp_path: Path):
    rng = np.random.default_rng(1)
    frames = [Frame(k, 10.0 + k / 25, rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)) for k in range(5)]
    out = tmp_path / "noise.mkv"
    assert record(frames, out, fps=25.0, info={"fps": 25.0, "note": "noise"}) == 5
    cam = CaptureSpec(str(out), str(out.with_suffix(".json")), pace=False, loop=True).open()
    try:
        assert cam.info()["note"] == "noise"
        got = [cam.grab() for _ in range(7)]
    finally:
        cam.close()
    for g, f in zip(got, frames + frames[:2]):
        assert g is not None
        np.testing.assert_array_equal(g.image, f.image)
    assert [g.seq for g in got if g] == list(range(7))
    assert [round(g.t, 6) for g in got if g] == [round(k / 25, 6) for k in range(7)]  # a loop goes on in time


def test_a_file_is_read_at_its_frame_rate_unless_told_otherwise():
    cam = _play()
    try:
        t_start = time.monotonic()
        first = cam.grab()
        for _ in range(9):
            last = cam.grab()
        took = time.monotonic() - t_start
    finally:
        cam.close()
    assert first is not None and last is not None
    assert took >= 0.9 * (last.t - first.t)  # 9 frame periods of 40 ms, as the camera delivered them


def test_sources_in_services_toml_params_are_taken_relative_to_its_directory(tmp_path: Path):
    services = str(tmp_path / "services.toml")
    spec = CaptureSpec.from_params({"source": "cams/lab.mkv", "calibration": "cams/lab.json"}, services)
    assert spec is not None and spec.source == str(tmp_path / "cams" / "lab.mkv") and spec.is_file
    assert spec.calibration == str(tmp_path / "cams" / "lab.json")
    for live in ("0", "/dev/video0", "rtsp://camera.lab/stream", "http://camera.lab/mjpg"):
        got = CaptureSpec.from_params({"source": live}, services)
        assert got is not None and got.source == live and not got.is_file
    assert CaptureSpec.from_params({"port": 7210}, services) is None  # the frame server
    with pytest.raises(ValueError, match="camera api 'directshow'"):
        CaptureSpec.from_params({"source": "0", "api": "directshow"}, services)
    with pytest.raises(ConnectionError, match="no such file"):
        CaptureSpec(str(tmp_path / "missing.mkv")).open()


def test_a_camera_read_through_videocapture_needs_no_camera_server_before_its_node_starts():
    location = parse_location("""
[nodes.vision]
host = "127.0.0.1"
port = 7103

[nodes.perception]
host = "127.0.0.1"
port = 7105

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = { source = "/dev/video0", calibration = "table.json" }

[drivers.mobile_camera]
node = "perception"
impl = "services.mobile.perception_node:PerceptionDriver"
params = { port = 7220 }
""")
    found = [(spec.name, endpoint.port) for spec, endpoint in device_endpoints(location)]
    assert found == [("mobile_camera", 7220)]  # petrobot up probes the frame server only
