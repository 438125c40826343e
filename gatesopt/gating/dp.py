"""Exact gating when the problem separates: one linear, vectorised pass (formulations/gating.md "dp").

With no budgets, no shared stall and additive XY power, the energy of a gating is
E0 - sum_g x_g * net_g with net_g = idle_saving_j[g] - idle_stall_j[g]: each idle interval is
decided on its own, off iff net_g > 0 (a tie keeps the motor on: fewer lines). The best rotation is
the one with the least energy, then the fewest lines. Otherwise (budgets, shared stalls,
non-additive power) the same pass is a heuristic: budgets are repaired by dropping the intervals of
least net value per unit of budget, and the answer is bounded by the coupled model's share bound
(``coupled.build_model``): status "feasible" with that gap, "optimal" where the gap is within
``mip_rel_gap``. ``warm_start`` is the pass as ``milp`` and ``cpsat`` start from it.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..solvers import Status, relative_gap
from . import _kernels as _k
from .coupled import build_model
from .problem import GatingProblem, chain_predecessors
from .solution import GatingSolution, solution_from_idle

_REL_TIE = 1e-12


def spaced(problem: GatingProblem, candidates: np.ndarray) -> np.ndarray:
    """The most valuable subset of the idle intervals in the mask ``candidates`` (each worth its
    ``idle_net_j``) that keeps rule B of a firmware schedule (``problem.spacing_need_s``): per
    angle and motor a chain, solved exactly by ``_kernels.chain_choice`` (formulations/gating.md
    §7). Without rule B, ``candidates`` itself."""
    o = problem.options
    if o.schedule is None or o.schedule.min_spacing_s <= 0:
        return candidates
    out = np.zeros(len(candidates), bool)
    key = problem.idle_angle.astype(np.int64) * 8 + problem.idle_motor
    idx = np.flatnonzero(candidates)
    if not len(idx):
        return out
    # idle arrays are sorted by angle, motor, time: each key's candidates are a run
    starts = np.flatnonzero(np.concatenate(([True], key[idx][1:] != key[idx][:-1])))
    for lo, hi in zip(starts, np.append(starts[1:], len(idx))):
        chain = idx[lo:hi]
        pick = _k.chain_choice(np.ascontiguousarray(problem.idle_net_j[chain], float),
                               chain_predecessors(problem, chain))
        out[chain[pick]] = True
    return out


def choose(problem: GatingProblem) -> tuple[int, np.ndarray]:
    """(angle index, chosen idle-interval indices) of the separable optimum (budgets ignored;
    rule B of a firmware schedule kept, ``spaced``)."""
    net = problem.idle_net_j
    on = spaced(problem, net > 0.0)
    K = problem.n_angles
    gain = np.bincount(problem.idle_angle[on], weights=net[on], minlength=K)
    lines = np.bincount(problem.idle_angle[on], weights=problem.idle_lines[on], minlength=K)
    best = gain.max() if K else 0.0
    tied = np.flatnonzero(gain >= best - _REL_TIE * max(abs(problem.energy_before_j), 1.0))
    k = int(tied[np.argmin(lines[tied])])       # energy first, then lines (first angle on a tie)
    chosen = np.flatnonzero(on & (problem.idle_angle == k))
    return k, chosen


def repair_budgets(problem: GatingProblem, chosen: np.ndarray) -> np.ndarray:
    """Drop chosen idle intervals, least net value per unit of budget first, until both budgets
    hold (counted with each interval's own lines and stall: an upper bound on the shared count)."""
    T_max, L_max = problem.max_added_time_s, problem.max_added_lines
    if not np.isfinite(T_max) and not np.isfinite(L_max):
        return chosen
    net = problem.idle_net_j[chosen]
    use = 0.0
    if np.isfinite(T_max) and T_max >= 0:
        use = use + problem.idle_stall_s[chosen] / max(T_max, 1e-12)
    if np.isfinite(L_max):
        use = use + problem.idle_lines[chosen] / max(L_max, 1e-12)
    density = net / np.maximum(use, 1e-300)
    order = np.argsort(-density, kind="stable")
    t = np.cumsum(problem.idle_stall_s[chosen][order])
    l = np.cumsum(problem.idle_lines[chosen][order])
    ok = (t <= T_max + 1e-12) & (l <= L_max)
    # keep the longest prefix that fits, then any later interval that still fits (one greedy pass)
    keep = np.zeros(len(order), bool)
    if ok.all():
        return chosen
    n_pref = int(np.argmin(ok)) if not ok.all() else len(ok)
    keep[:n_pref] = True
    tt = t[n_pref - 1] if n_pref else 0.0
    ll = l[n_pref - 1] if n_pref else 0
    for j in range(n_pref, len(order)):
        g = chosen[order[j]]
        if tt + problem.idle_stall_s[g] <= T_max + 1e-12 and ll + problem.idle_lines[g] <= L_max:
            keep[j] = True
            tt += problem.idle_stall_s[g]
            ll += problem.idle_lines[g]
    return np.sort(chosen[order[keep]])


def heuristic(problem: GatingProblem) -> GatingSolution:
    """The pass itself: ``choose``, then ``repair_budgets`` under budgets. Where the problem
    separates, the optimum ("optimal", its own bound); else a feasible answer without a bound --
    the warm start of milp and cpsat, which bound it themselves (``solve`` adds the bound)."""
    t0 = time.perf_counter()
    k, chosen = choose(problem)
    exact = problem.separable
    if problem.options.has_budget:
        chosen = repair_budgets(problem, chosen)
    sol = solution_from_idle(problem, "dp", Status.OPTIMAL if exact else Status.FEASIBLE, k, chosen,
                             solve_s=time.perf_counter() - t0,
                             message="" if exact else "not separable: dp is a heuristic here")
    if exact:   # the separable optimum is its own bound
        sol = replace(sol, bound_j=sol.energy_j, gap=0.0, solve_s=time.perf_counter() - t0)
    return sol


def solve(problem: GatingProblem, *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    t0 = time.perf_counter()
    sol = heuristic(problem)
    if problem.separable:
        return sol
    # the heuristic still says how far from optimal it can be: the share bound of the coupled
    # model (formulations/gating.md section 3; shared stalls charged 1/|sharers| to each sharer).
    # Measured under Marlin: within 8e-6 of a 217k-line Cura file's dp answer, for ~0.5 s
    bound = min(build_model(problem, sol.energy_j).bound_j, sol.energy_j)
    gap = relative_gap(sol.energy_j, bound)
    proven = gap <= problem.options.mip_rel_gap       # as milp / cpsat call it optimal
    return replace(sol, bound_j=bound, gap=gap, status=Status.OPTIMAL if proven else Status.FEASIBLE,
                   solve_s=time.perf_counter() - t0,
                   message=sol.message + ("; within mip_rel_gap of the share bound" if proven else
                                          f"; share bound {bound:.3f} J"))


def warm_start(problem: GatingProblem, hint: GatingSolution | None = None) -> GatingSolution:
    """A feasible start for the exact formulations: the better of ``hint`` and the pass with its
    budget repair (``heuristic``; not ``solve``, which would build the coupled model once more for
    its bound)."""
    start = heuristic(problem)
    if (hint is not None and _within_budgets(problem, hint)
            and (hint.energy_j, hint.lines_added) < (start.energy_j, start.lines_added)):
        start = hint
    return start


def _within_budgets(problem: GatingProblem, sol: GatingSolution) -> bool:
    return (sol.added_time_s <= problem.max_added_time_s + 1e-9
            and sol.lines_added <= problem.max_added_lines)
