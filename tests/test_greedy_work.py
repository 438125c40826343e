"""The greedy pass's budget is work, not wall-clock (issue 36: the same numbers from every
command): which groups greedy orders, and how, follows from counts (``budget.WorkPlan``), so a
clock running fast or slow, a second worker making the matrices, or a loaded machine give the
same answer; small groups are solved exactly by the subset DP in the pass itself and stay proven
where the exact phase gets no time; safe mode's block orders do not read the clock either."""
from __future__ import annotations

import time

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import budget, greedy_pass, layers, matrix_helper, runner
from gatesopt.ordering.groups import build
from gatesopt.ordering.problem import OrderingOptions
from gatesopt.ordering.runner import OUT_OF_TIME
from gatesopt.rewrite.guard import same_entry_groups
from gatesopt.rewrite.order import order_program
from gatesopt.solvers import Status

from conftest import PROJECT_INSTANCES, matrix_helper_first


def _same_answer(a, b) -> None:
    assert np.array_equal(a.curve_order, b.curve_order)
    assert np.array_equal(a.curve_reversed, b.curve_reversed)
    assert np.array_equal(a.curve_seam, b.curve_seam)
    assert [gs.formulation for gs in a.groups] == [gs.formulation for gs in b.groups]


def _problem(mode: str = "free"):
    return build(gatesopt.parse(str(PROJECT_INSTANCES / "star_lines_m82.gcode")),
                 OrderingOptions(mode=mode))


def _half_budget(prob) -> float:
    """A work budget that pays for the pass and about half of the groups' searches."""
    plan = budget.WorkPlan(prob, 0.0)
    reserve = -plan.left_s
    return reserve + 0.5 * float(plan.est_s.sum())


def _clock(monkeypatch, speed: float) -> None:
    """``time.perf_counter`` runs ``speed`` times as fast from now on (a loaded machine: > 1)."""
    real = time.perf_counter
    t0 = real()
    monkeypatch.setattr(time, "perf_counter", lambda: t0 + speed * (real() - t0))


def _late(sol) -> int:
    return sum(gs.formulation == OUT_OF_TIME for gs in sol.groups)


def test_the_greedy_pass_reads_no_clock_for_its_reach(monkeypatch):
    """One budget, the clock at 1x, 0.01x and 20x its speed: the same groups left out of time
    (some are, some are not), the same paths. Before, the budget was wall-clock: a fast clock
    left every group out of time, a slow one none."""
    prob = _problem()
    b = _half_budget(prob)
    ref = layers.solve(prob, "greedy", budget_s=b)
    assert 0 < _late(ref) < int(np.count_nonzero(prob.group_reorderable))
    assert not ref.work_net_fired
    for speed in (0.01, 20.0):
        with monkeypatch.context() as m:
            _clock(m, speed)
            got = layers.solve(prob, "greedy", budget_s=b)
        _same_answer(ref, got)
        assert not got.work_net_fired


def test_the_safety_net_fires_on_a_very_slow_machine(monkeypatch):
    """A clock far past the budget (``WORK_NET_FACTOR``): the groups after it keep the slicer's
    order and the solution says the net fired."""
    prob = _problem()
    b = _half_budget(prob)
    _clock(monkeypatch, 1e6)
    got = layers.solve(prob, "greedy", budget_s=b)
    assert got.work_net_fired
    assert _late(got) == int(np.count_nonzero(prob.group_reorderable))


def test_the_greedy_pass_is_the_same_with_two_workers_under_a_budget(monkeypatch):
    """With a budget that leaves groups out of time, the matrix helper making every matrix first
    changes nothing: its matrices are charged as if made in the main process. Before, the plan
    counted the helper's time as the pass's and reached more groups with two workers."""
    monkeypatch.setattr(matrix_helper, "MATRIX_HELPER_MIN_GROUPS", 2)
    monkeypatch.setattr(matrix_helper, "MATRIX_HELPER_MIN_S", 0.0)
    # waiting for the helper's fresh interpreter (seconds on a loaded machine) is not the net's
    monkeypatch.setattr(budget, "WORK_NET_MIN_S", 600.0)
    monkeypatch.setattr(runner, "WORK_NET_MIN_S", 600.0)
    prob = _problem()
    b = _half_budget(prob)
    one = layers.solve_greedy(prob, budget_s=b, workers=1)
    matrix_helper_first(monkeypatch)
    two = layers.solve_greedy(prob, budget_s=b, workers=2)
    assert two.handed                       # the helper made matrices
    assert 0 < _late(one.solution)
    assert not two.solution.work_net_fired
    _same_answer(one.solution, two.solution)


