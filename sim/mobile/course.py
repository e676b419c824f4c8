"""Courses of the mobile-robot testbed: tiles on a chessboard, course files, a random generator.

Paper section 6 ("Mobile Robot Task", Fig. 2): a 5 cm track on a chessboard of 2 m squares, made
of 2 m straight lines and quarter-circle arcs of 1 m radius, with interruptions (squares with no
track) and a T-shaped mark at the end.

**Grid and tiles.** Square (i, j) covers x ∈ [2i, 2i+2], y ∈ [2j, 2j+2] m (for the default 2 m
side). A course is a sequence of *tiles*, one per square; each tile enters its square at the
midpoint of one edge, travelling in a heading d ∈ {east, north, west, south}, and leaves at the
midpoint of another:

* ``S`` straight: 2 m across to the opposite edge's midpoint;
* ``L`` / ``R``: a quarter arc of radius half a side (1 m), centred on the square's corner
  between the entry and exit edges, turning left / right;
* ``B``, ``BL``, ``BR``: an **interruption** — the square carries no track; its *hidden* path
  (straight, left or right arc) says where the track resumes (the exit midpoint), the
  retroreflector marks that point;
* ``E``: the end: the track runs from the entry midpoint to the square's centre, where the T mark's
  cross bar lies across it.

**Validity rules** (:func:`check`, used for files and by the generator alike):

1. at least two tiles; the last tile, and only it, is ``E``;
2. every tile in its own square, and the square behind the start is not in the course. With the
   track touching square edges only at midpoints this means the painted track never touches or
   crosses itself, and a robot crossing a blank square can see no other piece of track;
3. interruptions: never the first tile (the robot starts on the track), never the end tile nor
   the tile just before it (after a resume at least one whole painted tile precedes the T), never
   two in a row;
4. an interruption hiding an arc (``BL``/``BR``) needs straights before and after it. Decided, a
   conservative rule for the "arc-to-arc corner": the robot places the blank square's possible
   exits from the track's tangent where it ended, which a straight gives best, and leaves the blank
   square onto a straight. (The closed loop also drove hidden arcs next to painted arcs correctly
   with the rule lifted; see ``docs/mobile.md``.)

**Course files**: :mod:`sim.mobile.coursefile` (TOML). Problems are reported as
:class:`CourseError` ``FILE:LINE: problem``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from services.errors import PetrobotError

__all__ = [
    "HEADINGS",
    "TILE_CODES",
    "BeaconSpec",
    "Course",
    "CourseError",
    "Tile",
    "build_tiles",
    "check",
    "course_from_codes",
    "random_course",
    "with_beacon",
]

HEADINGS = ("east", "north", "west", "south")
"""Headings by index d: travel along (cos dπ/2, sin dπ/2)."""
_STEP = ((1, 0), (0, 1), (-1, 0), (0, -1))

TILE_CODES = {
    "S": ("S", False), "L": ("L", False), "R": ("R", False), "E": ("E", False),
    "B": ("S", True), "BL": ("L", True), "BR": ("R", True),
}
"""Tile code → (shape, blank). Shapes: S straight, L/R quarter arc, E end."""


class CourseError(PetrobotError, ValueError):
    """A course is invalid or its file cannot be read; str() is ``FILE:LINE: problem``.

    Attributes:
        file: the course file (None for courses built in code).
        line: 1-based line of the problem (None when not known).
        problem: the message without location.
    """

    def __init__(self, problem: str, file: str | None = None, line: int | None = None) -> None:
        self.problem = problem
        self.file = file
        self.line = line
        where = f"{file}:{line}: " if file and line else (f"{file}: " if file else "")
        super().__init__(where + problem)


@dataclass(frozen=True, slots=True, kw_only=True)
class BeaconSpec:
    """The retroreflector that marks where the track resumes after an interruption.

    The paper places it "1 meter above the point where the track resumes". A post standing *on*
    that point would stand on the track the robot has to drive over, so the default build is a
    post of the beacon's height standing beside the resume point, on the exit edge's line, with an
    arm carrying the reflector over the resume point; ``post = False`` hangs the reflector there
    with nothing on the floor.

    Attributes:
        height: height of the reflector's centre above the floor, m.
        radius: radius of the reflective cylinder, m.
        length: height of the reflective cylinder, m.
        post: build the post and arm (True) or hang the reflector (False).
        post_offset: distance of the post from the resume point along the exit edge, m.

    Raises:
        ValueError: on sizes that make no beacon or a post a robot cannot pass.
    """

    height: float = 1.0
    radius: float = 0.04
    length: float = 0.15
    post: bool = True
    post_offset: float = 0.5

    def __post_init__(self) -> None:
        if not self.height > self.length / 2.0 + 0.3:
            raise ValueError(f"beacon height {self.height} m leaves no room for a robot under it")
        if not (self.radius > 0 and self.length > 0):
            raise ValueError("beacon radius and length must be positive")
        if self.post and not 0.3 <= self.post_offset <= 0.9:
            raise ValueError(
                f"beacon post_offset {self.post_offset} m must be within 0.3–0.9 m "
                "(clear of the robot, inside the square's edge)"
            )


@dataclass(frozen=True, slots=True)
class Tile:
    """One tile of a course.

    Attributes:
        index: position in the course, from 0.
        shape: ``S``, ``L``, ``R`` or ``E`` (for a blank: the hidden shape).
        blank: True for an interruption (no track painted).
        square: (i, j) grid square.
        heading: direction of travel into the square, 0..3 (see :data:`HEADINGS`).
        line: line of the tile in its course file, or None.
    """

    index: int
    shape: str
    blank: bool
    square: tuple[int, int]
    heading: int
    line: int | None = None

    @property
    def code(self) -> str:
        """The tile's code (``S``, ``L``, ``R``, ``E``, ``B``, ``BL``, ``BR``)."""
        if not self.blank:
            return self.shape
        return "B" if self.shape == "S" else "B" + self.shape

    @property
    def exit_heading(self) -> int:
        """Direction of travel out of the square (the entry heading for ``E``)."""
        return (self.heading + {"S": 0, "E": 0, "L": 1, "R": 3}[self.shape]) % 4

    @property
    def curvature(self) -> float:
        """Curvature of the centre line per unit half-side (+1 left arc, -1 right arc, else 0)."""
        return {"L": 1.0, "R": -1.0}.get(self.shape, 0.0)


