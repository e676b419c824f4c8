"""The Petri-net model of a robotic task (paper section 2): structure and firing rule, no I/O.

A :class:`PetriNet` is frozen and keyed by ids: two nets loaded from the same file compare equal.
Its places carry a :class:`PlaceKind` — *resource* (a robot, a camera), *primitive_task* (a token
there means a primitive action of that primitive task is running), *control* (edited by the
operator, e.g. ``runs_remaining``) or *plain*. Its transitions carry the events linked to them
(``int:<task>.<outcome>`` raised by a primitive task, ``ext:<topic>`` raised by a sensor or device),
a priority and a weight for conflict resolution and, for the GSPN view (section 2, "Quantitative
Performance Evaluation"), a kind (immediate or exponential), a rate and a server semantics. A rate
or a weight may instead be a marking expression (``rate_expr = "min(1, #Np / 3) * #P"``, the
language of :mod:`coordinator.expr`): its value in the current marking, with no server multiplier.

A :class:`Marking` maps place ids to token counts. It is immutable and hashable; places with zero
tokens are not stored, so ``Marking({"p": 0}) == Marking({})``.

Firing rule (ordinary P/T semantics with inhibitor and reset arcs): transition *t* is enabled in
marking *M* when ``M(p) >= W(p, t)`` for every input place *p* and ``M(q) < I(q, t)`` for every
inhibitor arc of weight ``I(q, t)`` (reset arcs play no part in enabling); firing consumes the
input arcs, then empties every place *r* with a reset arc r → t, then produces the output arcs:
``M'(p) = M(p) - Pre[p, t] + Post[p, t]`` off the reset places and ``M'(r) = Post[r, t]`` on them.
A reset arc may sit beside an input, output or inhibitor arc between the same place and
transition; each keeps its meaning (docs/netfile.md, "Reset arcs"). The interpreted-net
execution semantics (events, busy tokens of running primitive actions) are in
:mod:`coordinator.engine`; this module is the structure they share with the analyses.

The module is longer than most: it is one concept, the frozen model, whose classes refer to each
other and which every layer imports whole. ``numpy`` is imported on the first use of a matrix
(:attr:`PetriNet.incidence`...), so that loading and checking a net does not pay for it.
"""

from __future__ import annotations

import enum
import numbers
import re
from collections.abc import ItemsView, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from coordinator.errors import NetError, NotEnabledError
from coordinator.expr import ExprError, Node, check_places, evaluate, parse

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "PlaceKind",
    "TransitionKind",
    "Place",
    "Transition",
    "Arc",
    "ActionSpec",
    "PrimitiveTask",
    "OperatorRights",
    "FORCE_STATUSES",
    "Marking",
    "PetriNet",
    "parse_event",
    "EVENT_RE",
    "INFINITE_SERVERS",
]

#: Event names: ``int:<task>.<outcome>`` or ``ext:<topic>``; identifiers are ``[A-Za-z_][A-Za-z0-9_]*``.
EVENT_RE = re.compile(
    r"^(?:int:(?P<task>[A-Za-z_][A-Za-z0-9_]*)\.(?P<outcome>[A-Za-z_][A-Za-z0-9_]*)"
    r"|ext:(?P<topic>[A-Za-z_][A-Za-z0-9_]*))$"
)
_ID_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: Value of :attr:`Transition.servers` for infinite-server semantics.
INFINITE_SERVERS: None = None


def parse_event(name: str) -> tuple[str, str, str]:
    """Split an event name into its parts.

    Args:
        name: ``"int:<task>.<outcome>"`` or ``"ext:<topic>"``.

    Returns:
        ``("int", task, outcome)`` or ``("ext", topic, "")``.

    Raises:
        NetError: if the name matches neither form.
    """
    match = EVENT_RE.match(name)
    if match is None:
        raise NetError(
            f"bad event name {name!r}: expected 'int:<task>.<outcome>' or 'ext:<topic>' "
            "with identifiers made of letters, digits and '_'"
        )
    if match.group("task") is not None:
        return ("int", match.group("task"), match.group("outcome"))
    return ("ext", match.group("topic"), "")


class PlaceKind(enum.Enum):
    """What a place stands for in the robotic task model (section 2)."""

    #: A resource: a robot, a camera, an object to be manipulated.
    RESOURCE = "resource"
    #: A primitive task: each token is one running instance of one of its primitive actions.
    PRIMITIVE_TASK = "primitive_task"
    #: A place for task flow control only; the operator inserts and removes its tokens (section 5).
    CONTROL = "control"
    #: Any other place (a condition, a buffer).
    PLAIN = "plain"


class TransitionKind(enum.Enum):
    """Timing of a transition in the GSPN view."""

    #: Fires in zero time; conflicts among immediate transitions are random switches (weights).
    IMMEDIATE = "immediate"
    #: Fires after an exponentially distributed delay of rate :attr:`Transition.rate` (1/s).
    EXPONENTIAL = "exponential"


def _shown(text: str) -> str:
    return repr(text if len(text) <= 80 else text[:77] + "...")


