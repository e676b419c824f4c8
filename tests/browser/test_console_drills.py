"""The operator's cockpit on a live run, in a real browser against real node processes: a run started
from the page with the CLI's preflight (and refused when the nodes are not ready), an external event
raised from the page, breakpoints set on the drawing, the blackboard of a running action (its
parameters and feedback, the latched result and its payload), an outcome forced for a drill —
journaled as the operator's, shown as forced in the replay, left out of perf — several runs of
different nets followed at once, and an interrupted run resumed from the page."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.browser.conftest import ROOT, Page

DRILL = """
[net]
name = "drill"
description = "A drill: each run waits for the operator's go, then works for a while."
home = { robot = 1 }

[operator]
inject = ["ext:go"]
force = { work = ["success", "error"] }

[[place]]
id = "runs"
kind = "control"
tokens = 2
pos = [60, 40]

[[place]]
id = "robot"
kind = "resource"
tokens = 1
pos = [260, 40]

[[place]]
id = "working"
kind = "primitive_task"
task = "work"
pos = [160, 220]

[[place]]
id = "done"
pos = [60, 400]

[[place]]
id = "failed"
pos = [260, 400]

[task.work]
actions = [{ name = "wait", params = { seconds = 60.0, step = 0.2, target = "bin 3" } }]
deadline_s = 120.0

[[transition]]
id = "start"
events = ["ext:go"]
pos = [160, 130]
inputs = { runs = 1, robot = 1 }
outputs = { working = 1 }

[[transition]]
id = "finished"
events = ["int:work.ok"]
pos = [60, 310]
inputs = { working = 1 }
outputs = { robot = 1, done = 1 }

[[transition]]
id = "broke"
events = ["int:work.error"]
hidden = true
pos = [260, 310]
inputs = { working = 1 }
outputs = { robot = 1, failed = 1 }
"""


@pytest.fixture
def lab(tmp_path: Path) -> Any:
    """Nodes alpha and beta of a services.toml whose alpha also publishes ``go`` (nothing sends it:
    the operator raises it), the drill net and the foundation demo net in the console's folder."""
    from tests.integration.cluster import DEMO_SERVICES, Cluster

    cluster = Cluster(tmp_path)
    cluster.write_services(DEMO_SERVICES + '\n[events.go]\nnode = "alpha"\n\n[actions.coin]\nnode = "alpha"\n'
                           'impl = "services.actions.demo:coin"\n')
    (tmp_path / "drill.toml").write_text(DRILL)
    (tmp_path / "demo.toml").write_text((ROOT / "nets" / "demo.toml").read_text())
    cluster.key_file.chmod(0o600)
    try:
        yield cluster
    finally:
        for name in list(cluster.procs):
            cluster.kill(name)


def console(petrobot: Any, lab: Any) -> Any:
    return petrobot("console", "--listen", "0", "--root", str(lab.tmp), "--services", str(lab.services_path),
                    "--key-file", str(lab.key_file), cwd=lab.tmp, env=lab.env())


def start_from_page(page: Page, net: str, tokens: dict[str, int] | None = None) -> None:
    page.page.click("#start-run")
    page.wait("document.getElementById('run-net').options.length > 0 && "
              "document.getElementById('run-net').options[0].value !== '...'", what="the nets to start")
    page.page.select_option("#run-net", net)
    for place, n in (tokens or {}).items():
        field = f"#run-marking input[data-place={place}]"
        page.wait("(s) => document.querySelector(s)", arg=field, what=f"the tokens of {place}")
        page.page.fill(field, str(n))
    page.page.click("#run-go")


def rows(journal: Path, sql: str) -> list[tuple[Any, ...]]:
    with sqlite3.connect(f"file:{journal}?mode=ro", uri=True) as db:
        return db.execute(sql).fetchall()


def test_a_run_the_nodes_are_not_ready_for_is_refused_with_the_preflights_words(page: Page, petrobot: Any, lab: Any):
    proc = console(petrobot, lab)  # no node started
    page.page.goto(proc.url())
    page.wait("document.body.dataset.ready === '1'", what="the page")
    start_from_page(page, "drill.toml")
    page.wait("document.body.dataset.refused", what="the refusal")
    refusal = page.eval("document.body.dataset.refused")
    assert "the nodes are not ready for this net" in refusal and "nothing was run" in refusal
    assert not (lab.tmp / "runs" / "journal.sqlite").exists() or \
        rows(lab.tmp / "runs" / "journal.sqlite", "SELECT COUNT(*) FROM run") == [(0,)]


