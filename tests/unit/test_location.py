"""services.toml parsing (services.location)."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.errors import LocationError
from services.location import MEMORY_ACTIONS, ActionPlacement, load_location, parse_location

ROOT = Path(__file__).resolve().parents[2]

GOOD = """
[nodes.vision]
host = "127.0.0.1"
port = 7101
max_in_flight = 4

[nodes.motion]
host = "127.0.0.1"
port = 7102

[actions.locate]
node = "vision"
impl = "services.actions.demo:echo"
local_only = true
deadline_s = 2
params = { k = 1 }

[actions.move]
node = "motion"
impl = "services.actions.demo:wait"

[drivers.camera]
node = "vision"
impl = "services.actions.demo:echo"

[events.image_sampling_tick]
node = "vision"

[memory]
node = "motion"
"""


def test_a_good_file_gives_nodes_actions_drivers_events_and_memory() -> None:
    loc = parse_location(GOOD, path="s.toml")
    assert loc.node_of("locate") == "vision"
    assert loc.address("motion") == ("127.0.0.1", 7102)
    assert loc.nodes["vision"].max_in_flight == 4
    assert loc.nodes["motion"].max_in_flight == 16
    placement = loc.action("locate")
    assert isinstance(placement, ActionPlacement)
    assert placement.local_only and placement.deadline_s == 2.0 and dict(placement.params) == {"k": 1}
    assert [a.name for a in loc.actions_on("vision")] == ["locate"]
    assert [d.name for d in loc.drivers_on("vision")] == ["camera"]
    assert loc.publisher_of("ext:image_sampling_tick") == "vision"
    assert loc.memory_node == "motion"
    assert all(loc.node_of(a) == "motion" for a in MEMORY_ACTIONS)


def test_the_location_is_frozen() -> None:
    loc = parse_location(GOOD)
    with pytest.raises(AttributeError):
        loc.memory_node = "vision"  # type: ignore[misc]
    with pytest.raises(TypeError):
        loc.nodes["x"] = loc.nodes["vision"]  # type: ignore[index]


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t.replace('node = "motion"\nimpl = "services.actions.demo:wait"', 'node = "arm"\nimpl = "services.actions.demo:wait"'), "unknown node 'arm'"),
        (lambda t: t.replace('"services.actions.demo:wait"', '"services.actions.demo.wait"'), "impl must be"),
        (lambda t: t.replace("port = 7102", "port = 7101"), "duplicate address"),
        (lambda t: t.replace("port = 7102", 'port = "x"'), "port must be"),
        (lambda t: t.replace("max_in_flight = 4", "max_in_flight = 0"), "max_in_flight"),
        (lambda t: t.replace("local_only = true", "local_only = 1"), "local_only"),
        (lambda t: t.replace("deadline_s = 2", "deadline_s = -1"), "deadline_s"),
        (lambda t: t.replace("[actions.move]", "[actions.move]\nspeed = 3"), "unknown key"),
        (lambda t: t + "\n[actions.\"memory.get\"]\nnode = \"vision\"\nimpl = \"a:b\"\n", "reserved"),
        (lambda t: t + "\n[events.beep]\nnode = \"nowhere\"\n", "unknown node"),
        (lambda t: t + "\nnot toml [", "not valid TOML"),
    ],
)
def test_errors_name_the_file_and_the_problem(edit, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(LocationError, match=match) as info:
        parse_location(edit(GOOD), path="where/services.toml")
    assert "where/services.toml" in str(info.value)


def test_unknown_action_and_topic_are_location_errors() -> None:
    loc = parse_location(GOOD)
    with pytest.raises(LocationError, match="no action named 'fly'"):
        loc.node_of("fly")
    with pytest.raises(LocationError, match="no node publishes"):
        loc.publisher_of("thunder")
    with pytest.raises(LocationError, match="no node named"):
        loc.address("ghost")


def test_a_file_without_nodes_is_refused() -> None:
    with pytest.raises(LocationError, match="no \\[nodes"):
        parse_location("[memory]\n")


def test_the_project_services_file_loads() -> None:
    loc = load_location(ROOT / "services.toml")
    assert {"alpha", "beta"} <= set(loc.nodes)
    assert loc.node_of("echo") in loc.nodes


def test_a_missing_file_is_a_location_error(tmp_path: Path) -> None:
    with pytest.raises(LocationError, match="cannot read"):
        load_location(tmp_path / "nope.toml")
