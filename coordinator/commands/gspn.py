"""``petrobot gspn``: the quantitative (GSPN) view of a net — CTMC measures, bottlenecks, task time."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

from coordinator.commands import options
from coordinator.commands.options import parse_pairs
from coordinator.errors import AnalysisError, JournalError, NetError
from coordinator.net import PetriNet, PlaceKind
from services.errors import PetrobotError

if TYPE_CHECKING:
    from coordinator.analysis.simulate import Delay

__all__ = ["add_parser", "render", "report", "run"]


def add_parser(subparsers: Any) -> None:
    """Register ``gspn`` on the ``petrobot`` sub-command parser."""
    parser = subparsers.add_parser(
        "gspn",
        help="quantitative analysis: GSPN view, CTMC, throughputs, bottlenecks, task time and reliability",
        description=(
            "Turn a task net into its generalized stochastic Petri net (section 2 of the paper: each "
            "primitive-task place gets an exponential delay with the mean measured in the journal or its "
            "a-priori mean_time_s; its normal and error exits become a random switch with the measured or "
            "a-priori reliability; external events become exponential transitions) and solve it: tangible "
            "reachability graph with vanishing markings eliminated, CTMC steady state, mean tokens and "
            "probability of a token per place, throughput per transition, utilisation and bottlenecks, and "
            "for nets that terminate the mean time to absorption (task execution time, s) and the "
            "probability of each final marking. A net that is already a GSPN (no primitive-task place, no "
            "event) is solved as it is. Exit status 0 on success, 2 on an unreadable net or journal, 1 if "
            "the analysis fails (state limit, timeless trap)."),
    )
    parser.add_argument("net", metavar="NET", help="net file (.toml, .pnml or .xml)")
    options.add_journal(parser, help="SQLite journal of real runs: mean times and reliabilities of primitive tasks")
    options.add_run(parser)
    options.add_ext_rate(parser, help="rate (1/s) of external event ext:TOPIC (default 1/s, with a warning); "
                                      "repeatable")
    parser.add_argument("--max-states", type=int, default=2_000_000, metavar="N",
                        help="stop with an error past N reachable markings (default 2,000,000)")
    parser.add_argument("--method", choices=["auto", "dense", "direct", "bicgstab"], default="auto",
                        help="steady-state solver: direct (SuperLU), bicgstab (iterative), dense (numpy), or "
                             "auto (direct up to 2,000 tangible markings); default auto")
    parser.add_argument("--write-gspn", metavar="FILE",
                        help="also write the GSPN view as a TOML net file, to inspect or edit")
    parser.add_argument("--simulate", type=int, default=0, metavar="RUNS",
                        help="also simulate the GSPN: RUNS independent runs to the end for a net that "
                             "terminates, else RUNS batches of 100 s after a 100 s warm-up; primitive tasks "
                             "take their durations from the journal's samples when --journal is given "
                             "(exponential otherwise); 95%% confidence intervals")
    options.add_seed(parser, help="seed of the simulation (default 0)")
    options.add_json(parser)
    # reward measures (docs/gspn.md, "Measures"): self-contained, kept together
    parser.add_argument("--measure", action="append", default=[], metavar="MEASURE",
                        help="a reward measure, repeatable: 'P{#p1 == 1 and #p3 == 1}' (long-run probability "
                             "of a condition), 'E{#p1 + #p2}' (long-run expected value), 'X{t3}' (throughput of "
                             "a transition, 1/s); expressions use #place, numbers, + - * /, min/max, "
                             "comparisons, and/or/not, parentheses")
    parser.add_argument("--markings", action="store_true",
                        help="also give the long-run probability of every tangible marking (most probable first)")


def _is_interpreted(net: PetriNet) -> bool:
    return any(p.kind is PlaceKind.PRIMITIVE_TASK for p in net.places) or any(t.events for t in net.transitions)


def report(args: argparse.Namespace, damaged: list[str] | None = None) -> dict[str, Any]:
    """Compute the ``gspn`` report as a JSON-ready dict (raises PetrobotError subclasses); the
    journal's damaged records, left out, are added to ``damaged`` when given."""
    from coordinator.analysis.gspn import analyse
    from coordinator.analysis.ptimed import empirical_delays, task_stats, to_gspn
    from coordinator.journal import read_results
    from coordinator.netfile import dump_net, load_any

    net = load_any(args.net, interpreted=False)
    warnings: list[str] = []
    sources: dict[str, str] = {}
    delays: dict[str, Delay] = {}
    if _is_interpreted(net):
        records = read_results(args.journal, args.run, damaged) if args.journal else []
        stats = task_stats(records)
        model = to_gspn(net, stats=stats, ext_rates=parse_pairs(args.ext_rate, "--ext-rate"))
        gspn, warnings, sources = model.net, model.warnings, model.sources
        delays = empirical_delays(model, stats)
    else:
        gspn = net
    if args.write_gspn:
        with open(args.write_gspn, "w", encoding="utf-8") as fh:
            fh.write(dump_net(gspn))
    result = analyse(gspn, method=args.method, max_states=args.max_states,
                     measures=getattr(args, "measure", None) or (), markings=bool(getattr(args, "markings", False)))
    rep = {"net": net.name, **result.to_json(), "warnings": warnings, "sources": sources}
    if args.simulate > 0:
        rep["simulation"] = _simulate(gspn, delays, result.terminates, args.simulate, args.seed)
    return rep


