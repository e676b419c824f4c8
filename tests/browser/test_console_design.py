"""Designing a task net by drawing it (paper section 5), in a real browser: places, transitions and
arcs placed with the mouse, kinds, tokens and events set in the inspector, undo and redo, saved to
a TOML net file that `petrobot check` accepts with its drawing kept; a finished run's replay
scrubbed back and forth."""

from __future__ import annotations

import asyncio
import concurrent.futures
import subprocess
import sys
from pathlib import Path
from typing import Any

from coordinator.journal import Journal
from coordinator.netfile import load_any, load_layout, loads_net
from coordinator.runtime import Runtime
from services.results import ActionResult
from tests.browser.conftest import ROOT, Page
from tests.unit.runtime_fakes import FakeClient


def set_field(page: Page, label: str, value: str) -> None:
    """Type into the inspector field labelled ``label`` and commit it (change event)."""
    field = page.page.locator("#panel-inspect .field", has=page.page.locator(f"label:text-is('{label}')"))
    box = field.locator("input, select, textarea").first
    if box.evaluate("e => e.tagName") == "SELECT":
        box.select_option(value)
    else:
        box.fill(value)
        box.press("Enter")
        box.dispatch_event("change")


def test_a_net_drawn_with_the_mouse_and_saved_passes_petrobot_check(page: Page, petrobot: Any, tmp_path: Path):
    console = petrobot("console", "--listen", "0", "--root", str(tmp_path), "--services", str(ROOT / "services.toml"))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the page to be ready")
    assert page.eval("window.petrobot.control") is True
    # places and transitions, clicked onto the empty canvas
    page.page.keyboard.press("p")
    page.click_canvas(0.30, 0.20)                     # p1
    page.click_canvas(0.30, 0.55)                     # p2
    page.page.keyboard.press("t")
    page.click_canvas(0.30, 0.375)                    # t1
    page.click_canvas(0.20, 0.75)                     # t2
    page.click_canvas(0.40, 0.75)                     # t3
    page.wait("window.petrobot.design.draft.transitions.length === 3", what="three transitions")
    # arcs: click the source, then the target
    page.page.keyboard.press("a")
    for source, target in [("p1", "t1"), ("t1", "p2"), ("p2", "t2"), ("t2", "p1"), ("p2", "t3"), ("t3", "p1")]:
        page.click_node(source)
        page.click_node(target)
    page.wait("window.petrobot.design.draft.arcs.length === 6", what="six arcs")
    # undo the last arc, redo it
    page.page.keyboard.press("Control+z")
    page.wait("window.petrobot.design.draft.arcs.length === 5", what="undo")
    page.page.keyboard.press("Control+y")
    page.wait("window.petrobot.design.draft.arcs.length === 6", what="redo")
    # the inspector: p1 a resource with a token, p2 a primitive task, t2/t3 its exits
    page.page.keyboard.press("v")
    page.click_node("p1")
    set_field(page, "kind", "resource")
    set_field(page, "tokens", "1")
    page.click_node("p2")
    set_field(page, "kind", "primitive_task")
    page.wait("window.petrobot.design.draft.tasks.p2 !== undefined", what="a task made for p2")
    for transition, outcome in [("t2", "ok"), ("t3", "error")]:
        page.click_node(transition)
        adder = page.page.locator("#panel-inspect .field", has=page.page.locator("label:text-is('link event')"))
        adder.locator("input[type=text]").first.fill(outcome)
        adder.locator("button:text-is('link')").click()
    page.click_node("t3")
    page.page.locator("#panel-inspect input[type=checkbox]").check()   # hidden: an error branch
    # checked as drawn, with the messages of petrobot check
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation && window.petrobot.validation.ok", what="the drawing to pass the checks")
    assert page.eval("document.getElementById('problem-count').textContent") == "0"
    page.screenshot("design-drawn")
    # save
    page.page.click("#save")
    page.page.fill("#save-path", "drawn.toml")
    page.page.click("#save-go")
    page.wait("document.body.dataset.saved === 'drawn.toml'", what="the save")
    saved = tmp_path / "drawn.toml"
    check = subprocess.run([sys.executable, "-m", "coordinator.cli", "check", str(saved), "--services",
                            str(ROOT / "services.toml")], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert check.returncode == 0, check.stdout + check.stderr
    net = load_any(saved)
    assert net.place("p1").kind.value == "resource" and net.initial_marking["p1"] == 1
    assert net.tasks["p2"].actions[0].name == "echo"
    assert net.transition("t2").events == ("int:p2.ok",) and net.transition("t3").hidden
    layout = load_layout(saved)
    assert set(layout) == {"p1", "p2", "t1", "t2", "t3"}
    assert layout["p1"][1] < layout["t1"][1] < layout["p2"][1]  # where it was drawn


def test_errors_are_shown_as_drawn_and_error_branches_can_be_hidden(page: Page, petrobot: Any):
    console = petrobot("console", str(ROOT / "nets" / "catch.toml"), "--listen", "0", "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the catching net to open")
    assert page.eval("window.petrobot.validation.ok") is True
    assert page.tokens("runs_remaining") == 4  # the paper's 4-run experiment
    visible = "window.petrobot.graph.cy.getElementById('locate_failed').style('display')"
    assert page.eval(visible) == "element"
    page.page.click("#toggle-hidden")
    assert page.eval(visible) == "none"
    page.screenshot("catch-design")
    # break the net: delete the normal exit of the return home
    page.click_node("at_home")
    page.page.keyboard.press("Delete")
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation && !window.petrobot.validation.ok", what="the problem to be found")
    problems = page.eval("window.petrobot.validation.problems.map(p => p.problem)")
    assert any("has no normal exit" in p for p in problems)
    page.page.keyboard.press("Control+z")
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation && window.petrobot.validation.ok", what="undo to fix it")


def finished_journal(path: Path) -> str:
    """A journal with one finished run of a small net, one of whose calls ended in error."""
    text = (ROOT / "nets" / "demo.toml").read_text(encoding="utf-8")
    net = loads_net(text)
    calls = iter([ActionResult.success(), ActionResult.error("simulated fault")] * 10)

    async def go() -> str:
        client = FakeClient({"coin": lambda params: next(calls), "compute_primes": ActionResult.success(),
                             "wait": ActionResult.success()})
        with Journal(path) as journal:
            runtime = Runtime(net, client, journal, net_text=text)
            await runtime.run()
            return runtime.run_id
    with concurrent.futures.ThreadPoolExecutor(1) as pool:  # Playwright's loop owns this thread
        return pool.submit(asyncio.run, go()).result(timeout=120)


def test_the_replay_of_a_finished_run_scrubs_back_and_forth_and_jumps_to_errors(page: Page, petrobot: Any,
                                                                                   tmp_path: Path):
    run_id = finished_journal(tmp_path / "j.sqlite")
    console = petrobot("console", str(ROOT / "nets" / "demo.toml"), "--journal", str(tmp_path / "j.sqlite"),
                       "--listen", "0", "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the page")
    page.page.click("#modes [data-mode=replay]")
    page.page.locator("#panel-timeline .runs-list li", has_text=run_id).click()
    page.wait("window.petrobot.replay.data && window.petrobot.mode === 'replay'", what="the replay")
    total = page.eval("window.petrobot.replay.records.length")
    # a replay opens where the run started, and says so
    assert page.tokens("runs_remaining") == 3 and page.tokens("robot") == 1 and page.tokens("done") == 0
    assert page.eval("document.getElementById('rp-pos').textContent").startswith(f"0 / {total} records")
    assert "shown at its start" in page.eval("document.getElementById('message').textContent")
    page.page.click("#rp-end")
    assert page.tokens("done") == 3 and page.tokens("runs_remaining") == 0  # the end of the run
    page.page.click("#rp-start")
    assert page.tokens("runs_remaining") == 3 and page.tokens("robot") == 1 and page.tokens("done") == 0
    slider = page.page.locator("#rp-slider")
    slider.focus()
    page.page.keyboard.press("ArrowRight")  # the slider takes the arrow keys too
    page.wait("window.petrobot.replay.k >= 1", what="a step forward")
    assert page.tokens("runs_remaining") == 2 and page.tokens("sensing") == 1
    page.page.click("#rp-next-error")
    k = page.eval("window.petrobot.replay.k")
    record = page.eval("(k) => window.petrobot.replay.records[k - 1]", k)
    assert record[0] == "r" and record[5] == "error" and record[7] == "simulated fault"
    assert page.eval("document.getElementById('rp-pos').textContent").startswith(f"{k} / {total}")
    page.screenshot("replay-error")
    page.page.click("#rp-end")
    assert page.tokens("done") == 3


def test_the_readme_console_example_opens_the_demos_journal_and_replay_says_to_pick_a_run(page: Page, petrobot: Any,
                                                                                          tmp_path: Path):
    import re

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    (command,) = re.findall(r"`(petrobot console nets/\S+ --journal \S+)`", readme)
    journal = command.split("--journal ")[1].split()[0]
    demo_help = subprocess.run([sys.executable, "-m", "coordinator.cli", "demo", "--help"], capture_output=True,
                               text=True, cwd=ROOT, timeout=120).stdout
    assert journal == "runs/catching.sqlite" and journal in demo_help  # the journal the demo writes
    (tmp_path / "runs").mkdir()
    (tmp_path / "nets").mkdir()
    (tmp_path / "nets" / "catch.toml").write_text((ROOT / "nets" / "catch.toml").read_text())
    run_id = finished_journal(tmp_path / journal)
    console = petrobot(*command.split()[1:], "--listen", "0", cwd=tmp_path)  # as the README says, on a free port
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the page")
    assert page.eval("document.getElementById('run-state').textContent") == "design"
    page.page.click("#modes [data-mode=replay]")
    assert page.eval("document.getElementById('run-state').textContent") == "replay"  # no design badge left
    assert "pick a run in the Runs panel" in page.eval("document.getElementById('hint').textContent")
    page.page.locator("#panel-timeline .runs-list li", has_text=run_id).click()
    page.wait("window.petrobot.replay.data && window.petrobot.replay.k === 0", what="the replay at its start")
    assert page.eval("document.getElementById('hint').textContent") == ""
    assert page.eval("document.getElementById('run-state').textContent") == "replay"
    page.screenshot("replay-start")


def test_the_png_export_draws_the_net_with_its_tokens(page: Page, petrobot: Any, tmp_path: Path):
    import cv2

    console = petrobot("console", str(ROOT / "nets" / "catch.toml"), "--listen", "0", "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the catching net to open")
    page.page.click("#export")
    with page.page.expect_download() as download:
        page.page.click("#exp-png")
    path = tmp_path / "catch.png"
    download.value.save_as(path)
    image = cv2.imread(str(path))
    assert image is not None, "the export is not a PNG"
    # where cytoscape's export (2 px per model unit, the drawing's bounding box) puts runs_remaining
    at = page.eval("() => { const cy = window.petrobot.graph.cy; const bb = cy.mutableElements().boundingBox();"
                   " const p = cy.getElementById('runs_remaining').position();"
                   " return [(p.x - bb.x1) * 2, (p.y - bb.y1) * 2, bb.w * 2, bb.h * 2]; }")
    assert abs(image.shape[1] - at[2]) <= 2 and abs(image.shape[0] - at[3]) <= 2
    x, y = round(at[0]), round(at[1])
    # its 4 tokens are dots 7 model units from the place's centre on both axes; the centre is white
    for dx, dy in ((-7, -7), (7, -7), (-7, 7), (7, 7)):
        assert image[y + 2 * dy, x + 2 * dx].max() < 80, f"no token dot at {(dx, dy)} in the exported PNG"
    assert image[y, x].min() > 150


def test_tokens_stay_on_their_place_when_it_is_dragged_and_the_view_zooms(page: Page, petrobot: Any):
    console = petrobot("console", str(ROOT / "nets" / "catch.toml"), "--listen", "0", "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the catching net to open")

    def token_centre() -> tuple[float, float]:
        box = page.page.locator(".token-layer .tokens[data-place='runs_remaining']").bounding_box()
        assert box is not None, "no tokens drawn on runs_remaining"
        return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2

    def on_place() -> None:
        (tx, ty), (px, py) = token_centre(), page.node_xy("runs_remaining")
        assert abs(tx - px) < 1.5 and abs(ty - py) < 1.5, f"tokens at {(tx, ty)}, place at {(px, py)}"

    on_place()
    x, y = page.node_xy("runs_remaining")
    page.page.mouse.move(x, y)
    page.page.mouse.down()
    page.page.mouse.move(x + 60, y + 40, steps=8)
    page.page.mouse.up()
    assert abs(page.node_xy("runs_remaining")[0] - (x + 60)) < 2  # the place moved
    on_place()
    # zoom in around a point away from the place (as the mouse wheel does), then pan
    page.eval("() => { const cy = window.petrobot.graph.cy;"
              " cy.zoom({ level: cy.zoom() * 1.7, renderedPosition: { x: 300, y: 250 } }); cy.panBy({ x: -40, y: 25 }); }")
    on_place()
    page.page.click("#toggle-hidden")  # hide the error branches: their places' tokens go with them
    assert page.page.locator(".token-layer .tokens[data-place='home_retries_left']").is_hidden()
