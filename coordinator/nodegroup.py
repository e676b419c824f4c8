"""The nodes of a location file as processes on this machine, started and stopped together.

Each node runs as ``python -m services.node NAME`` in its own process; its log lines are printed
prefixed with the node name. :class:`NodeGroup` waits until every node reports it is listening,
and stops them all with SIGTERM (SIGKILL after a grace period). ``petrobot up`` and ``petrobot
demo`` use it for a one-machine setup (paper section 5).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
from pathlib import Path
from types import TracebackType
from typing import Self, TextIO

from services.errors import PetrobotError
from services.keys import load_key
from services.location import load_location

__all__ = ["NodeGroup"]


class NodeGroup:
    """Node subprocesses on this machine, started and stopped together.

    Args:
        services: path of services.toml.
        names: nodes to start (default: every node of the file).
        key_file: shared key file passed to each node (default: the nodes' own default).
        log_level: the nodes' log level.
        out: where prefixed log lines go (default: stderr).

    Raises (from :meth:`start`):
        LocationError: services.toml is bad or names an unknown node.
        PetrobotError: a node exited or did not listen within ``timeout_s``.
    """

    def __init__(self, services: str | os.PathLike[str], names: list[str] | None = None, *,
                 key_file: str | None = None, log_level: str = "INFO", out: TextIO | None = None) -> None:
        self.services = Path(services)
        self.location = load_location(self.services)
        self.names = list(names) if names else list(self.location.nodes)
        for name in self.names:
            self.location.address(name)
        self.key_file = key_file
        self.log_level = log_level
        self.out = out if out is not None else sys.stderr
        self.procs: dict[str, asyncio.subprocess.Process] = {}
        self._pumps: list[asyncio.Task[None]] = []
        self._ready: dict[str, asyncio.Event] = {}

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

    async def start(self, timeout_s: float = 20.0) -> None:
        """Start the nodes and wait until each reports it is listening."""
        load_key(self.key_file)  # create the key file once, before the nodes race for it
        width = max(len(n) for n in self.names)
        for name in self.names:
            cmd = [sys.executable, "-m", "services.node", name, "--services", str(self.services),
                   "--log-level", self.log_level]
            if self.key_file:
                cmd += ["--key-file", self.key_file]
            proc = await asyncio.create_subprocess_exec(
                *cmd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
                start_new_session=True,  # Ctrl-C reaches us only; we stop the nodes ourselves
            )
            self.procs[name] = proc
            self._ready[name] = asyncio.Event()
            self._pumps.append(asyncio.get_running_loop().create_task(self._pump(name, width, proc)))
        try:
            async with asyncio.timeout(timeout_s):
                await asyncio.gather(*(self._wait_listening(n) for n in self.names))
        except TimeoutError:
            late = [n for n in self.names if not self._ready[n].is_set()]
            raise PetrobotError(f"node(s) {', '.join(late)} not listening after {timeout_s:g} s") from None

    async def _pump(self, name: str, width: int, proc: asyncio.subprocess.Process) -> None:
        assert proc.stdout is not None
        ready = f"node {name} listening on "
        while line := await proc.stdout.readline():
            text = line.decode(errors="replace").rstrip()
            if text.startswith(ready):
                self._ready[name].set()
            print(f"[{name.ljust(width)}] {text}", file=self.out, flush=True)

    async def _wait_listening(self, name: str) -> None:
        # the node's own "listening" line, not a connect test: another process may hold the port
        proc = self.procs[name]
        ready = asyncio.get_running_loop().create_task(self._ready[name].wait())
        exited = asyncio.get_running_loop().create_task(proc.wait())
        try:
            await asyncio.wait({ready, exited}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            ready.cancel()
            exited.cancel()
        if not self._ready[name].is_set():
            raise PetrobotError(f"node {name} exited with status {proc.returncode} before listening")

    async def wait_any_exit(self) -> str:
        """Wait until some node process exits; return its name."""
        waits = {asyncio.get_running_loop().create_task(p.wait()): n for n, p in self.procs.items()}
        try:
            done, _ = await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
            return waits[next(iter(done))]
        finally:
            for t in waits:
                t.cancel()

    async def stop(self, grace_s: float = 5.0) -> None:
        """SIGTERM every node, SIGKILL those still running after ``grace_s``."""
        for proc in self.procs.values():
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        for proc in self.procs.values():
            try:
                await asyncio.wait_for(proc.wait(), grace_s)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
        for t in self._pumps:
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                await asyncio.wait_for(t, 1.0)
