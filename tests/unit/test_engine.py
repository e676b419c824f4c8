"""Execution semantics of the interpreted net (coordinator.engine), without sockets."""

from __future__ import annotations

from collections import Counter

import pytest

from coordinator.engine import (
    CancelAction,
    Engine,
    EngineState,
    Firing,
    Instance,
    StartAction,
)
from coordinator.errors import EngineError, NotEnabledError
from coordinator.net import (
    ActionSpec,
    Arc,
    PetriNet,
    Place,
    PlaceKind,
    PrimitiveTask,
    Transition,
)
from services.results import ActionResult, Status


def make_net(places, transitions, arcs, marking, tasks=()) -> PetriNet:
    """Build a net from compact specs: places 'id' or ('id', kind, task); arcs (src, dst[, w[, inhib]])."""
    ps = []
    for p in places:
        if isinstance(p, str):
            ps.append(Place(id=p))
        else:
            pid, kind, *task = p
            ps.append(Place(id=pid, kind=PlaceKind(kind), task=task[0] if task else None))
    ts = [Transition(id=t) if isinstance(t, str) else t for t in transitions]
    arcs_ = [Arc(source=a[0], target=a[1], weight=a[2] if len(a) > 2 else 1,
                 inhibitor=a[3] if len(a) > 3 else False) for a in arcs]
    tasks_ = {name: PrimitiveTask(name=name, actions=tuple(ActionSpec(name=a) for a in acts))
              for name, acts in tasks}
    return PetriNet(name="t", places=ps, transitions=ts, arcs=arcs_, initial_marking=marking, tasks=tasks_)


def task_net(extra_transitions=(), extra_arcs=()) -> PetriNet:
    """idle -start-> working(task work) -done(ok)-> finished ; -fail(error)-> recovered."""
    return make_net(
        ["idle", ("working", "primitive_task", "work"), "finished", "recovered", *[]],
        ["start",
         Transition(id="done", events=("int:work.ok",)),
         Transition(id="fail", events=("int:work.error",), hidden=True),
         *extra_transitions],
        [("idle", "start"), ("start", "working"), ("working", "done"), ("done", "finished"),
         ("working", "fail"), ("fail", "recovered"), *extra_arcs],
        {"idle": 1},
        tasks=[("work", ["fast", "slow"])],
    )


def test_transition_without_events_fires_as_soon_as_enabled():
    net = make_net(["a", "b", "c"], ["t1", "t2"], [("a", "t1"), ("t1", "b"), ("b", "t2"), ("t2", "c")], {"a": 1})
    engine = Engine(net)
    effects = engine.advance()
    assert [e.transition for e in effects if isinstance(e, Firing)] == ["t1", "t2"]
    assert engine.marking == {"c": 1}
    assert engine.state is EngineState.DEAD


def test_token_entering_a_primitive_task_place_starts_one_instance_with_the_chosen_action():
    engine = Engine(task_net(), chooser=lambda task, actions: actions[1])
    effects = engine.advance()
    starts = [e for e in effects if isinstance(e, StartAction)]
    assert len(starts) == 1
    assert (starts[0].task, starts[0].place, starts[0].action) == ("work", "working", "slow")
    assert engine.marking == {"working": 1}
    assert [i.id for i in engine.running_instances()] == [starts[0].instance]


def test_busy_token_does_not_enable_the_output_transitions():
    engine = Engine(task_net())
    engine.advance()
    assert engine.next_firing() is None
    assert engine.state is EngineState.RUNNING


def test_fireable_transitions_are_enabled_ones_whose_events_are_latched():
    net = task_net()
    engine = Engine(net)
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    # the token in 'working' is busy: the net's firing rule enables both exits, the engine fires neither
    assert net.enabled_transitions(engine.marking) == ("done", "fail")
    assert engine.fireable() == ()
    engine.complete(start.instance, ActionResult(status=Status.ERROR, reason="x"))
    assert engine.fireable() == ("fail",)


def test_success_takes_the_normal_branch():
    engine = Engine(task_net())
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult(status=Status.SUCCESS))
    fired = [e.transition for e in engine.advance() if isinstance(e, Firing)]
    assert fired == ["done"]
    assert engine.marking == {"finished": 1}


def test_failure_still_takes_the_normal_branch():
    engine = Engine(task_net())
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult(status=Status.FAILURE))
    assert [e.transition for e in engine.advance() if isinstance(e, Firing)] == ["done"]


def test_error_status_takes_the_error_branch():
    engine = Engine(task_net())
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult(status=Status.ERROR))
    effects = engine.advance()
    assert [e.transition for e in effects if isinstance(e, Firing)] == ["fail"]
    assert effects[0].instances == (start.instance,)
    assert engine.marking == {"recovered": 1}