def _simulate(net: PetriNet, delays: dict[str, Delay], terminates: bool, runs: int, seed: int) -> dict[str, Any]:
    """Simulation estimates (mean and 95 % half-width) beside the CTMC figures."""
    from coordinator.analysis.simulate import simulate_absorption, simulate_steady

    laws = {tid: d.kind for tid, d in delays.items()}
    if terminates:
        est = simulate_absorption(net, delays, seed=seed, replications=max(2, runs))
        return {
            "replications": est.replications, "delays": laws,
            "mean_time_to_absorption": est.mean_time_to_absorption.to_json(),
            "absorption": [{"marking": dict(k), **v.to_json()} for k, v in est.absorption.items()],
        }
    steady = simulate_steady(net, delays, seed=seed, batches=max(2, runs))
    return {
        "batches": steady.batches, "delays": laws,
        "mean_tokens": {p: e.to_json() for p, e in steady.mean_tokens.items()},
        "throughput": {t: e.to_json() for t, e in steady.throughput.items()},
    }


def render(rep: dict[str, Any]) -> str:
    """Return the readable text of a :func:`report` dict."""
    lines = [(f"net {rep['net']!r}: {rep['tangible_markings']:,} tangible and {rep['vanishing_markings']:,} "
              f"vanishing markings; steady state by {rep['method']}, residual {rep['residual']:.1e}")]
    size = rep.get("ctmc") or {}
    if size:
        lines.append(f"CTMC: {size['tangible_states']:,} states, {size['arcs']:,} arcs")
    if rep["terminates"]:
        lines.append(f"the net terminates: mean time to absorption {rep['mean_time_to_absorption']:.6g} s")
        for a in sorted(rep["absorption"], key=lambda a: -a["probability"])[:15]:
            marking = ", ".join(f"{p}:{n}" for p, n in a["marking"].items()) or "empty"
            lines.append(f"  {a['probability']:.6f}  {{{marking}}}")
        if len(rep["absorption"]) > 15:
            lines.append(f"  ... {len(rep['absorption']) - 15} more final markings (see --json)")
    elif rep["absorption"]:
        lines.append(f"the chain is reducible: mean time to reach a closed class {rep['mean_time_to_absorption']:.6g} s")
    lines += ["", f"{'place':28} {'mean tokens':>12} {'P(nonempty)':>12}"]
    for p, v in rep["mean_tokens"].items():
        lines.append(f"{p:28} {v:12.6g} {rep['probability_nonempty'][p]:12.6g}")
    key = "expected_firings" if rep["terminates"] else "throughput"
    title = "expected firings" if rep["terminates"] else "throughput 1/s"
    lines += ["", f"{'transition':28} {title:>16} {'utilisation':>12}"]
    for t, v in rep[key].items():
        u = rep["utilisation"].get(t)
        lines.append(f"{t:28} {v:16.6g} {'' if u is None else f'{u:12.6g}'}")
    lines += ["", "bottlenecks (" + ("share of the task time each timed transition is enabled" if rep["terminates"]
                                      else "utilisation of finite-server timed transitions") + ")"]
    for b in rep["bottlenecks"][:10]:
        score = b.get("share", b.get("utilisation"))
        lines.append(f"  {b['transition']:28} {score:.4f}")
    if rep.get("measures"):
        lines += ["", "measures (long run" + (", and until absorption" if any("until_absorption" in m
                                                                             for m in rep["measures"]) else "") + ")"]
        for m in rep["measures"]:
            extra = f"   until absorption {m['until_absorption']:.6g}" if "until_absorption" in m else ""
            lines.append(f"  {m['measure']:40} {m['value']:.6g}{extra}")
    if rep.get("marking_probabilities") is not None:
        probs = rep["marking_probabilities"]
        lines += ["", f"marking probabilities ({len(probs):,} tangible markings, most probable first)"]
        for entry in probs[:20]:
            marking = ", ".join(f"{p}:{n}" for p, n in entry["marking"].items()) or "empty"
            lines.append(f"  {entry['probability']:.6g}  {{{marking}}}")
        if len(probs) > 20:
            lines.append(f"  ... {len(probs) - 20:,} more (see --json)")
    sim = rep.get("simulation")
    if sim:
        laws = ", ".join(f"{t}: {k}" for t, k in sim["delays"].items()) or "all exponential"
        lines += ["", f"simulation ({laws}; 95% intervals)"]
        if "mean_time_to_absorption" in sim:
            m = sim["mean_time_to_absorption"]
            lines.append(f"  mean time to absorption {m['mean']:.6g} ± {m['half_width']:.2g} s "
                         f"over {sim['replications']} runs")
            for a in sorted(sim["absorption"], key=lambda a: -a["mean"])[:10]:
                marking = ", ".join(f"{p}:{n}" for p, n in a["marking"].items()) or "empty"
                lines.append(f"  {a['mean']:.4f} ± {a['half_width']:.2g}  {{{marking}}}")
        else:
            for t, e in sim["throughput"].items():
                lines.append(f"  throughput {t:24} {e['mean']:.6g} ± {e['half_width']:.2g} /s")
    for w in rep["warnings"]:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the report; 0 on success, 2 on an unreadable net or journal, 1 if the analysis fails."""
    from coordinator.analysis.expr import ExprError

    damaged: list[str] = []
    try:
        rep = report(args, damaged)
    except (NetError, JournalError, OSError) as exc:
        print(f"petrobot gspn: {exc}", file=sys.stderr)
        return 2
    except ExprError as exc:
        print(f"petrobot gspn: bad --measure: {exc}", file=sys.stderr)
        return 2
    except (AnalysisError, PetrobotError) as exc:
        print(f"petrobot gspn: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(rep, indent=2) if args.json else render(rep))
    return options.report_damage("petrobot gspn", damaged)
