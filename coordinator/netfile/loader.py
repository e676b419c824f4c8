"""Loading a TOML net file, with every problem at its file and line (docs/netfile.md).

A net file describes an interpreted Petri net of a robotic task (paper section 2): ``[net]``,
``[[place]]`` tables, ``[task.<name>]`` tables mapping each primitive task to its alternative
primitive actions, ``[[transition]]`` tables whose ``inputs``/``outputs``/``inhibitors`` tables
give the arcs, and optionally ``[[arc]]`` tables (``from``/``to``/``weight``/``inhibitor``/``reset``).
A transition's ``rate`` and ``weight`` are numbers or marking expressions (strings in the language of
:mod:`coordinator.expr`); an expression's problems are reported at the line of its key with their
column, and one that is negative, zero (a weight) or not finite in the initial marking, where its
transition is enabled, is reported too.

Every problem is a :class:`~coordinator.errors.NetError` naming the file, the 1-based line
(:class:`~coordinator.netfile.source_map.SourceMap`) and the problem. A primitive task's
``learner`` table is checked here too (section 4, :func:`coordinator.learning.validation.learner_spec`).

The module is longer than most: one loader walks the whole document so that every problem is
collected with its line, instead of stopping at the first.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

from coordinator.errors import NetError, NetFileError
from coordinator.expr import MAX_LENGTH as MAX_EXPRESSION
from coordinator.expr import ExprError, Node, check_places, parse
from coordinator.learning.validation import learner_spec
from coordinator.net import (
    ActionSpec,
    Arc,
    Marking,
    OperatorRights,
    PetriNet,
    Place,
    PlaceKind,
    PrimitiveTask,
    Transition,
    TransitionKind,
)
from coordinator.netfile.layout import position_problem
from coordinator.netfile.limits import (
    MAX_DESCRIPTION,
    MAX_LABEL,
    MAX_NAME,
    count_problem,
    event_problem,
    finite_problem,
    id_problem,
    priority_problem,
    task_name_problem,
    text_problem,
)
from coordinator.netfile.schema import (
    ACTION_KEYS,
    ARC_KEYS,
    FORMAT_VERSION,
    NET_KEYS,
    OPERATOR_KEYS,
    PLACE_KEYS,
    TASK_KEYS,
    TOP_KEYS,
    TRANSITION_KEYS,
)
from coordinator.netfile.source_map import SourceMap
from services.textfile import TextProblem, decode_utf8, read_capped
from services.tomllines import parse_toml

__all__ = ["lint_net", "load_net", "loads_net", "read_text"]

_T = TypeVar("_T")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_num(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _brief(value: Any) -> str:
    """``repr`` of a value, cut to a length fit for one line of a message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _type_name(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a float", str: "a string", list: "an array",
            dict: "a table"}.get(type(value), type(value).__name__)


class _Skip(Exception):
    """The current element is unusable; its problem is already recorded."""


