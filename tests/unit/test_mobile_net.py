"""The mobile robot's task net (nets/mobile.toml, the paper's Fig. 3): its file, its analysis (the
robotic reading) and its execution by the engine with scripted results, without sockets."""

from __future__ import annotations

from pathlib import Path

import pytest

from coordinator.analysis.robotic import report
from coordinator.engine import Engine, EngineState, Firing, StartAction
from coordinator.net import PetriNet, PlaceKind, parse_event
from coordinator.netfile import load_any, load_net
from services.results import ActionResult

NET = Path(__file__).resolve().parents[2] / "nets" / "mobile.toml"

TASK_OUTCOMES = {  # the contract with the nodes: task -> (actions, named outcomes of its exits)
    "follow_track": ({"follow_centroid", "follow_ransac", "follow_scanline"}, {"interruption", "end", "lost"}),
    "find_beacon": ({"find_beacon"}, {"found", "not_found"}),
    "goto_beacon": ({"goto_beacon"}, {"ok"}),
    "reacquire_track": ({"reacquire_track"}, {"success", "lost"}),
    "stop_at_t": ({"stop_at_t"}, {"ok"}),
    "stop_robot": ({"stop_robot"}, {"ok"}),
}


@pytest.fixture(scope="module")
def net() -> PetriNet:
    return load_net(NET)


@pytest.fixture(scope="module")
def analysis() -> dict:
    return report(load_any(NET, interpreted=False))


def _exits(net: PetriNet, place: str) -> list:
    return [t for t in net.transitions if place in net.input_places[t.id] and t.internal_events]


def test_the_net_names_the_contracts_tasks_actions_and_outcomes(net: PetriNet) -> None:
    assert net.interpretation_problems() == []
    assert set(net.tasks) == set(TASK_OUTCOMES)
    for name, (actions, outcomes) in TASK_OUTCOMES.items():
        assert {a.name for a in net.tasks[name].actions} == actions
        (place,) = [p.id for p in net.places if p.task == name]
        named = {parse_event(e)[2] for t in _exits(net, place) for e in t.internal_events}
        assert outcomes | {"error"} <= named, name
    assert net.tasks["follow_track"].learner["scheme"] == "pursuit"
    assert all(e.startswith("int:") for t in net.transitions for e in t.events)  # all events internal


def test_the_operator_has_runs_a_stop_request_and_a_reset_request(net: PetriNet) -> None:
    control = {p.id for p in net.places if p.kind is PlaceKind.CONTROL}
    assert control == {"runs_remaining", "stop_request", "reset_request"}
    assert net.home_marking is not None and net.home_marking["robot_ready"] == 1


def test_every_error_exit_is_a_hidden_recovery_branch(net: PetriNet) -> None:
    for t in net.transitions:
        if any(parse_event(e)[2] == "error" for e in t.internal_events):
            assert t.hidden, t.id


def test_the_nominal_conflicts_are_binary_choices_on_named_outcomes(net: PetriNet) -> None:
    # Among the exits of a task place that need nothing but the task's token, no result enables two
    # of the same priority: each choice is decided by the outcome of the task that just ended.
    kinds = {"interruption": "success", "end": "success", "found": "success", "not_found": "failure",
             "lost": "failure", "success": "success", "ok": "success"}
    for p in net.places:
        if p.kind is not PlaceKind.PRIMITIVE_TASK:
            continue
        pure = [t for t in _exits(net, p.id) if set(net.input_places[t.id]) == {p.id}
                and not net.inhibitor_places[t.id]]
        for outcome, status in kinds.items():
            latched = {"ok", status, outcome}
            taken = [t.id for t in pure if all(parse_event(e)[2] in latched for e in t.internal_events)]
            assert len(taken) <= 1, (p.id, outcome, taken)
    nominal = {t.id: parse_event(t.events[0])[2] for t in _exits(net, "following") if not t.hidden
               and t.priority == 0}
    assert nominal == {"interruption": "interruption", "end_mark": "end"}  # interruption or not, end or not


def test_the_robotic_reading_holds_stable_error_recoverable_controllable(analysis: dict) -> None:
    rob = analysis["robotic"]
    assert analysis["bounded"] is True and rob["stable"]["holds"] is True
    assert rob["error_recoverable"]["holds"] is True, rob["error_recoverable"]["explanation"]
    assert rob["controllable"]["holds"] is True, rob["controllable"]["explanation"]
    assert analysis["environment"]["control_places"] == {"runs_remaining": 1, "stop_request": 1, "reset_request": 1}
    assert analysis["retries"]["unbounded"] == []
    assert [r["transition"] for r in analysis["retries"]["retries"]] == ["brake_retry"]
    conflicts = {c["place"]: set(c["transitions"]) for c in analysis["structural_conflicts"]}
    assert {"interruption", "end_mark"} <= conflicts["following"]
    assert {"beacon_found", "no_beacon"} <= conflicts["finding"]


def test_the_gspn_view_gives_a_course_time_near_the_measured_one() -> None:
    from coordinator.analysis.gspn import analyse as solve
    from coordinator.analysis.ptimed import to_gspn

    view = to_gspn(load_net(NET))
    res = solve(view.net)
    # phase 1: ~20 m courses at 0.75 m/s mean (26.7 s); a-priori reliabilities are lower bounds
    assert 20.0 < res.mean_time_to_absorption < 32.0
    completed = sum(a["probability"] for a in res.absorption if a["marking"].get("completed_runs") == 1)
    assert completed > 0.9


