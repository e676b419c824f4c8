"""The ``petrobot`` command as a process: what a shell pipeline sees of it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from coordinator.cli import EXIT_READER_GONE, reader_gone

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


def test_only_a_closed_reader_of_stdout_counts_as_gone(tmp_path: Path) -> None:
    # a BrokenPipeError from anything else (a socket to a node) is re-raised, not hidden behind 141
    read, write = os.pipe()
    with os.fdopen(write, "w") as stream:
        assert not reader_gone(stream)  # its reader is still there
        os.close(read)
        assert reader_gone(stream)
        with (tmp_path / "file").open("w") as plain:
            assert not reader_gone(plain)
