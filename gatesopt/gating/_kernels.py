"""Sequential cores of the gating problem builder (numba): one pass over the steps per rotation.

The semantics are those of ``problem.py`` and ``rotation.py`` (formulations/gating.md §1 and §6);
these loops only make them linear-time without temporaries, with the timeline's tolerance
(``timeline.TIME_EPS_S``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .timeline import TIME_EPS_S as EPS_S


@njit(cache=True)
def rotated_steps(start_xy, end_xy, steps0, arc, lo, hi, cx, cy, c, s, snap_mm, out, snap_out):
    """Fill ``out`` (n, 2) with X/Y stepping under rotation (c, s) of rows [lo, hi) about (cx, cy),
    and ``snap_out`` (n,) with the displacement each row has snapped to zero.

    A row's end is rotated iff lo <= i < hi, its start iff lo < i <= hi (or lo == 0 and i == 0);
    rows that are arcs or move neither X nor Y keep ``steps0``. Returns the largest snap."""
    n = steps0.shape[0]
    snap_max = 0.0
    for i in range(n):
        out[i, 0] = steps0[i, 0]
        out[i, 1] = steps0[i, 1]
        snap_out[i] = 0.0
    top = hi + 1 if hi + 1 <= n else n
    for i in range(lo, top):
        if arc[i] or not (steps0[i, 0] or steps0[i, 1]):
            continue
        sx, sy = start_xy[i, 0], start_xy[i, 1]
        if i > lo or lo == 0:
            x, y = sx - cx, sy - cy
            sx, sy = c * x - s * y + cx, s * x + c * y + cy
        ex, ey = end_xy[i, 0], end_xy[i, 1]
        if i < hi:
            x, y = ex - cx, ey - cy
            ex, ey = c * x - s * y + cx, s * x + c * y + cy
        dx = abs(ex - sx)
        dy = abs(ey - sy)
        out[i, 0] = dx > snap_mm
        out[i, 1] = dy > snap_mm
        sn = 0.0
        if dx <= snap_mm and dx > sn:
            sn = dx
        if dy <= snap_mm and dy > sn:
            sn = dy
        snap_out[i] = sn
        if sn > snap_max:
            snap_max = sn
    return snap_max


@njit(cache=True)
def single_axis_time(dx, dy, w, c, s, snap_mm):
    """Time (sum of ``w``) of moves (dx, dy) that run on one axis after rotating by (c, s)."""
    tot = 0.0
    for i in range(dx.shape[0]):
        rx = abs(c * dx[i] - s * dy[i])
        ry = abs(s * dx[i] + c * dy[i])
        if rx <= snap_mm or ry <= snap_mm:
            tot += w[i]
    return tot


@njit(cache=True)
def idle_intervals(start_s, steps, rate, cum, stall_w, sa, el, on_line, stall_off_s, stall_on_s, per_event,
                   split_lines, whole):
    """Idle intervals of one motor (or enable group): (start, end, off_row, on_row, prev_row,
    next_row, saving_j, lines, stall_s, stall_j), all of length = number of intervals.
    ``per_event``: instruction lines (each with its stall) per off or on moment; ``split_lines``:
    an instruction inside a step splits it (one line more); False when the firmware times the
    switch itself and the line goes between steps (``firmware.Schedule``); ``whole`` (n,) bool:
    steps an instruction must not split (``timeline.whole_steps``): an off that falls inside one
    comes at its end, an on at its start (the safe sides)."""
    n = steps.shape[0]
    T = start_s[n]
    cap = 1
    for i in range(n):
        if steps[i]:
            cap += 1
    g_start = np.empty(cap)
    g_end = np.empty(cap)
    off_row = np.empty(cap, np.int64)
    on_row = np.empty(cap, np.int64)
    prev_row = np.empty(cap, np.int64)
    next_row = np.empty(cap, np.int64)
    k = 0
    prev = -1
    for j in range(n + 1):
        if j < n and not steps[j]:
            continue
        a = 0.0 if prev < 0 else start_s[prev + 1] + el
        b = T if j == n else start_s[j] - sa
        if b > T:
            b = T
        if prev >= 0:
            r = prev + 1
            while r < n and start_s[r + 1] <= a + EPS_S:
                r += 1
            if r < n and whole[r] and start_s[r] + EPS_S < a:
                a = start_s[r + 1]
        if j < n:
            q = j - 1
            while q >= 0 and start_s[q] >= b - EPS_S:
                q -= 1
            if q >= 0 and whole[q] and b < start_s[q + 1] - EPS_S:
                b = start_s[q]
        ok = b > a + EPS_S
        if prev < 0 and not b > 0.0:
            ok = False
        if ok:
            g_start[k] = a
            g_end[k] = b
            prev_row[k] = prev
            next_row[k] = j
            k += 1
        prev = j
    saving = np.empty(k)
    lines = np.empty(k, np.int64)
    stall_s = np.empty(k)
    stall_j = np.empty(k)
    for g in range(k):
        a = g_start[g]
        b = g_end[g]
        # off row: last row starting at or before a (+eps), not before prev + 1
        r = prev_row[g] + 1
        while r < n and start_s[r + 1] <= a + EPS_S:
            r += 1
        off_row[g] = r
        # on row: the first row starting at b (within eps), else the row holding b; not after next
        if b >= T - EPS_S:
            q = n
        else:
            idx = next_row[g]
            while idx > 0 and start_s[idx - 1] >= b - EPS_S:
                idx -= 1
            if abs(start_s[idx] - b) <= EPS_S:
                q = idx
            else:
                q = idx - 1
            if q > next_row[g]:
                q = next_row[g]
        on_row[g] = q
        # saving: integral of rate over [a, b]
        ia = cum[r] + (rate[r] * (a - start_s[r]) if r < n else 0.0)
        ib = cum[q] + (rate[q] * (b - start_s[q]) if q < n else 0.0)
        sv = ib - ia
        saving[g] = sv if sv > 0.0 else 0.0
        has_on = on_line and q < n
        ln = per_event
        rr = r if r < n else n - 1
        if split_lines and r < n and start_s[rr] + EPS_S < a and a < start_s[rr + 1] - EPS_S:
            ln += 1
        st = stall_off_s * per_event
        sj = stall_off_s * per_event * stall_w[rr]
        if has_on:
            ln += per_event
            qq = q
            if split_lines and start_s[qq] + EPS_S < b and b < start_s[qq + 1] - EPS_S:
                ln += 1
            st += stall_on_s * per_event
            sj += stall_on_s * per_event * stall_w[qq]
        lines[g] = ln
        stall_s[g] = st
        stall_j[g] = sj
    return (g_start[:k], g_end[:k], off_row[:k], on_row[:k], prev_row[:k], next_row[:k], saving, lines,
            stall_s, stall_j)


@njit(cache=True)
def angle_stats(steps, steps0, arc, dur, rdur_x, rdur_y):
    """(single-axis time, straight X + Y move count, X saving bound, Y saving bound) of one angle:
    XY rows (not arcs) where exactly one of X/Y steps, and the sum of ``rdur`` over rows where the
    motor does not step."""
    single = 0.0
    straight = 0
    ubx = 0.0
    uby = 0.0
    for i in range(steps.shape[0]):
        sx = steps[i, 0]
        sy = steps[i, 1]
        if (steps0[i, 0] or steps0[i, 1]) and not arc[i] and sx != sy:
            single += dur[i]
            straight += 1
        if not sx:
            ubx += rdur_x[i]
        if not sy:
            uby += rdur_y[i]
    return single, straight, ubx, uby


@njit(cache=True)
def chain_choice(net, p):
    """Most valuable subset of a chain of intervals (``net`` each, in time order) in which interval
    j may follow interval i only if i < p[j] (``problem.chain_predecessors``: rule B, the spacing
    grows going back). Returns a bool mask. best(j) = net[j] + (the best subset of chain[:p[j]]);
    a tie keeps the interval out (fewer lines)."""
    k = net.shape[0]
    top = np.zeros(k + 1)                 # top[q]: the best value over chain[:q]
    last = np.full(k + 1, -1, np.int64)   # the last interval of that best subset (-1: none)
    for j in range(k):
        v = net[j] + top[p[j]]
        if v > top[j]:
            top[j + 1] = v
            last[j + 1] = j
        else:
            top[j + 1] = top[j]
            last[j + 1] = last[j]
    out = np.zeros(k, np.bool_)
    q = k
    while last[q] >= 0:
        j = last[q]
        out[j] = True
        q = p[j]
    return out