@dataclass(frozen=True, slots=True)
class Course:
    """A course: tiles plus the floor's dimensions (see the module docstring).

    Attributes:
        tiles: the tiles in driving order.
        square: side of a square, m.
        track_width: width of the painted track, m.
        end_bar_length: length of the T mark's cross bar, m.
        first_black: square (0, 0) is black (True) or white.
        beacon: the retroreflectors' build.
        name: a name for reports.
        file: the course file it came from, or None.
    """

    tiles: tuple[Tile, ...]
    square: float = 2.0
    track_width: float = 0.05
    end_bar_length: float = 0.40
    first_black: bool = True
    beacon: BeaconSpec = field(default_factory=BeaconSpec)
    name: str = "course"
    file: str | None = None

    # --- squares ----------------------------------------------------------------------------
    @property
    def half(self) -> float:
        """Half the side of a square (the arcs' radius), m."""
        return self.square / 2.0

    def is_black(self, i: int, j: int) -> bool:
        """Whether square (i, j) is black."""
        return ((i + j) % 2 == 0) == self.first_black

    def centre(self, i: int, j: int) -> tuple[float, float]:
        """Centre of square (i, j), m."""
        return ((i + 0.5) * self.square, (j + 0.5) * self.square)

    def board(self, margin: int = 1) -> tuple[int, int, int, int]:
        """(i_min, j_min, i_max, j_max), inclusive, of the course's squares plus ``margin``."""
        sq = np.array([t.square for t in self.tiles])
        lo = sq.min(axis=0) - margin
        hi = sq.max(axis=0) + margin
        return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])

    def tile_grid(self, margin: int = 1) -> tuple[np.ndarray, int, int]:
        """(grid, i_min, j_min): grid[i - i_min, j - j_min] is the tile index in square (i, j), -1
        for a square without a tile; the grid covers :meth:`board`."""
        i0, j0, i1, j1 = self.board(margin)
        grid = np.full((i1 - i0 + 1, j1 - j0 + 1), -1, dtype=np.int32)
        for t in self.tiles:
            grid[t.square[0] - i0, t.square[1] - j0] = t.index
        return grid, i0, j0

    # --- centre line ------------------------------------------------------------------------
    def tile_length(self, tile: Tile) -> float:
        """Length of a tile's centre line (hidden or painted), m."""
        return {"S": self.square, "E": self.half}.get(tile.shape, math.pi / 2.0 * self.half)

    @property
    def length(self) -> float:
        """Length of the centre line from the start to the T mark, m."""
        return float(sum(self.tile_length(t) for t in self.tiles))

    def tile_start(self, tile: Tile) -> tuple[float, float]:
        """Entry midpoint of a tile, m."""
        cx, cy = self.centre(*tile.square)
        dx, dy = _STEP[tile.heading]
        return cx - dx * self.half, cy - dy * self.half

    def tile_exit(self, tile: Tile) -> tuple[float, float]:
        """Exit midpoint of a tile (the square's centre for ``E``), m."""
        cx, cy = self.centre(*tile.square)
        if tile.shape == "E":
            return cx, cy
        dx, dy = _STEP[tile.exit_heading]
        return cx + dx * self.half, cy + dy * self.half

    def start_pose(self) -> tuple[float, float, float]:
        """(x, y, heading) at the start of the track (entry midpoint of the first tile)."""
        x, y = self.tile_start(self.tiles[0])
        return x, y, self.tiles[0].heading * math.pi / 2.0

    def end_point(self) -> tuple[float, float]:
        """Centre of the T mark's cross bar, m."""
        return self.centre(*self.tiles[-1].square)

    def resume_points(self) -> list[tuple[int, float, float, float]]:
        """Per interruption: (blank tile index, x, y, heading) of the point where the track
        resumes and the direction it resumes in."""
        out = []
        for t in self.tiles:
            if t.blank:
                x, y = self.tile_exit(t)
                out.append((t.index, x, y, t.exit_heading * math.pi / 2.0))
        return out

    def pose_at(self, s: float) -> tuple[float, float, float]:
        """(x, y, heading) of the centre line at path length s (clamped to the course), m/rad."""
        s = min(max(s, 0.0), self.length)
        for t in self.tiles:
            ln = self.tile_length(t)
            if s <= ln or t is self.tiles[-1]:
                return self._tile_pose(t, min(s, ln))
            s -= ln
        raise AssertionError("unreachable")

    def _tile_pose(self, t: Tile, s: float) -> tuple[float, float, float]:
        x0, y0 = self.tile_start(t)
        th0 = t.heading * math.pi / 2.0
        k = t.curvature / self.half
        if k == 0.0:
            return x0 + s * math.cos(th0), y0 + s * math.sin(th0), th0
        th = th0 + k * s
        return (
            x0 + (math.sin(th) - math.sin(th0)) / k,
            y0 - (math.cos(th) - math.cos(th0)) / k,
            th,
        )

    def to_local(self, tile: Tile, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Points in the tile's frame: origin the square's centre, x along the entry heading, m."""
        cx, cy = self.centre(*tile.square)
        c, s = _STEP[tile.heading]
        dx, dy = np.asarray(x, dtype=float) - cx, np.asarray(y, dtype=float) - cy
        return c * dx + s * dy, -s * dx + c * dy

    def project(self, tile: Tile, x: float, y: float) -> tuple[float, float]:
        """(s along the tile from its entry, signed cross-track offset + left) of a point, m."""
        lx, ly = (float(v) for v in self.to_local(tile, np.array(x), np.array(y)))
        h = self.half
        if tile.shape in ("S", "E"):
            return lx + h, ly
        if tile.shape == "L":
            r = math.hypot(lx + h, ly - h)
            phi = math.atan2(ly - h, lx + h) + math.pi / 2.0
            return h * phi, h - r
        r = math.hypot(lx + h, ly + h)
        phi = math.pi / 2.0 - math.atan2(ly + h, lx + h)
        return h * phi, r - h

    def tile_at(self, x: float, y: float) -> Tile | None:
        """The tile whose square contains (x, y), or None."""
        key = (math.floor(x / self.square), math.floor(y / self.square))
        for t in self.tiles:
            if t.square == key:
                return t
        return None

    def locate(self, x: float, y: float) -> tuple[Tile, float, float] | None:
        """(tile, s along the course, cross-track offset + left) of a point, by its square; None
        off the course."""
        tile = self.tile_at(x, y)
        if tile is None:
            return None
        s_tile, off = self.project(tile, x, y)
        before = sum(self.tile_length(t) for t in self.tiles[: tile.index])
        return tile, before + s_tile, off

    def codes(self) -> list[str]:
        """The tile codes in order."""
        return [t.code for t in self.tiles]


# --------------------------------------------------------------------------------------------------
# building and checking
# --------------------------------------------------------------------------------------------------
def build_tiles(
    codes: Sequence[str], start: tuple[int, int], heading: int, lines: Sequence[int | None] | None,
    file: str | None,
) -> tuple[Tile, ...]:
    """Tiles from codes, walking the grid from ``start`` in ``heading`` (no rules checked).

    Args:
        codes: tile codes.
        start: square of the first tile.
        heading: direction of travel into it, 0..3.
        lines: the file line of each code (or None).
        file: the file name for errors.

    Raises:
        CourseError: on an unknown code.
    """
    tiles = []
    sq, d = start, heading
    for k, code in enumerate(codes):
        line = lines[k] if lines else None
        if code not in TILE_CODES:
            known = ", ".join(TILE_CODES)
            raise CourseError(f"tile {k + 1} {code!r}: unknown tile (expected one of {known})", file, line)
        shape, blank = TILE_CODES[code]
        t = Tile(k, shape, blank, sq, d, line)
        tiles.append(t)
        d = t.exit_heading
        sq = (sq[0] + _STEP[d][0], sq[1] + _STEP[d][1])
    return tuple(tiles)


def check(course: Course) -> None:
    """Check a course against the validity rules of the module docstring.

    Raises:
        CourseError: naming the first broken rule (with the tile's file line when known).
    """
    tiles, f = course.tiles, course.file
    if len(tiles) < 2:
        raise CourseError(f"a course needs at least two tiles, got {len(tiles)}", f, tiles[0].line if tiles else None)
    if not 0 < course.track_width <= course.square / 8:
        raise CourseError(f"track_width {course.track_width} m must be in (0, square/8]", f)
    if not course.track_width < course.end_bar_length <= course.square / 2:
        raise CourseError(f"end_bar_length {course.end_bar_length} m must be in (track_width, square/2]", f)
    last = tiles[-1]
    if last.code != "E":
        raise CourseError(f"the last tile must be the end E, got {last.code!r}", f, last.line)
    used: dict[tuple[int, int], int] = {}
    first = tiles[0]
    behind = (first.square[0] - _STEP[first.heading][0], first.square[1] - _STEP[first.heading][1])
    for t in tiles:
        n = t.index + 1
        if t.code == "E" and t is not last:
            raise CourseError(f"tile {n}: the end E may only be the last tile", f, t.line)
        if t.square in used:
            raise CourseError(
                f"tile {n} ({t.code}) runs into square {t.square}, already used by tile {used[t.square] + 1}"
                " (the track would touch itself)", f, t.line,
            )
        if t.square == behind:
            raise CourseError(
                f"tile {n} ({t.code}) uses square {t.square}, right behind the start of the track", f, t.line
            )
        used[t.square] = t.index
        if not t.blank:
            continue
        if t.index == 0:
            raise CourseError(f"tile 1 ({t.code}): the course cannot start with an interruption", f, t.line)
        if t.index >= len(tiles) - 2:
            raise CourseError(
                f"tile {n} ({t.code}): an interruption needs a whole painted tile before the end", f, t.line
            )
        if tiles[t.index + 1].blank:
            raise CourseError(f"tiles {n} and {n + 1}: two interruptions in a row", f, tiles[t.index + 1].line)
        if t.shape != "S":
            for nb in (tiles[t.index - 1], tiles[t.index + 1]):
                if nb.code != "S":
                    raise CourseError(
                        f"tile {n} ({t.code}): an interruption hiding an arc needs straights on both "
                        f"sides, tile {nb.index + 1} is {nb.code}", f, t.line,
                    )


def course_from_codes(
    codes: Sequence[str], *, start: tuple[int, int] = (0, 0), heading: int | str = 0,
    name: str = "course", **kw: Any,
) -> Course:
    """A checked course from tile codes, e.g. ``course_from_codes("S L B S R E".split())``.

    Args:
        codes: tile codes (see :data:`TILE_CODES`).
        start: square of the first tile.
        heading: direction of travel into it, 0..3 or a name from :data:`HEADINGS`.
        name: a name for reports.
        **kw: further :class:`Course` fields (square, track_width, end_bar_length, first_black,
            beacon).

    Raises:
        CourseError: on an unknown code or a broken rule.
    """
    d = HEADINGS.index(heading) if isinstance(heading, str) else int(heading)
    course = Course(build_tiles(list(codes), start, d, None, None), name=name, **kw)
    check(course)
    return course


# --------------------------------------------------------------------------------------------------
# generator
# --------------------------------------------------------------------------------------------------
def random_course(
    seed: int,
    *,
    tiles: int | None = None,
    interruptions: int | None = None,
    arc_share: float = 0.5,
    max_extent: int = 8,
    name: str | None = None,
    **kw: Any,
) -> Course:
    """A seeded random valid course.

    A self-avoiding walk on the grid (depth-first with random move order, arcs left and right
    drawn with probability ``arc_share`` / 2 each) within a ``max_extent`` × ``max_extent`` block
    of squares, ending with ``E``; then up to ``interruptions`` blanks placed at random where the
    rules of :func:`check` allow (a hidden arc only between straights). Fewer interruptions are
    placed when the course has too few eligible tiles.

    Args:
        seed: seed of the generator (numpy PCG64); the same seed gives the same course.
        tiles: number of tiles including ``E`` (default: drawn from 8–16).
        interruptions: wanted interruptions (default: drawn from 0–3).
        arc_share: probability that a tile is an arc.
        max_extent: the course fits in a block of this many squares per side.
        name: course name (default ``random-<seed>``).
        **kw: further :class:`Course` fields.

    Raises:
        ValueError: on fewer than 2 tiles or an extent too small for the length.
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(8, 17)) if tiles is None else int(tiles)
    if n < 2:
        raise ValueError(f"a course needs at least 2 tiles, got {n}")
    if n > max_extent * max_extent - 1:
        raise ValueError(f"{n} tiles do not fit in {max_extent}x{max_extent} squares")
    k_int = int(rng.integers(0, 4)) if interruptions is None else int(interruptions)
    shapes = _random_walk(rng, n, arc_share, max_extent)
    codes = list(shapes)
    # interruptions
    eligible = [i for i in range(1, n - 2)]
    rng.shuffle(eligible)
    chosen: list[int] = []
    for i in eligible:
        if len(chosen) >= k_int:
            break
        if any(abs(i - j) < 2 for j in chosen):
            continue  # never two in a row: a blank's neighbours stay painted
        if codes[i] != "S" and not (codes[i - 1] == "S" and codes[i + 1] == "S"):
            continue  # a hidden arc only between straights
        chosen.append(i)
    for i in chosen:
        codes[i] = "B" if codes[i] == "S" else "B" + codes[i]
    course = course_from_codes(codes, name=name or f"random-{seed}", **kw)
    return course


def _random_walk(rng: np.random.Generator, n: int, arc_share: float, extent: int) -> list[str]:
    """Shapes of a self-avoiding walk of n tiles from (0, 0) heading east, last one ``E``."""
    p_s = 1.0 - arc_share
    forbidden = {(-1, 0)}  # behind the start

    for _attempt in range(200):
        used = [(0, 0)]
        heading = [0]
        out: list[str] = []
        choices: list[list[str]] = []
        budget = 20000

        def options() -> list[str]:
            order = ["S", "L", "R"]
            w = np.array([p_s, arc_share / 2.0, arc_share / 2.0])
            w = w / w.sum()
            return list(rng.choice(order, size=3, replace=False, p=w))

        choices.append(options())
        while len(out) < n - 1 and budget > 0:
            budget -= 1
            if not choices[-1]:
                choices.pop()
                if not out:
                    break
                out.pop()
                used.pop()
                heading.pop()
                continue
            shape = choices[-1].pop(0)
            d = (heading[-1] + {"S": 0, "L": 1, "R": 3}[shape]) % 4
            sq = (used[-1][0] + _STEP[d][0], used[-1][1] + _STEP[d][1])
            xs = [u[0] for u in used] + [sq[0]]
            ys = [u[1] for u in used] + [sq[1]]
            if sq in used or sq in forbidden or max(xs) - min(xs) >= extent or max(ys) - min(ys) >= extent:
                continue
            out.append(shape)
            used.append(sq)
            heading.append(d)
            choices.append(options())
        if len(out) == n - 1:
            return out + ["E"]
    raise ValueError(f"no self-avoiding course of {n} tiles found within {extent}x{extent} squares")


def with_beacon(course: Course, beacon: BeaconSpec) -> Course:
    """The same course with another beacon build."""
    return replace(course, beacon=beacon)
