"""The analyses on the drawing (paper section 2's views of one net), in a real browser: `petrobot
analyze`, `gspn`, `perf` and `learn` run with --json and the page draws their JSON on the net — a
deadlock as a marking reached by its firing sequence, played step by step; bounds on places; dead
transitions marked; P-invariants highlighted on click; the GSPN heat map with its bottleneck; J, R
and C beside a task's place; the learner's probabilities as bars — each number linked to its
definition in the docs."""

from __future__ import annotations

import json
import subprocess
import sys
import urllib.request
from pathlib import Path
from typing import Any

from coordinator.journal import Journal
from coordinator.learning import Learner
from coordinator.netfile import loads_net
from coordinator.runtime import Runtime
from services.results import ActionResult
from tests.browser.conftest import ROOT, Page
from tests.unit.runtime_fakes import FakeClient

FORKS = """
[net]
name = "forks"
description = "Two arms share two grippers and take them in opposite orders: a deadlock."

[[place]]
id = "left_free"
kind = "resource"
tokens = 1

[[place]]
id = "right_free"
kind = "resource"
tokens = 1

[[place]]
id = "a_idle"
tokens = 1

[[place]]
id = "a_has_left"

[[place]]
id = "a_has_both"

[[place]]
id = "b_idle"
tokens = 1

[[place]]
id = "b_has_right"

[[place]]
id = "b_has_both"

[[place]]
id = "spare"

[[transition]]
id = "a_takes_left"
inputs = { a_idle = 1, left_free = 1 }
outputs = { a_has_left = 1 }

[[transition]]
id = "a_takes_right"
inputs = { a_has_left = 1, right_free = 1 }
outputs = { a_has_both = 1 }

[[transition]]
id = "a_puts_back"
inputs = { a_has_both = 1 }
outputs = { a_idle = 1, left_free = 1, right_free = 1 }

[[transition]]
id = "b_takes_right"
inputs = { b_idle = 1, right_free = 1 }
outputs = { b_has_right = 1 }

[[transition]]
id = "b_takes_left"
inputs = { b_has_right = 1, left_free = 1 }
outputs = { b_has_both = 1 }

[[transition]]
id = "b_puts_back"
inputs = { b_has_both = 1 }
outputs = { b_idle = 1, left_free = 1, right_free = 1 }

[[transition]]
id = "use_spare"
inputs = { spare = 1 }
outputs = { a_idle = 1 }
"""


def learned_journal(path: Path, runs: int = 8) -> None:
    """A journal of ``runs`` runs of the foundation demo net with its learners (compute learns
    between compute_primes and wait), one sense error in four."""
    import asyncio
    import concurrent.futures

    text = (ROOT / "nets" / "demo.toml").read_text(encoding="utf-8")
    net = loads_net(text)
    net = net.with_initial_marking({**net.initial_marking.to_dict(), "runs_remaining": runs})
    coins = iter([ActionResult.success()] * 3 + [ActionResult.error("simulated fault")])

    def coin(params: dict[str, Any]) -> ActionResult:
        return next(coins, ActionResult.success())

    async def go() -> None:
        client = FakeClient({"coin": coin, "compute_primes": ActionResult.success(), "wait": ActionResult.success()})
        with Journal(path) as journal:
            await Runtime(net, client, journal, net_text=text, learner=Learner.from_net(net, 1)).run()
    with concurrent.futures.ThreadPoolExecutor(1) as pool:  # Playwright's loop owns this thread
        pool.submit(asyncio.run, go()).result(timeout=120)


def open_forks(page: Page, petrobot: Any, tmp_path: Path) -> Path:
    net = tmp_path / "forks.toml"
    net.write_text(FORKS)
    console = petrobot("console", str(net), "--listen", "0", "--root", str(tmp_path))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the net")
    return net


def analyse(page: Page, kind: str) -> None:
    page.page.click("#tabs [data-tab=analysis]")
    page.page.click(f"#panel-analysis button[data-kind={kind}]")
    page.wait("(k) => document.body.dataset.analysed === k", arg=kind, what=f"petrobot {kind}")


def cli_json(*args: str) -> dict[str, Any]:
    out = subprocess.run([sys.executable, "-m", "coordinator.cli", *args, "--json"], capture_output=True, text=True,
                         cwd=ROOT, timeout=300, check=True).stdout
    return json.loads(out)


