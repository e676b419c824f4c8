#!/usr/bin/env python3
"""The web console under load: firing-to-screen latency, the engine's rate with the console attached,
opening a 1,000-node net, and the page's memory over a long run, in a headless browser.

Two processes, as in use: a *run* process (``--serve``, started by this script) runs an endless net
of rings (``--rings`` R rings of ``--length`` L plain transitions: no node, no primitive task) in the
asyncio runtime with a journal, and serves the web console attached to it; this process drives
Debian's chromium (headless, through Playwright) on the console's page.

* **latency**: the page records, once each repaint showing new firings has been painted (a message
  posted from its ``requestAnimationFrame`` callback runs after the page's style, layout and paint),
  how long ago (server wall clock) the *oldest* firing it shows was fired (``window.petrobotStats``);
  p50 and p99 over every such repaint of the attached phases. Frames are coalesced server-side
  (≤ one per ``--period``, 10 ms), applied as they arrive, and drawn at most once per screen frame.
* **throughput ratio**: the run alternates phases of ``--phase`` seconds with the console's observer
  removed from the runtime and added back (the page stays connected); the ratio is the firing rate
  of the attached phases over that of the detached ones, in the same run (also the median over
  each detached phase and the attached one after it: short interleaved phases and many of them,
  because other processes on a shared machine move the rate by more than the console does).
* **memory**: the page's JavaScript heap after a forced garbage collection, every ``--sample``
  seconds, and the number of DOM nodes, from the start to the end of the run (``--minutes``).
* **feed cost** (no browser): the same rings in this process with a live feed whose frames go
  nowhere, attached and detached every ``--phase`` s (``--feed-pairs`` pairs); the process's CPU time
  per firing in each kind of phase, whose difference is the console's own cost on the run
  (``feed_cpu_cost``, a fraction), free of what other processes do to the wall-clock rate.
* **open 1,000 nodes**: ``petrobot console`` serves a net of 500 places and 500 transitions without
  positions; the time from navigation to the page being ready (laid out, drawn, two frames later),
  then to a click on a transition showing it in the inspector.
* **under CPU load** (``--load N``): N busy processes (a Python loop each) run beside the run and
  the browser for the whole measurement; the run is then measured twice in the same invocation,
  the console detached and attached in turns (the throughput ratio) and never detached (``--null``:
  the ratio the alternation alone gives, the noise floor), and both ratios are printed side by side.

* **viewers** (``--viewers``, no browser; issue 22): the same run and console, the console attached
  in every phase, and pages without the token (WebSocket clients in a process of their own at the
  lowest CPU priority, as other hosts would be) on in every other phase of ``--phase`` seconds:
  first four read-only pages asking, each in a loop, for the validation of a 3.3 MB drawing of
  20,000 places, of a 0.4 MB one of 2,500 places, and for a DOT export of the large one; then 200
  idle read-only viewers. The firing rate of the phases with them over that of the phases without
  them (target: >= 0.9), what the console answered them (checked, refused, closed), and the
  console process's resident memory at the first phase and at its highest.

Usage: python bench/console.py [--minutes M] [--phase S] [--rings R] [--length L] [--period S]
       [--skip-open] [--skip-run] [--feed-pairs N | --feed-only] [--load N] [--json]
       python bench/console.py --viewers [--viewer-minutes M] [--phase S] [--json]
(needs /usr/bin/chromium or $PETROBOT_CHROMIUM, and the playwright package, except --viewers).
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]
TIMEOUT_S = 120.0


# ---------------------------------------------------------------------- nets
def ring_toml(rings: int, length: int) -> str:
    """R rings of L places and L transitions, one token per ring, laid out as rows."""
    lines = ['[net]', f'name = "rings{rings}x{length}"', 'description = "console bench: endless rings"', '']
    for r in range(rings):
        for k in range(length):
            tokens = "tokens = 1\n" if k == 0 else ""
            lines.append(f'[[place]]\nid = "p{r}_{k}"\n{tokens}pos = [{k * 120.0}, {r * 160.0}]\n')
    for r in range(rings):
        for k in range(length):
            lines.append(f'[[transition]]\nid = "t{r}_{k}"\npos = [{k * 120.0 + 60}, {r * 160.0 + 60}]\n'
                         f'inputs = {{ p{r}_{k} = 1 }}\noutputs = {{ p{r}_{(k + 1) % length} = 1 }}\n')
    return "\n".join(lines)


def big_toml(pairs: int) -> str:
    """``pairs`` places and ``pairs`` transitions in 20 parallel chains, no positions (the server lays
    them out)."""
    lines = ['[net]', f'name = "big{2 * pairs}"', 'description = "console bench: a large net to open"', '']
    chains = 20
    per = pairs // chains
    for c in range(chains):
        for k in range(per):
            lines.append(f'[[place]]\nid = "p{c}_{k}"\n' + ("tokens = 1\n" if k == 0 else ""))
    for c in range(chains):
        for k in range(per):
            nxt = f"p{c}_{(k + 1) % per}"
            extra = f", p{(c + 1) % chains}_{k} = 1" if k % 10 == 5 else ""
            lines.append(f'[[transition]]\nid = "t{c}_{k}"\ninputs = {{ p{c}_{k} = 1 }}\n'
                         f'outputs = {{ {nxt} = 1{extra} }}\n')
    return "\n".join(lines)


# ---------------------------------------------------------------------- the run process
class _NoNodes:
    """A service client for nets without primitive tasks or external events."""

    location = None

    def subscribe(self, topic: str, callback: object) -> None:
        raise AssertionError("the bench net has no external event")


async def serve(args: argparse.Namespace) -> None:
    """Run the rings with the console attached; phases on the orders read from stdin."""
    from coordinator.journal import Journal
    from coordinator.netfile import load_any
    from coordinator.runtime import Runtime
    from coordinator.web.server import ConsoleConfig, ConsoleServer

    tmp = Path(args.serve)
    net_path = tmp / "rings.toml"
    net_path.write_text(ring_toml(args.rings, args.length), encoding="utf-8")
    net = load_any(net_path)
    loop = asyncio.get_running_loop()
    with Journal(tmp / "bench.sqlite") as journal:
        runtime = Runtime(net, _NoNodes(), journal, net_text=net_path.read_text(encoding="utf-8"))
        server = ConsoleServer(ConsoleConfig(root=tmp, nets=[net_path], journal=tmp / "bench.sqlite",
                                             period_s=args.period))
        print(json.dumps({"url": await server.start()}), flush=True)
        feed = server.attach_run(runtime, net_path)
        feed.adaptive = not args.fixed_period
        await loop.run_in_executor(None, sys.stdin.readline)  # the page is live
        run = loop.create_task(runtime.run())
        phases: list[dict[str, Any]] = []
        attached = True
        end = time.monotonic() + args.minutes * 60
        while time.monotonic() < end and not run.done():
            attached = not attached
            if args.null:
                pass  # the noise floor: the console stays attached in both kinds of phase
            elif attached:
                runtime.add_observer(feed)
            else:
                runtime.remove_observer(feed)
            f0, t0 = runtime.engine.fired, time.perf_counter()
            await asyncio.sleep(min(args.phase, max(0.0, end - time.monotonic())))
            phases.append({"attached": attached, "firings": runtime.engine.fired - f0,
                           "seconds": time.perf_counter() - t0})
            print(json.dumps({"phase": phases[-1]}), flush=True)
        if not attached and not args.null:
            runtime.add_observer(feed)
        from coordinator.operator import Command, OperatorCommand

        runtime.command(OperatorCommand(Command.ABORT))
        await asyncio.wait_for(run, TIMEOUT_S)
        await server.close("the bench is over")
    print(json.dumps({"phases": phases}), flush=True)


async def feed_cost(args: argparse.Namespace) -> dict[str, Any]:
    """The console's own cost on the engine, without a browser: the rings run in this process with
    a live feed whose frames go nowhere, the observer removed and added back every ``--phase``
    seconds; the process's CPU time per firing of each kind of phase (journal thread included), so
    that other processes on the machine do not move it."""
    from coordinator.journal import Journal
    from coordinator.netfile import load_any
    from coordinator.operator import Command, OperatorCommand
    from coordinator.runtime import Runtime
    from coordinator.web.frames import LiveFeed

    with tempfile.TemporaryDirectory() as tmp:
        net_path = Path(tmp) / "rings.toml"
        net_path.write_text(ring_toml(args.rings, args.length), encoding="utf-8")
        loop = asyncio.get_running_loop()
        with Journal(Path(tmp) / "bench.sqlite") as journal:
            runtime = Runtime(load_any(net_path), _NoNodes(), journal)
            feed = LiveFeed(runtime, period_s=args.period)
            frames: list[int] = []
            feed.subscribe(lambda text: frames.append(len(text)))
            framing = loop.create_task(feed.run())
            run = loop.create_task(runtime.run())
            await asyncio.sleep(0.5)
            cpu_us: dict[bool, list[float]] = {True: [], False: []}
            for k in range(2 * args.feed_pairs):
                attached = k % 2 == 1
                if attached:
                    runtime.add_observer(feed)
                else:
                    runtime.remove_observer(feed)
                f0, c0 = runtime.engine.fired, time.process_time()
                await asyncio.sleep(args.phase)
                cpu_us[attached].append((time.process_time() - c0) / max(1, runtime.engine.fired - f0) * 1e6)
            runtime.command(OperatorCommand(Command.ABORT))
            await asyncio.wait_for(run, TIMEOUT_S)
            framing.cancel()
    detached, attached_us = statistics.median(cpu_us[False]), statistics.median(cpu_us[True])
    return {"feed_cpu_us_per_firing_detached": round(detached, 2), "feed_cpu_us_per_firing_attached": round(attached_us, 2),
            "feed_cpu_cost": round((attached_us - detached) / detached, 4), "feed_frames": len(frames),
            "feed_frame_bytes_mean": round(statistics.mean(frames)) if frames else None}


# ---------------------------------------------------------------------- the browser side
def chromium() -> str:
    path = os.environ.get("PETROBOT_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        sys.exit("bench/console.py: no chromium (apt-get install chromium, or set PETROBOT_CHROMIUM)")
    return path


def js_heap(page: Any, cdp: Any) -> dict[str, float]:
    cdp.send("HeapProfiler.collectGarbage")
    metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
    return {"heap_mb": round(metrics.get("JSHeapUsedSize", 0) / 2**20, 2), "dom_nodes": int(metrics.get("Nodes", 0))}


def measure_run(browser: Any, args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        child = subprocess.Popen([sys.executable, __file__, "--serve", tmp, "--minutes", str(args.minutes),
                                  "--phase", str(args.phase), *(["--null"] if args.null else []),
                                  *(["--fixed-period"] if args.fixed_period else []), "--period", str(args.period), "--rings", str(args.rings), "--length", str(args.length)],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                 env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert child.stdin is not None and child.stdout is not None
        url = json.loads(child.stdout.readline())["url"]
        context = browser.new_context(viewport={"width": 1400, "height": 900})
        page = context.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url)
        page.wait_for_function("() => window.petrobot && window.petrobot.mode === 'live'", timeout=TIMEOUT_S * 1000)
        cdp = context.new_cdp_session(page)
        cdp.send("Performance.enable")
        memory = [{"t_s": 0.0, **js_heap(page, cdp)}]
        page.evaluate("() => window.petrobotStats.reset()")
        child.stdin.write("go\n")
        child.stdin.flush()
        t0 = time.monotonic()
        next_sample = args.sample
        phases: list[dict[str, Any]] = []
        import selectors

        sel = selectors.DefaultSelector()
        sel.register(child.stdout, selectors.EVENT_READ)
        while True:
            if sel.select(timeout=1.0):
                line = child.stdout.readline()
                if not line:
                    break
                msg = json.loads(line)
                if "phases" in msg:
                    phases = msg["phases"]
                    break
            if time.monotonic() - t0 >= next_sample:
                memory.append({"t_s": round(time.monotonic() - t0, 1), **js_heap(page, cdp)})
                next_sample += args.sample
        memory.append({"t_s": round(time.monotonic() - t0, 1), **js_heap(page, cdp)})
        latencies = sorted(page.evaluate("() => window.petrobotStats.latencies()"))
        frames = page.evaluate("() => window.petrobotStats.frames")
        paints = page.evaluate("() => window.petrobotStats.paints")
        context.close()
        child.wait(timeout=TIMEOUT_S)

    def rate(attached: bool) -> float:
        chosen = [p for p in phases if p["attached"] is attached]
        return sum(p["firings"] for p in chosen) / max(1e-9, sum(p["seconds"] for p in chosen))

    def pct(q: float) -> float | None:
        return round(latencies[min(len(latencies) - 1, int(q * len(latencies)))], 4) if latencies else None

    pairs = [(a, b) for a, b in itertools.pairwise(phases) if not a["attached"] and b["attached"]]
    pair_ratios = sorted((b["firings"] / b["seconds"]) / max(1e-9, a["firings"] / a["seconds"]) for a, b in pairs)
    heap = [m["heap_mb"] for m in memory]
    return {"latency_p50_s": pct(0.50), "latency_p99_s": pct(0.99), "latency_max_s": pct(1.0),
            "repaints_measured": len(latencies), "frames_received": frames, "repaints": paints,
            "firings_per_s_detached": round(rate(False)), "firings_per_s_attached": round(rate(True)),
            "throughput_ratio": round(rate(True) / max(1e-9, rate(False)), 3), "phases": len(phases),
            "throughput_ratio_median_pair": round(statistics.median(pair_ratios), 3) if pair_ratios else None,
            "run_minutes": args.minutes, "memory": memory, "heap_first_mb": heap[0], "heap_last_mb": heap[-1],
            "heap_max_mb": max(heap), "page_errors": errors}


def measure_open(browser: Any, pairs: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        net = Path(tmp) / "big.toml"
        net.write_text(big_toml(pairs), encoding="utf-8")
        proc = subprocess.Popen([sys.executable, "-m", "coordinator.cli", "console", str(net), "--listen", "0",
                                 "--root", tmp], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert proc.stdout is not None
        try:
            url = ""
            for line in proc.stdout:
                if line.startswith("petrobot console: http://"):
                    url = line.split()[-1]
                    break
            context = browser.new_context(viewport={"width": 1400, "height": 900})
            page = context.new_page()
            # warm the browser's cache of the page's scripts as a returning operator would have it
            page.goto(url.split("?")[0] + "?token=none")
            page.wait_for_function("() => document.body.dataset.ready === '1'", timeout=TIMEOUT_S * 1000)
            t0 = time.perf_counter()
            page.goto(url)
            page.wait_for_function("(arg) => document.body.dataset.ready === '1' && "
                                   "window.petrobot.graph.cy.nodes().length >= 2 * arg", arg=pairs, timeout=TIMEOUT_S * 1000)
            ready = time.perf_counter() - t0
            nodes = page.evaluate("() => window.petrobot.graph.cy.nodes().length")
            box = page.locator("#cy").bounding_box()
            pos = page.evaluate("() => window.petrobot.graph.cy.getElementById('t3_7').renderedPosition()")
            page.mouse.click(box["x"] + pos["x"], box["y"] + pos["y"])
            page.wait_for_function("() => document.getElementById('panel-inspect').textContent.includes('t3_7')",
                                   timeout=TIMEOUT_S * 1000)
            clicked = time.perf_counter() - t0
            context.close()
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    return {"open_1000_nodes_s": round(ready, 3), "open_then_click_s": round(clicked, 3), "open_nodes": nodes}


class BusyLoad:
    """``n`` busy processes (a Python loop each, bounded by ``seconds``), started and stopped around a
    measurement: the CPU load of issue 23's target (two busy processes on two cores)."""

    def __init__(self, n: int, seconds: float) -> None:
        self.procs = [subprocess.Popen([sys.executable, "-c", f"import time\nend = time.monotonic() + {seconds}\n"
                                        "while time.monotonic() < end:\n    pass"]) for _ in range(n)]

    def __enter__(self) -> BusyLoad:
        return self

    def __exit__(self, *exc: object) -> None:
        for proc in self.procs:
            proc.terminate()
        for proc in self.procs:
            proc.wait(timeout=30)


