"""A rebuilt travel's moves planned as the planner plans them (issue 36; formulations/ordering.md,
"Cost model"): the kernels ``link_cost.rebuilt_s`` and ``cost._dense`` price a link with, and
``move_times.MoveTimes.gaps_s`` prices a file's gaps with. Each move gets its nominal speed,
acceleration and safe speed by its kind and the per-axis caps (``prep_move``, as
``_planner_kernel.prepare_moves``), the junctions between them the firmware's rule
(``_planner_kernel.junction_speed``), then the look-ahead passes and trapezoids
(``plan_moves_s``). The moves live in one work array (``work_array``), so a link allocates
nothing.

The per-move steps (``prep_move``, ``junction``, ``plan_ends_s``, ``joined_s``, ``same_z_s``, and
the planner's rules they call) are inlined into their callers (``inline="always"``): a link is a
few moves, and calls passing row views of the work array and the ``ends`` tuple cost as much as
the arithmetic (``cost._dense`` per link 0.73 -> 0.33 us on the Cura bunny, the same numbers bit
for bit; docs/BENCHMARKS.md, "Link-cost build against the previous checkout"). ``_dense`` plans
each link at one call site: inlined at two, a first run compiled 325 s instead of 239 s
(158 s with nothing inlined).
"""
from __future__ import annotations

import numba
import numpy as np

from .. import _planner_kernel as pk
from ..program import MOTION_KINDS

#: below this a length is no move (the writer skips axes that change by less than 1e-9 mm)
MOVE_EPS_MM = 1e-9
#: sin(theta/2) / (1 - sin(theta/2)) of junction deviation at a right angle (``junction_speed``)
R_JD_RIGHT_ANGLE = float(np.sqrt(0.5) / (1.0 - np.sqrt(0.5)))


@numba.njit(cache=True, inline="always")
def prep_move(w, k, code, row):
    """Row k of the work array: unit vector, nominal speed and acceleration by the move's kind
    and the per-axis caps (``_planner_kernel.nominal_speed_accel``, as the planner), safe speed;
    marked ready."""
    Lk = w[k, W_L]
    for ax in range(4):
        w[k, W_U + ax] = w[k, ax] / Lk
    has_e = w[k, 3] != 0.0
    no_xy = w[k, 0] == 0.0 and w[k, 1] == 0.0
    f, a = pk.nominal_speed_accel(code, w[k, W_U:W_U + 4], w[k, W_F], Lk, has_e, no_xy and w[k, 2] == 0.0, no_xy,
                                  w[k, 3] < 0.0, row)
    w[k, W_V], w[k, W_A] = f, a
    w[k, W_SAFE] = pk.safe_speed(code, w[k, W_U:W_U + 4], f, row)
    w[k, W_READY] = 1.0


@numba.njit(cache=True, inline="always")
def junction(w, k, code, row):
    """The planner's junction speed from work row k - 1 into row k (both ready)."""
    return pk.junction_speed(code, w[k - 1, W_U:W_U + 4], w[k, W_U:W_U + 4], w[k - 1, W_V],
                             w[k, W_V], w[k - 1, W_A], w[k, W_A], w[k - 1, W_L], w[k, W_L],
                             w[k - 1, W_SAFE], w[k, W_SAFE], row)


@numba.njit(cache=True)
def plan_moves_s(w, n, code, row):
    """Time (s) of moves 0..n-1 planned as ``planner.plan`` plans them: each move's nominal speed
    and acceleration by its kind and the per-axis caps (``prep_move``), the junction speeds
    between them by the firmware's rule (``junction_speed``), look-ahead passes, trapezoids.
    ``w`` (``work_array``): per move its displacement X Y Z E (columns 0-3), length ``W_L`` (XYZ,
    or |E| for an extruder-only move) and feed ``W_F``; a row marked ``W_READY`` (and a junction
    marked ``W_JREADY``) was prepared by the caller, the rest is written here. The first move
    starts and the last ends at its safe speed (``plan_ends_s`` with -1 for both)."""
    return plan_ends_s(w, n, code, row, -1.0, -1.0)


