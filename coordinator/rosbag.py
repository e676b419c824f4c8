"""The journal of a run as a rosbag2 bag in MCAP (``petrobot export RUN --to mcap``), for the ROS tools.

One topic per kind of journal record, each message a type of petrobot's own defined in
``services/ros2/definitions/petrobot_msgs/msg`` (schemas embedded in the file, ``ros2msg``
encoding, so Foxglove, ``ros2 bag info`` and rosbags read it without petrobot), stamped with the
record's wall time:

==============================  ===================================  ===========================
topic                           type                                 one message per
==============================  ===================================  ===========================
``/petrobot/run``               ``petrobot_msgs/msg/RunInfo``        run (at its start)
``/petrobot/firing``            ``petrobot_msgs/msg/Firing``         firing
``/petrobot/marking``           ``petrobot_msgs/msg/Marking``        firing, plus the initial one
``/petrobot/action_start``      ``petrobot_msgs/msg/ActionStart``    primitive action started
``/petrobot/action_feedback``   ``petrobot_msgs/msg/ActionFeedback`` feedback the journal kept
``/petrobot/action_result``     ``petrobot_msgs/msg/ActionResult``   primitive action ended
``/petrobot/operator``          ``petrobot_msgs/msg/OperatorCommand`` operator command
``/petrobot/reconciliation``    ``petrobot_msgs/msg/Reconciliation`` reconciliation
==============================  ===================================  ===========================

The markings are replayed from the net's initial marking (the net text the run stored) and each
firing's consumed and produced tokens. The feedback is what the journal kept of it: sampled per
running call (:mod:`coordinator.feedback`: at most ten a second, and the last one before the
result), stamped with the time the coordinator received it.

The bag is a directory (``metadata.yaml`` and ``<name>.mcap``), written beside its destination and
renamed into place once complete and read back: the ``.mcap`` is read with Foxglove's
``mcap-ros2-support`` and every topic's message count compared with the journal's. An existing
destination is never replaced.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coordinator.errors import JournalError
from coordinator.journal import JournalReader
from services.errors import PetrobotError

__all__ = ["TOPICS", "BagWritten", "export_run"]

TOPICS = {
    "/petrobot/run": "petrobot_msgs/msg/RunInfo",
    "/petrobot/firing": "petrobot_msgs/msg/Firing",
    "/petrobot/marking": "petrobot_msgs/msg/Marking",
    "/petrobot/action_start": "petrobot_msgs/msg/ActionStart",
    "/petrobot/action_feedback": "petrobot_msgs/msg/ActionFeedback",
    "/petrobot/action_result": "petrobot_msgs/msg/ActionResult",
    "/petrobot/operator": "petrobot_msgs/msg/OperatorCommand",
    "/petrobot/reconciliation": "petrobot_msgs/msg/Reconciliation",
}
"""Each topic of the bag and its message type."""


@dataclass(frozen=True, slots=True)
class BagWritten:
    """What :func:`export_run` wrote.

    Attributes:
        directory: the bag directory.
        mcap: the MCAP file in it.
        counts: messages per topic (as read back from the file).
        note: what was left out and why, or ``""``.
        damaged: the journal's damaged records left out (one line each, naming table, row and
            field), empty when none.
    """

    directory: Path
    mcap: Path
    counts: dict[str, int]
    note: str = ""
    damaged: tuple[str, ...] = ()


def _tokens(mapping: Any) -> list[dict[str, Any]]:
    return [{"place": str(p), "tokens": int(n)} for p, n in sorted(dict(mapping or {}).items())]


def _json(value: Any) -> str:
    try:
        return json.dumps(value, sort_keys=True, default=str)
    except (TypeError, ValueError):
        return "null"


def _stamp(t_wall: float) -> int:
    return int(round(t_wall * 1e9))


def _initial_marking(net_text: str | None) -> dict[str, int] | None:
    if not net_text:
        return None
    from coordinator.netfile import loads_net

    try:
        net = loads_net(net_text, "<journal>", interpreted=False)
    except PetrobotError:
        return None
    return {p: int(n) for p, n in net.initial_marking.items() if n}


def _messages(reader: JournalReader, run_id: str) -> tuple[list[tuple[int, str, dict[str, Any]]], str]:
    """Every message of the bag, in the journal's order: (stamp ns, topic, fields); and a note."""
    from coordinator.journal import FeedbackRow, FiringRow, OperatorRow, ReconciliationRow, ResultRow, StartRow

    run = reader.run(run_id)
    out: list[tuple[int, str, dict[str, Any]]] = [(_stamp(run.started_wall), "/petrobot/run", {
        "run": run.id, "net_name": run.net_name, "seed": int(run.seed), "started_wall": run.started_wall,
        "ended_wall": run.ended_wall if run.ended_wall is not None else math.nan,
        "end_state": run.end_state or "", "note": run.note or ""})]
    marking = _initial_marking(run.net_text)
    note = "" if marking is not None else "no markings: the run did not store a net text that loads"
    if marking is not None:
        out.append((_stamp(run.started_wall), "/petrobot/marking", {"run": run.id, "seq": 0,
                                                                     "places": _tokens(marking)}))
    records: list[Any] = [*reader.timeline(run_id), *reader.feedback_messages(run_id)]
    records.sort(key=lambda r: (r.entry, r.t_wall))
    for record in records:
        stamp = _stamp(record.t_wall)
        if isinstance(record, FiringRow):
            out.append((stamp, "/petrobot/firing", {
                "run": run.id, "seq": record.seq, "transition": record.transition, "pulse": record.pulse or "",
                "consumed": _tokens(record.consumed), "produced": _tokens(record.produced),
                "instances": list(record.instances)}))
            if marking is not None:
                for place, n in record.consumed.items():
                    marking[place] = marking.get(place, 0) - n
                for place, n in record.produced.items():
                    marking[place] = marking.get(place, 0) + n
                marking = {p: n for p, n in marking.items() if n}
                out.append((stamp, "/petrobot/marking", {"run": run.id, "seq": record.seq,
                                                          "places": _tokens(marking)}))
        elif isinstance(record, StartRow):
            out.append((stamp, "/petrobot/action_start", {
                "run": run.id, "instance": record.instance, "task": record.task, "place": record.place,
                "action": record.action, "node": record.node or "", "params_json": _json(dict(record.params))}))
        elif isinstance(record, FeedbackRow):
            out.append((stamp, "/petrobot/action_feedback", {
                "run": run.id, "instance": record.instance, "task": record.task, "action": record.action,
                "data_json": _json(record.data)}))
        elif isinstance(record, ResultRow):
            out.append((stamp, "/petrobot/action_result", {
                "run": run.id, "instance": record.instance, "task": record.task, "action": record.action,
                "node": record.node or "", "status": record.status.value, "outcome": record.outcome or "",
                "reason": record.reason or "", "cost": math.nan if record.cost is None else float(record.cost),
                "wall_s": float(record.wall_s or 0.0), "cpu_s": float(record.cpu_s or 0.0),
                "value_json": _json(record.value)}))
        elif isinstance(record, OperatorRow):
            out.append((stamp, "/petrobot/operator", {
                "run": run.id, "command": record.command, "place": record.place or "",
                "count": -1 if record.count is None else int(record.count), "accepted": bool(record.accepted),
                "reason": record.reason or ""}))
        elif isinstance(record, ReconciliationRow):
            out.append((stamp, "/petrobot/reconciliation", {
                "run": run.id, "instance": record.instance, "task": record.task, "action": record.action,
                "node": record.node or "", "assumed": _value_of(record.assumed), "status": _value_of(record.status),
                "outcome": record.outcome or "", "reason": record.reason or "", "value_json": _json(record.value)}))
    return out, note


