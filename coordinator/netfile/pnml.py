"""PNML import and export of place/transition nets (ISO/IEC 15909-2, 2009 grammar).

Reads the 2009 grammar (``<pnml><net type=".../ptnet"><page><place>...``, labels holding
``<text>``), the older dialect that writes ``<value>`` instead of ``<text>`` and puts nodes straight
under ``<net>`` without a ``<page>`` (PIPE-style ``"Default,3"`` markings included), nested or
multiple pages (flattened; reference places and transitions resolved to the nodes they stand for),
and ``<type value="inhibitor"/>`` or ``<type value="reset"/>`` on arcs. Ids of places and transitions are kept. Duplicate arcs
between the same place and transition are merged by adding their weights.

The interpretation that plain PNML cannot express (place kinds, primitive tasks and their actions,
events, priorities, weights, GSPN timing, hidden branches, inhibitor and reset arcs, labels, the home
marking) travels in ``<toolspecific tool="petrobot" version="1">`` elements (a marking-dependent rate
or weight in its ``rate_expr`` or ``weight_expr`` attribute; docs/netfile.md, section 7), so that a net written by
:func:`dump_pnml` reads back equal (``loads_pnml(dump_pnml(n)) == n``). A model without them -
any Model Checking Contest model - loads as a net of plain places and immediate transitions.

Every problem raises :class:`~coordinator.errors.NetError` (syntax errors and non-P/T nets:
:class:`~coordinator.errors.NetFileError`) naming the file and the 1-based line of the element.

Reference: ISO/IEC 15909-2:2011, *Petri net Markup Language*; Hillah, Kordon, Petrucci, Trèves,
"PNML Framework", 2010.

Length: about 690 lines because reading and writing share one table of petrobot's tool-specific
elements and are tested as a round trip; splitting them would split that table.
"""

from __future__ import annotations

import math
import re
import xml.parsers.expat
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import Any, TypeVar
from xml.etree import ElementTree as ET
from xml.sax.saxutils import escape, quoteattr

from coordinator.errors import NetError, NetFileError
from coordinator.expr import MAX_LENGTH as MAX_EXPRESSION
from coordinator.expr import ExprError, check_places, parse
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
from coordinator.netfile.limits import (
    MAX_COUNT,
    MAX_DESCRIPTION,
    MAX_LABEL,
    MAX_NAME,
    MAX_PRIORITY,
    event_problem,
    finite_problem,
    id_problem,
    task_name_problem,
    text_problem,
)
from coordinator.netfile.writer import format_value
from services.textfile import (
    MAX_FILE_BYTES,
    TextProblem,
    decode_utf8,
    read_capped,
    screen_text,
    size_text,
    write_atomically,
)
from services.tomllines import parse_toml

__all__ = ["PNML_NS", "PTNET_TYPE", "TOOL", "TOOL_VERSION", "dump_pnml", "load_pnml", "loads_pnml", "save_pnml"]

#: XML namespace of the 2009 grammar.
PNML_NS = "http://www.pnml.org/version-2009/grammar/pnml"
#: Net type of place/transition nets in the 2009 grammar.
PTNET_TYPE = "http://www.pnml.org/version-2009/grammar/ptnet"
#: ``tool`` attribute of our ``<toolspecific>`` elements.
TOOL = "petrobot"
#: ``version`` attribute of our ``<toolspecific>`` elements.
TOOL_VERSION = "1"

#: Deepest nesting of XML elements accepted. PNML nests six levels (pnml, net, page, place,
#: initialMarking, text) plus one per nested page; 5,000 nested pages are refused, not recursed into.
MAX_XML_DEPTH = 256

_T = TypeVar("_T")
_NOT_PT = ("symmetricnet", "highlevelnet", "pt-hlpng", "hlpng", "coloured", "colored")
_SPACE = re.compile(r"\s+")


