"""``auto``: exact where it pays, heuristic where it must (formulations/ordering.md, "auto").

Per group: groups small enough for the subset DP (``dp.py``, up to ~12-16 curves) are solved
exactly there. Otherwise the greedy path (nearest neighbour + 2-opt/Or-opt + orientation DP) and the cheap
bound of ``bounds.py`` first — on real layers many groups are proven optimal right there (their
greedy path uses each curve's cheapest links). Then, where the symmetric model applies, the
cheapest perfect matching of the end points (``matching.py``): a bound within ~2 % of the optimum
on real groups and, patched into one path, often the optimum itself. Otherwise ILS, then the
exact step of ``milp.py``
within the per-group time limit: the symmetric model (``symmetric.py``: sparse LP with subtour and
blossom cuts, pricing, reduced-cost fixing, branch-and-cut; where links cost otherwise one way
than the other, its directed refinement) for groups of open curves and
fixed-seam loops up to ``SYMMETRIC_MAX_CANDS`` candidates, the directed model up to
``exact_max_cands``; the rest keep the ILS path with status "fallback" and the gap to the better
of the two bounds.

Measured on 30 real Cura bunny groups of 19-183 curves (same machine, 10 s each): the symmetric
model proved 29-30 of them in ~30 s in all; the previous dense model with subtour cuts only proved
17 in ~200 s (its root bound was up to 36 % below the optimum; with blossoms it is within ~3 %).
"""
from __future__ import annotations

import time

import numpy as np

from ..solvers import Status
from . import dp, greedy, greedy_pass, ils, matching, milp, symmetric, symmetric_graph
from .budget import exact_time_s
from .problem import OPTIMAL_ABS_TOL, Group, GroupSolution

#: largest group (in candidates, i.e. ~2x curves) handed to the exact formulation (HiGHS: its
#: model has ~m^2 columns; beyond ~160 candidates it rarely closes the gap within seconds)
EXACT_MAX_CANDS = 160
#: largest group (candidates) for the symmetric model (formulations/ordering.md, "milp,
#: symmetric"): sparse columns with pricing keep its LP small, but it holds a few N x N arrays
SYMMETRIC_MAX_CANDS = 1000
#: ILS kicks per curve before the symmetric model: none, it builds its own incumbent from the LP
#: point and kicks proved no more groups, only slower (docs/BENCHMARKS.md, "Curve-ordering constants")
SYMMETRIC_WARM_KICKS_PER_CURVE = 0
#: up to this many curves the subset DP goes first; above it (up to ``dp.fits``, ~16 curves) the
#: DP takes 20-50 ms and the symmetric model, faster there, is tried first where it applies, the
#: DP after it if the model did not prove the group in time (docs/BENCHMARKS.md)
DP_FIRST_CURVES = 12
#: below this per-group limit (a spent budget) the exact step is not even built
MIN_EXACT_S = 0.05
#: the same for the symmetric model: ``budget.exact_time_s`` (MIN_SYMMETRIC_S plus a share per
#: curve), which a shared budget must give a group it wants proven
#: without an exact step next, ILS runs only if this much time per curve is left before the
#: group's deadline: it first builds its link matrix (~10 us per curve) and each kick runs a local
#: search, so a short ILS overruns its deadline and rarely improves the path (docs/BENCHMARKS.md)
MIN_FALLBACK_ILS_S_PER_CURVE = 2e-4
#: stop after the MILP's LP cutting-plane rounds if they leave more than this gap
GIVE_UP_GAP = None   # measured: with 0.15, free-mode Cura groups lost most proofs the branch loop finds


_WARM = False


def warm_up() -> None:
    """Load every compiled kernel auto may call (numba caches, HiGHS) once per process, on a
    made-up group of 14 lines: the first real group would otherwise pay ~0.35 s for it, and a
    shared budget would read that as an overrun to expect from every group still to come."""
    global _WARM
    if _WARM:
        return
    _WARM = True
    from .polylines import from_polylines
    rng = np.random.default_rng(0)
    lines = [rng.uniform(0, 50, (2, 2)) for _ in range(DP_FIRST_CURVES + 2)]
    prob = from_polylines([lines, lines[:DP_FIRST_CURVES]])
    solve(prob.group(0, prob.origin_xy), time_limit_s=1.0)                # greedy, ILS, model
    solve(prob.group(1, prob.origin_xy), time_limit_s=1.0)                # DP
    symmetric.load_kernels()        # what these groups may not have reached


def _ils_from(group: Group, start: GroupSolution, bound: float, deadline: float,
              formulation: str, **kwargs) -> GroupSolution:
    """``start``, or the ILS path from it (``ils.improve_ils`` until ``deadline``, stopped once
    it reaches ``bound``) if that is shorter: then with its status against ``bound``,
    ``start``'s solve time and ``formulation``."""
    order = ils.improve_ils(group, start.order, deadline=deadline,
                            target=bound + OPTIMAL_ABS_TOL, **kwargs)
    obj = group.path_cost(order)
    if obj >= start.objective - 1e-9:
        return start
    status = Status.OPTIMAL if obj - bound <= OPTIMAL_ABS_TOL else Status.FEASIBLE
    return GroupSolution.make(order, obj, bound, status, start.solve_s, formulation)


