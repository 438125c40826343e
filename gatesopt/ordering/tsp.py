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
from .bounds import lower_bound
from .cpsat import closed_tour
from .problem import OPTIMAL_ABS_TOL, Group, GroupSolution


def cut_open(group: Group, tour: np.ndarray) -> np.ndarray:
    """Best open path from the start point obtained by deleting one link of the closed tour
    (walked as it is, or reversed with every curve flipped)."""
    tour = np.asarray(tour, np.int64)
    n = len(tour)
    if n == 1:
        return tour
    ds, de = group.start_cost(), group.end_cost()
    prev = np.roll(tour, 1)                               # the curve before position j
    link = group.link_cost(prev, tour)                    # link (j-1 -> j) of the tour
    fwd = ds[tour] + link.sum() - link + de[prev]         # start at tour[j], end at tour[j-1]
    # reversed: start at flip(tour[j-1]), walk backwards to flip(tour[j])
    flip = group.cand_flip
    back = group.link_cost(flip[tour], flip[prev])        # link flip(j) -> flip(j-1)
    rev = ds[flip[prev]] + back.sum() - back + de[flip[tour]]
    j_f, j_r = int(np.argmin(fwd)), int(np.argmin(rev))
    if fwd[j_f] <= rev[j_r]:
        return np.roll(tour, -j_f)
    back_order = np.roll(tour, -j_r)[::-1]                # tour[j-1], tour[j-2], ..., tour[j]
    return flip[back_order]


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          exact_max_curves: int = 60) -> GroupSolution:
    t0 = time.perf_counter()
    n = group.n_curves
    if n <= 1:
        order = np.zeros(0, np.int64) if n == 0 else np.array(
            [int(np.argmin(group.start_cost() + group.end_cost()))])
        obj = group.path_cost(order)
        return GroupSolution.make(order, obj, obj, Status.OPTIMAL, time.perf_counter() - t0, "tsp")
    tour = None
    if n <= exact_max_curves:
        res = closed_tour(group, time_limit_s=time_limit_s)
        tour = None if res is None else res[0]
    if tour is None:
        tour = greedy.improve(group, greedy.nearest_neighbour(group), closed=True)
    order = cut_open(group, tour)
    obj = group.path_cost(order)
    lb = lower_bound(group)
    status = Status.OPTIMAL if obj - lb <= OPTIMAL_ABS_TOL else Status.FEASIBLE
    return GroupSolution.make(order, obj, lb, status, time.perf_counter() - t0, "tsp")
