"""Minimum-cost perfect matching of a group's end points: a lower bound and the odd sets behind it
(formulations/ordering.md, "Bounds", matching bound).

In the symmetric model (``symmetric.py``) every end point of an open curve meets exactly one
travel edge (the curve itself is its other edge), a loop's seam two, S and E one each: the
travel edges of any path form a perfect matching of the end points (a loop's seam counted twice,
as two vertices). The cheapest perfect matching is therefore a lower bound on the path's travel.
Unlike the degree LP (a fractional matching, measured ~10 % below the optimum on Cura bunny
groups) it pays for the odd sets a matching must leave: the blossom inequalities that the LP root
otherwise finds a few per round.

Edmonds' weighted blossom algorithm, primal-dual, O(V^3), with integer weights (0.1 um units
rounded down, so the bound stays valid in mm), run on a sparse search graph that grows by
pricing. The bound is taken from the dual, not from the matching: ``_certify`` checks every
allowed edge's reduced cost (raising a vertex dual where one is negative) and the sign of every
blossom dual, so the bound is certified whatever the primal did. The live blossoms of the final dual are odd sets H whose constraint ``x(δ(H)) >= 1`` holds
for every path: ``symmetric.SymmetricModel`` starts its LP with them.
"""
from __future__ import annotations

import threading

import numba
import numpy as np

from .greedy import keep_smallest

#: cost units per mm (0.1 um): costs are rounded down to whole units
UNITS_PER_MM = 1e4
#: rounds of adding the left-out edges with negative reduced cost to a sparse search graph;
#: what is still negative after them is repaired in the dual (``_certify``)
MAX_PRICING_ROUNDS = 3
#: above this many vertices auto skips the matching (O(V^3); not tuned: on a 163-curve group, 328
#: vertices, the blossom algorithm takes ~3 ms, ~6 ms when it allocated its arrays per call)
MAX_VERTICES = 500


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
def _perfect_matching(c, adj_ptr, adj, hub, gu, gv, gw, flower, flower_from):
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


#: the blossom algorithm's (2V + 2)^2 and (2V + 2) x V arrays, kept from call to call: allocated
#: afresh each call they cost more than the algorithm on groups of ~250 end points (fresh pages,
#: 2.6 ms of a ~4 ms call; measured). One set per thread: ``flower`` is read after the call
#: (``_blossom_tree``, ``_members``), so two threads must not share it.
_WORK = threading.local()


def _workspace(V: int) -> tuple:
    """(gu, gv, gw, flower, flower_from) for V vertices: this thread's kept arrays if large enough
    (all zero in gw and flower_from, as ``_perfect_matching`` leaves them), else new ones."""
    m = 2 * V + 2
    arrays = getattr(_WORK, "arrays", None)
    if arrays is None or arrays[2].shape[0] < m:
        arrays = _WORK.arrays = (np.zeros((m, m), np.int32), np.zeros((m, m), np.int32),
                                 np.zeros((m, m), np.int64), np.zeros((m, V + 2), np.int32),
                                 np.zeros((m, V + 1), np.int32))
    return arrays


@numba.njit(cache=True)
def _blossom_tree(n, n_x, st, flower, flen):
    """Parent blossom (0 = none) and depth of every vertex and live blossom of the final dual,
    and the size of each live blossom."""
    parent = np.zeros(n_x + 1, np.int64)
    size = np.zeros(n_x + 1, np.int64)
    live = np.zeros(n_x + 1, np.bool_)
    order = []                                 # live blossoms, parents before children
    for b in range(n + 1, n_x + 1):
        if st[b] == b:
            order.append(b)
            live[b] = True
    i = 0
    while i < len(order):
        b = order[i]
        i += 1
        for k in range(flen[b]):
            ch = flower[b, k]
            parent[ch] = b
            if ch > n:
                live[ch] = True
                order.append(ch)
    depth = np.zeros(n_x + 1, np.int64)
    for b in order:
        depth[b] = depth[parent[b]] + 1 if parent[b] else 1
    for u in range(1, n + 1):
        depth[u] = depth[parent[u]] + 1 if parent[u] else 1
        b = parent[u]
        while b:
            size[b] += 1
            b = parent[b]
    return parent, depth, size, live


@numba.njit(cache=True)
def _members(n, b, flower, flen, inside):
    """Mark the vertices of blossom b in ``inside`` (bool, size n + 1)."""
    stack = [b]
    while len(stack):
        y = stack.pop()
        if y <= n:
            inside[y] = True
        else:
            for i in range(flen[y]):
                stack.append(flower[y, i])