@numba.njit(cache=True, inline="always")
def plan_ends_s(w, n, code, row, v_first, v_last):
    """``plan_moves_s`` with the speeds at the two ends given: the first move's entry at most
    ``v_first`` and the last move's exit at most ``v_last`` (a link joined to the curves around
    it: its first row is the last move of the curve it leaves, which the curve enters at
    ``v_first``, its last row the first move of the curve it enters, left at ``v_last``;
    ``curve_time.CurveEnds``). -1: the move's safe speed, except under junction deviation, where
    a junction with an extruder-only move is a right angle whatever the curve's direction
    (Marlin: its unit vector is along E), v^2 = a JD sin(45)/(1 - sin(45)), a the entered move's
    acceleration (the print acceleration for the curve after); a dry travel's first or last move
    is taken at that angle too."""
    if n == 0:
        return 0.0
    for k in range(n):
        if w[k, W_READY] == 0.0:
            prep_move(w, k, code, row)
    for k in range(1, n):
        if w[k, W_JREADY] == 0.0:
            w[k, W_J] = junction(w, k, code, row)
    last = w[n - 1, W_SAFE]
    w[0, W_J] = w[0, W_SAFE]
    if code == pk.DEVIATION and row[pk.C_JD] > 0.0:
        w[0, W_J] = max(w[0, W_J], min(np.sqrt(w[0, W_A] * row[pk.C_JD] * R_JD_RIGHT_ANGLE),
                                       w[0, W_V]))
        last = max(last, min(np.sqrt(row[pk.C_ACCEL_PRINT] * row[pk.C_JD] * R_JD_RIGHT_ANGLE),
                             w[n - 1, W_V]))
    if v_first >= 0.0:
        w[0, W_J] = min(v_first, w[0, W_V])
    if v_last >= 0.0:
        last = min(v_last, w[n - 1, W_V])
    if code == pk.SCV:
        klipper_smoothing(w, n, row)
    nxt = last
    for k in range(n - 1, -1, -1):          # backward: each entry can brake to the next
        v = np.sqrt(nxt * nxt + 2.0 * w[k, W_A] * w[k, W_L])
        w[k, W_E] = min(w[k, W_J], v)
        nxt = w[k, W_E]
    for k in range(1, n):                   # forward: each entry reachable from the one before
        v = np.sqrt(w[k - 1, W_E] * w[k - 1, W_E] + 2.0 * w[k - 1, W_A] * w[k - 1, W_L])
        w[k, W_E] = min(w[k, W_E], v)
    t = 0.0
    for k in range(n):
        e0, vc, a, Lk = w[k, W_E], w[k, W_V], w[k, W_A], w[k, W_L]
        ex = w[k + 1, W_E] if k + 1 < n else last
        v0 = min(e0, vc)
        v1 = min(ex, np.sqrt(e0 * e0 + 2.0 * a * Lk), vc)
        d_acc = (vc * vc - v0 * v0) / (2.0 * a)
        d_dec = (vc * vc - v1 * v1) / (2.0 * a)
        if d_acc + d_dec <= Lk:
            t += (vc - v0) / a + (vc - v1) / a + (Lk - d_acc - d_dec) / vc
        else:
            vp = max(np.sqrt(a * Lk + 0.5 * (v0 * v0 + v1 * v1)), v0, v1)
            t += (vp - v0) / a + (vp - v1) / a
    return t


