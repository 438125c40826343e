"""Exact gating for the coupled problem as a MILP, solved by HiGHS through highspy.

The model is ``coupled.CoupledModel`` (formulations/gating.md "milp", same symbols): binaries
``x[g]`` (idle interval g off) and ``y[k]`` (rotation k), line variables ``z[e]`` and ``w[t]``,
AND variables ``a[p]``, budget rows. Objective: energy (J) + ``LINE_WEIGHT_J`` x lines
(lexicographic by a small weight, see the md). The matrices are built directly (column-wise CSC):
this path passes HiGHS a warm start and reads its dual bound; ``gating.cvxpy_model`` writes the
same model with cvxpy for planners that add constraints or pick another MIP solver.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .._native import run_highs
from ..solvers import Status, relative_gap
from .coupled import CoupledModel, build_model, hint_vector
from .dp import warm_start
from .problem import GatingProblem
from .solution import GatingSolution, solution_from_idle

#: HiGHS's symmetry detection (uninterruptible, 6.7 s on a 27k-column model) runs only under a
#: time limit at least this long (see ``solve``)
SYMMETRY_MIN_LIMIT_S = 10.0
LINE_WEIGHT_J = 1e-6            # J per added line in the objective (lexicographic tie-break)


# ------------------------------------------------------------------------------------------------
# HiGHS
def _status_map():
    import highspy
    S = highspy.HighsModelStatus
    return {S.kOptimal: Status.OPTIMAL, S.kInfeasible: Status.INFEASIBLE, S.kTimeLimit: Status.FEASIBLE,
            S.kIterationLimit: Status.FEASIBLE, S.kSolutionLimit: Status.FEASIBLE,
            S.kInterrupt: Status.FEASIBLE, S.kObjectiveBound: Status.FEASIBLE,
            S.kObjectiveTarget: Status.FEASIBLE, S.kMemoryLimit: Status.FEASIBLE}


def _columns(model: CoupledModel):
    """Column-wise matrix of the model. Column order: x, y, z, w, a."""
    nx, ny, nz, nw, na = model.nx, len(model.angles), len(model.z_members), len(model.w_members), len(model.a_pairs)
    ox, oy, oz, ow, oa = 0, nx, nx + ny, nx + ny + nz, nx + ny + nz + nw
    ncol = oa + na
    rows, cols, vals, rlo, rhi = [], [], [], [], []
    r = 0

    def add(rr, cc, vv):
        rows.append(np.asarray(rr, np.int64))
        cols.append(np.asarray(cc, np.int64))
        vals.append(np.asarray(vv, float))

    # sum y = 1
    add(np.zeros(ny), oy + np.arange(ny), np.ones(ny)); rlo.append(1.0); rhi.append(1.0); r += 1
    # x[g] - y[k(g)] <= 0
    if ny > 1:
        ix = np.arange(nx)
        add(r + ix, ox + ix, np.ones(nx)); add(r + ix, oy + model.x_angle, -np.ones(nx))
        rlo += [-math.inf] * nx; rhi += [0.0] * nx; r += nx
    # rule B of a firmware schedule: at most one interval of each clique off
    if model.c_members:
        lens = np.array([len(c) for c in model.c_members])
        add(r + np.repeat(np.arange(len(lens)), lens), ox + np.concatenate(model.c_members), np.ones(int(lens.sum())))
        rlo += [-math.inf] * len(lens); rhi += [1.0] * len(lens); r += len(lens)
    # x[g] - z[e] <= 0 for members, same for w
    for off, members in ((oz, model.z_members), (ow, model.w_members)):
        if members:
            lens = np.array([len(m) for m in members])
            mem = np.concatenate(members)
            cnt = len(mem)
            rr = r + np.arange(cnt)
            add(rr, ox + mem, np.ones(cnt)); add(rr, off + np.repeat(np.arange(len(members)), lens), -np.ones(cnt))
            rlo += [-math.inf] * cnt; rhi += [0.0] * cnt; r += cnt
    # AND: positive correction a >= x + x' - 1 ; negative: a <= x, a <= x'
    if na:
        posc = model.a_energy_j > 0
        ip = np.flatnonzero(posc)
        if len(ip):
            rr = r + np.arange(len(ip))
            add(rr, ox + model.a_pairs[ip, 0], np.ones(len(ip))); add(rr, ox + model.a_pairs[ip, 1], np.ones(len(ip)))
            add(rr, oa + ip, -np.ones(len(ip)))
            rlo += [-math.inf] * len(ip); rhi += [1.0] * len(ip); r += len(ip)
        ineg = np.flatnonzero(~posc)
        for c in (0, 1):
            if len(ineg):
                rr = r + np.arange(len(ineg))
                add(rr, oa + ineg, np.ones(len(ineg))); add(rr, ox + model.a_pairs[ineg, c], -np.ones(len(ineg)))
                rlo += [-math.inf] * len(ineg); rhi += [0.0] * len(ineg); r += len(ineg)
    # budgets
    if math.isfinite(model.max_time_s):
        add(np.full(nx, r), ox + np.arange(nx), model.x_stall_s)
        add(np.full(nz, r), oz + np.arange(nz), model.z_stall_s)
        rlo.append(-math.inf); rhi.append(model.max_time_s + 1e-9); r += 1
    if math.isfinite(model.max_lines):
        add(np.full(nx, r), ox + np.arange(nx), model.x_lines)
        add(np.full(nz, r), oz + np.arange(nz), np.ones(nz))
        add(np.full(nw, r), ow + np.arange(nw), np.ones(nw))
        rlo.append(-math.inf); rhi.append(float(model.max_lines)); r += 1
    cost = np.concatenate((model.x_energy_j + LINE_WEIGHT_J * model.x_lines, np.zeros(ny),
                           model.z_energy_j + LINE_WEIGHT_J, np.full(nw, LINE_WEIGHT_J), model.a_energy_j))
    R = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    C = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    V = np.concatenate(vals) if vals else np.zeros(0)
    keep = V != 0
    R, C, V = R[keep], C[keep], V[keep]
    order = np.lexsort((R, C))
    R, C, V = R[order], C[order], V[order]
    start = np.searchsorted(C, np.arange(ncol + 1))
    integer = np.zeros(ncol, bool)
    integer[: oy + ny] = True                   # x, y binary; z, w, a continuous in [0, 1]
    return dict(ncol=ncol, nrow=r, cost=cost, start=start, index=R, value=V,
                row_lower=np.array(rlo, float), row_upper=np.array(rhi, float), integer=integer,
                offsets=(ox, oy, oz, ow, oa))


def solve(problem: GatingProblem, *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    t0 = time.perf_counter()
    start = warm_start(problem, hint)
    model = build_model(problem, start.energy_j)
    if model.nx == 0:       # nothing can save energy: keeping every motor on is optimal
        sol = solution_from_idle(problem, "milp", Status.OPTIMAL, int(model.angles[0]),
                                 np.zeros(0, np.int64), solve_s=time.perf_counter() - t0,
                                 bound_j=problem.energy_before_j)
        return sol
    share_bound = model.bound_j
    M = _columns(model)
    h = _highs(problem, model, M, time_limit_s)
    if time_limit_s is not None:
        # the limit is for the whole call: the dp start and the model's build count against it
        h.setOptionValue("time_limit", max(float(time_limit_s) - (time.perf_counter() - t0), 0.01))
    hv = hint_vector(problem, model, start)
    run_highs(h, start=None if hv is None else _full_start(model, M, *hv))
    return _decode(problem, model, M, h, start, share_bound, time.perf_counter() - t0)


def _highs(problem: GatingProblem, model: CoupledModel, M: dict, time_limit_s: float | None):
    """A ``highspy.Highs`` holding the model's LP (``_columns``), options set."""
    import highspy

    lp = highspy.HighsLp()
    lp.num_col_ = M["ncol"]
    lp.num_row_ = M["nrow"]
    lp.col_cost_ = M["cost"]
    lp.col_lower_ = np.zeros(M["ncol"])
    lp.col_upper_ = np.ones(M["ncol"])
    lp.row_lower_ = M["row_lower"]
    lp.row_upper_ = M["row_upper"]
    lp.offset_ = model.energy_before_j
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = M["start"]
    lp.a_matrix_.index_ = M["index"]
    lp.a_matrix_.value_ = M["value"]
    lp.integrality_ = [highspy.HighsVarType.kInteger if b else highspy.HighsVarType.kContinuous
                       for b in M["integer"]]
    h = highspy.Highs()
    for name, value in highs_options(problem, time_limit_s).items():
        h.setOptionValue(name, value)
    h.passModel(lp)
    return h


