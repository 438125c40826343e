"""Minimum-cost perfect matching of a group's end points: a lower bound and the odd sets behind it
(formulations/ordering.md, "Bounds", matching bound).

In the symmetric model (``symmetric.py``) every end point of an open curve meets exactly one
travel edge (the curve itself is its other edge), a loop's seam two, S and E one each: the
travel edges of any path form a perfect matching of the end points (a loop's seam counted twice,
as two vertices). The cheapest perfect matching is therefore a lower bound on the path's travel.
Unlike the degree LP (a fractional matching, measured ~10 % below the optimum on Cura bunny
groups) it pays for the odd sets a matching must leave: the blossom inequalities that the LP root
otherwise finds a few per round.

Edmonds' weighted blossom algorithm (``blossom.py``), primal-dual, O(V^3), with integer weights
(0.1 um units rounded down, so the bound stays valid in mm), run on a sparse search graph that
grows by pricing. The bound is taken from the dual, not from the matching: ``_certify`` checks
every allowed edge's reduced cost (raising a vertex dual where one is negative) and the sign of
every blossom dual, so the bound is certified whatever the primal did. The live blossoms of the
final dual are odd sets H whose constraint ``x(δ(H)) >= 1`` holds for every path:
``symmetric.SymmetricModel`` starts its LP with them.
"""
from __future__ import annotations

import threading

import numba
import numpy as np

from .blossom import perfect_matching
from .greedy import keep_smallest

#: cost units per mm (0.1 um): costs are rounded down to whole units
UNITS_PER_COST = 1e4
#: rounds of adding the left-out edges with negative reduced cost to a sparse search graph;
#: what is still negative after them is repaired in the dual (``_certify``)
MAX_PRICING_ROUNDS = 3
#: above this many vertices auto skips the matching (O(V^3); not tuned: on a 163-curve group, 328
#: vertices, the blossom algorithm takes ~3 ms, ~6 ms when it allocated its arrays per call)
MAX_VERTICES = 500

#: the blossom algorithm's (2V + 2)^2 and (2V + 2) x V arrays, kept from call to call: allocated
#: afresh each call they cost more than the algorithm on groups of ~250 end points (fresh pages,
#: 2.6 ms of a ~4 ms call; measured). One set per thread: ``flower`` is read after the call
#: (``_blossom_tree``, ``_members``), so two threads must not share it.
_WORK = threading.local()


def _workspace(V: int) -> tuple:
    """(gu, gv, gw, flower, flower_from) for V vertices: this thread's kept arrays if large enough
    (all zero in gw and flower_from, as ``blossom.perfect_matching`` leaves them), else new ones."""
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
    c, ok, sub = _prepare(np.ascontiguousarray(C, float), idx, int(k), int(search_node), UNITS_PER_COST)
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
        match, lab, flower, flen, st, n_x, K, err = perfect_matching(
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
