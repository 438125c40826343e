"""The sequential core of the planner time model: look-ahead passes and trapezoids (numba).

Everything here works on *moves*: the motion steps of a Program with nonzero length, in order.
Per move k the caller gives its length ``L[k]`` (mm), acceleration ``a[k]`` (mm/s^2), nominal
(cruise) speed ``vnom[k]``, the highest speed allowed at its start junction ``vj[k]`` (already the
minimum of the junction rule and both nominal speeds) and its "safe" speed ``safe[k]`` -- the speed
at which it may start from, or end into, a standstill (Marlin classic jerk: the per-axis jerk; junction
deviation: MINIMUM_PLANNER_SPEED; Klipper: 0). ``stop_before[k]`` marks a full stop between move k-1
and move k (a dwell, heat wait, homing or motor instruction drains the queue, as does the start).

The passes follow Marlin's planner.cpp (``reverse_pass_kernel`` / ``forward_pass_kernel``: the
entry speed of each block is lowered so it can still decelerate to the next block's entry, then so
that it can be reached from the previous one) and Klipper's toolhead.py ``LookAheadQueue.flush``
(the same two constraints as v^2 bounds: ``max_start_v2 + delta_v2``). Unlike the firmware's finite
queue (16 blocks on Marlin) the look-ahead here spans every move between two stops.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# junction rules (MachineLimits.junction)
JERK, DEVIATION, SCV = 0, 1, 2
JUNCTION_CODE = {"jerk": JERK, "deviation": DEVIATION, "scv": SCV}
# columns of the limits table (gatesopt.limits.KEYS order)
C_MAX_ACCEL, C_MAX_FEED, C_JERK = 0, 4, 8
C_ACCEL_PRINT, C_ACCEL_TRAVEL, C_ACCEL_RETRACT, C_ACCEL_TO_DECEL = 12, 13, 14, 15
C_JD, C_SCV, C_MAX_VELOCITY, C_MIN_SEGMENT_TIME, C_MIN_FEED, C_MIN_TRAVEL_FEED = 16, 17, 18, 19, 20, 21
C_MIN_CRUISE_RATIO = 22
MINIMUM_PLANNER_SPEED = 0.05      # Marlin planner.h (mm/s)
KLIPPER_INSTANT_CORNER_V = 1.0    # Klipper kinematics/extruder.py instant_corner_velocity default (mm/s)
ARC_SEGMENT_MM = 1.0              # firmware arc segment (Marlin MM_PER_ARC_SEGMENT, Klipper gcode_arcs resolution)


# The per-move rules below are inlined into their callers (``inline="always"``): the ordering
# prices each link by planning its few moves (``ordering.gap_plan``), where a call passing row
# views of its work array cost as much as the rule itself


@njit(cache=True, inline="always")
def safe_speed(code, u, vnom, row):
    """Speed from which a move may start at rest and to which it may stop.

    Classic jerk (Marlin planner.cpp ``safe_speed``): the largest speed at which no axis moves
    faster than its jerk, ``min_a jerk_a / |u_a|``. Junction deviation: MINIMUM_PLANNER_SPEED.
    Klipper: 0 (a flush ends at standstill).
    """
    if code == JERK:
        v = vnom
        for ax in range(4):
            ua = abs(u[ax])
            if ua > 0.0 and row[C_JERK + ax] < v * ua:
                v = row[C_JERK + ax] / ua
        return v
    if code == DEVIATION:
        return min(vnom, MINIMUM_PLANNER_SPEED)
    return 0.0


@njit(cache=True, inline="always")
def junction_speed(code, up, uc, vp, vc, ap, ac, lp, lc, sp, sc, row):
    """Highest speed at the junction from a move (direction ``up`` at its end, nominal ``vp``,
    acceleration ``ap``, length ``lp``, safe speed ``sp``) into the next (``uc``, ``vc``, ...).

    ``row``: the limits in force (KEYS order). Never above either nominal speed.
    """
    return junction_speed_rows(code, up, uc, vp, vc, ap, ac, lp, lc, sp, sc, row, row)


@njit(cache=True, inline="always")
def junction_speed_rows(code, up, uc, vp, vc, ap, ac, lp, lc, sp, sc, row_p, row):
    """``junction_speed`` where the two moves were planned under different limits: ``row_p``
    the previous move's, ``row`` the next's (Klipper keeps each move's own junction deviation)."""
    vmax = min(vp, vc)
    if code == JERK:
        # Marlin planner.cpp, CLASSIC_JERK branch of _buffer_steps (also what PrusaSlicer's
        # GCodeProcessor::process_G1 simulates): per axis, the speed change across the junction,
        # told apart as coasting (same sign) or reversal, must stay within that axis's jerk.
        smaller = vmax / vp if vp > 0.0 else 0.0
        v_factor = 1.0
        for ax in range(4):
            v_exit = vp * up[ax] * smaller * v_factor
            v_entry = vc * uc[ax] * v_factor
            if v_exit > v_entry:
                if v_entry > 0.0 or v_exit < 0.0:
                    jerk = v_exit - v_entry              # coasting
                else:
                    jerk = max(v_exit, -v_entry)         # axis reversal
            else:
                if v_entry < 0.0 or v_exit > 0.0:
                    jerk = v_entry - v_exit
                else:
                    jerk = max(-v_exit, v_entry)
            mj = row[C_JERK + ax]
            if jerk > mj:
                v_factor *= mj / jerk
        vj = vmax * v_factor
        # "Now the transition velocity is known ... it may be possible that applying separate safe
        # exit / entry velocities will achieve faster prints" (Marlin): threshold 0.99
        thr = vj * 0.99
        if sp > thr and sc > thr:
            vj = sc
        return min(vj, vmax)
    # geometric rules use the XYZ direction; Marlin and Klipper treat extruder-only moves apart
    np_ = math.sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2])
    nc = math.sqrt(uc[0] * uc[0] + uc[1] * uc[1] + uc[2] * uc[2])
    if np_ > 0.0 and nc > 0.0:
        cos_theta = -(up[0] * uc[0] + up[1] * uc[1] + up[2] * uc[2]) / (np_ * nc)
    else:
        cos_theta = 0.0     # Marlin: an extruder-only move's unit vector is along E, orthogonal to XYZ
    if cos_theta > 0.999999:
        # a full reversal: Marlin gives MINIMUM_PLANNER_SPEED, Klipper no junction speed at all
        return min(MINIMUM_PLANNER_SPEED, vmax) if code == DEVIATION else 0.0
    if code == DEVIATION:
        # Marlin: NOLESS(junction_cos_theta, -0.999999) against round-off (Klipper clamps nothing)
        cos_theta = max(cos_theta, -0.999999)
    sin_d2 = math.sqrt(max(0.5 * (1.0 - cos_theta), 0.0))
    cos_d2 = math.sqrt(max(0.5 * (1.0 + cos_theta), 0.0))
    r_jd = sin_d2 / (1.0 - sin_d2) if sin_d2 < 1.0 else math.inf
    if code == DEVIATION:
        # Marlin planner.cpp (junction deviation): v^2 = a * JD * sin(theta/2) / (1 - sin(theta/2)),
        # and JD_HANDLE_SMALL_SEGMENTS: a short move turning less than 45 degrees is part of a
        # curve, v^2 <= a * L / turn_angle (centripetal on the implied radius L / angle)
        v2 = ac * row[C_JD] * r_jd
        if lc < 1.0 and cos_theta < -0.7071067812:
            turn = math.pi - math.acos(cos_theta)
            if turn > 1e-12:
                v2 = min(v2, lc * ac / turn)
        return min(math.sqrt(v2), vmax)
    # Klipper toolhead.py Move.calc_junction
    if np_ == 0.0 or nc == 0.0:
        return 0.0          # extruder-only moves are not kinematic: full stop around them
    # the junction deviation is the toolhead's, from its max_accel (toolhead.py
    # _calc_junction_deviation: scv^2 (sqrt 2 - 1) / max_accel), times each move's own
    # acceleration: a Z move (max_z_accel) turns slower than an XY move at the same angle. Each
    # move keeps the deviation in force when it was made (Move.__init__: junction_deviation =
    # toolhead.junction_deviation): across a SET_VELOCITY_LIMIT ACCEL change each side its own
    scv = row[C_SCV]
    jd = scv * scv * (math.sqrt(2.0) - 1.0) / row[C_ACCEL_PRINT]
    scv_p = row_p[C_SCV]
    jd_p = scv_p * scv_p * (math.sqrt(2.0) - 1.0) / row_p[C_ACCEL_PRINT]
    v2 = math.inf
    if sin_d2 < 1.0 and cos_d2 > 0.0:
        # Klipper skips the rule where the moves are straight in line (one_minus_sin_theta_d2 or
        # cos_theta_d2 is 0): a move split in two pieces, however short one is, keeps its speed
        # through the cut (with Marlin's clamp a 0.00013 mm first piece of a 22.7 mm/s move would
        # cap it at 19.2 mm/s: real_cura410_cubic's greedy output, the stop there mispriced).
        quarter_tan = 0.25 * sin_d2 / cos_d2
        v2 = min(r_jd * jd * ac, r_jd * jd_p * ap, 2.0 * lc * ac * quarter_tan,
                 2.0 * lp * ap * quarter_tan)
    # extruder.calc_junction: instant_corner_velocity on the change of E per mm of XYZ path
    diff_r = abs(uc[3] / nc - up[3] / np_)
    if diff_r > 1e-9:
        v2 = min(v2, (KLIPPER_INSTANT_CORNER_V / diff_r) ** 2)
    return min(math.sqrt(v2), vmax)


