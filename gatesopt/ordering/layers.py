"""Solve a whole OrderingProblem: group after group, layer after layer.

Each group starts where the previous one ended (Fleming et al. Eq. 1: the layer's entry point is
the previous layer's exit), so groups are solved in print order and chained, as the paper's
Algorithm 1 chains layers. Fixed-order groups are copied (status "optimal": nothing to decide).

Better than the paper's purely greedy chaining where the next group's entry is known: when the
next group is fixed (walls of the same island, or the next layer's walls in safe mode), the path
of this group must travel on to that entry (``Group.end_xy``), so its end is chosen with the next
group in mind. And a group never gets worse than the slicer's own order from the same start to the
same end: if a heuristic's path costs more, the original order is kept.
"""
from __future__ import annotations

import time

import numpy as np

from .. import _jit
from . import auto, cpsat, dp, greedy, milp, tsp
from .helper import Helper
from .problem import (OPTIMAL_ABS_TOL_MM, GroupSolution, OrderingProblem, OrderingSolution,
                      path_travel_mm)

#: groups up to this many curves are settled by the subset DP (``dp.fits``) in milliseconds
DP_CURVES = 12
#: what a group costs in the budget plan without an exact step: the greedy path (nearest
#: neighbour, 2-opt, Or-opt, cheap bound; ~35 us per curve) and the matching's bound and path
#: (``auto._matching_path``): measured 80 us per curve in all on 52 sampled Cura bunny groups of
#: 13-163 curves given no time for an exact step (134 us before the blossom algorithm kept its
#: arrays and ``travel_graph`` was vectorised). Before the matching, at 30 us per curve, those
#: groups kept the cheap bound's gap (median 27 %, <= 2 % for 6 of 52); with it the median gap
#: is 1.8 %, <= 2 % for 27 of 52
HEURISTIC_S_PER_CURVE = 8e-5
#: what the main process spends outside the solvers, kept out of a budget: per curve still to
#: come, building its group and taking the helper's answers (measured 3-6 us per curve on the
#: Cura bunny and two other Cura files); per curve of the file, ``_chain`` and the travel totals
#: after the last group (1-2 us); and stopping the helper process (~30 ms)
OVERHEAD_S_PER_CURVE = 6e-6
TAIL_S_PER_CURVE = 2e-6
STOP_HELPER_S = 0.05
#: what a group takes beyond its limit (the greedy path and the cheap bound run whatever the
#: limit; model building; a last ILS kick), per curve: measured 33-46 us on the Cura bunny under
#: a 5.4 s budget, where most groups get next to no limit. The reserve for the groups to come is
#: the rate measured so far, per curve, starting from this prior as if measured on
#: OVERRUN_PRIOR_CURVES curves: one slow group early (the helper process starting beside it,
#: a busy machine: 0.17 s for a 183-curve group given 11 ms) made the former per-group mean reserve
#: the whole budget for the ~900 groups after it, and none of them was given an exact step
OVERRUN_S_PER_CURVE = 3.5e-5
OVERRUN_PRIOR_CURVES = 5000
#: a group given its exact time ``auto.exact_time_s(n)`` mostly needs a fraction of it: the plan
#: charges each exact group ``exact_s`` times the ratio of what the exact groups solved so far
#: used of it, starting from EXACT_PRIOR_RATIO as if measured on EXACT_PRIOR_S seconds of exact
#: time. Measured without a budget (1 s per group, groups of > 12 curves, each use capped at its
#: exact time) on the 39 corpus files: 0.04-0.97 per file, about 0.5 for the median file, 0.55 /
#: 0.65 over all groups in safe / free mode. The prior weighs little: the groups planned
#: heuristic are not measured, so a ratio learnt slowly keeps early groups from their proofs.
#: Charged in full, 68 of PrusaSlicer's 289 free-mode honeycomb groups fell back and the run
#: ended at 4.3 s of its 10 s budget (they prove in ~18 ms, their exact time is ~70 ms)
EXACT_PRIOR_RATIO = 0.5
EXACT_PRIOR_S = 0.25
#: what a proof uses of its exact time grows with the group's size: the plan charges an exact
#: group ``rho * e * (n / EXACT_SHAPE_CURVES) ** EXACT_SHAPE_EXPONENT`` (at most ``e``) and learns
#: ``rho`` against the same shape. Measured without a budget on the 39 corpus files (1 s per
#: group, 44 file-mode pairs, groups of > 12 curves, use capped at ``e``): per file and size band
#: (12-20, 20-40, 40-80, 80-120, > 120 curves) one ratio per file predicts the band's use with a
#: weighted rms log error of 0.61 for exponent 0 (the plain ratio), 0.46 / 0.35 / 0.35 / 0.46 for
#: 0.25 / 0.5 / 0.75 / 1; median ratio 0.47 at 0.5. On the Cura bunny in safe mode the plain
#: ratio is 0.13 for groups of 12-20 curves and 0.43 above 120: one ratio learnt early on the
#: large groups kept the small ones from their proofs
EXACT_SHAPE_EXPONENT = 0.5
EXACT_SHAPE_CURVES = 100.0
#: a group whose solve spent more than this compiling numba kernels (a first run after an
#: install) and did not prove it is solved once more: its limit went to the compiler (measured:
#: the README's first command, run cold, left 8 of 9 groups "feasible at limit", warm all 9 optimal)
RESOLVE_AFTER_COMPILE_S = 0.2

