"""Marking expressions compiled once and evaluated on many markings at a time (pure, no I/O; never
``eval``).

The language, its parser and its one-marking evaluator live in :mod:`coordinator.expr` (the net
model needs them and does not import this package); this module binds a parsed expression to the
columns of a markings matrix and evaluates it with numpy. Used by the reward measures of
``petrobot gspn`` (``P{...}``, ``E{...}``; docs/gspn.md) and by the marking-dependent rates and
weights of the GSPN analyses. Grammar, types and limits: :mod:`coordinator.expr`. Sums, differences
and products of counts and integers stay exact int64 here; ``/`` is true division (IEEE: ``x/0``
is ±inf or nan), as in the one-marking evaluator.

:func:`compile_expr` binds the place names to the columns of a marking array and returns a
:class:`Compiled` evaluator: ``f(markings)`` with markings of shape (n, |P|) gives an (n,) array, with
shape (|P|,) a scalar array; one numpy operation per node of the expression, whatever n is.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from coordinator.expr import ExprError, Node, check_places, parse

__all__ = ["Compiled", "ExprError", "Node", "bind", "compile_expr", "parse"]


Evaluator = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Compiled:
    """A marking expression bound to the columns of a marking array.

    Attributes:
        text: the source text.
        tree: its syntax tree.
        kind: ``"num"`` or ``"bool"``.
        places: the place ids it reads.
    """

    text: str
    tree: Node
    kind: str
    places: tuple[str, ...]
    _fn: Evaluator

    def __call__(self, markings: np.ndarray) -> np.ndarray:
        """Evaluate on markings of shape (n, |P|) → (n,), or (|P|,) → a 0-d array.

        Numbers come back as int64 when only integers were involved, float64 otherwise; truth values
        as bool.
        """
        arr = np.asarray(markings)
        single = arr.ndim == 1
        rows = arr[None, :] if single else arr
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.broadcast_to(self._fn(rows), (rows.shape[0],))
        return out[0] if single else np.ascontiguousarray(out)


def _build(node: Node, index: Mapping[str, int]) -> Evaluator:
    op = node.op
    if op == "num":
        value = node.value
        return lambda m: np.asarray(value)
    if op == "bool":
        flag = bool(node.value)
        return lambda m: np.asarray(flag)
    if op == "place":
        col = index[str(node.value)]
        return lambda m: m[:, col].astype(np.int64)
    fns = [_build(a, index) for a in node.args]
    if op == "neg":
        f = fns[0]
        return lambda m: np.negative(f(m))
    if op == "not":
        f = fns[0]
        return lambda m: np.logical_not(f(m))
    if op in ("min", "max"):
        red = np.minimum if op == "min" else np.maximum
        if len(fns) == 1:
            return fns[0]
        return lambda m: red.reduce(np.broadcast_arrays(*(g(m) for g in fns)))
    ufunc = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "==": np.equal,
             "!=": np.not_equal, "<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal,
             "and": np.logical_and, "or": np.logical_or}[op]
    a, b = fns
    return lambda m: ufunc(a(m), b(m))


def bind(tree: Node, text: str, places: Mapping[str, int] | Sequence[str]) -> Compiled:
    """Bind an already parsed tree to marking columns (as :func:`compile_expr`, without parsing).

    Raises:
        ExprError: an unknown place, with the column and the closest known id.
    """
    index = dict(places) if isinstance(places, Mapping) else {p: i for i, p in enumerate(places)}
    check_places(tree, text, index)
    return Compiled(text=text, tree=tree, kind=tree.kind, places=tuple(tree.places()), _fn=_build(tree, index))


def compile_expr(text: str, places: Mapping[str, int] | Sequence[str], *, kind: str | None = None) -> Compiled:
    """Parse ``text`` and bind it to marking columns.

    Args:
        text: the expression.
        places: place id → column, or the place ids in column order.
        kind: require ``"num"`` or ``"bool"``.

    Returns:
        A :class:`Compiled` evaluator.

    Raises:
        ExprError: syntax, type or unknown-place errors, with the column.
    """
    return bind(parse(text, kind=kind), text, places)