def _check_id(what: str, value: str) -> None:
    if not isinstance(value, str) or not _ID_RE.match(value):
        raise NetError(
            f"bad {what} id {value!r}: use letters, digits, '_', '.', '-', starting with a letter or '_'"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Place:
    """A place of the net.

    Attributes:
        id: unique id within the net.
        kind: what the place stands for.
        task: name of the primitive task, for ``kind == PRIMITIVE_TASK`` only.
        label: text for displays; defaults to the id.
        capacity: informational bound on tokens (not enforced by the firing rule), or ``None``.
    """

    id: str
    kind: PlaceKind = PlaceKind.PLAIN
    task: str | None = None
    label: str = ""
    capacity: int | None = None

    def __post_init__(self) -> None:
        _check_id("place", self.id)
        if self.kind is PlaceKind.PRIMITIVE_TASK and not self.task:
            raise NetError(f"primitive_task place {self.id!r} names no task")
        if self.kind is not PlaceKind.PRIMITIVE_TASK and self.task is not None:
            raise NetError(f"place {self.id!r} of kind {self.kind.value} cannot name a task")
        if self.capacity is not None and self.capacity < 0:
            raise NetError(f"place {self.id!r} has a negative capacity {self.capacity}")


@dataclass(frozen=True, slots=True, kw_only=True)
class Transition:
    """A transition of the net.

    Attributes:
        id: unique id within the net.
        events: events linked to the transition (section 2); it fires when enabled *and* every linked
            event has occurred. No events: fires as soon as it is enabled.
        priority: conflict resolution, higher first (GSPN priority of immediate transitions).
        weight: random-switch weight among fireable transitions of equal priority (> 0).
        kind: immediate or exponential (GSPN view).
        rate: firing rate in 1/s of an exponential transition (per server), else ``None``.
        servers: 1 for single-server, ``None`` (:data:`INFINITE_SERVERS`) for infinite-server
            semantics, or any k ≥ 1 for k-server semantics.
        hidden: an error-recovery branch that displays may hide (section 2).
        label: text for displays; defaults to the id.
        rate_expr: a marking-dependent rate instead of ``rate`` (exponential transitions): a
            number expression of :mod:`coordinator.expr` whose value in marking M, in 1/s, is the
            firing rate of the transition when it is enabled in M; no server multiplier applies
            (``servers`` stays 1: write it into the expression, e.g. ``"min(#q, 3) * 2"``). A
            value of 0 means the transition does not fire in M; a negative or non-finite value is an
            error of the analysis that meets it.
        weight_expr: a marking-dependent weight instead of ``weight``: its value in the current
            marking is the weight of the random switch; it must be > 0 wherever the transition
            takes part in a switch (the engine, the simulator and the GSPN analysis raise
            otherwise).

    Raises:
        NetError: on a bad value or combination, or an expression that does not parse (with its
            column).
    """

    id: str
    events: tuple[str, ...] = ()
    priority: int = 0
    weight: float = 1.0
    kind: TransitionKind = TransitionKind.IMMEDIATE
    rate: float | None = None
    servers: int | None = 1
    hidden: bool = False
    label: str = ""
    rate_expr: str | None = None
    weight_expr: str | None = None

    def __post_init__(self) -> None:
        _check_id("transition", self.id)
        for event in self.events:
            parse_event(event)
        if len(set(self.events)) != len(self.events):
            raise NetError(f"transition {self.id!r} lists an event twice")
        if not self.weight > 0:
            raise NetError(f"transition {self.id!r} has weight {self.weight}; weights must be > 0")
        if self.weight_expr is not None:
            self._parsed("weight")
            if self.weight != 1.0:
                raise NetError(f"transition {self.id!r} gives both a weight ({self.weight}) and a weight "
                               "expression; give one")
        if self.rate_expr is not None:
            self._parsed("rate")
            if self.kind is not TransitionKind.EXPONENTIAL:
                raise NetError(f"immediate transition {self.id!r} cannot have a rate")
            if self.rate is not None:
                raise NetError(f"transition {self.id!r} gives both a rate ({self.rate}) and a rate expression; "
                               "give one")
            if self.servers != 1:
                raise NetError(f"transition {self.id!r} has a rate expression and servers = "
                               f"{'infinite' if self.servers is None else self.servers}: a marking-dependent "
                               "rate is the whole rate, write the servers into it (e.g. \"min(#q, 3) * 2\")")
        elif self.kind is TransitionKind.EXPONENTIAL:
            if self.rate is None or not self.rate > 0:
                raise NetError(f"exponential transition {self.id!r} needs a rate > 0 (1/s)")
        elif self.rate is not None:
            raise NetError(f"immediate transition {self.id!r} cannot have a rate")
        if self.servers is not None and self.servers < 1:
            raise NetError(f"transition {self.id!r} has servers={self.servers}; use >= 1 or 'infinite'")

    def _parsed(self, what: str) -> Node:
        text = self.rate_expr if what == "rate" else self.weight_expr
        assert text is not None
        if not isinstance(text, str):
            raise NetError(f"{what} expression of transition {self.id!r} must be a string, not {text!r}")
        try:
            return parse(text, kind="num")
        except ExprError as exc:
            raise NetError(f"{what} of transition {self.id!r}: {exc.message} (column {exc.column} of "
                           f"{_shown(text)})") from None

    @property
    def rate_tree(self) -> Node | None:
        """The parsed :attr:`rate_expr`, or ``None`` (parsed on each call: compile it once)."""
        return None if self.rate_expr is None else self._parsed("rate")

    @property
    def weight_tree(self) -> Node | None:
        """The parsed :attr:`weight_expr`, or ``None`` (parsed on each call: compile it once)."""
        return None if self.weight_expr is None else self._parsed("weight")

    @property
    def marking_dependent(self) -> bool:
        """True when the rate or the weight is a marking expression."""
        return self.rate_expr is not None or self.weight_expr is not None

    @property
    def external_events(self) -> tuple[str, ...]:
        """The ``ext:`` events linked to this transition."""
        return tuple(e for e in self.events if e.startswith("ext:"))

    @property
    def internal_events(self) -> tuple[str, ...]:
        """The ``int:`` events linked to this transition."""
        return tuple(e for e in self.events if e.startswith("int:"))


@dataclass(frozen=True, slots=True, kw_only=True)
class Arc:
    """An arc between a place and a transition (either direction).

    Attributes:
        source: id of a place or a transition.
        target: id of a transition or a place (the other kind).
        weight: multiplicity, ≥ 1.
        inhibitor: an inhibitor arc (place → transition only): the transition is disabled while the
            place holds ``weight`` tokens or more.
        reset: a reset ("flush") arc (place → transition only, weight 1): firing the transition
            empties the place after its input arcs have consumed; it plays no part in enabling.
    """

    source: str
    target: str
    weight: int = 1
    inhibitor: bool = False
    reset: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.weight, int) or isinstance(self.weight, bool) or self.weight < 1:
            raise NetError(
                f"arc {self.source} -> {self.target} has weight {self.weight!r}; weights are integers >= 1"
            )
        if self.reset and self.inhibitor:
            raise NetError(f"arc {self.source} -> {self.target} cannot be both a reset and an inhibitor arc; "
                           "give two arcs")
        if self.reset and self.weight != 1:
            raise NetError(f"reset arc {self.source} -> {self.target} has weight {self.weight}; a reset arc "
                           "empties its place whatever it holds, so it takes no weight")

    @property
    def kind(self) -> str:
        """``"normal"``, ``"inhibitor"`` or ``"reset"``."""
        return "inhibitor" if self.inhibitor else "reset" if self.reset else "normal"


