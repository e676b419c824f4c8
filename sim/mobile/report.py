"""The report of one mobile-robot run, and its top view (paper section 6, "Mobile Robot Task").

Scores a run from the robot's ground-truth path against the course geometry
(:meth:`sim.mobile.course.Course.locate`: the square a point is in, its path length along the
course and its signed cross-track offset — the same geometry the closed-loop harness scores
with):

* **completed**: the robot stopped (a ``stop`` event) within :data:`STOP_TOLERANCE` of the T mark's
  centre, recovered every interruption of the course and was never more than :data:`OFF_TRACK`
  from the track on a painted square while following (the criteria of
  :class:`sim.mobile.harness.RunResult`);
* **time** from the first path sample to the stop (or the last sample), s; **mean speed** = course
  length / time (m/s, as the harness reports it) and the path's own length / time;
* **cross-track error** RMS and maximum per segment kind, *straight* (``S`` and the ``E`` tile) and
  *arc* (``L``, ``R``): the axle midpoint's offset on painted squares while following — samples
  between an ``interruption`` event and the next ``recovered`` event are left out (the robot is
  crossing the blank square or picking the track up again), and so are samples after ``stop``;
* each **interruption**: when it was declared, on which blank square, when the track was picked up
  again (the ``recovered`` event) and whether the ground truth agrees: half a metre into the square
  after the blank one, the robot was within :data:`RECOVERY_OFFSET` of its track (the harness's
  criterion);
* where the robot **stopped** relative to the T mark: along the track (positive past the bar),
  across it (positive to the left), heading error, distance.

``path`` is an (N, 4) float array (or a list of 4-tuples) of t [s], x, y [m], heading [rad] (world
frame, ground truth); ``events`` a list of dicts with at least ``t`` [s, on the path's clock] and
``kind`` (``interruption``, ``recovered``, ``lost``, ``end``, ``stop``, ``error``), other keys kept
and shown (e.g. ``{"how": "beacon"}``) — or the run's primitive-action ends (objects with ``task``,
``action``, ``result``: an ``ActionResult``, and ``t_wall``, as ``coordinator.events.ActionEnded``),
read as events by task and outcome (``follow_track`` success ``interruption`` → ``interruption``,
``reacquire_track`` success → ``recovered``, ``stop_at_t`` or ``stop_robot`` success → ``stop``, any
error → ``error``, ...) at the result value's ``t`` when it has one, else at ``t_wall - t0_wall``.
Events none of whose times fall in the path's time span are on another clock: the report says so,
matches interruptions to the blank squares in order and counts every sample as following.
``stop_pose`` is (x, y, heading), or None if the robot never stopped. Per-primitive-task statistics
come from the journal and are the demo's job.

:func:`score` returns the numbers (JSON-ready), :func:`render_report` the text,
:func:`write_top_view` a PNG of the floor, track, beacons, path and stop (matplotlib, Agg), drawn by
:func:`top_view`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .course import Course, Tile

__all__ = ["OFF_TRACK", "RECOVERY_OFFSET", "STOP_TOLERANCE", "render_report", "score", "top_view", "write_top_view"]

#: A stop counts as on the T mark within this distance of its centre, m.
STOP_TOLERANCE = 0.3
#: The run is judged lost when the axle is further than this from the track on a painted square, m.
OFF_TRACK = 0.4
#: An interruption counts as recovered when, 0.5 m into the next square, the robot is this close, m.
RECOVERY_OFFSET = 0.1
_RECOVERY_DEPTH = 0.5
_KIND = {"S": "straight", "E": "straight", "L": "arc", "R": "arc"}


def _check_path(path: Any) -> np.ndarray:
    arr = np.asarray(path, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"path must be an (N, 4) array of t, x, y, heading; got shape {arr.shape}")
    if arr.shape[0] and not np.isfinite(arr).all():
        raise ValueError("path holds a non-finite value")
    if arr.shape[0] > 1 and np.any(np.diff(arr[:, 0]) < 0):
        raise ValueError("path times must not decrease")
    return arr


#: (task, status, named outcome or None) of a primitive action's result → event kind.
_RESULT_KINDS = {
    ("follow_track", "success", "interruption"): "interruption",
    ("follow_track", "success", "end"): "end",
    ("follow_track", "failure", "lost"): "lost",
    ("reacquire_track", "success", None): "recovered",
    ("reacquire_track", "failure", "lost"): "reacquire_lost",
    ("find_beacon", "success", "found"): "beacon_found",
    ("find_beacon", "failure", "not_found"): "beacon_not_found",
    ("stop_at_t", "success", None): "stop",
    ("stop_robot", "success", None): "stop",
}


def _from_action_ended(e: Any, t0_wall: float | None) -> dict[str, Any]:
    """An event dict from a primitive action's end (an object with ``task``, ``action``,
    ``result`` (:class:`services.results.ActionResult`) and ``t_wall``, as the run's events carry
    it): the time is the result value's ``t`` (simulated time) when it has one, else ``t_wall``
    (minus ``t0_wall`` when given)."""
    result = e.result
    status = str(getattr(result.status, "value", result.status))
    outcome = result.outcome
    kind = _RESULT_KINDS.get((e.task, status, outcome))
    if kind is None:
        kind = "error" if status == "error" else f"{e.task}.{outcome or status}"
    value = result.value if isinstance(result.value, Mapping) else {}
    t = value.get("t")
    if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
        t = float(e.t_wall) - (t0_wall or 0.0)
    out: dict[str, Any] = {"t": float(t), "kind": kind, "task": e.task, "action": e.action}
    if result.reason:
        out["reason"] = result.reason
    return out


def _check_events(events: Sequence[Any], t0_wall: float | None = None) -> list[dict[str, Any]]:
    out = []
    for i, e in enumerate(events):
        if isinstance(e, Mapping):
            if "t" not in e or "kind" not in e:
                raise ValueError(f"event {i} needs 't' and 'kind': {dict(e)!r}")
            t = e["t"]
            if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
                raise ValueError(f"event {i} has a bad time {t!r}")
            out.append(dict(e))
        elif all(hasattr(e, k) for k in ("task", "action", "result", "t_wall")):
            out.append(_from_action_ended(e, t0_wall))
        else:
            raise ValueError(f"event {i} is neither a dict with 't' and 'kind' nor a primitive action's end: {e!r}")
    return sorted(out, key=lambda e: float(e["t"]))


def _same_clock(t: np.ndarray, evs: list[dict[str, Any]], slack: float = 5.0) -> bool:
    """Whether the events' times can be on the path's clock (some lie within its span)."""
    if not evs or not t.size:
        return True
    return any(float(t[0]) - slack <= float(e["t"]) <= float(t[-1]) + slack for e in evs)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _following_mask(t: np.ndarray, events: list[dict[str, Any]]) -> np.ndarray:
    """(N,) bool: the samples taken while following (not between an interruption and its recovery,
    not after the stop)."""
    mask = np.ones(t.shape, dtype=bool)
    open_at: float | None = None
    for e in events:
        if e["kind"] == "interruption" and open_at is None:
            open_at = float(e["t"])
        elif e["kind"] == "recovered" and open_at is not None:
            mask &= ~((t >= open_at) & (t < float(e["t"])))
            open_at = None
        elif e["kind"] == "stop":
            mask &= t <= float(e["t"])
    if open_at is not None:
        mask &= t < open_at
    return mask


def _stats(values: list[float]) -> dict[str, Any]:
    if not values:
        return {"samples": 0, "rms_m": None, "max_m": None}
    a = np.abs(np.asarray(values))
    return {"samples": int(a.size), "rms_m": float(np.sqrt(np.mean(a * a))), "max_m": float(a.max())}


def score(course: Course, path: Any, events: Sequence[Any],
          stop_pose: tuple[float, float, float] | None, *, t0_wall: float | None = None) -> dict[str, Any]:
    """Score a run (see the module docstring).

    Returns:
        JSON-ready ``{"course", "length_m", "completed", "reasons", "time_s", "mean_speed_mps",
        "path_speed_mps", "path_length_m", "cross_track": {"straight": {...}, "arc": {...}, "all":
        {...}} (each ``samples``, ``rms_m``, ``max_m``; None without samples), "off_track_max_m",
        "interruptions": [...], "lost": [...], "errors": [...], "events_on_path_clock", "end_seen_t",
        "stop"}``; ``stop`` is None or
        ``{"t", "x", "y", "along_m", "across_m", "heading_error_rad", "distance_m"}``.

    Raises:
        ValueError: on a path that is not (N, 4) finite with non-decreasing times, or an event
            without ``t`` and ``kind``.
    """
    arr = _check_path(path)
    evs = _check_events(events, t0_wall)
    t = arr[:, 0]
    same_clock = _same_clock(t, evs)
    follow = _following_mask(t, evs) if same_clock else np.ones(t.shape, dtype=bool)
    by_kind: dict[str, list[float]] = {"straight": [], "arc": []}
    off_max = 0.0
    where: list[tuple[Tile, float, float] | None] = [course.locate(float(x), float(y)) for x, y in arr[:, 1:3]]
    for i, loc in enumerate(where):
        if loc is None or loc[0].blank or not follow[i]:
            continue
        by_kind[_KIND[loc[0].shape]].append(loc[2])
        off_max = max(off_max, abs(loc[2]))
    cross = {k: _stats(v) for k, v in by_kind.items()}
    cross["all"] = _stats(by_kind["straight"] + by_kind["arc"])

    stop_ev = next((e for e in evs if e["kind"] == "stop"), None)
    t0 = float(t[0]) if t.size else 0.0
    t_end = float(stop_ev["t"]) if stop_ev is not None and same_clock else (float(t[-1]) if t.size else 0.0)
    upto = t <= t_end
    steps = np.hypot(np.diff(arr[upto, 1]), np.diff(arr[upto, 2])) if upto.sum() > 1 else np.zeros(0)
    duration = t_end - t0

    interruptions = _interruptions(course, arr, where, evs, same_clock)
    stop = None
    if stop_pose is not None:
        stop = _stop(course, stop_pose, float(stop_ev["t"]) if stop_ev is not None else None)

    reasons = []
    blanks = [tl for tl in course.tiles if tl.blank]
    recovered = sum(1 for it in interruptions if it["tile"] is not None and it["on_track_after"])
    if stop_ev is None or stop is None:
        reasons.append("the robot did not stop")
    elif stop["distance_m"] > STOP_TOLERANCE:
        reasons.append(f"stopped {stop['distance_m']:.2f} m from the T mark")
    if recovered < len(blanks):
        reasons.append(f"recovered {recovered} of {len(blanks)} interruptions")
    if off_max > OFF_TRACK:
        reasons.append(f"{off_max:.2f} m off the track while following")
    completed = not reasons
    return {
        "course": course.name,
        "length_m": course.length,
        "completed": completed,
        "reasons": reasons,
        "time_s": duration,
        "mean_speed_mps": course.length / duration if completed and duration > 0 else None,
        "path_length_m": float(steps.sum()),
        "path_speed_mps": float(steps.sum()) / duration if duration > 0 else None,
        "cross_track": cross,
        "off_track_max_m": off_max,
        "interruptions": interruptions,
        "lost": [e for e in evs if e["kind"] == "lost"],
        "errors": [e for e in evs if e["kind"] == "error"],
        "events_on_path_clock": same_clock,
        "end_seen_t": next((float(e["t"]) for e in evs if e["kind"] == "end"), None),
        "stop": stop,
    }


def _extra(e: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in e.items() if k not in ("t", "kind")}


def _pairs(evs: list[dict[str, Any]]) -> list[tuple[dict[str, Any], dict[str, Any] | None]]:
    """Each ``interruption`` event with the ``recovered`` event that follows it (before the next
    interruption), or None."""
    out: list[tuple[dict[str, Any], dict[str, Any] | None]] = []
    for e in evs:
        if e["kind"] == "interruption":
            out.append((e, None))
        elif e["kind"] == "recovered" and out and out[-1][1] is None:
            out[-1] = (out[-1][0], e)
    return out


def _blank_at(course: Course, arr: np.ndarray, t: float) -> Tile | None:
    """The blank square the robot was on, or about to enter (within 0.3 m), at time ``t``."""
    if not arr.shape[0]:
        return None
    i = int(np.clip(np.searchsorted(arr[:, 0], t), 0, arr.shape[0] - 1))
    x, y, th = arr[i, 1], arr[i, 2], arr[i, 3]
    for ahead in (0.0, 0.3):
        tile = course.tile_at(x + ahead * math.cos(th), y + ahead * math.sin(th))
        if tile is not None and tile.blank:
            return tile
    return None


def _interruptions(course: Course, arr: np.ndarray, where: list[tuple[Tile, float, float] | None],
                   evs: list[dict[str, Any]], same_clock: bool = True) -> list[dict[str, Any]]:
    """One entry per blank square of the course, in course order, with the events of its crossing;
    then one per declared interruption that matches no blank square (``tile`` None: a false one).
    Events on another clock than the path's are matched to the blank squares in order."""
    matched: dict[int, tuple[dict[str, Any], dict[str, Any] | None]] = {}
    false: list[tuple[dict[str, Any], dict[str, Any] | None]] = []
    blanks = iter([t for t in course.tiles if t.blank])
    for pair in _pairs(evs):
        tile = _blank_at(course, arr, float(pair[0]["t"])) if same_clock else next(blanks, None)
        if tile is None or tile.index in matched:
            false.append(pair)
        else:
            matched[tile.index] = pair
    out = []
    for tile in (t for t in course.tiles if t.blank):
        nxt = course.tiles[tile.index + 1]
        check = next((i for i, loc in enumerate(where) if loc is not None and loc[0].index == nxt.index
                      and course.project(nxt, arr[i, 1], arr[i, 2])[0] >= _RECOVERY_DEPTH), None)
        loc = None if check is None else where[check]
        offset = None if loc is None else float(loc[2])
        got = matched.get(tile.index)
        dec: dict[str, Any] | None = None if got is None else got[0]
        rec: dict[str, Any] | None = None if got is None else got[1]
        out.append({
            "tile": tile.index + 1, "code": tile.code,
            "declared": None if dec is None else {"t": float(dec["t"]), **_extra(dec)},
            "recovered": None if rec is None else {"t": float(rec["t"]), **_extra(rec)},
            "offset_after_m": offset,
            "on_track_after": offset is not None and abs(offset) < RECOVERY_OFFSET,
        })
    for fdec, frec in false:
        out.append({"tile": None, "code": None, "declared": {"t": float(fdec["t"]), **_extra(fdec)},
                    "recovered": None if frec is None else {"t": float(frec["t"]), **_extra(frec)},
                    "offset_after_m": None, "on_track_after": False})
    return out