class _Loader:
    """Turns a parsed TOML document into a net, collecting every problem with its line."""

    def __init__(self, doc: dict[str, Any], smap: SourceMap, path: str) -> None:
        self.doc = doc
        self.smap = smap
        self.path = path
        self.problems: list[NetError] = []
        self.declared: dict[str, set[str]] = {"place": set(), "transition": set()}
        self.seen: dict[str, set[str]] = {"place": set(), "transition": set()}
        # (transition index, key, tree, text) of every rate or weight expression, checked against
        # the places once they are all known
        self.expressions: list[tuple[int, str, Node, str]] = []
        self.transition_rows: dict[str, int] = {}

    # ---------------------------------------------------------------- reporting
    def report(self, problem: str, line: int | None) -> None:
        self.problems.append(NetError(problem, path=self.path, line=line))

    def fail(self, problem: str, line: int | None) -> _Skip:
        self.report(problem, line)
        return _Skip()

    def check_keys(self, table: Mapping[str, Any], allowed: tuple[str, ...], what: str,
                   section: str, ident: Any) -> None:
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f" (known keys: {', '.join(allowed)})"
                self.report(f"unknown key {_brief(key)} in {what}{hint}", self.smap.key(section, ident, key))

    def get(self, table: Mapping[str, Any], key: str, kind: str, what: str, section: str, ident: Any,
            default: Any = None) -> Any:
        """Fetch ``table[key]`` checking its type; ``kind`` is str|int|num|bool|table|array|numexpr."""
        if key not in table:
            return default
        value = table[key]
        ok = {"str": isinstance(value, str), "int": _is_int(value), "num": _is_num(value),
              "bool": isinstance(value, bool), "table": isinstance(value, dict),
              "array": isinstance(value, list), "numexpr": _is_num(value) or isinstance(value, str)}[kind]
        if not ok:
            wanted = {"str": "a string", "int": "an integer", "num": "a number", "bool": "true or false",
                      "table": "a table", "array": "an array",
                      "numexpr": "a number or a marking expression (a string)"}[kind]
            raise self.fail(f"{key} of {what} must be {wanted}, not {_type_name(value)} ({_brief(value)})",
                            self.smap.key(section, ident, key))
        return value

    def check(self, problem: str | None, line: int | None) -> None:
        """Raise :class:`_Skip` after recording ``problem``, if there is one."""
        if problem is not None:
            raise self.fail(problem, line)

    def real(self, table: Mapping[str, Any], key: str, what: str, section: str, ident: Any,
             default: Any = None) -> Any:
        """Fetch a finite number (TOML allows ``inf`` and ``nan``; no field of a net does)."""
        value = self.get(table, key, "num", what, section, ident, default)
        if value is not None:
            self.check(finite_problem(value, f"{key} of {what}"), self.smap.key(section, ident, key))
        return value

    def number_or_expression(self, table: Mapping[str, Any], key: str, what: str, index: int,
                             default: float | None) -> tuple[float | None, str | None]:
        """Fetch a transition's ``rate`` or ``weight``: ``(number, None)`` or ``(None, expression)``;
        the expression is parsed and type-checked here (its places are checked later)."""
        value = self.get(table, key, "numexpr", what, "transition", index, default)
        line = self.smap.key("transition", index, key)
        if not isinstance(value, str):
            if value is not None:
                self.check(finite_problem(value, f"{key} of {what}"), line)
            return value, None
        self.check(text_problem(value, f"{key} expression of {what}", MAX_EXPRESSION), line)
        try:
            tree = parse(value, kind="num")
        except ExprError as exc:
            raise self.fail(f"{key} of {what}: {exc.message} (column {exc.column} of {_brief(value)})",
                            line) from None
        self.expressions.append((index, key, tree, value))
        return None, value

    def check_expressions(self, places: Mapping[str, Place]) -> None:
        """Report the rate and weight expressions that name places the net does not have."""
        known = set(places) | self.declared["place"]
        for index, key, tree, text in self.expressions:
            try:
                check_places(tree, text, known)
            except ExprError as exc:
                tid = self.doc["transition"][index].get("id")
                self.report(f"{key} of transition {tid!r}: {exc.message} (column {exc.column} of {_brief(text)})",
                            self.smap.key("transition", index, key))

    def text(self, table: Mapping[str, Any], key: str, what: str, section: str, ident: Any,
             default: str, limit: int, lines: bool = False) -> str:
        """Fetch a string of at most ``limit`` characters without control characters."""
        value: str = self.get(table, key, "str", what, section, ident, default)
        self.check(text_problem(value, f"{key} of {what}", limit, lines=lines), self.smap.key(section, ident, key))
        return value

    def position(self, table: Mapping[str, Any], what: str, section: str, ident: Any) -> None:
        """Check the drawing position ``pos = [x, y]`` (kept in the file, not in the net: layout.py)."""
        if "pos" in table:
            self.check(position_problem(table["pos"], what), self.smap.key(section, ident, "pos"))

    def build(self, line: int | None, make: Callable[[], _T]) -> _T:
        """Call a model constructor; turn its NetError into a problem at ``line``."""
        try:
            return make()
        except NetError as exc:
            raise self.fail(exc.problem, line) from None

    # ---------------------------------------------------------------- top level
    def load(self, default_name: str, interpreted: bool) -> PetriNet | None:
        doc = self.doc
        if not doc:
            self.report("no net in this file: it has no [net] table and no [[place]]; see docs/netfile.md", 1)
            return None
        for key in doc:
            if key not in TOP_KEYS:
                close = difflib.get_close_matches(key, TOP_KEYS, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(TOP_KEYS)})"
                line = self.smap.elements.get((key, None))
                self.report(f"unknown section {_brief(key)}{hint}", line or self._find_header(key))
        for key, kind in (("net", dict), ("task", dict), ("place", list), ("transition", list), ("arc", list),
                          ("operator", dict)):
            if key in doc and not isinstance(doc[key], kind):
                form = f"[{key}]" if kind is dict else f"[[{key}]]"
                self.report(f"{key} must be written as {form} table(s)", self._find_header(key))
                return None
        if not doc.get("place"):
            self.report("the net has no places: add at least one [[place]]",
                        self.smap.elements.get(("net", None)) or self._find_header(next(iter(doc))))
        for section in self.declared:  # ids of every element, usable or not: no cascade of "unknown id"
            self.declared[section] = {t["id"] for t in doc.get(section, [])
                                      if isinstance(t, dict) and isinstance(t.get("id"), str)}
        name, description, home = self.load_header(default_name)
        tasks = self.load_tasks()
        places, marking = self.load_places()
        transitions = self.load_transitions()
        for tid in transitions:
            if tid in places:
                self.report(f"id {tid!r} is both a place and a transition; ids must be unique across both",
                            self.smap.ids.get(("transition", tid)))
        arcs = self.load_arcs(places, transitions)
        self.check_places(places, tasks)
        self.check_expressions(places)
        if home is not None:
            for pid in home:
                if pid not in places and pid not in self.declared["place"]:
                    self.report(f"home marking of [net] puts tokens in unknown place {pid!r}",
                                self.smap.key("net", None, "home"))
        operator = self.load_operator(tasks, transitions)
        if self.problems:
            return None
        try:
            net = PetriNet(name=name, places=tuple(places.values()), transitions=tuple(transitions.values()),
                           arcs=tuple(arcs), initial_marking=marking, tasks=tasks, description=description,
                           home_marking=home, operator=operator)
        except NetError as exc:
            self.report(exc.problem, None)
            return None
        for tid, key, problem in net.expression_problems():
            self.report(problem, self.smap.key("transition", self.transition_rows[tid], key))
        if interpreted:
            for ident, problem in net.interpretation_problems():
                self.report(problem, self.smap.of_id(ident))
        return None if self.problems else net

    def _find_header(self, key: str) -> int | None:
        for (section, _), line in sorted(self.smap.elements.items(), key=lambda kv: kv[1]):
            if section == key:
                return line
        return None

    def load_header(self, default_name: str) -> tuple[str, str, Marking | None]:
        table = self.doc.get("net", {})
        self.check_keys(table, NET_KEYS, "[net]", "net", None)
        name, description, home = default_name, "", None
        try:
            name = self.text(table, "name", "[net]", "net", None, default_name, MAX_NAME)
            description = self.text(table, "description", "[net]", "net", None, "", MAX_DESCRIPTION, lines=True)
            version = self.get(table, "format", "int", "[net]", "net", None, FORMAT_VERSION)
            if version != FORMAT_VERSION:
                self.report(f"net file format {version} is not supported (this reader knows format "
                            f"{FORMAT_VERSION})", self.smap.key("net", None, "format"))
            home_table = self.get(table, "home", "table", "[net]", "net", None)
            if home_table is not None:
                home = self.marking_table(home_table, "home of [net]", "net", None, "home")
        except _Skip:
            pass
        return name, description, home

    def marking_table(self, table: Mapping[str, Any], what: str, section: str, ident: Any, key: str) -> Marking:
        line = self.smap.key(section, ident, key)
        for place, count in table.items():
            if not _is_int(count) or count < 0:
                raise self.fail(f"{what}: token count of {_brief(place)} must be an integer >= 0, not "
                                f"{_brief(count)}", line)
            self.check(count_problem(count, f"{what}: token count of {_brief(place)}", 0), line)
        return Marking(table)

    # ---------------------------------------------------------------- what an operator may force
    def load_operator(self, tasks: Mapping[str, PrimitiveTask], transitions: Mapping[str, Transition]
                      ) -> OperatorRights:
        """``[operator]``: the external events an operator may raise and the outcomes they may force."""
        table = self.doc.get("operator", {})
        self.check_keys(table, OPERATOR_KEYS, "[operator]", "operator", None)
        inject: list[str] = []
        force: dict[str, tuple[str, ...]] = {}
        linked = {e for t in transitions.values() for e in t.external_events}
        try:
            events = self.get(table, "inject", "array", "[operator]", "operator", None, [])
            line = self.smap.key("operator", None, "inject")
            for event in events:
                if not isinstance(event, str) or not event.startswith("ext:") or event_problem(event) is not None:
                    self.report(f"inject of [operator] names {_brief(event)}: only external events (ext:<topic>) "
                                "can be raised by the operator", line)
                elif event not in linked:
                    known = ", ".join(sorted(linked)) or "none"
                    self.report(f"inject of [operator] names {event!r}, which no transition links (external "
                                f"events: {known})", line)
                else:
                    inject.append(event)
        except _Skip:
            pass
        try:
            outcomes = self.get(table, "force", "table", "[operator]", "operator", None, {})
            line = self.smap.key("operator", None, "force")
            for task, listed in outcomes.items():
                if task not in tasks:
                    if task not in self.doc.get("task", {}):
                        known = ", ".join(sorted(tasks)) or "none defined"
                        self.report(f"force of [operator] names unknown task {task!r} (tasks: {known})", line)
                    continue
                if not isinstance(listed, list) or not listed:
                    self.report(f"force of [operator]: the outcomes of task {task!r} must be a non-empty array, "
                                f"e.g. [\"success\", \"failure\", \"error\"]", line)
                    continue
                good = []
                for outcome in listed:
                    try:
                        OperatorRights(force={task: (outcome,)})
                    except NetError as exc:
                        self.report(f"force of [operator]: {exc.problem}", line)
                        continue
                    good.append(outcome)
                force[task] = tuple(dict.fromkeys(good))
        except _Skip:
            pass
        return OperatorRights(inject=tuple(dict.fromkeys(inject)), force=force)

    # ---------------------------------------------------------------- tasks
    def load_tasks(self) -> dict[str, PrimitiveTask]:
        tasks: dict[str, PrimitiveTask] = {}
        for name, table in self.doc.get("task", {}).items():
            try:
                tasks[name] = self.load_task(name, table)
            except _Skip:
                continue
        return tasks

    def load_task(self, name: str, table: Any) -> PrimitiveTask:
        line = self.smap.elements.get(("task", name))
        self.check(task_name_problem(name), line)
        what = f"[task.{name}]"
        if not isinstance(table, dict):
            raise self.fail(f"{what} must be a table", line)
        self.check_keys(table, TASK_KEYS, what, "task", name)
        if "actions" not in table:
            raise self.fail(f"{what} has no actions: list its alternative primitive actions", line)
        actions_value = self.get(table, "actions", "array", what, "task", name)
        common = self.get(table, "params", "table", what, "task", name, {})
        actions_line = self.smap.key("task", name, "actions")
        actions: list[ActionSpec] = []
        for item in actions_value:
            if isinstance(item, str):
                spec: dict[str, Any] = {"name": item}
            elif isinstance(item, dict):
                spec = item
                for key in item:
                    if key not in ACTION_KEYS:
                        close = difflib.get_close_matches(key, ACTION_KEYS, n=1)
                        hint = f"; did you mean {close[0]!r}?" if close else ""
                        raise self.fail(f"unknown key {_brief(key)} in an action of {what}{hint}", actions_line)
            else:
                raise self.fail(f"actions of {what} must be names or tables {{ name = ..., params = ..., "
                                f"cost = ... }}, not {_type_name(item)}", actions_line)
            action_name = spec.get("name")
            params = spec.get("params", {})
            cost = spec.get("cost")
            if not isinstance(action_name, str):
                raise self.fail(f"an action of {what} has no name (a string)", actions_line)
            self.check(id_problem(action_name, f"action of {what}"), actions_line)
            if not isinstance(params, dict):
                raise self.fail(f"params of action {action_name!r} in {what} must be a table", actions_line)
            if cost is not None and (not _is_num(cost) or not 0 <= cost < float("inf")):
                raise self.fail(f"cost of action {action_name!r} in {what} must be a finite number >= 0, "
                                f"not {_brief(cost)}", actions_line)
            merged = {**common, **params}
            actions.append(self.build(actions_line, partial(
                ActionSpec, name=action_name, params=merged, cost=None if cost is None else float(cost))))
        values: dict[str, float | None] = {}
        for key in ("deadline_s", "mean_time_s", "reliability"):
            value = self.real(table, key, what, "task", name)
            if value is not None and not (0 <= value <= 1 if key == "reliability" else value > 0):
                wanted = "in [0, 1]" if key == "reliability" else "> 0"
                raise self.fail(f"{key} of {what} is {value}; it must be {wanted}", self.smap.key("task", name, key))
            values[key] = None if value is None else float(value)
        learner = self.get(table, "learner", "table", what, "task", name, {})
        if learner:  # section 4: reject a bad learner configuration here, with its line
            costs = {a.name: a.cost for a in actions if a.cost is not None}
            self.build(self.smap.key("task", name, "learner") or line,
                       lambda: learner_spec(learner, [a.name for a in actions], costs or None))
        return self.build(line, lambda: PrimitiveTask(name=name, actions=tuple(actions), learner=learner, **values))

    # ---------------------------------------------------------------- places
    def load_places(self) -> tuple[dict[str, Place], Marking]:
        places: dict[str, Place] = {}
        marking: dict[str, int] = {}
        for index, table in enumerate(self.doc.get("place", [])):
            try:
                place, tokens = self.load_place(index, table, places)
            except _Skip:
                continue
            places[place.id] = place
            if tokens:
                marking[place.id] = tokens
        return places, Marking(marking)

    def element_id(self, section: str, index: int, table: Mapping[str, Any], taken: Mapping[str, Any]) -> str:
        header = self.smap.elements.get((section, index))
        if "id" not in table:
            raise self.fail(f"a [[{section}]] has no id", header)
        ident = table["id"]
        line = self.smap.element(section, index)
        if not isinstance(ident, str):
            raise self.fail(f"id of a [[{section}]] must be a string, not {_type_name(ident)}", line)
        self.check(id_problem(ident, section), line)
        if ident in taken or ident in self.seen[section]:
            raise self.fail(f"duplicate {section} id {ident!r}", line)
        self.seen[section].add(ident)
        return ident

    def load_place(self, index: int, table: Any, places: Mapping[str, Place]) -> tuple[Place, int]:
        if not isinstance(table, dict):
            raise self.fail("a [[place]] must be a table", self.smap.elements.get(("place", index)))
        pid = self.element_id("place", index, table, places)
        what = f"place {pid!r}"
        self.check_keys(table, PLACE_KEYS, what, "place", index)
        task = self.get(table, "task", "str", what, "place", index)
        kind_text = self.get(table, "kind", "str", what, "place", index,
                             "primitive_task" if task is not None else "plain")
        try:
            kind = PlaceKind(kind_text)
        except ValueError:
            kinds = ", ".join(k.value for k in PlaceKind)
            raise self.fail(f"{what} has unknown kind {kind_text!r} (use one of {kinds})",
                            self.smap.key("place", index, "kind")) from None
        if kind is PlaceKind.PRIMITIVE_TASK and task is None:
            raise self.fail(f"{what} is a primitive_task place but names no task (add task = \"...\")",
                            self.smap.key("place", index, "kind"))
        if kind is not PlaceKind.PRIMITIVE_TASK and task is not None:
            raise self.fail(f"{what} of kind {kind.value} cannot name a task", self.smap.key("place", index, "task"))
        tokens = self.get(table, "tokens", "int", what, "place", index, 0)
        if tokens < 0:
            raise self.fail(f"{what} has a negative initial marking ({tokens})", self.smap.key("place", index, "tokens"))
        self.check(count_problem(tokens, f"initial marking of {what}", 0), self.smap.key("place", index, "tokens"))
        label = self.text(table, "label", what, "place", index, "", MAX_LABEL)
        self.position(table, what, "place", index)
        capacity = self.get(table, "capacity", "int", what, "place", index)
        if capacity is not None and capacity < 0:
            raise self.fail(f"{what} has a negative capacity ({capacity})", self.smap.key("place", index, "capacity"))
        if capacity is not None:
            self.check(count_problem(capacity, f"capacity of {what}", 0), self.smap.key("place", index, "capacity"))
        return self.build(self.smap.element("place", index), lambda: Place(
            id=pid, kind=kind, task=task, label=label, capacity=capacity)), tokens

    def check_places(self, places: Mapping[str, Place], tasks: Mapping[str, PrimitiveTask]) -> None:
        for index, table in enumerate(self.doc.get("place", [])):
            if not isinstance(table, dict):
                continue
            ident = table.get("id")
            place = places.get(ident) if isinstance(ident, str) else None
            if place is None or place.task is None or place.task in tasks:
                continue
            if place.task in self.doc.get("task", {}):
                continue  # the task itself is broken, already reported
            known = ", ".join(sorted(tasks)) or "none defined"
            self.report(f"place {place.id!r} names unknown task {place.task!r} (tasks: {known}); "
                        f"add a [task.{place.task}] table", self.smap.key("place", index, "task"))

    # ---------------------------------------------------------------- transitions
    def load_transitions(self) -> dict[str, Transition]:
        transitions: dict[str, Transition] = {}
        self.transition_arcs: list[tuple[int, str, str, Mapping[str, Any]]] = []
        for index, table in enumerate(self.doc.get("transition", [])):
            try:
                t = self.load_transition(index, table, transitions)
            except _Skip:
                continue
            transitions[t.id] = t
        return transitions

    def load_transition(self, index: int, table: Any, transitions: Mapping[str, Transition]) -> Transition:
        if not isinstance(table, dict):
            raise self.fail("a [[transition]] must be a table", self.smap.elements.get(("transition", index)))
        tid = self.element_id("transition", index, table, transitions)
        what = f"transition {tid!r}"
        sec = "transition"
        self.check_keys(table, TRANSITION_KEYS, what, sec, index)
        events = self.get(table, "events", "array", what, sec, index, [])
        for event in events:
            problem = event_problem(event) if isinstance(event, str) else "an event name must be a string"
            if problem is not None:
                raise self.fail(f"{what} links a {problem}" if isinstance(event, str) else
                                f"{what} links {_brief(event)}: {problem}", self.smap.key(sec, index, "events"))
        priority = self.get(table, "priority", "int", what, sec, index, 0)
        self.check(priority_problem(priority, f"priority of {what}"), self.smap.key(sec, index, "priority"))
        weight, weight_expr = self.number_or_expression(table, "weight", what, index, 1.0)
        if weight is not None and not weight > 0:
            raise self.fail(f"{what} has weight {weight}; weights must be > 0", self.smap.key(sec, index, "weight"))
        kind_text = self.get(table, "kind", "str", what, sec, index, "immediate")
        try:
            kind = TransitionKind(kind_text)
        except ValueError:
            raise self.fail(f"{what} has unknown kind {kind_text!r} (use immediate or exponential)",
                            self.smap.key(sec, index, "kind")) from None
        if "rate" in table and kind is TransitionKind.IMMEDIATE:
            raise self.fail(f"immediate {what} cannot have a rate (add kind = \"exponential\")",
                            self.smap.key(sec, index, "rate"))
        rate, rate_expr = self.number_or_expression(table, "rate", what, index, None)
        if rate is not None and not rate > 0:
            raise self.fail(f"rate of {what} is {rate}; it must be > 0 (1/s)", self.smap.key(sec, index, "rate"))
        if rate_expr is not None and table.get("servers", 1) != 1:
            raise self.fail(f"{what} has a rate expression and servers = {_brief(table.get('servers'))}: a "
                            "marking-dependent rate is the whole rate (no server multiplier); write the servers "
                            "into the expression, e.g. \"min(#queue, 3) * 2\"", self.smap.key(sec, index, "servers"))
        servers_value = table.get("servers", 1)
        if servers_value == "infinite":
            servers: int | None = None
        elif _is_int(servers_value) and servers_value >= 1:
            servers = servers_value
            self.check(count_problem(servers, f"servers of {what}", 1), self.smap.key(sec, index, "servers"))
        else:
            raise self.fail(f"servers of {what} must be an integer >= 1 or \"infinite\", not "
                            f"{_brief(servers_value)}", self.smap.key(sec, index, "servers"))
        hidden = self.get(table, "hidden", "bool", what, sec, index, False)
        label = self.text(table, "label", what, sec, index, "", MAX_LABEL)
        self.position(table, what, sec, index)
        for key in ("inputs", "outputs", "inhibitors"):
            arcs = self.get(table, key, "table", what, sec, index, {})
            self.transition_arcs.append((index, tid, key, arcs))
        self.transition_rows[tid] = index
        return self.build(self.smap.element(sec, index), lambda: Transition(
            id=tid, events=tuple(events), priority=priority, weight=1.0 if weight is None else float(weight),
            kind=kind, rate=None if rate is None else float(rate), servers=servers, hidden=hidden, label=label,
            rate_expr=rate_expr, weight_expr=weight_expr))

    # ---------------------------------------------------------------- arcs
    def arc_weight(self, weight: Any, what: str, line: int | None) -> int:
        if not _is_int(weight) or weight < 1:
            raise self.fail(f"{what} has weight {_brief(weight)}; arc weights are integers >= 1", line)
        self.check(count_problem(weight, f"weight of {what}", 1), line)
        return int(weight)

    def load_arcs(self, places: Mapping[str, Place], transitions: Mapping[str, Transition]) -> list[Arc]:
        arcs: list[Arc] = []
        seen: dict[tuple[str, str, str], int | None] = {}

        def add(source: str, target: str, weight: int, inhibitor: bool, line: int | None,
                reset: bool = False) -> None:
            arc = Arc(source=source, target=target, weight=weight, inhibitor=inhibitor, reset=reset)
            key = (source, target, arc.kind)
            if key in seen:
                kind = "arc" if arc.kind == "normal" else f"{arc.kind} arc"
                first = f" (first at line {seen[key]})" if seen[key] else ""
                advice = "; use one arc with a weight" if not reset else ""
                self.report(f"{kind} {source} -> {target} is given twice{first}{advice}", line)
                return
            seen[key] = line
            arcs.append(arc)

        for index, tid, key, table in self.transition_arcs:
            line = self.smap.key("transition", index, key)
            for pid, weight in table.items():
                what = f"{key[:-1]} arc {pid} -> {tid}" if key != "outputs" else f"output arc {tid} -> {pid}"
                try:
                    w = self.arc_weight(weight, what, line)
                except _Skip:
                    continue
                if pid not in places:
                    if pid in transitions or pid in self.declared["transition"]:
                        self.report(f"{key} of transition {tid!r} names transition {pid!r}; arcs join a place "
                                    "and a transition", line)
                    elif pid in self.declared["place"]:
                        pass  # the place is broken, already reported
                    else:
                        self.report(f"{key} of transition {tid!r} names unknown place {pid!r}", line)
                    continue
                if key == "outputs":
                    add(tid, pid, w, False, line)
                else:
                    add(pid, tid, w, key == "inhibitors", line)
        for index, table in enumerate(self.doc.get("arc", [])):
            try:
                self.load_arc(index, table, places, transitions, add)
            except _Skip:
                continue
        return arcs

    def load_arc(self, index: int, table: Any, places: Mapping[str, Place],
                 transitions: Mapping[str, Transition], add: Any) -> None:
        header = self.smap.elements.get(("arc", index))
        if not isinstance(table, dict):
            raise self.fail("an [[arc]] must be a table", header)
        self.check_keys(table, ARC_KEYS, "an [[arc]]", "arc", index)
        ends = []
        for key in ("from", "to"):
            if key not in table:
                raise self.fail(f"an [[arc]] has no {key!r}", header)
            end = self.get(table, key, "str", "an [[arc]]", "arc", index)
            if end not in places and end not in transitions:
                if end in self.declared["place"] or end in self.declared["transition"]:
                    raise _Skip()  # the element is broken, already reported
                raise self.fail(f"arc {table.get('from')} -> {table.get('to')}: unknown place or transition "
                                f"{end!r}", self.smap.key("arc", index, key))
            ends.append(end)
        source, target = ends
        line = self.smap.key("arc", index, "from")
        if (source in places) == (target in places):
            what = "two places" if source in places else "two transitions"
            raise self.fail(f"arc {source} -> {target} joins {what}; arcs join a place and a transition", line)
        weight = self.arc_weight(table.get("weight", 1), f"arc {source} -> {target}",
                                 self.smap.key("arc", index, "weight"))
        inhibitor = self.get(table, "inhibitor", "bool", "an [[arc]]", "arc", index, False)
        if inhibitor and source not in places:
            raise self.fail(f"inhibitor arc {source} -> {target} must go from a place to a transition",
                            self.smap.key("arc", index, "inhibitor"))
        reset = self.get(table, "reset", "bool", "an [[arc]]", "arc", index, False)
        if reset:
            reset_line = self.smap.key("arc", index, "reset")
            if source not in places:
                raise self.fail(f"reset arc {source} -> {target} must go from a place to a transition", reset_line)
            if inhibitor:
                raise self.fail(f"arc {source} -> {target} cannot be both a reset and an inhibitor arc; give two "
                                "[[arc]] tables", reset_line)
            if "weight" in table:
                raise self.fail(f"reset arc {source} -> {target} takes no weight: it empties its place whatever "
                                "it holds", self.smap.key("arc", index, "weight"))
        add(source, target, weight, inhibitor, line, reset)


