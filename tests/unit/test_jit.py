"""Where numba caches the compiled search (coordinator.analysis.jit), and the compile notice."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coordinator.analysis import jit
from coordinator.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_the_cache_goes_to_the_xdg_cache_home_or_the_home_cache() -> None:
    assert jit.cache_dir({"XDG_CACHE_HOME": "/c", "HOME": "/h"}) == Path("/c/petrobot/numba")
    assert jit.cache_dir({"HOME": "/h"}) == Path("/h/.cache/petrobot/numba")
    assert jit.cache_dir({"XDG_CACHE_HOME": "relative", "HOME": "/h"}) == Path("/h/.cache/petrobot/numba")


def configured(env: dict[str, str]) -> str:
    code = "from coordinator.analysis import jit; import os; print(jit.configure(), os.environ['NUMBA_CACHE_DIR'])"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=60, check=True)
    return out.stdout.strip()


def test_configure_sets_numba_cache_dir_only_when_the_user_has_not(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    want = str(tmp_path / "petrobot" / "numba")
    assert configured(env) == f"{want} {want}"
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    assert configured(env) == f"{tmp_path / 'mine'} {tmp_path / 'mine'}"


def test_analyze_says_on_stderr_when_it_has_to_compile_the_search(monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.analysis import reach_kernel, statespace

    net = ROOT / "tests" / "data" / "mcc" / "FMS-PT-00002" / "model.pnml"  # 3,444 markings
    statespace.load_search()
    # as on a machine whose cache lacks the search: the interpreter's share of a search is used up at once
    monkeypatch.setattr(statespace, "_RK", None)
    monkeypatch.setattr(statespace, "search_is_compiled", lambda: False)
    monkeypatch.setattr(reach_kernel, "cached", lambda: False)
    monkeypatch.setattr(statespace, "INTERPRETED_SECONDS", 0.0)
    assert main(["analyze", str(net), "--json"]) == 0
    assert "compiling the state-space search (once per machine)..." in capsys.readouterr().err
    monkeypatch.setattr(reach_kernel, "cached", lambda: True)  # now it is loaded
    assert main(["analyze", str(net), "--json"]) == 0
    assert "compiling" not in capsys.readouterr().err
    # with the progress shown, the notice is a line of its own: no blank line before it
    monkeypatch.setattr(statespace, "_RK", None)
    monkeypatch.setattr(reach_kernel, "cached", lambda: False)
    assert main(["analyze", str(net), "--json", "--progress", "--engine", "explicit"]) == 0
    err = capsys.readouterr().err
    assert "\ncompiling the state-space search (once per machine)...\n" in err and "\n\n" not in err


def test_the_loaded_search_reports_itself_compiled() -> None:
    from coordinator.analysis.statespace import load_search, search_is_compiled

    load_search()
    assert search_is_compiled() is True


def test_the_compiled_kernels_cache_in_the_users_directory_whoever_imports_them_first(tmp_path: Path) -> None:
    # importing a kernel directly (as a test or a bench child does), not through a
    # command that configures numba first, must not write numba's cache beside the source
    code = ("import coordinator.analysis.symbolic, coordinator.analysis.mdd_kernel as k, "
            "coordinator.analysis.mdd_order as o, coordinator.analysis.reach_kernel as r\n"
            "print('\\n'.join(f._cache._cache_path for m in (k, o, r) for f in vars(m).values() "
            "if hasattr(f, '_cache')))")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=120, check=True)
    paths = out.stdout.split()
    assert len(paths) > 10
    assert all(p.startswith(str(tmp_path / "petrobot" / "numba")) for p in paths), paths


def test_a_second_checkout_of_the_same_source_loads_the_kernels_the_first_compiled(tmp_path: Path) -> None:
    # numba would name the cache folder after the checkout's absolute path and compile everything
    # again in a fresh clone; jit_locator names it after the module, and numba checks the content
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    subprocess.run([sys.executable, "-c", "from coordinator.analysis.statespace import load_search; load_search()"],
                   cwd=ROOT, env=env, check=True, capture_output=True)
    other = tmp_path / "other"
    shutil.copytree(ROOT / "coordinator", other / "coordinator", ignore=shutil.ignore_patterns("__pycache__"))
    for source in (other / "coordinator").rglob("*.py"):
        os.utime(source, (1_000_000_000, 1_000_000_000))  # another time stamp, the same content
    code = ("import coordinator\nfrom coordinator.analysis.statespace import search_is_compiled\n"
            "print(coordinator.__file__, search_is_compiled())")
    out = subprocess.run([sys.executable, "-c", code], cwd=other, env=env, check=True, capture_output=True, text=True)
    where, compiled = out.stdout.split()
    assert Path(where).is_relative_to(other)
    assert compiled == "True"
    assert [p.name for p in (tmp_path / "cache" / "petrobot" / "numba").iterdir()] == ["petrobot-coordinator.analysis"]


def test_functions_outside_petrobot_keep_numbas_own_cache_folders(tmp_path: Path) -> None:
    (tmp_path / "theirs.py").write_text("from numba import njit\n\n\n@njit(cache=True)\ndef one(x):\n"
                                        "    return x + 1\n", encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), str(ROOT)])
    # nor does a child process inherit a locator it would have to import petrobot for
    code = ("import os\nfrom coordinator.analysis import jit; jit.configure()\nimport theirs\n"
            "assert theirs.one(1) == 2\nassert 'NUMBA_CACHE_LOCATOR_CLASSES' not in os.environ\n"
            "print(theirs.one._cache._cache_path)")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, check=True, capture_output=True,
                         text=True)
    folder = Path(out.stdout.strip())
    assert folder.parent == tmp_path / "cache" / "petrobot" / "numba"
    assert not folder.name.startswith("petrobot-")


def test_analyze_compiles_the_symbolic_kernels_beside_the_search_and_ends_that_process(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.analysis import reach_kernel, statespace
    from coordinator.commands import analyze

    started: list[analyze._Beside] = []
    real_start = analyze._Beside.start

    def start(self: analyze._Beside) -> None:
        real_start(self)
        started.append(self)

    monkeypatch.setattr(analyze._Beside, "start", start)
    net = ROOT / "tests" / "data" / "mcc" / "FMS-PT-00002" / "model.pnml"
    statespace.load_search()
    monkeypatch.setattr(statespace, "_RK", None)
    monkeypatch.setattr(statespace, "search_is_compiled", lambda: False)
    monkeypatch.setattr(reach_kernel, "cached", lambda: False)
    monkeypatch.setattr(statespace, "INTERPRETED_SECONDS", 0.0)
    assert main(["analyze", str(net), "--json", "--engine", "explicit"]) == 0
    assert "symbolic engine" not in capsys.readouterr().err and not started
    monkeypatch.setattr(statespace, "_RK", None)
    assert main(["analyze", str(net), "--json"]) == 0
    assert "compiling the symbolic engine's kernels beside it, in another process" in capsys.readouterr().err
    assert len(started) == 1 and started[0].proc is not None
    assert started[0].proc.poll() is not None  # ended (done, or stopped) when analyze returned


def test_the_symbolic_engine_waits_once_for_kernels_compiled_elsewhere() -> None:
    from coordinator.analysis.statespace import explore
    from coordinator.analysis.symbolic import analyse_symbolic, set_kernels_wait
    from coordinator.commands.analyze import compile_symbolic
    from coordinator.netfile.pnml import load_pnml

    compile_symbolic()  # what the second process runs: here the kernels are loaded already
    net = load_pnml(str(ROOT / "tests" / "data" / "mcc" / "Philosophers-PT-000005" / "model.pnml"))
    waits: list[int] = []
    set_kernels_wait(lambda: waits.append(1))
    try:
        bounds = np.ones(len(net.places), np.int64)
        for _ in range(2):
            assert analyse_symbolic(net, bounds).states == explore(net).n_states
    finally:
        set_kernels_wait(None)
    assert waits == [1]
