"""A net being drawn in the console: the draft, its TOML text, and its problems (paper section 5).

The page edits a *draft*: the net file's tables as JSON, with the arcs drawn apart from the
transitions::

    {"net": {"name": "catch", "home": {...}},          # [net]
     "places": [{"id": "p", "kind": "control", "tokens": 4, "pos": [x, y]}, ...],   # [[place]]
     "tasks": {"locate": {"actions": [...], "deadline_s": 12.0}},                   # [task.*]
     "transitions": [{"id": "t", "events": ["ext:tick"], "pos": [x, y]}, ...],      # [[transition]]
     "arcs": [{"from": "p", "to": "t", "weight": 1, "inhibitor": false}, ...],
     "operator": {"inject": ["ext:tick"], "force": {"locate": ["error"]}}}            # [operator], optional

:func:`draft_to_toml` writes a draft as the text of a net file (arcs between a place and a
transition go into the transition's ``inputs``/``outputs``/``inhibitors``; any other arc is an
``[[arc]]`` table, so the linter names what is wrong with it) and remembers which element each
line belongs to. :func:`validate_draft` lints that text with :func:`coordinator.netfile.lint_net`
and checks placement with :func:`coordinator.netfile.check_net` — the same rules and the same
``FILE:LINE: problem`` messages as ``petrobot check``, with each problem tied to the element the
page highlights. :func:`draft_of_net` and :func:`draft_of_text` turn a net file into a draft.
Keys the page does not know (a newer net format's) travel through untouched.

No I/O: the caller reads and writes files.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from coordinator.errors import NetError
from coordinator.net import PetriNet
from coordinator.netfile import SourceMap, check_net, dump_net, lint_net
from coordinator.netfile.layout import Layout, position_problem
from coordinator.netfile.placement import Placement
from coordinator.netfile.writer import format_key, format_value
from services.errors import LocationError
from services.textfile import TextProblem
from services.tomllines import parse_toml

__all__ = ["UNSAVED", "Element", "Problem", "Validation", "draft_layout", "draft_of_net", "draft_of_text",
           "draft_to_toml", "placement_of", "validate_draft", "validate_text"]

Element = tuple[str, str]
"""What a problem is about: ``("place", id)``, ``("transition", id)``, ``("task", name)``,
``("arc", "from->to")`` or ``("net", "")``."""

_ARC_SECTIONS = ("inputs", "outputs", "inhibitors")
_FIRST_KEYS = {"place": ("id", "kind", "task", "tokens", "label", "capacity"),
               "transition": ("id", "label", "events", "priority", "weight", "kind", "rate", "servers", "hidden"),
               "task": ("actions", "params", "deadline_s", "mean_time_s", "reliability", "learner"),
               "net": ("name", "description", "format", "home")}


@dataclass(frozen=True, slots=True)
class Problem:
    """One problem of a draft.

    Attributes:
        text: the message exactly as ``petrobot check`` prints it (``FILE:LINE: problem``), the
            line being that of the file a save would write.
        problem: the problem alone.
        element: what it is about, or ``None`` for the file as a whole.
    """

    text: str
    problem: str
    element: Element | None

    def to_json(self) -> dict[str, Any]:
        kind, ident = self.element if self.element is not None else (None, None)
        return {"text": self.text, "problem": self.problem, "kind": kind, "id": ident}


@dataclass(slots=True)
class Validation:
    """The verdict on a draft.

    Attributes:
        net: the net, when the draft loads (it may still be unplaceable).
        problems: every problem: the net file's, then placement's.
        placement: action → node it is placed on (``None``: not placed), and ``ext:topic`` → its
            publishing node; empty without a location file.
        text: the TOML text the problems' lines refer to.
    """

    net: PetriNet | None
    problems: list[Problem]
    placement: dict[str, str | None] = field(default_factory=dict)
    text: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"ok": not self.problems, "problems": [p.to_json() for p in self.problems],
                "placement": self.placement,
                "summary": self.net.summary() if self.net is not None else ""}


# ------------------------------------------------------------------------------------------ writing
def _value(value: Any) -> str:
    """One TOML value; ``None`` inside arrays and tables is refused by format_value (NetError)."""
    return format_value(value)


def _table_lines(table: Mapping[str, Any], order: tuple[str, ...], skip: tuple[str, ...] = ()) -> list[str]:
    keys = [k for k in order if k in table] + [k for k in table if k not in order]
    out = []
    for key in keys:
        value = table[key]
        if key in skip or value is None:
            continue
        try:
            out.append(f"{format_key(str(key))} = {_value(value)}")
        except NetError:
            out.append(f"{format_key(str(key))} = \"(a value TOML cannot hold)\"")
    return out


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.owner: list[Element | None] = []

    def add(self, lines: list[str], element: Element | None) -> None:
        self.lines += lines
        self.owner += [element] * len(lines)


def draft_to_toml(draft: Mapping[str, Any]) -> tuple[str, list[Element | None]]:
    """Write a draft as the text of a TOML net file.

    Returns:
        ``(text, owner)``: ``owner[i]`` is the element line ``i + 1`` belongs to (``None`` for
        blank and ``[net]`` lines).
    """
    w = _Writer()
    w.add(["# petrobot net file, format 1 (see docs/netfile.md)", "", "[net]"], None)
    net = dict(draft.get("net") or {})
    net.setdefault("format", 1)
    w.add(_table_lines(net, _FIRST_KEYS["net"]), ("net", ""))
    operator = draft.get("operator")
    if isinstance(operator, Mapping) and operator:
        w.add(["", "[operator]"] + _table_lines(operator, ("inject", "force")), ("net", ""))
    places = [p for p in draft.get("places") or [] if isinstance(p, Mapping)]
    transitions = [t for t in draft.get("transitions") or [] if isinstance(t, Mapping)]
    place_ids = {p.get("id") for p in places if isinstance(p.get("id"), str)}
    trans_ids = {t.get("id") for t in transitions if isinstance(t.get("id"), str)}
    for place in places:
        w.add(["", "[[place]]"] + _table_lines(place, _FIRST_KEYS["place"]), ("place", str(place.get("id", ""))))
    for name, task in (draft.get("tasks") or {}).items():
        w.add(["", f"[task.{format_key(str(name))}]"] + _table_lines(task, _FIRST_KEYS["task"]), ("task", str(name)))
    # arcs: into their transition's tables when they can be written there, else [[arc]] tables
    tables: dict[str, dict[str, dict[str, int]]] = {str(t.get("id")): {k: {} for k in _ARC_SECTIONS}
                                                  for t in transitions}
    loose: list[Mapping[str, Any]] = []
    for arc in draft.get("arcs") or []:
        if not isinstance(arc, Mapping):
            continue
        src, dst = arc.get("from"), arc.get("to")
        weight = arc.get("weight", 1)
        inhibitor = arc.get("inhibitor", False) is True
        plain = set(arc) <= {"from", "to", "weight", "inhibitor"} and isinstance(weight, int) \
            and not isinstance(weight, bool)
        if plain and src in place_ids and dst in trans_ids:
            section = tables[str(dst)]["inhibitors" if inhibitor else "inputs"]
            if src not in section:
                section[str(src)] = weight
                continue
        elif plain and src in trans_ids and dst in place_ids and not inhibitor:
            section = tables[str(src)]["outputs"]
            if dst not in section:
                section[str(dst)] = weight
                continue
        loose.append(arc)
    for t in transitions:
        tid = str(t.get("id", ""))
        lines = ["", "[[transition]]"] + _table_lines(t, _FIRST_KEYS["transition"], _ARC_SECTIONS)
        arcs = tables.get(tid, {})
        for key in _ARC_SECTIONS:
            if arcs.get(key) or key != "inhibitors":
                lines.append(f"{key} = {_value(arcs.get(key, {}))}")
        w.add(lines, ("transition", tid))
    for arc in loose:
        label = f"{arc.get('from')}->{arc.get('to')}"
        w.add(["", "[[arc]]"] + _table_lines(arc, ("from", "to", "weight", "inhibitor")), ("arc", label))
    return "\n".join(w.lines) + "\n", w.owner


# ------------------------------------------------------------------------------------------ reading
def draft_of_text(text: str) -> dict[str, Any]:
    """A draft of the text of a TOML net file, even one with problems (as far as it is TOML).

    Raises:
        NetError: the text is not TOML, or its sections are not tables and arrays of tables.
    """
    try:
        doc, _ = parse_toml(text)
    except TextProblem as exc:
        raise NetError(exc.problem, line=exc.line) from None
    net = doc.get("net", {})
    places = doc.get("place", [])
    tasks = doc.get("task", {})
    transitions = doc.get("transition", [])
    loose = doc.get("arc", [])
    operator = doc.get("operator", {})
    if not (isinstance(net, dict) and isinstance(places, list) and isinstance(tasks, dict)
            and isinstance(transitions, list) and isinstance(loose, list) and isinstance(operator, dict)):
        raise NetError("the file's sections are not the tables of a net file (docs/netfile.md)")
    draft_transitions, arcs = [], []
    for t in transitions:
        if not isinstance(t, dict):
            continue
        tid = t.get("id")
        for key in _ARC_SECTIONS:
            table = t.get(key, {})
            if not isinstance(table, dict):
                continue
            for pid, weight in table.items():
                if key == "outputs":
                    arcs.append({"from": tid, "to": pid, "weight": weight})
                else:
                    arcs.append({"from": pid, "to": tid, "weight": weight, **({"inhibitor": True}
                                                                            if key == "inhibitors" else {})})
        draft_transitions.append({k: v for k, v in t.items() if k not in _ARC_SECTIONS})
    arcs += [dict(a) for a in loose if isinstance(a, dict)]
    net = {k: v for k, v in net.items() if k != "format"}
    draft = {"net": net, "places": [dict(p) for p in places if isinstance(p, dict)],
             "tasks": {str(k): dict(v) for k, v in tasks.items() if isinstance(v, dict)},
             "transitions": draft_transitions, "arcs": arcs}
    if operator:
        draft["operator"] = dict(operator)
    return draft


def draft_of_net(net: PetriNet, layout: Layout | None = None) -> dict[str, Any]:
    """A draft of a net (through its canonical TOML form, so every key the writer knows travels)."""
    return draft_of_text(dump_net(net, layout))


def draft_layout(draft: Mapping[str, Any]) -> Layout:
    """The positions of a draft's places and transitions."""
    layout: Layout = {}
    for key in ("places", "transitions"):
        for item in draft.get(key) or []:
            if isinstance(item, Mapping) and isinstance(item.get("id"), str):
                pos = item.get("pos")
                if pos is not None and position_problem(pos, "") is None:
                    layout[item["id"]] = (float(pos[0]), float(pos[1]))
    return layout


