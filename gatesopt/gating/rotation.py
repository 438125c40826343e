"""Rotation of the print on the bed (formulations/gating.md §6): which rows rotate, about which
centre, the candidate angles and the policy that keeps 0 deg (a print of objects one at a time, a
file that gates its own motors, a bed the rotated print does not fit).

3DGates (Chen et al., ASPLOS'17) Section 4.3 turns the model in 30 deg steps (Algorithm 1 lines
6-8, ``greedy_angle``); ``candidate_angles`` adds the angles that make the print's moves single-axis.
"""
from __future__ import annotations

import math

import numpy as np

from .. import firmware as fw_mod
from ..errors import InfeasibleError
from ..program import Kind, Program, X, Y
from . import _kernels as _k

def rotation_matrix(deg: float) -> np.ndarray:
    """Counter-clockwise rotation; exact for multiples of 90 degrees."""
    k, r = divmod(float(deg), 90.0)
    if r == 0.0:
        c, s = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(k) % 4]
    else:
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def rotate_points(p, center, deg):
    """Points (k, 2) rotated counter-clockwise by ``deg`` about ``center``."""
    (c, ms), (s, c2) = rotation_matrix(deg)
    x = p[:, 0] - center[0]
    y = p[:, 1] - center[1]
    return np.column_stack((c * x + ms * y + center[0], s * x + c2 * y + center[1]))

def steps_at(start_mm, end_mm, steps0, arc, lo, hi, center, deg, snap_mm):
    """((n, 4) bool steps, (n,) snapped other-axis displacement) under rotation ``deg`` of rows
    [lo, hi) about ``center`` (``problem.steps_motor_at`` for a built problem).

    At a non-zero angle an XY displacement below ``snap_mm`` is taken as zero: the emitter must
    write that coordinate exactly equal to the previous one (DESIGN.md "Rotation")."""
    if deg % 360.0 == 0.0 or hi <= lo:
        return steps0, np.zeros(len(steps0))
    (c, _), (s, _) = rotation_matrix(deg)
    steps = np.array(steps0, copy=True, order="C")
    xy = np.empty((len(steps0), 2), bool)
    snapped = np.empty(len(steps0))
    _k.rotated_steps(np.ascontiguousarray(start_mm[:, :2]), np.ascontiguousarray(end_mm[:, :2]),
                     np.ascontiguousarray(steps0), np.ascontiguousarray(arc), int(lo), int(hi),
                     float(center[0]), float(center[1]), float(c), float(s), float(snap_mm), xy, snapped)
    steps[:, :2] = xy
    return steps, snapped


def greedy_angle(angles_deg, straight_moves) -> int:
    """3DGates Algorithm 1 lines 6-8: among the 30-degree steps (0 always is one), the angle with the
    most straight X + Y moves; the first on a tie. A fixed --rotate angle is the only choice."""
    deg = np.asarray(angles_deg, float)
    steps30 = np.flatnonzero(np.abs(deg / 30.0 - np.round(deg / 30.0)) < 1e-9)
    if len(steps30) == 0:
        steps30 = np.arange(len(deg))
    return int(steps30[np.argmax(np.asarray(straight_moves)[steps30])])


def bed_fits(start_mm, end_mm, lo, hi, center, deg, bed) -> bool:
    """Every rotated end point of rows [lo, hi) lies on the ``bed`` (W, H) mm; no bed: True."""
    if bed is None or hi <= lo or deg % 360.0 == 0.0:
        return True         # the slicer's own placement is taken as valid
    pts = rotate_points(end_mm[lo:hi, :2], center, deg)
    tol = 1e-6
    return bool(pts.min() >= -tol and pts[:, 0].max() <= bed[0] + tol and pts[:, 1].max() <= bed[1] + tol)


