"""The catching net (nets/catch.toml) under the engine, without sockets: the move home is retried a
bounded number of times, then the robot is out of service and the experiment ends."""

from __future__ import annotations

from pathlib import Path

from coordinator.engine import Engine, EngineState, Firing, StartAction
from coordinator.netfile import load_net
from services.results import ActionResult

NET = Path(__file__).resolve().parents[2] / "nets" / "catch.toml"


class Driver:
    """Feeds the engine results by task, counting the primitive actions started."""

    def __init__(self) -> None:
        self.engine = Engine(load_net(NET), seed=1)
        self.running: dict[str, StartAction] = {}
        self.started: list[str] = []
        self.fired: list[str] = []
        self._take(self.engine.start())

    def _take(self, effects: list) -> None:
        for e in effects:
            if isinstance(e, StartAction):
                self.running[e.task] = e
                self.started.append(e.task)
            elif isinstance(e, Firing):
                self.fired.append(e.transition)

    def tick(self) -> None:
        self._take(self.engine.pulse("ext:image_sampling_tick"))

    def end(self, task: str, result: ActionResult) -> None:
        start = self.running.pop(task)
        self.engine.complete(start.instance, result)
        self._take(self.engine.advance())


def _run_to_a_failed_catch(d: Driver) -> None:
    d.tick()
    d.end("locate", ActionResult.success({}))
    d.end("predict", ActionResult.success({}))
    d.end("catch", ActionResult.error("drive 1 is in FAULT (following error)", outcome="bus"))


def test_a_move_home_that_keeps_failing_is_retried_three_times_then_the_robot_is_out_of_service():
    d = Driver()
    _run_to_a_failed_catch(d)
    for _ in range(10):  # far more errors than retries: the net must stop asking
        if "home" not in d.running:
            break
        d.end("home", ActionResult.error("drive 1 is in FAULT (following error)", outcome="bus"))
    assert d.started.count("home") == 4  # the first attempt and three retries
    assert d.fired.count("home_retry") == 3 and d.fired[-1] == "home_given_up"
    d.tick()  # no run starts without the robot
    assert d.engine.state is EngineState.DEAD
    marking = d.engine.marking
    assert marking["robot_out_of_service"] == 1 and marking["runs_remaining"] == 3
    assert "robot_ready" not in marking


def test_a_move_home_that_succeeds_on_a_retry_gives_the_spent_retries_back():
    d = Driver()
    _run_to_a_failed_catch(d)
    d.end("home", ActionResult.error("drive 1 is in FAULT (following error)", outcome="bus"))
    d.end("home", ActionResult.error("drive 1 is in FAULT (following error)", outcome="bus"))
    d.end("home", ActionResult.success({"recovered": "fault reset and enable"}))
    assert d.fired.count("home_retries_restored") == 2
    m = d.engine.marking
    assert m["home_retries_left"] == 3 and "home_retries_spent" not in m and m["robot_ready"] == 1
    d.tick()
    assert "locate" in d.running  # the next run starts
