"""Independent verifier: re-parse an emitted file and prove it prints what the original printed.

DESIGN.md "Verification": every output, every test. The checks trust nothing the solver says; they
read the two Programs (``gatesopt.parse`` of the original and of the output) and:

1. ``geometry``: per layer, the extruded moves are the same after undoing the declared rotation
   (``; gatesopt: rotate_deg=`` header): a multiset of segments up to direction (so a re-ordered
   curve, printed either way, matches), matched within ``geometry_tol_mm``; arcs as arcs (end
   points + centre). On the output side, runs of continuous collinear pieces separated only by
   motor instruction lines (a split move) are joined back, taking from each piece the longest
   stretch that is a move of the original -- so an instruction inserted *between* two original
   moves never merges them. Moves shorter than ``SHORT_MM`` are below any printer's resolution
   and not reported.
2. ``extrusion``: net E per layer equal (relative ``e_rel_tol``).
3. ``commands``: for gating output every original line that is not a motion is still there,
   unchanged and in order (only motor instructions and the rotation header may be added); for
   re-ordered output the heater and tool commands (and fans other than the part-cooling fan)
   keep their order, and each layer extrudes as much filament at each part-fan duty as before
   (the re-ordering re-issues M106 / M107 where a curve needs it).
4. ``timing``: no motor steps while a motor instruction holds it off (on firmware that needs an
   explicit enable), each explicit enable comes at least ``start_ahead_s`` before the motor's next
   step, and no disable comes within ``end_late_s`` of the motor's last step (3DGates Sec. 4.4,
   instruction inertia and delay). Times are the paper's T = L/F (Eq. 2) without stalls: a stall
   only adds time between an instruction and the moves around it, so this is the strict reading.
4b. ``firmware`` (run before ``timing``): every motor enable/disable line the rewrite added (the
   original's own lines, a slicer's closing ``M84``, are not checked) is one the firmware carries
   out as gating means it: in its dialect (``Firmware.off_word`` / ``on_word``: no ``M18 X`` for
   Klipper, which turns every stepper off, no ``S0`` for stock firmware, which does not know it),
   on a motor it may gate (``allowed_motors``: RepRapFirmware's ``M18 X`` unhomes X) and keeping
   the axis homed (``homing_kept``), all read from ``gatesopt.firmware``.
5. ``energy``: energy and time of the output, recomputed from its text with the one energy model
   (``gatesopt.energy.step_energy_j``, stall times from ``gatesopt.firmware.stall_durations``),
   agree with what the solver claimed within ``claim_rel_tol``.
6. ``positions`` (gating output, not re-ordered): every move of the original -- travels, wipes,
   z-hops, start and end G-code too, not only the extruded segments ``geometry`` sees -- ends in
   the output where the original's move ends, either as written or under the declared rotation
   (start and end G-code stay put, the print turns), positions as the parser resolves them in
   both files; and a relative (G91) move that starts in the rotated frame ends in it: its XY
   delta is the rotated delta. (A relative wipe written as a travel to where the *unrotated*
   print ended lands on a point of the original and passes every other check.)

Findings carry the 1-based line number in the output file (or the original, said so).

A gated file of millions of lines is checked in bulk, with the same answers as a line-by-line
reading: lines are compared as bytes in a compiled walk (``gatesopt._text``), each distinct text of
a motor instruction is parsed once, a split move is joined back in one lookup when its whole run is
a move of the original, and a layer whose segments are exactly the original's, none repeated, is
matched without a k-d tree (``gatesopt._rowset``); everything else takes the general path.
"""
from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from . import _rowset, _text
from . import firmware as fwmod
from .energy import load_profile, step_energy_j
from .errors import GatesoptError
from .program import AXES, MOTION_KINDS, Kind, Program

# 1 um: the single-axis snap of a rotated output (<= 1e-3 mm) plus the 0.05 um rounding of its text
GEOMETRY_TOL_MM = 1.1e-3
SHORT_MM = 5e-3        # unmatched extruded moves shorter than this are not reported (see check_geometry)
E_REL_TOL = 1e-4
# The emitted text has finite resolution (split points 0.01 um, rotated points 0.1 um); 20 us is
# about 1 % of the 1.8 ms start-ahead and covers 0.1 um of rounding at 5 mm/s.
TIME_TOL_S = 2e-5
CLAIM_REL_TOL = 1e-6
_JOIN_ANGLE_RAD = 2e-3
ROTATE_PREFIX = "; gatesopt: rotate_deg="
ORDER_PREFIX = "; gatesopt: order"
CONTROL_COMMANDS = (("M", 104), ("M", 109), ("M", 140), ("M", 190), ("M", 141), ("M", 191),
                    ("M", 106), ("M", 107),
                    # progress and display messages: a re-ordering moves them with curves, but
                    # their sequence must stay the slicer's (a printer showing 40 % after 42 %)
                    ("M", 73), ("M", 117))


@dataclass(frozen=True)
class Finding:
    """One failed check. ``line``: 1-based line in the output (``in_original``: in the original)."""

    check: str
    line: int | None
    message: str
    in_original: bool = False

    def __str__(self) -> str:
        where = "" if self.line is None else (f"original line {self.line}: " if self.in_original
                                              else f"line {self.line}: ")
        return f"[{self.check}] {where}{self.message}"


@dataclass(frozen=True)
class VerifyReport:
    ok: bool
    findings: tuple
    energy_j: float                 # output, recomputed from its text (stalls included)
    time_s: float
    energy_before_j: float          # original, same model
    time_before_s: float
    stall_s: float
    lines_before: int
    lines_after: int
    bytes_before: int
    bytes_after: int
    rotate_deg: float
    center_mm: tuple
    reordered: bool
    firmware: str
    checks: tuple = field(default=())

    @property
    def saving_pct(self) -> float:
        return 100.0 * (1.0 - self.energy_j / self.energy_before_j) if self.energy_before_j else 0.0

    def to_dict(self) -> dict:
        return {"ok": self.ok, "findings": [str(f) for f in self.findings],
                "energy_j": self.energy_j, "time_s": self.time_s,
                "energy_before_j": self.energy_before_j, "time_before_s": self.time_before_s,
                "stall_s": self.stall_s, "lines_before": self.lines_before,
                "lines_after": self.lines_after, "bytes_before": self.bytes_before,
                "bytes_after": self.bytes_after, "rotate_deg": self.rotate_deg,
                "reordered": self.reordered, "firmware": self.firmware, "checks": list(self.checks)}


# ------------------------------------------------------------------------------------------------
def _rotation_headers(program: Program) -> list[tuple[float, float, float]]:
    """Every ``; gatesopt: rotate_deg=`` line in the first 50 lines, as (deg, center_x, center_y),
    in file order: the newest first (each rotating rewrite puts its line on top of the text it
    read, which may hold the lines of an earlier one)."""
    out = []
    for i in range(min(program.n_lines, 50)):
        t = program.line_text(i).strip()
        if t.startswith(ROTATE_PREFIX):
            try:
                kv = dict(w.split("=", 1) for w in t[len("; gatesopt:"):].split() if "=" in w)
                out.append((float(kv["rotate_deg"]), float(kv.get("center_x", 0)),
                            float(kv.get("center_y", 0))))
            except (KeyError, ValueError):
                raise GatesoptError(f"{program.source}:{i + 1}: unreadable rotation header: {t[:80]}") from None
    return out


def read_rotation(program: Program, original: Program | None = None) -> tuple[float, float, float]:
    """(deg, center_x, center_y): the rotation ``program`` declares against ``original``.

    The rotation lines ``original`` has itself (a gatesopt output solved again) came along with its
    text and are not this rewrite's; the others, if there are several (an output rewritten twice,
    compared with the slicer's file), compose into one rotation: about a centre c, p -> c +
    e^{i deg}(p - c), so two of them make p -> w p + t with w = e^{i(a + b)}, whose centre is
    t / (1 - w). Rotations that add up to a whole turn with a shift left over cannot be undone
    as a rotation: an error."""
    heads = _rotation_headers(program)
    if original is not None and heads:
        own = _rotation_headers(original)
        if own and heads[len(heads) - len(own):] == own:
            heads = heads[:len(heads) - len(own)]
    if not heads:
        return 0.0, 0.0, 0.0
    if len(heads) == 1:
        return heads[0]
    w, t, deg = 1 + 0j, 0j, 0.0
    for d, cx, cy in reversed(heads):           # the oldest was applied first
        r = complex(math.cos(math.radians(d)), math.sin(math.radians(d)))
        w, t, deg = r * w, r * t + (1 - r) * complex(cx, cy), deg + d
    if abs(1 - w) < 1e-12:
        if abs(t) > 1e-9:
            raise GatesoptError(f"{program.source}: its {len(heads)} rotation headers add up to a "
                                "whole turn and a shift, which verify cannot undo")
        return 0.0, 0.0, 0.0
    c = t / (1 - w)
    return math.remainder(deg, 360.0), c.real, c.imag