@njit(cache=True, inline="always")
def _axis_capped(v, ua, row, col, e_caps):
    """``v`` (a speed or an acceleration along unit vector ``ua``) capped so that no axis
    exceeds its own limit ``row[col + ax]`` (M203 / M201 per axis); E only where ``e_caps``."""
    for ax in range(4):
        if ax == 3 and not e_caps:
            continue
        u = abs(ua[ax])
        if u > 0.0 and v * u > row[col + ax]:
            v = row[col + ax] / u
    return v


@njit(cache=True, inline="always")
def nominal_speed_accel(code, ua, feed, length, has_e, e_only, no_xy, retract, row):
    """A move's nominal speed (mm/s) and acceleration (mm/s^2) by its kind and the firmware's
    caps: ``ua`` its unit vector X Y Z E (signs ignored), ``feed`` its requested speed, ``length`` its path
    length, ``has_e`` / ``e_only`` it moves E / only E, ``no_xy`` it moves neither X nor Y (a
    line), ``retract`` E runs backwards, ``row`` the limits in force. One rule for the planner
    (``prepare_moves``) and the ordering's travel pricing (``ordering.gap_plan.prep_move``)."""
    f = feed
    fmin = row[C_MIN_FEED] if has_e else row[C_MIN_TRAVEL_FEED]
    if f < fmin:
        f = fmin
    # Klipper: the extruder's limits (max_extrude_only_velocity / _accel, the E columns) apply
    # to a move without X and Y (extrude-only, or Z with E) and to a retraction (E < 0), as
    # the move's speed and acceleration over |E per mm| (klippy/kinematics/extruder.py
    # PrinterExtruder.check_move); Marlin caps E on every move (M203 / M201 E)
    e_caps = True
    if code == SCV:
        e_caps = no_xy or retract
    # M203 per-axis feedrate caps (the Z caps are Klipper's max_z_velocity * move_d / |dz|,
    # klippy/kinematics/cartesian.py check_move), Klipper max_velocity, minimum segment
    # time (M205 B)
    f = _axis_capped(f, ua, row, C_MAX_FEED, e_caps)
    # an extrude-only move keeps its requested speed on Klipper (toolhead.py Move: no
    # max_velocity for it), capped by max_extrude_only_velocity above
    if f > row[C_MAX_VELOCITY] and not (code == SCV and e_only):
        f = row[C_MAX_VELOCITY]
    mst = row[C_MIN_SEGMENT_TIME]
    if mst > 0.0 and f * mst > length:
        f = length / mst
    # acceleration: Marlin planner.cpp -- retract_acceleration for extruder-only moves,
    # travel_acceleration for moves without E steps, acceleration otherwise; M201 per axis
    # Klipper: an extrude-only move's acceleration is max_extrude_only_accel alone (toolhead.py
    # Move starts it at 99999999.9, extruder.py check_move lowers it), not max_accel
    if e_only:
        a = row[C_ACCEL_RETRACT]
        if code == SCV and row[C_MAX_ACCEL + 3] < 1e300:
            a = row[C_MAX_ACCEL + 3]
    elif has_e:
        a = row[C_ACCEL_PRINT]
    else:
        a = row[C_ACCEL_TRAVEL]
    return f, _axis_capped(a, ua, row, C_MAX_ACCEL, e_caps)


