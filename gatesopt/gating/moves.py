"""A gating problem from another planner's move arrays (no G-code): ``from_moves``.

The moves become a minimal ``Program`` (no text) so that the energy profile prices them as it
prices a parsed file; ``problem.build`` does the rest.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..energy import PowerCoefficients
from ..program import Kind, Program
from .options import GatingOptions
from .problem import GatingProblem, build


def _moves_program(start_mm, end_mm, duration_s, extruding=None, source="<moves>", layer=None) -> Program:
    """A minimal Program over another planner's move arrays (no G-code), for the energy profile."""
    s = np.zeros((len(start_mm), 4))
    e = np.zeros((len(end_mm), 4))
    s[:, : np.shape(start_mm)[1]] = start_mm
    e[:, : np.shape(end_mm)[1]] = end_mm
    n = len(s)
    d = e - s
    if extruding is None:
        extruding = d[:, 3] > 0
    extruding = np.asarray(extruding, bool)
    kind = np.full(n, Kind.TRAVEL, np.int8)
    xyz = np.any(d[:, :3] != 0, axis=1)
    kind[extruding & xyz] = Kind.EXTRUDE
    kind[~xyz & (d[:, 3] < 0)] = Kind.RETRACT
    kind[~xyz & (d[:, 3] > 0)] = Kind.UNRETRACT
    kind[~xyz & (d[:, 3] == 0)] = Kind.DWELL
    kind[(d[:, 2] != 0) & (d[:, 0] == 0) & (d[:, 1] == 0) & (d[:, 3] == 0)] = Kind.Z_ONLY
    dur = np.asarray(duration_s, float)
    length = np.linalg.norm(d[:, :3], axis=1)
    z = np.zeros(n)
    kw = dict(
        source=source, data=b"", line_start=np.arange(n + 1, dtype=np.int64), line=np.arange(n, dtype=np.int64),
        kind=kind, start_mm=s, end_mm=e, feed_mm_s=np.where(dur > 0, length / np.where(dur > 0, dur, 1), 0),
        length_mm=length, duration_s=dur,
        layer=np.zeros(n, np.int32) if layer is None else np.asarray(layer, np.int32),
        feature=np.full(n, -1, np.int16),
        fan=z.astype(np.float32), hotend_c=np.full(n, 200, np.float32), bed_c=np.full(n, 60, np.float32),
        arc_center_mm=np.full((n, 2), np.nan), arc_ccw=np.zeros(n, bool), offset_mm=np.zeros((n, 4)),
        relative_xyz=np.zeros(n, bool), relative_e=np.zeros(n, bool), inch=np.zeros(n, bool),
        enabled=np.ones((n, 4), bool), line_letter=np.full(n, ord("G"), np.uint8),
        line_number=np.ones(n, np.float32))
    names = {f.name for f in dataclasses.fields(Program)}
    return Program(**{k: v for k, v in kw.items() if k in names})


def from_moves(start_mm, end_mm, duration_s, options: GatingOptions | None = None, *, extruding=None,
               coeffs: PowerCoefficients | None = None, stall_coeffs: PowerCoefficients | None = None,
               bed_size_mm=None, layer=None, source: str = "<moves>") -> GatingProblem:
    """A problem from another planner's move arrays (no G-code).

    ``start_mm``/``end_mm``: (n, 2..4) X Y [Z [E]] in absolute mm; ``duration_s``: (n,) the planner's
    own times; ``layer`` (n,) optional layer index per move (the greedy groups by layer).
    ``coeffs`` overrides the profile's coefficients (e.g. measured powers); by default the profile
    in ``options`` prices each move as extrusion (ΔE > 0 or ``extruding``) or travel.
    """
    options = options or GatingOptions()
    program = _moves_program(np.atleast_2d(np.asarray(start_mm, float)),
                             np.atleast_2d(np.asarray(end_mm, float)), duration_s, extruding, source, layer)
    if bed_size_mm is not None:
        program = program.replace(header={"bed_size_mm": tuple(bed_size_mm)})
    # the caller's own times, whatever the options' time model
    return build(program, options, duration_s=program.duration_s, coeffs=coeffs, stall_coeffs=stall_coeffs,
                 rotate_rows=(0, program.n_steps))