def test_a_deadlock_of_a_small_net_is_shown_on_the_drawing_with_the_sequence_that_reaches_it(
        page: Page, petrobot: Any, tmp_path: Path):
    net = open_forks(page, petrobot, tmp_path)
    analyse(page, "analyze")
    (deadlock,) = cli_json("analyze", str(net))["deadlocks"]  # the command line's own JSON
    assert deadlock["marking"] == {"a_has_left": 1, "b_has_right": 1}
    assert page.eval("window.petrobot.analysis.results.analyze.data.deadlocks") == [deadlock]
    page.page.locator("#deadlock-list li").first.click()
    page.wait("document.body.dataset.traceStep === '2'", what="the dead marking on the drawing")
    tokens = "() => Object.fromEntries(window.petrobot.graph.tokens)"
    assert page.eval(tokens) == {"a_has_left": 1, "b_has_right": 1}
    assert page.page.locator(".mark.trace-step").inner_text() == "2/2"  # beside the last transition fired
    page.screenshot("analysis-deadlock")
    # step back to the initial marking, then play the sequence on the drawing like a replay
    page.page.locator(".trace button[title='the initial marking']").click()
    assert page.eval(tokens) == {"left_free": 1, "right_free": 1, "a_idle": 1, "b_idle": 1}
    page.page.locator(".trace button[title='one firing on']").click()
    assert page.eval(tokens) == {"right_free": 1, "a_has_left": 1, "b_idle": 1}
    page.page.locator(".trace button[title='play the sequence']").click()
    page.wait("document.body.dataset.traceStep === '2'", what="the sequence played to its end")
    assert page.eval(tokens) == {"a_has_left": 1, "b_has_right": 1}


def test_bounds_dead_transitions_and_invariants_are_drawn_and_link_to_their_definitions(
        page: Page, petrobot: Any, tmp_path: Path):
    open_forks(page, petrobot, tmp_path)
    analyse(page, "analyze")
    bound = page.page.locator(".mark.bound[data-node='left_free']")
    assert bound.inner_text() == "\u22641"
    href = bound.get_attribute("href")
    assert href.startswith("/docs/analysis.md#")
    base = page.eval("location.origin")
    with urllib.request.urlopen(base + href.split("#")[0]) as answer:  # the definition, served as HTML
        assert f'id="{href.split("#")[1]}"' in answer.read().decode()
    # the spare place never gets a token: use_spare is dead, and marked so
    assert page.eval("window.petrobot.graph.cy.getElementById('use_spare').hasClass('dead')")
    assert page.page.locator(".mark.dead[data-node='use_spare']").inner_text() == "dead"
    # a P-invariant highlighted on click
    invariants = page.eval("window.petrobot.analysis.results.analyze.data.p_invariants")
    first = sorted(invariants[0])
    page.page.locator("#p-invariants-list li").first.click()
    assert page.eval("window.petrobot.graph.cy.$('.inv').map(n => n.id()).sort()") == first
    assert set(first) >= {"a_idle", "a_has_left", "a_has_both"} or set(first) >= {"left_free", "a_has_left"}
    page.screenshot("analysis-invariant")


def test_the_gspn_heat_map_names_the_bottleneck_and_j_r_c_and_learner_bars_sit_on_task_places(
        page: Page, petrobot: Any, tmp_path: Path):
    learned_journal(tmp_path / "j.sqlite")
    console = petrobot("console", str(ROOT / "nets" / "demo.toml"), "--journal", str(tmp_path / "j.sqlite"),
                       "--listen", "0", "--root", str(ROOT))
    page.page.goto(console.url())
    page.wait("document.body.dataset.ready === '1'", what="the demo net")
    analyse(page, "gspn")
    data = page.eval("window.petrobot.analysis.results.gspn.data")
    bottleneck = data["bottlenecks"][0]["transition"].removesuffix(".run")
    assert page.eval("(id) => window.petrobot.graph.cy.getElementById(id).hasClass('bottleneck')", bottleneck)
    assert page.page.locator(f".mark.bottleneck[data-node='{bottleneck}']").is_visible()
    assert f"bottleneck: {bottleneck}" in page.eval("document.getElementById('panel-analysis').innerText")
    assert page.eval("window.petrobot.graph.cy.$('.heat').length") >= 2
    analyse(page, "perf")
    jrc = page.page.locator(".mark.jrc[data-node='computing']")
    assert jrc.inner_text().startswith("J ") and " \u00b7 R " in jrc.inner_text()
    assert jrc.get_attribute("href").startswith("/docs/gspn.md#")
    analyse(page, "learn")
    bars = page.page.locator(".mark.learner[data-node='computing'] .lbar")
    assert bars.count() == 2  # compute_primes and wait, each with its probability
    learned = page.eval("window.petrobot.analysis.results.learn.data.tasks.compute.actions")
    assert abs(sum(a["probability"] for a in learned.values()) - 1.0) < 1e-9
    page.screenshot("analysis-gspn-perf-learn")
