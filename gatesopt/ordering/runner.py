"""One group at a time under the budget plan (``budget.BudgetPlan``), with the cache of repeated
geometry and the overrun reserve; used by the main process (``layers.solve``) and by the helper
process (``helper.main``) alike."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import _jit
from ..solvers import Status
from .budget import (OVERHEAD_S_PER_CURVE, OVERRUN_PRIOR_CURVES, OVERRUN_S_PER_CURVE,
                     STOP_HELPER_S, TAIL_S_PER_CURVE, WORK_NET_FACTOR, WORK_NET_MIN_S,
                     BudgetPlan, WorkPlan, exact_time_s, greedy_work_s, matching_work_s)
from .greedy_pass import DP_FORMULATION, MATCHING_FORMULATION
from .problem import OPTIMAL_ABS_TOL, GroupSolution, kept_solution

#: a group whose solve spent more than this compiling numba kernels (a first run after an
#: install) and did not prove it is solved once more: its limit went to the compiler (measured:
#: the README's first command, run cold, left 8 of 9 groups "feasible at limit", warm all 9 optimal)
RESOLVE_AFTER_COMPILE_S = 0.2
#: the formulation of a group the budget left no time for (``GroupRunner.run``): the slicer's
#: order, status fallback
OUT_OF_TIME = "kept:out of time"
#: the formulation of a group the budget left no time to search exactly but that the greedy pass
#: before the exact solve had ordered (``GroupRunner.run`` with ``greedy``): its greedy path,
#: status fallback unless its bound still closes (issue 36: never the slicer's order unsearched
#: where greedy had an answer)
OUT_OF_TIME_GREEDY = "greedy:out of time"


@dataclass(frozen=True, eq=False)
class GreedyAnswer:
    """What the greedy pass (``layers.solve_greedy``) found for one group, as the exact solve
    after it uses it: its path (candidate indices, forward), the cheap bound it proved, and the
    start and end costs (per candidate) of the group as greedy solved it -- the exact chain may
    reach the group from another start, and the bound moves by at most what those costs moved
    (``for_group``). Small: it goes to the helper process too."""

    order: np.ndarray
    bound: float
    start_cost: np.ndarray
    end_cost: np.ndarray

    def same_costs(self, grp, backwards: bool = False) -> bool:
        """Whether ``grp`` starts and ends as the group greedy solved (the same start and end
        costs: its answer there is greedy's answer here; the link matrix is the group's own)."""
        return (not backwards and np.array_equal(self.start_cost, grp.start_cost())
                and np.array_equal(self.end_cost, grp.end_cost()))

    def for_group(self, grp, backwards: bool = False) -> GroupSolution:
        """This path as an answer for ``grp`` (the same group of the problem, from the start the
        exact chain gives it; ``backwards``: ``grp`` is its ``Group.backwards()`` mirror, the
        path walked from its end), priced without making a link matrix the group does not have
        yet (``path_cost_lazy``). Its bound: greedy's, less the most any candidate's start or end
        cost fell -- a path's cost here is its cost there minus the start and end costs it had
        there plus those it has here (for the mirror: no start cost, its end cost is the
        mirror's start cost). Status optimal if that still closes, else fallback (the exact step
        did not run)."""
        order = self.order[::-1].copy() if backwards else self.order
        obj = path_cost_lazy(grp, order)
        if backwards:
            s_new, e_new = np.zeros(grp.n_cands), np.asarray(grp.start_cost(), float)
        else:
            s_new, e_new = np.asarray(grp.start_cost(), float), np.asarray(grp.end_cost(), float)
        with np.errstate(invalid="ignore"):
            ds, de = self.start_cost - s_new, self.end_cost - e_new
        bound = 0.0
        if len(order) and np.all(np.isfinite(ds)) and np.all(np.isfinite(de)):
            bound = max(0.0, self.bound - max(0.0, float(ds.max())) - max(0.0, float(de.max())))
        status = Status.OPTIMAL if obj - bound <= OPTIMAL_ABS_TOL else Status.FALLBACK
        return GroupSolution.make(order, obj, bound, status, 0.0,
                                  "greedy" if status == Status.OPTIMAL else OUT_OF_TIME_GREEDY)


def greedy_answer(grp, gs: GroupSolution) -> GreedyAnswer | None:
    """The greedy pass's answer ``gs`` for group ``grp`` (as it solved it), None where the greedy
    pass had no time for the group either (``OUT_OF_TIME``: the slicer's order unsearched)."""
    if gs.formulation.startswith(OUT_OF_TIME) or len(gs.order) != grp.n_curves:
        return None
    return GreedyAnswer(np.asarray(gs.order, np.int64), float(gs.bound),
                        np.asarray(grp.start_cost(), float).copy(),
                        np.asarray(grp.end_cost(), float).copy())


def path_cost_lazy(grp, order) -> float:
    """``grp.path_cost(order)``, but where the group's link matrix is still to be made (a group
    the budget leaves unsearched) its path's links are priced one by one (``LinkCosts.link``,
    the numbers the matrix would hold) instead of making the matrix."""
    c = grp.costs
    order = np.asarray(order, np.int64)
    if (c is not None and c.arc is None and c.make_arc is not None and c.link is not None
            and len(order) > 1):
        inner = float(np.sum(np.asarray(c.link(order[:-1], order[1:]), float)))
        return float(c.start[order[0]]) + inner + float(c.end[order[-1]])
    return grp.path_cost(order)


class GroupRunner:
    """Solves groups with ``fn`` (a formulation's ``solve``): ``time_limit_s`` per group, and
    under ``budget_s`` (from ``t0``) each group's share of what is left. ``shared``: the helper's
    shared "done" marks (both processes plan over the same groups); ``other_alive``: whether the
    other process still solves (then both spend the time left at once). ``warm_up``: called once,
    before the first group (``formulations.warm_up`` for the formulations that call compiled
    kernels)."""

    def __init__(self, problem, fn, time_limit_s, budget_s, t0, kwargs, shared=None,
                 other_alive=None, warm_up=None, matrices_made: bool = False):
        self.problem, self.fn, self.time_limit_s, self.budget_s = problem, fn, time_limit_s, budget_s
        self.t0, self.kwargs = t0, kwargs
        self.cache = {}     # identical groups recur layer after layer (same infill, same start)
        # the budget goes by plan (BudgetPlan): a group the DP settles, a fixed group or a repeat
        # of an earlier group's geometry costs next to nothing; of the others the smallest get the
        # time an exact proof needs, the rest the greedy path's
        # (``matrices_made``: the groups come with their link matrices, made by the greedy pass)
        self.plan = (BudgetPlan(problem, shared, matrices_made) if budget_s is not None
                     else None)
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

    def run(self, g: int, grp, greedy: GreedyAnswer | None = None,
            backwards: bool = False) -> GroupSolution:
        """Group g's answer. ``greedy``: the greedy pass's answer for it (``backwards``: ``grp`` is
        the group's mirror): the warm start of the search (``hint``), and what the group keeps
        where the budget leaves it no time (``OUT_OF_TIME_GREEDY``; without it the slicer's
        order, ``OUT_OF_TIME``); a greedy path whose bound closes for ``grp`` is taken as it is."""
        t_in = time.perf_counter()
        try:
            return self._run(g, grp, greedy, backwards)
        finally:
            self.in_run_s += time.perf_counter() - t_in

    def _late(self, grp, greedy: GreedyAnswer | None, backwards: bool) -> GroupSolution:
        """A group the budget left no time for: greedy's path if the greedy pass had one, else
        the slicer's order, unsearched."""
        self.out_of_time += 1
        t = time.perf_counter()
        if greedy is not None:
            gs = greedy.for_group(grp, backwards)
            return GroupSolution.make(gs.order, gs.objective, gs.bound, gs.status,
                                      time.perf_counter() - t, gs.formulation)
        return kept_solution(grp, t, OUT_OF_TIME)

    def _run(self, g: int, grp, greedy: GreedyAnswer | None = None,
             backwards: bool = False) -> GroupSolution:
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
                # bunny's 1081 groups ran 20 s of greedy paths at limit 0 before this); greedy's
                # path where the greedy pass had one
                return self._late(grp, greedy, backwards)
        share = None
        if self.plan is not None:
            other = wall_left if self.other_alive() else 0.0
            left = max(0.0, wall_left + other - rate * self.plan.pending_curves())
            share = self.plan.limit(g, left)
            if share is None:
                # what is left goes to smaller groups (``BudgetPlan``: smallest first where it
                # does not pay every group's heuristic time): the slicer's order, unsearched
                # (before its key, which makes its link matrix), or greedy's path
                return self._late(grp, greedy, backwards)
        kwargs = self.kwargs
        if greedy is not None:
            t_g = time.perf_counter()
            gs = greedy.for_group(grp, backwards)
            if gs.status == Status.OPTIMAL or (
                    share is not None and share < exact_time_s(grp.n_curves)
                    and greedy.same_costs(grp, backwards)):
                # greedy's path proven by its bound from this start too, or a group the plan
                # gives no exact step whose start is greedy's: the search would begin with
                # greedy's own path and local search (one whole pass to find it a local optimum:
                # ~1 s on a group of 618 curves at a load of 5) and have no time to better it
                return GroupSolution.make(gs.order, gs.objective, gs.bound, gs.status,
                                          time.perf_counter() - t_g, gs.formulation)
            kwargs = {**kwargs, "hint": gs.order}
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
        gs = self.fn(grp, time_limit_s=limit, **kwargs)
        compiled = _jit.compile_s_since(t_g)
        if compiled > RESOLVE_AFTER_COMPILE_S and gs.status != Status.OPTIMAL:
            # its limit went to compiling numba kernels (a first run: a kernel warm_up did not
            # load, say the directed model's): solved again with them compiled
            t_g = time.perf_counter()
            gs = self.fn(grp, time_limit_s=limit, **kwargs)
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


class WorkRunner:
    """The greedy chain's groups (``layers.solve`` of a ``one_chain`` formulation) under a budget
    in work (``budget.WorkPlan``, deterministic seconds), not wall-clock: which groups are
    searched, and whether the matching step runs on them, follows from counts alone, so two runs
    (one worker or two, a quiet machine or a loaded one) give the same answer. The wall-clock
    safety net: once ``WORK_NET_FACTOR`` times the budget plus ``WORK_NET_MIN_S`` has passed
    since ``t0`` (numba compiling not counted), every group after keeps the slicer's order
    (``OUT_OF_TIME``) and ``net_fired`` says so. ``budget_s`` None: every group searched."""

    def __init__(self, problem, fn, time_limit_s, budget_s, t0, kwargs):
        self.fn, self.time_limit_s, self.t0, self.kwargs = fn, time_limit_s, t0, kwargs
        self.plan = None if budget_s is None else WorkPlan(problem, budget_s)
        self.net_s = None if budget_s is None else WORK_NET_FACTOR * budget_s + WORK_NET_MIN_S
        self.net_fired = False

    def run(self, g: int, grp) -> GroupSolution:
        """Group g's answer: searched if the plan pays for it, else the slicer's order."""
        if self.plan is None:
            return self.fn(grp, time_limit_s=self.time_limit_s, **self.kwargs)
        if not self.net_fired:
            elapsed = time.perf_counter() - self.t0 - _jit.compile_s_since(self.t0)
            self.net_fired = elapsed > self.net_s
        if self.net_fired or not self.plan.funds(g):
            self.plan.charge(g, 0.0)
            return kept_solution(grp, time.perf_counter(), OUT_OF_TIME)
        n, m = grp.n_curves, grp.n_cands
        extra_s = matching_work_s(n, m)
        gs = self.fn(grp, time_limit_s=self.time_limit_s,
                     with_matching=self.plan.affords(g, extra_s),
                     **self.kwargs)
        work_s = float(greedy_work_s(n, m, self.plan.time_objective, gs.formulation == DP_FORMULATION))
        if gs.formulation == MATCHING_FORMULATION:
            work_s += extra_s
        self.plan.charge(g, work_s)
        return gs

    def passed(self, g: int) -> None:
        """Group g is done (``GroupRunner.passed``'s place in the loop): the pass's work was set
        aside when the plan was made."""
