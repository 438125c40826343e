"""The curve ordering's whole job: build -> solve within a budget -> emit with the time guard ->
re-parse -> verify -> report (``order_program``; ``reorder`` stops before the verification, which
``rewrite.pipeline.run`` does on the gated output).

Travel and print time in the report are the figures every report gives (``rewrite.figures``:
travel measured on the two parsed files, print time under the planner model); the solver's own
model travel is there too, as ``model_travel_*_mm``.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from .. import _jit
from ..ordering import formulations
from ..ordering.groups import build
from ..ordering.layers import solve, solve_greedy
from ..ordering.problem import OrderingOptions, OrderingProblem, OrderingSolution
from ..ordering.repair import can_repair, planner_priced, repaired_status_counts, resolve_layers
from ..ordering.budget import OVERHEAD_S_PER_CURVE, OVERHEAD_S_PER_GROUP, TAIL_S_PER_CURVE
from ..ordering.runner import OUT_OF_TIME, OUT_OF_TIME_GREEDY
from ..ordering.travel_stats import runs, travel_mask
from ..program import Program
from ..solvers import stop_requested
from ..verify.ordering import check
from .figures import figure_notes, figures
from .guard import (FROM_GREEDY, FROM_SOLVER, GUARD_TOL_S, emit_guarded,  # noqa: F401 (re-exported)
                    greedy_taken, keep_layers, layer_times_s, same_entry_groups, same_next_entries,
                    step_times_s)


@dataclass(frozen=True, eq=False)
class OrderResult:
    """A verified re-ordering (``order_program``): nothing is written to disk here."""

    program: Program
    problem: OrderingProblem
    solution: OrderingSolution
    text: str
    output: Program
    findings: tuple
    summary: dict

    @property
    def ok(self) -> bool:
        return not self.findings


def out_of_time_groups(problem: OrderingProblem, solution: OrderingSolution) -> int:
    """Re-orderable groups the budget left no time for (``runner.OUT_OF_TIME``: the slicer's
    order, unsearched)."""
    reorderable = problem.group_reorderable
    return sum(bool(reorderable[g]) and gs.formulation.startswith(OUT_OF_TIME)
               for g, gs in enumerate(solution.groups))


def greedy_out_of_time_groups(problem: OrderingProblem, solution: OrderingSolution) -> int:
    """Re-orderable groups the budget left no time to search exactly that keep the greedy pass's
    path (``runner.OUT_OF_TIME_GREEDY``)."""
    reorderable = problem.group_reorderable
    return sum(bool(reorderable[g]) and gs.formulation.startswith(OUT_OF_TIME_GREEDY)
               for g, gs in enumerate(solution.groups))


def greedy_out_of_time_note(n_groups: int, n_decided: int) -> str:
    """The report's line for groups that keep greedy's path, unproven, for want of time."""
    return (f"curve ordering: {n_groups:,} of {n_decided:,} re-orderable groups keep the greedy "
            f"path, not searched exactly for want of time (a larger --budget searches them)")


def out_of_time_note(n_groups: int, n_decided: int, solve_budget_s) -> str:
    """The report's line for groups the budget left no time for (``out_of_time_groups``)."""
    of = f" of the {solve_budget_s:.2f} s the budget left the solve" if solve_budget_s else ""
    return (f"curve ordering ran out of time{of}: {n_groups:,} of {n_decided:,} re-orderable groups "
            f"keep the slicer's order unsearched (status fallback; a larger --budget searches them)")


#: the report's line where the greedy chain's wall-clock safety net fired
WORK_NET_NOTE = ("curve ordering: this machine ran the greedy pass far slower than its work budget "
                 "plans (the wall-clock safety net fired): groups after that point keep the "
                 "slicer's order, and another run may order a different number of them")


def kept_slower_note(n_layers: int) -> str:
    """The report's line for layers the time guard put back (``emit_guarded``)."""
    return (f"{n_layers} layers keep the slicer's order: re-ordered they took longer under the "
            "planner model (the time guard)")


