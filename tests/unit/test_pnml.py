"""PNML import and export: the 2009 grammar, the older dialect, MCC models, lossless round trips."""

from __future__ import annotations

import time
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from coordinator.errors import NetError, NetFileError
from coordinator.net import Arc, PetriNet, Place, PlaceKind, Transition, TransitionKind
from coordinator.netfile import dump_net, load_net, loads_net
from coordinator.netfile.pnml import (
    PNML_NS,
    PTNET_TYPE,
    dump_pnml,
    load_pnml,
    loads_pnml,
    save_pnml,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
from tests.unit.mcc_models import MCC

TOML_NETS = [ROOT / "nets" / "demo.toml", *sorted((ROOT / "nets" / "examples").glob("*.toml"))]

#: model -> (places, transitions, arcs, initial tokens), counted in the model files.
MCC_COUNTS = {
    "CircularTrains-PT-012": (24, 12, 48, 12),
    "ERK-PT-000001": (11, 11, 34, 5),
    "Eratosthenes-PT-010": (9, 8, 24, 9),
    "FMS-PT-00002": (22, 20, 50, 12),
    "Kanban-PT-00005": (16, 16, 40, 20),
    "Philosophers-PT-000005": (25, 25, 80, 10),
    "Railroad-PT-005": (68, 56, 313, 15),
    "ResAllocation-PT-R003C005": (30, 20, 84, 15),
    "SharedMemory-PT-000005": (41, 55, 200, 11),
    "TokenRing-PT-005": (36, 156, 624, 6),
}



def pnml(body: str, net_type: str = PTNET_TYPE) -> str:
    return (f'<?xml version="1.0"?>\n<pnml xmlns="{PNML_NS}">\n<net id="n" type="{net_type}">\n'
            f'<page id="pg">\n{body}\n</page>\n</net>\n</pnml>\n')


# ----------------------------------------------------------------------------------- MCC models
@pytest.mark.parametrize("model", sorted(MCC_COUNTS))
def test_every_mcc_model_loads_as_a_plain_net_with_its_counts(model: str) -> None:
    path = MCC / model / "model.pnml"
    start = time.perf_counter()
    net = load_pnml(path)
    elapsed = time.perf_counter() - start
    assert elapsed < 2.0
    places, transitions, arcs, tokens = MCC_COUNTS[model]
    assert (len(net.places), len(net.transitions), len(net.arcs), net.initial_marking.total) == (
        places, transitions, arcs, tokens)
    root = ET.parse(path).getroot()
    ids = {e.get("id") for e in root.iter(f"{{{PNML_NS}}}place")}
    assert {p.id for p in net.places} == ids
    assert all(p.kind is PlaceKind.PLAIN for p in net.places)
    assert all(t.kind is TransitionKind.IMMEDIATE and not t.events for t in net.transitions)
    assert net.name == model
    assert net.interpretation_problems() == []


@pytest.mark.parametrize("model", sorted(MCC_COUNTS))
def test_mcc_models_round_trip_through_pnml_and_toml(model: str) -> None:
    net = load_pnml(MCC / model / "model.pnml")
    assert loads_pnml(dump_pnml(net)) == net
    assert loads_net(dump_net(net)) == net


def test_kanban_matrices_match_its_arcs() -> None:
    net = load_pnml(MCC / "Kanban-PT-00005" / "model.pnml")
    assert int(net.pre.sum() + net.post.sum()) == sum(a.weight for a in net.arcs)


# ----------------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("path", TOML_NETS, ids=lambda p: p.name)
def test_toml_to_pnml_to_toml_is_unchanged(path: Path) -> None:
    net = load_net(path)
    back = loads_pnml(dump_pnml(net))
    assert back == net
    assert dump_net(back) == dump_net(net)


def test_awkward_text_and_every_field_survive_pnml() -> None:
    net = PetriNet(
        name='a <net> & "quotes"', description="two\nlines & <tags>",
        places=(Place(id="p", kind=PlaceKind.RESOURCE, label="<p> & 'q'", capacity=2),
                Place(id="q", kind=PlaceKind.CONTROL)),
        transitions=(Transition(id="t", events=("ext:tick",), priority=4, weight=0.1,
                                kind=TransitionKind.EXPONENTIAL, rate=1 / 3, servers=None, hidden=True,
                                label="t & u"),
                     Transition(id="a1")),
        arcs=(Arc(source="p", target="t", weight=2), Arc(source="t", target="q"),
              Arc(source="q", target="t", weight=9, inhibitor=True), Arc(source="q", target="a1")),
        initial_marking={"p": 2}, home_marking={"q": 1},
    )
    text = dump_pnml(net)
    assert loads_pnml(text) == net
    # arc ids never collide with node ids (a transition is called "a1" here)
    ids = [e.get("id") for e in ET.fromstring(text).iter() if e.get("id")]
    assert len(ids) == len(set(ids))


def test_export_follows_the_2009_grammar() -> None:
    net = load_net(ROOT / "nets" / "demo.toml")
    root = ET.fromstring(dump_pnml(net))
    assert root.tag == f"{{{PNML_NS}}}pnml"
    (net_elem,) = root.findall(f"{{{PNML_NS}}}net")
    assert net_elem.get("type") == PTNET_TYPE
    page = net_elem.find(f"{{{PNML_NS}}}page")
    assert page is not None
    assert len(page.findall(f"{{{PNML_NS}}}place")) == len(net.places)
    assert len(page.findall(f"{{{PNML_NS}}}arc")) == len(net.arcs)
    marking = page.find(f"{{{PNML_NS}}}place/{{{PNML_NS}}}initialMarking/{{{PNML_NS}}}text")
    assert marking is not None and marking.text == "3"
    tools = {e.get("tool") for e in root.iter(f"{{{PNML_NS}}}toolspecific")}
    assert tools == {"petrobot"}


def test_export_without_toolspecific_is_read_by_others_as_the_plain_net(tmp_path: Path) -> None:
    net = load_net(ROOT / "nets" / "examples" / "mutex.toml")
    text = dump_pnml(net)
    stripped = ET.fromstring(text)
    for parent in stripped.iter():
        for child in list(parent):
            if child.tag.endswith("toolspecific"):
                parent.remove(child)
    plain = loads_pnml(ET.tostring(stripped))
    assert plain.pre.tolist() == net.pre.tolist() and plain.post.tolist() == net.post.tolist()
    assert plain.initial_marking == net.initial_marking
    save_pnml(net, tmp_path / "m.pnml")
    assert load_pnml(tmp_path / "m.pnml") == net


# ----------------------------------------------------------------------------------- dialects
def test_older_dialect_with_value_and_no_page_loads() -> None:
    net = load_pnml(DATA / "old_dialect.xml")
    assert net.name == "Net-One"
    assert [p.id for p in net.places] == ["P0", "P1", "busy"]
    assert net.place("P0").label == "waiting" and net.place("P1").label == ""
    assert net.initial_marking == {"P0": 2}
    assert set(net.arcs) == {Arc(source="P0", target="T0", weight=2), Arc(source="T0", target="P1"),
                             Arc(source="busy", target="T0", inhibitor=True)}
    assert net.enabled(net.initial_marking, "T0")
    assert not net.enabled({"P0": 2, "busy": 1}, "T0")


def test_pages_are_flattened_and_reference_places_resolved() -> None:
    net = load_pnml(DATA / "two_pages.pnml")
    assert net.name == "two pages"
    assert [p.id for p in net.places] == ["p_start", "p_shared", "p_end"]
    assert Arc(source="p_shared", target="t2", weight=3) in net.arcs
    marking = net.fire(net.fire(net.initial_marking, "t1"), "t2")
    assert marking == {"p_end": 1}


def test_duplicate_arcs_are_merged_by_adding_weights() -> None:
    text = pnml('<place id="p"><initialMarking><text>3</text></initialMarking></place><transition id="t"/>'
                '<arc id="a" source="p" target="t"/>'
                '<arc id="b" source="p" target="t"><inscription><text>2</text></inscription></arc>')
    assert loads_pnml(text).arcs == (Arc(source="p", target="t", weight=3),)


def test_a_net_can_be_chosen_among_several() -> None:
    text = (f'<pnml xmlns="{PNML_NS}"><net id="a" type="{PTNET_TYPE}"><page id="x"><place id="p"/></page></net>'
            f'<net id="b" type="{PTNET_TYPE}"><page id="y"><place id="q"/></page></net></pnml>')
    with pytest.raises(NetError, match="2 nets"):
        loads_pnml(text)
    assert [p.id for p in loads_pnml(text, net_id="b").places] == ["q"]


# ----------------------------------------------------------------------------------- errors
def test_malformed_xml_names_the_line() -> None:
    with pytest.raises(NetFileError) as info:
        loads_pnml("<pnml>\n<net id='n'>\n<place id='p'>\n</net>\n</pnml>\n", path="bad.pnml")
    assert info.value.path == "bad.pnml" and info.value.line == 4


def test_arc_to_an_unknown_node_names_the_arc_line() -> None:
    text = pnml('<place id="p"/>\n<transition id="t"/>\n<arc id="a" source="p" target="nope"/>')
    with pytest.raises(NetError, match="unknown node 'nope'") as info:
        loads_pnml(text, path="x.pnml")
    assert info.value.line == text.splitlines().index('<arc id="a" source="p" target="nope"/>') + 1


def test_arc_between_two_places_is_refused() -> None:
    text = pnml('<place id="p"/>\n<place id="q"/>\n<arc id="a" source="p" target="q"/>')
    with pytest.raises(NetError, match="joins two places") as info:
        loads_pnml(text)
    assert info.value.line == 7


@pytest.mark.parametrize("marking", ["x", "-1", "1.5"])
def test_bad_initial_marking_is_refused(marking: str) -> None:
    text = pnml(f'<place id="p">\n<initialMarking><text>{marking}</text></initialMarking>\n</place>')
    with pytest.raises(NetError, match="initial marking") as info:
        loads_pnml(text)
    assert info.value.line == 5


def test_zero_arc_inscription_is_refused() -> None:
    text = pnml('<place id="p"/><transition id="t"/>'
                '<arc id="a" source="p" target="t"><inscription><text>0</text></inscription></arc>')
    with pytest.raises(NetError, match="weight of arc 'a'"):
        loads_pnml(text)


def test_duplicate_ids_are_refused() -> None:
    with pytest.raises(NetError, match="duplicate id 'p'"):
        loads_pnml(pnml('<place id="p"/><transition id="p"/>'))


def test_coloured_nets_are_refused() -> None:
    with pytest.raises(NetFileError, match="not a place/transition net"):
        loads_pnml(pnml('<place id="p"/>', "http://www.pnml.org/version-2009/grammar/symmetricnet"))


def test_bad_petrobot_data_names_the_element_line() -> None:
    text = pnml('<place id="p">\n<toolspecific tool="petrobot" version="1" kind="robot"/>\n</place>')
    with pytest.raises(NetError, match="unknown kind 'robot'") as info:
        loads_pnml(text)
    assert info.value.line == 6  # the <toolspecific> element


def test_bad_number_in_a_task_is_a_net_error() -> None:
    text = pnml("").replace('<page id="pg">', '<toolspecific tool="petrobot" version="1"><tasks>'
                            '<task name="x" deadline_s="soon"><action name="a"/></task></tasks></toolspecific>'
                            '<page id="pg">')
    with pytest.raises(NetError, match="deadline_s of task 'x' 'soon' is not a number"):
        loads_pnml(text)


def test_missing_file_is_a_net_file_error(tmp_path: Path) -> None:
    with pytest.raises(NetFileError, match="cannot read"):
        load_pnml(tmp_path / "none.pnml")
