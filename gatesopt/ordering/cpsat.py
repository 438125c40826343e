"""Exact curve ordering with OR-Tools CP-SAT (formulations/ordering.md, "cpsat").

``AddCircuit`` over the nodes {depot 0} + {one node per candidate}: the circuit leaves the depot
into the first candidate (cost = travel from the group's start point), runs candidate to
candidate (cost = exit-to-entry travel), and returns to the depot at cost 0 (the path is open:
it ends wherever its last curve ends). A candidate the path skips takes its self-loop literal
``skip[k]``; exactly one candidate per curve is visited (generalised TSP with clusters, the
OR-Tools idiom for optional nodes). Costs are integers: travel in units of 1/SCALE mm.
"""
from __future__ import annotations

import time

import numpy as np
from ortools.sat.python import cp_model

from .bounds import lower_bound_mm
from .ils import warm_start
from .problem import OPTIMAL_ABS_TOL_MM, Group, GroupSolution

#: integer cost scale: 1 unit = 0.1 µm of travel (rounding error <= n * 0.05 µm per path)
SCALE = 10_000

STATUS = {
    cp_model.OPTIMAL: "optimal",
    cp_model.FEASIBLE: "feasible",
    cp_model.INFEASIBLE: "infeasible",
    cp_model.MODEL_INVALID: "infeasible",
    cp_model.UNKNOWN: "fallback",
}


def _trivial(group: Group, t0: float, method: str) -> GroupSolution | None:
    """The answer for a group of 0 or 1 curves (no solver needed), else None."""
    if group.n_curves == 0:
        return GroupSolution.make([], 0.0, 0.0, "optimal", time.perf_counter() - t0, method)
    if group.n_curves == 1:
        c = group.start_cost_mm() + group.end_cost_mm()
        k = int(np.argmin(c))
        return GroupSolution.make([k], c[k], c[k], "optimal", time.perf_counter() - t0, method)
    return None


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None, num_workers: int = 2,
          seed: int = 0) -> GroupSolution:
    t0 = time.perf_counter()
    triv = _trivial(group, t0, "cpsat")
    if triv is not None:
        return triv
    hint = warm_start(group, hint, t0, time_limit_s)
    return _solve_circuit(group, t0, time_limit_s, hint, num_workers, seed, closed=False)


def closed_tour(group: Group, *, time_limit_s: float = 10.0, num_workers: int = 2, seed: int = 0):
    """Shortest *closed* tour through every curve (start point ignored): the Concorde step of
    Fleming et al. Algorithm 1. Returns (candidate order, proven optimal?) or None (no tour found)."""
    t0 = time.perf_counter()
    if group.n_curves < 2:
        return None
    sol = _solve_circuit(group, t0, time_limit_s, None, num_workers, seed, closed=True)
    return sol


