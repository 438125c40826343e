"""Iterated local search: escape the greedy path's local optimum (formulations/ordering.md, "ils").

2-opt and Or-opt (``greedy.py``) stop at the first path no single move improves; on real infill
that can be 5-40 % above the optimum (a zig-zag block entered at the wrong corner needs several
coordinated moves). Iterated local search (Lourenço, Martin & Stützle 2003, with the kick that
LKH and Concorde's ``linkern`` use) repeats: perturb the best path with a *segment-swap kick* —
the open path's double bridge, A B C D -> A C B D with B and C each kept or reversed-and-flipped —
then descend again and keep the result if it is shorter. One 2-opt or Or-opt move cannot undo the
kick, which is why it escapes.

The descent after a kick is local: only curves next to a changed link are examined ("don't-look
bits", Bentley 1992), each with 2-opt (it as either end of the reversed run) and Or-opt (runs of
1-3 curves starting or ending at it, moved anywhere, either direction), over a precomputed matrix
of link lengths. Then the exact orientation DP of ``greedy.py`` picks each curve's candidate.

Deterministic: the kicks come from a fixed seed and the work is bounded by a kick count, not the
clock, so a group gets the same path on every machine; ``deadline`` is only a safety net.
"""
from __future__ import annotations

import numba
import numpy as np

from .._jit import now_ns
from .greedy import (IMPROVE_EPS, clusters, improve, keep_smallest, matrices,
                     nearest_neighbour, orient_dp, path_cost)
from .problem import Group

#: kicks per curve in the group, and the cap: enough to match LKH-3's tour on most of the hardest
#: peer groups (docs/BENCHMARKS.md, "Curve-ordering constants"); a kick costs ~0.15 ms at 60 curves
KICKS_PER_CURVE = 15
MAX_KICKS = 3000
#: longest segment a kick moves (a local double bridge: far-apart segments rarely pay on layers)
MAX_SEGMENT = 30
#: largest group (candidates) the link matrix is built for (m^2 doubles: 2000 -> 32 MB)
MAX_CANDS = 2000
#: share of an exact formulation's time limit its warm start (this search) may use
WARM_START_SHARE = 0.25
#: neighbour-list length: a move must create a link to one of the K nearest candidates
NEIGHBOURS = 10


@numba.njit(cache=True, inline="always")
def _link(D, ds, de, a, b):
    """Travel from candidate a's exit to candidate b's entry; a = -1: the start; b = -1: the end."""
    if a < 0:
        return ds[b]
    if b < 0:
        return de[a]
    return D[a, b]


@numba.njit(cache=True, inline="always")
def _curve(cc, k):
    return cc[k] if k >= 0 else -1


@numba.njit(cache=True)
def _apply_reverse(seq, posof, cc, flip, i, j):
    while i < j:
        t = seq[i]
        seq[i] = flip[seq[j]]
        seq[j] = flip[t]
        posof[cc[seq[i]]] = i
        posof[cc[seq[j]]] = j
        i += 1
        j -= 1
    if i == j:
        seq[i] = flip[seq[i]]


@numba.njit(cache=True)
def _apply_move(seq, posof, cc, flip, i, k, a, rev):
    """Move seq[i..k] to just after position a (a outside [i-1, k]), reversed if ``rev``."""
    L = k - i + 1
    seg = seq[i:k + 1].copy()
    if rev:
        for t in range(L):
            seg[t] = flip[seq[k - t]]
    if a > k:
        for t in range(k + 1, a + 1):
            seq[t - L] = seq[t]
        start = a - L + 1
        lo, hi = i, a
    else:
        for t in range(i - 1, a, -1):
            seq[t + L] = seq[t]
        start = a + 1
        lo, hi = a + 1, k
    for t in range(L):
        seq[start + t] = seg[t]
    for t in range(lo, hi + 1):
        posof[cc[seq[t]]] = t