def _stop(course: Course, pose: tuple[float, float, float], t: float | None) -> dict[str, Any]:
    x, y, th = (float(v) for v in pose)
    end = course.tiles[-1]
    s, across = course.project(end, x, y)
    ex, ey = course.end_point()
    return {"t": t, "x": x, "y": y, "along_m": s - course.half, "across_m": across,
            "heading_error_rad": _wrap(th - end.heading * math.pi / 2.0),
            "distance_m": math.hypot(x - ex, y - ey)}


def _mm(v: float | None) -> str:
    return "—" if v is None else f"{1000.0 * v:.1f} mm"


def render_report(course: Course, path: Any, events: Sequence[Any],
                  stop_pose: tuple[float, float, float] | None, *, t0_wall: float | None = None) -> str:
    """Return the run's report as text (see the module docstring and :func:`score`).

    Raises:
        ValueError: as :func:`score`.
    """
    r = score(course, path, events, stop_pose, t0_wall=t0_wall)
    blanks = sum(t.blank for t in course.tiles)
    head = (f"course {r['course']!r}: {len(course.tiles)} squares, {r['length_m']:.2f} m, "
            f"{blanks} interruption{'s' if blanks != 1 else ''}")
    lines = [head]
    lines.append("completed: yes" if r["completed"] else "completed: no — " + "; ".join(r["reasons"]))
    speed = f", mean speed {r['mean_speed_mps']:.3f} m/s" if r["mean_speed_mps"] is not None else ""
    pspeed = f" ({r['path_length_m']:.2f} m driven, {r['path_speed_mps']:.3f} m/s)" if r["path_speed_mps"] else ""
    lines.append(f"time: {r['time_s']:.2f} s{speed}{pspeed}")
    lines.append("cross-track error while following (axle midpoint, painted squares):")
    for kind in ("straight", "arc", "all"):
        c = r["cross_track"][kind]
        lines.append(f"  {kind + ':':<9} RMS {_mm(c['rms_m'])}, max {_mm(c['max_m'])} ({c['samples']} samples)")
    for it in r["interruptions"]:
        head = (f"interruption on square {it['tile']} ({it['code']}):" if it["tile"] is not None
                else "false interruption (no blank square there):")
        if it["declared"] is None:
            lines.append(f"{head} not declared")
            continue
        d = it["declared"]
        extra = ", ".join(f"{k} {v}" for k, v in d.items() if k != "t")
        text = f"{head} declared at {d['t']:.2f} s" + (f" ({extra})" if extra else "")
        rec = it["recovered"]
        if rec is None:
            text += "; not recovered"
        else:
            how = ", ".join(f"{k} {v}" for k, v in rec.items() if k != "t")
            text += f"; track picked up at {rec['t']:.2f} s, {rec['t'] - d['t']:.2f} s later" + (f" ({how})" if how else "")
        if it["offset_after_m"] is not None:
            verdict = "on the track" if it["on_track_after"] else "off the track"
            text += f"; 0.5 m into the next square {verdict} ({_mm(abs(it['offset_after_m']))} off)"
        lines.append(text)
    for e in r["lost"]:
        extra = ", ".join(f"{k} {v}" for k, v in e.items() if k not in ("t", "kind"))
        lines.append(f"track lost at {float(e['t']):.2f} s" + (f" ({extra})" if extra else ""))
    for e in r["errors"]:
        what = f"{e.get('task', '?')} ({e.get('action', '?')})" if "task" in e else "a primitive task"
        lines.append(f"error in {what} at {float(e['t']):.2f} s" + (f": {e['reason']}" if e.get("reason") else ""))
    if not r["events_on_path_clock"]:
        lines.append("note: the events' times are not on the path's clock (give events with the simulated time, "
                     "or t0_wall); interruptions were matched in order and every sample counted as following")
    if r["end_seen_t"] is not None:
        lines.append(f"T mark seen at {r['end_seen_t']:.2f} s")
    s = r["stop"]
    if s is None:
        lines.append("stop: the robot did not stop")
    else:
        past = "past" if s["along_m"] >= 0 else "short of"
        side = "left" if s["across_m"] >= 0 else "right"
        at = f" at {s['t']:.2f} s" if s["t"] is not None else ""
        lines.append(f"stop{at}: {_mm(abs(s['along_m']))} {past} the T bar, {_mm(abs(s['across_m']))} to the "
                     f"{side} of the track, heading off by {math.degrees(s['heading_error_rad']):.1f}°; "
                     f"{_mm(s['distance_m'])} from the mark's centre")
    return "\n".join(lines)


