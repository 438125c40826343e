"""``auto``: exact where it pays, heuristic where it must (formulations/ordering.md, "auto").

Per group: groups small enough for the subset DP (``dp.py``, up to ~12-16 curves) are solved
exactly there. Otherwise the greedy path (nearest neighbour + 2-opt/Or-opt + orientation DP) and the cheap
bound of ``bounds.py`` first — on real layers many groups are proven optimal right there (their
greedy path uses each curve's cheapest links). Otherwise, groups of at most ``exact_max_cands``
candidates go to the MILP warm-started with the greedy path, within the per-group time limit; the
rest keep the greedy path with status "fallback" and the cheap bound's gap.

The exact step is the HiGHS model of ``milp.py`` (the symmetric model with min-cut separated
subtour cuts where it applies; LP cutting-plane rounds first, then the solve–separate–re-solve
loop): on real infill groups it proved optimality about 10x faster than CP-SAT (26-curve Cura grid
groups: 0.11-0.15 s vs 1-3.6 s, same machine).
"""
from __future__ import annotations

import time

from . import dp, greedy, ils, milp
from .problem import OPTIMAL_ABS_TOL_MM, Group, GroupSolution

#: largest group (in candidates, i.e. ~2x curves) handed to the exact formulation (HiGHS: its
#: model has ~m^2 columns; beyond ~160 candidates it rarely closes the gap within seconds)
EXACT_MAX_CANDS = 160
#: below this per-group limit (a spent budget) the exact step is not even built
MIN_EXACT_S = 0.05
#: stop after the MILP's LP cutting-plane rounds if they leave more than this gap
GIVE_UP_GAP = None   # measured: with 0.15, free-mode Cura groups lost most proofs the branch loop finds


def solve(group: Group, *, time_limit_s: float = 2.0, hint=None,
          exact_max_cands: int = EXACT_MAX_CANDS) -> GroupSolution:
    t0 = time.perf_counter()
    if dp.fits(group):                             # small: exact by DP over subsets, sub-millisecond
        ex = dp.solve(group)
        return GroupSolution.make(ex.order, ex.objective_mm, ex.bound_mm, "optimal",
                                  time.perf_counter() - t0, "auto:dp")
    heur = greedy.solve(group, hint=hint)
    if heur.status == "optimal" or group.n_curves <= 1:
        return GroupSolution.make(heur.order, heur.objective_mm, heur.bound_mm, "optimal",
                                  time.perf_counter() - t0, "auto:bound")
    # escape the local optimum before anything else: a better incumbent is what lets the exact
    # step (or the bound) prove it, and what a fallback group keeps
    exact_next = group.n_cands <= exact_max_cands and time_limit_s >= MIN_EXACT_S
    share = ils.WARM_START_SHARE if exact_next else 1.0
    order = ils.improve_ils(group, heur.order, deadline=t0 + share * time_limit_s)
    obj = group.path_cost_mm(order)
    if obj < heur.objective_mm - 1e-9:
        status = "optimal" if obj - heur.bound_mm <= OPTIMAL_ABS_TOL_MM else "feasible"
        heur = GroupSolution.make(order, obj, heur.bound_mm, status, heur.solve_s, "ils")
        if status == "optimal":
            return GroupSolution.make(heur.order, heur.objective_mm, heur.bound_mm, "optimal",
                                      time.perf_counter() - t0, "auto:ils+bound")
    if not exact_next:
        return GroupSolution.make(heur.order, heur.objective_mm, heur.bound_mm, "fallback",
                                  time.perf_counter() - t0, "auto:ils")
    left = max(time_limit_s - (time.perf_counter() - t0), 0.05)
    ex = milp.solve(group, time_limit_s=left, hint=heur, give_up_gap=GIVE_UP_GAP)
    if ex.objective_mm > heur.objective_mm:        # never worse than the warm start
        ex = GroupSolution.make(heur.order, heur.objective_mm, max(ex.bound_mm, heur.bound_mm),
                                "feasible", ex.solve_s, ex.method)
    status = ex.status if ex.status != "fallback" else "fallback"
    return GroupSolution.make(ex.order, ex.objective_mm, max(ex.bound_mm, heur.bound_mm), status,
                              time.perf_counter() - t0, "auto:milp")
