"""Rotation of the print on the bed (formulations/gating.md §6): which rows rotate, about which
centre, the candidate angles and the policy that keeps 0 deg (a print of objects one at a time, a
file that gates its own motors, a bed the rotated print does not fit).

3DGates (Chen et al., ASPLOS'17) Section 4.3 turns the model in 30 deg steps (Algorithm 1 lines
6-8, ``greedy_angle``); ``candidate_angles`` adds the angles that make the print's moves single-axis,
exactly (45 deg, and the slicer's infill angle where its rounded coordinates scatter the moves'
directions around it).

A rotation moves the print on the bed, so it needs the bed (issue 37): from ``--bed WxD``
(``GatingOptions.bed_size_mm``) or the file (``slicers.read_bed``: PrusaSlicer's ``bed_shape``,
Orca's ``printable_area``, ...). Without one the print stays where the slicer put it. With one,
a rotated print must keep ``BED_MARGIN_MM`` from the bed's edges, or as much as the slicer's own
placement kept where that is less (``RotationPlan``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import firmware as fw_mod
from .. import slicers
from ..errors import InfeasibleError
from ..program import Kind, Program, X, Y
from . import _kernels as _k

#: a rotated print keeps at least this far (mm) from the bed's edges -- a bed clip, a wipe past
#: the part's edge -- or as far as the slicer's own placement kept, where that is less (the
#: slicer's placement shows what its printer profile allows); ``GatingOptions.bed_margin_mm``
#: sets it instead
BED_MARGIN_MM = 5.0
#: the exact angles always among the candidates (mod 90): the paper's 30-degree steps and 45
BASE_ANGLES_DEG = (0.0, 30.0, 45.0, 60.0)
#: a candidate this close (deg) to a whole degree is tried at the whole degree too: slicers write
#: lines at their infill angle (45, 60, ...) and round the coordinates, which scatters the moves'
#: directions by up to ~1e-3 deg around it
WHOLE_DEGREE_DEG = 0.05

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


def candidate_angles(start_mm, end_mm, duration_s, steps0, arc, lo, hi, center, opts, asym):
    """Rotation candidates (degrees in [0, 90), or [0, 180) when X and Y are not symmetric).

    An XY move of direction theta runs on one axis after rotating by (-theta mod 90); energy is
    piecewise constant in the angle and can only improve where a move becomes single-axis, so the
    optimum (snap tolerance 0, no bed limit) is one of these angles. We keep the ``max_angles`` with
    the most single-axis time (each cluster's whole degree too, where it scatters around one),
    plus ``BASE_ANGLES_DEG`` (the paper's 30-degree sweep modulo 90, and 45).
    See formulations/gating.md "Rotation".
    """
    base = list(BASE_ANGLES_DEG)
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
        # the whole degree a cluster of directions scatters around (the slicer's infill angle)
        # stands for the cluster where it makes at least as much time single-axis
        whole = np.round(reps)
        for i in np.flatnonzero((np.abs(reps - whole) <= WHOLE_DEGREE_DEG) & (reps != whole)):
            sw = single_time(whole[i])
            if sw >= scores[i]:
                reps[i], scores[i] = whole[i], sw
        reps, first_rep = np.unique(reps, return_index=True)
        scores = scores[first_rep]
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


def refuse_sequential_angle(program: Program, rotate) -> None:
    """Raise ``InfeasibleError`` (at the line of ``program`` where the print goes back down) for an
    explicit angle other than 0 on a print of objects one at a time (``sequential_drop``). Run
    on the file as given, before it is re-ordered (``rewrite.pipeline.run``): the line is then
    the user's, and no time goes to an ordering the rotation would refuse."""
    if _explicit_angle(rotate):
        _refuse_angle(program, sequential_drop(program, *rotated_rows(program)), rotate)


def _explicit_angle(rotate) -> bool:
    """An angle other than 0 asked for by number (not "auto", "none")."""
    return rotate not in ("auto", "none") and float(rotate) % 360.0 != 0.0


def _refuse_angle(program: Program, drop, rotate) -> None:
    """Raise ``InfeasibleError`` at ``drop`` (``sequential_drop``; None: nothing) for ``rotate``."""
    if drop is not None:
        raise InfeasibleError(f"{_where(program, drop[0])}: {_sequential_words(drop)}; "
                              f"rotating it by {float(rotate):g} deg could drive the print head into "
                              f"an object already printed: use --rotate none")


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


# -- the bed -----------------------------------------------------------------------------------------
def bed_of(program: Program, options) -> slicers.Bed | None:
    """The bed a rotated print must stay on: ``options.bed_size_mm`` (``--bed WxD``, from 0, 0),
    else ``options.bed`` (the user's file's, where ``program`` is a rewritten copy whose line
    numbers differ), else the one the file names (``slicers.read_bed``), else
    ``program.header["bed_size_mm"]`` (``gating.from_moves``), else None."""
    if options.bed_size_mm is not None:
        w, d = options.bed_size_mm
        return slicers.rectangle_bed(0.0, 0.0, w, d, "--bed")
    if options.bed is not None:
        return options.bed
    bed = slicers.read_bed(program.data) if len(program.data) else None
    if bed is None and program.header.get("bed_size_mm") is not None:
        w, d = (float(v) for v in program.header["bed_size_mm"])
        x0, y0 = (float(v) for v in program.header.get("bed_min_mm", (0.0, 0.0)))
        bed = slicers.rectangle_bed(x0, y0, x0 + w, y0 + d, "header")
    return bed


def _edges(polygon) -> tuple[np.ndarray, np.ndarray]:
    """(m, 2) outward unit normals and (m,) offsets of the convex hull of ``polygon``: a point p
    is inside iff n . p <= c on every edge, and c - n . p is its distance to that edge. (Beds are
    rectangles and circles; a non-convex custom bed is taken as its hull.)"""
    pts = np.asarray(polygon, float)
    try:
        from scipy.spatial import ConvexHull
        pts = pts[ConvexHull(pts).vertices]          # counter-clockwise
    except Exception:                               # degenerate: keep the polygon as given
        area = np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1])
        if area < 0:
            pts = pts[::-1]
    d = np.roll(pts, -1, axis=0) - pts
    n = np.column_stack((d[:, 1], -d[:, 0]))        # right of a ccw edge: outward
    L = np.hypot(n[:, 0], n[:, 1])
    keep = L > 0
    n = n[keep] / L[keep, None]
    return n, np.einsum("ij,ij->i", n, pts[keep])


