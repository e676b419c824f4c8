"""The TOML net format: loading, file:line validation, canonical saving, placement checks."""

from __future__ import annotations

import argparse
import datetime as dt
import tomllib
from pathlib import Path

import pytest

from coordinator.commands import check as check_cmd
from coordinator.commands import export as export_cmd
from coordinator.errors import NetError, NetFileError
from coordinator.net import (
    ActionSpec,
    Arc,
    PetriNet,
    Place,
    PlaceKind,
    PrimitiveTask,
    Transition,
    TransitionKind,
)
from coordinator.netfile import (
    SourceMap,
    check_net,
    dump_net,
    format_value,
    lint_net,
    load_any,
    load_net,
    loads_net,
    save_net,
)
from services.location import parse_location
from services.results import ActionResult, Status

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "nets" / "demo.toml"
EXAMPLES = sorted((ROOT / "nets" / "examples").glob("*.toml"))
SERVICES = ROOT / "tests" / "data" / "services_demo.toml"

BASE = """\
[net]
name = "locate_once"

[[place]]
id = "idle"
kind = "resource"
tokens = 1

[[place]]
id = "locating"
kind = "primitive_task"
task = "locate"

[task.locate]
actions = ["locate_threshold"]

[[transition]]
id = "start"
inputs = { idle = 1 }
outputs = { locating = 1 }

[[transition]]
id = "ok"
events = ["int:locate.ok"]
inputs = { locating = 1 }
outputs = { idle = 1 }

[[transition]]
id = "error"
events = ["int:locate.error"]
hidden = true
inputs = { locating = 1 }
outputs = { idle = 1 }
"""


def line_of(text: str, snippet: str, occurrence: int = 1) -> int:
    """1-based line of the ``occurrence``-th line containing ``snippet``."""
    found = 0
    for number, line in enumerate(text.splitlines(), start=1):
        if snippet in line:
            found += 1
            if found == occurrence:
                return number
    raise AssertionError(f"{snippet!r} not in text")


def edit(old: str, new: str, text: str = BASE) -> str:
    assert text.count(old) >= 1, old
    return text.replace(old, new, 1)


def first_problem(text: str) -> NetError:
    with pytest.raises(NetError) as info:
        loads_net(text, path="task.toml")
    assert info.value.path == "task.toml"
    return info.value


# ----------------------------------------------------------------------------------- loading
def test_base_net_loads_with_kinds_tasks_and_arcs() -> None:
    net = loads_net(BASE)
    assert net.name == "locate_once"
    assert net.place("idle").kind is PlaceKind.RESOURCE
    assert net.place("locating").task == "locate"
    assert net.tasks["locate"].actions == (ActionSpec(name="locate_threshold"),)
    assert net.initial_marking == {"idle": 1}
    assert net.transition("error").hidden
    assert net.input_places["ok"] == {"locating": 1}
    assert net.interpretation_problems() == []


def test_demo_net_is_a_valid_task_net_that_terminates_at_home() -> None:
    net = load_net(DEMO)
    assert net.interpretation_problems() == []
    assert net.initial_marking["runs_remaining"] == 3
    assert {p.kind for p in net.places} >= {PlaceKind.RESOURCE, PlaceKind.CONTROL, PlaceKind.PRIMITIVE_TASK}
    assert len(net.tasks["compute"].actions) == 2
    assert any(t.hidden for t in net.transitions)
    # Play every run down the success path and, separately, down the error branches: both end at home.
    for exits in (("sensed", "computed"), ("sense_failed", "recovered"), ("sensed", "compute_failed", "recovered")):
        marking = net.initial_marking
        for _ in range(3):
            marking = net.fire(marking, "start_run")
            for t in exits:
                marking = net.fire(marking, t)
        assert net.enabled_transitions(marking) == ()
        assert marking == net.home_marking


def test_task_params_are_merged_under_each_action_params() -> None:
    text = edit('actions = ["locate_threshold"]',
                'actions = ["a", { name = "b", params = { k = 2 }, cost = 3 }]\nparams = { k = 1, j = 0 }')
    task = loads_net(text).tasks["locate"]
    assert dict(task.action("a").params) == {"k": 1, "j": 0}
    assert dict(task.action("b").params) == {"k": 2, "j": 0}
    assert task.action("b").cost == 3.0 and isinstance(task.action("b").cost, float)


