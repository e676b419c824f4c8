"""Mobile-robot courses: geometry, validity rules, the seeded generator and course files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sim.mobile.course import (
    BeaconSpec,
    CourseError,
    check,
    course_from_codes,
    random_course,
)
from sim.mobile.coursefile import load_course, parse_course

ROOT = Path(__file__).resolve().parents[2]
FIG2 = ROOT / "nets" / "courses" / "fig2.toml"


def test_the_centre_line_is_continuous_from_tile_to_tile_and_ends_on_the_t_mark():
    c = course_from_codes(["S", "L", "S", "B", "S", "R", "S", "BL", "S", "R", "E"])
    s = 0.0
    for t in c.tiles[:-1]:
        s += c.tile_length(t)
        before = np.array(c.pose_at(s - 1e-6)[:2])
        assert np.allclose(before, c.tile_exit(t), atol=1e-5)
        assert np.allclose(c.pose_at(s + 1e-6)[:2], c.tile_start(c.tiles[t.index + 1]), atol=1e-5)
    assert np.allclose(c.pose_at(c.length)[:2], c.end_point())


def test_points_on_the_centre_line_project_with_zero_offset_and_their_path_length():
    c = course_from_codes(["S", "L", "R", "L", "S", "E"])
    for s in np.linspace(0.05, c.length - 0.05, 40):
        x, y, th = c.pose_at(float(s))
        _, s_here, off = c.locate(x, y)  # type: ignore[misc]
        assert abs(off) < 1e-9
        assert s_here == pytest.approx(s, abs=1e-9)
        # a point 3 cm to the left of the direction of travel has offset +0.03
        _, _, off_left = c.locate(x - 0.03 * math.sin(th), y + 0.03 * math.cos(th))  # type: ignore[misc]
        assert off_left == pytest.approx(0.03, abs=1e-9)


def test_resume_points_are_the_exit_midpoints_of_the_blank_squares():
    c = course_from_codes(["S", "B", "S", "S", "BR", "S", "E"])
    (i1, x1, y1, h1), (i2, x2, y2, h2) = c.resume_points()
    assert (i1, x1, y1, h1) == (1, 4.0, 1.0, 0.0)  # a hidden straight: 2 m on, same heading
    assert i2 == 4 and (x2, y2) == (9.0, 0.0) and h2 == pytest.approx(-math.pi / 2 % (2 * math.pi))


@pytest.mark.parametrize(
    ("codes", "problem"),
    [
        ("S S S", "last tile must be the end"),
        ("S E S E", "only be the last tile"),
        ("B S S E", "cannot start with an interruption"),
        ("S S B E", "whole painted tile before the end"),
        ("S B B S S E", "two interruptions in a row"),
        ("S L BL S S E", "needs straights on both sides"),
        ("S BR R S S E", "needs straights on both sides"),
        ("S L L L L E", "already used by tile 1"),
        ("S L L S L L S E", "right behind the start"),
        ("S X E", "unknown tile"),
    ],
)
def test_broken_course_rules_are_reported_by_name(codes, problem):
    with pytest.raises(CourseError, match=problem):
        course_from_codes(codes.split())


def test_random_courses_obey_every_rule_over_many_seeds():
    kinds: set[str] = set()
    counts = []
    for seed in range(300):
        c = random_course(seed)
        check(c)  # the rules, as for files
        squares = [t.square for t in c.tiles]
        assert len(set(squares)) == len(squares)
        blanks = [t.index for t in c.tiles if t.blank]
        counts.append(len(blanks))
        for i in blanks:
            assert 1 <= i <= len(c.tiles) - 3
            assert not c.tiles[i + 1].blank and not c.tiles[i - 1].blank
            if c.tiles[i].shape != "S":
                assert c.tiles[i - 1].code == "S" and c.tiles[i + 1].code == "S"
        kinds.update(c.codes())
        i0, j0, i1, j1 = c.board(margin=0)
        assert i1 - i0 < 8 and j1 - j0 < 8
    assert {"S", "L", "R", "B", "BL", "BR", "E"} <= kinds
    assert set(counts) == {0, 1, 2, 3}


def test_the_generator_is_reproducible_and_takes_a_length_and_an_interruption_count():
    assert random_course(42).codes() == random_course(42).codes()
    assert random_course(42).codes() != random_course(43).codes()
    long = random_course(5, tiles=40, interruptions=3, max_extent=12)
    assert len(long.tiles) == 40 and sum(t.blank for t in long.tiles) == 3
    short = random_course(5, tiles=3, interruptions=3)  # no tile may be blank: fewer are placed
    assert len(short.tiles) == 3 and not any(t.blank for t in short.tiles)


def test_the_fig2_course_file_loads():
    c = load_course(FIG2)
    assert c.name == "fig2"
    assert c.codes()[-1] == "E" and sum(t.blank for t in c.tiles) == 2
    assert {"L", "R"} <= set(c.codes())
    assert c.beacon == BeaconSpec(height=1.0, post=True, post_offset=0.5)


_GOOD = """[course]
start = [0, 0]
heading = "east"
tiles = [
    "S",
    "L",
    "B",
    "S",
    "E",
]
"""


def _err(text: str) -> str:
    with pytest.raises(CourseError) as exc:
        parse_course(text, "c.toml")
    return str(exc.value)


def test_course_file_errors_name_the_file_and_line_of_the_problem():
    assert parse_course(_GOOD, "c.toml").codes() == ["S", "L", "B", "S", "E"]
    assert _err(_GOOD.replace('"B",', '"Q",')).startswith("c.toml:7: tile 3 'Q': unknown tile")
    # a hidden arc next to an arc: the blank's own line
    assert _err(_GOOD.replace('"B",', '"BL",')).startswith("c.toml:7: tile 3 (BL)")
    assert _err(_GOOD.replace('"S",\n    "E"', '"B",\n    "E"')) == "c.toml:8: tiles 3 and 4: two interruptions in a row"
    assert _err(_GOOD.replace('heading = "east"', 'heading = "up"')).startswith("c.toml:3: [course] heading 'up'")
    assert _err(_GOOD + "\n[floor]\nsquare = 2.0\ncolour = 1\n").startswith("c.toml:14: [floor] has no key 'colour'")
    assert _err(_GOOD + "\n[lights]\n").startswith("c.toml:12: unknown section [lights]")
    assert _err(_GOOD + "\n[beacon]\nheight = 0.2\n").startswith("c.toml:13: beacon height 0.2 m")
    assert _err(_GOOD.replace("tiles = [", "tiles = [[")).startswith("c.toml:")
    assert _err("[course]\ntiles = [\"S\", \"E\"\n").startswith("c.toml:")  # TOML syntax
    assert _err(_GOOD.replace('start = [0, 0]', 'start = [0]')).startswith("c.toml:2: [course] start")


def test_a_self_touching_course_file_names_the_tile_that_runs_into_a_used_square():
    text = '[course]\ntiles = ["S", "L", "L",\n  "L", "L", "E"]\n'
    assert _err(text) == "c.toml:3: tile 5 (L) runs into square (0, 0), already used by tile 1 (the track would touch itself)"


def test_an_unreadable_course_file_is_a_course_error(tmp_path):
    with pytest.raises(CourseError, match="cannot read"):
        load_course(tmp_path / "missing.toml")
