"""The generated fleet net (coordinator.netfile.fleet, ``petrobot example fleet``) and what analyze says of it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from coordinator.analysis.robotic import report
from coordinator.cli import main
from coordinator.net import Marking
from coordinator.netfile.fleet import fleet_toml
from coordinator.netfile.loader import loads_net


def test_two_robots_going_opposite_ways_can_block_each_other_and_the_witness_shows_how() -> None:
    net = loads_net(fleet_toml(2))
    rep = report(net)
    assert rep["engine"]["used"] == "explicit" and rep["deadlock"] is True and rep["n_deadlocks"] == 4
    m = net.initial_marking
    for t in rep["deadlocks"][0]["firing_sequence"]:
        m = net.fire(m, t)
    assert m == Marking(rep["deadlocks"][0]["marking"]) and not net.enabled_transitions(m)
    waiting = {p for p, n in m.items() if n and "waiting_after" in p}
    assert len(waiting) == 2  # each robot done with a task, waiting for what the other holds
    assert rep["ends"]["stuck"] == 4


def test_the_corridor_token_makes_the_fleet_deadlock_free() -> None:
    rep = report(loads_net(fleet_toml(3, safe=True)))
    assert rep["deadlock"] is False and rep["bounded"] is True and rep["quasi_live"] is True


@pytest.mark.parametrize("safe", [False, True])
def test_both_engines_agree_on_a_fleet_of_four(safe: bool) -> None:
    net = loads_net(fleet_toml(4, safe=safe))
    explicit = report(net, engine="explicit")
    symbolic = report(net, engine="symbolic")
    assert symbolic["engine"]["used"] == "symbolic"
    for key in ("states", "edges", "deadlock", "n_deadlocks", "quasi_live", "live", "reversible", "place_bounds"):
        assert symbolic[key] == explicit[key], key


def test_example_writes_the_fleet_and_analyze_hands_it_to_the_symbolic_engine_beyond_its_share(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "fleet.toml"
    assert main(["example", "fleet", "--robots", "5", "--safe", "-o", str(path)]) == 0
    capsys.readouterr()
    assert main(["analyze", str(path), "--json", "--max-states", "20000"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["engine"]["used"] == "symbolic" and "stopped at 20,000 markings" in rep["engine"]["reason"]
    assert rep["deadlock"] is False and rep["complete"] is True and rep["states"] > 20_000


def test_the_symbolic_encoding_keeps_each_robot_on_one_level_and_the_shared_resources_below_the_robots() -> None:
    import numpy as np

    from coordinator.analysis import jit, lp

    jit.configure()
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.mdd_order import encode

    net = loads_net(fleet_toml(8))
    sn = sparse_net(net)
    flows = lp.semiflow_cover(sn, seconds=3.0)
    enc = encode(sn, lp.place_bounds(sn, seconds=10.0).bounds, flows, sink=True)
    ids = [p.id for p in net.places]
    level_of = {ids[p]: int(enc.place_level[p]) for p in range(len(ids))}
    robot_levels = set()
    for i in range(8):
        levels = {k for pid, k in level_of.items() if pid.startswith(f"r{i}_")}
        assert len(levels) == 1, f"robot {i} is split over levels {sorted(levels)}"
        robot_levels |= levels
    shared = [level_of[p] for p in ("aisle_1_free", "lift_free", "aisle_2_free", "chargers_free")]
    assert enc.sunk == 4 and min(shared) > max(robot_levels) and int(np.max(shared)) == enc.n_levels - 1


def test_the_symbolic_engine_finds_the_deadlock_of_eight_robots_with_a_witness_that_replays() -> None:
    net = loads_net(fleet_toml(8))
    rep = report(net, engine="symbolic")
    assert rep["engine"]["used"] == "symbolic" and rep["complete"] is True
    assert rep["states"] == 4_320_496_257  # as counted on the order of least spans, resources among the robots
    assert rep["deadlock"] is True and rep["n_deadlocks"] > 0
    m = net.initial_marking
    for t in rep["deadlocks"][0]["firing_sequence"]:
        m = net.fire(m, t)
    assert m == Marking(rep["deadlocks"][0]["marking"]) and not net.enabled_transitions(m)
    assert sum(1 for p, n in m.items() if n and "waiting_after" in p) >= 2


def test_a_fleet_size_out_of_range_is_a_clear_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["example", "fleet", "--robots", "0"]) == 2
    assert "robots must be between 1 and" in capsys.readouterr().err


def test_with_missions_the_safe_fleet_ends_only_at_home_and_the_endless_one_never_ends() -> None:
    rep = report(loads_net(fleet_toml(2, safe=True, missions=1)))
    assert rep["deadlock"] is True and rep["ends"]["stuck"] == 0 and rep["ends"]["intended"] == rep["n_deadlocks"] > 0
    assert report(loads_net(fleet_toml(2, safe=True)))["deadlock"] is False


def test_missions_below_one_are_a_clear_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["example", "fleet", "--robots", "2", "--missions", "0"]) == 2
    assert "missions must be at least 1" in capsys.readouterr().err
