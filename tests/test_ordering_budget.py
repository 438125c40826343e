"""Budget plan (budget.BudgetPlan), auto's order of DP and symmetric model for 13-16 curves, and
the compiled kernels that replaced library calls (nearest-neighbour scan, union-find components):
each against the behaviour it must keep."""
from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from gatesopt.ordering import (auto, budget, dp, formulations, greedy, greedy_pass, layers,
                               symmetric_graph)
from gatesopt.ordering.polylines import from_polylines
from gatesopt.ordering.problem import GroupSolution, OrderingOptions
from gatesopt.ordering.runner import GroupRunner
from gatesopt.solvers import Formulation

from test_ordering import random_problem
from conftest import random_line_layers


def _stand_in(monkeypatch, name: str, fn) -> None:
    """Formulation ``name`` answered by ``fn`` in this process: its registry record points at this
    module, whose ``solve`` is ``fn`` while the test runs (a helper process, a fresh interpreter,
    still has the real one). Its paths are chained with look-ahead; no kernels are warmed up."""
    monkeypatch.setattr(sys.modules[__name__], "solve", fn, raising=False)
    monkeypatch.setitem(formulations.FORMULATIONS, name,
                        Formulation(name, __name__, capabilities=frozenset({"look_ahead"})))


def _shape(n):
    """What the plan charges per unit of the learnt ratio for an exact group of n curves."""
    return float(auto.exact_time_s(n)) * (n / budget.EXACT_SHAPE_CURVES) ** budget.EXACT_SHAPE_EXPONENT


def _charge(n, ratio):
    return min(ratio * _shape(n), float(auto.exact_time_s(n)))


def test_plan_charges_an_exact_group_by_a_shape_that_grows_faster_than_its_exact_time():
    sizes = [150, 20]
    prob = from_polylines(random_line_layers(sizes, seed=2), options=OrderingOptions(mode="free"))
    plan = budget.BudgetPlan(prob)
    # small groups use a smaller share of their exact time than large ones (measured on the
    # corpus): one learnt ratio, applied to a shape growing with n, charges them less
    share = plan.shape_s / plan.exact_s                 # sorted by size: 20, then 150
    assert list(plan.curves) == [20, 150] and share[0] < share[1]
    assert share == pytest.approx([_shape(n) / float(auto.exact_time_s(n)) for n in (20, 150)])
    # proofs that used 50 times their shape: the ratio is far above 1, but a group is never
    # charged more than its exact time, so what pays that time still gets it
    plan.measured(0, float(auto.exact_time_s(150)), 50 * _shape(150))
    assert plan.used_ratio * _shape(20) > float(auto.exact_time_s(20))
    left = float(auto.exact_time_s(20)) + budget.HEURISTIC_S_PER_CURVE * 150 + 0.001
    assert plan.limit(1, left) >= float(auto.exact_time_s(20))


def test_plan_gives_the_smallest_groups_their_exact_time_first():
    sizes = [80, 20, 150, 30, 5, 60]          # 5 curves: the DP's, no claim on the budget
    prob = from_polylines(random_line_layers(sizes), options=OrderingOptions(mode="free"))
    plan = budget.BudgetPlan(prob)
    exact = {n: float(auto.exact_time_s(n)) for n in sizes}
    heur = {n: budget.HEURISTIC_S_PER_CURVE * n for n in sizes}
    # an exact group is charged its shape times the ratio proofs used of it so far
    r = plan.used_ratio
    assert r == pytest.approx(budget.EXACT_PRIOR_RATIO)
    # enough for the charge of 20 and 30, heuristic for the rest, and 1 ms to spare
    left = _charge(20, r) + _charge(30, r) + heur[80] + heur[150] + heur[60] + 0.001
    scale = left / (left - 0.001)
    assert plan.limit(1, left) == pytest.approx(exact[20] * scale)    # given its whole exact time
    assert plan.limit(3, left) == pytest.approx(exact[30] * scale)
    assert plan.limit(0, left) == pytest.approx(heur[80] * scale)
    assert plan.limit(0, left) < auto.exact_time_s(80)     # auto will not start the model on it
    assert plan.limit(4, left) == left                      # no claim: capped by what is left
    # once 20 and 30 are done, the time they left unused pays the exact time of 60 too
    plan.done(1), plan.done(3)
    left = _charge(60, r) + heur[80] + heur[150] + 0.001
    assert plan.limit(5, left) >= exact[60]
    assert plan.limit(2, left) < exact[150]


