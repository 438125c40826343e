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
from .problem import FILE_END, OPTIMAL_ABS_TOL, Anchor, GroupSolution, OrderingProblem

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
#: the formulation suffix of a path solved backwards (``solve_backwards``: its start free, the
#: travel into it the group before's)
BACKWARDS = "+back"
#: the formulation suffixes of a look-ahead pair (``look_ahead``): group g's path solved to end at
#: an entry of group g + 1 (``LOOKAHEAD_TO``) and g + 1's path solved from that entry
#: (``LOOKAHEAD_FROM``): a split proof, each of its part, taken together by the chain DP
LOOKAHEAD = "+ahead"
LOOKAHEAD_TO = LOOKAHEAD + ":to"
LOOKAHEAD_FROM = LOOKAHEAD + ":from"
#: the formulation suffix of the slicer's order offered beside the solver's path (``path_options``)
KEPT = "+kept"


def look_ahead(problem: OrderingProblem, plans, fn, time_limit_s, deadline, kwargs) -> None:
    """Chain options across boundaries whose next group is small and re-orderable (its entry is
    the path's choice, so group g was solved with a free end; formulations/ordering.md, "Across
    groups and layers"). For the entries ``e`` of group g+1 whose lower bound on the pair (g's
    bound with a free end plus g+1's optimum from ``e``) is lowest and below the pair as solved:
    group g again with its end at ``e``; if g's path to ``e`` and g+1's path from it cost less than
    the pair, both join the groups' options (in place) and ``pick_paths`` takes them where the whole
    chain gets cheaper. Identical re-solves (layers that repeat) are solved once. Seen on KISSlicer
    output: a 24-curve infill group proven optimal for itself ended 19 mm further from the next
    layer's 2-curve group than the greedy path did. (``plans``: per group (Group, options, start
    Anchor, end Anchor or None).)"""
    cache: dict = {}
    for g in range(problem.n_groups - 1):
        if (deadline is not None and time.perf_counter() > deadline) or stop_requested():
            return              # (Ctrl-C: every group has its answer; the options stay as they are)
        grp, opts, start, _ = plans[g]
        nxt, nxt_opts, _, nxt_end = plans[g + 1]
        if (problem.group_fixed[g] or problem.group_fixed[g + 1] or grp.end_xy is not None
                or grp.n_curves == 0 or not 0 < nxt.n_curves <= LOOKAHEAD_CURVES
                or opts[0].status != Status.OPTIMAL):
            continue
        pair = opts[0].objective + nxt_opts[0].objective
        _, first = np.unique(nxt.cand_entry_xy, axis=0, return_index=True)
        ahead = []
        for k in first.tolist():
            e = problem.cand_anchor(g + 1, nxt, k)
            ng = problem.group(g + 1, Anchor.of(e.xy), nxt_end)      # already at e
            ns = dp.solve(ng) if dp.fits(ng) else fn(ng, time_limit_s=time_limit_s, **kwargs)
            low = opts[0].bound + ns.objective
            if low < pair - OPTIMAL_ABS_TOL:
                ahead.append((low, k, e, ns))
        ahead.sort(key=lambda a: a[0])
        for low, k, e, ns in ahead[:LOOKAHEAD_TRIES]:
            gg = problem.group(g, start, e)
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
            if gs.objective + ns.objective < pair - OPTIMAL_ABS_TOL:
                opts.append(GroupSolution.make(gs.order, gs.objective, gs.bound, gs.status,
                                               gs.solve_s, gs.formulation + LOOKAHEAD_TO))
                nxt_opts.append(GroupSolution.make(ns.order, ns.objective, ns.bound,
                                                   ns.status, ns.solve_s,
                                                   ns.formulation + LOOKAHEAD_FROM))


#: a proof made for another start is made again for the start printed where the subset DP takes
#: at most this long on the group (``reprove``; a DP of <= 12 curves takes about a millisecond)
REPROVE_MAX_S = 0.01


def quick_dp(grp) -> bool:
    """Whether the subset DP takes ``grp`` in at most ``REPROVE_MAX_S`` (proofs made again where
    a group prints: ``reprove``, ``settle``, ``guard.printed_answer``)."""
    return dp.fits(grp) and dp.time_s(grp) <= REPROVE_MAX_S