def test_task_key_alone_infers_a_primitive_task_place() -> None:
    net = loads_net(edit('kind = "primitive_task"\n', ""))
    assert net.place("locating").kind is PlaceKind.PRIMITIVE_TASK


def test_arc_tables_and_transition_tables_give_the_same_net() -> None:
    text = """\
[net]
name = "n"
[[place]]
id = "p"
tokens = 2
[[place]]
id = "q"
[[transition]]
id = "t"
[[arc]]
from = "p"
to = "t"
weight = 2
[[arc]]
from = "t"
to = "q"
[[arc]]
from = "q"
to = "t"
inhibitor = true
weight = 3
"""
    net = loads_net(text)
    assert set(net.arcs) == {Arc(source="p", target="t", weight=2), Arc(source="t", target="q"),
                             Arc(source="q", target="t", weight=3, inhibitor=True)}
    assert loads_net(dump_net(net)) == net
    assert "[[arc]]" not in dump_net(net)
    assert "inhibitors = { q = 3 }" in dump_net(net)


def test_gspn_fields_load_as_floats_and_infinite_servers() -> None:
    text = edit('id = "start"\n', 'id = "start"\nkind = "exponential"\nrate = 2\nservers = "infinite"\n'
                                  'priority = 3\nweight = 2\nlabel = "go"\n')
    t = loads_net(text).transition("start")
    assert t.kind is TransitionKind.EXPONENTIAL and t.rate == 2.0 and isinstance(t.rate, float)
    assert t.servers is None and t.priority == 3 and t.weight == 2.0 and t.label == "go"


# ----------------------------------------------------------------------------------- errors with lines
def test_toml_syntax_error_names_the_line_from_tomllib() -> None:
    text = edit("tokens = 1", "tokens = = 1")
    err = first_problem(text)
    assert isinstance(err, NetFileError)
    assert err.line == line_of(text, "tokens = = 1")
    assert "syntax" in err.problem


def test_unknown_place_in_an_arc_names_the_arc_line() -> None:
    text = edit("outputs = { locating = 1 }", "outputs = { locatin = 1 }")
    err = first_problem(text)
    assert err.line == line_of(text, "locatin = 1")
    assert "unknown place 'locatin'" in err.problem


def test_arc_from_place_to_place_is_reported_at_its_from_line() -> None:
    text = BASE + '\n[[arc]]\nfrom = "idle"\nto = "locating"\n'
    err = first_problem(text)
    assert err.line == line_of(text, 'from = "idle"')
    assert "joins two places" in err.problem


def test_arc_from_transition_to_transition_is_reported() -> None:
    text = BASE + '\n[[arc]]\nfrom = "start"\nto = "ok"\n'
    err = first_problem(text)
    assert err.line == line_of(text, 'from = "start"')
    assert "joins two transitions" in err.problem


def test_transition_named_in_inputs_is_reported_as_not_a_place() -> None:
    text = edit("inputs = { idle = 1 }", "inputs = { ok = 1 }")
    err = first_problem(text)
    assert err.line == line_of(text, "inputs = { ok = 1 }")
    assert "names transition 'ok'" in err.problem


def test_primitive_task_place_without_error_exit_is_reported_at_the_place() -> None:
    text = edit('events = ["int:locate.error"]\n', "")
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "locating"')
    assert "no error exit" in err.problem


def test_primitive_task_place_without_normal_exit_is_reported_at_the_place() -> None:
    text = edit('events = ["int:locate.ok"]', 'events = ["int:locate.error"]')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "locating"')
    assert "no normal exit" in err.problem


def test_internal_event_of_an_unknown_task_is_reported_at_its_transition() -> None:
    text = edit('events = ["int:locate.ok"]', 'events = ["int:locate.ok", "int:grasp.ok"]')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "ok"')
    assert "grasp" in err.problem


