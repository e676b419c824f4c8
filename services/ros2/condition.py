"""Conditions on ROS 2 message fields (pure, never ``eval``): success of a result, events from topics.

A condition is a small expression over the fields of one message, true or false: ``data == true``
on a ``std_msgs/msg/Bool``, ``sum > 10`` on an ``AddTwoInts`` response, ``len(sequence) >= 5`` on a
Fibonacci result, ``pose.position.x > 1.5 and not stalled``. The language::

    expr     := or
    or       := and ("or" and)*
    and      := not ("and" not)*
    not      := "not" not | compare
    compare  := sum (("==" | "!=" | "<" | "<=" | ">" | ">=") sum)?
    sum      := product (("+" | "-") product)*
    product  := unary (("*" | "/" | "%") unary)*
    unary    := "-" unary | postfix
    postfix  := primary ("." NAME | "[" expr "]")*
    primary  := NUMBER | STRING | "true" | "false" | ("len" | "abs") "(" expr ")" | NAME | "(" expr ")"

* A ``NAME`` on its own is a field of the message; ``.NAME`` a field of a nested message;
  ``[i]`` an element of an array (``i`` from 0; negative counts from the end).
* ``STRING`` is quoted with ``"`` or ``'`` (``\\"``, ``\\'`` and ``\\\\`` escape); ``NUMBER`` is
  ``3``, ``-2.5``, ``1e-3``.
* Values keep their types, checked when the condition is evaluated: ``and``, ``or`` and ``not``
  take true/false; arithmetic and ``<``, ``<=``, ``>``, ``>=`` take numbers (or two strings for the
  comparisons); ``==`` and ``!=`` compare values of the same kind (numbers with numbers, true/false
  with true/false...); ``len`` takes an array or a string, ``abs`` a number. The whole condition
  must be true or false. A type mismatch, a missing field, an index out of range or a division by
  zero is a :class:`~services.ros2.errors.ConditionError` with the column of the culprit.
* Limits: at most :data:`MAX_LENGTH` characters and :data:`MAX_NESTING` nested brackets or
  operators, so a hostile services.toml cannot exhaust the interpreter.

An *edge* (:class:`Edge`) turns the condition's value on each message into events: ``rising``
(default) fires when it becomes true (the state before the first message counts as false), ``every``
on every message for which it holds.
"""

from __future__ import annotations

import enum
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from services.ros2.errors import ConditionError

__all__ = ["MAX_LENGTH", "MAX_NESTING", "Condition", "Edge", "EdgeDetector"]

MAX_LENGTH = 1024
"""Longest condition accepted, in characters."""
MAX_NESTING = 32
"""Most brackets, unary signs and ``not`` nested in one another."""

_TOKEN = re.compile(r"""
    (?P<space>\s+)
  | (?P<number>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)
  | (?P<string>"(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*')
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<op>==|!=|<=|>=|<|>|\+|-|\*|/|%|\(|\)|\[|\]|\.|,)
""", re.VERBOSE)
_KEYWORDS = frozenset({"and", "or", "not", "true", "false"})
_FUNCTIONS = frozenset({"len", "abs"})


@dataclass(frozen=True, slots=True)
class _Tok:
    kind: str
    text: str
    column: int


@dataclass(frozen=True, slots=True)
class _Node:
    op: str
    args: tuple[Any, ...]
    column: int