@dataclass(frozen=True, slots=True, kw_only=True)
class ActionSpec:
    """One primitive action that can translate a primitive task (section 2).

    Attributes:
        name: the action's name in ``services.toml``.
        params: parameters passed to the action on every call.
        cost: a-priori cost C(a) in the task's cost unit (section 3), or ``None`` if measured only.
    """

    name: str
    params: Mapping[str, Any] = field(default_factory=dict, hash=False)
    cost: float | None = None

    def __post_init__(self) -> None:
        _check_id("action", self.name)
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        if self.cost is not None and self.cost < 0:
            raise NetError(f"action {self.name!r} has a negative cost {self.cost}")


#: The statuses an operator may force on a running primitive action (``[operator] force``).
FORCE_STATUSES = ("success", "failure", "error")


def _forced_problem(task: str, outcome: str) -> str | None:
    """Why ``outcome`` cannot be written in ``[operator] force`` for ``task``, or ``None``."""
    status, _, named = outcome.partition(".")
    if status not in FORCE_STATUSES or (named and not _NAME_RE.match(named)) or (_ and not named):
        return (f"operator may force {outcome!r} on task {task!r}: write a status (success, failure, error) or "
                "a status and a named outcome, e.g. 'failure.no_ball'")
    return None


@dataclass(frozen=True, slots=True, kw_only=True)
class OperatorRights:
    """What an operator may force from a console (paper section 5; the ``[operator]`` table of a net
    file, docs/netfile.md): raise external events and force the outcome of running primitive actions,
    for training and recovery drills (the idea of FlexBE's autonomy levels). Everything forced is
    journaled as the operator's and never counts as a measured result (``perf``, the learners).

    Attributes:
        inject: the ``ext:<topic>`` events an operator may raise.
        force: primitive task → the outcomes an operator may force on its running action: a status
            (``success``, ``failure``, ``error``) or a status and a named outcome
            (``failure.no_ball``: status failure, ``int:<task>.no_ball`` raised).
    """

    inject: tuple[str, ...] = ()
    force: Mapping[str, tuple[str, ...]] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inject", tuple(self.inject))
        object.__setattr__(self, "force", MappingProxyType({k: tuple(v) for k, v in self.force.items()}))
        for event in self.inject:
            m = EVENT_RE.match(event) if isinstance(event, str) else None
            if m is None or m.group("topic") is None:
                raise NetError(f"operator may inject {event!r}: only external events (ext:<topic>) can be raised")
        for task, outcomes in self.force.items():
            for outcome in outcomes:
                problem = _forced_problem(task, outcome) if isinstance(outcome, str) else \
                    f"operator may force {outcome!r} on task {task!r}: an outcome is a string"
                if problem is not None:
                    raise NetError(problem)

    def __bool__(self) -> bool:
        return bool(self.inject or self.force)

    def may_inject(self, event: str) -> bool:
        """Whether the operator may raise ``event`` (``ext:<topic>``)."""
        return event in self.inject

    def may_force(self, task: str, outcome: str) -> bool:
        """Whether the operator may force ``outcome`` (``status`` or ``status.named``) on ``task``."""
        return outcome in self.force.get(task, ())

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OperatorRights):
            return NotImplemented
        return self.inject == other.inject and dict(self.force) == dict(other.force)

    def __hash__(self) -> int:
        return hash((self.inject, tuple(sorted(self.force))))