@numba.njit(cache=True)
def klipper_smoothing(w, n, row):
    """Klipper's smoothed look-ahead on moves 0..n-1 as one queue from rest, as ``planner.plan``
    applies it to a Klipper file (``_planner_kernel.klipper_cruise_cap``: each move's peak
    capped as if the moves accelerated at min(accel_to_decel, its acceleration, max_accel
    (1 - minimum_cruise_ratio))): lowers the nominal speeds ``W_V`` (the junctions stay those of
    the uncapped speeds, the trapezoids clip to the cap, as the planner does). Called per
    link on a Klipper file: the work array's columns go to ``klipper_cruise_cap`` as views and
    its own scratch is one array (each allocation here costs as much as a junction)."""
    a_print = row[pk.C_ACCEL_PRINT] * (1.0 - row[pk.C_MIN_CRUISE_RATIO])
    smooth = False
    for k in range(n):
        if min(row[pk.C_ACCEL_TO_DECEL], w[k, W_A], a_print) < w[k, W_A]:
            smooth = True
            break
    if not smooth:
        return
    scratch = np.empty((2, n))
    a_s, vj_b = scratch[0], scratch[1]
    for k in range(n):
        a_s[k] = min(row[pk.C_ACCEL_TO_DECEL], w[k, W_A], a_print)
    stop = np.zeros(n, np.bool_)
    stop[0] = True
    cap = pk.klipper_cruise_cap(w[:n, W_L], w[:n, W_A], a_s, w[:n, W_V], w[:n, W_J], stop)
    # and the window run backwards: Klipper's flush assigns a run's smoothed peak from its end,
    # so the caps of a window and of the same moves backwards differ by a few 0.1 ms at its short
    # boundary moves (a Klipper queue is not cut there; the window is). The lower of the two
    # caps, so that a link and its mirror -- the link run backwards where the rule is the same
    # both ways (``cost._dense``) -- are one price
    vj_b[0] = 0.0
    for j in range(1, n):
        vj_b[j] = w[n - j, W_J]
    cap_b = pk.klipper_cruise_cap(w[:n, W_L][::-1], w[:n, W_A][::-1], a_s[::-1],
                                  w[:n, W_V][::-1], vj_b, stop)
    for k in range(n):
        w[k, W_V] = min(cap[k], cap_b[n - 1 - k])


#: ``plan_moves_s``'s work array: columns per move (a rebuilt travel has at most 5 moves,
#: after the slicer's wipe it writes first)
W_L, W_F, W_U, W_V, W_A, W_SAFE, W_J, W_E, W_READY, W_JREADY, W_COLS = (
    4, 5, 6, 10, 11, 12, 13, 14, 15, 16, 17)
#: the slicer's wipe moves a rebuilt travel writes first at most (``wipes.SlicerWipes``)
WIPE_MAX_MOVES = 16
#: a rebuilt travel's moves, and with the curves' moves around it (``plan_ends_s``)
REBUILT_MAX_MOVES = 5 + WIPE_MAX_MOVES
JOINED_MAX_MOVES = REBUILT_MAX_MOVES + 2


def work_array(n: int = REBUILT_MAX_MOVES) -> np.ndarray:
    """A work array for ``plan_moves_s`` (and ``link_cost.rebuilt_s``) of ``n`` moves."""
    return np.zeros((n, W_COLS))


@numba.njit(cache=True)
def gaps_planned(a, b, motion, d_all, L_all, F_all, code, row):
    """``MoveTimes.gaps_s`` with the limits: per gap its motion steps planned together."""
    out = np.zeros(len(a))
    for i in range(len(a)):
        n = 0
        for s in range(a[i], b[i]):
            n += motion[s]
        if n == 0:
            continue
        w = np.zeros((n, W_COLS))
        k = 0
        for s in range(a[i], b[i]):
            if motion[s]:
                for ax in range(4):
                    w[k, ax] = d_all[s, ax]
                w[k, W_L], w[k, W_F] = L_all[s], F_all[s]
                k += 1
        out[i] = plan_moves_s(w, n, code, row)
    return out


@numba.njit(cache=True)
def e_row(w, k, e_mm, feed, code, row):
    """Work row k: an extruder-only move of ``e_mm`` (signed) at ``feed``, prepared."""
    w[k, :] = 0.0
    w[k, 3], w[k, W_L], w[k, W_F] = e_mm, abs(e_mm), feed
    prep_move(w, k, code, row)