class Driver:
    """Feeds the engine results by task, as the nodes would, recording firings and starts."""

    def __init__(self) -> None:
        self.engine = Engine(load_net(NET), seed=1)
        self.running: dict[str, StartAction] = {}
        self.started: list[str] = []
        self.fired: list[str] = []
        self._take(self.engine.start())
        self._take(self.engine.advance())

    def _take(self, effects: list) -> None:
        for e in effects:
            if isinstance(e, StartAction):
                self.running[e.task] = e
                self.started.append(e.task)
            elif isinstance(e, Firing):
                self.fired.append(e.transition)

    def end(self, task: str, result: ActionResult) -> None:
        start = self.running.pop(task)
        self.engine.complete(start.instance, result)
        self._take(self.engine.advance())

    def at_rest(self) -> dict[str, int]:
        assert not self.running and self.engine.state is EngineState.DEAD, (self.running, self.engine.state)
        return dict(self.engine.marking)


HOME = {"robot_ready": 1, "recovery_attempts_left": 2, "brake_retries_left": 2}


def test_a_course_with_one_interruption_ends_on_the_t_mark() -> None:
    d = Driver()
    d.end("follow_track", ActionResult.success(outcome="interruption"))
    d.end("find_beacon", ActionResult.success(outcome="found"))
    d.end("goto_beacon", ActionResult.success())
    d.end("reacquire_track", ActionResult.success(outcome="ok"))
    d.end("follow_track", ActionResult.success(outcome="end"))
    d.end("stop_at_t", ActionResult.success())
    assert d.fired == ["start_run", "interruption", "beacon_found", "at_beacon", "track_reacquired",
                       "end_mark", "stopped_at_t"]
    assert d.started == ["follow_track", "find_beacon", "goto_beacon", "reacquire_track", "follow_track",
                         "stop_at_t"]
    assert d.at_rest() == {**HOME, "completed_runs": 1}


def test_a_lost_track_brakes_and_aborts_the_run() -> None:
    d = Driver()
    d.end("follow_track", ActionResult.failure(outcome="lost", reason="no line for 0.3 s off an interruption"))
    assert d.fired[-1] == "track_lost" and "stop_robot" in d.running
    d.end("stop_robot", ActionResult.success())
    assert d.at_rest() == {**HOME, "aborted_runs": 1}


def test_an_error_in_goto_beacon_brakes_and_aborts_the_run() -> None:
    d = Driver()
    d.end("follow_track", ActionResult.success(outcome="interruption"))
    d.end("find_beacon", ActionResult.success(outcome="found"))
    d.end("goto_beacon", ActionResult.error("drive node gone"))
    assert d.fired[-1] == "goto_failed"
    d.end("stop_robot", ActionResult.success())
    assert d.at_rest() == {**HOME, "aborted_runs": 1}


def test_a_lost_reacquisition_looks_for_the_beacon_again_twice_then_gives_up() -> None:
    d = Driver()
    d.end("follow_track", ActionResult.success(outcome="interruption"))
    for _ in range(3):
        d.end("find_beacon", ActionResult.success(outcome="found"))
        d.end("goto_beacon", ActionResult.success())
        d.end("reacquire_track", ActionResult.failure(outcome="lost"))
    assert d.fired.count("reacquire_retry") == 2 and d.fired[-1] == "reacquire_given_up"
    d.end("stop_robot", ActionResult.success())
    assert d.fired.count("recovery_attempts_restored") == 2
    assert d.at_rest() == {**HOME, "aborted_runs": 1}


def test_a_stop_request_brakes_when_the_follow_segment_ends() -> None:
    d = Driver()
    d.engine.insert_tokens("stop_request")
    d.end("follow_track", ActionResult.success(outcome="interruption"))
    assert d.fired[-1] == "stop_requested_after_follow"
    d.end("stop_robot", ActionResult.success())
    assert d.at_rest() == {**HOME, "stopped_runs": 1}


def test_braking_that_keeps_failing_puts_the_robot_out_of_service_until_the_operator_resets_it() -> None:
    d = Driver()
    d.end("follow_track", ActionResult.error("camera frames stopped"))
    for _ in range(3):
        d.end("stop_robot", ActionResult.error("drive fault"))
    assert d.fired.count("brake_retry") == 2 and d.fired[-1] == "brake_given_up"
    assert d.at_rest()["robot_out_of_service"] == 1
    d.engine.insert_tokens("reset_request")
    d.engine.insert_tokens("runs_remaining")
    d._take(d.engine.advance())
    assert d.fired[-4:-1] == ["operator_reset", "brake_retries_restored", "brake_retries_restored"]
    assert d.fired[-1] == "start_run" and "follow_track" in d.running


def test_the_exits_declared_weights_are_the_a_priori_shares_of_the_outcomes_in_the_gspn() -> None:
    from coordinator.analysis.ptimed import to_gspn

    view = to_gspn(load_net(NET))
    w = {t.id: t.weight for t in view.net.transitions}
    normal = w["interruption"] + w["end_mark"] + w["track_lost"] + w["stop_requested_after_follow"]
    assert normal == pytest.approx(0.995)  # follow_track's a-priori reliability
    assert w["interruption"] / w["end_mark"] == pytest.approx(0.57 / 0.43)
    assert w["follow_failed"] == pytest.approx(0.005)
    assert not any("assuming 1/" in warning for warning in view.warnings)
