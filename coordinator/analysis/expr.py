"""Marking expressions: a small, safe language over place counts, compiled once and evaluated on
many markings at a time (pure, no I/O; never ``eval``).

Used by the reward measures of ``petrobot gspn`` (``P{...}``, ``E{...}``; docs/gspn.md) and meant
for marking-dependent rates and weights. The language::

    expr    := or
    or      := and ("or" and)*
    and     := not ("and" not)*
    not     := "not" not | compare
    compare := sum (("==" | "!=" | "<" | "<=" | ">" | ">=") sum)*     chains: a < b < c means a < b and b < c
    sum     := product (("+" | "-") product)*
    product := unary (("*" | "/") unary)*
    unary   := ("-" | "+") unary | atom
    atom    := NUMBER | "#" PLACE | ("min" | "max") "(" expr ("," expr)* ")" | "(" expr ")" | "true" | "false"

* ``NUMBER``: ``3``, ``2.5``, ``1e-3``; ``#p`` is the token count of place p (an id made of letters,
  digits, ``_`` and ``.``; ids with other characters are quoted: ``#"arm-left"``).
* Two types, checked when the expression is compiled: numbers (from numbers, counts, + − * /,
  min, max) and truth values (from comparisons, and/or/not, true/false). ``and``/``or``/``not`` take
  truth values, arithmetic and comparisons take numbers. Sums, differences and products of counts
  and integers stay exact integers (int64); ``/`` is true division (IEEE: ``x/0`` is ±inf or nan).
* Errors are :class:`ExprError` with the 1-based column of the problem (and the text with a caret).

:func:`compile_expr` binds the place names to the columns of a marking array and returns a
:class:`Compiled` evaluator: ``f(markings)`` with markings of shape (n, |P|) gives an (n,) array, with
shape (|P|,) a scalar array; one numpy operation per node of the expression, whatever n is.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Compiled", "ExprError", "Node", "compile_expr", "parse"]


class ExprError(ValueError):
    """A syntax, type or name error in a marking expression.

    Attributes:
        message: what is wrong.
        column: 1-based column in ``text`` where the problem is.
        text: the expression.
    """

    def __init__(self, message: str, column: int, text: str) -> None:
        self.message = message
        self.column = column
        self.text = text
        super().__init__(f"{message} (column {column})\n  {text}\n  {' ' * (column - 1)}^")


@dataclass(frozen=True)
class Node:
    """A node of the syntax tree.

    Attributes:
        op: ``num``, ``place``, ``bool``, ``neg``, ``+``, ``-``, ``*``, ``/``, ``min``, ``max``,
            ``==``, ``!=``, ``<``, ``<=``, ``>``, ``>=``, ``and``, ``or``, ``not``.
        args: operands.
        value: the number (``num``), the place id (``place``) or the truth value (``bool``).
        column: 1-based column where the node's text starts (its left operand for binary nodes).
    """

    op: str
    args: tuple[Node, ...] = ()
    value: float | int | str | bool | None = None
    column: int = 1

    @property
    def kind(self) -> str:
        """``"num"`` or ``"bool"``: the type of the value (the tree is type-checked by :func:`parse`)."""
        if self.op in ("num", "place", "neg", "+", "-", "*", "/", "min", "max"):
            return "num"
        return "bool"

    def places(self) -> list[str]:
        """Place ids the expression reads, in order of first appearance."""
        out: list[str] = []
        stack = [self]
        while stack:
            node = stack.pop()
            if node.op == "place" and node.value not in out:
                out.append(str(node.value))
            stack.extend(reversed(node.args))
        return out


_TOKEN = re.compile(r"""
    (?P<space>\s+)
  | (?P<number>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)
  | (?P<place>\#(?:"[^"]*"|[A-Za-z_][A-Za-z0-9_.]*)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<op>==|!=|<=|>=|[-+*/(),<>])
""", re.VERBOSE)
_COMPARE = ("==", "!=", "<", "<=", ">", ">=")
_KEYWORDS = ("and", "or", "not", "min", "max", "true", "false")


@dataclass(frozen=True)
class _Tok:
    kind: str  # number, place, name, op, end
    text: str
    column: int


def _tokens(text: str) -> list[_Tok]:
    out: list[_Tok] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise ExprError(f"unexpected character {text[pos]!r}", pos + 1, text)
        kind = m.lastgroup or ""
        if kind == "place" and len(m.group()) == 1:
            raise ExprError("'#' must be followed by a place id, e.g. #p1 or #\"arm-left\"", pos + 1, text)
        if kind != "space":
            out.append(_Tok(kind, m.group(), pos + 1))
        pos = m.end()
    out.append(_Tok("end", "", len(text) + 1))
    return out


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.toks = _tokens(text)
        self.i = 0

    @property
    def tok(self) -> _Tok:
        return self.toks[self.i]

    def error(self, message: str, tok: _Tok | None = None) -> ExprError:
        t = tok or self.tok
        return ExprError(message, t.column, self.text)

    def take(self, kind: str, text: str | None = None) -> _Tok | None:
        t = self.tok
        if t.kind == kind and (text is None or t.text == text):
            self.i += 1
            return t
        return None

    def expect(self, text: str, what: str) -> _Tok:
        t = self.take("op", text)
        if t is None:
            found = "the end" if self.tok.kind == "end" else repr(self.tok.text)
            raise self.error(f"expected {what}, found {found}")
        return t

    def need(self, node: Node, kind: str, what: str) -> Node:
        if node.kind != kind:
            have = "a number" if node.kind == "num" else "a truth value"
            want = "a number" if kind == "num" else "a truth value (a comparison, and/or/not)"
            raise ExprError(f"{what} needs {want}, not {have}", node.column, self.text)
        return node

    def parse(self) -> Node:
        if self.tok.kind == "end":
            raise self.error("empty expression")
        node = self.or_()
        if self.tok.kind != "end":
            raise self.error(f"unexpected {self.tok.text!r} after a complete expression")
        return node

    def or_(self) -> Node:
        node = self.and_()
        while self.take("name", "or") is not None:
            right = self.and_()
            node = Node("or", (self.need(node, "bool", "'or'"), self.need(right, "bool", "'or'")), column=node.column)
        return node

    def and_(self) -> Node:
        node = self.not_()
        while self.take("name", "and") is not None:
            right = self.not_()
            node = Node("and", (self.need(node, "bool", "'and'"), self.need(right, "bool", "'and'")),
                        column=node.column)
        return node

    def not_(self) -> Node:
        t = self.take("name", "not")
        if t is not None:
            arg = self.not_()
            return Node("not", (self.need(arg, "bool", "'not'"),), column=t.column)
        return self.compare()

    def compare(self) -> Node:
        left = self.sum_()
        parts: list[Node] = []
        while self.tok.kind == "op" and self.tok.text in _COMPARE:
            t = self.tok
            self.i += 1
            right = self.sum_()
            self.need(left, "num", f"'{t.text}'")
            self.need(right, "num", f"'{t.text}'")
            parts.append(Node(t.text, (left, right), column=left.column))
            left = right
        if not parts:
            return left
        node = parts[0]
        for p in parts[1:]:
            node = Node("and", (node, p), column=node.column)
        return node

    def sum_(self) -> Node:
        node = self.product()
        while self.tok.kind == "op" and self.tok.text in ("+", "-"):
            t = self.tok
            self.i += 1
            right = self.product()
            node = Node(t.text, (self.need(node, "num", f"'{t.text}'"), self.need(right, "num", f"'{t.text}'")),
                        column=node.column)
        return node

    def product(self) -> Node:
        node = self.unary()
        while self.tok.kind == "op" and self.tok.text in ("*", "/"):
            t = self.tok
            self.i += 1
            right = self.unary()
            node = Node(t.text, (self.need(node, "num", f"'{t.text}'"), self.need(right, "num", f"'{t.text}'")),
                        column=node.column)
        return node

    def unary(self) -> Node:
        t = self.take("op", "-") or self.take("op", "+")
        if t is not None:
            arg = self.need(self.unary(), "num", f"unary '{t.text}'")
            return Node("neg", (arg,), column=t.column) if t.text == "-" else arg
        return self.atom()

    def atom(self) -> Node:
        t = self.tok
        if t.kind == "number":
            self.i += 1
            value: float | int = float(t.text) if any(c in t.text for c in ".eE") else int(t.text)
            return Node("num", value=value, column=t.column)
        if t.kind == "place":
            self.i += 1
            name = t.text[1:]
            if name.startswith('"'):
                name = name[1:-1]
                if not name:
                    raise self.error("empty place id", t)
            return Node("place", value=name, column=t.column)
        if t.kind == "name":
            if t.text in ("min", "max"):
                self.i += 1
                self.expect("(", f"'(' after {t.text}")
                args = [self.need(self.or_(), "num", f"{t.text}()")]
                while self.take("op", ","):
                    args.append(self.need(self.or_(), "num", f"{t.text}()"))
                self.expect(")", f"')' or ',' in {t.text}(...)")
                return Node(t.text, tuple(args), column=t.column)
            if t.text in ("true", "false"):
                self.i += 1
                return Node("bool", value=t.text == "true", column=t.column)
            if t.text in _KEYWORDS:
                raise self.error(f"'{t.text}' cannot start an operand", t)
            raise self.error(f"unknown name {t.text!r}: write a place count as #{t.text}", t)
        if (t_open := self.take("op", "(")) is not None:
            node = self.or_()
            self.expect(")", "')'")
            return Node(node.op, node.args, node.value, column=t_open.column)
        if t.kind == "end":
            raise self.error("the expression ends too early")
        raise self.error(f"unexpected {t.text!r}")


def parse(text: str) -> Node:
    """Parse and type-check a marking expression (grammar in the module docstring).

    Raises:
        ExprError: with the column of the first problem.
    """
    return _Parser(text).parse()


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


def _build(node: Node, index: Mapping[str, int], text: str) -> Evaluator:
    op = node.op
    if op == "num":
        value = node.value
        return lambda m: np.asarray(value)
    if op == "bool":
        flag = bool(node.value)
        return lambda m: np.asarray(flag)
    if op == "place":
        name = str(node.value)
        if name not in index:
            close = difflib.get_close_matches(name, list(index), n=1, cutoff=0.5)
            hint = f"; did you mean #{close[0]}?" if close else ""
            raise ExprError(f"unknown place {name!r}{hint}", node.column, text)
        col = index[name]
        return lambda m: m[:, col].astype(np.int64)
    fns = [_build(a, index, text) for a in node.args]
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
    index = dict(places) if isinstance(places, Mapping) else {p: i for i, p in enumerate(places)}
    tree = parse(text)
    if kind is not None and tree.kind != kind:
        want = "a number" if kind == "num" else "a condition (a truth value)"
        have = "a number" if tree.kind == "num" else "a truth value"
        raise ExprError(f"expected {want}, but the expression is {have}", tree.column, text)
    fn = _build(tree, index, text)
    return Compiled(text=text, tree=tree, kind=tree.kind, places=tuple(tree.places()), _fn=fn)
