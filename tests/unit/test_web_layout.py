"""The drawing's positions live in the net file (``pos = [x, y]``; PNML ``<graphics><position>``), are
checked like every other key, and never change the net itself."""

from __future__ import annotations

from pathlib import Path

import pytest

from coordinator.netfile import (
    dump_net,
    lint_net,
    load_any,
    load_layout,
    loads_layout,
    loads_net,
)
from coordinator.netfile.layout import pnml_layout
from coordinator.netfile.pnml import dump_pnml, loads_pnml

ROOT = Path(__file__).resolve().parents[2]

NET = """
[net]
name = "two"

[[place]]
id = "a"
tokens = 1
pos = [10, -20.5]

[[place]]
id = "b"

[[transition]]
id = "t"
pos = [30.0, 40.0]
inputs = { a = 1 }
outputs = { b = 1 }
"""


def test_positions_are_read_from_a_toml_net_file_and_do_not_change_the_net():
    assert loads_layout(NET) == {"a": (10.0, -20.5), "t": (30.0, 40.0)}
    without = "\n".join(line for line in NET.splitlines() if not line.startswith("pos"))
    assert loads_net(NET) == loads_net(without)


def test_the_canonical_form_keeps_the_positions_it_is_given():
    net = loads_net(NET)
    text = dump_net(net, loads_layout(NET))
    assert loads_layout(text) == loads_layout(NET)
    assert loads_net(text) == net
    assert "pos" not in dump_net(net)  # without a layout, the canonical form is as before


def test_the_catching_net_carries_a_hand_placed_drawing_of_every_element():
    net = load_any(ROOT / "nets" / "catch.toml")
    layout = load_layout(ROOT / "nets" / "catch.toml")
    assert set(layout) == {p.id for p in net.places} | {t.id for t in net.transitions}
    assert layout["runs_remaining"][1] < layout["start_run"][1] < layout["locating"][1]  # the run flows down


@pytest.mark.parametrize("value, problem", [
    ('"here"', "must be [x, y]"),
    ("[1]", "must be [x, y]"),
    ("[1, 2, 3]", "must be [x, y]"),
    ("[true, 2]", "must be [x, y]"),
    ("[nan, 2]", "finite coordinates"),
    ("[1e9, 2]", "finite coordinates"),
])
def test_a_bad_position_is_a_problem_at_its_line(value: str, problem: str):
    net, problems = lint_net(NET.replace("pos = [10, -20.5]", f"pos = {value}"), "two.toml")
    assert net is None
    assert [(p.line, problem in p.problem) for p in problems] == [(8, True)]
    assert "a" not in loads_layout(NET.replace("pos = [10, -20.5]", f"pos = {value}"))


def test_pnml_positions_travel_in_the_standard_graphics_element():
    net = loads_net(NET)
    text = dump_pnml(net, loads_layout(NET))
    assert '<graphics><position x="10.0" y="-20.5"/></graphics>' in text
    assert pnml_layout(text) == {"a": (10.0, -20.5), "t": (30.0, 40.0)}
    assert loads_pnml(text) == loads_pnml(dump_pnml(net))  # the net read back is the same


def test_a_pnml_document_the_reader_refuses_has_no_positions():
    assert pnml_layout('<!DOCTYPE x [<!ENTITY a "b">]><pnml/>') == {}
    assert pnml_layout(b"\xff\xfe not xml") == {}


def test_a_long_chain_without_positions_is_folded_into_bands_that_fit_a_screen():
    from coordinator.web.autolayout import layered_layout

    nodes = [f"n{k}" for k in range(400)]
    arcs = [(nodes[k], nodes[k + 1]) for k in range(399)]
    pos = layered_layout(nodes, arcs, first=["n0"])
    xs = [x for x, _ in pos.values()]
    ys = [y for _, y in pos.values()]
    assert len(set(pos.values())) == 400                    # no two nodes on one spot
    assert max(ys) - min(ys) <= 4 * (max(xs) - min(xs))       # not one column 400 layers tall
    assert pos["n0"][1] < pos["n1"][1]                        # still top to bottom within a band