@njit(cache=True)
def prepare_moves(code, d, L, F, arc_row, arc_us, arc_ue, arc_phi, arc_seg, stop_before, regime, table):
    """Per move: nominal speed, acceleration, safe speed, max junction (entry) speed, and the
    junction speed the move would have if no stop came before it (``vj_free``).

    ``d`` (m, 4) displacement, ``L`` path length (XYZ, arc length for arcs, |E| for E-only);
    arcs: ``arc_row[k]`` indexes ``arc_us`` / ``arc_ue`` (unit tangent at start / end, X Y Z E per
    mm) and ``arc_phi`` (signed turn of one firmware arc segment), ``arc_seg`` (its length), -1
    for a line; ``regime[k]`` the row of ``table`` (limits in force, KEYS order).
    """
    m = L.shape[0]
    vnom = np.empty(m)
    acc = np.empty(m)
    safe = np.empty(m)
    vj = np.empty(m)
    vj_free = np.empty(m)
    us = np.empty(4)
    ue = np.empty(4)
    ua = np.empty(4)
    prev_ue = np.zeros(4)
    u1 = np.empty(4)
    for k in range(m):
        row = table[regime[k]]
        j = arc_row[k]
        if j >= 0:
            for ax in range(4):
                us[ax] = arc_us[j, ax]
                ue[ax] = arc_ue[j, ax]
            # along an arc the tangent may point along X or Y: bound |u| by the XY share
            xy = math.sqrt(us[0] * us[0] + us[1] * us[1])
            ua[0] = xy
            ua[1] = xy
            ua[2] = max(abs(us[2]), abs(ue[2]))
            ua[3] = max(abs(us[3]), abs(ue[3]))
        else:
            for ax in range(4):
                us[ax] = d[k, ax] / L[k]
                ue[ax] = us[ax]
                ua[ax] = abs(us[ax])
        has_e = d[k, 3] != 0.0
        e_only = j < 0 and d[k, 0] == 0.0 and d[k, 1] == 0.0 and d[k, 2] == 0.0
        f, a = nominal_speed_accel(code, ua, F[k], L[k], has_e, e_only,
                                   j < 0 and d[k, 0] == 0.0 and d[k, 1] == 0.0, d[k, 3] < 0.0, row)
        acc[k] = a
        # arcs: the firmware cuts them into ~1 mm segments; cap by their mutual junction speed
        if j >= 0 and arc_phi[j] != 0.0:
            c, sn = math.cos(arc_phi[j]), math.sin(arc_phi[j])
            u1[0] = us[0] * c - us[1] * sn
            u1[1] = us[0] * sn + us[1] * c
            u1[2] = us[2]
            u1[3] = us[3]
            seg = arc_seg[j]
            sa = safe_speed(code, us, f, row)
            va = junction_speed(code, us, u1, f, f, a, a, seg, seg, sa, sa, row)
            if code == JERK and va < sa:
                va = sa
            if va < MINIMUM_PLANNER_SPEED:
                va = MINIMUM_PLANNER_SPEED
            if code == SCV and va < f:
                # Klipper plans each chord as a move of its own: from the junction speed va it
                # accelerates (to f at most) and decelerates back to va within the chord
                # (toolhead.py LookAheadQueue.flush: each move's own trapezoid); the arc runs at
                # that chord's average speed
                vp = math.sqrt(va * va + a * seg)
                if vp > f:
                    vp = f
                t_chord = 2.0 * (vp - va) / a + max(seg - (vp * vp - va * va) / a, 0.0) / vp
                va = seg / t_chord
            if va < f:
                f = va
        vnom[k] = f
        s0 = safe_speed(code, us, f, row)
        s1 = safe_speed(code, ue, f, row)
        safe[k] = s0 if s0 < s1 else s1
        if k == 0:
            vj_free[k] = safe[k]
        else:
            vj_free[k] = junction_speed_rows(code, prev_ue, us, vnom[k - 1], f, acc[k - 1], a,
                                             L[k - 1], L[k], safe[k - 1], safe[k],
                                             table[regime[k - 1]], row)
        vj[k] = safe[k] if stop_before[k] or k == 0 else vj_free[k]
        for ax in range(4):
            prev_ue[ax] = ue[ax]
    return vnom, acc, safe, vj, vj_free


