"""The coupled gating model, solver-neutral, and its share bound (formulations/gating.md §3).

Binaries ``x[g]`` (idle interval g off) and ``y[k]`` (rotation k chosen, sum 1, ``x[g] <=
y[k(g)]``); line variables ``z[e]`` for instruction moments shared by several intervals (merged
lines, one stall each) and ``w[t]`` for split moments shared by several intervals; AND variables
``a[p]`` for X/Y interval pairs whose overlap has a non-additive power correction; budget rows on
added time and added lines. ``build_model`` writes it with exact reductions and a lower bound on
the optimum (the *share bound*, ``bound_j``), which ``dp`` reports for its heuristic answer and
``milp`` / ``cpsat`` / ``cvxpy_model`` solve or export.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..energy import step_power_w
from ..program import X, Y
from .problem import GatingProblem, chain_predecessors, off_stall_s, on_stall_s
from .scoring import line_moments
from .solution import GatingSolution
from .timeline import TIME_EPS_S, integral, is_split, row_at

#: the exact formulations (``milp``, ``cpsat``) stop when the gap they report, on the energy, is
#: within ``mip_rel_gap``; from then on the search goes on for the line tie-break (fewest lines at
#: that energy) for at most this long, or this share of the time it took to get there if that is
#: longer: lines are a tie-break, never a reason to run to the time limit (HiGHS's own gap counts
#: them: it ran to 60 s limits on budgeted Marlin files while the energy gap was 6e-6..4e-5)
LINE_TIEBREAK_S = 0.5
LINE_TIEBREAK_SHARE = 0.25


@dataclass(frozen=True, eq=False)
class CoupledModel:
    """Variables: x (one per kept idle interval), y (one per kept angle), z (shared lines),
    w (shared splits), a (XY AND pairs). Costs in J; lines and stall seconds per variable for the
    budgets."""

    x_idle: np.ndarray          # (nx,) problem idle-interval index of each x
    x_angle: np.ndarray         # (nx,) position in ``angles`` of each x
    angles: np.ndarray          # (ny,) problem angle index of each y
    x_energy_j: np.ndarray      # (nx,) -saving + own (unshared) stall energy
    x_lines: np.ndarray         # (nx,) own (unshared) lines
    x_stall_s: np.ndarray       # (nx,) own stall
    z_members: list             # (nz,) arrays of x positions sharing one instruction line
    z_energy_j: np.ndarray      # (nz,) stall energy of that line
    z_stall_s: np.ndarray       # (nz,)
    w_members: list             # (nw,) arrays of x positions sharing one split
    a_pairs: np.ndarray         # (na, 2) x positions of an X and a Y idle interval that overlap
    a_energy_j: np.ndarray      # (na,) non-additive correction when both are off (J)
    energy_before_j: float
    max_time_s: float           # budgets (inf: none)
    max_lines: float
    pruned: tuple               # angle indices left out by the bound (see ``build_model``)
    bound_j: float = -math.inf  # lower bound on the optimum energy over all angles (``build_model``)
    c_members: list = field(default_factory=list)   # cliques of x positions, at most one off each:
                                                    # rule B of a firmware schedule (``_spacing_cliques``)

    @property
    def nx(self) -> int:
        return len(self.x_idle)


def _overlap_integral(problem, rate, cum, a, b):
    """Integral of ``rate`` (per step) over [a, b] on the problem timeline."""
    ra = row_at(problem.start_s, a, "off")
    rb = row_at(problem.start_s, b, "on")
    return integral(cum, problem.start_s, rate, b, rb) - integral(cum, problem.start_s, rate, a, ra)


def build_model(problem: GatingProblem, incumbent_j: float = math.inf) -> CoupledModel:
    """The coupled model, with three safe reductions:

    * an idle interval with ``idle_saving_j <= 0`` is never off in an optimum unless a negative XY
      correction could pay for it, so it gets no variable in that case;
    * nor does one whose saving does not exceed the stall energy of those of its instructions no
      other interval can share (``_worth_a_variable``);
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
    sav = problem.idle_saving_j
    keep_idle = (sav > 0) | (neg_inter & np.isin(problem.idle_motor, (X, Y)))
    # angle bound
    K = problem.n_angles
    pos = np.bincount(problem.idle_angle, weights=np.maximum(sav, 0.0), minlength=K)
    lb = E0 - pos
    if neg_inter:
        lb = lb + float(np.minimum(inter, 0.0) @ problem.duration_s)   # most the correction can give
    kept_angles = np.flatnonzero(lb <= incumbent_j + 1e-9 * max(abs(E0), 1.0))
    if len(kept_angles) == 0:
        kept_angles = np.array([int(np.argmin(lb))])
    model = _build_model(problem, kept_angles, keep_idle, neg_inter, use_inter)
    lbk = _angle_bounds(model)
    tol = 1e-9 * max(abs(E0), 1.0)
    if len(kept_angles) > 1 and math.isfinite(incumbent_j):
        # On a 217k-line Cura file under Marlin (shared M18 stalls) this leaves 1 angle of 16 and
        # bounds the dp start within 8e-6; HiGHS on all 16 (86k interval variables) had not finished
        # its root in 10 s and reported a 75 % gap
        keep = lbk <= incumbent_j + tol
        if not keep.all():
            if not keep.any():
                keep[int(np.argmin(lbk))] = True
            model = _build_model(problem, kept_angles[keep], keep_idle, neg_inter, use_inter)
            lbk = lbk[keep]
    bound = float(lbk.min()) if len(lbk) else E0
    return replace(model, bound_j=min(bound, incumbent_j))


