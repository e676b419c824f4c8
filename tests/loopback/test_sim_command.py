"""`petrobot sim catching` in lock-step mode, run in-process for a few simulated seconds; where each world
serves its devices (and `petrobot sim zenoh` its router) when services.toml says."""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from coordinator.commands import sim
from tests.ports import free_port


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    sim.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["sim", "catching", *argv])


def test_sim_catching_reports_ready_throw_crossing_and_result_as_json_lines(capsys):
    args = _parse("--lockstep", "--renderer", "analytic", "--duration", "4.5", "--throws", "1",
                  "--first-throw", "0.2", "--camera-port", "0", "--can-port", "0", "--seed", "3")
    assert sim.run(args) == 0
    events = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    kinds = [e["event"] for e in events]
    assert kinds == ["ready", "throw", "crossing", "result", "stopped"]
    ready, throw, crossing, result, stopped = events
    assert stopped["throws"] == 1 and 112 <= stopped["frames"] <= 113
    assert ready["mode"] == "lockstep" and ready["camera_port"] > 0 and ready["can_port"] > 0
    assert ready["calibration_rms_m"] < 0.002
    assert 0.5 <= throw["speed"] <= 1.5
    assert abs(crossing["y"]) <= 0.26 and crossing["x_base"] == 0.75
    assert abs(crossing["y_base"] + crossing["y"]) < 1e-9
    assert result["crossed"] is True and result["caught"] is False  # nobody moved the robot


def test_sim_help_explains_every_option(capsys):
    parser = argparse.ArgumentParser()
    sim.add_parser(parser.add_subparsers(dest="command"))
    try:
        parser.parse_args(["sim", "catching", "--help"])
    except SystemExit:
        pass
    text = capsys.readouterr().out
    for option in ("--realtime", "--lockstep", "--seed", "--throws", "--interval", "--renderer",
                   "--camera-port", "--can-port", "--fps", "--duration"):
        assert option in text


SERVICES = {
    "catching": """
[nodes.vision]
host = "127.0.0.1"
port = 7103

[nodes.motion]
host = "127.0.0.1"
port = 7104

[drivers.camera]
node = "vision"
impl = "services.catching.camera:CameraDriver"
params = {{ port = {camera} }}

[drivers.puma]
node = "motion"
impl = "services.catching.arm:PumaDriver"
params = {{ can_port = {can} }}
""",
    "mobile": """
[nodes.perception]
host = "127.0.0.1"
port = 7105

[nodes.drive]
host = "127.0.0.1"
port = 7106

[drivers.mobile_camera]
node = "perception"
impl = "services.mobile.perception_node:PerceptionDriver"
params = {{ port = {camera} }}

[drivers.wheels]
node = "drive"
impl = "services.mobile.drive_node:DriveDriver"
params = {{ can_port = {can} }}
""",
}


@pytest.mark.parametrize("world", ["catching", "mobile"])
def test_sim_serves_its_devices_on_the_ports_services_toml_gives_their_drivers(world, tmp_path, capsys):
    camera, can = free_port(), free_port()
    services = tmp_path / "services.toml"
    services.write_text(SERVICES[world].format(camera=camera, can=can))
    parser = argparse.ArgumentParser()
    sim.add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["sim", world, "--services", str(services), "--lockstep", "--renderer", "analytic",
                              "--duration", "0.1"])
    assert sim.run(args) == 0
    ready = json.loads(capsys.readouterr().out.splitlines()[0])
    assert ready["event"] == "ready" and (ready["camera_port"], ready["can_port"]) == (camera, can)



def test_sim_zenoh_listens_where_services_toml_has_its_ros2_nodes_connect(tmp_path):
    port = free_port()
    services = tmp_path / "services.toml"
    services.write_text(f"""
[nodes.rosbot]
host = "127.0.0.1"
port = 7107

[nodes.rosbot.ros2]
connect = ["tcp/127.0.0.1:{port}"]

[events.crossfire]
node = "rosbot"
ros2 = {{ topic = "/crossfire", type = "std_msgs/msg/Bool", when = "data" }}
""")
    proc = subprocess.Popen([sys.executable, "-m", "coordinator.commands.sim", "zenoh", "--services", str(services)],
                            cwd=Path(__file__).resolve().parents[2], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        ready = json.loads(proc.stdout.readline())
        assert ready["event"] == "ready" and ready["listen"] == f"tcp/127.0.0.1:{port}"
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass
    finally:
        proc.terminate()
        assert proc.wait(timeout=30) == 0