@njit(cache=True)
def _passes(L, a, vnom, vj, safe, stop_before, last_exit, entry, exit_):
    """Backward then forward pass over moves 0..m-1; writes ``entry`` and ``exit_`` (mm/s).

    ``last_exit``: the highest exit speed of the last move (its safe speed at the end of the queue).
    """
    m = L.shape[0]
    if m == 0:
        return
    # backward (reverse) pass: the entry speed must allow decelerating to the next entry
    nxt = 0.0
    for k in range(m - 1, -1, -1):
        if k == m - 1:
            ex = last_exit
        elif stop_before[k + 1]:
            ex = safe[k]
        else:
            ex = nxt
        v = math.sqrt(ex * ex + 2.0 * a[k] * L[k])
        lim = vj[k]
        if stop_before[k] and safe[k] < lim:
            lim = safe[k]
        nxt = lim if lim < v else v
        entry[k] = nxt
    # forward pass: the entry speed must be reachable from the previous entry
    for k in range(1, m):
        if not stop_before[k]:
            v = math.sqrt(entry[k - 1] * entry[k - 1] + 2.0 * a[k - 1] * L[k - 1])
            if v < entry[k]:
                entry[k] = v
    # exit speeds: the next entry, or the safe speed into a stop, never above what is reachable
    for k in range(m):
        if k == m - 1:
            ex = last_exit
        elif stop_before[k + 1]:
            ex = safe[k]
        else:
            ex = entry[k + 1]
        v = math.sqrt(entry[k] * entry[k] + 2.0 * a[k] * L[k])
        exit_[k] = ex if ex < v else v


