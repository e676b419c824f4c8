"""The run summary's text: the per-action table keeps its columns apart whatever the names."""

from coordinator.runsummary import ActionStats, RunSummary
from services.results import ActionResult


def test_long_task_action_and_node_names_keep_the_table_columns_apart():
    stats = ActionStats("reacquire_track", "reacquire_track_with_a_long_name", "perception_node_01")
    stats.record(ActionResult.success())
    summary = RunSummary("r1", "completed", {}, 1, 1.0, {("reacquire_track", "x"): stats}, [])
    header, row = summary.format().splitlines()[-2:]
    assert row.split()[:3] == ["reacquire_track", "reacquire_track_with_a_long_name", "perception_node_01"]
    assert header.index("action") == row.index("reacquire_track_with_a_long_name")
    assert header.index("node") == row.index("perception_node_01")
