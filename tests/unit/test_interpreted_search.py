"""The state-space search run by the interpreter (jit.interpreted) while the compiled one is not in
numba's cache: the same arrays as the compiled search, and the compile only when a net needs it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from analysis_nets import make_net

from coordinator.analysis import reach_kernel, statespace
from coordinator.analysis.statespace import StateSpace, explore
from coordinator.net import Arc, PetriNet
from tests.unit.mcc_models import MCC

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["CircularTrains-PT-012", "ERK-PT-000001", "Eratosthenes-PT-010", "FMS-PT-00002", "Philosophers-PT-000005",
         "Railroad-PT-005", "ResAllocation-PT-R003C005", "SharedMemory-PT-000005", "TokenRing-PT-005"]
ARRAYS = ("words", "layout", "out_ptr", "dst", "transition", "parent", "expanded", "fired")


@pytest.fixture
def cold(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """This process as on a machine whose numba cache lacks the compiled search: nothing loaded, and
    the cache says it does not hold it."""
    statespace._kernel()  # the compiled search, for the comparisons
    monkeypatch.setattr(statespace, "_RK", None)
    monkeypatch.setattr(statespace, "search_is_compiled", lambda: False)
    monkeypatch.setattr(statespace, "INTERPRETED_SECONDS", 1e9)
    yield


def compiled_explore(net: PetriNet, **kwargs: object) -> StateSpace:
    saved = statespace._RK
    statespace._RK = reach_kernel
    try:
        return explore(net, **kwargs)  # type: ignore[arg-type]
    finally:
        statespace._RK = saved


def assert_same(net: PetriNet, **kwargs: object) -> StateSpace:
    twin = explore(net, **kwargs)  # type: ignore[arg-type]
    machine = compiled_explore(net, **kwargs)
    assert twin.interpreted and not machine.interpreted
    for name in ARRAYS:
        assert np.array_equal(getattr(twin, name), getattr(machine, name)), name
        assert getattr(twin, name).dtype == getattr(machine, name).dtype, name
    for name in ("complete", "stopped_by", "packed_bits", "store_bytes", "max_count", "edges_kept", "edges_shed_at"):
        assert getattr(twin, name) == getattr(machine, name), name
    assert np.array_equal(twin.states, machine.states)
    for a, b in zip(twin.extremes(), machine.extremes()):
        assert np.array_equal(a, b)
    if twin.complete:
        for a, b in zip(twin.implicit_liveness(), machine.implicit_liveness()):
            assert np.array_equal(a, b)
    return twin


@pytest.mark.parametrize("model", SMALL)
def test_the_interpreted_search_gives_the_compiled_searchs_arrays_on_the_mcc_models(model: str, cold: None) -> None:
    from coordinator.netfile.pnml import load_pnml

    net = load_pnml(str(MCC / model / "model.pnml"))
    full = assert_same(net)
    assert full.complete
    assert_same(net, edges=False)
    assert_same(net, max_states=max(1, full.n_states // 3), finish_level=False)
    assert_same(net, max_bytes=1 << 20)


def test_the_interpreted_search_applies_priorities_inhibitors_resets_and_widens_fields(cold: None) -> None:
    base = make_net("flush", {"go": 1}, {"fill": ({"go": 1}, {"go": 1, "buf": 1}),
                                         "flush": ({"go": 1, "buf": 1}, {"done": 1})},
                    inhibitors={"fill": {"buf": 300}})
    resets = PetriNet(name=base.name, places=base.places, transitions=base.transitions,
                      arcs=(*base.arcs, Arc(source="buf", target="flush", reset=True)),
                      initial_marking=base.initial_marking)
    space = assert_same(resets, bounds=np.array([1, 1, 1], np.int64))  # buf's field widens past its wrong bound
    assert space.n_states == 302 and space.max_count == 300  # buf = 0..300 with go, then done
    assert_same(base, priority=np.array([0, 1], np.int64))


def test_a_net_too_large_for_the_interpreters_share_is_searched_compiled(cold: None,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.netfile.pnml import load_pnml

    notices: list[str] = []
    monkeypatch.setattr(statespace, "INTERPRETED_SECONDS", 0.0)
    monkeypatch.setattr(reach_kernel, "cached", lambda: False)  # as if the compile were still to come
    statespace.set_compile_notice(lambda: notices.append("compiling"))
    try:
        net = load_pnml(str(MCC / "FMS-PT-00002" / "model.pnml"))
        reports: list[int] = []
        space = explore(net, progress=lambda states, edges: reports.append(states))
    finally:
        statespace.set_compile_notice(None)
    assert notices == ["compiling"]
    assert not space.interpreted and space.complete and space.n_states == 3444
    assert reports and reports[-1] == 3444
    assert statespace._RK is reach_kernel


def test_the_counts_reported_never_start_again_when_the_interpreted_search_is_given_up(
        cold: None, monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.netfile.pnml import load_pnml

    monkeypatch.setattr(statespace, "INTERPRETED_SECONDS", 0.3)  # Murphy-PT-D1N010 needs some seconds
    reports: list[int] = []
    space = explore(load_pnml(str(MCC / "Murphy-PT-D1N010" / "model.pnml")), report_every=500,
                    progress=lambda states, edges: reports.append(states))
    assert not space.interpreted and space.n_states == 39_780
    assert len(reports) > 10 and reports == sorted(reports) and reports[-1] == 39_780


def test_a_stop_event_ends_the_interpreted_search_with_what_it_found(cold: None) -> None:
    import threading

    from coordinator.netfile.pnml import load_pnml

    stop = threading.Event()
    stop.set()
    space = explore(load_pnml(str(MCC / "FMS-PT-00002" / "model.pnml")), stop=stop, report_every=100)
    assert space.interpreted and not space.complete and space.stopped_by == "stopped"
    assert 0 < space.n_states < 3444


def test_analyze_on_a_machine_without_the_compiled_search_compiles_nothing_for_a_small_net(tmp_path: Path) -> None:
    def analyze(cache: Path) -> tuple[dict[str, object], str]:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
        out = subprocess.run([sys.executable, "-m", "coordinator.cli", "analyze", "nets/demo.toml", "--json"],
                             cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=True)
        return json.loads(out.stdout), out.stderr

    empty = tmp_path / "empty"
    cold_report, said = analyze(empty)
    assert "compiling" not in said
    assert not [p for p in empty.rglob("*") if p.is_file()]  # nothing compiled, nothing cached
    statespace.load_search()  # the compiled search in this process's cache, which the next run loads
    warm_report, _ = analyze(Path(os.environ["NUMBA_CACHE_DIR"]))
    assert cold_report == warm_report


def test_the_interpreted_copy_leaves_the_compiled_module_and_numbas_switches_alone() -> None:
    from numba.core import config

    from coordinator.analysis import jit

    twin = jit.interpreted(reach_kernel)
    assert not hasattr(twin._search, "py_func") and not hasattr(twin.run, "py_func")  # plain functions
    assert hasattr(reach_kernel._search, "py_func") and hasattr(reach_kernel.run, "py_func")  # still numba's
    assert not config.DISABLE_JIT
    assert twin.__name__ == "coordinator.analysis.reach_kernel_interpreted"
    assert twin.RUN_SIGNATURE == reach_kernel.RUN_SIGNATURE
