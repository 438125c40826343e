"""The chain picked, made right where it is printed (issue 36: a group's proof holds for the start
it prints from and the end it travels on to; formulations/ordering.md, "Across groups and
layers").

The chain DP (``chain.pick_paths``) takes, per group, one of a few paths each solved for its own
start and end: the solver's path from where the solver's path before it ended, the slicer's order
(``+kept``) for the next group's sake, a look-ahead or backwards half. Where the path taken is not
proven for the start and end the chain gives it (``proof_holds``), the subset DP, where it takes
the group in milliseconds, solves the group again from there (``settle``): its optimum replaces
the path if cheaper, so the chain only gets cheaper and the group is proven where it prints.

A group solved to travel on to the next group's entry ("tied": the slicer's order taken for the
next group's sake, a look-ahead path, a path to the helper's entry) keeps that entry: the next
group is then settled from its first curve (``first``), and where that is dearer than its
optimum, the two are solved in turn (``settle_pair``) until each is the other's optimum.
"""
from __future__ import annotations

import numpy as np

from ..solvers import Status
from . import dp
from .chain import (BACKWARDS, KEPT, LOOKAHEAD_FROM, LOOKAHEAD_TO, end_of, quick_dp,
                    reprove)
from .problem import OPTIMAL_ABS_TOL, Anchor, GroupSolution, OrderingProblem, same_anchor

#: the formulation suffix of a path the subset DP put in place of the chain's pick
SETTLED = "+settled"
#: ``settle_pair``: at most this many turns (each two subset DPs of <= ``REPROVE_MAX_S``)
PAIR_TURNS = 4


def settle_chain(problem: OrderingProblem, plans, picked: list, priced: list | None = None) -> list:
    """``picked`` (per group the answer the chain DP took, ``plans`` as ``layers.solve`` keeps
    them) with each re-orderable group whose answer is not proven where it prints settled there
    (``settle``), in print order: each group's start is the exit of the group before as
    settled. ``priced``: a list of ``len(plans)`` Nones, where each answer settled gets the
    (start, end) anchors its cost and bound are for, None where not known (``layers.solve_greedy``
    hands them on with the answer: a bound holds for the costs it was proven with)."""
    picked = list(picked)
    reorderable = problem.group_reorderable
    entry = Anchor.of(problem.origin_xy)       # where the chain picked enters each group
    tied = False        # the group before is proven for this group's picked entry as its end
    before = None       # (start, first) the group before was settled with
    for g, (grp, _, _, _) in enumerate(plans):
        gs = picked[g]
        first = int(gs.order[0]) if tied and len(gs.order) else None
        fixed = end_of(problem, g)
        to = printed_end(problem, plans, picked, g)
        # (a fallback -- a group the budget left no time for -- stays as it is: no search
        # after the budget; nor is an unproven group the DP cannot take quickly priced again)
        unproven = gs.status == Status.FEASIBLE and quick_dp(grp)
        if reorderable[g] and (unproven or (gs.status == Status.OPTIMAL and (
                gs.formulation.endswith(KEPT) or not proof_holds(problem, plans, picked, g, entry)))):
            nxt = next_entry(problem, plans, picked, g) if fixed is None else None
            gs, tied, end_priced = settle(problem, g, entry, gs, first, fixed, nxt, to)
            picked[g] = gs
            if priced is not None:
                priced[g] = None if end_priced is False else (entry, end_priced)
            if (first is not None and gs.status != Status.OPTIMAL and before is not None
                    and reorderable[g - 1]):
                end = fixed if fixed is not None else nxt
                pair = settle_pair(problem, g - 1, before[0], before[1], picked[g - 1], g, end, gs)
                if pair is not None:
                    picked[g - 1], gs, on_a, on_b = pair
                    picked[g] = gs
                    if priced is not None:
                        priced[g - 1], priced[g] = on_a, on_b
                    entry = problem.exit_anchor(g - 1, problem.group(g - 1, before[0]),
                                                picked[g - 1].order)
                    first = int(gs.order[0])        # where the group before now ends
                    tied = end is not None and fixed is None
        else:
            # (a fixed group, or one not proven, holds no claim on the next group's entry)
            tied = (to is not None and fixed is None and bool(reorderable[g])
                    and gs.status == Status.OPTIMAL)
        before = (entry, first)
        if grp.n_curves:
            entry = problem.exit_anchor(g, grp, gs.order)
    return picked


