"""``petrobot analyze NET [--json] [--max-states N] [--max-memory SIZE] [--max-file-size SIZE] [--engine E] [--progress]``:
qualitative analysis of a task net.

Thin shell over :func:`coordinator.analysis.robotic.report` (paper section 2, "Qualitative
Performance Evaluation"): loads the net (TOML or PNML), analyses its ordinary view (events dropped)
within a state limit and a memory budget, and prints a readable report, or the JSON report with
``--json``. The engine (explicit reachability graph or symbolic decision diagram) is chosen by the
analysis unless ``--engine`` forces one; the report says which ran and why. Progress of long state-space constructions goes to stderr, on a terminal or with
``--progress``; a one-line notice goes to stderr when the compiled search has to be compiled first
(once per machine). The symbolic engine's kernels are then compiled beside it, in a second
process (:func:`compile_symbolic`), which the symbolic engine waits for if it is needed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any, TextIO

from coordinator.analysis.budget import default_max_bytes
from services.errors import PetrobotError

__all__ = ["add_parser", "compile_symbolic", "parse_size", "render", "run"]

DEFAULT_MAX_STATES = 25_000_000
_UNITS = {"": 1, "B": 1, "K": 1 << 10, "KB": 1 << 10, "KIB": 1 << 10, "M": 1 << 20, "MB": 1 << 20,
          "MIB": 1 << 20, "G": 1 << 30, "GB": 1 << 30, "GIB": 1 << 30, "T": 1 << 40, "TB": 1 << 40, "TIB": 1 << 40}


#: The largest PNML file ``analyze`` reads by default: a model of the user's own, analysed within the
#: memory budget (reading a 42 MiB contest model, 387,200 arcs, takes about 14 s and 0.7 GiB).
DEFAULT_MAX_FILE_BYTES = 256 * 2**20


def parse_size(text: str) -> int:
    """Parse a memory size: a number with an optional unit K, M, G, T (powers of 1024; "MB", "MiB"
    accepted), e.g. ``512M``, ``4G``, ``1.5GiB``; bytes without a unit.

    Raises:
        argparse.ArgumentTypeError: on anything else, or a size below 1 MiB.
    """
    raw = text.strip().upper().replace(" ", "")
    num = raw.rstrip("KMGTIB")
    unit = raw[len(num):]
    try:
        value = float(num)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a memory size: {text!r} (use e.g. 512M, 4G)") from None
    if unit not in _UNITS:
        raise argparse.ArgumentTypeError(f"unknown unit in {text!r} (use K, M, G or T)")
    size = int(value * _UNITS[unit])
    if size < 1 << 20:
        raise argparse.ArgumentTypeError(f"memory budget {text!r} is below 1 MiB")
    return size


def _search_is_compiled() -> bool | None:
    """:func:`coordinator.analysis.statespace.search_is_compiled`, imported when asked (scipy and
    the search are not imported by commands that do not analyse)."""
    from coordinator.analysis.statespace import search_is_compiled as compiled

    return compiled()

def add_parser(subparsers: Any) -> None:
    """Register ``analyze`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "analyze",
        help="qualitative analysis: boundedness, deadlocks, liveness, invariants, robotic reading",
        description=(
            "Analyse the ordinary Petri net of a task (events dropped, so every transition fires as "
            "soon as it is enabled): reachability graph (state count, edges), boundedness and the bound "
            "of each place (Karp-Miller coverability when the graph is infinite), safeness, deadlocks "
            "with a shortest firing sequence, liveness level L0-L4 of each transition, reversibility and "
            "home states, stable places, minimal P- and T-invariants, structural conflicts; then read "
            "them as robotic properties: stable (bounded), error recoverable (every marking can return "
            "to the home marking) and controllable (live). Exit status 0 when the analysis ran, 1 on an "
            "unreadable net."),
    )
    parser.add_argument("net", metavar="NET", help="net file (.toml, .pnml or .xml)")
    parser.add_argument("--json", action="store_true",
                        help="print the machine-readable report (JSON; null means 'not decided')")
    parser.add_argument("--max-states", type=int, default=DEFAULT_MAX_STATES, metavar="N",
                        help=f"stop the reachability graph at N markings (default: {DEFAULT_MAX_STATES:,}); "
                             "properties that need the whole graph are then left undecided")
    parser.add_argument("--max-memory", type=parse_size, default=None, metavar="SIZE",
                        help="memory budget of the analysis, e.g. 512M or 8G (default: half the physical "
                             f"memory or 4 GiB, whichever is smaller; here {default_max_bytes() / 2**30:.1f} GiB); "
                             "at the default or above, what the process already holds counts against it; "
                             "a search that reaches it stops with a partial, labelled report")
    parser.add_argument("--max-file-size", type=parse_size, default=DEFAULT_MAX_FILE_BYTES, metavar="SIZE",
                        help=f"largest PNML file read, e.g. 64M (default: {DEFAULT_MAX_FILE_BYTES // 2**20} MiB; "
                             "Model Checking Contest models reach 42 MiB; other commands read at most 16 MiB)")
    parser.add_argument("--engine", choices=("auto", "explicit", "symbolic"), default="auto",
                        help="explicit: the reachability graph, marking by marking (every property, up to the "
                             "state limit); symbolic: the reachable set as a decision diagram (exact counts, "
                             "deadlocks, bounds, liveness, reversibility of nets of 10^12 markings and more; a "
                             "bounded net: a place without a proven bound gets levels guessed from the counts seen, "
                             "and the net is shown bounded when no firing leaves them); auto (default): explicit up "
                             "to 1,000,000 markings, symbolic beyond (when not every place has a proven bound, only "
                             "if no pumping witness shows the net unbounded). The report says which ran and why")
    parser.add_argument("--progress", action="store_true",
                        help="report state-space progress on stderr even when stderr is not a terminal")


class _Progress:
    """The progress on stderr: the markings counter, rewritten in place (``\\r``), and one line per
    phase or notice (the compile's), written whole with its newline, so that a reader of a pipe (a
    log, ``tee``) gets each phase when it begins, not when the next one does; an open line (the
    counter's) is ended first."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.start = time.monotonic()
        self.last = 0.0
        self.open = False  # the counter's line is not ended yet

    def count(self, states: int, edges: int) -> None:
        now = time.monotonic()
        if now - self.last < 0.5:
            return
        self.last = now
        rate = states / max(now - self.start, 1e-9)
        self.stream.write(f"\r  {states:>12,} markings  {edges:>14,} edges  {rate:>11,.0f} markings/s")
        self.stream.flush()
        self.open = True

    def phase(self, text: str) -> None:
        self.note(f"  {text}")

    def note(self, text: str) -> None:
        """A line of its own (a phase, or a notice such as the compile's), the counter's line ended
        first if it is open."""
        self.stream.write(("\n" if self.open else "") + f"{text}\n")
        self.stream.flush()
        self.open = False

    def begin(self, text: str) -> None:
        """A line left open, for :meth:`end` to finish (a notice in between starts a line of its own)."""
        self.stream.write(text)
        self.stream.flush()
        self.open = True

    def end(self, tail: str = "", alone: str = "") -> None:
        """End the open line (the counter's, or :meth:`begin`'s) with ``tail``; if a notice ended it
        already, ``alone`` on a line of its own instead (nothing if empty)."""
        if self.open:
            self.stream.write(f"{tail}\n")
            self.stream.flush()
            self.open = False
        elif alone:
            self.note(alone)


def _yes(value: Any) -> str:
    return {True: "yes", False: "no", None: "not decided"}.get(value, str(value))


def _marking(marking: dict[str, int]) -> str:
    return "{" + (", ".join(f"{p}:{c}" for p, c in marking.items()) or "no tokens") + "}"


#: the firings a text report shows of a long firing sequence: the first ones and the last ones
_SEQUENCE_HEAD, _SEQUENCE_TAIL = 30, 10


def _sequence(ids: list[str]) -> str:
    """A firing sequence for the text report: whole when short, else its first and last firings
    and how many there are (``--json`` lists them all)."""
    if len(ids) <= _SEQUENCE_HEAD + _SEQUENCE_TAIL + 1:
        return " ".join(ids)
    return (" ".join(ids[:_SEQUENCE_HEAD]) + f" ... ({len(ids):,} firings in all, --json lists them) ... "
            + " ".join(ids[-_SEQUENCE_TAIL:]))


def _ends(rep: dict[str, Any]) -> list[str]:
    """The dead markings read as the runtime ends a run there (robotic.dead_ends)."""
    ends = rep.get("ends") or {}
    if rep["deadlock"] is None and not ends.get("total"):
        return ["ends:               not decided: no dead marking was found, and the markings searched are not "
                "all the reachable ones"]
    if not rep["deadlock"] and not ends.get("total"):
        return ["ends:               none: in every reachable marking some transition can fire"]
    total = ends.get("total")
    counted = ends.get("decided")
    lines = [f"ends: {total if total is not None else 'some'} dead marking{'s' if total != 1 else ''} (nothing can fire), "
             "read as a run ends there (home compared on the places that hold work: control places and counters "
             "aside)"]
    home = ", ".join(f"{p} {n}" for p, n in ends.get("home", {}).items() if n)
    what = {"intended": f"intended ends (the run completes at home: {home or 'no tokens'})",
            "operator": "waiting for the operator (a command on a control place would let a transition fire)",
            "stuck": "real deadlocks (the run ends stuck, away from home)"}
    for kind in ("intended", "operator", "stuck"):
        n = ends.get(kind)
        examples = ends.get("examples", {}).get(kind, [])
        if counted:
            extra = ""
            if kind == "stuck" and n and ends.get("stuck_designed_stop") == n:
                extra = ", every one after the net's designed stop (a give-up error exit)"
            lines.append(f"  {what[kind]}: {n}{extra}")
        elif examples:
            lines.append(f"  {what[kind]}: among the examples found")
        for ex in examples:
            seq = _sequence(ex["firing_sequence"]) or "(initial marking)"
            lines.append(f"    {_marking(ex['marking'])} after: {seq}")
            if kind == "stuck" and ex["away_from_home"]:
                lines.append(f"      away from home: {'; '.join(ex['away_from_home'])}")
            if kind == "operator":
                lines.append(f"      {'; '.join(ex['operator'])}")
    return lines


#: What each property means, in plain words (shown in brackets after its value).
_PLAIN = {
    "quasi-live": "quasi-live = every transition can fire at least once",
    "live": "live = every transition can fire again from every reachable marking",
    "reversible": "reversible = the initial marking can be reached again from every reachable marking",
    "1-safe": "1-safe = no place ever holds more than one token",
    "conservative": "conservative = a weighted sum of the tokens of all places never changes: none made, none lost",
    "consistent": "consistent = some sequence of firings that fires every transition brings the net back to the "
                  "marking it started from",
    "home states": "markings reachable again from every reachable marking",
    "stable places": "places whose count never changes",
}


def render(rep: dict[str, Any]) -> str:
    """Return the readable text of a :func:`~coordinator.analysis.robotic.report` dictionary."""
    from coordinator.analysis.robotic import LEVEL_MEANINGS

    lines = [f"net {rep['net']!r}: {rep['places']} places, {rep['transitions']} transitions (ordinary view: events "
             "dropped, every enabled transition may fire)"]
    trunc = rep.get("truncated")
    full = ""
    if trunc:
        why = {"max_states": "the state limit", "max_memory": "the memory budget"}.get(trunc["by"], trunc["by"])
        full = f" (partial: stopped by {why})" if not rep["complete"] else f" (complete; later passes skipped: {why})"
    records = [p for p, b in (rep.get("place_bounds") or {}).items()
               if p in set((rep.get("environment") or {}).get("record_only", []))]
    env_states = (rep.get("environment") or {}).get("states")
    kept = (f" (markings that differ only in the counts {', '.join(records)} are told apart; the robotic reading "
            f"below uses another graph, of {env_states:,} markings: without those counts, with the operator's "
            "additions)" if records and env_states else "")
    engine = rep.get("engine") or {}
    if engine.get("used") == "symbolic":
        lines.append(f"reachable set (symbolic): {rep['states']:,} markings, {rep['edges']:,} edges of the net as "
                     f"written, exact{kept}")
    elif rep["states"] is None and trunc:
        lines.append(f"reachability graph: {trunc['states_found']:,} markings, {trunc['edges_found']:,} edges of "
                     f"the net as written found before the search stopped{full}{kept}")
    else:
        lines.append(f"reachability graph: {rep['states']:,} markings, {rep['edges']:,} edges of the net as "
                     f"written{full}{kept}")
    if engine.get("reason"):
        lines.append(f"engine: {engine['reason']}")
    if trunc and trunc.get("undecided"):
        lines.append(f"undecided: {', '.join(trunc['undecided'])}")
    lines.append("")
    lines.append("robotic reading")
    for key, title in (("stable", "stable"), ("error_recoverable", "error recoverable"),
                       ("controllable", "controllable")):
        v = rep["robotic"][key]
        lines.append(f"  {title + ':':<19}{_yes(v['holds'])}")
        lines.append(f"    {v['explanation']}")
    env = rep.get("environment") or {}
    if env.get("modelled"):
        places = ", ".join(f"{p} (up to {k})" for p, k in env["control_places"].items())
        dropped = env.get("record_only") or []
        without = (f"the net without its record-only places ({', '.join(dropped)}: counts no transition reads, "
                   "which change nothing the task can do next)" if dropped else "the net as written")
        lines.append(f"  environment:       the operator may add tokens to {places} at any time; recovery and "
                     f"control are judged on {env['states']:,} markings: {without}, with the operator's additions")
    else:
        lines.append("  environment:       no control places: nothing for the operator to add")
    retries = (rep.get("retries") or {}).get("retries", [])
    for r in retries:
        if r["bounded"] is None:
            lines.append(f"  retry {r['transition']} (task {r['task']}): bound not decided")
        elif r["bounded"]:
            lines.append(f"  retry {r['transition']} (task {r['task']}): bounded (no loop of error branches repeats it)")
        else:
            ex = r.get("example")
            where = f" (e.g. after {_sequence(ex['firing_sequence']) or 'the initial marking'})" if ex else ""
            lines.append(f"  retry {r['transition']} (task {r['task']}): UNBOUNDED: it can fire for ever while nothing "
                         f"else happens{where}; bound it with a counter place")
    lines.append("")
    lines.append("properties (of the net as written, without the operator: a transition that needs an operator's "
                 "token is dead here)")
    lines.append(f"  bounded:            {_yes(rep['bounded'])}")
    if rep["unbounded_places"]:
        lines.append(f"    unbounded places: {', '.join(rep['unbounded_places'])}")
    bounds = rep["place_bounds"]
    if bounds and rep["bounded"]:
        exact = rep.get("place_bounds_exact", "all")
        shown = list(bounds.items())[:40]
        lines.append("    bounds: " + ", ".join(f"{p}≤{b}" for p, b in shown)
                     + (f" ... ({len(bounds) - 40} more in --json)" if len(bounds) > 40 else ""))
        if exact != "all":
            lines.append(f"    (upper bounds; exact for {len(exact)} of {len(bounds)} places)")
    lines.append(f"  1-safe:             {_yes(rep['one_safe'])} [{_PLAIN['1-safe']}]")
    lines.append(f"  max tokens/place:   {rep['max_token_in_place'] if rep['max_token_in_place'] is not None else '-'}")
    lines.append(f"  max tokens/marking: {rep['max_token_per_marking'] if rep['max_token_per_marking'] is not None else '-'}")
    ends = rep.get("ends") or {}
    if ends.get("decided"):
        real = ends.get("stuck") or 0
        lines.append(f"  deadlock:           {_yes(real > 0)} [a real deadlock = a dead marking away from home that no "
                     f"operator command moves on: {real} of the {ends['total']} dead markings; "
                     f"{ends.get('intended') or 0} intended end(s), {ends.get('operator') or 0} waiting for the "
                     "operator; see ends below]")
    else:
        n_dead = rep["n_deadlocks"]
        lines.append(f"  deadlock:           {_yes(rep['deadlock'])} [deadlock = some reachable marking enables no "
                     "transition" + (f"; {n_dead} dead markings, intended ends included" if n_dead else "")
                     + "; see ends below]")
    lines.append(f"  quasi-live:         {_yes(rep['quasi_live'])} [{_PLAIN['quasi-live']}]")
    lines.append(f"  live:               {_yes(rep['live'])} [{_PLAIN['live']}]")
    if rep["liveness"]:
        by_level: dict[str, list[str]] = {}
        for t, lvl in rep["liveness"].items():
            by_level.setdefault(lvl, []).append(t)
        for lvl in sorted(by_level, reverse=True):
            lines.append(f"    {lvl} ({LEVEL_MEANINGS.get(lvl, lvl)}): {', '.join(by_level[lvl])}")
    lines.append(f"  reversible:         {_yes(rep['reversible'])} [{_PLAIN['reversible']}]")
    if rep["home_states"] is not None:
        lines.append(f"  home states:        {rep['home_states']} [{_PLAIN['home states']}]")
    if rep["home_marking_is_home"] is not None:
        lines.append(f"  declared home marking is a home state: {_yes(rep['home_marking_is_home'])}")
    stable = rep["stable_places"]
    lines.append(f"  stable places:      {', '.join(stable) if stable else ('none' if stable is not None else '-')} "
                 f"[{_PLAIN['stable places']}]")
    lines.append(f"  conservative:       {_yes(rep['conservative'])} [{_PLAIN['conservative']}]")
    lines.append(f"  consistent:         {_yes(rep['consistent'])} [{_PLAIN['consistent']}]")
    for key, title in (("p_invariants", "P-invariants"), ("t_invariants", "T-invariants")):
        inv = rep[key]
        lines.append(f"  {title}: {len(inv)}" + ("" if rep[f"{key}_complete"] else " (size guard hit)"))
        for vec in inv[:10]:
            lines.append("    " + " + ".join(f"{w}·{i}" if w != 1 else i for i, w in vec.items()))
        if len(inv) > 10:
            lines.append(f"    ... {len(inv) - 10} more (see --json)")
    sources = rep.get("sources") or {}
    if sources and not rep["complete"]:
        lines.append("  decided by:")
        for key, how in sources.items():
            lines.append(f"    {key}: {how}")
    conflicts = rep["structural_conflicts"]
    lines.append(f"  structural conflicts: {len(conflicts)}")
    for c in conflicts[:10]:
        eff = {True: "effective", False: "never effective", None: "?"}[c["effective"]]
        many = len(c["transitions"]) - 10
        listed = ", ".join(c["transitions"][:10]) + (f" and {many:,} more (see --json)" if many > 0 else "")
        lines.append(f"    {c['place']}: {listed} ({eff})")
    if len(conflicts) > 10:
        lines.append(f"    ... {len(conflicts) - 10} more (see --json)")
    lines.append("")
    lines.extend(_ends(rep))
    for problem in rep["interpretation_problems"]:
        lines.append(f"  note: {problem['problem']}")
    for note in rep["notes"]:
        lines.append(f"  note: {note}")
    return "\n".join(lines)


#: seconds the symbolic engine waits for the process compiling its kernels before it compiles them
#: itself (a compile takes 25-30 s on 2 cores)
SYMBOLIC_COMPILE_WAIT = 120.0


def compile_symbolic() -> None:
    """Compile the symbolic engine's kernels into numba's cache (or load them from there): the
    symbolic analysis of a two-robot fleet (:mod:`coordinator.netfile.fleet`), its report dropped.
    Run by ``analyze`` in a second process while it compiles the explicit search, so that a first
    analysis on a machine compiles the two at once (docs/analysis.md, section 9, *Cold start*)."""
    from coordinator.analysis.robotic import report
    from coordinator.netfile.fleet import fleet_toml
    from coordinator.netfile.loader import loads_net

    report(loads_net(fleet_toml(2), "<fleet of 2>", interpreted=False), engine="symbolic")


class _Beside:
    """The process that compiles the symbolic engine's kernels beside this one's compile; ``say``
    writes its notices (a line each)."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.proc: subprocess.Popen[bytes] | None = None
        self.say = say

    def start(self) -> None:
        if self.proc is not None:
            return
        import os
        from pathlib import Path

        import coordinator

        code = "from coordinator.commands.analyze import compile_symbolic; compile_symbolic()"
        root = str(Path(coordinator.__file__).resolve().parents[1])  # this petrobot, wherever it runs from
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
        try:
            self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        except OSError as exc:
            self.say(f"(the symbolic engine's kernels will compile when needed: {exc})")

    def wait(self) -> None:
        if self.proc is None:
            return
        self.say("waiting for the symbolic engine's kernels, compiling in another process...")
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=SYMBOLIC_COMPILE_WAIT)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=10)


def run(args: argparse.Namespace) -> int:
    """Analyse the net; print the report; return 0, or 1 if the net cannot be loaded."""
    from coordinator.analysis.robotic import report
    from coordinator.analysis.statespace import load_search, set_compile_notice
    from coordinator.netfile import load_any

    try:
        net = load_any(args.net, interpreted=False, max_pnml_bytes=args.max_file_size)
    except PetrobotError as exc:
        print(f"petrobot analyze: {exc}", file=sys.stderr)
        return 2
    show = args.progress or sys.stderr.isatty()
    shown = _Progress(sys.stderr) if show else None

    def say(text: str) -> None:
        """A notice on a line of its own (after the progress counter's line, if that is open)."""
        if shown is not None:
            shown.note(text)
        else:
            sys.stderr.write(f"{text}\n")
            sys.stderr.flush()

    beside = _Beside(say)

    def compiling() -> None:
        say("compiling the state-space search (once per machine)...")
        if args.engine != "explicit":
            from coordinator.analysis.symbolic import set_kernels_wait

            say("compiling the symbolic engine's kernels beside it, in another process")
            beside.start()
            if beside.proc is not None:
                set_kernels_wait(beside.wait)

    set_compile_notice(compiling)
    if shown is not None and _search_is_compiled() is not False:
        shown.begin("  loading the compiled state-space search ...")
        seconds = load_search()
        shown.end(f" {seconds:.1f} s", f"  loaded the compiled state-space search in {seconds:.1f} s")
    elif show:
        sys.stderr.write("  the compiled state-space search is not in the cache yet: a small net is searched by "
                         "the interpreter, a larger one compiles it first\n")
    if shown is not None:
        shown.start = time.monotonic()  # the markings/s figure counts from here, the search's loading aside
    with _long_counts():
        try:
            rep = report(net, max_states=args.max_states, max_bytes=args.max_memory,
                         progress=shown.count if shown else None, engine=args.engine,
                         phase=shown.phase if shown else None)
        except PetrobotError as exc:
            print(f"petrobot analyze: {exc}", file=sys.stderr)
            return 1
        finally:
            set_compile_notice(None)
            if beside.proc is not None:
                from coordinator.analysis.symbolic import set_kernels_wait

                set_kernels_wait(None)
            beside.stop()
            if shown:
                shown.end()
        if args.json:
            print(json.dumps(rep, indent=2))
        else:
            print(render(rep))
    return 0


@contextlib.contextmanager
def _long_counts() -> Iterator[None]:
    """Lift Python's limit on the digits of an integer turned into text (4,300 by default, a guard
    against parsing long numbers) while the report is made: the symbolic engine's exact counts can
    be longer (2^15000 markings have 4,516 digits) and are written whole. The net was read before,
    under the limit."""
    old = sys.get_int_max_str_digits()
    sys.set_int_max_str_digits(0)
    try:
        yield
    finally:
        sys.set_int_max_str_digits(old)
