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

from tests.browser.conftest import ROOT, Page, catching_demo, without_token

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


# ---------------------------------------------------------------------- what the page says is true
FLAKY = """
[net]
name = "flaky"
description = "Three grasps on node alpha, which is down: each ends in error and takes the error branch."
home = { hand = 1 }

[[place]]
id = "runs"
kind = "control"
tokens = 3
pos = [200, 40]

[[place]]
id = "hand"
kind = "resource"
tokens = 1
pos = [380, 40]

[[place]]
id = "grasping"
kind = "primitive_task"
task = "grasp"
pos = [200, 220]

[[place]]
id = "held"
pos = [120, 400]

[[place]]
id = "failed"
pos = [300, 400]

[task.grasp]
actions = ["coin"]
deadline_s = 30.0

[[transition]]
id = "start"
pos = [200, 130]
inputs = { runs = 1, hand = 1 }
outputs = { grasping = 1 }

[[transition]]
id = "grasped"
pos = [120, 310]
events = ["int:grasp.ok"]
inputs = { grasping = 1 }
outputs = { hand = 1, held = 1 }

[[transition]]
id = "grasp_failed"
pos = [300, 310]
events = ["int:grasp.error"]
hidden = true
inputs = { grasping = 1 }
outputs = { hand = 1, failed = 1 }
"""

# alpha hosts the grasp; nobody listens on its port. vision and motion are in services.toml, unused
FLAKY_SERVICES = """
[nodes.alpha]
host = "127.0.0.1"
port = {alpha}

[nodes.vision]
host = "127.0.0.1"
port = {vision}

[nodes.motion]
host = "127.0.0.1"
port = {motion}

[actions.coin]
node = "alpha"
impl = "services.actions.demo:coin"

[actions.echo]
node = "vision"
impl = "services.actions.demo:echo"
"""


def test_the_page_shows_failing_tasks_unused_nodes_the_real_state_and_keeps_the_end(page: Page, petrobot: Any,
                                                                                    tmp_path: Path):
    from tests.integration.cluster import free_port

    net = tmp_path / "flaky.toml"
    net.write_text(FLAKY)
    services = tmp_path / "services.toml"
    services.write_text(FLAKY_SERVICES.format(alpha=free_port(), vision=free_port(), motion=free_port()))
    key = tmp_path / "key"
    key.write_text(secrets.token_hex(32) + "\n")
    journal = tmp_path / "j.sqlite"
    proc = petrobot("run", str(net), "--services", str(services), "--key-file", str(key), "--journal", str(journal),
                    "--console", "0", "--lines", "--degraded", "--max-seconds", "600", cwd=tmp_path)
    open_live(page, proc.url())
    page.wait("window.petrobot.live.tasks.grasp && window.petrobot.live.tasks.grasp.in_a_row === 3 && "
              "window.petrobot.live.state.state === 'waiting'", what="three failed grasps, then the run at rest")
    page.page.click("#tabs [data-tab=run]")

    # nodes: the one the net uses is down (truly); the others are not used, not "down"
    health = page.eval("document.getElementById('panel-run').innerText")
    assert "not used by this net" in health and "vision, motion" in health
    rows_shown = page.eval("[...document.querySelectorAll('#panel-run table.grid tr')].map(r => r.innerText)")
    assert any(r.startswith("alpha") and "down" in r for r in rows_shown)
    assert not any(r.startswith(("vision", "motion")) for r in rows_shown)

    # the failing task is marked on the drawing, with its error branch, and its last reason is there in full
    page.wait("window.petrobot.graph.cy.$('.failing').not('.badge').length >= 2",  # painted with the next frame
              what="the failing task marked on the drawing")
    failing = page.eval("window.petrobot.graph.cy.$('.failing').not('.badge').map(e => e.id()).sort()")
    assert failing == ["grasp_failed", "grasping"]
    (reason,) = rows(journal, "SELECT reason FROM action_result ORDER BY rowid DESC LIMIT 1")[0]
    x, y = page.node_xy("grasping")
    page.page.mouse.move(x, y)
    page.wait("!document.getElementById('task-pop').hidden", what="the task's record on hover")
    assert page.eval("document.getElementById('task-pop-reason').textContent") == reason
    assert "3 errors in a row" in page.eval("document.getElementById('task-pop-title').textContent")
    page.screenshot("live-failing-task")

    # the page's words fit the page, and the badge follows the run: paused, even once it waits
    page.page.click("#cmd-pause")
    page.wait("document.getElementById('run-state').textContent === 'paused'", what="the paused badge")
    page.click_node("runs")
    page.page.click("#steer-insert")
    page.wait("window.petrobot.live.marking.runs === 1 && window.petrobot.live.state.state === 'waiting'",
              what="the token inserted while paused")
    assert page.eval("document.getElementById('run-state').textContent") == "paused"
    page.page.keyboard.press("Escape")
    text = page.eval("document.body.innerText")
    assert "type resume" not in text and "type end" not in text and "Ctrl-D" not in text
    assert "paused: resume, or step" in page.eval("document.getElementById('waiting').textContent")
    page.page.click("#cmd-resume")
    page.wait("window.petrobot.live.tasks.grasp.in_a_row === 4 && window.petrobot.live.state.state === 'waiting'",
              what="a fourth failed grasp")
    page.page.click("#cmd-end")
    assert proc.wait() == 6, proc.output()  # completed, but every call ended in error

    # the end stays on the page: the state, the final marking, the summary
    page.wait("document.getElementById('link').textContent === 'run ended'", what="the console to close")
    assert page.eval("document.getElementById('run-state').textContent") == "completed"
    assert page.tokens("hand") == 1 and page.tokens("failed") == 4
    run_panel = page.eval("document.getElementById('panel-run').innerText")
    assert "completed after" in run_panel and "final marking" in run_panel and "4 errors" in run_panel
    page.screenshot("live-ended")


# ---------------------------------------------------------------------- the catching demo
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_the_catching_demo_live_tokens_move_and_emptying_runs_remaining_ends_the_experiment(
        page: Page, petrobot: Any, tmp_path: Path):
    journal = tmp_path / "j.sqlite"
    with catching_demo(petrobot, tmp_path, journal) as proc:
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
    started = rows(journal, "SELECT COUNT(*) FROM firing WHERE transition = 'start_run'")[0][0]
    removed = rows(journal, "SELECT SUM(count) FROM operator WHERE command = 'remove' AND accepted")[0][0]
    assert started + removed == 4 and 1 <= started < 4
    assert rows(journal, "SELECT end_state FROM run") == [("completed",)]