def test_plan_learns_what_proofs_use_of_their_exact_time():
    sizes = [80, 20, 150, 30, 60]
    prob = from_polylines(random_line_layers(sizes, seed=4), options=OrderingOptions(mode="free"))
    plan = budget.BudgetPlan(prob)
    exact = {n: float(auto.exact_time_s(n)) for n in sizes}
    heur = {n: budget.HEURISTIC_S_PER_CURVE * n for n in sizes}
    # a group given less than its exact time did not try the exact step: not counted
    plan.measured(0, 0.5 * exact[80], 0.5 * exact[80])
    assert plan.used_ratio == pytest.approx(budget.EXACT_PRIOR_RATIO)
    # two proofs that took 1 % of their exact time: the ratio falls towards it
    for g, n in ((1, 20), (3, 30)):
        plan.measured(g, exact[n], 0.01 * exact[n])
        plan.done(g)
    learnt = ((budget.EXACT_PRIOR_RATIO * budget.EXACT_PRIOR_S + 0.01 * (exact[20] + exact[30]))
              / (budget.EXACT_PRIOR_S + _shape(20) + _shape(30)))
    assert plan.used_ratio == pytest.approx(learnt)
    assert learnt < 0.85 * budget.EXACT_PRIOR_RATIO
    # what is left pays for the exact time of 60 and 80 at the learnt ratio, not at the prior
    left = _charge(60, learnt) + _charge(80, learnt) + heur[150] + 0.001
    assert left < _charge(60, budget.EXACT_PRIOR_RATIO) + _charge(80, budget.EXACT_PRIOR_RATIO) + heur[150]
    assert plan.limit(0, left) >= exact[80]          # planned exact
    assert plan.limit(2, left) < exact[150]


def test_plan_funds_the_smallest_groups_first_when_even_the_heuristic_share_does_not_fit():
    # what is left pays less than every group's heuristic time: the smallest group gets all of
    # it, the larger none (None: the slicer's order, unsearched), instead of each a share too
    # thin for the greedy path that runs whatever its limit
    sizes = [50, 40]
    prob = from_polylines(random_line_layers(sizes, seed=1), options=OrderingOptions(mode="free"))
    plan = budget.BudgetPlan(prob)
    heur = {n: budget.HEURISTIC_S_PER_CURVE * n for n in sizes}
    left = 0.5 * sum(heur.values())
    assert heur[40] <= left < _charge(40, plan.used_ratio)      # no exact time fits
    assert plan.limit(1, left) == pytest.approx(left)           # 40 curves: heuristic, all of it
    assert plan.limit(0, left) is None                          # 50 curves: none
    # with every heuristic time paid the plan is as before: the 50 gets its heuristic share
    left = sum(heur.values()) + 0.001
    assert plan.limit(0, left) == pytest.approx(heur[50] * left / sum(heur.values()))


def test_plan_counts_the_time_objectives_link_matrix_in_a_groups_heuristic_time():
    lines = random_line_layers([30], seed=3)
    plain = budget.BudgetPlan(from_polylines(lines, options=OrderingOptions(mode="free")))
    assert plain.heuristic_s[0] == pytest.approx(budget.HEURISTIC_S_PER_CURVE * 30)
    priced = dataclasses.replace(from_polylines(lines, options=OrderingOptions(mode="free")),
                                 pricer=object())
    plan = budget.BudgetPlan(priced)
    assert plan.heuristic_s[0] == pytest.approx(budget.HEURISTIC_S_PER_CURVE * 30
                                                + budget.MATRIX_S_PER_LINK * 60 ** 2)


def test_budgeted_solve_gives_small_groups_the_exact_time_first(monkeypatch):
    # a budget that pays for the exact step on the small groups only: what each group is given
    # (recorded by a stand-in for auto that answers at once), not how long anything took
    sizes = [200, 20, 200, 22, 24]
    prob = from_polylines(random_line_layers(sizes, seed=2), options=OrderingOptions(mode="free"))
    given = {}

    def record(grp, *, time_limit_s, **kw):     # the slicer's order, at once
        given[grp.n_curves] = time_limit_s
        order = np.flatnonzero(~grp.cand_reversed & (grp.cand_seam == 0))
        obj = grp.path_cost(order)
        return GroupSolution.make(order, obj, 0.0, "fallback", 0.0, "stand-in")

    _stand_in(monkeypatch, "auto", record)
    layers.solve(prob, "auto", time_limit_s=2.0, budget_s=0.4)
    assert all(given[n] >= auto.exact_time_s(n) for n in (20, 22, 24)), given
    assert given[200] < auto.exact_time_s(200), given