def test_small_groups_are_proven_by_the_dp_in_the_greedy_pass():
    """Groups the subset DP takes are solved exactly by the greedy formulation, under a budget
    too small for any larger group, and the exact solve after it with no time at all keeps
    them proven (before: greedy's path, status feasible, "kept" out of time)."""
    prob = _problem()
    small = [g for g in range(prob.n_groups) if prob.group_reorderable[g]
             and greedy_pass.dp_first(prob.group(g, prob.origin_xy))]
    assert small
    plan = budget.WorkPlan(prob, 0.0)
    b = -plan.left_s + float(plan.est_s[small].sum()) * 1.01
    gp = layers.solve_greedy(prob, budget_s=b)
    for g in small:
        assert gp.solution.groups[g].status == Status.OPTIMAL
        assert gp.solution.groups[g].formulation == greedy_pass.DP_FORMULATION
    exact = layers.solve(prob, "auto", budget_s=0.0, greedy=gp)
    for g in small:
        assert exact.groups[g].status == Status.OPTIMAL


def test_a_group_is_entered_alike_where_the_curve_before_it_is_printed_alike():
    """Turning the last curve of layer k around changes how the group after it (the first of
    layer k + 1) is entered, and nothing else; printing layer k backwards (it then ends on
    another curve) too, and the groups whose own order changed but whose entry did not are
    still entered alike."""
    import dataclasses
    prob = _problem()
    sol = layers.solve(prob, "greedy")
    assert same_entry_groups(prob, sol, sol).all()
    order = np.asarray(sol.curve_order)
    lay = np.asarray(prob.curve_layer)[order]
    glay = np.asarray(prob.group_layer)
    k = next(k for k in range(1, int(lay.max())) if np.count_nonzero(lay == k) >= 2)
    after = int(np.flatnonzero(glay == k + 1)[0])       # the first group of layer k + 1
    last = int(order[np.flatnonzero(lay == k)[-1]])
    rev = sol.curve_reversed.copy()
    rev[last] = ~rev[last]
    turned = dataclasses.replace(sol, curve_reversed=rev)
    assert np.flatnonzero(~same_entry_groups(prob, sol, turned)).tolist() == [after]
    at = np.flatnonzero(lay == k)
    backwards = order.copy()
    backwards[at] = order[at][::-1]
    other = dataclasses.replace(sol, curve_order=backwards)
    differ = np.flatnonzero(~same_entry_groups(prob, sol, other)).tolist()
    assert after in differ and all(glay[g] == k or g == after for g in differ)


@pytest.mark.parametrize("mode", ["safe", "free"])
def test_auto_is_never_slower_than_greedy_under_a_budget_that_leaves_groups_out(monkeypatch, mode):
    """A 10 s budget whose work (greedy's charges made 10^4 times dearer) pays for only some
    groups: greedy leaves groups out of time, and auto's file, guarded against the same greedy
    pass, prints no slower than greedy's; run twice, greedy's output is the same bytes."""
    program = gatesopt.parse(str(PROJECT_INSTANCES / "star_lines_m82.gcode"))
    prob = build(program, OrderingOptions(mode=mode))
    plan = budget.WorkPlan(prob, 0.0)
    # ~a third of the groups' searches fit in the ~9.8 s the budget leaves the solve
    scale = 9.8 / (float(plan.est_s.sum()) / 3.0)
    for name in ("WORK_GREEDY_S_PER_GROUP", "WORK_GREEDY_S_PER_LINK", "WORK_MATRIX_S_PER_LINK",
                 "WORK_DP_S_PER_GROUP", "WORK_DP_S_PER_STATE"):
        monkeypatch.setattr(budget, name, getattr(budget, name) * scale)
    opts = OrderingOptions(mode=mode)
    greedy = order_program(program, opts, formulation="greedy", budget_s=10.0)
    again = order_program(program, opts, formulation="greedy", budget_s=10.0)
    auto = order_program(program, opts, formulation="auto", budget_s=10.0)
    assert greedy.summary["groups_out_of_time"] > 0
    assert greedy.text == again.text
    assert (auto.summary["print_time_after_s"]
            <= greedy.summary["print_time_after_s"] + 1e-6)


def test_passing_many_small_groups_is_charged_per_group():
    # a plate of many one-island groups (safe mode's pin plates: ~0.35 ms a group to pass
    # whatever its size): a budget that pays the per-curve rates but not the per-group one funds
    # no group, one that pays both funds every group. Before, a Cura pin plate of 4,966 groups
    # was charged 0.1 s for passing them and its greedy pass ran 6 s on a 4.6 s budget
    from conftest import random_line_layers
    from gatesopt.ordering.polylines import from_polylines
    prob = from_polylines(random_line_layers([14] * 300, seed=9), options=OrderingOptions(mode="free"))
    per_curve = (budget.WORK_PASS_S_PER_CURVE + budget.WORK_TAIL_S_PER_CURVE) * prob.n_curves
    per_group = budget.WORK_PASS_S_PER_GROUP * prob.n_groups
    est = budget.WorkPlan(prob, 1e9).est_s
    assert per_group > 0.05
    short = budget.WorkPlan(prob, per_curve + 0.9 * per_group)
    assert not any(short.funds(g) for g in range(prob.n_groups) if prob.group_reorderable[g])
    enough = budget.WorkPlan(prob, per_curve + per_group + est.sum() + 1e-9)
    assert all(enough.funds(g) for g in range(prob.n_groups))
