"""Edmonds' weighted blossom algorithm, primal-dual, O(V^3), with integer weights: the compiled
kernels of ``matching.min_cost_perfect_matching`` (formulations/ordering.md, "Bounds").

Vertices are 1..n, blossoms n+1..n_x (0: none). Per (blossom or) vertex pair the edge stored
between them (``gu``, ``gv``: its end vertices, ``gw``: its weight, 0 = no edge); ``lab``: twice
the duals; ``flower``: the cycle of children of each blossom. Kept as many small numba kernels
rather than one: each is one step of the textbook algorithm (grow, augment, shrink, expand) and
reads as it. ``perfect_matching`` is the entry point.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _slack2(gu, gv, gw, lab, a, b):
    """Twice the reduced cost of the edge stored between (blossoms or vertices) a and b."""
    return lab[gu[a, b]] + lab[gv[a, b]] - 2 * gw[a, b]


@numba.njit(cache=True)
def _update_slack(gu, gv, gw, lab, slack, u, x):
    if slack[x] == 0 or _slack2(gu, gv, gw, lab, u, x) < _slack2(gu, gv, gw, lab, slack[x], x):
        slack[x] = u


@numba.njit(cache=True)
def _set_slack(n, gu, gv, gw, lab, slack, st, S, x):
    slack[x] = 0
    for u in range(1, n + 1):
        if gw[u, x] > 0 and st[u] != x and S[st[u]] == 0:
            _update_slack(gu, gv, gw, lab, slack, u, x)


@numba.njit(cache=True)
def _q_push(n, flower, flen, queue, qt, x):
    """Append vertex x, or every vertex of blossom x, to the queue; returns the new tail."""
    stack = [x]
    while len(stack):
        y = stack.pop()
        if y <= n:
            if qt >= len(queue):
                return -1
            queue[qt] = y
            qt += 1
        else:
            for i in range(flen[y]):
                stack.append(flower[y, i])
    return qt


@numba.njit(cache=True)
def _set_st(n, flower, flen, st, x, b):
    stack = [x]
    while len(stack):
        y = stack.pop()
        st[y] = b
        if y > n:
            for i in range(flen[y]):
                stack.append(flower[y, i])


@numba.njit(cache=True)
def _get_pr(flower, flen, b, xr):
    """Position of child xr in blossom b's cycle, made even by reversing the cycle if needed."""
    k = flen[b]
    pr = 0
    while flower[b, pr] != xr:
        pr += 1
    if pr % 2 == 1:
        flower[b, 1:k] = flower[b, 1:k][::-1].copy()
        return k - pr
    return pr


@numba.njit(cache=True)
def _set_match(n, gu, gv, flower, flen, flower_from, match, u0, v0):
    """Match (blossom or vertex) u0 along its stored edge to v0, re-matching inside blossoms."""
    su = [u0]
    sv = [v0]
    while len(su):
        u = su.pop()
        v = sv.pop()
        match[u] = gv[u, v]
        if u > n:
            xr = flower_from[u, gu[u, v]]
            pr = _get_pr(flower, flen, u, xr)
            for i in range(pr):
                su.append(flower[u, i])
                sv.append(flower[u, i ^ 1])
            su.append(xr)
            sv.append(v)
            k = flen[u]
            flower[u, :k] = np.concatenate((flower[u, pr:k], flower[u, :pr]))


@numba.njit(cache=True)
def _augment(n, gu, gv, flower, flen, flower_from, match, st, pa, u, v):
    while True:
        xnv = st[match[u]]
        _set_match(n, gu, gv, flower, flen, flower_from, match, u, v)
        if xnv == 0:
            return
        _set_match(n, gu, gv, flower, flen, flower_from, match, xnv, st[pa[xnv]])
        u = st[pa[xnv]]
        v = xnv


@numba.njit(cache=True)
def _get_lca(match, st, pa, vis, stamp, u, v):
    while u != 0 or v != 0:
        if u != 0:
            if vis[u] == stamp:
                return u
            vis[u] = stamp
            u = st[match[u]]
            if u != 0:
                u = st[pa[u]]
        u, v = v, u
    return 0


