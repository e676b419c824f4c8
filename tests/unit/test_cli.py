"""The ``petrobot`` command as a process: what a shell pipeline sees of it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from coordinator.cli import EXIT_READER_GONE

ROOT = Path(__file__).resolve().parents[2]
NET = ROOT / "tests" / "data" / "mcc" / "Philosophers-PT-000005" / "model.pnml"


def test_a_reader_that_closes_stdout_ends_the_command_quietly_as_sigpipe_would() -> None:
    # `petrobot analyze --json NET | head -1`, with the reader already gone when the report is
    # written: no traceback on stderr, the exit code a shell gives a filter that SIGPIPE ended.
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "coordinator.cli", "analyze", "--json", str(NET)],
                              stdout=write, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    finally:
        os.close(write)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == EXIT_READER_GONE == 141