def solve(group: Group, *, time_limit_s: float = 2.0, hint=None,
          exact_max_cands: int = EXACT_MAX_CANDS) -> GroupSolution:
    t0 = time.perf_counter()
    sym = symmetric_graph.applies(group)
    sym_next = (sym and group.n_cands <= SYMMETRIC_MAX_CANDS
                and time_limit_s >= exact_time_s(group.n_curves))
    if dp.fits(group) and (group.n_curves <= DP_FIRST_CURVES
                           or (not sym_next and dp.time_s(group) <= time_limit_s)):
        # small: exact by DP over subsets, sub-millisecond up to ~12 curves. Above, the DP takes
        # 10-140 ms and cannot be stopped: under a budget's small share it would take the time of
        # several proofs by the model from the groups after it
        ex = dp.solve(group)
        return GroupSolution.make(ex.order, ex.objective, ex.bound, Status.OPTIMAL,
                                  time.perf_counter() - t0, "auto:dp")
    heur = greedy.solve(group, hint=hint)
    if heur.status == Status.OPTIMAL or group.n_curves <= 1:
        return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.OPTIMAL,
                                  time.perf_counter() - t0, "auto:bound")
    if sym and 2 * group.n_curves + 2 <= matching.MAX_VERTICES:
        # the cheapest perfect matching of the end points: a bound within ~2 % of the optimum
        # on real groups (the cheap bound: ~20 %), and, patched into one path, a path that is
        # often the optimum (formulations/ordering.md, "Bounds")
        heur = greedy_pass.matching_path(group, heur)
        if heur.status == Status.OPTIMAL:
            return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.OPTIMAL,
                                      time.perf_counter() - t0, "auto:matching")
    # escape the local optimum before anything else: a better incumbent is what lets the exact
    # step (or the bound) prove it, and what a fallback group keeps. Before the symmetric model a
    # short search is enough: that model builds its own incumbent from the LP point
    exact_next = sym_next or (not sym and group.n_cands <= exact_max_cands
                              and time_limit_s >= MIN_EXACT_S)
    share = ils.WARM_START_SHARE if exact_next else 1.0
    kicks = SYMMETRIC_WARM_KICKS_PER_CURVE * group.n_curves if sym_next else None
    deadline = t0 + share * time_limit_s
    if (not exact_next
            and deadline - time.perf_counter() < MIN_FALLBACK_ILS_S_PER_CURVE * group.n_curves):
        # a budget's heuristic share, spent by the greedy path and the matching: ILS would still
        # pay for its link matrix and a kick, past the deadline, for next to nothing
        return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.FALLBACK,
                                  time.perf_counter() - t0, "auto:greedy")
    heur = _ils_from(group, heur, heur.bound, deadline, "ils", kicks=kicks,
                     local_optimum=heur.formulation in ("greedy", "matching"))
    if heur.status == Status.OPTIMAL:
        return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.OPTIMAL,
                                  time.perf_counter() - t0, "auto:ils+bound")
    if not exact_next:
        return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.FALLBACK,
                                  time.perf_counter() - t0, "auto:ils")
    left = time_limit_s - (time.perf_counter() - t0)
    if left <= 0.0:
        # the greedy path, the matching and ILS took the whole limit (a large group on a loaded
        # machine): no exact step after the deadline (it once got 50 ms more whatever was left)
        return GroupSolution.make(heur.order, heur.objective, heur.bound, Status.FALLBACK,
                                  time.perf_counter() - t0, "auto:ils")
    ex = milp.solve(group, time_limit_s=left, hint=heur, give_up_gap=GIVE_UP_GAP,
                    known_bound=heur.bound)
    if ex.objective > heur.objective:        # never worse than the warm start
        ex = GroupSolution.make(heur.order, heur.objective, max(ex.bound, heur.bound),
                                Status.FEASIBLE, ex.solve_s, ex.formulation)
    if ex.status != Status.OPTIMAL and dp.fits(group) and dp.time_s(group) <= time_limit_s:
        # the model did not prove it in time: the DP will, in at most about one limit more
        d = dp.solve(group)
        return GroupSolution.make(d.order, d.objective, d.bound, Status.OPTIMAL,
                                  time.perf_counter() - t0, "auto:dp")
    bound = max(ex.bound, heur.bound)
    deadline = t0 + time_limit_s
    if (ex.status != Status.OPTIMAL
            and deadline - time.perf_counter() >= MIN_FALLBACK_ILS_S_PER_CURVE * group.n_curves):
        # the exact step gave up with time left (a root gap too wide to branch on: strips of
        # parallel lines, zig-zag infill): the rest of the limit goes to the path, as for a
        # fallback group. On the 3 large groups where LKH-3 had beaten auto (docs/RESULTS.md,
        # "peers on large groups": 249, 299, 107 curves, 2 s each) the model stopped after
        # 0.3 / 0.8 / 0.06 s: 166.0 / 182.5 / 77.8 mm, now 158.8 / 182.4 / 76.6 (LKH 156.4 /
        # 182.0 / 76.8)
        polished = _ils_from(group, ex, bound, deadline, "auto:milp+ils")
        if polished is not ex:
            return GroupSolution.make(polished.order, polished.objective, bound, polished.status,
                                      time.perf_counter() - t0, polished.formulation)
    return GroupSolution.make(ex.order, ex.objective, bound, ex.status,
                              time.perf_counter() - t0, "auto:milp")
