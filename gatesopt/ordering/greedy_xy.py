"""The greedy local search on XY points (Euclidean travel): for groups above
``problem.DENSE_MAX_CANDS`` candidates, which get no link matrix (``greedy`` uses these kernels
there; for the time objective the travel's length stands in for its time, and the path found is
priced link by link). The same moves as ``greedy``'s matrix kernels (formulations/ordering.md,
"greedy"), on the distances |q_u - p_v|.
"""
from __future__ import annotations

import numba
import numpy as np

#: a move must shorten the path by more than this to be taken: float noise is no improvement
IMPROVE_EPS = 1e-9


@numba.njit(cache=True, inline="always")
def _d(ax, ay, bx, by):
    return np.sqrt((ax - bx) ** 2 + (ay - by) ** 2)


@numba.njit(cache=True)
def path_cost_xy(seq, ent, ext, sx, sy, closed, has_end=False, ex=0.0, ey=0.0):
    """Travel (mm) of candidate order ``seq``: from (sx, sy) or, ``closed``, around the tour; on
    to (ex, ey) with ``has_end``."""
    n = len(seq)
    if n == 0:
        return 0.0
    if closed:
        t = _d(ext[seq[n - 1], 0], ext[seq[n - 1], 1], ent[seq[0], 0], ent[seq[0], 1])
    else:
        t = _d(sx, sy, ent[seq[0], 0], ent[seq[0], 1])
    for i in range(n - 1):
        t += _d(ext[seq[i], 0], ext[seq[i], 1], ent[seq[i + 1], 0], ent[seq[i + 1], 1])
    if has_end and not closed:
        t += _d(ext[seq[n - 1], 0], ext[seq[n - 1], 1], ex, ey)
    return t


@numba.njit(cache=True)
def local_search_xy(seq, ent, ext, flip, sx, sy, closed, max_passes, has_end=False, ex=0.0, ey=0.0):
    """2-opt with flips + Or-opt (runs of 1..3, either direction), first improvement.

    One numba kernel of ~120 lines: both moves share the loop over passes and the sequence they
    rewrite in place; split into calls, each move's scan would pass the arrays again per position.

    Open path (``closed`` False): position -1 is the start point (exit only), and after the last
    curve comes the end point (``has_end``: the next fixed group's entry) or nothing (travel 0).
    Closed tour: positions wrap around.
    """
    n = len(seq)
    seq = seq.copy()
    if n < 2:
        return seq
    for _ in range(max_passes):
        improved = False
        # ---- 2-opt: reverse seq[i..j] and flip each curve in it
        for i in range(n):
            if closed:
                p = seq[(i - 1) % n]
                px, py = ext[p, 0], ext[p, 1]
            elif i == 0:
                px, py = sx, sy
            else:
                px, py = ext[seq[i - 1], 0], ext[seq[i - 1], 1]
            ni = seq[i]
            jmax = n - 1 if not closed else (n - 2 if i == 0 else n - 1)
            for j in range(i + 1, jmax + 1):
                xj = seq[j]
                old = _d(px, py, ent[ni, 0], ent[ni, 1])
                new = _d(px, py, ext[xj, 0], ext[xj, 1])
                if closed or j < n - 1:
                    q = seq[(j + 1) % n]
                    old += _d(ext[xj, 0], ext[xj, 1], ent[q, 0], ent[q, 1])
                    new += _d(ent[ni, 0], ent[ni, 1], ent[q, 0], ent[q, 1])
                elif has_end:
                    old += _d(ext[xj, 0], ext[xj, 1], ex, ey)
                    new += _d(ent[ni, 0], ent[ni, 1], ex, ey)
                if new < old - IMPROVE_EPS:
                    a, b = i, j
                    while a < b:
                        t = seq[a]
                        seq[a] = flip[seq[b]]
                        seq[b] = flip[t]
                        a += 1
                        b -= 1
                    if a == b:
                        seq[a] = flip[seq[a]]
                    improved = True
                    ni = seq[i]
        # ---- Or-opt: move seq[i..k] (k = i+L-1) after position a, forwards or reversed
        for L in range(1, 4):
            if L >= n:
                break
            i = 0
            while i + L - 1 < n:
                k = i + L - 1
                f, l = seq[i], seq[k]
                # removal gain
                if i == 0:
                    if closed:
                        p = seq[n - 1]
                        px, py = ext[p, 0], ext[p, 1]
                    else:
                        px, py = sx, sy
                else:
                    px, py = ext[seq[i - 1], 0], ext[seq[i - 1], 1]
                has_next = closed or k < n - 1
                rem = _d(px, py, ent[f, 0], ent[f, 1])
                if has_next:
                    q = seq[(k + 1) % n]
                    rem += _d(ext[l, 0], ext[l, 1], ent[q, 0], ent[q, 1]) - _d(px, py, ent[q, 0], ent[q, 1])
                elif has_end:
                    rem += _d(ext[l, 0], ext[l, 1], ex, ey) - _d(px, py, ex, ey)
                if closed and L >= n - 1:
                    break
                best_delta = -IMPROVE_EPS
                best_a = -2
                best_rev = False
                # insertion after position a (a = -1: right after the start point)
                for a in range(-1, n):
                    if a >= i - 1 and a <= k:
                        continue
                    if closed and a == -1:
                        continue
                    if a == -1:
                        ax, ay = sx, sy
                    else:
                        ax, ay = ext[seq[a], 0], ext[seq[a], 1]
                    b_next = closed or a < n - 1
                    if b_next:
                        bnode = seq[(a + 1) % n]
                        if closed and (a + 1) % n == i:
                            continue
                        bx, by = ent[bnode, 0], ent[bnode, 1]
                        base = _d(ax, ay, bx, by)
                        fwd = _d(ax, ay, ent[f, 0], ent[f, 1]) + _d(ext[l, 0], ext[l, 1], bx, by)
                        rev = _d(ax, ay, ext[l, 0], ext[l, 1]) + _d(ent[f, 0], ent[f, 1], bx, by)
                    elif has_end:
                        base = _d(ax, ay, ex, ey)
                        fwd = _d(ax, ay, ent[f, 0], ent[f, 1]) + _d(ext[l, 0], ext[l, 1], ex, ey)
                        rev = _d(ax, ay, ext[l, 0], ext[l, 1]) + _d(ent[f, 0], ent[f, 1], ex, ey)
                    else:
                        base = 0.0
                        fwd = _d(ax, ay, ent[f, 0], ent[f, 1])
                        rev = _d(ax, ay, ext[l, 0], ext[l, 1])
                    df = fwd - base - rem
                    dr = rev - base - rem
                    if df < best_delta:
                        best_delta, best_a, best_rev = df, a, False
                    if dr < best_delta:
                        best_delta, best_a, best_rev = dr, a, True
                if best_a != -2:
                    seq = move_run(seq, flip, i, k, best_a, best_rev)
                    improved = True
                i += 1
        if not improved:
            break
    return seq


