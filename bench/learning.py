"""Benchmark: learning the J-optimal primitive action online (paper section 4).

For synthetic primitive tasks whose actions have known reliability R and cost C (so the J-optimal
action, J = 1 − R + ρ·C, is known), run each learning scheme on many seeds until one action's
probability reaches 0.95 (or a trial budget runs out), and report:

* ``correct_fraction``: runs whose converged action is the J-optimal one;
* ``median_trials_to_converge`` / ``p90_trials_to_converge``: trials until convergence (runs that did
  not converge within the budget count as the budget, a lower bound);
* ``mean_excess_j``: mean of J(chosen) − J* over the first ``--horizon`` trials (default 1000; the
  run goes on past convergence up to the horizon): the price of learning, on equal terms for all.

Baseline in the same run, on the same seeds: *uniform explore-then-commit*, which draws actions
uniformly at random for exactly as many trials as pursuit needed on that seed and then commits to
the action with the lowest empirical J, which it runs for the rest of the horizon. Ratios compare
the schemes with it and with each other.

Usage::

    python bench/learning.py --seeds 200 --seed 1 [--trials 20000] [--horizon 1000] [--json] [--sweep]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from coordinator.learning import DEFAULT_RATES, make_learner, task_seed
from coordinator.performance import cost_function, rho_for

THRESHOLD = 0.95
#: (label, scheme, extra config, rates) of the --sweep runs.
SWEEPS: tuple[tuple[str, str, dict[str, Any], tuple[float, ...]], ...] = (
    ("pursuit", "pursuit", {}, (0.005, 0.01, 0.02, 0.05)),
    ("pursuit_mean", "pursuit", {"estimator": "mean"}, (0.005, 0.01, 0.02)),
    ("lri", "lri", {}, (0.005, 0.01, 0.02, 0.05)),
)


@dataclass(frozen=True)
class ActionSet:
    """A synthetic primitive task: actions with known R and mean cost C."""

    name: str
    description: str
    reliability: tuple[float, ...]
    cost: tuple[float, ...]
    measured: bool = False  # costs are reported as noisy measurements, not given a priori

    @property
    def actions(self) -> list[str]:
        return [f"a{i}" for i in range(len(self.reliability))]

    @property
    def j(self) -> np.ndarray:
        rho = rho_for(self.cost)
        return np.array([cost_function(r, c, rho) for r, c in zip(self.reliability, self.cost)])

    @property
    def optimal(self) -> int:
        return int(np.argmin(self.j))

    @property
    def gap(self) -> float:
        js = np.sort(self.j)
        return float(js[1] - js[0])


ACTION_SETS = (
    ActionSet("clear", "3 actions, equal cost, R 0.9 / 0.6 / 0.5", (0.9, 0.6, 0.5), (1.0, 1.0, 1.0)),
    ActionSet("frames", "average 1/2/4/8 frames: R rises with C (paper sec. 3)",
              (0.70, 0.88, 0.93, 0.96), (1.0, 2.0, 4.0, 8.0)),
    ActionSet("cheap_wins", "the less reliable, cheaper action is J-optimal",
              (0.95, 0.80), (4.0, 3.0)),
    ActionSet("close", "2 actions, equal cost, R 0.80 vs 0.75", (0.80, 0.75), (1.0, 1.0)),
    ActionSet("measured", "costs measured (gamma noise, CV 0.5), not given a priori",
              (0.70, 0.90, 0.95), (0.02, 0.05, 0.08), measured=True),
    ActionSet("many", "6 actions, equal cost, R 0.85 ... 0.60", (0.85, 0.80, 0.75, 0.70, 0.65, 0.60),
              (1.0,) * 6),
)


def _env(seed: int, set_index: int, run: int) -> np.random.Generator:
    return np.random.default_rng([seed, set_index, run, 7])


def _outcome(env: np.random.Generator, aset: ActionSet, i: int) -> tuple[str, float]:
    status = "success" if env.random() < aset.reliability[i] else "failure"
    mean = aset.cost[i]
    cost = float(env.gamma(4.0, mean / 4.0)) if aset.measured else mean
    return status, cost


def run_scheme(aset: ActionSet, set_index: int, scheme: str, rate: float, seed: int, run: int,
               budget: int, horizon: int, extra: dict[str, Any] | None = None) -> tuple[int | None, int, float]:
    """One learning run.

    Returns (action index at the first convergence or None, trials to it, mean excess J over the
    first ``horizon`` trials).
    """
    config: dict[str, Any] = {"scheme": scheme, "rate": rate, **(extra or {})}
    costs = None if aset.measured else dict(zip(aset.actions, aset.cost))
    auto = make_learner(config, aset.actions, costs, task_seed(seed, f"{aset.name}/{run}"))
    env = _env(seed, set_index, run)
    js = aset.j
    best = float(js.min())
    excess = 0.0
    index = {a: i for i, a in enumerate(aset.actions)}
    first: tuple[int, int] | None = None
    for t in range(1, max(budget, horizon) + 1):
        i = index[auto.choose()]
        if t <= horizon:
            excess += js[i] - best
        status, cost = _outcome(env, aset, i)
        auto.update(aset.actions[i], status, cost)
        if first is None and t <= budget:
            done = auto.converged(THRESHOLD)
            if done is not None:
                first = (index[done], t)
        if t >= horizon and (first is not None or t >= budget):
            break
    if first is None:
        return None, budget, excess / horizon
    return first[0], first[1], excess / horizon


def run_uniform_commit(aset: ActionSet, set_index: int, seed: int, run: int, trials: int,
                       horizon: int) -> tuple[int, float]:
    """Baseline: uniform random choice for ``trials`` trials, then commit to the lowest empirical J.

    Returns (committed action index, mean excess J over the first ``horizon`` trials).
    """
    env = np.random.default_rng([seed, set_index, run, 11])
    r = len(aset.actions)
    n = np.zeros(r)
    s = np.zeros(r)
    c = np.zeros(r)
    js = aset.j
    excess = 0.0
    for t in range(1, trials + 1):
        i = int(env.integers(r))
        if t <= horizon:
            excess += js[i] - js.min()
        status, cost = _outcome(env, aset, i)
        n[i] += 1
        s[i] += status == "success"
        c[i] += cost
    tried = n > 0
    mean_c = np.where(tried, c / np.maximum(n, 1), 0.0)
    rho = rho_for(mean_c[tried]) if aset.measured else rho_for(aset.cost)
    cost_used = mean_c if aset.measured else np.array(aset.cost)
    emp_j = np.where(tried, 1.0 - s / np.maximum(n, 1) + rho * cost_used, np.inf)
    chosen = int(np.argmin(emp_j))
    excess += max(0, horizon - trials) * (js[chosen] - js.min())
    return chosen, excess / horizon


def _summary(correct: list[bool], trials: list[int], excess: list[float], unconverged: int) -> dict[str, Any]:
    t = np.array(trials, dtype=float)
    return {
        "runs": len(correct),
        "correct_fraction": float(np.mean(correct)),
        "unconverged_fraction": unconverged / len(correct),
        "median_trials_to_converge": float(np.median(t)),
        "p90_trials_to_converge": float(np.percentile(t, 90)),
        "mean_excess_j": float(np.mean(excess)),
    }


def bench_scheme(scheme: str, rate: float, seeds: int, seed: int, budget: int, horizon: int,
                 extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one scheme at one rate over every action set and ``seeds`` runs each."""
    per_set: dict[str, Any] = {}
    all_c: list[bool] = []
    all_t: list[int] = []
    all_x: list[float] = []
    all_u = 0
    for k, aset in enumerate(ACTION_SETS):
        c: list[bool] = []
        t: list[int] = []
        x: list[float] = []
        u = 0
        for run in range(seeds):
            chosen, n, ex = run_scheme(aset, k, scheme, rate, seed, run, budget, horizon, extra)
            c.append(chosen == aset.optimal)
            t.append(n)
            x.append(ex)
            u += chosen is None
        per_set[aset.name] = {**_summary(c, t, x, u), "_trials": t}
        all_c += c
        all_t += t
        all_x += x
        all_u += u
    return {"rate": rate, **_summary(all_c, all_t, all_x, all_u), "sets": per_set}


