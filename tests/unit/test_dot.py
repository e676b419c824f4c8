"""DOT pictures of nets: shapes per kind, events, hidden branches, inhibitor arcs, weights."""

from __future__ import annotations

import re
from pathlib import Path

from coordinator.net import Arc, PetriNet, Place, PlaceKind, Transition, TransitionKind
from coordinator.netfile import load_net
from coordinator.netfile.dot import to_dot

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "nets" / "demo.toml"


def node_line(dot: str, node: str) -> str:
    for line in dot.splitlines():
        if line.strip().startswith(f'"{node}" ['):
            return line
    raise AssertionError(f"no node {node!r} in\n{dot}")


def edge_lines(dot: str) -> list[str]:
    return [line.strip() for line in dot.splitlines() if " -> " in line]


def small_net() -> PetriNet:
    return PetriNet(
        name="small",
        places=(Place(id="p", kind=PlaceKind.RESOURCE), Place(id="q"), Place(id="r", label='say "r"')),
        transitions=(Transition(id="t", events=("ext:tick",), priority=2),
                     Transition(id="u", kind=TransitionKind.EXPONENTIAL, rate=0.5, servers=None),
                     Transition(id="h", hidden=True)),
        arcs=(Arc(source="p", target="t", weight=3), Arc(source="t", target="q"),
              Arc(source="r", target="t", inhibitor=True), Arc(source="q", target="u"),
              Arc(source="u", target="p"), Arc(source="q", target="h"), Arc(source="h", target="r")),
        initial_marking={"p": 3},
    )


def test_places_are_circles_with_token_counts_and_names() -> None:
    dot = to_dot(small_net())
    line = node_line(dot, "p:p")
    assert 'shape="circle"' in line and 'label="3"' in line and 'xlabel="p"' in line
    assert 'label=""' in node_line(dot, "p:q")


def test_place_kinds_get_distinct_styles_and_tasks_are_named() -> None:
    dot = to_dot(load_net(DEMO))
    styles = {node_line(dot, f"p:{pid}").split("label=")[0] for pid in ("runs_remaining", "robot", "sensing", "done")}
    assert len(styles) == 4
    sensing = node_line(dot, "p:sensing")
    assert 'shape="doublecircle"' in sensing and "(sense)" in sensing


def test_transitions_are_boxes_with_events_priority_and_rate() -> None:
    dot = to_dot(small_net())
    t = node_line(dot, "t:t")
    assert 'shape="box"' in t and "ext:tick" in t and "priority 2" in t
    u = node_line(dot, "t:u")
    assert "rate 0.5/s" in u and "inf servers" in u and 'style="solid"' in u


def test_hidden_branches_are_dashed_or_left_out() -> None:
    net = small_net()
    dot = to_dot(net)
    assert "dashed" in node_line(dot, "t:h")
    assert any('"t:h" -> "p:r"' in e and "dashed" in e for e in edge_lines(dot))
    hidden = to_dot(net, show_hidden=False)
    assert '"t:h"' not in hidden
    # r is still drawn: a visible transition (t) touches it through its inhibitor arc
    node_line(hidden, "p:r")


def test_places_only_hidden_branches_touch_are_left_out_with_them() -> None:
    dot = to_dot(load_net(DEMO), show_hidden=False)
    assert '"p:recovering"' not in dot and '"t:recovered"' not in dot
    assert '"t:sense_failed"' not in dot
    assert '"p:computing" -> "t:computed";' in dot


def test_inhibitor_arcs_have_odot_heads_and_weights_label_arcs() -> None:
    edges = edge_lines(to_dot(small_net()))
    assert any(e.startswith('"p:r" -> "t:t"') and 'arrowhead="odot"' in e for e in edges)
    assert any(e.startswith('"p:p" -> "t:t"') and 'label="3"' in e for e in edges)
    assert '"t:t" -> "p:q";' in edges


def test_a_given_marking_replaces_the_initial_one() -> None:
    dot = to_dot(small_net(), marking={"q": 12})
    assert 'label="12"' in node_line(dot, "p:q") and 'label=""' in node_line(dot, "p:p")


def test_output_is_balanced_and_quotes_are_escaped() -> None:
    dot = to_dot(small_net())
    assert dot.startswith('digraph "small" {') and dot.rstrip().endswith("}")
    assert 'xlabel="say \\"r\\""' in node_line(dot, "p:r")
    unescaped = re.sub(r'\\.', "", dot)
    assert unescaped.count('"') % 2 == 0
    assert unescaped.count("[") == unescaped.count("]")
    assert len(edge_lines(dot)) == len(small_net().arcs)