# ------------------------------------------------------------------------------------------ checking
def placement_of(net: PetriNet | None, draft: Mapping[str, Any], location: Any) -> dict[str, str | None]:
    """Where each primitive action of the draft runs and which node publishes each external event."""
    out: dict[str, str | None] = {}
    if location is None:
        return out
    names: list[str] = []
    if net is not None:
        names = [a.name for t in net.tasks.values() for a in t.actions]
        events = [e for t in net.transitions for e in t.external_events]
    else:
        for task in (draft.get("tasks") or {}).values():
            for a in task.get("actions") or [] if isinstance(task, Mapping) else []:
                name = a if isinstance(a, str) else a.get("name") if isinstance(a, Mapping) else None
                if isinstance(name, str):
                    names.append(name)
        events = [e for t in draft.get("transitions") or [] if isinstance(t, Mapping)
                  for e in (t.get("events") or []) if isinstance(e, str) and e.startswith("ext:")]
    for name in names:
        try:
            out[name] = location.node_of(name)
        except LocationError:
            out[name] = None
    for event in events:
        try:
            out[event] = location.publisher_of(event[4:])
        except LocationError:
            out[event] = None
    return out


#: What the problems of a drawing that is not saved as it stands are said to be in.
UNSAVED = "unsaved drawing"