def test_named_outcome_branches_on_the_result_of_the_primitive_task():
    net = task_net(
        extra_transitions=[Transition(id="missed", events=("int:work.missed",), priority=1)],
        extra_arcs=[("working", "missed"), ("missed", "idle")],
    )
    engine = Engine(net)
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult(status=Status.FAILURE, outcome="missed"))
    fired = [e.transition for e in engine.advance() if isinstance(e, Firing)]
    assert fired[:2] == ["missed", "start"]


def test_internal_event_stays_latched_until_the_transition_can_consume_it():
    net = make_net(
        ["go", ("working", "primitive_task", "work"), "gate", "out", "err"],
        ["start", Transition(id="done", events=("int:work.ok",)), Transition(id="fail", events=("int:work.error",))],
        [("go", "start"), ("start", "working"), ("working", "done"), ("gate", "done"), ("done", "out"),
         ("working", "fail"), ("fail", "err")],
        {"go": 1},
        tasks=[("work", ["a"])],
    )
    engine = Engine(net)
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult(status=Status.SUCCESS))
    assert engine.advance() == []
    assert [i.id for i in engine.ended_instances()] == [start.instance]
    net_gate = net.place("gate")
    assert net_gate.kind is PlaceKind.PLAIN
    # the gate token arrives later (through a restore of the marking, as an operator would edit)
    engine.restore({"working": 1, "gate": 1}, engine.ended_instances(), fired=engine.fired, next_instance=2)
    assert [e.transition for e in engine.advance() if isinstance(e, Firing)] == ["done"]
    assert engine.marking == {"out": 1}


def tick_net(tokens=1) -> PetriNet:
    return make_net(
        [("runs", "control"), "ready", "done"],
        ["arm", Transition(id="shoot", events=("ext:tick",))],
        [("runs", "arm"), ("arm", "ready"), ("ready", "shoot"), ("shoot", "done")],
        {"runs": tokens},
    )


def test_external_event_fires_an_enabled_transition_once_per_pulse():
    engine = Engine(tick_net(tokens=2))
    engine.advance()
    assert engine.marking == {"ready": 2}
    assert engine.waiting_for() == ("ext:tick",)
    fired = [e for e in engine.pulse("ext:tick") if isinstance(e, Firing)]
    assert [f.transition for f in fired] == ["shoot"]
    assert fired[0].pulse == "ext:tick"
    assert engine.marking == {"ready": 1, "done": 1}


def test_external_event_that_finds_nothing_enabled_is_dropped():
    net = make_net(
        ["a", "b", "c"],
        [Transition(id="t", events=("ext:tick",)), "late"],
        [("a", "late"), ("late", "b"), ("b", "t"), ("t", "c")],
        {"a": 1},
    )
    engine = Engine(net, seed=1)
    engine.pause()
    assert engine.pulse("tick") == []  # paused: lost
    engine.resume()
    engine.advance()
    assert engine.marking == {"b": 1}
    assert engine.next_firing() is None  # the earlier pulse was not remembered
    engine.pulse("tick")
    assert engine.marking == {"c": 1}


def test_bad_external_event_name_is_refused():
    with pytest.raises(EngineError):
        Engine(tick_net()).pulse("ext:not a topic")


def test_priority_wins_a_conflict():
    net = make_net(["a", "x", "y"], [Transition(id="lo"), Transition(id="hi", priority=2)],
                   [("a", "lo"), ("a", "hi"), ("lo", "x"), ("hi", "y")], {"a": 1})
    engine = Engine(net)
    assert [e.transition for e in engine.advance()] == ["hi"]


def test_weights_resolve_a_conflict_reproducibly_with_a_seed():
    net = make_net(["a", "x", "y"], [Transition(id="p", weight=3.0), Transition(id="q", weight=1.0)],
                   [("a", "p"), ("a", "q"), ("p", "x"), ("q", "y")], {"a": 1})
    picks = [Engine(net, seed=s).advance()[0].transition for s in range(2000)]
    share = Counter(picks)["p"] / len(picks)
    assert 0.70 < share < 0.80
    again = [Engine(net, seed=s).advance()[0].transition for s in range(2000)]
    assert picks == again


def test_inhibitor_arc_holds_the_transition_back():
    net = make_net(["a", "block", "b"], ["t"], [("a", "t"), ("block", "t", 1, True), ("t", "b")],
                   {"a": 1, "block": 1})
    engine = Engine(net)
    assert engine.advance() == []
    assert not net.enabled(engine.marking, "t")


def test_next_firing_decides_without_changing_the_marking():
    engine = Engine(tick_net())
    before = engine.marking
    firing = engine.next_firing()
    assert firing is not None and firing.transition == "arm"
    assert engine.marking == before
    journal: list[Firing] = []
    engine.advance(before_fire=journal.append)
    assert [f.transition for f in journal] == ["arm"]