# ---------------------------------------------------------------------------------------- parsing
def _brief(value: object) -> str:
    """``repr`` of a value, cut to a length fit for one line of a message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


class _Refused(Exception):
    """Raised from an expat handler to stop parsing a document we refuse."""


def _parse_xml(data: bytes, path: str) -> tuple[ET.Element, dict[ET.Element, int]]:
    """Parse XML with expat, stripping namespaces, and remember each element's line.

    A document type declaration is refused (PNML needs none; refusing it rules out entity
    expansion bombs and external entities), and so is nesting deeper than :data:`MAX_XML_DEPTH`.
    """
    builder = ET.TreeBuilder()
    lines: dict[ET.Element, int] = {}
    # The bytes were checked to be UTF-8; an encoding the document declares is not followed.
    parser = xml.parsers.expat.ParserCreate(encoding="utf-8", namespace_separator="}")
    depth = 0

    def start(tag: str, attrs: dict[str, str]) -> None:
        nonlocal depth
        depth += 1
        if depth > MAX_XML_DEPTH:
            raise _Refused(f"elements nested deeper than {MAX_XML_DEPTH} levels")
        local = tag.rsplit("}", 1)[-1]
        attributes = {k.rsplit("}", 1)[-1]: v for k, v in attrs.items()}
        lines[builder.start(local, attributes)] = parser.CurrentLineNumber

    def end(tag: str) -> None:
        nonlocal depth
        depth -= 1
        builder.end(tag.rsplit("}", 1)[-1])

    def doctype(*_: object) -> None:
        raise _Refused("a document type declaration (<!DOCTYPE>) is not allowed in PNML: "
                       "entities are not expanded")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = builder.data
    parser.StartDoctypeDeclHandler = doctype
    parser.EntityDeclHandler = doctype
    parser.buffer_text = True
    try:
        parser.Parse(data, True)
    except _Refused as exc:
        raise NetFileError(str(exc), path=path, line=parser.CurrentLineNumber) from None
    except xml.parsers.expat.ExpatError as exc:
        raise NetFileError(
            f"not well-formed XML: {xml.parsers.expat.ErrorString(exc.code)} (column {exc.offset + 1})",
            path=path, line=exc.lineno,
        ) from None
    return builder.close(), lines


def _label_text(elem: ET.Element | None) -> str | None:
    """Text of a PNML label: ``<text>`` (2009) or ``<value>`` (older dialect), stripped."""
    if elem is None:
        return None
    for child in elem:
        if child.tag in ("text", "value"):
            return (child.text or "").strip()
    return None


def _name_text(elem: ET.Element | None) -> str | None:
    """A ``<name>`` label with its runs of white space (line breaks, tabs) made single spaces."""
    text = _label_text(elem)
    return None if text is None else _SPACE.sub(" ", text)


class _Reader:
    """One PNML document being turned into a :class:`PetriNet`."""

    def __init__(self, root: ET.Element, lines: dict[ET.Element, int], path: str) -> None:
        self.root = root
        self.lines = lines
        self.path = path
        self.elements: dict[str, ET.Element] = {}  # places, transitions and tasks by id or name
        self.place_ids: set[str] = set()

    def error(self, problem: str, elem: ET.Element | None) -> NetError:
        return NetError(problem, path=self.path, line=self.lines.get(elem) if elem is not None else None)

    def guarded(self, elem: ET.Element, build: Callable[[], _T]) -> _T:
        """Run a constructor of the net model; re-raise its NetError with this element's line."""
        try:
            return build()
        except NetError as exc:
            raise self.error(exc.problem, elem) from None
        except (TypeError, ValueError) as exc:
            raise self.error(str(exc), elem) from None

    def integer(self, text: str | None, what: str, elem: ET.Element, minimum: int,
                maximum: int = MAX_COUNT) -> int:
        """Parse an integer in ``[minimum, maximum]`` (2**31 - 1 by default: docs/netfile.md, "Limits")."""
        if text is None or text == "":
            raise self.error(f"{what} is empty", elem)
        # PIPE writes "Default,3"; the 2009 grammar writes "3".
        token = text.rsplit(",", 1)[-1].strip()
        try:
            if len(token) > 32:
                raise ValueError(token)
            value = int(token)
        except ValueError:
            raise self.error(f"{what} {_brief(text)} is not an integer", elem) from None
        if value < minimum:
            raise self.error(f"{what} is {value}; it must be >= {minimum}", elem)
        if value > maximum:
            raise self.error(f"{what} is {value}; the limit is {maximum}", elem)
        return value

    def number(self, text: str | None, what: str, elem: ET.Element, expression_key: str | None = None) -> float | None:
        """Parse an optional finite float attribute (``expression_key``: where an expression goes instead)."""
        if text is None:
            return None
        try:
            value = float(text)
        except ValueError:
            hint = f" (a marking expression goes in the {expression_key} attribute)" if expression_key else ""
            raise self.error(f"{what} {_brief(text)} is not a number{hint}", elem) from None
        problem = finite_problem(value, what)
        if problem is not None:
            raise self.error(problem, elem)
        return value

    def text(self, value: str, what: str, elem: ET.Element, limit: int, lines: bool = False) -> str:
        """Check free text (a name, label, description) against the limits of docs/netfile.md."""
        problem = text_problem(value, what, limit, lines=lines)
        if problem is not None:
            raise self.error(problem, elem)
        return value

    def tool(self, elem: ET.Element) -> ET.Element | None:
        for child in elem:
            if child.tag == "toolspecific" and child.get("tool") == TOOL:
                version = child.get("version", TOOL_VERSION)
                if version != TOOL_VERSION:
                    raise self.error(f"toolspecific petrobot version {version!r} is not supported "
                                     f"(expected {TOOL_VERSION!r})", child)
                return child
        return None

    # ---------------------------------------------------------------- net
    def interpreted(self, net: PetriNet) -> PetriNet:
        """Apply the interpreted-net rules; raise the first problem at its element's line."""
        for ident, problem in net.interpretation_problems():
            raise self.error(problem, self.elements.get(ident))
        return net

    def net(self, net_id: str | None) -> PetriNet:
        root = self.root
        if root.tag == "net":
            nets = [root]
        elif root.tag == "pnml":
            nets = [n for n in root if n.tag == "net"]
        else:
            raise NetFileError(f"not a PNML document: root element is <{root.tag}>", path=self.path, line=1)
        if net_id is not None:
            nets = [n for n in nets if n.get("id") == net_id]
            if not nets:
                raise NetFileError(f"no <net> with id {net_id!r}", path=self.path, line=1)
        if not nets:
            raise NetFileError("the document holds no <net>", path=self.path, line=1)
        if len(nets) > 1:
            ids = ", ".join(repr(n.get("id")) for n in nets)
            raise self.error(f"the document holds {len(nets)} nets ({ids}); choose one with net_id", nets[1])
        return self.read_net(nets[0])

    def read_net(self, net: ET.Element) -> PetriNet:
        ntype = (net.get("type") or "").lower()
        if any(word in ntype for word in _NOT_PT):
            raise NetFileError(f"net type {net.get('type')!r} is not a place/transition net",
                               path=self.path, line=self.lines.get(net))
        places: dict[str, ET.Element] = {}
        transitions: dict[str, ET.Element] = {}
        arcs: list[ET.Element] = []
        refs: dict[str, tuple[str, ET.Element]] = {}
        self.collect(net, places, transitions, arcs, refs)
        self.elements = {**places, **transitions}
        self.place_ids = set(places)

        tool = self.tool(net)
        tasks = self.read_tasks(tool) if tool is not None else {}
        marking: dict[str, int] = {}
        place_objs = [self.read_place(pid, elem, marking) for pid, elem in places.items()]
        trans_objs = [self.read_transition(tid, elem) for tid, elem in transitions.items()]
        arc_objs = self.read_arcs(arcs, refs, places, transitions)

        name = self.text(_name_text(net.find("name")) or net.get("id") or "net", "the net's name", net, MAX_NAME)
        description = ""
        home: Marking | None = None
        if tool is not None:
            desc = tool.find("description")
            if desc is not None:
                description = self.text(desc.text or "", "the net's description", desc, MAX_DESCRIPTION,
                                        lines=True)
            home_elem = tool.find("home")
            if home_elem is not None:
                counts: dict[str, int] = {}
                for tok in home_elem.iter("token"):
                    place = tok.get("place", "")
                    if place not in places:
                        raise self.error(f"home marking puts tokens in unknown place {_brief(place)}", tok)
                    counts[place] = self.integer(tok.get("count"), "home token count", tok, 0)
                home = self.guarded(home_elem, lambda: Marking(counts))
        operator = OperatorRights()
        rights = tool.find("operator") if tool is not None else None
        if rights is not None:
            inject = [self.text(e.get("name", ""), "an event the operator may inject", e, MAX_NAME)
                      for e in rights.iter("inject")]
            force: dict[str, list[str]] = {}
            for f in rights.iter("force"):
                force.setdefault(self.text(f.get("task", ""), "a task whose outcome the operator may force", f,
                                           MAX_NAME), []).append(
                    self.text(f.get("outcome", ""), "an outcome the operator may force", f, MAX_NAME))
            operator = self.guarded(rights, lambda: OperatorRights(
                inject=tuple(inject), force={task: tuple(outcomes) for task, outcomes in force.items()}))
        result = self.guarded(net, lambda: PetriNet(
            name=name, places=tuple(place_objs), transitions=tuple(trans_objs), arcs=tuple(arc_objs),
            initial_marking=Marking(marking), tasks=tasks, description=description, home_marking=home,
            operator=operator,
        ))
        for tid, _, problem in result.expression_problems():
            raise self.error(problem, self.elements.get(tid))
        return result

    def collect(self, container: ET.Element, places: dict[str, ET.Element],
                transitions: dict[str, ET.Element], arcs: list[ET.Element],
                refs: dict[str, tuple[str, ET.Element]]) -> None:
        """Gather nodes and arcs of ``container`` and of all its pages, in document order."""
        stack = [iter(container)]
        while stack:
            child = next(stack[-1], None)
            if child is None:
                stack.pop()
                continue
            tag = child.tag
            if tag == "page":
                stack.append(iter(child))
                continue
            if tag not in ("place", "transition", "arc", "referencePlace", "referenceTransition"):
                continue
            ident = child.get("id")
            if not ident:
                raise self.error(f"<{tag}> has no id", child)
            if ident in places or ident in transitions or ident in refs:
                raise self.error(f"duplicate id {_brief(ident)}", child)
            if tag == "place":
                places[ident] = child
            elif tag == "transition":
                transitions[ident] = child
            elif tag == "arc":
                arcs.append(child)
            else:
                ref = child.get("ref")
                if not ref:
                    raise self.error(f"<{tag}> {ident!r} has no ref", child)
                refs[ident] = (ref, child)

    # ---------------------------------------------------------------- nodes
    def read_place(self, pid: str, elem: ET.Element, marking: dict[str, int]) -> Place:
        self.check_id(pid, "place", elem)
        text = _label_text(elem.find("initialMarking"))
        if text:
            tokens = self.integer(text, f"initial marking of place {pid!r}", elem, 0)
            if tokens:
                marking[pid] = tokens
        tool = self.tool(elem)
        if tool is None:
            name = _name_text(elem.find("name"))
            label = self.text(name, f"the name of place {pid!r}", elem, MAX_LABEL) if name and name != pid else ""
            return self.guarded(elem, lambda: Place(id=pid, label=label))
        kind_text = tool.get("kind", "plain")
        try:
            kind = PlaceKind(kind_text)
        except ValueError:
            raise self.error(f"place {pid!r} has unknown kind {_brief(kind_text)}", tool) from None
        capacity = tool.get("capacity")
        cap = None if capacity is None else self.integer(capacity, f"capacity of place {pid!r}", tool, 0)
        label = self.text(tool.get("label", ""), f"label of place {pid!r}", tool, MAX_LABEL)
        return self.guarded(elem, lambda: Place(
            id=pid, kind=kind, task=tool.get("task"), label=label, capacity=cap))

    def check_id(self, ident: str, what: str, elem: ET.Element) -> None:
        problem = id_problem(ident, what)
        if problem is not None:
            raise self.error(problem, elem)

    def read_transition(self, tid: str, elem: ET.Element) -> Transition:
        self.check_id(tid, "transition", elem)
        tool = self.tool(elem)
        if tool is None:
            name = _name_text(elem.find("name"))
            label = self.text(name, f"the name of transition {tid!r}", elem, MAX_LABEL) if name and name != tid else ""
            return self.guarded(elem, lambda: Transition(id=tid, label=label))
        kind_text = tool.get("kind", "immediate")
        try:
            kind = TransitionKind(kind_text)
        except ValueError:
            raise self.error(f"transition {tid!r} has unknown kind {_brief(kind_text)}", tool) from None
        events: list[str] = []
        for ev in tool.iter("event"):
            problem = event_problem(ev.get("name", ""))
            if problem is not None:
                raise self.error(f"transition {tid!r} links a {problem}", ev)
            events.append(ev.get("name", ""))
        servers_text = tool.get("servers", "1")
        servers = None if servers_text == "infinite" else self.integer(
            servers_text, f"servers of transition {tid!r}", tool, 1)
        rate = self.number(tool.get("rate"), f"rate of transition {tid!r}", tool, "rate_expr")
        weight = self.number(tool.get("weight", "1.0"), f"weight of transition {tid!r}", tool, "weight_expr")
        rate_expr = self.expression(tool.get("rate_expr"), "rate", tid, tool)
        weight_expr = self.expression(tool.get("weight_expr"), "weight", tid, tool)
        hidden = tool.get("hidden", "false")
        if hidden not in ("true", "false"):
            raise self.error(f"transition {tid!r}: hidden must be 'true' or 'false', not {_brief(hidden)}", tool)
        priority = self.integer(tool.get("priority", "0"), f"priority of transition {tid!r}", tool,
                                -MAX_PRIORITY - 1, MAX_PRIORITY)
        label = self.text(tool.get("label", ""), f"label of transition {tid!r}", tool, MAX_LABEL)
        return self.guarded(elem, lambda: Transition(
            id=tid, events=tuple(events), priority=priority, weight=1.0 if weight is None else weight,
            kind=kind, rate=rate, servers=servers, hidden=hidden == "true", label=label,
            rate_expr=rate_expr, weight_expr=weight_expr,
        ))

    def expression(self, text: str | None, what: str, tid: str, elem: ET.Element) -> str | None:
        """Check a ``rate_expr`` or ``weight_expr`` attribute: limits, syntax, type, place ids."""
        if text is None:
            return None
        self.text(text, f"{what} expression of transition {tid!r}", elem, MAX_EXPRESSION)
        try:
            check_places(parse(text, kind="num"), text, self.place_ids)
        except ExprError as exc:
            raise self.error(f"{what} of transition {tid!r}: {exc.message} (column {exc.column} of "
                             f"{_brief(text)})", elem) from None
        return text

    def read_arcs(self, arcs: list[ET.Element], refs: dict[str, tuple[str, ET.Element]],
                  places: dict[str, ET.Element], transitions: dict[str, ET.Element]) -> list[Arc]:
        """The arcs, those between the same nodes of the same kind merged (weights added). The
        common case is read with no call per arc but the net model's: a node that is no reference,
        and an arc with no child (no inscription: weight 1) or an inscription alone
        (StigmergyElection-PT-09b's 720,585 arcs: 4.4 s before, most of it in calls per arc)."""
        def resolve(node: str, elem: ET.Element) -> str:
            seen: set[str] = set()
            while node in refs and node not in seen:
                seen.add(node)
                node = refs[node][0]
            if node not in places and node not in transitions:
                raise self.error(f"arc {_brief(elem.get('id'))} refers to unknown node {_brief(node)}", elem)
            return node

        merged: dict[tuple[str, str, str], int] = {}
        first_elem: dict[tuple[str, str, str], ET.Element] = {}
        for elem in arcs:
            source = elem.get("source") or ""
            if source in refs or (source not in places and source not in transitions):
                source = resolve(source, elem)
            target = elem.get("target") or ""
            if target in refs or (target not in places and target not in transitions):
                target = resolve(target, elem)
            if (source in places) == (target in places):
                what = "places" if source in places else "transitions"
                raise self.error(f"arc {elem.get('id')!r} joins two {what} ({source} -> {target}); "
                                 "arcs join a place and a transition", elem)
            n_children = len(elem)
            inscription = None if n_children == 0 else elem.find("inscription")
            text = None if inscription is None else _label_text(inscription)
            weight = 1 if not text else self.integer(text, f"weight of arc {elem.get('id')!r}", elem, 1)
            if n_children == 0 or (n_children == 1 and inscription is not None):
                key = (source, target, "normal")
            else:
                tool = self.tool(elem)
                type_elem = elem.find("type")
                arc_type = None if type_elem is None else (type_elem.get("value") or _label_text(type_elem))
                inhibitor = (tool is not None and tool.get("inhibitor") == "true") or arc_type == "inhibitor"
                reset = (tool is not None and tool.get("reset") == "true") or arc_type == "reset"
                if inhibitor and reset:
                    raise self.error(f"arc {elem.get('id')!r} cannot be both a reset and an inhibitor arc", elem)
                if reset and weight != 1:
                    raise self.error(f"reset arc {elem.get('id')!r} has weight {weight}; a reset arc empties its "
                                     "place whatever it holds, so it takes no weight", elem)
                if reset and source not in places:
                    raise self.error(f"reset arc {elem.get('id')!r} must go from a place to a transition", elem)
                key = (source, target, "inhibitor" if inhibitor else "reset" if reset else "normal")
            total = 1 if key[2] == "reset" else merged.get(key, 0) + weight
            if total > MAX_COUNT:
                raise self.error(f"arcs {source} -> {target} add up to weight {total}; the limit is "
                                 f"{MAX_COUNT}", elem)
            merged[key] = total
            if key not in first_elem:
                first_elem[key] = elem

        def arc(key: tuple[str, str, str], weight: int) -> Arc:
            return Arc(source=key[0], target=key[1], weight=weight, inhibitor=key[2] == "inhibitor",
                       reset=key[2] == "reset")

        out: list[Arc] = []
        try:
            for key, w in merged.items():
                out.append(arc(key, w))
        except (NetError, TypeError, ValueError):
            # the arc that failed, again, with its element's line
            key, w = list(merged.items())[len(out)]
            self.guarded(first_elem[key], partial(arc, key, w))
            raise
        return out

    # ---------------------------------------------------------------- tasks
    def read_tasks(self, tool: ET.Element) -> dict[str, PrimitiveTask]:
        tasks: dict[str, PrimitiveTask] = {}
        container = tool.find("tasks")
        if container is None:
            return tasks
        for elem in container.iter("task"):
            name = elem.get("name", "")
            problem = task_name_problem(name)
            if problem is not None:
                raise self.error(problem, elem)
            if name in tasks:
                raise self.error(f"primitive task {name!r} is defined twice", elem)
            self.elements.setdefault(name, elem)
            actions: list[ActionSpec] = []
            for act in elem.iter("action"):
                self.check_id(act.get("name", ""), "action", act)
                cost = self.number(act.get("cost"), f"cost of action {act.get('name')!r}", act)
                actions.append(self.guarded(act, partial(
                    ActionSpec, name=act.get("name", ""), params=self.toml_table(act.find("params")), cost=cost)))
            numbers = {key: self.number(elem.get(key), f"{key} of task {name!r}", elem)
                       for key in ("deadline_s", "mean_time_s", "reliability")}
            tasks[name] = self.guarded(elem, partial(
                PrimitiveTask, name=name, actions=tuple(actions), learner=self.toml_table(elem.find("learner")),
                **numbers))
        return tasks

    def toml_table(self, elem: ET.Element | None) -> dict[str, Any]:
        """Read a table kept as a TOML inline table in the text of ``elem``."""
        if elem is None or not (elem.text or "").strip():
            return {}
        text = (elem.text or "").strip()
        try:
            doc, _ = parse_toml("value = " + text)
        except TextProblem as exc:
            raise self.error(f"<{elem.tag}> does not hold a TOML inline table: {exc.problem}", elem) from None
        value = doc.get("value")
        if set(doc) != {"value"} or not isinstance(value, dict):
            raise self.error(f"<{elem.tag}> does not hold a TOML inline table {{ key = value, ... }}", elem)
        return value