FORMULATIONS = {
    "greedy": greedy.solve,
    "tsp": tsp.solve,
    "cpsat": cpsat.solve,
    "milp": milp.solve,
    "auto": auto.solve,
    "dp": dp.solve,             # library only: exact for small groups, raises on larger ones
}


def solve(problem: OrderingProblem, formulation: str = "auto", *, time_limit_s: float = 2.0,
          budget_s: float | None = None, workers: int = 1, progress=None,
          **kwargs) -> OrderingSolution:
    """Order every group; ``time_limit_s`` is per group (exact formulations only); ``budget_s``
    caps the whole solve: each group gets at most its share of what is left (groups the DP or the
    bound settle take next to nothing). ``workers = 2``: a second process solves the chain from the
    back (``helper.Helper``) until it meets the main process. ``progress``: called as
    ``progress(groups_done, n_groups, groups_proven)`` after each group (the CLI draws a bar)."""
    if formulation not in FORMULATIONS:
        raise ValueError(f"unknown formulation {formulation!r}: one of {sorted(FORMULATIONS)}")
    if workers not in (1, 2):
        raise ValueError(f"workers must be 1 or 2, not {workers!r}")
    fn = FORMULATIONS[formulation]
    t0 = time.perf_counter()
    n = problem.n_curves
    order_out = []
    reversed_ = np.zeros(n, bool)
    seam = np.zeros(n, np.int64)
    sols = []
    pos = np.asarray(problem.origin_xy, float)
    plans = []      # per group: [(GroupSolution, Group)] options: the solver's path, the slicer's
    proven = 0      # re-orderable groups proven so far (for ``progress``)
    reorderable = problem.group_reorderable
    helper = (Helper.start(problem, formulation, time_limit_s, budget_s, t0, kwargs)
              if workers == 2 else None)
    try:
        runner = _GroupRunner(problem, fn, time_limit_s, budget_s, t0, kwargs,
                              shared=helper.shared if helper else None,
                              other_alive=(lambda: not helper.dead) if helper else None)
        for g in range(problem.n_groups):
            end = _end_of(problem, g)
            if end is None and helper:
                end = helper.entry_of(g + 1)    # the next group's path, if the helper has it
            grp = problem.group(g, pos, end)
            if problem.group_fixed[g] or grp.n_curves == 0:
                order = np.arange(grp.n_cands)      # one candidate per curve, in the slicer's order
                obj = grp.path_cost_mm(order)
                opts = [GroupSolution.make(order, obj, obj, "optimal", 0.0, "fixed")]
            else:
                answer = helper.take(g) if helper else None
                if answer is None:
                    gs = runner.run(g, grp)
                    grp.check_order(gs.order)
                    opts = _options(grp, gs)
                else:
                    opts, guess = answer
                    if guess is not None:
                        opts = _rescored(grp, opts, guess)
                    for gs in opts:
                        grp.check_order(gs.order)
            plans.append((grp, opts))
            runner.passed(g)
            if progress is not None:
                proven += bool(reorderable[g]) and opts[0].status == "optimal"
                progress(g + 1, problem.n_groups, proven)
            pos = grp.exit_xy(opts[0].order)
    finally:
        if helper:
            helper.stop()
    if fn is not greedy.solve and fn is not tsp.solve:     # the baselines chain as the paper does
        deadline = None if budget_s is None else t0 + budget_s - runner.rest_s(problem.n_groups - 1)
        _look_ahead(problem, plans, fn, time_limit_s, deadline, kwargs)
    choice = _chain(problem, plans)
    for g, (grp, opts) in enumerate(plans):
        gs = opts[choice[g]]
        curves = problem.group_curves(g)
        for k in gs.order:
            c = int(curves[grp.cand_curve[k]])
            order_out.append(c)
            reversed_[c] = bool(grp.cand_reversed[k])
            seam[c] = int(grp.cand_seam[k])
        sols.append(gs)
    after = model_travel_mm(problem, np.asarray(order_out, np.int64), reversed_, seam)
    return OrderingSolution(np.asarray(order_out, np.int64), reversed_, seam, tuple(sols),
                            problem.original_travel_mm(), after, time.perf_counter() - t0, formulation)