def reprove(problem: OrderingProblem, g: int, start: Anchor, end,
            gs: GroupSolution) -> GroupSolution:
    """Group g's answer ``gs`` (proven for another start or end than those it is printed with:
    another path taken before it, or after it where it was solved to the next group's entry)
    from ``start`` to ``end`` (None: free): priced there, and proven again where the subset DP
    takes the group in at most ``REPROVE_MAX_S`` -- optimal if its path costs the DP's optimum,
    else feasible with that optimum as its bound; elsewhere at best feasible, unpriced again."""
    grp = problem.group(g, start, end)
    if len(gs.order) == grp.n_curves and quick_dp(grp):
        best = dp.solve(grp).objective
        cost = grp.path_cost(gs.order)
        status = Status.OPTIMAL if cost - best <= OPTIMAL_ABS_TOL else Status.FEASIBLE
        return GroupSolution.make(gs.order, cost, min(best, cost), status, gs.solve_s,
                                  gs.formulation)
    status = Status.FEASIBLE if gs.status == Status.OPTIMAL else gs.status
    return GroupSolution.make(gs.order, gs.objective, gs.bound, status, gs.solve_s, gs.formulation)


def path_curves(problem: OrderingProblem, g: int, grp, path) -> np.ndarray:
    """The program curves (``curve_source`` applied) group g prints along ``path`` (indices of
    ``grp``'s candidates, ``grp`` = ``problem.group(g, ...)``), in order."""
    cand = np.asarray(grp.cand_curve, np.int64)[np.asarray(path, np.int64)]
    curves = np.asarray(problem.group_curves(g), np.int64)[cand]
    if problem.curve_source is not None:
        curves = np.asarray(problem.curve_source, np.int64)[curves]
    return curves


def entry_positions(problem: OrderingProblem, solution) -> np.ndarray:
    """Per group, the position in ``solution``'s print order (an ``OrderingSolution``, program
    curve numbering) of the group's first curve printed; the number of curves for an empty
    group."""
    pp = problem.program_problem
    n, G = pp.n_curves, problem.n_groups
    owner = np.repeat(np.arange(G), np.diff(np.asarray(problem.group_curve_start, np.int64)))
    if problem.curve_source is not None:
        own = np.empty(n, np.int64)
        own[np.asarray(problem.curve_source, np.int64)] = owner
        owner = own
    first = np.full(G, n, np.int64)
    if n:
        np.minimum.at(first, owner[np.asarray(solution.curve_order, np.int64)], np.arange(n))
    return first


def anchor_before(problem: OrderingProblem, solution, pos: int) -> Anchor:
    """Where ``solution`` stands before printing its curve at position ``pos``: the exit of the
    curve before it, as printed (the origin before the first)."""
    if pos <= 0:
        return Anchor.of(problem.origin_xy)
    return _printed_anchor(problem, solution, pos - 1, 1)


def anchor_at(problem: OrderingProblem, solution, pos: int) -> Anchor:
    """Where ``solution`` enters its curve at position ``pos``: the curve's entry point as
    printed (the end a group's path travels on to where the next group begins there)."""
    return _printed_anchor(problem, solution, pos, 0)


def _printed_anchor(problem: OrderingProblem, solution, pos: int, side: int) -> Anchor:
    """The entry (``side`` 0) or exit (1) of ``solution``'s curve at position ``pos`` as an
    Anchor in the problem's numbering."""
    c = int(np.asarray(solution.curve_order, np.int64)[pos])
    ends = problem.program_problem.entry_exit_xy(np.array([c]), solution.curve_reversed,
                                                 solution.curve_seam)
    changed = bool(solution.curve_reversed[c]) or int(solution.curve_seam[c]) != 0
    pc = c
    if problem.curve_source is not None:
        pc = int(np.flatnonzero(np.asarray(problem.curve_source) == c)[0])
    return Anchor(np.asarray(ends[side][0], float).copy(), pc, changed)


