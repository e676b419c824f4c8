"""End-to-end tests of the web console in a real browser: Debian's chromium driven headless by Playwright.

The browser is the system's (``/usr/bin/chromium``, or ``$PETROBOT_CHROMIUM``); Playwright never
downloads one. Without it the tests are skipped with a message saying what to install, except under
``CI=true``, where a missing browser is an error (``.ci/run`` installs it). Each test starts the
console as a real ``petrobot`` process on 127.0.0.1 and drives the page with the mouse; every page
error and every console error (a Content-Security-Policy violation is one) fails the test.
"""

from __future__ import annotations

import contextlib
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 90.0  # generous bound of every wait: a failing test fails, a loaded machine passes
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]

pytestmark = pytest.mark.browser


def chromium_path() -> str | None:
    """The system's chromium, or ``None``."""
    given = os.environ.get("PETROBOT_CHROMIUM")
    if given:
        return given if Path(given).exists() else None
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _missing(reason: str) -> None:
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason} (CI=true: the browser tests must run; .ci/run installs chromium with apt-get)",
                    pytrace=False)
    pytest.skip(f"{reason}: install Debian's chromium (apt-get install chromium) and playwright "
                "(pip install playwright) to run the console's browser tests")


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Chromium, one per test module: Playwright's sync API keeps an event loop running in this
    thread while it is open, so it must be closed before the asyncio tests of later modules run."""
    path = chromium_path()
    if path is None:
        _missing("no chromium browser found")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("the playwright package is not installed")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


class Page:
    """A browser page on the console, with what the page logged."""

    def __init__(self, page: Any) -> None:
        self.page = page
        self.errors: list[str] = []
        page.on("pageerror", lambda e: self.errors.append(f"page error: {e}"))
        page.on("console", lambda m: self.errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
        page.set_default_timeout(TIMEOUT_S * 1000)

    def wait(self, js: str, arg: Any = None, what: str = "") -> Any:
        """Wait until the JavaScript expression is truthy (bounded by TIMEOUT_S)."""
        # a function, not an expression: Playwright evaluates an expression with eval(), which the page's
        # Content-Security-Policy rightly refuses
        fn = js if js.lstrip().startswith("(") and "=>" in js else f"(arg) => ({js})"
        try:
            return self.page.wait_for_function(fn, arg=arg, timeout=TIMEOUT_S * 1000).json_value()
        except Exception as exc:
            raise AssertionError(f"waited {TIMEOUT_S:.0f} s for {what or js}; page errors: {self.errors}") from exc

    def eval(self, js: str, arg: Any = None) -> Any:
        return self.page.evaluate(js, arg)

    def node_xy(self, ident: str) -> tuple[float, float]:
        """Where node ``ident`` is drawn on the screen (page coordinates)."""
        box = self.page.locator("#cy").bounding_box()
        pos = self.eval("(id) => { const n = window.petrobot.graph.cy.getElementById(id); "
                        "return n.empty() ? null : n.renderedPosition(); }", ident)
        assert pos is not None, f"no element {ident} on the drawing"
        return box["x"] + pos["x"], box["y"] + pos["y"]

    def click_node(self, ident: str) -> None:
        x, y = self.node_xy(ident)
        self.page.mouse.click(x, y)

    def click_canvas(self, fx: float, fy: float) -> None:
        """Click the canvas at a fraction of its width and height."""
        box = self.page.locator("#cy").bounding_box()
        self.page.mouse.click(box["x"] + fx * box["width"], box["y"] + fy * box["height"])

    def tokens(self, place: str) -> int:
        return int(self.eval("(p) => window.petrobot.graph.tokens.get(p) || 0", place))

    def screenshot(self, name: str) -> Path:
        out = Path(os.environ.get("PETROBOT_SCREENSHOTS", "/tmp/petrobot-console-screenshots"))
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"{name}.png"
        self.page.screenshot(path=str(path))
        return path


@pytest.fixture
def page(browser: Any) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1400, "height": 900}, accept_downloads=True)
    p = Page(context.new_page())
    try:
        yield p
    finally:
        context.close()
    assert p.errors == [], f"the page logged errors: {p.errors}"


class Petrobot:
    """A ``petrobot`` process (console or run --console) whose output is read by a thread."""

    def __init__(self, args: list[str], *, cwd: Path, env: dict[str, str] | None = None) -> None:
        environ = dict(env or os.environ)
        environ["PYTHONPATH"] = str(ROOT) + os.pathsep + environ.get("PYTHONPATH", "")
        environ["PYTHONUNBUFFERED"] = "1"
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator.cli", *args], cwd=cwd, env=environ,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.lines: list[str] = []
        self._urls: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
            if line.startswith("petrobot console: http://"):
                self._urls.put(line.split()[-1])

    def url(self) -> str:
        """The console's address with its token, once the process prints it."""
        try:
            return self._urls.get(timeout=TIMEOUT_S)
        except queue.Empty:
            raise AssertionError(f"no console address after {TIMEOUT_S:.0f} s:\n" + "\n".join(self.lines)) from None

    def wait(self) -> int:
        """Wait for the process to end; its exit code."""
        try:
            return self.proc.wait(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"petrobot did not end within {TIMEOUT_S:.0f} s:\n" + "\n".join(self.lines)) from None

    def output(self) -> str:
        return "\n".join(self.lines)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)


@pytest.fixture
def petrobot() -> Iterator[Any]:
    """Start petrobot processes; every one is stopped at the end of the test."""
    started: list[Petrobot] = []

    def start(*args: str, cwd: Path = ROOT, env: dict[str, str] | None = None) -> Petrobot:
        proc = Petrobot(list(args), cwd=cwd, env=env)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()


def without_token(url: str) -> str:
    return url.split("?", 1)[0]


def elapsed_since(t0: float) -> float:
    return time.monotonic() - t0


@contextlib.contextmanager
def catching_demo(petrobot: Any, tmp_path: Path, journal: Path, max_seconds: int = 240) -> Iterator[Petrobot]:
    """``petrobot run nets/catch.toml --console 0`` against the simulated catching world (analytic
    camera, as the demo runs it) and the vision and motion nodes; the world and the nodes are stopped
    on leaving."""
    from coordinator.commands.demo_start import SimWorld
    from tests.integration.cluster import Cluster
    from tests.integration.test_catching import SERVICES

    cluster = Cluster(tmp_path)
    cluster.write_services(SERVICES.replace("PREDICT_NODE", "vision"))
    sim = SimWorld(["--realtime", "--seed", "3", "--renderer", "analytic", "--throws", "0", "--interval", "0",
                    "--throw-when-home", "1.0", "--first-throw", "4", "--camera-port", str(cluster.ports["camera"]),
                    "--can-port", str(cluster.ports["can"])])
    try:
        sim.wait_ready(TIMEOUT_S)
        cluster.start("vision", "motion")
        yield petrobot("run", str(ROOT / "nets" / "catch.toml"), "--services", str(cluster.services_path),
                       "--key-file", str(cluster.key_file), "--journal", str(journal), "--console", "0", "--lines",
                       "--max-seconds", str(max_seconds), env=cluster.env(), cwd=tmp_path)
    finally:
        for name in list(cluster.procs):
            cluster.kill(name)
        sim.stop()