def _tokens(text: str) -> list[_Tok]:
    out: list[_Tok] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise ConditionError(f"unexpected character {text[pos]!r}", pos + 1, text)
        kind = m.lastgroup or ""
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
        self.depth = 0

    def peek(self) -> _Tok:
        return self.toks[self.i]

    def take(self) -> _Tok:
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def expect(self, text: str) -> _Tok:
        tok = self.take()
        if tok.text != text or tok.kind == "string":
            raise ConditionError(f"expected {text!r}, found {tok.text or 'the end'!r}", tok.column, self.text)
        return tok

    def nest(self, column: int) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise ConditionError(f"nested deeper than {MAX_NESTING}", column, self.text)

    def is_op(self, *ops: str) -> bool:
        tok = self.peek()
        return tok.kind in ("op", "name") and tok.text in ops

    def parse(self) -> _Node:
        node = self.or_()
        tok = self.peek()
        if tok.kind != "end":
            raise ConditionError(f"unexpected {tok.text!r}", tok.column, self.text)
        return node

    def or_(self) -> _Node:
        node = self.and_()
        while self.is_op("or"):
            tok = self.take()
            node = _Node("or", (node, self.and_()), tok.column)
        return node

    def and_(self) -> _Node:
        node = self.not_()
        while self.is_op("and"):
            tok = self.take()
            node = _Node("and", (node, self.not_()), tok.column)
        return node

    def not_(self) -> _Node:
        if self.is_op("not"):
            tok = self.take()
            self.nest(tok.column)
            node = _Node("not", (self.not_(),), tok.column)
            self.depth -= 1
            return node
        return self.compare()

    def compare(self) -> _Node:
        node = self.sum()
        if self.is_op("==", "!=", "<", "<=", ">", ">="):
            tok = self.take()
            node = _Node(tok.text, (node, self.sum()), tok.column)
            if self.is_op("==", "!=", "<", "<=", ">", ">="):
                tok = self.peek()
                raise ConditionError("chained comparisons are not supported (use 'and')", tok.column, self.text)
        return node

    def sum(self) -> _Node:
        node = self.product()
        while self.is_op("+", "-"):
            tok = self.take()
            node = _Node(tok.text, (node, self.product()), tok.column)
        return node

    def product(self) -> _Node:
        node = self.unary()
        while self.is_op("*", "/", "%"):
            tok = self.take()
            node = _Node(tok.text, (node, self.unary()), tok.column)
        return node

    def unary(self) -> _Node:
        if self.is_op("-"):
            tok = self.take()
            self.nest(tok.column)
            node = _Node("neg", (self.unary(),), tok.column)
            self.depth -= 1
            return node
        return self.postfix()

    def postfix(self) -> _Node:
        node = self.primary()
        while self.is_op(".", "["):
            tok = self.take()
            if tok.text == ".":
                name = self.take()
                if name.kind != "name" or name.text in _KEYWORDS:
                    raise ConditionError("expected a field name after '.'", name.column, self.text)
                node = _Node("field", (node, name.text), name.column)
            else:
                self.nest(tok.column)
                index = self.or_()
                self.depth -= 1
                self.expect("]")
                node = _Node("index", (node, index), tok.column)
        return node

    def primary(self) -> _Node:
        tok = self.take()
        if tok.kind == "number":
            value: Any = float(tok.text) if any(c in tok.text for c in ".eE") else int(tok.text)
            return _Node("const", (value,), tok.column)
        if tok.kind == "string":
            return _Node("const", (_unquote(tok.text),), tok.column)
        if tok.kind == "name":
            if tok.text in ("true", "false"):
                return _Node("const", (tok.text == "true",), tok.column)
            if tok.text in _KEYWORDS:
                raise ConditionError(f"unexpected {tok.text!r}", tok.column, self.text)
            if tok.text in _FUNCTIONS and self.is_op("("):
                self.take()
                self.nest(tok.column)
                arg = self.or_()
                self.depth -= 1
                self.expect(")")
                return _Node(tok.text, (arg,), tok.column)
            return _Node("name", (tok.text,), tok.column)
        if tok.text == "(" and tok.kind == "op":
            self.nest(tok.column)
            node = self.or_()
            self.depth -= 1
            self.expect(")")
            return node
        raise ConditionError(f"expected a value, found {tok.text or 'the end'!r}", tok.column, self.text)


def _unquote(text: str) -> str:
    body = text[1:-1]
    return re.sub(r"\\(.)", lambda m: m.group(1), body)


def _kind(value: Any) -> str:
    if type(value) is bool:
        return "true/false"
    if type(value) in (int, float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, (list, tuple)):
        return "array"
    if isinstance(value, Mapping):
        return "message"
    return type(value).__name__


