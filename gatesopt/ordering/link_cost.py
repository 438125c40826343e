"""One link's price by how ``emitter.emit`` writes it (formulations/ordering.md, "Cost model"):
the kernels ``cost.TimePricer`` calls per link (``link_one``) and ``cost._dense`` per group.

- copied: the slicer's gap, ``copy_ms``;
- reversed (``reversed_link``, ``reversed_ms``): the slicer's gap between the two curves the
  other way round, written backwards (``gaps.reversed_gap``);
- rebuilt (``rebuilt_s``): retraction (after the wipe, ``wipes``), lift, travel, lowering,
  unretraction, planned as the planner plans them (``gap_plan``), as ``gaps.rebuilt_gap`` writes
  them.
"""
from __future__ import annotations

import numba
import numpy as np

from .gap_plan import MOVE_EPS_MM, W_F, W_L, end_side, joined_s
from .gaps import REVERSE_EPS
from .move_times import MT_CODE, trapezoid_one_s
from .wipes import WIPE_E_EPS_MM


@numba.njit(cache=True)
def rebuilt_s(dx, dy, z0, z1, retract, use_fw, r, net, mt, style, w, p, po, c, co, ends, row,
               wipe=-1):
    """Time (s) of a rebuilt travel (``gaps.rebuilt_gap``): retraction (E, at the retract feed),
    lift by the z-hop if it retracts, the straight XY travel (dx, dy), lowering, and the
    unretraction that brings the consumed gaps to their net E (or that net E alone). ``wipe``
    >= 0: curve p's wipe on that side first (``wipes.SlicerWipes``, ``ends[11:15]``), its
    moves at their feeds, then the rest of the retraction in place and the travel from where
    the wipe ended. ``mt``:
    MoveTimes.vector(); ``style``: (retract feed, unretract feed, travel feed, z feed, hop).
    With the file's limits (``mt[MT_CODE] >= 0``) the moves are planned together, as the planner
    plans them (``plan_moves_s``, in the work array ``w``: ``work_array(JOINED_MAX_MOVES)``),
    joined to the last move of curve p and the first of curve c (sides ``po`` / ``co``,
    ``gap_plan.joined_s``), under the limits ``row`` (``TimePricer.gap_rows``); else each alone
    from and to its kind's junction speed."""
    v_r, v_u, v_xy, v_z, hop = style[0], style[1], style[2], style[3], style[4]
    n_wipe = ends[11][p, wipe] if wipe >= 0 else 0
    e_wipe = ends[13][p, wipe] if wipe >= 0 else 0.0
    if wipe >= 0:
        dx -= ends[14][p, wipe, 0]
        dy -= ends[14][p, wipe, 1]
    dist = np.sqrt(dx * dx + dy * dy)
    z_up = max(z0, z1)
    if retract and hop > 0.0:
        z_up += hop
    e_r = r - e_wipe if retract and not use_fw else 0.0
    e_u = abs(net + r) if retract and not use_fw else abs(net)
    e_u_sign = 1.0 if (net + r if retract and not use_fw else net) >= 0.0 else -1.0
    if mt[MT_CODE] >= 0.0:
        w[:, :] = 0.0
        n = 0
        if po >= 0:
            w[n, :] = ends[1][p, po]
            n += 1
        for k in range(n_wipe):
            mv = ends[12][p, wipe, k]
            w[n, 0], w[n, 1], w[n, 3] = mv[0], mv[1], mv[2]
            xy = np.sqrt(mv[0] * mv[0] + mv[1] * mv[1])
            w[n, W_L], w[n, W_F] = xy if xy > MOVE_EPS_MM else abs(mv[2]), mv[3]
            n += 1
        if e_r > MOVE_EPS_MM:
            w[n, 3], w[n, W_L], w[n, W_F] = -e_r, e_r, v_r
            n += 1
        if z_up - z0 > MOVE_EPS_MM:
            w[n, 2], w[n, W_L], w[n, W_F] = z_up - z0, z_up - z0, v_z
            n += 1
        if dist > MOVE_EPS_MM:
            w[n, 0], w[n, 1], w[n, W_L], w[n, W_F] = dx, dy, dist, v_xy
            n += 1
        if abs(z_up - z1) > MOVE_EPS_MM:
            w[n, 2], w[n, W_L], w[n, W_F] = z1 - z_up, abs(z_up - z1), v_z
            n += 1
        if e_u > MOVE_EPS_MM:
            w[n, 3], w[n, W_L], w[n, W_F] = e_u_sign * e_u, e_u, v_u
            n += 1
        if co >= 0:
            w[n, :] = ends[0][c, co]
            n += 1
        return joined_s(w, n, int(mt[MT_CODE]), row, p, po, c, co, ends)
    t = 0.0
    for k in range(n_wipe):
        # a wipe's moves by their kinds (``MoveTimes.steps_s``): XY with E at the print
        # acceleration, an XY travel, an E-only retraction
        mv = ends[12][p, wipe, k]
        xy = np.sqrt(mv[0] * mv[0] + mv[1] * mv[1])
        if xy > MOVE_EPS_MM:
            t += trapezoid_one_s(xy, min(mv[3], mt[1]), mt[3] if mv[2] != 0.0 else mt[0], mt[2])
        else:
            t += trapezoid_one_s(abs(mv[2]), min(mv[3], mt[5]), mt[4], mt[6])
    if e_r > MOVE_EPS_MM:
        t += trapezoid_one_s(e_r, min(v_r, mt[5]), mt[4], mt[6])
    if e_u > MOVE_EPS_MM:
        t += trapezoid_one_s(e_u, min(v_u, mt[5]), mt[4], mt[6])
    if z_up - z0 > MOVE_EPS_MM:
        t += trapezoid_one_s(z_up - z0, min(v_z, mt[8]), mt[7], mt[9])
    if dist > MOVE_EPS_MM:
        t += trapezoid_one_s(dist, min(v_xy, mt[1]), mt[0], mt[2])
    if abs(z_up - z1) > MOVE_EPS_MM:
        t += trapezoid_one_s(abs(z_up - z1), min(v_z, mt[8]), mt[7], mt[9])
    return t