def _solve_circuit(group: Group, t0, time_limit_s, hint, num_workers, seed, closed):
    m, n = group.n_cands, group.n_curves
    start_c = np.rint(group.start_cost_mm() * SCALE).astype(np.int64)
    end_c = np.rint(group.end_cost_mm() * SCALE).astype(np.int64)
    arc = group.arc_cost_mm()
    finite = np.isfinite(arc)
    arc_c = np.where(finite, np.rint(np.where(finite, arc, 0) * SCALE), 0).astype(np.int64)

    model = cp_model.CpModel()
    arcs, costs = [], []
    # first[k]: the path starts with candidate k; last[k]: it ends with k (return arc, cost 0)
    first = [model.NewBoolVar(f"first_{k}") for k in range(m)]
    last = [model.NewBoolVar(f"last_{k}") for k in range(m)]
    if closed:          # the depot sits out of the circuit (self-loop fixed true)
        depot_out = model.NewBoolVar("depot_out")
        model.Add(depot_out == 1)
        arcs.append((0, 0, depot_out))
    for k in range(m):
        if closed:      # no depot: the circuit closes on the candidates themselves
            model.Add(first[k] == 0)
            model.Add(last[k] == 0)
            continue
        arcs.append((0, k + 1, first[k]))
        costs.append((first[k], int(start_c[k])))
        arcs.append((k + 1, 0, last[k]))
        if end_c[k]:
            costs.append((last[k], int(end_c[k])))
    # x[u, v]: candidate v follows candidate u (different curves only)
    us, vs = np.nonzero(finite)
    x = {}
    for u, v in zip(us.tolist(), vs.tolist()):
        lit = model.NewBoolVar(f"x_{u}_{v}")
        x[u, v] = lit
        arcs.append((u + 1, v + 1, lit))
        costs.append((lit, int(arc_c[u, v])))
    # skip[k]: candidate k is not visited (self-loop); exactly one candidate per curve is visited
    counts = np.bincount(group.cand_curve, minlength=n)
    skip = {}
    for k in range(m):
        if counts[group.cand_curve[k]] > 1:
            skip[k] = model.NewBoolVar(f"skip_{k}")
            arcs.append((k + 1, k + 1, skip[k]))
    for c in np.nonzero(counts > 1)[0]:
        ks = np.nonzero(group.cand_curve == c)[0]
        model.Add(sum(skip[int(k)] for k in ks) == len(ks) - 1)
    model.AddCircuit(arcs)
    model.Minimize(sum(c * lit for lit, c in costs))

    if hint is not None:
        order = np.asarray(getattr(hint, "order", hint), np.int64)
        used = set(zip(order[:-1].tolist(), order[1:].tolist()))
        visited = set(order.tolist())
        for (u, v), lit in x.items():
            model.AddHint(lit, (u, v) in used)
        for k in range(m):
            model.AddHint(first[k], k == order[0])
            model.AddHint(last[k], k == order[-1])
        for k, lit in skip.items():
            model.AddHint(lit, k not in visited)

    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = max(float(time_limit_s), 0.01)
    solver.parameters.num_workers = int(num_workers)
    solver.parameters.random_seed = int(seed)
    code = solver.Solve(model)
    status = STATUS.get(code, "fallback")
    if closed:
        if status not in ("optimal", "feasible"):
            return None
        succ = {u: v for (u, v), lit in x.items() if solver.BooleanValue(lit)}
        cur = next(iter(succ))
        order = [cur]
        while succ[cur] != order[0]:
            cur = succ[cur]
            order.append(cur)
        return np.asarray(order, np.int64), status == "optimal"
    if status in ("optimal", "feasible"):
        succ = {}
        for k in range(m):
            if solver.BooleanValue(first[k]):
                succ[-1] = k
        for (u, v), lit in x.items():
            if solver.BooleanValue(lit):
                succ[u] = v
        order, cur = [], succ[-1]
        while cur is not None and len(order) <= n:
            order.append(cur)
            cur = succ.get(cur)
        order = np.asarray(order, np.int64)
        # integer rounding: each of the n links is off by at most 0.5 unit
        bound = max(solver.BestObjectiveBound() / SCALE - (n + 1) * 0.5 / SCALE, lower_bound_mm(group))
    else:  # no solution within the limit: keep the hint (solve always passes one), cheap bound
        order = np.asarray(getattr(hint, "order", hint), np.int64)
        bound = lower_bound_mm(group)
        status = "fallback"
    group.check_order(order)
    obj = group.path_cost_mm(order)
    # integer costs: the model's optimum may be a hair longer than the hint in float travel
    h_order = np.asarray(getattr(hint, "order", hint), np.int64)
    h_obj = group.path_cost_mm(h_order)
    if h_obj < obj - 1e-9:
        order, obj = h_order, h_obj
    if status == "optimal" or obj - bound <= OPTIMAL_ABS_TOL_MM:
        status = "optimal"
    return GroupSolution.make(order, obj, bound, status, time.perf_counter() - t0, "cpsat")
