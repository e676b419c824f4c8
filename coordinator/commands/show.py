"""``petrobot show RUN``: one run of a journal in order — firings, calls with their reasons,
operator commands (refused ones with why), what nodes said afterwards about the calls the run had
given up on (reconciliations) — and how it ended."""

from __future__ import annotations

import argparse
import collections
import enum
import json
import sys
import time
from typing import TYPE_CHECKING, Any

from coordinator.commands import options

if TYPE_CHECKING:
    from coordinator.journal import JournalReader, Record, RunRow

__all__ = ["add_parser", "describe", "find_run", "operator_detail", "render", "report", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``show`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser(
        "show", help="one run of a journal in order: firings, calls with reasons, operator commands",
        description="Show one run of a journal: how it ended and why, then every record in the order it was "
                    "written — firings (places that gave and took tokens), primitive-action starts and results "
                    "(status, outcome, duration and the action's reason), operator commands (refused ones with "
                    "the refusal), reconciliations (what a node said afterwards about a call the run had given "
                    "up on when the node was lost, marked DIFFERS when the node's final status is not the one "
                    "the net went on with) — and the errors counted by reason. RUN is a run id or a unique prefix of one "
                    "(`petrobot runs` lists them), or `last`. The journal is opened read-only. Exit status 0; 1 on a "
                    "missing journal or an unknown run; 2 on a damaged journal (the damaged records are named on "
                    "stderr, with table, row and field, and the rest is shown) or one written by a newer petrobot.")
    p.add_argument("run_id", metavar="RUN", help="run id, a unique prefix of one, or 'last'")
    options.add_journal(p, default="runs/journal.sqlite", help="SQLite journal (default: %(default)s)")
    p.add_argument("--no-firings", action="store_true", help="leave the firings out (calls and operator commands only)")
    options.add_json(p)
    p.set_defaults(func=run)


def find_run(journal: JournalReader, wanted: str) -> RunRow:
    """The run ``wanted`` names: an id, a unique prefix of one, or ``last``.

    Raises:
        JournalError: no such run, or an ambiguous prefix.
    """
    from coordinator.errors import JournalError

    runs = journal.runs()
    if wanted == "last" and runs:
        return runs[-1]
    exact = [r for r in runs if r.id == wanted]
    matches = exact or [r for r in runs if r.id.startswith(wanted)]
    if len(matches) == 1:
        return matches[0]
    if not matches:
        raise JournalError(f"{journal.path}: no run {wanted!r} (petrobot runs --journal {journal.path} lists them)")
    raise JournalError(f"{journal.path}: {wanted!r} names {len(matches)} runs: {', '.join(r.id for r in matches)}")


def describe(record: Record, t0: float) -> str:
    """One line for a record, stamped with its time since the run started (s)."""
    from coordinator.journal import (
        FiringRow,
        OperatorRow,
        ReconciliationRow,
        ResultRow,
        StartRow,
    )
    from coordinator.reconcile import describe as describe_reconciliation

    stamp = f"{record.t_wall - t0:9.3f}s  "
    if isinstance(record, FiringRow):
        via = f" on {record.pulse}" if record.pulse else ""
        took = ", ".join(p if n == 1 else f"{p}x{n}" for p, n in record.consumed.items()) or "-"
        gave = ", ".join(p if n == 1 else f"{p}x{n}" for p, n in record.produced.items()) or "-"
        return f"{stamp}fire     #{record.seq:<5} {record.transition}{via}   {took} -> {gave}"
    if isinstance(record, StartRow):
        return f"{stamp}start    {record.task} -> {record.action} on {record.node or '?'} [{record.instance}]"
    if isinstance(record, ResultRow):
        extra = f" ({record.outcome})" if record.outcome else ""
        wall = f" in {record.wall_s:.3f} s" if record.wall_s is not None else ""
        why = f": {record.reason}" if record.reason else ""
        head = "FORCED   " if record.forced else "result   "  # by the operator: no measured result
        return (f"{stamp}{head}{record.task}/{record.action} on {record.node or '?'}: "
                f"{record.status.value}{extra}{wall}{why} [{record.instance}]")
    if isinstance(record, ReconciliationRow):
        mark = "DIFFERS  " if record.differs else ""
        return (f"{stamp}reconcile {mark}{record.task}/{record.action}: "
                f"{describe_reconciliation(record.node, record.action, record.assumed, record.truth)} [{record.instance}]")
    if isinstance(record, OperatorRow):
        what = record.command + (f" {record.place} {record.count}" if record.place is not None else "")
        what += operator_detail(record.command, record.detail)
        if record.accepted:
            return f"{stamp}operator {what}"
        return f"{stamp}operator {what} REFUSED: {record.reason or ''}"
    raise TypeError(type(record).__name__)


def operator_detail(command: str, detail: Any) -> str:
    """What an operator command carried besides a place and a count, in words (``" ext:tick"``,
    ``' ext:tick {"by":"drill"}'`` with its payload,
    ``" at breakpoint fires ball_caught: ball_caught fired"``), or ``""``."""
    if not isinstance(detail, dict):
        return ""
    bp = detail.get("breakpoint")
    if isinstance(bp, dict):
        text = f"{bp.get('kind')} {bp.get('target')}" + (f" {bp.get('count')}" if bp.get("kind") == "count" else "")
        return f" at breakpoint {text}: {detail.get('why', '')}" if command == "pause" else f" {text}"
    if "event" in detail:
        if detail.get("payload") is None:
            return f" {detail['event']}"
        payload = json.dumps(detail["payload"], separators=(",", ":"), default=str)
        return f" {detail['event']} {payload if len(payload) <= 80 else payload[:79] + '…'}"
    if "instance" in detail:
        why = f" ({detail['reason']})" if detail.get("reason") else ""
        return f" {detail.get('outcome')} on {detail['instance']}{why}"
    return ""


def report(args: argparse.Namespace) -> dict[str, Any]:
    """The run and its records as a JSON-ready dict (raises JournalError)."""
    from coordinator.journal import (
        FiringRow,
        JournalReader,
        ReconciliationRow,
        ResultRow,
    )

    with JournalReader.open(args.journal) as journal:
        row = find_run(journal, args.run_id)
        records = [r for r in journal.timeline(row.id) if not (args.no_firings and isinstance(r, FiringRow))]
        damaged = journal.damage_report()
    reconciled = [r for r in records if isinstance(r, ReconciliationRow)]
    reasons = collections.Counter(f"{r.task}/{r.action}: {r.reason or 'no reason given'}"
                                  for r in records if isinstance(r, ResultRow) and r.status == "error")
    return {
        "run": row.id, "net": row.net_name, "seed": row.seed, "started_wall": row.started_wall,
        "ended_wall": row.ended_wall, "end_state": row.end_state, "note": row.note or "",
        "records": [{"kind": type(r).__name__.removesuffix("Row").lower(), **_fields(r)} for r in records],
        "error_reasons": dict(reasons.most_common()),
        "reconciled": len(reconciled), "differed": sum(r.differs for r in reconciled),
        "damaged": damaged,
        "_lines": [describe(r, row.started_wall) for r in records],
    }


_RESULT_FIELDS = ("status", "outcome", "cost", "wall_s", "cpu_s", "reason", "value")
"""The fields of an action's result, flat in a record's JSON (``null`` when a node did not know the call)."""


def _fields(record: Any) -> dict[str, Any]:
    out = {}
    for name in record.__slots__:
        if name in ("result", "truth"):  # the ActionResult a result or a reconciliation holds
            out.update((f, _plain(getattr(record, f))) for f in _RESULT_FIELDS)
        else:
            out[name] = _plain(getattr(record, name))
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, tuple):
        return list(value)
    if hasattr(value, "items"):
        return dict(value)
    return value


def render(rep: dict[str, Any]) -> str:
    """Readable text of a :func:`report` dict."""
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(rep["started_wall"]))
    if rep["ended_wall"] is not None:
        end = f"{rep['end_state']} after {rep['ended_wall'] - rep['started_wall']:.2f} s"
    else:
        end = "unfinished (resumable with petrobot run NET --resume)"
    lines = [f"run {rep['run']} of net {rep['net']!r}, seed {rep['seed']}, started {started}: {end}"]
    for part in (rep["note"] or "").split(" | "):
        if part:
            lines.append(f"  {part}")
    if rep.get("reconciled"):
        n = rep["reconciled"]
        lines.append(f"  {n} call{'' if n == 1 else 's'} given up on reconciled with {'its' if n == 1 else 'their'} "
                     f"node{'' if n == 1 else 's'}; {rep['differed']} ended otherwise than the net assumed")
    lines.append("")
    lines.extend(rep["_lines"] or ["  (no records)"])
    if rep["error_reasons"]:
        lines += ["", "errors by reason:"]
        lines.extend(f"  {n:5d} x {why}" for why, n in rep["error_reasons"].items())
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the run; 0, 1 on a missing journal or an unknown run, 2 on a damaged or newer journal."""
    from coordinator.errors import JournalError

    try:
        rep = report(args)
    except JournalError as exc:
        print(f"petrobot show: {exc}", file=sys.stderr)
        return exc.exit_status
    if args.json:
        print(json.dumps({k: v for k, v in rep.items() if not k.startswith("_")}, indent=2, default=str))
    else:
        print(render(rep))
    return options.report_damage("petrobot show", rep["damaged"])