@njit(cache=True)
def _trapezoids(L, a, vnom, entry, exit_, peak, t_acc, t_cruise, t_dec):
    """Per move: accelerate from ``entry`` to ``peak``, cruise, decelerate to ``exit_``.

    Trapezoid when the move is long enough to reach ``vnom``; else a triangle whose peak solves
    (peak^2 - entry^2)/2a + (peak^2 - exit^2)/2a = L.
    """
    for k in range(L.shape[0]):
        v0, v1, vc, acc, d = entry[k], exit_[k], vnom[k], a[k], L[k]
        if v0 > vc:
            v0 = vc
        if v1 > vc:
            v1 = vc
        d_acc = (vc * vc - v0 * v0) / (2.0 * acc)
        d_dec = (vc * vc - v1 * v1) / (2.0 * acc)
        if d_acc + d_dec <= d:
            vp = vc
            cruise_d = d - d_acc - d_dec
        else:
            vp2 = acc * d + 0.5 * (v0 * v0 + v1 * v1)
            vp = math.sqrt(vp2)
            if vp < v0:
                vp = v0
            if vp < v1:
                vp = v1
            cruise_d = 0.0
        peak[k] = vp
        t_acc[k] = (vp - v0) / acc
        t_dec[k] = (vp - v1) / acc
        t_cruise[k] = cruise_d / vp if vp > 0.0 else 0.0
        if vp <= 0.0:   # degenerate: no speed at all (cannot happen with a > 0, L > 0)
            t_cruise[k] = 0.0


