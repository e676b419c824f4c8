"""The competition floor: analytic paint, texture rasters, the floor map, the pybullet floor.

Paper section 6 ("Mobile Robot Task"): squares of 2 m "of alternating black and white colors"; the
5 cm track "has the opposite color of the corresponding background square"; a T-shaped pattern
ends it. One geometry (:mod:`sim.mobile.course`) gives everything here, so that what a camera sees
and the ground truth never disagree:

* :func:`painted` and :func:`colour` — the analytic floor: which points carry track paint, and the
  grey level at any (x, y) (exact, no anti-aliasing);
* :func:`tile_raster` — one square's texture, the analytic colour averaged over ``supersample``²
  points per texel (so edges are anti-aliased), computed once per tile shape and square colour in
  the tile's own frame and turned by whole quarter turns (exact on a square grid of texels);
* :class:`FloorMap` — the whole board as one grey image (texels of ``texel`` m), composed from the
  rasters; the analytic camera warps it;
* :class:`PybulletFloor` — the board in a pybullet world: a collision plane and, for the
  TinyRenderer camera, one textured quad per square with the same rasters as textures.

Grey levels are those of matt paint seen by a camera: black 30, white 225 by default
(:class:`FloorStyle`).
"""

from __future__ import annotations

import functools
import os
import tempfile
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from .course import Course

__all__ = ["FloorMap", "FloorStyle", "PybulletFloor", "colour", "edge_distance", "painted", "tile_raster"]


@dataclass(frozen=True, slots=True, kw_only=True)
class FloorStyle:
    """Appearance of the floor.

    Attributes:
        black, white: grey levels (0–255) of the black and white paint.
        texel: size of a texture/floor-map pixel, m (rounded so that a square holds a whole number).
        supersample: samples per texel side when rasterising (anti-aliasing).
    """

    black: int = 30
    white: int = 225
    texel: float = 0.004
    supersample: int = 2

    def texels_per_square(self, square: float) -> int:
        """Texels along a square's side."""
        return max(8, round(square / self.texel))


# --------------------------------------------------------------------------------------------------
# analytic paint
# --------------------------------------------------------------------------------------------------
def _local_paint(
    shape: str, lx: np.ndarray, ly: np.ndarray, half: float, width: float, bar: float
) -> np.ndarray:
    """Track paint of a tile shape at points of the tile's frame (origin the square's centre, x the
    entry heading), as a bool array."""
    w2 = width / 2.0
    if shape == "S":
        return np.abs(ly) <= w2
    if shape == "L":
        return np.abs(np.hypot(lx + half, ly - half) - half) <= w2
    if shape == "R":
        return np.abs(np.hypot(lx + half, ly + half) - half) <= w2
    stem = (np.abs(ly) <= w2) & (lx <= 0.0)
    cross = (np.abs(lx) <= w2) & (np.abs(ly) <= bar / 2.0)
    return stem | cross


