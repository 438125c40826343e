"""Check ``ordering``: re-ordered G-code against its original (issue 4, "Verified on every output").

``geometry``: per layer, the multiset of extruded moves is the same up to direction — move by
move, without merging collinear pieces (re-ordering never splits a move, and merging is
order-dependent: a reversed piece next to a forward one would not merge as in the original).
A move is its two end points (ordered), arc centre and turning sense, and its E. Then the shared checks
(``verify.extrusion``, ``verify.commands``): E per layer equal, heater/tool commands (and fans other
than the part-cooling fan) in the same order; ``fan``: every extruded move sees the part-cooling fan
duty it saw in the original (emit re-issues M106 / M107); ``limits``: every extruded move runs
under the machine limits it ran under in the original (emit re-issues the limit lines); and
``barriers``: between two consecutive barrier lines (heaters, G92, tool changes, see
``gatesopt.ordering.layout``) each layer extrudes the same filament over the same path length in
both files — so no extrusion moved across a barrier. ``objects``: object labels
(``slicers.OBJECT_LABELS``; safe mode moves a labelled object's moves of a layer with its labels,
``ordering/blocks.py``) are not barriers but the regions they open: each layer extrudes the same
filament over the same path length inside each object's labels in both files (an extruded move's
object is, per label family, the one the last label line before it opened), and each layer has
the same label lines (a label line counts to the layer of the last extrusion before it).
"""
from __future__ import annotations

import numpy as np

from ..limits import KEYS, machine_limits
from ..ordering.layout import LINE_BARRIER, LINE_FATAL, Layout, layout
from ..program import Kind, Program
from ..slicers import LABEL_OPEN
from .commands import check_commands, fan_duty_s
from .extrusion import check_extrusion
from .finding import Finding


def _barrier_bins(program: Program, lay: Layout | None = None):
    lay = lay or layout(program)
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


def _bins_differ(ia, ib, m, e_a_rows, e_b_rows, s_a_rows, s_b_rows, arc_a_rows, rel_tol, snap_tol_mm):
    """Per bin (``ia`` / ``ib``: each extruding row's bin in the original / output, ``m`` bins) the
    extruded E and path length of both files, and the bins where they differ beyond the
    tolerances (relative, plus an allowance per arc and per snapped move): the comparison
    ``check_barriers`` and ``check_objects`` share."""
    e_a, s_a = np.bincount(ia, e_a_rows, m), np.bincount(ia, s_a_rows, m)
    e_b, s_b = np.bincount(ib, e_b_rows, m), np.bincount(ib, s_b_rows, m)
    n_arc = np.bincount(ia, arc_a_rows.astype(float), m)
    n_moves = np.bincount(ia, minlength=m) + np.bincount(ib, minlength=m)
    len_tol = (rel_tol * np.maximum(s_a, s_b) + 1e-3 + ARC_LENGTH_TOL_MM * n_arc
               + snap_tol_mm * n_moves)
    bad = ((np.abs(e_a - e_b) > rel_tol * np.maximum(np.abs(e_a), np.abs(e_b)) + 1e-6)
           | (np.abs(s_a - s_b) > len_tol))
    return np.flatnonzero(bad), e_a, e_b, s_a, s_b


