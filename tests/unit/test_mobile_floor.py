"""The competition floor: analytic paint, texture rasters and floor map agree; paint rules hold."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.mobile.course import course_from_codes, random_course
from sim.mobile.floor import (
    FloorMap,
    FloorStyle,
    colour,
    edge_distance,
    painted,
    tile_raster,
)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_floor_map_shows_the_analytic_colour_everywhere_away_from_edges(seed):
    course = random_course(seed, interruptions=3)
    fmap = FloorMap(course)
    rng = np.random.default_rng(seed)
    i0, j0, i1, j1 = course.board()
    n = 200_000
    x = rng.uniform(i0 * course.square, (i1 + 1) * course.square, n)
    y = rng.uniform(j0 * course.square, (j1 + 1) * course.square, n)
    # half a diagonal of a texel plus the anti-aliasing: farther than that a texel is one colour
    far = edge_distance(course, x, y) > 1.5 * fmap.texel
    assert far.mean() > 0.95
    np.testing.assert_array_equal(fmap.sample(x[far], y[far]), colour(course, x[far], y[far]))
    # and the track is where the paint is: a few percent of the floor near the track
    assert 0.001 < painted(course, x, y).mean() < 0.05


def test_the_track_has_the_opposite_colour_of_the_square_it_crosses():
    course = course_from_codes(["S", "L", "R", "S", "E"])
    st = FloorStyle()
    for s in np.linspace(0.01, course.length - 0.3, 300):
        x, y, th = course.pose_at(float(s))
        on = colour(course, x, y)
        # 10 cm to the side is the square's own colour
        side = colour(course, x - 0.1 * math.sin(th), y + 0.1 * math.cos(th))
        assert {int(on), int(side)} == {st.black, st.white}


def test_the_track_is_five_centimetres_wide_on_straights_and_arcs():
    course = course_from_codes(["S", "L", "E"])
    for s in (1.0, 2.0 + math.pi / 4):
        x, y, th = course.pose_at(s)
        offs = np.linspace(-0.05, 0.05, 1001)
        px, py = x - offs * math.sin(th), y + offs * math.cos(th)
        width = painted(course, px, py).sum() * (offs[1] - offs[0])
        assert width == pytest.approx(0.05, abs=2e-4)


def test_the_t_mark_crosses_the_end_square_and_blank_squares_carry_no_paint():
    course = course_from_codes(["S", "B", "S", "E"])
    ex, ey = course.end_point()
    ys = np.linspace(ey - 0.19, ey + 0.19, 50)
    assert painted(course, np.full_like(ys, ex), ys).all()  # the 0.40 m cross bar, east-west course
    assert not painted(course, ex + 0.1, ey)  # nothing beyond the bar
    bx = np.linspace(2.01, 3.99, 200)
    assert not painted(course, bx, np.full_like(bx, 1.0)).any()  # the blank square's hidden straight


def test_tile_rasters_turn_with_the_heading_like_the_analytic_floor():
    course = course_from_codes(["L", "E"], heading="north")
    raster = tile_raster(course, "L", heading=1, black=True)
    n = raster.shape[0]
    # texel centres of the square (0, 0): row 0 is the +y side
    c = (np.arange(n) + 0.5) * course.square / n
    gx, gy = np.meshgrid(c, course.square - c)
    far = edge_distance(course, gx, gy) > 2 * course.square / n
    np.testing.assert_array_equal(raster[far], colour(course, gx, gy)[far])
