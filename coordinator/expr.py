"""Marking expressions: a small, safe language over place counts (pure, no I/O, never ``eval``).

One parser serves every use: the reward measures of ``petrobot gspn`` (``P{...}``, ``E{...}``;
docs/gspn.md), the marking-dependent rates and weights of transitions (docs/netfile.md) and the
engine's random switch. This module holds the grammar, the syntax tree, the checks that need only
the net's place ids, and a one-marking evaluator in plain Python (the engine and the simulator
evaluate one marking at a time); :mod:`coordinator.analysis.expr` compiles the same trees to numpy
to evaluate many markings at once. The net model imports this module, so it does not import numpy.

The language::

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
* Two types, checked when the expression is parsed: numbers (from numbers, counts, + − * /,
  min, max) and truth values (from comparisons, and/or/not, true/false). ``and``/``or``/``not`` take
  truth values, arithmetic and comparisons take numbers. Sums, differences and products of counts
  and integers stay exact integers; ``/`` is true division with the IEEE conventions (``x/0`` is
  ±inf, ``0/0`` is nan), in both evaluators.
* Limits, so that a hostile file cannot exhaust the interpreter's stack: at most
  :data:`MAX_LENGTH` characters, :data:`MAX_NESTING` nested brackets, unary signs or ``not``, and a
  syntax tree at most :data:`MAX_DEPTH` deep (``1+1+...+1`` with 300 terms is refused).
* Errors are :class:`ExprError` with the 1-based column of the problem (and the text with a caret).
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import Any

from services.errors import PetrobotError

__all__ = [
    "MAX_DEPTH",
    "MAX_LENGTH",
    "MAX_NESTING",
    "ExprError",
    "Node",
    "Scalar",
    "check_places",
    "evaluate",
    "parse",
    "scalar",
]

#: Longest expression accepted, in characters.
MAX_LENGTH = 4096
#: Most brackets, unary signs and ``not`` nested inside one another.
MAX_NESTING = 48
#: Deepest syntax tree accepted (a chain ``a + b + c`` is as deep as it is long).
MAX_DEPTH = 200

Scalar = int | float | bool
"""The value of an expression on one marking."""


class ExprError(PetrobotError, ValueError):
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
        shown = text if len(text) <= 200 else text[:197] + "..."
        caret = " " * (column - 1) + "^" if column <= len(shown) + 1 else ""
        super().__init__(f"{message} (column {column})\n  {shown}\n  {caret}")


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
        return [str(node.value) for node in self._place_nodes()]

    def _place_nodes(self) -> list[Node]:
        out: list[Node] = []
        seen: set[str] = set()
        stack = [self]
        while stack:
            node = stack.pop()
            if node.op == "place" and str(node.value) not in seen:
                seen.add(str(node.value))
                out.append(node)
            stack.extend(reversed(node.args))
        return out

    def depth(self) -> int:
        """Height of the tree (1 for a leaf), computed without recursion."""
        best = 0
        stack: list[tuple[Node, int]] = [(self, 1)]
        while stack:
            node, level = stack.pop()
            best = max(best, level)
            stack.extend((a, level + 1) for a in node.args)
        return best


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
        self.nesting = 0

    @property
    def tok(self) -> _Tok:
        return self.toks[self.i]

    def error(self, message: str, tok: _Tok | None = None) -> ExprError:
        t = tok or self.tok
        return ExprError(message, t.column, self.text)

    def enter(self, tok: _Tok) -> None:
        self.nesting += 1
        if self.nesting > MAX_NESTING:
            raise self.error(f"brackets, signs and 'not' nested more than {MAX_NESTING} deep", tok)

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
        if node.depth() > MAX_DEPTH:
            raise ExprError(f"the expression is nested more than {MAX_DEPTH} operations deep", 1, self.text)
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
            self.enter(t)
            arg = self.not_()
            self.nesting -= 1
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
            self.enter(t)
            arg = self.need(self.unary(), "num", f"unary '{t.text}'")
            self.nesting -= 1
            return Node("neg", (arg,), column=t.column) if t.text == "-" else arg
        return self.atom()

    def atom(self) -> Node:
        t = self.tok
        if t.kind == "number":
            self.i += 1
            value: float | int = float(t.text) if any(c in t.text for c in ".eE") else int(t.text)
            if isinstance(value, float) and not math.isfinite(value):
                raise self.error(f"number {t.text!r} is too large", t)
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
                self.enter(t)
                self.expect("(", f"'(' after {t.text}")
                args = [self.need(self.or_(), "num", f"{t.text}()")]
                while self.take("op", ","):
                    args.append(self.need(self.or_(), "num", f"{t.text}()"))
                self.expect(")", f"')' or ',' in {t.text}(...)")
                self.nesting -= 1
                return Node(t.text, tuple(args), column=t.column)
            if t.text in ("true", "false"):
                self.i += 1
                return Node("bool", value=t.text == "true", column=t.column)
            if t.text in _KEYWORDS:
                raise self.error(f"'{t.text}' cannot start an operand", t)
            raise self.error(f"unknown name {t.text!r}: write a place count as #{t.text}", t)
        if (t_open := self.take("op", "(")) is not None:
            self.enter(t_open)
            node = self.or_()
            self.expect(")", "')'")
            self.nesting -= 1
            return Node(node.op, node.args, node.value, column=t_open.column)
        if t.kind == "end":
            raise self.error("the expression ends too early")
        raise self.error(f"unexpected {t.text!r}")


def parse(text: str, *, kind: str | None = None) -> Node:
    """Parse and type-check a marking expression (grammar in the module docstring).

    Args:
        text: the expression.
        kind: require ``"num"`` (a number) or ``"bool"`` (a condition).

    Raises:
        ExprError: with the column of the first problem.
    """
    if len(text) > MAX_LENGTH:
        raise ExprError(f"the expression is {len(text)} characters long; the limit is {MAX_LENGTH}", 1, text)
    tree = _Parser(text).parse()
    if kind is not None and tree.kind != kind:
        want = "a number" if kind == "num" else "a condition (a truth value)"
        have = "a number" if tree.kind == "num" else "a truth value"
        raise ExprError(f"expected {want}, but the expression is {have}", tree.column, text)
    return tree


def check_places(tree: Node, text: str, known: Collection[str]) -> None:
    """Check that every ``#place`` of ``tree`` names one of ``known``.

    Raises:
        ExprError: at the column of the first unknown place, with the closest known id suggested.
    """
    for node in tree._place_nodes():
        name = str(node.value)
        if name not in known:
            close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.5)
            hint = f"; did you mean #{close[0]}?" if close else ""
            raise ExprError(f"unknown place {name!r}{hint}", node.column, text)


def _divide(a: Scalar, b: Scalar) -> float:
    if b == 0:
        if a == 0 or (isinstance(a, float) and math.isnan(a)):
            return math.nan
        return math.copysign(math.inf, a) * (math.copysign(1.0, b) if isinstance(b, float) else 1.0)
    return a / b


_BINARY: dict[str, Callable[[Any, Any], Scalar]] = {
    "+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b, "/": _divide,
    "==": lambda a, b: a == b, "!=": lambda a, b: a != b, "<": lambda a, b: a < b, "<=": lambda a, b: a <= b,
    ">": lambda a, b: a > b, ">=": lambda a, b: a >= b,
}


def scalar(tree: Node, key: Callable[[str], Any] = str) -> Callable[[Any], Scalar]:
    """Compile a tree to a plain-Python function of one marking.

    Args:
        tree: a tree from :func:`parse`.
        key: maps a place id to the key the marking is indexed by: the id itself for a mapping
            (the default), or its position for a list of counts.

    Returns:
        ``f(marking)``: ``marking[key(place)]`` is read for each ``#place``; the value is an int when
        only integers were involved, a float otherwise, a bool for a condition.
    """
    op = tree.op
    if op in ("num", "bool"):
        value = tree.value
        return lambda m: value  # type: ignore[return-value]
    if op == "place":
        k = key(str(tree.value))
        return lambda m: int(m[k])
    fns = [scalar(a, key) for a in tree.args]
    if op == "neg":
        f = fns[0]
        return lambda m: -f(m)
    if op == "not":
        f = fns[0]
        return lambda m: not f(m)
    if op == "and":
        f, g = fns
        return lambda m: bool(f(m)) and bool(g(m))
    if op == "or":
        f, g = fns
        return lambda m: bool(f(m)) or bool(g(m))
    if op in ("min", "max"):
        pick = min if op == "min" else max
        return lambda m: _nan_aware(pick, [h(m) for h in fns])
    bin_op = _BINARY[op]
    f, g = fns
    return lambda m: bin_op(f(m), g(m))


def _nan_aware(pick: Callable[[list[Scalar]], Scalar], values: list[Scalar]) -> Scalar:
    """min/max that propagate nan, as numpy's minimum/maximum do."""
    for v in values:
        if isinstance(v, float) and math.isnan(v):
            return math.nan
    return pick(values)


def evaluate(tree: Node, marking: Mapping[str, int]) -> Scalar:
    """Evaluate a tree on one marking (place id → tokens; missing places hold 0)."""
    return scalar(tree, str)(_Defaulting(marking))


class _Defaulting(dict[str, int]):
    """A dict view of a marking where missing places hold 0."""

    def __init__(self, marking: Mapping[str, int]) -> None:
        super().__init__(marking)

    def __missing__(self, key: str) -> int:
        return 0