def bench_baseline(pursuit: dict[str, Any], seeds: int, seed: int, horizon: int) -> dict[str, Any]:
    """Uniform explore-then-commit with, per run, the trial count pursuit needed on that run."""
    per_set: dict[str, Any] = {}
    all_c: list[bool] = []
    all_t: list[int] = []
    all_x: list[float] = []
    for k, aset in enumerate(ACTION_SETS):
        c: list[bool] = []
        t: list[int] = []
        x: list[float] = []
        for run in range(seeds):
            n = pursuit["sets"][aset.name]["_trials"][run]
            chosen, ex = run_uniform_commit(aset, k, seed, run, n, horizon)
            c.append(chosen == aset.optimal)
            t.append(n)
            x.append(ex)
        per_set[aset.name] = _summary(c, t, x, 0)
        all_c += c
        all_t += t
        all_x += x
    return {"rate": None, **_summary(all_c, all_t, all_x, 0), "sets": per_set}


def _ratio(a: float, b: float) -> float | None:
    return None if b == 0 else a / b


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=200, help="runs per action set and scheme (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="base seed of the whole bench (default 1)")
    parser.add_argument("--trials", type=int, default=20000,
                        help="trial budget of one run; runs not converged by then count as wrong")
    parser.add_argument("--horizon", type=int, default=1000,
                        help="trials over which the mean excess J is measured (default 1000)")
    parser.add_argument("--sweep", action="store_true",
                        help="also run every scheme at several learning rates (speed/accuracy trade-off)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of tables")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.trials < 1 or args.horizon < 1:
        parser.error("--seeds, --trials and --horizon must be positive")

    started = time.perf_counter()
    schemes: dict[str, Any] = {}
    for scheme in ("pursuit", "lri"):
        schemes[scheme] = bench_scheme(scheme, DEFAULT_RATES[scheme], args.seeds, args.seed, args.trials,
                                       args.horizon)
    schemes["uniform_commit"] = bench_baseline(schemes["pursuit"], args.seeds, args.seed, args.horizon)
    for res in schemes.values():
        for per in res["sets"].values():
            per.pop("_trials", None)
    p, lri, base = schemes["pursuit"], schemes["lri"], schemes["uniform_commit"]
    ratios = {
        "lri_over_pursuit_median_trials": _ratio(lri["median_trials_to_converge"], p["median_trials_to_converge"]),
        "lri_over_pursuit_excess_j": _ratio(lri["mean_excess_j"], p["mean_excess_j"]),
        "baseline_over_pursuit_excess_j": _ratio(base["mean_excess_j"], p["mean_excess_j"]),
        "pursuit_over_baseline_correct": _ratio(p["correct_fraction"], base["correct_fraction"]),
    }
    sweep: dict[str, list[dict[str, Any]]] = {}
    if args.sweep:
        for label, scheme, extra, rates in SWEEPS:
            sweep[label] = []
            for rate in rates:
                if not extra and rate == DEFAULT_RATES[scheme]:
                    res = dict(schemes[scheme])  # already measured above
                else:
                    res = bench_scheme(scheme, rate, args.seeds, args.seed, args.trials, args.horizon, extra)
                res.pop("sets")  # per-set detail only for the default rates
                sweep[label].append(res)
    out = {
        "seeds": args.seeds, "seed": args.seed, "trial_budget": args.trials, "horizon": args.horizon,
        "threshold": THRESHOLD,
        "action_sets": {a.name: {"description": a.description, "reliability": a.reliability,
                                 "cost": a.cost, "measured": a.measured,
                                 "j": [round(float(v), 4) for v in a.j], "optimal": a.actions[a.optimal],
                                 "gap": round(a.gap, 4)} for a in ACTION_SETS},
        "schemes": schemes, "ratios": ratios, "sweep": sweep,
        "seconds": round(time.perf_counter() - started, 2),
    }
    # Top-level shortcuts per scheme, as the issue asks.
    for name in ("pursuit", "lri", "uniform_commit"):
        out[name] = {k: schemes[name][k] for k in ("correct_fraction", "median_trials_to_converge")}
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"learning bench: {args.seeds} seeds per set, seed {args.seed}, budget {args.trials} trials, "
          f"threshold {THRESHOLD}, excess J over the first {args.horizon} trials")
    for a in ACTION_SETS:
        print(f"  set {a.name:10s} J* gap {a.gap:.3f}  optimal {a.actions[a.optimal]}  ({a.description})")
    header = f"{'scheme':16s}{'rate':>7s}{'set':>12s}{'correct':>9s}{'median N':>10s}{'p90 N':>9s}" \
             f"{'excess J':>10s}{'unconv':>8s}"
    print(header)
    for name, res in schemes.items():
        shown = "-" if res["rate"] is None else f"{res['rate']:g}"
        for set_name, r in [("ALL", res), *res["sets"].items()]:
            print(f"{name:16s}{shown:>7s}{set_name:>12s}{r['correct_fraction']:9.3f}"
                  f"{r['median_trials_to_converge']:10.0f}{r['p90_trials_to_converge']:9.0f}"
                  f"{r['mean_excess_j']:10.4f}{r['unconverged_fraction']:8.3f}")
    print("ratios:")
    for k, v in ratios.items():
        print(f"  {k:34s} {'n/a' if v is None else f'{v:.2f}'}")
    for scheme, rows in sweep.items():
        print(f"sweep {scheme}:")
        for r in rows:
            print(f"  rate {r['rate']:<7g} correct {r['correct_fraction']:.3f}  median N "
                  f"{r['median_trials_to_converge']:.0f}  p90 N {r['p90_trials_to_converge']:.0f}  "
                  f"excess J {r['mean_excess_j']:.4f}")
    print(f"({out['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