#: look-ahead at a boundary (``_look_ahead``): next groups of up to this many curves (the subset DP
#: solves one from each of its possible entries in well under a millisecond)
LOOKAHEAD_CURVES = 12
#: at most this many entries of the next group tried per boundary, the most promising first
LOOKAHEAD_TRIES = 2
#: a re-solve may take this multiple of the group's first solve (at least its
#: ``auto.exact_time_s``, at most the per-group limit). Only groups proven the first time are
#: solved again (a fallback would take its limit). A fixed end can make the proof several times
#: slower: a 40-curve KISSlicer 1.6.3 group proven in ~5 ms with a free end stopped at 2x (gap
#: 35.7 %) and at 10x, and closed at 20x; the chain took the unproven path all the same
LOOKAHEAD_TIME_FACTOR = 20.0


def _look_ahead(problem: OrderingProblem, plans, fn, time_limit_s, deadline, kwargs) -> None:
    """Chain options across boundaries whose next group is small and re-orderable (its entry is
    the path's choice, so group g was solved with a free end; formulations/ordering.md, "Across
    groups and layers"). For the entries ``e`` of group g+1 whose lower bound on the pair (g's
    bound with a free end plus g+1's optimum from ``e``) is lowest and below the pair as solved:
    group g again with its end at ``e``; if g's path to ``e`` and g+1's path from it cost less than
    the pair, both join the groups' options (in place) and ``_chain`` takes them where the whole
    chain gets shorter. Identical re-solves (layers that repeat) are solved once. Seen on KISSlicer
    output: a 24-curve infill group proven optimal for itself ended 19 mm further from the next
    layer's 2-curve group than the greedy path did."""
    cache: dict = {}
    for g in range(problem.n_groups - 1):
        if deadline is not None and time.perf_counter() > deadline:
            return
        grp, opts = plans[g]
        nxt, nxt_opts = plans[g + 1]
        if (problem.group_fixed[g] or problem.group_fixed[g + 1] or grp.end_xy is not None
                or grp.n_curves == 0 or not 0 < nxt.n_curves <= LOOKAHEAD_CURVES
                or opts[0].status != "optimal"):
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
            key = _key(gg)
            gs = cache.get(key)
            if gs is None:
                limit = min(time_limit_s, max(auto.exact_time_s(gg.n_curves),
                                              LOOKAHEAD_TIME_FACTOR * opts[0].solve_s))
                if deadline is not None:
                    limit = min(limit, deadline - time.perf_counter())
                    if limit <= 0:
                        return
                gs = cache[key] = fn(gg, time_limit_s=limit, **kwargs)
                gg.check_order(gs.order)
            if gs.objective_mm + ns.objective_mm < pair - OPTIMAL_ABS_TOL_MM:
                opts.append(GroupSolution.make(gs.order, gs.objective_mm, gs.bound_mm, gs.status,
                                               gs.solve_s, gs.method + "+ahead"))
                nxt_opts.append(GroupSolution.make(ns.order, ns.objective_mm, ns.bound_mm,
                                                   ns.status, ns.solve_s, ns.method + "+ahead"))


