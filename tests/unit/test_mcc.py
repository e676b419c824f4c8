"""Every Model Checking Contest model in tests/data/mcc against the contest's published answers."""

from __future__ import annotations

import csv
import json

import pytest

from coordinator.analysis.robotic import report
from coordinator.analysis.structure import analyse
from coordinator.netfile.pnml import load_pnml
from tests.unit.mcc_models import MCC

ORACLE = MCC / "oracle.tsv"


def oracle_rows() -> list[dict[str, str]]:
    if not ORACLE.exists():
        return []
    with ORACLE.open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def params() -> list[object]:
    out: list[object] = []
    for row in oracle_rows():
        marks = [pytest.mark.slow] if int(row["states"]) > 1_000_000 else []
        out.append(pytest.param(row, id=row["model"], marks=marks))
    return out


def expected(value: str) -> object:
    if value in ("true", "false"):
        return value == "true"
    return int(value)


@pytest.mark.timeout(180)
@pytest.mark.parametrize("row", params())
def test_model_matches_every_column_of_the_oracle(row: dict[str, str]) -> None:
    a = analyse(load_pnml(MCC / row["model"] / "model.pnml"))
    got = {
        "states": a.states, "edges": a.edges, "max_token_in_place": a.max_token_in_place,
        "max_token_per_marking": a.max_token_per_marking, "deadlock": a.deadlock, "live": a.live,
        "quasi_live": a.quasi_live, "one_safe": a.one_safe, "stable_marking": a.stable_marking,
    }
    want = {k: expected(v) for k, v in row.items() if k != "model"}
    assert set(want) <= set(got), f"oracle has columns the test does not know: {set(want) - set(got)}"
    assert {k: got[k] for k in want} == want
    assert a.complete and a.bounded is True


def test_json_report_of_an_mcc_model_carries_the_oracle_columns() -> None:
    rep = report(load_pnml(MCC / "Philosophers-PT-000005" / "model.pnml"))
    json.dumps(rep)
    for key in ("states", "edges", "max_token_in_place", "max_token_per_marking", "bounded", "deadlock", "live",
                "quasi_live", "reversible", "one_safe", "stable_marking", "p_invariants", "t_invariants", "robotic"):
        assert key in rep
    assert (rep["states"], rep["edges"], rep["deadlock"]) == (243, 945, True)
    assert len(rep["deadlocks"]) == 2
    assert rep["robotic"]["error_recoverable"]["holds"] is False