def _has_line(program: Program, prefix: str, within: int = 50) -> bool:
    return any(program.line_text(i).startswith(prefix) for i in range(min(program.n_lines, within)))


def _rotate(xy: np.ndarray, deg: float, center) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    x = xy[..., 0] - center[0]
    y = xy[..., 1] - center[1]
    return np.stack([center[0] + c * x - s * y, center[1] + s * x + c * y], axis=-1)


# ------------------------------------------------------------------------------------------------
# 1. geometry
def _near(points: np.ndarray, q: np.ndarray, tol: float) -> np.ndarray:
    """(len(q),) bool: a point of ``points`` lies within Chebyshev ``tol`` of each q (exact
    copies found by hashing, the rest by a k-d tree; the tree's bound is strict, so not with tol 0)."""
    from scipy.spatial import cKDTree
    if len(points) == 0 or len(q) == 0:
        return np.zeros(len(q), bool)
    near = _rowset.member(points, q) if tol > 0 else np.zeros(len(q), bool)
    rest = np.flatnonzero(~near)
    if len(rest):
        d, _ = cKDTree(points).query(q[rest], k=1, p=np.inf, distance_upper_bound=tol)
        near[rest] = np.isfinite(d)
    return near


def _moves(program: Program) -> np.ndarray:
    """(2k, 6) start+end xyz of every extruded move of ``program``, both directions."""
    ext = program.extruding
    a, b = program.start_mm[ext, :3], program.end_mm[ext, :3]
    return np.concatenate([np.concatenate([a, b], axis=1), np.concatenate([b, a], axis=1)]).astype(float)


def _vertices(program: Program) -> np.ndarray:
    """End points (xyz) of every extruded move: the joints a rewrite must keep."""
    ext = program.extruding
    return np.concatenate([program.start_mm[ext, :3], program.end_mm[ext, :3]]).astype(float)


def _rotated_run(near_undo: np.ndarray, near_raw: np.ndarray) -> np.ndarray:
    """The rows of the one contiguous run the emitter rotated (``render``'s ``rotate_rows``),
    read from the geometry: the run that maximises (#rows whose end is an original vertex only
    once un-rotated) - (#rows whose end is one as written), by prefix sums. A row inside the run
    whose end happens to lie on an unrelated original vertex as written (a split piece, found on
    PrusaSlicer output) is still un-rotated, as its neighbours are."""
    score = near_undo.astype(np.int64) - near_raw.astype(np.int64)
    out = np.zeros(len(score), bool)
    if not len(score):
        return out
    p = np.concatenate(([0], np.cumsum(score)))
    low = np.minimum.accumulate(p)[:-1]           # best start before each end
    gain = p[1:] - low
    j = int(np.argmax(gain))
    if gain[j] <= 0:
        return out
    i = int(np.flatnonzero(p[:j + 1] == low[j])[-1])
    out[i:j + 1] = True
    return out


PARTITION_MAX_PIECES = 64   # longer runs of joinable pieces take the greedy reading


def _read_runs(original_moves: np.ndarray, s: np.ndarray, e: np.ndarray, runs, tol_mm: float,
               join: np.ndarray) -> None:
    """Set ``join`` over the runs of pieces (k, j_end) (rows of ``s``/``e``) that can be read
    more than one way.

    A run is ambiguous when its pieces can be read more than one way: on a path that doubles
    back, two original moves A, B in a row are also, joined, a third one (C reversed); and a move
    that retraces an original move can be split exactly where that move ended, so its first piece
    is an original move too. The reading taken splits the run into consecutive groups, each
    joined into one segment, with (1) the fewest groups that are no move of the original, then
    (2) the most groups -- a piece that is a move by itself stays one, as the slicer wrote it:
    a shortest path over the run's joints (dynamic programming). Every stretch of every run is
    looked up in one batch (one hash and k-d tree over the original's moves, not one per run).
    A run longer than ``PARTITION_MAX_PIECES`` takes the greedy reading: from each piece, the
    longest stretch that is a move of the original."""
    short = [(k, j) for k, j in runs if j - k + 1 <= PARTITION_MAX_PIECES]
    long_ = [(k, j) for k, j in runs if j - k + 1 > PARTITION_MAX_PIECES]
    if short:
        pairs = [np.triu_indices(j - k + 1) for k, j in short]
        first = np.concatenate([k + ii for (k, _), (ii, _) in zip(short, pairs)])
        last = np.concatenate([k + jj for (k, _), (_, jj) in zip(short, pairs)])
        found = _near(original_moves, np.concatenate([s[first], e[last]], axis=1), tol_mm)
        at = 0
        for (k, j_end), (ii, jj) in zip(short, pairs):
            n = j_end - k + 1
            is_move = np.zeros((n, n), bool)
            is_move[ii, jj] = found[at:at + len(ii)]
            at += len(ii)
            # cost[j] = (groups that are no move, -groups) of the best reading of pieces 0..j-1
            cost = [(0, 0)] + [None] * n
            back = [0] * (n + 1)
            for j in range(1, n + 1):
                for i in range(j):
                    c = (cost[i][0] + (0 if is_move[i, j - 1] else 1), cost[i][1] - 1)
                    if cost[j] is None or c < cost[j]:
                        cost[j], back[j] = c, i
            j = n
            while j > 0:
                i = back[j]
                join[k + i:k + j - 1] = True
                j = i
    if long_:
        from scipy.spatial import cKDTree
        tree = cKDTree(original_moves)
        for k, j_end in long_:
            i = k
            while i < j_end:
                best = None
                for j in range(j_end, i, -1):
                    d, _ = tree.query(np.concatenate([s[i], e[j]]), k=1, p=np.inf,
                                      distance_upper_bound=tol_mm)
                    if np.isfinite(d):
                        best = j
                        break
                if best is None:
                    i += 1
                    continue
                join[i:best] = True
                i = best + 1