def test_breakpoints_an_injected_event_the_blackboard_and_a_forced_outcome_on_a_run_started_from_the_page(
        page: Page, petrobot: Any, lab: Any, capsys: pytest.CaptureFixture[str]):
    lab.start("alpha", "beta")
    proc = console(petrobot, lab)
    page.page.goto(proc.url())
    page.wait("document.body.dataset.ready === '1'", what="the page")
    start_from_page(page, "drill.toml", {"runs": 3})
    page.wait("window.petrobot.mode === 'live' && window.petrobot.live.state.state === 'waiting'",
              what="the run, waiting for its go")
    assert page.eval("window.petrobot.live.marking.runs") == 3
    # a breakpoint on the drawing: the transition start fires
    page.click_node("start")
    page.page.locator("#node-pop input[data-bp=fires]").check()
    page.wait("window.petrobot.live.breakpoints.length === 1", what="the breakpoint set")
    assert page.page.locator(".mark.bp[data-node='start']").is_visible()
    # the operator raises ext:go (the net's [operator] inject allows it), with a payload
    page.page.keyboard.press("Escape")
    page.page.fill("#inject-payload", '{"by": "drill", "bin": 3')  # not JSON: nothing is sent
    page.page.click("#inject-go")
    assert page.eval("document.getElementById('inject-payload').validity.valid") is False
    assert page.eval("window.petrobot.live.firings") == 0
    page.page.fill("#inject-payload", '{"by": "drill", "bin": 3}')
    page.page.click("#inject-go")
    page.wait("window.petrobot.live.paused && document.body.dataset.hit === 'fires start'",
              what="the pause at the breakpoint")
    assert page.eval("window.petrobot.live.firings") == 1
    page.page.click("#cmd-resume")
    page.wait("[...window.petrobot.live.running.values()].some(r => r.action === 'wait')", what="the action running")
    # its blackboard: parameters, feedback as it comes, the event that started it
    page.click_node("working")
    page.page.locator("#node-pop button:text-is('blackboard')").click()
    page.wait("window.petrobot.live.blackboard && window.petrobot.live.blackboard.running.length === 1 && "
              "window.petrobot.live.blackboard.running[0].feedback_count >= 2", what="the blackboard with feedback")
    board = page.eval("window.petrobot.live.blackboard")
    assert board["running"][0]["params"] == {"seconds": 60.0, "step": 0.2, "target": "bin 3"}
    assert 0 <= board["running"][0]["feedback"]["fraction"] < 1
    assert board["events"][0]["event"] == "ext:go" and board["events"][0]["operator"] is True
    assert board["events"][0]["payload"] == {"by": "drill", "bin": 3}  # the event's payload, end to end
    text = page.eval("document.getElementById('panel-blackboard').innerText")
    assert "bin 3" in text and "fraction" in text and "raised by the operator" in text and '"by": "drill"' in text
    page.screenshot("live-blackboard")
    # an error forced for a drill, with a breakpoint on the task's errors: the run pauses, the error latched
    page.click_node("working")
    page.page.locator("#node-pop input[data-bp=error]").check()
    page.wait("window.petrobot.live.breakpoints.length === 2", what="the second breakpoint")
    page.click_node("working")
    page.page.fill("#force-reason", "drill: camera lost")
    page.page.locator("#node-pop button[data-outcome=error]").click()
    page.wait("window.petrobot.live.paused && document.body.dataset.hit === 'error work'", what="the pause on the error")
    assert page.eval("window.petrobot.live.latched.working[0][2]") == ["int:work.error"]
    page.wait("window.petrobot.live.blackboard.latched.length === 1", what="the latched result on the blackboard")
    latched = page.eval("window.petrobot.live.blackboard.latched[0]")
    assert latched["forced"] is True and latched["reason"] == "forced by the operator: drill: camera lost"
    assert page.eval("window.petrobot.live.results.at(-1).forced") is True
    page.screenshot("live-forced")
    page.page.click("#cmd-resume")
    page.wait("window.petrobot.live.marking.failed === 1", what="the error branch")
    # what the journal says: the operator's commands, and a forced result
    journal = lab.tmp / "runs" / "journal.sqlite"
    commands = rows(journal, "SELECT command, detail FROM operator WHERE accepted ORDER BY entry")
    assert [c for c, _ in commands] == ["break", "inject", "pause", "resume", "break", "force", "pause", "resume"]
    assert json.loads(commands[1][1]) == {"event": "ext:go", "payload": {"by": "drill", "bin": 3}}
    assert json.loads(commands[5][1]) == {"instance": board["running"][0]["i"], "outcome": "error",
                                          "reason": "drill: camera lost"}
    assert rows(journal, "SELECT status, forced FROM action_result") == [("error", 1)]
    # perf measures nothing from it
    perf = subprocess.run([sys.executable, "-m", "coordinator.cli", "perf", str(lab.tmp / "drill.toml"), "--journal",
                           str(journal), "--json"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert json.loads(perf.stdout)["forced_left_out"] == 1 and json.loads(perf.stdout)["results"] == 0
    # the replay shows the forced outcome and the breakpoints as the operator's
    page.page.click("#cmd-end")
    page.wait("window.petrobot.live.ended", what="the run's end")
    page.page.click("#modes [data-mode=replay]")
    run_id = page.eval("window.petrobot.live.runId")
    page.page.locator("#panel-timeline .runs-list li", has_text=run_id).click()
    page.wait("window.petrobot.replay.data && window.petrobot.mode === 'replay'", what="the replay")
    forced = page.eval("window.petrobot.replay.records.findIndex(r => r[0] === 'r' && r[10])")
    page.eval("(k) => window.petrobot.replay.seek(k)", forced + 1)
    assert page.page.locator("#rp-records .rec.forced").first.inner_text().split(None, 1)[1].startswith("FORCED work/wait")
    assert page.page.locator(".mark.bp").count() == 2
    records = page.page.locator("#rp-records").inner_text()
    assert 'inject ext:go {"bin":3,"by":"drill"} (raised by the operator)' in records  # with its payload
    assert "FORCED by the operator" in page.page.locator(".token-plane .badge.latched").inner_text()
    page.screenshot("replay-forced")


def test_several_runs_of_different_nets_are_followed_at_once_and_an_interrupted_run_resumes(
        page: Page, petrobot: Any, lab: Any):
    lab.start("alpha", "beta")
    proc = console(petrobot, lab)
    url = proc.url()
    page.page.goto(url)
    page.wait("document.body.dataset.ready === '1'", what="the page")
    start_from_page(page, "drill.toml")
    page.wait("window.petrobot.runs.length === 1 && window.petrobot.live.state.state === 'waiting'", what="the drill")
    drill = page.eval("window.petrobot.live.runId")
    start_from_page(page, "demo.toml")
    page.wait("window.petrobot.runs.length === 2 && window.petrobot.live.runId !== window.petrobot.runs[0].run",
              what="the demo, followed too")
    assert sorted(r["net"] for r in page.eval("window.petrobot.runs")) == ["demo", "drill"]
    assert page.page.locator("#live-runs button").count() == 2  # both visible in the header
    page.screenshot("live-two-runs")
    # back to the drill: its drawing and state; a second page watches the demo at the same time
    page.page.locator(f"#live-runs button[data-run='{drill}']").click()
    page.wait("(r) => document.body.dataset.watching === r", arg=drill, what="the drill followed again")
    assert page.eval("window.petrobot.liveNet.draft.net.name") == "drill"
    page.click_node("start")  # a breakpoint on the drill, which its resume re-arms
    page.page.locator("#node-pop input[data-bp=fires]").check()
    page.wait("window.petrobot.live.breakpoints.length === 1", what="the breakpoint set")
    page.page.keyboard.press("Escape")
    other = Page(page.page.context.new_page())
    demo = next(r["run"] for r in page.eval("window.petrobot.runs") if r["net"] == "demo")
    other.page.goto(url + f"&run={demo}")
    other.wait("(r) => document.body.dataset.watching === r", arg=demo, what="a second page on the demo")
    assert other.eval("window.petrobot.liveNet.draft.net.name") == "demo"
    # the console stops: both runs are interrupted, resumable; a new console resumes the drill from the page
    proc.stop()
    journal = lab.tmp / "runs" / "journal.sqlite"
    assert rows(journal, f"SELECT end_state FROM run WHERE id='{drill}'") == [("interrupted",)]
    proc = console(petrobot, lab)
    page.page.goto(proc.url())
    page.wait("document.body.dataset.ready === '1'", what="the page again")
    page.page.click("#start-run")
    resume = page.page.locator("#run-resumable li", has_text=drill)
    resume.wait_for()
    resume.click()
    page.wait("(r) => window.petrobot.live && window.petrobot.live.runId === r && "
              "window.petrobot.live.state.state === 'waiting'", arg=drill, what="the drill resumed")
    assert rows(journal, f"SELECT end_state FROM run WHERE id='{drill}'") == [(None,)]
    page.wait("window.petrobot.live.breakpoints.length === 1", what="the breakpoint re-armed")
    assert page.eval("window.petrobot.live.breakpoints[0]") == {"kind": "fires", "target": "start", "count": None}
    assert page.page.locator(".mark.bp[data-node='start']").is_visible()
    assert other.errors == []
