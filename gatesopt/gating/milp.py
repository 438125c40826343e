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
from ..solvers import Status, Stopped, relative_gap, stop_requested
from .coupled import LINE_TIEBREAK_S, LINE_TIEBREAK_SHARE, CoupledModel, build_model, hint_vector
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
    """The coupled model solved by HiGHS within ``time_limit_s`` for the whole call (the dp start
    and the model's build count against it), stopped as soon as the gap it reports
    (``solvers.relative_gap`` of the re-scored energy against its bound, ``_decode``) is at most
    ``options.mip_rel_gap`` (``GapRule``), or on a stop request (Ctrl-C) with its best answer."""
    t0 = time.perf_counter()
    start = warm_start(problem, hint)
    model = build_model(problem, start.energy_j)
    if model.nx == 0:       # nothing can save energy: keeping every motor on is optimal
        sol = solution_from_idle(problem, "milp", Status.OPTIMAL, int(model.angles[0]),
                                 np.zeros(0, np.int64), solve_s=time.perf_counter() - t0,
                                 bound_j=problem.energy_before_j)
        return sol
    share_bound = model.bound_j
    if stop_requested():    # Ctrl-C before the search: the start, bounded, said so
        return _start_answer(problem, start, share_bound, Status.FEASIBLE, time.perf_counter() - t0,
                             "not searched: stop requested", Stopped.INTERRUPTED)
    M = _columns(model)
    rule = GapRule(model, M, problem.options.mip_rel_gap, t0)
    h = _highs(problem, model, M, time_limit_s, rule.highs_rel_gap)
    if time_limit_s is not None:
        # the limit is for the whole call: the dp start and the model's build count against it
        h.setOptionValue("time_limit", max(float(time_limit_s) - (time.perf_counter() - t0), 0.01))
    hv = hint_vector(problem, model, start)
    run = run_highs(h, start=None if hv is None else _full_start(model, M, *hv), stop_when=rule)
    sol = _decode(problem, model, M, h, start, share_bound, time.perf_counter() - t0, run.stopped)
    if run.by_rule:
        sol = replace(sol, message=sol.message + "; stopped at the reported gap (fewest lines at "
                                                 "that energy not proven)")
    return sol


class GapRule:
    """The stopping rule: the gap ``_decode`` will report, from a HiGHS MIP callback's data.

    HiGHS's objective is energy + ``LINE_WEIGHT_J`` x lines, with the energy before gating as its
    offset; the gap we report is on the energy alone against ``max(dual bound - LINE_WEIGHT_J x
    lines_ub, share bound)`` (``_decode``). The two differ: the share bound can be far above
    HiGHS's dual bound (budgets: the survey's Marlin 1 % runs reported gaps of 6e-6..4e-5 while
    HiGHS ran to its 60 s limit on its own), and the line weight sits in HiGHS's gap. So HiGHS
    is stopped by this rule (``__call__``), and its own ``mip_rel_gap`` is set low enough
    (``highs_rel_gap``) that when it stops by itself our gap is within the tolerance too:
    with E the energy, P = E + w l its objective, D its dual bound and L the most lines,
    (E - max(D - w L, .)) / E <= tolH (1 + w L / E) + w L / E, at most ``rel_gap`` for
    tolH = (rel_gap - w L / E_min) / (1 + w L / E_min), E_min the share bound. Once our gap is
    within the tolerance the search goes on for the line tie-break only a little longer
    (``LINE_TIEBREAK_S``, ``LINE_TIEBREAK_SHARE``)."""

    def __init__(self, model: CoupledModel, M: dict, rel_gap: float, t0: float | None = None):
        self.t0 = time.perf_counter() if t0 is None else t0
        self.stop_at = math.inf         # set when our gap is first within the tolerance
        self.rel_gap = float(rel_gap)
        self.share_bound = float(model.bound_j)
        self.lines_ub = float(model.x_lines.sum() + len(model.z_members) + len(model.w_members))
        ox, oy, oz, ow, oa = M["offsets"]
        # lines of a solution, from its column values (x own lines, one per z and w)
        self.line_cols = np.concatenate((ox + np.arange(model.nx), oz + np.arange(len(model.z_members)),
                                         ow + np.arange(len(model.w_members))))
        self.line_coef = np.concatenate((model.x_lines, np.ones(len(model.z_members) + len(model.w_members))))
        w_l = LINE_WEIGHT_J * self.lines_ub / max(self.share_bound, 1e-12)
        self.highs_rel_gap = max(0.0, (self.rel_gap - w_l) / (1.0 + w_l))
        self._primal = math.nan
        self._energy = math.nan

    def bound_j(self, dual: float, primal: float) -> float:
        """The bound on the energy alone that ``_decode`` reports."""
        return max(float(min(dual, primal)) - LINE_WEIGHT_J * self.lines_ub, self.share_bound)

    def __call__(self, out) -> bool:
        primal = float(out.mip_primal_bound)
        if not math.isfinite(primal):
            return False                    # no incumbent yet
        if primal != self._primal:          # a new incumbent: its energy without the line weight
            col = np.asarray(out.mip_solution)
            if len(col) <= int(self.line_cols.max(initial=-1)):
                return False
            lines = float(self.line_coef @ np.round(col[self.line_cols]))
            self._primal, self._energy = primal, primal - LINE_WEIGHT_J * lines
        gap = relative_gap(self._energy, self.bound_j(float(out.mip_dual_bound), primal))
        if gap > self.rel_gap:
            return False
        now = time.perf_counter()
        if self.stop_at == math.inf:    # the gap is reached: a little more for the lines
            self.stop_at = now + max(LINE_TIEBREAK_S, LINE_TIEBREAK_SHARE * (now - self.t0))
        return now >= self.stop_at


