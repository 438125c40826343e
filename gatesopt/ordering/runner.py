"""One group at a time under the budget plan (``budget.BudgetPlan``), with the cache of repeated
geometry and the overrun reserve; used by the main process (``layers.solve``) and by the helper
process (``helper.main``) alike."""
from __future__ import annotations

import time

from .. import _jit
from ..solvers import Status
from .budget import (OVERHEAD_S_PER_CURVE, OVERRUN_PRIOR_CURVES, OVERRUN_S_PER_CURVE,
                     STOP_HELPER_S, TAIL_S_PER_CURVE, BudgetPlan)
from .problem import GroupSolution, kept_solution

#: a group whose solve spent more than this compiling numba kernels (a first run after an
#: install) and did not prove it is solved once more: its limit went to the compiler (measured:
#: the README's first command, run cold, left 8 of 9 groups "feasible at limit", warm all 9 optimal)
RESOLVE_AFTER_COMPILE_S = 0.2
#: the formulation of a group the budget left no time for (``GroupRunner.run``): the slicer's
#: order, status fallback
OUT_OF_TIME = "kept:out of time"


class GroupRunner:
    """Solves groups with ``fn`` (a formulation's ``solve``): ``time_limit_s`` per group, and
    under ``budget_s`` (from ``t0``) each group's share of what is left. ``shared``: the helper's
    shared "done" marks (both processes plan over the same groups); ``other_alive``: whether the
    other process still solves (then both spend the time left at once). ``warm_up``: called once,
    before the first group (``formulations.warm_up`` for the formulations that call compiled
    kernels)."""

    def __init__(self, problem, fn, time_limit_s, budget_s, t0, kwargs, shared=None,
                 other_alive=None, warm_up=None):
        self.problem, self.fn, self.time_limit_s, self.budget_s = problem, fn, time_limit_s, budget_s
        self.t0, self.kwargs = t0, kwargs
        self.cache = {}     # identical groups recur layer after layer (same infill, same start)
        # the budget goes by plan (BudgetPlan): a group the DP settles, a fixed group or a repeat
        # of an earlier group's geometry costs next to nothing; of the others the smallest get the
        # time an exact proof needs, the rest the greedy path's
        self.plan = BudgetPlan(problem, shared) if budget_s is not None else None
        # with a helper both processes spend the time left at once, while both are running
        self.other_alive = other_alive if other_alive is not None else (lambda: shared is not None)
        if warm_up is not None:
            # outside any group's limit: a group's first call of a kernel would otherwise load it
            # (~0.35 s in all) or, on a first run after an install, compile it (~20 s) inside
            # that group's time (the budget does not count compiling; a group's limit does)
            warm_up()
        self.over_s = OVERRUN_S_PER_CURVE * OVERRUN_PRIOR_CURVES     # the prior, as if measured
        self.curves_timed = OVERRUN_PRIOR_CURVES
        self.n_curves_from = problem.n_curves - problem.group_curve_start   # per group, to the end
        self.shared = shared
        self.out_of_time = 0    # groups the budget left no time for (the slicer's order kept)
        # the caller's time between groups (building each group, its paths' options), per
        # curve passed, measured from here on (``passed``) and started from the prior
        self.pass_s = OVERHEAD_S_PER_CURVE * OVERRUN_PRIOR_CURVES
        self.curves_passed = OVERRUN_PRIOR_CURVES
        self.mark = time.perf_counter()     # when the caller's time since the last group began
        self.in_run_s = 0.0                 # of it, what ``run`` took

    def run(self, g: int, grp) -> GroupSolution:
        t_in = time.perf_counter()
        try:
            return self._run(g, grp)
        finally:
            self.in_run_s += time.perf_counter() - t_in

    def _run(self, g: int, grp) -> GroupSolution:
        limit = self.time_limit_s
        if self.plan is not None:
            # what groups took beyond their limit so far (greedy passes, bounds, model building),
            # per curve, is reserved for the groups still to come; with a helper process both
            # spend the time left at once
            rate = self.over_s / self.curves_timed
            # time spent compiling numba kernels (a first run) is not charged
            elapsed = time.perf_counter() - self.t0 - _jit.compile_s_since(self.t0)
            wall_left = self.budget_s - elapsed - self.rest_s(g)
            if wall_left - rate * grp.n_curves <= 0.0:
                # even the cheapest answer (the greedy path, taken whatever the limit) would end
                # after the budget: the slicer's order, unsearched (a 3 s budget on the Cura
                # bunny's 1081 groups ran 20 s of greedy paths at limit 0 before this)
                self.out_of_time += 1
                return kept_solution(grp, time.perf_counter(), OUT_OF_TIME)
        share = None
        if self.plan is not None:
            cpus = 2 if self.other_alive() else 1
            left = max(0.0, cpus * wall_left - rate * self.plan.pending_curves())
            share = self.plan.limit(g, left)
            if share is None:
                # what is left goes to smaller groups (``BudgetPlan``: smallest first where it
                # does not pay every group's heuristic time): the slicer's order, unsearched
                # (before its key, which makes its link matrix)
                self.out_of_time += 1
                return kept_solution(grp, time.perf_counter(), OUT_OF_TIME)
        key = grp.key()
        gs = self.cache.get(key)
        if gs is not None:
            return GroupSolution.make(gs.order, gs.objective, gs.bound, gs.status, 0.0,
                                      gs.formulation + "+cached")
        if self.plan is not None:
            # the two processes pool their time, but one group runs on one of them: it must end
            # (with its expected overrun) before the budget does, or the file ends late
            limit = min(limit, share, max(0.0, wall_left - rate * grp.n_curves))
        t_g = time.perf_counter()
        gs = self.fn(grp, time_limit_s=limit, **self.kwargs)
        compiled = _jit.compile_s_since(t_g)
        if compiled > RESOLVE_AFTER_COMPILE_S and gs.status != Status.OPTIMAL:
            # its limit went to compiling numba kernels (a first run: a kernel warm_up did not
            # load, say the directed model's): solved again with them compiled
            t_g = time.perf_counter()
            gs = self.fn(grp, time_limit_s=limit, **self.kwargs)
            compiled = _jit.compile_s_since(t_g)
        took = time.perf_counter() - t_g - compiled
        self.over_s += max(0.0, took - limit)
        self.curves_timed += grp.n_curves
        if self.plan is not None:
            self.plan.measured(g, limit, min(took, limit))
        self.cache[key] = gs
        return gs

    def pass_rate(self) -> float:
        """Seconds per curve the caller spends between groups (``passed``), as measured so far
        on this run (so on this machine as loaded), from the prior ``OVERHEAD_S_PER_CURVE``."""
        return self.pass_s / self.curves_passed

    def rest_s(self, g: int) -> float:
        """What the main process needs after group g outside any solver: passing the groups
        after it (building each group, taking the helper's answers) and the end of the solve
        (``chain.pick_paths``, travel totals): the same kind of work per curve, both at the rate
        measured (``pass_rate``)."""
        scale = self.pass_rate() / OVERHEAD_S_PER_CURVE
        return (self.pass_rate() * float(self.n_curves_from[g + 1])
                + scale * TAIL_S_PER_CURVE * float(self.n_curves_from[0])
                + (STOP_HELPER_S if self.shared is not None else 0.0))

    def passed(self, g: int) -> None:
        """Group g is done (the caller's loop calls this once per group, solved here or not):
        the time since the last call, less what ``run`` took, is the caller's, per curve of g."""
        now = time.perf_counter()
        self.pass_s += max(0.0, now - self.mark - self.in_run_s - _jit.compile_s_since(self.mark))
        self.curves_passed += int(self.n_curves_from[g] - self.n_curves_from[g + 1])
        self.mark, self.in_run_s = now, 0.0
        if self.plan is not None:
            self.plan.done(g)
