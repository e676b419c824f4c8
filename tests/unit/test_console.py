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
    ("end", OperatorCommand(Command.END)),
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


def test_pulses_are_summed_up_at_most_every_ten_seconds_not_printed_one_by_one():
    from coordinator.events import PulseDelivered, RunStateChanged

    now = [0.0]
    out = io.StringIO()
    console = Console(loads_net(NET), stream=out, live=False, clock=lambda: now[0])
    for second in range(25):  # a camera ticking at 10 Hz for 25 s; a run started on one tick every 5 s
        for tick in range(10):
            now[0] = second + tick / 10
            fired = int(second % 5 == 0 and tick == 0)
            console(PulseDelivered("r", "ext:image_sampling_tick", fired))
            if fired:
                console(TransitionFired("r", Firing(second + 1, "go", {"runs": 1}, {"out": 1},
                                                    pulse="ext:image_sampling_tick")))
    console(RunStateChanged("r", "completed", "at the home marking"))
    lines = out.getvalue().splitlines()
    summaries = [line for line in lines if "pulses that fired nothing" in line]
    assert not any("fired 1" in line for line in lines)  # the firing line names its pulse
    assert sum("on ext:image_sampling_tick" in line for line in lines) == 5
    assert len(summaries) == 2 and len(lines) == 8
    # the first line printed 10 s or more after the counting began (the firing at 15 s) brings the first
    # summary; the end of the run brings the rest: 245 pulses that fired nothing in all
    assert summaries[0].endswith("pulses that fired nothing in the last 14.9 s: ext:image_sampling_tick x147")
    assert summaries[1].endswith("in the last 9.8 s: ext:image_sampling_tick x98")
    assert lines[-1].endswith("run r completed: at the home marking")


def test_the_line_view_gives_reasons_waiting_and_the_places_a_firing_moved():
    from coordinator.events import RunStateChanged

    out = io.StringIO()
    console = Console(loads_net(NET), stream=out, live=False)
    console(TransitionFired("r", Firing(3, "go", {"runs": 1, "robot": 1}, {"out": 2})))
    console(ActionEnded("r", "r-1", "catch", "catch", "motion",
                        ActionResult(status=Status.FAILURE, outcome="missed", wall_s=1.25, reason="ball passed")))
    console(RunStateChanged("r", "waiting", "waiting for the operator: + runs 1 would enable go",
                            detail=("out: 2 tokens (home 0)", "+ runs 1 would enable go")))
    lines = out.getvalue().splitlines()
    assert lines[0].endswith("fire  #3     go   runs, robot -> outx2")
    assert lines[1].endswith("done  catch/catch on motion: failure (missed) in 1.250 s: ball passed")
    assert lines[2].endswith("run r waiting: waiting for the operator: + runs 1 would enable go")
    assert lines[3].strip() == "- out: 2 tokens (home 0)" and len(lines) == 4


class _Screen(io.StringIO):
    def isatty(self) -> bool:
        return True


class _Runtime:
    """What the live view reads of a runtime."""

    def __init__(self, net) -> None:
        from coordinator.engine import Engine

        self.engine = Engine(net)
        self.run_id = "r"
        self.observer = None

    def running(self) -> list:
        return []


def test_a_refused_command_stays_on_the_live_screen_until_the_next_command():
    from coordinator.events import OperatorApplied, OperatorRefused, RunStateChanged

    net = loads_net(NET)
    console = Console(net, stream=_Screen())
    console.attach(_Runtime(net))  # type: ignore[arg-type]
    assert console.live
    console(OperatorRefused("r", "fly", "commands: + PLACE [N] | ..."))
    console(TransitionFired("r", Firing(1, "go", {"runs": 1}, {"out": 1})))
    console(RunStateChanged("r", "waiting", "waiting for the operator: + runs 1 would enable go"))
    view = "\n".join(console.screen_lines())
    assert console.operator_note == "refused: fly: commands: + PLACE [N] | ..."
    assert "state waiting" in view and "waiting: waiting for the operator: + runs 1 would enable go" in view
    console(OperatorApplied("r", OperatorCommand(Command.INSERT, "runs", 1)))
    assert console.operator_note == "applied: insert runs 1"


def test_the_live_view_says_paused_while_the_engine_is_paused_even_when_the_run_waits():
    from coordinator.events import RunStateChanged

    net = loads_net(NET)
    console = Console(net, stream=_Screen())
    runtime = _Runtime(net)
    console.attach(runtime)  # type: ignore[arg-type]
    runtime.engine.pause()
    console(RunStateChanged("r", "paused", "paused by the operator"))
    console(RunStateChanged("r", "waiting", "paused: resume, or step to fire one transition"))
    assert console.shown_state == "paused" and "state paused" in console.screen_lines()[0]
    runtime.engine.resume()
    console(RunStateChanged("r", "running", "resumed by the operator"))
    assert console.shown_state == "running"


def test_cursor_keys_typed_in_line_mode_are_taken_out_of_the_line_never_refused_as_a_command():
    import asyncio
    import threading

    from coordinator.console import read_operator_commands

    class Sink:
        def __init__(self) -> None:
            self.got: list = []

        def command(self, cmd: OperatorCommand) -> None:
            self.got.append(cmd)

        def refuse_input(self, text: str, reason: str) -> None:
            self.got.append(("refused", text))

    typed = "\x1b[4~\n+ runs\x1b[D\x1b[C 2\n\x1b[A\x1b[B\x1bOH\n\x1b[1;5Cpause\n"  # End; arrows; Home; Ctrl-Right

    async def main() -> list:
        sink = Sink()
        thread: threading.Thread = read_operator_commands(sink, io.StringIO(typed))  # type: ignore[arg-type]
        await asyncio.to_thread(thread.join, 30)
        await asyncio.sleep(0)
        return sink.got

    assert asyncio.run(main()) == [OperatorCommand(Command.INSERT, "runs", 2), OperatorCommand(Command.PAUSE),
                                   OperatorCommand(Command.END)]


def test_the_live_view_shows_each_running_actions_latest_feedback_until_it_ends():
    from types import SimpleNamespace

    from coordinator.events import ActionFeedback

    net = loads_net(NET)
    console = Console(net, stream=_Screen())
    runtime = _Runtime(net)
    call = SimpleNamespace(start=SimpleNamespace(instance="r-1", task="count", action="fibonacci"), node="rosbot",
                           elapsed_s=0.4)
    runtime.running = lambda: [call]  # type: ignore[method-assign]
    console.attach(runtime)  # type: ignore[arg-type]
    console(ActionFeedback("r", "r-1", "count", "fibonacci", {"sequence": [0, 1, 1]}))
    console(ActionFeedback("r", "r-1", "count", "fibonacci", {"sequence": [0, 1, 1, 2]}))
    (row,) = [line for line in console.screen_lines() if line.startswith("  count ")]
    assert row.endswith('{"sequence": [0, 1, 1, 2]}')
    console(ActionEnded("r", "r-1", "count", "fibonacci", "rosbot", ActionResult.success()))
    (row,) = [line for line in console.screen_lines() if line.startswith("  count ")]
    assert "sequence" not in row
