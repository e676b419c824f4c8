"""Benchmark: reachability-graph construction, petrobot's explorer against pm4py's.

For each PNML model, two child processes (so memory peaks do not mix and a slow baseline can be
killed): one runs :func:`coordinator.analysis.statespace.explore`, the other pm4py's
``construct_reachability_graph`` on the same net (built in memory from the same PNML import), under
a time cap. Each side is timed on a fresh net (import and net building untimed) and, while its runs
so far took under ``--repeat-budget`` seconds, run again: ``seconds`` is the best run,
``first_seconds`` the first (cold) one, ``runs`` the count; small models are so fast that one cold
run measures mostly noise. Reported per model: states, edges, seconds, cpu_seconds (of the best
run), first_seconds, runs, load_seconds (numba's import and the compiled search's load, once per
process, before any run), net_matrices_seconds, peak_rss_bytes, bytes_per_marking (peak minus the
RSS after that load and before the first PNML import, per marking), memory_per_marking_bytes (the
search's packed marking store and hash table per marking) and packed_bits (one packed marking; the
search gets the place bounds ``petrobot analyze`` proves before its search, computed untimed),
markings_per_s, and for pm4py
pm4py_seconds / pm4py_first_seconds / pm4py_runs / pm4py_markings_per_s / speedup (best wall clock
against best wall clock) and speedup_cpu. pm4py runs with its own time limit (``max_elab_time``);
when it hits the cap, its rate is measured on the part of the graph it built (``pm4py_complete``
false, ``pm4py_seconds`` null) and the outer process is killed 120 s later.

A model is a PNML path, or ``FAMILY:N``: a contest family built at size N (``bench/families.py``:
``kanban:N``, the Kanban net of Ciardo and Tilgner with N tokens per stage, built from the structure
of the contest's Kanban-PT-00005 found through ``tests/unit/mcc_models.py`` or ``--mcc DIR`` —
Kanban-7 has 41,644,800 markings; ``fms:N``, ``philosophers:N``, ``sharedmemory:N``). ``--max-memory`` is the explorer's byte budget (default 16 GiB): a search that
reaches it stops and says so (``stopped_by``).

``--symbolic`` runs the symbolic engine (:mod:`coordinator.analysis.symbolic`) instead, one cold run
per model in its own process, the way ``petrobot analyze --engine symbolic`` does (bounds, groups,
saturation, then every property): states, edges, deadlock, the other oracle columns, seconds (wall
and CPU, bounds included, the kernel's load excluded: ``load_seconds``), ``phase_seconds``,
``nodes``, ``peak_rss_bytes``, and ``oracle_disagrees`` (the columns that differ from the
``oracle.tsv`` beside a ``model.pnml``; empty when all nine agree).

``--count-edges`` has our explorer count the edges without keeping them (``explore(...,
edges=False)``, ``edges_kept`` false in the row): what a question that needs the markings, their
number, the edge count and the deadlocks costs without the graph's 8 bytes an edge.

``--liveness`` then computes, once, the liveness levels and strongly connected components of the
graph found (:func:`coordinator.analysis.structure.liveness_levels`: scipy's components over the
kept edges, or, with ``--count-edges``, the components from the markings alone, each marking's
successors computed again): ``liveness_seconds``, ``liveness_cpu_seconds``, ``live``,
``reversible``, ``components``, ``terminal_components``; with the edges kept, the compiled pass
over them (:meth:`~coordinator.analysis.statespace.StateSpace.implicit_liveness`) is timed too,
scipy's as its baseline: ``edge_pass_seconds``, ``edge_pass_agrees`` (the same liveness levels);
``search_peak_rss_bytes`` is the peak before this pass, ``peak_rss_bytes`` the peak after it.

``--structural`` adds, per model, the structural path that needs no state space: the two semiflow
LPs (conservative, consistent) and the state-equation place bounds (:mod:`coordinator.analysis.lp`),
with their times and whether they decide boundedness (``structural_bounded``, ``structural_max_bound``).

Usage::

    python bench/statespace.py [--json] [--pm4py-timeout S] [--repeat-budget S] [--no-pm4py]
                               [--max-memory GIB] [--count-edges] [--liveness] [--structural]
                               [--mcc DIR] MODEL...
    python bench/statespace.py --symbolic [--json] [--seconds S] [--max-memory GIB] MODEL...
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from coordinator.net import PetriNet

ROOT = Path(__file__).resolve().parents[1]


def _rss_now() -> int:
    with open("/proc/self/statm", encoding="ascii") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _peak_rss() -> int:
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _best_of(build: Callable[[], Any], run: Callable[[Any], Any], budget: float) -> tuple[Any, float, float, float, int]:
    """Time ``run(build())`` (``build`` untimed, a fresh input each time) repeatedly while the runs so
    far took under ``budget`` seconds in total (at most 200 runs); return the last result, the
    first (cold) wall time, the best wall time, the CPU time of the best run and the number of runs."""
    first = best = best_cpu = float("inf")
    spent, runs, result = 0.0, 0, None
    while runs == 0 or (spent < budget and runs < 200):
        item = build()
        cpu, wall = time.process_time(), time.perf_counter()
        result = run(item)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if runs == 0:
            first = wall
        if wall < best:
            best, best_cpu = wall, cpu
        spent += wall
        runs += 1
    return result, first, best, best_cpu, runs


def mcc_dir(given: str | None) -> Path:
    """The MCC models: ``--mcc DIR``, else where the tests find them (tests/unit/mcc_models.py)."""
    if given:
        return Path(given)
    sys.path.insert(0, str(ROOT))
    from tests.unit.mcc_models import MCC

    return Path(MCC)


def load_model(spec: str, mcc: str | None) -> PetriNet:
    """A PNML path, or ``FAMILY:N``: a contest family at size N (:mod:`bench.families`)."""
    sys.path.insert(0, str(ROOT))
    from coordinator.netfile.pnml import load_pnml

    if _family(spec):
        from bench.families import build

        return build(spec, mcc_dir(mcc))
    return load_pnml(spec)


def _family(spec: str) -> bool:
    """``spec`` names a generated family (``FAMILY:N``, :mod:`bench.families`), not a file."""
    family, sep, size = spec.partition(":")
    return bool(sep) and size.isdigit() and not Path(spec).exists()


def model_name(spec: str) -> str:
    if _family(spec):
        sys.path.insert(0, str(ROOT))
        from bench.families import build

        return f"{build(spec, mcc_dir(None)).name} (generated)"
    return Path(spec).parent.name if Path(spec).name == "model.pnml" else Path(spec).stem


def child_structural(spec: str, mcc: str | None) -> dict[str, Any]:
    """The LP path: semiflow supports and state-equation bounds, timed, on a fresh net."""
    sys.path.insert(0, str(ROOT))
    from coordinator.analysis import lp
    from coordinator.analysis.matrices import sparse_net

    net = load_model(spec, mcc)
    start = time.perf_counter()
    sn = sparse_net(net)
    t_sparse = time.perf_counter() - start
    start = time.perf_counter()
    p_sup, t_sup = lp.conservative(sn), lp.consistent(sn)
    t_semiflows = time.perf_counter() - start
    start = time.perf_counter()
    pb = lp.place_bounds(sn, seconds=60.0)
    t_bounds = time.perf_counter() - start
    known = pb.bounds[pb.bounds >= 0]
    return {"structural_sparse_seconds": t_sparse, "structural_semiflow_seconds": t_semiflows,
            "structural_bounds_seconds": t_bounds, "conservative": p_sup.all_covered,
            "consistent": t_sup.all_covered, "semiflows_certified": p_sup.certified and t_sup.certified,
            "structural_bounded": bool(pb.total is not None or (pb.bounds >= 0).all()),
            "structural_total_bound": pb.total, "structural_max_bound": int(known.max()) if known.size else None,
            "structural_bounds_certified": bool(pb.certified[pb.bounds >= 0].all()),
            "structural_peak_rss_bytes": _peak_rss()}


def child_ours(path: str, max_states: int, budget: float, max_bytes: int | None = None,
               mcc: str | None = None, edges: bool = True, liveness: bool = False) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from coordinator.analysis.statespace import explore, load_search
    from coordinator.analysis.structure import search_bounds
    from coordinator.net import PetriNet

    # numba's import and the compiled search's load from its cache, once per process: reported on
    # their own (load_seconds), outside the runs and below the RSS baseline of bytes_per_marking
    load = load_search()
    if liveness and not edges:  # the pass over the markings loaded too (from numba's cache), outside the runs
        explore(load_model("kanban:1", mcc), edges=False).implicit_liveness()

    matrices: list[float] = []
    bounds: list[Any] = []

    def build() -> PetriNet:
        # the net's own cached matrices are part of the net model, as pm4py's arc objects are of
        # its net: built here untimed, their cost reported as net_matrices_seconds
        net = load_model(path, mcc)
        start = time.perf_counter()
        for view in (net.pre, net.post, net.inhibitor, net.incidence):
            assert view.shape == (len(net.places), len(net.transitions))
        matrices.append(time.perf_counter() - start)
        if not bounds:  # the bounds petrobot analyze proves before its search, untimed as the matrices
            bounds.append(search_bounds(net))
        return net

    before = _rss_now()
    space, first, wall, cpu, runs = _best_of(
        build, lambda net: explore(net, max_states=max_states, max_bytes=max_bytes, bounds=bounds[0], edges=edges),
        budget)
    peak = _peak_rss()
    found: dict[str, Any] = {}
    if liveness and space.complete:
        from coordinator.analysis.structure import liveness_levels

        stats: dict[str, int] = {}
        wall0, cpu0 = time.perf_counter(), time.process_time()
        levels, labels, terminal = liveness_levels(space) if space.edges_kept else space.implicit_liveness(stats)
        found = {**stats, "liveness_seconds": time.perf_counter() - wall0,
                 "liveness_cpu_seconds": time.process_time() - cpu0, "live": bool((levels == 4).all()),
                 "reversible": bool(terminal.shape[0] == 1),
                 "components": int(terminal.shape[0]), "terminal_components": int(terminal.sum()),
                 "search_peak_rss_bytes": peak}
        del labels
        peak = _peak_rss()
        if space.edges_kept:  # the compiled pass over the same edges, against scipy's as baseline
            space.implicit_liveness()  # compiled or loaded from numba's cache outside the timing
            wall0 = time.perf_counter()
            edge_levels = space.implicit_liveness()[0]
            found["edge_pass_seconds"] = time.perf_counter() - wall0
            found["edge_pass_agrees"] = edge_levels.tolist() == levels.tolist()
    return {**found, "states": space.n_states, "edges": space.n_edges, "edges_kept": space.edges_kept,
            "complete": space.complete,
            "stopped_by": space.stopped_by, "graph_bytes": space.nbytes, "seconds": wall,
            "cpu_seconds": cpu, "first_seconds": first, "runs": runs, "load_seconds": load,
            "net_matrices_seconds": min(matrices),
            "peak_rss_bytes": peak,
            "rss_before_bytes": before, "bytes_per_marking": (peak - before) / max(space.n_states, 1),
            "memory_per_marking_bytes": space.memory_per_marking_bytes, "packed_bits": space.packed_bits}


def _oracle_row(spec: str) -> dict[str, str] | None:
    """The contest's answers for a model folder's ``model.pnml``: the row of ``oracle.tsv`` beside it."""
    from bench.contest import oracle

    path = Path(spec)
    if path.name != "model.pnml" or not (path.parent.parent / "oracle.tsv").is_file():
        return None
    return oracle(path.parent.parent).get(path.parent.name)


def child_symbolic(spec: str, max_bytes: int, seconds: float, mcc: str | None = None) -> dict[str, Any]:
    """The symbolic engine as ``petrobot analyze --engine symbolic`` runs it: state-equation and
    P-semiflow bounds, small semiflows for the groups, then :func:`analyse_symbolic`; one cold run
    (the compiled kernel loaded first, untimed), checked against the model's oracle when it has one."""
    sys.path.insert(0, str(ROOT))
    from coordinator.analysis import jit

    jit.configure()
    from coordinator.analysis import lp
    from coordinator.analysis.matrices import sparse_net
    from coordinator.analysis.symbolic import analyse_symbolic
    from coordinator.net import Arc, Marking, PetriNet, Place, Transition

    start = time.perf_counter()
    one = PetriNet(name="load", places=(Place(id="p"),), transitions=(Transition(id="t"),),
                   arcs=(Arc(source="p", target="t"), Arc(source="t", target="p")), initial_marking=Marking({"p": 1}))
    analyse_symbolic(one, np.array([1], dtype=np.int64))
    load = time.perf_counter() - start
    net = load_model(spec, mcc)
    before = _rss_now()
    start = time.perf_counter()
    cpu = time.process_time()
    sn = sparse_net(net)
    pb = lp.place_bounds(sn, seconds=10.0)
    flows = lp.semiflow_cover(sn, seconds=3.0)
    t_bounds = time.perf_counter() - start
    out: dict[str, Any] = {"engine": "symbolic", "load_seconds": load, "bounds_seconds": t_bounds,
                           "places": sn.n_places, "transitions": sn.n_transitions}
    try:
        r = analyse_symbolic(net, pb.bounds, flows=flows, max_bytes=max_bytes, seconds=seconds)
    except Exception as exc:  # noqa: BLE001 - a bench row says why the engine gave up
        out.update({"complete": False, "error": str(exc), "seconds": time.perf_counter() - start,
                    "cpu_seconds": time.process_time() - cpu, "peak_rss_bytes": _peak_rss()})
        return out
    wall = time.perf_counter() - start
    top = int(r.place_bounds.max(initial=0))
    got = {"states": r.states, "edges": r.edges, "max_token_in_place": top,
           "max_token_per_marking": r.max_token_per_marking, "deadlock": r.deadlock, "live": r.live,
           "quasi_live": bool(r.fireable.all()), "one_safe": top <= 1, "stable_marking": bool(r.stable.any())}
    out.update(got)
    out.update({"complete": True, "seconds": wall, "cpu_seconds": time.process_time() - cpu,
                "phase_seconds": r.seconds, "levels": r.levels, "groups": r.groups, "nodes": r.nodes,
                "method": r.method,
                "n_deadlocks": r.n_deadlocks, "reversible": r.reversible,
                "deadlock_sequence_length": None if r.deadlock_sequence is None else len(r.deadlock_sequence),
                "peak_rss_bytes": _peak_rss(), "rss_before_bytes": before, "notes": r.notes})
    oracle = _oracle_row(spec)
    if oracle is not None:
        from bench.contest import COLUMNS, expected

        want = {k: expected(oracle[k]) for k in COLUMNS}
        out["oracle_disagrees"] = sorted(k for k in COLUMNS if want[k] is not None and got.get(k) != want[k])
    return out


