"""Every analysis respects its state limit and its memory budget, and says what it left undecided.

The hostile nets (tests/data/hostile_nets.py): a ring of 20,000 places and transitions, which used to
reach 18 GB in a minute (dense |P|×|T| matrices, the Farkas table), and a 500-place ring that took 35 s
(the Farkas minimality test over the whole table at every step).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from analysis_nets import make_net

from coordinator.analysis import statespace
from coordinator.analysis.budget import default_max_bytes, resident_bytes, room
from coordinator.analysis.statespace import arc_table, explore
from coordinator.analysis.structure import analyse
from coordinator.cli import main
from coordinator.commands.analyze import parse_size
from coordinator.net import PetriNet

DATA = Path(__file__).resolve().parents[1] / "data"


def hostile() -> ModuleType:
    spec = importlib.util.spec_from_file_location("hostile_nets", DATA / "hostile_nets.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_json(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    assert main(["analyze", "--json", *args]) == 0
    out = json.loads(capsys.readouterr().out)
    assert isinstance(out, dict)
    return out


@pytest.mark.timeout(120)
def test_a_20000_place_ring_ends_with_an_honest_partial_report(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ring20000.toml"
    path.write_text(hostile().ring_toml(20_000), encoding="utf-8")
    rep = run_json([str(path), "--max-states", "1000", "--engine", "explicit"], capsys)
    # a partial graph's counts are lower bounds, reported as found, never as the net's
    assert rep["states"] is None and rep["edges"] is None and rep["complete"] is False
    assert rep["truncated"]["by"] == "max_states" and rep["truncated"]["states_found"] == 1000  # type: ignore[index]
    assert rep["bounded"] is True and rep["one_safe"] is True and rep["max_token_in_place"] == 1
    assert rep["conservative"] is True and rep["consistent"] is True
    assert rep["sources"]["bounded"].startswith("state equation")  # type: ignore[index]
    assert set(rep["undecided"]) >= {"live", "reversible"}  # type: ignore[arg-type]
    assert rep["p_invariants_complete"] is False and any("not started" in n for n in rep["notes"])  # type: ignore[union-attr]
    assert rep["robotic"]["controllable"]["holds"] is None  # type: ignore[index]


@pytest.mark.timeout(120)
def test_a_20000_place_ring_under_a_small_memory_budget_stops_the_search_not_the_machine(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ring20000.toml"
    path.write_text(hostile().ring_toml(20_000), encoding="utf-8")
    rep = run_json([str(path), "--max-memory", "256M", "--engine", "explicit"], capsys)
    assert rep["complete"] is False and rep["truncated"]["by"] == "max_memory"  # type: ignore[index]
    # a marking of 20,000 places costs ~23 kB in the search (its packed fields, and the result's byte
    # a place): half of 256 MiB holds a few thousand
    assert 1 < rep["truncated"]["states_found"] < 6000  # type: ignore[index]
    assert rep["budget"]["max_memory_bytes"] == 256 << 20  # type: ignore[index]
    assert rep["bounded"] is True and rep["consistent"] is True


def test_the_500_place_ring_is_analysed_completely(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ring500.toml"
    path.write_text(hostile().ring_toml(500), encoding="utf-8")
    rep = run_json([str(path)], capsys)
    assert (rep["states"], rep["edges"], rep["complete"]) == (500, 500, True)
    assert rep["live"] is True and rep["reversible"] is True and rep["undecided"] == []
    assert rep["p_invariants"] == [{f"p{i}": 1 for i in range(500)}]
    assert rep["t_invariants"] == [{f"t{i}": 1 for i in range(500)}]


def test_the_text_report_names_the_limit_that_stopped_the_search(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ring50.toml"
    path.write_text(hostile().ring_toml(50, tokens=3), encoding="utf-8")
    assert main(["analyze", str(path), "--max-states", "100", "--engine", "explicit"]) == 0
    out = capsys.readouterr().out
    assert "partial: stopped by the state limit" in out and "undecided:" in out and "decided by:" in out


def test_memory_sizes_parse_with_units() -> None:
    assert parse_size("4G") == 4 << 30 and parse_size("512M") == 512 << 20 and parse_size("1.5GiB") == 3 << 29
    assert parse_size("2097152") == 2 << 20
    for bad in ("lots", "12X", "100K"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_size(bad)


def producer() -> PetriNet:
    return make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})


def test_the_byte_budget_stops_the_search_with_a_breadth_first_prefix() -> None:
    net = make_net("grid", {"a": 200, "b": 200}, {"ab": ({"a": 1}, {"c": 1}), "ba": ({"b": 1}, {"d": 1}),
                                                "ca": ({"c": 1}, {"a": 1}), "db": ({"d": 1}, {"b": 1})})
    full = explore(net)
    part = explore(net, max_bytes=1_000_000)
    assert full.complete and not part.complete and part.stopped_by == "max_memory"
    assert 0 < part.n_states < full.n_states
    assert np.array_equal(part.states, full.states[:part.n_states])
    done = part.expanded
    assert done[:done.sum()].all() and not done[done.sum():].any()  # expanded states come first
    k = int(done.sum())
    assert np.array_equal(part.out_ptr[:k + 1], full.out_ptr[:k + 1])
    assert (np.diff(part.out_ptr)[k:] == 0).all()  # unexpanded states have no edges
    assert np.array_equal(part.dst, full.dst[:part.n_edges])


def test_the_symbolic_engine_leaves_room_for_what_the_process_holds_under_the_default_budget() -> None:
    whole, held = default_max_bytes(), resident_bytes()
    assert held > 0  # Linux: /proc/self/statm
    assert room(1 << 20) == 1 << 20  # a small budget asked for bounds the data alone
    slack = 64 << 20  # what the process allocates or frees between the two reads
    assert whole - held - slack <= room(whole) <= whole - held + slack


def test_a_graph_dropped_for_the_symbolic_engine_is_searched_again_when_it_gives_up() -> None:
    # 1,000 independent cycles of two places: bounded (one token each), 2^1000 markings. In 1 MB the
    # explicit search stops at once, by its memory; the symbolic engine takes over with that graph
    # dropped, cannot hold its encoding and gives up; the search runs again for the partial report
    cycles = make_net("cycles", {f"p{i}": 1 for i in range(1000)},
                      {t: arcs for i in range(1000) for t, arcs in ((f"a{i}", ({f"p{i}": 1}, {f"q{i}": 1})),
                                                                    (f"b{i}", ({f"q{i}": 1}, {f"p{i}": 1})))})
    a = analyse(cycles, engine="auto", max_bytes=1_000_000)
    assert a.engine == "explicit" and a.engine_reason.startswith("explicit: the symbolic engine gave up")
    assert not a.complete and a.space is not None and a.space.stopped_by == "max_memory"
    assert a.bounded is True and a.one_safe is True and a.live is None
    assert len(a.notes) == len(set(a.notes))  # the search run again does not say twice what it found
    assert sum("filled its memory budget" in n for n in a.notes) == 1


def test_the_byte_budget_leaves_unbounded_nets_decided_by_their_witness() -> None:
    a = analyse(producer(), max_bytes=1 << 20)
    assert a.bounded is False and a.unbounded_places == ["buf"]


@pytest.mark.parametrize("seed", range(6))
def test_the_arc_lists_built_from_sparse_matrices_give_the_same_graph(seed: int,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    from test_statespace import random_net

    rng = np.random.default_rng(100 + seed)
    net = random_net(rng, n_places=int(rng.integers(3, 7)), n_transitions=int(rng.integers(3, 9)))
    dense = explore(net, max_states=300)
    monkeypatch.setattr(statespace, "dense_is_cheap", lambda _net: False)
    sparse = explore(net, max_states=300)
    for name in ("states", "src", "dst", "transition", "parent_edge", "expanded", "out_ptr"):
        assert np.array_equal(getattr(dense, name), getattr(sparse, name)), name
    from coordinator.analysis.reach_kernel import HEAD

    assert arc_table(net)[0] == HEAD  # the header of the packed lists, reset lists included
