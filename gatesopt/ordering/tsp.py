"""Fleming et al., Algorithm 1 ("Minimize-Material-Greedy"): a shortest *closed* tour through
the layer's curves, cut open at the curve that makes the layer cheapest given where the previous
layer ended (formulations/ordering.md, "tsp").

The paper takes the closed tour from Concorde (exact). Here it comes from CP-SAT's circuit model
(exact when it proves optimality within the limit; ``exact_max_curves`` caps its size) or, for
larger groups, from nearest neighbour + 2-opt/Or-opt on the closed tour. The cut also tries the
reversed tour (every curve flipped), which the paper does not: it can only help.
The result is a heuristic for the open path even when the tour is optimal (the paper says so).
"""
from __future__ import annotations

import time

import numpy as np

from ..solvers import Status
from . import greedy
from .bounds import lower_bound_mm
from .cpsat import closed_tour
from .problem import OPTIMAL_ABS_TOL_MM, Group, GroupSolution


def cut_open(group: Group, tour: np.ndarray) -> np.ndarray:
    """Best open path from the start point obtained by deleting one link of the closed tour."""
    tour = np.asarray(tour, np.int64)
    n = len(tour)
    ent, ext = group.cand_entry_xy[tour], group.cand_exit_xy[tour]
    prev_ext = np.roll(ext, 1, axis=0)                    # exit of the curve before position j
    link = np.hypot(*(ent - prev_ext).T)                  # link (j-1 -> j) of the tour
    total = link.sum()
    fwd = np.hypot(*(ent - group.start_xy).T) + total - link           # start at tour[j]
    rev = np.hypot(*(prev_ext - group.start_xy).T) + total - link      # start at flip(tour[j-1]), backwards
    if group.end_xy is not None:    # ... and travel on to the end point from the path's last exit
        fwd = fwd + np.hypot(*(prev_ext - group.end_xy).T)
        rev = rev + np.hypot(*(ent - group.end_xy).T)
    j_f, j_r = int(np.argmin(fwd)), int(np.argmin(rev))
    if n == 1 or fwd[j_f] <= rev[j_r]:
        return np.roll(tour, -j_f)
    back = np.roll(tour, -j_r)[::-1]                      # tour[j-1], tour[j-2], ..., tour[j]
    return group.cand_flip[back]


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          exact_max_curves: int = 60) -> GroupSolution:
    t0 = time.perf_counter()
    n = group.n_curves
    if n <= 1:
        order = np.zeros(0, np.int64) if n == 0 else np.array(
            [int(np.argmin(group.start_cost_mm() + group.end_cost_mm()))])
        obj = group.path_cost_mm(order)
        return GroupSolution.make(order, obj, obj, Status.OPTIMAL, time.perf_counter() - t0, "tsp")
    tour = None
    if n <= exact_max_curves:
        res = closed_tour(group, time_limit_s=time_limit_s)
        tour = None if res is None else res[0]
    if tour is None:
        tour = greedy.improve(group, greedy.nearest_neighbour(group), closed=True)
    order = cut_open(group, tour)
    obj = group.path_cost_mm(order)
    lb = lower_bound_mm(group)
    status = Status.OPTIMAL if obj - lb <= OPTIMAL_ABS_TOL_MM else Status.FEASIBLE
    return GroupSolution.make(order, obj, lb, status, time.perf_counter() - t0, "tsp")