def loads_pnml(text: str | bytes, path: str = "<string>", *, net_id: str | None = None,
               interpreted: bool = False, max_bytes: int = MAX_FILE_BYTES) -> PetriNet:
    """Read a PNML document.

    Args:
        text: the XML document, UTF-8 when given as bytes.
        path: name used in error messages.
        net_id: id of the ``<net>`` to read when the document holds several.
        interpreted: also apply :meth:`PetriNet.interpretation_problems` (a net with primitive
            tasks), reporting the first at the line of its element.
        max_bytes: the largest document read, bytes (16 MiB: what a file from elsewhere may
            cost; ``petrobot analyze`` raises it for a model file of the user's own).

    Returns:
        The net. Without petrobot tool-specific data, places are plain and transitions immediate.

    Raises:
        NetFileError: on text that is not UTF-8 or holds NUL, more than ``max_bytes``, malformed XML, a
            document type declaration, elements nested deeper than 256, a document with no or
            several nets, a non-P/T net type.
        NetError: on a structural problem (unknown arc end, arc between two places, bad marking or
            inscription, duplicate id, a value beyond the limits of docs/netfile.md), naming
            ``path`` and the element's line.
    """
    try:
        if isinstance(text, str):
            screen_text(text, max_bytes)
            data = text.encode("utf-8")
        else:
            if len(text) > max_bytes:
                raise TextProblem(f"net file too large: {len(text)} bytes (the limit is {size_text(max_bytes)})", 1)
            decode_utf8(text, max_bytes)
            data = text
    except TextProblem as exc:
        raise NetFileError(exc.problem, path=path, line=exc.line) from None
    root, lines = _parse_xml(data, path)
    reader = _Reader(root, lines, path)
    net = reader.net(net_id)
    return reader.interpreted(net) if interpreted else net