def _segments(program: Program, undo_deg: float = 0.0, center=(0.0, 0.0), tol_mm: float = GEOMETRY_TOL_MM,
              vertices: np.ndarray | None = None, original_moves: np.ndarray | None = None):
    """Extruded segments: (layer, key (k, 10), first row, E) with key = start xyz, end xyz, centre
    xy (0 for lines), arc flag. ``vertices`` (the original's joints) given: the output side, whose
    split pieces are joined back into the moves they came from."""
    motion = np.isin(program.kind, MOTION_KINDS)
    rows = np.flatnonzero(motion)
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros((0, 9)), np.zeros(0, np.int64), np.zeros(0)
    ext = program.extruding[rows]
    s = program.start_mm[rows, :3].astype(float).copy()
    e = program.end_mm[rows, :3].astype(float).copy()
    c = np.nan_to_num(program.arc_center_mm[rows].astype(float), nan=0.0)
    arc = program.kind[rows] == Kind.ARC
    lay = program.layer[rows]
    de = (program.end_mm[rows, 3] - program.start_mm[rows, 3]).astype(float)
    if undo_deg % 360.0 != 0.0:
        # The rotation covers the print proper (layer >= 0); start G-code (purge lines, layer -1)
        # stays where the slicer put it. Where the layer finder's view is unsure, the geometry
        # decides: a row whose end is an original vertex only once un-rotated was rotated.
        sel = lay >= 0
        if vertices is not None:
            e_undo = e.copy()
            e_undo[:, :2] = _rotate(e[:, :2], -undo_deg, center)
            near_undo = _near(vertices, e_undo, tol_mm)
            near_raw = _near(vertices, e, tol_mm)
            sel = near_undo | (~near_raw & sel) | _rotated_run(near_undo, near_raw)
        s[sel, :2] = _rotate(s[sel, :2], -undo_deg, center)
        e[sel, :2] = _rotate(e[sel, :2], -undo_deg, center)
        c[sel & arc] = _rotate(c[sel & arc], -undo_deg, center)
    ccw = program.arc_ccw[rows]
    keep = ext.copy()
    join = np.zeros(max(len(rows) - 1, 0), bool)
    closed_join = {}
    if vertices is not None and len(rows) > 1:
        # Output side: join row k to row k+1 when they are the pieces of one split move: both
        # extruding, same layer, continuous, separated by motor instruction lines only (what
        # gating inserts), collinear (lines: the joint on the chord within the tolerance) or on
        # one circle in one sense (arcs) -- and the joint is no vertex of the original print (an
        # instruction inserted *between* two original moves must not merge them).
        d0 = e[:-1] - s[:-1]
        d1 = e[1:] - s[1:]
        chord = e[1:] - s[:-1]
        cl = np.linalg.norm(chord, axis=1)
        u = chord / np.maximum(cl, 1e-300)[:, None]
        w = e[:-1] - s[:-1]
        off_chord = np.linalg.norm(w - np.einsum("ij,ij->i", w, u)[:, None] * u, axis=1)
        forward = (np.einsum("ij,ij->i", d0, d1) > 0) & (cl > 0)
        cont = np.all(np.abs(e[:-1] - s[1:]) <= 1e-6, axis=1)
        motor_cum = np.cumsum(program.kind == Kind.MOTOR)
        between_motor = motor_cum[rows[1:] - 1] - motor_cum[rows[:-1]]
        line_gap = program.line[rows[1:]] - program.line[rows[:-1]] - 1
        only_motor = (rows[1:] - rows[:-1] - 1 == between_motor) & (line_gap == between_motor)
        # (no same-layer test: a z-change layer finder may start a layer inside a split move)
        same = ext[:-1] & ext[1:] & cont & only_motor
        line_ok = ~arc[:-1] & ~arc[1:] & forward & (off_chord <= tol_mm)
        arc_ok = arc[:-1] & arc[1:] & (ccw[:-1] == ccw[1:]) & np.all(np.abs(c[:-1] - c[1:]) <= tol_mm, axis=1)
        # Rebuild the original moves from runs of joinable pieces: join the stretches of a run
        # that are moves of the original (so a line inserted *between* two original moves keeps
        # them two, and a split move becomes one again).
        cand = same & (line_ok | arc_ok)
        if original_moves is not None and cand.any():
            # runs of joinable pieces: rows k..j_end with cand[k:j_end] all true
            edge = np.diff(np.concatenate(([0], cand.astype(np.int8), [0])))
            run_k, run_end = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
            # a run whose first piece is an original move by itself is ambiguous (A+B = C
            # reversed on a path that doubles back; a retracing move split where the move it
            # retraces ended): _read_runs reads it
            in_runs = np.flatnonzero(cand | np.concatenate(([False], cand[:-1])))
            piece_is_move = np.zeros(len(rows), bool)
            piece_is_move[in_runs] = _near(
                original_moves, np.concatenate([s[in_runs], e[in_runs]], axis=1), tol_mm)
            # the common case, one split move: the whole run is a move of the original
            whole = _near(original_moves, np.concatenate([s[run_k], e[run_end]], axis=1), tol_mm)
            whole &= ~piece_is_move[run_k]
            mark = np.zeros(len(join) + 1, np.int64)
            np.add.at(mark, run_k[whole], 1)
            np.add.at(mark, run_end[whole], -1)
            join |= np.cumsum(mark[:-1]) > 0
            _read_runs(original_moves, s, e, list(zip(run_k[~whole].tolist(), run_end[~whole].tolist())),
                       tol_mm, join)
        else:
            join[:] = cand
        # a closed loop whose seam was moved inside a straight side (a re-ordering may start a
        # loop anywhere) has that side in two pieces, first and last of the chain: join them
        chain_start = np.ones(len(rows), bool)
        chain_start[1:] = ~same
        firsts = np.flatnonzero(chain_start)
        lasts = np.append(firsts[1:] - 1, len(rows) - 1)
        cand = ((lasts > firsts) & ext[firsts] & ext[lasts] & ~arc[firsts] & ~arc[lasts]
                & np.all(np.abs(e[lasts] - s[firsts]) <= tol_mm, axis=1))
        firsts, lasts = firsts[cand], lasts[cand]
        if len(lasts):
            keep_c = ~_near(vertices, e[lasts], tol_mm)
            firsts, lasts = firsts[keep_c], lasts[keep_c]
        for f, l in zip(firsts, lasts):
            v0, v1 = e[l] - s[l], e[f] - s[f]
            n0, n1 = np.linalg.norm(v0), np.linalg.norm(v1)
            if n0 > 0 and n1 > 0 and np.dot(v0, v1) / (n0 * n1) > math.cos(2e-2):
                closed_join[int(l)] = int(f)
    start_of = np.ones(len(rows), bool)
    start_of[1:] = ~join
    gid = np.cumsum(start_of) - 1
    g_first = np.flatnonzero(start_of)
    g_last = np.append(g_first[1:] - 1, len(rows) - 1)
    gk = keep[g_first]
    g_first, g_last = g_first[gk], g_last[gk]
    e_sum = np.bincount(gid, weights=de)[gid[g_first]]
    a = s[g_first]
    b = e[g_last]
    is_arc = arc[g_first]
    cc = np.where(is_arc[:, None], c[g_first], 0.0)
    if closed_join:
        pos_first = {int(r): k for k, r in enumerate(g_first)}
        pos_last = {int(r): k for k, r in enumerate(g_last)}
        drop = np.zeros(len(g_first), bool)
        for l, f in closed_join.items():
            kl, kf = pos_last.get(l), pos_first.get(f)
            if kl is None or kf is None or kl == kf:
                continue
            b[kl] = b[kf]
            e_sum[kl] += e_sum[kf]
            drop[kf] = True
        keep2 = ~drop
        a, b, cc, is_arc, g_first, e_sum = a[keep2], b[keep2], cc[keep2], is_arc[keep2], g_first[keep2], e_sum[keep2]
    # a move shorter than the tolerance is below any printer's resolution (a microstep is ~12 um);
    # a rotated output may write it as a point (both axes snapped)
    big = (np.abs(b - a).max(axis=1) > tol_mm) | is_arc
    if not big.all():
        a, b, cc, is_arc, g_first, e_sum = a[big], b[big], cc[big], is_arc[big], g_first[big], e_sum[big]
    # as written; matching tries both directions (an arc reversed runs the other sense, which
    # the key ignores: the end points and the centre fix the arc up to that)
    key = np.concatenate([a, b, cc, is_arc[:, None].astype(float)], axis=1)
    return lay[g_first], key, rows[g_first], e_sum


@njit(cache=True)
def _take_nearest_free(dist, idx, used):
    """Each row i in order takes its nearest candidate idx[i] (sorted by dist, inf = none) that is
    not ``used`` yet, and marks it used. Returns the rows that found none."""
    miss = np.empty(dist.shape[0], np.int64)
    n_miss = 0
    for i in range(dist.shape[0]):
        found = False
        for c in range(dist.shape[1]):
            if not np.isfinite(dist[i, c]):
                break
            j = idx[i, c]
            if not used[j]:
                used[j] = True
                found = True
                break
        if not found:
            miss[n_miss] = i
            n_miss += 1
    return miss[:n_miss]


def _match(ka: np.ndarray, kb: np.ndarray, tol: float):
    """Greedy one-to-one matching of rows of ka to rows of kb within Chebyshev ``tol``.
    Returns (unmatched a indices, unmatched b indices)."""
    from scipy.spatial import cKDTree

    if len(ka) == 0 or len(kb) == 0:
        return np.arange(len(ka)), np.arange(len(kb))
    tree = cKDTree(kb)
    kq = min(8, len(kb))
    rev = ka.copy()
    rev[:, 0:3], rev[:, 3:6] = ka[:, 3:6], ka[:, 0:3]
    d1, i1 = tree.query(ka, k=kq, p=np.inf, distance_upper_bound=tol)
    d2, i2 = tree.query(rev, k=kq, p=np.inf, distance_upper_bound=tol)
    if kq == 1:
        d1, i1, d2, i2 = d1[:, None], i1[:, None], d2[:, None], i2[:, None]
    dist = np.concatenate([d1, d2], axis=1)
    idx = np.concatenate([i1, i2], axis=1)
    o = np.argsort(dist, axis=1, kind="stable")
    dist = np.take_along_axis(dist, o, axis=1)
    idx = np.take_along_axis(idx, o, axis=1)
    used = np.zeros(len(kb), bool)
    miss_a = _take_nearest_free(dist, idx, used).tolist()
    # second chance for a's whose 8 nearest were all taken (many identical segments)
    if miss_a:
        left_b = np.flatnonzero(~used)
        still = []
        if len(left_b):
            t2 = cKDTree(kb[left_b])
            for i in miss_a:
                kk = min(len(left_b), 64)
                da, ja = t2.query(ka[i], k=kk, p=np.inf, distance_upper_bound=tol)
                db, jb = t2.query(rev[i], k=kk, p=np.inf, distance_upper_bound=tol)
                d = np.concatenate([np.atleast_1d(da), np.atleast_1d(db)])
                j = np.concatenate([np.atleast_1d(ja), np.atleast_1d(jb)])
                oo = np.argsort(d, kind="stable")
                d, j = d[oo], j[oo]
                for dd, jj in zip(d, j):
                    if not np.isfinite(dd):
                        still.append(i)
                        break
                    if not used[left_b[jj]]:
                        used[left_b[jj]] = True
                        break
                else:
                    still.append(i)
        else:
            still = miss_a
        miss_a = still
    return np.array(miss_a, np.int64), np.flatnonzero(~used)


