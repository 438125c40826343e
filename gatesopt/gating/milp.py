"""Exact gating for the coupled problem as a MILP, solved by HiGHS through highspy.

Model (formulations/gating.md "milp", same symbols): binaries ``x[g]`` (gap g off) and ``y[k]``
(rotation k chosen, sum 1, ``x[g] <= y[k(g)]``); line variables ``z[e]`` for instruction moments
shared by several gaps (merged lines, one stall each) and ``w[t]`` for split moments shared by
several gaps; AND variables ``a[p]`` for X/Y gap pairs whose overlap has a non-additive power
correction; budget rows on added time and added lines. Objective: energy (J) + ``LINE_WEIGHT_J`` x
lines (lexicographic by a small weight, see the md). The matrices are built directly (column-wise
CSC) because a modelling layer (cvxpy) takes longer to build than HiGHS takes to solve at 10^5 gaps.

``CoupledModel`` is the solver-neutral model; ``gatesopt.gating.cpsat`` solves the same one.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .._native import run_highs

from ..program import X, Y
from . import dp
from .problem import (GatingProblem, GatingSolution, _integral, _is_split, _row_at, _TIME_EPS_S,
                      solution_from_gaps)

#: HiGHS's symmetry detection (uninterruptible, 6.7 s on a 27k-column model) runs only under a
#: time limit at least this long (see ``solve``)
SYMMETRY_MIN_LIMIT_S = 10.0
LINE_WEIGHT_J = 1e-6            # J per added line in the objective (lexicographic tie-break)


@dataclass(frozen=True, eq=False)
class CoupledModel:
    """Variables: x (one per kept gap), y (one per kept angle), z (shared lines), w (shared splits),
    a (XY AND pairs). Costs in J; lines and stall seconds per variable for the budgets."""

    gaps: np.ndarray            # (nx,) problem gap index of each x
    x_angle: np.ndarray         # (nx,) position in ``angles`` of each x
    angles: np.ndarray          # (ny,) problem angle index of each y
    x_energy_j: np.ndarray      # (nx,) -saving + own (unshared) stall energy
    x_lines: np.ndarray         # (nx,) own (unshared) lines
    x_stall_s: np.ndarray       # (nx,) own stall
    z_members: list             # (nz,) arrays of x positions sharing one instruction line
    z_energy_j: np.ndarray      # (nz,) stall energy of that line
    z_stall_s: np.ndarray       # (nz,)
    w_members: list             # (nw,) arrays of x positions sharing one split
    a_pairs: np.ndarray         # (na, 2) x positions of an X gap and a Y gap that overlap
    a_energy_j: np.ndarray      # (na,) non-additive correction when both are off (J)
    energy_before_j: float
    max_time_s: float           # budgets (inf: none)
    max_lines: float
    pruned: tuple               # angle indices left out by the bound (see ``build_model``)
    bound_j: float = -math.inf  # lower bound on the optimum energy over all angles (``build_model``)

    @property
    def nx(self) -> int:
        return len(self.gaps)


def _overlap_integral(problem, rate, cum, a, b):
    """Integral of ``rate`` (per step) over [a, b] on the problem timeline."""
    ra = _row_at(problem.start_s, a, "off")
    rb = _row_at(problem.start_s, b, "on")
    return _integral(cum, problem.start_s, rate, b, rb) - _integral(cum, problem.start_s, rate, a, ra)


def build_model(problem: GatingProblem, incumbent_j: float = math.inf) -> CoupledModel:
    """The coupled model, with three safe reductions:

    * a gap with ``gap_saving_j <= 0`` is never off in an optimum unless a negative XY correction
      could pay for it, so it gets no variable in that case;
    * nor does a gap whose saving does not exceed the stall energy of those of its instructions no
      other gap can share (``_worth_a_variable``);
    * angle k is left out when its relaxation bound ``energy_before_j - sum(max(saving, 0)) +
      (negative XY corrections)`` is above ``incumbent_j`` (the energy of a known feasible solution):
      stalls and budgets only add energy, so no solution at that angle beats the incumbent;
      then also when the share bound (``_angle_bounds``: each shared line's stall charged
      1/|sharers| to each sharer, with budgets the fractional knapsacks) is above it.

    ``bound_j`` of the result is a lower bound on the optimum over every angle (the share bound of
    the kept angles, the incumbent for the rest).
    """
    E0 = problem.energy_before_j
    inter = problem.xy_inter_w
    use_inter = problem.xy_coupled
    neg_inter = use_inter and bool(np.any(inter < 0))
    sav = problem.gap_saving_j
    keep_gap = (sav > 0) | (neg_inter & np.isin(problem.gap_motor, (X, Y)))
    # angle bound
    K = problem.n_angles
    pos = np.bincount(problem.gap_angle, weights=np.maximum(sav, 0.0), minlength=K)
    lb = E0 - pos
    if neg_inter:
        lb = lb + float(np.minimum(inter, 0.0) @ problem.duration_s)   # most the correction can give
    kept_angles = np.flatnonzero(lb <= incumbent_j + 1e-9 * max(abs(E0), 1.0))
    if len(kept_angles) == 0:
        kept_angles = np.array([int(np.argmin(lb))])
    model = _build_model(problem, kept_angles, keep_gap, neg_inter, use_inter)
    lbk = _angle_bounds(model)
    tol = 1e-9 * max(abs(E0), 1.0)
    if len(kept_angles) > 1 and math.isfinite(incumbent_j):
        # On a 217k-line Cura file under Marlin (shared M18 stalls) this leaves 1 angle of 16 and
        # bounds the dp start within 8e-6; HiGHS on all 16 (86k gap variables) had not finished
        # its root in 10 s and reported a 75 % gap
        keep = lbk <= incumbent_j + tol
        if not keep.all():
            if not keep.any():
                keep[int(np.argmin(lbk))] = True
            model = _build_model(problem, kept_angles[keep], keep_gap, neg_inter, use_inter)
            lbk = lbk[keep]
    bound = float(lbk.min()) if len(lbk) else E0
    return replace(model, bound_j=min(bound, incumbent_j))


def _angle_bounds(model: CoupledModel) -> np.ndarray:
    """Per kept angle, a lower bound on the energy (the share bound): a shared line, split or
    stall is charged 1/|sharers| to each sharer (their sum never exceeds what is really paid, and
    never more than the LP relaxation's ``x <= z`` charges), which makes the gaps independent: every
    gap of negative charged energy off, plus every negative XY correction. Under budgets each
    budget alone then gives a fractional knapsack over the same charges; the larger bound is kept."""
    e = model.x_energy_j.copy()
    lines = model.x_lines.copy()
    tau = model.x_stall_s.copy()
    if model.z_members:
        lens = np.array([len(m) for m in model.z_members])
        mem = np.concatenate(model.z_members)
        np.add.at(e, mem, np.repeat(model.z_energy_j / lens, lens))
        np.add.at(lines, mem, np.repeat(1.0 / lens, lens))
        np.add.at(tau, mem, np.repeat(model.z_stall_s / lens, lens))
    if model.w_members:
        lens = np.array([len(m) for m in model.w_members])
        np.add.at(lines, np.concatenate(model.w_members), np.repeat(1.0 / lens, lens))
    ny = len(model.angles)
    neg_a = np.zeros(ny)
    if len(model.a_pairs):
        np.add.at(neg_a, model.x_angle[model.a_pairs[:, 0]], np.minimum(model.a_energy_j, 0.0))
    out = model.energy_before_j + neg_a
    for k in range(ny):
        sel = np.flatnonzero((model.x_angle == k) & (e < 0))
        if not len(sel):
            continue
        gain = -e[sel]
        best = gain.sum()
        for w, cap in ((lines[sel], model.max_lines), (tau[sel], model.max_time_s)):
            if not math.isfinite(cap):
                continue
            pos = w > 0
            free = gain[~pos].sum()
            order = np.argsort(-gain[pos] / w[pos], kind="stable")
            g, ww = gain[pos][order], w[pos][order]
            cw = np.cumsum(ww)
            j = int(np.searchsorted(cw, cap, "right"))
            val = free + g[:j].sum()
            if j < len(g):
                val += g[j] * (cap - (cw[j - 1] if j else 0.0)) / ww[j]
            best = min(best, val)
        out[k] -= best
    return out


def _build_model(problem, kept_angles, keep_gap, neg_inter, use_inter) -> CoupledModel:
    o = problem.options
    n = problem.n_steps
    T = problem.total_s
    E0 = problem.energy_before_j
    sav = problem.gap_saving_j
    K = problem.n_angles
    pruned = tuple(int(k) for k in np.setdiff1d(np.arange(K), kept_angles))
    keep_gap = keep_gap & np.isin(problem.gap_angle, kept_angles)
    if not neg_inter:
        keep_gap[keep_gap] = _worth_a_variable(problem, np.flatnonzero(keep_gap))
    gaps = np.flatnonzero(keep_gap)
    ang_pos = np.full(K, -1)
    ang_pos[kept_angles] = np.arange(len(kept_angles))
    x_angle = ang_pos[problem.gap_angle[gaps]]

    gs, ge = problem.gap_start_s[gaps], problem.gap_end_s[gaps]
    nx = len(gaps)
    has_on = (ge < T - _TIME_EPS_S) & o.on_line
    # events: one per off and per on instruction of each gap
    ev_x = np.concatenate((np.arange(nx), np.flatnonzero(has_on)))
    ev_on = np.concatenate((np.zeros(nx, bool), np.ones(int(has_on.sum()), bool)))
    ev_t = np.concatenate((gs, ge[has_on]))
    ev_row = np.concatenate((_row_at(problem.start_s, gs, "off"), _row_at(problem.start_s, ge[has_on], "on")))
    ev_split = _is_split(problem.start_s, ev_row, ev_t)
    ev_ang = x_angle[ev_x]
    stall_w = _stall_power_w(problem)
    # lines per event: a group on one enable pin writes one line per motor unless lines merge
    size = {g[0]: len(g) for g in o.groups}
    mult = np.ones(nx) if o.merge_lines else np.array([size[int(m)] for m in problem.gap_motor[gaps]], float)
    ev_mult = mult[ev_x]
    ev_stall_s = np.where(ev_on, o.stall_on_s, o.stall_off_s) * ev_mult
    ev_stall_j = ev_stall_s * stall_w[np.minimum(ev_row, n - 1)]

    x_energy = -sav[gaps].astype(float)
    x_lines = np.zeros(nx)
    x_stall = np.zeros(nx)
    z_members, z_energy, z_stall = [], [], []

    def groups(keys_sorted_idx, key_arrays):
        """Split sorted event indices into runs of equal keys."""
        idx = keys_sorted_idx
        if len(idx) == 0:
            return []
        change = np.zeros(len(idx), bool)
        change[0] = True
        for arr in key_arrays:
            change[1:] |= arr[idx][1:] != arr[idx][:-1]
        starts = np.flatnonzero(change)
        return np.split(idx, starts[1:])

    # instruction lines: shared by (angle, moment, direction) when merge_lines
    if o.merge_lines:
        order = np.lexsort((ev_on, ev_t, ev_ang))
        runs = groups(order, (ev_ang, ev_t, ev_on))
    else:
        runs = [np.array([i]) for i in range(len(ev_x))]
    single = [r[0] for r in runs if len(r) == 1]
    if single:
        s = np.array(single)
        np.add.at(x_lines, ev_x[s], ev_mult[s])
        np.add.at(x_stall, ev_x[s], ev_stall_s[s])
        np.add.at(x_energy, ev_x[s], ev_stall_j[s])
    for r in runs:
        if len(r) > 1:
            z_members.append(np.unique(ev_x[r]))
            z_energy.append(ev_stall_j[r[0]])
            z_stall.append(ev_stall_s[r[0]])
    # splits: one per (angle, moment) whatever number of lines go there
    sp = np.flatnonzero(ev_split)
    w_members = []
    if len(sp):
        order = sp[np.lexsort((ev_t[sp], ev_ang[sp]))]
        for r in groups(order, (ev_ang, ev_t)):
            mem = np.unique(ev_x[r])
            if len(mem) == 1:
                x_lines[mem[0]] += 1.0
            else:
                w_members.append(mem)

    # non-additive XY power: AND of overlapping X and Y gaps of the same angle
    a_pairs = np.zeros((0, 2), np.int64)
    a_energy = np.zeros(0)
    if use_inter:
        rate = problem.xy_inter_w
        cum = np.concatenate(([0.0], np.cumsum(rate * problem.duration_s)))
        pairs, vals = [], []
        mot = problem.gap_motor[gaps]
        for k in range(len(kept_angles)):
            xi = np.flatnonzero((x_angle == k) & (mot == X))
            yi = np.flatnonzero((x_angle == k) & (mot == Y))
            if not len(xi) or not len(yi):
                continue
            # gaps of one motor are disjoint and sorted: Y gaps overlapping X gap i are a range
            lo = np.searchsorted(ge[yi], gs[xi], "right")
            hi = np.searchsorted(gs[yi], ge[xi], "left")
            cnt = np.maximum(hi - lo, 0)
            px = np.repeat(xi, cnt)
            py = yi[np.concatenate([np.arange(a, b) for a, b in zip(lo, hi)]).astype(np.int64)] if cnt.sum() else np.zeros(0, np.int64)
            if not len(px):
                continue
            a0 = np.maximum(gs[px], gs[py])
            b0 = np.minimum(ge[px], ge[py])
            ok = b0 > a0
            v = _overlap_integral(problem, rate, cum, a0[ok], b0[ok])
            pairs.append(np.column_stack((px[ok], py[ok])))
            vals.append(v)
        if pairs:
            a_pairs = np.concatenate(pairs).astype(np.int64)
            a_energy = np.concatenate(vals)
            nz = a_energy != 0
            a_pairs, a_energy = a_pairs[nz], a_energy[nz]

    return CoupledModel(gaps=gaps, x_angle=x_angle, angles=kept_angles, x_energy_j=x_energy,
                        x_lines=x_lines, x_stall_s=x_stall, z_members=z_members,
                        z_energy_j=np.array(z_energy, float), z_stall_s=np.array(z_stall, float),
                        w_members=w_members, a_pairs=a_pairs, a_energy_j=a_energy,
                        energy_before_j=E0, max_time_s=problem.max_added_time_s,
                        max_lines=problem.max_added_lines, pruned=pruned)


def _worth_a_variable(problem: GatingProblem, cand: np.ndarray) -> np.ndarray:
    """False for a gap whose saving cannot pay for the stalls of its instructions that no other
    gap can share (switching it off never lowers the energy and never saves a line or budget)."""
    o = problem.options
    if o.stall_off_s == 0 and o.stall_on_s == 0:
        return np.ones(len(cand), bool)
    n, T = problem.n_steps, problem.total_s
    gs, ge = problem.gap_start_s[cand], problem.gap_end_s[cand]
    ang = problem.gap_angle[cand]
    has_on = (ge < T - _TIME_EPS_S) & o.on_line

    def shared(t, mask):
        # another candidate gap of the same angle has an instruction of this direction at t
        if not o.merge_lines:
            return np.zeros(len(t), bool)
        key = np.where(mask, t, np.nan)
        order = np.lexsort((key, ang))
        k2, a2 = key[order], ang[order]
        dup = np.zeros(len(t), bool)
        same = (k2[1:] == k2[:-1]) & (a2[1:] == a2[:-1])
        dup[order[1:][same]] = True
        dup[order[:-1][same]] = True
        return dup

    stall_w = _stall_power_w(problem)
    r_off = np.minimum(_row_at(problem.start_s, gs, "off"), n - 1)
    r_on = np.minimum(_row_at(problem.start_s, ge, "on"), n - 1)
    size = {g[0]: len(g) for g in o.groups}
    mult = 1.0 if o.merge_lines else np.array([size[int(m)] for m in problem.gap_motor[cand]], float)
    own = mult * (~shared(gs, np.ones(len(cand), bool)) * o.stall_off_s * stall_w[r_off]
                  + (has_on & ~shared(ge, has_on)) * o.stall_on_s * stall_w[r_on])
    return problem.gap_saving_j[cand] > own


def _stall_power_w(problem: GatingProblem) -> np.ndarray:
    from ..energy import step_power_w
    return step_power_w(problem.stall_coeffs, problem.enable0)


def hint_vector(problem: GatingProblem, model: CoupledModel, hint: GatingSolution | None):
    """(x, y) 0/1 vectors of a hint solution: a gap is on in the hint's angle if the hint switches
    its motor off anywhere inside it (the gap off throughout is at least as good; the solver
    rejects the start if it breaks a budget)."""
    if hint is None:
        return None
    k = int(np.searchsorted(model.angles, hint.angle_index))
    if k >= len(model.angles) or model.angles[k] != hint.angle_index:
        return None
    x = np.zeros(model.nx)
    sel = np.flatnonzero(model.x_angle == k)
    g = model.gaps[sel]
    for m in np.unique(hint.off_motor):
        hs = hint.off_start_s[hint.off_motor == m]
        he = hint.off_end_s[hint.off_motor == m]
        mine = sel[problem.gap_motor[g] == m]
        if not len(mine):
            continue
        a = problem.gap_start_s[model.gaps[mine]]
        b = problem.gap_end_s[model.gaps[mine]]
        mid = (hs + he) / 2.0
        j = np.searchsorted(a, mid, "right") - 1
        ok = (j >= 0) & (mid < b[np.maximum(j, 0)])
        x[mine[j[ok]]] = 1.0
    y = np.zeros(len(model.angles))
    y[k] = 1.0
    return x, y


def incumbent(problem: GatingProblem, hint: GatingSolution | None = None) -> GatingSolution:
    """A feasible start: the better of ``hint`` and dp's pass with its budget repair (not
    ``dp.solve``, which would build the model once more for its bound)."""
    start = dp.heuristic(problem)
    if hint is not None and _feasible(problem, hint) and (hint.energy_j, hint.lines_added) < (start.energy_j, start.lines_added):
        start = hint
    return start


def _feasible(problem: GatingProblem, sol: GatingSolution) -> bool:
    return (sol.added_time_s <= problem.max_added_time_s + 1e-9
            and sol.lines_added <= problem.max_added_lines)


# ------------------------------------------------------------------------------------------------
# HiGHS
def _status_map():
    import highspy
    S = highspy.HighsModelStatus
    return {S.kOptimal: "optimal", S.kInfeasible: "infeasible", S.kTimeLimit: "feasible",
            S.kIterationLimit: "feasible", S.kSolutionLimit: "feasible", S.kInterrupt: "feasible",
            S.kObjectiveBound: "feasible", S.kObjectiveTarget: "feasible", S.kMemoryLimit: "feasible"}


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
    import highspy

    t0 = time.perf_counter()
    start = incumbent(problem, hint)
    model = build_model(problem, start.energy_j)
    if model.nx == 0:       # nothing can save energy: keeping every motor on is optimal
        sol = solution_from_gaps(problem, "milp", "optimal", int(model.angles[0]), np.zeros(0, np.int64),
                                 solve_s=time.perf_counter() - t0, bound=problem.energy_before_j)
        return sol
    share_bound = model.bound_j
    M = _columns(model)
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
    h.setOptionValue("output_flag", False)
    h.setOptionValue("mip_rel_gap", problem.options.mip_rel_gap)
    h.setOptionValue("threads", 1)
    h.setOptionValue("presolve", "off")
    # HiGHS 1.12's symmetry detection does not look at the clock. On the Marlin 1 % budget of a
    # PrusaSlicer y-motor file (12.8k gaps) it took 6.7 s at the root and, after HiGHS restarted
    # the search, ran on to 192 s against a 20 s time limit (also 80 s on a Cura file). No restart:
    # every budgeted corpus file keeps a 20 s limit and proves what it proved. Symmetry detection
    # itself only where the limit leaves room for it: it proves 4 of those files in 1-3 s that
    # stay open at 20 s without it, but under a 2 s limit it made the same run 8.3 s
    h.setOptionValue("mip_allow_restart", False)
    h.setOptionValue("mip_detect_symmetry", time_limit_s is None or time_limit_s >= SYMMETRY_MIN_LIMIT_S)
    h.setOptionValue("random_seed", int(problem.options.seed))
    h.passModel(lp)
    if time_limit_s is not None:
        # the limit is for the whole call: the dp start and the model's build count against it
        h.setOptionValue("time_limit", max(float(time_limit_s) - (time.perf_counter() - t0), 0.01))
    hv = hint_vector(problem, model, start)
    run_highs(h, start=None if hv is None else _full_start(model, M, *hv))
    status = h.getModelStatus()
    info = h.getInfo()
    mapped = _status_map().get(status, "fallback")
    has_sol = info.primal_solution_status == 2  # kSolutionStatusFeasible
    solve_s = time.perf_counter() - t0
    if mapped == "infeasible" or not has_sol:
        # no solution of its own (time limit before any, or an error): the incumbent, said so
        st = "fallback" if mapped != "infeasible" else "infeasible"
        return replace(start, formulation="milp", status=st, solve_s=solve_s,
                       bound=share_bound, gap=_gap(start.energy_j, share_bound),
                       message=f"HiGHS: {h.modelStatusToString(status)}; returned the dp/hint start")
    col = np.asarray(h.getSolution().col_value)
    ox, oy = M["offsets"][0], M["offsets"][1]
    xs = col[ox:ox + model.nx] > 0.5
    ys = col[oy:oy + len(model.angles)]
    k = int(model.angles[int(np.argmax(ys))])
    chosen = model.gaps[xs]
    # the objective is energy + LINE_WEIGHT_J * lines; any solution has lines <= lines_ub, so
    # energy >= dual bound - LINE_WEIGHT_J * lines_ub is a valid bound on energy alone
    lines_ub = float(model.x_lines.sum() + len(model.z_members) + len(model.w_members))
    bound = float(min(info.mip_dual_bound, info.objective_function_value)) - LINE_WEIGHT_J * lines_ub
    bound = max(bound, share_bound)     # HiGHS stopped before its root LP: the share bound holds
    sol = solution_from_gaps(problem, "milp", mapped, k, chosen, solve_s=solve_s, bound=bound,
                             message=f"HiGHS {h.modelStatusToString(status)}; {model.nx} gap variables, "
                                     f"{len(model.angles)} angle(s), {len(model.pruned)} pruned by bound")
    # the model's objective must be the re-scored energy plus the line weight: say so if not
    model_j = float(info.objective_function_value) - LINE_WEIGHT_J * sol.lines_added
    if abs(model_j - sol.energy_j) > 1e-6 * max(abs(sol.energy_j), 1.0):
        sol = replace(sol, message=sol.message + f"; model energy {model_j:.6f} J != scored {sol.energy_j:.6f} J")
    return sol


def _gap(energy_j: float, bound_j: float) -> float:
    """(energy - bound) / energy, as ``solution_from_gaps`` reports it."""
    return max(0.0, (energy_j - bound_j) / max(abs(energy_j), 1e-12)) if math.isfinite(bound_j) else math.nan


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
