"""The ``greedy`` formulation's solve of one group: what ``--formulation greedy`` and an exact
run's greedy pass (``layers.solve_greedy``) give every group (issue 36; formulations/ordering.md,
"greedy").

- A group of at most ``budget.DP_CURVES`` curves that the subset DP takes (``dp.fits``) is solved
  exactly there (``dp.py``: auto's first step): on the Cura bunny 113 groups in 0.08 s in all, so
  they count as proven even where a budget leaves the exact solve no time (before, the greedy pass
  gave them greedy's path and the exact phase, out of time, never proved them).
- Every other group: nearest neighbour, 2-opt, Or-opt and the orientation DP (``greedy.solve``)
  with the cheap bound.
- Then, where the bound did not close and the matching step of auto applies
  (``matching_applies``: the symmetric model's groups, at most ``MATCHING_MAX_CURVES`` curves) and
  the caller allows it (``with_matching``: the greedy chain's work plan, ``budget.WorkPlan``, where it
  is paid for), the cheapest perfect matching's bound and its path polished by the local search
  (``matching_path``): the better path, the better bound.

Every step is deterministic (no clock is read), so a group's answer depends on the group alone.
"""
from __future__ import annotations

import time

from ..solvers import Status
from . import dp, greedy, matching, symmetric_graph
from .budget import DP_CURVES
from .problem import OPTIMAL_ABS_TOL, Group, GroupSolution

#: the matching step runs on groups of at most this many curves in the greedy pass, where it is
#: cheap and proves: on the Cura bunny (groups greedy's bound left open, docs/BENCHMARKS.md,
#: "Greedy pass work units"), safe mode, 13-20 curves 112 groups 0.05 s CPU 42 proven, 21-40 257
#: groups 0.21 s 11 proven, 41-80 173 groups 0.32 s none proven, 81-200 399 groups 13.6 s none
#: proven; the exact phase runs it on the larger groups where it has time
MATCHING_MAX_CURVES = 40
#: formulation names of the greedy pass's steps (``budget.WorkPlan`` charges each its work)
DP_FORMULATION = "greedy:dp"
MATCHING_FORMULATION = "greedy+matching"


def dp_first(group: Group) -> bool:
    """Whether the group is solved by the subset DP (the module docstring)."""
    return 2 <= group.n_curves <= DP_CURVES and dp.fits(group)


def matching_applies(group: Group) -> bool:
    """Whether the matching step may run on the group (the module docstring)."""
    return (2 <= group.n_curves <= MATCHING_MAX_CURVES
            and 2 * group.n_curves + 2 <= matching.MAX_VERTICES and symmetric_graph.applies(group))


def matching_path(group: Group, heur: GroupSolution) -> GroupSolution:
    """The better of ``heur`` and the matching's path (``symmetric_graph.matching_path``,
    polished by the greedy local search), with the better of the two bounds."""
    order, bound = symmetric_graph.matching_path(group)
    bound = max(bound, heur.bound)
    best, obj, formulation = heur.order, heur.objective, heur.formulation
    if order is not None:
        order = greedy.improve(group, order)
        o = group.path_cost(order)
        if o < obj - 1e-9:
            best, obj, formulation = order, o, "matching"
    status = Status.OPTIMAL if obj - bound <= OPTIMAL_ABS_TOL else Status.FEASIBLE
    return GroupSolution.make(best, obj, bound, status, heur.solve_s, formulation)


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          with_matching: bool = True) -> GroupSolution:
    """The group's answer (module docstring); ``time_limit_s`` is not needed: every step runs to
    its end. ``hint``: greedy's local search starts from it (no DP then: a caller with a path
    wants it improved)."""
    t0 = time.perf_counter()
    if hint is None and dp_first(group):
        ex = dp.solve(group)
        return GroupSolution.make(ex.order, ex.objective, ex.bound, Status.OPTIMAL,
                                  time.perf_counter() - t0, DP_FORMULATION)
    heur = greedy.solve(group, hint=hint)
    if heur.status == Status.OPTIMAL or not with_matching or not matching_applies(group):
        return heur
    got = matching_path(group, heur)
    return GroupSolution.make(got.order, got.objective, got.bound, got.status,
                              time.perf_counter() - t0, MATCHING_FORMULATION)