def _undone_tol(tol_mm: float, deg: float) -> float:
    """``tol_mm`` per axis of a rotated output's own frame, seen in the original's frame where the
    geometry is compared: the box |dx|, |dy| <= tol turned by ``deg`` reaches tol * (|cos| + |sin|)
    on each axis (1.37x at 30 deg, 1.41x at 45). A rotated output's single-axis snap moves a point
    by up to ``SNAP_MM`` on each of the output's axes (both, for a move of a micrometre or two):
    a Cura file rotated by 30 deg failed here on a 1 um travel between two extrusions."""
    t = math.radians(deg % 360.0)
    return tol_mm * (abs(math.cos(t)) + abs(math.sin(t)))


def _segment_pair(original: Program, output: Program, tol_mm: float = GEOMETRY_TOL_MM):
    """``_segments`` of the original and of the output (its split moves joined back)."""
    deg, cx, cy = read_rotation(output, original)
    return (_segments(original, tol_mm=tol_mm),
            _segments(output, deg, (cx, cy), tol_mm=_undone_tol(tol_mm, deg), vertices=_vertices(original),
                      original_moves=_moves(original)))


def _by_value(v: np.ndarray, values: np.ndarray) -> list[np.ndarray]:
    """For each of ``values``: the indices where ``v`` equals it, ascending."""
    o = np.argsort(v, kind="stable")
    lo = np.searchsorted(v[o], values, "left")
    hi = np.searchsorted(v[o], values, "right")
    return [o[a:b] for a, b in zip(lo, hi)]


def _self_matched_layers(la, ka, lb, kb, layers, tol) -> np.ndarray:
    """Per layer of ``layers``: True where ``_match`` would pair every segment with itself, so
    nothing is unmatched: both sides hold the same keys in the same order, and no two keys of the
    layer coincide in either direction (then each segment's nearest candidate, at distance 0, is
    its own copy and nobody else's). Gating output is this case unless a split changed a number."""
    out = np.zeros(len(layers), bool)
    if (tol <= 0 or la.shape != lb.shape or ka.shape != kb.shape or not np.array_equal(la, lb)
            or not np.isfinite(ka).all() or not np.array_equal(ka, kb)):
        return out
    rev = ka.copy()
    rev[:, 0:3], rev[:, 3:6] = ka[:, 3:6], ka[:, 0:3]
    distinct_rev = ~(rev == ka).all(axis=1)            # a key that is its own reverse counts once
    keys = np.concatenate([ka, rev[distinct_rev]])
    lay = np.concatenate([la, la[distinct_rev]])
    dup = _rowset.repeated(np.concatenate([lay[:, None].astype(float), keys], axis=1))
    out[:] = True
    out[np.isin(layers, lay[dup])] = False
    return out


def check_geometry(original: Program, output: Program, *, tol_mm: float = GEOMETRY_TOL_MM,
                   max_findings: int = 10, segments=None) -> list[Finding]:
    """``segments``: ``_segment_pair(original, output, tol_mm)`` if the caller has it already."""
    (la, ka, ra, ea), (lb, kb, rb, eb) = segments or _segment_pair(original, output, tol_mm)
    tol_mm = _undone_tol(tol_mm, read_rotation(output, original)[0])
    out: list[Finding] = []
    if original.n_layers != output.n_layers:
        # the layer finder saw the two files differently (a z-change file whose XY moved): compare
        # the whole print at once -- a segment's key holds its Z, so nothing is lost but speed
        la = np.zeros_like(la)
        lb = np.zeros_like(lb)
    layers = np.union1d(np.unique(la), np.unique(lb))
    same = _self_matched_layers(la, ka, lb, kb, layers, tol_mm)
    for L, ia, ib, skip in zip(layers, _by_value(la, layers), _by_value(lb, layers), same):
        if skip:
            continue
        ma, mb = _match(ka[ia], kb[ib], tol_mm)
        # a move of a few micrometres that a rotated output's snaps shortened below the tolerance
        # (or lengthened above it) has no partner: below any printer's resolution, not reported
        ma = ma[np.abs(ka[ia][ma, 3:6] - ka[ia][ma, 0:3]).max(axis=1) > SHORT_MM] if len(ma) else ma
        mb = mb[np.abs(kb[ib][mb, 3:6] - kb[ib][mb, 0:3]).max(axis=1) > SHORT_MM] if len(mb) else mb
        for i in ma[:3]:
            k = ka[ia[i]]
            out.append(Finding("geometry", int(original.line[ra[ia[i]]]) + 1,
                               f"layer {L}: extruded segment ({k[0]:.3f},{k[1]:.3f},{k[2]:.3f})-"
                               f"({k[3]:.3f},{k[4]:.3f},{k[5]:.3f}) of the original is not in the output",
                               in_original=True))
        for j in mb[:3]:
            k = kb[ib[j]]
            out.append(Finding("geometry", int(output.line[rb[ib[j]]]) + 1,
                               f"layer {L}: extruded segment ({k[0]:.3f},{k[1]:.3f},{k[2]:.3f})-"
                               f"({k[3]:.3f},{k[4]:.3f},{k[5]:.3f}) is not in the original"))
        if len(out) >= max_findings:
            break
    return out


# ------------------------------------------------------------------------------------------------
# 6. positions
def _only_motor_between(program: Program, rows: np.ndarray) -> np.ndarray:
    """(len(rows) - 1,) bool: steps rows[k] and rows[k+1] are separated by motor instruction lines
    only (what gating inserts), so they may be pieces of one split move."""
    if len(rows) < 2:
        return np.zeros(0, bool)
    motor_cum = np.cumsum(program.kind == Kind.MOTOR)
    between_motor = motor_cum[rows[1:] - 1] - motor_cum[rows[:-1]]
    line_gap = program.line[rows[1:]] - program.line[rows[:-1]] - 1
    return (rows[1:] - rows[:-1] - 1 == between_motor) & (line_gap == between_motor)


@njit(cache=True)
def _match_positions(a_raw, a_rot, a_last, a_rel, a_home, b_end, b_run_end, tol, e_tol, out_k, out_flag,
                     out_allowed):
    """Walk the original's moves (ends ``a_raw``, rotated ``a_rot``: X Y Z E) against the output's
    (``b_end``) in order. Each original move is one block of output moves (a split move's pieces,
    joined by motor lines only) whose last move ends at the original's end, as written (flag 1)
    or rotated (flag 2); the last move of a run of the original (``a_last``: a non-motor line
    follows) ends the output's run too (``b_run_end[k]``: the last move of the output's run holding
    move k, found once for all, not per move: a file with no other line between its moves is one
    run). Within a run the block ends at the earliest
    output move that matches, which finds an alignment whenever there is one (matching a
    subsequence greedily). ``a_rel``: a relative XY move: from a start that is rotated only, its
    end must be rotated (allowed flags 2), unless homing (``a_home``) came between. Fills
    ``out_k`` (the output move taken, -1: none left), ``out_flag`` (0: no match) and
    ``out_allowed``."""
    n = a_raw.shape[0]
    m = b_end.shape[0]
    k = 0
    prev = 3
    for i in range(n):
        if a_home[i]:
            prev = 3        # homed since the last move: the head is at a machine position
        allowed = 2 if (a_rel[i] and prev == 2) else 3
        out_allowed[i] = allowed
        if k >= m:
            out_k[i] = -1
            out_flag[i] = 0
            prev = 3
            continue
        end = b_run_end[k]
        cand_hi = end if a_last[i] else end - 1     # a move inside a run ends before the run does
        first = end if a_last[i] else k
        found = -1
        flag = 0
        for kk in range(first, cand_hi + 1):
            f = 0
            d_raw = 0.0
            d_rot = 0.0
            for q in range(3):
                d_raw = max(d_raw, abs(b_end[kk, q] - a_raw[i, q]))
                d_rot = max(d_rot, abs(b_end[kk, q] - a_rot[i, q]))
            de = abs(b_end[kk, 3] - a_raw[i, 3])
            if de <= e_tol:
                if d_raw <= tol:
                    f |= 1
                if d_rot <= tol:
                    f |= 2
            f &= allowed
            if f:
                found = kk
                flag = f
                break
        if found < 0:
            # no match: report it, and go on as if the move were not split
            found = end if a_last[i] else k
        out_k[i] = found
        out_flag[i] = flag
        prev = flag if flag else 3
        k = found + 1
    return 0


