"""Chaining the groups' paths: each group starts where the previous one ended (Fleming et al.
Eq. 1), so the driver (``layers.solve``) keeps per group a few candidate paths ("options": the
solver's, the slicer's order, look-ahead re-solves) and a DP over the whole chain picks one per
group (``pick_paths``; formulations/ordering.md, "Across groups and layers").
"""
from __future__ import annotations

import time

import numpy as np

from ..solvers import Status, stop_requested
from . import dp
from .budget import exact_time_s
from .problem import OPTIMAL_ABS_TOL_MM, GroupSolution, OrderingProblem

#: look-ahead at a boundary (``look_ahead``): next groups of up to this many curves (the subset DP
#: solves one from each of its possible entries in well under a millisecond)
LOOKAHEAD_CURVES = 12
#: at most this many entries of the next group tried per boundary, the most promising first
LOOKAHEAD_TRIES = 2
#: a re-solve may take this multiple of the group's first solve (at least its
#: ``budget.exact_time_s``, at most the per-group limit). Only groups proven the first time are
#: solved again (a fallback would take its limit). A fixed end can make the proof several times
#: slower (docs/BENCHMARKS.md, "Curve-ordering constants")
LOOKAHEAD_TIME_FACTOR = 20.0


def look_ahead(problem: OrderingProblem, plans, fn, time_limit_s, deadline, kwargs) -> None:
    """Chain options across boundaries whose next group is small and re-orderable (its entry is
    the path's choice, so group g was solved with a free end; formulations/ordering.md, "Across
    groups and layers"). For the entries ``e`` of group g+1 whose lower bound on the pair (g's
    bound with a free end plus g+1's optimum from ``e``) is lowest and below the pair as solved:
    group g again with its end at ``e``; if g's path to ``e`` and g+1's path from it cost less than
    the pair, both join the groups' options (in place) and ``pick_paths`` takes them where the whole
    chain gets shorter. Identical re-solves (layers that repeat) are solved once. Seen on KISSlicer
    output: a 24-curve infill group proven optimal for itself ended 19 mm further from the next
    layer's 2-curve group than the greedy path did."""
    cache: dict = {}
    for g in range(problem.n_groups - 1):
        if (deadline is not None and time.perf_counter() > deadline) or stop_requested():
            return              # (Ctrl-C: every group has its answer; the options stay as they are)
        grp, opts = plans[g]
        nxt, nxt_opts = plans[g + 1]
        if (problem.group_fixed[g] or problem.group_fixed[g + 1] or grp.end_xy is not None
                or grp.n_curves == 0 or not 0 < nxt.n_curves <= LOOKAHEAD_CURVES
                or opts[0].status != Status.OPTIMAL):
            continue
        pair = opts[0].objective_mm + nxt_opts[0].objective_mm
        entries = np.unique(nxt.cand_entry_xy, axis=0)
        ahead = []
        for e in entries:
            ng = problem.group(g + 1, e, nxt.end_xy)
            ns = dp.solve(ng) if dp.fits(ng) else fn(ng, time_limit_s=time_limit_s, **kwargs)
            low = opts[0].bound_mm + ns.objective_mm
            if low < pair - OPTIMAL_ABS_TOL_MM:
                ahead.append((low, tuple(e), ns))
        ahead.sort(key=lambda a: a[0])
        for low, e, ns in ahead[:LOOKAHEAD_TRIES]:
            gg = problem.group(g, grp.start_xy, e)
            key = gg.key()
            gs = cache.get(key)
            if gs is None:
                limit = min(time_limit_s, max(exact_time_s(gg.n_curves),
                                              LOOKAHEAD_TIME_FACTOR * opts[0].solve_s))
                if deadline is not None:
                    limit = min(limit, deadline - time.perf_counter())
                    if limit <= 0:
                        return
                gs = cache[key] = fn(gg, time_limit_s=limit, **kwargs)
                gg.check_order(gs.order)
            if gs.objective_mm + ns.objective_mm < pair - OPTIMAL_ABS_TOL_MM:
                opts.append(GroupSolution.make(gs.order, gs.objective_mm, gs.bound_mm, gs.status,
                                               gs.solve_s, gs.formulation + "+ahead"))
                nxt_opts.append(GroupSolution.make(ns.order, ns.objective_mm, ns.bound_mm,
                                                   ns.status, ns.solve_s, ns.formulation + "+ahead"))


