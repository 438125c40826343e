"""Proof rules of the exact step under direction-dependent link costs (issue 36; formulations/
ordering.md, "milp, symmetric model", "direction-dependent costs"): the symmetric model prices
each travel edge the cheaper way round, so it relaxes a group whose copied slicer gaps cost
otherwise one way than the other. Whatever the exact step proves optimal must cost what the
subset DP (exact for any costs) finds, on random small groups with one-way links cheaper or
dearer, and a path priced above the model must never be called optimal by the model's bound."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from gatesopt.ordering import auto, dp, milp, rc_search, symmetric, symmetric_graph
from gatesopt.ordering.polylines import from_polylines
from gatesopt.ordering.problem import OPTIMAL_ABS_TOL, LinkCosts
from gatesopt.solvers import Status


def random_polylines(rng, n_lines: int, loops: int) -> list:
    """``n_lines`` random open lines in a 40 mm square, then ``loops`` closed 3 mm squares."""
    polys = [rng.uniform(0, 40, (2, 2)) for _ in range(n_lines)]
    for _ in range(loops):
        c = rng.uniform(5, 35, 2)
        polys.append(np.array([c, c + [3, 0], c + [3, 3], c + [0, 3], c]))
    return polys


def asymmetric_group(seed: int, n_lines: int = 11, n_one_way: int = 8, loops: int = 0,
                     scale: float = 1.0):
    """A random group of open lines (and ``loops`` closed squares) whose link matrix is the
    Euclidean one with ``n_one_way`` links changed one way only (the way the slicer printed
    them: a copied gap), by a factor in [0.3, 1.6] (or, with ``scale`` small, by a few
    thousandths of their cost: the near-ties the model meets on real layers)."""
    rng = np.random.default_rng(seed)
    prob = from_polylines([random_polylines(rng, n_lines, loops)])
    grp = prob.group(0, prob.origin_xy)
    arc = grp.arc_cost().copy()
    m = grp.n_cands
    for _ in range(n_one_way):
        u, v = rng.integers(0, m, 2)
        if np.isfinite(arc[u, v]):
            f = rng.uniform(0.3, 1.6) if scale >= 1.0 else 1.0 + scale * rng.uniform(-1, 1)
            arc[u, v] *= f
    costs = LinkCosts(arc, grp.start_cost().copy(), grp.end_cost().copy())
    return dataclasses.replace(grp, costs=costs)


CASES = [(seed, scale) for seed in range(14) for scale in (1.0, 0.003)]


@pytest.mark.parametrize("seed,scale", CASES)
def test_symmetric_model_proves_only_the_true_optimum(seed, scale):
    grp = asymmetric_group(seed, n_lines=10 + seed % 3, loops=seed % 2, scale=scale)
    assert symmetric_graph.applies(grp)
    best = dp.solve(grp).objective
    # the slicer's order as incumbent (candidate of each curve as given)
    start = np.array([int(np.flatnonzero(grp.cand_curve == c)[0]) for c in range(grp.n_curves)])
    order, obj, bound, proven = symmetric.solve(grp, start, time.perf_counter() + 20.0)
    grp.check_order(order)
    assert obj == pytest.approx(grp.path_cost(order))
    assert bound <= best + OPTIMAL_ABS_TOL          # a valid bound for the true costs
    if proven:
        assert obj <= best + OPTIMAL_ABS_TOL
    # the full exact step (auto's: greedy, matching, ILS, model, the directed model after it)
    gs = milp.solve(grp, time_limit_s=20.0)
    assert gs.bound <= best + OPTIMAL_ABS_TOL
    if gs.status == Status.OPTIMAL:
        assert gs.objective <= best + OPTIMAL_ABS_TOL


@pytest.mark.parametrize("directed", [False, True])
def test_asymmetric_groups_proven_at_the_true_optimum(directed, monkeypatch):
    """On groups where the model's cheapest tours are priced above the model (a one-way link
    taken the dear way), the exact step proves the true optimum: in the symmetric model alone
    (``DIRECTED`` off) the cut of each such tour (``SymmetricModel.add_no_good``) lets the
    node's bound rise past it; with ``DirectedModel`` the root prices each direction itself.
    (Without the reduced-cost search, which would prove most of them before any branching.)"""
    monkeypatch.setattr(symmetric, "DIRECTED", directed)
    monkeypatch.setattr(rc_search, "ENABLED", False)
    proven = 0
    used = 0
    for seed in range(30):
        grp = asymmetric_group(100 + seed, n_lines=12, n_one_way=20, scale=0.003)
        best = dp.solve(grp).objective
        start = np.array([int(np.flatnonzero(grp.cand_curve == c)[0]) for c in range(grp.n_curves)])
        no_goods = []
        orig = symmetric.SymmetricModel.add_no_good

        def spy(model, on, _orig=orig, _log=no_goods):
            _log.append(int(on.sum()))
            return _orig(model, on)

        symmetric.SymmetricModel.add_no_good = spy
        try:
            order, obj, bound, ok = symmetric.solve(grp, start, time.perf_counter() + 20.0)
        finally:
            symmetric.SymmetricModel.add_no_good = orig
        used += bool(no_goods)
        if ok:
            proven += 1
            assert obj <= best + OPTIMAL_ABS_TOL
    if not directed:
        assert used >= 1      # the instances do reach a tour priced above the model
    assert proven == 30       # and the model alone proves every one of them


def test_auto_agrees_with_dp_on_larger_asymmetric_groups():
    """Groups above the DP-first size (auto goes to the model, not the DP) with one-way links:
    what auto calls optimal costs the DP's optimum."""
    for seed in range(8):
        grp = asymmetric_group(200 + seed, n_lines=14, n_one_way=30,
                               scale=1.0 if seed % 2 else 0.003)
        best = dp.solve(grp).objective
        gs = auto.solve(grp, time_limit_s=0.0 + auto.exact_time_s(grp.n_curves) + 2.0)
        grp.check_order(gs.order)
        assert gs.bound <= best + OPTIMAL_ABS_TOL
        if gs.status == Status.OPTIMAL:
            assert gs.objective <= best + OPTIMAL_ABS_TOL


