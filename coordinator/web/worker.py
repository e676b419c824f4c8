"""Heavy console work in a process of its own, with a budget: validating and exporting drawings.

The web console serves the run it follows on the run's own event loop (docs/console.md). Checking
or converting a large drawing — 20,000 places, megabytes of JSON — or reading a long run's replay
from the journal takes the CPU for a while, and a thread of the same process would hold the
interpreter's lock as long: four read-only pages asking for it took a run from 2,000 firings a
second to 4 (issue 22). :class:`Worker` runs that work in one child process (``python -m
coordinator.web.worker``), started on first use and kept:

* one job at a time, in the order asked; :class:`~coordinator.web.limits.ConsoleGuard` bounds who
  may queue how much;
* the child runs at a lower CPU priority than the console (``nice`` +10: on a loaded machine the run
  goes first), with its address space capped (:data:`MEMORY_BYTES`) and each job given
  :data:`JOB_TIMEOUT_S`: a job over time is killed with its process, which is started again for the
  next job; a job over memory fails with ``MemoryError`` in the child, which goes on;
* requests and answers are JSON lines on the child's stdin and stdout, the drawing sent as the
  text the page sent (no object is built on the event loop for it).

``python -m coordinator.web.worker`` is the child's side (:func:`serve`): it reads one request per
line (``{"id", "kind": "validate" | "export", "message": TEXT, "name", "services", "format",
"hidden"}``), checks the message as the server does (:func:`coordinator.web.protocol.parse_client_message`),
does the work and writes ``{"id", "ok": true, "result": ...}`` or ``{"id", "ok": false, "error": TEXT}``
(with ``"violation": CODE`` when the message breaks the protocol, ``"journal": true`` when the
journal is missing or damaged). A ``validate`` job's result is ``{"id": the message's id,
"validation": ...}``: the server need not parse a read-only page's large message at all to answer
it. A ``replay`` job (``{"id", "kind": "replay", "journal", "run", "fallback", "preloaded",
"shown"}``, :func:`replay_text`) answers ``{"id", "ok": true, "raw": N}`` followed by the N bytes
of the HTTP response's JSON body, which the server sends on as they are (nothing of it is parsed
or built on the run's loop).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import os
import resource
import sys
from pathlib import Path
from typing import Any, Final

__all__ = ["JOB_TIMEOUT_S", "MEMORY_BYTES", "NICE", "Worker", "WorkFailed", "replay_text", "serve"]

JOB_TIMEOUT_S: Final = 20.0
"""Longest one job may take, seconds (validating a 20,000-place drawing takes about 2 s)."""
MEMORY_BYTES: Final = 2 * 1024**3
"""The child's address-space cap (``RLIMIT_AS``), bytes."""
NICE: Final = 10
"""How much lower the child's CPU priority is than the console's."""
_LINE_LIMIT: Final = 64 * 1024 * 1024


class WorkFailed(Exception):
    """A job could not be done: the drawing is refused, the child ran out of time or memory, or died.

    Attributes:
        violation: the WebSocket close code when the message itself breaks the console's protocol
            (:class:`~coordinator.web.protocol.ProtocolViolation`), else ``None``.
    """

    def __init__(self, reason: str, violation: int | None = None, journal: bool = False) -> None:
        super().__init__(reason)
        self.violation = violation
        self.journal = journal
        """Whether the journal asked for is missing or damaged (:class:`~coordinator.errors.JournalError`)."""


class Worker:
    """The console's worker process (see the module docstring).

    Args:
        timeout_s: the time one job is given, seconds.
    """

    def __init__(self, timeout_s: float = JOB_TIMEOUT_S) -> None:
        self.timeout_s = timeout_s
        self._proc: asyncio.subprocess.Process | None = None
        self._lock = asyncio.Lock()
        self._ids = itertools.count(1)
        self.jobs = 0
        """Jobs done so far."""
        self.restarts = 0
        """Times the child was killed (a job over time) or found dead."""

    async def _child(self) -> asyncio.subprocess.Process:
        proc = self._proc
        if proc is not None and proc.returncode is None:
            return proc
        if proc is not None:  # it died by itself
            self.restarts += 1
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
                   PYTHONPATH=root + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else ""))
        self._proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "coordinator.web.worker", stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL, env=env, limit=_LINE_LIMIT)
        return self._proc

    async def run(self, kind: str, message: str, **fields: Any) -> Any:
        """Do one job: ``validate`` (the drawing of ``message``, a ``validate`` message's text; fields
        ``name``, ``services``: the services.toml path or ``None``) or ``export`` (``message`` a
        ``validate`` message holding the drawing; fields ``format``, ``hidden``).

        Returns:
            ``validate``: ``{"id": the message's id, "validation": the validation's JSON}``;
            ``export``: ``[text, media type]``; ``replay`` (``message`` empty; fields of
            :func:`replay_text`): the response body, bytes of JSON.

        Raises:
            WorkFailed: with the reason, in words.
        """
        async with self._lock:
            proc = await self._child()
            assert proc.stdin is not None and proc.stdout is not None
            jid = next(self._ids)
            line = json.dumps({"id": jid, "kind": kind, "message": message, **fields}, separators=(",", ":"))
            try:
                proc.stdin.write(line.encode("utf-8") + b"\n")
                async with asyncio.timeout(self.timeout_s):
                    await proc.stdin.drain()
                    answer = await proc.stdout.readline()
            except TimeoutError:
                self._kill()
                raise WorkFailed(f"took more than {self.timeout_s:g} s: stopped") from None
            except (ConnectionError, ValueError, asyncio.LimitOverrunError) as exc:
                self._kill()
                raise WorkFailed(f"the worker process failed: {exc}") from None
            if not answer:
                self._kill()
                raise WorkFailed("the worker process died (out of memory?)")
            got = json.loads(answer)
            if got.get("ok") and "raw" in got:
                try:
                    async with asyncio.timeout(self.timeout_s):
                        raw = await proc.stdout.readexactly(int(got["raw"]))
                except (TimeoutError, asyncio.IncompleteReadError):
                    self._kill()
                    raise WorkFailed("the worker process stopped in the middle of its answer") from None
                self.jobs += 1
                return raw
            self.jobs += 1
        if not got.get("ok"):
            raise WorkFailed(str(got.get("error")), got.get("violation"), bool(got.get("journal")))
        return got["result"]

    def _kill(self) -> None:
        """Kill the child (a job over time, a broken pipe): the next job starts a new one."""
        proc, self._proc = self._proc, None
        if proc is not None:
            self.restarts += 1
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()

    async def close(self) -> None:
        """Stop the child (it is started again if a job comes)."""
        proc, self._proc = self._proc, None
        if proc is not None and proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()


