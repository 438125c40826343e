"""Cheap lower bounds on a group's open-path travel (formulations/ordering.md, "Bounds").

An open path from the start point through n curves uses exactly n links: one from the start
into the first curve and one into each other curve from some other curve's exit; and n - 1 links
out of curves (the last curve leaves to nothing). Relaxing "which" to "the cheapest possible":

    LB_in  = sum_i in_i + min_k (s_k - in_i=k)     in_i: cheapest link from another curve's exit
                                                  into any candidate of curve i; s_k: cheapest
                                                  link from the start into curve k
    LB_out = min_k s_k + sum_i out_i - max_i out_i out_i: cheapest link out of curve i
    LB_half: each link split in halves between the curves it joins (see ``_half_link``)

All need only each candidate's cheapest link in and out: a column and row minimum of the link
matrix (any costs: the time objective's are asymmetric and break the triangle inequality, which
none of these bounds uses), or for groups without a matrix a KD-tree query over the points
(travel distance only). They serve as the proof of optimality for the many small or
trivially-chained groups of real layers (for instance a group whose heuristic path uses exactly
each curve's cheapest links), and as the reported bound for groups no exact formulation touched.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .problem import EuclideanCosts, Group


def _nearest_other(src_xy, src_curve, dst_xy, dst_curve, n_curves) -> np.ndarray:
    """For each src point, distance to the nearest dst point of another curve."""
    tree = cKDTree(dst_xy)
    per_curve = np.bincount(dst_curve, minlength=n_curves).max()
    k = int(min(per_curve + 1, len(dst_xy)))
    d, idx = tree.query(src_xy, k=k)
    d = d.reshape(len(src_xy), k)
    idx = idx.reshape(len(src_xy), k)
    same = dst_curve[np.minimum(idx, len(dst_xy) - 1)] == src_curve[:, None]
    d = np.where(same | (idx >= len(dst_xy)), np.inf, d)
    return d.min(axis=1)


def lower_bound(group: Group) -> float:
    """max(LB_in, LB_out) for the group (0 for an empty group)."""
    n = group.n_curves
    if n == 0:
        return 0.0
    cc = group.cand_curve
    s_cand = group.start_cost()
    e_cand = group.end_cost()
    if n == 1:
        return float((s_cand + e_cand).min())
    s = np.full(n, np.inf)
    np.minimum.at(s, cc, s_cand)
    e = np.full(n, np.inf)
    np.minimum.at(e, cc, e_cand)
    if group.dense:
        # the cheapest link into each candidate (its column of the link matrix; inf within its
        # own curve) and out of it (its row): valid for any costs, asymmetric or not
        D = group.arc_cost()
        into, out_ = D.min(axis=0), D.min(axis=1)
    elif isinstance(group.costs, EuclideanCosts) or group.costs is None:
        into = _nearest_other(group.cand_entry_xy, cc, group.cand_exit_xy, cc, n)   # per candidate
        out_ = _nearest_other(group.cand_exit_xy, cc, group.cand_entry_xy, cc, n)
    else:
        # no link matrix and costs that are not distances (a group above DENSE_MAX_CANDS under
        # the time objective): a path enters its first curve from the start, that is all
        return float(max(s.min() + e.min(), 0.0))
    in_c = np.full(n, np.inf)
    np.minimum.at(in_c, cc, into)
    out_c = np.full(n, np.inf)
    np.minimum.at(out_c, cc, out_)
    lb_in = in_c.sum() + (s - in_c).min() + e.min()
    lb_out = s.min() + out_c.sum() - (out_c - e).max()
    return float(max(lb_in, lb_out, _half_link(group, s_cand, e_cand, into, out_), 0.0))


def _half_link(group: Group, s_cand, e_cand, into, out_) -> float:
    """LB_half: every link is split in halves, one charged to the curve it leaves and one to the
    curve it enters; a candidate pays for its own entry *and* exit end, which couples the two ends
    of a curve (an open line cannot use its best end twice)."""
    n, cc = group.n_curves, group.cand_curve
    mid = 0.5 * into + 0.5 * out_                 # a curve in the middle of the path
    first = s_cand + 0.5 * out_                   # entered from the start point
    last = 0.5 * into + e_cand                    # leaves to the end point (or nothing)
    h = np.full(n, np.inf)
    np.minimum.at(h, cc, mid)
    f = np.full(n, np.inf)
    np.minimum.at(f, cc, first)
    lt = np.full(n, np.inf)
    np.minimum.at(lt, cc, last)
    df, dl = f - h, lt - h
    i_f = np.argsort(df)[:2]
    i_l = np.argsort(dl)[:2]
    best = min(df[a] + dl[b] for a in i_f for b in i_l if a != b)
    return float(h.sum() + best)
