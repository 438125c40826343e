"""What a whole rewrite gives (``pipeline.run``): ``RunResult``, its report (``summary``: the keys
of ``gatesopt solve --json``), and the seconds per stage (``Stages``)."""
from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, field

from ..gating.emit import EmitResult
from ..gating.solution import GatingSolution
from ..program import Kind, Program
from ..verify import VerifyReport
from .figures import figures
from .printer import FirmwareChoice

#: the keys of the ordering's report that ``gatesopt solve --json`` carries at its top level (the
#: travel figures are the run's own, ``figures``: measured on the input and the final output);
#: the rest of that report is under ``"ordering"``
ORDER_KEYS = ("groups_optimal", "groups_feasible", "groups_fallback", "layers_optimal",
              "layers_feasible", "layers_fallback", "layers_kept", "worst_gap")
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
    wall_s: float                       # from ``started_s`` (the caller's read) to the verified output
    order_problem: object = None        # the OrderingProblem, when curves were ordered
    order_summary: dict | None = None   # the ordering's report (``rewrite.order.order_summary``)
    choice: FirmwareChoice | None = None    # the firmware chosen for the file (``printer.choose``)
    rotation: dict | None = None        # how the rotation was chosen (``rotation_report``)
    times: dict = field(default_factory=dict)   # seconds per stage (``Stages``)
    stopped: str = ""                   # "interrupted (Ctrl-C)" when a stop was requested
    figures: dict = field(default_factory=dict)  # print time and travel (``rewrite.figures``)
    slowdown: float = 1.0               # wall / CPU seconds before the ordering (``budget.slowdown_factor``)

    @property
    def solve_s(self) -> float:
        """Every solver's time: the curve ordering's solve and both gating solves."""
        return self.times.get("ordering_solve_s", 0.0) + self.times.get("gating_solve_s", 0.0)

    def summary(self) -> dict:
        """The report keys of ``gatesopt solve --json`` (issue 3): energy (3DGates model over
        the paper's times), the one print time (planner model) and travel (measured on the
        files), ``figures``; every time spent, ``times``."""
        r, s = self.report, self.solution
        figs = self.figures or figures(self.original, self.output, r.firmware)
        d = {
            # the dialect the output's motor lines are in; "none" where nothing was gated (the
            # output was checked by the paper firmware's rules, which add nothing: not a choice)
            "source": self.original.source, "firmware": r.firmware if s else "none", "verified": r.ok,
            "findings": [str(f) for f in r.findings],
            "energy_before_j": r.energy_before_j, "energy_after_j": r.energy_j,
            "saving_pct": r.saving_pct,
            **figs,
            # the time the print takes more than the user's file as given (re-ordering, rotation
            # and stalls together), planner model: the print time every report gives, and what
            # --max-added-time-pct bounds (``budget_limit_s``)
            "added_time_pct": figs["print_time_change_pct"],
            # the energy model's time (paper T = L/F, firmware stalls included): what the
            # energies integrate over
            "paper_time_before_s": r.time_before_s, "paper_time_after_s": r.time_s,
            "paper_added_time_pct": 100.0 * (r.time_s / r.time_before_s - 1.0) if r.time_before_s else 0.0,
            "lines_before": r.lines_before, "lines_after": r.lines_after,
            "lines_added": r.lines_after - r.lines_before,
            "bytes_before": r.bytes_before, "bytes_after": r.bytes_after,
            "size_change_pct": 100.0 * (r.bytes_after / r.bytes_before - 1.0) if r.bytes_before else 0.0,
            "rotation_deg": r.rotate_deg, "center_xy": list(r.center_mm), "ordered": self.ordered,
            "formulation": s.formulation if s else None, "status": s.status if s else "skipped",
            "stopped": str(s.stopped) if s else self.stopped,
            "objective_j": s.energy_j if s else None,
            "objective_time_s": s.time_after_s if s else None,
            "bound": (None if s is None or math.isnan(s.bound_j) else s.bound_j),
            "gap": (None if s is None or math.isnan(s.gap) else s.gap),
            "solve_s": self.solve_s,
            "gating_solve_s": self.times.get("gating_solve_s", 0.0),
            "ordering_solve_s": self.times.get("ordering_solve_s", 0.0),
            "instruction_lines": self.emitted.instruction_lines if self.emitted else 0,
            "splits": self.emitted.splits if self.emitted else 0,
            "max_snap_mm": float(self.emitted.max_snap_mm) if self.emitted else 0.0,
            "off_time_s": s.off_time_s() if s else {},
            "off_time_model": s.problem.options.time_model if s else None,
            # of which during heat-up waits (M109 / M190 / TEMPERATURE_WAIT): their length is the
            # energy profile's heating assumption, and a host that skips them (klippy's batch
            # mode) sees the rest only
            "off_time_waits_s": s.off_time_in_s(self.base.kind == Kind.WAIT) if s else {},
            "message": s.message if s else "",
            "notes": list(self.notes), "wall_s": self.wall_s, "times": dict(self.times),
            "slowdown": self.slowdown,
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


class Stages:
    """Seconds per stage of a run, as ``RunResult.times`` reports them (``add``: a stage's time,
    summed where it runs twice; ``stage``: a timed block)."""

    def __init__(self):
        self.s: dict = {}

    def add(self, name: str, seconds: float) -> None:
        self.s[name] = self.s.get(name, 0.0) + float(seconds)

    @contextlib.contextmanager
    def stage(self, name: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - t)