def check_positions(original: Program, output: Program, *, tol_mm: float = GEOMETRY_TOL_MM,
                    e_tol_mm: float = 1e-5, max_findings: int = 10) -> list[Finding]:
    """Every move of the original ends in the output where the original's move ends, as written
    or rotated by the output's declared rotation (``; gatesopt: rotate_deg=``), and a relative XY
    move (G91) that starts in the rotated frame ends in it (its delta is the rotated delta, no
    translation). Positions are the parser's, in both files. For gating output (the original's
    moves in order, split moves' pieces joined by motor lines); a re-ordering is checked by
    ``geometry`` and ``gatesopt.ordering.verify``. ``tol_mm`` covers the single-axis snaps of a
    rotated output; E (the cumulative filament position) must agree within ``e_tol_mm``."""
    deg, cx, cy = read_rotation(output, original)
    ra = np.flatnonzero(np.isin(original.kind, MOTION_KINDS))
    rb = np.flatnonzero(np.isin(output.kind, MOTION_KINDS))
    if not len(ra):
        return []
    a_raw = np.ascontiguousarray(original.end_mm[ra], dtype=np.float64)
    a_rot = a_raw.copy()
    if deg % 360.0 != 0.0:
        a_rot[:, :2] = _rotate(a_raw[:, :2], deg, (cx, cy))
    a_last = np.ones(len(ra), bool)
    a_last[:-1] = ~_only_motor_between(original, ra)
    b_last = np.ones(len(rb), bool)
    b_last[:-1] = ~_only_motor_between(output, rb)
    ends = np.flatnonzero(b_last)
    b_run_end = ends[np.searchsorted(ends, np.arange(len(rb)))]     # b_last[-1] holds: never past it
    moves_xy = ((original.end_mm[ra, :2] != original.start_mm[ra, :2]).any(axis=1)
                | (original.kind[ra] == Kind.ARC))
    a_rel = np.asarray(original.relative_xyz[ra], bool) & moves_xy
    home_cum = np.cumsum(original.kind == Kind.HOME)
    a_home = np.diff(np.concatenate(([0], home_cum[ra]))) > 0    # a G28 since the move before
    b_end = np.ascontiguousarray(output.end_mm[rb], dtype=np.float64)
    out_k = np.empty(len(ra), np.int64)
    out_flag = np.zeros(len(ra), np.int64)
    out_allowed = np.zeros(len(ra), np.int64)
    _match_positions(a_raw, a_rot, a_last, a_rel, a_home, b_end, b_run_end, float(tol_mm), float(e_tol_mm),
                     out_k, out_flag, out_allowed)
    out: list[Finding] = []
    for i in np.flatnonzero(out_flag == 0)[:max_findings].tolist():
        oline = int(original.line[ra[i]]) + 1
        k = int(out_k[i])
        if k < 0:
            out.append(Finding("positions", oline, "move of the original has no counterpart in the output "
                                                   "(the output ends before it)", in_original=True))
            continue
        b, raw, rot = b_end[k], a_raw[i], a_rot[i]
        at = f"({b[0]:.4f}, {b[1]:.4f}, {b[2]:.4f})"
        if out_allowed[i] == 2:
            out.append(Finding("positions", int(output.line[rb[k]]) + 1,
                               f"relative move (G91, original line {oline}) from the rotated print ends at "
                               f"{at}, not at ({rot[0]:.4f}, {rot[1]:.4f}, {rot[2]:.4f}): its XY delta is "
                               f"not the original's delta rotated by {deg:g} deg"))
        else:
            where = (f"({raw[0]:.4f}, {raw[1]:.4f}, {raw[2]:.4f})" + (
                f", or rotated ({rot[0]:.4f}, {rot[1]:.4f}, {rot[2]:.4f})" if deg % 360.0 != 0.0 else ""))
            out.append(Finding("positions", int(output.line[rb[k]]) + 1,
                               f"move ends at {at} E{b[3]:.5f}; the original's move (line {oline}) ends at "
                               f"{where} E{raw[3]:.5f}"))
    return out


# ------------------------------------------------------------------------------------------------
# 2. extrusion
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
    if original.n_layers != output.n_layers:     # the layer finder disagrees: compare the total
        ea, eb = ea.sum(keepdims=True), eb.sum(keepdims=True)
    n = max(len(ea), len(eb))
    ea = np.pad(ea, (0, n - len(ea)))
    eb = np.pad(eb, (0, n - len(eb)))
    bad = np.abs(ea - eb) > rel_tol * np.maximum(np.abs(ea), np.abs(eb)) + 1e-6
    out = []
    for k in np.flatnonzero(bad)[:5]:
        L = k - 1
        rows = np.flatnonzero((output.layer == L) & output.extruding)
        line = int(output.line[rows[0]]) + 1 if len(rows) else None
        out.append(Finding("extrusion", line, f"layer {L}: net E {eb[k]:.5f} mm, original {ea[k]:.5f} mm"))
    return out


# ------------------------------------------------------------------------------------------------
# 3. commands
def _non_motion_lines(program: Program) -> np.ndarray:
    motion_lines = program.line[np.isin(program.kind, MOTION_KINDS)]
    mask = np.ones(program.n_lines, bool)
    mask[motion_lines] = False
    return np.flatnonzero(mask)


def fan_duty_s(program: Program, rows: np.ndarray) -> np.ndarray:
    """The part-cooling fan duty at steps ``rows`` in M106 S units (0-255, rounded): the
    parser's modal ``fan``, as the fan checks compare it."""
    return np.round(program.fan[rows].astype(np.float64) * 255.0).astype(np.int64)


def _check_fan_duty(original: Program, output: Program, max_findings: int) -> list[Finding]:
    """Per layer, the filament extruded under each part-cooling fan duty is the same in both
    files (the parser's modal ``fan``; order-free, so it holds for re-ordered and gated output,
    whose moves may be split; ``gatesopt.ordering.verify.check_fan`` checks move by move)."""
    def table(p):
        rows = np.flatnonzero(p.extruding)
        de = p.end_mm[rows, 3] - p.start_mm[rows, 3]
        return p.layer[rows].astype(np.int64), fan_duty_s(p, rows), de, rows
    la, da, ea, _ = table(original)
    lb, db, eb, rb = table(output)
    key = np.concatenate([la * 1024 + da, lb * 1024 + db])
    key, inv = np.unique(key, return_inverse=True)
    sum_a = np.bincount(inv[:len(la)], ea, len(key))
    sum_b = np.bincount(inv[len(la):], eb, len(key))
    bad = np.flatnonzero(np.abs(sum_a - sum_b) > 1e-4 * np.maximum(np.abs(sum_a), np.abs(sum_b)) + 1e-4)
    out = []
    for k in bad[:max_findings].tolist():
        L, duty = divmod(int(key[k]), 1024)
        at = rb[(lb == L) & (db == duty)]
        line = int(output.line[at[0]]) + 1 if len(at) else None
        out.append(Finding("commands", line, f"layer {L}: {sum_b[k]:.5f} mm of filament extruded with the "
                                             f"part fan at S{duty}, {sum_a[k]:.5f} mm in the original"))
    return out


