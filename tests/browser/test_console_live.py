"""Following and steering a live run in a real browser (paper section 5): `petrobot run NET --console`,
tokens moving on the drawing, a paused run stepped one firing at a time, tokens removed from a control
place ending the experiment, a page without the token that can only watch, and a hostile WebSocket
message that disturbs nothing."""

from __future__ import annotations

import secrets
import sqlite3
from pathlib import Path
from typing import Any

import pytest

from tests.browser.conftest import ROOT, TIMEOUT_S, Page, without_token

STEPPER = """
[net]
name = "stepper"
description = "Three runs; each start needs the operator's go token (kept, not consumed)."
home = { ready = 1 }

[[place]]
id = "go"
kind = "control"
pos = [60, 40]

[[place]]
id = "runs"
kind = "control"
tokens = 3
pos = [200, 40]

[[place]]
id = "ready"
kind = "resource"
tokens = 1
pos = [340, 40]

[[place]]
id = "busy"
pos = [200, 220]

[[place]]
id = "done"
pos = [200, 400]

[[transition]]
id = "take"
pos = [200, 130]
inputs = { go = 1, runs = 1, ready = 1 }
outputs = { go = 1, busy = 1 }

[[transition]]
id = "put"
pos = [200, 310]
inputs = { busy = 1 }
outputs = { ready = 1, done = 1 }
"""


def start_stepper(petrobot: Any, tmp_path: Path) -> tuple[Any, Path]:
    net = tmp_path / "stepper.toml"
    net.write_text(STEPPER)
    key = tmp_path / "key"
    key.write_text(secrets.token_hex(32) + "\n")
    journal = tmp_path / "j.sqlite"
    proc = petrobot("run", str(net), "--services", str(ROOT / "services.toml"), "--key-file", str(key),
                    "--journal", str(journal), "--console", "0", "--lines", "--max-seconds", "600", cwd=tmp_path)
    return proc, journal


def rows(journal: Path, sql: str) -> list[tuple[Any, ...]]:
    with sqlite3.connect(f"file:{journal}?mode=ro", uri=True) as db:
        return db.execute(sql).fetchall()


def open_live(page: Page, url: str) -> None:
    page.page.goto(url)
    page.wait("window.petrobot.mode === 'live' && window.petrobot.live.runId", what="the live run")


def test_a_paused_run_fires_exactly_one_transition_per_step(page: Page, petrobot: Any, tmp_path: Path):
    proc, journal = start_stepper(petrobot, tmp_path)
    open_live(page, proc.url())
    page.wait("window.petrobot.live.state.state === 'waiting'", what="the run to wait for the operator")
    page.page.click("#cmd-pause")
    page.wait("window.petrobot.live.paused", what="the pause")
    page.click_node("go")                                   # the control place's popover
    page.page.click("#steer-insert")
    page.wait("window.petrobot.live.marking.go === 1", what="the go token")
    assert page.eval("window.petrobot.live.firings") == 0   # paused: inserting fired nothing
    page.page.keyboard.press("Escape")
    page.page.click("#cmd-step")
    page.wait("window.petrobot.live.firings === 1", what="one firing")
    assert page.tokens("busy") == 1 and page.tokens("runs") == 2
    page.page.click("#cmd-step")
    page.wait("window.petrobot.live.firings === 2", what="a second firing")
    assert page.tokens("done") == 1 and page.tokens("ready") == 1
    page.screenshot("live-stepped")
    page.page.click("#cmd-resume")
    page.wait("window.petrobot.live.firings === 6 && window.petrobot.live.state.state === 'waiting'",
              what="the two remaining runs")
    page.page.click("#cmd-end")
    assert proc.wait() == 0
    commands = rows(journal, "SELECT command, place, accepted FROM operator ORDER BY entry")
    assert commands == [("pause", None, 1), ("insert", "go", 1), ("step", None, 1), ("step", None, 1),
                        ("resume", None, 1), ("end", None, 1)]
    fired = [t for (t,) in rows(journal, "SELECT transition FROM firing ORDER BY seq")]
    assert fired == ["take", "put"] * 3


def test_without_the_token_the_page_follows_but_cannot_steer(page: Page, petrobot: Any, tmp_path: Path):
    proc, journal = start_stepper(petrobot, tmp_path)
    open_live(page, without_token(proc.url()))
    assert page.eval("document.getElementById('access').textContent") == "read-only"
    assert page.eval("document.getElementById('cmd-pause').disabled") is True
    page.click_node("runs")
    assert page.page.locator("#steer-remove").is_disabled()
    assert "read-only" in page.eval("document.getElementById('steer-note').textContent")
    # a hand-made command from this page is refused by the server, and nothing is journaled
    reply = page.eval("""() => new Promise((resolve) => {
        const ws = new WebSocket(`ws://${location.host}/ws`);
        ws.onopen = () => { ws.send(JSON.stringify({type: "hello", v: 1}));
                            ws.send(JSON.stringify({type: "command", id: 7, command: "abort"})); };
        ws.onmessage = (ev) => { const m = JSON.parse(ev.data); if (m.type === "reply") { ws.close(); resolve(m); } };
    })""")
    assert reply["ok"] is False and "read-only" in reply["reason"]
    page.screenshot("live-read-only")
    assert rows(journal, "SELECT COUNT(*) FROM operator") == [(0,)]