def _end_of(problem: OrderingProblem, g: int):
    """Where group g's path must travel on to: the next group's entry if that one is fixed."""
    if g + 1 < problem.n_groups and problem.group_fixed[g + 1]:
        return problem.curve_start_xy[problem.group_curve_start[g + 1]]
    return None


def _options(grp, gs: GroupSolution, backwards: bool = False) -> list:
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
                                       gs.method + "+kept"))
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
                               o.method + "+back")
            for o in _options(back, gs, backwards=True)]
    return fwd, opts


def _rescored(grp, opts, guess_xy) -> list:
    """Options solved from a guessed start, scored from the real one (``grp.start_xy``): a path
    from the real start costs at least its cost from the guess minus the distance between the
    two (triangle inequality), so the bound stays valid; "optimal" stays only if it still closes."""
    shift = float(np.hypot(*(np.asarray(grp.start_xy) - guess_xy)))
    out = []
    for o in opts:
        obj = grp.path_cost_mm(o.order)
        bound = max(0.0, o.bound_mm - shift)
        status = o.status
        if status == "optimal" and obj - bound > OPTIMAL_ABS_TOL_MM:
            status = "feasible"
        out.append(GroupSolution.make(o.order, obj, bound, status, o.solve_s, o.method))
    return out


class _GroupRunner:
    """Solves one group at a time under the budget plan, with the cache of repeated geometry and
    the overrun reserve; used by the main process and by the helper process alike."""

    def __init__(self, problem, fn, time_limit_s, budget_s, t0, kwargs, shared=None,
                 other_alive=None):
        self.problem, self.fn, self.time_limit_s, self.budget_s = problem, fn, time_limit_s, budget_s
        self.t0, self.kwargs = t0, kwargs
        self.cache = {}     # identical groups recur layer after layer (same infill, same start)
        # the budget goes by plan (_BudgetPlan): a group the DP settles, a fixed group or a repeat
        # of an earlier group's geometry costs next to nothing; of the others the smallest get the
        # time an exact proof needs, the rest the greedy path's
        self.plan = _BudgetPlan(problem, shared) if budget_s is not None else None
        # with a helper both processes spend the time left at once, while both are running
        self.other_alive = other_alive if other_alive is not None else (lambda: shared is not None)
        if fn is auto.solve or fn is milp.solve:
            # outside any group's limit: a group's first call of a kernel would otherwise load it
            # (~0.35 s in all) or, on a first run after an install, compile it (~20 s) inside
            # that group's time (the budget does not count compiling; a group's limit does)
            auto.warm_up()
        self.over_s = OVERRUN_S_PER_CURVE * OVERRUN_PRIOR_CURVES     # the prior, as if measured
        self.curves_timed = OVERRUN_PRIOR_CURVES
        self.n_curves_from = problem.n_curves - problem.group_curve_start   # per group, to the end
        self.shared = shared

    def run(self, g: int, grp) -> GroupSolution:
        key = _key(grp)
        gs = self.cache.get(key)
        if gs is not None:
            return GroupSolution.make(gs.order, gs.objective_mm, gs.bound_mm, gs.status, 0.0,
                                      gs.method + "+cached")
        limit = self.time_limit_s
        if self.plan is not None:
            # what groups took beyond their limit so far (greedy passes, bounds, model building),
            # per curve, is reserved for the groups still to come; with a helper process both
            # spend the time left at once
            rate = self.over_s / self.curves_timed
            # time spent compiling numba kernels (a first run) is not charged
            elapsed = time.perf_counter() - self.t0 - _jit.compile_s_since(self.t0)
            wall_left = self.budget_s - elapsed - self.rest_s(g)
            cpus = 2 if self.other_alive() else 1
            left = max(0.0, cpus * wall_left - rate * self.plan.pending_curves())
            # the two processes pool their time, but one group runs on one of them: it must end
            # (with its expected overrun) before the budget does, or the file ends late
            limit = min(limit, self.plan.limit(g, left),
                        max(0.0, wall_left - rate * grp.n_curves))
        t_g = time.perf_counter()
        gs = self.fn(grp, time_limit_s=limit, **self.kwargs)
        compiled = _jit.compile_s_since(t_g)
        if compiled > RESOLVE_AFTER_COMPILE_S and gs.status != "optimal":
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

    def rest_s(self, g: int) -> float:
        """What the main process needs after group g outside any solver: passing the groups
        after it (building each group, taking the helper's answers) and the end of the solve
        (``_chain``, travel totals)."""
        return (OVERHEAD_S_PER_CURVE * float(self.n_curves_from[g + 1])
                + TAIL_S_PER_CURVE * float(self.n_curves_from[0])
                + (STOP_HELPER_S if self.shared is not None else 0.0))

    def passed(self, g: int) -> None:
        if self.plan is not None:
            self.plan.done(g)


