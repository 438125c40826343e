"""Proofs audited on the printed order (issue 36: "no proven group" claim without its check): every
group a re-ordered output reports proven optimal is checked, where the subset DP takes it
quickly, against the DP's optimum from where the output prints it -- independent of the solve's
bookkeeping of which start and end each proof was made for (``ordering.settle``,
``rewrite.guard.printed_answer``). Used by ``bench/ordering_as_printed.py`` and the tests."""
from __future__ import annotations

import numpy as np

from ..ordering import dp
from ..ordering.chain import (BACKWARDS, LOOKAHEAD_FROM, anchor_at, anchor_before, end_of,
                              entry_positions, path_curves)
from ..ordering.problem import OPTIMAL_ABS_TOL, OrderingProblem, OrderingSolution
from ..ordering.repair import REPAIRED
from ..solvers import Status

#: the proof audit checks a group with the subset DP where that takes at most this long
AUDIT_DP_MAX_S = 0.01


def printed_as_answered(problem: OrderingProblem, solution: OrderingSolution, g: int, grp,
                        first: np.ndarray) -> bool:
    """Whether ``solution`` prints group g's reported path (``grp``: ``problem.group(g, ...)``,
    any start) from position ``first[g]`` (``chain.entry_positions``) on."""
    curves = path_curves(problem, g, grp, solution.groups[g].order)
    at = int(first[g])
    return np.array_equal(curves, np.asarray(solution.curve_order)[at:at + len(curves)])


def audit_proofs(problem: OrderingProblem, solution: OrderingSolution) -> tuple[int, int]:
    """(groups checked, groups reported optimal that are not): every re-orderable group the
    output reports proven optimal, not the second half of a split proof (``+back``,
    ``+ahead:from``) nor repaired on joined costs (``+joined``), that the subset DP takes in at
    most ``AUDIT_DP_MAX_S``, must print the DP's optimum from the curve the output prints before
    it, to its own end (free, a fixed group's entry, the file's end) or to the next group's
    entry as the output prints it. Independent of the solve's bookkeeping (which start each
    proof was made for): the claims are checked on the printed order itself."""
    first = entry_positions(problem, solution)
    n = len(solution.curve_order)
    checked = failed = 0
    for g, gs in enumerate(solution.groups):
        if (not problem.group_reorderable[g] or gs.status != Status.OPTIMAL or first[g] >= n
                or any(s in gs.formulation for s in (BACKWARDS, LOOKAHEAD_FROM, REPAIRED))):
            continue
        start = anchor_before(problem, solution, int(first[g]))
        ends = [end_of(problem, g)]
        grp = problem.group(g, start, ends[0])
        if len(gs.order) != grp.n_curves or not (dp.fits(grp)
                                                 and dp.time_s(grp) <= AUDIT_DP_MAX_S):
            continue
        # (a layer the time guard put back prints the slicer's order, not the answer reported:
        # the "proven groups reverted")
        if not printed_as_answered(problem, solution, g, grp, first):
            continue
        if ends[0] is None and g + 1 < problem.n_groups and first[g + 1] < n:
            ends.append(anchor_at(problem, solution, int(first[g + 1])))
        checked += 1
        failed += not any(problem.group(g, start, e).path_cost(gs.order)
                          <= dp.solve(problem.group(g, start, e)).objective + OPTIMAL_ABS_TOL
                          for e in ends)
    return checked, failed