@numba.njit(cache=True)
def _matching(n, adj_ptr, adj, gu, gv, gw, lab, match, slack, st, pa, S, vis, flower, flen,
              flower_from, queue, nx_stamp):
    """One augmentation (True) or none left (False). nx_stamp = [n_x, lca stamp, error]."""
    n_x = nx_stamp[0]
    for x in range(1, n_x + 1):
        S[x] = -1
        slack[x] = 0
    qh = 0
    qt = np.int64(0)
    for x in range(1, n_x + 1):
        if st[x] == x and match[x] == 0:
            pa[x] = 0
            S[x] = 0
            qt = _q_push(n, flower, flen, queue, qt, x)
    if qt == 0:
        return False
    while True:
        while qh < qt:
            u = queue[qh]
            qh += 1
            if S[st[u]] == 1:
                continue
            for j in range(adj_ptr[u], adj_ptr[u + 1]):
                v = adj[j]
                if st[u] != st[v]:
                    if _slack2(gu, gv, gw, lab, u, v) == 0:
                        r, qt = _on_found_edge(n, gu, gv, gw, lab, match, slack, st, pa, S, vis,
                                               flower, flen, flower_from, queue, qt, nx_stamp,
                                               gu[u, v], gv[u, v])
                        if qt < 0:
                            nx_stamp[2] = 1
                            return False
                        if r:
                            return True
                    else:
                        _update_slack(gu, gv, gw, lab, slack, u, st[v])
        n_x = nx_stamp[0]
        d = np.int64(1) << 62
        for b in range(n + 1, n_x + 1):
            if st[b] == b and S[b] == 1:
                d = min(d, lab[b] // 2)
        for x in range(1, n_x + 1):
            if st[x] == x and slack[x] != 0:
                if S[x] == -1:
                    d = min(d, _slack2(gu, gv, gw, lab, slack[x], x))
                elif S[x] == 0:
                    d = min(d, _slack2(gu, gv, gw, lab, slack[x], x) // 2)
        if d >= (np.int64(1) << 62):
            nx_stamp[2] = 2                 # nothing left to grow: no perfect matching
            return False
        for u in range(1, n + 1):
            if S[st[u]] == 0:
                lab[u] -= d
            elif S[st[u]] == 1:
                lab[u] += d
        for b in range(n + 1, n_x + 1):
            if st[b] == b:
                if S[b] == 0:
                    lab[b] += 2 * d
                elif S[b] == 1:
                    lab[b] -= 2 * d
        qh = 0
        qt = np.int64(0)
        for x in range(1, n_x + 1):
            if (st[x] == x and slack[x] != 0 and st[slack[x]] != x
                    and _slack2(gu, gv, gw, lab, slack[x], x) == 0):
                a = slack[x]
                r, qt = _on_found_edge(n, gu, gv, gw, lab, match, slack, st, pa, S, vis, flower,
                                       flen, flower_from, queue, qt, nx_stamp, gu[a, x], gv[a, x])
                if qt < 0:
                    nx_stamp[2] = 1
                    return False
                if r:
                    return True
        n_x = nx_stamp[0]
        for b in range(n + 1, n_x + 1):
            if st[b] == b and S[b] == 1 and lab[b] == 0:
                qt = _expand_blossom(n, gu, gv, gw, lab, slack, st, pa, S, flower, flen,
                                     flower_from, queue, qt, b)
                if qt < 0:
                    nx_stamp[2] = 1
                    return False


@numba.njit(cache=True)
def _on_found_edge(n, gu, gv, gw, lab, match, slack, st, pa, S, vis, flower, flen, flower_from,
                   queue, qt, nx_stamp, eu, ev):
    """A tight edge (eu, ev) from an even vertex: grow the tree, augment, or shrink a blossom.
    Returns (augmented, queue tail)."""
    u = st[eu]
    v = st[ev]
    if S[v] == -1:
        pa[v] = eu
        S[v] = 1
        nu = st[match[v]]
        slack[v] = 0
        slack[nu] = 0
        S[nu] = 0
        qt = _q_push(n, flower, flen, queue, qt, nu)
    elif S[v] == 0:
        nx_stamp[1] += 1
        lca = _get_lca(match, st, pa, vis, nx_stamp[1], u, v)
        if lca == 0:
            _augment(n, gu, gv, flower, flen, flower_from, match, st, pa, u, v)
            _augment(n, gu, gv, flower, flen, flower_from, match, st, pa, v, u)
            return True, qt
        qt = _add_blossom(n, gu, gv, gw, lab, match, slack, st, pa, S, flower, flen, flower_from,
                          queue, qt, nx_stamp, u, lca, v)
    return False, qt


@numba.njit(cache=True)
def _append_tree_path(n, match, st, pa, flower, flen, queue, qt, b, k, x, lca):
    """Append to blossom b's cycle (from position k) the tree path from x up to ``lca``: each
    (blossom or) vertex and its mate; the mates, odd until now, join the queue. Returns the new
    length and queue tail."""
    while x != lca:
        y = st[match[x]]
        flower[b, k] = x
        flower[b, k + 1] = y
        k += 2
        qt = _q_push(n, flower, flen, queue, qt, y)
        x = st[pa[y]]
    return k, qt


@numba.njit(cache=True)
def _add_blossom(n, gu, gv, gw, lab, match, slack, st, pa, S, flower, flen, flower_from, queue,
                 qt, nx_stamp, u, lca, v):
    n_x = nx_stamp[0]
    b = n + 1
    while b <= n_x and st[b] != 0:
        b += 1
    if b > n_x:
        n_x += 1
        nx_stamp[0] = n_x
    lab[b] = 0
    S[b] = 0
    match[b] = match[lca]
    flower[b, 0] = lca
    k, qt = _append_tree_path(n, match, st, pa, flower, flen, queue, qt, b, 1, u, lca)
    flower[b, 1:k] = flower[b, 1:k][::-1].copy()
    k, qt = _append_tree_path(n, match, st, pa, flower, flen, queue, qt, b, k, v, lca)
    flen[b] = k
    _set_st(n, flower, flen, st, b, b)
    for x in range(1, n_x + 1):
        gw[b, x] = 0
        gw[x, b] = 0
    for x in range(1, n + 1):
        flower_from[b, x] = 0
    for i in range(k):
        xs = np.int64(flower[b, i])       # int64 throughout: one compiled signature per kernel
        for x in range(1, n_x + 1):
            if gw[xs, x] > 0 and (gw[b, x] == 0 or _slack2(gu, gv, gw, lab, xs, x)
                                  < _slack2(gu, gv, gw, lab, b, x)):
                gu[b, x] = gu[xs, x]
                gv[b, x] = gv[xs, x]
                gw[b, x] = gw[xs, x]
                gu[x, b] = gu[x, xs]
                gv[x, b] = gv[x, xs]
                gw[x, b] = gw[x, xs]
        for x in range(1, n + 1):
            if flower_from[xs, x] != 0:
                flower_from[b, x] = xs
    _set_slack(n, gu, gv, gw, lab, slack, st, S, b)
    return qt


@numba.njit(cache=True)
def _expand_blossom(n, gu, gv, gw, lab, slack, st, pa, S, flower, flen, flower_from, queue, qt, b):
    for i in range(flen[b]):
        _set_st(n, flower, flen, st, flower[b, i], flower[b, i])
    xr = flower_from[b, gu[b, pa[b]]]
    pr = _get_pr(flower, flen, b, xr)
    for i in range(0, pr, 2):
        xs = np.int64(flower[b, i])
        xns = np.int64(flower[b, i + 1])
        pa[xs] = gu[xns, xs]
        S[xs] = 1
        S[xns] = 0
        slack[xs] = 0
        _set_slack(n, gu, gv, gw, lab, slack, st, S, xns)
        qt = _q_push(n, flower, flen, queue, qt, xns)
        if qt < 0:
            return qt
    S[xr] = 1
    pa[xr] = pa[b]
    for i in range(pr + 1, flen[b]):
        xs = np.int64(flower[b, i])
        S[xs] = -1
        _set_slack(n, gu, gv, gw, lab, slack, st, S, xs)
    st[b] = 0
    return qt


@numba.njit(cache=True)
def perfect_matching(c, adj_ptr, adj, hub, gu, gv, gw, flower, flower_from):
    """Minimum-cost perfect matching of vertices 1..V on the edges ``adj`` (CSR by vertex,
    ``adj_ptr`` of length V + 2; integer costs ``c``, (V+1) x (V+1)), as a maximum-weight perfect
    matching of weights K - c. Starts from a greedy dual (each vertex raised as far as its edges
    allow, in turn) and the greedy matching of its tight edges, so the blossom stages only finish
    what is left. ``gu``, ``gv``, ``gw``, ``flower``, ``flower_from``: the workspace of
    ``_workspace``, all zero in ``gw`` and ``flower_from`` on entry and left so on return.
    Returns (mate per vertex, 0 = unmatched; duals ``lab`` = K - 2 y; blossom children
    ``flower``/``flen``; ``st``; ``n_x``; K; error flag)."""
    n = c.shape[0] - 1
    m = 2 * n + 2
    K = np.int64(1)
    for u in range(1, n + 1):
        for j in range(adj_ptr[u], adj_ptr[u + 1]):
            K = max(K, c[u, adj[j]] + 1)
    # the edge stored between two (blossoms or) vertices: its end points and weight, read only
    # where the weight is > 0 (an edge); between vertices only the edges are written
    for u in range(1, n + 1):
        for j in range(adj_ptr[u], adj_ptr[u + 1]):
            v = adj[j]
            gu[u, v] = u
            gv[u, v] = v
            gw[u, v] = K - c[u, v]
    # greedy dual (min-cost form, integer y: every root keeps the same parity, so the dual
    # steps stay integral as with Galil's uniform start): y_u = half u's cheapest edge, then
    # y_u = min_v c_uv - y_v in turn. A hub (the free end E: an edge of cost 0 to every vertex)
    # would hold every y_u at 0; it is left out of the first step and then gets the lowest y
    # its edges allow
    y = np.zeros(n + 1, np.int64)
    for u in range(1, n + 1):
        if u == hub:
            continue
        best = np.int64(1) << 62
        for j in range(adj_ptr[u], adj_ptr[u + 1]):
            if adj[j] != hub:
                best = min(best, c[u, adj[j]])
        y[u] = best // 2 if best < (np.int64(1) << 62) else 0
    if hub:
        best = np.int64(1) << 62
        for j in range(adj_ptr[hub], adj_ptr[hub + 1]):
            best = min(best, c[hub, adj[j]] - y[adj[j]])
        y[hub] = best if best < (np.int64(1) << 62) else 0
    match = np.zeros(m, np.int64)
    for u in range(1, n + 1):
        best = np.int64(1) << 62
        arg = 0
        for j in range(adj_ptr[u], adj_ptr[u + 1]):
            v = adj[j]
            r = c[u, v] - y[v]
            if r < best or (r == best and match[arg] != 0 and match[v] == 0):
                best = r
                arg = v
        if arg == 0:
            continue
        y[u] = best
        if match[u] == 0 and match[arg] == 0:
            match[u] = arg
            match[arg] = u
    lab = np.zeros(m, np.int64)
    for u in range(1, n + 1):
        lab[u] = K - 2 * y[u]
    slack = np.zeros(m, np.int64)
    st = np.zeros(m, np.int64)
    pa = np.zeros(m, np.int64)
    S = np.zeros(m, np.int64)
    vis = np.zeros(m, np.int64)
    flen = np.zeros(m, np.int64)
    queue = np.zeros(8 * m, np.int64)
    for u in range(n + 1):
        st[u] = u
    for u in range(1, n + 1):
        flower_from[u, u] = u
    nx_stamp = np.array([n, 0, 0], np.int64)
    while _matching(n, adj_ptr, adj, gu, gv, gw, lab, match, slack, st, pa, S, vis, flower, flen,
                    flower_from, queue, nx_stamp):
        pass
    # leave the workspace as it came: what this call wrote into gw and flower_from back to 0
    n_x = nx_stamp[0]
    for u in range(1, n + 1):
        for j in range(adj_ptr[u], adj_ptr[u + 1]):
            gw[u, adj[j]] = 0
        flower_from[u, u] = 0
    for b in range(n + 1, n_x + 1):
        for x in range(n_x + 1):
            gw[b, x] = 0
            gw[x, b] = 0
        for x in range(n + 1):
            flower_from[b, x] = 0
    return match[:n + 1].copy(), lab, flower, flen, st, n_x, K, nx_stamp[2]