def end_of(problem: OrderingProblem, g: int):
    """Where group g's path must travel on to: the next group's entry (an Anchor: its first
    curve as the slicer printed it) if that group is fixed; for the file's last group, the
    file's end where its first XY move starts from the last curve printed (``FILE_END``,
    ``file_end.FileEnd``: a Cura file's ``G1 X0 Y210`` at the retraction feed,
    KISSlicer's lift at 5 mm/s); else None."""
    if g + 1 < problem.n_groups and problem.group_fixed[g + 1]:
        c = int(problem.group_curve_start[g + 1])
        return Anchor(problem.curve_start_xy[c].copy(), c, False)
    if g + 1 == problem.n_groups:
        fe = getattr(problem.pricer, "file_end", None)
        if fe is not None:
            return Anchor(np.asarray(fe.xy, float).copy(), FILE_END, False)
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
        ident_obj = grp.path_cost(ident)
        # proven only where it is an optimum too (the chain DP may take it for the chain's sake)
        status = gs.status
        if status == Status.OPTIMAL and ident_obj - gs.bound > OPTIMAL_ABS_TOL:
            status = Status.FEASIBLE
        opts.append(GroupSolution.make(ident, ident_obj, gs.bound, status, gs.solve_s,
                                       gs.formulation + KEPT))
        if ident_obj < gs.objective - 1e-9:
            opts = opts[::-1]
    return opts


def solve_backwards(runner, problem: OrderingProblem, g: int, end, greedy=None) -> tuple:
    """Group g with its end fixed (the next group's entry) and its start free: solved as
    ``Group.backwards()``. Returns (forward Group, options in forward order). Each option is
    proven for that problem: the travel into its first curve belongs to the group before, whose
    own end is then chosen to be this path's entry (formulations/ordering.md, "Two processes").
    ``greedy``: the greedy pass's answer for g (``runner.GreedyAnswer``), walked backwards."""
    fwd = problem.group(g, end, end)            # (its start is not used)
    back = fwd.backwards()
    gs = runner.run(g, back, greedy, backwards=True)
    back.check_order(gs.order)
    opts = [GroupSolution.make(o.order[::-1].copy(), o.objective, o.bound, o.status, o.solve_s,
                               o.formulation + BACKWARDS)
            for o in path_options(back, gs, backwards=True)]
    return fwd, opts


def rescored(problem: OrderingProblem, g: int, grp, opts, guess) -> list:
    """Options solved from a guessed start (an Anchor), scored from the real one (``grp``'s): a
    path from the real start costs its cost from the guess less the guess's start cost of its
    first candidate plus the real one, so its bound minus the largest such difference stays
    valid (for travel distance at most |s - s'|, the triangle inequality; the time objective
    has none); "optimal" stays only if it still closes."""
    guessed = problem.group(g, guess, None if grp.end_xy is None else grp.end_xy)
    shift = float(np.max(guessed.start_cost() - grp.start_cost())) if grp.n_cands else 0.0
    out = []
    for o in opts:
        obj = grp.path_cost(o.order)
        bound = max(0.0, o.bound - max(shift, 0.0))
        status = o.status
        if status == Status.OPTIMAL and obj - bound > OPTIMAL_ABS_TOL:
            status = Status.FEASIBLE
        out.append(GroupSolution.make(o.order, obj, bound, status, o.solve_s, o.formulation))
    return out


def pick_paths(problem: OrderingProblem, plans) -> list[int]:
    """Pick, per group, the solver's path or the slicer's order so that the whole chain is
    cheapest (a DP over groups with one state per option: each path is fixed, only the link into
    it depends on where the previous group ended). Contains the all-original choice, so the
    total never exceeds the slicer's."""
    pos = [Anchor.of(problem.origin_xy)]
    cost = [0.0]
    back = []
    for g, (grp, opts, _, _) in enumerate(plans):
        new_pos, new_cost, new_back = [], [], []
        for gs in opts:
            o = gs.order
            if len(o) == 0:
                new_cost.append(min(cost))
                arg = int(np.argmin(cost))
                new_pos.append(pos[arg])
                new_back.append(arg)
                continue
            entry = problem.cand_anchor(g, grp, int(o[0]))
            inner = grp.path_cost(o) - float(grp.start_cost()[o[0]])
            end = plans[g][3]
            if end is None or getattr(end, "curve", -1) != FILE_END:
                # (the link into the next group is that group's; the file's end is no group's)
                inner -= float(grp.end_cost()[o[-1]])
            links = [c + problem.link_cost(p, entry) for p, c in zip(pos, cost)]
            arg = int(np.argmin(links))
            new_cost.append(links[arg] + inner)
            new_pos.append(problem.exit_anchor(g, grp, o))
            new_back.append(arg)
        pos, cost = new_pos, new_cost
        back.append(new_back)
    choice = [0] * len(plans)
    k = int(np.argmin(cost)) if cost else 0
    for g in range(len(plans) - 1, -1, -1):
        choice[g] = k
        k = back[g][k]
    return choice