def test_bad_event_name_is_reported_at_the_events_line() -> None:
    text = edit('"int:locate.ok"', '"int:locate"')
    err = first_problem(text)
    assert err.line == line_of(text, 'events = ["int:locate"]')
    assert "bad event name 'int:locate'" in err.problem


@pytest.mark.parametrize("weight", ["-1", "0", "1.5", "true", '"2"'])
def test_negative_zero_or_non_integer_arc_weight_is_reported(weight: str) -> None:
    text = edit("inputs = { idle = 1 }", f"inputs = {{ idle = {weight} }}")
    err = first_problem(text)
    assert err.line == line_of(text, "inputs = { idle =")
    assert "integers >= 1" in err.problem


def test_bad_weight_in_an_arc_table_names_its_weight_line() -> None:
    text = BASE + '\n[[arc]]\nfrom = "idle"\nto = "ok"\nweight = 0\n'
    err = first_problem(text)
    assert err.line == line_of(text, "weight = 0")


def test_unknown_key_is_reported_with_a_suggestion() -> None:
    text = edit('events = ["int:locate.ok"]', 'evnts = ["int:locate.ok"]')
    net, problems = lint_net(text, "task.toml")
    assert net is None
    assert problems[0].line == line_of(text, "evnts")
    assert "did you mean 'events'" in problems[0].problem


def test_unknown_section_is_reported_with_a_suggestion() -> None:
    text = BASE + '\n[[places]]\nid = "x"\n'
    err = first_problem(text)
    assert err.line == line_of(text, "[[places]]")
    assert "did you mean 'place'" in err.problem


@pytest.mark.parametrize(("old", "new", "key"), [
    ("tokens = 1", 'tokens = "1"', "tokens"),
    ("hidden = true", 'hidden = "yes"', "hidden"),
    ('name = "locate_once"', "name = 3", "name"),
    ('actions = ["locate_threshold"]', 'actions = "locate_threshold"', "actions"),
])
def test_wrong_type_is_reported_at_its_key(old: str, new: str, key: str) -> None:
    text = edit(old, new)
    err = first_problem(text)
    assert err.line == line_of(text, new)
    assert err.problem.startswith(f"{key} of ")


def test_unknown_task_is_reported_at_the_task_key_of_the_place() -> None:
    text = edit('task = "locate"', 'task = "locat"')
    err = first_problem(text)
    assert err.line == line_of(text, 'task = "locat"')
    assert "unknown task 'locat'" in err.problem


def test_duplicate_place_id_is_reported_at_the_second_id() -> None:
    text = edit('id = "locating"', 'id = "idle"')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "idle"', occurrence=2)
    assert "duplicate place id 'idle'" in err.problem


def test_duplicate_transition_id_is_reported_at_the_second_id() -> None:
    text = edit('id = "error"', 'id = "ok"')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "ok"', occurrence=2)
    assert "duplicate transition id" in err.problem


def test_id_shared_by_a_place_and_a_transition_is_reported_at_the_transition() -> None:
    text = edit('id = "start"', 'id = "idle"')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "idle"', occurrence=2)
    assert "both a place and a transition" in err.problem


def test_place_without_id_is_reported_at_its_header() -> None:
    text = BASE + "\n[[place]]\ntokens = 1\n"
    err = first_problem(text)
    assert err.line == line_of(text, "[[place]]", occurrence=3)
    assert "no id" in err.problem


def test_unknown_place_kind_is_reported_at_the_kind_key() -> None:
    text = edit('kind = "resource"', 'kind = "robot"')
    err = first_problem(text)
    assert err.line == line_of(text, 'kind = "robot"')
    assert "unknown kind" in err.problem


def test_newer_format_version_is_refused() -> None:
    text = edit('name = "locate_once"', 'name = "locate_once"\nformat = 2')
    err = first_problem(text)
    assert err.line == line_of(text, "format = 2")


def test_exponential_transition_without_rate_is_reported_at_its_id() -> None:
    text = edit('id = "start"\n', 'id = "start"\nkind = "exponential"\n')
    err = first_problem(text)
    assert err.line == line_of(text, 'id = "start"')
    assert "rate" in err.problem