@njit(cache=True)
def plan_moves(L, a, vnom, vj, safe, stop_before):
    """The whole plan: (entry, exit, peak, t_acc, t_cruise, t_dec) per move."""
    m = L.shape[0]
    entry = np.empty(m)
    exit_ = np.empty(m)
    peak = np.empty(m)
    t_acc = np.empty(m)
    t_cruise = np.empty(m)
    t_dec = np.empty(m)
    if m == 0:
        return entry, exit_, peak, t_acc, t_cruise, t_dec
    _passes(L, a, vnom, vj, safe, stop_before, safe[m - 1], entry, exit_)
    _trapezoids(L, a, vnom, entry, exit_, peak, t_acc, t_cruise, t_dec)
    return entry, exit_, peak, t_acc, t_cruise, t_dec


@njit(cache=True)
def _window_time(wL, wa, wv, wj, ws, wstop, last):
    n = wL.shape[0]
    e2 = np.empty(n)
    x2 = np.empty(n)
    _passes(wL, wa, wv, wj, ws, wstop, last, e2, x2)
    pk = np.empty(n)
    ta = np.empty(n)
    tc = np.empty(n)
    td = np.empty(n)
    _trapezoids(wL, wa, wv, e2, x2, pk, ta, tc, td)
    t = 0.0
    for j in range(n):
        t += ta[j] + tc[j] + td[j]
    return t


@njit(cache=True)
def stop_costs(queries, L, a, vnom, vj, vj_free, safe, stop_before, entry, exit_):
    """Time (s) a full stop at the start of each move in ``queries`` adds, against the same plan
    without a stop there (``vj_free``: the junction speed the move would have without one).

    A stop only lowers speeds within the distance needed to brake from / accelerate to the fastest
    nominal speed nearby, so each query re-plans a window around the move, whose ends keep the
    plan's entry (left) and exit (right) speeds, once with and once without the stop.
    """
    m = L.shape[0]
    out = np.zeros(queries.shape[0])
    for qi in range(queries.shape[0]):
        k = queries[qi]
        if k <= 0 or k >= m:
            continue        # the first move starts from rest anyway
        # left end: walk back until braking from the fastest speed seen fits in the distance
        lo = k
        cum = 0.0
        amin = 1e300
        vmax = vnom[k]
        while lo > 0 and (lo == k or not stop_before[lo]):
            lo -= 1
            cum += L[lo]
            amin = min(amin, a[lo])
            vmax = max(vmax, vnom[lo])
            if 2.0 * amin * cum > 1.0001 * vmax * vmax + 1e-9 and lo < k - 1:
                break
        hi = k
        cum = 0.0
        amin = 1e300
        vmax = vnom[k]
        while hi < m - 1 and not stop_before[hi + 1]:
            cum += L[hi]
            amin = min(amin, a[hi])
            vmax = max(vmax, vnom[hi])
            hi += 1
            if 2.0 * amin * cum > 1.0001 * vmax * vmax + 1e-9 and hi > k + 1:
                break
        wL = L[lo:hi + 1].copy()
        wa = a[lo:hi + 1].copy()
        wv = vnom[lo:hi + 1].copy()
        wj = vj[lo:hi + 1].copy()
        ws = safe[lo:hi + 1].copy()
        wstop = stop_before[lo:hi + 1].copy()
        # the window's first move keeps the entry it has in the plan
        if not wstop[0]:
            wj[0] = min(wj[0], entry[lo])
        last = exit_[hi]
        wstop[k - lo] = True
        t_with = _window_time(wL, wa, wv, wj, ws, wstop, last)
        wstop[k - lo] = False
        wj[k - lo] = vj_free[k]
        t_without = _window_time(wL, wa, wv, wj, ws, wstop, last)
        out[qi] = max(t_with - t_without, 0.0)
    return out