@numba.njit(cache=True)
def end_side(c, changed, ends):
    """Which of curve c's rows in ``ends`` (``cost.TimePricer.ends_args``: the
    ``curve_time.CurveEnds`` arrays, then the curves' ``closed``) a link joins: 0 as the slicer
    printed it, 1 backwards; -1 none (no curve, a loop entered at another seam, no moves)."""
    if c < 0 or not ends[6][c]:
        return -1
    if changed:
        return -1 if ends[7][c] else 1
    return 0


@numba.njit(cache=True, inline="always")
def joined_s(w, n, code, row, p, po, c, co, ends):
    """Time (s) of a link's moves ``w[:n]`` joined to the curves around it (``plan_ends_s``):
    row 0 the last move of curve p (side ``po``) where ``po >= 0``, the last row the first move
    of curve c (side ``co``) where ``co >= 0``, less what those two moves take in their curves
    planned alone (``curve_time.CurveEnds``: the rest of the curve's time is its own)."""
    vf = ends[3][p, po] if po >= 0 else -1.0
    vl = ends[2][c, co] if co >= 0 else -1.0
    t = plan_ends_s(w, n, code, row, vf, vl)
    if po >= 0:
        t -= ends[5][p, po] / 1000.0
    if co >= 0:
        t -= ends[4][c, co] / 1000.0
    return t


@numba.njit(cache=True, inline="always")
def same_z_s(dx, dy, dist, retract, with_e, hop_on, pre, u_rows, v, has_u, w, code, row, v_xy,
             p, po, c, co, ends):
    """``link_cost.rebuilt_s`` for a link at one height inside a group (``_dense``), from
    prepared rows: ``pre`` the retraction, lift and lowering (the lift's junction from the
    retraction made), ``u_rows[0 / 1, v]`` the unretraction into candidate v retracting / dry
    (with, retracting, its junction from the lowering); per link only the travel and its
    junctions are made. Joined to the last move of curve p and the first of curve c
    (``joined_s``)."""
    n = 0
    if po >= 0:
        w[n, :] = ends[1][p, po]
        n += 1
    if retract and with_e:
        w[n, :] = pre[0]
        n += 1
    if retract and hop_on:
        w[n, :] = pre[1]
        if not (retract and with_e):
            w[n, W_JREADY] = 0.0        # its junction is from the curve's move (or none)
        n += 1
    if dist > MOVE_EPS_MM:
        w[n, :] = 0.0
        w[n, 0], w[n, 1], w[n, W_L], w[n, W_F] = dx, dy, dist, v_xy
        n += 1
    if retract and hop_on:
        w[n, :] = pre[2]
        n += 1
    if has_u:
        w[n, :] = u_rows[0 if retract else 1, v]
        if not (retract and hop_on):
            w[n, W_JREADY] = 0.0
        n += 1
    if co >= 0:
        w[n, :] = ends[0][c, co]
        n += 1
    return joined_s(w, n, code, row, p, po, c, co, ends)