def check_commands(original: Program, output: Program, *, reordered: bool = False,
                   fan_duty: bool = True, max_findings: int = 5) -> list[Finding]:
    """Control commands (heaters, tools, fans, ...) in the same order. ``reordered``: the part
    fan's lines may move and repeat; what counts is the filament each layer extrudes under each
    fan duty (``_check_fan_duty``), unless ``fan_duty`` is False (a caller that checks the fan
    move by move, ``gatesopt.ordering.verify.check``, would otherwise report one fault twice)."""
    out: list[Finding] = []
    if reordered:
        def seq(p):
            m = np.zeros(p.n_lines, bool)
            for letter, num in CONTROL_COMMANDS:
                m |= p.is_command(letter, num)
            m |= p.line_letter == ord("T")
            # the part-cooling fan is state a re-ordering re-issues where a curve would see
            # another value: its lines may be more, and are checked by what each layer extrudes
            # under each fan duty (``_check_fan_duty``), not by their order
            m[p.part_fan_lines] = False
            idx = np.flatnonzero(m)
            return idx, [p.line_text(i).strip() for i in idx]
        if fan_duty:
            out += _check_fan_duty(original, output, max_findings)
        ia, ta = seq(original)
        ib, tb = seq(output)
        for k in range(max(len(ta), len(tb))):
            if k >= len(ta):
                out.append(Finding("commands", int(ib[k]) + 1, f"control command not in the original: {tb[k][:60]}"))
            elif k >= len(tb):
                out.append(Finding("commands", int(ia[k]) + 1, f"control command missing: {ta[k][:60]}", True))
            elif ta[k] != tb[k]:
                out.append(Finding("commands", int(ib[k]) + 1, f"control command {tb[k][:40]!r} where the "
                                                            f"original has {ta[k][:40]!r}"))
            if len(out) >= max_findings:
                break
        return out
    a = _non_motion_lines(original)
    b = _non_motion_lines(output)
    inverse, texts = _text.distinct_lines(output, b)
    inserted = np.array([fwmod.parse_motor_line(t) is not None or t.startswith(ROTATE_PREFIX)
                         for t in texts], bool)[inverse]
    buf_a, buf_b = np.frombuffer(original.data, np.uint8), np.frombuffer(output.data, np.uint8)
    i = j = 0
    while i < len(a) and len(out) < max_findings:
        # equal lines and inserted motor instructions / rotation header, in bulk
        i, j = _text.walk_kept(buf_a, original.line_start, a, buf_b, output.line_start, b, inserted, i, j)
        if i >= len(a):
            break
        if j >= len(b):
            out.append(Finding("commands", int(a[i]) + 1,
                               f"line missing from the output: {original.line_text(int(a[i])).strip()[:60]}", True))
            i += 1
            continue
        # line b[j] is neither a[i] nor an insertion: deleted or changed: say which;
        # resynchronise on the next equal line
        ta = original.line_text(int(a[i]))
        tb = output.line_text(int(b[j]))
        nxt = next((jj for jj in range(j, min(j + 50, len(b))) if output.line_text(int(b[jj])) == ta), None)
        if nxt is not None:
            out.append(Finding("commands", int(b[j]) + 1, f"line added: {tb.strip()[:60]}"))
            j = nxt
        else:
            out.append(Finding("commands", int(a[i]) + 1,
                               f"line missing or changed in the output: {ta.strip()[:60]}", True))
            i += 1
    if not out:
        extra = j + np.flatnonzero(~inserted[j:])
        if len(extra):
            out.append(Finding("commands", int(b[extra[0]]) + 1,
                               f"line added: {output.line_text(int(b[extra[0]])).strip()[:60]}"))
    return out


# ------------------------------------------------------------------------------------------------
# 4. timing
def _anchors(program: Program) -> np.ndarray:
    """Lines a gating rewrite keeps one for one and in order: every line that is neither a motion
    (a split move gives several) nor a motor instruction (gating adds those), nor gatesopt's own
    header in the first 50 lines (``; gatesopt: rotate_deg=``)."""
    mask = np.ones(program.n_lines, bool)
    mask[program.line[np.isin(program.kind, MOTION_KINDS) | (program.kind == Kind.MOTOR)]] = False
    for i in range(min(program.n_lines, 50)):
        if mask[i] and program.line_text(i).startswith("; gatesopt:"):
            mask[i] = False
    return np.flatnonzero(mask)


def _step_starts(program: Program) -> np.ndarray:
    """(n + 1,) stall-free start time of each step, and the end of the print."""
    return np.concatenate(([0.0], np.cumsum(np.asarray(program.duration_s, float))))


def _places_by_anchor(program: Program, rows: np.ndarray, anchors: np.ndarray):
    """Where steps ``rows`` are: (stretch: the number of ``anchors`` lines before them, stall-free
    time since the end of the last of those, and inf: the time is always counted from there)."""
    line = np.asarray(program.line)
    start = _step_starts(program)
    seg = np.searchsorted(anchors, line[rows])
    t_anchor = np.concatenate(([0.0], start[np.searchsorted(line, anchors, "right")]))
    return seg, start[rows] - t_anchor[seg], np.full(len(rows), np.inf)


def _places_by_layer(program: Program, rows: np.ndarray):
    """Where steps ``rows`` are: (layer, stall-free time since the layer's first step, time to the
    end of its last step)."""
    start = _step_starts(program)
    layer = np.asarray(program.layer, np.int64)
    key = layer - layer.min() if len(layer) else layer
    first = np.full(int(key.max()) + 1 if len(key) else 0, len(layer), np.int64)
    last = np.full(len(first), -1, np.int64)
    np.minimum.at(first, key, np.arange(len(layer)))
    np.maximum.at(last, key, np.arange(len(layer)))
    k = key[rows]
    return layer[rows], start[rows] - start[first[k]], start[last[k] + 1] - start[rows]


def _own_motor_rows(original: Program | None, output: Program, rows: np.ndarray) -> np.ndarray:
    """Per output step of ``rows`` (motor lines): True if it is one of the original's own motor
    lines (a start G-code ``M17``, a closing ``M84``), kept by the rewrite, False if the rewrite
    added it.

    By text alone the two cannot be told apart: Marlin gating writes ``M18 X``, and a file may have
    an ``M18 X`` of its own. So each own line is paired with an output line of the same text in the
    same place, nearest in stall-free time to where the original has it. Gating keeps every other
    non-motion line one for one and in order (``check_commands``; ``_anchors``), so the place is
    the stretch between two such lines and the time is counted from its start (a split keeps a
    stretch's time; a rotation only changes the travels into and out of the print). A re-ordered
    file keeps its layers: the place is the layer, the time counted from the nearer end of it."""
    own = np.zeros(len(rows), bool)
    if original is None or not len(rows):
        return own
    if output is original:
        return np.ones(len(rows), bool)
    orows = np.flatnonzero(original.kind == Kind.MOTOR)
    if not len(orows):
        return own
    oinv, otexts = _text.distinct_lines(original, original.line[orows])
    ids: dict[str, int] = {}
    ocode = np.array([ids.setdefault(t.strip(), len(ids)) for t in otexts], np.int64)[oinv]
    inv, texts = _text.distinct_lines(output, output.line[rows])
    code = np.array([ids.get(t.strip(), -1) for t in texts], np.int64)[inv]
    oanch, anch = _anchors(original), _anchors(output)
    if len(oanch) == len(anch):
        oplace, o_from, o_to = _places_by_anchor(original, orows, oanch)
        place, c_from, c_to = _places_by_anchor(output, rows, anch)
    else:
        oplace, o_from, o_to = _places_by_layer(original, orows)
        place, c_from, c_to = _places_by_layer(output, rows)
    lo_place = min(int(oplace.min()), int(place.min()))
    width = max(int(oplace.max()), int(place.max())) - lo_place + 1
    okey = ocode * width + (oplace - lo_place)
    cand = np.flatnonzero(code >= 0)
    key = code[cand] * width + (place[cand] - lo_place)
    order = np.argsort(key, kind="stable")               # by key, then in file order
    cand, key = cand[order], key[order]
    # a place with as many lines of a text as the original's: all of them are its own
    ukeys, ocount = np.unique(okey, return_counts=True)
    lo, hi = np.searchsorted(key, ukeys, "left"), np.searchsorted(key, ukeys, "right")
    same = (hi - lo) == ocount
    for a, b in zip(lo[same].tolist(), hi[same].tolist()):
        own[cand[a:b]] = True
    used = np.zeros(len(cand), bool)
    for i in np.flatnonzero(~np.isin(okey, ukeys[same])).tolist():
        a, b = int(np.searchsorted(key, okey[i], "left")), int(np.searchsorted(key, okey[i], "right"))
        if a >= b:
            continue                    # gone from the output: check_commands reports it
        c = cand[a:b]
        if o_from[i] <= o_to[i]:
            d = np.abs(c_from[c] - o_from[i])
        else:
            d = np.abs(c_to[c] - o_to[i])
        d[used[a:b]] = np.inf
        j = int(np.argmin(d))
        if not np.isfinite(d[j]):
            continue
        used[a + j] = True
        own[c[j]] = True
    return own


def _motor_rows(program: Program, rows: np.ndarray, original: Program | None = None):
    """Per step of ``rows``: (a motor line, on, motor mask with bit m = AXES[m], the file's own
    line (``_own_motor_rows``)); each distinct text is read once."""
    inverse, texts = _text.distinct_lines(program, program.line[rows])
    ok, on, mask = fwmod.parse_motor_lines(texts)
    return ok[inverse], on[inverse], mask[inverse], _own_motor_rows(original, program, rows)