def test_the_marking_is_a_snapshot_of_the_non_empty_places():
    engine = Engine(tick_net())
    for _ in range(3):
        marking = engine.marking
        before = marking.to_dict()
        assert all(n > 0 for n in before.values()) and dict(marking.items()) == before
        engine.advance()
        assert marking.to_dict() == before  # a snapshot: firing does not change it


def test_a_stale_firing_is_refused():
    engine = Engine(tick_net())
    firing = engine.next_firing()
    engine.apply(firing)
    with pytest.raises(NotEnabledError):
        engine.apply(firing)


def test_operator_inserts_and_removes_tokens_in_control_places_only():
    engine = Engine(tick_net(tokens=0))
    assert engine.state is EngineState.DEAD
    engine.insert_tokens("runs", 2)
    assert engine.state is EngineState.RUNNING
    engine.remove_tokens("runs", 1)
    assert engine.marking == {"runs": 1}
    with pytest.raises(EngineError, match="not a control place"):
        engine.insert_tokens("ready")
    with pytest.raises(EngineError, match="holds 1 tokens"):
        engine.remove_tokens("runs", 5)
    with pytest.raises(EngineError):
        engine.insert_tokens("runs", 0)


def test_emptying_the_control_place_stops_further_runs():
    engine = Engine(tick_net(tokens=3))
    engine.pause()
    engine.step()
    engine.remove_tokens("runs", 2)
    engine.resume()
    engine.advance()
    engine.pulse("tick")
    assert engine.marking == {"done": 1}
    assert engine.state is EngineState.DEAD


def test_pause_stops_firing_and_step_fires_exactly_one():
    net = make_net(["a", "b", "c"], ["t1", "t2"], [("a", "t1"), ("t1", "b"), ("b", "t2"), ("t2", "c")], {"a": 1})
    engine = Engine(net)
    engine.pause()
    assert engine.advance() == []
    assert engine.state is EngineState.PAUSED
    assert [e.transition for e in engine.step()] == ["t1"]
    assert engine.marking == {"b": 1}
    engine.resume()
    assert [e.transition for e in engine.advance()] == ["t2"]


def test_abort_cancels_every_running_action():
    net = make_net(["go", ("w", "primitive_task", "work"), "out"],
                   ["start", Transition(id="ok", events=("int:work.ok",)), Transition(id="err", events=("int:work.error",))],
                   [("go", "start", 1), ("start", "w", 2), ("w", "ok"), ("w", "err"), ("ok", "out"), ("err", "out")],
                   {"go": 1}, tasks=[("work", ["a"])])
    engine = Engine(net)
    starts = [e for e in engine.advance() if isinstance(e, StartAction)]
    assert len(starts) == 2
    cancels = engine.abort()
    assert sorted(c.instance for c in cancels) == sorted(s.instance for s in starts)
    assert all(isinstance(c, CancelAction) for c in cancels)
    assert engine.state is EngineState.ABORTED
    assert engine.advance() == []
    with pytest.raises(EngineError):
        engine.resume()


def test_completing_an_unknown_or_ended_instance_is_an_error():
    engine = Engine(task_net())
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    with pytest.raises(EngineError, match="no instance"):
        engine.complete("nope", ActionResult(status=Status.SUCCESS))
    engine.complete(start.instance, ActionResult(status=Status.SUCCESS))
    with pytest.raises(EngineError, match="already ended"):
        engine.complete(start.instance, ActionResult(status=Status.SUCCESS))


def test_max_firings_bounds_a_net_that_cycles_without_events():
    net = make_net(["a", "b"], ["t1", "t2"], [("a", "t1"), ("t1", "b"), ("b", "t2"), ("t2", "a")], {"a": 1})
    engine = Engine(net)
    assert len(engine.advance(max_firings=7)) == 7
    assert engine.fired == 7
    assert engine.state is EngineState.RUNNING


def test_start_launches_instances_for_tokens_already_in_task_places():
    net = task_net().with_initial_marking({"working": 2})
    engine = Engine(net)
    starts = engine.start()
    assert len(starts) == 2 and all(isinstance(s, StartAction) for s in starts)
    with pytest.raises(EngineError):
        engine.start()


def test_restore_rebuilds_marking_and_instances_from_a_journal():
    engine = Engine(task_net(), instance_prefix="run7-")
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    assert start.instance == "run7-1"
    other = Engine(task_net(), instance_prefix="run7-")
    other.restore({"working": 1}, [Instance(start.instance, "work", "working", start.action)],
                  fired=1, next_instance=2)
    other.complete("run7-1", ActionResult(status=Status.ERROR))
    assert [e.transition for e in other.advance() if isinstance(e, Firing)] == ["fail"]
    assert other.fired == 2
    with pytest.raises(EngineError):
        other.restore({}, [Instance("x", "work", "working", "fast")], fired=0, next_instance=1)


