"""The marking-expression language (coordinator.analysis.expr): grammar, types, error columns, and
vectorised evaluation against a one-marking-at-a-time reference."""

from __future__ import annotations

import numpy as np
import pytest

from coordinator.analysis.expr import ExprError, Node, compile_expr, parse

PLACES = ["p1", "p2", "p3", "arm.left", "arm-right"]


def reference(node: Node, m: dict[str, int]) -> float | int | bool:
    """Plain Python evaluation of a syntax tree on one marking."""
    a = [reference(x, m) for x in node.args]
    op = node.op
    if op in ("num", "bool"):
        return node.value  # type: ignore[return-value]
    if op == "place":
        return m[str(node.value)]
    table = {
        "neg": lambda: -a[0], "not": lambda: not a[0], "min": lambda: min(a), "max": lambda: max(a),
        "+": lambda: a[0] + a[1], "-": lambda: a[0] - a[1], "*": lambda: a[0] * a[1],
        "/": lambda: a[0] / a[1] if a[1] != 0 else (np.inf if a[0] > 0 else -np.inf if a[0] < 0 else np.nan),
        "==": lambda: a[0] == a[1], "!=": lambda: a[0] != a[1], "<": lambda: a[0] < a[1],
        "<=": lambda: a[0] <= a[1], ">": lambda: a[0] > a[1], ">=": lambda: a[0] >= a[1],
        "and": lambda: a[0] and a[1], "or": lambda: a[0] or a[1],
    }
    return table[op]()  # type: ignore[no-any-return]


CASES = [
    "#p1 == 1 and #p3 == 1",
    "#p1 + #p2",
    "2 * #p1 - #p2 / 4 + 0.5",
    "min(#p1, #p2, 3) + max(#p3, 1)",
    "not (#p1 > 0 or #p2 > 0) or #p3 >= 2",
    "0 < #p1 <= #p2 < 5",
    "-#p1 * -(#p2 + 1)",
    '#"arm-right" + #arm.left',
    "#p1 / #p2",
    "true and #p1 != 2",
    "1e-1 * #p3",
]


@pytest.mark.parametrize("text", CASES)
def test_vectorised_evaluation_matches_the_one_marking_reference(text: str) -> None:
    rng = np.random.default_rng(7)
    rows = rng.integers(0, 4, size=(200, len(PLACES)))
    f = compile_expr(text, PLACES)
    got = f(rows)
    tree = parse(text)
    want = [reference(tree, dict(zip(PLACES, r.tolist()))) for r in rows]
    assert got.shape == (200,)
    np.testing.assert_array_equal(got, np.array(want, dtype=got.dtype))
    assert f(rows[3]) == got[3]  # one marking, same answer


def test_integer_arithmetic_stays_exact_and_division_is_true_division() -> None:
    f = compile_expr("#p1 * 1000000 + #p2", ["p1", "p2"])
    rows = np.array([[255, 255]], dtype=np.uint8)  # no wrap-around of small storage types
    assert f(rows).dtype == np.int64 and f(rows)[0] == 255_000_255
    assert compile_expr("#p1 / 2", ["p1"])(np.array([[3]]))[0] == 1.5


def test_types_are_checked_when_compiling() -> None:
    assert parse("#p1 + 1").kind == "num" and parse("#p1 > 1").kind == "bool"
    with pytest.raises(ExprError, match="expected a condition"):
        compile_expr("#p1 + 1", PLACES, kind="bool")
    with pytest.raises(ExprError, match="expected a number"):
        compile_expr("#p1 > 1", PLACES, kind="num")


@pytest.mark.parametrize(("text", "column", "words"), [
    ("#p1 +", 6, "ends too early"),
    ("#p1 and #p2", 1, "'and' needs a truth value"),
    ("#p1 > 1 or 2", 12, "'or' needs a truth value"),
    ("(#p1 > 1", 9, "expected ')'"),
    ("#p9 > 1", 1, "unknown place 'p9'; did you mean #p"),
    ("p1 > 1", 1, "write a place count as #p1"),
    ("3 $ 4", 3, "unexpected character '$'"),
    ("min(#p1 > 0)", 5, "min() needs a number"),
    ("#p1 > 1)", 8, "after a complete expression"),
    ("", 1, "empty expression"),
    ("# > 1", 1, "must be followed by a place id"),
    ("not 3", 5, "'not' needs a truth value"),
    ("#p1 + (#p2 < 1)", 7, "'+' needs a number"),
])
def test_errors_name_the_column_of_the_problem(text: str, column: int, words: str) -> None:
    with pytest.raises(ExprError) as info:
        compile_expr(text, PLACES)
    assert info.value.column == column
    assert words in info.value.message
    assert "^" in str(info.value)


def test_the_parser_never_evaluates_python() -> None:
    for text in ("__import__('os')", "#p1.__class__", "lambda: 1", "[1]", "'a'", "#p1 ** 2"):
        with pytest.raises(ExprError):
            compile_expr(text, PLACES)


def test_places_read_are_listed_once_in_order() -> None:
    assert compile_expr("#p2 + #p1 * #p2 > #p3", PLACES).places == ("p2", "p1", "p3")


@pytest.mark.parametrize("text", CASES)
def test_the_one_marking_evaluator_of_the_engine_agrees_with_the_vectorised_one(text: str) -> None:
    from coordinator.expr import evaluate

    rng = np.random.default_rng(11)
    rows = rng.integers(0, 4, size=(100, len(PLACES)))
    got = compile_expr(text, PLACES)(rows)
    tree = parse(text)
    for i, r in enumerate(rows.tolist()):
        value = evaluate(tree, {p: c for p, c in zip(PLACES, r) if c})  # missing places hold 0
        assert value == got[i] or (value != value and got[i] != got[i]), (text, r)


def test_the_net_model_and_the_analyses_share_one_parser() -> None:
    import coordinator.analysis.expr as vectorised
    import coordinator.expr as language

    assert vectorised.parse is language.parse and vectorised.ExprError is language.ExprError


@pytest.mark.parametrize("text, words", [
    ("1" + " + 1" * 300, "nested more than"),
    ("(" * 60 + "1" + ")" * 60, "nested more than"),
    ("1" * 5000, "characters long"),
])
def test_hostile_expressions_are_refused_by_the_limits(text: str, words: str) -> None:
    with pytest.raises(ExprError, match=words):
        parse(text)
