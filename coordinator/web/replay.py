"""A run's timeline for the console's replay, read from its journal (paper section 5).

:func:`replay_json` turns the records of one run (:meth:`coordinator.journal.JournalReader.timeline`:
firings, action starts, results and operator commands, in the order they were written) into
compact arrays the page scrubs through: the marking at any point is the initial marking plus the
firings and accepted ``insert``/``remove`` commands up to it; the running actions are the starts
without a result yet. The net comes from the run's stored text when the journal has it, else from
the net the console has open under the same name.

Record arrays (``t`` is the Unix time the record was written, seconds)::

    ["f", seq, transition, {consumed}, {produced}, t, pulse, [instances consumed]]
    ["s", instance, task, place, action, node, t]
    ["r", instance, task, action, node, status, outcome, reason, wall_s, t, forced]
    ["o", command, place, count, accepted, reason, t, detail]

``forced`` is true for an outcome the operator forced (a drill: no measured result); ``detail`` is
what an operator command carried besides a place and a count (a breakpoint, an injected event, a
forced outcome; a ``pause`` a breakpoint made carries it), or null.

Pure apart from the reader it is given.
"""

from __future__ import annotations

from typing import Any

from coordinator.journal import (
    FiringRow,
    JournalReader,
    OperatorRow,
    ResultRow,
    StartRow,
)
from coordinator.learning.state import automaton_from_state
from coordinator.web.draft import draft_of_text
from coordinator.web.frames import learner_view

__all__ = ["MAX_RECORDS", "replay_json", "runs_json"]

#: Most records one replay carries (a longer run is cut at its end, and says so).
MAX_RECORDS = 200_000


def runs_json(reader: JournalReader) -> list[dict[str, Any]]:
    """Every run of a journal, newest first: id, net, start, end, end state, counts, note."""
    out = []
    for st in reversed(reader.run_stats()):
        run = st.run
        out.append({"id": run.id, "net": run.net_name, "started": run.started_wall, "ended": run.ended_wall,
                    "state": run.end_state, "firings": st.firings, "calls": st.calls, "errors": st.errors,
                    "failures": st.failures, "operator": st.operator_commands, "note": run.note,
                    "duration_s": st.duration_s})
    return out


def _record(rec: Any) -> list[Any]:
    if isinstance(rec, FiringRow):
        return ["f", rec.seq, rec.transition, dict(rec.consumed), dict(rec.produced), rec.t_wall, rec.pulse,
                list(rec.instances)]
    if isinstance(rec, StartRow):
        return ["s", rec.instance, rec.task, rec.place, rec.action, rec.node, rec.t_wall]
    if isinstance(rec, ResultRow):
        return ["r", rec.instance, rec.task, rec.action, rec.node, rec.status.value, rec.outcome, rec.reason,
                rec.wall_s, rec.t_wall, rec.forced]
    if isinstance(rec, OperatorRow):
        return ["o", rec.command, rec.place, rec.count, rec.accepted, rec.reason, rec.t_wall, rec.detail]
    raise TypeError(type(rec).__name__)


def _initial(draft: dict[str, Any] | None) -> dict[str, int]:
    if draft is None:
        return {}
    out = {}
    for place in draft.get("places", []):
        tokens = place.get("tokens", 0)
        if isinstance(place.get("id"), str) and isinstance(tokens, int) and tokens > 0:
            out[place["id"]] = tokens
    return out


def replay_json(reader: JournalReader, run: str, *, fallback: dict[str, Any] | None = None) -> dict[str, Any]:
    """The timeline of one run for the page.

    Args:
        reader: an open journal.
        run: the run id.
        fallback: the draft of the net to show when the run did not store its net's text.

    Returns:
        ``{"run": {...}, "draft": draft or None, "initial": {place: tokens}, "records": [...],
        "cut": bool, "notes": [...], "learner": {task: learner_view}}`` (the learners' latest saved
        state, :func:`~coordinator.web.frames.learner_view`). When the run started from another marking than its file's
        (``petrobot demo --runs``), a place would go below zero: its initial count is raised to
        the least that keeps it at zero or above, and a note says so.

    Raises:
        JournalError: the journal cannot be read, or has no run ``run``.
    """
    row = reader.run(run)
    draft = None
    notes: list[str] = []
    if row.net_text:
        try:
            draft = draft_of_text(row.net_text)
        except Exception as exc:
            notes.append(f"the net stored with the run does not read: {exc}")
    if draft is None and fallback is not None:
        draft = fallback
        notes.append("the run did not store its net; showing the open net of the same name")
    records = reader.timeline(run)
    cut = len(records) > MAX_RECORDS
    items = [_record(r) for r in records[:MAX_RECORDS]]
    initial = _initial(draft)
    level = dict(initial)
    low: dict[str, int] = {}
    for item in items:
        if item[0] == "f":
            for p, n in item[3].items():
                level[p] = level.get(p, 0) - n
                low[p] = min(low.get(p, 0), level[p])
            for p, n in item[4].items():
                level[p] = level.get(p, 0) + n
        elif item[0] == "o" and item[4] and item[1] in ("insert", "remove") and item[2]:
            level[item[2]] = level.get(item[2], 0) + (item[3] or 0) * (1 if item[1] == "insert" else -1)
            low[item[2]] = min(low.get(item[2], 0), level[item[2]])
    for p, lowest in low.items():
        if lowest < 0:
            notes.append(f"{p} starts with {initial.get(p, 0) - lowest} tokens, not the file's "
                         f"{initial.get(p, 0)}: the run started from another marking")
            initial[p] = initial.get(p, 0) - lowest
    if cut:
        notes.append(f"only the first {MAX_RECORDS} records are shown")
    learner: dict[str, Any] = {}
    for task, saved in reader.learner_states().items():
        try:
            learner[task] = learner_view(automaton_from_state(saved.state))
        except Exception:  # a state this version cannot rebuild is left out of the panel
            continue
    info = {"id": row.id, "net": row.net_name, "started": row.started_wall, "ended": row.ended_wall,
            "state": row.end_state, "note": row.note, "seed": row.seed}
    return {"run": info, "draft": draft, "initial": initial, "records": items, "cut": cut, "notes": notes,
            "learner": learner}