def load_pnml(path: str | Path, *, net_id: str | None = None, interpreted: bool = False,
              max_bytes: int = MAX_FILE_BYTES) -> PetriNet:
    """Read a PNML file (a regular file of at most ``max_bytes``, 16 MiB by default); see :func:`loads_pnml`.

    Raises:
        NetFileError: if the file cannot be read, or as :func:`loads_pnml`.
        NetError: as :func:`loads_pnml`.
    """
    try:
        data = read_capped(path, what="net file", limit=max_bytes)
    except TextProblem as exc:
        raise NetFileError(exc.problem, path=str(path), line=exc.line) from None
    return loads_pnml(data, str(path), net_id=net_id, interpreted=interpreted, max_bytes=max_bytes)


# ---------------------------------------------------------------------------------------- writing
def _num(value: float) -> str:
    """Exact text of a float (``repr`` round-trips)."""
    if math.isnan(value) or math.isinf(value):
        raise NetError(f"cannot write non-finite number {value!r} to PNML")
    return repr(float(value))


def _attrs(pairs: dict[str, str | None]) -> str:
    return "".join(f" {k}={quoteattr(v)}" for k, v in pairs.items() if v is not None)


def _graphics(layout: Mapping[str, tuple[float, float]] | None, ident: str) -> list[str]:
    if layout is None or ident not in layout:
        return []
    x, y = layout[ident]
    return [f'        <graphics><position x="{_num(round(float(x), 1))}" y="{_num(round(float(y), 1))}"/></graphics>']