def _highs(problem: GatingProblem, model: CoupledModel, M: dict, time_limit_s: float | None,
           highs_rel_gap: float | None = None):
    """A ``highspy.Highs`` holding the model's LP (``_columns``), options set; HiGHS's own
    ``mip_rel_gap`` is ``highs_rel_gap`` where given (``GapRule.highs_rel_gap``)."""
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
    opts = highs_options(problem, time_limit_s)
    if highs_rel_gap is not None:
        opts["mip_rel_gap"] = highs_rel_gap
    for name, value in opts.items():
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


def _start_answer(problem: GatingProblem, start: GatingSolution, share_bound: float, status: Status,
                  solve_s: float, why: str, stopped: Stopped) -> GatingSolution:
    """The warm start as milp's answer (no solution of HiGHS's own), bounded by the share bound;
    "optimal" only where that bound proves it."""
    gap = relative_gap(start.energy_j, share_bound)
    if status == Status.FEASIBLE and gap <= problem.options.mip_rel_gap:
        status = Status.OPTIMAL
    return replace(start, formulation="milp", status=status, solve_s=solve_s, bound_j=share_bound,
                   gap=gap, stopped=Stopped.NO if status == Status.OPTIMAL else stopped,
                   message=f"{why}; returned the dp/hint start")


def _decode(problem: GatingProblem, model: CoupledModel, M: dict, h, start: GatingSolution,
            share_bound: float, solve_s: float, stopped: Stopped = Stopped.NO) -> GatingSolution:
    """The solution HiGHS found (re-scored), its bound and the gap we report; the start where it
    found none. The status follows the reported gap: "optimal" when it is within
    ``mip_rel_gap`` (``GapRule``), else "feasible", with why the search stopped."""
    import highspy
    status = h.getModelStatus()
    info = h.getInfo()
    mapped = _status_map().get(status, Status.FALLBACK)
    has_sol = info.primal_solution_status == 2  # kSolutionStatusFeasible
    if not stopped and status == highspy.HighsModelStatus.kTimeLimit:
        stopped = Stopped.TIME_LIMIT
    if mapped == Status.INFEASIBLE:
        return _start_answer(problem, start, share_bound, Status.INFEASIBLE, solve_s,
                             f"HiGHS: {h.modelStatusToString(status)}", Stopped.NO)
    if not has_sol:
        # no solution of its own (time limit or Ctrl-C before any, or an error): the incumbent
        return _start_answer(problem, start, share_bound, Status.FALLBACK, solve_s,
                             f"HiGHS: {h.modelStatusToString(status)}", stopped)
    col = np.asarray(h.getSolution().col_value)
    ox, oy = M["offsets"][0], M["offsets"][1]
    xs = col[ox:ox + model.nx] > 0.5
    ys = col[oy:oy + len(model.angles)]
    k = int(model.angles[int(np.argmax(ys))])
    chosen = model.x_idle[xs]
    # the objective is energy + LINE_WEIGHT_J * lines; any solution has lines <= lines_ub, so
    # energy >= dual bound - LINE_WEIGHT_J * lines_ub is a valid bound on energy alone; the
    # share bound holds too (HiGHS stopped before its root LP, or bounds less)
    rule = GapRule(model, M, problem.options.mip_rel_gap)
    bound = rule.bound_j(float(info.mip_dual_bound), float(info.objective_function_value))
    sol = solution_from_idle(problem, "milp", Status.FEASIBLE, k, chosen, solve_s=solve_s, bound_j=bound,
                             message=f"HiGHS {h.modelStatusToString(status)}; {model.nx} gap variables, "
                                     f"{len(model.angles)} angle(s), {len(model.pruned)} pruned by bound")
    proven = sol.gap <= problem.options.mip_rel_gap
    sol = replace(sol, status=Status.OPTIMAL if proven else Status.FEASIBLE,
                  stopped=Stopped.NO if proven else stopped)
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