@dataclass(frozen=True, slots=True, kw_only=True)
class PrimitiveTask:
    """A primitive task and its alternative primitive actions (sections 2 and 4).

    Attributes:
        name: the task name used in places and ``int:<name>.<outcome>`` events.
        actions: the translating primitive actions (at least one).
        deadline_s: deadline of one instance in seconds; exceeding it is an ``error`` status.
        learner: learning configuration (section 4), e.g. ``{"scheme": "pursuit", "rate": 0.05}``;
            empty means the first action is always chosen.
        mean_time_s: a-priori mean duration of an instance in seconds (GSPN view), or ``None``.
        reliability: a-priori probability of the normal exit (GSPN random switch), or ``None``.
    """

    name: str
    actions: tuple[ActionSpec, ...]
    deadline_s: float | None = None
    learner: Mapping[str, Any] = field(default_factory=dict, hash=False)
    mean_time_s: float | None = None
    reliability: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.match(self.name):
            raise NetError(f"bad primitive task name {self.name!r}: it appears in 'int:<task>.<outcome>' events, "
                           "so use letters, digits and '_', starting with a letter or '_'")
        if not self.actions:
            raise NetError(f"primitive task {self.name!r} has no primitive action")
        names = [a.name for a in self.actions]
        if len(set(names)) != len(names):
            raise NetError(f"primitive task {self.name!r} lists an action twice")
        object.__setattr__(self, "learner", MappingProxyType(dict(self.learner)))
        if self.deadline_s is not None and not self.deadline_s > 0:
            raise NetError(f"primitive task {self.name!r} has deadline {self.deadline_s}; must be > 0 s")
        if self.mean_time_s is not None and not self.mean_time_s > 0:
            raise NetError(f"primitive task {self.name!r} has mean_time_s {self.mean_time_s}; must be > 0")
        if self.reliability is not None and not 0.0 <= self.reliability <= 1.0:
            raise NetError(f"primitive task {self.name!r} has reliability {self.reliability}; must be in [0, 1]")

    def action(self, name: str) -> ActionSpec:
        """Return the action called ``name``.

        Raises:
            KeyError: if the task has no such action.
        """
        for spec in self.actions:
            if spec.name == name:
                return spec
        raise KeyError(f"primitive task {self.name!r} has no action {name!r}")


class Marking(Mapping[str, int]):
    """An immutable, hashable marking: place id → token count (≥ 0).

    Missing places hold 0 tokens; zero counts are not stored. Equality and hash ignore order.

    Raises:
        NetError: on a negative or non-integer count.
    """

    __slots__ = ("_items", "_hash")

    def __init__(self, tokens: Mapping[str, int] | Iterable[tuple[str, int]] = ()) -> None:
        items = tokens.items() if isinstance(tokens, Mapping) else tokens
        data: dict[str, int] = {}
        for place, count in items:
            if isinstance(count, bool) or not isinstance(count, (int, numbers.Integral)):
                raise NetError(f"token count of {place!r} must be an integer, got {count!r}")
            if count < 0:
                raise NetError(f"token count of {place!r} is negative ({count})")
            if count:
                data[str(place)] = int(count)
        self._items: dict[str, int] = dict(sorted(data.items()))
        self._hash: int | None = None

    @classmethod
    def from_counts(cls, counts: Mapping[str, int]) -> Marking:
        """The marking of ``counts`` that whoever counted them keeps non-negative integers (an
        engine's place counts): zeros dropped, no other check, for a reader that asks many times a
        second (the web console's frames)."""
        m = cls.__new__(cls)
        m._items = dict(sorted((p, n) for p, n in counts.items() if n))
        m._hash = None
        return m

    def __getitem__(self, place: str) -> int:
        return self._items.get(place, 0)

    def items(self) -> ItemsView[str, int]:
        """(place, tokens) of the non-empty places, in place order."""
        return self._items.items()

    def __contains__(self, place: object) -> bool:
        return place in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        if self._hash is None:
            self._hash = hash(tuple(self._items.items()))
        return self._hash

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Marking):
            return self._items == other._items
        if isinstance(other, Mapping):
            return self._items == {k: v for k, v in other.items() if v}
        return NotImplemented

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}: {v}" for k, v in self._items.items())
        return f"Marking({{{inner}}})"

    @property
    def total(self) -> int:
        """Total number of tokens."""
        return sum(self._items.values())

    def add(self, delta: Mapping[str, int]) -> Marking:
        """Return a new marking with ``delta`` (place → signed change) added.

        Raises:
            NetError: if a count would become negative.
        """
        data = dict(self._items)
        for place, change in delta.items():
            data[place] = data.get(place, 0) + change
        return Marking(data)

    def to_dict(self) -> dict[str, int]:
        """Return a plain dict of the non-empty places (for serialisation)."""
        return dict(self._items)