@numba.njit(cache=True, inline="always")
def _gain_2opt(seq, flip, D, ds, de, lo, hi, turn):
    """Gain of reversing seq[lo..hi]: its two boundary links, plus the change of the links
    inside it (``turn``: prefix sums of each link's cost reversed minus forwards, 0 where the
    costs are the same both ways)."""
    n = len(seq)
    p = seq[lo - 1] if lo > 0 else -1
    q = seq[hi + 1] if hi < n - 1 else -1
    old = _link(D, ds, de, p, seq[lo]) + _link(D, ds, de, seq[hi], q)
    new = _link(D, ds, de, p, flip[seq[hi]]) + _link(D, ds, de, flip[seq[lo]], q)
    return old - new - (turn[hi] - turn[lo])


@numba.njit(cache=True)
def _turn_prefix(seq, flip, D, turn):
    """turn[t] = sum over links s_i -> s_(i+1), i < t, of (reversed minus forwards cost)."""
    turn[0] = 0.0
    for t in range(len(seq) - 1):
        turn[t + 1] = turn[t] + D[flip[seq[t + 1]], flip[seq[t]]] - D[seq[t], seq[t + 1]]


@numba.njit(cache=True)
def _try_curve(seq, posof, cc, flip, D, ds, de, near_out, near_in, c, turn):
    """First improving 2-opt or Or-opt move involving curve c; applied. Returns the curves next
    to a changed link (to wake them; -1: the start or end point) or an empty array.

    Only moves that create a link to one of the K nearest candidates are tried (neighbour lists,
    ``near_out[u]``: the entries nearest u's exit; ``near_in[v]``: the exits nearest v's entry),
    plus the moves to the path's two ends."""
    n = len(seq)
    i = posof[c]
    K = near_out.shape[1]
    # ---- 2-opt: reverse seq[lo..hi] with c at one end; new links p -> flip(seq[hi]) and
    # flip(seq[lo]) -> q
    for side in range(2):
        for t in range(K + 1):
            if side == 0:                 # c at lo: hi from the neighbours of p's exit
                lo = i
                if t == K:
                    hi = n - 1
                else:
                    if lo == 0:
                        break
                    v = near_out[seq[lo - 1], t]
                    hi = posof[cc[v]]
                    if seq[hi] != flip[v]:
                        continue
            else:                         # c at hi: lo from the neighbours of q's entry
                hi = i
                if t == K:
                    lo = 0
                else:
                    if hi == n - 1:
                        break
                    u = near_in[seq[hi + 1], t]
                    lo = posof[cc[u]]
                    if seq[lo] != flip[u]:
                        continue
            if hi <= lo:
                continue
            if _gain_2opt(seq, flip, D, ds, de, lo, hi, turn) > IMPROVE_EPS:
                p = seq[lo - 1] if lo > 0 else -1
                q = seq[hi + 1] if hi < n - 1 else -1
                woken = np.array([_curve(cc, p), cc[seq[lo]], cc[seq[hi]], _curve(cc, q)])
                _apply_reverse(seq, posof, cc, flip, lo, hi)
                return woken
    # ---- Or-opt: a run of 1..3 curves that starts or ends at c, inserted after position a
    for L in range(1, 4):
        if L >= n:
            break
        for side in range(2):
            s = i if side == 0 else i - L + 1
            k = s + L - 1
            if s < 0 or k >= n or (side == 1 and L == 1):
                continue
            f, l = seq[s], seq[k]
            p = seq[s - 1] if s > 0 else -1
            q = seq[k + 1] if k < n - 1 else -1
            rem = _link(D, ds, de, p, f) + _link(D, ds, de, l, q) - _link(D, ds, de, p, q)
            for t in range(4 * K + 2):
                if t == 4 * K:
                    a = -1
                elif t == 4 * K + 1:
                    a = n - 1
                else:
                    which, r = t // K, t % K
                    if which == 0:            # x -> f
                        a = posof[cc[near_in[f, r]]]
                        if seq[a] != near_in[f, r]:
                            continue
                    elif which == 1:          # l -> y
                        a = posof[cc[near_out[l, r]]] - 1
                        if seq[a + 1] != near_out[l, r]:
                            continue
                    elif which == 2:          # x -> flip(l)
                        a = posof[cc[near_in[flip[l], r]]]
                        if seq[a] != near_in[flip[l], r]:
                            continue
                    else:                     # flip(f) -> y
                        a = posof[cc[near_out[flip[f], r]]] - 1
                        if seq[a + 1] != near_out[flip[f], r]:
                            continue
                if a >= s - 1 and a <= k:
                    continue
                x = seq[a] if a >= 0 else -1
                y = seq[a + 1] if a + 1 < n else -1
                base = _link(D, ds, de, x, y)
                fwd = _link(D, ds, de, x, f) + _link(D, ds, de, l, y) - base
                rv = (_link(D, ds, de, x, flip[l]) + _link(D, ds, de, flip[f], y) - base
                      + turn[k] - turn[s])
                if fwd < rem - IMPROVE_EPS or rv < rem - IMPROVE_EPS:
                    woken = np.array([_curve(cc, p), cc[f], cc[l], _curve(cc, q), _curve(cc, x),
                                      _curve(cc, y)])
                    _apply_move(seq, posof, cc, flip, s, k, a, rv < fwd)
                    return woken
    return np.zeros(0, np.int64)


