"""The slicer's wipes, written again on the travels a re-ordering rebuilds (formulations/
ordering.md, "Wipes").

A wiping slicer (PrusaSlicer, SuperSlicer, Orca, Bambu Studio) pulls back most of its retraction
while it moves the nozzle over the curve it has just printed, or into it::

    ;WIPE_START
    G1 F8640
    G1 X97.764 Y164.028 E-.76        <- the wipe: XY moves with -E, at the layer's height
    ;WIPE_END
    G1 E-.04 F2100                   <- the rest of the retraction, in place
    G1 Z.6 F720                      <- lift, travel, lower, unretract

so the ooze lands on the part, not as a blob at the seam or a string across the travel. A
rebuilt travel (``gaps.rebuilt_gap``) that leaves a curve printed as the slicer printed it, and
retracts, writes that curve's wipe first -- the slicer's own moves, verbatim: where it wipes is
the slicer's choice, relative to the curve's end, which has not moved -- then the rest of the
retraction in place, then travels from where the wipe ended. The time objective prices that
(``link_cost.rebuilt_s``: the wipe's moves planned with the rest, the travel from the wipe's end). A
curve printed backwards or from another seam ends elsewhere: its travel retracts in place, as
before, and the report counts the wipes that are gone.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..program import Kind, Program
from .gap_plan import MOVE_EPS_MM, WIPE_MAX_MOVES
from .layout import Layout

EXTRUDE, ARC = int(Kind.EXTRUDE), int(Kind.ARC)
#: a wipe along an arc follows it by chords that stray from it by at most this (mm): a tenth of
#: a line width
ARC_SAGITTA_MM = 0.04
#: a wipe pulls back at most the rebuilt travel's retraction, within this (mm of filament)
WIPE_E_EPS_MM = 1e-9


#: a slicer wipes (every retraction after a curve), where it wiped after at least this share of
#: the curves after which it retracted
WIPING_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class SlicerWipes:
    """Per curve u and side (0: left as the slicer printed it, 1: printed backwards), the wipe a
    rebuilt travel out of it writes first.

    Where the slicer wiped after u: side 0 is its own wipe, the first steps of the gap after u
    up to its last that moves in XY at one height while retracting (``Kind.RETRACT`` with an XY
    move), with the E-only retractions and XY travels at one height among them, at most
    ``WIPE_MAX_MOVES`` moves, an arc among them written as chords within ``ARC_SAGITTA_MM`` of it
    (``arc_chords``: Bambu Studio, Orca and PrusaSlicer with arc fitting wipe along arcs). Where the
    slicer wipes (after ``WIPING_SHARE`` of its retractions after a curve, as PrusaSlicer's,
    Orca's and Bambu Studio's "wipe while retracting" does after every one), every other side of
    an open curve, and side 0 of a loop, gets a wipe of the slicer's usual length (the median of
    its wipes), back over the output's last extrusion (from the curve's end backwards along its
    moves; printed backwards, from its first point forwards), pulling back the slicer's usual
    filament per mm at its usual feed, fewer mm where the curve is shorter or its moves reach a
    height change or ``WIPE_MAX_MOVES`` (the rest of the retraction in place); along an arc, by
    chords within ``ARC_SAGITTA_MM`` of it. A loop printed backwards, or from another seam, has
    none."""

    n_moves: np.ndarray     # (n, 2) int64: its moves (0: no wipe)
    moves: np.ndarray       # (n, 2, WIPE_MAX_MOVES, 4): per move dX, dY, dE (mm) and feed (mm/s)
    e_mm: np.ndarray        # (n, 2) filament it pulls back (> 0 where it wipes)
    shift_xy: np.ndarray    # (n, 2, 2) where it ends less where the curve is left (mm)

    @staticmethod
    def none(n: int) -> "SlicerWipes":
        """No wipe on any side of ``n`` curves."""
        return SlicerWipes(np.zeros((n, 2), np.int64), np.zeros((n, 2, WIPE_MAX_MOVES, 4)),
                           np.zeros((n, 2)), np.zeros((n, 2, 2)))

    @staticmethod
    def of(program: Program, lay: Layout, closed=None) -> "SlicerWipes":
        """``closed``: per curve, whether it is a loop (None: only the slicer's own wipes)."""
        n = len(lay.curve_s0)
        none = SlicerWipes.none(n)
        n_moves, moves, e_mm, shift = none.n_moves, none.moves, none.e_mm, none.shift_xy
        if n < 2:
            return none
        d = program.end_mm - program.start_mm
        retract = program.kind == int(Kind.RETRACT)
        xy_mm = np.hypot(d[:, 0], d[:, 1])
        flat = np.abs(d[:, 2]) <= MOVE_EPS_MM
        # a wipe move: XY at one height pulling filament back, straight or an arc (Bambu Studio
        # and Orca wipe along arcs; written again as chords, ``arc_chords``)
        arc_wipe = (program.kind == ARC) & flat & (d[:, 3] < 0.0) & (xy_mm > MOVE_EPS_MM)
        wipe = (retract & (xy_mm > MOVE_EPS_MM) & flat & (d[:, 3] < 0.0)) | arc_wipe
        # what may come before or between a wipe's moves: E-only retractions (PrusaSlicer's
        # "retract before wipe") and XY travels at one height (its move inwards after an
        # external perimeter, before the wipe)
        lead = flat & (retract | (program.kind == int(Kind.TRAVEL)) | arc_wipe)
        a = lay.curve_s1[:-1]                       # the gap after curve u: steps [a, b)
        b = lay.curve_s0[1:]
        hit = np.zeros(len(wipe) + 1, np.int64)
        hit[1:] = np.cumsum(wipe)
        last = np.minimum(a + WIPE_MAX_MOVES, b)
        feed_of, start = program.feed_mm_s, program.start_mm
        centre, ccw = program.arc_center_mm, program.arc_ccw
        xy_len, xy_e = [], []
        for u in np.flatnonzero(hit[last] > hit[a]).tolist():
            rows: list = []
            n_ok = 0        # the wipe: the rows up to its last XY move pulling filament back
            for st in range(int(a[u]), int(last[u])):
                if not lead[st]:
                    break
                if program.kind[st] == ARC:
                    rows += [(dx, dy, float(d[st, 3]) * f, float(feed_of[st])) for dx, dy, f in
                             arc_chords(start[st, :2], centre[st], bool(ccw[st]), d[st, :2])]
                else:
                    rows.append((float(d[st, 0]), float(d[st, 1]), float(d[st, 3]),
                                 float(feed_of[st])))
                if len(rows) > WIPE_MAX_MOVES:
                    break
                if wipe[st]:
                    n_ok = len(rows)
            if not n_ok:
                continue
            r = np.asarray(rows[:n_ok])
            n_moves[u, 0] = n_ok
            moves[u, 0, :n_ok] = r
            e_mm[u, 0] = -r[:, 2].sum()
            shift[u, 0] = r[:, 0:2].sum(axis=0)
            xy = np.hypot(r[:, 0], r[:, 1])
            w = (xy > MOVE_EPS_MM) & (r[:, 2] < 0.0)
            xy_len.append(float(xy[w].sum()))
            xy_e.append(float(-r[w, 2].sum()))
        us = np.flatnonzero(n_moves[:, 0])
        cum = np.concatenate(([0], np.cumsum(retract)))
        n_retracting = int(np.count_nonzero(cum[b] - cum[a]))
        if closed is None or len(us) < 3 or len(us) < WIPING_SHARE * n_retracting:
            return SlicerWipes(n_moves, moves, e_mm, shift)
        # the slicer's usual wipe: length, filament per mm, feed (medians of its XY wipe moves)
        length = np.asarray(xy_len)
        want_mm = float(np.median(length))
        e_per_mm = float(np.median(np.asarray(xy_e) / np.maximum(length, MOVE_EPS_MM)))
        feed = float(np.median(program.feed_mm_s[wipe]))
        _walks(program.kind, d, program.start_mm, np.nan_to_num(program.arc_center_mm),
               program.arc_ccw, lay.curve_s0, lay.curve_s1, np.asarray(closed, np.bool_),
               want_mm, e_per_mm, feed, n_moves, moves, e_mm, shift)
        return SlicerWipes(n_moves, moves, e_mm, shift)


@numba.njit(cache=True)
def arc_span(ax, ay, bx, by, ccw):
    """(radius, sweep, chord turn) of an arc from (ax, ay) to (bx, by) about the origin,
    counter-clockwise or not: its sweep in (0, 2 pi] radians (a full turn where it ends where it
    starts) and the turn of the longest chord within ``ARC_SAGITTA_MM`` of it (a quarter turn
    below that radius: a tiny circle as four chords, never one of no length)."""
    r = math.sqrt(ax * ax + ay * ay)
    sweep = (1.0 if ccw else -1.0) * (math.atan2(by, bx) - math.atan2(ay, ax))
    while sweep <= 1e-12:
        sweep += 2.0 * math.pi
    per = 2.0 * math.acos(1.0 - ARC_SAGITTA_MM / r) if ARC_SAGITTA_MM < r else math.pi / 2.0
    return r, sweep, per


@numba.njit(cache=True)
def _walks(kind, d, start, centre, ccw, s0, s1, closed, want_mm, e_per_mm, feed_mm_s, n_moves,
           moves, e_mm, shift):
    """The usual wipe on every side without one (``SlicerWipes``: side 0 of a curve the slicer
    did not wipe after, side 1 of an open curve)."""
    for u in range(len(s0)):
        if n_moves[u, 0] == 0:
            n_moves[u, 0] = _walk(kind, d, start, centre, ccw, s1[u] - 1, s0[u] - 1, -1,
                                  want_mm, e_per_mm, feed_mm_s, moves[u, 0], e_mm[u], shift[u], 0)
        if not closed[u]:
            n_moves[u, 1] = _walk(kind, d, start, centre, ccw, s0[u], s1[u], 1, want_mm,
                                  e_per_mm, feed_mm_s, moves[u, 1], e_mm[u], shift[u], 1)


@numba.njit(cache=True)
def _walk(kind, d, start, centre, ccw, first, stop, step, want_mm, e_per_mm, feed_mm_s, out,
          e_out, shift, side):
    """One side's wipe: along the curve's steps ``first``, ``first + step``, ... (before
    ``stop``), each run in the direction ``step``, for ``want_mm`` of XY at most; returns its
    number of moves. An arc is followed by chords whose sagitta is at most ``ARC_SAGITTA_MM``
    (the wipe stays on the printed line)."""
    left = want_mm
    j = 0
    sx = sy = e = 0.0
    s = first
    while s != stop and j < WIPE_MAX_MOVES and left > MOVE_EPS_MM:
        if abs(d[s, 2]) > MOVE_EPS_MM or d[s, 3] <= 0.0 or (kind[s] != EXTRUDE and kind[s] != ARC):
            break
        if kind[s] == ARC:
            cx, cy = centre[s, 0], centre[s, 1]
            ax, ay = start[s, 0] - cx, start[s, 1] - cy
            bx, by = ax + d[s, 0], ay + d[s, 1]
            r, sweep, per = arc_span(ax, ay, bx, by, ccw[s])
            if not r > MOVE_EPS_MM:
                break
            # walked forwards from its start, or backwards from its end
            th = np.arctan2(ay, ax) if step > 0 else np.arctan2(by, bx)
            turn = (1.0 if ccw[s] else -1.0) * step
            chord_max = per * r
            done = 0.0
            arc_len = sweep * r
            while done < arc_len - MOVE_EPS_MM and j < WIPE_MAX_MOVES and left > MOVE_EPS_MM:
                piece = min(arc_len - done, left, chord_max)
                th2 = th + turn * piece / r
                dx = r * (np.cos(th2) - np.cos(th))
                dy = r * (np.sin(th2) - np.sin(th))
                out[j, 0], out[j, 1], out[j, 2], out[j, 3] = dx, dy, -e_per_mm * piece, feed_mm_s
                sx += dx
                sy += dy
                e += e_per_mm * piece
                left -= piece
                done += piece
                th = th2
                j += 1
            if done < arc_len - MOVE_EPS_MM:
                break
            s += step
            continue
        seg = np.sqrt(d[s, 0] * d[s, 0] + d[s, 1] * d[s, 1])
        if seg > MOVE_EPS_MM:
            f = min(1.0, left / seg)
            dx, dy = step * d[s, 0] * f, step * d[s, 1] * f
            out[j, 0], out[j, 1], out[j, 2], out[j, 3] = dx, dy, -e_per_mm * seg * f, feed_mm_s
            sx += dx
            sy += dy
            e += e_per_mm * seg * f
            left -= seg * f
            j += 1
        s += step
    e_out[side] = e
    shift[side, 0], shift[side, 1] = sx, sy
    return j


def arc_chords(start_xy, centre_xy, ccw: bool, d_xy) -> list:
    """An arc (from ``start_xy`` by ``d_xy`` around ``centre_xy``, counter-clockwise or not) as
    equal chords within ``ARC_SAGITTA_MM`` of it: (dX, dY, share of the arc) each."""
    cx, cy = float(centre_xy[0]), float(centre_xy[1])
    ax, ay = float(start_xy[0]) - cx, float(start_xy[1]) - cy
    bx, by = ax + float(d_xy[0]), ay + float(d_xy[1])
    r, sweep, per = arc_span(ax, ay, bx, by, bool(ccw))
    turn = 1.0 if ccw else -1.0
    n = max(1, math.ceil(sweep / per))
    th = math.atan2(ay, ax)
    out = []
    for _ in range(n):
        th2 = th + turn * sweep / n
        out.append((r * (math.cos(th2) - math.cos(th)), r * (math.sin(th2) - math.sin(th)),
                    1.0 / n))
        th = th2
    return out


def side_of(changed: bool) -> int:
    """The side of a curve's wipe (``SlicerWipes``) a link out of it leaves by."""
    return 1 if changed else 0