@njit(cache=True)
def klipper_cruise_cap(L, a, a_smooth, vnom, vj, stop_before):
    """Klipper's "smoothed" look-ahead (klippy/toolhead.py ``LookAheadQueue.flush`` at 84104bb,
    ``minimum_cruise_ratio``; older Klipper: ``max_accel_to_decel``, the same machinery): the
    peak speed of each move is also capped as if the moves accelerated and decelerated at
    ``a_smooth`` (``Move.mcr_delta_v2``), so a run of short moves does not accelerate fully only to
    brake at once. Returns the cruise cap (mm/s) per move; entry and exit speeds are those of the
    ordinary passes, clipped to the cap (``Move.set_junction``).

    As in ``flush``: backward over one queue (the moves between two stops), a move that can
    accelerate on the smoothed speeds gets ``min((start + reachable) / 2, max_cruise, peak)``
    with ``peak`` the smoothed peak of the last move that could both accelerate and decelerate
    (or that ends a run of moves that could not); a move that cannot accelerate takes in the
    forward pass ``min(cruise of the move before, its own start)``. All in v^2.
    """
    m = L.shape[0]
    # the temporaries in one allocation (the ordering calls this per link of a Klipper file,
    # ``ordering.gap_plan.klipper_smoothing``): max_start_v2, max_mcr_start_v2, ...; the result
    # apart, so that a whole file's plan keeps m numbers alive, not 8 m
    tmp = np.empty((7, m))
    cap2, ms, msm, dv2, sdv2, cruise, start_v2 = (tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5],
                                                  tmp[6])
    out = np.empty(m)
    for k in range(m):
        dv2[k] = 2.0 * L[k] * a[k]
        sdv2[k] = min(2.0 * L[k] * a_smooth[k], dv2[k])
        cap2[k] = vnom[k] * vnom[k]
        if stop_before[k] or k == 0:
            ms[k] = 0.0
            msm[k] = 0.0
        else:
            ms[k] = min(vj[k] * vj[k], cap2[k], cap2[k - 1], ms[k - 1] + dv2[k - 1])
            msm[k] = min(ms[k], msm[k - 1] + sdv2[k - 1])
    k = m - 1
    while k >= 0:
        # one queue: from the last move back to the first one after a stop (the queue ends at rest)
        hi = k
        next_start = 0.0
        next_mcr = 0.0
        peak = 0.0
        pending = 0
        while True:
            reach = next_start + dv2[k]
            start = min(ms[k], reach)
            pending += 1
            reach_m = next_mcr + sdv2[k]
            mcr_start = min(msm[k], reach_m)
            cruise[k] = -1.0            # None: set in the forward pass
            if mcr_start < reach_m:
                if mcr_start + sdv2[k] > next_mcr or pending > 1:
                    peak = (mcr_start + reach_m) * 0.5
                cruise[k] = min((start + reach) * 0.5, cap2[k], peak)
                pending = 0
            start_v2[k] = start
            next_start = start
            next_mcr = mcr_start
            if stop_before[k] or k == 0:
                break
            k -= 1
        prev = 0.0
        for i in range(k, hi + 1):
            if cruise[i] < 0.0:
                cruise[i] = min(prev, start_v2[i])
            prev = cruise[i]
        k -= 1
    for k in range(m):
        out[k] = math.sqrt(max(min(cruise[k], cap2[k]), 0.0))
    return out