def check_timing(output: Program, *, firmware="3dgates", start_ahead_s: float = 1.8e-3,
                 end_late_s: float = 1.0e-3, original: Program | None = None,
                 tol_s: float = TIME_TOL_S, max_findings: int = 10) -> list[Finding]:
    fw = fwmod.get(firmware)
    dur = np.asarray(output.duration_s, float)
    t_end = np.cumsum(dur)
    t_start = t_end - dur
    steps = np.asarray(output.steps_motor(), bool)
    motor_rows = np.flatnonzero(output.kind == Kind.MOTOR)
    parsed, is_on, mask, own = _motor_rows(output, motor_rows, original)
    explicit_on = fw.reenable == "exact"
    out: list[Finding] = []
    for m, letter in enumerate(AXES):
        sel = parsed & (mask >> m & 1).astype(bool)
        if not sel.any():
            continue
        ev_rows, on, orig = motor_rows[sel], is_on[sel], own[sel]
        step_rows = np.flatnonzero(steps[:, m])
        if explicit_on:
            # the first step whose last instruction before it is an inserted "off"
            k = np.searchsorted(ev_rows, step_rows, "right") - 1
            kk = np.maximum(k, 0)
            held = np.flatnonzero((k >= 0) & ~on[kk] & ~orig[kk])
            if len(held):
                sr, r = step_rows[held[0]], ev_rows[k[held[0]]]
                out.append(Finding("timing", int(output.line[sr]) + 1,
                                   f"motor {letter} steps while off (switched off at line {int(output.line[r]) + 1})"))
        if not len(step_rows):
            continue
        # each inserted instruction against the motor's steps around it; the state before an
        # instruction is the previous instruction's (on before the first)
        t = t_start[ev_rows]
        was_on = np.concatenate(([True], on[:-1]))
        j = np.searchsorted(step_rows, ev_rows)                 # first step at or after it
        nxt = step_rows[np.minimum(j, len(step_rows) - 1)]
        prv = step_rows[np.maximum(j - 1, 0)]
        lead = t_start[nxt] - t
        lag = t - t_end[prv]
        late_on = ~orig & on & ~was_on & (j < len(step_rows)) & (lead < start_ahead_s - tol_s)
        early_off = ~orig & ~on & (j >= 1) & (lag < end_late_s - tol_s)
        hits = np.flatnonzero(late_on | early_off)
        # at most max_findings in all; once reached, a motor still reports its first inserted
        # instruction if that one fails
        if len(out) >= max_findings:
            first = np.flatnonzero(~orig)[:1]
            hits = hits[:1] if len(first) and len(hits) and hits[0] == first[0] else hits[:0]
        else:
            hits = hits[:max_findings - len(out)]
        for h in hits:
            r = ev_rows[h]
            if on[h]:
                out.append(Finding("timing", int(output.line[r]) + 1,
                                   f"motor {letter} switched on only {lead[h] * 1e3:.3f} ms before its step "
                                   f"at line {int(output.line[nxt[h]]) + 1} (start-ahead {start_ahead_s * 1e3:g} ms)"))
            else:
                out.append(Finding("timing", int(output.line[r]) + 1,
                                   f"motor {letter} switched off {lag[h] * 1e3:.3f} ms after its step at "
                                   f"line {int(output.line[prv[h]]) + 1} (end-late {end_late_s * 1e3:g} ms)"))
    return out


# ------------------------------------------------------------------------------------------------
# 4b. firmware
# M84 is M18 under another number (Marlin's ``GcodeSuite::M18_M84``; the parser reads them alike,
# ``firmware.parse_motor_line``): a line's instruction word is compared as M18.
_SAME_WORD = {"M84": "M18"}
_HOMED = AXES[:3]       # the axes a printer homes (X Y Z); the extruder has no home


def _dialect(fw: fwmod.Firmware) -> tuple[str, ...]:
    """The instruction words ``fw`` gates with (``Firmware.off_word`` / ``on_word``)."""
    return tuple(w for w in (fw.off_word, fw.on_word) if w is not None)


def _motor_word(text: str) -> str:
    """The instruction word of a motor line (``firmware.motor_line_word``: ``S0``, ``M18``,
    ``SET_STEPPER_ENABLE``), ``M84`` read as ``M18``."""
    word = fwmod.motor_line_word(text) or ""
    return _SAME_WORD.get(word, word)


def firmware_problem(text: str, firmware="3dgates") -> str | None:
    """Why ``firmware`` would not carry out the motor enable/disable line ``text`` the way gating
    means it (switch just the named motors, keep the axes homed), or None if it would (or ``text``
    is no motor line). Everything is read from ``gatesopt.firmware``: the dialect
    (``Firmware.off_word`` / ``on_word``), ``allowed_motors`` (with ``refused_note``) and
    ``homing_kept``."""
    fw = fwmod.get(firmware)
    parsed = fwmod.parse_motor_line(text)
    if parsed is None:
        return None
    on, motors = parsed
    shown = text.split(";", 1)[0].strip()
    word = _motor_word(text)
    own = _dialect(fw)
    if word not in own:
        owners = [name for name, p in fwmod.PRESETS.items() if word in _dialect(p)]
        whose = f"{'/'.join(owners)}'s" if owners else "no firmware's"
        return f"{shown} is {whose} motor instruction, not {fw.name}'s ({fw.name} gates with {' / '.join(own)})"
    if on:
        return None
    refused = [m for m in motors if m not in fw.allowed_motors]
    if refused:
        return (f"{shown} switches motor {','.join(refused)} off, which {fw.name} may not gate: "
                f"{fw.refused_note or 'not allowed'}")
    unhomed = [m for m in motors if m in _HOMED]
    if not fw.homing_kept and unhomed:
        return f"{shown} switches axis {','.join(unhomed)} off, and {fw.name} forgets it is homed after a disable"
    return None


def _added_motor_lines(original: Program | None, output: Program):
    """The motor enable/disable lines (``firmware.parse_motor_line``) of ``output`` that the rewrite
    added: (rows, per row the index of its stripped text in ``texts``, ``texts``). A line of the
    original's own (a slicer's closing ``M84``, end G-code's ``M18``) is not one, a copy the rewrite
    added of an original line is (``_own_motor_rows``)."""
    rows = np.flatnonzero(output.kind == Kind.MOTOR)
    inverse, texts = _text.distinct_lines(output, output.line[rows])
    texts = [t.strip() for t in texts]
    motor = np.array([fwmod.parse_motor_line(t) is not None for t in texts], bool)
    if not len(rows) or not motor.any():
        return rows[:0], inverse[:0], texts
    keep = motor[inverse]
    rows, inverse = rows[keep], inverse[keep]
    own = _own_motor_rows(original, output, rows)
    return rows[~own], inverse[~own], texts


def check_firmware(output: Program, *, firmware="3dgates", original: Program | None = None,
                   max_findings: int = 10) -> list[Finding]:
    """Every motor enable/disable line the rewrite added (``_added_motor_lines``; the original's own
    lines are not checked) is one ``firmware`` carries out as gating means it
    (``firmware_problem``): its own dialect, a motor it may gate, the axis kept homed."""
    fw = fwmod.get(firmware)
    rows, inverse, texts = _added_motor_lines(original, output)
    problem = [firmware_problem(t, fw) for t in texts]
    bad = np.array([p is not None for p in problem], bool)
    if not len(rows) or not bad.any():
        return []
    hit = np.flatnonzero(bad[inverse])[:max_findings]
    return [Finding("firmware", int(output.line[rows[h]]) + 1, problem[inverse[h]]) for h in hit.tolist()]


def detect_firmware(original: Program | None, output: Program) -> str:
    """The firmware ``gatesopt verify --firmware auto`` checks ``output`` for: ``firmware.detect``
    (the dialect of the output's motor lines) when that firmware takes every line the rewrite added
    (``firmware_problem``), else the first preset that does -- so a start G-code's own ``M17`` does
    not make S-series output Marlin's. When no preset takes them all, ``detect``'s answer stands
    (and ``check_firmware`` reports the lines)."""
    guess = fwmod.detect(output)
    _, inverse, texts = _added_motor_lines(original, output)
    texts = [texts[k] for k in np.unique(inverse).tolist()]
    if not texts:
        return guess
    takes = [name for name in fwmod.PRESETS
             if all(firmware_problem(t, name) is None for t in texts)]
    return guess if guess in takes or not takes else takes[0]


