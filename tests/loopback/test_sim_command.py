"""`petrobot sim catching` in lock-step mode, run in-process for a few simulated seconds."""

from __future__ import annotations

import argparse
import json

from coordinator.commands import sim


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
