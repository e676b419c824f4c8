"""Discrete-event simulation of a GSPN with general delays (pure: randomness from a seeded generator).

Semantics are those of :mod:`coordinator.analysis.gspn` (Ajmone Marsan et al., *Modelling with
GSPNs*, 1995) extended to general delays under the *race policy with enabling memory*: every timed
transition runs ``min(d, k)`` servers (``d`` its enabling degree, k its server count, ``d`` for
infinite-server semantics); a server starting draws its delay from the transition's distribution;
the earliest server to finish fires its transition; a server that loses its enabling is discarded.
With exponential delays this is exactly the CTMC of the GSPN. Immediate transitions fire in zero
time, the highest priority first, among equals at random in proportion to their weights.

A marking-dependent rate (``rate_expr``) runs one exponential clock whose rate is the expression's
value in the current marking; the clock is drawn again after every event (exact, since the
exponential law is memoryless), and a value of 0 stops it. A marking-dependent weight is evaluated
in the marking where the switch happens. Reset arcs empty their places when their transition fires.
A delay given in ``delays`` for a transition with a rate expression replaces the expression (one
server).

Estimates come with Student-t confidence intervals: batch means over one long run after a warm-up
for long-run measures, independent replications for terminating nets (A. M. Law, *Simulation
Modeling and Analysis*, 5th ed., McGraw-Hill, 2015, ch. 9).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from coordinator.errors import AnalysisError
from coordinator.expr import scalar
from coordinator.net import PetriNet, TransitionKind

__all__ = [
    "AbsorptionEstimates",
    "Delay",
    "Estimate",
    "SteadyEstimates",
    "simulate_absorption",
    "simulate_steady",
]

#: Immediate firings in a row after which the simulator reports a timeless trap.
MAX_IMMEDIATE_CHAIN = 100_000


@dataclass(frozen=True, slots=True)
class Delay:
    """A firing-delay distribution (seconds).

    Attributes:
        kind: ``"exponential"`` (parameter ``rate`` in 1/s), ``"deterministic"`` (``value`` s) or
            ``"empirical"`` (resampled uniformly from ``samples``, s).
        rate: rate of the exponential law.
        value: constant delay.
        samples: observed durations.
    """

    kind: str
    rate: float = 0.0
    value: float = 0.0
    samples: tuple[float, ...] = ()

    @classmethod
    def exponential(cls, rate: float) -> Delay:
        """Exponential delay of ``rate`` (1/s, > 0)."""
        if not rate > 0:
            raise AnalysisError(f"exponential delay needs a rate > 0, got {rate}")
        return cls("exponential", rate=rate)

    @classmethod
    def deterministic(cls, value: float) -> Delay:
        """Constant delay of ``value`` seconds (>= 0)."""
        if value < 0:
            raise AnalysisError(f"deterministic delay must be >= 0 s, got {value}")
        return cls("deterministic", value=value)

    @classmethod
    def empirical(cls, samples: Sequence[float]) -> Delay:
        """Delay resampled from observed durations (seconds, at least one, all >= 0)."""
        if not samples or min(samples) < 0:
            raise AnalysisError("empirical delay needs at least one non-negative sample")
        return cls("empirical", samples=tuple(float(s) for s in samples))

    @property
    def mean(self) -> float:
        """Mean delay in seconds."""
        if self.kind == "exponential":
            return 1.0 / self.rate
        if self.kind == "deterministic":
            return self.value
        return float(np.mean(self.samples))

    def sample(self, rng: np.random.Generator) -> float:
        """Draw one delay (s)."""
        if self.kind == "exponential":
            return float(rng.exponential(1.0 / self.rate))
        if self.kind == "deterministic":
            return self.value
        return self.samples[int(rng.integers(len(self.samples)))]


@dataclass(frozen=True, slots=True)
class Estimate:
    """A point estimate with the half-width of its confidence interval (same unit)."""

    mean: float
    half_width: float

    def contains(self, value: float) -> bool:
        """True when ``value`` lies in the interval."""
        return abs(value - self.mean) <= self.half_width

    def to_json(self) -> dict[str, float]:
        """Return ``{"mean": ..., "half_width": ...}``."""
        return {"mean": self.mean, "half_width": self.half_width}


@dataclass(frozen=True)
class SteadyEstimates:
    """Long-run estimates by batch means.

    Attributes:
        mean_tokens: per place.
        probability_nonempty: per place.
        throughput: per transition, firings per second.
        batches: number of batches; confidence: level of the intervals.
    """

    mean_tokens: dict[str, Estimate]
    probability_nonempty: dict[str, Estimate]
    throughput: dict[str, Estimate]
    batches: int
    confidence: float


@dataclass(frozen=True)
class AbsorptionEstimates:
    """Estimates from independent runs to a dead marking.

    Attributes:
        mean_time_to_absorption: seconds.
        absorption: probability of each dead marking, keyed by ``tuple(sorted(marking.items()))``.
        replications: number of runs; confidence: level of the intervals.
    """

    mean_time_to_absorption: Estimate
    absorption: dict[tuple[tuple[str, int], ...], Estimate] = field(default_factory=dict)
    replications: int = 0
    confidence: float = 0.95


class _Sim:
    """One simulation run: marking, server clocks, statistics accumulators."""

    def __init__(self, net: PetriNet, delays: Mapping[str, Delay] | None, rng: np.random.Generator) -> None:
        self.net = net
        self.rng = rng
        pre, inh, inc = np.asarray(net.pre), np.asarray(net.inhibitor), np.asarray(net.incidence)
        post, reset = np.asarray(net.post), np.asarray(net.reset)
        n_t = len(net.transitions)
        self.inputs = [[(int(p), int(pre[p, t])) for p in np.flatnonzero(pre[:, t])] for t in range(n_t)]
        self.inhib = [[(int(p), int(inh[p, t])) for p in np.flatnonzero(inh[:, t])] for t in range(n_t)]
        self.delta = [[(int(p), int(inc[p, t])) for p in np.flatnonzero(inc[:, t]) if not reset[p, t]]
                      for t in range(n_t)]
        self.resets = [[(int(p), int(post[p, t])) for p in np.flatnonzero(reset[:, t])] for t in range(n_t)]
        self.timed = [t.kind is TransitionKind.EXPONENTIAL for t in net.transitions]
        self.servers = [t.servers for t in net.transitions]
        self.priority = [t.priority for t in net.transitions]
        self.weight = [t.weight for t in net.transitions]
        index = net.place_index.__getitem__
        self.weight_fn = {j: scalar(t.weight_tree, index) for j, t in enumerate(net.transitions)
                          if t.weight_tree is not None}
        delays = dict(delays or {})
        self.rate_fn = {j: scalar(t.rate_tree, index) for j, t in enumerate(net.transitions)
                        if t.rate_tree is not None and t.id not in delays}
        self.delay: list[Delay | None] = []
        for t in net.transitions:
            if t.kind is TransitionKind.EXPONENTIAL and t.id in delays:
                self.delay.append(delays[t.id])
            elif t.kind is TransitionKind.EXPONENTIAL and t.rate_expr is None:
                self.delay.append(Delay.exponential(float(t.rate or 0.0)))
            else:
                self.delay.append(None)
        self.marking = [int(v) for v in net.initial_vector]
        self.clocks: list[list[float]] = [[] for _ in range(n_t)]
        self.heap: list[tuple[float, int, int]] = []
        self.seq = 0
        self.now = 0.0

    def degree(self, t: int) -> int:
        m = self.marking
        for p, w in self.inhib[t]:
            if m[p] >= w:
                return 0
        deg = 1 << 30
        for p, w in self.inputs[t]:
            deg = min(deg, m[p] // w)
            if deg == 0:
                return 0
        return 1 if deg == 1 << 30 else deg

    def fire(self, t: int) -> None:
        for p, c in self.delta[t]:
            self.marking[p] += c
        for p, after in self.resets[t]:
            self.marking[p] = after

    def value(self, t: int, what: str) -> float:
        """The rate or weight expression of transition t in the current marking, checked."""
        fn = self.rate_fn[t] if what == "rate" else self.weight_fn[t]
        v = float(fn(self.marking))
        if not math.isfinite(v) or v < 0 or (what == "weight" and v == 0):
            need = "finite and >= 0" if what == "rate" else "finite and > 0"
            raise AnalysisError(f"the {what} of transition {self.net.transitions[t].id!r} is {v:g} in marking "
                                f"{self.net.marking(self.marking).to_dict()}, where the transition is enabled; "
                                f"a {what} expression must be {need} there")
        return v

    def settle(self, fired: list[int]) -> bool:
        """Fire immediate transitions until the marking is tangible; False if it is dead."""
        for _ in range(MAX_IMMEDIATE_CHAIN):
            best, cands = None, []
            for t, timed in enumerate(self.timed):
                if timed or self.degree(t) == 0:
                    continue
                if best is None or self.priority[t] > best:
                    best, cands = self.priority[t], [t]
                elif self.priority[t] == best:
                    cands.append(t)
            if not cands:
                return self.schedule()
            w = np.array([self.value(t, "weight") if t in self.weight_fn else self.weight[t] for t in cands])
            pick = cands[int(self.rng.choice(len(cands), p=w / w.sum()))] if len(cands) > 1 else cands[0]
            self.fire(pick)
            fired.append(pick)
        raise AnalysisError(
            f"timeless trap: {MAX_IMMEDIATE_CHAIN} immediate firings in a row at t = {self.now:.6g} s "
            f"in marking {self.net.marking(self.marking).to_dict()}"
        )

    def schedule(self) -> bool:
        """Start or discard servers so that each timed transition runs min(d, k) of them."""
        active = False
        for t, timed in enumerate(self.timed):
            if not timed:
                continue
            d = self.degree(t)
            clocks = self.clocks[t]
            if t in self.rate_fn:  # one memoryless clock, drawn again at the current rate
                rate = self.value(t, "rate") if d else 0.0
                clocks.clear()
                if rate > 0:
                    when = self.now + float(self.rng.exponential(1.0 / rate))
                    clocks.append(when)
                    heapq.heappush(self.heap, (when, self.seq, t))
                    self.seq += 1
                    active = True
                continue
            k = self.servers[t]
            want = d if k is None else min(d, k)
            while len(clocks) > want:
                clocks.remove(max(clocks))
            while len(clocks) < want:
                delay = self.delay[t]
                assert delay is not None
                when = self.now + delay.sample(self.rng)
                clocks.append(when)
                heapq.heappush(self.heap, (when, self.seq, t))
                self.seq += 1
            active = active or want > 0
        return active

    def next_event(self) -> tuple[float, int]:
        """Pop the earliest live server: (time, transition)."""
        while self.heap:
            when, _, t = heapq.heappop(self.heap)
            if when in self.clocks[t]:
                self.clocks[t].remove(when)
                return when, t
        raise AnalysisError("internal error: no live server in a marking that is not dead")


def _ci(values: np.ndarray, confidence: float) -> Estimate:
    n = values.size
    mean = float(values.mean())
    if n < 2:
        return Estimate(mean, math.inf)
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1) * values.std(ddof=1) / math.sqrt(n))
    return Estimate(mean, half)


def simulate_steady(
    net: PetriNet,
    delays: Mapping[str, Delay] | None = None,
    *,
    seed: int = 0,
    batch_time: float = 100.0,
    batches: int = 30,
    warmup: float = 100.0,
    confidence: float = 0.95,
) -> SteadyEstimates:
    """Estimate long-run measures by batch means over one run.

    Args:
        net: the GSPN; its exponential transitions use ``delays[tid]`` when given, else their rate.
        delays: delay law per timed transition id.
        seed: seed of :func:`numpy.random.default_rng`.
        batch_time: simulated seconds per batch.
        batches: number of batches (>= 2).
        warmup: simulated seconds discarded first.
        confidence: level of the intervals, e.g. 0.95.

    Returns:
        :class:`SteadyEstimates`.

    Raises:
        AnalysisError: on a timeless trap, or if the net dies (use :func:`simulate_absorption`).
    """
    sim = _Sim(net, delays, np.random.default_rng(seed))
    n_p, n_t = len(net.places), len(net.transitions)
    tokens = np.zeros((batches, n_p))
    busy = np.zeros((batches, n_p))
    counts = np.zeros((batches, n_t))
    fired: list[int] = []
    if not sim.settle(fired):
        raise AnalysisError("the net reaches a dead marking: use simulate_absorption")
    end = warmup + batch_time * batches
    while sim.now < end:
        when, t = sim.next_event()
        when = min(when, end)
        # Accumulate the marking held over [now, when), split across batch boundaries.
        start = sim.now
        m = np.array(sim.marking, dtype=float)
        while start < when:
            b = int((start - warmup) // batch_time) if start >= warmup else -1
            stop = min(when, warmup + (b + 1) * batch_time) if b >= 0 else min(when, warmup)
            if b >= 0:
                tokens[b] += m * (stop - start)
                busy[b] += (m > 0) * (stop - start)
            start = stop
        sim.now = when
        if when >= end:
            break
        sim.fire(t)
        fired.clear()
        fired.append(t)
        alive = sim.settle(fired)
        if sim.now >= warmup:
            b = min(int((sim.now - warmup) // batch_time), batches - 1)
            for f in fired:
                counts[b, f] += 1
        if not alive:
            raise AnalysisError("the net reaches a dead marking: use simulate_absorption")
    places = [p.id for p in net.places]
    tids = [t.id for t in net.transitions]
    return SteadyEstimates(
        mean_tokens={p: _ci(tokens[:, i] / batch_time, confidence) for i, p in enumerate(places)},
        probability_nonempty={p: _ci(busy[:, i] / batch_time, confidence) for i, p in enumerate(places)},
        throughput={t: _ci(counts[:, j] / batch_time, confidence) for j, t in enumerate(tids)},
        batches=batches, confidence=confidence,
    )


def simulate_absorption(
    net: PetriNet,
    delays: Mapping[str, Delay] | None = None,
    *,
    seed: int = 0,
    replications: int = 1000,
    max_events: int = 1_000_000,
    confidence: float = 0.95,
) -> AbsorptionEstimates:
    """Estimate the time to a dead marking and the probability of each, by independent runs.

    Args:
        net: the GSPN (it should terminate).
        delays: delay law per timed transition id (default: exponential at the net's rate).
        seed: seed of :func:`numpy.random.default_rng`.
        replications: number of runs (>= 2).
        max_events: timed firings allowed per run.
        confidence: level of the intervals.

    Returns:
        :class:`AbsorptionEstimates`.

    Raises:
        AnalysisError: if a run exceeds ``max_events`` (the net may not terminate) or on a
            timeless trap.
    """
    rng = np.random.default_rng(seed)
    times = np.zeros(replications)
    ends: dict[tuple[tuple[str, int], ...], np.ndarray] = {}
    fired: list[int] = []
    for r in range(replications):
        sim = _Sim(net, delays, rng)
        alive = sim.settle(fired)
        events = 0
        while alive:
            events += 1
            if events > max_events:
                raise AnalysisError(f"a run exceeded {max_events} timed firings: does the net terminate?")
            when, t = sim.next_event()
            sim.now = when
            sim.fire(t)
            alive = sim.settle(fired)
        times[r] = sim.now
        key = tuple(sorted(sim.net.marking(sim.marking).to_dict().items()))
        ends.setdefault(key, np.zeros(replications))[r] = 1.0
    return AbsorptionEstimates(
        mean_time_to_absorption=_ci(times, confidence),
        absorption={k: _ci(v, confidence) for k, v in ends.items()},
        replications=replications, confidence=confidence,
    )