def _value_of(status: Any) -> str:
    return "" if status is None else str(getattr(status, "value", status))


def _read_back(mcap: Path) -> Counter[str]:
    """Messages per topic, decoded with Foxglove's reader (every message must decode)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    counts: Counter[str] = Counter()
    with open(mcap, "rb") as fh:
        for _, channel, _, _ in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[channel.topic] += 1
    return counts


def export_run(journal: str | os.PathLike[str], run_id: str, destination: str | os.PathLike[str]) -> BagWritten:
    """Write run ``run_id`` of ``journal`` as a rosbag2 MCAP bag at ``destination`` (a directory).

    Raises:
        JournalError: the journal cannot be read, or it has no such run.
        PetrobotError: ``destination`` exists, the bag cannot be written, or what was read back
            differs from what was written (the bag is then not left behind).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    from services.ros2.typestore import TypeStore, load_definitions

    target = Path(destination)
    if target.exists():
        raise PetrobotError(f"{target} exists: choose another -o, or remove it first")
    with JournalReader.open(journal) as reader:
        messages, note = _messages(reader, run_id)
        damaged = tuple(reader.damage_report())
    store = TypeStore({n: t for n, t in load_definitions().items()
                       if n.split("/")[0] in ("petrobot_msgs", "builtin_interfaces")})
    target.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    bag = scratch / target.name
    try:
        writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        try:
            connections = {topic: writer.add_connection(topic, msgtype, typestore=store.rosbags)
                           for topic, msgtype in TOPICS.items()}
            for stamp, topic, fields in messages:
                writer.write(connections[topic], stamp, store.encode(TOPICS[topic], fields))
        finally:
            writer.close()
        mcaps = sorted(bag.glob("*.mcap"))
        if len(mcaps) != 1:
            raise PetrobotError(f"the bag writer left {len(mcaps)} MCAP files in {bag}")
        counts = _read_back(mcaps[0])
        wanted = Counter(topic for _, topic, _ in messages)
        if counts != wanted:
            raise PetrobotError(f"read back {dict(counts)} messages, wrote {dict(wanted)}")
        os.rename(bag, target)
    except JournalError:
        raise
    except PetrobotError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags and mcap raise their own
        raise PetrobotError(f"cannot write the bag {target}: {exc.__class__.__name__}: {exc}") from None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return BagWritten(directory=target, mcap=target / mcaps[0].name, counts={t: counts[t] for t in TOPICS}, note=note,
                      damaged=damaged)
