"""Exact ordering of small groups by dynamic programming over subsets (Held–Karp for clusters;
formulations/ordering.md, "dp").

    D[S, k] = cost of the cheapest path from the start point through exactly the curves in S,
              ending with candidate k (its curve in S)
    D[{i}, k]      = c(s, k)                                    k in K_i
    D[S + {j}, v]  = min_{k: curve in S} D[S, k] + c(k, v)      v in K_j, j not in S
    J*             = min_k D[all, k] + c(k, e)                  (e: end point, if any)

with c the group's link costs (``Group.arc_cost``, ``start_cost``, ``end_cost``: travel |q_k - p_v|,
or its time as emitted, asymmetric; the recursion needs no symmetry or triangle inequality).

O(2^n m^2) time and O(2^n m) memory (m candidates), so it is used up to ``MAX_STATES`` work; most
groups of real layers are that small (an island's few infill pieces, gap fill), and there it is
exact in well under a millisecond — far below the cost of setting up CP-SAT or HiGHS.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from ..solvers import Status
from .problem import Group, GroupSolution, OrderingOptionsError

#: largest 2^n * m^2 the DP takes on (about 0.1 s in numba)
MAX_WORK = 4e7
#: seconds per unit of 2^n * m^2: measured 1.9-4.7 ns on 25 Cura bunny groups of 13-15 curves
#: (10-140 ms each; the spread is the cache), so the DP's time is known before it starts
S_PER_WORK = 3e-9


def work(group: Group) -> float:
    return (2.0 ** group.n_curves) * group.n_cands ** 2


def fits(group: Group) -> bool:
    return group.n_curves <= 20 and work(group) <= MAX_WORK


def time_s(group: Group) -> float:
    """What the DP is expected to take on ``group`` (it cannot be stopped early)."""
    return S_PER_WORK * work(group)


@numba.njit(cache=True)
def _held_karp(n, cand_curve, arc, start_c, end_c):
    m = len(cand_curve)
    full = (1 << n) - 1
    D = np.full((1 << n, m), np.inf)
    P = np.full((1 << n, m), -1, np.int64)
    for k in range(m):
        D[1 << cand_curve[k], k] = start_c[k]
    for S in range(1, full + 1):
        for k in range(m):
            dk = D[S, k]
            if dk == np.inf:
                continue
            for v in range(m):
                b = 1 << cand_curve[v]
                if S & b:
                    continue
                c = dk + arc[k, v]
                if c < D[S | b, v]:
                    D[S | b, v] = c
                    P[S | b, v] = k
    best, arg = np.inf, -1
    for k in range(m):
        c = D[full, k] + end_c[k]
        if c < best:
            best, arg = c, k
    order = np.empty(n, np.int64)
    S, k = full, arg
    for t in range(n - 1, -1, -1):
        order[t] = k
        pk = P[S, k]
        S = S & ~(1 << cand_curve[k])
        k = pk
    return order, best


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          first: int | None = None) -> GroupSolution:
    """Exact for groups that ``fits``; larger ones raise OrderingOptionsError (a ValueError: use
    cpsat or milp). ``first``: the path must begin with that candidate (the cheapest such path:
    "feasible", bound 0: optimal for the group only where it costs the unconstrained optimum;
    ``chain.settle``)."""
    t0 = time.perf_counter()
    if group.n_curves == 0:
        return GroupSolution.make([], 0.0, 0.0, Status.OPTIMAL, 0.0, "dp")
    if not fits(group):
        raise OrderingOptionsError(f"dp: group of {group.n_curves} curves / {group.n_cands} "
                                   "candidates is too large")
    start_c = np.array(group.start_cost(), float)
    if first is not None:
        keep = start_c[first]
        start_c[:] = np.inf
        start_c[first] = keep
    order, best = _held_karp(group.n_curves, np.asarray(group.cand_curve, np.int64),
                             np.ascontiguousarray(group.arc_cost(), float), start_c,
                             np.ascontiguousarray(group.end_cost(), float))
    obj = group.path_cost(order)
    if first is not None:       # the cheapest of some paths: no bound on the group's optimum
        return GroupSolution.make(order, obj, 0.0, Status.FEASIBLE, time.perf_counter() - t0,
                                  "dp:first")
    return GroupSolution.make(order, obj, obj, Status.OPTIMAL, time.perf_counter() - t0, "dp")
