"""A net drawn in the console is checked by the one implementation `petrobot check` uses: the same
messages, at the lines of the file a save writes, each tied to the element the page highlights."""

from __future__ import annotations

from pathlib import Path

import pytest

from coordinator.cli import main
from coordinator.netfile import load_any, load_layout, loads_net
from coordinator.web.draft import (
    draft_layout,
    draft_of_net,
    draft_of_text,
    draft_to_toml,
    validate_draft,
)
from coordinator.web.files import (
    FileRefused,
    export_draft,
    inside,
    open_net,
    save_draft,
    with_layout,
)
from services.location import load_location

ROOT = Path(__file__).resolve().parents[2]


def drawn_net() -> dict:
    """A small net as the page would send it after drawing it with the mouse."""
    return {
        "net": {"name": "drawn"},
        "places": [{"id": "idle", "kind": "resource", "tokens": 1, "pos": [100.0, 50.0]},
                   {"id": "busy", "kind": "primitive_task", "task": "work", "pos": [100.0, 200.0]}],
        "tasks": {"work": {"actions": ["echo"], "deadline_s": 2.0}},
        "transitions": [{"id": "go", "pos": [100.0, 120.0]},
                        {"id": "done", "events": ["int:work.ok"], "pos": [40.0, 270.0]},
                        {"id": "failed", "events": ["int:work.error"], "hidden": True, "pos": [160.0, 270.0]}],
        "arcs": [{"from": "idle", "to": "go", "weight": 1}, {"from": "go", "to": "busy", "weight": 1},
                 {"from": "busy", "to": "done", "weight": 1}, {"from": "done", "to": "idle", "weight": 1},
                 {"from": "busy", "to": "failed", "weight": 1}, {"from": "failed", "to": "idle", "weight": 1}],
    }


def test_a_drawn_net_saved_by_the_console_passes_petrobot_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    target = tmp_path / "drawn.toml"
    saved = save_draft(drawn_net(), target, load_location(ROOT / "services.toml"))
    assert saved["validation"]["ok"], saved["validation"]["problems"]
    assert main(["check", str(target), "--services", str(ROOT / "services.toml")]) == 0
    assert "OK" in capsys.readouterr().out
    assert load_layout(target)["busy"] == (100.0, 200.0)  # the drawing is kept in the file
    assert load_any(target).transition("failed").hidden


def test_the_problems_of_a_draft_are_the_messages_petrobot_check_prints_for_the_saved_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    draft = drawn_net()
    draft["transitions"] = [t for t in draft["transitions"] if t["id"] != "failed"]  # no error exit
    draft["arcs"] = [a for a in draft["arcs"] if "failed" not in (a["from"], a["to"])]
    draft["arcs"].append({"from": "idle", "to": "busy", "weight": 1})  # place -> place
    draft["transitions"][0]["events"] = ["ext:no such topic"]
    target = tmp_path / "broken.toml"
    saved = save_draft(draft, target)
    problems = [p["text"] for p in saved["validation"]["problems"]]
    assert main(["check", str(target), "--services", str(ROOT / "services.toml")]) == 2
    printed = [line.replace(str(target), "broken.toml") for line in capsys.readouterr().out.splitlines()]
    assert problems and printed == problems
    elements = {(p["kind"], p["id"]) for p in saved["validation"]["problems"]}
    assert ("transition", "go") in elements and ("arc", "idle->busy") in elements


def test_unplaced_actions_and_unpublished_events_are_shown_with_their_problem():
    draft = drawn_net()
    draft["tasks"]["work"]["actions"] = ["echo", "nowhere"]
    draft["transitions"][0]["events"] = ["ext:nobody_publishes"]
    result = validate_draft(draft, "drawn.toml", load_location(ROOT / "services.toml"))
    assert result.placement["echo"] == "alpha" and result.placement["nowhere"] is None
    assert result.placement["ext:nobody_publishes"] is None
    texts = [p.problem for p in result.problems]
    assert any("'nowhere' of task 'work' is not placed" in t for t in texts)
    assert any("has no publisher" in t for t in texts)
    assert {p.element for p in result.problems} == {("task", "work"), ("transition", "go")}


def test_opening_the_catching_net_gives_a_draft_that_writes_back_the_same_net():
    net = load_any(ROOT / "nets" / "catch.toml")
    opened = open_net(ROOT / "nets" / "catch.toml")
    assert opened["validation"]["ok"] and not opened["laid_out"]
    text, _ = draft_to_toml(opened["draft"])
    assert loads_net(text, "catch.toml") == net
    assert draft_layout(opened["draft"]) == load_layout(ROOT / "nets" / "catch.toml")


def test_keys_the_page_does_not_know_travel_through_a_draft_untouched():
    text = (ROOT / "nets" / "demo.toml").read_text(encoding="utf-8")
    draft = draft_of_text(text)
    draft["places"][0]["future_key"] = 3
    written, _ = draft_to_toml(draft)
    assert "future_key = 3" in written
    problems = validate_draft(draft).problems
    assert any("unknown key 'future_key'" in p.problem for p in problems)


def test_a_net_without_positions_gets_a_layered_drawing_when_opened(tmp_path: Path):
    draft = draft_of_net(load_any(ROOT / "nets" / "demo.toml"))
    for item in draft["places"] + draft["transitions"]:
        item.pop("pos", None)
    laid = with_layout(draft)
    positions = draft_layout(laid)
    assert len(positions) == len(draft["places"]) + len(draft["transitions"])
    assert len(set(positions.values())) == len(positions)  # no two elements on one spot
    # the run flows downwards: a place is above the transition it feeds (cycles aside)
    assert positions["runs_remaining"][1] < positions["start_run"][1] < positions["sensing"][1]


@pytest.mark.parametrize("path", ["../outside.toml", "/etc/passwd", "nets/../../x.toml", "net.exe", ""])
def test_the_console_refuses_paths_outside_its_folder_or_of_other_kinds(tmp_path: Path, path: str):
    with pytest.raises(FileRefused):
        inside(tmp_path, path)


def test_a_symbolic_link_leading_out_of_the_folder_is_refused(tmp_path: Path):
    (tmp_path / "root").mkdir()
    (tmp_path / "secret.toml").write_text("[net]\n")
    (tmp_path / "root" / "link.toml").symlink_to(tmp_path / "secret.toml")
    with pytest.raises(FileRefused, match="under"):
        inside(tmp_path / "root", "link.toml")


def test_exports_are_the_command_lines_formats_with_the_drawing():
    draft = drawn_net()
    pnml, _ = export_draft(draft, "pnml")
    assert '<position x="100.0" y="200.0"/>' in pnml
    dot, _ = export_draft(draft, "dot", hidden=False)
    assert "digraph" in dot and "failed" not in dot
    toml, _ = export_draft(draft, "toml")
    assert "pos = [100.0, 50.0]" in toml
    broken = drawn_net()
    broken["arcs"].append({"from": "idle", "to": "nowhere"})
    with pytest.raises(FileRefused, match="problems"):
        export_draft(broken, "pnml")


def test_a_net_with_rate_expressions_and_reset_arcs_survives_the_page_unchanged():
    text = (ROOT / "nets" / "examples" / "fms.toml").read_text(encoding="utf-8")
    net = loads_net(text)
    assert loads_net(draft_to_toml(draft_of_text(text))[0]) == net
    assert loads_net(draft_to_toml(draft_of_net(net))[0]) == net
