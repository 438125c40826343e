"""Travel as the reports measure it, on a parsed file (not the solver's model): every
non-extruding XY move (straight or arc) from the first layer on, its time under the paper's
T = L/F, and retractions (steps that pull filament back, and firmware retractions: a bare
``G10``), of them the wipes (retracting while moving in XY). Every report reads them here
(``rewrite.figures``: ``solve``, ``order``, ``batch``, ``compare``, the HTML report;
``ordering.plot``), so their numbers agree.

Counts are of *paths*: consecutive travel moves are one travel, consecutive retracting moves one
retraction, and motor lines between them (a gated file's instruction lines, which split a move in
two) do not separate them, so gating a file never changes its counts.
"""
from __future__ import annotations

import numpy as np

from ..program import Kind, Program
from .layout import firmware_retraction


#: an E move back by less than this is no retraction: the float noise of a slicer's rounded
#: retraction and unretraction (PrusaSlicer's -.76 -.04 +.8001), which a rebuilt travel keeps
#: (net E per gap is kept exactly: ``gaps.rebuilt_gap``) as ``G1 E-.00001``; counted, a free-mode
#: output showed 245 retractions more than it made
RETRACT_NOISE_MM = 1e-4


def travel_mask(program: Program) -> np.ndarray:
    """(n_steps,) bool: the travel moves the report counts: every non-extruding XY move
    (straight or arc) from the first layer on."""
    d = program.delta_mm
    xy = np.hypot(d[:, 0], d[:, 1])
    return ((program.layer >= 0) & ~program.extruding & np.isin(program.kind, (Kind.TRAVEL, Kind.ARC))
            & (xy > 0))


def runs(mask: np.ndarray, program: Program) -> int:
    """How many runs of consecutive True rows ``mask`` has, motor-line rows skipped (a motor line
    between two rows of a run does not end it)."""
    keep = program.kind != Kind.MOTOR
    m = np.asarray(mask, bool)[keep]
    return int((m & ~np.concatenate(([False], m[:-1]))).sum())


def travel_stats(program: Program) -> dict:
    """Travel distance/time, travel paths and retractions from the first layer on."""
    d = program.delta_mm
    printing = program.layer >= 0
    travel = travel_mask(program)
    retract = printing & (d[:, 3] < -RETRACT_NOISE_MM)
    # a retraction spread over several wipe moves counts once
    n_retract = runs(retract, program) + len(firmware_retraction_lines(program))
    # a wipe: the slicer's retraction while moving back over the last extrusion (XY and -E)
    wipe = retract & (np.hypot(d[:, 0], d[:, 1]) > 0)
    return {"travel_mm": float(program.length_mm[travel].sum()),
            "travel_s": float(program.duration_s[travel].sum()),
            # everything from the first layer on (paper time model): extrusion is the same in
            # both files, so a change is travel, retractions and z-hops together
            "print_s": float(program.duration_s[printing].sum()),
            "travels": runs(travel, program), "retractions": n_retract,
            "wipes": runs(wipe, program)}


def firmware_retraction_lines(program: Program) -> np.ndarray:
    """Lines of firmware retractions (a bare ``G10``, ``build.firmware_retraction``) from the
    first layer on: the firmware pulls the filament back, so no step shows it."""
    if not len(program.layer_line):
        return np.zeros(0, np.int64)
    lines = firmware_retraction(program)[0]
    return lines[lines >= program.layer_line[0]]
