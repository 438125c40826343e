"""How a shared time budget is spent over a file's groups (formulations/ordering.md, "Budget").

Proof time grows much faster than linearly with a group's size, so proofs per second are highest
on the small groups: the plan (``BudgetPlan``) gives the smallest groups still to come the time
an exact step needs to be tried at all (``exact_time_s``), the rest the greedy path's, as many of
the smallest as the time left pays for. ``runner.GroupRunner`` asks it for each group's limit.
The rates below are measured; their history is in docs/BENCHMARKS.md, "Curve-ordering constants".
"""
from __future__ import annotations

import numpy as np

from .candidates import one_way
from .problem import OrderingProblem

#: groups up to this many curves are settled by the subset DP (``dp.fits``) in milliseconds
DP_CURVES = 12
#: the least per-group limit at which ``auto`` builds the symmetric model: below it (a budget
#: spread thin over ~1000 groups) the root rarely finishes and the ILS path alone is the better
#: use of the time (real groups of 20-60 curves are often proven in 10-30 ms, of ~100 curves in
#: 0.1-0.5 s): MIN_SYMMETRIC_S plus MIN_SYMMETRIC_S_PER_CURVE per curve
MIN_SYMMETRIC_S = 0.01
MIN_SYMMETRIC_S_PER_CURVE = 0.002
#: what a group costs in the plan without an exact step, per curve: the greedy path and the
#: matching's bound and path (``greedy_pass.matching_path``), measured (docs/BENCHMARKS.md)
HEURISTIC_S_PER_CURVE = 8e-5
#: making a group's time-objective link matrix (``cost._dense``, on first use: inside the group's
#: search since ``problem.LinkCosts.make_arc``), per link (m^2 for m candidates): measured 0.22 us
#: per link on the Cura bunny's 1,070 re-orderable groups (24.1 M links, 5.2 s CPU at load 8;
#: docs/BENCHMARKS.md, "Link-cost build"). Part of what any search of the group costs: the plan
#: adds it to a time-objective group's heuristic time. (The travel objective's matrix is one
#: numpy expression: not counted.) With the links joined to the curves (each planned with the
#: curves' end moves, no mirror: ``cost._dense``) a link costs ~2.2x that: every link priced
#: itself 7.40 -> 15.6 s CPU (safe, 24.2 M links) and 11.06 -> 24.0 s (free, 37.3 M), 0.64 us a
#: link at load 2-5 (docs/BENCHMARKS.md, "Link-cost build"); 1.5e-7 scaled by that ratio
MATRIX_S_PER_LINK = 3.3e-7
#: what the main process spends outside the solvers, kept out of a budget: per curve still to
#: come, building its group and taking the helper's answers; per curve of the file, the chain DP
#: and the travel totals after the last group; and stopping the helper process. The first two
#: are priors: ``runner.GroupRunner`` measures the per-curve time between groups as it goes and
#: scales both by it. Measured (cProfile, CPU seconds, budget 3 s on the Cura bunny's 67,356
#: curves, time objective, machine loaded): passing the 2,446 groups 4.4 s (building their link
#: costs 3.5 s of it), ``pick_paths`` 0.83 s; the earlier 6e-6 and 2e-6 predate the time
#: objective's link costs, and the solve ran ~2 s past its budget on building groups alone.
#: Since a group's link matrix is made on first use (``problem.LinkCosts.make_arc``: in the
#: solver's time, not the pass) and its start and end links in one call, passing those groups
#: took 0.38 s CPU (load 8; docs/BENCHMARKS.md, "Link-cost build")
OVERHEAD_S_PER_CURVE = 8e-6
TAIL_S_PER_CURVE = 6e-6
#: and per group, whatever its size (``WORK_PASS_S_PER_GROUP``, measured on the greedy pass): what
#: a file of thousands of one-island groups (safe mode's pin plates) takes to pass its groups
OVERHEAD_S_PER_GROUP = 3.5e-4
STOP_HELPER_S = 0.05
#: what a group takes beyond its limit (the greedy path and the cheap bound run whatever the
#: limit; model building; a last ILS kick), per curve. The reserve for the groups to come is the
#: rate measured so far, starting from this prior as if measured on OVERRUN_PRIOR_CURVES curves,
#: so that one slow group early does not reserve the whole budget (docs/BENCHMARKS.md)
OVERRUN_S_PER_CURVE = 3.5e-5
OVERRUN_PRIOR_CURVES = 5000
#: a group given its exact time mostly needs a fraction of it: the plan charges each exact group
#: ``exact_s`` times the ratio the exact groups solved so far used of it, starting from
#: EXACT_PRIOR_RATIO as if measured on EXACT_PRIOR_S seconds (a light prior: charged in full, too
#: few groups got their proofs; docs/BENCHMARKS.md)
EXACT_PRIOR_RATIO = 0.5
EXACT_PRIOR_S = 0.25
#: what a proof uses of its exact time grows with the group's size: the plan charges an exact
#: group ``rho * e * (n / EXACT_SHAPE_CURVES) ** EXACT_SHAPE_EXPONENT`` (at most ``e``) and learns
#: ``rho`` against the same shape (one ratio learnt on large groups kept the small ones from
#: their proofs; the exponent is fitted, docs/BENCHMARKS.md)
EXACT_SHAPE_EXPONENT = 0.5
EXACT_SHAPE_CURVES = 100.0