@numba.njit(cache=True)
def _descend(seq, posof, cc, flip, D, ds, de, near_out, near_in, active):
    """Local search from the curves marked in ``active`` until none of them has a move."""
    n = len(seq)
    stack = np.empty(4 * n + 64, np.int64)
    turn = np.empty(n)
    _turn_prefix(seq, flip, D, turn)
    top = 0
    for c in range(len(active)):
        if active[c]:
            stack[top] = c
            top += 1
    while top > 0:
        top -= 1
        c = stack[top]
        active[c] = False
        touched = _try_curve(seq, posof, cc, flip, D, ds, de, near_out, near_in, c, turn)
        if len(touched) == 0:
            continue
        _turn_prefix(seq, flip, D, turn)
        for cw in touched:
            if cw >= 0:
                if not active[cw] and top < len(stack):
                    active[cw] = True
                    stack[top] = cw
                    top += 1
        if not active[c] and top < len(stack):
            active[c] = True
            stack[top] = c
            top += 1


@numba.njit(cache=True)
def _ils(seq, cc, cand_start, cand_list, flip, D, ds, de, near_out, near_in, kicks, max_seg,
         seed, deadline_ns, target):
    np.random.seed(seed)
    n = len(seq)
    n_curves = len(cand_start) - 1
    best = seq.copy()
    best_cost = path_cost(best, D, ds, de, False)
    if n < 4:
        return best
    posof = np.zeros(n_curves, np.int64)
    active = np.zeros(n_curves, np.bool_)
    curve_seq = np.empty(n, np.int64)
    for it in range(kicks):
        if best_cost <= target:
            break
        # the clock without numba.objmode, which is compiled again in every process (_jit)
        if deadline_ns > 0 and (it & 15) == 0 and now_ns() > deadline_ns:
            break
        # kick: A B C D -> A C' B' D
        lb = np.random.randint(1, min(max_seg, n - 1) + 1)
        lc = np.random.randint(1, min(max_seg, n - lb) + 1)
        p1 = np.random.randint(0, n - lb - lc + 1)
        p2, p3 = p1 + lb, p1 + lb + lc
        rev_c = np.random.randint(0, 2) == 1
        rev_b = np.random.randint(0, 2) == 1
        cand = best.copy()
        w = p1
        for t in range(lc):
            cand[w] = flip[best[p3 - 1 - t]] if rev_c else best[p2 + t]
            w += 1
        for t in range(lb):
            cand[w] = flip[best[p2 - 1 - t]] if rev_b else best[p1 + t]
            w += 1
        for t in range(n):
            posof[cc[cand[t]]] = t
        for t in (p1 - 1, p1, p1 + lc - 1, p1 + lc, p3 - 1, p3):
            if 0 <= t < n:
                active[cc[cand[t]]] = True
        _descend(cand, posof, cc, flip, D, ds, de, near_out, near_in, active)
        for t in range(n):
            curve_seq[t] = cc[cand[t]]
        cand = orient_dp(curve_seq, cand_start, cand_list, D, ds, de)
        c = path_cost(cand, D, ds, de, False)
        if c < best_cost + IMPROVE_EPS:          # equal too: drifting on plateaus helps escape
            best, best_cost = cand, min(c, best_cost)
    return best


