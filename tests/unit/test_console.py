"""Operator commands typed on a terminal, and the line-by-line view of a run (no sockets)."""

from __future__ import annotations

import io

import pytest

from coordinator.console import Console
from coordinator.netfile import loads_net
from coordinator.engine import Firing
from coordinator.events import ActionEnded, ActionStarted, TransitionFired
from services.results import ActionResult, Status
from coordinator.operator import Command, OperatorCommand, parse_operator_command

NET = """
[net]
name = "c"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "out"

[[transition]]
id = "go"
inputs = { runs = 1 }
outputs = { out = 1 }
"""


@pytest.mark.parametrize("text, command", [
    ("+ runs_remaining", OperatorCommand(Command.INSERT, "runs_remaining", 1)),
    ("+ runs_remaining 3", OperatorCommand(Command.INSERT, "runs_remaining", 3)),
    ("- runs_remaining 2", OperatorCommand(Command.REMOVE, "runs_remaining", 2)),
    ("remove runs 1", OperatorCommand(Command.REMOVE, "runs", 1)),
    ("pause", OperatorCommand(Command.PAUSE)),
    ("  step ", OperatorCommand(Command.STEP)),
    ("resume", OperatorCommand(Command.RESUME)),
    ("abort", OperatorCommand(Command.ABORT)),
])
def test_typed_operator_commands_are_understood(text, command):
    assert parse_operator_command(text) == command


@pytest.mark.parametrize("text, hint", [
    ("", "empty"), ("+", "usage"), ("+ runs two", "integer"), ("fly", "commands"), ("pause now", "commands"),
])
def test_a_bad_operator_command_gets_a_hint(text, hint):
    with pytest.raises(ValueError, match=hint):
        parse_operator_command(text)


def test_the_line_view_prints_one_line_per_event_and_errors_even_when_quiet():
    out = io.StringIO()
    console = Console(loads_net(NET), stream=out, live=False)
    fire = TransitionFired("r", Firing(1, "go", {}, {}))
    console(fire)
    console(ActionStarted("r", "r-1", "t", "t", "a", "alpha"))
    lost = ActionEnded("r", "r-1", "t", "a", "alpha", ActionResult(status=Status.ERROR, wall_s=0.5, reason="node lost"))
    console(lost)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3
    assert "fire  #1     go" in lines[0] and "start t -> a on alpha" in lines[1]
    assert lines[2].endswith("done  t/a on alpha: error in 0.500 s: node lost")
    quiet_out = io.StringIO()
    quiet = Console(loads_net(NET), stream=quiet_out, live=False, quiet=True)
    quiet(fire)
    quiet(lost)
    assert len(quiet_out.getvalue().splitlines()) == 1