@pytest.mark.parametrize(("insert", "key"), [
    ("deadline_s = 0", "deadline_s"), ("mean_time_s = -1.0", "mean_time_s"), ("reliability = 1.5", "reliability"),
])
def test_out_of_range_task_values_are_reported_at_their_key(insert: str, key: str) -> None:
    text = edit('actions = ["locate_threshold"]', f'actions = ["locate_threshold"]\n{insert}')
    err = first_problem(text)
    assert err.line == line_of(text, insert)
    assert err.problem.startswith(key)


def test_rate_on_an_immediate_transition_is_reported_at_the_rate() -> None:
    text = edit('id = "start"\n', 'id = "start"\nrate = 2.0\n')
    err = first_problem(text)
    assert err.line == line_of(text, "rate = 2.0")
    assert "exponential" in err.problem


def test_task_without_actions_is_reported_at_its_header() -> None:
    text = edit('actions = ["locate_threshold"]', "actions = []")
    err = first_problem(text)
    assert err.line == line_of(text, "[task.locate]")


def test_unknown_key_inside_an_action_table_is_reported() -> None:
    text = edit('actions = ["locate_threshold"]', 'actions = [{ name = "a", parms = {} }]')
    err = first_problem(text)
    assert err.line == line_of(text, "parms")
    assert "did you mean 'params'" in err.problem


def test_inhibitor_arc_from_a_transition_is_refused() -> None:
    text = BASE + '\n[[arc]]\nfrom = "start"\nto = "idle"\ninhibitor = true\n'
    err = first_problem(text)
    assert err.line == line_of(text, "inhibitor = true")


def test_arc_given_twice_is_reported_at_the_second() -> None:
    text = BASE + '\n[[arc]]\nfrom = "idle"\nto = "start"\n'
    err = first_problem(text)
    assert err.line == line_of(text, 'from = "idle"')
    assert "given twice" in err.problem


def test_home_marking_with_unknown_place_is_reported_at_home() -> None:
    text = edit('name = "locate_once"', 'name = "locate_once"\nhome = { idel = 1 }')
    err = first_problem(text)
    assert err.line == line_of(text, "home = ")


def test_multiline_strings_and_arrays_do_not_confuse_line_finding() -> None:
    text = edit('name = "locate_once"', 'name = "locate_once"\ndescription = """\n[[place]]\nid = "x"\n"""')
    text = edit('events = ["int:locate.ok"]', 'events = [\n  "int:locate.ok",\n]\nevnts = 1', text)
    assert tomllib.loads(text)["net"]["description"].startswith("[[place]]")
    err = first_problem(text)
    assert err.line == line_of(text, "evnts")


def test_lint_collects_every_problem_sorted_by_line() -> None:
    text = edit("tokens = 1", 'tokens = "1"')
    text = edit('"int:locate.ok"', '"int:locate"', text)
    text = edit("outputs = { locating = 1 }", "outputs = { nowhere = 1 }", text)
    net, problems = lint_net(text, "task.toml")
    assert net is None
    lines = [p.line for p in problems]
    assert lines == sorted(lines) and len(problems) == 3
    assert str(problems[0]).startswith(f"task.toml:{line_of(text, 'tokens')}: ")


def test_plain_nets_may_skip_the_interpretation_rules() -> None:
    text = edit('events = ["int:locate.error"]\n', "")
    with pytest.raises(NetError):
        loads_net(text)
    assert loads_net(text, interpreted=False).transition("error").events == ()


# ----------------------------------------------------------------------------------- saving
@pytest.mark.parametrize("path", [DEMO, *EXAMPLES], ids=lambda p: p.name)
def test_shipped_nets_round_trip_through_canonical_toml(path: Path) -> None:
    net = load_net(path)
    text = dump_net(net)
    assert loads_net(text) == net
    assert dump_net(loads_net(text)) == text


