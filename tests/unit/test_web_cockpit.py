"""The console's server side of the cockpit, without a browser: the protocol's new messages (break,
clear, inject, force, watch, blackboard, start, resume, painted, analyses as JSON), the definitions
the page links its numbers to, Open listing nets only, problems at the real file's lines, and frames
paced by the pages that say when they have painted one."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest

from coordinator.breakpoints import BreakKind, Breakpoint
from coordinator.journal import Journal
from coordinator.netfile import loads_net
from coordinator.operator import Command
from coordinator.runtime import Runtime
from coordinator.web.docs import DEFINITIONS, DocMissing, render_doc
from coordinator.web.draft import draft_of_text, validate_text
from coordinator.web.files import list_nets
from coordinator.web.frames import PACE_MAX_S, LiveFeed, json_value
from coordinator.web.protocol import ProtocolViolation, parse_client_message
from tests.unit.runtime_fakes import FakeClient
from tests.unit.test_runtime import CYCLE
from tests.unit.test_web_frames import fire

ROOT = Path(__file__).resolve().parents[2]


def msg(**fields: Any) -> str:
    return json.dumps(fields)


def test_breakpoints_injections_and_forced_outcomes_are_commands_of_the_protocol():
    m = parse_client_message(msg(type="command", id=1, command="break",
                                 breakpoint={"kind": "count", "target": "caught", "count": 2}))
    assert m.fields["command"] is Command.BREAK and m.fields["breakpoint"] == Breakpoint(BreakKind.COUNT, "caught", 2)
    m = parse_client_message(msg(type="command", id=2, command="inject", event="ext:ball_caught", run="abc"))
    assert m.fields["event"] == "ext:ball_caught" and m.fields["run"] == "abc"
    m = parse_client_message(msg(type="command", id=3, command="force", instance="r-1", outcome="failure.no_ball",
                                 reason="drill"))
    assert (m.fields["instance"], m.fields["outcome"], m.fields["reason"]) == ("r-1", "failure.no_ball", "drill")
    for bad, why in [(msg(type="command", id=4, command="inject", event="int:a.ok"), "ext:TOPIC"),
                     (msg(type="command", id=5, command="pause", event="ext:x"), "takes no event"),
                     (msg(type="command", id=6, command="break", breakpoint={"kind": "fires", "target": "t", "count": 3}),
                      "takes no count"),
                     (msg(type="command", id=7, command="break", breakpoint={"kind": "when", "target": "t"}),
                      "enabled, fires, count or error"),
                     (msg(type="command", id=8, command="force", instance="r-1", outcome="error", reason="x" * 600),
                      "at most 512")]:
        with pytest.raises(ProtocolViolation, match=why):
            parse_client_message(bad)


def test_runs_blackboards_and_painted_frames_are_messages_of_the_protocol():
    m = parse_client_message(msg(type="start", id=1, net="nets/catch.toml", marking={"runs_remaining": 2}, seed=7,
                                 max_seconds=60, degraded=True))
    assert m.fields == {"net": "nets/catch.toml", "degraded": True, "marking": {"runs_remaining": 2}, "seed": 7,
                        "max_seconds": 60.0}
    assert parse_client_message(msg(type="resume", id=2, net="nets/catch.toml")).fields["degraded"] is False
    assert parse_client_message(msg(type="watch", id=3, run="abc")).fields == {"run": "abc"}
    assert parse_client_message(msg(type="blackboard", id=4, place="locating")).fields["place"] == "locating"
    assert parse_client_message(msg(type="painted", seq=12)).fields == {"seq": 12}
    assert parse_client_message(msg(type="analyze", id=5, kind="gspn", draft={}, format="json")).fields["format"] == "json"
    for bad, why in [(msg(type="start", id=1, net="a.toml", max_seconds=-1), "max_seconds"),
                     (msg(type="start", id=1, net="a.toml", marking={"p": -1}), "tokens"),
                     (msg(type="resume", id=1, net="a.toml", seed=3), "unknown key 'seed'"),
                     (msg(type="painted", seq=1, id=2), "unknown key 'id'"),
                     (msg(type="analyze", id=5, kind="gspn", draft={}, format="xml"), "text or json")]:
        with pytest.raises(ProtocolViolation, match=why):
            parse_client_message(bad)


def test_every_number_links_to_a_section_of_the_docs_that_exists():
    for kind, target in DEFINITIONS.items():
        page, anchor = target.split("#")
        assert f'id="{anchor}"' in render_doc(page), f"{kind}: docs/{target} has no such section"
    for name in ("../README.md", "nope.md", "analysis.txt"):
        with pytest.raises(DocMissing):
            render_doc(name)


def test_open_lists_net_files_only(tmp_path: Path):
    (tmp_path / "nets").mkdir()
    (tmp_path / "nets" / "a.toml").write_text((ROOT / "nets" / "demo.toml").read_text())
    (tmp_path / "services.toml").write_text((ROOT / "services.toml").read_text())
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    (tmp_path / "model.pnml").write_text('<?xml version="1.0"?>\n<pnml xmlns="x"><net id="n"/></pnml>\n')
    (tmp_path / "other.xml").write_text("<svg/>")
    assert list_nets(tmp_path) == ["model.pnml", "nets/a.toml"]


def test_a_files_problems_are_at_the_files_own_lines_and_tied_to_their_element():
    text = (ROOT / "nets" / "demo.toml").read_text().replace('events = ["int:sense.error"]', 'events = ["int:snese.error"]', 1)
    validation = validate_text(text, "nets/broken.toml", draft_of_text(text))
    lines = text.splitlines()
    for problem in validation.problems:
        line = int(problem.text.split(":")[1])
        assert problem.text.startswith("nets/broken.toml:")
        kind, ident = problem.element
        assert kind in ("place", "transition") and ident in "\n".join(lines[:line])


def test_the_blackboard_shows_read_only_parameters_as_json_and_cuts_what_is_too_large():
    from types import MappingProxyType

    assert json_value(MappingProxyType({"a": MappingProxyType({"b": 1})})) == {"a": {"b": 1}}
    cut = json_value({"x": "y" * 100}, limit=50)
    assert cut["cut"].startswith("108 bytes") and len(cut["text"]) == 50


async def test_a_page_that_says_when_it_has_painted_paces_the_frames(tmp_path: Path):
    with Journal(tmp_path / "j.sqlite") as journal:
        runtime = Runtime(loads_net(CYCLE), FakeClient(), journal)
        feed = LiveFeed(runtime, period_s=0.001)
        sent: list[dict[str, Any]] = []

        def sink(text: str) -> None:
            sent.append(json.loads(text))
        feed.subscribe(sink)
        runtime.engine.start()
        task = asyncio.get_running_loop().create_task(feed.run())
        try:
            fire(runtime, feed, 3)
            while not sent:
                await asyncio.sleep(0.001)
            feed.painted(sink, 0)  # from now on this page paces the frames: it has not painted frame 1
            fire(runtime, feed, 3)
            while len(sent) < 2:
                await asyncio.sleep(0.001)
            fire(runtime, feed, 5)  # frame 2 is not painted yet: these wait, piled up into one frame
            await asyncio.sleep(PACE_MAX_S / 5)
            assert len(sent) == 2
            feed.painted(sink, sent[-1]["seq"])
            while len(sent) < 3:
                await asyncio.sleep(0.001)
            assert sum(sent[2]["fired"].values()) == 5
        finally:
            task.cancel()


def test_frames_are_spaced_when_the_machine_has_no_idle_core(tmp_path: Path):
    from coordinator.web.frames import BUSY_PERIOD_S, SPARE_CORES, IdleCpu, frame_period

    assert frame_period(0.01, None) == 0.01               # unknown: as configured
    assert frame_period(0.01, SPARE_CORES) == 0.01        # a core to spare: full rate
    assert frame_period(0.01, 0.0) == BUSY_PERIOD_S       # no idle CPU: a few frames a second
    assert 0.01 < frame_period(0.01, SPARE_CORES / 2) < BUSY_PERIOD_S
    stat = tmp_path / "stat"
    stat.write_text("cpu  100 0 100 800 0 0 0 0 0 0\n")
    idle = IdleCpu(str(stat))
    stat.write_text("cpu  200 0 200 800 0 0 0 0 0 0\n")   # 200 jiffies more, none of them idle
    assert idle.sample() == 0.0
    stat.write_text("cpu  200 0 200 1000 0 0 0 0 0 0\n")  # 200 more, all idle
    assert idle.sample() == pytest.approx(float(__import__("os").cpu_count() or 1))
    assert IdleCpu(str(tmp_path / "none")).sample() is None
