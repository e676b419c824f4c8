"""The nodes of a location file as processes on this machine, started and stopped together.

Each node runs as ``python -m services.node NAME`` in its own process (its own session, so that a
Ctrl-C reaches the command only). Its output goes to ``LOG_DIR/NAME.log`` when a log directory is
given (``petrobot up`` and ``petrobot demo`` put it beside the journal, ``runs/logs``), else it is
printed prefixed with the node name. :class:`NodeGroup` waits until every node reports it is
listening, reports a node that exits, and stops them all with SIGTERM (SIGKILL after a grace
period). ``petrobot up`` and ``petrobot demo`` use it for a one-machine setup (paper section 5).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
from collections import deque
from pathlib import Path
from types import TracebackType
from typing import Self, TextIO

from services.errors import PetrobotError
from services.keys import load_key
from services.location import load_location

__all__ = ["NodeGroup"]

_POLL_S = 0.05
"""How often a node's log file is read for its "listening" line, s."""


def _read_from(path: Path, pos: int) -> bytes:
    """The bytes of ``path`` from offset ``pos`` on (empty if it cannot be read)."""
    try:
        with path.open("rb") as fh:
            fh.seek(pos)
            return fh.read()
    except OSError:
        return b""


class NodeGroup:
    """Node subprocesses on this machine, started and stopped together.

    Args:
        services: path of services.toml.
        names: nodes to start (default: every node of the file).
        key_file: shared key file passed to each node (default: the nodes' own default).
        log_level: the nodes' log level.
        log_dir: directory of the nodes' log files ``NAME.log`` (rewritten at each start); ``None``
            prints their lines prefixed with the node name on ``out`` instead.
        out: where prefixed log lines go without ``log_dir`` (default: stderr).

    Raises (from :meth:`start`):
        LocationError: services.toml is bad or names an unknown node.
        PetrobotError: a node exited or did not listen within ``timeout_s`` (unless tolerated).
    """

    def __init__(self, services: str | os.PathLike[str], names: list[str] | None = None, *,
                 key_file: str | None = None, log_level: str = "INFO", log_dir: str | os.PathLike[str] | None = None,
                 out: TextIO | None = None) -> None:
        self.services = Path(services)
        self.location = load_location(self.services)
        self.names = list(names) if names else list(self.location.nodes)
        for name in self.names:
            self.location.address(name)
        self.key_file = key_file
        self.log_level = log_level
        self.log_dir = Path(log_dir) if log_dir is not None else None
        self.out = out if out is not None else sys.stderr
        self.procs: dict[str, asyncio.subprocess.Process] = {}
        self._pumps: list[asyncio.Task[None]] = []
        self._ready: dict[str, asyncio.Event] = {}
        self._tails: dict[str, deque[str]] = {}

    async def __aenter__(self) -> Self:
        try:
            await self.start()
        except BaseException:
            await self.stop()  # no node is left behind when one of them fails to start
            raise
        return self

    async def __aexit__(self, et: type[BaseException] | None, ev: BaseException | None,
                        tb: TracebackType | None) -> None:
        await self.stop()

    def log_path(self, name: str) -> Path | None:
        """The log file of node ``name`` (``None`` without a log directory)."""
        return self.log_dir / f"{name}.log" if self.log_dir is not None else None

    async def start(self, timeout_s: float = 20.0, *, tolerate: bool = False) -> list[str]:
        """Start the nodes and wait until each reports it is listening.

        Args:
            timeout_s: how long to wait for every node's "listening" line, s.
            tolerate: a node that exits or does not listen in time is left out (returned) instead
                of raising; the others run on.

        Returns:
            The nodes that did not come up (empty unless ``tolerate``).

        Raises:
            PetrobotError: (without ``tolerate``) a node exited first or did not listen in time.
        """
        load_key(self.key_file)  # create the key file once, before the nodes race for it
        width = max(len(n) for n in self.names)
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
        for name in self.names:
            cmd = [sys.executable, "-m", "services.node", name, "--services", str(self.services),
                   "--log-level", self.log_level]
            if self.key_file:
                cmd += ["--key-file", self.key_file]
            self._ready[name] = asyncio.Event()
            self._tails[name] = deque(maxlen=20)
            path = self.log_path(name)
            loop = asyncio.get_running_loop()
            if path is not None:
                fh = await asyncio.to_thread(path.open, "wb")
                try:
                    proc = await asyncio.create_subprocess_exec(
                        *cmd, stdout=fh, stderr=asyncio.subprocess.STDOUT, start_new_session=True)
                finally:
                    fh.close()  # the node has its own copy of the descriptor
                self._pumps.append(loop.create_task(self._follow(name, path, proc)))
            else:
                proc = await asyncio.create_subprocess_exec(
                    *cmd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
                    start_new_session=True)
                self._pumps.append(loop.create_task(self._pump(name, width, proc)))
            self.procs[name] = proc
        results = await asyncio.gather(*(self._wait_listening(n, timeout_s) for n in self.names),
                                       return_exceptions=True)
        failed = [(n, r) for n, r in zip(self.names, results) if isinstance(r, BaseException)]
        if failed and not tolerate:
            raise failed[0][1] if isinstance(failed[0][1], PetrobotError) else PetrobotError(str(failed[0][1]))
        for name, _ in failed:
            proc = self.procs[name]
            if proc.returncode is None:
                await self._terminate(proc)
        return [n for n, _ in failed]

    def tail(self, name: str, n: int = 3) -> list[str]:
        """The last ``n`` lines node ``name`` wrote (for saying why it exited)."""
        return list(self._tails.get(name, ()))[-n:]

    async def _pump(self, name: str, width: int, proc: asyncio.subprocess.Process) -> None:
        assert proc.stdout is not None
        ready = f"node {name} listening on "
        while line := await proc.stdout.readline():
            text = line.decode(errors="replace").rstrip()
            self._tails[name].append(text)
            if text.startswith(ready):
                self._ready[name].set()
            print(f"[{name.ljust(width)}] {text}", file=self.out, flush=True)

    async def _follow(self, name: str, path: Path, proc: asyncio.subprocess.Process) -> None:
        """Read node ``name``'s log file as it grows: its "listening" line and its last lines."""
        ready = f"node {name} listening on "
        pos = 0
        partial = b""
        while True:
            exited = proc.returncode is not None
            chunk = await asyncio.to_thread(_read_from, path, pos)
            pos += len(chunk)
            lines = (partial + chunk).split(b"\n")
            partial = lines.pop()
            for raw in lines:
                text = raw.decode(errors="replace").rstrip()
                self._tails[name].append(text)
                if text.startswith(ready):
                    self._ready[name].set()
            if exited:
                if partial:
                    self._tails[name].append(partial.decode(errors="replace").rstrip())
                return
            await asyncio.sleep(_POLL_S)

    async def _wait_listening(self, name: str, timeout_s: float) -> None:
        # the node's own "listening" line, not a connect test: another process may hold the port
        proc = self.procs[name]
        loop = asyncio.get_running_loop()
        ready = loop.create_task(self._ready[name].wait())
        exited = loop.create_task(proc.wait())
        try:
            await asyncio.wait({ready, exited}, timeout=timeout_s, return_when=asyncio.FIRST_COMPLETED)
        finally:
            ready.cancel()
            exited.cancel()
        if self._ready[name].is_set():
            return
        if proc.returncode is not None:
            await asyncio.sleep(2 * _POLL_S)  # let the follower read the last lines
            last = "; ".join(line for line in self.tail(name) if line) or "no output"
            raise PetrobotError(f"node {name} exited with status {proc.returncode} before listening: {last}"
                                + self._log_said(name))
        raise PetrobotError(f"node {name} not listening after {timeout_s:g} s" + self._log_said(name))

    def _log_said(self, name: str) -> str:
        path = self.log_path(name)
        return f" (log {path})" if path is not None else ""

    def running(self) -> list[str]:
        """The nodes whose process has not exited."""
        return [n for n, p in self.procs.items() if p.returncode is None]

    async def wait_any_exit(self, names: list[str] | None = None) -> str:
        """Wait until one of ``names`` (default: every running node) exits; return its name."""
        watch = names if names is not None else self.running()
        if not watch:
            raise PetrobotError("no node is running")
        loop = asyncio.get_running_loop()
        waits = {loop.create_task(self.procs[n].wait()): n for n in watch}
        try:
            done, _ = await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
            return waits[next(iter(done))]
        finally:
            for t in waits:
                t.cancel()

    async def _terminate(self, proc: asyncio.subprocess.Process, grace_s: float = 5.0) -> None:
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
        try:
            await asyncio.wait_for(proc.wait(), grace_s)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()

    async def stop(self, grace_s: float = 5.0) -> None:
        """SIGTERM every node, SIGKILL those still running after ``grace_s``."""
        for proc in self.procs.values():
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        for proc in self.procs.values():
            await self._terminate(proc, grace_s)
        for t in self._pumps:
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                await asyncio.wait_for(t, 1.0)