def test_the_slicers_order_kept_as_an_option_is_proven_only_at_the_optimum():
    # ``chain.path_options`` offers the slicer's order beside the solver's path (the chain DP may
    # take it for the chain's sake): it carries the solver's bound, and is called optimal only
    # where it costs that optimum
    from gatesopt.ordering.chain import path_options
    rng = np.random.default_rng(5)
    prob = from_polylines([[rng.uniform(0, 40, (2, 2)) for _ in range(9)]])
    grp = prob.group(0, prob.origin_xy)
    gs = dp.solve(grp)
    assert gs.status == Status.OPTIMAL
    opts = path_options(grp, gs)
    kept = [o for o in opts if o.formulation.endswith("+kept")]
    assert len(kept) == 1 and kept[0].objective > gs.objective + OPTIMAL_ABS_TOL
    assert kept[0].status == Status.FEASIBLE
    assert [o for o in opts if o is gs][0].status == Status.OPTIMAL


def test_every_group_reported_proven_prints_its_optimum_from_where_the_file_enters_it():
    # a group is proven for the start its chain gave it; the chain DP (``pick_paths``) and the
    # time guard (a layer printed in greedy's or the slicer's order before it) can enter it from
    # elsewhere. On a real file whose groups the subset DP solves (prusa25_bunny_triangles15_lh01
    # free: 1,069 groups of <= 21 curves), every group reported optimal, solved forward (not a
    # backwards half of the two-process chain, not repaired on joined costs, not a look-ahead
    # path proven for its end), prints the DP's optimum from the curve the output enters it from
    import gatesopt
    from conftest import SHARED_INSTANCES
    from gatesopt.ordering import OrderingOptions
    from gatesopt.ordering.chain import end_of
    from gatesopt.ordering.problem import Anchor
    from gatesopt.rewrite.order import order_program
    path = SHARED_INSTANCES / "prusa25_bunny_triangles15_lh01.gcode.gz"
    if not path.exists():
        pytest.skip(f"development corpus not found at {SHARED_INSTANCES}")
    res = order_program(gatesopt.parse(str(path)), OrderingOptions(mode="free"), budget_s=10,
                        workers=1)
    prob, sol = res.problem, res.solution
    pos = Anchor.of(prob.origin_xy)
    checked = 0
    for g in range(prob.n_groups):
        grp = prob.group(g, pos, end_of(prob, g))
        gs = sol.groups[g]
        forward = not any(s in gs.formulation for s in ("+back", "+joined", "+ahead"))
        if (prob.group_reorderable[g] and gs.status == Status.OPTIMAL and forward
                and dp.fits(grp)):
            checked += 1
            # proven for its end (free, a fixed group's entry, the file's end), or, taken for the
            # next group's sake (``settle``), for that group's entry as printed
            ends = [end_of(prob, g)]
            if end_of(prob, g) is None and g + 1 < prob.n_groups and len(sol.groups[g + 1].order):
                nxt = prob.group(g + 1, pos)
                ends.append(prob.cand_anchor(g + 1, nxt, int(sol.groups[g + 1].order[0])))
            assert any(prob.group(g, pos, e).path_cost(gs.order)
                       <= dp.solve(prob.group(g, pos, e)).objective + OPTIMAL_ABS_TOL
                       for e in ends), g
        if grp.n_curves:
            pos = prob.exit_anchor(g, grp, gs.order)
    assert checked >= 500