#: seconds per input line that the work after the solve takes (emit with the time guard's passes,
#: re-parse, verify, the report's travel totals). Measured on the 39 corpus files after budgeted
#: two-process solves (10 s, both modes; the guard's passes re-emit only the layers they change):
#: 7.6-14.4 us per line, build included (most: real_ideamaker420 free 14.4, the Cura bunny safe,
#: 204 k lines, absolute E, 13.5). At 15 us every file's whole run ended within 9.12 s of a 10 s
#: budget (cura413_xend_zigzag100 free; the bunny 8.97-9.12 s over four runs). Before the guard
#: was memoised the bunny took 17.3-19.8 us and a run at 16-17 us reached 10.06 s; the emit alone
#: varies by ~+-25 % between runs on this shared machine, hence the margin. The rest of a small
#: file is a few tenths of a second whatever its rate. Then 15 us; since the verifier sorts by one
#: key, the report reuses the guard's planner runs and the emit copies lines from per-program
#: lists (bench/after_solve.py), the same runs' work after the solve takes 0.62-0.79 of its CPU
#: time (budget 10, workers 1, same machine and hour, CPU us per line before -> after:
#: cura413_xend_zigzag100 free, 7 emits, 25.5 -> 19.7; the bunny safe 7.8 -> 6.0, free 15.4 ->
#: 9.6; prusa25_xend_honey25_acp free 12.5 -> 9.9; real_ideamaker420 free 39 -> 28), so 0.8 x 15
#: = 12 us. Since the emit copies runs of unchanged curves as runs of lines and writes re-ordered
#: curves' numbers per layer at once (``ordering.writer``, the same text byte for byte), the
#: guard (its emits, parses, planner runs) takes 0.73-0.86 of its CPU time and the work after the
#: solve 0.76-0.91 with the verifier's time taken as before (bench/after_solve.py, the bunny and
#: cura413_xend_zigzag100, both modes, load ~2.5 on 2 cores): 11 us would follow. Kept at 12: the
#: whole-run check at that load (bench/ordering_as_printed.py, the bunny, auto, 2 workers) ended
#: 10.5-11.5 s with 12 us as with 11 us, the solve itself 0.3-1.9 s past its budget; lower it
#: after a quiet-machine run of every corpus file ends within the budget
FINISH_S_PER_LINE = 12e-6
#: and per file, whatever its size (imports on first use, the report)
FINISH_FIXED_S = 0.15
#: building the ordering problem (``ordering.groups.build``), per input line: ``reorder`` measures
#: it, ``stage_floor_s`` estimates it before (the Cura bunny: 1.28 s for 204,404 lines, quiet)
BUILD_S_PER_LINE = 7e-6
#: reading the file (``parse``), per input line, as the greedy chain's work budget counts it
#: (``greedy_work_budget_s``): the Cura bunny (gzip, 204,404 lines) 0.45 s CPU
READ_S_PER_LINE = 2.5e-6


def greedy_work_budget_s(budget_s: float | None, n_lines: int, read: bool = False) -> float | None:
    """The greedy chain's budget in work (deterministic seconds, ``ordering.runner.WorkRunner``):
    ``solve_budget_s`` with the build (and, ``read``, the file's reading) counted at their quiet
    rates per line instead of as measured, and the work after the solve at its quiet rate: from the
    budget and the file's size alone, so the greedy pass orders the same groups the same way on
    every run (issue 36). None (no budget) stays None."""
    if budget_s is None:
        return None
    spent = (BUILD_S_PER_LINE + (READ_S_PER_LINE if read else 0.0)) * n_lines
    return solve_budget_s(budget_s, n_lines, spent, 1.0)


def solve_budget_s(budget_s: float | None, n_lines: int, spent_s: float,
                   slow: float = 1.0) -> float | None:
    """What a budget for the whole run leaves the solve: ``budget_s`` less what is spent
    (``spent_s``: parse, build) and an estimate of what is to come after the solve
    (``FINISH_S_PER_LINE`` per line of the file, ``FINISH_FIXED_S``, at ``slow`` times those
    quiet rates: ``rewrite.budget.slowdown_factor``), never below 0: with nothing left every
    group keeps the slicer's order (``runner.OUT_OF_TIME``). (It once kept a quarter of the
    budget however little was left: a late answer by design.) None (no budget) stays None."""
    if budget_s is None:
        return None
    left = budget_s - spent_s - slow * (FINISH_FIXED_S + FINISH_S_PER_LINE * n_lines)
    return max(0.0, left)


