"""Conditions on message fields, their edges, and the map from ROS 2 statuses to petrobot results.
No sockets."""

from __future__ import annotations

import pytest

from services.results import Status
from services.ros2.condition import MAX_NESTING, Condition, Edge, EdgeDetector
from services.ros2.errors import ConditionError
from services.ros2.outcome import GoalStatus, action_result, rejected_result, service_result

POSE = {"pose": {"position": {"x": 1.5, "y": -2.0}}, "stalled": False, "name": "arm", "sequence": [0, 1, 1, 2]}


@pytest.mark.parametrize("text, expected", [
    ("stalled", False),
    ("not stalled", True),
    ("stalled == false", True),
    ("pose.position.x > 1.0 and pose.position.y < 0", True),
    ("pose.position.x >= 2 or name == 'arm'", True),
    ("len(sequence) == 4 and sequence[-1] == 2", True),
    ("sequence[1] + sequence[3] * 2 == 5", True),
    ("abs(pose.position.y) == 2.0", True),
    ("-pose.position.y / 4 == 0.5", True),
    ("sequence[3] % 2 == 0", True),
    ('name != "a\\"m"', True),
    ("(1 < 2) == true", True),
])
def test_conditions_evaluate_on_message_fields(text, expected):
    assert Condition(text).evaluate(POSE) is expected


@pytest.mark.parametrize("text, column", [
    ("data ==", 8),
    ("data = true", 6),
    ("1 < x < 3", 7),
    ("len(data", 9),
    ("data.", 6),
    ("data $ 2", 6),
    ("and data", 1),
])
def test_syntax_errors_give_the_column(text, column):
    with pytest.raises(ConditionError) as caught:
        Condition(text)
    assert caught.value.column == column


@pytest.mark.parametrize("text, words", [
    ("speed > 1", "no field 'speed'"),
    ("pose.velocity", "no field 'velocity'"),
    ("name > 1", "ordering a string and a number"),
    ("stalled == 0", "comparing a true/false with a number"),
    ("not stalled and 1", "expected true/false, got a number"),
    ("sequence[9] == 1", "out of range"),
    ("pose.position.x / 0 > 1", "division by zero"),
    ("pose.position.x + 1", "not true or false"),
    ("len(stalled) > 0", r"len\(\) of a true/false"),
])
def test_evaluation_errors_say_what_is_wrong(text, words):
    with pytest.raises(ConditionError, match=words):
        Condition(text).evaluate(POSE)


def test_the_paths_a_condition_reads_are_listed_for_checking():
    assert Condition("pose.position.x > 1 and len(sequence) > 0 and sequence[0] == 0").paths() == \
        [("pose", "position", "x"), ("sequence",), ("sequence",)]


def test_hostile_conditions_are_bounded():
    with pytest.raises(ConditionError, match="nested deeper"):
        Condition("(" * (MAX_NESTING + 1) + "true" + ")" * (MAX_NESTING + 1))
    with pytest.raises(ConditionError, match="longer than"):
        Condition("true or " * 200 + "true")
    with pytest.raises(ConditionError):
        Condition("")


def test_a_rising_edge_fires_once_per_crossing_and_every_fires_each_time():
    rising = EdgeDetector(Edge.RISING)
    assert [rising.update(v) for v in (True, True, False, False, True, True)] == \
        [True, False, False, False, True, False]
    every = EdgeDetector(Edge.EVERY)
    assert [every.update(v) for v in (True, False, True, True)] == [True, False, True, True]


def test_a_succeeded_goal_is_a_success_unless_its_condition_is_false():
    result = {"sequence": [0, 1, 1]}
    done = action_result(GoalStatus.SUCCEEDED, result, goal_id="ab")
    assert done.status is Status.SUCCESS
    assert done.value == {"status": "SUCCEEDED", "goal_id": "ab", "result": result}
    short = action_result(4, result, goal_id="ab", success=Condition("len(sequence) > 5"))
    assert short.status is Status.FAILURE and "is false on the result" in short.reason
    broken = action_result(4, result, goal_id="ab", success=Condition("missing"))
    assert broken.status is Status.ERROR


def test_aborted_canceled_and_rejected_goals_map_to_failure_or_error_with_an_outcome():
    aborted = action_result(GoalStatus.ABORTED, {}, goal_id="ab")
    assert (aborted.status, aborted.outcome) == (Status.FAILURE, "aborted")
    assert action_result(6, {}, goal_id="ab", aborted=Status.ERROR).status is Status.ERROR
    canceled = action_result(GoalStatus.CANCELED, {}, goal_id="ab", cancel_reason="deadline")
    assert (canceled.status, canceled.outcome, canceled.reason) == (Status.ERROR, "canceled", "deadline")
    assert canceled.value["status"] == "CANCELED"
    assert action_result(2, {}, goal_id="ab").status is Status.ERROR
    rejected = rejected_result("ab")
    assert (rejected.status, rejected.outcome, rejected.value["status"]) == (Status.FAILURE, "rejected", "REJECTED")
    assert rejected_result("ab", Status.ERROR).status is Status.ERROR


def test_a_service_response_is_judged_by_its_condition():
    assert service_result({"sum": 3}).value == {"sum": 3}
    assert service_result({"sum": 3}, Condition("sum > 5")).status is Status.FAILURE
    assert service_result({"sum": 9}, Condition("sum > 5")).status is Status.SUCCESS