def test_a_chooser_that_picks_an_unknown_action_is_refused():
    engine = Engine(task_net(), chooser=lambda task, actions: "teleport")
    with pytest.raises(EngineError, match="teleport"):
        engine.advance()


def test_a_seeded_run_fires_the_same_sequence_in_another_process():
    import os
    import subprocess
    import sys

    code = (
        "from coordinator.net import *; from coordinator.engine import Engine\n"
        "ps=[Place(id=f'p{i}') for i in range(20)]; ts=[Transition(id=f't{i}') for i in range(20)]\n"
        "arcs=[Arc(source=f'p{i}',target=f't{i}') for i in range(20)]"
        "+[Arc(source=f't{i}',target=f'p{(i*7+3)%20}') for i in range(20)]\n"
        "net=PetriNet(name='n',places=ps,transitions=ts,arcs=arcs,initial_marking={f'p{i}':1 for i in range(0,20,3)})\n"
        "print(','.join(f.transition for f in Engine(net, seed=5).advance(max_firings=300)))\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    outs = set()
    for hashseed in ("1", "2", "3"):
        env = dict(os.environ, PYTHONHASHSEED=hashseed, PYTHONPATH=root)
        outs.add(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                check=True, timeout=60).stdout)
    assert len(outs) == 1


# ---------------------------------------------------------------------- a run at rest
def test_operator_options_name_the_control_tokens_that_would_let_a_transition_fire():
    net = make_net(
        [("runs", "control"), ("hold", "control"), "robot", "busy", "done"],
        [Transition(id="start", events=("ext:tick",)), "finish"],
        [("runs", "start", 2), ("robot", "start"), ("hold", "start", 1, True), ("start", "busy"),
         ("busy", "finish"), ("finish", "robot"), ("finish", "done")],
        {"runs": 1, "hold": 2, "robot": 1},
    )
    engine = Engine(net)
    (option,) = engine.operator_options()
    assert (option.transition, dict(option.insert), dict(option.remove), option.event) == (
        "start", {"runs": 1}, {"hold": 2}, "ext:tick")
    assert str(option) == "+ runs 1, - hold 2 would enable start (then it waits for ext:tick)"
    engine.remove_tokens("hold", 2)
    engine.insert_tokens("runs", 1)
    assert engine.operator_options() == ()  # nothing is held back by a control place any more
    engine.remove_tokens("runs", 2)
    assert [dict(o.insert) for o in engine.operator_options()] == [{"runs": 2}]


def test_a_transition_held_back_by_another_place_is_no_operator_option():
    net = make_net([("runs", "control"), "robot", "x"], ["start"],
                   [("runs", "start"), ("robot", "start"), ("start", "x")], {"runs": 0, "robot": 0})
    assert Engine(net).operator_options() == ()


def test_a_pulse_window_can_be_fired_one_firing_at_a_time():
    engine = Engine(tick_net(tokens=2))
    engine.advance()
    engine.begin_pulse("ext:tick")
    firing = engine.next_firing()
    assert firing is not None and firing.pulse == "ext:tick"
    engine.apply(firing)
    assert engine.next_firing() is None  # each linked transition fires once per pulse
    engine.end_pulse()
    assert engine.next_firing() is None and engine.marking == {"ready": 1, "done": 1}


def test_a_run_at_rest_is_home_on_its_work_places_whatever_its_counters_hold():
    from coordinator.engine.rest import at_rest, work_places

    net = task_net()
    assert work_places(net) == ("idle", "working")  # finished and recovered are sinks
    engine = Engine(net)
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult.success())
    engine.advance()
    rest = at_rest(engine, home={"idle": 0})
    assert rest.at_home and rest.stuck == () and engine.marking == {"finished": 1}
    rest = at_rest(engine)  # home is the initial marking: idle 1
    assert not rest.at_home and rest.stuck == ("idle: 0 tokens (home 1)",)


def test_a_token_left_in_a_primitive_task_place_is_named_with_how_its_action_ended():
    from coordinator.engine.rest import at_rest

    net = make_net(["idle", ("working", "primitive_task", "work"), "finished"],
                   ["start", Transition(id="done", events=("int:work.caught",))],
                   [("idle", "start"), ("start", "working"), ("working", "done"), ("done", "finished")],
                   {"idle": 1}, tasks=[("work", ["a"])])
    engine = Engine(net)
    (start,) = [e for e in engine.advance() if isinstance(e, StartAction)]
    engine.complete(start.instance, ActionResult.failure(outcome="missed"))
    assert engine.advance() == [] and engine.state is EngineState.DEAD
    rest = at_rest(engine, home={"idle": 0})
    assert rest.stuck == ("working: 1 token (work ended failure (missed); no transition takes it)",)
