"""The analyses of the open net, for the console's side panel: the command line's own reports.

``petrobot analyze`` (the ordinary-net view: boundedness, liveness, reversibility, invariants),
``gspn`` (the quantitative view: with the console's journal, the mean times and reliabilities measured
there, as ``petrobot gspn --journal`` takes them), ``perf`` (J = 1 − R + ρC from the journal) and
``learn`` (the learning automata, with their plot) run as child processes of the same Python on a temporary copy
of the drawn net, so the page shows exactly what the terminal would, an analysis that takes long or
much memory never holds up a live run on the console's event loop, and one that goes wrong ends in
its own process. :func:`run_analysis` returns the report's text, the exit status and the plot; with
``as_json`` the command's own ``--json`` document too (``data``), from which the page draws the
analyses on the net (the same JSON the command line gives: the page reads it, never reshapes it).
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from coordinator.netfile import dump_net
from coordinator.web.draft import draft_layout, validate_draft

__all__ = ["ANALYSES", "READS_JOURNAL", "run_analysis"]

#: The analyses, and whether each needs a journal.
ANALYSES = {"analyze": False, "gspn": False, "perf": True, "learn": True}
#: The analyses that read the console's journal when it has one (``gspn`` without one takes the net
#: file's mean times and reliabilities).
READS_JOURNAL = frozenset({"gspn", "perf", "learn"})
#: Longest an analysis may run, seconds.
TIMEOUT_S = 300.0
#: Most bytes of a report kept.
MAX_OUTPUT = 1 << 20
#: Largest ``--json`` document read back, bytes (a state space's examples stay far below).
MAX_JSON = 32 << 20


async def run_analysis(kind: str, draft: dict[str, Any], *, journal: str | None = None, run: str | None = None,
                       cwd: Path | None = None, timeout_s: float = TIMEOUT_S, as_json: bool = False) -> dict[str, Any]:
    """Run ``petrobot KIND`` on a draft and return its report.

    Args:
        kind: ``analyze``, ``gspn``, ``perf`` or ``learn``.
        draft: the drawn net (it must load).
        journal: the journal ``gspn``, ``perf`` and ``learn`` read (the one the page has open).
        run: restrict ``gspn``/``perf``/``learn`` to one run.
        cwd: folder the command runs in.
        timeout_s: the command is killed after this many seconds.
        as_json: run the command with ``--json`` and parse its document into ``data``.

    Returns:
        ``{"kind", "command", "exit", "stdout", "stderr", "plot", "data"}``: ``plot`` is a PNG as
        base64 (``learn``), else ``None``; ``exit`` is ``None`` when the command was killed;
        ``data`` is the ``--json`` document (``None`` without ``as_json`` or when the command
        printed none).
    """
    validation = validate_draft(draft, "drawing.toml")
    if validation.net is None:
        return {"kind": kind, "command": f"petrobot {kind}", "exit": 2, "stdout": "", "plot": None, "data": None,
                "stderr": "the drawing has problems; fix them first:\n" + "\n".join(
                    p["text"] for p in validation.to_json()["problems"])}
    if ANALYSES.get(kind) and not journal:
        return {"kind": kind, "command": f"petrobot {kind}", "exit": 2, "stdout": "", "plot": None, "data": None,
                "stderr": f"petrobot {kind} reads a journal: start the console with --journal FILE"}
    with tempfile.TemporaryDirectory(prefix="petrobot-console-") as tmp:
        net_file = Path(tmp) / f"{validation.net.name or 'net'}.toml"
        net_file.write_text(dump_net(validation.net, draft_layout(draft)), encoding="utf-8")
        args = [kind, str(net_file)]
        plot = Path(tmp) / "plot.png"
        if kind in READS_JOURNAL and journal:
            args += ["--journal", str(journal)]
            if run:
                args += ["--run", run]
        if kind == "learn":
            args += ["--plot", str(plot)]
        if as_json:
            args.append("--json")
        shown = "petrobot " + " ".join(a if a != str(net_file) else net_file.name for a in args)
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "coordinator.cli", *args, cwd=str(cwd) if cwd else None, env=env,
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
        try:
            out, err = await asyncio.wait_for(proc.communicate(), timeout_s)
            code: int | None = proc.returncode
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
            out, err, code = b"", f"killed after {timeout_s:g} s".encode(), None
        except asyncio.CancelledError:  # the page went away: the analysis goes with it
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            raise
        image = base64.b64encode(plot.read_bytes()).decode("ascii") if plot.exists() else None
    data = None
    if as_json and out and len(out) <= MAX_JSON:
        with contextlib.suppress(ValueError):
            data = json.loads(out)
    return {"kind": kind, "command": shown, "exit": code, "plot": image, "data": data,
            "stdout": "" if data is not None else out[:MAX_OUTPUT].decode("utf-8", "replace"),
            "stderr": err[:MAX_OUTPUT].decode("utf-8", "replace")}