def test_net_built_in_code_round_trips_with_awkward_values() -> None:
    net = PetriNet(
        name='odd "name" 2 ✓', description="line one\nline two\t\\ é ✓",
        places=(Place(id="a.b", kind=PlaceKind.CONTROL, label='say "hi"', capacity=4),
                Place(id="task-place", kind=PlaceKind.PRIMITIVE_TASK, task="do_it"),
                Place(id="err")),
        transitions=(Transition(id="go", priority=-2, weight=0.25),
                     Transition(id="done", events=("int:do_it.ok",)),
                     Transition(id="fail", events=("int:do_it.error",), hidden=True),
                     Transition(id="tick", events=("ext:camera_tick",), kind=TransitionKind.EXPONENTIAL,
                                rate=1e-3, servers=3)),
        arcs=(Arc(source="a.b", target="go", weight=2), Arc(source="go", target="task-place"),
              Arc(source="task-place", target="done"), Arc(source="task-place", target="fail"),
              Arc(source="fail", target="err"), Arc(source="err", target="tick", inhibitor=True, weight=5),
              Arc(source="tick", target="a.b")),
        initial_marking={"a.b": 7},
        tasks={"do_it": PrimitiveTask(name="do_it", actions=(
            ActionSpec(name="x", params={"when": dt.datetime(2026, 11, 21, 12, 0), "v": [1, 2.5, "s"],
                                         "nested": {"k y": True}}, cost=2.5),
            ActionSpec(name="y", cost=0.0)), deadline_s=1.5, learner={"scheme": "lri", "rate": 0.1},
            reliability=1.0)},
        home_marking={},
    )
    text = dump_net(net)
    back = loads_net(text)
    assert back == net
    assert dump_net(back) == text
    assert '"a.b" = 2' in text and "[task.do_it]" in text


def test_canonical_form_leaves_defaults_out() -> None:
    text = dump_net(loads_net(BASE))
    assert "priority" not in text and "weight" not in text and "servers" not in text
    assert "inhibitors" not in text
    assert text.startswith("# petrobot net file")


def test_format_value_round_trips_through_tomllib() -> None:
    value = {"s": 'q"\\\x01\n', "i": -3, "f": 1e-300, "inf": float("inf"), "b": False, "l": [[1], {}],
             "t": {"dotted.key": dt.date(2026, 11, 21)}, "time": dt.time(12, 30)}
    assert tomllib.loads("v = " + format_value(value))["v"] == value
    with pytest.raises(NetError):
        format_value(None)


def test_save_and_load_any_dispatch_on_suffix(tmp_path: Path) -> None:
    net = load_net(DEMO)
    save_net(net, tmp_path / "n.toml")
    assert load_any(tmp_path / "n.toml") == net
    from coordinator.netfile.pnml import save_pnml

    save_pnml(net, tmp_path / "n.pnml")
    save_pnml(net, tmp_path / "n.xml")
    assert load_any(tmp_path / "n.pnml") == net == load_any(tmp_path / "n.xml")
    with pytest.raises(NetFileError, match="unknown net file type"):
        load_any(tmp_path / "n.json")
    with pytest.raises(NetFileError, match="cannot read"):
        load_net(tmp_path / "missing.toml")


def test_source_map_finds_headers_keys_and_ids() -> None:
    smap = SourceMap.scan(BASE)
    assert smap.elements[("place", 1)] == line_of(BASE, "[[place]]", occurrence=2)
    assert smap.key("transition", 2, "hidden") == line_of(BASE, "hidden = true")
    assert smap.of_id("ok") == line_of(BASE, 'id = "ok"')
    assert smap.of_id("locate") == line_of(BASE, "[task.locate]")
    assert smap.of_id("nothing") is None


# ----------------------------------------------------------------------------------- placement
def test_check_net_accepts_the_demo_against_its_services_file() -> None:
    location = parse_location(SERVICES.read_text(), path=str(SERVICES))
    assert check_net(load_net(DEMO), location) == []


def test_check_net_reports_unplaced_actions_and_unpublished_events() -> None:
    text = edit('actions = ["locate_threshold"]', 'actions = ["echo", "teleport"]')
    text = edit('id = "start"\n', 'id = "start"\nevents = ["ext:go_signal"]\n', text)
    location = parse_location(SERVICES.read_text(), path=str(SERVICES))
    problems = check_net(loads_net(text), location)
    assert [element for element, _ in problems] == ["locate", "start"]
    assert "'teleport'" in problems[0][1] and "ext:go_signal" in problems[1][1]


