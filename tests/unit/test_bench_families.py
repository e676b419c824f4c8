"""bench/families.py builds the contest's families at any size: at the sizes the contest publishes in
tests/data/mcc, the very nets of the contest (places, transitions, arcs with weights, initial marking)."""

from __future__ import annotations

import pytest

from bench.families import build
from coordinator.net import PetriNet
from coordinator.netfile.pnml import load_pnml
from tests.unit.mcc_models import MCC


def shape(net: PetriNet) -> tuple[set[str], set[str], set[tuple[str, str, int, bool]], dict[str, int]]:
    return ({p.id for p in net.places}, {t.id for t in net.transitions},
            {(a.source, a.target, a.weight, a.inhibitor) for a in net.arcs},
            {p: k for p, k in net.initial_marking.items() if k})


@pytest.mark.parametrize("spec, model", [("philosophers:5", "Philosophers-PT-000005"),
                                         ("sharedmemory:5", "SharedMemory-PT-000005"),
                                         ("fms:2", "FMS-PT-00002"), ("kanban:5", "Kanban-PT-00005")])
def test_a_family_built_at_a_published_size_is_the_contests_net(spec: str, model: str) -> None:
    assert shape(build(spec, MCC)) == shape(load_pnml(MCC / model / "model.pnml"))


def test_a_family_at_another_size_scales_what_the_family_scales() -> None:
    net = build("philosophers:7", MCC)
    assert len(net.places) == 35 and len(net.transitions) == 35
    assert build("fms:9", MCC).initial_marking["P1"] == 9 and build("fms:9", MCC).initial_marking["M1"] == 3


def test_an_unknown_family_or_size_is_refused_with_the_known_ones() -> None:
    with pytest.raises(ValueError, match="known: fms, kanban, philosophers, sharedmemory"):
        build("railroad:3", MCC)
    with pytest.raises(ValueError, match="positive integer"):
        build("kanban:0", MCC)


def test_the_deadlock_bench_finds_the_same_dead_markings_both_ways_and_prints_their_ratio(
        capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from bench.deadlocks import main

    assert main(["--json", "--mcc", str(MCC), "philosophers:6", "sharedmemory:5"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(r["model"], r["states"], r["dead"]) for r in rows] == [("philosophers:6", 3 ** 6, 2),
                                                                    ("sharedmemory:5", 1863, 0)]
    assert all(r["ratio"] > 0 for r in rows)


def test_the_witness_bench_finds_the_same_sequence_both_ways_and_prints_their_ratio(
        capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from bench.witness import main

    assert main(["--json", "--mcc", str(MCC), "philosophers:6", "sharedmemory:5"]) == 0
    out = capsys.readouterr().out.splitlines()
    row = json.loads(out[0])
    assert (row["model"], row["states"], row["dead"], row["length"]) == ("philosophers:6", 3 ** 6, 2, 6)
    assert row["ratio"] > 0 and len(row["after_seconds"]) == len(row["beside_seconds"]) == 1
    assert out[1] == "sharedmemory:5: 1,863 markings and no dead marking: no witness to time"
