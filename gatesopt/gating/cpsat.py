"""Exact gating for the coupled problem with OR-Tools CP-SAT (formulations/gating.md "cpsat").

The same model as ``gatesopt.gating.milp`` (``CoupledModel``: x, y, z, w, a), all Boolean, with
integer coefficients: energy in units of ``unit_j`` (1 µJ, coarser only if the objective would not
fit in 2^53), stall time in microseconds, and the lexicographic objective written exactly as
``energy_units * (lines_ub + 1) + lines``. Hinted with the dp (or given) solution, fixed seed,
``options.num_workers`` workers.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .milp import _gap, build_model, hint_vector, incumbent
from .problem import GatingProblem, GatingSolution, solution_from_gaps

UNIT_J = 1e-6           # energy unit of the integer objective
TIME_UNIT_S = 1e-6      # time unit of the stall budget


def _status_map():
    from ortools.sat.python import cp_model as cp
    return {cp.OPTIMAL: "optimal", cp.FEASIBLE: "feasible", cp.INFEASIBLE: "infeasible",
            cp.MODEL_INVALID: "infeasible", cp.UNKNOWN: "fallback"}


def _add_share_cuts(m, model, x) -> None:
    """Redundant budget rows over x alone: a shared line, split or stall charged 1/|sharers| to each
    sharer never exceeds what is paid (the argument of ``milp._angle_bounds``). They give CP-SAT's
    LP relaxation a plain knapsack row to work with. Scaled by 12 = lcm(1..4) (sharers <= 4 when
    X, Y, Z, E share one moment; larger groups round the shares down, which keeps the row valid)."""
    S = 12
    lines = model.x_lines * S
    tau = model.x_stall_s * S
    for i, mem in enumerate(model.z_members):
        lines[mem] += S / len(mem)
        tau[mem] += model.z_stall_s[i] * S / len(mem)
    for mem in model.w_members:
        lines[mem] += S / len(mem)
    if math.isfinite(model.max_lines):
        cl = np.floor(lines + 1e-9).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(cl, x) if c) <= int(model.max_lines) * S)
    if math.isfinite(model.max_time_s):
        ct = np.floor(tau / TIME_UNIT_S + 1e-6).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(ct, x) if c) <= int(math.floor(model.max_time_s * S / TIME_UNIT_S + 1e-6)))


def solve(problem: GatingProblem, *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    from ortools.sat.python import cp_model as cp

    t0 = time.perf_counter()
    start = incumbent(problem, hint)
    model = build_model(problem, start.energy_j)
    if model.nx == 0:
        return solution_from_gaps(problem, "cpsat", "optimal", int(model.angles[0]), np.zeros(0, np.int64),
                                  solve_s=time.perf_counter() - t0, bound=problem.energy_before_j)
    nx, ny, nz, nw, na = (model.nx, len(model.angles), len(model.z_members), len(model.w_members),
                          len(model.a_pairs))
    lines_ub = int(round(model.x_lines.sum())) + nz + nw
    W = lines_ub + 1
    # energy unit: 1 µJ unless sum |c| * W would leave the exactly representable integers
    mag = (abs(model.energy_before_j) + np.abs(model.x_energy_j).sum() + np.abs(model.z_energy_j).sum()
           + np.abs(model.a_energy_j).sum())
    unit = max(UNIT_J, mag * W / 2.0 ** 53)
    q = lambda v: np.round(np.asarray(v, float) / unit).astype(np.int64)

    m = cp.CpModel()
    x = [m.NewBoolVar(f"x_{g}") for g in model.gaps]            # x[g]: gap g off
    y = [m.NewBoolVar(f"y_{k}") for k in model.angles]          # y[k]: rotation k chosen
    z = [m.NewBoolVar(f"z_{i}") for i in range(nz)]             # z[e]: shared instruction line e
    w = [m.NewBoolVar(f"w_{i}") for i in range(nw)]             # w[t]: shared split at moment t
    a = [m.NewBoolVar(f"a_{i}") for i in range(na)]             # a[p]: X and Y gaps of pair p both off
    m.AddExactlyOne(y)
    if ny > 1:
        for i, k in enumerate(model.x_angle.tolist()):
            m.AddImplication(x[i], y[k])
    for i, mem in enumerate(model.z_members):
        for j in mem.tolist():
            m.AddImplication(x[j], z[i])
    for i, mem in enumerate(model.w_members):
        for j in mem.tolist():
            m.AddImplication(x[j], w[i])
    for i, (g, h) in enumerate(model.a_pairs.tolist()):
        if model.a_energy_j[i] > 0:
            m.AddBoolOr([x[g].Not(), x[h].Not(), a[i]])
        else:
            m.AddImplication(a[i], x[g])
            m.AddImplication(a[i], x[h])
    if math.isfinite(model.max_time_s):
        ts = np.round(model.x_stall_s / TIME_UNIT_S).astype(np.int64).tolist()
        tz = np.round(model.z_stall_s / TIME_UNIT_S).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(ts, x) if c) + sum(c * v for c, v in zip(tz, z) if c)
              <= int(math.floor(model.max_time_s / TIME_UNIT_S + 1e-6)))
    if math.isfinite(model.max_lines):
        xl = np.round(model.x_lines).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(xl, x) if c) + sum(z) + sum(w) <= int(model.max_lines))
    _add_share_cuts(m, model, x)
    cx = q(model.x_energy_j) * W + np.round(model.x_lines).astype(np.int64)
    cz = q(model.z_energy_j) * W + 1
    cw = np.ones(nw, np.int64)
    ca = q(model.a_energy_j) * W
    terms = [(int(c), v) for c, v in zip(cx.tolist(), x) if c]
    terms += [(int(c), v) for c, v in zip(cz.tolist(), z) if c]
    terms += [(int(c), v) for c, v in zip(cw.tolist(), w) if c]
    terms += [(int(c), v) for c, v in zip(ca.tolist(), a) if c]
    # the constant energy_before_j is in the objective so that CP-SAT's relative gap is relative
    # to the print's energy, as HiGHS's is (its offset_)
    e0 = int(round(model.energy_before_j / unit)) * W
    m.Minimize(cp.LinearExpr.WeightedSum([v for _, v in terms], [c for c, _ in terms]) + e0)
    hv = hint_vector(problem, model, start)
    if hv is not None:
        hx, hy = hv
        for v, b in zip(x, hx.tolist()):
            m.AddHint(v, int(b))
        for v, b in zip(y, hy.tolist()):
            m.AddHint(v, int(b))
        for i, mem in enumerate(model.z_members):
            m.AddHint(z[i], int(hx[mem].max()))
        for i, mem in enumerate(model.w_members):
            m.AddHint(w[i], int(hx[mem].max()))
        for i, (g, h) in enumerate(model.a_pairs.tolist()):
            m.AddHint(a[i], int(hx[g] * hx[h]))
    solver = cp.CpSolver()
    nw = max(1, int(problem.options.num_workers))
    solver.parameters.num_workers = nw
    # The LP relaxation is what proves a budgeted instance (a knapsack row). With 2 workers the
    # default portfolio has no worker at the full linearization and stalled at a 1-2 % gap on
    # 9k-gap files for 60 s; "max_lp" (linearization level 2) proves them in well under a second.
    # CP-SAT's presolve spent the whole 60 s on the largest instance (clique merging and symmetry
    # detection over the x -> z implications) before searching; without it that instance is
    # proven in ~12 s. Our model is already reduced (milp.build_model).
    solver.parameters.cp_model_presolve = False
    if nw == 1:
        solver.parameters.linearization_level = 2
    elif nw == 2:
        solver.parameters.subsolvers.extend(["max_lp", "default_lp"])
    else:
        solver.parameters.extra_subsolvers.append("max_lp")
    solver.parameters.random_seed = int(problem.options.seed)
    solver.parameters.relative_gap_limit = float(problem.options.mip_rel_gap)
    if time_limit_s is not None:
        # the limit is for the whole call: the dp start and building the model count against it
        solver.parameters.max_time_in_seconds = max(float(time_limit_s) - (time.perf_counter() - t0), 0.01)
    st = solver.Solve(m)
    mapped = _status_map().get(st, "fallback")
    solve_s = time.perf_counter() - t0
    if st not in (cp.OPTIMAL, cp.FEASIBLE):
        return replace(start, formulation="cpsat", status="infeasible" if mapped == "infeasible" else "fallback",
                       solve_s=solve_s, bound=model.bound_j, gap=_gap(start.energy_j, model.bound_j),
                       message=f"CP-SAT {solver.StatusName(st)}; returned the dp/hint start")
    xs = np.array([solver.BooleanValue(v) for v in x], bool)
    ys = np.array([solver.BooleanValue(v) for v in y], bool)
    lines_note = ""
    if st == cp.OPTIMAL and solver.ObjectiveValue() - solver.BestObjectiveBound() >= 1.0:
        # relative_gap_limit stopped the search with room for a line less at the same energy (a
        # gap of 1 unit is one line, see W). Second stage: energy held at what was found, fewest
        # lines (the lexicographic order of formulations/gating.md section 4, exactly).
        energy = [(int(c), v) for c, v in zip(q(model.x_energy_j).tolist(), x) if c]
        energy += [(int(c), v) for c, v in zip(q(model.z_energy_j).tolist(), z) if c]
        energy += [(int(c), v) for c, v in zip(q(model.a_energy_j).tolist(), a) if c]
        found = sum(c * solver.BooleanValue(v) for c, v in energy)
        if energy:
            m.Add(cp.LinearExpr.WeightedSum([v for _, v in energy], [c for c, _ in energy]) <= found)
        xl = np.round(model.x_lines).astype(np.int64).tolist()
        lines = [(c, v) for c, v in zip(xl, x) if c] + [(1, v) for v in z + w]
        m.Minimize(cp.LinearExpr.WeightedSum([v for _, v in lines], [c for c, _ in lines]))
        m.ClearHints()
        for v in x + y + z + w + a:
            m.AddHint(v, int(solver.BooleanValue(v)))
        used = time.perf_counter() - t0
        second = cp.CpSolver()
        second.parameters.num_workers = nw
        second.parameters.cp_model_presolve = False
        second.parameters.random_seed = int(problem.options.seed)
        # at most as long again as the first stage took, within what is left of the limit
        left = used if time_limit_s is None else min(used, float(time_limit_s) - used)
        second.parameters.max_time_in_seconds = max(left, 0.05)
        st2 = second.Solve(m)
        if st2 in (cp.OPTIMAL, cp.FEASIBLE):
            xs = np.array([second.BooleanValue(v) for v in x], bool)
            ys = np.array([second.BooleanValue(v) for v in y], bool)
            lines_note = f"; fewest lines at that energy: {second.StatusName(st2)}"
    k = int(model.angles[int(np.argmax(ys))])
    # bound: objective units -> J. obj = energy_units * W + lines with 0 <= lines <= lines_ub, so
    # energy_units >= floor(bound / W); each rounded coefficient is off by <= unit / 2
    bound_units = math.floor((solver.BestObjectiveBound() - e0) / W)
    slack = unit / 2.0 * (nx + nz + na + 1)            # +1: the rounded constant
    bound = max(model.energy_before_j + bound_units * unit - slack, model.bound_j)
    return solution_from_gaps(problem, "cpsat", mapped, k, model.gaps[xs], solve_s=solve_s, bound=bound,
                              message=f"CP-SAT {solver.StatusName(st)}; {nx} gap variables, {ny} angle(s), "
                                      f"{len(model.pruned)} pruned by bound; energy unit {unit:.3g} J"
                                      + lines_note)