@numba.njit(cache=True, inline="always")
def reversed_link(p, p_changed, c, fx, fy, tx, ty, group_first, rev_ok, rev_plain, rev_start,
                   rev_end):
    """``gaps.ReversibleGaps.applies`` for the link p -> c leaving p at (fx, fy) (the head stands
    at p's end if p is printed as the slicer printed it) and entering c at (tx, ty)."""
    if p != c + 1 or c < 0 or not rev_ok[p] or group_first[p] != group_first[c]:
        return False
    if c != group_first[c] and not rev_plain[c]:
        return False
    hx, hy = (fx, fy) if p_changed else (rev_end[p, 0], rev_end[p, 1])
    return (abs(hx - rev_start[p, 0]) <= REVERSE_EPS and abs(hy - rev_start[p, 1]) <= REVERSE_EPS
            and abs(tx - rev_end[c, 0]) <= REVERSE_EPS and abs(ty - rev_end[c, 1]) <= REVERSE_EPS)


@numba.njit(cache=True, inline="always")
def reversed_ms(p, c, group_first, own_net, rev_ms, style, mt):
    """A reversed gap's cost (ms): the gap's moves backwards (``rev_ms``:
    ``TimePricer.rev_ms``), plus the E move of the net E of c's own gap, which the entry into c
    consumes (``gaps.reversed_gap``)."""
    t = rev_ms[p]
    if c != group_first[c] and abs(own_net[c]) > MOVE_EPS_MM:
        t += trapezoid_one_s(abs(own_net[c]), min(style[1], mt[5]), mt[4], mt[6]) * 1000.0
    return t


@numba.njit(cache=True, inline="always")
def link_one(p, p_changed, c, c_changed, fx, fy, tx, ty, z0, z1, group_first, own_net, own_r,
              own_fw_net, own_fw, bnd_net, bnd_r, bnd_fw_net, bnd_fw, copy_ms, rev_ok, rev_plain,
              rev_start, rev_end, rule, style, mt, w, ends):
    """One link's cost (ms) as emitted, mirroring ``gaps.rebuilt_gap`` and ``travel.TravelRule``,
    except the combing exemption: returns (cost, whether the exemption applies if the travel
    crosses no wall, the cost then). ``rule``: TravelRule.vector(); ``w``: ``work_array()``."""
    if p >= 0 and p == c - 1 and not p_changed and not c_changed:
        return copy_ms[c], False, 0.0                   # the slicer's own gap, copied
    if p >= 0 and reversed_link(p, p_changed, c, fx, fy, tx, ty, group_first, rev_ok, rev_plain,
                                 rev_start, rev_end):
        return reversed_ms(p, c, group_first, own_net, ends[8], style, mt), False, 0.0
    retract_mm, min_travel, fw_style, comb_cap = rule[0], rule[1], rule[2] > 0.5, rule[3]
    crossing = p < 0 or group_first[c] != group_first[p]
    own = c != group_first[c]
    net = 0.0
    r_b = 0.0
    r_i = 0.0
    fw_net = 0
    fw_ret = False
    fw_bnd = False
    if crossing:
        net += bnd_net[c]
        r_b = bnd_r[c]
        fw_net += bnd_fw_net[c]
        fw_ret = bnd_fw[c]
        fw_bnd = bnd_fw[c]
    if own:
        net += own_net[c]
        r_i = own_r[c]
        fw_net += own_fw_net[c]
        fw_ret = fw_ret or own_fw[c]
    use_fw = fw_net == 0 and (fw_ret or (fw_style and r_b <= 0.0 and r_i <= 0.0))
    r = r_b if r_b > 0.0 else retract_mm
    dx = tx - fx
    dy = ty - fy
    dist = np.sqrt(dx * dx + dy * dy)
    dz = abs(z1 - z0)
    moving = dist > MOVE_EPS_MM or dz > MOVE_EPS_MM
    if use_fw:
        retract = moving and (fw_bnd or (fw_style and dist >= min_travel))
    else:
        retract = moving and r > 0.0 and (r_b > 0.0 or (retract_mm > 0.0 and dist >= min_travel))
    po = end_side(p, p_changed, ends)
    co = end_side(c, c_changed, ends)
    row = ends[9][ends[10][c]]          # the limits at the slicer's travel into c
    # the wipe out of p on the side it is left by (``wipes.SlicerWipes``), retracting by E
    wipe = -1
    if retract and not use_fw and p >= 0:
        side = 1 if p_changed else 0     # (``wipes.side_of``)
        if ends[11][p, side] > 0 and ends[13][p, side] <= r + WIPE_E_EPS_MM:
            wipe = side
    t = rebuilt_s(dx, dy, z0, z1, retract, use_fw, r, net, mt, style, w, p, po, c, co,
                   ends, row, wipe) * 1000.0
    if retract and comb_cap > 0.0 and dist <= comb_cap and dz <= MOVE_EPS_MM:
        return t, True, rebuilt_s(dx, dy, z0, z1, False, use_fw, r, net, mt, style, w, p, po, c,
                                   co, ends, row) * 1000.0
    return t, False, 0.0
