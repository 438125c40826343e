"""The whole rewrite as one library call: [order curves] -> build -> solve -> [rotate -> re-solve]
-> emit -> re-parse -> verify.

``gatesopt solve``, ``gatesopt compare``, ``gatesopt batch`` and ``bench/gating.py`` are thin
layers over ``run``. Nothing is written to disk here; the caller writes ``RunResult.text`` only if
``report.ok``. Nothing is swallowed either: an error in the ordering (a missing backend, a bug) is
the caller's to see.

Time: every stage is timed (``RunResult.times``) and the solve time a report gives is all of it:
the curve ordering's solve and both gating solves (the rotation search over every candidate
angle, and the solve again on the rotated text). ``time_limit_s`` bounds the gating solves
together, warm starts and model building included; ``budget_s`` is the whole run's, from
``started_s`` (the caller's clock reading before it read the file) to the verified output, every
solve included: the ordering's solve gets what the rest is estimated to leave
(``budget.ordering_budget_s``), less a share for an exact gating formulation's search, which gets
what is left of the budget when it starts, at most ``time_limit_s`` (``budget.gating_limit_s``).

The time budget (``GatingOptions.max_added_time_pct``) is on the print time the user will see: the
output's planner time (``figures.print_time_s``, the one print time every report gives) at most
(1 + P / 100) times the file's as given, re-ordering, rotation and stalls together
(``budget_limit_s``). The gating problem prices stalls in its firmware's model; the stall budget it
gets is what that limit leaves above the program it gates, and an output over the limit is solved
again with less (``_within_limit``).

Ctrl-C (``solvers.stop_scope``): the first one stops whatever solver is running, which answers
with the best it has; a stop during the curve ordering keeps the slicer's order; the gating
solves after it return their warm start; the run then emits and verifies as usual, and the notes
and the status say what happened. A second Ctrl-C raises ``KeyboardInterrupt``.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from .. import _jit, slicers
from ..kinematics import check_gateable
from ..gating.emit import EmitResult, emit_result, render
from ..gating.options import GatingOptions
from ..gating.problem import build
from ..gating.rotation import clearance_mm, print_outline, refuse_sequential_angle
from ..gating.solution import GatingSolution
from ..gating.solve import solve
from ..ordering.problem import OrderingOptions
from ..parse import parse
from ..program import Program
from ..solvers import Interrupted, Status, Stopped, request_stop, stop_requested, stop_scope
from ..verify import SHARED_CHECKS, VerifyReport, check_ordering, check_positions, energy_of, verify
from .budget import (EXACT_GATING_RESERVE_S, EXACT_GATING_SHARE, budget_clock, gating_limit_s,
                     no_time_note, on_print, ordering_budget_s)
from .figures import figure_notes, figures, print_time_s
from .order import (READ_S_PER_LINE, NoTimeToOrder, greedy_work_budget_s, kept_slower_note,
                    order_summary, out_of_time_groups, out_of_time_note, reorder, stage_floor_s)
from .printer import FirmwareChoice, choose
from .result import RunResult, Stages

#: a re-ordered and gated print may use this much more energy than as given (J; rounding) before
#: the run is made again without the ordering (``run``)
ENERGY_TOL_J = 1e-6
#: the first gating solve (over every rotation candidate) gets this share of ``time_limit_s``
#: when more than one angle is a candidate; the solve again on the rotated text the rest
ROTATION_SEARCH_SHARE = 0.75


def _order_curves(program: Program, time_limit_s: float, workers: int = 1,
                  budget_s: float | None = None, progress=None, options=None,
                  formulation: str = "auto", started_s: float | None = None,
                  slow: float | None = None, work_budget_s: float | None = None):
    """Re-order curves (``rewrite.order.reorder``): (program, ordered?, note, problem,
    ``summarize(findings)``: the ordering's report, given the findings of its checks, solve
    seconds). A stop request (Ctrl-C) keeps the slicer's order (a valid answer) with a note, as
    does a budget that once the problem is built leaves its solve too little to pass its groups
    (``slow``: ``reorder``'s ``NoTimeToOrder``); every other exception propagates."""
    t0 = time.perf_counter()      # the ordering's own clock (its report's wall_s)
    options = options or OrderingOptions()
    try:
        problem, solve_budget, guarded = reorder(
            program, options, formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
            workers=workers, progress=progress, started_s=t0 if started_s is None else started_s,
            slow=slow, work_budget_s=work_budget_s)
    except NoTimeToOrder as exc:
        return (program, False, f"curve ordering skipped after its build: {exc}: the slicer's order "
                "kept (a larger --budget re-orders)", None, None, 0.0)
    except KeyboardInterrupt as exc:    # Ctrl-C: the slicer's own order is a valid answer
        if not isinstance(exc, Interrupted):
            if stop_requested():
                raise           # a second Ctrl-C: the user wants out
            request_stop()      # a first one outside our handler: the solves after it stop too
        return (program, False, f"curve ordering interrupted (Ctrl-C) after "
                f"{time.perf_counter() - t0:.1f} s: the slicer's order kept", None, None,
                time.perf_counter() - t0)
    solution, _, out, slower = guarded
    wall_s = time.perf_counter() - t0
    notes = [f"curve ordering: {kept_slower_note(len(slower))}"] if len(slower) else []
    late = out_of_time_groups(problem, solution)
    if late:
        notes.append(out_of_time_note(late, int(np.count_nonzero(problem.group_reorderable)),
                                      solve_budget))
    note = "; ".join(notes)
    out = dataclasses.replace(out, source=program.source)

    def summarize(findings) -> dict:
        return order_summary(program, out, problem, solution, options, slower, findings,
                             formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
                             solve_budget_s=solve_budget, workers=workers, wall_s=wall_s,
                             with_figures=False, greedy_layers=guarded.greedy_layers,
                             repaired=guarded.repaired, proofs_put_back=guarded.proofs_put_back)
    return out, True, note, problem, summarize, solution.solve_s


def _solve_interruptible(problem, formulation: str, time_limit_s, notes: list) -> GatingSolution:
    """``solve``; a ``KeyboardInterrupt`` that still reaches here (outside a ``stop_scope``, or
    from Python code between two native calls) gives dp's answer (linear time, budgets
    repaired), marked "fallback" and said in the notes. Inside a stop scope the exact
    formulations stop on the first Ctrl-C by themselves, with their best answer."""
    try:
        return solve(problem, formulation, time_limit_s=time_limit_s)
    except KeyboardInterrupt:
        if formulation == "dp" or stop_requested():
            raise               # a second Ctrl-C: the user wants out
        request_stop()          # a first one outside our handler: the solves after it stop too
        sol = solve(problem, "dp")
        notes.append(f"{formulation} interrupted (Ctrl-C): dp's answer used instead")
        return dataclasses.replace(sol, status=Status.FALLBACK, stopped=Stopped.INTERRUPTED,
                                   message=f"{formulation} interrupted; dp answer ({sol.status})")


def _limit_left(time_limit_s, deadline: float | None, share: float = 1.0):
    """What is left of a gating time limit at its ``deadline`` (None: no limit), times ``share``;
    never below 10 ms (a formulation then answers with its warm start)."""
    if time_limit_s is None or deadline is None:
        return None
    return max(share * (deadline - time.perf_counter()), 0.01)


def _stop_note(sol: GatingSolution, what: str) -> str | None:
    """A note for a gating solve that stopped before its gap: why, and what it gave."""
    if not sol.stopped:
        return None
    gap = "" if math.isnan(sol.gap) else f", gap {100 * sol.gap:.4f} %"
    return f"{what}: {sol.formulation} stopped by {sol.stopped} after {sol.solve_s:.2f} s ({sol.status}{gap})"


def _gate(base: Program, o: GatingOptions, formulation: str, time_limit_s, notes: list, source: str,
          times: Stages, limit_s: float | None = None, planned=None):
    """Gate ``base``: (the program gating rewrote, solution, emitted). A rotation is its own
    rewrite first: the rotated text (a move whose rotated X or Y change is at most 1 um gets
    exactly the previous text on that axis, as long as the snaps do not drift the print by more
    than 1 um) is re-parsed, and gating is solved again on exactly that geometry, so that the
    emitted times and energies are the ones the solver scored. ``time_limit_s`` bounds both
    solves together (``ROTATION_SEARCH_SHARE``); both count in ``times["gating_solve_s"]``.
    ``limit_s``: the print time (planner model, ``figures.print_time_s``) the output may take at
    most, the user's file's times (1 + ``max_added_time_pct`` / 100) (``budget_limit_s``); None:
    the budget as the options give it, a share of the problem's own time. Returns (the program
    gating rewrote, solution, emitted, rotation report, the output parsed)."""
    with times.stage("gating_build_s"):
        problem = build(base, o)
        base_planned = planned if planned is not None else _Planned(base, o.firmware, o.printer, o.planner_family)
        problem = _budget_on_print(problem, base_planned, limit_s)
    notes += list(problem.notes)
    t = time.perf_counter()
    deadline = None if time_limit_s is None else t + float(time_limit_s)
    share = ROTATION_SEARCH_SHARE if problem.n_angles > 1 else 1.0
    sol = _solve_interruptible(problem, formulation, _limit_left(time_limit_s, deadline, share), notes)
    first_s = time.perf_counter() - t
    times.add("gating_solve_s", first_s)
    first = sol
    deg = sol.rotation_deg
    rotation = rotation_report(base, problem, deg, sol.formulation)
    if deg % 360.0 != 0.0:
        times.add("rotation_search_s", first_s)     # the solve that chose the rotation
    max_snap = 0.0
    if deg % 360.0 != 0.0:
        with times.stage("rotate_s"):
            rot = render(base, [], firmware=o.firmware, rotation_deg=deg,
                         center_mm=tuple(float(v) for v in sol.center_mm),
                         rotate_rows=(problem.rotate_lo, problem.rotate_hi))
            rbase = parse(rot.text, source=source)
        with times.stage("gating_build_s"):
            ro = o.replace(rotate="none")
            rproblem = build(rbase, ro)
            # the rotated text can take a little longer itself (0.15 s of 1175 s on a PrusaSlicer
            # file): the budget is on the print as sliced, so the stalls get what is left of it
            rbase_planned = _Planned(rbase, o.firmware, o.printer, o.planner_family)
            if limit_s is not None:
                rproblem = _budget_on_print(rproblem, rbase_planned, limit_s)
            elif o.max_added_time_pct is not None and rproblem.time_before_s > problem.time_before_s > 0:
                left = (1.0 + o.max_added_time_pct / 100.0) * problem.time_before_s / rproblem.time_before_s
                rproblem = dataclasses.replace(      # the budget enters only through max_added_time_s
                    rproblem, options=ro.replace(max_added_time_pct=max(0.0, 100.0 * (left - 1.0))))
        slower = _rotation_too_slow(base, problem, rbase, rproblem, o) if rotation["how"] == "auto" else None
        check = rotation["how"] == "auto" and (o.min_rotation_gain_pct > 0 or slower is not None)
        t = time.perf_counter()
        rsol = _solve_interruptible(rproblem, formulation,
                                    _limit_left(time_limit_s, deadline, 0.5 if check else 1.0), notes)
        times.add("gating_solve_s", time.perf_counter() - t)
        times.add("resolve_s", time.perf_counter() - t)
        kept = None
        if check:
            kept = _unrotated_if_better(base, o, formulation, _limit_left(time_limit_s, deadline), notes,
                                        rsol, deg, rotation, times, slower,
                                        lambda p: _budget_on_print(p, base_planned, limit_s))
        if kept is None:
            notes += list(rot.notes)
            max_snap = rot.max_snap_mm
            base, sol, base_planned = rbase, rsol, rbase_planned
        else:
            sol, deg = kept, 0.0
    for n in (_stop_note(first, "rotation search") if first is not sol else None,
              _stop_note(sol, "gating")):
        if n:
            notes.append(n)
    with times.stage("emit_s"):
        em = emit_result(base, sol, firmware=o.firmware)
    with times.stage("verify_s"):
        out = parse(em.text, source=source + " (output)")
    sol, em, out = _within_limit(base, base_planned, sol, em, out, o, limit_s, formulation,
                                 _limit_left(time_limit_s, deadline), notes, source, times)
    em = dataclasses.replace(em, max_snap_mm=max(em.max_snap_mm, max_snap), rotation_deg=deg)
    notes += list(em.notes)
    return base, sol, em, rotation, out


class _Planned:
    """A program's print time under the planner model in a dialect (``figures.print_time_s``),
    computed once and only when asked for."""

    def __init__(self, program: Program, firmware: str, printer=None, family: str | None = None):
        self.program, self.firmware, self.printer, self.family, self._s = program, firmware, printer, family, None

    @property
    def s(self) -> float:
        if self._s is None:
            self._s = print_time_s(self.program, self.firmware, printer=self.printer, family=self.family)
        return self._s


def budget_limit_s(program: Program, o: GatingOptions, planned: _Planned | None = None) -> float | None:
    """The print time the output may take at most under ``o.max_added_time_pct``: the user's file
    as given (before any re-ordering or rotation), planner model in the output's dialect
    (``figures.print_time_s``: what the reports call print time, within a few per cent of the
    slicers' estimates), times 1 + P / 100. None without a time budget. The budget is what the
    user will see: re-ordering, rotation and the firmware's stalls together."""
    if o.max_added_time_pct is None:
        return None
    planned = planned if planned is not None else _Planned(program, o.firmware, o.printer, o.planner_family)
    return (1.0 + o.max_added_time_pct / 100.0) * planned.s


def _budget_on_print(problem, planned: _Planned, limit_s: float | None):
    """``problem`` with its stall budget (``max_added_time_s``, in the problem's own seconds) set
    to what ``limit_s`` leaves above the planned print time of the program it was built on. The
    problem prices a stall by its firmware's model (Marlin's full stop and Klipper's
    planner stop plus dwells, priced per move), which the planner's time of the output need not match exactly:
    ``_within_limit`` checks the output and tightens the budget where it is over."""
    if limit_s is None or problem.options.max_added_time_pct is None or problem.time_before_s <= 0:
        return problem
    left_s = max(0.0, limit_s - planned.s)
    return dataclasses.replace(problem, options=problem.options.replace(
        max_added_time_pct=100.0 * left_s / problem.time_before_s))


#: tightening rounds of ``_within_limit`` before it solves with no stall allowed
LIMIT_ROUNDS = 3


def _within_limit(base: Program, planned: _Planned, sol: GatingSolution, em: EmitResult, out: Program,
                  o: GatingOptions, limit_s: float | None, formulation: str, time_limit_s, notes: list,
                  source: str, times: Stages):
    """(solution, emitted, output parsed) whose planner print time is within ``limit_s``: where the
    output's is over (the problem's stall model and the planner's stops differ: a Marlin stop from
    a fast travel costs more than 0.05 s), the stall budget shrinks by the planner's seconds per
    problem second measured on this output and solved again (greedy: labelled, ``budget.on_print``)."""
    if limit_s is None or sol.problem.options.max_added_time_pct is None:
        return sol, em, out
    problem = sol.problem
    for k in range(LIMIT_ROUNDS + 1):
        after_s = print_time_s(out, o.firmware, printer=o.printer, family=o.planner_family)
        if after_s <= limit_s * (1.0 + 1e-9) or sol.formulation == "greedy":   # greedy: no budget
            return on_print(sol, after_s, limit_s), em, out
        planner_added = after_s - planned.s
        model_added = sol.time_after_s - problem.time_before_s
        left_s = max(0.0, limit_s - planned.s)
        per_s = model_added / planner_added if planner_added > 0 and model_added > 0 else 0.0
        # the last round: no stall at all (the print as the rewrite left it, before gating)
        budget_s = 0.98 * left_s * per_s if k < LIMIT_ROUNDS else 0.0
        notes.append(f"time budget: the output's print time {after_s:.2f} s is over the "
                     f"{limit_s:.2f} s allowed (planner model): stalls cut to {budget_s:.2f} s of "
                     "the solver's model and solved again")
        problem = dataclasses.replace(problem, options=problem.options.replace(
            max_added_time_pct=100.0 * budget_s / problem.time_before_s))
        t = time.perf_counter()
        sol = _solve_interruptible(problem, formulation, time_limit_s, notes)
        times.add("gating_solve_s", time.perf_counter() - t)
        with times.stage("emit_s"):
            em = emit_result(base, sol, firmware=o.firmware)
        with times.stage("verify_s"):
            out = parse(em.text, source=source + " (output)")
    return sol, em, out


def _print_span_s(program: Program, problem) -> float:
    """Time from the print's first extrusion to its end, on the problem's timeline: what issue 34
    measures a dialect's added time on (bench/klipper_replay.py: first extrusion to last step)."""
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    first = int(ext[0]) if len(ext) else 0
    return float(problem.start_s[-1] - problem.start_s[first])


def _rotation_too_slow(base: Program, problem, rbase: Program, rproblem, o: GatingOptions) -> str | None:
    """Why the rotated print (``rproblem``, the rotated text) is refused for time, or None: it
    takes more than ``o.max_rotation_added_time_pct`` longer than the print as sliced, from its
    first extrusion to its end, on the options' time model (the travels into and out of the turned
    print change: 0.37 s of 549 s on real_kisslicer206 at 90 deg, Klipper's planner 0.39 s)."""
    limit = o.max_rotation_added_time_pct
    if limit is None:
        return None
    before = _print_span_s(base, problem)
    if before <= 0:
        return None
    added = _print_span_s(rbase, rproblem) - before
    pct = 100.0 * added / before
    if pct <= limit:
        return None
    return f"adds {added:.2f} s ({pct:.3f} %) to the planned print, more than the {limit:g} % allowed"


def _unrotated_if_better(base: Program, o: GatingOptions, formulation: str, time_limit_s, notes: list,
                         rotated: GatingSolution, deg: float, rotation: dict,
                         times: Stages, slower: str | None = None,
                         on_print=lambda p: p) -> GatingSolution | None:
    """The 0 deg solution of ``base`` where the rotated print's (``rotated``, solved on the
    rotated text) saves less than ``o.min_rotation_gain_pct`` more energy, else None; updates the
    ``rotation`` report (its line says why the print stays). A turned print for next to nothing is
    a surprise (89.9965 deg for 0.013 % on a SuperSlicer file), and the angle can lose to 0 deg
    once rotated: ``dp`` picks it on the separable optimum before it repairs a time budget
    (holes__prusa_mk3s, stock 1 % budget: 3.88 % at 45 deg, 4.91 % at 0 deg; issue 37's check)."""
    with times.stage("gating_build_s"):
        problem0 = on_print(build(base, o.replace(rotate="none")))
    t = time.perf_counter()
    sol0 = _solve_interruptible(problem0, formulation, time_limit_s, notes)
    times.add("gating_solve_s", time.perf_counter() - t)
    times.add("rotation_check_s", time.perf_counter() - t)
    gain_pct = 100.0 * (sol0.energy_j - rotated.energy_j) / sol0.energy_j if sol0.energy_j else 0.0
    rotation["gain_pct"] = gain_pct
    if slower is not None:
        rotation.update(deg=0.0, clearance_mm=None, line=(
            f"none: {deg:g} deg, {rotation['chosen']}, {slower} (--rotate {deg:g} to take it)"))
        return sol0
    if gain_pct >= o.min_rotation_gain_pct:
        return None
    more = f"saves {gain_pct:.2f} % more" if gain_pct >= 0 else f"saves {-gain_pct:.2f} % less"
    rotation.update(deg=0.0, clearance_mm=None, line=(
        f"none: {deg:g} deg, {rotation['chosen']}, {more} than 0 deg once rotated, below the "
        f"{o.min_rotation_gain_pct:g} % a rotation must save (--rotate {deg:g} to take it)"))
    return sol0


def _angle_list(angles) -> str:
    base = [a for a in angles if float(a) in (0.0, 30.0, 45.0, 60.0)]
    rest = len(angles) - len(base)
    words = ", ".join(f"{a:g}" for a in base)
    return words + (f" deg and {rest} of the print's line directions" if rest else " deg")


def rotation_report(program: Program, problem, deg: float, formulation: str) -> dict:
    """How the rotation of a solve was chosen and what it was checked against, with the one line
    that says so: the angle (or why none), among which candidates, by what, on which bed."""
    plan = problem.rotation_plan
    angles = [float(a) for a in problem.angles_deg]
    d = {"deg": float(deg), "how": getattr(plan, "how", "auto"), "candidates_deg": angles,
         "chosen_by": formulation, "why_none": getattr(plan, "why_none", ""),
         "bed": plan.bed.describe() if plan is not None and plan.bed is not None else None,
         "margin_mm": getattr(plan, "margin_mm", None), "clearance_mm": None}
    if plan is None:
        d["line"] = f"{deg:g} deg" if deg % 360.0 else "none"
        return d
    if plan.why_none:
        d["line"] = f"none ({plan.why_none})"
        return d
    if plan.how == "auto":
        chosen = (f"the best of {len(angles)} candidate angles ({_angle_list(angles)}) by {formulation}'s "
                  f"energy")
    else:
        chosen = f"--rotate {deg:g}"
    d["chosen"] = chosen
    bed_words = f", on the {plan.bed.describe()}" if plan.bed is not None else " (no bed check)"
    if deg % 360.0 == 0.0:
        d["line"] = f"none: 0 deg is {chosen}{bed_words}"
        return d
    cx, cy = (float(v) for v in problem.center_mm)
    if plan.bed is None:
        d["line"] = f"{deg:g} deg about ({cx:.3f}, {cy:.3f}), {chosen}; not checked against a bed (check_bed=False)"
        return d
    c = clearance_mm(print_outline(program, problem.rotate_lo, problem.rotate_hi), plan.bed,
                     problem.center_mm, deg)
    d["clearance_mm"] = c
    d["line"] = f"{deg:g} deg about ({cx:.3f}, {cy:.3f}), {chosen}; {plan.clearance_words(c)}"
    return d


def _verify_run(program: Program, ordered_base: Program, out: Program, o: GatingOptions,
                sol: GatingSolution | None, ordered: bool) -> tuple[VerifyReport, tuple]:
    """(the report, the ordering checks' findings when gating ran on a re-ordered print)."""
    claimed = (sol.energy_j, sol.time_after_s) if sol is not None else None
    rep = verify(program, out, firmware=o.firmware, start_ahead_s=o.start_ahead_s,
                 end_late_s=o.end_late_s, claimed=claimed, profile=o.profile, reordered=ordered,
                 printer=o.printer)
    extra = ()
    if ordered and sol is not None:
        # the ordering's own checks, on the re-ordered print before gating split any move
        extra = tuple(check_ordering(program, ordered_base))
        # the report has ``verify``'s extrusion and commands findings on the output itself: the
        # same faults seen on the re-ordered print are not added twice (the ordering's summary
        # below counts them all)
        own = tuple(f for f in extra if f.check not in SHARED_CHECKS)
        # and the positions check ``verify`` skips for a re-ordering, on what gating rewrote: the
        # re-ordered print against the output (rotation and gating keep its moves in order)
        pos = check_positions(ordered_base, out)
        if own or pos:
            rep = dataclasses.replace(rep, ok=False, findings=rep.findings + own + tuple(pos))
        elif extra:
            rep = dataclasses.replace(rep, ok=False)
        rep = dataclasses.replace(rep, checks=rep.checks + ("ordering", "positions"))
    return rep, extra


def _exact(formulation: str) -> bool:
    """True for a gating formulation whose search runs until its time limit (milp, cpsat)."""
    from ..gating.solve import FORMULATIONS
    f = FORMULATIONS.get(formulation)
    return f is not None and "exact" in f.capabilities


def order_formulation_of(gating_formulation: str) -> str:
    """The curve ordering's formulation a gating formulation names ("--formulation milp means exact
    for both", issue 4): the same name where the ordering has it for groups of any size (greedy,
    milp, cpsat), else auto (dp is gating's alone). ``solve``, ``compare`` and ``batch`` all
    take it from here."""
    from ..ordering import FORMULATIONS as ORDER_FORMULATIONS
    f = ORDER_FORMULATIONS.get(gating_formulation)
    return gating_formulation if f is not None and "any_size" in f.capabilities else "auto"


def run(program: Program, options: GatingOptions | None = None, *, formulation: str = "dp",
        time_limit_s: float | None = None, order: bool = True, gating: bool = True,
        order_time_limit_s: float = 2.0, order_workers: int = 1,
        order_budget_s: float | None = None, order_progress=None, order_options=None,
        order_formulation: str = "auto", choice: FirmwareChoice | None = None,
        budget_s: float | None = None, started_s: float | None = None,
        cpu_started_s: float | None = None) -> RunResult:
    """Rewrite ``program`` as ``gatesopt solve`` does: optional curve ordering, then power gating
    (a chosen rotation applied, the rotated print parsed and solved again); verify the result.
    ``options``: the gating options; None: what fits the file's printer (``printer.choose``:
    the firmware the file names, a time budget for stock firmware, rotation only on a known bed),
    or ``choice.options`` where a ``choice`` is given (``printer.choose``, as the CLI makes it).
    ``order_options``: an ``ordering.OrderingOptions`` (mode, seams; default safe, seams kept);
    ``order_formulation``: the ordering's formulation (``auto``, ``milp``, ``cpsat``, ``greedy``,
    ``tsp``); ``order_progress``: called after each ordering group (``ordering.layers.solve``).
    ``time_limit_s``: the gating solves together (module docstring); ``budget_s``: the whole
    run from ``started_s`` (a ``time.perf_counter()`` reading, default now), the ordering's solve
    getting what the rest leaves (estimated at the rates of the machine as loaded: the wall / CPU
    seconds since ``started_s`` and ``cpu_started_s``, a ``time.process_time()`` reading taken
    with it, ``budget.slowdown_factor``); ``order_budget_s``: the ordering stage alone (build, solve,
    emit), if given instead."""
    program.check_rewritable()
    t0 = time.perf_counter() if started_s is None else started_s
    if options is None:
        choice = choice if choice is not None else choose(program)
        options = choice.options
        gating = gating and options is not None
    o = options or GatingOptions()
    if gating:
        # corexy: X, Y are not one motor each (``choose`` never picks them; options made by hand may)
        check_gateable(program.data, o.motors, o.printer, program.source)
        refuse_sequential_angle(program, o.rotate)      # (at the input's line, before ordering)
    notes = []
    times = Stages()
    times.add("read_s", time.perf_counter() - t0)
    slow = 1.0
    budget_t0 = t0       # what the budget counts from (a first run: ``budget.budget_clock``)
    if budget_s is not None:
        budget_t0, slow = budget_clock(t0, cpu_started_s, program.n_lines)
    with stop_scope():
        base, ordered, order_problem, summarize = program, False, None, None
        ob = order_budget_s
        order_work_s = None
        if order and budget_s is not None:
            # compiling numba kernels (a first run) is not charged to the budget (cli.progress)
            spent_s = time.perf_counter() - budget_t0 - _jit.compile_s_since(budget_t0)
            def ordering_share(spent, rate):
                b = ordering_budget_s(budget_s, program, o, formulation, gating, spent, time_limit_s, rate)
                if gating and _exact(formulation):
                    # an exact gating formulation's search is part of the budget too (issue 37):
                    # the ordering leaves it a share of what it has beyond its own floor, at most
                    # --time-limit and EXACT_GATING_RESERVE_S -- never the ordering itself:
                    # re-ordering gains percents, the search over dp's warm start hundredths (a
                    # 121k-line Cura file: the ordering skipped under milp, 1.47 % "optimal"
                    # against dp's 3.90 %)
                    b -= min(math.inf if time_limit_s is None else float(time_limit_s),
                             EXACT_GATING_RESERVE_S,
                             EXACT_GATING_SHARE * max(b - stage_floor_s(program, rate), 0.0))
                return b
            ob = ordering_share(spent_s, slow)
            # the greedy chain's budget in work (issue 36: the same greedy pass on every run):
            # the same estimate with the reading counted at its quiet rate, not as measured
            order_work_s = greedy_work_budget_s(ordering_share(READ_S_PER_LINE * program.n_lines, 1.0),
                                                program.n_lines)
            floor = stage_floor_s(program, slow)
            if ob <= floor:
                # what the rest leaves the ordering would not pay for its build, a pass over
                # every group and its emit even with no time to search (seconds on a large file:
                # the run would end late by the difference): the slicer's order, said so
                order = False
                notes.append(no_time_note(budget_s, spent_s, slow, max(ob, 0.0), floor))
        if order:
            with times.stage("ordering_s"):
                base, ordered, note, order_problem, summarize, order_solve_s = _order_curves(
                    program, order_time_limit_s, order_workers, ob, order_progress,
                    (order_options or OrderingOptions()).planned_by(o.planner_family, o.printer),
                    order_formulation,
                    slow=slow if budget_s is not None else None, work_budget_s=order_work_s)
            times.add("ordering_solve_s", order_solve_s)
            if note:
                notes.append(note)
        ordered_base = base
        if ordered and o.bed is None and o.bed_size_mm is None:
            # the re-ordered copy has other line numbers: the rotation line cites the user's file
            o = o.replace(bed=slicers.read_bed(program.data))
        sol = em = rotation = out = None
        planned0 = _Planned(program, o.firmware, o.printer, o.planner_family)
        if gating:
            if budget_s is not None and _exact(formulation):
                time_limit_s = gating_limit_s(program, o, budget_s, budget_t0, time_limit_s,
                                                             slow, notes)
            with times.stage("report_s"):   # the time budget's reference: the file as given
                limit_s = budget_limit_s(program, o, planned0)
            base, sol, em, rotation, out = _gate(base, o, formulation, time_limit_s, notes,
                                                 program.source, times, limit_s,
                                                 planned0 if base is program else None)
            text = em.text
        else:
            text = base.to_gcode()
        stopped = str(Stopped.INTERRUPTED) if stop_requested() else ""
    with times.stage("verify_s"):
        if out is None:
            out = parse(text, source=(program.source + " (output)"))
        rep, extra = _verify_run(program, ordered_base, out, o, sol, ordered)
    with times.stage("report_s"):
        figs = figures(program, out, o.firmware if sol is not None else None,
                       before_s=planned0._s if sol is not None else None,
                       printer=o.printer if sol is not None else None,
                       family=o.planner_family if sol is not None else None)
        order_report = None
        if summarize is not None:
            # without gating ``verify`` above ran the ordering checks itself: its findings are theirs
            order_report = summarize(extra if sol is not None else rep.findings)
        notes += figure_notes(figs, rep.saving_pct, sol is not None) if ordered else []
    result = RunResult(program, base, sol, em, text, out, rep, ordered, tuple(notes),
                       time.perf_counter() - t0, order_problem=order_problem,
                       order_summary=order_report, choice=choice, rotation=rotation, times=times.s,
                       stopped=stopped, figures=figs, slowdown=slow)
    if (ordered and sol is not None and rep.ok and not stopped
            and rep.energy_j > rep.energy_before_j + ENERGY_TOL_J):
        # the ordering prices print time (planner model), the energy the 3DGates model over the
        # paper's T = L/F: a re-ordering that saves time but lengthens the travel can cost more
        # energy than gating saves (seen: PrusaSlicer, RepRapFirmware flavour, E-only gating,
        # travel +0.5 %: saving -0.07 %). Gating alone never costs energy (no gating is one of
        # its answers): the run again without the ordering, taken where it saves more
        plain = run(program, options, formulation=formulation, time_limit_s=time_limit_s,
                    order=False, gating=gating, choice=choice, started_s=t0)
        if plain.report.ok and plain.report.energy_j < rep.energy_j:
            # (the run again counts its "read" from ``t0``: the whole first run)
            spent = {k: times.s.get(k, 0.0) + (plain.times.get(k, 0.0) if k != "read_s" else 0.0)
                     for k in {**times.s, **plain.times}}
            note = (f"curve ordering not applied: re-ordered, the print saved "
                    f"{rep.saving_pct:.2f} % of its energy (3DGates model over T = L/F: the "
                    f"travel it rebuilt is longer), gated in the slicer's order "
                    f"{plain.report.saving_pct:.2f} % (its time counted in 'time spent')")
            return dataclasses.replace(plain, notes=plain.notes + (note,),
                                       times=spent, slowdown=slow)
    return result


def energy_time(program: Program, firmware: str = "3dgates", profile: str = "paper"):
    """(energy J, time s) of a program as it stands (its own motor lines, stalls included)."""
    e, t, _ = energy_of(program, firmware=firmware, profile=profile, original=program)
    return e, t
