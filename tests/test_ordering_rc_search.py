"""The reduced-cost search after a complete root (gatesopt/ordering/rc_search.py): its dual bound
holds for every path (brute force), what it proves is the subset DP's optimum on symmetric and
direction-dependent costs, in the symmetric and the directed model, and a search stopped by its
node limit proves nothing and never returns a dearer path than it was given."""
from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

from gatesopt.ordering import auto, dp, greedy, rc_search, symmetric
from gatesopt.ordering.problem import OPTIMAL_ABS_TOL
from gatesopt.solvers import Status

from test_ordering import random_problem
from test_ordering_proof_rules import asymmetric_group


def _rooted(grp, directed: bool, start=None):
    """A model of ``grp`` after its complete root (the symmetric one, or ``DirectedModel`` from
    it, as ``symmetric.solve`` goes), and the incumbent it started from."""
    start = greedy.nearest_neighbour(grp) if start is None else start
    model = symmetric.SymmetricModel(grp, start)
    model.seed_odd_sets()
    model.root(time.perf_counter() + 30)
    assert model.complete
    if directed:
        sym = model
        model = symmetric.DirectedModel(grp, start, graph=(
            sym.pos, sym.node_curve, sym.deg, sym.C, sym.curve_nodes, sym.first_cand, sym.A))
        model.take_cuts(sym)
        model.root(time.perf_counter() + 30)
        assert model.complete
    return model, start


def _all_paths(grp):
    """Every candidate order of a small group: each curve once, in each of its candidates."""
    by_curve = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    for perm in itertools.permutations(range(grp.n_curves)):
        for cands in itertools.product(*(by_curve[c] for c in perm)):
            yield np.asarray(cands, np.int64)


@pytest.mark.parametrize("directed", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_the_dual_bound_holds_for_every_path(seed, directed):
    """cost(T) >= z + sum of max(rc, 0) over T's arcs, for every path T of the group (brute
    force over all orders and directions): what lets the search drop a partial path."""
    if seed % 2:
        grp = asymmetric_group(40 + seed, n_lines=5, n_one_way=12, scale=1.0)
    else:
        prob = random_problem(700 + seed, 5, closed_share=0.2, clustered=True)
        grp = prob.group(0, prob.origin_xy, end=(25.0, 0.0) if seed == 2 else None)
    model, _ = _rooted(grp, directed)
    z = float(model.h.getInfo().objective_function_value)
    rc = np.maximum(rc_search.reduced_cost_matrix(model), 0.0)
    worst = np.inf
    for order in _all_paths(grp):
        arcs = model.tour_edges(order)
        worst = min(worst, grp.path_cost(order) - (z + rc[arcs[:, 0], arcs[:, 1]].sum()))
    assert worst >= -1e-6


def _cases():
    for seed in range(16):
        if seed % 2:
            yield seed, asymmetric_group(300 + seed, n_lines=11 + seed % 4, n_one_way=20,
                                         loops=seed % 3 == 0, scale=1.0 if seed % 4 == 1 else 0.003)
        else:
            prob = random_problem(1700 + seed, 12 + seed % 4, closed_share=0.2 if seed % 4 else 0.0,
                                  clustered=seed % 3 != 0)
            yield seed, prob.group(0, prob.origin_xy, end=(25.0, 0.0) if seed % 4 == 2 else None)


@pytest.mark.parametrize("directed", [False, True])
def test_what_the_search_proves_is_the_dp_optimum(directed):
    proven = 0
    for seed, grp in _cases():
        opt = dp.solve(grp).objective
        model, start = _rooted(grp, directed)
        start_obj = grp.path_cost(start)
        order, obj, bound, ok = rc_search.search(model, start, start_obj, 1_000_000)
        grp.check_order(order)
        assert obj == pytest.approx(grp.path_cost(order), abs=1e-9)
        assert obj <= start_obj + 1e-9                  # never dearer than the incumbent
        if ok:
            proven += 1
            assert obj == pytest.approx(opt, abs=OPTIMAL_ABS_TOL), seed
            assert bound <= opt + OPTIMAL_ABS_TOL
        else:
            assert bound is None
    assert proven >= 12, proven          # it does prove most of these groups


def test_a_search_stopped_by_its_node_limit_proves_nothing():
    stopped = 0
    for seed, grp in _cases():
        model, start = _rooted(grp, False)
        start_obj = grp.path_cost(start)
        z = float(model.h.getInfo().objective_function_value)
        if start_obj - z <= OPTIMAL_ABS_TOL:
            continue
        order, obj, bound, ok = rc_search.search(model, start, start_obj, 1)
        full = rc_search.search(model, start, start_obj, 1_000_000)
        if full[3] and ok:
            continue                    # (proven at the root's bounds alone: no node needed)
        stopped += 1
        assert not ok and bound is None
        assert obj <= start_obj + 1e-9
    assert stopped >= 3, stopped


def test_groups_above_the_size_limit_are_not_searched(monkeypatch):
    prob = random_problem(1750, 12, clustered=True)
    grp = prob.group(0, prob.origin_xy)
    model, start = _rooted(grp, False)
    monkeypatch.setattr(rc_search, "MAX_CURVES", 11)
    order, obj, bound, ok = rc_search.search(model, start, grp.path_cost(start), 1_000_000)
    assert not ok and bound is None and np.array_equal(order, start)


def test_auto_proves_the_same_optima_with_and_without_the_search(monkeypatch):
    """``symmetric.solve`` runs the search after each complete root: every group auto proves
    with it costs what it costs without it (the branch-and-cut's optimum), and the search is
    what proves some of them."""
    calls = []
    orig = rc_search.search

    def spy(model, order, obj, nodes):
        got = orig(model, order, obj, nodes)
        calls.append(got[3])
        return got
    monkeypatch.setattr(rc_search, "search", spy)
    for seed, grp in _cases():
        if grp.n_curves <= auto.DP_FIRST_CURVES:
            continue
        monkeypatch.setattr(rc_search, "ENABLED", True)
        with_search = auto.solve(grp, time_limit_s=10.0)
        monkeypatch.setattr(rc_search, "ENABLED", False)
        without = auto.solve(grp, time_limit_s=10.0)
        assert with_search.status == without.status == Status.OPTIMAL
        assert with_search.objective == pytest.approx(without.objective, abs=OPTIMAL_ABS_TOL)
    assert sum(calls) >= 2, calls
