"""Verify re-ordered G-code against its original (issue 4, "Verified on every output").

``geometry``: per layer, the multiset of extruded moves is the same up to direction — move by
move, without merging collinear pieces (re-ordering never splits a move, and merging is
order-dependent: a reversed piece next to a forward one would not merge as in the original).
A move is its two end points (ordered), arc centre and turning sense, and its E. Then the shared checks
of ``gatesopt.verify`` (``Finding``): E per layer equal, heater/fan/tool commands in the same
order; and
``barriers``: between two consecutive barrier lines (heaters, fan, G92, object labels, tool
changes, see ``gatesopt.ordering.build``) each layer extrudes the same filament over the same
path length in both files — so no extrusion moved across a barrier.
"""
from __future__ import annotations

import numpy as np

from .. import verify as _v
from ..program import Kind, Program
from .build import LINE_BARRIER, LINE_FATAL, layout

Finding = _v.Finding


def _barrier_bins(program: Program):
    lay = layout(program)
    is_b = (lay.line_class == LINE_BARRIER) | (lay.line_class == LINE_FATAL)
    count = np.concatenate(([0], np.cumsum(is_b)))
    ext = program.extruding
    rows = np.flatnonzero(ext)
    bins = count[program.line[rows]]
    d = program.end_mm[rows] - program.start_mm[rows]
    return (int(is_b.sum()), program.layer[rows], bins, d[:, 3], program.length_mm[rows],
            program.kind[rows] == Kind.ARC)


#: path-length allowance per arc move: a slicer rounds an arc's end point, so it lies up to half a
#: unit of the last digit off the circle; printed reversed, the arc is drawn around the same centre
#: from that end, and its length differs by up to |dr| * sweep (measured: 0.004 mm on a Bambu
#: Studio layer of 531 arcs; 2*pi * 1.5e-3 < 0.01)
ARC_LENGTH_TOL_MM = 0.01


def check_barriers(original: Program, output: Program, *, rel_tol: float = 1e-4) -> list[Finding]:
    na, la, ba, ea, sa, arc_a = _barrier_bins(original)
    nb, lb, bb, eb, sb, arc_b = _barrier_bins(output)
    if na != nb:
        return [Finding("barriers", None, f"{nb} barrier lines in the output, {na} in the original")]
    out = []
    keys_a = {}
    for L, B, e, s, arc in zip(la.tolist(), ba.tolist(), ea.tolist(), sa.tolist(), arc_a.tolist()):
        k = keys_a.setdefault((L, B), [0.0, 0.0, 0])
        k[0] += e
        k[1] += s
        k[2] += arc
    keys_b = {}
    for L, B, e, s in zip(lb.tolist(), bb.tolist(), eb.tolist(), sb.tolist()):
        k = keys_b.setdefault((L, B), [0.0, 0.0])
        k[0] += e
        k[1] += s
    for key in sorted(set(keys_a) | set(keys_b)):
        a = keys_a.get(key, [0.0, 0.0, 0])
        b = keys_b.get(key, [0.0, 0.0])
        len_tol = rel_tol * max(a[1], b[1]) + 1e-3 + ARC_LENGTH_TOL_MM * a[2]
        if (abs(a[0] - b[0]) > rel_tol * max(abs(a[0]), abs(b[0])) + 1e-6
                or abs(a[1] - b[1]) > len_tol):
            out.append(Finding("barriers", None,
                               f"layer {key[0]}, after barrier line #{key[1]}: extruded E {b[0]:.5f} mm over "
                               f"{b[1]:.3f} mm, original {a[0]:.5f} mm over {a[1]:.3f} mm"))
            if len(out) >= 5:
                break
    return out


def _move_keys(program: Program, q: float):
    rows = np.flatnonzero(program.extruding)
    a = program.start_mm[rows, :3]
    b = program.end_mm[rows, :3]
    first_is_a = (a[:, 0] < b[:, 0]) | ((a[:, 0] == b[:, 0]) & ((a[:, 1] < b[:, 1]) | (
        (a[:, 1] == b[:, 1]) & (a[:, 2] <= b[:, 2]))))
    lo = np.where(first_is_a[:, None], a, b)
    hi = np.where(first_is_a[:, None], b, a)
    centre = np.nan_to_num(program.arc_center_mm[rows], nan=0.0)
    arc = program.kind[rows] == Kind.ARC
    # an arc is its end points, centre and turning sense; reversed, the sense flips with the ends
    sense = np.where(arc, np.where(program.arc_ccw[rows] == first_is_a, 1.0, -1.0), 0.0)
    de = program.end_mm[rows, 3] - program.start_mm[rows, 3]
    k = np.concatenate([lo, hi, centre, sense[:, None], de[:, None] * 10], axis=1)
    return rows, np.round(k / q).astype(np.int64), k


def check_geometry(original: Program, output: Program, *, tol_mm: float = 1e-3) -> list[Finding]:
    out = []
    ra, qa, ka = _move_keys(original, 1e-4)
    rb, qb, kb = _move_keys(output, 1e-4)
    for L in np.union1d(np.unique(original.layer[ra]), np.unique(output.layer[rb])):
        ia = np.flatnonzero(original.layer[ra] == L)
        ib = np.flatnonzero(output.layer[rb] == L)
        ta = {}
        for i in ia:
            ta.setdefault(qa[i].tobytes(), []).append(i)
        left_b = []
        for j in ib:
            lst = ta.get(qb[j].tobytes())
            if lst:
                lst.pop()
            else:
                left_b.append(j)
        left_a = [i for v in ta.values() for i in v]
        # near misses (text rounding at a grid boundary): match within tol
        still_b = []
        for j in left_b:
            hit = next((t for t, i in enumerate(left_a) if np.all(np.abs(ka[i] - kb[j]) <= tol_mm)), None)
            if hit is None:
                still_b.append(j)
            else:
                left_a.pop(hit)
        for i in left_a[:3]:
            k = ka[i]
            out.append(Finding("geometry", int(original.line[ra[i]]) + 1,
                               f"layer {L}: extruded move ({k[0]:.3f},{k[1]:.3f})-({k[3]:.3f},{k[4]:.3f}) "
                               "of the original is not in the output", in_original=True))
        for j in still_b[:3]:
            k = kb[j]
            out.append(Finding("geometry", int(output.line[rb[j]]) + 1,
                               f"layer {L}: extruded move ({k[0]:.3f},{k[1]:.3f})-({k[3]:.3f},{k[4]:.3f}) "
                               "is not in the original"))
        if len(out) >= 10:
            break
    return out


def check(original: Program, output: Program) -> list[Finding]:
    """All findings for a re-ordered output (empty list: it prints what the original printed)."""
    return (check_geometry(original, output) + _v.check_extrusion(original, output)
            + _v.check_commands(original, output, reordered=True) + check_barriers(original, output))
