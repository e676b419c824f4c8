#!/usr/bin/env python3
"""petrobot quick start: `python3 run.py demo` runs the main job, `python3 run.py test` the tests.

On first use it makes a virtual environment in .venv and installs petrobot with its test
dependencies there (again whenever pyproject.toml changes). If the standard library's venv
module is missing (Debian without python3-venv), it installs into the current interpreter's
user site instead. Anything after the command is passed on: `python3 run.py test -k engine`,
`python3 run.py demo --help`, `python3 run.py petrobot analyze nets/catch.toml`.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".petrobot-installed"
USAGE = """usage: python3 run.py demo [ARGS...]      the catching demo on localhost (petrobot demo)
       python3 run.py test [PYTEST ARGS...] the test suite
       python3 run.py bench                  every benchmark in bench/ (writes nothing; prints results)
       python3 run.py petrobot ARGS...       any petrobot command in the project's environment"""


def say(text: str) -> None:
    print(f"[run.py] {text}", file=sys.stderr, flush=True)


def environment() -> Path:
    """Return the Python interpreter to use, installing petrobot first if needed."""
    wanted = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    python = VENV / "bin" / "python"
    if python.exists() and STAMP.exists() and STAMP.read_text().strip() == wanted:
        return python
    extras = ".[test,bench]" if os.environ.get("PETROBOT_BENCH") else ".[test]"
    try:
        if not python.exists():
            say(f"creating a virtual environment in {VENV}")
            venv.EnvBuilder(with_pip=True).create(VENV)
        say(f"installing petrobot and its dependencies into {VENV} (first run: a few minutes)")
        subprocess.run([str(python), "-m", "pip", "install", "--disable-pip-version-check", "-q", "-e", extras],
                       cwd=ROOT, check=True)
        STAMP.write_text(wanted)
        return python
    except (subprocess.CalledProcessError, OSError) as exc:
        if python.exists():
            raise SystemExit(f"[run.py] installing into {VENV} failed: {exc}")
        say(f"no virtual environment ({exc}); installing into the user site of {sys.executable}")
        subprocess.run([sys.executable, "-m", "pip", "install", "--user", "-q", "-e", extras], cwd=ROOT, check=True)
        return Path(sys.executable)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(USAGE)
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command not in ("demo", "test", "bench", "petrobot"):
        print(USAGE, file=sys.stderr)
        return 2
    python = environment()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    if command == "test":
        args = [str(python), "-m", "pytest", *rest]
    elif command == "demo":
        args = [str(python), "-m", "coordinator.cli", "demo", *rest]
    elif command == "petrobot":
        args = [str(python), "-m", "coordinator.cli", *rest]
    else:
        status = 0
        for bench in sorted((ROOT / "bench").glob("*.py")):
            say(f"running {bench.name}")
            status |= subprocess.run([str(python), str(bench)], cwd=ROOT, env=env).returncode
        return status
    try:
        return subprocess.run(args, cwd=ROOT, env=env).returncode
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
