"""The time guard's repair pass (formulations/ordering.md, "Time guard", "Repair"): the groups of
a layer the guard put back, solved again on link costs that agree with the planner.

The solver's costs (``cost.TimePricer``) leave some of the planner out by default: under Marlin's
classic jerk a rebuilt link is priced without its junctions with the curves' own moves
(``cost.joins``: joined there, a link and its mirror differ, and the symmetric model that proves
most groups relaxes each pair to its cheaper direction). Where that difference decides a layer,
an order proven optimal on the default costs prints slower under the planner and the time guard
puts the slicer's order back (a "proven group reverted": 36 of the 43 on the corpus lay in
prusa25_bunny_triangles15_lh01). Such layers are few, so paying the joined prices there only
costs little: ``planner_priced`` is the problem with every link joined
(``OrderingOptions.joined_links="all"``), ``resolve_layers`` solves the groups of the layers
given on it, each group from where the printed file's group before it ends. The guard then
measures the answer against what it printed (``rewrite.guard.emit_guarded(repair=...)``); each
group's status is its status on the joined costs.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..program import Program
from ..solvers import Status
from .chain import anchor_before, end_of, path_options
from .cost import TimePricer
from .problem import GroupSolution, OrderingProblem, OrderingSolution

#: the formulation suffix of a group solved again by the repair pass (its status is its status on
#: the joined costs)
REPAIRED = "+joined"


def planner_priced(program: Program, problem: OrderingProblem) -> OrderingProblem | None:
    """``problem`` with its links joined to the curves' moves under every junction rule
    (``cost.TimePricer`` with ``joined_links="all"``: under Marlin's classic jerk the prices that
    agree with the planner, a rebuilt link planned with the curves' boundary moves,
    tests/test_ordering_cost_jerk.py; a permuted problem, safe mode's blocks, keeps its
    permutation and its base gets the same pricer). None where that prices every link as
    ``problem`` does (not the time objective, links joined already, no plan)."""
    base = problem.program_problem
    pricer = base.pricer
    if not isinstance(pricer, TimePricer):
        return None
    opts = dataclasses.replace(problem.options, joined_links="all")
    base_all = dataclasses.replace(base, options=opts)
    if pricer.joined or pricer.step_plan is None or pricer.move.junction_code < 0:
        return None
    # made from what the default pricer was made of (rule, limits, the program's plan, the
    # curves' ends): only the links' join policy differs
    joined = TimePricer(program, base.layout, base_all, pricer.rule, pricer.move,
                        pricer.step_plan.duration_s, pricer.limits, pricer.step_plan, pricer.ends)
    if not joined.joined:
        return None
    base_all = dataclasses.replace(base_all, pricer=joined)
    if problem.base is None:
        return base_all
    return dataclasses.replace(problem, options=opts, pricer=joined, base=base_all)


def can_repair(problem: OrderingProblem) -> bool:
    """Whether ``planner_priced`` would give ``problem`` other link costs (without making them):
    the time objective's links are planned, but not joined to the curves' moves (classic jerk
    under the default ``joined_links``)."""
    pricer = problem.program_problem.pricer
    return (pricer is not None and not getattr(pricer, "joined", True)
            and getattr(pricer, "step_plan", None) is not None and pricer.move.junction_code >= 0)


def _layer_positions(problem: OrderingProblem, order: np.ndarray, layer: int) -> np.ndarray:
    """Positions of ``order`` (program curves) that hold the curves of ``layer``: one contiguous
    block (``guard.mix_layers``)."""
    return np.flatnonzero(problem.program_problem.curve_layer[order] == layer)


def resolve_layers(problem: OrderingProblem, printed: OrderingSolution, layers, fn, *,
                   time_limit_s: float = 2.0, deadline_s: float | None = None,
                   kwargs: dict | None = None) -> OrderingSolution:
    """``printed`` with the groups of ``layers`` solved again on ``problem``'s costs (``fn``: a
    formulation's ``solve``), layer by layer: the first group of a layer from where ``printed``
    leaves the curve before the layer, each next from where the one before now ends, a group's
    end where the next group is fixed (``chain.end_of``); of the solver's path and the slicer's
    order the cheaper (``chain.path_options``). ``deadline_s`` (a ``time.perf_counter()``
    reading): each group gets at most an even share of what is left before it (a group reached
    with nothing left keeps its printed order). The groups' answers carry ``REPAIRED``."""
    kwargs = kwargs or {}
    order = np.asarray(printed.curve_order, np.int64).copy()
    rev = np.asarray(printed.curve_reversed, bool).copy()
    seam = np.asarray(printed.curve_seam, np.int64).copy()
    groups = list(printed.groups)
    src = problem.curve_source
    layers = sorted({int(x) for x in np.asarray(layers, np.int64).tolist()})
    left_groups = int(np.count_nonzero(np.isin(problem.group_layer, layers)
                                       & problem.group_reorderable))
    for lay_i in layers:
        posn = _layer_positions(problem, order, lay_i)
        if not len(posn):
            continue
        first = int(posn[0])
        pos = anchor_before(problem, printed, first)
        new_order, layer_groups = [], {}
        g_all = np.flatnonzero(np.asarray(problem.group_layer) == lay_i)
        for g in g_all.tolist():
            grp = problem.group(g, pos, end_of(problem, g))
            if problem.group_fixed[g] or grp.n_curves < 2:
                path = np.arange(grp.n_cands) if problem.group_fixed[g] else None
                if path is None:
                    # one curve: the cheaper of its candidates (its other end, a loop's seam)
                    costs = [grp.path_cost(np.array([k])) for k in range(grp.n_cands)]
                    path = np.array([int(np.argmin(costs))]) if grp.n_cands else np.zeros(0, np.int64)
            else:
                limit = time_limit_s
                if deadline_s is not None:
                    limit = min(limit, max(0.0, deadline_s - time.perf_counter()) / max(left_groups, 1))
                left_groups -= 1
                if limit <= 0.0:
                    path = None
                else:
                    gs = fn(grp, time_limit_s=limit, **kwargs)
                    grp.check_order(gs.order)
                    best = path_options(grp, gs)[0]
                    path = best.order
                    layer_groups[g] = GroupSolution.make(best.order, best.objective, best.bound,
                                                         best.status, best.solve_s,
                                                         best.formulation + REPAIRED)
                if path is None:
                    # no time: the layer keeps what was printed
                    new_order = None
                    break
            curves = problem.group_curves(g)
            for k in np.asarray(path, np.int64).tolist():
                c = int(curves[grp.cand_curve[k]])
                pc = int(src[c]) if src is not None else c
                new_order.append(pc)
                rev[pc] = bool(grp.cand_reversed[k])
                seam[pc] = int(grp.cand_seam[k])
            if grp.n_curves:
                pos = problem.exit_anchor(g, grp, path)
        if new_order is None or len(new_order) != len(posn):
            # (a layer left as printed: its curves' directions as printed, too)
            keep = np.asarray(printed.curve_order, np.int64)[posn]
            rev[keep] = np.asarray(printed.curve_reversed, bool)[keep]
            seam[keep] = np.asarray(printed.curve_seam, np.int64)[keep]
            continue
        order[posn] = new_order
        for g, gs in layer_groups.items():
            groups[g] = gs
    return dataclasses.replace(printed, curve_order=order, curve_reversed=rev, curve_seam=seam,
                               groups=tuple(groups))


def repaired_status_counts(solution: OrderingSolution, problem: OrderingProblem) -> dict:
    """Of the re-orderable groups solved again by the repair pass: how many, how many proven."""
    reorderable = problem.group_reorderable
    rep = [gs for g, gs in enumerate(solution.groups)
           if reorderable[g] and gs.formulation.endswith(REPAIRED)]
    return {"groups": len(rep), "optimal": sum(gs.status == Status.OPTIMAL for gs in rep)}