def dump_pnml(net: PetriNet, layout: Mapping[str, tuple[float, float]] | None = None) -> str:
    """Write a net as a PNML document (2009 grammar, one page, petrobot tool-specific data).

    Arc ids are generated (``a1``, ``a2``... made unique against node ids); the net's ``id`` is
    ``net`` and its name label carries :attr:`PetriNet.name`. ``layout`` (id → (x, y),
    :mod:`~coordinator.netfile.layout`) adds ``<graphics><position>`` to the nodes it names.

    Returns:
        The XML text, UTF-8, with an XML declaration.

    Raises:
        NetError: if a number to write is not finite.
    """
    out: list[str] = ['<?xml version="1.0" encoding="utf-8"?>', f'<pnml xmlns="{PNML_NS}">',
                      f'  <net id="net" type="{PTNET_TYPE}">',
                      f"    <name><text>{escape(net.name)}</text></name>"]
    net_tool: list[str] = []
    if net.description:
        net_tool.append(f"        <description>{escape(net.description)}</description>")
    if net.home_marking is not None:
        net_tool.append("        <home>")
        net_tool += [f"          <token{_attrs({'place': p, 'count': str(c)})}/>" for p, c in net.home_marking.items()]
        net_tool.append("        </home>")
    if net.tasks:
        net_tool.append("        <tasks>")
        for task in net.tasks.values():
            net_tool.append("          <task" + _attrs({
                "name": task.name,
                "deadline_s": None if task.deadline_s is None else _num(task.deadline_s),
                "mean_time_s": None if task.mean_time_s is None else _num(task.mean_time_s),
                "reliability": None if task.reliability is None else _num(task.reliability),
            }) + ">")
            for action in task.actions:
                attrs = _attrs({"name": action.name, "cost": None if action.cost is None else _num(action.cost)})
                if action.params:
                    net_tool.append(f"            <action{attrs}><params>"
                                    f"{escape(format_value(dict(action.params)))}</params></action>")
                else:
                    net_tool.append(f"            <action{attrs}/>")
            if task.learner:
                net_tool.append(f"            <learner>{escape(format_value(dict(task.learner)))}</learner>")
            net_tool.append("          </task>")
        net_tool.append("        </tasks>")
    if net.operator:
        net_tool.append("        <operator>")
        net_tool += [f"          <inject{_attrs({'name': e})}/>" for e in net.operator.inject]
        net_tool += [f"          <force{_attrs({'task': task, 'outcome': o})}/>"
                     for task, outcomes in net.operator.force.items() for o in outcomes]
        net_tool.append("        </operator>")
    if net_tool:
        out.append(f'    <toolspecific tool="{TOOL}" version="{TOOL_VERSION}">')
        out += [line[2:] for line in net_tool]
        out.append("    </toolspecific>")
    out.append('    <page id="page0">')
    for place in net.places:
        out.append(f"      <place id={quoteattr(place.id)}>")
        out.append(f"        <name><text>{escape(place.label or place.id)}</text></name>")
        out += _graphics(layout, place.id)
        tokens = net.initial_marking[place.id]
        if tokens:
            out.append(f"        <initialMarking><text>{tokens}</text></initialMarking>")
        out.append(f'        <toolspecific tool="{TOOL}" version="{TOOL_VERSION}"' + _attrs({
            "kind": place.kind.value, "task": place.task, "label": place.label or None,
            "capacity": None if place.capacity is None else str(place.capacity),
        }) + "/>")
        out.append("      </place>")
    for t in net.transitions:
        out.append(f"      <transition id={quoteattr(t.id)}>")
        out.append(f"        <name><text>{escape(t.label or t.id)}</text></name>")
        out += _graphics(layout, t.id)
        head = f'        <toolspecific tool="{TOOL}" version="{TOOL_VERSION}"' + _attrs({
            "kind": t.kind.value, "priority": str(t.priority), "weight": _num(t.weight),
            "rate": None if t.rate is None else _num(t.rate), "rate_expr": t.rate_expr,
            "weight_expr": t.weight_expr,
            "servers": "infinite" if t.servers is None else str(t.servers),
            "hidden": "true" if t.hidden else "false", "label": t.label or None,
        })
        if t.events:
            out.append(head + ">")
            out += [f"          <event name={quoteattr(e)}/>" for e in t.events]
            out.append("        </toolspecific>")
        else:
            out.append(head + "/>")
        out.append("      </transition>")
    taken = {p.id for p in net.places} | {t.id for t in net.transitions} | {"net", "page0"}
    for counter, arc in enumerate(net.arcs, start=1):
        arc_id = f"a{counter}"
        while arc_id in taken:
            arc_id = "_" + arc_id
        out.append(f"      <arc{_attrs({'id': arc_id, 'source': arc.source, 'target': arc.target})}>")
        if arc.weight != 1:
            out.append(f"        <inscription><text>{arc.weight}</text></inscription>")
        if arc.inhibitor:
            out.append(f'        <toolspecific tool="{TOOL}" version="{TOOL_VERSION}" inhibitor="true"/>')
        if arc.reset:
            out.append(f'        <toolspecific tool="{TOOL}" version="{TOOL_VERSION}" reset="true"/>')
        out.append("      </arc>")
    out += ["    </page>", "  </net>", "</pnml>", ""]
    return "\n".join(out)


def save_pnml(net: PetriNet, path: str | Path) -> None:
    """Write :func:`dump_pnml` of ``net`` to ``path`` (UTF-8).

    Raises:
        NetFileError: if the file cannot be written.
    """
    try:
        write_atomically(path, dump_pnml(net))
    except OSError as exc:
        raise NetFileError(f"cannot write net file: {exc.strerror or exc}", path=str(path)) from None