@numba.njit(cache=True)
def _shortfall(c, K, lab, parent, depth, u, v):
    """How far edge (u, v) is from dual feasibility, ``2 w_uv - lab_u - lab_v - sum_{B ∋ u, v}
    lab_B`` (> 0: its reduced cost is negative). The blossoms holding both are those from the
    lowest common ancestor of u and v in the blossom tree up."""
    need = 2 * (K - c[u, v]) - lab[u] - lab[v]
    if need <= 0:
        return need                 # blossom duals are >= 0: they only add to the left side
    a, b = parent[u], parent[v]
    while a and b and a != b:
        if depth[a] >= depth[b]:
            a = parent[a]
        else:
            b = parent[b]
    if a and a == b:
        while a:
            need -= lab[a]
            a = parent[a]
    return need


@numba.njit(cache=True)
def _violated(c, allowed, search, K, lab, parent, depth):
    """The allowed edges outside ``search`` whose reduced cost is negative in the dual of the
    search graph's optimum, as (u, v) arrays."""
    n = c.shape[0] - 1
    out_u = []
    out_v = []
    for u in range(1, n + 1):
        for v in range(u + 1, n + 1):
            if not allowed[u, v] or search[u, v]:
                continue
            if _shortfall(c, K, lab, parent, depth, u, v) > 0:
                out_u.append(u)
                out_v.append(v)
    return np.array(out_u, np.int64), np.array(out_v, np.int64)