def stage_floor_s(program: Program, slow: float = 1.0) -> float:
    """What the ordering stage takes with no time to search at all: building the problem, passing
    every group (``runner.GroupRunner``'s priors per curve, the curves estimated by the file's
    travels: one per curve on the corpus, 67,775 for the Cura bunny's 67,356 curves) and the
    emit; building and passing at ``slow`` times their quiet rates (``budget.slowdown_factor``).
    A whole-run budget that leaves the ordering less keeps the slicer's order without building
    anything (``rewrite.pipeline.run``)."""
    curves = runs(travel_mask(program), program)
    return (slow * (BUILD_S_PER_LINE * program.n_lines
                    + (OVERHEAD_S_PER_CURVE + TAIL_S_PER_CURVE) * curves)
            + FINISH_FIXED_S + FINISH_S_PER_LINE * program.n_lines)


class NoTimeToOrder(Exception):
    """The solve's budget, once the problem is built, would not pay for passing its groups
    (``reorder`` with ``slow``): searching nothing, the solve and its emit would still end the
    run late."""

    def __init__(self, solve_budget_s: float, pass_s: float, n_groups: int):
        super().__init__(f"the {solve_budget_s:.2f} s the budget left the solve would not pay for "
                         f"passing its {n_groups:,} groups ({pass_s:.2f} s)")
        self.solve_budget_s, self.pass_s, self.n_groups = solve_budget_s, pass_s, n_groups


#: seconds per input line of the time guard's second stage (the exact answer against the greedy
#: stage's file: its emits and planner runs), which only a run with a greedy stage pays and the
#: finish estimate (``FINISH_S_PER_LINE``, measured with one stage) does not hold: 5.1 us on
#: real_cura591 (44,755 lines: 0.14 s one stage, 0.36 s two), quiet machine; then 6 us, lowered
#: by the ratio ``FINISH_S_PER_LINE`` was (its emits, parses and planner runs are the same work;
#: after the faster emit the guard's ratio is at most 0.86 -- 4.3 us -- kept at 5 as that is)
GUARD_STAGE_S_PER_LINE = 5e-6


#: seconds per input line of what follows the time guard in ``order_program`` (the
#: verification, the report's figures): the repair pass leaves that much of the budget.
#: Measured on prusa25_bunny_triangles15_lh01 safe (259,028 lines), load ~4 on the 2 cores:
#: 0.755 s wall (2.9 us a line), 0.51 s CPU
AFTER_GUARD_S_PER_LINE = 3e-6
#: seconds per input line of the repair pass, besides its groups' solves: the joined pricer
#: (``repair.planner_priced``, the whole file: 0.05-0.12 s CPU on the bunnies, 0.19-0.56 us a
#: line) and its stage's two emits at most (``guard._repair_stage``; with the guard's memo only
#: the changed layers are written again: emit, parse and plan 0.145 s, 0.56 us a line, on
#: prusa25_bunny_triangles15_lh01), plus what a group solve needs at least
#: (``REPAIR_FIXED_S``). Where the repair can change costs (``repair.can_repair``: classic
#: jerk), the exact solve's budget keeps it back
REPAIR_S_PER_LINE = 2.5e-6
REPAIR_FIXED_S = 0.05
#: past the budget's end the repair pass's solves still get this much per group (s): the subset
#: DP takes the groups it is made for in milliseconds (lh01's 39 in ~0.1 s)
REPAIR_MIN_S_PER_GROUP = 0.05


def _repair_deadline(t0: float, budget_s: float | None, program: Program,
                     finish_slow: float) -> float | None:
    """What the budget leaves the repair pass (a ``time.perf_counter()`` reading; None: no
    budget): up to the end of the budget less the work after the guard (compiling kernels
    counts no time, as in ``reorder``)."""
    if budget_s is None:
        return None
    return (t0 + budget_s + _jit.compile_s_since(t0)
            - finish_slow * (FINISH_FIXED_S + AFTER_GUARD_S_PER_LINE * program.n_lines))


