"""From the interpreted task net to its GSPN view, the P-timed model (paper section 2); pure.

Section 2 ("Quantitative Performance Evaluation") turns the interpreted net into a generalized
stochastic Petri net: time is attached to the places of primitive tasks, and the two exits of a
primitive task, *normal execution* and *error recovery required*, become a random switch whose
probabilities are measured as relative frequencies. Here each primitive-task place ``p`` becomes

    p --[p.run: exponential, rate 1/mean, infinite server]--> p.done --{exits: random switch}

* ``mean``: mean ``wall_s`` of the task's results in the journal, else the task's a-priori
  ``mean_time_s``, else 1 s with a warning. Infinite-server semantics: every token in ``p`` is one
  running instance, independent of the others.
* the exits (transitions linked to ``int:<task>.<outcome>``) take their input from ``p.done``. With
  journal results, each exit's weight is the probability that the engine takes it: for each kind
  of result (status and named outcome, with its share of the task's results) the exits whose
  events the result latches (``ok`` and ``success``/``failure``, or ``error``, plus the named
  outcome: :func:`services.results.latched_events`) are enabled, the highest priority among them
  wins and equal priorities split by weight; results that enable no exit are left out, with a
  warning. Without results, normal exits get ``R_n / n_outcomes`` per outcome (or, when any normal
  exit of the task declares a weight other than 1, ``R_n · w / Σ w`` over the task's normal exits:
  the a-priori shares of its outcomes) and error exits ``(1 - R_n) / n_error``, ``R_n`` being the task's a-priori ``reliability`` (the probability of the
  normal branch: success and failure both take it, section 4). The exits of one place get one
  priority (the highest among them): a priority would otherwise override the switch.
* transitions linked to an ``ext:<topic>`` event become exponential at the topic's rate
  (``ext_rates``, else 1/s with a warning).

Events are removed from the GSPN's transitions (it is not meant to run) and kept in their labels.
The result is an ordinary :class:`~coordinator.net.PetriNet` that
:func:`coordinator.netfile.dump_net` can write for a user to inspect and edit.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

from coordinator.analysis.simulate import Delay
from coordinator.net import (
    INFINITE_SERVERS,
    Arc,
    PetriNet,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
    parse_event,
)
from coordinator.performance import ActionRecord
from services.results import Status, latched_events

__all__ = ["DEFAULT_EXT_RATE", "DEFAULT_MEAN_S", "PTimedNet", "TaskStats", "empirical_delays", "task_stats", "to_gspn"]

#: Mean duration used for a primitive task with neither journal data nor ``mean_time_s`` (s).
DEFAULT_MEAN_S = 1.0
#: Rate used for an external event with no measured or given rate (1/s).
DEFAULT_EXT_RATE = 1.0
#: Weight given to an exit whose measured probability is 0 (GSPN weights must be > 0).
MIN_WEIGHT = 1e-12


@dataclass(frozen=True, slots=True)
class TaskStats:
    """What the journal says about one primitive task.

    Attributes:
        runs: results of any of its actions.
        mean_s: mean ``wall_s`` (s), or None if no result has one.
        normal: share of results without ``error`` status (probability of the normal branch).
        outcomes: share of each outcome among the results without ``error`` status.
        samples: the ``wall_s`` values (s), for the simulator's empirical delays.
        classes: share of each kind of result, ``(status, named outcome or None)``, among all.
    """

    runs: int
    mean_s: float | None
    normal: float
    outcomes: Mapping[str, float] = field(default_factory=dict)
    samples: tuple[float, ...] = ()
    classes: Mapping[tuple[str, str | None], float] = field(default_factory=dict)


def task_stats(records: Iterable[ActionRecord]) -> dict[str, TaskStats]:
    """Group journal results per primitive task: ``{task: TaskStats}``."""
    grouped: dict[str, list[ActionRecord]] = {}
    for rec in records:
        grouped.setdefault(rec.task, []).append(rec)
    out: dict[str, TaskStats] = {}
    for task, recs in grouped.items():
        walls = tuple(float(r.wall_s) for r in recs if r.wall_s is not None)
        normal = [r for r in recs if r.status != "error"]
        outcomes: dict[str, int] = {}
        for r in normal:
            outcomes[r.outcome or "ok"] = outcomes.get(r.outcome or "ok", 0) + 1
        classes: dict[tuple[str, str | None], int] = {}
        for r in recs:
            key = (str(r.status), r.outcome)
            classes[key] = classes.get(key, 0) + 1
        out[task] = TaskStats(
            runs=len(recs), mean_s=sum(walls) / len(walls) if walls else None,
            normal=len(normal) / len(recs),
            outcomes={k: v / len(normal) for k, v in outcomes.items()} if normal else {},
            samples=walls,
            classes={k: v / len(recs) for k, v in classes.items()},
        )
    return out


@dataclass(frozen=True)
class PTimedNet:
    """The GSPN view and where its numbers came from.

    Attributes:
        net: the GSPN.
        means: mean delay (s) used per primitive task.
        normal: probability of the normal branch used per primitive task.
        ext_rates: rate (1/s) used per external topic.
        sources: ``{task or "ext:topic": "journal" | "apriori" | "given" | "default"}``.
        warnings: parameters that fell back on defaults.
        timed: ``{task place id: id of its timed transition}``.
    """

    net: PetriNet
    means: dict[str, float]
    normal: dict[str, float]
    ext_rates: dict[str, float]
    sources: dict[str, str]
    warnings: list[str]
    timed: dict[str, str]


def to_gspn(
    net: PetriNet,
    *,
    stats: Mapping[str, TaskStats] | None = None,
    ext_rates: Mapping[str, float] | None = None,
    means: Mapping[str, float] | None = None,
    normal: Mapping[str, float] | None = None,
) -> PTimedNet:
    """Build the P-timed GSPN of an interpreted task net (see the module docstring).

    Args:
        net: the interpreted task net.
        stats: journal statistics per primitive task (:func:`task_stats`).
        ext_rates: rate in 1/s per external topic (``ext:<topic>``).
        means: mean delay (s) per primitive task, overriding journal and a-priori values.
        normal: probability of the normal branch per primitive task, overriding the others.

    Returns:
        :class:`PTimedNet`.
    """
    stats = stats or {}
    ext_rates = dict(ext_rates or {})
    warnings: list[str] = []
    sources: dict[str, str] = {}
    used_mean, used_normal = _task_parameters(net, stats, means, normal, warnings, sources)
    places, transitions, arcs, timed, done_of = _timed_transitions(net, used_mean)
    exit_priority, measured, dropped = _exits(net, stats, normal, done_of, warnings)
    used_ext: dict[str, float] = {}
    rewired: dict[tuple[str, str], str] = {}
    for t in net.transitions:
        weight, weight_expr = t.weight, t.weight_expr
        kind, rate, servers, rate_expr = t.kind, t.rate, t.servers, t.rate_expr
        exits: list[tuple[str, str]] = []
        for event in t.internal_events:
            _, tname, outcome = parse_event(event)
            for pid in net.input_places[t.id]:
                if net.place(pid).task == tname and pid in done_of:
                    rewired[(pid, t.id)] = done_of[pid]
                    exits.append((tname, outcome))
        if t.id in dropped:
            warnings.append(f"transition {t.id!r}: no journal result takes this exit; left out of the GSPN")
            continue
        if exits:
            weight_expr = None  # an exit's weight is its measured or a-priori probability
            weight = _exit_weight(net, t, exits[0], stats, used_normal, measured, warnings)
        for event in t.external_events:
            topic = parse_event(event)[1]
            if topic in ext_rates:
                used_ext[topic], sources[event] = float(ext_rates[topic]), "given"
            else:
                used_ext[topic], sources[event] = DEFAULT_EXT_RATE, "default"
                warnings.append(f"external event {event!r}: no rate given; using {DEFAULT_EXT_RATE}/s")
            kind, rate, servers = TransitionKind.EXPONENTIAL, used_ext[topic], 1
            rate_expr = None
        label = t.label or (" ".join(t.events) if t.events else "")
        priority = exit_priority.get(t.id, t.priority)
        transitions.append(replace(t, events=(), kind=kind, rate=rate, servers=servers, weight=weight,
                                   label=label, priority=priority, rate_expr=rate_expr, weight_expr=weight_expr))
    arcs = [replace(a, source=rewired.get((a.source, a.target), a.source)) if not a.inhibitor else a for a in arcs
            if not ({a.source, a.target} & dropped)]
    gspn = PetriNet(name=f"{net.name}_gspn", places=tuple(places), transitions=tuple(transitions), arcs=tuple(arcs),
                    initial_marking=net.initial_marking, tasks=net.tasks,
                    description=f"GSPN (P-timed) view of {net.name}", home_marking=net.home_marking)
    return PTimedNet(gspn, used_mean, used_normal, used_ext, sources, warnings, timed)


def _task_parameters(net: PetriNet, stats: Mapping[str, TaskStats], means: Mapping[str, float] | None,
                     normal: Mapping[str, float] | None, warnings: list[str],
                     sources: dict[str, str]) -> tuple[dict[str, float], dict[str, float]]:
    """Mean delay (s) and probability of the normal exit of every primitive task: given, else from
    the journal, else a-priori (the task's declaration), else a default with a warning."""
    used_mean: dict[str, float] = {}
    used_normal: dict[str, float] = {}
    for name, task in net.tasks.items():
        st = stats.get(name)
        given = float(means[name]) if means and name in means else None
        if given is not None and given > 0:
            used_mean[name], src = given, "given"
        elif st is not None and st.mean_s is not None and st.mean_s > 0:
            used_mean[name], src = st.mean_s, "journal"
        elif task.mean_time_s is not None:
            used_mean[name], src = task.mean_time_s, "apriori"
        else:
            used_mean[name], src = DEFAULT_MEAN_S, "default"
            warnings.append(f"primitive task {name!r}: no journal time and no mean_time_s; "
                            f"using {DEFAULT_MEAN_S} s")
        if (given is not None and given <= 0) or (st is not None and st.mean_s == 0 and src != "given"):
            warnings.append(f"primitive task {name!r}: mean time 0 s (a timed transition needs a positive "
                            f"mean); using the {src} value {used_mean[name]:g} s")
        if normal and name in normal:
            used_normal[name], rsrc = float(normal[name]), "given"
        elif st is not None and st.runs:
            used_normal[name], rsrc = st.normal, "journal"
        elif task.reliability is not None:
            used_normal[name], rsrc = task.reliability, "apriori"
        else:
            used_normal[name], rsrc = 1.0, "default"
            warnings.append(f"primitive task {name!r}: no journal results and no reliability; "
                            "assuming the normal exit is always taken")
        sources[name] = f"time:{src} reliability:{rsrc}"
    return used_mean, used_normal


def _timed_transitions(net: PetriNet, used_mean: Mapping[str, float]
                       ) -> tuple[list[Place], list[Transition], list[Arc], dict[str, str], dict[str, str]]:
    """The places and arcs of the net with, for each primitive-task place p, a timed transition
    ``p.run`` (exponential, infinite servers, rate 1/mean) into a new place ``p.done``; returns
    places, the new transitions, arcs, ``{p: p.run}`` and ``{p: p.done}``."""
    places = list(net.places)
    transitions: list[Transition] = []
    arcs = list(net.arcs)
    timed: dict[str, str] = {}
    done_of: dict[str, str] = {}
    for p in net.places:
        if p.kind is not PlaceKind.PRIMITIVE_TASK or p.task is None:
            continue
        done, run = f"{p.id}.done", f"{p.id}.run"
        done_of[p.id] = done
        timed[p.id] = run
        places.append(Place(id=done, label=f"{p.task} finished"))
        transitions.append(Transition(id=run, kind=TransitionKind.EXPONENTIAL, rate=1.0 / used_mean[p.task],
                                      servers=INFINITE_SERVERS, label=f"{p.task} running"))
        arcs += [Arc(source=p.id, target=run), Arc(source=run, target=done)]
    return places, transitions, arcs, timed, done_of


def _exits(net: PetriNet, stats: Mapping[str, TaskStats], normal: Mapping[str, float] | None,
           done_of: Mapping[str, str], warnings: list[str]) -> tuple[dict[str, int], dict[str, float], set[str]]:
    """The exits of each primitive-task place as one random switch: their common priority (the
    highest among them), the probability the engine takes each (journal results), and the exits no
    journal result takes while another exit of their place is taken (left out)."""
    exits_of: dict[str, list[Transition]] = {}
    for t in net.transitions:
        for event in t.internal_events:
            _, tname, _ = parse_event(event)
            for pid in net.input_places[t.id]:
                if net.place(pid).task == tname and pid in done_of:
                    exits_of.setdefault(pid, []).append(t)
    exit_priority: dict[str, int] = {}
    for group in exits_of.values():
        top = max(u.priority for u in group)
        for u in group:
            exit_priority[u.id] = max(exit_priority.get(u.id, top), top)
    measured: dict[str, float] = {}  # exit id -> probability the engine takes it (journal results)
    dropped: set[str] = set()
    for pid, group in exits_of.items():
        tname = net.place(pid).task or ""
        st = stats.get(tname)
        if st is not None and st.classes and not (normal and tname in normal):
            shares, lost = _exit_probabilities(tname, group, st.classes)
            for tid, prob in shares.items():
                measured[tid] = max(measured.get(tid, 0.0), prob)
            if any(shares.values()):  # an exit no result takes would still fire when it is the only one enabled
                dropped.update(tid for tid, prob in shares.items() if prob <= 0)
            if lost:
                warnings.append(f"primitive task {tname!r}: {sum(lost.values()):.0%} of its results "
                                f"({', '.join(lost)}) enable no exit of place {pid!r}; left out of its random switch")
    return exit_priority, measured, dropped


def _exit_weight(net: PetriNet, t: Transition, first_exit: tuple[str, str], stats: Mapping[str, TaskStats],
                 used_normal: Mapping[str, float], measured: Mapping[str, float], warnings: list[str]) -> float:
    """The random-switch weight of an exit t of a primitive task: its measured probability, else its
    share of the task's normal (or error) probability, split among the exits of the same outcome."""
    if t.id in measured:
        weight = measured[t.id]
        if weight <= 0:
            warnings.append(f"transition {t.id!r}: probability 0 measured; weight {MIN_WEIGHT} kept")
            weight = MIN_WEIGHT
        return weight
    tname, outcome = first_exit
    same = [u for u in net.transitions if any(
        parse_event(e)[1] == tname and (parse_event(e)[2] == "error") == (outcome == "error")
        for e in u.internal_events)]
    if outcome == "error":
        weight = (1.0 - used_normal[tname]) / max(1, len(same))
    else:
        st = stats.get(tname)
        share = st.outcomes.get(outcome, 0.0) if st is not None and st.outcomes else None
        normal_exits = [u for u in same if all(parse_event(e)[2] != "error" for e in u.internal_events
                                               if parse_event(e)[1] == tname)]
        declared = share is None and any(u.weight != 1.0 for u in normal_exits)
        if declared:  # a-priori shares of the outcomes, written as the exits' weights
            share = t.weight / sum(u.weight for u in normal_exits)
            n_same = 1
        elif share is None:
            outs = {parse_event(e)[2] for u in same for e in u.internal_events if parse_event(e)[1] == tname}
            share = 1.0 / max(1, len(outs))
            if len(outs) > 1:
                warnings.append(f"transition {t.id!r}: no journal share of outcome {outcome!r} "
                                f"of {tname!r}; assuming 1/{len(outs)} of the normal exits")
        if not declared:
            n_same = sum(1 for u in same if any(parse_event(e)[2] == outcome for e in u.internal_events))
        weight = used_normal[tname] * share / max(1, n_same)
    if weight <= 0:
        warnings.append(f"transition {t.id!r}: probability 0 measured; weight {MIN_WEIGHT} kept")
        weight = MIN_WEIGHT
    return weight


def _exit_probabilities(task: str, group: list[Transition], classes: Mapping[tuple[str, str | None], float]
                        ) -> tuple[dict[str, float], dict[str, float]]:
    """Probability that the engine takes each exit of one primitive-task place, from the shares of
    the task's kinds of result (see the module docstring), and the share of each kind no exit takes."""
    exits = list({t.id: t for t in group}.values())
    needs = {t.id: frozenset(parse_event(e)[2] for e in t.internal_events if parse_event(e)[1] == task)
             for t in exits}
    shares = {t.id: 0.0 for t in exits}
    lost: dict[str, float] = {}
    for (status, outcome), share in classes.items():
        latched = latched_events(Status(status), outcome)
        enabled = [t for t in exits if needs[t.id] <= latched]
        if not enabled:
            key = f"{status} {outcome}" if outcome else status
            lost[key] = lost.get(key, 0.0) + share
            continue
        top = max(t.priority for t in enabled)
        best = [t for t in enabled if t.priority == top]
        total = sum(t.weight for t in best)
        for t in best:
            shares[t.id] += share * t.weight / total
    return shares, lost


def empirical_delays(model: PTimedNet, stats: Mapping[str, TaskStats]) -> dict[str, Delay]:
    """Delay laws for :mod:`coordinator.analysis.simulate` from the journal's durations.

    Args:
        model: the result of :func:`to_gspn`.
        stats: journal statistics per primitive task (:func:`task_stats`).

    Returns:
        ``{timed transition id: Delay.empirical(wall_s samples)}`` for every primitive-task place
        whose task has samples; other transitions keep their exponential law.
    """
    out: dict[str, Delay] = {}
    for pid, tid in model.timed.items():
        task = model.net.place(pid).task
        st = stats.get(task) if task is not None else None
        if st is not None and st.samples:
            out[tid] = Delay.empirical(st.samples)
    return out