def _centre_line(course: Course, tile: Tile, n: int = 40) -> np.ndarray:
    before = sum(course.tile_length(t) for t in course.tiles[: tile.index])
    ss = np.linspace(before, before + course.tile_length(tile), n)
    return np.array([course.pose_at(float(s))[:2] for s in ss])


def top_view(course: Course, path: Any) -> Any:
    """The top view of a run as a matplotlib figure (Agg): the chessboard, every square of the course
    numbered as the report names it (``6 (B)``: its place in the course and, for an interruption, its
    code), the painted track, the interruptions (hatched squares, the hidden path dotted), the T mark,
    the beacons (resume points), the robot's path, where it started and, hollow so that the T stays
    visible under it, where it stopped.

    Returns:
        The figure; close it (``matplotlib.pyplot.close``) when done.

    Raises:
        ValueError: as :func:`score` for a bad path.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from matplotlib.patches import Rectangle

    arr = _check_path(path)
    i0, j0, i1, j1 = course.board(margin=1)
    sq = course.square
    fig, ax = plt.subplots(figsize=(max(4.0, 0.9 * (i1 - i0 + 1)), max(4.0, 0.9 * (j1 - j0 + 1))))
    try:
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                ax.add_patch(Rectangle((i * sq, j * sq), sq, sq, color="0.15" if course.is_black(i, j) else "0.85",
                                       zorder=0))
        for tile in course.tiles:
            pts = _centre_line(course, tile)
            i, j = tile.square
            ink = "white" if course.is_black(i, j) else "black"
            if tile.blank:
                ax.add_patch(Rectangle((i * sq, j * sq), sq, sq, fill=False, hatch="//", edgecolor="tab:orange",
                                       lw=1.5, zorder=0.5))
                ax.plot(pts[:, 0], pts[:, 1], ":", color="tab:orange", lw=1.0, zorder=1)
            else:
                ax.plot(pts[:, 0], pts[:, 1], "-", color=ink, lw=2.0, zorder=1)
            label = f"{tile.index + 1} ({tile.code})" if tile.blank else str(tile.index + 1)
            ax.text(i * sq + 0.06 * sq, j * sq + 0.94 * sq, label, color="tab:orange" if tile.blank else ink,
                    fontsize=7, fontweight="bold" if tile.blank else "normal", ha="left", va="top", zorder=3)
        ex, ey = course.end_point()
        end = course.tiles[-1]
        hx, hy = math.cos(end.heading * math.pi / 2.0), math.sin(end.heading * math.pi / 2.0)
        half_bar = course.end_bar_length / 2.0
        colour = "white" if course.is_black(*end.square) else "black"
        ax.plot([ex - hy * half_bar, ex + hy * half_bar], [ey + hx * half_bar, ey - hx * half_bar], "-",
                color=colour, lw=3.0, zorder=5, label="T mark")
        for _, bx, by, _ in course.resume_points():
            ax.plot(bx, by, "o", color="tab:orange", ms=7, zorder=3)
        if arr.shape[0]:
            ax.plot(arr[:, 1], arr[:, 2], "-", color="tab:red", lw=1.0, zorder=2, label="robot (axle midpoint)")
            ax.plot(arr[0, 1], arr[0, 2], "^", color="tab:green", ms=8, zorder=4, label="start")
            ax.plot(arr[-1, 1], arr[-1, 2], "s", mfc="none", mec="tab:blue", mew=1.5, ms=9, zorder=4, label="stop")
        ax.plot([], [], "o", color="tab:orange", label="beacon (resume point)")
        ax.add_patch(Rectangle((0, 0), 0, 0, fill=False, hatch="//", edgecolor="tab:orange",
                               label="interruption (no track painted)"))
        ax.set_aspect("equal")
        ax.set_xlim(i0 * sq, (i1 + 1) * sq)
        ax.set_ylim(j0 * sq, (j1 + 1) * sq)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{course.name}: top view (squares numbered as in the report)")
        ax.legend(loc="upper left", fontsize=7, framealpha=0.8)
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return fig


def write_top_view(course: Course, path: Any, png_path: str) -> None:
    """Write :func:`top_view` as a PNG.

    Raises:
        ValueError: as :func:`score` for a bad path.
        OSError: if the file cannot be written.
    """
    from matplotlib import pyplot as plt

    fig = top_view(course, path)
    try:
        fig.savefig(png_path, dpi=100)
    finally:
        plt.close(fig)
