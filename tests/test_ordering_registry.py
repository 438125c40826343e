"""The curve ordering's formulation registry and its share of the solver vocabulary
(gatesopt.solvers): lazy imports, capabilities, statuses, the gap, errors a user can read."""
import subprocess
import sys

import numpy as np
import pytest

from gatesopt import solvers
from gatesopt.errors import GatesoptError
from gatesopt.ordering import (FORMULATIONS, GroupSolution, OrderingOptions, OrderingOptionsError,
                               from_polylines, solve)
from gatesopt.ordering.formulations import lookup
from gatesopt.ordering.problem import OPTIMAL_ABS_TOL


def test_importing_the_package_loads_no_solver_backend():
    """OR-Tools and HiGHS are imported when a formulation that needs them is first used, not by
    ``import gatesopt.ordering`` (a fresh interpreter: this one has them loaded already)."""
    code = ("import sys, gatesopt.ordering as o; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'ortools', 'highspy'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_record_names_an_importable_module_with_a_solve():
    for name, record in FORMULATIONS.items():
        assert record.name == name and record.is_installed()
        assert callable(record.load().solve)


def test_capabilities_say_what_the_driver_does():
    # the paper's baselines chain as the paper does; the exact formulations get look-ahead
    assert {n for n, f in FORMULATIONS.items() if "look_ahead" in f.capabilities} == {
        "cpsat", "milp", "auto", "dp"}
    assert {n for n, f in FORMULATIONS.items() if "exact" in f.capabilities} == {
        "cpsat", "milp", "auto", "dp"}
    assert {n for n, f in FORMULATIONS.items() if "warm_up" in f.capabilities} == {"milp", "auto"}
    # the CLI's choices: every formulation that takes groups of any size, in registry order
    assert tuple(n for n, f in FORMULATIONS.items() if "any_size" in f.capabilities) == (
        "greedy", "tsp", "cpsat", "milp", "auto")


def test_bad_formulations_and_options_are_one_line_errors():
    prob = from_polylines([[np.array([[0.0, 0.0], [1.0, 0.0]])]])
    for call in (lambda: lookup("nope"), lambda: solve(prob, "nope"),
                 lambda: solve(prob, "greedy", workers=3),
                 lambda: OrderingOptions(mode="fast"), lambda: OrderingOptions(objective="money"),
                 lambda: OrderingOptions(seam_candidates=0),
                 lambda: OrderingOptions(planner_family="prusa")):
        with pytest.raises(OrderingOptionsError) as err:
            call()
        assert isinstance(err.value, GatesoptError) and isinstance(err.value, ValueError)
        assert "\n" not in str(err.value)
    with pytest.raises(OrderingOptionsError, match="unknown ordering formulation 'nope': choose one "
                                                   "of greedy, tsp, cpsat, milp, auto, dp"):
        solve(prob, "nope")
    with pytest.raises(OrderingOptionsError, match="planner_family must be one of marlin, "):
        OrderingOptions(planner_family="Klipper")
    assert OrderingOptions(planner_family="klipper").planner_family == "klipper"


def test_group_solutions_speak_the_solver_vocabulary():
    a = GroupSolution.make([0, 1], 10.0, 9.0, "feasible", 0.0, "x")
    assert a.status is solvers.Status.FEASIBLE and a.status == "feasible"
    assert a.gap == pytest.approx(0.1) == solvers.relative_gap(10.0, 9.0)
    # within the absolute tolerance: no gap (and an optimal answer's bound is its objective)
    b = GroupSolution.make([0], 10.0, 10.0 - 0.5 * OPTIMAL_ABS_TOL, "feasible", 0.0, "x")
    assert b.gap == 0.0
    c = GroupSolution.make([0], 10.0, 3.0, "optimal", 0.0, "x")
    assert c.bound == 10.0 and c.gap == 0.0
    # no bound is the trivial bound 0 (travel is never negative): a gap of 1, never NaN
    d = GroupSolution.make([0], 10.0, -np.inf, "fallback", 0.0, "x")
    assert d.bound == 0.0 and d.gap == 1.0
    with pytest.raises(ValueError, match="unknown status"):
        GroupSolution.make([0], 1.0, 1.0, "fine", 0.0, "x")