def candidate_angles(start_mm, end_mm, duration_s, steps0, arc, lo, hi, center, opts, asym):
    """Rotation candidates (degrees in [0, 90), or [0, 180) when X and Y are not symmetric).

    An XY move of direction theta runs on one axis after rotating by (-theta mod 90); energy is
    piecewise constant in the angle and can only improve where a move becomes single-axis, so the
    optimum (snap tolerance 0, no bed limit) is one of these angles. We keep the ``max_angles`` with
    the most single-axis time, plus 0, 30, 60 (the paper's 30-degree sweep modulo 90).
    See formulations/gating.md "Rotation".
    """
    base = [0.0, 30.0, 60.0]
    rows = np.arange(lo, hi)
    d = end_mm[rows, :2] - start_mm[rows, :2]
    L = np.hypot(d[:, 0], d[:, 1])
    ok = (L > opts.snap_mm) & ~arc[rows] & (steps0[rows, X] | steps0[rows, Y])
    d, L, w = d[ok], L[ok], duration_s[rows][ok]
    cands = list(base)
    if len(L):
        theta = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
        a = np.mod(-theta, 90.0)
        a[a >= 90.0 - 1e-9] = 0.0
        # coarse bins of 1e-3 degree, weighted by time; the representative of a bin is the angle of
        # its longest move (the narrowest snap window)
        key = np.round(a * 1000.0).astype(np.int64)
        uk, inv = np.unique(key, return_inverse=True)
        wt = np.bincount(inv, weights=w)
        top = np.argsort(-wt, kind="stable")[: 2 * opts.max_angles]
        order = np.lexsort((-L, inv))
        first = order[np.searchsorted(inv[order], np.arange(len(uk)))]
        reps = np.round(a[first[top]], 6)
        # exact single-axis time of each representative (snap tolerance), keep the best
        dx, dy, wc = np.ascontiguousarray(d[:, 0]), np.ascontiguousarray(d[:, 1]), np.ascontiguousarray(w)

        def single_time(deg):
            t = np.radians(deg)
            return _k.single_axis_time(dx, dy, wc, math.cos(t), math.sin(t), float(opts.snap_mm))
        scores = np.array([single_time(r) for r in reps])
        best = reps[np.argsort(-scores, kind="stable")][: opts.max_angles]
        cands += [float(b) for b in best]
    out = []
    for c in cands:
        c = float(np.round(c % 90.0, 6))
        if c >= 90.0:
            c = 0.0
        if all(abs(c - o) > 1e-6 for o in out):
            out.append(c)
    if asym:
        out = out + [c + 90.0 for c in out]
    return out

def rotated_run_end(program: Program, hi: int) -> int:
    """The first row at or after ``hi`` whose end point a rotation leaves where the slicer put it:
    where the rotated run [lo, hi) really ends.

    A caller ends the run at the first XY move after the print (``rotated_rows``); that
    row is the transition (its start rotated, its end not). That is right for an absolute move,
    which names a position on the bed (parking, "present print"). It is wrong for a relative move
    (G91): "G1 X5 Y5" means 5 mm from where the head *is*, and after the rotated print the head
    is in the rotated frame -- Cura's end G-code "G91 / G1 X5 Y5 ;Wipe out" would otherwise be
    written as a travel to where the *unrotated* print ended, dragging the nozzle across the top
    of the print. So relative XY moves (lines and arcs), and rows that leave X/Y where they are,
    carry the rotation on: their end is rotated too, i.e. their XY delta is turned by the
    rotation alone. The run ends at the first row that sets X/Y to a position of its own: an
    absolute (G90) move or homing. Rows that do not move X/Y are passed over whatever their mode.
    """
    n = int(program.n_steps)
    hi = int(hi)
    if hi >= n:
        return n
    kind = program.kind[hi:]
    moves_xy = (program.end_mm[hi:, :2] != program.start_mm[hi:, :2]).any(axis=1) | (kind == Kind.ARC)
    own = moves_xy & ((kind == Kind.HOME) | ~np.asarray(program.relative_xyz[hi:], bool))
    k = np.flatnonzero(own)
    return hi + int(k[0]) if len(k) else n