def _default_name(path: str) -> str:
    stem = Path(path).stem if not path.startswith("<") else "net"
    return stem or "net"


def lint_net(text: str, path: str = "<string>", *, interpreted: bool = True) -> tuple[PetriNet | None, list[NetError]]:
    """Load a net from TOML text, collecting every problem instead of stopping at the first.

    Args:
        text: the TOML source.
        path: file name for error messages.
        interpreted: also apply :meth:`PetriNet.interpretation_problems` (exits of primitive tasks,
            ``int:`` events naming tasks of input places).

    Returns:
        ``(net, [])`` for a valid file, else ``(None, problems)`` sorted by line; each problem is a
        :class:`NetError` (:class:`NetFileError` for a syntax error) with ``path`` and ``line``.
    """
    try:
        doc, lines = parse_toml(text)
    except TextProblem as exc:
        return None, [NetFileError(exc.problem, path=path, line=exc.line)]
    smap = SourceMap.from_lines(lines)
    loader = _Loader(doc, smap, path)
    net = loader.load(_default_name(path), interpreted)
    problems = sorted(loader.problems, key=lambda e: (e.line is None, e.line or 0))
    return (net, []) if net is not None and not problems else (None, problems)


def loads_net(text: str, path: str = "<string>", *, interpreted: bool = True) -> PetriNet:
    """Load a net from the text of a TOML net file (format: docs/netfile.md).

    Args:
        text: the TOML source.
        path: file name for error messages.
        interpreted: also check the interpreted-net rules (see :func:`lint_net`).

    Returns:
        The net.

    Raises:
        NetFileError: on a TOML syntax error (line from :mod:`tomllib`), text that no net file may
            hold (NUL, nesting deeper than 64, a 5,000-digit number: docs/netfile.md, "Limits").
        NetError: on the first problem found (by line), with ``path`` and ``line`` set.
    """
    net, problems = lint_net(text, path, interpreted=interpreted)
    if problems:
        raise problems[0]
    assert net is not None
    return net


def read_text(path: str | Path) -> str:
    """Read a net file as text: a regular file of at most 16 MiB, UTF-8, without NUL.

    Raises:
        NetFileError: the file cannot be read or is refused, with the line of the offending byte.
    """
    try:
        return decode_utf8(read_capped(path, what="net file"))
    except TextProblem as exc:
        raise NetFileError(exc.problem, path=str(path), line=exc.line) from None


def load_net(path: str | Path, *, interpreted: bool = True) -> PetriNet:
    """Load a TOML net file; see :func:`loads_net`.

    Raises:
        NetFileError: if the file cannot be read, is not a regular file, is larger than 16 MiB, is
            not UTF-8 text or holds a NUL byte; or as :func:`loads_net`.
        NetError: as :func:`loads_net`.
    """
    return loads_net(read_text(path), str(path), interpreted=interpreted)