def _budget_weights(problem: OrderingProblem) -> np.ndarray:
    """Per group, its claim on a shared budget: its curve count if some solver will have to work
    on it (not fixed, too large for the subset DP, geometry not seen in an earlier group), else 0."""
    w = np.zeros(problem.n_groups)
    seen = set()
    for g in range(problem.n_groups):
        curves = problem.group_curves(g)
        if problem.group_fixed[g] or len(curves) <= DP_CURVES:
            continue
        key = np.rint(np.concatenate([problem.curve_start_xy[curves], problem.curve_end_xy[curves]])
                      * 1e4).astype(np.int64).tobytes()
        if key not in seen:
            seen.add(key)
            w[g] = len(curves)
    return w


class _BudgetPlan:
    """How a shared budget is spent (formulations/ordering.md, "Budget"). Proof time grows much
    faster than linearly with a group's size, so proofs per second are highest on the small
    groups: of the groups still to come, the smallest get ``auto.exact_time_s(n)`` (what the exact
    step needs to be tried at all), the rest ``HEURISTIC_S_PER_CURVE * n`` (the greedy path), as
    many of the smallest as the time left pays for. Most proofs take a fraction of their exact
    time, the smaller the group the smaller, so the plan charges an exact group a shape of its
    size (``shape_s``, at most its exact time) times the ratio measured so far (``used_ratio``).
    Each group's limit is its exact or heuristic time scaled by time left / time
    planned, so what finished early flows to the groups after it, and every re-plan promotes the
    next smallest."""

    def __init__(self, problem: OrderingProblem, shared=None):
        w = _budget_weights(problem)
        self.claims = w > 0
        n = w[self.claims]
        self.groups = np.flatnonzero(self.claims)[np.argsort(n, kind="stable")]  # smallest first
        n = w[self.groups]
        self.curves = n
        self.exact_s = auto.exact_time_s(n)
        self.shape_s = self.exact_s * (n / EXACT_SHAPE_CURVES) ** EXACT_SHAPE_EXPONENT
        self.heuristic_s = HEURISTIC_S_PER_CURVE * n
        # per group, 1 once solved (or taken by the other process when shared with a helper)
        self.done_mask = np.zeros(problem.n_groups, np.int8) if shared is None else shared
        self.rank = np.empty(problem.n_groups, np.int64)
        self.rank[self.groups] = np.arange(len(self.groups))
        self.exact_used_s = EXACT_PRIOR_RATIO * EXACT_PRIOR_S       # the prior
        self.exact_planned_s = EXACT_PRIOR_S

    @property
    def used_ratio(self) -> float:
        """What the groups given their exact time used so far (within their limits), per
        second of their ``shape_s``."""
        return self.exact_used_s / self.exact_planned_s

    @property
    def pending(self) -> np.ndarray:
        """Per claim (sorted by size), whether it is still to be solved."""
        return self.done_mask[self.groups] == 0

    def pending_curves(self) -> float:
        return float(self.curves[self.pending].sum())

    def limit(self, g: int, left_s: float) -> float:
        """Time for group ``g`` out of ``left_s`` seconds left for it and the groups after it."""
        if not self.claims[g]:
            return left_s          # DP, repeat: takes next to nothing, capped by what is left
        pending = self.pending
        pending[self.rank[g]] = True
        h = self.heuristic_s[pending]
        e = np.minimum(self.used_ratio * self.shape_s[pending], self.exact_s[pending])
        # the longest prefix (smallest groups) that can have its exact time, the rest heuristic
        cost = np.cumsum(np.maximum(e, h) - h) + h.sum()
        n_exact = int(np.searchsorted(cost, left_s, side="right"))
        planned = cost[n_exact - 1] if n_exact else h.sum()
        i = int(self.rank[g])
        pos = int(np.count_nonzero(pending[:i]))        # g's place among the pending groups
        mine = self.exact_s[i] if pos < n_exact else self.heuristic_s[i]
        return float(mine * left_s / planned) if planned > 0 else left_s

    def measured(self, g: int, limit_s: float, used_s: float) -> None:
        """Group ``g`` was given ``limit_s`` and used ``used_s`` of it: if that was its exact
        time, it counts towards ``used_ratio``."""
        if self.claims[g] and limit_s >= self.exact_s[self.rank[g]]:
            self.exact_used_s += used_s
            self.exact_planned_s += float(self.shape_s[self.rank[g]])

    def done(self, g: int) -> None:
        self.done_mask[g] = 1


def model_travel_mm(problem: OrderingProblem, order, reversed_, seam) -> float:
    """Model travel of a full solution (start of each curve from the end of the one before)."""
    order = np.asarray(order, np.int64)
    a, b = problem.curve_start_xy[order].copy(), problem.curve_end_xy[order].copy()
    moved = np.flatnonzero(seam[order] != 0)        # a loop entered and left at another vertex
    if len(moved):
        c = order[moved]
        a[moved] = b[moved] = problem.points_xy[problem.curve_point_start[c] + seam[c]]
    rev = np.asarray(reversed_, bool)[order]
    a[rev], b[rev] = b[rev], a[rev].copy()
    return path_travel_mm(problem.origin_xy, a, b)


def _chain(problem: OrderingProblem, plans) -> list[int]:
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


def _key(grp) -> bytes:
    """Exact identity of a group instance (coordinates to 0.1 µm)."""
    parts = [grp.start_xy, grp.cand_entry_xy, grp.cand_exit_xy,
             np.zeros(2) - 1e9 if grp.end_xy is None else grp.end_xy]
    q = np.concatenate([np.ravel(np.rint(np.asarray(a, float) * 1e4)) for a in parts]).astype(np.int64)
    return q.tobytes() + grp.cand_curve.tobytes()