def exact_time_s(n_curves):
    """The least per-group limit at which the exact step is tried on a group of ``n_curves``
    (numpy arrays too): what a shared budget must give a group it wants proven."""
    return MIN_SYMMETRIC_S + MIN_SYMMETRIC_S_PER_CURVE * n_curves


def budget_weights(problem: OrderingProblem) -> np.ndarray:
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


class BudgetPlan:
    """How a shared budget is spent (module docstring). Of the groups still to come, the smallest
    get ``exact_time_s(n)``, the rest ``HEURISTIC_S_PER_CURVE * n`` (plus, on the time
    objective, ``MATRIX_S_PER_LINK`` per link of their matrix). Most proofs take a fraction
    of their exact time, the smaller the group the smaller, so the plan charges an exact group a
    shape of its size (``shape_s``, at most its exact time) times the ratio measured so far
    (``used_ratio``). Each group's limit is its exact or heuristic time scaled by time left / time
    planned, so what finished early flows to the groups after it, and every re-plan promotes the
    next smallest.

    Where what is left does not pay even every group's heuristic time, the groups are funded
    smallest first: as many exact times as it pays, then as many heuristic times of the next
    smallest as the rest pays, and the largest get none (``limit`` None: the slicer's order,
    unsearched). Spreading it thin over every group instead (the plan before) let the first large
    groups of the chain (a file's bottom layers) run their greedy paths and matrices far past
    their shares, and the runner's overrun reserve then kept every group after them from any
    search: the Cura bunny, safe mode, 3.2 s: 13 groups searched, 0 proven, 1,055 out of time."""

    def __init__(self, problem: OrderingProblem, shared=None, matrices_made: bool = False):
        """``matrices_made``: the groups come with their link matrices already made (the exact
        solve after the greedy pass, ``layers.solve(greedy=...)``): a search no longer pays for
        them."""
        w = budget_weights(problem)
        self.claims = w > 0
        n = w[self.claims]
        self.groups = np.flatnonzero(self.claims)[np.argsort(n, kind="stable")]  # smallest first
        n = w[self.groups]
        self.curves = n
        self.exact_s = exact_time_s(n)
        self.shape_s = self.exact_s * (n / EXACT_SHAPE_CURVES) ** EXACT_SHAPE_EXPONENT
        self.heuristic_s = HEURISTIC_S_PER_CURVE * n
        #: per claim, what making its matrix adds to its heuristic time (0: made already)
        self.matrix_s = np.zeros(len(n))
        if problem.pricer is not None and not matrices_made:
            # the time objective: its matrix, ~2 candidates a curve
            self.matrix_s = MATRIX_S_PER_LINK * (2.0 * n) ** 2
            self.heuristic_s = self.heuristic_s + self.matrix_s
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

    def limit(self, g: int, left_s: float) -> float | None:
        """Time for group ``g`` out of ``left_s`` seconds left for it and the groups after it;
        None: none (what is left is spent on smaller groups: the class docstring)."""
        if not self.claims[g]:
            return left_s          # DP, repeat: takes next to nothing, capped by what is left
        pending = self.pending
        pending[self.rank[g]] = True
        h = self.heuristic_s[pending]
        e = np.maximum(np.minimum(self.used_ratio * self.shape_s[pending], self.exact_s[pending]), h)
        i = int(self.rank[g])
        pos = int(np.count_nonzero(pending[:i]))        # g's place among the pending groups
        if h.sum() <= left_s:
            # every group its heuristic time, and the longest prefix (smallest groups) that the
            # rest pays its exact time
            cost = np.cumsum(e - h) + h.sum()
            n_exact = int(np.searchsorted(cost, left_s, side="right"))
            planned = cost[n_exact - 1] if n_exact else h.sum()
        else:
            # not even that: smallest first, exact times, then heuristic times, then nothing
            cost = np.cumsum(e)
            n_exact = int(np.searchsorted(cost, left_s, side="right"))
            spent = cost[n_exact - 1] if n_exact else 0.0
            rest = np.cumsum(h[n_exact:])
            n_heur = int(np.searchsorted(rest, left_s - spent, side="right"))
            planned = spent + (rest[n_heur - 1] if n_heur else 0.0)
            if pos >= n_exact + n_heur:
                return None
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


