"""Linear-programming answers (coordinator.analysis.lp): semiflow supports with exact certificates,
state-equation bounds, and the verdicts that no longer depend on the Farkas enumeration."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from analysis_nets import make_net, philosophers_arcs

from coordinator.analysis import lp
from coordinator.analysis.invariants import farkas_estimate, semiflows
from coordinator.analysis.matrices import sparse_net
from coordinator.analysis.structure import analyse, ordinary_view
from coordinator.net import PetriNet
from coordinator.netfile import loads_net
from coordinator.netfile.pnml import load_pnml
from tests.unit.mcc_models import MCC

DATA = Path(__file__).resolve().parents[1] / "data"


def hostile() -> ModuleType:
    spec = importlib.util.spec_from_file_location("hostile_nets", DATA / "hostile_nets.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def choices(k: int) -> PetriNet:
    return loads_net(hostile().choices_toml(k), interpreted=False)


def mutex() -> PetriNet:
    return make_net("mutex", {"idle1": 1, "idle2": 1, "free": 1}, {
        "enter1": ({"idle1": 1, "free": 1}, {"crit1": 1}),
        "leave1": ({"crit1": 1}, {"idle1": 1, "free": 1}),
        "enter2": ({"idle2": 1, "free": 1}, {"crit2": 1}),
        "leave2": ({"crit2": 1}, {"idle2": 1, "free": 1}),
    })


def check_support(matrix: np.ndarray, sup: lp.Support) -> None:
    """The certificates prove the partition: yᵀA = 0 on the covered support, A·x ≥ 0 and > 0 outside."""
    assert sup.covered is not None and sup.certified
    if sup.covered.any():
        assert sup.semiflow is not None
        y = sup.semiflow.astype(np.int64)
        assert (y >= 0).all() and not (y @ matrix).any()
        assert np.array_equal(y > 0, sup.covered)
    if not sup.covered.all():
        assert sup.witness is not None
        ax = matrix @ sup.witness.astype(np.int64)
        assert (ax >= 0).all() and (ax[~sup.covered] > 0).all()


def test_mutex_is_conservative_and_consistent_with_exact_certificates() -> None:
    sn = sparse_net(mutex())
    c = sn.incidence.toarray()
    p, t = lp.conservative(sn), lp.consistent(sn)
    assert p.all_covered and t.all_covered
    check_support(c, p)
    check_support(c.T, t)


def test_a_producer_is_neither_and_the_witnesses_say_why() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    sn = sparse_net(net)
    c = sn.incidence.toarray()
    p, t = lp.conservative(sn), lp.consistent(sn)
    assert p.covered is not None and p.covered.tolist() == [True, False]
    assert t.covered is not None and t.covered.tolist() == [False]
    check_support(c, p)
    check_support(c.T, t)


@pytest.mark.parametrize("seed", range(10))
def test_random_matrices_partition_exactly_into_covered_and_witnessed(seed: int) -> None:
    rng = np.random.default_rng(seed)
    matrix = rng.integers(-2, 3, size=(7, 4)) * (rng.random((7, 4)) < 0.6)
    sup = lp.semiflow_support(matrix)
    check_support(matrix, sup)
    vecs, complete, _ = semiflows(matrix)
    assert complete
    union = vecs.sum(axis=0) > 0 if vecs.shape[0] else np.zeros(7, dtype=bool)
    assert np.array_equal(union, sup.covered)  # the union of the minimal supports is the LP's support


def test_choice_net_whose_farkas_table_explodes_is_decided_by_the_lp() -> None:
    """Stands in for Peterson-PT-2 and SafeBus-PT-03: consistent and conservative, but 2**16 minimal
    semiflows of each kind; the enumeration gives up within its budget and the LP still says yes."""
    net = choices(16)
    a = analyse(net)
    assert not a.t_invariants.complete and not a.p_invariants.complete
    assert a.consistent is True and a.conservative is True
    assert a.sources["consistent"] == a.sources["conservative"] == "LP (semiflow support, exact certificate)"
    assert a.complete and a.states == 256 and a.live is True


def test_the_enumeration_is_refused_before_it_starts_when_the_table_cannot_fit() -> None:
    """Stands in for IBM319: the cost is estimated from the matrix before anything is allocated."""
    n = 20_000
    ring = sp.csr_matrix((np.r_[-np.ones(n), np.ones(n)], (np.r_[np.arange(n), (np.arange(n) + 1) % n],
                                                         np.r_[np.arange(n), np.arange(n)])), shape=(n, n))
    est = farkas_estimate(ring, max_bytes=512 << 20)
    assert est.first_bytes > 512 << 20
    vecs, complete, why = semiflows(ring, max_bytes=512 << 20)
    assert not complete and vecs.shape == (0, n) and why.startswith("not started")
    assert lp.semiflow_support(ring).all_covered is True


def test_a_step_that_would_outrun_the_time_budget_is_not_made() -> None:
    net = choices(12)
    vecs, complete, why = semiflows(sparse_net(net).incidence.T, seconds=0.05)
    assert not complete and "time budget" in why and vecs.shape[0] == 0


def test_state_equation_bounds_of_mutex_are_exact_and_certified() -> None:
    pb = lp.place_bounds(sparse_net(mutex()))
    assert pb.total == 3
    assert pb.bounds.tolist() == [1, 1, 1, 1, 1] and pb.certified.all()


def test_weighted_arcs_bound_by_the_dual_vector() -> None:
    net = make_net("pairs", {"a": 4}, {"join": ({"a": 2}, {"b": 1}), "split": ({"b": 1}, {"a": 2})})
    pb = lp.place_bounds(sparse_net(net))
    assert pb.bounds.tolist() == [4, 2] and pb.certified.all()


def test_an_unbounded_relaxation_gives_no_total_but_bounds_the_other_places() -> None:
    net = make_net("producer", {"go": 1}, {"produce": ({"go": 1}, {"go": 1, "buf": 1})})
    total, finished, _ = lp.total_bound(sparse_net(net))
    assert finished and total is None
    pb = lp.place_bounds(sparse_net(net))
    assert pb.bounds.tolist() == [1, -1]


def test_bounds_hold_on_nets_with_inhibitor_arcs() -> None:
    net = make_net("guarded", {"a": 3}, {"t": ({"a": 1}, {"b": 1}), "u": ({"b": 1}, {"a": 1})},
                   inhibitors={"t": {"b": 2}})
    pb = lp.place_bounds(sparse_net(net))
    assert pb.bounds.tolist() == [3, 3]  # the relaxation ignores the inhibitor: b <= 2 in fact, 3 is sound


@pytest.mark.parametrize("seed", range(20))
def test_the_bounds_from_one_basis_to_the_next_are_each_place_s_own_lp_solved_alone(seed: int) -> None:
    # the LPs of place_bounds share one HiGHS instance (only the objective changes): each optimum
    # is the one scipy's linprog finds for that place alone (their certificates, where the duals
    # round to small denominators, are checked exactly inside)
    rng = np.random.default_rng(seed)
    n_p, n_t = int(rng.integers(3, 12)), int(rng.integers(2, 14))
    pre = rng.integers(0, 3, (n_p, n_t)) * (rng.random((n_p, n_t)) < 0.4)
    post = rng.integers(0, 3, (n_p, n_t)) * (rng.random((n_p, n_t)) < 0.4)
    marking = {f"p{i}": int(v) for i, v in enumerate(rng.integers(0, 4, n_p)) if v}
    trans = {f"t{j}": ({f"p{i}": int(pre[i, j]) for i in range(n_p) if pre[i, j]},
                       {f"p{i}": int(post[i, j]) for i in range(n_p) if post[i, j]}) for j in range(n_t)}
    sn = sparse_net(make_net(f"random{seed}", marking, trans))
    pb = lp.place_bounds(sn, seconds=60.0)
    c = sn.incidence.toarray().astype(float)
    m0 = np.asarray(sn.m0, dtype=float)
    total = linprog(-np.ones(sn.n_places) @ c, A_ub=-c, b_ub=m0, method="highs")
    for p in range(sn.n_places):
        alone = linprog(-c[p], A_ub=-c, b_ub=m0, method="highs")
        if alone.status == 3:  # unbounded alone: at most what the total's certificate says, if any
            assert pb.bounds[p] == -1 or total.status == 0
            continue
        # a place another LP's certificate bounds by 0 needs no LP of its own: its optimum is 0 too
        assert pb.own[p] or pb.bounds[p] == 0
        assert pb.bounds[p] == int(np.floor(m0[p] - alone.fun + 1e-7)), (p, alone.fun)
    assert pb.complete


@pytest.mark.parametrize("big", [False, True])
def test_the_exact_product_is_exact_in_int64_and_beyond_it(big: bool) -> None:
    # the certificates' check yᵀC: an int64 array where the product provably fits, Python ints past
    # 2**63 otherwise; both the sums a Python loop gives
    rng = np.random.default_rng(7)
    mat = sp.csr_matrix(rng.integers(-3, 4, (30, 40)) * (rng.random((30, 40)) < 0.3)).astype(np.int64)
    vec = rng.integers(0, 2**61 if big else 1000, 40, dtype=np.int64)
    out = lp._exact_product(mat, vec)
    dense = mat.toarray().tolist()
    want = [sum(int(a) * int(v) for a, v in zip(row, vec.tolist())) for row in dense]
    assert out.dtype == (object if big else np.int64)
    assert out.tolist() == want
    assert big == any(abs(v) >= 2**63 for v in want)


def test_a_run_of_places_that_exclude_each_other_is_bounded_by_one_lp() -> None:
    # a choice among 64 values (AirplaneLD's altitudes): one token in stp goes to one of alt_i and
    # back; each val_i is read. The total's LP bounds each alt_i by 65; an LP for a run of _BLOCK
    # places bounds them by one, with the certificate checked, as each one's own LP does
    n = 64
    trans = {f"get{i}": ({"stp": 1, f"val{i}": 1}, {f"val{i}": 1, f"alt{i}": 1}) for i in range(n)}
    trans |= {f"put{i}": ({f"alt{i}": 1}, {"stp": 1}) for i in range(n)}
    alts = [f"alt{i}" for i in range(n)]
    net = make_net("choice", {"stp": 1} | {f"val{i}": 1 for i in range(n)}, trans, places=("stp", *alts))
    sn = sparse_net(net)
    lps = lp._StateEquation(sn)
    bounds = np.full(sn.n_places, n + 1, dtype=np.int64)
    cert = np.zeros(sn.n_places, dtype=bool)
    todo = np.arange(1, n + 1)
    lp._blocks(sn, lps, todo, lambda ps: bounds[ps] > 1, bounds, cert, float("inf"))
    assert 1 <= lps.solved <= n // lp._BLOCK  # one LP a run at most (here the first
    # run's certificate, stp plus every alt_i, bounds all of them)
    assert (bounds[todo] == 1).all() and cert[todo].all()
    alone = lp.place_bounds(sn, seconds=60.0)
    assert (alone.bounds[todo] == 1).all()


def test_kanban_bounds_are_decided_by_structure_when_the_graph_is_cut_short() -> None:
    a = analyse(load_pnml(MCC / "Kanban-PT-00005" / "model.pnml"), max_states=20_000)
    assert not a.complete and a.stopped_by == "max_states"
    assert a.bounded is True and a.sources["bounded"] == "state equation (LP, exact certificate)"
    assert a.max_token_in_place == 5  # the oracle's value: explored markings reach the LP bound
    assert all(b == 5 for b in a.place_bounds.values())
    assert a.live is None and "live" in a.undecided


def test_a_net_without_any_semiflow_gets_an_empty_cover_from_one_lp() -> None:
    # a producer feeding a chain: no y ≥ 0 with yᵀC = 0 but 0, so the per-place LPs would all be
    # infeasible; the cover is empty, and a net with semiflows still gets them
    n = 300
    trans = {"produce": ({}, {"p0": 1})} | {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(n - 1)}
    chain = make_net("chain", {}, trans)
    assert lp.semiflow_cover(sparse_net(chain), seconds=3.0) == []
    ring = make_net("ring", {"p0": 1}, {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % n}": 1}) for i in range(n)})
    cover = lp.semiflow_cover(sparse_net(ring), seconds=3.0)
    assert len(cover) == 1 and (cover[0] == 1).all()


@pytest.mark.parametrize("warm", [True, False])
def test_the_cover_finds_the_small_semiflows_from_scratch_and_from_one_basis_to_the_next(warm: bool) -> None:
    # a ring of philosophers beside a producer feeding a chain (no semiflow there): the LPs of
    # successive places share one HiGHS instance, a place of the chain gets none (its LP is
    # infeasible, and the next one starts from there when warm), and every y returned is a semiflow
    n = 40
    marking, trans = philosophers_arcs(n)
    trans |= {"produce": ({}, {"c0": 1})} | {f"move{i}": ({f"c{i}": 1}, {f"c{i + 1}": 1}) for i in range(5)}
    net = make_net("both", marking, trans)
    sn = sparse_net(net)
    cover = lp.semiflow_cover(sn, seconds=60.0, warm=warm)
    c = sn.incidence.toarray()
    assert all((y >= 0).all() and not (y @ c).any() for y in cover)
    covered = np.zeros(sn.n_places, dtype=bool)
    for y in cover:
        covered |= y > 0
    ids = [p.id for p in net.places]
    assert covered.tolist() == [not i.startswith("c") for i in ids]
    # each place bounded by 1, the bound its semiflows give (M(p) <= y.M0 / y_p), a lower one kept
    for start, want in ((-1, [1 if not i.startswith("c") else -1 for i in ids]), (0, [0] * sn.n_places)):
        upper = np.full(sn.n_places, start, dtype=np.int64)
        for y in cover:
            lp._apply(upper, np.zeros(sn.n_places, dtype=bool), y, sn.m0, True)
        assert upper.tolist() == want


def test_whether_the_cover_starts_each_lp_from_the_last_basis_is_decided_by_the_places_to_cover() -> None:
    # beyond _WARM_PLACES places each LP starts from the last one's basis, whatever the first LP's
    # time (made on that time, ASLink-PT-02a's choice, and its cover, changed from run to run);
    # below, from scratch while the places left fit in the time
    def cover(n: int, warm: bool | None) -> list[list[int]]:
        marking, trans = philosophers_arcs(n)
        return [y.tolist() for y in lp.semiflow_cover(sparse_net(make_net("ring", marking, trans)), seconds=60.0,
                                                        warm=warm)]

    big = lp._WARM_PLACES // 4 + 10  # four places a philosopher
    assert cover(big, None) == cover(big, True)
    assert cover(20, None) == cover(20, False)


def test_an_lp_of_a_shared_instance_has_its_own_time_whatever_the_runs_before_it_took() -> None:
    # HiGHS compares its time limit with the instance's run time summed over its runs: given the
    # time left alone, the LPs of NeoElection-PT-3's cover stopped at about half their budget
    sn = sparse_net(ordinary_view(load_pnml(DATA / "mcc-large" / "NeoElection-PT-3" / "model.pnml")))
    through = lp._Through(sp.csr_matrix(sn.incidence.T, dtype=np.float64))
    runs = 0
    while through.h.getRunTime() < 0.5 and runs < 20 * sn.n_places:  # LPs of a few ms each
        through.solve(runs % sn.n_places, 60.0, False)
        runs += 1
    assert through.h.getRunTime() >= 0.5
    y = through.solve(0, 0.25, False)  # the first place's LP again, from scratch: a few ms of its own
    assert isinstance(y, np.ndarray) and y[0] >= 1 and not (y @ sn.incidence.toarray()).round(6).any()


def counter(k: int, m: int = 4) -> PetriNet:
    """A one-hot counter load0..load{k}, moved up by taking one of ``m`` free slots and leaving one
    of ``m`` requests, and down the other way (k free slots at first): semiflows Σ load = 1,
    Σ free + Σ request = k, Σ (k − i)·load_i + Σ request = k and Σ i·load_i + Σ free = k."""
    trans = {}
    for i in range(k):
        for a in range(m):
            for b in range(m):
                trans[f"up{i}_{a}_{b}"] = ({f"load{i}": 1, f"free{a}": 1}, {f"load{i + 1}": 1, f"request{b}": 1})
                trans[f"down{i}_{a}_{b}"] = ({f"load{i + 1}": 1, f"request{b}": 1}, {f"load{i}": 1, f"free{a}": 1})
    loads = tuple(f"load{i}" for i in range(k + 1))
    return make_net("counter", {"load0": 1, "free0": k}, trans,
                    places=loads + tuple(f"free{a}" for a in range(m)) + tuple(f"request{b}" for b in range(m)))


def test_the_second_pass_finds_the_one_hot_semiflow_two_weighted_ones_hide() -> None:
    # the first pass's LP for load0 has the smaller Σ y from Σ (k − i)·load_i + Σ request, scaled
    # to y_load0 = 1, and load{k}'s from Σ i·load_i + Σ free: every place is covered, the one-hot
    # Σ load never comes out. With every y ≤ 1 (spread), it does: one level of k + 1 local markings
    # for the counter in a decision diagram, instead of k + 1 levels (SimpleLoadBal-PT-10's loads)
    from coordinator.analysis.mdd_order import MAX_LOCAL, encode

    k, m = 10, 4
    sn = sparse_net(counter(k, m))
    one_hot = [1] * (k + 1) + [0] * (2 * m)
    first = lp.semiflow_cover(sn, seconds=60.0)
    assert len(first) == 2 and not any((y <= 1).all() for y in first)
    both = lp.semiflow_cover(sn, seconds=60.0, spread=MAX_LOCAL)
    assert [y.tolist() for y in both] == [y.tolist() for y in first] + [one_hot]
    bounds = np.array([1] * (k + 1) + [k] * (2 * m), dtype=np.int64)
    # neither weighted semiflow makes a group (their places' local markings are more than MAX_LOCAL)
    assert len(encode(sn, bounds, first, seconds=5.0).levels) == k + 1 + 2 * m
    levels = encode(sn, bounds, both, seconds=5.0).levels
    assert sorted(len(ps) for ps in levels) == [1] * (2 * m) + [k + 1]
    # Σ free + Σ request = k is a 0/1 semiflow too, not added: its k tokens lie on its 2m places in
    # C(2m + k − 1, k) = 19,448 ways; and none is added with a smaller spread than the one-hot's 11
    assert len(lp.semiflow_cover(sn, seconds=60.0, spread=k)) == 2
    # nor where it would take a place from a small semiflow of the first pass (a group of its own):
    # with k = 2 and one slot, 2·load0 + load1 + request = 2 has 18 ways at most
    small = sparse_net(counter(2, 1))
    assert [y.tolist() for y in lp.semiflow_cover(small, seconds=60.0, spread=MAX_LOCAL)] == [
        y.tolist() for y in lp.semiflow_cover(small, seconds=60.0)] == [[2, 1, 0, 0, 1], [0, 1, 2, 1, 0]]


def test_a_place_another_lp_s_certificate_bounds_by_one_gets_no_lp_of_its_own() -> None:
    # two rings, of one token (a, b) and of five (c, d): the total's certificate bounds each place by
    # six; a's own LP bounds a and b by one (its certificate weighs both), so b needs no LP of its own
    # when one token is all the encoding asks (lp_above 1); c's bounds c and d by five, which d's own
    # LP is still given (five is above one and no marking reached it)
    net = make_net("two rings", {"a": 1, "c": 5}, {"ab": ({"a": 1}, {"b": 1}), "ba": ({"b": 1}, {"a": 1}),
                                                  "cd": ({"c": 1}, {"d": 1}), "dc": ({"d": 1}, {"c": 1})})
    sn = sparse_net(net)
    order = [net.places[i].id for i in range(sn.n_places)]
    pb = lp.place_bounds(sn, lp_above=1)
    bounds = dict(zip(order, pb.bounds.tolist()))
    own = dict(zip(order, pb.own.tolist()))
    assert bounds == {"a": 1, "b": 1, "c": 5, "d": 5} and pb.complete and pb.certified.all()
    assert own == {"a": True, "b": False, "c": True, "d": True}
    # every place's bound to the last token (lp_above 0), counts reached given: a's certificate brings
    # b's bound down to the one token it reached, c's brings d's to five, which d did not reach
    seen = np.array([{"a": 1, "b": 1, "c": 5, "d": 3}[p] for p in order])
    pb = lp.place_bounds(sn, seen=seen)
    assert dict(zip(order, pb.own.tolist())) == {"a": True, "b": False, "c": True, "d": True}
    assert pb.bounds.tolist() == [{"a": 1, "b": 1, "c": 5, "d": 5}[p] for p in order] and pb.complete
