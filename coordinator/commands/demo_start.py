"""The simulated world of a demo as a child process (``petrobot sim catching|mobile``), and the demo's
journal file (fresh by default, the previous one kept)."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from services.errors import PetrobotError

__all__ = ["SimWorld", "journal_for"]

ROOT = Path(__file__).resolve().parents[2]


def journal_for(given: str | None, default: str) -> Path:
    """The demo's journal: ``given`` as is (its learner state is continued), else a fresh
    ``default`` (an existing one, with its SQLite side files, is renamed ``*.prev.sqlite``)."""
    if given:
        path = Path(given)
        path.parent.mkdir(parents=True, exist_ok=True)
        return path
    path = Path(default)
    path.parent.mkdir(parents=True, exist_ok=True)
    prev = path.with_suffix(".prev" + path.suffix)
    for suffix in ("", "-wal", "-shm"):
        old = Path(str(path) + suffix)
        if old.exists():
            old.replace(Path(str(prev) + suffix))
        elif Path(str(prev) + suffix).exists():
            Path(str(prev) + suffix).unlink()
    return path


class SimWorld:
    """The ``petrobot sim WORLD`` process, its JSON event lines read by a thread.

    Args:
        args: command-line arguments after ``sim WORLD``.
        log: file for the simulator's stderr (log lines, warnings), or ``None`` to drop them.
        world: ``catching`` or ``mobile``.
    """

    def __init__(self, args: list[str], log: Path | None = None, world: str = "catching") -> None:
        self._log = open(log, "w") if log is not None else None  # noqa: SIM115 (kept open for the process, closed by stop())
        self.proc = subprocess.Popen([sys.executable, "-m", "coordinator.commands.sim", world, *args],
                                     cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=self._log if self._log is not None else subprocess.DEVNULL, text=True)
        self.events: list[dict[str, Any]] = []
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._read, name="sim-events", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                try:
                    event = json.loads(line)
                except ValueError:
                    continue
                event["t_wall"] = time.time()
                self.events.append(event)
                if event.get("event") == "ready":
                    self._ready.set()

    def wait_ready(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while not self._ready.wait(0.1):
            if self.proc.poll() is not None:
                raise PetrobotError(f"the simulator exited with status {self.proc.returncode} before it was ready")
            if time.monotonic() > end:
                raise PetrobotError(f"the simulator was not ready after {timeout_s:.0f} s")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        self._reader.join(timeout=5)  # the last lines ("stopped") are read before the report
        if self._log is not None:
            self._log.close()