def settle(problem: OrderingProblem, g: int, start: Anchor, gs: GroupSolution, first, fixed,
           nxt, to) -> tuple:
    """Group g's answer ``gs`` where the chain prints it, entered from ``start`` (from
    candidate ``first`` if not None: the group before was proven for it as its end, so the path
    keeps it), and whether it is now proven for the next group's entry as its end (the group
    after then keeps its first candidate). Where the subset DP takes the group in at most
    ``REPROVE_MAX_S``: proven as it stands if it is the DP's optimum from ``start`` to ``fixed``
    (the problem's end: a fixed group's entry, the file's end; None: free); else the DP's
    optimum to ``fixed``, or where that is free, to ``nxt`` (the next group's entry as picked,
    None where there is none), in its place if cheaper: the rest of the chain unchanged (the
    start is the group before's exit, the end the group after's entry), so the chain only gets
    cheaper. With ``first``: the cheapest path from it, optimal where it costs the DP's optimum.
    Elsewhere ``chain.reprove`` for the end the path was taken for (``to``: ``printed_end``).
    Returns (the answer, tied, the end its cost and bound are for from ``start``: an Anchor or
    None (free); False where not known).
    Seen on fresh PrusaSlicer output in free mode: the slicer's order taken by the chain DP for
    the next group's entry (``+kept``), 76 of 324 groups unproven where a DP path to the same
    entry was cheaper."""
    grp = problem.group(g, start, fixed)
    if not (len(gs.order) == grp.n_curves and quick_dp(grp)):
        gs = reprove(problem, g, start, to, gs)
        return gs, gs.status == Status.OPTIMAL and to is not None and fixed is None, False
    best = dp.solve(grp)
    cost = grp.path_cost(gs.order)
    if cost - best.objective <= OPTIMAL_ABS_TOL:
        return GroupSolution.make(gs.order, cost, cost, Status.OPTIMAL, gs.solve_s,
                                  gs.formulation), False, fixed
    tied = fixed is None and nxt is not None
    end = fixed
    if tied:
        end = nxt
        grp = problem.group(g, start, nxt)
        best = dp.solve(grp)
        cost = grp.path_cost(gs.order)
    order, form = gs.order, gs.formulation
    cand = best if first is None else dp.solve(grp, first=int(first))
    if cand.objective < cost - OPTIMAL_ABS_TOL:
        order, cost, form = cand.order, cand.objective, _settled(gs.formulation)
    status = Status.OPTIMAL if cost - best.objective <= OPTIMAL_ABS_TOL else Status.FEASIBLE
    return (GroupSolution.make(order, cost, min(best.objective, cost), status, gs.solve_s, form),
            tied and status == Status.OPTIMAL, end)