def rotated_rows(program: Program) -> tuple[int, int]:
    """Rows whose end point a rotation moves: from the XY move that reaches the first extrusion of
    the print (layer >= 0) up to, not including, the first move after the last extrusion that
    sets X/Y to a position of its own (an absolute move or homing). Those two are the
    transitions (one end rotated, one not); start and end G-code (purge line, parking) stay where
    the slicer put them. Relative (G91) moves after the print -- Cura's end G-code "G91 / G1 X5 Y5
    ;Wipe out" -- are inside the run: they move the head *from* the rotated print, so their XY
    delta is rotated (``rotated_run_end``); ending the run at such a move would make it a
    travel to where the unrotated print ended."""
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    if not len(ext):
        return 0, 0
    steps = program.steps_motor()
    xy = (steps[:, X] | steps[:, Y]) & (program.kind != Kind.HOME)   # arcs step both; homing stays
    before = np.flatnonzero(xy[: ext[0]])
    lo = int(before[-1]) if len(before) else int(ext[0])
    hi = rotated_run_end(program, int(ext[-1]) + 1)
    return lo, hi


#: an extrusion this far below the highest one before it means the print went back down to the
#: bed: objects printed one after the other (PrusaSlicer "complete_objects", Cura "one at a
#: time"). Z-hops do not extrude and a layer is at most ~0.3 mm, so 1 mm is no ordinary layer.
SEQUENTIAL_DROP_MM = 1.0


def sequential_drop(program: Program, lo: int, hi: int):
    """(row, z_mm, z_max_mm) of the first extrusion in rows [lo, hi) that lies more than
    SEQUENTIAL_DROP_MM below an earlier extrusion, or None. Such a print was laid out by the
    slicer so that the print head (an asymmetric shape: Cura's head polygon, the gantry) clears
    the objects already printed, in this position on the bed: a rotation does not keep that."""
    ext = np.flatnonzero(program.extruding[lo:hi]) + lo
    if len(ext) < 2:
        return None
    z = program.end_mm[ext, 2]
    high = np.maximum.accumulate(z)
    down = np.flatnonzero(z[1:] < high[:-1] - SEQUENTIAL_DROP_MM)
    if not len(down):
        return None
    i = int(down[0]) + 1
    return int(ext[i]), float(z[i]), float(high[i - 1])


def _sequential_words(drop) -> str:
    return (f"objects are printed one at a time (the print goes back down to Z={drop[1]:g} "
            f"after Z={drop[2]:g})")


def own_xy_disable(program: Program, lo: int, hi: int):
    """The first row in [lo, hi) whose own motor line switches the X or Y motor off
    (``firmware.xy_disable_rows``: a gated file, gatesopt's output or the paper's re-compiler's),
    or None. Such lines were placed for the moves of that file's X and Y axes; rotated, the moves
    each motor makes change, and the lines would hold a motor off while it steps."""
    rows = fw_mod.xy_disable_rows(program)
    # a disable after the last X/Y step (the slicer's closing 'M84 X Y E', with no move after it
    # in the run) holds nothing off that steps: the print is over
    steps = program.steps_motor()
    xy = np.flatnonzero((steps[:, X] | steps[:, Y])[lo:hi])
    last_xy = lo + int(xy[-1]) if len(xy) else lo
    rows = rows[(rows >= lo) & (rows < min(hi, last_xy))]
    return int(rows[0]) if len(rows) else None


def _where(program: Program, row: int) -> str:
    return f"{program.source}:{int(program.line[row]) + 1}"


def rotation_center(program: Program, lo: int, hi: int) -> np.ndarray:
    """(2,) the XY bounding-box centre of the extruding moves in rows [lo, hi) (0, 0 if none)."""
    ext = np.flatnonzero(program.extruding[lo:hi]) + lo
    if not len(ext):
        return np.zeros(2)
    pts = np.concatenate((program.start_mm[ext, :2], program.end_mm[ext, :2]))
    return (pts.min(axis=0) + pts.max(axis=0)) / 2.0


