"""Drills on the catching demo from the web console (paper section 6, Fig. 1), in a real browser, with
the simulated world, the vision and motion nodes and `petrobot run nets/catch.toml --console`: a
breakpoint on ball_caught pauses the run there, an ext:ball_caught raised by the operator fires the
crossfire transition, and a forced error of locate takes the error branch, is shown as forced in
the replay and is left out of perf's reliability."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.browser.conftest import ROOT, Page, catching_demo


def rows(journal: Path, sql: str) -> list[tuple[Any, ...]]:
    with sqlite3.connect(f"file:{journal}?mode=ro", uri=True) as db:
        return db.execute(sql).fetchall()


def breakpoint_on(page: Page, node: str, kind: str) -> None:
    page.click_node(node)
    page.page.locator(f"#node-pop input[data-bp={kind}]").check()
    page.wait("(n) => window.petrobot.live.breakpoints.some(b => b.target === n)", arg=node,
              what=f"the breakpoint {kind} {node}")
    page.page.keyboard.press("Escape")


@pytest.mark.slow
@pytest.mark.timeout(420)
def test_breakpoint_on_ball_caught_injected_crossfire_and_a_forced_locate_error_on_the_catching_demo(
        page: Page, petrobot: Any, tmp_path: Path):
    journal = tmp_path / "j.sqlite"
    with catching_demo(petrobot, tmp_path, journal, max_seconds=360) as proc:
        page.page.goto(proc.url())
        page.wait("window.petrobot.mode === 'live' && window.petrobot.live.runId", what="the live run")
        # stop when the crossfire sensor is about to be awaited, and when ball_caught fires
        breakpoint_on(page, "crossfire", "enabled")
        breakpoint_on(page, "ball_caught", "fires")
        page.eval("() => window.petrobot.command('insert', { place: 'runs_remaining', count: 3 })")  # room for misses
        crossfired = caught = False
        for attempt in range(6):  # a ball the robot misses goes on to the next run
            page.wait("window.petrobot.live.paused && ['enabled crossfire', 'fires ball_caught']"
                      ".includes(document.body.dataset.hit)", what=f"run {attempt + 1}: the pause with the sensor armed")
            if page.eval("document.body.dataset.hit") == "fires ball_caught":
                # the run was ahead of the page: its first ball was located (the sensor armed) before the
                # breakpoints were set, so "enabled crossfire" was already true and paused nothing
                page.eval("() => { document.body.dataset.hit = ''; }")
                page.page.click("#cmd-resume")
                continue
            assert page.eval("window.petrobot.live.marking.cup_armed") == 1
            page.eval("() => { document.body.dataset.hit = ''; }")
            # resume, and the operator raises ext:ball_caught at once (the net's [operator] allows it)
            page.page.click("#cmd-resume")
            page.page.select_option("#inject-event", "ext:ball_caught")
            page.page.click("#inject-go")
            # crossfire fires on it, unless the catch had ended first (a miss: the sensor is disarmed)
            page.wait("window.petrobot.live.marking.ball_in_cup === 1 || !window.petrobot.live.marking.cup_armed",
                      what="crossfire fired on the operator's event, or the catch over")
            if page.eval("window.petrobot.live.marking.ball_in_cup") != 1:
                continue
            crossfired = True
            page.wait("document.body.dataset.hit === 'fires ball_caught' || !window.petrobot.live.marking.ball_in_cup",
                      what="the catch's outcome")
            if page.eval("document.body.dataset.hit") == "fires ball_caught":
                caught = True
                break
        assert crossfired and caught, "the robot missed five balls in a row"
        assert page.eval("window.petrobot.live.paused") is True
        assert page.eval("window.petrobot.live.marking.caught") >= 1
        page.screenshot("catch-breakpoint-ball_caught")
        # clear both breakpoints, resume; force an error of the next locate (a drill)
        for bp in page.eval("window.petrobot.live.breakpoints"):
            page.eval("(b) => window.petrobot.command('clear', { breakpoint: b })", bp)
        page.wait("window.petrobot.live.breakpoints.length === 0", what="the breakpoints cleared")
        page.page.click("#cmd-resume")
        page.wait("[...window.petrobot.live.running.values()].some(r => r.task === 'locate')",
                  what="the next locate running")
        page.click_node("locating")
        page.page.fill("#force-reason", "drill: the camera is covered")
        page.page.locator("#node-pop button[data-outcome=error]").click()
        page.wait("window.petrobot.live.results.some(r => r.task === 'locate' && r.forced && r.status === 'error')",
                  what="the forced error")
        page.wait("(window.petrobot.live.marking.aborted_runs || 0) >= 1", what="the error branch locate_failed")
        page.screenshot("catch-forced-locate-error")
        # end the experiment: no run left, the run comes home, end
        page.click_node("runs_remaining")
        while page.tokens("runs_remaining") > 0:
            left = page.tokens("runs_remaining")
            page.page.click("#steer-remove")
            page.wait("(n) => (window.petrobot.live.marking.runs_remaining || 0) !== n", arg=left, what="a token removed")
        page.page.keyboard.press("Escape")
        page.wait("window.petrobot.live.state.state === 'waiting' && "
                  "window.petrobot.live.state.reason.startsWith('completed')", what="the experiment home")
        page.page.click("#cmd-end")
        assert proc.wait() == 0, proc.output()
    # the journal: crossfire fired on the operator's pulse, right after the inject; the pause at ball_caught
    records = rows(journal, "SELECT entry, 'o', command, detail FROM operator WHERE accepted UNION ALL "
                            "SELECT entry, 'f', transition, pulse FROM firing ORDER BY 1")
    injects = [i for i, r in enumerate(records) if r[1:3] == ("o", "inject")]
    assert any(records[i + 1][1:] == ("f", "crossfire", "ext:ball_caught") for i in injects)
    pauses = [json.loads(r[3]) for r in records if r[1:3] == ("o", "pause") and r[3]]
    assert {"kind": "fires", "target": "ball_caught", "count": None} in [p["breakpoint"] for p in pauses]
    hit = next(i for i, r in enumerate(records) if r[1:3] == ("o", "pause") and r[3] and "ball_caught" in r[3])
    assert records[hit - 1][1:3] == ("f", "ball_caught")  # the run paused right after ball_caught fired
    forced = rows(journal, "SELECT task, status, reason FROM action_result WHERE forced")
    assert forced == [("locate", "error", "forced by the operator: drill: the camera is covered")]
    assert rows(journal, "SELECT COUNT(*) FROM firing WHERE transition = 'locate_failed'") == [(1,)]
    # perf: the forced error is no measurement of locate's reliability
    perf = json.loads(subprocess.run([sys.executable, "-m", "coordinator.cli", "perf", str(ROOT / "nets" / "catch.toml"),
                                      "--journal", str(journal), "--json"], capture_output=True, text=True, cwd=ROOT,
                                     timeout=300, check=True).stdout)
    assert perf["forced_left_out"] == 1
    locate_errors = sum(a["errors"] for a in perf["actions"]["locate"].values())
    measured = rows(journal, "SELECT COUNT(*) FROM action_result WHERE task='locate' AND status='error' AND NOT forced")
    assert locate_errors == measured[0][0]
    # the replay shows it as forced
    console = petrobot("console", str(ROOT / "nets" / "catch.toml"), "--journal", str(journal), "--listen", "0",
                       "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the console on the journal")
    page.page.click("#modes [data-mode=replay]")
    page.page.locator("#panel-timeline .runs-list li").first.click()
    page.wait("window.petrobot.replay.data && window.petrobot.mode === 'replay'", what="the replay")
    k = page.eval("window.petrobot.replay.records.findIndex(r => r[0] === 'r' && r[10])")
    page.eval("(k) => window.petrobot.replay.seek(k)", k + 1)
    assert page.page.locator("#rp-records .rec.forced").first.inner_text().split(None, 1)[1].startswith("FORCED locate/")
    assert "FORCED by the operator" in page.page.locator(".token-plane .badge.latched[data-place='locating']").inner_text()
    page.screenshot("replay-forced-locate")