@dataclass(frozen=True, eq=True)
class PetriNet:
    """A frozen, id-keyed Petri net: places, transitions, arcs, initial marking, primitive tasks.

    Build with keyword arguments; ``PetriNet.build(...)`` accepts any iterables. The constructor
    checks the structure (unknown ids, place→place arcs, duplicate arcs, unknown tasks) and raises
    :class:`~coordinator.errors.NetError`; interpretation checks (exits of primitive tasks, events)
    are in :meth:`interpretation_problems`.

    Attributes:
        name: net name.
        places: places in a fixed order (the row order of every matrix).
        transitions: transitions in a fixed order (the column order of every matrix).
        arcs: arcs.
        initial_marking: M0.
        tasks: primitive tasks by name.
        description: free text.
        home_marking: a declared home marking for reversibility analysis, or ``None`` (M0 is used).
        operator: what an operator may force from a console (events raised, outcomes forced).
    """

    name: str
    places: tuple[Place, ...]
    transitions: tuple[Transition, ...]
    arcs: tuple[Arc, ...]
    initial_marking: Marking = field(default_factory=Marking)
    tasks: Mapping[str, PrimitiveTask] = field(default_factory=dict, hash=False)
    description: str = ""
    home_marking: Marking | None = None
    operator: OperatorRights = field(default_factory=OperatorRights, hash=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "places", tuple(self.places))
        object.__setattr__(self, "transitions", tuple(self.transitions))
        object.__setattr__(self, "arcs", tuple(self.arcs))
        object.__setattr__(self, "tasks", MappingProxyType(dict(self.tasks)))
        if not isinstance(self.initial_marking, Marking):
            object.__setattr__(self, "initial_marking", Marking(self.initial_marking))
        if self.home_marking is not None and not isinstance(self.home_marking, Marking):
            object.__setattr__(self, "home_marking", Marking(self.home_marking))
        self._check_structure()

    # ------------------------------------------------------------------ construction checks
    def _check_structure(self) -> None:
        place_ids = [p.id for p in self.places]
        trans_ids = [t.id for t in self.transitions]
        for what, ids in (("place", place_ids), ("transition", trans_ids)):
            seen: set[str] = set()
            for i in ids:
                if i in seen:
                    raise NetError(f"duplicate {what} id {i!r}")
                seen.add(i)
        both = set(place_ids) & set(trans_ids)
        if both:
            raise NetError(f"id {sorted(both)[0]!r} is both a place and a transition")
        pset, tset = set(place_ids), set(trans_ids)
        seen_arcs: set[tuple[str, str, str]] = set()
        resets = False
        for arc in self.arcs:
            src_p, src_t = arc.source in pset, arc.source in tset
            dst_p, dst_t = arc.target in pset, arc.target in tset
            if not (src_p or src_t):
                raise NetError(f"arc {arc.source} -> {arc.target}: unknown place or transition {arc.source!r}")
            if not (dst_p or dst_t):
                raise NetError(f"arc {arc.source} -> {arc.target}: unknown place or transition {arc.target!r}")
            if src_p and dst_p:
                raise NetError(f"arc {arc.source} -> {arc.target} joins two places; arcs join a place and a transition")
            if src_t and dst_t:
                raise NetError(
                    f"arc {arc.source} -> {arc.target} joins two transitions; arcs join a place and a transition"
                )
            if arc.inhibitor and not src_p:
                raise NetError(f"inhibitor arc {arc.source} -> {arc.target} must go from a place to a transition")
            if arc.reset and not src_p:
                raise NetError(f"reset arc {arc.source} -> {arc.target} must go from a place to a transition")
            resets = resets or arc.reset
            key = (arc.source, arc.target, arc.kind)
            if key in seen_arcs:
                what = "arc" if arc.kind == "normal" else f"{arc.kind} arc"
                raise NetError(f"{what} {arc.source} -> {arc.target} is given twice"
                               + ("; use one arc with a weight" if arc.kind != "reset" else ""))
            seen_arcs.add(key)
        self.__dict__["has_resets"] = resets  # the cached property, known at no extra cost here
        for t in self.transitions:
            for what, text in (("rate", t.rate_expr), ("weight", t.weight_expr)):
                if text is None:
                    continue
                tree = t.rate_tree if what == "rate" else t.weight_tree
                assert tree is not None
                try:
                    check_places(tree, text, pset)
                except ExprError as exc:
                    raise NetError(f"{what} of transition {t.id!r}: {exc.message} (column {exc.column} of "
                                   f"{_shown(text)})") from None
        for marking, what in ((self.initial_marking, "initial"), (self.home_marking, "home")):
            if marking is None:
                continue
            for pid in marking:
                if pid not in pset:
                    raise NetError(f"{what} marking puts tokens in unknown place {pid!r}")
        for place in self.places:
            if place.kind is PlaceKind.PRIMITIVE_TASK and place.task not in self.tasks:
                raise NetError(f"place {place.id!r} names primitive task {place.task!r}, which is not defined")
        for name, task in self.tasks.items():
            if name != task.name:
                raise NetError(f"task registered as {name!r} is named {task.name!r}")
        problem = self.operator_problem()
        if problem is not None:
            raise NetError(problem)

    def operator_problem(self) -> str | None:
        """What is wrong with :attr:`operator` in this net, or ``None``: an event to inject that no
        transition links, a task to force that the net does not have."""
        linked = {e for t in self.transitions for e in t.external_events}
        for event in self.operator.inject:
            if event not in linked:
                known = ", ".join(sorted(linked)) or "none"
                return f"operator may inject {event!r}, which no transition links (external events: {known})"
        for task in self.operator.force:
            if task not in self.tasks:
                known = ", ".join(self.tasks) or "none"
                return f"operator may force an outcome of task {task!r}, which the net does not have (tasks: {known})"
        return None

    def interpretation_problems(self) -> list[tuple[str, str]]:
        """Check the interpreted-net rules of section 2.

        Returns:
            ``(element id, problem)`` pairs, empty when the net is a valid task net:
            no reset arc empties a primitive-task place; every primitive-task place has at least one
            normal exit (a transition linked to
            ``int:<task>.<outcome>`` with outcome ≠ ``error``) and one error exit
            (``int:<task>.error``); every ``int:`` event names a primitive task that has a place
            among the transition's input places; at most one ``ext:`` event per transition
            (external events are pulses, two never occur at the same instant).
        """
        problems: list[tuple[str, str]] = []
        inputs = self.input_places
        for t in self.transitions:
            for pid in self.reset_places[t.id]:
                if self.place(pid).kind is PlaceKind.PRIMITIVE_TASK:
                    problems.append((t.id, f"transition {t.id!r} has a reset arc from primitive-task place "
                                           f"{pid!r}: its tokens are running primitive actions, which a reset "
                                           "cannot take away; consume them with input arcs"))
            if len(t.external_events) > 1:
                problems.append((t.id, f"transition {t.id!r} links {len(t.external_events)} external events; "
                                       "external events are pulses, link at most one"))
            in_tasks = {self.place(p).task for p in inputs[t.id] if self.place(p).kind is PlaceKind.PRIMITIVE_TASK}
            for event in t.internal_events:
                _, task, _ = parse_event(event)
                if task not in self.tasks:
                    problems.append((t.id, f"transition {t.id!r} links {event!r} but no primitive task {task!r} exists"))
                elif task not in in_tasks:
                    problems.append((t.id, f"transition {t.id!r} links {event!r} but no input place of it "
                                           f"is a place of primitive task {task!r}"))
        outputs_of_place: dict[str, list[str]] = {p.id: [] for p in self.places}
        for t in self.transitions:
            for pid in inputs[t.id]:
                outputs_of_place[pid].append(t.id)
        for p in self.places:
            if p.kind is not PlaceKind.PRIMITIVE_TASK:
                continue
            normal = error = False
            for tid in outputs_of_place[p.id]:
                for event in self.transition(tid).internal_events:
                    _, task, outcome = parse_event(event)
                    if task != p.task:
                        continue
                    if outcome == "error":
                        error = True
                    else:
                        normal = True
            if not normal:
                problems.append((p.id, f"primitive-task place {p.id!r} ({p.task}) has no normal exit: "
                                       f"link a transition leaving it to 'int:{p.task}.ok'"))
            if not error:
                problems.append((p.id, f"primitive-task place {p.id!r} ({p.task}) has no error exit: "
                                       f"link a transition leaving it to 'int:{p.task}.error'"))
        return problems

    # ------------------------------------------------------------------ lookup
    @cached_property
    def place_index(self) -> Mapping[str, int]:
        """Place id → row index in the matrices."""
        return MappingProxyType({p.id: i for i, p in enumerate(self.places)})

    @cached_property
    def transition_index(self) -> Mapping[str, int]:
        """Transition id → column index in the matrices."""
        return MappingProxyType({t.id: j for j, t in enumerate(self.transitions)})

    def place(self, place_id: str) -> Place:
        """Return the place with this id.

        Raises:
            KeyError: if there is none.
        """
        try:
            return self.places[self.place_index[place_id]]
        except KeyError:
            raise KeyError(f"net {self.name!r} has no place {place_id!r}") from None

    def transition(self, transition_id: str) -> Transition:
        """Return the transition with this id.

        Raises:
            KeyError: if there is none.
        """
        try:
            return self.transitions[self.transition_index[transition_id]]
        except KeyError:
            raise KeyError(f"net {self.name!r} has no transition {transition_id!r}") from None

    @cached_property
    def input_places(self) -> Mapping[str, Mapping[str, int]]:
        """Transition id → {input place id: arc weight} (normal arcs only)."""
        return self._adjacency(lambda a: a.source in self.place_index and not a.inhibitor and not a.reset,
                               "target", "source")

    @cached_property
    def output_places(self) -> Mapping[str, Mapping[str, int]]:
        """Transition id → {output place id: arc weight}."""
        return self._adjacency(lambda a: a.source in self.transition_index, "source", "target")

    @cached_property
    def inhibitor_places(self) -> Mapping[str, Mapping[str, int]]:
        """Transition id → {place id: inhibitor threshold}."""
        return self._adjacency(lambda a: a.inhibitor, "target", "source")

    @cached_property
    def reset_places(self) -> Mapping[str, tuple[str, ...]]:
        """Transition id → ids of the places its reset arcs empty, in arc order."""
        table: dict[str, list[str]] = {t.id: [] for t in self.transitions}
        for arc in self.arcs:
            if arc.reset:
                table[arc.target].append(arc.source)
        return MappingProxyType({k: tuple(v) for k, v in table.items()})

    @cached_property
    def has_resets(self) -> bool:
        """True when the net has at least one reset arc."""
        return any(arc.reset for arc in self.arcs)

    @cached_property
    def marking_dependent(self) -> bool:
        """True when some transition has a rate or weight expression."""
        return any(t.marking_dependent for t in self.transitions)

    def _adjacency(self, keep: Any, tkey: str, pkey: str) -> Mapping[str, Mapping[str, int]]:
        table: dict[str, dict[str, int]] = {t.id: {} for t in self.transitions}
        for arc in self.arcs:
            if keep(arc):
                table[getattr(arc, tkey)][getattr(arc, pkey)] = arc.weight
        return MappingProxyType({k: MappingProxyType(v) for k, v in table.items()})

    @cached_property
    def task_places(self) -> Mapping[str, tuple[str, ...]]:
        """Primitive task name → ids of its places."""
        table: dict[str, list[str]] = {name: [] for name in self.tasks}
        for p in self.places:
            if p.kind is PlaceKind.PRIMITIVE_TASK and p.task is not None:
                table[p.task].append(p.id)
        return MappingProxyType({k: tuple(v) for k, v in table.items()})

    # ------------------------------------------------------------------ matrices
    @cached_property
    def pre(self) -> np.ndarray:
        """Pre-incidence matrix, shape (|P|, |T|), int64: ``pre[p, t]`` = weight of arc p → t."""
        return self._matrix(self.input_places)

    @cached_property
    def post(self) -> np.ndarray:
        """Post-incidence matrix, shape (|P|, |T|), int64: ``post[p, t]`` = weight of arc t → p."""
        return self._matrix(self.output_places)

    @cached_property
    def inhibitor(self) -> np.ndarray:
        """Inhibitor matrix, shape (|P|, |T|), int64: threshold of the inhibitor arc p → t, 0 if none."""
        return self._matrix(self.inhibitor_places)

    @cached_property
    def reset(self) -> np.ndarray:
        """Reset matrix, shape (|P|, |T|), int64: 1 where a reset arc p → t empties p, else 0."""
        return self._matrix({tid: {pid: 1 for pid in pids} for tid, pids in self.reset_places.items()})

    @cached_property
    def incidence(self) -> np.ndarray:
        """Incidence matrix C = Post − Pre, shape (|P|, |T|), int64 (reset arcs are not in it: with them,
        the change of a firing depends on the marking; see :meth:`fire`)."""
        out: np.ndarray = self.post - self.pre
        out.flags.writeable = False
        return out

    @cached_property
    def initial_vector(self) -> np.ndarray:
        """The initial marking M0 as a read-only vector of shape (|P|,), int64, in :attr:`places` order."""
        out = self.vector(self.initial_marking)
        out.flags.writeable = False
        return out

    def _matrix(self, table: Mapping[str, Mapping[str, int]]) -> np.ndarray:
        import numpy as np  # on first use: loading and checking a net does not need numpy

        out = np.zeros((len(self.places), len(self.transitions)), dtype=np.int64)
        for tid, places in table.items():
            j = self.transition_index[tid]
            for pid, w in places.items():
                out[self.place_index[pid], j] = w
        out.flags.writeable = False
        return out

    def vector(self, marking: Mapping[str, int]) -> np.ndarray:
        """Return a marking as a vector of shape (|P|,), int64, in :attr:`places` order.

        Raises:
            KeyError: if the marking names an unknown place.
        """
        import numpy as np  # on first use, as in _matrix

        vec = np.zeros(len(self.places), dtype=np.int64)
        for pid, count in marking.items():
            if count:
                vec[self.place_index[pid] if pid in self.place_index else self._unknown(pid)] = count
        return vec

    def _unknown(self, pid: str) -> int:
        raise KeyError(f"net {self.name!r} has no place {pid!r}")

    def marking(self, vector: np.ndarray | Iterable[int]) -> Marking:
        """Return the :class:`Marking` of a vector of shape (|P|,) in :attr:`places` order."""
        return Marking((p.id, int(c)) for p, c in zip(self.places, vector, strict=True) if c)

    # ------------------------------------------------------------------ firing rule
    def enabled(self, marking: Mapping[str, int], transition_id: str) -> bool:
        """Tell whether ``transition_id`` is enabled in ``marking`` (inhibitor arcs honoured).

        Raises:
            KeyError: if the transition does not exist.
        """
        if transition_id not in self.transition_index:
            raise KeyError(f"net {self.name!r} has no transition {transition_id!r}")
        for pid, w in self.input_places[transition_id].items():
            if marking.get(pid, 0) < w:
                return False
        for pid, w in self.inhibitor_places[transition_id].items():
            if marking.get(pid, 0) >= w:
                return False
        return True

    def enabled_transitions(self, marking: Mapping[str, int]) -> tuple[str, ...]:
        """Return the ids of the transitions enabled in ``marking``, in net order."""
        return tuple(t.id for t in self.transitions if self.enabled(marking, t.id))

    def fire(self, marking: Mapping[str, int], transition_id: str) -> Marking:
        """Fire a transition and return the new marking (the argument is not changed).

        Raises:
            NotEnabledError: if the transition is not enabled in ``marking``.
            KeyError: if the transition does not exist.
        """
        if not self.enabled(marking, transition_id):
            raise NotEnabledError(
                f"transition {transition_id!r} is not enabled in {Marking(marking)!r}"
            )
        data = dict(marking)
        for pid, w in self.input_places[transition_id].items():
            data[pid] = data.get(pid, 0) - w
        for pid in self.reset_places[transition_id]:
            data[pid] = 0
        for pid, w in self.output_places[transition_id].items():
            data[pid] = data.get(pid, 0) + w
        return Marking(data)

    def expression_problems(self, marking: Mapping[str, int] | None = None) -> list[tuple[str, str, str]]:
        """Check the rate and weight expressions in one marking (the initial one by default).

        Only transitions enabled there are checked, since an expression is used only where its
        transition is enabled: a rate must be finite and ≥ 0, a weight finite and > 0.

        Returns:
            ``(transition id, "rate" or "weight", problem)`` triples, empty when all is well.
        """
        where = self.initial_marking if marking is None else marking
        out: list[tuple[str, str, str]] = []
        for t in self.transitions:
            if not t.marking_dependent or not self.enabled(where, t.id):
                continue
            for what, tree, positive in (("rate", t.rate_tree, False), ("weight", t.weight_tree, True)):
                if tree is None:
                    continue
                value = float(evaluate(tree, where))
                bad = value != value or value in (float("inf"), float("-inf")) or value < 0 or (positive and value == 0)
                if bad:
                    need = "> 0" if positive else ">= 0"
                    out.append((t.id, what, f"the {what} of transition {t.id!r} is {value:g} in the "
                                           f"{'initial ' if marking is None else ''}marking "
                                           f"{Marking(where).to_dict()}, where it is enabled; it must be "
                                           f"finite and {need}"))
        return out

    def summary(self) -> str:
        """One line describing the net: its name, places, transitions, arcs, primitive tasks (and
        their actions) and initial tokens (what ``petrobot check`` and the web console say of it)."""
        actions = sum(len(t.actions) for t in self.tasks.values())
        return (f"net {self.name!r}: {len(self.places)} places, {len(self.transitions)} transitions, "
                f"{len(self.arcs)} arcs, {len(self.tasks)} primitive tasks ({actions} actions), "
                f"{self.initial_marking.total} initial tokens")

    # ------------------------------------------------------------------ derived nets
    def with_initial_marking(self, marking: Mapping[str, int]) -> PetriNet:
        """Return a copy of the net with another initial marking."""
        return PetriNet(
            name=self.name, places=self.places, transitions=self.transitions, arcs=self.arcs,
            initial_marking=Marking(marking), tasks=self.tasks, description=self.description,
            home_marking=self.home_marking, operator=self.operator,
        )

    def __hash__(self) -> int:
        return hash((self.name, self.places, self.transitions, frozenset(self.arcs), self.initial_marking))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PetriNet):
            return NotImplemented
        return (
            self.name == other.name and self.places == other.places
            and self.transitions == other.transitions and set(self.arcs) == set(other.arcs)
            and self.initial_marking == other.initial_marking and dict(self.tasks) == dict(other.tasks)
            and self.description == other.description and self.home_marking == other.home_marking
            and self.operator == other.operator
        )