def _squares(course: Course, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Square indices (i, j) of points and the index of the tile there (-1 for none)."""
    i = np.floor(x / course.square).astype(np.int64)
    j = np.floor(y / course.square).astype(np.int64)
    grid, i0, j0 = course.tile_grid()
    gi, gj = i - i0, j - j0
    inside = (gi >= 0) & (gi < grid.shape[0]) & (gj >= 0) & (gj < grid.shape[1])
    tile = np.full(x.shape, -1, dtype=np.int64)
    tile[inside] = grid[gi[inside], gj[inside]]
    return i, j, tile


def painted(course: Course, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    """Whether track paint (track or T mark) covers the floor at (x, y).

    Args:
        course: the course.
        x, y: floor points, m (arrays of one shape, or scalars).

    Returns:
        Bool array of the points' shape.
    """
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    _, _, tile = _squares(course, xa, ya)
    out = np.zeros(xa.shape, dtype=bool)
    for t in course.tiles:
        if t.blank:
            continue
        m = tile == t.index
        if not m.any():
            continue
        lx, ly = course.to_local(t, xa[m], ya[m])
        out[m] = _local_paint(t.shape, lx, ly, course.half, course.track_width, course.end_bar_length)
    return out


def colour(course: Course, x: np.ndarray | float, y: np.ndarray | float, style: FloorStyle | None = None) -> np.ndarray:
    """Grey level (uint8) of the floor at (x, y): the square's colour, inverted where painted.

    Args:
        course: the course (its board extends without end as a chessboard).
        x, y: floor points, m.
        style: grey levels of the paint.

    Returns:
        uint8 array of the points' shape.
    """
    st = style or FloorStyle()
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    i = np.floor(xa / course.square).astype(np.int64)
    j = np.floor(ya / course.square).astype(np.int64)
    black = ((i + j) % 2 == 0) == course.first_black
    dark = black ^ painted(course, xa, ya)
    return np.where(dark, np.uint8(st.black), np.uint8(st.white))


def edge_distance(course: Course, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A lower bound of the distance (m) from (x, y) to the nearest colour edge of the floor.

    Edges are the square boundaries, the track band's sides and the T mark's outline.
    """
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    sq = course.square
    gx, gy = np.mod(xa, sq), np.mod(ya, sq)
    d = np.minimum(np.minimum(gx, sq - gx), np.minimum(gy, sq - gy))
    _, _, tile = _squares(course, xa, ya)
    h, w2, b2 = course.half, course.track_width / 2.0, course.end_bar_length / 2.0
    for t in course.tiles:
        m = tile == t.index
        if t.blank or not m.any():
            continue
        lx, ly = course.to_local(t, xa[m], ya[m])
        if t.shape == "S":
            e = np.abs(np.abs(ly) - w2)
        elif t.shape in ("L", "R"):
            cy = h if t.shape == "L" else -h
            e = np.abs(np.abs(np.hypot(lx + h, ly - cy) - h) - w2)
        else:
            stem = np.maximum(np.abs(ly) - w2, lx)  # box sdf approximations: |sdf| bounds the edge distance
            cross = np.maximum(np.abs(lx) - w2, np.abs(ly) - b2)
            e = np.minimum(np.abs(stem), np.abs(cross))
            e = np.minimum(e, np.hypot(lx, np.abs(ly) - w2))  # the stem's end corners
        d[m] = np.minimum(d[m], e)
    return d


# --------------------------------------------------------------------------------------------------
# rasters and the floor map
# --------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=64)
def _canonical_raster(
    shape: str, black: bool, n: int, square: float, width: float, bar: float, dark: int, light: int, ss: int
) -> np.ndarray:
    half = square / 2.0
    tx = square / n
    offs = (np.arange(ss) + 0.5) / ss
    c = np.arange(n)
    acc = np.zeros((n, n), dtype=np.float64)
    for oy in offs:
        ly = half - (c + oy) * tx  # rows: top of the image is +y
        for ox in offs:
            lx = -half + (c + ox) * tx
            gx, gy = np.meshgrid(lx, ly)
            acc += _local_paint(shape, gx, gy, half, width, bar) if shape != "-" else 0.0
    frac = acc / (ss * ss)
    base, other = (dark, light) if black else (light, dark)
    img = np.rint(base + (other - base) * frac).astype(np.uint8)
    img.setflags(write=False)
    return img


def tile_raster(course: Course, shape: str, heading: int, black: bool, style: FloorStyle | None = None) -> np.ndarray:
    """Texture of one square, (N, N) uint8, row 0 at the square's +y side, column 0 at its -x side.

    Args:
        course: gives the square size, track width and T bar length.
        shape: ``S``, ``L``, ``R``, ``E``, or ``-`` for a square without paint.
        heading: direction of travel into the square, 0..3 (quarter turns CCW from east).
        black: colour of the square.
        style: grey levels, texel size, anti-aliasing.

    Returns:
        A read-only (N, N) array, N = ``style.texels_per_square(course.square)``.
    """
    st = style or FloorStyle()
    n = st.texels_per_square(course.square)
    img = _canonical_raster(
        shape, black, n, course.square, course.track_width, course.end_bar_length, st.black, st.white,
        st.supersample,
    )
    return np.rot90(img, k=heading % 4)


class FloorMap:
    """The board as one grey image: the analytic camera's source and the floor textures' origin.

    Pixel (row r, column c) covers the floor around x = x_min + (c + ½)·τ, y = y_max - (r + ½)·τ
    (τ = :attr:`texel`): row 0 is the board's +y side.

    Args:
        course: the course; the board is its squares plus one square of margin.
        style: paint and texel size.

    Attributes:
        image: (rows, cols) uint8.
        texel: m per pixel.
        x_min, y_max: floor coordinates of the image's top-left corner, m.
    """

    def __init__(self, course: Course, style: FloorStyle | None = None) -> None:
        self.course = course
        self.style = st = style or FloorStyle()
        n = st.texels_per_square(course.square)
        self.texel = course.square / n
        i0, j0, i1, j1 = course.board()
        self.x_min = i0 * course.square
        self.y_max = (j1 + 1) * course.square
        cols, rows = (i1 - i0 + 1) * n, (j1 - j0 + 1) * n
        self.image = np.empty((rows, cols), dtype=np.uint8)
        tiles = {t.square: t for t in course.tiles}
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                r0, c0 = (j1 - j) * n, (i - i0) * n
                black = course.is_black(i, j)
                t = tiles.get((i, j))
                block = self.image[r0 : r0 + n, c0 : c0 + n]
                if t is None or t.blank:
                    block[:] = st.black if black else st.white
                else:
                    block[:] = tile_raster(course, t.shape, t.heading, black, st)

    def world_to_pixel(self) -> np.ndarray:
        """(2, 3) affine map [c, r]ᵀ = M · [x, y, 1]ᵀ from floor point (m) to pixel coordinates."""
        k = 1.0 / self.texel
        return np.array([[k, 0.0, -self.x_min * k - 0.5], [0.0, -k, self.y_max * k - 0.5]])

    def sample(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Grey level of the map's pixel containing each floor point (nearest texel), uint8.

        Points off the map raise IndexError.
        """
        c = np.floor((np.asarray(x, dtype=float) - self.x_min) / self.texel).astype(np.int64)
        r = np.floor((self.y_max - np.asarray(y, dtype=float)) / self.texel).astype(np.int64)
        if (c < 0).any() or (r < 0).any() or (c >= self.image.shape[1]).any() or (r >= self.image.shape[0]).any():
            raise IndexError("floor point off the floor map")
        return self.image[r, c]


# --------------------------------------------------------------------------------------------------
# the floor in pybullet
# --------------------------------------------------------------------------------------------------
_QUAD_OBJ = """v {a} {a} 0
v {b} {a} 0
v {b} {b} 0
v {a} {b} 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1
f 1/1/1 3/3/1 4/4/1
"""


class PybulletFloor:
    """The board in a pybullet world.

    Always a static collision plane at z = 0 (lateral friction ``friction``). With ``textured``,
    one visual quad per board square carrying :func:`tile_raster` as its texture (for the
    TinyRenderer camera); each distinct raster is loaded once.

    Args:
        client: a pybullet client (``BulletClient``).
        course: the course.
        style: paint and texel size.
        textured: build the textured quads.
        friction: lateral friction of the floor.

    Attributes:
        plane_id: body id of the collision plane.
        quad_ids: body ids of the textured quads (empty without texture).
    """

    def __init__(
        self, client: Any, course: Course, style: FloorStyle | None = None, *, textured: bool = False,
        friction: float = 0.9,
    ) -> None:
        pb = client
        st = style or FloorStyle()
        col = pb.createCollisionShape(pb.GEOM_PLANE)
        self.plane_id = int(pb.createMultiBody(0, col, -1, [0.0, 0.0, 0.0]))
        pb.changeDynamics(self.plane_id, -1, lateralFriction=friction, rollingFriction=0.0, spinningFriction=0.0)
        self.quad_ids: list[int] = []
        if not textured:
            return
        tiles = {t.square: t for t in course.tiles}
        textures: dict[tuple[str, int, bool], int] = {}
        i0, j0, i1, j1 = course.board()
        with tempfile.TemporaryDirectory(prefix="petrobot-floor-") as tmp:
            obj = os.path.join(tmp, "quad.obj")
            with open(obj, "w", encoding="ascii") as fh:
                fh.write(_QUAD_OBJ.format(a=-course.half, b=course.half))
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    t = tiles.get((i, j))
                    black = course.is_black(i, j)
                    key = ("-", 0, black) if t is None or t.blank else (t.shape, t.heading, black)
                    if key not in textures:
                        img = tile_raster(course, key[0], key[1], black, st)
                        path = os.path.join(tmp, f"tex{len(textures)}.png")
                        # texture coordinate v = 0 is the image's last row (OpenGL convention)
                        cv2.imwrite(path, cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_GRAY2BGR))
                        textures[key] = int(pb.loadTexture(path))
                    vis = pb.createVisualShape(pb.GEOM_MESH, fileName=obj)
                    cx, cy = course.centre(i, j)
                    body = int(pb.createMultiBody(0, -1, vis, [cx, cy, 0.0005]))
                    pb.changeVisualShape(body, -1, textureUniqueId=textures[key], rgbaColor=[1, 1, 1, 1])
                    self.quad_ids.append(body)
        self.texture_count = len(textures)