def child_pm4py(path: str, cap: float, budget: float, mcc: str | None = None) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from pm4py.objects.petri_net.obj import Marking as PMarking
    from pm4py.objects.petri_net.obj import PetriNet as PNet
    from pm4py.objects.petri_net.utils import petri_utils
    from pm4py.objects.petri_net.utils.reachability_graph import (
        Parameters,
        construct_reachability_graph,
    )

    def build() -> tuple[Any, Any]:
        net = load_model(path, mcc)
        pnet = PNet(net.name)
        places = {p.id: PNet.Place(p.id) for p in net.places}
        trans = {t.id: PNet.Transition(t.id, t.id) for t in net.transitions}
        for p in places.values():
            pnet.places.add(p)
        for t in trans.values():
            pnet.transitions.add(t)
        for arc in net.arcs:
            if arc.inhibitor:
                raise SystemExit("pm4py baseline: inhibitor arcs are not supported")
            src = places.get(arc.source) or trans[arc.source]
            dst = places.get(arc.target) or trans[arc.target]
            petri_utils.add_arc_from_to(src, dst, pnet, weight=arc.weight)
        m0 = PMarking()
        for pid, count in net.initial_marking.items():
            m0[places[pid]] = count
        return pnet, m0

    # pm4py's own time limit: it stops and returns the part of the graph built so far
    ts, first, wall, cpu, runs = _best_of(
        build, lambda item: construct_reachability_graph(item[0], item[1], parameters={Parameters.MAX_ELAB_TIME: cap}),
        budget)
    return {"states": len(ts.states), "edges": len(ts.transitions), "seconds": wall, "cpu_seconds": cpu,
            "first_seconds": first, "runs": runs, "peak_rss_bytes": _peak_rss()}


