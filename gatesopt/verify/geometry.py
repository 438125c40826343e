"""Check 1, ``geometry``: per layer, the extruded moves are the same (see ``gatesopt.verify``)."""
from __future__ import annotations

import math
import weakref

import numpy as np
from numba import njit

from .. import _rowset
from ..program import MOTION_KINDS, Kind, Program
from .finding import Finding
from .motor_lines import only_motor_between
from .rotation import read_rotation, rotate_xy, undone_tol

# 1 um: the single-axis snap of a rotated output (<= 1e-3 mm) plus the 0.05 um rounding of its text
GEOMETRY_TOL_MM = 1.1e-3
SHORT_MM = 5e-3        # unmatched extruded moves shorter than this are not reported (see check_geometry)


def _near(points: np.ndarray, q: np.ndarray, tol: float) -> np.ndarray:
    """(len(q),) bool: a point of ``points`` lies within Chebyshev ``tol`` of each q (exact
    copies found by hashing, the rest by a k-d tree; the tree's bound is strict, so not with tol 0)."""
    if len(points) == 0 or len(q) == 0:
        return np.zeros(len(q), bool)
    index = _index_of(points)
    near = index.rows(points).member(q) if tol > 0 else np.zeros(len(q), bool)
    rest = np.flatnonzero(~near)
    if len(rest):
        d, _ = index.tree(points).query(q[rest], k=1, p=np.inf, distance_upper_bound=tol)
        near[rest] = np.isfinite(d)
    return near


class _PointIndex:
    """A points array's hash table and k-d tree, each made on first use (both copy the rows:
    the index holds the array only weakly)."""

    def __init__(self, points: np.ndarray):
        self.ref = weakref.ref(points)
        self._rows = self._tree = None

    def rows(self, points: np.ndarray) -> _rowset.RowSet:
        if self._rows is None:
            self._rows = _rowset.RowSet(points)
        return self._rows

    def tree(self, points: np.ndarray):
        if self._tree is None:
            from scipy.spatial import cKDTree
            # unbalanced, not compacted: built ~2-3x faster on the 1.4 M rows of a 28 MB file's
            # joints (0.3 s against 0.9 s), queried as fast; the answers are the same. Its own
            # copy of the rows: the tree would otherwise keep the array itself alive
            self._tree = cKDTree(points, balanced_tree=False, compact_nodes=False, copy_data=True)
        return self._tree


#: id(points) -> index, for as long as that array lives: a verification asks of the same
#: original joints and moves up to six times (``segment_pair``), each a table and a tree of
#: ~1.4 M rows on a large file (~5 s of a 28 MB file's 20 s check made them again each time)
_INDEXES: dict[int, _PointIndex] = {}


def _index_of(points: np.ndarray) -> _PointIndex:
    key = id(points)
    index = _INDEXES.get(key)
    if index is None or index.ref() is not points:
        index = _INDEXES[key] = _PointIndex(points)
        # dropped with the array (its id may then be another array's)
        weakref.finalize(points, _INDEXES.pop, key, None)
    return index


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
        # the original's moves that start at piece i (one ball query), then every end of the
        # run at once against theirs: the largest j whose end one of them ends at. (One k-d tree
        # query per (i, j), from j_end down, took 19 s of a real Simplify3D 4.0 file's 21 s
        # verify; the same test: a move within Chebyshev tol, strictly, at both ends.)
        from scipy.spatial import cKDTree
        starts = cKDTree(original_moves[:, :3])
        for k, j_end in long_:
            i = k
            while i < j_end:
                cand = np.asarray(starts.query_ball_point(s[i], tol_mm, p=np.inf), np.int64)
                if len(cand):
                    cand = cand[np.max(np.abs(original_moves[cand, :3] - s[i]), axis=1) < tol_mm]
                best = None
                if len(cand):
                    ends = original_moves[cand, 3:]
                    d = np.max(np.abs(e[i + 1:j_end + 1, None, :] - ends[None, :, :]), axis=2)
                    hit = np.flatnonzero((d < tol_mm).any(axis=1))
                    if len(hit):
                        best = i + 1 + int(hit[-1])
                if best is None:
                    i += 1
                    continue
                join[i:best] = True
                i = best + 1