def validate_draft(draft: Mapping[str, Any], name: str = UNSAVED, location: Placement | None = None, *,
                   lines: bool | None = None) -> Validation:
    """Check a draft as ``petrobot check`` checks a net file (and its placement, given a location).

    Args:
        draft: the draft (shape checked by :func:`coordinator.web.protocol.parse_client_message`).
        name: what the messages say the problems are in: a file, or :data:`UNSAVED`.
        location: a :class:`services.location.Location` (``node_of``/``publisher_of``), or ``None``.
        lines: give each message the line of :attr:`Validation.text` (the file Save would write);
            by default only when ``name`` names a file (an unsaved drawing has no lines: its
            problems point to their elements).

    Returns:
        The :class:`Validation`.
    """
    text, owner = draft_to_toml(draft)
    net, errors = lint_net(text, name)
    with_lines = name != UNSAVED if lines is None else lines
    problems = []
    for err in errors:
        element = owner[err.line - 1] if err.line is not None and 0 < err.line <= len(owner) else None
        problems.append(Problem(str(err) if with_lines else f"{name}: {err.problem}", err.problem, element))
    if net is not None and location is not None:
        smap = SourceMap.scan(text)
        problems += _placement_problems(net, location, smap, name, with_lines)
    return Validation(net, problems, placement_of(net, draft, location), text)