# ---------------------------------------------------------------------- read-only pages (--viewers)
def viewer_draft(places: int) -> str:
    """A drawing of ``places`` places and as many transitions in one ring, as JSON text."""
    return json.dumps({"net": {"name": f"big{places}"},
                       "places": [{"id": f"p{i}", "tokens": int(i == 0), "pos": [i * 10.0, 0.0]} for i in range(places)],
                       "transitions": [{"id": f"t{i}", "pos": [i * 10.0 + 5, 40.0]} for i in range(places)],
                       "arcs": [a for i in range(places) for a in ({"from": f"p{i}", "to": f"t{i}"},
                                                                    {"from": f"t{i}", "to": f"p{(i + 1) % places}"})]})


async def viewer_clients(url: str, kind: str) -> None:
    """The read-only pages of ``--viewers``, on while stdin says ``on``; counts on stdout at ``end``."""
    import aiohttp

    base = url.split("/?")[0]
    ws_url = base.replace("http", "ws") + "/ws"
    large, medium = viewer_draft(20_000), viewer_draft(2_500)
    counts: dict[str, int] = {}
    on = asyncio.Event()

    def count(what: str) -> None:
        counts[what] = counts.get(what, 0) + 1

    async def validator(http: aiohttp.ClientSession, i: int) -> None:
        n = 0
        while True:
            await on.wait()
            try:
                async with http.ws_connect(ws_url, max_msg_size=0) as ws:
                    await ws.send_str(json.dumps({"type": "hello", "v": 1}))
                    while on.is_set():
                        n += 1
                        draft = large if n % 3 == 0 else medium
                        await ws.send_str('{"type":"validate","id":%d,"draft":%s}' % (n, draft))
                        while True:
                            msg = await ws.receive()
                            if msg.type != aiohttp.WSMsgType.TEXT:
                                count(f"closed {ws.close_code}")
                                raise ConnectionError
                            data = json.loads(msg.data)
                            if data.get("type") == "reply" and data.get("id") == n:
                                count("checked" if data.get("ok") else "refused")
                                break
                        if n % 5 == 0:
                            async with http.post(base + "/api/export?format=dot", data=large) as res:
                                count(f"export {res.status}")
            except (ConnectionError, aiohttp.ClientError):
                await asyncio.sleep(0.05)

    async def viewer(http: aiohttp.ClientSession) -> None:
        while True:
            await on.wait()
            try:
                async with http.ws_connect(ws_url, max_msg_size=0) as ws:
                    await ws.send_str(json.dumps({"type": "hello", "v": 1}))
                    first = True
                    while on.is_set():
                        msg = await ws.receive()
                        if msg.type != aiohttp.WSMsgType.TEXT:
                            count(f"closed {ws.close_code}")
                            while on.is_set():  # refused: wait for the next phase with viewers
                                await asyncio.sleep(0.2)
                            break
                        if first:
                            count("viewing")
                            first = False
            except (ConnectionError, aiohttp.ClientError):
                await asyncio.sleep(0.2)

    loop = asyncio.get_running_loop()
    async with aiohttp.ClientSession() as http:
        tasks = [loop.create_task(validator(http, i)) for i in range(4)] if kind == "validators" else \
            [loop.create_task(viewer(http)) for _ in range(200)]
        while True:
            line = (await loop.run_in_executor(None, sys.stdin.readline)).strip()
            if line == "on":
                on.set()
            elif line == "off":
                on.clear()
            else:
                break
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    print(json.dumps(counts), flush=True)


