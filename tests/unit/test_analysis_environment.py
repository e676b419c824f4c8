"""The operator as the environment of a task net (control places it may fill) and retry loops
(`coordinator/analysis/environment.py`, issue 11 item 11)."""

from __future__ import annotations

from pathlib import Path

from coordinator.analysis.environment import (
    environment_limits,
    retry_transitions,
    with_environment,
)
from coordinator.analysis.robotic import report
from coordinator.commands.analyze import render
from coordinator.netfile import load_any, loads_net

ROOT = Path(__file__).resolve().parents[2]

# A task whose error leaves the robot faulted; only the operator's reset request brings it back.
OPERATOR_RESET = """
[net]
name = "operator_reset"
format = 1
home = { idle = 1 }

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "working"
kind = "primitive_task"
task = "work"

[[place]]
id = "faulted"
label = "robot faulted: waiting for the operator"

[[place]]
id = "reset_request"
kind = "control"
label = "the operator asks for a reset"

[task.work]
actions = ["work"]

[[transition]]
id = "start"
inputs = { idle = 1 }
outputs = { working = 1 }

[[transition]]
id = "done"
events = ["int:work.ok"]
inputs = { working = 1 }
outputs = { idle = 1 }

[[transition]]
id = "failed"
events = ["int:work.error"]
hidden = true
inputs = { working = 1 }
outputs = { faulted = 1 }

[[transition]]
id = "operator_reset"
hidden = true
inputs = { faulted = 1, reset_request = 1 }
outputs = { idle = 1 }
"""


def test_a_recovery_through_the_operator_makes_the_task_recoverable_and_controllable() -> None:
    rep = report(loads_net(OPERATOR_RESET))
    rob = rep["robotic"]
    assert rob["error_recoverable"]["holds"] is True, rob["error_recoverable"]["explanation"]
    assert rob["controllable"]["holds"] is True, rob["controllable"]["explanation"]
    for key in ("error_recoverable", "controllable"):
        assert "operator is modelled as the environment" in rob[key]["explanation"]
        assert "reset_request" in rob[key]["explanation"]
    assert rep["environment"]["modelled"] is True
    assert rep["environment"]["control_places"] == {"reset_request": 1}
    # the operator's own transition is not judged as a step of the task
    assert set(rob["controllable"]["witness"]["liveness"]) == {"start", "done", "failed", "operator_reset"}
    text = render(rep)
    assert "environment:       the operator may add tokens to reset_request (up to 1)" in text


def test_the_net_as_written_keeps_its_own_properties_beside_the_environment() -> None:
    rep = report(loads_net(OPERATOR_RESET))
    # without the operator, operator_reset can never fire and the faulted state is a deadlock
    assert rep["dead_transitions"] == ["operator_reset"] and rep["deadlock"] is True
    assert rep["robotic"]["stable"]["holds"] is True


def test_environment_limit_is_the_capacity_or_the_largest_declared_count() -> None:
    net = loads_net(OPERATOR_RESET)
    assert environment_limits(net) == {"reset_request": 1}
    runs = loads_net(OPERATOR_RESET.replace('kind = "control"\n', 'kind = "control"\ntokens = 3\n'))
    assert environment_limits(runs) == {"reset_request": 3}
    capped = loads_net(OPERATOR_RESET.replace('kind = "control"\n', 'kind = "control"\ncapacity = 2\n'))
    assert environment_limits(capped) == {"reset_request": 2}
    env, limits = with_environment(net)
    added = env.transitions[len(net.transitions):]
    assert [t.id for t in added] == ["operator_adds_to.reset_request"] and limits == {"reset_request": 1}
    assert env.inhibitor_places["operator_adds_to.reset_request"] == {"reset_request": 1}


def test_a_net_without_control_places_has_no_environment() -> None:
    net = load_any(ROOT / "tests" / "data" / "analysis" / "unbounded_retry.toml", interpreted=False)
    assert with_environment(net) == (net, {})
    rep = report(net)
    assert rep["environment"]["modelled"] is False
    assert "modelled as the environment" not in rep["robotic"]["controllable"]["explanation"]


def test_a_retry_without_a_limit_is_flagged_as_able_to_fire_for_ever() -> None:
    net = load_any(ROOT / "tests" / "data" / "analysis" / "unbounded_retry.toml", interpreted=False)
    assert retry_transitions(net) == {"home_retry": "home"}
    rep = report(net)
    assert rep["retries"]["unbounded"] == ["home_retry"]
    (row,) = rep["retries"]["retries"]
    assert row["bounded"] is False and row["example"]["marking"] == {"returning": 1}
    assert "retry home_retry (task home): UNBOUNDED" in render(rep)


def test_the_catch_net_bounds_its_retries_of_the_move_home() -> None:
    rep = report(load_any(ROOT / "nets" / "catch.toml", interpreted=False))
    assert rep["retries"]["retries"] == [{"transition": "home_retry", "task": "home", "bounded": True}]
    assert rep["retries"]["unbounded"] == []
    assert rep["environment"]["control_places"] == {"runs_remaining": 4}
    assert "retry home_retry (task home): bounded" in render(rep)