def _placement_problems(net: PetriNet, location: Placement, smap: SourceMap, name: str, with_lines: bool
                        ) -> list[Problem]:
    out = []
    for ident, problem in check_net(net, location):
        line = smap.of_id(ident) if with_lines else None
        kind = "task" if ident in net.tasks else "transition"
        out.append(Problem(f"{name}:{line}: {problem}" if line else f"{name}: {problem}", problem, (kind, ident)))
    return out


def validate_text(text: str, name: str, draft: Mapping[str, Any], location: Placement | None = None) -> Validation:
    """Check the text of a net file as it is on disk: the problems name ``name`` and the lines of
    ``text`` itself (what ``petrobot check FILE`` says), each tied to the element at its line.

    Args:
        text: the file's text.
        name: the file as the page shows it (``nets/catch.toml``).
        draft: the draft of ``text`` (:func:`draft_of_text`), for the placement table.
        location: as :func:`validate_draft`.
    """
    net, errors = lint_net(text, name)
    smap = SourceMap.scan(text)
    starts = sorted(((line, _element_of(section, ident, smap, text)) for (section, ident), line in smap.elements.items()),
                    key=lambda item: item[0])
    problems = []
    for err in errors:
        element = None
        if err.line is not None:
            for line, owner in starts:
                if line > err.line:
                    break
                element = owner
        problems.append(Problem(str(err), err.problem, element))
    if net is not None and location is not None:
        problems += _placement_problems(net, location, smap, name, True)
    return Validation(net, problems, placement_of(net, draft, location), text)


def _element_of(section: str, ident: Any, smap: SourceMap, text: str) -> Element | None:
    """The element a table of the file is (its id read back from the map), for :func:`validate_text`."""
    if section in ("place", "transition") and isinstance(ident, int):
        for (kind, name), line in smap.ids.items():
            if kind == section and line == smap.keys.get((section, ident, "id")):
                return (section, name)
        return None
    if section == "task" and isinstance(ident, str):
        return ("task", ident)
    if section in ("net", "operator"):
        return ("net", "")
    return None
