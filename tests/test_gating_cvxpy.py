"""The gating problem exported as a cvxpy model (gatesopt.gating.cvxpy_model): its optimum is the
brute-force optimum and milp's on the tiny instances of test_gating_solvers, budgets and the
non-additive XY term included, and a constraint a planner adds is honoured."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gatesopt.gating import from_moves, score, solve

from test_gating_solvers import brute_force, check_solution, small_problem, with_xy_off

cp = pytest.importorskip("cvxpy")
if "HIGHS" not in cp.installed_solvers():
    pytest.skip("cvxpy has no HiGHS (highspy) here", allow_module_level=True)

from gatesopt.gating import cvxpy_model  # noqa: E402


@pytest.mark.parametrize("opts", [
    {},
    {"stall_off_s": 0.3, "on_line": False, "merge_lines": False},          # Klipper-like
    {"stall_off_s": 0.05, "merge_lines": True},                              # Marlin-like, shared stalls
    {"max_added_lines_pct": 60.0},
    {"stall_off_s": 0.05, "max_added_time_pct": 2.0, "max_added_lines_pct": 80.0},
    {"rotate": "auto", "max_angles": 2, "stall_off_s": 0.02, "max_added_lines_pct": 50.0,
     "max_added_time_pct": 1.0},
    {"motors": ("X", "Y", "E"), "stall_off_s": 0.02, "max_added_lines_pct": 80.0},
    {"shared_enable": (("X", "Y"),), "stall_off_s": 0.05, "max_added_lines_pct": 60.0},
    {"max_added_lines_pct": 0.0},
])
def test_cvxpy_optimum_is_the_brute_force_and_milp_optimum(opts):
    p = small_problem(**opts)
    best = brute_force(p)
    sol = cvxpy_model.solve(p)
    check_solution(sol)
    assert sol.status == "optimal" and sol.formulation == "cvxpy"
    assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6) and sol.lines_added == best[1]
    m = solve(p, "milp")
    assert math.isclose(sol.energy_j, m.energy_j, abs_tol=1e-6) and sol.lines_added == m.lines_added


def test_cvxpy_non_additive_xy_power():
    p0 = small_problem()
    p = from_moves(p0.start_mm, p0.end_mm, p0.duration_s, p0.options, coeffs=with_xy_off(p0.coeffs, 3.0))
    m = cvxpy_model.to_cvxpy(p)
    assert m.xy_both_off is not None and len(m.model.a_pairs) > 0
    m.problem.solve(solver="HIGHS")
    sol = m.solution()
    check_solution(sol)
    assert math.isclose(sol.energy_j, brute_force(p)[0], abs_tol=1e-6)
    # the model's objective is the re-scored energy plus the line weight
    assert m.problem.value == pytest.approx(sol.energy_j + cvxpy_model.LINE_WEIGHT_J * sol.lines_added,
                                            abs=1e-6)


def test_a_planners_constraint_is_honoured():
    """A planner allows at most two off intervals: the answer is the best over such subsets."""
    p = small_problem(stall_off_s=0.05)
    m = cvxpy_model.to_cvxpy(p)
    free = solve(p, "milp")
    assert len(free.off_motor) > 2
    constrained = cp.Problem(m.problem.objective, m.problem.constraints + [cp.sum(m.off) <= 2])
    constrained.solve(solver="HIGHS")
    sol = m.solution(constrained)
    check_solution(sol)
    best = None
    g = p.idle_intervals_of(0)
    for r in range(3):
        for sub in itertools.combinations(g, r):
            sub = np.array(sub, np.int64)
            sc = score(p, p.idle_motor[sub], p.idle_start_s[sub], p.idle_end_s[sub])
            best = min(best or (math.inf, 0), (sc.energy_j, sc.lines_added))
    assert len(sol.off_motor) <= 2
    assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6) and sol.energy_j > free.energy_j