def link_matrix(group: Group, k: int = NEIGHBOURS):
    """(D, ds, de, near_out, near_in): the group's link costs (exit -> entry between candidates,
    start -> entry, exit -> end: 0 without an end) and per candidate the k candidates of other
    curves cheapest to link to from its exit (``near_out``) and into its entry (``near_in``)."""
    k = min(k, group.n_cands - 1)
    D, ds, de = matrices(group)
    near_out, near_in = _near_lists(D, np.ascontiguousarray(group.cand_curve, np.int64), max(k, 0))
    return D, ds, de, near_out, near_in


@numba.njit(cache=True)
def _near_lists(D, cc, k):
    """Both neighbour lists in one compiled pass: each row's k cheapest candidates of other
    curves, cheapest first, ties in index order, then (a group with fewer than k of them) the
    row's own curve's candidates in index order, as a stable sort of the row with those at
    infinity gives. (Numpy, a masked copy and a partial sort per row, took ~4x as long on
    200-candidate groups.)"""
    m = len(cc)
    near_out = np.empty((m, k), np.int64)
    near_in = np.empty((m, k), np.int64)
    val = np.empty(k + 1)
    idx = np.empty(k + 1, np.int64)
    for side in range(2):
        out = near_out if side == 0 else near_in
        for a in range(m):
            cnt = 0
            for b in range(m):
                if cc[a] == cc[b]:
                    continue
                cnt = keep_smallest(val, idx, cnt, k, D[a, b] if side == 0 else D[b, a], b)
            for t in range(cnt):
                out[a, t] = idx[t]
            b = 0
            while cnt < k:                              # own curve's candidates last
                if cc[b] == cc[a]:
                    out[a, cnt] = b
                    cnt += 1
                b += 1
    return near_out, near_in


def improve_ils(group: Group, order, *, kicks: int | None = None, seed: int = 0,
                deadline: float | None = None, local_optimum: bool = False,
                target: float = -np.inf) -> np.ndarray:
    """The best path found by ``kicks`` kicks from ``order`` after its own local search (default:
    KICKS_PER_CURVE per curve, at most MAX_KICKS); never longer than ``improve(order)``. Groups
    above MAX_CANDS candidates get the plain local search only. ``local_optimum``: ``order`` is
    already the output of ``improve`` (the greedy path), so that pass is not repeated."""
    order = np.asarray(order, np.int64)
    if not local_optimum:
        order = improve(group, order)
    n = group.n_curves
    if n < 4 or group.n_cands > MAX_CANDS or not group.dense:
        return order
    if kicks is None:
        kicks = min(MAX_KICKS, KICKS_PER_CURVE * n)
    if kicks <= 0:
        # nothing to kick (auto before the symmetric model): the link matrix below would cost
        # ~1 ms on a 100-curve group for nothing
        return order
    cand_start, cand_list = clusters(group)
    D, ds, de, near_out, near_in = link_matrix(group)
    deadline_ns = 0 if deadline is None else int(deadline * 1e9)
    return _ils(order, group.cand_curve.astype(np.int64), cand_start, cand_list,
                group.cand_flip.astype(np.int64), D, ds, de, near_out, near_in,
                int(kicks), MAX_SEGMENT, int(seed), deadline_ns, float(target))


def warm_start(group: Group, hint, t0: float, time_limit_s: float):
    """The exact formulations' incumbent: ``hint`` if given, else nearest neighbour then
    ``improve_ils`` within WARM_START_SHARE of the limit that started at ``t0``."""
    if hint is not None:
        return hint
    return improve_ils(group, nearest_neighbour(group), deadline=t0 + WARM_START_SHARE * time_limit_s)
