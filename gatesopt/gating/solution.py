"""A gating answer: the rotation and per-motor off intervals a formulation chose, re-scored.

Every formulation ends in ``make_solution``: whatever its own model said, the energy, lines and
added time of a ``GatingSolution`` come from ``gating.scoring`` (the one energy function), its
status is one of ``gatesopt.solvers.Status`` and its gap is ``solvers.relative_gap``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..program import AXES
from ..solvers import Status, Stopped, relative_gap
from . import scoring
from .problem import GatingProblem, readonly, steps_motor_at
from .scoring import Instructions, Pieces


@dataclass(frozen=True, eq=False)
class GatingSolution:
    """Decisions (rotation + per-motor off intervals), objective and solver report."""

    problem: GatingProblem = field(repr=False)
    formulation: str
    status: Status                  # optimal | feasible | fallback | infeasible (gatesopt.solvers)
    angle_index: int
    off_motor: np.ndarray           # (k,) int8 axis index
    off_start_s: np.ndarray         # (k,) on the problem's timeline
    off_end_s: np.ndarray           # (k,)
    energy_j: float                 # total energy after gating (step_energy_j over pieces())
    energy_before_j: float
    lines_added: int
    added_time_s: float
    bound_j: float = math.nan       # lower bound on energy_j where the method has one
    gap: float = math.nan           # solvers.relative_gap(energy_j, bound_j): a fraction
    solve_s: float = 0.0
    message: str = ""
    stopped: Stopped = Stopped.NO   # why the search ended before its gap (time limit, Ctrl-C)

    @property
    def rotation_deg(self) -> float:
        return float(self.problem.angles_deg[self.angle_index])

    @property
    def center_mm(self) -> np.ndarray:
        return self.problem.center_mm

    @property
    def max_snap_mm(self) -> float:
        return float(self.problem.angle_snap_mm[self.angle_index])

    @property
    def saving_j(self) -> float:
        return self.energy_before_j - self.energy_j

    @property
    def saving_pct(self) -> float:
        return 100.0 * self.saving_j / self.energy_before_j if self.energy_before_j else 0.0

    @property
    def time_after_s(self) -> float:
        return self.problem.time_before_s + self.added_time_s

    def off_time_s(self) -> dict:
        """Total off time per motor letter."""
        d = {AXES[m]: 0.0 for m in self.problem.motors}
        for m in self.problem.motors:
            sel = self.off_motor == m
            d[AXES[m]] = float((self.off_end_s[sel] - self.off_start_s[sel]).sum())
        return d

    def off_time_in_s(self, rows) -> dict:
        """Per motor letter, the part of the off time that falls in the steps ``rows`` (a bool
        mask over the problem's steps): e.g. the heat-up waits (``Kind.WAIT``), which a host that
        does not wait for its heaters (klippy's batch mode) passes in no time at all."""
        rows = np.asarray(rows, dtype=bool)
        d = {AXES[m]: 0.0 for m in self.problem.motors}
        if rows.shape != (self.problem.n_steps,) or not rows.any():
            return d
        t0 = self.problem.start_s[:-1][rows]
        t1 = self.problem.start_s[1:][rows]
        for m in self.problem.motors:
            sel = self.off_motor == m
            a, b = self.off_start_s[sel], self.off_end_s[sel]
            overlap = np.minimum(b[:, None], t1[None, :]) - np.maximum(a[:, None], t0[None, :])
            d[AXES[m]] = float(np.maximum(overlap, 0.0).sum())
        return d

    def steps_motor(self) -> np.ndarray:
        """(n, 4) which motors step in each row under this solution's rotation."""
        return steps_motor_at(self.problem, self.angle_index)[0]

    def pieces(self) -> Pieces:
        return scoring.pieces(self.problem, self.off_motor, self.off_start_s, self.off_end_s)

    def enable_pieces(self):
        """(row, duration_s, enable, stall) arrays: re-score with ``gatesopt.energy.step_energy_j``."""
        p = self.pieces()
        return p.row, p.duration_s, p.enable, p.stall

    def instructions(self) -> Instructions:
        return scoring.instructions(self.problem, self.off_motor, self.off_start_s, self.off_end_s)

    def summary(self) -> dict:
        """The solution's report (JSON keys as ``gatesopt solve --json`` has always written them)."""
        return {
            "formulation": self.formulation, "status": self.status,
            "energy_before_j": self.energy_before_j, "energy_after_j": self.energy_j,
            "saving_pct": self.saving_pct, "time_before_s": self.problem.time_before_s,
            "time_after_s": self.time_after_s, "lines_added": int(self.lines_added),
            "rotation_deg": self.rotation_deg, "center_xy": [float(v) for v in self.center_mm],
            "max_snap_mm": self.max_snap_mm, "off_time_s": self.off_time_s(),
            "bound": None if math.isnan(self.bound_j) else self.bound_j,
            "gap": None if math.isnan(self.gap) else self.gap, "solve_s": self.solve_s,
            "stopped": str(self.stopped), "message": self.message,
        }

    def __repr__(self) -> str:
        return (f"GatingSolution({self.formulation}, {self.status}, rot={self.rotation_deg:.4f}, "
                f"energy {self.energy_before_j:.1f} -> {self.energy_j:.1f} J ({self.saving_pct:.2f} %), "
                f"+{self.lines_added} lines, +{self.added_time_s:.3f} s, gap={self.gap:.2e})")



def make_solution(problem: GatingProblem, formulation: str, status: str, angle_index: int,
                  off_motor, off_start_s, off_end_s, *, bound_j=math.nan, solve_s=0.0,
                  message: str = "", stopped: Stopped = Stopped.NO) -> GatingSolution:
    """Score off intervals with the one energy model and wrap them (every formulation ends here)."""
    try:
        status = Status(status)
    except ValueError:
        raise ValueError(f"unknown status {status!r}") from None
    m, a, b = scoring.normalise(problem, off_motor, off_start_s, off_end_s)
    sc = scoring.score(problem, m, a, b)
    return GatingSolution(problem=problem, formulation=formulation, status=status,
                          angle_index=int(angle_index), off_motor=readonly(m.astype(np.int8)),
                          off_start_s=readonly(a), off_end_s=readonly(b), energy_j=sc.energy_j,
                          energy_before_j=problem.energy_before_j, lines_added=sc.lines_added,
                          added_time_s=sc.added_time_s, bound_j=float(bound_j),
                          gap=relative_gap(sc.energy_j, float(bound_j)),
                          solve_s=float(solve_s), message=message, stopped=Stopped(stopped))


def solution_from_idle(problem: GatingProblem, formulation: str, status: str, angle_index: int,
                       chosen: np.ndarray, **kw) -> GatingSolution:
    """A solution that switches off the idle intervals with indices ``chosen``, each whole."""
    chosen = np.asarray(chosen, np.int64)
    return make_solution(problem, formulation, status, angle_index, problem.idle_motor[chosen],
                         problem.idle_start_s[chosen], problem.idle_end_s[chosen], **kw)