# ---- the greedy chain's budget in work, not wall-clock (issue 36)
#
# The greedy pass (``--formulation greedy``, and an exact run's first pass) decides which groups
# it orders from counts, never from a clock, as OR-Tools CP-SAT's ``max_deterministic_time`` or
# Gurobi's ``WorkLimit`` do: each group's work is priced from its size in *deterministic seconds*
# (the CPU seconds the step takes on the calibration machine, fitted by bench/ordering_work.py:
# docs/BENCHMARKS.md, "Greedy pass work units"), and the budget's seconds are spent in those.
# Two runs of one file with one budget order the same groups the same way, whatever the
# machine's load and whichever process makes the link matrices (``matrix_helper``: its matrices
# are charged to the plan as if the main process had made them). A machine slower than the
# calibration one runs past the budget; the wall-clock safety net (``WORK_NET_FACTOR``) ends the
# pass there, and the run says so (then it is not reproducible).

#: The constants are fitted by bench/ordering_work.py on this machine (thread CPU seconds, 2,692
#: groups of the Cura bunny, real_cura591, prusa25_xend_honey25_acp and real_prusa261_benchy,
#: safe and free; docs/BENCHMARKS.md, "Greedy pass work units"), each scaled so that the modelled
#: total is the measured one.
#: per curve of the file, building its group and passing it (every group, fixed too: measured
#: 5.8e-6), and the chain's end (``chain.pick_paths``, travel totals); and per group, what
#: passing a group costs whatever its size (building it, its start and end links, settling it
#: in the chain). Measured again (the greedy pass without a budget, one worker, wall seconds
#: outside the groups' solves, thirteenth session): 2.0 s on a Cura pin plate of 4,966 groups
#: and 10,057 curves (safe mode: one group per island), 2.1 s on prusa25_bunny_triangles15_lh01
#: safe (5,583 / 9,201), 2.3 s on pins__prusa_mk3s safe (4,939 / 4,939), 3.2 s on
#: pins__cura_mk3 safe (7,271 / 12,922), 2.0 s on the Cura bunny safe (2,446 / 67,356): ~0.35 ms
#: a group and ~1.5e-5 s a curve with the tail; the per-curve rates alone had charged the pin
#: plate 0.1 s, and its greedy pass ran 6 s on a 4.6 s budget (the whole run 16 s). With these,
#: `gatesopt order` (10 s, two workers, alternating with the code before, two runs each): the
#: Cura bunny safe 13.3 / 18.7 s -> 12.3 / 12.4 s, 200 -> 259 groups left unsearched, print
#: time after 44,908 -> 44,990 s (of 45,305); pins__cura_mk3 safe and lh01 free unchanged
WORK_PASS_S_PER_CURVE = 1.1e-5
WORK_TAIL_S_PER_CURVE = 4e-6
WORK_PASS_S_PER_GROUP = 3.5e-4
#: making a group's time-objective link matrix, per link (m^2 for m candidates): measured 3.33e-7
#: (measured / modelled over the groups above 1 ms: p10 0.90, p50 0.96, p90 1.24)
WORK_MATRIX_S_PER_LINK = 3.3e-7
#: greedy's nearest neighbour, local search, orientation DP and cheap bound: per link (m^2), per
#: curve and per group (fitted 4.3e-8 per link and 1.4e-4 per group, x 1.4 to the measured total;
#: p10 0.84, p50 1.11, p90 1.55: the local search's passes vary)
WORK_GREEDY_S_PER_LINK = 6.1e-8
WORK_GREEDY_S_PER_CURVE = 0.0
WORK_GREEDY_S_PER_GROUP = 1.9e-4
#: the subset DP (``dp.work``: 2^n m^2 states x moves) and per group (p10 0.90, p90 1.13)
WORK_DP_S_PER_STATE = 1.3e-9
WORK_DP_S_PER_GROUP = 4.3e-5
#: the matching step (``greedy_pass.matching_path``) on groups of at most
#: ``greedy_pass.MATCHING_MAX_CURVES``: per group and per link (the Cura bunny, safe: 369 groups
#: of 13-40 curves, 0.26 s CPU in all)
WORK_MATCHING_S_PER_CURVE3 = 0.0
WORK_MATCHING_S_PER_LINK = 2e-7
WORK_MATCHING_S_PER_GROUP = 2e-4
#: ILS with a fixed number of kicks on safe mode's block orders (``blocks._solve``), per kick and
#: block, and per group: measured on pins__prusa_mk3s_acp and pins__cura_mk3 (11 calls each
#: after the first, 35 blocks, 175 kicks: 0.71 / 0.68 s CPU, 1.06e-5 / 1.01e-5 s per kick and
#: block, the per-group part included; one kick 0.6 ms; ``bench/ordering_work.py --blocks``). (On
#: the curves of real groups ILS costs ~1.2e-6 s per kick and curve plus 1.5e-2 s per group:
#: fitted on 180 groups of the four files above; a block group's kicks cost ~10x that)
WORK_ILS_S_PER_KICK_CURVE = 1.1e-5
WORK_ILS_S_PER_GROUP = 1e-3
#: the safety net: a pass still running this many times its budget (plus WORK_NET_MIN_S) of
#: wall-clock seconds after it began (a machine several times slower than the calibration one)
#: leaves the groups after it unsearched, and the run says the net fired
WORK_NET_FACTOR = 3.0
WORK_NET_MIN_S = 5.0