@dataclass(frozen=True, eq=False)
class PrintOutline:
    """What of rows [lo, hi) can reach the bed's edge: the convex hull of their end points (the
    farthest point in any direction is one of them) and the arcs, whose bulge lies between."""

    hull_mm: np.ndarray         # (k, 2)
    arc_start_mm: np.ndarray    # (a, 2)
    arc_end_mm: np.ndarray
    arc_center_mm: np.ndarray
    arc_ccw: np.ndarray         # (a,) bool


def print_outline(program: Program, lo: int, hi: int) -> PrintOutline:
    pts = np.asarray(program.end_mm[lo:hi, :2], float)
    if len(pts) >= 3:
        try:
            from scipy.spatial import ConvexHull
            pts = pts[ConvexHull(pts).vertices]
        except Exception:                           # collinear or too few: every point
            pass
    arcs = np.flatnonzero(program.kind[lo:hi] == Kind.ARC) + lo
    arcs = arcs[arcs > lo]                          # the first row's start is not rotated
    return PrintOutline(pts, np.asarray(program.start_mm[arcs, :2], float),
                        np.asarray(program.end_mm[arcs, :2], float),
                        np.asarray(program.arc_center_mm[arcs], float), np.asarray(program.arc_ccw[arcs], bool))


def clearance_mm(outline: PrintOutline, bed: slicers.Bed, center, deg: float) -> float:
    """The least distance from the print rotated by ``deg`` about ``center`` to the bed's edges
    (negative: that far outside it). An arc reaches out to ``centre + r n`` in the direction n of
    an edge where that lies within its sweep, else as far as its end points."""
    n, c = _edges(bed.polygon_mm)
    if not len(n):
        return math.inf
    pts = rotate_points(outline.hull_mm, center, deg) if len(outline.hull_mm) else np.zeros((0, 2))
    reach = (pts @ n.T).max(axis=0) if len(pts) else np.full(len(n), -math.inf)
    if len(outline.arc_center_mm):
        s = rotate_points(outline.arc_start_mm, center, deg)
        e = rotate_points(outline.arc_end_mm, center, deg)
        cc = rotate_points(outline.arc_center_mm, center, deg)
        r = np.hypot(*(s - cc).T)
        a0 = np.arctan2(*(s - cc).T[::-1])
        a1 = np.arctan2(*(e - cc).T[::-1])
        two_pi = 2.0 * math.pi
        sweep = np.where(outline.arc_ccw, np.mod(a1 - a0, two_pi), np.mod(a0 - a1, two_pi))
        sweep = np.where(sweep <= 1e-12, two_pi, sweep)          # start == end: a full circle
        for k in range(len(n)):
            phi = math.atan2(n[k, 1], n[k, 0])
            off = np.where(outline.arc_ccw, np.mod(phi - a0, two_pi), np.mod(a0 - phi, two_pi))
            ends = np.maximum(s @ n[k], e @ n[k])
            far = np.where(off <= sweep, cc @ n[k] + r, ends)
            reach[k] = max(reach[k], float(far.max()))
    return float((c - reach).min())