def settle_pair(problem: OrderingProblem, a: int, start_a: Anchor, first_a, gs_a: GroupSolution,
                b: int, end_b, gs_b: GroupSolution):
    """Group ``a`` (entered from ``start_a``, from candidate ``first_a`` if not None) tied to
    group ``b = a + 1`` (``a`` travels on to b's entry, ``b`` to ``end_b``), where b is dearer
    from that entry than its optimum: b's optimum from a's exit, then a's optimum to that
    optimum's entry, in turn, until a's path no longer changes (at most ``PAIR_TURNS``): then b
    is optimal from a's exit and a is to b's entry (at the optimum of paths from ``first_a``).
    The two answers and the (start, end) each is priced and bounded for, or None where the turns
    do not settle, a group is not quick for the DP, or the two cost more together than ``gs_a``
    and ``gs_b``."""
    free_a = problem.group(a, start_a)
    if len(gs_a.order) != free_a.n_curves or not len(gs_a.order):
        return None
    before = free_a.path_cost(gs_a.order) + problem.group(
        b, problem.exit_anchor(a, free_a, gs_a.order), end_b).path_cost(gs_b.order)
    q = gs_a.order
    for _ in range(PAIR_TURNS):
        grp_b = problem.group(b, problem.exit_anchor(a, free_a, q), end_b)
        if not quick_dp(grp_b):
            return None
        p = dp.solve(grp_b)
        grp_a = problem.group(a, start_a, problem.cand_anchor(b, grp_b, int(p.order[0])))
        if not quick_dp(grp_a):
            return None
        qa = dp.solve(grp_a) if first_a is None else dp.solve(grp_a, first=int(first_a))
        if np.array_equal(qa.order, q):
            break
        q = qa.order
    else:
        return None
    if free_a.path_cost(q) + p.objective > before + OPTIMAL_ABS_TOL:
        return None
    best_a = qa.objective if first_a is None else dp.solve(grp_a).objective
    status_a = (Status.OPTIMAL if qa.objective - best_a <= OPTIMAL_ABS_TOL else Status.FEASIBLE)
    new_a = GroupSolution.make(q, qa.objective, best_a, status_a, gs_a.solve_s,
                               _settled(gs_a.formulation))
    new_b = GroupSolution.make(p.order, p.objective, p.objective, Status.OPTIMAL, gs_b.solve_s,
                               _settled(gs_b.formulation))
    entry_b = problem.cand_anchor(b, grp_b, int(p.order[0]))
    return new_a, new_b, (start_a, entry_b), (problem.exit_anchor(a, free_a, q), end_b)


def _settled(formulation: str) -> str:
    return formulation if formulation.endswith(SETTLED) else formulation + SETTLED


def printed_end(problem: OrderingProblem, plans, picked, g: int):
    """Where group g's path travels on to in the chain picked, as far as its cost counts it: the
    end it was solved with if that came from the problem (a fixed group's entry, the file's end),
    the entry of the next group's picked path if it was solved to the helper's path or to an
    entry of the next group (a look-ahead path, the slicer's order taken for the next group's
    sake: proven again for the entry the chain takes), else none."""
    end = plans[g][3]
    form = picked[g].formulation
    to_next = LOOKAHEAD_TO in form or form.endswith(KEPT) or (
        end is not None and end_of(problem, g) is None)
    return next_entry(problem, plans, picked, g) if to_next else end


def next_entry(problem: OrderingProblem, plans, picked, g: int) -> Anchor | None:
    """Where the chain picked enters the group after g: its picked path's first candidate
    (None: g is the last group, or the next path is empty)."""
    if g + 1 < len(plans) and len(picked[g + 1].order):
        return problem.cand_anchor(g + 1, plans[g + 1][0], int(picked[g + 1].order[0]))
    return None


def proof_holds(problem: OrderingProblem, plans, picked, g: int, entry: Anchor) -> bool:
    """Whether group g's picked answer (proven for the problem it was solved as) is proven in the
    chain picked: a forward solve was proven from the start in ``plans`` (each group from the
    solver's path of the one before) -- the chain DP may enter it from elsewhere (``entry``:
    another option taken for the group before); one solved to the next group's path as the
    helper process found it (its end not the file's nor a fixed group's) was proven for that
    entry -- the chain may take another path there. Split proofs hold where their other half is
    taken: a path solved backwards (its start free, the travel into it the group before's: the
    group before was solved to it) and a look-ahead pair (``chain.look_ahead``: g's path to an
    entry of g + 1, g + 1's from it), taken together (of two tries the chain could pair halves
    of different ones: not told apart here)."""
    grp, _, start, end = plans[g]
    form = picked[g].formulation
    if BACKWARDS in form:
        return True
    if LOOKAHEAD_FROM in form:
        return g > 0 and LOOKAHEAD_TO in picked[g - 1].formulation
    if not same_anchor(entry, start):
        return False
    if LOOKAHEAD_TO in form:
        return g + 1 < len(plans) and LOOKAHEAD_FROM in picked[g + 1].formulation
    if end is None or end_of(problem, g) is not None:
        return True
    nxt = next_entry(problem, plans, picked, g)
    return nxt is not None and same_anchor(nxt, end)