def group_cands(problem: OrderingProblem) -> tuple[np.ndarray, np.ndarray]:
    """Per group (curves, candidates): one candidate per loop (its seam) and per one-way curve,
    two per other open curve (either direction); with ``move_seams`` a loop's extra seams are not
    counted (a lower estimate, the same on every run)."""
    start = np.asarray(problem.group_curve_start, np.int64)
    n = np.diff(start)
    two = ~np.asarray(problem.curve_closed, bool) & ~one_way(problem)
    open_cum = np.concatenate([[0], np.cumsum(two)])
    return n, n + (open_cum[start[1:]] - open_cum[start[:-1]])


def greedy_work_s(n, m, time_objective: bool, dp_first) -> np.ndarray:
    """Deterministic seconds of the greedy pass's solve of groups of ``n`` curves and ``m``
    candidates (numpy arrays): its link matrix (time objective) and the subset DP (``dp_first``)
    or greedy's path."""
    n, m = np.asarray(n, float), np.asarray(m, float)
    links = m * m
    states = np.where(dp_first, 2.0 ** np.minimum(n, 60.0) * links, 0.0)
    solve = np.where(dp_first, WORK_DP_S_PER_GROUP + WORK_DP_S_PER_STATE * states,
                     WORK_GREEDY_S_PER_GROUP + WORK_GREEDY_S_PER_CURVE * n
                     + WORK_GREEDY_S_PER_LINK * links)
    return solve + (WORK_MATRIX_S_PER_LINK * links if time_objective else 0.0)


