"""Where the instruction lines go: ``Switch``es (time, motor, on) and a ``GatingSolution``'s
instructions placed among the program's steps, as ``Placed`` groups or as arrays
(``PlacedArrays``) for the compiled emitter.

A moment on a step boundary goes right before the step that starts there; one strictly inside a
step splits it at that fraction of its duration (3DGates, Chen et al., ASPLOS'17, Algorithm 1
lines 11-16: "X -> X1 + S Y on + X2").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..program import AXES, Program, X, Y
from .problem import steps_motor_at

#: switches this close in time (s) and of one direction are one moment (one line group)
SWITCH_EPS_S = 1e-9


@dataclass(frozen=True)
class Switch:
    """One motor instruction: at ``time_s`` (paper time from program start) ``motor`` goes on/off."""

    time_s: float
    motor: int          # 0..3 = X Y Z E
    on: bool


@dataclass(frozen=True)
class Placed:
    """One instruction line group placed in the program (what ``render`` writes).

    ``fraction`` None: the lines go right before step ``row`` (``row == n_steps``: after the last
    step); else step ``row`` is split at that fraction of its duration and the lines go between.
    """

    time_s: float
    row: int
    on: bool
    motors: tuple           # motor letters
    fraction: float | None = None


@dataclass(frozen=True, eq=False)
class PlacedArrays:
    """``Placed`` groups as arrays, one entry each: what the unrotated emitter works on."""

    time_s: np.ndarray      # (k,) float
    row: np.ndarray         # (k,) int64
    on: np.ndarray          # (k,) bool
    motor_mask: np.ndarray  # (k,) uint8: bit m = motor AXES[m]
    split: np.ndarray       # (k,) bool: ``fraction`` is given (``Placed.fraction`` not None)
    fraction: np.ndarray    # (k,) float

    @classmethod
    def from_placed(cls, placed) -> "PlacedArrays":
        k = len(placed)
        return cls(np.fromiter((pl.time_s for pl in placed), float, k),
                   np.fromiter((pl.row for pl in placed), np.int64, k),
                   np.fromiter((pl.on for pl in placed), bool, k),
                   np.fromiter((sum(1 << AXES.index(m) for m in set(pl.motors)) for pl in placed), np.uint8, k),
                   np.fromiter((pl.fraction is not None for pl in placed), bool, k),
                   np.fromiter((0.0 if pl.fraction is None else pl.fraction for pl in placed), float, k))

    def to_placed(self) -> list[Placed]:
        return [Placed(float(t), int(r), bool(on), tuple(a for m, a in enumerate(AXES) if mask >> m & 1),
                       float(f) if s else None)
                for t, r, on, mask, s, f in zip(self.time_s, self.row, self.on, self.motor_mask.tolist(),
                                                 self.split, self.fraction)]

    def motors(self) -> list[str]:
        """Every motor letter switched, in X Y Z E order."""
        bits = int(np.bitwise_or.reduce(self.motor_mask)) if len(self.motor_mask) else 0
        return [a for m, a in enumerate(AXES) if bits >> m & 1]


def place_switches(program: Program, switches) -> list[Placed]:
    """Group ``Switch``es into instruction moments and locate each in the program's steps.

    Same time (within 1 ns) and same direction -> one moment. A moment on a step boundary goes
    right before the step that starts there; one strictly inside a step splits it.
    """
    items = sorted(((float(s.time_s), bool(s.on), int(s.motor)) for s in switches))
    moments: list[list] = []
    for t, on, m in items:
        if moments and moments[-1][1] == on and abs(moments[-1][0] - t) <= SWITCH_EPS_S:
            moments[-1][2].add(AXES[m])
        else:
            moments.append([t, on, {AXES[m]}])
    dur = np.asarray(program.duration_s, float)
    t_end = np.cumsum(dur)
    t_start = t_end - dur
    n = program.n_steps
    out = []
    for t, on, ms in moments:
        motors = tuple(a for a in AXES if a in ms)
        i = int(np.searchsorted(t_end, t + SWITCH_EPS_S, side="right"))
        if i >= n:
            out.append(Placed(t, n, on, motors))
        elif t <= t_start[i] + SWITCH_EPS_S:
            out.append(Placed(t, i, on, motors))
        else:
            out.append(Placed(t, i, on, motors, (t - t_start[i]) / dur[i]))
    return out


def solution_placed(solution) -> list[Placed]:
    """The solution's instruction lines (``GatingSolution.instructions()``) as ``Placed`` groups."""
    ins = solution.instructions()
    out = []
    for k in range(len(ins.time_s)):
        motors = tuple(AXES[m] for m in ins.motors[k])
        frac = float(ins.fraction[k]) if bool(ins.split[k]) else None
        out.append(Placed(float(ins.time_s[k]), int(ins.row[k]), bool(ins.on[k]), motors, frac))
    return out


def solution_snap(solution) -> np.ndarray | None:
    """(n, 2) bool: X/Y of rows the solution takes as not stepping under its rotation."""
    prob = solution.problem
    if float(solution.rotation_deg) % 360.0 == 0.0:
        return None
    steps, _ = steps_motor_at(prob, solution.angle_index)
    xy0 = (prob.steps_motor0[:, X] | prob.steps_motor0[:, Y]) & ~prob.arc
    return ~steps[:, :2] & xy0[:, None]


def solution_arrays(solution) -> PlacedArrays:
    """``solution_placed`` as arrays (no object per instruction line)."""
    ins = solution.instructions()
    return PlacedArrays(np.asarray(ins.time_s, float), np.asarray(ins.row, np.int64), np.asarray(ins.on, bool),
                        np.asarray(ins.motor_mask, np.uint8), np.asarray(ins.split, bool),
                        np.asarray(ins.fraction, float))
