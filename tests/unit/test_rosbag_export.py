"""`petrobot export RUN --to mcap`: a run of the catching demo's journal (tests/data/catching_demo.sqlite,
`petrobot demo catching --runs 2 --seed 3`, journal schema 5: with the feedback of predict) as a rosbag2
MCAP bag, read back with Foxglove's mcap + mcap-ros2-support and with rosbags' reader, message counts
equal to the journal's."""

from __future__ import annotations

import json
import math
import shutil
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from coordinator.cli import main
from coordinator.journal import JournalReader
from coordinator.rosbag import TOPICS, export_run

DATA = Path(__file__).resolve().parents[1] / "data" / "catching_demo.sqlite"


@pytest.fixture
def journal(tmp_path: Path) -> Path:
    copy = tmp_path / "catching.sqlite"
    shutil.copyfile(DATA, copy)
    return copy


def _journal_counts(journal: Path, run: str) -> Counter[str]:
    with JournalReader.open(journal) as reader:
        firings = len(reader.firings(run))
        return Counter({"/petrobot/run": 1, "/petrobot/firing": firings, "/petrobot/marking": firings + 1,
                        "/petrobot/action_start": len(reader.starts(run)),
                        "/petrobot/action_feedback": len(reader.feedback_messages(run)),
                        "/petrobot/action_result": len(reader.results(run)),
                        "/petrobot/operator": len(reader.operator_commands(run)),
                        "/petrobot/reconciliation": len(reader.reconciliations(run))})


def test_a_catching_run_reads_back_with_foxglove_and_rosbags_readers_with_the_journals_counts(journal, tmp_path):
    with JournalReader.open(journal) as reader:
        run = reader.runs()[-1].id
        first = reader.firings(run)[0]
    written = export_run(journal, run, tmp_path / "run.bag")
    expected = _journal_counts(journal, run)
    assert expected["/petrobot/firing"] > 10 and expected["/petrobot/action_result"] > 3
    assert expected["/petrobot/action_feedback"] > 2  # predict's predicted catching points
    with open(written.mcap, "rb") as fh:
        decoded = make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        foxglove = Counter(channel.topic for _, channel, _, _ in decoded)
    assert foxglove == +expected
    with open(written.mcap, "rb") as fh:
        schemas = {s.name: s for s in make_reader(fh).get_summary().schemas.values()}
    assert set(schemas) == set(TOPICS.values()) and {s.encoding for s in schemas.values()} == {"ros2msg"}
    # rosbags, with nothing but the definitions the bag itself carries
    store = get_typestore(Stores.EMPTY)
    seen: Counter[str] = Counter()
    with Reader(written.directory) as bag:
        for connection in bag.connections:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        markings = []
        for connection, stamp, raw in bag.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            seen[connection.topic] += 1
            if connection.topic == "/petrobot/firing" and seen[connection.topic] == 1:
                assert (message.transition, message.seq) == (first.transition, first.seq)
                assert stamp == round(first.t_wall * 1e9)
            if connection.topic == "/petrobot/marking":
                markings.append({p.place: p.tokens for p in message.places})
            if connection.topic == "/petrobot/action_result":
                assert message.status in ("success", "failure", "error")
                assert math.isnan(message.cost) or message.cost >= 0
    assert seen == +expected
    assert markings[0]["runs_remaining"] >= 1 and all(all(n > 0 for n in m.values()) for m in markings)


TWO_CALLS = """
[net]
name = "fb"

[[place]]
id = "runs"
kind = "control"
tokens = 2

[[place]]
id = "work"
kind = "primitive_task"
task = "w"

[[place]]
id = "done"

[task.w]
actions = ["act"]

[[transition]]
id = "go"
inputs = { runs = 1 }
outputs = { work = 1 }

[[transition]]
id = "ok"
inputs = { work = 1 }
outputs = { done = 1 }
events = ["int:w.success"]
"""


async def test_a_run_with_feedback_reads_back_with_both_readers_feedback_counted_as_the_journal_keeps_it(tmp_path):
    from coordinator.journal import Journal
    from coordinator.netfile import loads_net
    from coordinator.runtime import Runtime
    from services.results import ActionResult
    from tests.unit.runtime_fakes import FakeClient

    stream = [{"progress": i / 99, "point": [0.1 * i, -0.2]} for i in range(100)]
    client = FakeClient({"act": ActionResult.success()}, feedback={"act": stream})
    path = tmp_path / "fb.sqlite"
    with Journal(path) as journal:
        runtime = Runtime(loads_net(TWO_CALLS, interpreted=False), client, journal, net_text=TWO_CALLS)
        await runtime.run(max_seconds=30)
        run = runtime.run_id
    expected = _journal_counts(path, run)
    assert expected["/petrobot/action_feedback"] == 4  # per call: the first and the last before the result
    written = export_run(path, run, tmp_path / "fb.bag")
    assert written.counts["/petrobot/action_feedback"] == 4
    with open(written.mcap, "rb") as fh:
        decoded = list(make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    assert Counter(channel.topic for _, channel, _, _ in decoded) == +expected
    last = [m.data_json for _, c, _, m in decoded if c.topic == "/petrobot/action_feedback"][-1]
    assert json.loads(last) == stream[-1]
    store = get_typestore(Stores.EMPTY)
    seen: Counter[str] = Counter()
    order = []
    with Reader(written.directory) as bag:
        for connection in bag.connections:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        for connection, _, raw in bag.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            seen[connection.topic] += 1
            if connection.topic in ("/petrobot/action_feedback", "/petrobot/action_result"):
                order.append((message.instance, connection.topic.rsplit("_", 1)[-1]))
    assert seen == +expected
    first, second = sorted({i for i, _ in order})
    assert [k for i, k in order if i == first] == ["feedback", "feedback", "result"]


def test_the_command_writes_the_last_run_beside_the_journal_and_never_replaces_a_bag(journal, capsys):
    assert main(["export", "last", "--to", "mcap", "--journal", str(journal)]) == 0
    said = capsys.readouterr().err
    with JournalReader.open(journal) as reader:
        run = reader.runs()[-1].id
    bag = journal.parent / f"{run}.bag"
    assert f"run {run}: {bag}" in said and "read back with mcap-ros2-support" in said
    before = sorted(p.name for p in bag.iterdir())
    assert main(["export", "last", "--to", "mcap", "--journal", str(journal)]) == 2
    assert "exists" in capsys.readouterr().err
    assert sorted(p.name for p in bag.iterdir()) == before
    assert [p.name for p in journal.parent.iterdir() if p.name.startswith(".")] == []  # no scratch left


def test_an_unknown_run_is_refused_and_nothing_is_written(journal, tmp_path, capsys):
    assert main(["export", "nosuchrun", "--to", "mcap", "--journal", str(journal), "-o", str(tmp_path / "x.bag")]) == 2
    assert "no run 'nosuchrun'" in capsys.readouterr().err
    assert not (tmp_path / "x.bag").exists()