class Condition:
    """A parsed condition (see the module docstring).

    Args:
        text: the condition.

    Raises:
        ConditionError: a syntax error, too long, or nested too deep (with the column).
    """

    __slots__ = ("_tree", "text")

    def __init__(self, text: str) -> None:
        if not isinstance(text, str) or not text.strip():
            raise ConditionError("a condition must be a non-empty string", 0, str(text))
        if len(text) > MAX_LENGTH:
            raise ConditionError(f"longer than {MAX_LENGTH} characters", 0, text[:40] + "...")
        self.text = text
        self._tree = _Parser(text).parse()

    def __repr__(self) -> str:
        return f"Condition({self.text!r})"

    def paths(self) -> list[tuple[str, ...]]:
        """The field paths the condition reads, each up to its first index (``pose.position.x`` →
        ``("pose", "position", "x")``; ``sequence[0]`` → ``("sequence",)``), for checking them
        against the message type when services.toml is loaded."""
        out: list[tuple[str, ...]] = []

        def path_of(node: _Node) -> tuple[str, ...] | None:
            if node.op == "name":
                return (node.args[0],)
            if node.op == "field":
                base = path_of(node.args[0])
                return None if base is None else (*base, node.args[1])
            return None

        def walk(node: _Node) -> None:
            path = path_of(node)
            if path is not None:
                out.append(path)
                return
            for arg in node.args:
                if isinstance(arg, _Node):
                    walk(arg)

        walk(self._tree)
        return out

    def evaluate(self, fields: Mapping[str, Any]) -> bool:
        """The condition's value on a message.

        Args:
            fields: the message's fields (nested messages as mappings, arrays as lists).

        Raises:
            ConditionError: a missing field, a type mismatch, an index out of range, a division by
                zero, or a value that is not true/false.
        """
        value = self._eval(self._tree, fields)
        if type(value) is not bool:
            raise ConditionError(f"the condition gives a {_kind(value)}, not true or false", 0, self.text)
        return value

    def _fail(self, message: str, node: _Node) -> ConditionError:
        return ConditionError(message, node.column, self.text)

    def _eval(self, node: _Node, fields: Mapping[str, Any]) -> Any:
        op, args = node.op, node.args
        if op == "const":
            return args[0]
        if op == "name":
            if args[0] not in fields:
                raise self._fail(f"the message has no field {args[0]!r} (its fields: {', '.join(fields)})", node)
            return fields[args[0]]
        if op == "field":
            base = self._eval(args[0], fields)
            if not isinstance(base, Mapping):
                raise self._fail(f"'.{args[1]}' on a {_kind(base)}, not a message", node)
            if args[1] not in base:
                raise self._fail(f"no field {args[1]!r} (fields: {', '.join(base)})", node)
            return base[args[1]]
        if op == "index":
            base = self._eval(args[0], fields)
            index = self._eval(args[1], fields)
            if not isinstance(base, (list, tuple, str)):
                raise self._fail(f"indexing a {_kind(base)}, not an array", node)
            if type(index) is not int:
                raise self._fail(f"an index must be an integer, got a {_kind(index)}", node)
            if not -len(base) <= index < len(base):
                raise self._fail(f"index {index} out of range ({len(base)} elements)", node)
            return base[index]
        if op in ("and", "or"):
            left = self._truth(args[0], fields)
            if (op == "and" and not left) or (op == "or" and left):
                return left
            return self._truth(args[1], fields)
        if op == "not":
            return not self._truth(args[0], fields)
        if op == "neg":
            return -self._number(args[0], fields)
        if op in ("len", "abs"):
            value = self._eval(args[0], fields)
            if op == "len":
                if not isinstance(value, (list, tuple, str)):
                    raise self._fail(f"len() of a {_kind(value)}", node)
                return len(value)
            if _kind(value) != "number":
                raise self._fail(f"abs() of a {_kind(value)}", node)
            return abs(value)
        if op in ("==", "!="):
            left, right = self._eval(args[0], fields), self._eval(args[1], fields)
            if _kind(left) != _kind(right):
                raise self._fail(f"comparing a {_kind(left)} with a {_kind(right)}", node)
            return (left == right) == (op == "==")
        if op in ("<", "<=", ">", ">="):
            left, right = self._eval(args[0], fields), self._eval(args[1], fields)
            kinds = (_kind(left), _kind(right))
            if kinds not in (("number", "number"), ("string", "string")):
                raise self._fail(f"ordering a {kinds[0]} and a {kinds[1]}", node)
            return {"<": left < right, "<=": left <= right, ">": left > right, ">=": left >= right}[op]
        left, right = self._number(args[0], fields), self._number(args[1], fields)
        if op == "+":
            return left + right
        if op == "-":
            return left - right
        if op == "*":
            return left * right
        if right == 0:
            raise self._fail("division by zero", node)
        if op == "/":
            return left / right
        return math.fmod(left, right) if isinstance(left, float) or isinstance(right, float) else left % right

    def _truth(self, node: _Node, fields: Mapping[str, Any]) -> bool:
        value = self._eval(node, fields)
        if type(value) is not bool:
            raise self._fail(f"expected true/false, got a {_kind(value)}", node)
        return value

    def _number(self, node: _Node, fields: Mapping[str, Any]) -> Any:
        value = self._eval(node, fields)
        if _kind(value) != "number":
            raise self._fail(f"expected a number, got a {_kind(value)}", node)
        return value


class Edge(enum.StrEnum):
    """When a condition on a stream of messages raises an event."""

    RISING = "rising"
    """When the condition becomes true (it counts as false before the first message)."""
    EVERY = "every"
    """On every message for which the condition holds."""


class EdgeDetector:
    """Turns a condition's successive values into events (:class:`Edge`)."""

    __slots__ = ("edge", "previous")

    def __init__(self, edge: Edge = Edge.RISING) -> None:
        self.edge = edge
        self.previous = False

    def update(self, value: bool) -> bool:
        """Feed the condition's value on the next message; True if an event is raised now."""
        fire = value and (self.edge is Edge.EVERY or not self.previous)
        self.previous = value
        return fire