def test_a_proof_holds_only_for_the_start_and_the_end_it_was_made_for():
    # ``settle.proof_holds``: group 0 solved (as by the main process) to end where the helper's
    # path of group 1 begins; the chain picked must start it where it was solved from and enter
    # group 1 at that entry. A path solved backwards (start free) holds from any start
    from gatesopt.ordering.settle import proof_holds
    from gatesopt.ordering.problem import Anchor, GroupSolution
    strokes = [np.array([[0.0, y], [10.0, y]]) for y in (0, 40, 10, 30, 20)]
    prob = from_polylines([strokes, strokes])
    start = Anchor.of(prob.origin_xy)
    nxt = prob.group(1, start)
    end = prob.cand_anchor(1, nxt, 0)
    grp = prob.group(0, start, end)
    gs = dp.solve(grp)
    one = dp.solve(nxt)
    other = next(k for k in range(nxt.n_cands)
                 if not np.array_equal(nxt.cand_entry_xy[k], nxt.cand_entry_xy[0]))

    def picked_next(first):         # (only where group 1's path begins matters here)
        return GroupSolution.make(np.array([first]), 0.0, 0.0, Status.FEASIBLE, 0.0, "test")
    plans = [(grp, [gs], start, end), (nxt, [one], start, None)]
    assert proof_holds(prob, plans, [gs, picked_next(0)], 0, start)
    # the next group entered elsewhere: g's end link was to another point
    assert not proof_holds(prob, plans, [gs, picked_next(other)], 0, start)
    # entered from elsewhere
    assert not proof_holds(prob, plans, [gs, picked_next(0)], 0, Anchor.of((99.0, 99.0)))
    back = dataclasses.replace(gs, formulation=gs.formulation + "+back")
    assert proof_holds(prob, plans, [back, picked_next(other)], 0, Anchor.of((99.0, 99.0)))
    # a look-ahead pair holds where both halves are taken
    from gatesopt.ordering.chain import LOOKAHEAD_FROM, LOOKAHEAD_TO
    to = dataclasses.replace(gs, formulation=gs.formulation + LOOKAHEAD_TO)
    frm = dataclasses.replace(picked_next(other), formulation="dp" + LOOKAHEAD_FROM)
    assert proof_holds(prob, plans, [to, frm], 0, start)
    assert proof_holds(prob, plans, [to, frm], 1, start)
    assert not proof_holds(prob, plans, [to, picked_next(other)], 0, start)
    assert not proof_holds(prob, plans, [gs, frm], 1, start)


def one_way_group(seed: int, n_lines: int, n_one_way: int, loops: int = 0):
    """Random open lines (``n_one_way`` of them one-way: one candidate, forward, as
    ``candidates.one_way`` makes for a slicer's clipped loop or a coasted curve) and ``loops``
    closed squares."""
    rng = np.random.default_rng(seed)
    prob = from_polylines([random_polylines(rng, n_lines, loops)])
    one_way = np.zeros(prob.n_curves, bool)
    one_way[rng.choice(n_lines, n_one_way, replace=False)] = True
    prob = dataclasses.replace(prob, curve_one_way=one_way)
    return prob.group(0, prob.origin_xy), one_way


@pytest.mark.parametrize("seed", range(16))
def test_symmetric_model_takes_one_way_curves(seed):
    # a one-way curve is two nodes joined by its fixed edge with arcs into its entry and out of
    # its exit only: the symmetric model relaxes it (each edge the cheaper way round), the
    # directed model prices it exactly; what either proves is the subset DP's optimum
    auto.warm_up()
    grp, one_way = one_way_group(seed, n_lines=9 + seed % 4, n_one_way=1 + seed % 6, loops=seed % 2)
    assert symmetric_graph.applies(grp)
    assert (np.bincount(grp.cand_curve)[np.flatnonzero(one_way)] == 1).all()
    best = dp.solve(grp).objective
    start = np.array([int(np.flatnonzero(grp.cand_curve == c)[0]) for c in range(grp.n_curves)])
    # a deadline far past the few milliseconds these take: on a fresh clone the first call
    # compiles the directed model's kernels within it
    order, obj, bound, proven = symmetric.solve(grp, start, time.perf_counter() + 300.0)
    grp.check_order(order)
    assert obj == pytest.approx(grp.path_cost(order))
    assert bound <= best + OPTIMAL_ABS_TOL
    assert proven and obj <= best + OPTIMAL_ABS_TOL
    gs = auto.solve(grp, time_limit_s=5.0)
    grp.check_order(gs.order)
    assert gs.bound <= best + OPTIMAL_ABS_TOL
    assert gs.status == Status.OPTIMAL and gs.objective <= best + OPTIMAL_ABS_TOL


def test_paths_built_from_the_graph_visit_every_curve_when_all_are_one_way():
    # between two one-way curves' entries (or exits) there is no travel edge: the matching's
    # patching and the LP's greedy edge matching must still close one tour
    # (``symmetric_graph.joinable_costs``), and the path printed visits every curve its own way
    for seed in range(6):
        grp, _ = one_way_group(50 + seed, n_lines=14, n_one_way=14)
        assert grp.n_cands == grp.n_curves
        order, bound = symmetric_graph.matching_path(grp)
        grp.check_order(order)
        assert bound <= dp.solve(grp).objective + OPTIMAL_ABS_TOL
        model = symmetric.SymmetricModel(grp, np.arange(grp.n_curves))
        x = np.zeros(len(model.eu))          # no LP point: the tour is joined from the graph alone
        grp.check_order(model.tour_from(x))