def end_of(problem: OrderingProblem, g: int):
    """Where group g's path must travel on to: the next group's entry if that one is fixed."""
    if g + 1 < problem.n_groups and problem.group_fixed[g + 1]:
        return problem.curve_start_xy[problem.group_curve_start[g + 1]]
    return None


def path_options(grp, gs: GroupSolution, backwards: bool = False) -> list:
    """A group's candidate paths for the chain DP: the solver's and, if different, the slicer's
    (first when shorter: never worse than the slicer's order). ``backwards``: ``grp`` is a
    ``Group.backwards()`` problem (the slicer's order is walked from its last curve)."""
    ident = np.flatnonzero(~grp.cand_reversed & (grp.cand_seam == 0))
    if backwards:
        ident = ident[::-1]
    opts = [gs]
    if len(ident) == grp.n_curves and not np.array_equal(ident, gs.order):
        ident_obj = grp.path_cost_mm(ident)
        opts.append(GroupSolution.make(ident, ident_obj, gs.bound_mm, gs.status, gs.solve_s,
                                       gs.formulation + "+kept"))
        if ident_obj < gs.objective_mm - 1e-9:
            opts = opts[::-1]
    return opts


def solve_backwards(runner, problem: OrderingProblem, g: int, end_xy) -> tuple:
    """Group g with its end fixed (the next group's entry) and its start free: solved as
    ``Group.backwards()``. Returns (forward Group, options in forward order). Each option is
    proven for that problem: the travel into its first curve belongs to the group before, whose
    own end is then chosen to be this path's entry (formulations/ordering.md, "Two processes")."""
    fwd = problem.group(g, end_xy, end_xy)      # (its start is not used)
    back = fwd.backwards()
    gs = runner.run(g, back)
    back.check_order(gs.order)
    opts = [GroupSolution.make(o.order[::-1].copy(), o.objective_mm, o.bound_mm, o.status, o.solve_s,
                               o.formulation + "+back")
            for o in path_options(back, gs, backwards=True)]
    return fwd, opts


def rescored(grp, opts, guess_xy) -> list:
    """Options solved from a guessed start, scored from the real one (``grp.start_xy``): a path
    from the real start costs at least its cost from the guess minus the distance between the
    two (triangle inequality), so the bound stays valid; "optimal" stays only if it still closes."""
    shift = float(np.hypot(*(np.asarray(grp.start_xy) - guess_xy)))
    out = []
    for o in opts:
        obj = grp.path_cost_mm(o.order)
        bound = max(0.0, o.bound_mm - shift)
        status = o.status
        if status == Status.OPTIMAL and obj - bound > OPTIMAL_ABS_TOL_MM:
            status = Status.FEASIBLE
        out.append(GroupSolution.make(o.order, obj, bound, status, o.solve_s, o.formulation))
    return out


def pick_paths(problem: OrderingProblem, plans) -> list[int]:
    """Pick, per group, the solver's path or the slicer's order so that the whole chain is
    shortest (a DP over groups with one state per option: each path is fixed, only the link into
    it depends on where the previous group ended). Contains the all-original choice, so the
    total never exceeds the slicer's travel."""
    pos = [np.asarray(problem.origin_xy, float)]
    cost = [0.0]
    back = []
    for grp, opts in plans:
        new_pos, new_cost, new_back = [], [], []
        for gs in opts:
            o = gs.order
            if len(o) == 0:
                inner, entry, exit_ = 0.0, None, None
            else:
                entry, exit_ = grp.cand_entry_xy[o[0]], grp.cand_exit_xy[o[-1]]
                inner = float(np.hypot(*(grp.cand_entry_xy[o[1:]] - grp.cand_exit_xy[o[:-1]]).T).sum())
            best, arg = np.inf, 0
            for j, (p, c) in enumerate(zip(pos, cost)):
                v = c + (0.0 if entry is None else float(np.hypot(*(entry - p))))
                if v < best - 1e-12:
                    best, arg = v, j
            new_cost.append(best + inner)
            new_pos.append(pos[arg] if exit_ is None else exit_)
            new_back.append(arg)
        pos, cost = new_pos, new_cost
        back.append(new_back)
    choice = [0] * len(plans)
    k = int(np.argmin(cost)) if cost else 0
    for g in range(len(plans) - 1, -1, -1):
        choice[g] = k
        k = back[g][k]
    return choice