def matching_work_s(n: int, m: int) -> float:
    """Deterministic seconds of the matching step on a group of ``n`` curves, ``m`` candidates."""
    return (WORK_MATCHING_S_PER_GROUP + WORK_MATCHING_S_PER_CURVE3 * float(n) ** 3
            + WORK_MATCHING_S_PER_LINK * float(m) ** 2)


class WorkPlan:
    """The greedy chain's budget in deterministic seconds (the section's comment above). The pass
    of every group and the chain's end are set aside first; of the rest, each re-orderable group
    is charged its solve's work (``greedy_work_s``, counted from its size; the matching step's
    where it ran). Where what is left does not pay for every group still to come, the smallest
    are paid for first and the largest keep the slicer's order (as ``BudgetPlan`` funds them):
    ``funds`` answers per group, in print order, from counts alone."""

    def __init__(self, problem: OrderingProblem, budget_s: float):
        from .dp import MAX_WORK
        n, m = group_cands(problem)
        decided = np.asarray(problem.group_reorderable, bool)
        dp_first = decided & (n <= DP_CURVES) & ((2.0 ** np.minimum(n, 60)) * m * m <= MAX_WORK)
        self.est_s = np.where(decided, greedy_work_s(n, m, problem.pricer is not None, dp_first),
                              0.0)
        self.time_objective = problem.pricer is not None
        self.budget_s = float(budget_s)
        self.left_s = (self.budget_s - WORK_PASS_S_PER_GROUP * problem.n_groups
                       - (WORK_PASS_S_PER_CURVE + WORK_TAIL_S_PER_CURVE)
                       * float(problem.n_curves))
        self.order = np.flatnonzero(decided)[np.argsort(self.est_s[decided], kind="stable")]
        self.rank = np.full(problem.n_groups, -1, np.int64)
        self.rank[self.order] = np.arange(len(self.order))
        self.pending = np.ones(len(self.order), bool)       # by rank

    def funds(self, g: int) -> bool:
        """Whether group g (re-orderable, the next in print order) is searched: every group still
        to come is paid for, or g is among the smallest that what is left pays for."""
        r = int(self.rank[g])
        if r < 0:
            return True
        est = self.est_s[self.order[self.pending]]
        if est.sum() <= self.left_s:
            return True
        k = int(np.searchsorted(np.cumsum(est), self.left_s, side="right"))
        return int(np.count_nonzero(self.pending[:r])) < k

    def affords(self, g: int, extra_s: float) -> bool:
        """Whether ``extra_s`` more on group g (the matching step) still leaves every group after
        it paid for (then it takes nothing from them)."""
        r = int(self.rank[g])
        after = self.pending.copy()
        if r >= 0:
            after[r] = False
        return (self.est_s[self.order[after]].sum() + self.est_s[g] + extra_s) <= self.left_s

    def charge(self, g: int, work_s: float) -> None:
        """Group g is done, its solve charged ``work_s`` (0: it kept the slicer's order)."""
        r = int(self.rank[g])
        if r >= 0:
            self.pending[r] = False
        self.left_s -= work_s