def _angle_bounds(model: CoupledModel) -> np.ndarray:
    """Per kept angle, a lower bound on the energy (the share bound): a shared line, split or
    stall is charged 1/|sharers| to each sharer (their sum never exceeds what is really paid, and
    never more than the LP relaxation's ``x <= z`` charges), which makes the idle intervals independent:
    every interval of negative charged energy off, plus every negative XY correction. Under budgets each
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


def _run_starts(order: np.ndarray, keys) -> np.ndarray:
    """Where the runs of equal ``keys`` start in the event indices ``order`` (sorted by them)."""
    if len(order) == 0:
        return np.zeros(0, np.int64)
    change = np.zeros(len(order), bool)
    change[0] = True
    for arr in keys:
        a = arr[order]
        change[1:] |= a[1:] != a[:-1]
    return np.flatnonzero(change)


def _run_members(order: np.ndarray, starts: np.ndarray, ev_x: np.ndarray) -> list:
    """Per run of ``order`` (from ``starts``), the sorted distinct idle intervals of its events.
    Sorted once for all runs (``np.unique`` per run took ~3.5 s over the ~300,000 runs of a 28 MB
    file)."""
    if len(order) == 0:
        return []
    run = np.repeat(np.arange(len(starts)), np.diff(np.append(starts, len(order))))
    x = ev_x[order]
    o = np.lexsort((x, run))
    run, x = run[o], x[o]
    keep = np.ones(len(x), bool)
    keep[1:] = (run[1:] != run[:-1]) | (x[1:] != x[:-1])
    run, x = run[keep], x[keep]
    cut = np.searchsorted(run, np.arange(len(starts) + 1)).tolist()
    return [x[a:b] for a, b in zip(cut[:-1], cut[1:])]


def _build_model(problem, kept_angles, keep_idle, neg_inter, use_inter) -> CoupledModel:
    """The model over the angles ``kept_angles`` and the idle intervals ``keep_idle`` (after
    ``_worth_a_variable`` unless a negative XY correction could pay for any interval)."""
    o = problem.options
    n = problem.n_steps
    T = problem.total_s
    E0 = problem.energy_before_j
    sav = problem.idle_saving_j
    K = problem.n_angles
    pruned = tuple(int(k) for k in np.setdiff1d(np.arange(K), kept_angles))
    keep_idle = keep_idle & np.isin(problem.idle_angle, kept_angles)
    if not neg_inter:
        keep_idle[keep_idle] = _worth_a_variable(problem, np.flatnonzero(keep_idle))
    idle = np.flatnonzero(keep_idle)
    ang_pos = np.full(K, -1)
    ang_pos[kept_angles] = np.arange(len(kept_angles))
    x_angle = ang_pos[problem.idle_angle[idle]]

    gs, ge = problem.idle_start_s[idle], problem.idle_end_s[idle]
    nx = len(idle)
    has_on = (ge < T - TIME_EPS_S) & o.on_line
    # events: one per off and per on instruction of each idle interval
    ev_x = np.concatenate((np.arange(nx), np.flatnonzero(has_on)))
    ev_on = np.concatenate((np.zeros(nx, bool), np.ones(int(has_on.sum()), bool)))
    off_t, off_row = line_moments(problem, problem.idle_motor[idle], gs)
    ev_t = np.concatenate((off_t, ge[has_on]))
    ev_row = np.concatenate((off_row, row_at(problem.start_s, ge[has_on], "on")))
    ev_split = is_split(problem.start_s, ev_row, ev_t)
    ev_ang = x_angle[ev_x]
    stall_w = _stall_power_w(problem)
    # lines per event: a group on one enable pin writes one line per motor unless lines merge
    size = {g[0]: len(g) for g in o.groups}
    mult = np.ones(nx) if o.merge_lines else np.array([size[int(m)] for m in problem.idle_motor[idle]], float)
    ev_mult = mult[ev_x]
    ev_stall_s = np.where(ev_on, on_stall_s(problem, ev_row, ev_split),
                          off_stall_s(problem, ev_row, ev_split)) * ev_mult
    ev_stall_j = ev_stall_s * stall_w[np.minimum(ev_row, n - 1)]

    x_energy = -sav[idle].astype(float)
    x_lines = np.zeros(nx)
    x_stall = np.zeros(nx)
    # instruction lines: shared by (angle, moment, direction) when merge_lines
    if o.merge_lines:
        order = np.lexsort((ev_on, ev_t, ev_ang))
        starts = _run_starts(order, (ev_ang, ev_t, ev_on))
    else:
        order = starts = np.arange(len(ev_x))
    first, members = order[starts], _run_members(order, starts, ev_x)
    length = np.diff(np.append(starts, len(order)))
    s = first[length == 1]
    if len(s):
        np.add.at(x_lines, ev_x[s], ev_mult[s])
        np.add.at(x_stall, ev_x[s], ev_stall_s[s])
        np.add.at(x_energy, ev_x[s], ev_stall_j[s])
    shared = np.flatnonzero(length > 1)
    z_members = [members[i] for i in shared.tolist()]
    z_energy, z_stall = ev_stall_j[first[shared]], ev_stall_s[first[shared]]
    # splits: one per (angle, moment) whatever number of lines go there
    sp = np.flatnonzero(ev_split)
    w_members = []
    if len(sp):
        order = sp[np.lexsort((ev_t[sp], ev_ang[sp]))]
        starts = _run_starts(order, (ev_ang, ev_t))
        members = _run_members(order, starts, ev_x)
        one = [int(m[0]) for m in members if len(m) == 1]
        np.add.at(x_lines, np.asarray(one, np.int64), 1.0)
        w_members = [m for m in members if len(m) > 1]

    a_pairs, a_energy = (_xy_pairs(problem, len(kept_angles), x_angle, idle, gs, ge) if use_inter
                        else (np.zeros((0, 2), np.int64), np.zeros(0)))
    return CoupledModel(c_members=_spacing_cliques(problem, idle),
                        x_idle=idle, x_angle=x_angle, angles=kept_angles, x_energy_j=x_energy,
                        x_lines=x_lines, x_stall_s=x_stall, z_members=z_members,
                        z_energy_j=np.asarray(z_energy, float), z_stall_s=np.asarray(z_stall, float),
                        w_members=w_members, a_pairs=a_pairs, a_energy_j=a_energy,
                        energy_before_j=E0, max_time_s=problem.max_added_time_s,
                        max_lines=problem.max_added_lines, pruned=pruned)


def _spacing_cliques(problem: GatingProblem, x_idle: np.ndarray) -> list:
    """Rule B of a firmware schedule as cliques over the x variables (formulations/gating.md §9):
    in a chain of one angle and motor, intervals p[j]..j (``chain_predecessors``) pairwise break
    the spacing, so at most one of them is off; only the maximal such sets are written."""
    o = problem.options
    if o.schedule is None or o.schedule.min_spacing_s <= 0 or not len(x_idle):
        return []
    key = problem.idle_angle[x_idle].astype(np.int64) * 8 + problem.idle_motor[x_idle]
    starts = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1])))
    out = []
    for lo, hi in zip(starts, np.append(starts[1:], len(x_idle))):
        p = chain_predecessors(problem, x_idle[lo:hi])
        j = np.flatnonzero(p < np.arange(hi - lo))
        maximal = (j == hi - lo - 1) | (p[np.minimum(j + 1, hi - lo - 1)] > p[j])
        out += [np.arange(lo + p[i], lo + i + 1) for i in j[maximal]]
    return out


def _xy_pairs(problem: GatingProblem, n_angles: int, x_angle, x_idle, gs, ge):
    """(pairs (na, 2) of x positions, (na,) J): X and Y idle intervals of one angle that overlap,
    and the non-additive XY correction over their overlap (``a_energy_j``; pairs where it is 0
    are left out)."""
    a_pairs = np.zeros((0, 2), np.int64)
    a_energy = np.zeros(0)
    rate = problem.xy_inter_w
    cum = np.concatenate(([0.0], np.cumsum(rate * problem.duration_s)))
    pairs, vals = [], []
    mot = problem.idle_motor[x_idle]
    for k in range(n_angles):
        xi = np.flatnonzero((x_angle == k) & (mot == X))
        yi = np.flatnonzero((x_angle == k) & (mot == Y))
        if not len(xi) or not len(yi):
            continue
        # intervals of one motor are disjoint and sorted: Y ones overlapping X interval i are a range
        lo = np.searchsorted(ge[yi], gs[xi], "right")
        hi = np.searchsorted(gs[yi], ge[xi], "left")
        cnt = np.maximum(hi - lo, 0)
        px = np.repeat(xi, cnt)
        py = (yi[np.concatenate([np.arange(a, b) for a, b in zip(lo, hi)]).astype(np.int64)]
              if cnt.sum() else np.zeros(0, np.int64))
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
    return a_pairs, a_energy


def _worth_a_variable(problem: GatingProblem, cand: np.ndarray) -> np.ndarray:
    """False for an idle interval whose saving cannot pay for the stalls of its instructions that
    no other interval can share (switching it off never lowers the energy and never saves a line
    or budget)."""
    o = problem.options
    if o.stall_off_s == 0 and o.stall_on_s == 0:
        return np.ones(len(cand), bool)
    n, T = problem.n_steps, problem.total_s
    gs, ge = problem.idle_start_s[cand], problem.idle_end_s[cand]
    ang = problem.idle_angle[cand]
    has_on = (ge < T - TIME_EPS_S) & o.on_line

    def shared(t, mask):
        # another candidate interval of the same angle has an instruction of this direction at t
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
    r_off = np.minimum(row_at(problem.start_s, gs, "off"), n - 1)
    q_on = row_at(problem.start_s, ge, "on")
    r_on = np.minimum(q_on, n - 1)
    on_s = on_stall_s(problem, q_on, is_split(problem.start_s, q_on, ge))
    size = {g[0]: len(g) for g in o.groups}
    mult = 1.0 if o.merge_lines else np.array([size[int(m)] for m in problem.idle_motor[cand]], float)
    q_off = row_at(problem.start_s, gs, "off")
    off_s = off_stall_s(problem, q_off, is_split(problem.start_s, q_off, gs))
    own = mult * (~shared(gs, np.ones(len(cand), bool)) * off_s * stall_w[r_off]
                  + (has_on & ~shared(ge, has_on)) * on_s * stall_w[r_on])
    return problem.idle_saving_j[cand] > own


def _stall_power_w(problem: GatingProblem) -> np.ndarray:
    return step_power_w(problem.stall_coeffs, problem.enable0)


def hint_vector(problem: GatingProblem, model: CoupledModel, hint: GatingSolution | None):
    """(x, y) 0/1 vectors of a hint solution: an idle interval is on in the hint's angle if the
    hint switches its motor off anywhere inside it (the interval off throughout is at least as
    good; the solver rejects the start if it breaks a budget)."""
    if hint is None:
        return None
    k = int(np.searchsorted(model.angles, hint.angle_index))
    if k >= len(model.angles) or model.angles[k] != hint.angle_index:
        return None
    x = np.zeros(model.nx)
    sel = np.flatnonzero(model.x_angle == k)
    g = model.x_idle[sel]
    for m in np.unique(hint.off_motor):
        hs = hint.off_start_s[hint.off_motor == m]
        he = hint.off_end_s[hint.off_motor == m]
        mine = sel[problem.idle_motor[g] == m]
        if not len(mine):
            continue
        a = problem.idle_start_s[model.x_idle[mine]]
        b = problem.idle_end_s[model.x_idle[mine]]
        mid = (hs + he) / 2.0
        j = np.searchsorted(a, mid, "right") - 1
        ok = (j >= 0) & (mid < b[np.maximum(j, 0)])
        x[mine[j[ok]]] = 1.0
    y = np.zeros(len(model.angles))
    y[k] = 1.0
    return x, y
