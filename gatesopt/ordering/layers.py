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
from dataclasses import dataclass

import numpy as np

from ..solvers import Interrupted, Status, stop_requested
from . import formulations
from .chain import (BACKWARDS, LOOKAHEAD_FROM, LOOKAHEAD_TO, end_of, look_ahead, path_options,
                    pick_paths, rescored)
from .helper import Helper
from .matrix_helper import MatrixHelper, with_arc
from .problem import (Anchor, Group, GroupSolution, OrderingOptionsError, OrderingProblem,
                      OrderingSolution, path_travel_mm, same_anchor)
from .runner import GroupRunner, WorkRunner, greedy_answer
from .settle import settle_chain


@dataclass(frozen=True, eq=False)
class GreedyPass:
    """The greedy formulation's solve of every group (``solve_greedy``), kept for the exact solve
    after it (``solve(greedy=...)``, issue 36): ``solution`` (what ``solve(problem, "greedy")``
    returns: the time guard's greedy file), ``answers`` (per group a ``runner.GreedyAnswer``, None
    for a fixed group or one greedy had no time for) and ``matrices`` (per group the link matrix
    greedy made, None where it made none): the exact solve reuses them instead of making each
    searched group's matrix a second time (the time objective's matrices are most of what
    passing a file's groups costs: docs/BENCHMARKS.md, "Link-cost build")."""

    solution: OrderingSolution
    answers: tuple
    matrices: tuple
    #: groups whose matrix the helper process made (``matrix_helper``; empty with one worker)
    handed: frozenset = frozenset()
    #: per group (the Group as the greedy chain planned it, its start, its end): the exact chain
    #: takes the very group where it starts and ends the same way (``planned_at``)
    planned: tuple = ()

    def with_matrix(self, g: int, grp):
        """Group g as the exact chain builds it (its own start and end), with greedy's link
        matrix where greedy made one: the matrix depends on the group's candidates only
        (``cost.TimePricer.dense``), not on where the group starts or ends."""
        return with_arc(grp, self.matrices[g])

    def planned_at(self, g: int, start: Anchor, end) -> Group | None:
        """Group g as the greedy chain planned it, if it started at ``start`` and ended at
        ``end`` there too (the same anchors: the same group, its link costs and matrix made
        once), else None. Most groups of an exact chain start where greedy's did: the groups
        before them kept greedy's paths (bench/exact_pass_groups.py: prusa25_bunny_triangles15_lh01
        free 1,072 of 1,072, the Cura bunny safe 2,438 of 2,446; building a group, its start and
        end links, is ~0.4 ms)."""
        if g >= len(self.planned):
            return None
        grp, s, e = self.planned[g]
        same_end = (e is None) == (end is None) and (e is None or same_anchor(e, end))
        return grp if same_end and same_anchor(s, start) else None


def solve_greedy(problem: OrderingProblem, *, time_limit_s: float = 2.0,
                 budget_s: float | None = None, workers: int = 1,
                 progress=None) -> GreedyPass:
    """``solve(problem, "greedy", workers=workers)``, keeping per group greedy's answer, its bound
    and the link matrix it made or the helper made for it (``GreedyPass``): with two workers the
    second process makes matrices only (``matrix_helper``), so the answers are one worker's and
    every group comes to the exact solve with its bound and matrix. A group greedy had no time for
    keeps the matrix the helper made for it, if any."""
    built: list = []
    planned: list = []
    sol = solve(problem, "greedy", time_limit_s=time_limit_s, budget_s=budget_s, workers=workers,
                progress=progress, built_groups=built, planned=planned)
    answers, matrices, handed = [], [], set()
    for g, (grp, from_helper, priced_on, gs) in enumerate(built):
        # greedy's answer with the start and end costs of the group its bound is for
        # (``GreedyAnswer.for_group`` shifts the bound from those): the chain may print a path
        # settled for another start or end (``settle``). Seen: a group settled to the next
        # group's entry, its bound (1,676 ms, the travel on included) shifted as if from the
        # free end -> "optimal" at 939.28 ms where the DP's optimum was 936.20
        # (plate__cura_ender3 free, the proof audit)
        fixed = problem.group_fixed[g] or grp.n_curves == 0
        answers.append(None if fixed else greedy_answer(priced_on, gs))
        c = grp.costs
        arc = None if fixed or c is None or getattr(c, "euclidean", False) else c.arc
        matrices.append(arc)
        if from_helper and arc is not None:
            handed.add(g)
    return GreedyPass(sol, tuple(answers), tuple(matrices), frozenset(handed), tuple(planned))