# ----------------------------------------------------------------------------------- commands
def _args(command: object, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="petrobot")
    sub = parser.add_subparsers(dest="command")
    command.add_parser(sub)  # type: ignore[attr-defined]
    return parser.parse_args(argv)


def test_check_command_prints_ok_with_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    code = check_cmd.run(_args(check_cmd, ["check", str(DEMO), "--services", str(SERVICES)]))
    out = capsys.readouterr().out
    assert code == 0
    assert out.startswith("OK ") and "6 places, 6 transitions" in out and "2 primitive tasks" in out


def test_check_command_prints_each_problem_as_file_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = edit('actions = ["locate_threshold"]', 'actions = ["teleport"]')
    text = edit("tokens = 1", "tokens = -1", text)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    code = check_cmd.run(_args(check_cmd, ["check", str(path), "--services", str(SERVICES)]))
    assert code == 2
    out = capsys.readouterr().out.splitlines()
    assert out == [f"{path}:{line_of(text, 'tokens = -1')}: place 'idle' has a negative initial marking (-1)"]
    path.write_text(edit('actions = ["locate_threshold"]', 'actions = ["teleport"]'))
    assert check_cmd.run(_args(check_cmd, ["check", str(path), "--services", str(SERVICES)])) == 2
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith(f"{path}:{line_of(text, '[task.locate]')}: primitive action 'teleport'")


def test_export_command_writes_toml_pnml_and_dot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert export_cmd.run(_args(export_cmd, ["export", str(DEMO), "--to", "toml"])) == 0
    assert loads_net(capsys.readouterr().out) == load_net(DEMO)
    target = tmp_path / "demo.pnml"
    assert export_cmd.run(_args(export_cmd, ["export", str(DEMO), "--to", "pnml", "-o", str(target)])) == 0
    assert load_any(target) == load_net(DEMO)
    assert export_cmd.run(_args(export_cmd, ["export", str(DEMO), "--to", "dot", "--no-hidden"])) == 0
    dot = capsys.readouterr().out
    assert dot.startswith('digraph "demo"') and "recovered" not in dot
    assert export_cmd.run(_args(export_cmd, ["export", str(tmp_path / "none.toml"), "--to", "dot"])) == 2
    assert "cannot read" in capsys.readouterr().err


def test_the_example_in_the_format_documentation_is_a_valid_net() -> None:
    doc = (ROOT / "docs" / "netfile.md").read_text(encoding="utf-8")
    example = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    net = loads_net(example, path="docs/netfile.md")
    assert net.name == "locate_once" and len(net.tasks["locate"].actions) == 2


@pytest.mark.parametrize("seed", range(5))
def test_demo_net_terminates_at_home_under_the_engine_whatever_the_statuses(seed: int) -> None:
    import random

    from coordinator.engine import Engine, StartAction

    net = load_net(DEMO)
    engine = Engine(net, seed=seed)
    rng = random.Random(seed)
    pending = [e for e in engine.start() if isinstance(e, StartAction)]
    for _ in range(100):
        pending += [e for e in engine.advance() if isinstance(e, StartAction)]
        if not pending:
            break
        start = pending.pop(0)
        engine.complete(start.instance, ActionResult(status=rng.choice(list(Status))))
    assert not pending and engine.running_instances() == []
    assert engine.marking == net.home_marking


def test_a_bad_learner_configuration_is_reported_with_its_line():
    from coordinator.errors import NetError

    text = """
[net]
name = "l"

[[place]]
id = "w"
kind = "primitive_task"
task = "locate"
tokens = 0

[task.locate]
actions = ["a", "b"]
learner = { scheme = "pursuit", rate = 7.0 }

[[transition]]
id = "ok"
events = ["int:locate.ok"]
inputs = { w = 1 }

[[transition]]
id = "err"
events = ["int:locate.error"]
inputs = { w = 1 }
"""
    with pytest.raises(NetError) as info:
        loads_net(text, path="nets/l.toml")
    assert info.value.line == 13
    assert "rate" in info.value.problem and "nets/l.toml:13" in str(info.value)
