#!/usr/bin/env python3
"""Take the screenshots of docs/console.md: run the console's browser tests that show each feature
(Debian's chromium through Playwright, real processes) with PETROBOT_SCREENSHOTS pointing at a
scratch folder, then copy the pictures the guide shows into docs/ under their names.

Usage: python docs/console_screenshots.py [--keep DIR]
(needs /usr/bin/chromium or $PETROBOT_CHROMIUM and the playwright package, as the tests do; the
catching demo's pictures start the simulated world and its nodes, about a minute.)
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: test (file::name) -> the screenshots it takes that the guide shows: screenshot name -> docs file
SHOTS: dict[str, dict[str, str]] = {
    "tests/browser/test_console_readable.py::test_the_paper_nets_are_readable_at_1400x900_and_no_label_overlaps_after_tidy":
        {"readable-catch": "console_design.png", "readable-mobile": "console_mobile.png"},
    "tests/browser/test_console_readable.py::test_edits_are_marked_unsaved_and_new_or_open_asks_before_discarding_them":
        {"design-confirm": "console_unsaved.png"},
    "tests/browser/test_console_readable.py::test_the_arc_tool_drag_draws_an_arc_and_reset_arcs_and_expressions_are_saved":
        {"design-arcs": "console_arcs.png"},
    "tests/browser/test_console_analyses.py::test_a_deadlock_of_a_small_net_is_shown_on_the_drawing_with_the_sequence_that_reaches_it":
        {"analysis-deadlock": "console_deadlock.png"},
    "tests/browser/test_console_analyses.py::test_bounds_dead_transitions_and_invariants_are_drawn_and_link_to_their_definitions":
        {"analysis-invariant": "console_invariant.png"},
    "tests/browser/test_console_analyses.py::test_the_gspn_heat_map_names_the_bottleneck_and_j_r_c_and_learner_bars_sit_on_task_places":
        {"analysis-gspn-perf-learn": "console_heatmap.png"},
    "tests/browser/test_console_drills.py::test_breakpoints_an_injected_event_the_blackboard_and_a_forced_outcome_on_a_run_started_from_the_page":
        {"live-blackboard": "console_blackboard.png", "live-forced": "console_forced.png"},
    "tests/browser/test_console_drills.py::test_several_runs_of_different_nets_are_followed_at_once_and_an_interrupted_run_resumes":
        {"live-two-runs": "console_runs.png"},
    "tests/browser/test_console_catching_drills.py::test_breakpoint_on_ball_caught_injected_crossfire_and_a_forced_locate_error_on_the_catching_demo":
        {"catch-breakpoint-ball_caught": "console_live.png", "replay-forced-locate": "console_replay.png"},
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", metavar="DIR", help="keep every screenshot the tests took in DIR")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="petrobot-shots-") as scratch:
        folder = Path(args.keep) if args.keep else Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "PETROBOT_SCREENSHOTS": str(folder), "PYTHONPATH": str(ROOT)}
        tests = list(SHOTS)
        print(f"console_screenshots: running {len(tests)} browser tests, screenshots in {folder}", flush=True)
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests], cwd=ROOT,
                              env=env, check=False)
        missing = []
        for shots in SHOTS.values():
            for shot, target in shots.items():
                source = folder / f"{shot}.png"
                if source.is_file():
                    shutil.copyfile(source, DOCS / target)
                    print(f"  docs/{target}  <- {shot}")
                else:
                    missing.append(shot)
        if missing:
            print(f"console_screenshots: not taken: {', '.join(missing)} (a test failed: see above)", file=sys.stderr)
            return 1
        return done.returncode


if __name__ == "__main__":
    raise SystemExit(main())