def repair_pass(program: Program, problem: OrderingProblem, formulation: str, *,
                time_limit_s: float = 2.0, deadline_s: float | None = None, slow: float = 1.0):
    """The time guard's repair pass (``guard.emit_guarded(repair=...)``; formulations/ordering.md,
    "Time guard"): the layers the guard put back although a group in them was proven optimal
    solved again with ``formulation`` on link costs that agree with the planner
    (``repair.planner_priced``: joined to the curves' moves under classic jerk too). The groups'
    solves get what ``deadline_s`` (a ``time.perf_counter()`` reading, None: none) leaves less the
    stage (two emits at most, ``REPAIR_S_PER_LINE`` at ``slow`` times its quiet rate), and at
    least ``REPAIR_MIN_S_PER_GROUP`` each: the pass runs past the budget's end too (issue 36: a
    proof the planner disagrees with is made again on the planner's costs, not printed as the
    model's; a run that pays for it says so in its wall time). Its work is bounded by the layers
    it concerns: the few the guard put back although a group in them was proven."""
    fn = formulations.group_solver(formulation)

    def repair(printed: OrderingSolution, layers):
        joined = planner_priced(program, problem)
        if joined is None:
            return None
        deadline = None
        if deadline_s is not None:
            stage_s = slow * 0.5 * REPAIR_S_PER_LINE * program.n_lines
            n_groups = int(np.count_nonzero(np.isin(problem.group_layer, np.asarray(layers))
                                            & problem.group_reorderable))
            deadline = max(deadline_s - stage_s,
                           time.perf_counter() + REPAIR_MIN_S_PER_GROUP * n_groups)
        return resolve_layers(joined, printed, layers, fn, time_limit_s=time_limit_s,
                              deadline_s=deadline)
    return repair