def _split_joins(program: Program, rows, s, e, c, arc, ccw, ext, tol_mm: float, original_moves,
                 join: np.ndarray) -> np.ndarray:
    """Output side of ``_segments``: set ``join[k]`` where rows k and k+1 are the pieces of one
    split move: both extruding, continuous, separated by motor instruction lines only (what
    gating inserts), collinear (lines: the joint on the chord within the tolerance) or on one
    circle in one sense (arcs) -- and the joint is no vertex of the original print (an
    instruction inserted *between* two original moves must not merge them). Returns ``same``:
    the pairs that are continuous extrusions separated by motor lines only."""
    d0 = e[:-1] - s[:-1]
    d1 = e[1:] - s[1:]
    chord = e[1:] - s[:-1]
    cl = np.linalg.norm(chord, axis=1)
    u = chord / np.maximum(cl, 1e-300)[:, None]
    w = e[:-1] - s[:-1]
    off_chord = np.linalg.norm(w - np.einsum("ij,ij->i", w, u)[:, None] * u, axis=1)
    forward = (np.einsum("ij,ij->i", d0, d1) > 0) & (cl > 0)
    cont = np.all(np.abs(e[:-1] - s[1:]) <= 1e-6, axis=1)
    only_motor = only_motor_between(program, rows)
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
    return same


def _seam_joins(rows, s, e, arc, ext, same, vertices, tol_mm: float) -> dict[int, int]:
    """Output side of ``_segments``: {last row: first row} of the chains of split pieces (runs of
    ``same``) that are one straight side of a closed loop cut in two by its seam."""
    closed_join = {}
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
    return closed_join


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
            e_undo[:, :2] = rotate_xy(e[:, :2], -undo_deg, center)
            near_undo = _near(vertices, e_undo, tol_mm)
            near_raw = _near(vertices, e, tol_mm)
            sel = near_undo | (~near_raw & sel) | _rotated_run(near_undo, near_raw)
        s[sel, :2] = rotate_xy(s[sel, :2], -undo_deg, center)
        e[sel, :2] = rotate_xy(e[sel, :2], -undo_deg, center)
        c[sel & arc] = rotate_xy(c[sel & arc], -undo_deg, center)
    ccw = program.arc_ccw[rows]
    keep = ext.copy()
    join = np.zeros(max(len(rows) - 1, 0), bool)
    closed_join = {}
    if vertices is not None and len(rows) > 1:
        same = _split_joins(program, rows, s, e, c, arc, ccw, ext, tol_mm, original_moves, join)
        closed_join = _seam_joins(rows, s, e, arc, ext, same, vertices, tol_mm)
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



def segment_pair(original: Program, output: Program, tol_mm: float = GEOMETRY_TOL_MM):
    """``_segments`` of the original and of the output (its split moves joined back)."""
    deg, cx, cy = read_rotation(output, original)
    return (_segments(original, tol_mm=tol_mm),
            _segments(output, deg, (cx, cy), tol_mm=undone_tol(tol_mm, deg), vertices=_vertices(original),
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
    """``segments``: ``segment_pair(original, output, tol_mm)`` if the caller has it already."""
    (la, ka, ra, ea), (lb, kb, rb, eb) = segments or segment_pair(original, output, tol_mm)
    tol_mm = undone_tol(tol_mm, read_rotation(output, original)[0])
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


def order_changed(original: Program, output: Program, segments=None) -> bool:
    """True if the output prints its extruded segments in another order (or direction) than the
    original: then it is a re-ordering, else gating-only output (checked line by line).
    ``segments``: ``segment_pair(original, output)`` if the caller has it already."""
    (_, ka, _, _), (_, kb, _, _) = segments or segment_pair(original, output)
    if len(ka) != len(kb):
        return True
    return bool(np.any(np.abs(ka[:, :6] - kb[:, :6]) > 10 * GEOMETRY_TOL_MM))