@dataclass(frozen=True)
class RotationPlan:
    """The rotation candidates of a file and what decided them (``rotation_candidates``)."""

    angles_deg: tuple           # candidates that fit the bed (0 always, the slicer's placement)
    how: str                    # "auto" | "fixed" | "none"
    why_none: str = ""          # why the print stays at 0 deg whatever the solver says ("" if it may turn)
    bed: slicers.Bed | None = None
    margin_mm: float = math.nan         # kept from the bed's edges by a rotated print
    slicer_clearance_mm: float = math.nan   # what the slicer's own placement kept
    notes: tuple = ()

    def clearance_words(self, clearance: float) -> str:
        """e.g. "fits the 250 x 210 mm bed (bed_shape, line 24627) with 5 mm margin (12.3 mm to
        the nearest edge; the slicer kept 48.1 mm)"."""
        return (f"fits the {self.bed.describe()} with {self.margin_mm:.3g} mm margin ({clearance:.1f} mm "
                f"to the nearest edge; the slicer's placement kept {self.slicer_clearance_mm:.1f} mm)")


def _kept_unrotated(program: Program, options, lo: int, hi: int, notes: list) -> bool:
    """True where the print must stay as the slicer placed it: objects printed one at a time
    (``sequential_drop``) or a file that switches an X/Y motor off itself (``own_xy_disable``).
    An explicit angle other than 0 raises ``InfeasibleError`` at that line; "auto" gets a note."""
    o = options
    drop = sequential_drop(program, lo, hi)
    if _explicit_angle(o.rotate):
        _refuse_angle(program, drop, o.rotate)
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
                        duration_s, steps0, arc) -> RotationPlan:
    """The rotation candidates of ``options.rotate`` for rows [lo, hi) about ``center``: "none":
    0; a number: that angle; "auto": ``candidate_angles``, each only where the rotated print fits
    the bed (``bed_of``) with the margin (a candidate that does not fit is replaced by itself +
    180 deg, and +-90 deg when X and Y are symmetric, ``asym`` False, if that fits). No bed: 0 only
    under "auto" (an angle is refused). Raises ``InfeasibleError`` for an angle that the policy
    forbids (``_kept_unrotated``) or that does not fit."""
    o = options
    gated = o.motor_index
    notes: list[str] = []
    kept = _kept_unrotated(program, o, lo, hi, notes)
    if o.rotate == "none":
        return RotationPlan((0.0,), "none", "--rotate none", notes=tuple(notes))
    how = "auto" if o.rotate == "auto" else "fixed"
    fixed = None if how == "auto" else float(o.rotate) % 360.0
    if hi <= lo or not (X in gated or Y in gated):
        return RotationPlan((0.0,), how, "no X/Y motor gated" if hi > lo else "nothing printed", notes=tuple(notes))
    if kept:
        return RotationPlan((0.0,), how, notes[-1] if notes else "kept as the slicer placed it", notes=tuple(notes))
    if fixed == 0.0:
        return RotationPlan((0.0,), how, f"--rotate {o.rotate}", notes=tuple(notes))
    if not o.check_bed:         # a model experiment: every candidate, no bed
        angles = (fixed,) if fixed is not None else tuple(candidate_angles(
            program.start_mm, program.end_mm, duration_s, steps0, arc, lo, hi, center, o, asym))
        return RotationPlan(angles, how, notes=tuple(notes) + ("rotation not checked against a bed (check_bed=False)",))
    bed = bed_of(program, o)
    if bed is None:
        if fixed is not None:
            raise InfeasibleError(f"{program.source}: --rotate {float(o.rotate):g}: the bed size is unknown (the "
                                  "file names none): give --bed WxD so the rotated print can be checked against it")
        return RotationPlan((0.0,), how, "bed size unknown: --bed WxD to allow it", notes=tuple(notes))
    outline = print_outline(program, lo, hi)
    c0 = clearance_mm(outline, bed, center, 0.0)
    if c0 < -1e-6:
        msg = (f"the print reaches {-c0:.1f} mm past the edge of the {bed.describe()}: not the bed it "
               "was sliced for? (--bed WxD)")
        if fixed is not None:
            raise InfeasibleError(f"{program.source}: --rotate {fixed:g}: {msg}")
        return RotationPlan((0.0,), how, msg, bed, notes=tuple(notes))
    margin = float(o.bed_margin_mm) if o.bed_margin_mm is not None else min(BED_MARGIN_MM, c0)
    plan = dict(bed=bed, margin_mm=margin, slicer_clearance_mm=c0, notes=tuple(notes))
    if fixed is not None:
        c = clearance_mm(outline, bed, center, fixed)
        if c < margin - 1e-6:
            raise InfeasibleError(
                f"{program.source}: the print rotated by {fixed:g} deg about ({center[0]:.3f}, {center[1]:.3f}) "
                f"does not fit the {bed.describe()} with {margin:.3g} mm margin ({c:.1f} mm to its edge)")
        return RotationPlan((fixed,), how, **plan)
    angles = []
    for cand in candidate_angles(program.start_mm, program.end_mm, duration_s, steps0, arc, lo, hi,
                                 center, o, asym):
        # a quarter turn more keeps the single-axis structure (swapping X and Y): try those if the
        # angle itself does not fit the bed
        for t in [cand, cand + 180.0] + ([] if asym else [cand + 90.0, cand + 270.0]):
            t = t % 360.0
            if t == 0.0 or clearance_mm(outline, bed, center, t) >= margin - 1e-6:
                angles.append(t)
                break
    return RotationPlan(tuple(angles), how, **plan)