def check_barriers(original: Program, output: Program, *, rel_tol: float = 1e-4,
                   snap_tol_mm: float = 0.0, lays: tuple | None = None) -> list[Finding]:
    """``snap_tol_mm``: how far a rotated output's snap may have moved each end point of a move
    (``gatesopt.verify.rotation.undone_tol``): each move's length may differ by twice that.
    ``lays``: both files' layouts, if made already."""
    lays = lays or (None, None)
    na, la, ba, ea, sa, arc_a = _barrier_bins(original, lays[0])
    nb, lb, bb, eb, sb, arc_b = _barrier_bins(output, lays[1])
    if na != nb:
        return [Finding("barriers", None, f"{nb} barrier lines in the output, {na} in the original")]
    out = []
    # per (layer, barrier bin) of either file: extruded E, path length, arc count (summed in
    # numpy over all extruding moves; sorted by layer, then bin)
    span = int(max(ba.max(initial=0), bb.max(initial=0))) + 1       # one int key per (layer, bin)
    key = np.concatenate([(la.astype(np.int64) + 1) * span + ba, (lb.astype(np.int64) + 1) * span + bb])
    key, inv = np.unique(key, return_inverse=True)
    keys = np.column_stack([key // span - 1, key % span])
    ia, ib = inv[:len(la)], inv[len(la):]
    bad, e_a, e_b, s_a, s_b = _bins_differ(ia, ib, len(keys), ea, eb, sa, sb, arc_a, rel_tol,
                                           snap_tol_mm)
    for i in bad[:5].tolist():
        out.append(Finding("barriers", None,
                           f"layer {keys[i, 0]}, after barrier line #{keys[i, 1]}: extruded E "
                           f"{e_b[i]:.5f} mm over {s_b[i]:.3f} mm, original {e_a[i]:.5f} mm over "
                           f"{s_a[i]:.3f} mm"))
    return out


def _object_bins(program: Program, lay: Layout, names: dict):
    """Per extruding row its object key (an int: ``names`` maps each label family's open
    object names, as met, to ids, combined over the families), and the label lines as
    (layer of the last extrusion before it, text)."""
    rows = np.flatnonzero(program.extruding)
    row_line = program.line[rows]
    key = np.zeros(len(rows), np.int64)
    fams = sorted({fam for fam, _, _ in lay.labels.values()})
    for f, fam in enumerate(fams):
        at = sorted(i for i, lab in lay.labels.items() if lab[0] == fam)
        ids = [names.setdefault((fam, lab[2]), len(names) + 1) if lab[1] == LABEL_OPEN else 0
               for lab in (lay.labels[i] for i in at)]
        k = np.searchsorted(np.asarray(at, np.int64), row_line, side="right") - 1
        state = np.where(k >= 0, np.asarray([0] + ids, np.int64)[k + 1], 0)
        key = key * 1_000_003 + state + f
    lines = np.asarray(sorted(lay.labels), np.int64)
    j = np.searchsorted(row_line, lines, side="left") - 1
    lab_layer = np.where(j >= 0, program.layer[rows[np.maximum(j, 0)]], -1)
    texts = sorted((int(L), program.line_text(int(i)).strip()) for L, i in zip(lab_layer, lines))
    return rows, key, texts


def unique_pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``column_stack([a, b])`` (int64) in lexicographic order and each
    row's index among them: ``np.unique(..., axis=0, return_inverse=True)``, through one int64
    key per row (a's rank, then b's rank: the same order), which sorts several times faster."""
    ua, ra = np.unique(a, return_inverse=True)
    ub, rb = np.unique(b, return_inverse=True)
    nb = max(len(ub), 1)
    flat, inv = np.unique(np.ravel(ra).astype(np.int64) * nb + np.ravel(rb), return_inverse=True)
    pair = np.column_stack([ua[flat // nb], ub[flat % nb]]).astype(np.int64, copy=False)
    return pair, np.ravel(inv)


def check_objects(original: Program, output: Program, *, rel_tol: float = 1e-4,
                  snap_tol_mm: float = 0.0, lays: tuple | None = None) -> list[Finding]:
    """Each layer extrudes the same filament over the same path length inside each object's
    labels, and has the same label lines, in both files (module docstring). ``lays``: as for
    ``check_barriers``."""
    lay_a, lay_b = lays or (layout(original), layout(output))
    if not lay_a.labels and not lay_b.labels:
        return []
    names: dict = {}
    ra, ka, ta = _object_bins(original, lay_a, names)
    rb, kb, tb = _object_bins(output, lay_b, names)
    out = []
    if ta != tb:
        la = {}
        for L, t in ta:
            la[(L, t)] = la.get((L, t), 0) + 1
        for L, t in tb:
            la[(L, t)] = la.get((L, t), 0) - 1
        bad = sorted(k for k, v in la.items() if v)[:3]
        for L, t in bad:
            out.append(Finding("objects", None, f"layer {L}: object label '{t}' {la[(L, t)]:+d} "
                                                "times in the original than in the output"))
    key = np.concatenate([original.layer[ra].astype(np.int64), output.layer[rb].astype(np.int64)])
    obj = np.concatenate([ka, kb])
    pair, inv = unique_pairs(key, obj)
    ia, ib = inv[:len(ra)], inv[len(ra):]
    bad, e_a, e_b, s_a, s_b = _bins_differ(
        ia, ib, len(pair), original.end_mm[ra, 3] - original.start_mm[ra, 3],
        output.end_mm[rb, 3] - output.start_mm[rb, 3], original.length_mm[ra],
        output.length_mm[rb], original.kind[ra] == Kind.ARC, rel_tol, snap_tol_mm)
    for i in bad[:5].tolist():
        out.append(Finding("objects", None,
                           f"layer {pair[i, 0]}, inside object labels #{pair[i, 1]}: extruded E "
                           f"{e_b[i]:.5f} mm over {s_b[i]:.3f} mm, original {e_a[i]:.5f} mm over "
                           f"{s_a[i]:.3f} mm"))
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


def _sorted_rows(k: np.ndarray) -> np.ndarray:
    """The rows of ``k`` in lexicographic order (two multisets of rows are equal iff these are)."""
    return k[np.lexsort(k.T[::-1])]


#: odd 64-bit multipliers of ``_row_hash`` (any fixed odd numbers: a collision only sends a layer
#: to the exact move-by-move comparison)
_HASH_MUL = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9,
                      0xD6E8FEB86659FD93, 0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53,
                      0x94D049BB133111EB, 0xBF58476D1CE4E5B9, 0x2545F4914F6CDD1D,
                      0x9FB21C651E98DF25, 0x85EBCA77C2B2AE63, 0xA0761D6478BD642F], np.uint64)


def _row_hash(q: np.ndarray) -> np.ndarray:
    """One uint64 per row of the int64 matrix ``q`` (a mixed sum of its columns)."""
    with np.errstate(over="ignore"):
        h = np.zeros(len(q), np.uint64)
        for j in range(q.shape[1]):
            h += q[:, j].astype(np.uint64) * _HASH_MUL[j % len(_HASH_MUL)]
            h ^= h >> np.uint64(29)
    return h


#: bits of ``_by_layer``'s sort key taken from the row's hash (the layer above them)
KEY_HASH_BITS = 40


def _by_layer(layer: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The rows of ``column_stack([layer, q])`` sorted by layer, then by a hash of the row: two
    layers hold the same multiset of rows iff their sorted rows are equal, except where rows of
    equal hash but different values lie in another order (a collision of the hash's top
    ``KEY_HASH_BITS`` bits), which only makes the layer look different: ``_layers_differing``
    then says it differs, and the exact move-by-move comparison the caller runs on such layers
    decides. (A lexicographic sort of the 12 columns took ~0.13 s per file of 600 k moves; one
    key sorts several times faster. Layer and hash in one uint64 sorted once: 0.6x the time of
    sorting by the two, 42 vs 72 ms on prusa25_xend_honey25_acp's 204 k moves.)"""
    rows = np.column_stack([layer, q]).astype(np.int64, copy=False)
    h = _row_hash(q)
    lay = rows[:, 0]
    lo = int(lay.min()) if len(lay) else 0
    if len(lay) and int(lay.max()) - lo >= 1 << (64 - KEY_HASH_BITS):
        return rows[np.lexsort((h, lay))]           # (more layers than the key holds)
    key = (((lay - lo).astype(np.uint64) << np.uint64(KEY_HASH_BITS))
           | (h >> np.uint64(64 - KEY_HASH_BITS)))
    return rows[np.argsort(key)]


def _layers_differing(layer_a, qa, layer_b, qb) -> np.ndarray:
    """The layers whose multisets of move keys may differ (every layer whose multisets differ,
    and rarely one whose do not: ``_by_layer``), found by sorting both files' (layer, key) rows:
    a layer with the same rows in the same sorted order holds the same moves, so only the others
    need the move-by-move matching below (a per-move Python loop over every layer took ~1 s on
    a 67 k-curve file)."""
    a = _by_layer(layer_a, qa)
    b = _by_layer(layer_b, qb)
    layers = np.union1d(layer_a, layer_b)
    a_at = np.searchsorted(a[:, 0], layers, side="left"), np.searchsorted(a[:, 0], layers, side="right")
    b_at = np.searchsorted(b[:, 0], layers, side="left"), np.searchsorted(b[:, 0], layers, side="right")
    differ = []
    for i, L in enumerate(layers.tolist()):
        if not np.array_equal(a[a_at[0][i]:a_at[1][i]], b[b_at[0][i]:b_at[1][i]]):   # shape too
            differ.append(L)
    return np.asarray(differ, layers.dtype)


def _near_misses(ka: np.ndarray, kb: np.ndarray, left_a: list, left_b: list, tol_mm: float):
    """Near misses (text rounding at a grid boundary): each of ``left_b`` in turn takes the first
    of ``left_a`` still untaken whose key is within ``tol_mm`` in every column; (``left_a`` not
    taken, ``left_b`` that took none). Candidates come from a window of ``tol_mm`` on the first
    column (a search over the sorted column): the scan of every pair (a generator with
    ``np.all`` per pair) took 95 s on a fresh Slic3r slice whose output had merged layers
    (thousands of unmatched moves a layer), so a refused file was reported ~90 s late."""
    if not left_b or not left_a:
        return left_a, list(left_b)
    la = np.asarray(left_a, np.int64)
    keys = ka[la]
    order = np.argsort(keys[:, 0], kind="stable")
    first = keys[order, 0]
    taken = np.zeros(len(la), bool)
    still_b = []
    for j in left_b:
        k = kb[j]
        lo = np.searchsorted(first, k[0] - tol_mm, side="left")
        hi = np.searchsorted(first, k[0] + tol_mm, side="right")
        cand = order[lo:hi]
        cand = cand[~taken[cand]]
        cand = cand[np.all(np.abs(keys[cand] - k) <= tol_mm, axis=1)]
        if len(cand):
            taken[cand.min()] = True        # the first in ``left_a``'s order, as a scan takes
        else:
            still_b.append(j)
    return la[~taken].tolist(), still_b


def check_geometry(original: Program, output: Program, *, tol_mm: float = 1e-3,
                   keys=None) -> list[Finding]:
    """``keys``: both files' ``_move_keys`` (``check`` computes them once for every check)."""
    out = []
    (ra, qa, ka), (rb, qb, kb) = keys or (_move_keys(original, 1e-4), _move_keys(output, 1e-4))
    for L in _layers_differing(original.layer[ra], qa, output.layer[rb], qb):
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
        left_a, still_b = _near_misses(ka, kb, left_a, left_b, tol_mm)
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


def _moves_keep(original: Program, output: Program, val_a: np.ndarray, val_b: np.ndarray, keys,
                max_findings: int, finding) -> list[Finding]:
    """Every extruded move of ``output`` carries the value row (``val_b``, per extruded move) its
    move carried in ``original`` (``val_a``): per layer whose moves are the same (the others
    are the geometry check's), matched move by move. ``finding(L, j, got, want)`` makes the
    finding for output move j (``want``: an unmatched original value of that move, or None)."""
    (ra, qa, _), (rb, qb, _) = keys
    la, lb = original.layer[ra], output.layer[rb]
    out = []
    for L in _layers_differing(la, np.column_stack([qa, val_a]), lb,
                               np.column_stack([qb, val_b])).tolist():
        ia, ib = np.flatnonzero(la == L), np.flatnonzero(lb == L)
        if not np.array_equal(_sorted_rows(qa[ia]), _sorted_rows(qb[ib])):     # shape too
            continue                    # its moves differ: the geometry check's finding
        want: dict = {}
        for i in ia.tolist():
            want.setdefault(qa[i].tobytes(), []).append(val_a[i].tobytes())
        for j in ib.tolist():
            seen = want[qb[j].tobytes()]
            got = val_b[j].tobytes()
            if got in seen:
                seen.remove(got)
                continue
            was = np.frombuffer(seen[0], np.int64) if seen else None
            out.append(finding(L, j, val_b[j], was))
            break
        if len(out) >= max_findings:
            break
    return out


def check_fan(original: Program, output: Program, *, max_findings: int = 3,
              keys=None) -> list[Finding]:
    """Every extruded move sees the part-cooling fan duty it saw in the original (the parser's
    modal ``fan``; emit re-issues M106 / M107 where a re-ordered curve would see another value).
    Layers whose moves differ are the geometry check's; the others are compared move by move.
    ``keys``: as for ``check_geometry``."""
    keys = keys or (_move_keys(original, 1e-4), _move_keys(output, 1e-4))
    (ra, _, _), (rb, _, _) = keys
    duty_a = fan_duty_s(original, ra).reshape(-1, 1)
    duty_b = fan_duty_s(output, rb).reshape(-1, 1)

    def finding(L, j, got, was):
        return Finding("fan", int(output.line[rb[j]]) + 1,
                       f"layer {L}: extruded move with the part fan at S{int(got[0])}, "
                       f"at S{int(was[0]) if was is not None else '?'} in the original")
    return _moves_keep(original, output, duty_a, duty_b, keys, max_findings, finding)


#: the machine limits that bear on an extruded move (``limits.KEYS``): all but the travel's and
#: the retraction's own, which a re-ordering may change with the travels it rebuilds
_EXTRUDING_LIMITS = tuple(i for i, k in enumerate(KEYS)
                          if k not in ("accel_travel", "accel_retract", "min_travel_feed"))


def limits_at(program: Program, rows: np.ndarray,
              family: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(table, at): the machine limits in force at steps ``rows`` that bear on an extruded move
    (``_EXTRUDING_LIMITS``: the file's M201-M205 / SET_VELOCITY_LIMIT lines over its defaults,
    ``limits.machine_limits`` under ``family``'s rules, None: the file's own) are ``table[at[i]]``
    at ``rows[i]``, in thousandths (inf as -1), as compared; one row of ``table`` per regime of
    the file (``MachineLimits.regimes``: a few thousand rows where a slicer writes an M204 per
    feature, against hundreds of thousands of moves)."""
    table, at = machine_limits(program, family=family).regimes_at(
        program.line[np.asarray(rows, np.int64)])
    table = table[:, _EXTRUDING_LIMITS]
    finite = np.isfinite(table)
    table = np.where(finite, np.round(np.where(finite, table, 0.0) * 1000.0), -1.0).astype(np.int64)
    return table, at


def check_limits(original: Program, output: Program, *, max_findings: int = 3,
                 keys=None) -> list[Finding]:
    """Every extruded move runs under the machine limits it ran under in the original
    (acceleration, jerk / junction deviation / square corner velocity, velocity caps): the emitter
    re-issues the slicer's limit lines where a re-ordered curve would meet another feature's
    (``writer.Writer.reissue``; a bridge moved after a wall printed at the wall's corner velocity
    before it did so per parameter: real_crealityprint514 free, 2.95 s slower). Compared as
    ``check_fan`` compares the fan, each move's limits as one number: the index of its row among
    the distinct rows of both files' regime tables (equal rows, equal numbers; the move-wide rows
    sorted per layer took ~1 s on a 200,000-move PrusaSlicer file). ``keys``: as for
    ``check_geometry``."""
    keys = keys or (_move_keys(original, 1e-4), _move_keys(output, 1e-4))
    (ra, _, _), (rb, _, _) = keys
    names = [KEYS[i] for i in _EXTRUDING_LIMITS]
    # both under the original's planner rules: the lines gating adds (a SET_STEPPER_ENABLE
    # forced onto a Marlin file) would change the output's default family, not its limits
    family = machine_limits(original).firmware
    (ta, at_a), (tb, at_b) = limits_at(original, ra, family), limits_at(output, rb, family)
    values, ids = np.unique(np.concatenate([ta, tb]), axis=0, return_inverse=True)
    ids = ids.ravel()

    def finding(L, j, got, was):
        got = values[int(got[0])]
        was = values[int(was[0])] if was is not None else None
        k = int(np.flatnonzero(was != got)[0]) if was is not None else 0
        orig = f"{was[k] / 1000:g}" if was is not None else "?"
        return Finding("limits", int(output.line[rb[j]]) + 1,
                       f"layer {L}: extruded move with {names[k]} = {got[k] / 1000:g}, "
                       f"{orig} in the original")
    return _moves_keep(original, output, ids[:len(ta)][at_a].reshape(-1, 1),
                       ids[len(ta):][at_b].reshape(-1, 1), keys, max_findings, finding)


#: the checks ``check`` shares with ``gatesopt.verify.verify``, which runs them on every output
SHARED_CHECKS = ("extrusion", "commands")


#: a layer change that climbs more than this (mm) above both layers is a clearance lift (a
#: one-at-a-time print leaving an object, Cura's ``G0 X.. Y.. Z10``): the output's must climb as
#: high (``check_clearance``; z-hops are a few tenths of a millimetre)
CLEARANCE_LIFT_MM = 1.0


def _layer_change_tops(program: Program) -> dict:
    """Per change between extruding layers (a, b): (the highest Z of the steps after a's last
    extruding step up to b's first, the higher of the two layers' Z, b's first step)."""
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    if len(ext) < 2:
        return {}
    lay = program.layer[ext]
    at = np.flatnonzero(np.diff(lay) != 0)
    last, first = ext[at], ext[at + 1]
    z = program.end_mm[:, 2]
    # max over z[last:first + 1] per change (a sentinel after the last step keeps first + 1 a
    # valid index; the spans between changes are reduced too, and dropped)
    top = (np.maximum.reduceat(np.append(z, -np.inf), np.stack([last, first + 1], 1).ravel())[::2]
           if len(at) else np.zeros(0))
    return {(int(lay[i]), int(lay[i + 1])): (float(t), max(float(z[a]), float(z[b])), int(b))
            for i, t, a, b in zip(at.tolist(), top.tolist(), last.tolist(), first.tolist())}


def check_clearance(original: Program, output: Program, *, tol_mm: float = 1e-3) -> list[Finding]:
    """Each layer change where the original lifts over what is printed (more than
    ``CLEARANCE_LIFT_MM`` above both layers) climbs as high in the output: a travel re-built
    lower would cross the object just printed at its top's height."""
    want, got = _layer_change_tops(original), _layer_change_tops(output)
    out = []
    for key, (top, z, _) in want.items():
        if top - z <= CLEARANCE_LIFT_MM:
            continue
        have = got.get(key)
        if have is None or have[0] < top - tol_mm:
            line = int(output.line[have[2]]) + 1 if have is not None else None
            out.append(Finding("clearance", line,
                               f"layer {key[0]} -> {key[1]}: the original lifts to Z{top:g} over "
                               f"what is printed, the output only to "
                               f"Z{have[0] if have else float('nan'):g}"))
    return out


def check_moves(original: Program, output: Program) -> list[Finding]:
    """The re-ordering's own checks, move by move: ``check`` without ``SHARED_CHECKS`` (for
    ``verify``, which has run those: one finding per fault)."""
    keys = (_move_keys(original, 1e-4), _move_keys(output, 1e-4))
    lays = (layout(original), layout(output))
    return (check_geometry(original, output, keys=keys) + check_fan(original, output, keys=keys)
            + check_limits(original, output, keys=keys)
            + check_barriers(original, output, lays=lays) + check_objects(original, output, lays=lays)
            + check_clearance(original, output))


def check(original: Program, output: Program, original_layout: Layout | None = None) -> list[Finding]:
    """All findings for a re-ordered output (empty list: it prints what the original printed).
    ``original_layout``: ``layout(original)``, where the caller has it (the ordering problem's)."""
    keys = (_move_keys(original, 1e-4), _move_keys(output, 1e-4))
    lays = (original_layout or layout(original), layout(output))
    return (check_geometry(original, output, keys=keys) + check_extrusion(original, output)
            # the fan move by move (check_fan) implies the per-layer filament by fan duty that
            # check_commands would check too: one finding per fault, the stricter one
            + check_commands(original, output, reordered=True, fan_duty=False)
            + check_fan(original, output, keys=keys) + check_limits(original, output, keys=keys)
            + check_barriers(original, output, lays=lays) + check_objects(original, output, lays=lays)
            + check_clearance(original, output))
