"""The GSPN view of a task net: tangible CTMC and its measures (paper section 2, pure, no I/O).

Semantics and algorithms follow M. Ajmone Marsan, G. Balbo, G. Conte, S. Donatelli and
G. Franceschinis, *Modelling with Generalized Stochastic Petri Nets*, Wiley, 1995 (chs. 5–6):

* Exponential transitions fire after an exponential delay; with enabling degree
  ``d(M, t) = min_p floor(M(p) / W(p, t))`` the firing rate in marking M is
  ``rate(t) * min(d, k)`` for k-server semantics (k = 1: single server) and ``rate(t) * d`` for
  infinite-server semantics. A marking-dependent rate (``rate_expr``) is the expression's value in
  M, with no server multiplier (as GreatSPN's marking-dependent rates); it must be finite and ≥ 0
  in every reachable tangible marking that enables the transition, and 0 means the transition does
  not fire there (its edge is dropped, and so are the markings only such edges reach).
* In a *vanishing* marking (an immediate transition enabled) only the immediate transitions of the
  highest priority fire, transition *t* with probability ``w(t) / sum w`` (random switch); a
  marking-dependent weight (``weight_expr``) is evaluated in that marking and must be finite and
  > 0 there (:class:`AnalysisError` naming the transition and the marking otherwise).
* Reset arcs empty their places when their transition fires (:mod:`coordinator.net`); the
  reachability graph honours them, and nothing else here depends on them (they do not change
  enabling degrees).
* Vanishing markings are eliminated: with ``P_VV``, ``P_VT`` the switching probabilities among
  vanishing markings and into tangible ones, and ``R_TT``, ``R_TV`` the rates out of tangible
  markings, the tangible chain has rates ``R_TT + R_TV (I - P_VV)^-1 P_VT``. A set of vanishing
  markings that cannot reach a tangible marking is a *timeless trap*: :class:`AnalysisError`.
  Vanishing loops that can leave are solved exactly (sparse LU of ``I - P_VV``).
* Throughput of an exponential transition: ``sum_M pi(M) rate(M, t)``; of an immediate one: the
  expected number of visits to each vanishing marking per unit time,
  ``v = pi R_TV (I - P_VV)^-1``, times its switching probability.
* A net *terminates* when every bottom class of the tangible chain is one dead marking; then the
  mean time to absorption is the task execution time and the probability of each dead marking
  the probability of that ending (task reliability when the marking is the goal).
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import breadth_first_order, connected_components

from coordinator.analysis import ctmc
from coordinator.analysis.expr import Compiled, ExprError, bind, compile_expr
from coordinator.analysis.gspn_graph import GSPNGraph, explore_gspn
from coordinator.errors import AnalysisError
from coordinator.net import PetriNet, TransitionKind

__all__ = ["GSPNResult", "Measure", "TangibleChain", "analyse", "compile_measure", "enabling_degree",
           "parse_measure", "tangible_chain"]


def enabling_degree(net: PetriNet, states: np.ndarray, transitions: np.ndarray) -> np.ndarray:
    """Enabling degree of ``transitions[i]`` in marking ``states[i]``.

    Args:
        net: the net.
        states: markings, shape (E, |P|).
        transitions: transition indices, shape (E,).

    Returns:
        int64 array (E,): ``min_p floor(M(p) / W(p, t))`` over input places (a transition without
        input places has degree 1).
    """
    pre = np.asarray(net.pre)
    deg = np.ones(len(transitions), dtype=np.int64)
    for t in np.unique(transitions):
        inputs = np.flatnonzero(pre[:, t])
        if inputs.size == 0:
            continue
        sel = np.flatnonzero(transitions == t)
        d = states[sel][:, inputs] // pre[inputs, t][None, :]
        deg[sel] = d.min(axis=1)
    return deg


@dataclass(frozen=True)
class TangibleChain:
    """The CTMC on tangible markings of a GSPN, with what the measures need.

    Attributes:
        net: the GSPN.
        graph: the reachability graph (tangible and vanishing markings; without the edges whose
            marking-dependent rate is 0 and the markings only they reach).
        tangible: graph indices of the tangible markings, shape (n,); state *i* of ``q`` is
            ``graph.states[tangible[i]]``.
        q: generator (n, n) in 1/s.
        alpha: initial distribution over tangible markings, shape (n,).
        edge_value: per graph edge, the rate (1/s) for edges out of tangible markings and the
            switching probability for edges out of vanishing ones, shape (E,).
        r_tv: rates from tangible to vanishing markings, shape (n, v).
        p_vv: switching probabilities among vanishing markings, shape (v, v).
        v_index: position of each graph marking among the vanishing ones (−1 if tangible), (N,).
        t_index: position of each graph marking among the tangible ones (−1 if vanishing), (N,).
    """

    net: PetriNet
    graph: GSPNGraph
    tangible: np.ndarray
    q: sp.csr_matrix
    alpha: np.ndarray
    edge_value: np.ndarray
    r_tv: sp.csr_matrix
    p_vv: sp.csr_matrix
    v_index: np.ndarray
    t_index: np.ndarray

    @property
    def vanishing_count(self) -> int:
        """Number of vanishing markings."""
        return int(self.graph.vanishing.sum())

    def visits(self, flow_in: np.ndarray) -> np.ndarray:
        """Solve ``v (I - P_VV) = flow_in`` for the visit rates (or counts) of vanishing markings, (v,)."""
        if flow_in.size == 0:
            return flow_in
        a = sp.identity(flow_in.size, format="csc") - sp.csc_matrix(self.p_vv)
        return np.atleast_1d(spla.spsolve(sp.csc_matrix(a.T), flow_in))


def _expression_values(net: PetriNet, g: GSPNGraph, edges: np.ndarray, what: str) -> np.ndarray:
    """Values of the rate (``what == "rate"``) or weight expressions on ``edges`` (indices into the
    graph's edges, all of transitions that have such an expression), evaluated in each edge's
    source marking, as float64; raises on a value a rate or a weight may not take."""
    out = np.empty(edges.size)
    places = [p.id for p in net.places]
    trans = g.transition[edges]
    for j in np.unique(trans).tolist():
        t = net.transitions[j]
        text = t.rate_expr if what == "rate" else t.weight_expr
        tree = t.rate_tree if what == "rate" else t.weight_tree
        assert text is not None and tree is not None
        sel = edges[trans == j]
        values = np.asarray(bind(tree, text, places)(g.states[g.src[sel]]), dtype=np.float64)
        bad = ~np.isfinite(values) | (values < 0 if what == "rate" else values <= 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            need = "finite and >= 0" if what == "rate" else "finite and > 0"
            marking = net.marking(g.states[g.src[sel[k]]]).to_dict()
            raise AnalysisError(f"the {what} of transition {t.id!r} ({text}) is {values[k]:g} in marking {marking}, "
                                f"where the transition is enabled; a {what} expression must be {need} there")
        out[trans == j] = values
    return out


def _edge_values(net: PetriNet, g: GSPNGraph) -> np.ndarray:
    """Rates of edges out of tangible markings, switching probabilities out of vanishing ones.

    Raises:
        AnalysisError: a rate expression negative or not finite, or a weight expression not > 0 or
            not finite, where its transition is enabled.
    """
    rate = np.array([t.rate or 0.0 for t in net.transitions])
    weight = np.array([t.weight for t in net.transitions])
    servers = np.array([0 if t.servers is None else t.servers for t in net.transitions])
    rate_expr = np.array([t.rate_expr is not None for t in net.transitions], dtype=bool)
    weight_expr = np.array([t.weight_expr is not None for t in net.transitions], dtype=bool)
    out = np.empty(g.src.size)
    timed = ~g.vanishing[g.src]
    if timed.any():
        tt = g.transition[timed]
        deg = enabling_degree(net, g.states[g.src[timed]], tt)
        k = servers[tt]
        out[timed] = rate[tt] * np.where(k == 0, deg, np.minimum(deg, k))
        if rate_expr.any():
            sel = np.flatnonzero(timed & rate_expr[g.transition])
            if sel.size:
                out[sel] = _expression_values(net, g, sel, "rate")
    imm = ~timed
    if imm.any():
        w = weight[g.transition[imm]]
        if weight_expr.any():
            imm_edges = np.flatnonzero(imm)
            marked = weight_expr[g.transition[imm_edges]]
            if marked.any():
                w = w.copy()
                w[marked] = _expression_values(net, g, imm_edges[marked], "weight")
        total = np.bincount(g.src[imm], weights=w, minlength=g.states.shape[0])
        out[imm] = w / total[g.src[imm]]
    return out


def _prune(g: GSPNGraph, value: np.ndarray) -> tuple[GSPNGraph, np.ndarray]:
    """Drop the edges out of tangible markings whose rate is 0 (a marking-dependent rate that is 0
    there), then the markings no longer reachable from M0; return the graph and edge values kept."""
    keep = g.vanishing[g.src] | (value > 0)
    n = g.states.shape[0]
    adj = sp.csr_matrix((np.ones(int(keep.sum())), (g.src[keep], g.dst[keep])), shape=(n, n))
    reached = np.sort(breadth_first_order(adj, 0, directed=True, return_predecessors=False))
    new_index = np.full(n, -1, dtype=np.int64)
    new_index[reached] = np.arange(reached.size)
    keep &= new_index[g.src] >= 0
    graph = GSPNGraph(states=g.states[reached], src=new_index[g.src[keep]], dst=new_index[g.dst[keep]],
                      transition=g.transition[keep], vanishing=g.vanishing[reached])
    return graph, value[keep]


def _check_traps(g: GSPNGraph, v_index: np.ndarray, nv: int, net: PetriNet) -> None:
    """Raise if some vanishing marking cannot reach a tangible marking (a timeless trap)."""
    van_edges = g.vanishing[g.src]
    to_t = van_edges & ~g.vanishing[g.dst]
    to_v = van_edges & g.vanishing[g.dst]
    # Reverse graph on vanishing markings plus a source node nv linked to those that exit at once.
    rows = np.concatenate([v_index[g.dst[to_v]], np.full(int(to_t.sum()), nv)])
    cols = np.concatenate([v_index[g.src[to_v]], v_index[g.src[to_t]]])
    adj = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(nv + 1, nv + 1))
    reached = breadth_first_order(adj, nv, directed=True, return_predecessors=False)
    ok = np.zeros(nv + 1, dtype=bool)
    ok[reached] = True
    if not ok[:nv].all():
        bad = int(np.flatnonzero(~ok[:nv])[0])
        marking = net.marking(g.states[np.flatnonzero(g.vanishing)[bad]])
        raise AnalysisError(
            f"timeless trap: from vanishing marking {marking.to_dict()} immediate transitions fire "
            f"forever without reaching a tangible marking ({int((~ok[:nv]).sum())} vanishing markings "
            "are in such traps); give the loop an exit or make one of its transitions exponential"
        )


def _eliminate(p_vv: sp.csr_matrix, p_vt: sp.csr_matrix) -> sp.csr_matrix:
    """Return ``(I - P_VV)^-1 P_VT`` (v, n): exactly, by a finite series when the vanishing graph has
    no loop, else by sparse LU on the columns that are reachable."""
    nv = p_vv.shape[0]
    if nv == 0:
        return p_vt
    ncomp, _ = connected_components(p_vv, directed=True, connection="strong")
    if ncomp == nv and not p_vv.diagonal().any():
        total = p_vt.copy()
        term = p_vt
        for _ in range(nv + 1):
            term = sp.csr_matrix(p_vv @ term)
            if term.nnz == 0:
                return sp.csr_matrix(total)
            total = total + term
        raise AnalysisError("internal error: acyclic vanishing graph did not terminate")
    lu = spla.splu(sp.csc_matrix(sp.identity(nv) - p_vv))
    cols = np.unique(p_vt.tocoo().col)
    dense_rhs = p_vt[:, cols].toarray()
    block = 512
    parts = []
    for start in range(0, cols.size, block):
        sol = lu.solve(dense_rhs[:, start:start + block])
        sol[np.abs(sol) < 1e-15] = 0.0
        parts.append(sp.csr_matrix(sol))
    x = sp.hstack(parts).tocsr() if parts else sp.csr_matrix((nv, 0))
    expand = sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(cols.size, p_vt.shape[1]))
    return sp.csr_matrix(x @ expand)


def tangible_chain(net: PetriNet, *, graph: GSPNGraph | None = None, max_states: int = 5_000_000) -> TangibleChain:
    """Build the tangible CTMC of ``net`` (vanishing markings eliminated).

    Args:
        net: a net whose transitions carry GSPN attributes (kind, rate, servers, priority, weight).
        graph: a reachability graph from :func:`explore_gspn`, explored if omitted.
        max_states: limit on reachable markings (tangible + vanishing).

    Returns:
        :class:`TangibleChain`.

    Raises:
        AnalysisError: on a state limit, a timeless trap, no tangible marking, or a rate or weight
            expression with a value it may not take (see the module docstring).
    """
    g = graph if graph is not None else explore_gspn(net, max_states=max_states)
    n_all = g.states.shape[0]
    van = g.vanishing
    tangible = np.flatnonzero(~van)
    vanishing = np.flatnonzero(van)
    n, nv = tangible.size, vanishing.size
    if n == 0:
        raise AnalysisError(f"net {net.name!r} has no tangible marking: immediate transitions fire forever")
    t_index = np.full(n_all, -1, dtype=np.int64)
    t_index[tangible] = np.arange(n)
    v_index = np.full(n_all, -1, dtype=np.int64)
    v_index[vanishing] = np.arange(nv)
    if nv:
        _check_traps(g, v_index, nv, net)
    value = _edge_values(net, g)
    if not (value[~van[g.src]] > 0).all():
        g, value = _prune(g, value)
        n_all, van = g.states.shape[0], g.vanishing
        tangible, vanishing = np.flatnonzero(~van), np.flatnonzero(van)
        n, nv = tangible.size, vanishing.size
        t_index = np.full(n_all, -1, dtype=np.int64)
        t_index[tangible] = np.arange(n)
        v_index = np.full(n_all, -1, dtype=np.int64)
        v_index[vanishing] = np.arange(nv)
    sv, dv = van[g.src], van[g.dst]

    def block(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
        return sp.csr_matrix((value[mask], (rows[g.src[mask]], cols[g.dst[mask]])), shape=shape)

    r_tt = block(~sv & ~dv, t_index, t_index, (n, n))
    r_tv = block(~sv & dv, t_index, v_index, (n, nv))
    p_vt = block(sv & ~dv, v_index, t_index, (nv, n))
    p_vv = block(sv & dv, v_index, v_index, (nv, nv))
    x = _eliminate(p_vv, p_vt) if nv else sp.csr_matrix((0, n))
    rates = r_tt + (r_tv @ x if nv else 0)
    q = ctmc.generator(rates)
    alpha = np.zeros(n)
    if van[0]:
        alpha = np.asarray(x[v_index[0]].todense()).ravel()
        alpha /= alpha.sum()
    else:
        alpha[t_index[0]] = 1.0
    return TangibleChain(net, g, tangible, q, alpha, value, r_tv, p_vv, v_index, t_index)


@dataclass(frozen=True)
class GSPNResult:
    """Measures of a GSPN (all rates in 1/s, times in s).

    Attributes:
        tangible_markings: number of tangible markings.
        vanishing_markings: number of vanishing markings.
        terminates: True when every bottom class of the chain is one dead marking.
        mean_tokens: long-run mean token count per place.
        probability_nonempty: long-run probability that each place holds a token.
        throughput: long-run firings per second of each transition (0 for terminating nets).
        utilisation: per exponential transition, long-run probability that it is enabled (with a
            rate > 0, for a marking-dependent rate).
        busy_servers: per exponential transition of constant rate, long-run mean of
            ``min(degree, k)`` (a marking-dependent rate has no servers to count).
        bottlenecks: exponential transitions ranked (see :func:`analyse`), each with its score.
        residual: ``||pi Q||_inf`` of the long-run distribution.
        method: steady-state method used.
        mean_time_to_absorption: expected time to reach a bottom class (None if the initial
            marking is already in one).
        absorption: each bottom class with its probability; for a terminating net each is one
            dead marking ``{"marking": {...}, "probability": p}``.
        expected_firings: expected number of firings of each transition before absorption.
        time_enabled: expected time each exponential transition is enabled before absorption.
        ctmc: size of the tangible CTMC: ``{"tangible_states": n, "arcs": off-diagonal non-zeros of Q}``.
        measures: one entry per requested reward measure (:func:`parse_measure`): ``measure`` (as
            given), ``kind`` (P, E or X), ``value`` (long run), and for chains that reach a closed
            class from transient states ``until_absorption`` (expected time the condition holds, the
            expected time-integral of the expression, or the expected number of firings, before
            absorption).
        marking_probabilities: when requested, every tangible marking with its long-run probability,
            most probable first: ``{"marking": {...}, "probability": p}``; else None.
    """

    tangible_markings: int
    vanishing_markings: int
    terminates: bool
    mean_tokens: dict[str, float]
    probability_nonempty: dict[str, float]
    throughput: dict[str, float]
    utilisation: dict[str, float]
    busy_servers: dict[str, float]
    bottlenecks: list[dict[str, Any]]
    residual: float
    method: str
    mean_time_to_absorption: float | None = None
    absorption: list[dict[str, Any]] = field(default_factory=list)
    expected_firings: dict[str, float] = field(default_factory=dict)
    time_enabled: dict[str, float] = field(default_factory=dict)
    ctmc: dict[str, int] = field(default_factory=dict)
    measures: list[dict[str, Any]] = field(default_factory=list)
    marking_probabilities: list[dict[str, Any]] | None = None

    def to_json(self) -> dict[str, Any]:
        """Return a JSON-ready dict of every field (``marking_probabilities`` only when computed)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        if out["marking_probabilities"] is None:
            del out["marking_probabilities"]
        return out


_MEASURE = re.compile(r"\s*([PEX])\s*\{(.*)\}\s*$", re.DOTALL)


@dataclass(frozen=True)
class Measure:
    """A reward measure of a GSPN, as written on the command line.

    Attributes:
        text: the measure as given, e.g. ``P{#p1 == 1 and #p3 == 1}``.
        kind: ``P`` (probability of a condition), ``E`` (expected value of an expression) or ``X``
            (throughput of a transition).
        body: the expression, or the transition id for ``X``.
        offset: 0-based position of ``body`` in ``text`` (to report columns in the whole text).
    """

    text: str
    kind: str
    body: str
    offset: int


def parse_measure(text: str) -> Measure:
    """Split ``P{cond}``, ``E{expr}`` or ``X{transition}`` (definitions in docs/gspn.md).

    Raises:
        ExprError: when the text is none of the three forms (column of the problem).
    """
    m = _MEASURE.match(text)
    if m is None:
        lead = len(text) - len(text.lstrip())
        if lead < len(text) and text[lead] not in "PEX":
            raise ExprError("a measure starts with P{...} (probability), E{...} (expected value) or X{...} "
                            "(throughput)", lead + 1, text)
        raise ExprError("a measure is P{condition}, E{expression} or X{transition}: braces missing", lead + 2,
                        text)
    return Measure(text=text, kind=m.group(1), body=m.group(2), offset=m.start(2))


def compile_measure(measure: Measure | str, net: PetriNet) -> tuple[Measure, Compiled | int]:
    """Bind a measure to a net: the compiled condition or expression (over the places' columns), or
    the transition's index for ``X``.

    Raises:
        ExprError: syntax, type or name errors, with the column in the whole measure text.
    """
    meas = parse_measure(measure) if isinstance(measure, str) else measure
    if meas.kind == "X":
        tid = meas.body.strip()
        if tid not in net.transition_index:
            close = difflib.get_close_matches(tid, list(net.transition_index), n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            col = meas.offset + len(meas.body) - len(meas.body.lstrip()) + 1
            raise ExprError(f"unknown transition {tid!r}{hint}", col, meas.text)
        return meas, net.transition_index[tid]
    try:
        compiled = compile_expr(meas.body, [p.id for p in net.places], kind="bool" if meas.kind == "P" else "num")
    except ExprError as exc:
        raise ExprError(exc.message + (" (P{...} takes a condition)" if meas.kind == "P" and "expected" in exc.message
                                       else ""), exc.column + meas.offset, meas.text) from None
    return meas, compiled


def _per_transition(chain: TangibleChain, weight_t: np.ndarray, weight_v: np.ndarray) -> np.ndarray:
    """Sum ``edge_value * weight(src)`` per transition; weight_t over tangible, weight_v over vanishing."""
    g = chain.graph
    src_w = np.where(g.vanishing[g.src], weight_v[chain.v_index[g.src]] if weight_v.size else 0.0,
                     weight_t[chain.t_index[g.src]])
    return np.bincount(g.transition, weights=chain.edge_value * src_w, minlength=len(chain.net.transitions))


def analyse(net: PetriNet, *, chain: TangibleChain | None = None, method: str = "auto",
            max_states: int = 5_000_000, measures: Sequence[str | Measure] = (),
            markings: bool = False) -> GSPNResult:
    """Solve a GSPN and compute its measures.

    Bottleneck ranking: for a net that runs forever, exponential transitions with finitely many
    servers are ranked by utilisation ``E[min(d, k)] / k`` (the fraction of server capacity in use):
    a transition near 1 is saturated and bounds the throughput of everything that depends on it;
    infinite-server transitions are pure delays and never saturate, so they are left out, and so are
    transitions with a marking-dependent rate (no server count to saturate). For a net
    that terminates, transitions are ranked by the expected time they are enabled before the net
    stops, as a share of the mean time to absorption: where the task spends its time.

    Args:
        net: the GSPN.
        chain: a prebuilt :class:`TangibleChain` (built if omitted).
        method: steady-state method (see :func:`coordinator.analysis.ctmc.steady_state`).
        max_states: limit on reachable markings.
        measures: reward measures ``P{cond}``, ``E{expr}``, ``X{transition}`` (:func:`parse_measure`),
            compiled before anything is solved.
        markings: also list every tangible marking with its long-run probability.

    Returns:
        :class:`GSPNResult`.

    Raises:
        AnalysisError: see :func:`tangible_chain` and :func:`ctmc.steady_state`.
        ExprError: a measure does not parse, type-check or name a place or transition of the net.
    """
    bound = [compile_measure(m, net) for m in measures]
    chain = chain if chain is not None else tangible_chain(net, max_states=max_states)
    g, q = chain.graph, chain.q
    classes = ctmc.classify(q)
    steady = ctmc.long_run(q, chain.alpha, method=method) if not classes.irreducible else \
        ctmc.steady_state(q, method=method)
    pi = steady.pi
    tokens = g.states[chain.tangible].astype(float)
    places = [p.id for p in net.places]
    tids = [t.id for t in net.transitions]
    timed = np.array([t.kind is TransitionKind.EXPONENTIAL for t in net.transitions])
    constant = np.array([t.rate_expr is None for t in net.transitions])
    rate = np.array([t.rate or 1.0 for t in net.transitions])
    servers = [t.servers for t in net.transitions]
    nv = chain.vanishing_count
    visits = chain.visits(np.asarray(chain.r_tv.T @ pi)) if nv else np.zeros(0)
    thr = _per_transition(chain, pi, visits)
    busy = _per_transition(chain, pi, np.zeros(nv)) / rate
    enabled = np.zeros(len(tids))
    out_t = ~g.vanishing[g.src]
    np.add.at(enabled, g.transition[out_t], pi[chain.t_index[g.src[out_t]]])
    dead = np.asarray(-q.diagonal() == 0)
    terminates = all(c.size == 1 and dead[c[0]] for c in classes.bottom)
    result: dict[str, Any] = {
        "tangible_markings": int(chain.tangible.size), "vanishing_markings": nv, "terminates": terminates,
        "mean_tokens": dict(zip(places, (pi @ tokens).tolist(), strict=True)),
        "probability_nonempty": dict(zip(places, (pi @ (tokens > 0)).tolist(), strict=True)),
        "throughput": dict(zip(tids, thr.tolist(), strict=True)),
        "utilisation": {tids[i]: float(enabled[i]) for i in np.flatnonzero(timed)},
        "busy_servers": {tids[i]: float(busy[i]) for i in np.flatnonzero(timed & constant)},
        "residual": steady.residual, "method": steady.method,
    }
    bottlenecks: list[dict[str, Any]] = []
    sojourn: np.ndarray | None = None
    if terminates or not classes.irreducible:
        absorbed = ctmc.absorption(q, chain.alpha, classes)
        y = sojourn = absorbed.sojourn
        start = np.zeros(nv)
        if g.vanishing[0]:
            start[chain.v_index[0]] = 1.0
        v_abs = chain.visits(np.asarray(chain.r_tv.T @ y) + start) if nv else np.zeros(0)
        fired = _per_transition(chain, y, v_abs)
        en_time = np.zeros(len(tids))
        np.add.at(en_time, g.transition[out_t], y[chain.t_index[g.src[out_t]]])
        result["mean_time_to_absorption"] = absorbed.mean_time
        result["expected_firings"] = dict(zip(tids, fired.tolist(), strict=True))
        result["time_enabled"] = {tids[i]: float(en_time[i]) for i in np.flatnonzero(timed)}
        result["absorption"] = [
            {"marking": net.marking(g.states[chain.tangible[c[0]]]).to_dict(), "probability": float(p)}
            if c.size == 1 else
            {"markings": int(c.size), "example": net.marking(g.states[chain.tangible[c[0]]]).to_dict(),
             "probability": float(p)}
            for c, p in zip(classes.bottom, absorbed.probabilities, strict=True)
        ]
        total = absorbed.mean_time
        if terminates:
            order = np.argsort(-en_time, kind="stable")
            bottlenecks = [
                {"transition": tids[i], "time_enabled": float(en_time[i]),
                 "share": float(en_time[i] / total) if total > 0 else 0.0, "criterion": "time_enabled"}
                for i in order if timed[i] and en_time[i] > 0
            ]
    if not bottlenecks:
        scores = []
        for i in np.flatnonzero(timed & constant):
            if servers[i] is None:
                continue
            scores.append((float(busy[i] / servers[i]), i))
        scores.sort(key=lambda s: (-s[0], s[1]))
        bottlenecks = [{"transition": tids[i], "utilisation": s, "criterion": "utilisation"} for s, i in scores]
    result["bottlenecks"] = bottlenecks
    diag = q.diagonal()
    result["ctmc"] = {"tangible_states": int(q.shape[0]), "arcs": int(q.nnz - np.count_nonzero(diag))}
    fired_before = result.get("expected_firings")
    out_measures = []
    for meas, target in bound:
        entry: dict[str, Any] = {"measure": meas.text, "kind": meas.kind}
        if isinstance(target, int):
            entry["value"] = float(thr[target])
            if sojourn is not None and fired_before:
                entry["until_absorption"] = float(fired_before[tids[target]])
        else:
            values = np.asarray(target(g.states[chain.tangible]), dtype=float)
            entry["value"] = float(pi @ values)
            if sojourn is not None:
                entry["until_absorption"] = float(sojourn @ values)
        out_measures.append(entry)
    result["measures"] = out_measures
    if markings:
        order = np.argsort(-pi, kind="stable")
        result["marking_probabilities"] = [
            {"marking": net.marking(g.states[chain.tangible[i]]).to_dict(), "probability": float(pi[i])}
            for i in order.tolist()]
    return GSPNResult(**result)