def highs_options(problem: GatingProblem, time_limit_s: float | None) -> dict:
    """The HiGHS options of this formulation (also ``cvxpy_model.solve``'s defaults for HiGHS);
    the time limit is set apart, for what is left of it after the build."""
    # HiGHS 1.12's symmetry detection does not look at the clock. On the Marlin 1 % budget of a
    # PrusaSlicer y-motor file (12.8k idle intervals) it took 6.7 s at the root and, after HiGHS
    # restarted the search, ran on to 192 s against a 20 s time limit (also 80 s on a Cura file).
    # No restart: every budgeted corpus file keeps a 20 s limit and proves what it proved.
    # Symmetry detection itself only where the limit leaves room for it: it proves 4 of those
    # files in 1-3 s that stay open at 20 s without it, but under a 2 s limit it made the same
    # run 8.3 s. Presolve off: formulations/gating.md §3 (our reductions are the presolve).
    return {"output_flag": False, "mip_rel_gap": problem.options.mip_rel_gap, "threads": 1,
            "presolve": "off", "mip_allow_restart": False,
            "mip_detect_symmetry": time_limit_s is None or time_limit_s >= SYMMETRY_MIN_LIMIT_S,
            "random_seed": int(problem.options.seed)}


def _decode(problem: GatingProblem, model: CoupledModel, M: dict, h, start: GatingSolution,
            share_bound: float, solve_s: float) -> GatingSolution:
    """The solution HiGHS found (re-scored), its status and bound; the start where it found none."""
    status = h.getModelStatus()
    info = h.getInfo()
    mapped = _status_map().get(status, Status.FALLBACK)
    has_sol = info.primal_solution_status == 2  # kSolutionStatusFeasible
    if mapped == Status.INFEASIBLE or not has_sol:
        # no solution of its own (time limit before any, or an error): the incumbent, said so
        st = Status.FALLBACK if mapped != Status.INFEASIBLE else Status.INFEASIBLE
        return replace(start, formulation="milp", status=st, solve_s=solve_s,
                       bound_j=share_bound, gap=relative_gap(start.energy_j, share_bound),
                       message=f"HiGHS: {h.modelStatusToString(status)}; returned the dp/hint start")
    col = np.asarray(h.getSolution().col_value)
    ox, oy = M["offsets"][0], M["offsets"][1]
    xs = col[ox:ox + model.nx] > 0.5
    ys = col[oy:oy + len(model.angles)]
    k = int(model.angles[int(np.argmax(ys))])
    chosen = model.x_idle[xs]
    # the objective is energy + LINE_WEIGHT_J * lines; any solution has lines <= lines_ub, so
    # energy >= dual bound - LINE_WEIGHT_J * lines_ub is a valid bound on energy alone
    lines_ub = float(model.x_lines.sum() + len(model.z_members) + len(model.w_members))
    bound = float(min(info.mip_dual_bound, info.objective_function_value)) - LINE_WEIGHT_J * lines_ub
    bound = max(bound, share_bound)     # HiGHS stopped before its root LP: the share bound holds
    sol = solution_from_idle(problem, "milp", mapped, k, chosen, solve_s=solve_s, bound_j=bound,
                             message=f"HiGHS {h.modelStatusToString(status)}; {model.nx} gap variables, "
                                     f"{len(model.angles)} angle(s), {len(model.pruned)} pruned by bound")
    # the model's objective must be the re-scored energy plus the line weight: say so if not
    model_j = float(info.objective_function_value) - LINE_WEIGHT_J * sol.lines_added
    if abs(model_j - sol.energy_j) > 1e-6 * max(abs(sol.energy_j), 1.0):
        sol = replace(sol, message=sol.message + f"; model energy {model_j:.6f} J != scored {sol.energy_j:.6f} J")
    return sol


def _full_start(model, M, x, y):
    """Complete a start (x, y) with the z, w, a values it implies."""
    ox, oy, oz, ow, oa = M["offsets"]
    full = np.zeros(M["ncol"])
    full[ox:ox + model.nx] = x
    full[oy:oy + len(y)] = y
    for i, mem in enumerate(model.z_members):
        full[oz + i] = x[mem].max()
    for i, mem in enumerate(model.w_members):
        full[ow + i] = x[mem].max()
    if len(model.a_pairs):
        full[oa:] = x[model.a_pairs[:, 0]] * x[model.a_pairs[:, 1]]
    return full