def reorder(program: Program, options: OrderingOptions | None = None, *,
            formulation: str = "auto", time_limit_s: float = 2.0,
            budget_s: float | None = None, workers: int = 1, time_guard: bool = True,
            progress=None, started_s: float | None = None, slow: float | None = None,
            finish_slow: float = 1.0, work_budget_s: float | None = None):
    """build -> [greedy] -> solve with what ``budget_s`` leaves (``solve_budget_s``, counted from
    ``started_s``, default now) -> ``emit_guarded``, without verifying (``order_program`` does;
    ``rewrite.pipeline.run`` verifies its own output). Returns (problem, the solve's budget,
    ``guard.Guarded``: the solution emitted, its text and parsed file, the layers put back, where
    each layer's order comes from). ``slow`` (``budget.slowdown_factor``; None: never): raise
    ``NoTimeToOrder`` after the build where the solve's budget would not pay for passing the
    groups at ``slow`` times the runner's priors (every group would keep the slicer's order, late).
    ``finish_slow``: the work after the solve (emit, re-parse, verify) is estimated at that many
    times its quiet rates (``order_program`` measures it). ``work_budget_s``: the greedy chain's
    budget in work (``greedy_work_budget_s``; default: from ``budget_s`` and the file's lines, the
    reading not counted): the greedy formulation, and an exact run's greedy pass, spend that, not
    wall-clock seconds.

    With an exact formulation and the time guard (issue 36: never slower than greedy), greedy
    orders every group first (``layers.solve_greedy``: the answer ``--formulation greedy`` gives,
    as far as the budget pays for it), with all of the solve's budget; the exact solve then gets
    what greedy left less the guard's second stage (``GUARD_STAGE_S_PER_LINE``), starts each group from greedy's link
    matrix and path, and a group it has no time for keeps greedy's path
    (``runner.OUT_OF_TIME_GREEDY``), not the slicer's order. The guard prints per layer the
    slicer's, the greedy or the exact order, whichever the planner model says is faster; its
    first stage is the greedy run's own guard. Where what greedy left would not pay for passing
    the groups again, the exact solve does not run: greedy's answer is printed, its groups at
    best "feasible" (``guard.GREEDY_TAKEN``).

    The guard then runs its repair pass (``repair_pass``): the layers it put back although a
    group in them was proven optimal are solved again on the joined link costs (classic jerk),
    within what the budget leaves before the work after the guard (``AFTER_GUARD_S_PER_LINE``);
    where that pass can change the costs, the exact solve keeps its cost back
    (``REPAIR_S_PER_LINE``, ``REPAIR_FIXED_S``)."""
    t0 = time.perf_counter() if started_s is None else started_s
    problem = build(program, options or OrderingOptions())
    # compiling numba kernels (a first run) is not the run's to budget: it counts no time
    spent = time.perf_counter() - t0 - _jit.compile_s_since(t0)
    solve_budget = solve_budget_s(budget_s, program.n_lines, spent, finish_slow)
    # what passing every group takes with no time to search them (the runner's priors)
    pass_s = (slow or 1.0) * ((OVERHEAD_S_PER_CURVE + TAIL_S_PER_CURVE) * problem.n_curves
                              + OVERHEAD_S_PER_GROUP * problem.n_groups)
    if slow is not None and solve_budget is not None:
        if solve_budget < pass_s:
            raise NoTimeToOrder(solve_budget, pass_s, problem.n_groups)
    if work_budget_s is None:
        work_budget_s = greedy_work_budget_s(budget_s, program.n_lines)
    greedy = None
    exact_budget = solve_budget
    if "one_chain" in formulations.lookup(formulation).capabilities:
        exact_budget = work_budget_s            # greedy: its budget is work (module docstring)
    if time_guard and "exact" in formulations.lookup(formulation).capabilities:
        # the whole budget: greedy's answer in every group comes first (what a budget that
        # greedy uses up prints is then the greedy run's file, through one guard stage)
        t_g = time.perf_counter()
        greedy = solve_greedy(problem, time_limit_s=time_limit_s, budget_s=work_budget_s,
                              workers=workers)
        if solve_budget is not None:
            # what greedy left, less the guard's second stage (the exact answer against greedy's
            # file) that an exact solve adds after it
            stage_s = finish_slow * GUARD_STAGE_S_PER_LINE * program.n_lines
            if can_repair(problem):
                # and the repair pass, where it can change the costs (``repair_pass``)
                stage_s += finish_slow * (REPAIR_FIXED_S + REPAIR_S_PER_LINE * program.n_lines)
            exact_budget = max(0.0, solve_budget - (time.perf_counter() - t_g
                                                    - _jit.compile_s_since(t_g)) - stage_s)
    if greedy is not None and (stop_requested() or (exact_budget is not None
                                                    and exact_budget < pass_s)):
        # no time left to pass the groups again (or a Ctrl-C): greedy's answer is the solve's,
        # its proofs the planner disagrees with repaired as an exact solve's are
        repair = None if stop_requested() else repair_pass(
            program, problem, formulation, time_limit_s=time_limit_s,
            deadline_s=_repair_deadline(t0, budget_s, program, finish_slow), slow=finish_slow)
        guarded = emit_guarded(program, problem, greedy.solution, time_guard, repair=repair)
        decided = problem.group_reorderable
        # greedy's answers as printed (``emit_guarded``: its proofs stand in the groups entered
        # as its chain entered them, elsewhere made again from where the file enters them,
        # ``guard.printed_answer``), labelled as taken by the guard where entered otherwise
        same = ((guarded.source == FROM_SOLVER)[np.asarray(problem.group_layer, np.int64)]
                & same_entry_groups(problem, guarded.solution, greedy.solution)
                & same_next_entries(problem, guarded.solution, greedy.solution))
        groups = tuple(greedy_taken(gs) if d and not s else gs
                       for gs, d, s in zip(guarded.solution.groups, decided, same))
        sol = dataclasses.replace(guarded.solution, groups=groups, formulation=formulation,
                                  work_net_fired=greedy.solution.work_net_fired)
        source = np.where(guarded.source == FROM_SOLVER, FROM_GREEDY, guarded.source)
        return problem, solve_budget, dataclasses.replace(guarded, solution=sol, source=source)
    solution = solve(problem, formulation, time_limit_s=time_limit_s, budget_s=exact_budget,
                     workers=workers, progress=progress, greedy=greedy)
    if greedy is not None:
        solution = dataclasses.replace(solution, solve_s=solution.solve_s + greedy.solution.solve_s,
                                       work_net_fired=greedy.solution.work_net_fired)
    repair = (repair_pass(program, problem, formulation, time_limit_s=time_limit_s,
                          deadline_s=_repair_deadline(t0, budget_s, program, finish_slow),
                          slow=finish_slow) if time_guard else None)
    guarded = emit_guarded(program, problem, solution, time_guard,
                           greedy=None if greedy is None else greedy.solution, repair=repair)
    return problem, solve_budget, guarded


