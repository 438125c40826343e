"""Check 2, ``extrusion``: net filament per layer equal (see ``gatesopt.verify``)."""
from __future__ import annotations

import numpy as np

from ..program import MOTION_KINDS, Program
from .finding import Finding

E_REL_TOL = 1e-4


def _layer_e(program: Program) -> tuple[np.ndarray, np.ndarray]:
    """Net filament per layer (all E motion: extrusion, retraction, unretraction). Net, because a
    re-ordering may retract more or less often, and a move shorter than the single-axis snap
    may become an E-only move in a rotated output: neither changes what is deposited."""
    ext = np.isin(program.kind, MOTION_KINDS)
    de = program.end_mm[:, 3] - program.start_mm[:, 3]
    lay = program.layer[ext] + 1           # layer -1 -> bin 0
    n = max(program.n_layers + 1, int(lay.max()) + 1 if len(lay) else 1)
    return np.bincount(lay, weights=de[ext], minlength=n), np.arange(n) - 1


def check_extrusion(original: Program, output: Program, *, rel_tol: float = E_REL_TOL) -> list[Finding]:
    ea, layers = _layer_e(original)
    eb, _ = _layer_e(output)
    whole = original.n_layers != output.n_layers
    if whole:                   # the layer finder disagrees: compare the total
        ea, eb = ea.sum(keepdims=True), eb.sum(keepdims=True)
    n = max(len(ea), len(eb))
    ea = np.pad(ea, (0, n - len(ea)))
    eb = np.pad(eb, (0, n - len(eb)))
    bad = np.abs(ea - eb) > rel_tol * np.maximum(np.abs(ea), np.abs(eb)) + 1e-6
    out = []
    for k in np.flatnonzero(bad)[:5]:
        if whole:
            out.append(Finding("extrusion", None, f"whole print (layers found: {output.n_layers} in the "
                               f"output, {original.n_layers} in the original): net E {eb[k]:.5f} mm, "
                               f"original {ea[k]:.5f} mm"))
            continue
        L = k - 1
        rows = np.flatnonzero((output.layer == L) & output.extruding)
        line = int(output.line[rows[0]]) + 1 if len(rows) else None
        out.append(Finding("extrusion", line, f"layer {L}: net E {eb[k]:.5f} mm, original {ea[k]:.5f} mm"))
    return out