# ---------------------------------------------------------------------------------- the child's side
def replay_text(journal: str, run: str, fallback: dict[str, Any] | None, preloaded: list[list[str]],
                shown: dict[str, Any] | None) -> bytes:
    """The console's ``/api/replay`` answer for ``run`` of ``journal`` (``"last"``: its latest run),
    as the bytes of its JSON body (:func:`coordinator.web.replay.replay_json`).

    Args:
        journal: the journal's path.
        run: a run id, or ``"last"``.
        fallback: the draft to show when the run did not store its net's text, or ``None``: then the
            first of ``preloaded`` (``[shown name, path]`` pairs) that is the run's net.
        shown: the draft the console shows now; the replay uses it (and its layout) when it is of
            the same net, else the replay's own draft is laid out.

    Raises:
        JournalError: the journal or the run is missing or damaged.
    """
    from coordinator.errors import JournalError
    from coordinator.journal import JournalReader
    from coordinator.web.files import open_net, with_layout
    from coordinator.web.replay import replay_json

    with JournalReader.open(Path(journal)) as reader:
        found = run
        if run == "last":
            runs = reader.runs()
            if not runs:
                raise JournalError(f"{journal}: no runs")
            found = runs[-1].id
        opened = fallback
        if opened is None:
            row = reader.run(found)
            for name, path in preloaded:
                with contextlib.suppress(Exception):
                    candidate = open_net(Path(path), None, shown_as=name)
                    if candidate["draft"].get("net", {}).get("name", Path(path).stem) == row.net_name:
                        opened = candidate["draft"]
                        break
        data = replay_json(reader, found, fallback=opened)
    if data["draft"] is not None:
        if shown is not None and data["draft"].get("net", {}).get("name") == shown.get("net", {}).get("name"):
            data["draft"] = shown
        else:
            data["draft"] = with_layout(data["draft"])
    return json.dumps(data, separators=(",", ":"), default=str).encode("utf-8")


def _job(request: dict[str, Any], locations: dict[str, Any]) -> Any:
    from coordinator.web.draft import UNSAVED, validate_draft
    from coordinator.web.files import export_draft
    from coordinator.web.protocol import ProtocolViolation, parse_client_message

    if request["kind"] == "replay":
        return replay_text(str(request["journal"]), str(request["run"]), request.get("fallback"),
                           list(request.get("preloaded") or []), request.get("shown"))
    msg = parse_client_message(request["message"])
    if msg.type != "validate":
        raise ProtocolViolation(f"a {msg.type} message larger than the console takes on its event loop")
    draft = msg.fields["draft"]
    if request["kind"] == "validate":
        services = request.get("services")
        location = None
        if services:
            location = locations.get(services)
            if location is None:
                from services.location import load_location

                location = locations[services] = load_location(services)
        name = request.get("name") or msg.fields.get("name") or UNSAVED
        return {"id": msg.id, "validation": validate_draft(draft, name, location).to_json()}
    if request["kind"] == "export":
        text, media = export_draft(draft, str(request.get("format", "toml")), hidden=bool(request.get("hidden", True)))
        return [text, media]
    raise ValueError(f"no such job: {request['kind']!r}")


def serve() -> int:
    """The child: limits itself, then answers one job per line of stdin until it closes."""
    from coordinator.errors import JournalError
    from coordinator.web.protocol import ProtocolViolation

    with contextlib.suppress(OSError):
        os.nice(NICE)
    with contextlib.suppress(ValueError, OSError):
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES if hard == resource.RLIM_INFINITY
                                                else min(MEMORY_BYTES, hard), hard))
    locations: dict[str, Any] = {}
    for line in sys.stdin:
        jid = None
        raw = b""
        try:
            request = json.loads(line)
            jid = request.get("id")
            result = _job(request, locations)
            if isinstance(result, bytes):
                out, raw = {"id": jid, "ok": True, "raw": len(result)}, result
            else:
                out = {"id": jid, "ok": True, "result": result}
        except JournalError as exc:
            out = {"id": jid, "ok": False, "error": str(exc), "journal": True}
        except ProtocolViolation as exc:
            out = {"id": jid, "ok": False, "error": exc.reason, "violation": exc.code}
        except MemoryError:
            out = {"id": jid, "ok": False, "error": f"the drawing needs more than {MEMORY_BYTES >> 20} MiB"}
        except Exception as exc:  # noqa: BLE001 - every failure is the answer to its job
            out = {"id": jid, "ok": False, "error": getattr(exc, "reason", None) or f"{type(exc).__name__}: {exc}"}
        sys.stdout.write(json.dumps(out, separators=(",", ":"), default=str) + "\n")
        if raw:
            sys.stdout.flush()
            sys.stdout.buffer.write(raw)
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(serve())
