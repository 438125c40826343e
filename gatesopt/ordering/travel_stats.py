"""Travel as the reports measure it, on a parsed file (not the solver's model): every
non-extruding XY move (straight or arc) from the first layer on, its time under the paper's
T = L/F, and retractions (steps that pull filament back, and firmware retractions: a bare
``G10``). ``gatesopt order``'s and ``gatesopt solve``'s reports and ``ordering.plot`` read them here,
so their numbers agree.
"""
from __future__ import annotations

import numpy as np

from ..program import Kind, Program
from .layout import firmware_retraction


def travel_mask(program: Program) -> np.ndarray:
    """(n_steps,) bool: the travel moves the report counts: every non-extruding XY move
    (straight or arc) from the first layer on."""
    d = program.delta_mm
    xy = np.hypot(d[:, 0], d[:, 1])
    return ((program.layer >= 0) & ~program.extruding & np.isin(program.kind, (Kind.TRAVEL, Kind.ARC))
            & (xy > 0))


def travel_stats(program: Program) -> dict:
    """Travel distance/time, travel moves and retractions from the first layer on."""
    d = program.delta_mm
    printing = program.layer >= 0
    travel = travel_mask(program)
    retract = printing & (d[:, 3] < 0)
    # a retraction spread over several wipe moves counts once
    starts = retract & ~np.concatenate(([False], retract[:-1]))
    n_retract = int(starts.sum()) + len(firmware_retraction_lines(program))
    return {"travel_mm": float(program.length_mm[travel].sum()),
            "travel_s": float(program.duration_s[travel].sum()),
            # everything from the first layer on (paper time model): extrusion is the same in
            # both files, so a change is travel, retractions and z-hops together
            "print_s": float(program.duration_s[printing].sum()),
            "travels": int(travel.sum()), "retractions": n_retract}


def firmware_retraction_lines(program: Program) -> np.ndarray:
    """Lines of firmware retractions (a bare ``G10``, ``build.firmware_retraction``) from the
    first layer on: the firmware pulls the filament back, so no step shows it."""
    if not len(program.layer_line):
        return np.zeros(0, np.int64)
    lines = firmware_retraction(program)[0]
    return lines[lines >= program.layer_line[0]]