def order_program(program: Program, options: OrderingOptions | None = None, *,
                  formulation: str = "auto", time_limit_s: float = 2.0,
                  budget_s: float | None = None, workers: int = 1,
                  time_guard: bool = True, progress=None,
                  started_s: float | None = None, slow: float = 1.0) -> OrderResult:
    """Re-order ``program``'s curves and verify the result (see module docstring).
    ``budget_s``: about how long the whole run may take, from ``started_s`` (a
    ``time.perf_counter()`` reading, e.g. taken before the file was parsed; default: now) to the
    verified result; the solve gets what ``solve_budget_s`` leaves it.
    ``time_guard``: a layer whose re-ordered print takes longer than the slicer's (planner
    model) keeps the slicer's order.
    ``progress``: passed to ``ordering.layers.solve`` (called after each group).
    ``slow``: under a budget the work after the solve is estimated at that many times its quiet
    rates: the wall / CPU seconds the machine gave the run so far (``rewrite.budget.
    slowdown_factor``, as ``gatesopt solve`` measures it; ``cli.order`` passes it). A budget too
    short for searching keeps every group's order unsearched (``runner.OUT_OF_TIME``): passing
    them costs ~9 us per curve (the Cura bunny's 67,356: 0.61 s CPU)."""
    program.check_rewritable()
    # the greedy chain's budget in work: with ``started_s`` the budget counts the file's reading
    # too (at its quiet rate per line: never as measured, the same on every run)
    work_budget = greedy_work_budget_s(budget_s, program.n_lines, read=started_s is not None)
    t0 = time.perf_counter() if started_s is None else started_s
    options = options or OrderingOptions()
    problem, solve_budget, guarded = reorder(
        program, options, formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
        workers=workers, time_guard=time_guard, progress=progress, started_s=t0,
        finish_slow=slow, work_budget_s=work_budget)
    solution, text, out, slower_layers = guarded
    findings = tuple(check(program, out, problem.program_problem.layout))
    summary = order_summary(program, out, problem, solution, options, slower_layers, findings,
                            formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
                            solve_budget_s=solve_budget, workers=workers,
                            wall_s=time.perf_counter() - t0, greedy_layers=guarded.greedy_layers,
                            planned_s=guarded.planned_s, repaired=guarded.repaired,
                            proofs_put_back=guarded.proofs_put_back)
    return OrderResult(program, problem, solution, text, out, findings, summary)


#: why a layer keeps the slicer's order (the report's per-layer ``kept_why``)
KEPT_SLOWER = "re-ordered it printed slower (planner model): kept by the time guard"
KEPT_NOTHING = "nothing to re-order (walls, ordered fills, one-curve groups keep their order)"
KEPT_BEST = "the slicer's order was the best found"


def _solve_counts(problem: OrderingProblem, solution: OrderingSolution, slower_layers):
    """(per-layer rows, group status counts, layer status counts, decided groups): how each group
    and layer was solved. A layer the time guard put back, or with nothing in it to re-order, is
    "kept"; each kept layer's row says why (``kept_why``), and every row whether its order, a
    curve's direction or a seam changed (``changed``)."""
    layers = solution.layer_summary(problem)
    put_back = set(slower_layers.tolist())
    lay = problem.layout
    order = np.asarray(solution.curve_order, np.int64)
    turned = np.asarray(solution.curve_reversed, bool) | (np.asarray(solution.curve_seam) != 0)
    moved = np.zeros(problem.n_curves, bool)
    moved[order] = order != np.arange(problem.n_curves)
    changed_layers = set(np.unique(problem.curve_layer[moved | turned]).tolist())
    for row in layers:
        row["changed"] = row["layer"] in changed_layers
        if row["layer"] in put_back:
            row["status"] = "kept"          # re-ordered it took longer: the slicer's order
            row["kept_why"] = KEPT_SLOWER
    reorderable = problem.group_reorderable
    decided = [(g, gs) for g, gs in enumerate(solution.groups) if reorderable[g]]
    counts = {"optimal": 0, "feasible": 0, "fallback": 0}
    for _, gs in decided:
        counts[gs.status if gs.status in counts else "fallback"] += 1
    lay_counts = {"optimal": 0, "feasible": 0, "fallback": 0, "kept": 0}
    decided_layers = {int(problem.group_layer[g]) for g, _ in decided}
    # a layer with a curve printed from its other end or another seam changed too, even with no
    # group of >= 2 curves (the counts above leave one-curve groups out; their choice is exact:
    # both ways compared). Fixed groups keep the slicer's direction, so this adds only those
    decided_layers.update(np.unique(problem.curve_layer[turned]).tolist())
    # and a layer whose islands moved as blocks (safe mode, ordering/blocks.py)
    decided_layers.update(np.unique(problem.curve_layer[moved]).tolist())
    for row in layers:
        if row["layer"] in decided_layers:
            lay_counts[row["status"] if row["status"] in lay_counts else "fallback"] += 1
            if row["status"] != "kept" and not row["changed"]:
                row["kept_why"] = KEPT_BEST
        else:
            # nothing in it to re-order (walls, monotonic fill, a kept first layer): the slicer's
            # order, as the counts say (its fixed groups are trivially "optimal" for the solver)
            row["status"] = "kept"
            lay_counts["kept"] += 1
            why = ""
            if lay is not None and row["layer"] < len(lay.layer_why) and lay.layer_keep[row["layer"]]:
                why = lay.layer_why[row["layer"]]
            row["kept_why"] = why or KEPT_NOTHING
    # layers with something decided in them: a group of >= 2 curves, islands moved as blocks, a
    # one-curve group turned, or a change the time guard put back (the layers "kept slower" are
    # counted among these: tall__prusa_mk3s reported 3 kept slower of 0 whose only change was a
    # curve's direction)
    lay_counts["reorderable"] = len(decided_layers | put_back)
    return layers, counts, lay_counts, decided