@numba.njit(cache=True)
def move_run(seq, flip, i, k, after, reverse):
    """Or-opt's move, shared by the XY and the matrix kernels (``greedy``): the run seq[i..k]
    taken out and put back after position ``after`` of the sequence without it (-1: first),
    reversed with each curve flipped where ``reverse``."""
    L = k - i + 1
    seg = seq[i:k + 1].copy()
    if reverse:
        seg2 = np.empty_like(seg)
        for t in range(L):
            seg2[t] = flip[seg[L - 1 - t]]
        seg = seg2
    rest = np.concatenate((seq[:i], seq[k + 1:]))
    pos = after + 1 if after < i else after + 1 - L
    return np.concatenate((rest[:pos], seg, rest[pos:]))


@numba.njit(cache=True)
def orient_dp_xy(curve_seq, cand_start, cand_list, ent, ext, sx, sy, has_end=False, ex=0.0, ey=0.0):
    """Exact candidate choice (direction, seam) for a fixed curve order: DP over clusters."""
    n = len(curve_seq)
    out = np.empty(n, np.int64)
    if n == 0:
        return out
    maxc = 0
    for c in range(len(cand_start) - 1):
        maxc = max(maxc, cand_start[c + 1] - cand_start[c])
    cost = np.full((n, maxc), np.inf)
    back = np.full((n, maxc), -1, np.int64)
    c0 = curve_seq[0]
    for a in range(cand_start[c0 + 1] - cand_start[c0]):
        v = cand_list[cand_start[c0] + a]
        cost[0, a] = _d(sx, sy, ent[v, 0], ent[v, 1])
    for t in range(1, n):
        cp, cc = curve_seq[t - 1], curve_seq[t]
        for b in range(cand_start[cc + 1] - cand_start[cc]):
            v = cand_list[cand_start[cc] + b]
            for a in range(cand_start[cp + 1] - cand_start[cp]):
                u = cand_list[cand_start[cp] + a]
                c = cost[t - 1, a] + _d(ext[u, 0], ext[u, 1], ent[v, 0], ent[v, 1])
                if c < cost[t, b]:
                    cost[t, b] = c
                    back[t, b] = a
    cl = curve_seq[n - 1]
    if has_end:
        for a in range(cand_start[cl + 1] - cand_start[cl]):
            u = cand_list[cand_start[cl] + a]
            cost[n - 1, a] += _d(ext[u, 0], ext[u, 1], ex, ey)
    b = 0
    for a in range(cand_start[cl + 1] - cand_start[cl]):
        if cost[n - 1, a] < cost[n - 1, b]:
            b = a
    for t in range(n - 1, -1, -1):
        ct = curve_seq[t]
        out[t] = cand_list[cand_start[ct] + b]
        b = back[t, b]
    return out