def test_a_group_never_gets_more_than_the_wall_clock_time_left(monkeypatch):
    # with a helper both processes spend the time left at once (twice the seconds to share), but
    # one group runs in one process: its limit must end before the budget, less what the main
    # process needs for the groups after it (a group of 150 curves alone would get ~2x 0.5 s)
    sizes = [150, 3, 3]
    prob = from_polylines(random_line_layers(sizes, seed=3), options=OrderingOptions(mode="free"))
    given = []

    def record(grp, *, time_limit_s, **kw):
        given.append(time_limit_s)
        order = np.arange(grp.n_curves) * 2
        return GroupSolution.make(order, grp.path_cost(order), 0.0, "fallback", 0.0, "stand-in")

    import time
    runner = GroupRunner(prob, record, 5.0, 0.5, time.perf_counter(), {}, other_alive=lambda: True)
    runner.run(0, prob.group(0, prob.origin_xy))
    after = budget.OVERHEAD_S_PER_CURVE * 6 + budget.TAIL_S_PER_CURVE * 156
    assert runner.rest_s(0) == pytest.approx(after)
    assert 0.4 < given[0] <= 0.5 - after, given


@pytest.mark.parametrize("seed", range(4))
def test_auto_tries_the_model_before_the_dp_above_12_curves_and_stays_exact(seed, monkeypatch):
    auto.warm_up()          # on a fresh clone the first call compiles the kernels (seconds)
    prob = random_problem(700 + seed, 14, closed_share=0.0, clustered=seed % 2 == 0)
    grp = prob.group(0, prob.origin_xy)
    assert dp.fits(grp) and symmetric_graph.applies(grp)
    opt = dp.solve(grp).objective
    a = auto.solve(grp, time_limit_s=5.0)
    assert a.status == "optimal" and a.formulation in ("auto:milp", "auto:bound", "auto:matching",
                                                    "auto:ils+bound")
    assert a.objective == pytest.approx(opt, abs=1e-6)
    # a limit below the DP's own time (it cannot be stopped): no DP, the heuristic path, never
    # called optimal unless it is
    assert dp.time_s(grp) > 1e-4
    b = auto.solve(grp, time_limit_s=1e-4)
    assert b.formulation != "auto:dp" and b.objective >= opt - 1e-6
    assert b.status != "optimal" or b.objective == pytest.approx(opt, abs=1e-6)
    # no time for the model but enough for the DP (by its estimate): the DP, still exact
    monkeypatch.setattr(dp, "S_PER_WORK", 1e-4 / dp.work(grp))
    c = auto.solve(grp, time_limit_s=2e-4)
    assert c.status == "optimal" and c.formulation == "auto:dp"
    assert c.objective == pytest.approx(opt, abs=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_nearest_neighbour_scan_equals_the_kd_tree_walk(seed, monkeypatch):
    prob = random_problem(seed, 40 + 10 * seed, closed_share=0.3, move_seams=seed % 2 == 1)
    grp = prob.group(0, prob.origin_xy)
    scan = greedy.nearest_neighbour(grp)
    first = int(grp.n_cands // 2)
    scan_first = greedy.nearest_neighbour(grp, first=first)
    monkeypatch.setattr(greedy, "NN_SCAN_MAX_CANDS", -1)      # force the KD-tree walk
    np.testing.assert_array_equal(scan, greedy.nearest_neighbour(grp))
    np.testing.assert_array_equal(scan_first, greedy.nearest_neighbour(grp, first=first))
    assert scan_first[0] == first


@pytest.mark.parametrize("seed", range(5))
def test_components_equal_scipy(seed):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    rng = np.random.default_rng(seed)
    n = 30 + 20 * seed
    m = rng.integers(0, 2 * n)
    r, c = rng.integers(0, n, m), rng.integers(0, n, m)
    k, lab = symmetric_graph.components(n, r, c)
    k2, lab2 = connected_components(coo_matrix((np.ones(m), (r, c)), shape=(n, n)), directed=False)
    assert k == k2
    np.testing.assert_array_equal(lab, lab2)


def _walls_and_infill(n_layers=20, seed=5):
    """Safe-mode-like problem: each layer a fixed group (walls) then a free group (infill), so every
    free group's start is known in advance (the helper process's groups)."""
    rng = np.random.default_rng(seed)
    groups, fixed = [], []
    for i in range(n_layers):
        groups.append([rng.uniform(0, 60, (3, 2)) for _ in range(3)])
        fixed.append(len(groups) - 1)
        groups.append([rng.uniform(0, 60, (2, 2)) for _ in range(10 + i % 7)])
    return from_polylines(groups, options=OrderingOptions(mode="free"), fixed_layers=fixed)


def test_helper_process_gives_the_same_answer_as_one_process(monkeypatch):
    import time
    from gatesopt.ordering import helper
    prob = _walls_and_infill()
    assert len(helper.groups_to_solve(prob)) >= helper.HELPER_MIN_GROUPS
    one = layers.solve(prob, "greedy", time_limit_s=1.0, workers=1)
    # the main process is made slow (the helper, a fresh interpreter, is not): the helper must
    # answer most groups, and its answers must be the ones one process finds
    calls = []

    def slow_greedy(grp, **kw):
        calls.append(grp.n_curves)
        time.sleep(0.4)         # 20 groups: 8 s, time for a fresh interpreter to compile and answer
        return greedy_pass.solve(grp, **kw)     # what the helper's "greedy" runs

    _stand_in(monkeypatch, "greedy", slow_greedy)
    two = layers.solve(prob, "greedy", time_limit_s=1.0, workers=2)
    assert len(calls) < len(helper.groups_to_solve(prob)), "the helper answered no group"
    np.testing.assert_array_equal(one.curve_order, two.curve_order)
    np.testing.assert_array_equal(one.curve_reversed, two.curve_reversed)
    assert one.travel_after_mm == pytest.approx(two.travel_after_mm)


def test_a_helper_that_dies_leaves_the_main_process_to_finish(monkeypatch):
    # (auto: its exact pass has the chain helper; greedy chains in one process and starts a
    # helper only to make link matrices, none on this small travel-objective problem)
    import subprocess
    import sys
    from gatesopt.ordering import child
    real = subprocess.Popen
    started = []

    def broken(args, **kw):     # the helper exits at once, before answering anything
        started.append(args)
        return real([sys.executable, "-c", "import sys; sys.exit(3)"], **kw)

    monkeypatch.setattr(child.subprocess, "Popen", broken)
    prob = _walls_and_infill(seed=6)
    one = layers.solve(prob, "auto", time_limit_s=1.0, workers=1)
    two = layers.solve(prob, "auto", time_limit_s=1.0, workers=2)
    assert len(started) == 1, "the helper was not started: the test would prove nothing"
    np.testing.assert_array_equal(one.curve_order, two.curve_order)


def _brute_free_start(grp):
    """Shortest path over every order and direction, without the travel into the first curve."""
    import itertools
    best = np.inf
    cands = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    for perm in itertools.permutations(range(grp.n_curves)):
        for pick in itertools.product(*[cands[c] for c in perm]):
            o = np.asarray(pick)
            best = min(best, grp.path_cost(o) - float(np.hypot(*(grp.cand_entry_xy[o[0]] - grp.start_xy))))
    return best


@pytest.mark.parametrize("seed", range(4))
def test_backwards_group_costs_the_path_without_its_first_travel(seed):
    rng = np.random.default_rng(seed)
    lines = [rng.uniform(0, 40, (2, 2)) for _ in range(6)] + [np.array([[5.0, 5], [9, 5], [9, 9], [5, 5]])]
    prob = from_polylines([lines], options=OrderingOptions(mode="free"))
    end = rng.uniform(0, 40, 2)
    grp = prob.group(0, rng.uniform(0, 40, 2), end)
    back = grp.backwards()
    assert back.end_xy is None and np.array_equal(back.start_xy, end)
    for _ in range(20):
        order = np.array([rng.choice(np.flatnonzero(grp.cand_curve == c)) for c in rng.permutation(grp.n_curves)])
        first = float(np.hypot(*(grp.cand_entry_xy[order[0]] - grp.start_xy)))
        assert back.path_cost(order[::-1]) == pytest.approx(grp.path_cost(order) - first)
    with pytest.raises(ValueError):
        prob.group(0, end).backwards()


def _chain_only(n_layers=24, seed=7):
    """Free mode without fixed groups: every group's start is the previous group's end, so only
    the first group's start is known in advance."""
    rng = np.random.default_rng(seed)
    return from_polylines([[rng.uniform(0, 60, (2, 2)) for _ in range(4 + i % 2)] for i in range(n_layers)],
                          options=OrderingOptions(mode="free"))


def test_helper_solves_the_chain_from_the_back(monkeypatch):
    import time
    prob = _chain_only()
    calls = []

    def slow_dp(grp, **kw):             # the main process only: the helper is a fresh interpreter
        calls.append(grp.n_curves)
        time.sleep(0.4)
        return dp.solve(grp, **kw)

    _stand_in(monkeypatch, "dp", slow_dp)
    two = layers.solve(prob, "dp", workers=2)
    assert len(calls) < prob.n_groups, "the helper answered no group"
    back = [g for g, gs in enumerate(two.groups) if gs.formulation.endswith("+back")]
    assert back, "no group was solved from the back"
    checked = 0
    for g in back:
        gs, nxt = two.groups[g], (two.groups[g + 1] if g + 1 < prob.n_groups else None)
        if nxt is None or "+kept" in nxt.formulation or "+kept" in gs.formulation:
            continue
        # proven optimal for its end (the entry of the next group's path), its start free
        entry = prob.group(g + 1, np.zeros(2)).cand_entry_xy[nxt.order[0]]
        grp = prob.group(g, np.zeros(2), entry)
        assert gs.status == "optimal"
        assert gs.objective == pytest.approx(_brute_free_start(grp), abs=1e-6)
        first = float(np.hypot(*(grp.cand_entry_xy[gs.order[0]] - grp.start_xy)))
        assert grp.path_cost(gs.order) - first == pytest.approx(gs.objective, abs=1e-6)
        checked += 1
    assert checked >= 3
    # the file's last group was solved from a guessed start and scored from the real one: its
    # bound must hold from there
    last, prev = two.groups[-1], two.groups[-2]
    if "+kept" not in prev.formulation:
        start = prob.group(prob.n_groups - 2, np.zeros(2)).cand_exit_xy[prev.order[-1]]
        grp = prob.group(prob.n_groups - 1, start)
        assert last.objective == pytest.approx(grp.path_cost(last.order))
        assert last.bound <= dp.solve(grp).objective + 1e-6
    assert two.travel_after_mm <= two.travel_before_mm + 1e-9


def test_a_budget_is_for_the_whole_run_and_the_solve_gets_what_the_rest_leaves():
    from gatesopt.rewrite.order import FINISH_FIXED_S, FINISH_S_PER_LINE, solve_budget_s
    assert solve_budget_s(None, 10 ** 6, 3.0) is None
    assert solve_budget_s(10.0, 100_000, 0.5) == pytest.approx(
        10.0 - 0.5 - FINISH_FIXED_S - 100_000 * FINISH_S_PER_LINE)
    # a file whose emit alone would take longer than the budget: the solve gets nothing (every
    # group keeps the slicer's order), never a share past the budget's end
    assert solve_budget_s(10.0, 10 ** 8, 0.5) == 0.0


def test_order_program_counts_the_budget_from_when_the_run_started(monkeypatch):
    import time

    import gatesopt
    from gatesopt import _jit
    from gatesopt.rewrite import order as pipeline

    from conftest import PROJECT_INSTANCES
    prog = gatesopt.parse(str(PROJECT_INSTANCES / "star_lines_m82.gcode"))
    seen, greedy_s = [], []
    real, real_greedy = pipeline.solve, pipeline.solve_greedy

    def spy(problem, formulation="auto", **kw):
        seen.append(kw["budget_s"])
        return real(problem, formulation, **kw)

    def spy_greedy(problem, **kw):      # the greedy pass before the exact solve: its time
        t = time.perf_counter()
        out = real_greedy(problem, **kw)
        greedy_s.append(time.perf_counter() - t)
        return out

    monkeypatch.setattr(pipeline, "solve", spy)
    monkeypatch.setattr(pipeline, "solve_greedy", spy_greedy)
    est = pipeline.FINISH_FIXED_S + pipeline.FINISH_S_PER_LINE * prog.n_lines
    res = pipeline.order_program(prog, OrderingOptions(mode="free"), budget_s=10.0)
    # a parse that took 4 s before order_program was called counts against the budget; numba
    # loading (or compiling) kernels in those 4 s (the first call above, when this test runs
    # first in its process) does not
    started = time.perf_counter() - 4.0
    pipeline.order_program(prog, OrderingOptions(mode="free"), budget_s=10.0, started_s=started)
    not_charged = _jit.compile_s_since(started)
    pipeline.order_program(prog, OrderingOptions(mode="free"))
    # the exact solve gets what the greedy pass before it left (issue 36: greedy orders every
    # group first, with the whole solve's budget but the guard's second stage)
    assert len(greedy_s) == 3
    assert seen[0] <= 10.0 - est and seen[2] is None
    assert seen[1] <= 10.0 - est - 4.0 + not_charged
    assert res.ok and res.summary["budget_s"] == 10.0
    solve_budget = res.summary["solve_budget_s"]
    # less the guard's second stage that greedy's answer adds after the solve, at the measured
    # slowdown of the work after it (at least 1, at most budget.MAX_SLOWDOWN)
    stage = pipeline.GUARD_STAGE_S_PER_LINE * prog.n_lines
    assert solve_budget - greedy_s[0] - 4.0 * stage <= seen[0] <= solve_budget - stage


def test_one_slow_group_early_does_not_starve_the_groups_after_it(monkeypatch):
    # the first group runs 0.15 s past its limit (as when the helper process starts beside it on
    # a busy machine). The reserve for the groups to come is an overrun per curve, from a prior:
    # a mean per group times the groups to come reserved 0.15 s for each of the 60 groups here,
    # and the next four were given no time at all
    import time
    sizes = [150] + [20] * 60
    prob = from_polylines(random_line_layers(sizes, seed=4), options=OrderingOptions(mode="free"))
    given = []

    def record(grp, *, time_limit_s, **kw):
        if not given:
            end = time.perf_counter() + time_limit_s + 0.15
            while time.perf_counter() < end:
                pass
        given.append((grp.n_curves, time_limit_s))
        order = np.flatnonzero(~grp.cand_reversed & (grp.cand_seam == 0))
        return GroupSolution.make(order, grp.path_cost(order), 0.0, "fallback", 0.0, "stand-in")

    _stand_in(monkeypatch, "auto", record)
    layers.solve(prob, "auto", time_limit_s=2.0, budget_s=2.0)
    small = [lim for n, lim in given if n == 20]
    assert len(small) == 60
    assert all(lim >= auto.exact_time_s(20) for lim in small), small


def test_a_fallback_group_runs_ils_only_when_its_limit_leaves_time_for_it(monkeypatch):
    from gatesopt.ordering import ils
    auto.warm_up()          # a first call loading the kernels would pass any deadline by itself
    prob = from_polylines(random_line_layers([60], seed=7), options=OrderingOptions(mode="free"))
    grp = prob.group(0, prob.origin_xy)
    calls = []
    real = ils.improve_ils

    def spy(*a, **kw):
        calls.append(kw.get("deadline"))
        return real(*a, **kw)

    monkeypatch.setattr(ils, "improve_ils", spy)
    # below exact_time_s, so no exact step, and less than MIN_FALLBACK_ILS_S_PER_CURVE per curve
    # (minus what the greedy path and the matching take): those two only
    limit = 0.95 * auto.MIN_FALLBACK_ILS_S_PER_CURVE * grp.n_curves
    assert limit < auto.exact_time_s(grp.n_curves)
    small = auto.solve(grp, time_limit_s=limit)
    assert small.status in ("fallback", "optimal") and calls == []
    assert small.formulation in ("auto:greedy", "auto:matching", "auto:bound")
    # no exact step for this group (none may take it), and time enough: ILS runs
    monkeypatch.setattr(auto, "SYMMETRIC_MAX_CANDS", 0)
    monkeypatch.setattr(auto, "EXACT_MAX_CANDS", 0)
    big = auto.solve(grp, time_limit_s=0.2)
    if small.status != "optimal":
        assert len(calls) == 1 and big.formulation == "auto:ils"
        assert big.objective <= small.objective + 1e-9