def rss_mib(pid: int) -> float:
    """The resident memory of process ``pid``, MiB (0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def measure_viewers(args: argparse.Namespace, kind: str) -> dict[str, Any]:
    """One ``--viewers`` measurement: the run's rate with ``kind`` pages on in every other phase."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        child = subprocess.Popen([sys.executable, __file__, "--serve", tmp, "--minutes", str(args.viewer_minutes),
                                  "--phase", str(args.phase), "--null", "--period", str(args.period),
                                  "--rings", str(args.rings), "--length", str(args.length)],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        assert child.stdin is not None and child.stdout is not None
        url = json.loads(child.stdout.readline())["url"]
        clients = subprocess.Popen([sys.executable, __file__, "--clients", kind, "--url", url],
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                                   preexec_fn=lambda: os.nice(19))  # noqa: PLW1509 - no threads yet
        assert clients.stdin is not None and clients.stdout is not None
        child.stdin.write("go\n")
        child.stdin.flush()
        with_them = False
        phases: list[dict[str, Any]] = []
        rss: list[float] = []
        for line in child.stdout:
            msg = json.loads(line)
            if "phases" in msg:
                break
            rss.append(rss_mib(child.pid))
            phases.append({**msg["phase"], "with": with_them})
            with_them = not with_them  # the next phase has them or not
            clients.stdin.write("on\n" if with_them else "off\n")
            clients.stdin.flush()
        clients.stdin.write("end\n")
        clients.stdin.flush()
        answered = json.loads(clients.stdout.readline() or "{}")
        clients.wait(timeout=TIMEOUT_S)
        child.wait(timeout=TIMEOUT_S)
    phases = phases[1:]  # the first phase warms up

    def rate(flag: bool) -> float:
        chosen = [p for p in phases if p["with"] is flag]
        return sum(p["firings"] for p in chosen) / max(1e-9, sum(p["seconds"] for p in chosen))

    pairs = [(a, b) for a, b in itertools.pairwise(phases) if not a["with"] and b["with"]]
    ratios = sorted((b["firings"] / b["seconds"]) / max(1e-9, a["firings"] / a["seconds"]) for a, b in pairs)
    return {f"{kind}_firings_per_s_without": round(rate(False)), f"{kind}_firings_per_s_with": round(rate(True)),
            f"{kind}_ratio": round(rate(True) / max(1e-9, rate(False)), 3),
            f"{kind}_ratio_median_pair": round(statistics.median(ratios), 3) if ratios else None,
            f"{kind}_phases": len(phases), f"{kind}_answered": answered,
            f"{kind}_console_rss_mib_first_max": [round(rss[0], 1), round(max(rss), 1)] if rss else None}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the attached run, minutes")
    ap.add_argument("--phase", type=float, default=1.0, help="length of one attached or detached phase, seconds")
    ap.add_argument("--sample", type=float, default=30.0, help="seconds between two samples of the page's memory")
    ap.add_argument("--rings", type=int, default=4, help="rings of the run's net")
    ap.add_argument("--length", type=int, default=10, help="transitions per ring")
    ap.add_argument("--open-pairs", type=int, default=500, help="places (and transitions) of the net opened")
    ap.add_argument("--period", type=float, default=0.01, help="shortest time between two live frames, seconds (the console's default)")
    ap.add_argument("--null", action="store_true",
                    help="never detach the console (the ratio then shows the noise floor of the machine)")
    ap.add_argument("--skip-run", action="store_true", help="only measure opening the large net")
    ap.add_argument("--skip-open", action="store_true", help="do not measure opening the large net")
    ap.add_argument("--feed-pairs", type=int, default=8,
                    help="detached/attached phase pairs of the browser-less feed cost measurement (0: skip it)")
    ap.add_argument("--feed-only", action="store_true", help="only measure the feed's cost, no browser")
    ap.add_argument("--fixed-period", action="store_true",
                    help="frames every --period even when the machine has no idle core (the console spaces them "
                         "then, up to 0.2 s: the pipeline's own latency on a loaded machine)")
    ap.add_argument("--load", type=int, default=0, metavar="N",
                    help="run N busy processes beside the run and the browser, and measure the noise floor (--null) "
                         "under the same load in the same invocation (default: 0, no load)")
    ap.add_argument("--viewers", action="store_true",
                    help="only measure the run's rate with read-only pages asking for work and with 200 idle "
                         "viewers (no browser)")
    ap.add_argument("--viewer-minutes", type=float, default=1.0,
                    help="--viewers: minutes of each of its two measurements (default 1)")
    ap.add_argument("--json", action="store_true", help="print the results as one JSON object")
    ap.add_argument("--serve", metavar="DIR", help=argparse.SUPPRESS)
    ap.add_argument("--clients", choices=("validators", "viewers"), help=argparse.SUPPRESS)
    ap.add_argument("--url", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.serve:
        asyncio.run(serve(args))
        return 0
    if args.clients:
        asyncio.run(viewer_clients(args.url, args.clients))
        return 0
    if args.viewers:
        out: dict[str, Any] = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                               "load_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count()}
        for kind in ("validators", "viewers"):
            out.update(measure_viewers(args, kind))
        out["load_1min_after"] = round(os.getloadavg()[0], 2)
        print(json.dumps(out, indent=1) if args.json else "\n".join(f"{k:36} {v}" for k, v in out.items()))
        return 0
    result: dict[str, Any] = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                              "load_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count()}
    if args.feed_pairs > 0:
        result.update(asyncio.run(feed_cost(args)))
    if args.feed_only:
        result["load_1min_after"] = round(os.getloadavg()[0], 2)
        print(json.dumps(result, indent=1) if args.json else result)
        return 0
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium(), headless=True, args=CHROMIUM_ARGS)
        try:
            if not args.skip_open:
                result.update(measure_open(browser, args.open_pairs))
            if not args.skip_run and args.load > 0:
                # the run under load, then the noise floor under the same load: the console never detached
                budget = 2 * args.minutes * 60 + 4 * TIMEOUT_S
                with BusyLoad(args.load, budget):
                    result["busy_processes"] = args.load
                    result.update(measure_run(browser, args))
                    floor = measure_run(browser, argparse.Namespace(**{**vars(args), "null": True}))
                result["noise_floor_ratio"] = floor["throughput_ratio"]
                result["noise_floor_ratio_median_pair"] = floor["throughput_ratio_median_pair"]
                result["noise_floor_firings_per_s"] = floor["firings_per_s_attached"]
            elif not args.skip_run:
                result.update(measure_run(browser, args))
        finally:
            browser.close()
    result["load_1min_after"] = round(os.getloadavg()[0], 2)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key, value in result.items():
            if key != "memory":
                print(f"{key:26} {value}")
        for m in result.get("memory", []):
            print(f"  memory at {m['t_s']:7.1f} s: heap {m['heap_mb']:7.2f} MB, {m['dom_nodes']} DOM nodes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