def put_back_note(n: int) -> str:
    """The report's line on proofs the planner disagreed with (``guard.put_back_answer``)."""
    return (f"{n:,} group{'s' if n != 1 else ''} proven optimal on the model's link costs "
            f"print{'s' if n == 1 else ''} the slicer's order: the planner found it faster, even "
            f"after the repair pass (reported with the path printed, not as proven)")


def _slower_notes(fig: dict | None, slower_layers) -> list[str]:
    """The report's lines on a re-ordered print that is slower (or layers kept because they were)."""
    slower = []
    if len(slower_layers):
        slower.append(kept_slower_note(len(slower_layers)))
    if fig is not None and fig["print_time_after_s"] > fig["print_time_before_s"] + GUARD_TOL_S:
        slower.append(f"the re-ordered print takes {fig['print_time_after_s'] - fig['print_time_before_s']:.1f} s "
                      f"longer (planner model): its travels retract {fig['retractions_after']:,} "
                      f"times instead of {fig['retractions_before']:,}")
    return slower


def order_summary(program: Program, out: Program, problem: OrderingProblem,
                  solution: OrderingSolution, options: OrderingOptions, slower_layers,
                  findings, *, formulation: str, time_limit_s: float, budget_s: float | None,
                  solve_budget_s: float | None, workers: int, wall_s: float,
                  with_figures: bool = True, greedy_layers: int = 0,
                  planned_s: tuple = (None, None), repaired=(), proofs_put_back: int = 0) -> dict:
    """The report of a re-ordering (``gatesopt order --json``; ``gatesopt solve`` has it under
    ``"ordering"``): the figures of the input and the output (``rewrite.figures``: travel,
    travels and retractions measured on the parsed files, print time under the planner model;
    ``with_figures`` False leaves them to the caller, whose own output they would describe), the
    solver's model travel, how each group and layer was solved. ``planned_s``: both files'
    per-step planner durations where the time guard has them (``guard.Guarded.planned_s``);
    ``repaired``: the layers the guard's repair pass solved again (``guard.Guarded.repaired``);
    ``proofs_put_back``: ``guard.Guarded.proofs_put_back``."""
    fig = (figures(program, out, planned_s=planned_s, printer=options.printer,
                   family=options.planner_family) if with_figures else None)
    layers, counts, lay_counts, decided = _solve_counts(problem, solution, slower_layers)
    sizes = np.diff(problem.group_curve_start)
    slower = _slower_notes(fig, slower_layers)
    late = out_of_time_groups(problem, solution)
    if late:
        slower.append(out_of_time_note(late, len(decided), solve_budget_s))
    late_greedy = greedy_out_of_time_groups(problem, solution)
    if late_greedy:
        slower.append(greedy_out_of_time_note(late_greedy, len(decided)))
    if solution.work_net_fired:
        slower.append(WORK_NET_NOTE)
    if proofs_put_back:
        slower.append(put_back_note(proofs_put_back))
    if fig is not None:
        slower += figure_notes(fig)
    time_obj = problem.cost_unit == "ms"
    repaired_groups = repaired_status_counts(solution, problem)
    return {
        "objective": options.objective,
        # the objective the solver optimised: the travels' time as emitted (time) or their length
        "model_travel_time_before_s": solution.cost_before / 1000.0 if time_obj else None,
        "model_travel_time_after_s": solution.cost_after / 1000.0 if time_obj else None,
        "layers_reorderable": lay_counts["reorderable"],
        "source": program.source, "formulation": formulation, "order_mode": options.mode,
        "move_seams": options.move_seams, "time_limit_s": time_limit_s, "budget_s": budget_s,
        "solve_budget_s": solve_budget_s, "workers": workers,
        **(fig or {}),
        # the solver's objective: straight links between curve ends from the origin on
        "model_travel_before_mm": solution.travel_before_mm,
        "model_travel_after_mm": solution.travel_after_mm,
        "curves": problem.n_curves, "groups": problem.n_groups,
        "groups_reordered": len(decided),
        "largest_group": int(max((sizes[g] for g, _ in decided), default=0)),
        "groups_optimal": counts["optimal"], "groups_feasible": counts["feasible"],
        "groups_fallback": counts["fallback"],
        # of the fallback groups, those the budget left no time for: the slicer's order, unsearched
        "groups_out_of_time": late,
        # of the fallback groups, those the budget left no time to search exactly that keep the
        # greedy pass's path (``runner.OUT_OF_TIME_GREEDY``)
        "groups_out_of_time_greedy": late_greedy,
        # the greedy chain's wall-clock safety net fired (``ordering.runner.WorkRunner``): groups
        # kept the slicer's order for want of wall-clock time, not of work: not reproducible
        "work_net_fired": bool(solution.work_net_fired),
        # safe mode's blocks (ordering/blocks.py): segments of >= 3 islands, how many moved, how
        # many block orders were proven optimal (the slicer's order kept counts if it was proven)
        "block_segments": int(problem.block_report.get("segments", 0)),
        "block_islands": int(problem.block_report.get("blocks", 0)),
        "block_segments_moved": int(problem.block_report.get("segments_moved", 0)),
        "block_layers_moved": int(problem.block_report.get("layers_moved", 0)),
        "block_orders_optimal": int(problem.block_report.get("proven", 0)),
        "object_runs": int(problem.block_report.get("object_runs", 0)),
        "object_count": int(problem.block_report.get("objects", 0)),
        "object_runs_moved": int(problem.block_report.get("object_runs_moved", 0)),
        "object_orders_optimal": int(problem.block_report.get("objects_proven", 0)),
        "objects_kept": {k: int(v[0]) for k, v in problem.block_report.get("objects_kept", {}).items()},
        "layers_optimal": lay_counts["optimal"], "layers_feasible": lay_counts["feasible"],
        "layers_fallback": lay_counts["fallback"], "layers_kept": lay_counts["kept"],
        "layers_kept_slower": int(len(slower_layers)),
        # layers the time guard printed in the greedy order: the exact solve left them unproven
        # and the greedy order printed faster (``guard.emit_guarded``; their groups: at best
        # feasible, formulation ``guard.GREEDY_TAKEN``)
        "layers_greedy": int(greedy_layers),
        # the time guard's repair pass (``repair_pass``): layers the guard put back although a
        # group in them was proven optimal, solved again on costs that agree with the planner;
        # of them, those still put back; their groups and how many are proven on those costs
        "layers_repaired": int(len(repaired)),
        "layers_repaired_kept_slower": int(len(set(np.asarray(repaired).tolist())
                                               & set(np.asarray(slower_layers).tolist()))),
        "groups_repaired": repaired_groups["groups"],
        "groups_repaired_optimal": repaired_groups["optimal"],
        # groups proven on the model's costs printed in the slicer's order all the same (the
        # planner found it faster, after the repair pass): reported with that path, not proven
        "groups_proofs_put_back": int(proofs_put_back),
        "worst_gap": float(max((gs.gap for _, gs in decided), default=0.0)),
        "solve_s": solution.solve_s, "wall_s": wall_s,
        "verified": not findings, "findings": [str(f) for f in findings],
        "notes": slower + list(problem.notes[:20]) + ([f"... {len(problem.notes) - 20} more notes"]
                                                      if len(problem.notes) > 20 else []),
        "per_layer": layers,
    }
