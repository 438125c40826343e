"""cpsat within its limit: building the model counts against it, a group too large to build in
the time given keeps its warm start ("fallback"), small groups are still proven. No timing
assertions: what is checked is which path a call takes and that its answer is sound."""
from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import cpsat, dp, greedy, tsp
from gatesopt.ordering.bounds import lower_bound
from gatesopt.ordering.layers import solve
from gatesopt.rewrite.order import order_program
from gatesopt.ordering.polylines import from_polylines
from gatesopt.ordering.problem import OPTIMAL_ABS_TOL, OrderingOptions

from test_ordering import _handmade_gcode, random_problem


def _large_group(n=150, seed=3):
    prob = random_problem(seed, n, closed_share=0.0)
    return prob.group(0, prob.origin_xy)


def _no_build(monkeypatch):
    """Make building the model an error: the call must not get that far."""
    def build(self, deadline):
        raise AssertionError("the model was built")
    monkeypatch.setattr(cpsat._Model, "build", build)


def _sound(grp, gs):
    grp.check_order(gs.order)
    assert gs.objective == pytest.approx(grp.path_cost(gs.order), abs=1e-9)
    assert gs.bound <= gs.objective + 1e-9
    if gs.status == "optimal":
        assert gs.objective - gs.bound <= OPTIMAL_ABS_TOL


@pytest.mark.parametrize("closed,move_seams", [(False, False), (False, True), (True, True)])
def test_n_arcs_counts_the_models_variables(closed, move_seams):
    # the estimate of the build time rests on it: one 0-1 variable per arc of the circuit
    prob = random_problem(5, 14, closed_share=0.5, move_seams=move_seams)
    grp = prob.group(0, prob.origin_xy)
    mod = cpsat._Model(grp, closed)
    assert mod.build(None)
    assert len(mod.model.proto.variables) == cpsat.n_arcs(grp, closed) == mod.n_vars
    assert len(mod.model.proto.constraints[0].circuit.literals) == mod.n_vars


def test_large_group_with_a_tiny_limit_keeps_the_warm_start_without_building(monkeypatch):
    grp = _large_group()
    # ~90k arcs: building alone is estimated at several times the limit
    assert cpsat.BUILD_S_PER_ARC * cpsat.n_arcs(grp) > 4 * 0.05
    _no_build(monkeypatch)
    gs = cpsat.solve(grp, time_limit_s=0.05)
    assert gs.status == "fallback"
    _sound(grp, gs)
    assert gs.bound == pytest.approx(lower_bound(grp))
    # the warm start's path, never worse than nearest neighbour
    assert gs.objective <= grp.path_cost(greedy.nearest_neighbour(grp)) + 1e-9


def test_no_time_left_keeps_the_hint(monkeypatch):
    grp = _large_group(40, seed=4)
    hint = greedy.solve(grp)
    _no_build(monkeypatch)
    gs = cpsat.solve(grp, time_limit_s=0.0, hint=hint)
    _sound(grp, gs)
    assert np.array_equal(gs.order, hint.order)
    assert gs.status in ("fallback", "optimal")       # "optimal" only if the cheap bound proves it
    assert (gs.status == "optimal") == (gs.objective - lower_bound(grp) <= OPTIMAL_ABS_TOL)


def test_building_stops_at_its_deadline():
    grp = _large_group(60, seed=6)
    mod = cpsat._Model(grp, False)
    assert not mod.build(time.perf_counter() - 1.0)      # the deadline passed: model unusable


def test_a_build_cut_short_keeps_the_warm_start(monkeypatch):
    grp = _large_group(30, seed=7)
    monkeypatch.setattr(cpsat._Model, "build", lambda self, deadline: False)
    gs = cpsat.solve(grp, time_limit_s=30.0)
    assert gs.status in ("fallback", "optimal")
    _sound(grp, gs)
    assert tsp.solve(grp, time_limit_s=30.0, exact_max_curves=100).status in ("optimal", "feasible")
    assert cpsat.closed_tour(grp, time_limit_s=30.0) is None


def test_closed_tour_of_a_large_group_with_a_tiny_limit_is_not_built(monkeypatch):
    grp = _large_group()
    _no_build(monkeypatch)
    assert cpsat.closed_tour(grp, time_limit_s=0.05) is None
    # tsp then takes the greedy tour
    sol = tsp.solve(grp, time_limit_s=0.05, exact_max_curves=200)
    grp.check_order(sol.order)
    assert sol.bound <= sol.objective + 1e-9


@pytest.mark.parametrize("seed", range(6))
def test_small_groups_are_still_proven_and_agree_with_dp(seed):
    prob = random_problem(200 + seed, 5 + seed, move_seams=seed % 2 == 1, clustered=seed % 3 == 0)
    end = (25.0, 25.0) if seed % 2 == 0 else None
    grp = prob.group(0, prob.origin_xy, end)
    gs = cpsat.solve(grp, time_limit_s=30.0)
    assert gs.status == "optimal"
    _sound(grp, gs)
    assert gs.objective == pytest.approx(dp.solve(grp).objective, abs=2e-3)


def _closed_brute_force(grp) -> float:
    per_curve = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    best = np.inf
    for perm in itertools.permutations(range(1, grp.n_curves)):
        for choice in itertools.product(*(per_curve[c] for c in (0,) + perm)):
            t = np.array(choice)
            d = grp.cand_entry_xy[np.roll(t, -1)] - grp.cand_exit_xy[t]
            best = min(best, float(np.hypot(d[:, 0], d[:, 1]).sum()))
    return best


@pytest.mark.parametrize("seed", range(3))
def test_closed_tour_is_still_optimal_on_small_groups(seed):
    prob = random_problem(300 + seed, 5, move_seams=seed == 1)
    grp = prob.group(0, prob.origin_xy)
    tour, proven = cpsat.closed_tour(grp, time_limit_s=30.0)
    assert proven
    assert sorted(grp.cand_curve[tour].tolist()) == list(range(grp.n_curves))
    d = grp.cand_entry_xy[np.roll(tour, -1)] - grp.cand_exit_xy[tour]
    assert float(np.hypot(d[:, 0], d[:, 1]).sum()) == pytest.approx(_closed_brute_force(grp), abs=2e-3)


def test_a_budgeted_cpsat_solve_mixes_proofs_and_fallbacks_soundly():
    # one group too large for its share of the budget, small ones CP-SAT proves
    rng = np.random.default_rng(11)
    big = [rng.uniform(0, 80, (2, 2)) for _ in range(160)]
    small = [[rng.uniform(0, 40, (2, 2)) for _ in range(14)] for _ in range(3)]
    prob = from_polylines([big] + small, options=OrderingOptions(mode="free"))
    sol = solve(prob, "cpsat", time_limit_s=5.0, budget_s=1.0)
    assert sorted(sol.curve_order.tolist()) == list(range(prob.n_curves))
    assert sol.travel_after_mm <= sol.travel_before_mm + 1e-9
    for gs in sol.groups:
        assert gs.status in ("optimal", "feasible", "fallback")
        assert gs.bound <= gs.objective + 1e-9


def test_cpsat_with_a_budget_gives_a_verified_file():
    prog = gatesopt.parse(_handmade_gcode())
    res = order_program(prog, OrderingOptions(mode="free"), formulation="cpsat", budget_s=3.0)
    assert res.ok
    assert res.summary["groups_optimal"] >= 1
    assert res.solution.travel_after_mm <= res.solution.travel_before_mm + 1e-9
