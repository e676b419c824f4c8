"""A net an operator can read, and a drawing that keeps their work (issue: the console as a cockpit),
in Debian's chromium at 1400x900: names first and events second, labels readable, no label
overlapped by another label or a node after Tidy (counted on both paper nets and a generated
200-node net), the net fitted to the canvas, hidden error branches one click away; an unsaved
marker and a confirmation before edits are discarded, the Arc tool's drag drawing an arc, reset
arcs and rate/weight expressions drawn and saved, problems pointing at the real file or at the
unsaved drawing, and Open listing only nets."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from coordinator.netfile import load_any
from tests.browser.conftest import ROOT, Page


def generated_net(chains: int = 10, per: int = 10) -> str:
    """A net of ``chains`` rings of ``per`` places and transitions with cross links (200 nodes), no
    positions: what a tool that writes nets without a drawing gives."""
    lines = ['[net]', f'name = "generated{2 * chains * per}"', '']
    for c in range(chains):
        for k in range(per):
            lines += ['[[place]]', f'id = "p{c}_{k}"', *(['tokens = 1'] if k == 0 else []), '']
    for c in range(chains):
        for k in range(per):
            extra = f", p{(c + 1) % chains}_{(k + 3) % per} = 1" if k % 4 == 1 else ""
            lines += ['[[transition]]', f'id = "t{c}_{k}"', *([f'events = ["ext:tick_{c}"]'] if k == 0 else []),
                      f'inputs = {{ p{c}_{k} = 1 }}', f'outputs = {{ p{c}_{(k + 1) % per} = 1{extra} }}', '']
    return "\n".join(lines)


def open_console(page: Page, petrobot: Any, net: Path, root: Path) -> None:
    console = petrobot("console", str(net), "--listen", "0", "--root", str(root))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what=f"{net.name} to open")


def tidy(page: Page) -> None:
    before = page.eval("document.body.dataset.tidied || ''")
    page.page.click("#tidy")
    page.wait("(b) => (document.body.dataset.tidied || '') !== b", arg=before, what="Tidy")


def overlaps(page: Page) -> list[list[str]]:
    return page.eval("window.petrobot.graph.labelOverlaps()")


def readability(page: Page) -> dict[str, float]:
    return page.eval("window.petrobot.graph.readability()")


def test_transitions_show_their_name_first_and_their_event_second(page: Page, petrobot: Any):
    open_console(page, petrobot, ROOT / "nets" / "catch.toml", ROOT)
    label = "(id) => window.petrobot.graph.cy.getElementById(id).data('label')"
    assert page.eval(label, "ball_caught") == "ball_caught\nint:catch.success"  # the id the terminal trace prints
    assert page.eval(label, "locating") == "locating [locate]"
    page.page.click("#labels")
    assert page.eval(label, "ball_caught") == "ball_caught"
    page.page.click("#labels")
    assert page.eval(label, "ball_caught") == "int:catch.success"  # the paper's Fig. 1


@pytest.mark.parametrize("net", ["catch", "mobile"])
def test_the_paper_nets_are_readable_at_1400x900_and_no_label_overlaps_after_tidy(page: Page, petrobot: Any, net: str):
    open_console(page, petrobot, ROOT / "nets" / f"{net}.toml", ROOT)
    assert page.eval("[window.innerWidth, window.innerHeight]") == [1400, 900]
    # with the error-recovery branches hidden (one click away), as the paper suggests
    if page.eval("window.petrobot.graph.showHidden"):
        page.page.click("#toggle-hidden")
    tidy(page)
    assert overlaps(page) == []
    seen = readability(page)
    assert seen["fontPx"] >= 11.5, seen  # a 16-unit label at the zoom Fit gives: readable
    assert seen["fill"] >= 0.9, seen     # fitted to the canvas
    page.screenshot(f"readable-{net}")
    # every branch shown, laid out again: still no overlap, still fitted
    page.page.click("#toggle-hidden")
    tidy(page)
    assert overlaps(page) == []
    assert readability(page)["fill"] >= 0.9


def test_the_catching_nets_own_drawing_has_no_overlapping_label(page: Page, petrobot: Any):
    open_console(page, petrobot, ROOT / "nets" / "catch.toml", ROOT)
    assert overlaps(page) == []
    assert readability(page)["fontPx"] >= 10.5


def test_a_generated_200_node_net_is_laid_out_without_overlapping_labels(page: Page, petrobot: Any, tmp_path: Path):
    net = tmp_path / "generated200.toml"
    net.write_text(generated_net())
    assert len(load_any(net).places) + len(load_any(net).transitions) == 200
    open_console(page, petrobot, net, tmp_path)  # no positions: laid out on opening
    assert page.eval("window.petrobot.graph.cy.nodes().length") == 200
    assert overlaps(page) == []
    tidy(page)
    assert overlaps(page) == []
    assert readability(page)["fill"] >= 0.9


def test_hidden_error_branches_are_one_click_away(page: Page, petrobot: Any):
    open_console(page, petrobot, ROOT / "nets" / "catch.toml", ROOT)
    shown = "(id) => window.petrobot.graph.cy.getElementById(id).style('display') === 'element'"
    page.page.click("#toggle-hidden")
    assert not page.eval(shown, "locate_failed")
    mark = page.page.locator(".mark.reveal[data-node='locating']")
    assert mark.inner_text() == "\u22951"  # one hidden branch leaves locating
    mark.click()
    assert page.eval(shown, "locate_failed") and page.eval(shown, "home_given_up")


# ---------------------------------------------------------------------- the drawing keeps your work
def test_edits_are_marked_unsaved_and_new_or_open_asks_before_discarding_them(page: Page, petrobot: Any, tmp_path: Path):
    (tmp_path / "nets").mkdir()
    (tmp_path / "nets" / "catch.toml").write_text((ROOT / "nets" / "catch.toml").read_text())
    (tmp_path / "services.toml").write_text((ROOT / "services.toml").read_text())
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    open_console(page, petrobot, tmp_path / "nets" / "catch.toml", tmp_path)
    assert page.page.locator("#dirty").is_hidden()
    x, y = page.node_xy("caught")
    page.page.mouse.move(x, y)
    page.page.mouse.down()
    page.page.mouse.move(x + 40, y + 30, steps=5)
    page.page.mouse.up()
    page.wait("document.body.dataset.dirty === '1'", what="the unsaved marker")
    assert page.page.locator("#dirty").is_visible() and page.eval("document.title").startswith("\u25cf ")
    # New: asked, and "keep editing" keeps the drawing
    page.page.click("#new")
    assert page.page.locator("#confirm-dialog").is_visible()
    page.screenshot("design-confirm")
    page.page.click("#confirm-no")
    assert page.eval("window.petrobot.design.draft.places.length") == 15
    # Open lists nets only (not services.toml, not pyproject.toml), and asks too
    page.page.click("#open")
    page.wait("document.querySelectorAll('#open-list li').length >= 1 && "
              "document.getElementById('open-list').textContent !== '...'", what="the list of nets")
    assert page.eval("[...document.querySelectorAll('#open-list li')].map(li => li.textContent)") == ["nets/catch.toml"]
    page.page.fill("#open-path", "nets/catch.toml")
    page.page.click("#open-go")
    assert page.page.locator("#confirm-dialog").is_visible()
    page.page.click("#confirm-yes")
    page.wait("document.body.dataset.dirty === '0'", what="the file opened again, its changes discarded")
    # undoing an edit back to the file clears the marker too
    page.click_node("caught")
    page.page.keyboard.press("Delete")
    page.wait("document.body.dataset.dirty === '1'", what="marked")
    page.page.keyboard.press("Control+z")
    page.wait("document.body.dataset.dirty === '0'", what="clean again")
    # a reload or close of an edited drawing is asked by the browser (beforeunload)
    page.click_node("caught")
    page.page.keyboard.press("Delete")
    page.wait("document.body.dataset.dirty === '1'", what="marked")
    with page.page.expect_event("dialog") as asked:
        page.page.close(run_before_unload=True)
    assert asked.value.type == "beforeunload"
    asked.value.dismiss()


def test_the_arc_tool_drag_draws_an_arc_and_reset_arcs_and_expressions_are_saved(page: Page, petrobot: Any,
                                                                                  tmp_path: Path):
    console = petrobot("console", "--listen", "0", "--root", str(tmp_path))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the page")
    page.page.keyboard.press("p")
    page.click_canvas(0.3, 0.2)   # p1
    page.click_canvas(0.6, 0.2)   # p2
    page.page.keyboard.press("t")
    page.click_canvas(0.45, 0.5)  # t1
    page.wait("window.petrobot.design.draft.transitions.length === 1", what="the transition")
    before = page.eval("window.petrobot.design.draft.places.find(p => p.id === 'p1').pos")

    def drag(source: str, target: str) -> None:
        (x0, y0), (x1, y1) = page.node_xy(source), page.node_xy(target)
        page.page.mouse.move(x0, y0)
        page.page.mouse.down()
        page.page.mouse.move((x0 + x1) / 2, (y0 + y1) / 2, steps=6)
        assert page.page.locator("#rubber").is_visible()  # the arc being drawn follows the pointer
        page.page.mouse.move(x1, y1, steps=6)
        page.page.mouse.up()

    page.page.keyboard.press("a")
    drag("p1", "t1")
    drag("t1", "p2")
    page.wait("window.petrobot.design.draft.arcs.length === 2", what="two arcs drawn by dragging")
    assert page.eval("window.petrobot.design.draft.places.find(p => p.id === 'p1').pos") == before  # nothing moved
    page.page.keyboard.press("r")
    drag("p2", "t1")
    page.wait("window.petrobot.design.draft.arcs.length === 3", what="the reset arc")
    page.screenshot("design-arcs")
    assert page.eval("window.petrobot.design.draft.arcs[2]") == {"from": "p2", "to": "t1", "reset": True}
    # a weight expression and an exponential rate expression, typed in the inspector
    page.page.keyboard.press("v")
    page.click_node("t1")
    weight = page.page.locator("#panel-inspect .field", has=page.page.locator("label:text-is('weight')")).locator("input")
    weight.fill("1 + #p1")
    weight.press("Enter")
    timing = page.page.locator("#panel-inspect .field", has=page.page.locator("label:text-is('timing')")).locator("select")
    timing.select_option("exponential")
    rate = page.page.locator("#panel-inspect .field", has=page.page.locator("label:text-is('rate (1/s)')")).locator("input")
    rate.fill("min(#p1, 3) * 2")
    rate.press("Enter")
    page.wait("window.petrobot.design.draft.transitions[0].rate === 'min(#p1, 3) * 2' && "
              "window.petrobot.design.draft.transitions[0].weight === '1 + #p1'", what="the expressions")
    # a bad expression: the problem is the unsaved drawing's, pointing at its element
    rate.fill("min(#nowhere, 3)")
    rate.press("Enter")
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation && !window.petrobot.validation.ok", what="the bad expression found")
    (problem,) = page.eval("window.petrobot.validation.problems")
    assert problem["text"].startswith("unsaved drawing: ") and "nowhere" in problem["text"] and problem["id"] == "t1"
    rate.fill("min(#p1, 3) * 2")
    rate.press("Enter")
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation && window.petrobot.validation.ok", what="fixed")
    page.page.click("#save")
    page.page.fill("#save-path", "drawn.toml")
    page.page.click("#save-go")
    page.wait("document.body.dataset.saved === 'drawn.toml'", what="the save")
    assert page.page.locator("#dirty").is_hidden()
    check = subprocess.run([sys.executable, "-m", "coordinator.cli", "check", str(tmp_path / "drawn.toml")],
                           cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert check.returncode == 0, check.stdout + check.stderr
    net = load_any(tmp_path / "drawn.toml", interpreted=False)
    (t1,) = net.transitions
    assert t1.weight_expr == "1 + #p1" and t1.rate_expr == "min(#p1, 3) * 2"
    assert net.reset_places["t1"] == ("p2",)


def test_problems_point_to_the_real_file_then_to_the_unsaved_drawing(page: Page, petrobot: Any, tmp_path: Path):
    text = (ROOT / "nets" / "demo.toml").read_text().replace('events = ["int:sense.error"]', 'events = ["int:snese.error"]', 1)
    assert text != (ROOT / "nets" / "demo.toml").read_text()
    broken = tmp_path / "broken.toml"
    broken.write_text(text)
    check = subprocess.run([sys.executable, "-m", "coordinator.cli", "check", "broken.toml", "--services",
                            str(ROOT / "services.toml")], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
    expected = [line for line in check.stdout.splitlines() if line.startswith("broken.toml:")]
    assert expected, check.stdout
    console = petrobot("console", str(broken), "--listen", "0", "--root", str(tmp_path), "--services",
                       str(ROOT / "services.toml"))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the broken net to open")
    shown = page.eval("window.petrobot.validation.problems.map(p => p.text)")
    assert shown == expected  # the file's own lines, as petrobot check prints them
    # an edit: now the problems are the unsaved drawing's
    page.click_node("done")
    page.page.keyboard.press("Delete")
    page.wait("!window.petrobot.checkPending() && window.petrobot.validation.problems.every(p => p.text.startsWith('unsaved drawing: '))",
              what="the problems of the unsaved drawing")
    assert "drawing.toml" not in page.eval("document.getElementById('panel-problems').innerText")