@numba.njit(cache=True)
def reversed_gaps_ms(ok, a, b, motion, d_all, L_all, F_all, closed, ends, code, row):
    """Per curve p with ``ok[p]`` (``gaps.ReversibleGaps.ok``), the link from p back into
    p - 1 that writes the slicer's gap between them backwards (``gaps.reversed_gap``): its
    motion steps ``a[p]:b[p]`` in reverse order, each run from its end to its start at its own
    feed (E negated: the unretraction becomes the retraction), joined to the last move of p
    printed so that it ends where the gap ended (backwards, or a loop as printed) and the first
    move of p - 1 entered where the gap began (``joined_s``), in ms; 0 elsewhere. The planner's
    time of a move sequence run backwards is not its time forwards (``curve_time``), nor are
    its junctions with the curves the same. Under the limits in force at the gap's travel
    (``ends[9][ends[10][p]]``; ``row`` unused)."""
    n_c = len(ok)
    out = np.zeros(n_c)
    for p in range(1, n_c):
        if not ok[p]:
            continue
        c = p - 1
        n = 0
        for s in range(a[p], b[p]):
            n += motion[s]
        w = np.zeros((n + 2, W_COLS))
        po = end_side(p, not closed[p], ends)
        co = end_side(c, not closed[c], ends)
        k = 0
        if po >= 0:
            w[k, :] = ends[1][p, po]
            k += 1
        for s in range(b[p] - 1, a[p] - 1, -1):
            if motion[s]:
                for ax in range(4):
                    w[k, ax] = -d_all[s, ax]
                w[k, W_L], w[k, W_F] = L_all[s], F_all[s]
                k += 1
        if co >= 0:
            w[k, :] = ends[0][c, co]
            k += 1
        out[p] = joined_s(w, k, code, ends[9][ends[10][p]], p, po, c, co, ends) * 1000.0
    return out


def reversed_gap_times_ms(program, lay, ok, ends, code: int, limits_row) -> np.ndarray:
    """``reversed_gaps_ms`` for the gaps between the curves of ``lay`` (``layout.Layout``) in
    ``program``; ``ends``: ``cost.TimePricer.ends_args``."""
    n = len(ok)
    a, b = np.zeros(n, np.int64), np.zeros(n, np.int64)
    a[1:], b[1:] = lay.curve_s1[:-1], lay.curve_s0[1:]
    kind = program.kind
    motion = (np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype))
              & (program.length_mm > MOVE_EPS_MM))
    return reversed_gaps_ms(ok, a, b, motion, np.ascontiguousarray(program.end_mm - program.start_mm),
                            np.ascontiguousarray(program.length_mm, float),
                            np.ascontiguousarray(program.feed_mm_s, float), ends[7], ends, code,
                            np.asarray(limits_row, float))


@numba.njit(cache=True)
def regime_rows(gc, ends, code, planned, retract_mm, v_r, hop, v_z):
    """For a group's candidates (curves ``gc``): per candidate the local number of the limits
    regime its links run under (``ends[10]``, rows of ``ends[9]``: ``cost.TimePricer.gap_row``),
    those rows, and per regime the retraction, lift and lowering rows prepared under it (the lift's
    junction from the retraction made) where ``planned``."""
    m = len(gc)
    rtab, ridx = ends[9], ends[10]
    loc = np.full(len(rtab), -1, np.int64)
    vreg = np.zeros(m, np.int64)
    n_loc = 0
    for v in range(m):
        rr = ridx[gc[v]]
        if loc[rr] < 0:
            loc[rr] = n_loc
            n_loc += 1
        vreg[v] = loc[rr]
    rows_loc = np.zeros((max(n_loc, 1), rtab.shape[1]))
    for rr in range(len(rtab)):
        if loc[rr] >= 0:
            rows_loc[loc[rr]] = rtab[rr]
    pres = np.zeros((max(n_loc, 1), 3, W_COLS))
    hop_on = hop > MOVE_EPS_MM
    if planned:
        for q in range(n_loc):
            pre = pres[q]
            lim_row = rows_loc[q]
            if retract_mm > MOVE_EPS_MM:
                e_row(pre, 0, -retract_mm, v_r, code, lim_row)
            for k in (1, 2):
                dz_k = hop if k == 1 else -hop
                pre[k, 2], pre[k, W_L], pre[k, W_F] = dz_k, abs(dz_k), v_z
                if hop_on:
                    prep_move(pre, k, code, lim_row)
            if hop_on and retract_mm > MOVE_EPS_MM:
                pre[1, W_J] = junction(pre, 1, code, lim_row)
                pre[1, W_JREADY] = 1.0
    return vreg, rows_loc, pres