def solve(problem: OrderingProblem, formulation: str = "auto", *, time_limit_s: float = 2.0,
          budget_s: float | None = None, workers: int = 1, progress=None,
          greedy: GreedyPass | None = None, built_groups: list | None = None,
          planned: list | None = None, **kwargs) -> OrderingSolution:
    """Order every group; ``time_limit_s`` is per group (exact formulations only); ``budget_s``
    caps the whole solve: each group gets at most its share of what is left (groups the DP or the
    bound settle take next to nothing). ``workers = 2``: a second process solves the chain from the
    back (``helper.Helper``) until it meets the main process. ``progress``: called as
    ``progress(groups_done, n_groups, groups_proven)`` after each group (the CLI draws a bar).
    A formulation whose answer must not depend on the workers (capability ``one_chain``:
    greedy) chains every group in this process; its second process makes link matrices only
    (``matrix_helper.MatrixHelper``), so two workers give one worker's paths, sooner.
    ``greedy``: a greedy pass of the same problem (``solve_greedy``): each group starts from its
    link matrix and greedy's path (the warm start), and a group the budget leaves no time for
    keeps greedy's path instead of the slicer's order (``runner.OUT_OF_TIME_GREEDY``), in the
    helper process too. ``built_groups``: a list each group's (Group as planned, matrix from the
    helper?, the Group an answer's cost and bound are for, that answer) is appended to
    (``solve_greedy``); ``planned``: a list each group's (Group as planned, start, end) is
    appended to (``GreedyPass.planned``). With ``greedy``, a group that starts and ends where
    greedy's chain planned it is that very Group (``GreedyPass.planned_at``), not built again."""
    record = formulations.lookup(formulation)
    if workers not in (1, 2):
        raise OrderingOptionsError(f"workers must be 1 or 2, not {workers!r}")
    t0 = time.perf_counter()
    # the formulation's module and its backend are imported on first use, here: inside the budget,
    # as a whole-run budget counted them when every backend came with the package (measured on a
    # busy 2-core machine: auto with HiGHS 1.5 s, cpsat with OR-Tools 1.8 s)
    fn = record.load().solve
    n = problem.n_curves
    order_out = []
    reversed_ = np.zeros(n, bool)
    seam = np.zeros(n, np.int64)
    sols = []
    pos = Anchor.of(problem.origin_xy)
    plans = []      # per group: (Group, options: the solver's path, the slicer's..., start, end)
    proven = 0      # re-orderable groups proven so far (for ``progress``)
    reorderable = problem.group_reorderable
    answers = greedy.answers if greedy is not None else None
    one_chain = "one_chain" in record.capabilities
    helper = (Helper.start(problem, formulation, time_limit_s, budget_s, t0, kwargs, answers)
              if workers == 2 and not one_chain else None)
    maker = MatrixHelper.start(problem) if workers == 2 and one_chain else None
    try:
        if one_chain:
            # the greedy chain: its budget in work, not wall-clock (``runner.WorkRunner``): the
            # same groups searched the same way on every run, with one worker or two (the
            # matrix helper's matrices are charged as if made here)
            runner = WorkRunner(problem, fn, time_limit_s, budget_s, t0, kwargs)
        else:
            other_alive = (lambda: not helper.dead) if helper else None
            runner = GroupRunner(problem, fn, time_limit_s, budget_s, t0, kwargs,
                                 shared=helper.shared if helper else None,
                                 other_alive=other_alive,
                                 warm_up=(formulations.warm_up if "warm_up" in record.capabilities
                                          else None),
                                 matrices_made=greedy is not None)
        for g in range(problem.n_groups):
            if stop_requested():        # Ctrl-C (``solvers.stop_scope``): no whole answer yet
                raise Interrupted(f"curve ordering stopped at group {g} of {problem.n_groups}")
            end = end_of(problem, g)
            if end is None and helper:
                end = helper.entry_of(g + 1)    # the next group's path, if the helper has it
            grp = greedy.planned_at(g, pos, end) if greedy is not None else None
            if grp is None:
                grp = problem.group(g, pos, end)
                if greedy is not None:
                    grp = greedy.with_matrix(g, grp)
            handed = False
            if maker is not None and not problem.group_fixed[g] and grp.n_curves >= 2:
                mine = with_arc(grp, maker.take(g))
                handed, grp = mine is not grp, mine
            if problem.group_fixed[g] or grp.n_curves == 0:
                order = np.arange(grp.n_cands)      # one candidate per curve, in the slicer's order
                obj = grp.path_cost(order)
                opts = [GroupSolution.make(order, obj, obj, Status.OPTIMAL, 0.0, "fixed")]
            else:
                answer = helper.take(g) if helper else None
                if answer is None:
                    gs = (runner.run(g, grp) if one_chain else
                          runner.run(g, grp, answers[g] if answers is not None else None))
                    grp.check_order(gs.order)
                    opts = path_options(grp, gs)
                else:
                    opts, guess = answer
                    if guess is not None:
                        opts = rescored(problem, g, grp, opts, guess)
                    for gs in opts:
                        grp.check_order(gs.order)
            plans.append((grp, opts, pos, end))
            if planned is not None:
                planned.append((grp, pos, end))
            if built_groups is not None:
                built_groups.append((grp, handed, opts))
            runner.passed(g)
            if progress is not None:
                proven += bool(reorderable[g]) and opts[0].status == Status.OPTIMAL
                progress(g + 1, problem.n_groups, proven)
            pos = problem.exit_anchor(g, grp, opts[0].order) if grp.n_curves else pos
    finally:
        if helper:
            helper.stop()
        if maker:
            maker.stop()
    if "look_ahead" in record.capabilities:      # the baselines chain as the paper does
        deadline = None if budget_s is None else t0 + budget_s - runner.rest_s(problem.n_groups - 1)
        look_ahead(problem, plans, fn, time_limit_s, deadline, kwargs)
    choice = pick_paths(problem, plans)
    picked = [opts[choice[g]] for g, (_, opts, _, _) in enumerate(plans)]
    # each group made right where the chain prints it (proven for its printed start and end)
    priced = [None] * len(plans)
    picked = settle_chain(problem, plans, picked, priced)
    if built_groups is not None:
        # per group the answer printed and the group its cost and bound are for: the group as
        # planned for an option made on it, the start and end it was settled for, else the
        # solver's own answer on the group as planned (``solve_greedy``)
        for g, (grp, handed, opts) in enumerate(built_groups):
            if any(picked[g] is o for o in opts) and not any(
                    t in picked[g].formulation for t in (BACKWARDS, LOOKAHEAD_FROM, LOOKAHEAD_TO)):
                built_groups[g] = (grp, handed, grp, picked[g])
            elif priced[g] is not None:
                built_groups[g] = (grp, handed, problem.group(g, *priced[g]), picked[g])
            else:
                built_groups[g] = (grp, handed, grp, opts[0])
    for g, (grp, _, _, _) in enumerate(plans):
        gs = picked[g]
        curves = problem.group_curves(g)
        for k in gs.order:
            c = int(curves[grp.cand_curve[k]])
            order_out.append(c)
            reversed_[c] = bool(grp.cand_reversed[k])
            seam[c] = int(grp.cand_seam[k])
        sols.append(gs)
    order_out = np.asarray(order_out, np.int64)
    if problem.curve_source is not None:
        # a problem whose curves were permuted (safe mode's blocks): the solution in the
        # program's numbering, as emit and the time guard read it
        src = problem.curve_source
        order_out = src[order_out]
        reversed_[src], seam[src] = reversed_.copy(), seam.copy()
    base = problem.program_problem
    ident = np.arange(n)
    no = np.zeros(n, bool)
    return OrderingSolution(order_out, reversed_, seam, tuple(sols), base.original_travel_mm(),
                            model_travel_mm(base, order_out, reversed_, seam),
                            time.perf_counter() - t0, formulation,
                            cost_before=base.order_cost(ident, no, np.zeros(n, np.int64)),
                            cost_after=base.order_cost(order_out, reversed_, seam),
                            cost_unit=problem.cost_unit,
                            work_net_fired=one_chain and runner.net_fired)


def model_travel_mm(problem: OrderingProblem, order, reversed_, seam) -> float:
    """Model travel of a full solution (start of each curve from the end of the one before)."""
    a, b = problem.entry_exit_xy(order, reversed_, seam)
    return path_travel_mm(problem.origin_xy, a, b)