# ------------------------------------------------------------------------------------------------
# 5. energy
def _file_enable(program: Program, original: Program | None = None) -> np.ndarray:
    """(n, 4) motor state as the slicer's file has it: the parsed state with the effect of every
    inserted disable undone (a motor held off by a gating line counts as on). ``original`` tells
    the file's own motor lines from inserted ones (``_own_motor_rows``)."""
    en = np.asarray(program.enabled, bool).copy()
    rows = np.flatnonzero(program.kind == Kind.MOTOR)
    if not len(rows):
        return en
    parsed, on, mask, own = _motor_rows(program, rows, original)
    inserted_off = ~on & ~own
    idx = np.arange(program.n_steps)
    for m in range(4):
        sel = parsed & (mask >> m & 1).astype(bool)
        if not sel.any():
            continue
        k = np.searchsorted(rows[sel], idx, "right") - 1
        held = (k >= 0) & inserted_off[sel][np.maximum(k, 0)]
        en[held, m] = True
    return en


def energy_of(program: Program, *, firmware="3dgates", profile="paper", duration_s=None,
              original: Program | None = None):
    """(energy J, time s, stall s) of ``program`` recomputed from its text with the one model.

    A firmware stall at a motor instruction is priced with the motors as the slicer's file has
    them (``_file_enable``; ``original`` tells the file's own motor lines from inserted ones): the
    whole printer keeps drawing power while the firmware drains its queue or dwells, and no gating
    credit is taken for it -- the convention of ``gatesopt.gating.problem`` (``stall_coeffs``
    priced with ``enable0``)."""
    prof = load_profile(profile)
    coeffs = prof.coefficients(program)
    stall = fwmod.stall_durations(program, firmware)
    dur = (program.duration_s if duration_s is None else np.asarray(duration_s, float)) + stall
    en = np.asarray(program.enabled, bool).copy()
    motor = program.kind == Kind.MOTOR
    if motor.any():
        en[motor] = _file_enable(program, original)[motor]
    e = step_energy_j(dur, coeffs, en)
    return float(e.sum()), float(dur.sum()), float(stall.sum())


def _claimed(claimed):
    if claimed is None:
        return None
    if isinstance(claimed, dict):
        # a `gatesopt solve --json` report: the solver's own numbers where present
        e = claimed.get("objective_j", claimed.get("energy_after_j", claimed.get("energy_j")))
        t = claimed.get("objective_time_s", claimed.get("time_after_s", claimed.get("time_s")))
        return e, t
    if isinstance(claimed, (tuple, list)):
        return claimed[0], claimed[1]
    return getattr(claimed, "energy_j", None), getattr(claimed, "time_after_s", getattr(claimed, "time_s", None))


def _order_changed(original: Program, output: Program, segments=None) -> bool:
    """True if the output prints its extruded segments in another order (or direction) than the
    original: then it is a re-ordering, else gating-only output (checked line by line).
    ``segments``: ``_segment_pair(original, output)`` if the caller has it already."""
    (_, ka, _, _), (_, kb, _, _) = segments or _segment_pair(original, output)
    if len(ka) != len(kb):
        return True
    return bool(np.any(np.abs(ka[:, :6] - kb[:, :6]) > 10 * GEOMETRY_TOL_MM))


def _without_motor_lines(program: Program, original: Program) -> Program:
    """The program without the motor lines the rewrite added (``_added_motor_lines``; the file's
    own, such as a start G-code's ``M17``, stay: they are barriers for a re-ordering), re-parsed:
    what the ordering checks see."""
    rows = _added_motor_lines(original, program)[0]
    if not len(rows):
        return program
    from .parse import parse
    drop = set(program.line[rows].tolist())
    text = "".join(program.line_text(i) for i in range(program.n_lines) if i not in drop)
    return parse(text, source=program.source)


# ------------------------------------------------------------------------------------------------
def verify(original: Program, output: Program, *, firmware="3dgates", start_ahead_s: float = 1.8e-3,
           end_late_s: float = 1.0e-3, claimed=None, profile="paper", reordered: bool | None = None,
           claim_rel_tol: float = CLAIM_REL_TOL, geometry_tol_mm: float = GEOMETRY_TOL_MM,
           time_tol_s: float = TIME_TOL_S) -> VerifyReport:
    """Run every check of ``output`` against ``original``; ``ok`` only if all hold.

    ``claimed``: what the solver reported (a GatingSolution, a dict with ``energy_after_j`` /
    ``time_after_s``, or an (energy J, time s) pair); None skips that comparison.
    ``reordered``: output whose curves were re-ordered (None: detect it: a ``; gatesopt: order``
    header, or original lines that are not all kept in order); then only heater/tool commands (and other fans) must keep their order, the part-fan duty
    per layer its filament, and
    ``gatesopt.ordering.verify.check`` runs too if it exists.
    """
    fw = fwmod.get(firmware)
    segments = _segment_pair(original, output, geometry_tol_mm)
    if reordered is None:
        # detect: a header says so, or the lines are not the original's plus insertions (then the
        # output can only be a re-ordering, and is checked as one)
        reordered = _has_line(output, ORDER_PREFIX) or _order_changed(
            original, output, segments if geometry_tol_mm == GEOMETRY_TOL_MM else None)
    findings: list[Finding] = []
    checks = []
    deg, cx, cy = read_rotation(output, original)
    findings += check_geometry(original, output, tol_mm=geometry_tol_mm, segments=segments)
    checks.append("geometry")
    findings += check_extrusion(original, output)
    checks.append("extrusion")
    if reordered:
        # moves in another order: ``geometry`` and the ordering checks compare them
        # (``gating.pipeline.run`` checks the positions of the gated re-ordered print itself)
        checks.append("positions(skipped: re-ordered)")
    else:
        findings += check_positions(original, output, tol_mm=geometry_tol_mm)
        checks.append("positions")
    findings += check_commands(original, output, reordered=reordered)
    checks.append("commands")
    # the firmware's own dialect first: timing read with the wrong firmware's rules means little
    findings += check_firmware(output, firmware=fw, original=original)
    checks.append("firmware")
    findings += check_timing(output, firmware=fw, start_ahead_s=start_ahead_s, end_late_s=end_late_s,
                             original=original, tol_s=time_tol_s)
    checks.append("timing")
    if reordered:
        try:
            ov = importlib.import_module("gatesopt.ordering.verify")
        except ModuleNotFoundError:
            ov = None
        if ov is not None and hasattr(ov, "check"):
            bare = _without_motor_lines(output, original)
            if deg % 360.0 == 0.0 and bare.n_lines == output.n_lines:
                findings += list(ov.check(original, output))
                checks.append("ordering")
            else:
                # rotated or gated: the ordering checks' move-by-move comparison fails on rotated
                # and on split moves, and ``geometry`` above has compared those already (un-rotated,
                # splits joined). What a move-free comparison can still see holds for any output:
                # no extrusion crossed a barrier (per-bin sums of E and path length, with the
                # gating lines taken out and a rotation's snap allowed per move)
                findings += list(ov.check_barriers(
                    original, bare,
                    snap_tol_mm=_undone_tol(geometry_tol_mm, deg) if deg % 360.0 else 0.0))
                checks.append("ordering(barriers; moves: geometry)")
    e_after, t_after, stall = energy_of(output, firmware=fw, profile=profile, original=original)
    # the original's motor lines are all its own (a stall priced with the state they leave, as the
    # solver's ``energy_before_j`` does), not gating lines whose effect is undone
    e_before, t_before, _ = energy_of(original, firmware=fw, profile=profile, original=original)
    cl = _claimed(claimed)
    if cl is not None:
        checks.append("energy")
        ce, ct = cl
        if ce is not None and abs(ce - e_after) > claim_rel_tol * max(abs(e_after), 1e-12):
            findings.append(Finding("energy", None, f"energy recomputed from the text {e_after:.6f} J, "
                                                    f"solver claimed {ce:.6f} J (rel. diff "
                                                    f"{abs(ce - e_after) / max(abs(e_after), 1e-12):.2e})"))
        if ct is not None and abs(ct - t_after) > claim_rel_tol * max(abs(t_after), 1e-12):
            findings.append(Finding("energy", None, f"time recomputed from the text {t_after:.6f} s, "
                                                    f"solver claimed {ct:.6f} s"))
    return VerifyReport(
        ok=not findings, findings=tuple(findings), energy_j=e_after, time_s=t_after,
        energy_before_j=e_before, time_before_s=t_before, stall_s=stall,
        lines_before=original.n_lines, lines_after=output.n_lines, bytes_before=len(original.data),
        bytes_after=len(output.data), rotate_deg=deg, center_mm=(cx, cy), reordered=bool(reordered),
        firmware=fw.name, checks=tuple(checks))