@numba.njit(cache=True)
def _certify(check_u, check_v, K, c, lab, parent, depth, size, live):
    """Make (y, z) a feasible dual of the whole graph ``allowed`` (the matching ran on a subset
    of its edges) and return twice its objective, ``sum_v lab_v + sum_B lab_B (|B| - 1) / 2``.
    Only the edges (check_u, check_v) are checked: the caller knows the others feasible.

    Feasible: every z_B >= 0 and every edge ``lab_u + lab_v + sum_{B ∋ u, v} lab_B >= 2 w_uv``.
    An edge short of it raises lab_u by the shortfall (y_u falls, the bound with it): any feasible
    dual bounds every perfect matching's weight from above, as, summed over its edges, the left
    side counts each y once and each z_B at most (|B| - 1) / 2 times (y is free in sign as the
    matching is perfect). Returns -1 if a blossom dual is negative."""
    n = c.shape[0] - 1
    total = np.int64(0)
    for b in range(n + 1, len(live)):
        if live[b]:
            if lab[b] < 0:
                return -1
            total += lab[b] * ((size[b] - 1) // 2)
    for i in range(len(check_u)):
        u, v = check_u[i], check_v[i]
        need = _shortfall(c, K, lab, parent, depth, u, v)
        if need > 0:
            lab[u] += need
    for u in range(1, n + 1):
        total += lab[u]
    return total


def min_cost_perfect_matching(cost_units: np.ndarray, allowed: np.ndarray,
                              search: np.ndarray | None = None, hub: int | None = None):
    """Cheapest perfect matching of the graph with integer costs ``cost_units`` (V x V) on the
    ``allowed`` (symmetric, no diagonal) edges; ``search``: the subset of them the blossom
    algorithm runs on (default: all). It must hold a perfect matching (the travel edges of a
    known path, for instance). ``hub``: a vertex joined to every other at cost 0 (speeds up the
    start only).

    Returns (lower bound in units, mate per vertex, odd sets as a list of vertex index arrays),
    or (None, None, []) when the search graph has no perfect matching. The bound holds for every
    perfect matching of the ``allowed`` edges: the dual of the search graph's optimum, repaired
    on the edges it left out (``_certify``); with ``search`` = ``allowed`` it is the optimum."""
    V = len(cost_units)
    if V == 0 or V % 2:
        return None, None, []
    c = np.zeros((V + 1, V + 1), np.int64)
    c[1:, 1:] = cost_units
    ok = np.zeros((V + 1, V + 1), np.bool_)
    ok[1:, 1:] = allowed
    np.fill_diagonal(ok, False)
    sub = ok.copy() if search is None else ok & np.pad(np.asarray(search, bool), ((1, 0), (1, 0)))
    sub = sub | sub.T
    return _solve(c, ok, sub, int(hub) + 1 if hub is not None else 0, search is not None)


def travel_matching(C: np.ndarray, idx: np.ndarray, k: int, search_node: int,
                    hub: int | None = None):
    """``min_cost_perfect_matching`` of a travel graph given as its node cost matrix ``C`` (N x N,
    mm, inf where no edge) and the node of each vertex ``idx`` (a loop's seam twice): costs in
    whole units rounded down, no edge between two vertices of one node, searched on each vertex's
    ``k`` cheapest edges (ties: the lower vertex) and every edge at the vertices of node
    ``search_node``. ``_prepare`` builds the padded arrays in one compiled pass: the numpy
    version (fancy-indexed copies, masks, a partial sort per row, padding) took ~1 ms of the ~2 ms
    of a call on ~100-curve Cura bunny groups. If that search graph has no perfect matching, the
    whole graph is searched. Returns as ``min_cost_perfect_matching``."""
    V = len(idx)
    if V == 0 or V % 2:
        return None, None, []
    idx = np.ascontiguousarray(idx, np.int64)
    hub1 = int(hub) + 1 if hub is not None else 0
    c, ok, sub = _prepare(np.ascontiguousarray(C, float), idx, int(k), int(search_node), UNITS_PER_MM)
    out = _solve(c, ok, sub, hub1, True)
    if out[0] is None:              # no perfect matching among the nearest edges: all of them
        out = _solve(c, ok, ok.copy(), hub1, False)
    return out


@numba.njit(cache=True)
def _prepare(C, idx, k, search_node, units_per_mm):
    """(c, ok, sub) for ``_solve``, vertices 1..V: costs in units rounded down, allowed edges, and
    the search graph (each vertex's k cheapest allowed edges, every allowed edge at a vertex of
    ``search_node``; symmetric)."""
    V = len(idx)
    c = np.zeros((V + 1, V + 1), np.int64)
    ok = np.zeros((V + 1, V + 1), np.bool_)
    sub = np.zeros((V + 1, V + 1), np.bool_)
    for a in range(V):
        for b in range(V):
            w = C[idx[a], idx[b]]
            if idx[a] != idx[b] and np.isfinite(w):
                ok[a + 1, b + 1] = True
                c[a + 1, b + 1] = np.int64(np.floor(w * units_per_mm))
    val = np.empty(k + 1)
    best = np.empty(k + 1, np.int64)
    for a in range(V):
        if idx[a] == search_node:
            for b in range(V):
                if ok[a + 1, b + 1]:
                    sub[a + 1, b + 1] = True
                    sub[b + 1, a + 1] = True
            continue
        cnt = 0
        for b in range(V):
            if not ok[a + 1, b + 1]:
                continue
            cnt = keep_smallest(val, best, cnt, k, C[idx[a], idx[b]], b)
        for t in range(cnt):
            sub[a + 1, best[t] + 1] = True
            sub[best[t] + 1, a + 1] = True
    return c, ok, sub


def _solve(c, ok, sub, hub1: int, priced: bool):
    """The blossom algorithm on the padded arrays (vertex 0 unused): on ``sub``, adding the edges
    of ``ok`` whose reduced cost turns negative when ``priced`` (``sub`` is changed), then the
    certified bound and the odd sets. Returns as ``min_cost_perfect_matching``."""
    V = c.shape[0] - 1
    for _ in range(MAX_PRICING_ROUNDS + 1):
        u, v = np.nonzero(sub)
        adj_ptr = np.searchsorted(u, np.arange(V + 2)).astype(np.int64)
        match, lab, flower, flen, st, n_x, K, err = _perfect_matching(
            c, adj_ptr, v.astype(np.int64), hub1, *_workspace(V))
        if err:
            return None, None, []
        parent, depth, size, live = _blossom_tree(V, n_x, st, flower, flen)
        if not priced:
            break
        # edges left out whose reduced cost is negative: add them and solve again (pricing)
        vu, vv = _violated(c, ok, sub, K, lab, parent, depth)
        if len(vu) == 0:
            break
        sub[vu, vv] = sub[vv, vu] = True
    # the edges outside ``sub`` were just found feasible by ``_violated`` (or there are none:
    # not priced, ``sub`` is every allowed edge), so the repair checks ``sub``'s edges only: the
    # search graph and the violated edges added after the last solve. A second scan of all V^2
    # pairs was ~20 % of the matching's time on ~100-curve groups
    check_u, check_v = np.nonzero(np.triu(sub))
    dual2 = _certify(check_u.astype(np.int64), check_v.astype(np.int64), K, c, lab, parent, depth,
                     size, live)
    if dual2 < 0:
        return None, None, []
    # every perfect matching M of allowed edges: (V/2) K - cost(M) = w(M) <= dual = dual2 / 2
    bound = (V // 2) * int(K) - dual2 / 2.0
    mate = match[1:] - 1
    sets = []
    for b in np.flatnonzero(live):
        if b > V and lab[b] > 0:
            inside = np.zeros(V + 1, bool)
            _members(V, b, flower, flen, inside)
            sets.append(np.flatnonzero(inside[1:]))
    return bound, mate, sets
