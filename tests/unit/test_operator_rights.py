"""The ``[operator]`` table of a net file: which external events an operator may raise and which
outcomes they may force (loading with file:line problems, the canonical form, PNML, the console's
drafts)."""

from __future__ import annotations

from pathlib import Path

import pytest

from coordinator.errors import NetError
from coordinator.net import OperatorRights
from coordinator.netfile import dump_net, lint_net, loads_net
from coordinator.netfile.pnml import dump_pnml, loads_pnml
from coordinator.web.draft import draft_of_text, validate_draft

ROOT = Path(__file__).resolve().parents[2]

DRILL = """\
[net]
name = "drill"

[operator]
inject = ["ext:tick"]
force = { work = ["success", "failure.none_found", "error"] }

[[place]]
id = "idle"
tokens = 1

[[place]]
id = "working"
task = "work"

[task.work]
actions = ["echo"]

[[transition]]
id = "go"
events = ["ext:tick"]
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
inputs = { working = 1 }
outputs = { idle = 1 }
"""


def test_the_operator_table_says_what_may_be_injected_and_forced():
    net = loads_net(DRILL, "drill.toml")
    assert net.operator.may_inject("ext:tick") and not net.operator.may_inject("ext:tock")
    assert net.operator.may_force("work", "failure.none_found") and not net.operator.may_force("work", "failure")
    assert not loads_net((ROOT / "nets" / "demo.toml").read_text(encoding="utf-8")).operator  # nothing declared


def test_the_operator_table_survives_the_canonical_form_and_pnml():
    net = loads_net(DRILL, "drill.toml")
    text = dump_net(net)
    assert "[operator]" in text and loads_net(text) == net
    assert loads_pnml(dump_pnml(net)) == net
    catch = loads_net((ROOT / "nets" / "catch.toml").read_text(encoding="utf-8"))
    assert catch.operator.may_inject("ext:ball_caught") and catch.operator.may_force("locate", "error")


@pytest.mark.parametrize(("change", "line", "words"), [
    (('inject = ["ext:tick"]', 'inject = ["ext:tock"]'), 5, "which no transition links"),
    (('inject = ["ext:tick"]', 'inject = ["int:work.ok"]'), 5, "only external events"),
    (('"failure.none_found"', '"fail"'), 6, "write a status"),
    (("force = { work", "force = { wrok"), 6, "unknown task 'wrok'"),
    (("force = {", "forse = {"), 6, "did you mean 'force'"),
    (("force = { work = [", "force = { work = 3, x = ["), 6, "non-empty array"),
])
def test_a_bad_operator_table_is_a_problem_at_its_line(change, line, words):
    _, problems = lint_net(DRILL.replace(*change), "drill.toml")
    assert problems, "the file should have been refused"
    assert any(p.line == line and words in p.problem for p in problems), [str(p) for p in problems]


def test_rights_built_in_code_are_checked_too():
    with pytest.raises(NetError, match="only external events"):
        OperatorRights(inject=("int:a.ok",))
    with pytest.raises(NetError, match="write a status"):
        OperatorRights(force={"a": ("done",)})
    net = loads_net(DRILL)
    with pytest.raises(NetError, match="does not have"):
        type(net)(name="x", places=net.places, transitions=net.transitions, arcs=net.arcs, tasks=net.tasks,
                  operator=OperatorRights(force={"grasp": ("error",)}))


def test_the_console_draft_carries_the_operator_table():
    draft = draft_of_text(DRILL)
    assert draft["operator"] == {"inject": ["ext:tick"], "force": {"work": ["success", "failure.none_found", "error"]}}
    validation = validate_draft(draft, "drill.toml")
    assert validation.net is not None and validation.net.operator == loads_net(DRILL).operator
    draft["operator"]["inject"] = ["ext:nothing"]
    (problem,) = validate_draft(draft, "drill.toml").problems
    assert "ext:nothing" in problem.text and problem.text.startswith("drill.toml:")