def run_child(kind: str, path: str, timeout: float, max_states: int, budget: float,
              cap: float = 60.0, extra: list[str] | None = None) -> dict[str, Any] | None:
    cmd = [sys.executable, __file__, "--child", kind, "--max-states", str(max_states), "--pm4py-timeout", str(cap),
           "--repeat-budget", str(budget), *(extra or []), path]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=True)
    except subprocess.TimeoutExpired:
        return None
    except subprocess.CalledProcessError as exc:
        raise SystemExit(f"{kind} failed on {path}:\n{exc.stderr}") from exc
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def bench(path: str, cap: float, with_pm4py: bool, max_states: int, budget: float,
          extra: list[str] | None = None, structural: bool = False) -> dict[str, Any]:
    ours = run_child("ours", path, 3600.0, max_states, budget, extra=extra)
    assert ours is not None
    row: dict[str, Any] = {"model": model_name(path)}
    row.update(ours)
    row["markings_per_s"] = ours["states"] / max(ours["seconds"], 1e-9)
    if structural:
        found = run_child("structural", path, 600.0, max_states, budget, extra=extra)
        row.update(found or {"structural_seconds": None})
    if with_pm4py:
        base = run_child("pm4py", path, cap + budget + 120.0, max_states, budget, cap, extra=extra)
        row["pm4py_timeout_s"] = cap
        if base is None:
            row["pm4py_seconds"] = None
        else:
            row["pm4py_complete"] = base["states"] == ours["states"]
            row["pm4py_seconds"] = base["seconds"] if row["pm4py_complete"] else None
            row["pm4py_elapsed_s"] = base["seconds"]
            row["pm4py_states"] = base["states"]
            row["pm4py_edges"] = base["edges"]
            row["pm4py_cpu_seconds"] = base["cpu_seconds"]
            row["pm4py_first_seconds"] = base["first_seconds"]
            row["pm4py_runs"] = base["runs"]
            row["pm4py_peak_rss_bytes"] = base["peak_rss_bytes"]
            # rates on markings built per second (on a partial graph when pm4py hit its cap)
            row["pm4py_markings_per_s"] = base["states"] / max(base["seconds"], 1e-9)
            row["speedup"] = row["markings_per_s"] / row["pm4py_markings_per_s"]
            row["speedup_cpu"] = (ours["states"] / max(ours["cpu_seconds"], 1e-9)) / (
                base["states"] / max(base["cpu_seconds"], 1e-9))
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("models", nargs="+", metavar="MODEL",
                        help="PNML model files, or FAMILY:N, a contest family built at size N: kanban:N, fms:N, "
                             "philosophers:N, sharedmemory:N (bench/families.py)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    parser.add_argument("--pm4py-timeout", type=float, default=60.0, metavar="S",
                        help="time cap of the pm4py baseline per model, seconds (default 60)")
    parser.add_argument("--no-pm4py", action="store_true", help="skip the pm4py baseline")
    parser.add_argument("--max-states", type=int, default=2**31 - 1,
                        help="state limit of our explorer (default 2**31 - 1: the byte budget decides)")
    parser.add_argument("--repeat-budget", type=float, default=1.0, metavar="S",
                        help="repeat each side (a fresh net each time) while its runs took under S seconds in total "
                             "and report the best run (default 1; 0 = one cold run)")
    parser.add_argument("--max-memory", type=float, default=16.0, metavar="GIB",
                        help="byte budget of our explorer in GiB (default 16); the search stops there and says so")
    parser.add_argument("--count-edges", action="store_true",
                        help="our explorer counts the edges without keeping them (explore(..., edges=False)): "
                             "the markings, edge count and deadlocks of a question that needs no graph")
    parser.add_argument("--liveness", action="store_true",
                        help="then compute the liveness levels and components of the graph found, once (with "
                             "--count-edges: from the markings alone, each marking's successors computed again)")
    parser.add_argument("--structural", action="store_true",
                        help="also time the structural path: semiflow LPs and state-equation place bounds")
    parser.add_argument("--mcc", metavar="DIR", help="folder of the MCC models (default: where the tests find them)")
    parser.add_argument("--symbolic", action="store_true",
                        help="run the symbolic engine instead of the explicit search (no pm4py): one cold run per "
                             "model, its counts checked against the model's oracle.tsv when it has one")
    parser.add_argument("--seconds", type=float, default=600.0, metavar="S",
                        help="time budget of the symbolic engine per model (default 600)")
    parser.add_argument("--child", choices=["ours", "pm4py", "structural", "symbolic"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    extra = ["--max-memory", str(args.max_memory)] + (["--mcc", args.mcc] if args.mcc else []) + (
        ["--count-edges"] if args.count_edges else []) + (["--liveness"] if args.liveness else [])
    if args.child:
        if args.child == "ours":
            result = child_ours(args.models[0], args.max_states, args.repeat_budget,
                                int(args.max_memory * 2**30), args.mcc, not args.count_edges, args.liveness)
        elif args.child == "structural":
            result = child_structural(args.models[0], args.mcc)
        elif args.child == "symbolic":
            result = child_symbolic(args.models[0], int(args.max_memory * 2**30), args.seconds, args.mcc)
        else:
            result = child_pm4py(args.models[0], args.pm4py_timeout, args.repeat_budget, args.mcc)
        print(json.dumps(result))
        return 0
    rows = []
    for path in args.models:
        if args.symbolic:
            found = run_child("symbolic", path, args.seconds + 600.0, args.max_states, 0.0,
                              extra=[*extra, "--seconds", str(args.seconds)])
            row = {"model": model_name(path), **(found or {"complete": False, "error": "killed"})}
            rows.append(row)
            if not args.json:
                _print_symbolic(row)
            continue
        row = bench(path, args.pm4py_timeout, not args.no_pm4py, args.max_states, args.repeat_budget, extra,
                    args.structural)
        rows.append(row)
        if not args.json:
            _print_row(row)
    if args.json:
        print(json.dumps({"date": time.strftime("%Y-%m-%d"), "python": sys.version.split()[0],
                          "cpus": os.cpu_count(), "models": rows}, indent=2))
    return 0


def _print_symbolic(row: dict[str, Any]) -> None:
    if not row.get("complete"):
        print(f"{row['model']:<28} symbolic: gave up after {row.get('seconds', 0):.1f} s: {row.get('error')}", flush=True)
        return
    oracle = row.get("oracle_disagrees")
    check = "" if oracle is None else ("  oracle: all nine columns agree" if not oracle else f"  ORACLE DIFFERS: {oracle}")
    print(f"{row['model']:<28} symbolic {row['states']:>22,} markings  deadlock={row['deadlock']}  "
          f"{row['seconds']:7.1f} s (cpu {row['cpu_seconds']:.1f} s)  peak {row['peak_rss_bytes'] / 2**20:6.0f} MiB  "
          f"{row['nodes']:,} nodes{check}", flush=True)


def _print_row(row: dict[str, Any]) -> None:
    base = ""
    if "speedup" in row:
        done = "" if row["pm4py_complete"] else f" (capped: {row['pm4py_states']:,} markings)"
        base = (f"  pm4py {row['pm4py_elapsed_s'] * 1e3:,.2f} ms{done} ({row['pm4py_markings_per_s']:,.0f}/s)"
                f"  speedup {row['speedup']:,.0f}x (cpu {row['speedup_cpu']:,.0f}x)")
    if "structural_semiflow_seconds" in row:
        base += (f"  structural: LPs {row['structural_semiflow_seconds'] * 1e3:,.1f} ms + bounds "
                 f"{row['structural_bounds_seconds'] * 1e3:,.1f} ms, bounded={row['structural_bounded']} "
                 f"(max bound {row['structural_max_bound']}), conservative={row['conservative']}, "
                 f"consistent={row['consistent']}")
    if "liveness_seconds" in row:
        base += (f"  liveness {row['liveness_seconds']:.2f} s: live={row['live']} reversible={row['reversible']} "
                 f"({row['components']:,} components, {row['terminal_components']:,} terminal)")
        if "edge_pass_seconds" in row:
            base += (f"; compiled pass over the edges {row['edge_pass_seconds']:.2f} s "
                     f"({row['liveness_seconds'] / max(row['edge_pass_seconds'], 1e-9):.1f}x scipy's speed, "
                     f"levels {'agree' if row['edge_pass_agrees'] else 'DIFFER'})")
    stop = "" if row["complete"] else f" [stopped by {row['stopped_by']}]"
    kept = "" if row.get("edges_kept", True) else " (counted)"
    print(f"{row['model']:<26} {row['states']:>10,} states{stop} {row['edges']:>11,} edges{kept} "
          f"{row['seconds'] * 1e3:>10,.2f} ms (best of {row['runs']}; cold {row['first_seconds'] * 1e3:,.2f} ms; "
          f"search load {row['load_seconds']:.2f} s) "
          f"{row['markings_per_s']:>10,.0f}/s peak {row['peak_rss_bytes'] / 2**20:>6.0f} MiB "
          f"({row['bytes_per_marking']:.0f} B/marking; store {row['memory_per_marking_bytes']:.0f} B/marking, "
          f"packed {row['packed_bits']} bits){base}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
