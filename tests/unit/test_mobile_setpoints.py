"""The steering set-point stream's validation and the drive node's watchdog (services/mobile/setpoints.py)."""

from __future__ import annotations

import math

import pytest

from services.mobile.setpoints import (
    MalformedSetPoint,
    SteeringInput,
    parse_odometry,
    parse_setpoint,
    setpoint_to_dict,
)
from services.mobile.steering import SteeringSetPoint


def sp(seq: int, t: float = 1.0, left: float = 10.0, right: float = 12.0) -> dict[str, object]:
    return setpoint_to_dict(SteeringSetPoint(seq, t, 0.5, 0.4, left, right), 100.0)


def test_a_valid_set_point_round_trips_through_its_event_data():
    got = parse_setpoint(sp(7, 2.5))
    assert got == SteeringSetPoint(7, 2.5, 0.5, 0.4, 10.0, 12.0)


@pytest.mark.parametrize("field, bad", [
    ("seq", True), ("seq", -1), ("seq", 2**63), ("seq", 1.0), ("t", math.nan), ("t", -1.0),
    ("v", math.inf), ("v", 50.0), ("curvature", 1e6), ("left", "fast"), ("right", None), ("left", False),
])
def test_every_field_is_checked_and_the_message_names_it(field: str, bad: object):
    data = sp(1)
    data[field] = bad
    with pytest.raises(MalformedSetPoint, match=field):
        parse_setpoint(data)


def test_a_missing_field_a_non_map_and_too_many_keys_are_malformed():
    data = sp(1)
    del data["right"]
    with pytest.raises(MalformedSetPoint, match="right"):
        parse_setpoint(data)
    with pytest.raises(MalformedSetPoint):
        parse_setpoint([1, 2, 3])
    with pytest.raises(MalformedSetPoint):
        parse_setpoint({**sp(1), **{f"k{i}": i for i in range(40)}})


def test_malformed_stale_and_not_newer_set_points_are_dropped_counted_and_never_used():
    inp = SteeringInput(stale_s=0.25)
    assert inp.offer(sp(5, t=1.0), wall=10.0, bus=1.02) is not None
    assert inp.offer({"seq": 6, "t": math.inf}, wall=10.01, bus=1.03) is None
    assert inp.offer(sp(5, t=1.04, left=99.0), wall=10.02, bus=1.04) is None  # repeated seq
    assert inp.offer(sp(4, t=1.04, left=99.0), wall=10.02, bus=1.04) is None  # older seq
    assert inp.offer(sp(9, t=0.5, left=99.0), wall=10.03, bus=1.05) is None  # frame 0.55 s old
    assert (inp.malformed, inp.out_of_order, inp.stale, inp.accepted) == (1, 2, 1, 1)
    assert inp.wheels(wall=10.05, bus=1.06) == (10.0, 12.0)
    assert "stale" in inp.last_error


def test_the_latest_set_point_wins():
    inp = SteeringInput()
    inp.offer(sp(1, t=1.0, left=1.0), 0.0, 1.0)
    inp.offer(sp(2, t=1.02, left=2.0, right=2.0), 0.02, 1.02)
    assert inp.wheels(0.03, 1.03) == (2.0, 2.0)


def test_the_watchdog_stops_the_wheels_when_set_points_stop_on_both_clocks_and_counts_one_stop():
    inp = SteeringInput(stale_s=0.25)
    inp.offer(sp(1, t=1.0), wall=10.0, bus=1.0)
    assert inp.wheels(wall=10.2, bus=1.2) == (10.0, 12.0)
    assert inp.wheels(wall=10.3, bus=1.3) == (0.0, 0.0)
    assert inp.wheels(wall=10.4, bus=1.4) == (0.0, 0.0)
    assert inp.stopped and inp.watchdog_stops == 1
    inp.offer(sp(2, t=1.45), wall=10.45, bus=1.45)  # the stream comes back: it resumes
    assert inp.wheels(wall=10.46, bus=1.46) == (10.0, 12.0)
    assert not inp.stopped and inp.watchdog_stops == 1


def test_a_simulation_slowed_down_by_load_is_not_taken_for_a_lost_stream():
    inp = SteeringInput(stale_s=0.25)
    inp.offer(sp(1, t=1.0), wall=10.0, bus=1.0)
    # one second of wall time passed, but the bus clock only 0.1 s: the world is slow, not the stream
    assert inp.wheels(wall=11.0, bus=1.1) == (10.0, 12.0)
    assert inp.watchdog_stops == 0


def test_no_set_point_yet_means_standing_still_and_hold_forgets_the_last_one():
    inp = SteeringInput()
    assert inp.wheels(0.0, 0.0) == (0.0, 0.0)
    inp.offer(sp(1), 0.0, 1.0)
    inp.hold()
    assert inp.wheels(0.01, 1.01) == (0.0, 0.0)
    assert inp.offer(sp(1), 0.02, 1.02) is None  # hold keeps the sequence: no replay


def test_odometry_messages_are_validated_too():
    good = {"t": 1.0, "x": 0.1, "y": 0.2, "theta": 0.3, "s": 0.4, "v": 0.5, "w": 0.1, "seq": 3, "stops": 0,
            "state": "ok"}
    odo = parse_odometry(good)
    assert odo.pose.s == 0.4 and odo.seq == 3 and odo.state == "ok"
    with pytest.raises(MalformedSetPoint, match="x"):
        parse_odometry({**good, "x": math.nan})
    with pytest.raises(MalformedSetPoint):
        parse_odometry({**good, "stops": "many"})


def test_the_watchdog_needs_a_positive_staleness_limit():
    with pytest.raises(ValueError):
        SteeringInput(stale_s=0.0)


def test_a_forged_sequence_number_far_ahead_is_refused_and_the_stream_goes_on():
    """Issue 22: one set point numbered 2**62 made every later legitimate set point look old."""
    inp = SteeringInput(stale_s=0.25)
    assert inp.offer(sp(100, t=1.0), wall=10.0, bus=1.0) is not None
    assert inp.offer(sp(2**62, t=1.02, left=-50.0), wall=10.02, bus=1.02) is None
    assert inp.jumps == 1 and inp.note is not None and "refused" in inp.note
    assert inp.offer(sp(101, t=1.04, left=3.0, right=3.0), wall=10.04, bus=1.04) is not None
    assert inp.note is None and inp.wheels(10.05, 1.05) == (3.0, 3.0)


def test_after_a_silence_a_set_point_out_of_step_restarts_the_stream_and_says_so():
    inp = SteeringInput(stale_s=0.25)
    assert inp.offer(sp(5_000_000, t=1.0), wall=10.0, bus=1.0) is not None
    # the perception node restarted and numbers afresh, lower: taken once the stream was silent
    assert inp.offer(sp(7, t=1.1), wall=10.1, bus=1.1) is None
    restarted = inp.offer(sp(8, t=1.3), wall=10.3, bus=1.3)
    assert restarted is not None and inp.restarts == 1
    assert inp.note is not None and "restarted at seq 8" in inp.note
    assert inp.offer(sp(9, t=1.32), wall=10.32, bus=1.32) is not None and inp.note is None