def bed_size_mm(program: Program, options) -> tuple[float, float] | None:
    """The bed a rotated print must fit: ``options.bed_size_mm``, else the file's header, else None
    (no bed check)."""
    bed = options.bed_size_mm
    if bed is None and program.header.get("bed_size_mm") is not None:
        bed = tuple(float(v) for v in program.header["bed_size_mm"])
    return bed


def _kept_unrotated(program: Program, options, lo: int, hi: int, notes: list) -> bool:
    """True where the print must stay as the slicer placed it: objects printed one at a time
    (``sequential_drop``) or a file that switches an X/Y motor off itself (``own_xy_disable``).
    An explicit angle other than 0 raises ``InfeasibleError`` at that line; "auto" gets a note."""
    o = options
    drop = sequential_drop(program, lo, hi)
    if drop is not None and o.rotate not in ("auto", "none") and float(o.rotate) % 360.0 != 0.0:
        raise InfeasibleError(f"{_where(program, drop[0])}: {_sequential_words(drop)}; "
                              f"rotating it by {float(o.rotate):g} deg could drive the print head into "
                              f"an object already printed: use --rotate none")
    if drop is not None and o.rotate == "auto":
        notes.append(f"rotation kept at 0 deg: {_sequential_words(drop)} "
                     f"({_where(program, drop[0])}); rotated, the print head could hit an object "
                     f"already printed")
    own_off = None if o.rotate == "none" or hi <= lo else own_xy_disable(program, lo, hi)
    if own_off is not None:
        line = program.line_text(int(program.line[own_off])).strip()[:40]
        if o.rotate != "auto" and float(o.rotate) % 360.0 != 0.0:
            raise InfeasibleError(
                f"{_where(program, own_off)}: the file switches an X/Y motor off inside the print "
                f"itself ({line!r}: already gated?); rotated by {float(o.rotate):g} deg, that line "
                "would hold a motor off while it steps: use --rotate none, or gate the slicer's "
                "original")
        notes.append(f"rotation kept at 0 deg: the file switches an X/Y motor off inside the print "
                     f"itself ({_where(program, own_off)}: {line!r}; already gated?); rotated, "
                     "that line would hold a motor off while it steps")
    return drop is not None or own_off is not None


def rotation_candidates(program: Program, options, lo: int, hi: int, center, asym: bool,
                        duration_s, steps0, arc) -> tuple[list[float], list[str]]:
    """(angles that fit the bed, notes): the candidates of ``options.rotate`` ("none": 0; a number:
    that angle; "auto": ``candidate_angles``) for rows [lo, hi) about ``center``. Under "auto" a
    candidate that does not fit the bed is replaced by itself + 180 deg (and +-90 deg when X and Y
    are symmetric, ``asym`` False) if that fits, else dropped. Raises ``InfeasibleError`` when no
    angle fits (an explicit one) or the policy forbids an explicit angle (``_kept_unrotated``)."""
    o = options
    gated = o.motor_index
    notes: list[str] = []
    kept = _kept_unrotated(program, o, lo, hi, notes)
    if o.rotate == "none" or hi <= lo or not (X in gated or Y in gated) or kept:
        cands = [0.0]
    elif o.rotate == "auto":
        cands = candidate_angles(program.start_mm, program.end_mm, duration_s, steps0, arc, lo, hi,
                                 center, o, asym)
    else:
        cands = [float(o.rotate) % 360.0]
    bed = bed_size_mm(program, o)
    angles = []
    for c in cands:
        # a quarter turn more keeps the single-axis structure (swapping X and Y): try those if the
        # angle itself does not fit the bed
        tries = [c] if o.rotate != "auto" else [c, c + 180.0] + ([] if asym else [c + 90.0, c + 270.0])
        for t in tries:
            t = t % 360.0
            if bed_fits(program.start_mm, program.end_mm, lo, hi, center, t, bed):
                angles.append(t)
                break
    if not angles:
        raise InfeasibleError(f"{program.source}: the print rotated by {cands[0]:g} deg about "
                              f"({center[0]:.3f}, {center[1]:.3f}) does not fit the {bed[0]:g} x {bed[1]:g} mm bed")
    return angles, notes