def test_a_hostile_websocket_message_closes_that_socket_and_the_run_goes_on(page: Page, petrobot: Any,
                                                                          tmp_path: Path):
    proc, journal = start_stepper(petrobot, tmp_path)
    open_live(page, proc.url())
    closed = page.eval("""() => new Promise((resolve) => {
        const ws = new WebSocket(`ws://${location.host}/ws`);
        ws.onopen = () => { ws.send(JSON.stringify({type: "hello", v: 1}));
                            ws.send('{"type": "command", "id": 1, "command": "abort", "place": "x"'); };
        ws.onclose = (ev) => resolve({code: ev.code, reason: ev.reason});
    })""")
    assert closed["code"] == 1008 and closed["reason"].startswith("not JSON")
    # the page's own socket and the run are untouched: steer the run to its end
    assert page.eval("window.petrobot.link.open") is True
    page.click_node("go")
    page.page.click("#steer-insert")
    page.wait("window.petrobot.live.firings === 6 && window.petrobot.live.state.state === 'waiting'",
              what="the three runs")
    page.page.click("#cmd-end")
    assert proc.wait() == 0
    assert rows(journal, "SELECT end_state FROM run") == [("completed",)]


# ---------------------------------------------------------------------- the catching demo
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_the_catching_demo_live_tokens_move_and_emptying_runs_remaining_ends_the_experiment(
        page: Page, petrobot: Any, tmp_path: Path):
    from coordinator.commands.demo_start import SimWorld
    from tests.integration.conftest import Cluster
    from tests.integration.test_catching import SERVICES

    cluster = Cluster(tmp_path)
    cluster.write_services(SERVICES.replace("PREDICT_NODE", "vision"))
    # petrobot sim catching as the demo runs it (analytic camera)
    sim = SimWorld(["--realtime", "--seed", "3", "--renderer", "analytic", "--throws", "0", "--interval", "0",
                    "--throw-when-home", "1.0", "--first-throw", "4", "--camera-port", str(cluster.ports["camera"]),
                    "--can-port", str(cluster.ports["can"])])
    try:
        sim.wait_ready(TIMEOUT_S)
        cluster.start("vision", "motion")
        journal = tmp_path / "j.sqlite"
        proc = petrobot("run", str(ROOT / "nets" / "catch.toml"), "--services", str(cluster.services_path),
                        "--key-file", str(cluster.key_file), "--journal", str(journal), "--console", "0", "--lines",
                        "--max-seconds", "240", env=cluster.env(), cwd=tmp_path)
        open_live(page, proc.url())
        # tokens move: a run starts on an image sampling tick and locate runs on the vision node
        page.wait("window.petrobot.live.marking.runs_remaining === 3 && window.petrobot.live.firings >= 1",
                  what="the first run to start")
        page.wait("[...window.petrobot.live.running.values()].some(r => r.node === 'vision')",
                  what="an action running on the vision node")
        page.screenshot("catch-live")
        # the operator empties runs_remaining: the experiment ends after the current run
        page.click_node("runs_remaining")
        while page.tokens("runs_remaining") > 0:
            left = page.tokens("runs_remaining")
            page.page.click("#steer-remove")
            page.wait("(n) => window.petrobot.live.marking.runs_remaining !== n", arg=left, what="a token removed")
        page.page.keyboard.press("Escape")
        page.wait("window.petrobot.live.state.state === 'waiting' && "
                  "window.petrobot.live.state.reason.startsWith('completed: at the home marking')",
                  what="the current run to finish and the experiment to come home")
        page.screenshot("catch-live-home")
        page.page.click("#cmd-end")
        assert proc.wait() == 0, proc.output()
    finally:
        for name in list(cluster.procs):
            cluster.kill(name)
        sim.stop()
    started = rows(journal, "SELECT COUNT(*) FROM firing WHERE transition = 'start_run'")[0][0]
    removed = rows(journal, "SELECT SUM(count) FROM operator WHERE command = 'remove' AND accepted")[0][0]
    assert started + removed == 4 and 1 <= started < 4
    assert rows(journal, "SELECT end_state FROM run") == [("completed",)]
