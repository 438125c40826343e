"""The whole rewrite as one library call: [order curves] -> build -> solve -> [rotate -> re-solve]
-> emit -> re-parse -> verify.

``gatesopt solve``, ``gatesopt compare``, ``gatesopt batch`` and ``bench/gating.py`` are thin
layers over ``run``. Nothing is written to disk here; the caller writes ``RunResult.text`` only if
``report.ok``. Nothing is swallowed either: an error in the ordering (a missing backend, a bug) is
the caller's to see; only Ctrl-C during the ordering keeps the slicer's order, with a note.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

from ..gating.emit import EmitResult, emit_result, render
from ..gating.options import GatingOptions
from ..gating.problem import build
from ..gating.rotation import clearance_mm, print_outline
from ..gating.solution import GatingSolution
from ..gating.solve import solve
from ..ordering.problem import OrderingOptions
from ..parse import parse
from ..program import Program
from ..solvers import Status
from ..verify import VerifyReport, check_ordering, check_positions, energy_of, verify
from .order import kept_slower_note, order_summary, reorder
from .printer import FirmwareChoice, choose

#: the keys of the ordering's report that ``gatesopt solve --json`` carries (issue 4: "--json as
#: for gating, keys travel_before_mm, travel_after_mm added"); the rest of that report is under
#: ``"ordering"``
ORDER_KEYS = ("travel_before_mm", "travel_after_mm", "travel_change_pct", "travel_time_before_s",
              "travel_time_after_s", "travels_before", "travels_after", "retractions_before",
              "retractions_after", "groups_optimal", "groups_feasible", "groups_fallback",
              "layers_optimal", "layers_feasible", "layers_fallback", "layers_kept", "worst_gap")


@dataclass(frozen=True, eq=False)
class RunResult:
    original: Program
    base: Program                       # what gating worked on (the original, or the re-ordered print)
    solution: GatingSolution | None     # None with gating off
    emitted: EmitResult | None
    text: str
    output: Program
    report: VerifyReport
    ordered: bool
    notes: tuple
    wall_s: float
    order_problem: object = None        # the OrderingProblem, when curves were ordered
    order_summary: dict | None = None   # the ordering's report (``rewrite.order.order_summary``)
    choice: FirmwareChoice | None = None    # the firmware chosen for the file (``printer.choose``)
    rotation: dict | None = None        # how the rotation was chosen (``rotation_report``)

    def summary(self) -> dict:
        """The report keys of ``gatesopt solve --json`` (issue 3)."""
        r, s = self.report, self.solution
        d = {
            "source": self.original.source, "firmware": r.firmware, "verified": r.ok,
            "findings": [str(f) for f in r.findings],
            "energy_before_j": r.energy_before_j, "energy_after_j": r.energy_j,
            "saving_pct": r.saving_pct, "time_before_s": r.time_before_s, "time_after_s": r.time_s,
            "added_time_pct": 100.0 * (r.time_s / r.time_before_s - 1.0) if r.time_before_s else 0.0,
            "lines_before": r.lines_before, "lines_after": r.lines_after,
            "lines_added": r.lines_after - r.lines_before,
            "bytes_before": r.bytes_before, "bytes_after": r.bytes_after,
            "size_change_pct": 100.0 * (r.bytes_after / r.bytes_before - 1.0) if r.bytes_before else 0.0,
            "rotation_deg": r.rotate_deg, "center_xy": list(r.center_mm), "ordered": self.ordered,
            "formulation": s.formulation if s else None, "status": s.status if s else "skipped",
            "objective_j": s.energy_j if s else None,
            "objective_time_s": s.time_after_s if s else None,
            "bound": (None if s is None or math.isnan(s.bound_j) else s.bound_j),
            "gap": (None if s is None or math.isnan(s.gap) else s.gap),
            "solve_s": s.solve_s if s else 0.0,
            "instruction_lines": self.emitted.instruction_lines if self.emitted else 0,
            "splits": self.emitted.splits if self.emitted else 0,
            "max_snap_mm": float(self.emitted.max_snap_mm) if self.emitted else 0.0,
            "off_time_s": s.off_time_s() if s else {},
            "message": s.message if s else "",
            "notes": list(self.notes), "wall_s": self.wall_s,
            "firmware_line": self.choice.line if self.choice else f"{r.firmware} (given)",
            "firmware_choice": self.choice.summary() if self.choice else None,
            "rotation_line": (self.rotation or {}).get("line", "none"),
            "rotation": self.rotation,
        }
        if self.order_summary is not None:
            o = self.order_summary
            d.update({k: o[k] for k in ORDER_KEYS})
            d["ordering"] = {k: v for k, v in o.items() if k not in ("per_layer", "source", "notes")}
        return d


def _order_curves(program: Program, time_limit_s: float, workers: int = 1,
                  budget_s: float | None = None, progress=None, options=None,
                  formulation: str = "auto"):
    """Re-order curves (``rewrite.order.reorder``): (program, ordered?, note, problem,
    ``summarize(findings)``: the ordering's report, given the findings of its checks). Ctrl-C
    keeps the slicer's order (a valid answer) with a note; every other exception propagates."""
    t0 = time.perf_counter()      # the budget covers the ordering: build, solve, emit
    options = options or OrderingOptions()
    try:
        problem, solve_budget, solution, _, out, slower = reorder(
            program, options, formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
            workers=workers, progress=progress, started_s=t0)
    except KeyboardInterrupt:   # Ctrl-C: the slicer's own order is a valid answer
        return program, False, "curve ordering interrupted (Ctrl-C): the slicer's order kept", None, None
    wall_s = time.perf_counter() - t0
    note = f"curve ordering: {kept_slower_note(len(slower))}" if len(slower) else ""
    out = dataclasses.replace(out, source=program.source)

    def summarize(findings) -> dict:
        return order_summary(program, out, problem, solution, options, slower, findings,
                             formulation=formulation, time_limit_s=time_limit_s, budget_s=budget_s,
                             solve_budget_s=solve_budget, workers=workers, wall_s=wall_s)
    return out, True, note, problem, summarize


def _solve_interruptible(problem, formulation: str, time_limit_s, notes: list) -> GatingSolution:
    """``solve``, but a Ctrl-C during an exact solve still gives an answer: dp's (linear time,
    budgets repaired), marked "fallback" and said in the notes. (CP-SAT itself catches SIGINT and
    returns its best solution, which the formulation reports as feasible or fallback.)"""
    try:
        return solve(problem, formulation, time_limit_s=time_limit_s)
    except KeyboardInterrupt:
        if formulation == "dp":
            raise
        sol = solve(problem, "dp")
        notes.append(f"{formulation} interrupted (Ctrl-C): dp's answer used instead")
        return dataclasses.replace(sol, status=Status.FALLBACK,
                                   message=f"{formulation} interrupted; dp answer ({sol.status})")


def _gate(base: Program, o: GatingOptions, formulation: str, time_limit_s, notes: list, source: str):
    """Gate ``base``: (the program gating rewrote, solution, emitted). A rotation is its own
    rewrite first: the rotated text (a move whose rotated X or Y change is at most 1 um gets
    exactly the previous text on that axis, as long as the snaps do not drift the print by more
    than 1 um) is re-parsed, and gating is solved again on exactly that geometry, so that the
    emitted times and energies are the ones the solver scored."""
    problem = build(base, o)
    notes += list(problem.notes)
    sol = _solve_interruptible(problem, formulation, time_limit_s, notes)
    deg = sol.rotation_deg
    rotation = rotation_report(base, problem, deg, sol.formulation)
    max_snap = 0.0
    if deg % 360.0 != 0.0:
        rot = render(base, [], firmware=o.firmware, rotation_deg=deg,
                     center_mm=tuple(float(v) for v in sol.center_mm),
                     rotate_rows=(problem.rotate_lo, problem.rotate_hi))
        notes += list(rot.notes)
        max_snap = rot.max_snap_mm
        base = parse(rot.text, source=source)
        problem = build(base, o.replace(rotate="none"))
        sol = _solve_interruptible(problem, formulation, time_limit_s, notes)
    em = emit_result(base, sol, firmware=o.firmware)
    em = dataclasses.replace(em, max_snap_mm=max(em.max_snap_mm, max_snap), rotation_deg=deg)
    notes += list(em.notes)
    return base, sol, em, rotation


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
        # and the positions check ``verify`` skips for a re-ordering, on what gating rewrote: the
        # re-ordered print against the output (rotation and gating keep its moves in order)
        pos = check_positions(ordered_base, out)
        if extra or pos:
            rep = dataclasses.replace(rep, ok=False, findings=rep.findings + extra + tuple(pos))
        rep = dataclasses.replace(rep, checks=rep.checks + ("ordering", "positions"))
    return rep, extra


def run(program: Program, options: GatingOptions | None = None, *, formulation: str = "dp",
        time_limit_s: float | None = None, order: bool = True, gating: bool = True,
        order_time_limit_s: float = 2.0, order_workers: int = 1,
        order_budget_s: float | None = None, order_progress=None, order_options=None,
        order_formulation: str = "auto", choice: FirmwareChoice | None = None) -> RunResult:
    """Rewrite ``program`` as ``gatesopt solve`` does: optional curve ordering, then power gating
    (a chosen rotation applied, the rotated print parsed and solved again); verify the result.
    ``options``: the gating options; None: what fits the file's printer (``printer.choose``:
    the firmware the file names, a time budget for stock firmware, rotation only on a known bed),
    or ``choice.options`` where a ``choice`` is given (``printer.choose``, as the CLI makes it).
    ``order_options``: an ``ordering.OrderingOptions`` (mode, seams; default safe, seams kept);
    ``order_formulation``: the ordering's formulation (``auto``, ``milp``, ``cpsat``, ``greedy``,
    ``tsp``); ``order_progress``: called after each ordering group (``ordering.layers.solve``)."""
    program.check_rewritable()
    t0 = time.perf_counter()
    if options is None:
        choice = choice if choice is not None else choose(program)
        options = choice.options
        gating = gating and options is not None
    o = options or GatingOptions()
    notes = []
    base, ordered, order_problem, summarize = program, False, None, None
    if order:
        base, ordered, note, order_problem, summarize = _order_curves(
            program, order_time_limit_s, order_workers, order_budget_s, order_progress,
            order_options, order_formulation)
        if note:
            notes.append(note)
    ordered_base = base
    sol = em = rotation = None
    if gating:
        base, sol, em, rotation = _gate(base, o, formulation, time_limit_s, notes, program.source)
        text = em.text
    else:
        text = base.to_gcode()
    out = parse(text, source=(program.source + " (output)"))
    rep, extra = _verify_run(program, ordered_base, out, o, sol, ordered)
    order_report = None
    if summarize is not None:
        # without gating ``verify`` above ran the ordering checks itself: its findings are theirs
        order_report = summarize(extra if sol is not None else rep.findings)
    return RunResult(program, base, sol, em, text, out, rep, ordered, tuple(notes),
                     time.perf_counter() - t0, order_problem=order_problem,
                     order_summary=order_report, choice=choice, rotation=rotation)


def energy_time(program: Program, firmware: str = "3dgates", profile: str = "paper"):
    """(energy J, time s) of a program as it stands (its own motor lines, stalls included)."""
    e, t, _ = energy_of(program, firmware=firmware, profile=profile, original=program)
    return e, t
