"""Reduced-cost search: the root LP's duals bound every path, and a depth-first search over the
arcs they leave open proves small and mid-size groups optimal without branching on LPs
(formulations/ordering.md, "milp, symmetric model", "Reduced-cost search").

After a complete root (``SymmetricModel.root``: no violated cut found, no column priced in) with
LP value ``z`` and reduced costs ``rc`` (HiGHS's column duals for the columns in the model, the
dense pass of ``reduced_costs`` for the missing ones), every path T of the group costs

    cost(T) >= z + sum_{arcs a of T} max(rc_a, 0)

(the dual bound: the degree and "entered once" rows hold with equality on T, the cuts with
y >= 0 hold on T, and a column at its upper bound with rc < 0 pays |rc| unless T uses it). The
symmetric model's edges bound the true, direction-dependent costs from below (each edge is
priced the cheaper way round), so its ``z`` and ``rc`` bound them too; ``DirectedModel``'s are
exact for them. The search extends a path from S arc by arc, pricing each arc by the group's own
link costs (``graph_and_arcs``' ``A``), and drops a partial path once either lower bound of its
completions reaches the incumbent:

    z + rc(path) + sum_{curves not yet entered} min rc into it + min rc into E
    cost(path) + sum_{curves not yet entered} min cost into it + min cost into E

Once every partial path is extended or dropped, no path costs less than the incumbent (up to
``OPTIMAL_ABS_TOL``): the group is proven, its bound the least bound of what was dropped. Where
the root gap is small most arcs have ``rc`` above it and the search visits a few hundred
partial paths; where it is wide the node limit stops it and the branch-and-cut takes over. Two
partial paths through the same curves that end at the same node have the same completions: the
dearer one is dropped (the subset DP over the states the bounds leave open).

Run by ``symmetric.solve`` after the symmetric root and again after the directed one, on groups
of at most ``MAX_CURVES`` curves, where it usually proves what the directed root and its
branch-and-cut would have in ~7 LPs (each ~0.9 ms in HiGHS whatever the model's size)
(docs/BENCHMARKS.md, "Reduced-cost search").
"""
from __future__ import annotations

import time

import numba
import numpy as np

from .problem import OPTIMAL_ABS_TOL

#: partial paths the search may extend per call before it gives up (the branch-and-cut then
#: takes over): ~3 M a second in numba on this machine, so at most ~7 ms. On 80 groups of 13-29
#: curves of prusa25_xend_honey25_acp, free mode (1 s each): 20,000 proved 39 of 115 calls in
#: 0.21 s of search in all, 200,000 59 of 104 in 1.44 s, which the proofs did not pay back
MAX_NODES = 20_000
#: the search runs on groups of at most this many curves: on 5 corpus files (80 groups of 13-79
#: curves each, 1 s per group) it proved 117 of 125 calls on groups of 10-19 curves, 26 of 109
#: on 20-29, 3 of 73 on 30-39 and 1 of 162 above, those at ~8-12 ms a call
MAX_CURVES = 29
#: whether ``symmetric.solve`` runs the search after its complete roots
ENABLED = True
#: and per second of the group's time left, so that the search takes at most ~a tenth of it
NODES_PER_S = 300_000


def after_root(model, best, best_obj: float, bound: float, deadline: float):
    """The search after ``model``'s complete root (``symmetric.solve``), within ``MAX_NODES``
    and ``NODES_PER_S`` of the time left: (best, best_obj, None) with the path it may have
    improved, or, where it proved the group, also the answer as ``symmetric.solve`` returns it
    (order, objective, bound, True)."""
    if not ENABLED:
        return best, best_obj, None
    left = max(deadline - time.perf_counter(), 0.0)
    order, obj, found, proven = search(model, best, best_obj,
                                       min(MAX_NODES, int(left * NODES_PER_S)))
    if proven:
        return order, obj, (order, obj, max(bound, found), True)
    return order, obj, None


def reduced_cost_matrix(model) -> np.ndarray:
    """(N, N) reduced cost of each arc u -> v of ``model`` after a complete root: the dense pass
    (``model.rc``) for missing columns, HiGHS's column duals for the columns in the model (the
    dense pass does not know a blossom's teeth). A symmetric model's edge gives both arcs its
    reduced cost."""
    rc = np.array(model.rc, float)
    col = np.asarray(model.h.getSolution().col_dual, float)
    tail, head = model.col_tail[:len(col)], model.col_head[:len(col)]
    rc[tail, head] = col
    if model.PAIRS_FACTOR == 0.5:           # one column per edge: both directions
        rc[head, tail] = col
    return rc


def node_tables(model):
    """Per node of ``model``'s graph: the other end of its curve (itself for a loop's seam, S
    and E themselves) and the candidate that enters its curve there (-1: S, E)."""
    N = model.N
    group = model.group
    partner = np.arange(N, dtype=np.int64)
    enter = np.full(N, -1, np.int64)
    for c, nodes in enumerate(model.curve_nodes):
        first = int(model.first_cand[c])
        if len(nodes) == 1:
            enter[nodes[0]] = first
        else:
            a, b = nodes
            partner[a], partner[b] = b, a
            enter[a] = first
            enter[b] = int(group.cand_flip[first])
    return partner, enter


def search(model, best_order: np.ndarray, best_obj: float, max_nodes: int):
    """The search of the module docstring on ``model`` after a complete root. Returns (order,
    objective, bound, proven): the incumbent or a cheaper path it found, and, where the search
    ended within ``max_nodes``, proven with the least bound of what it dropped; else not
    proven (bound None)."""
    if model.group.n_curves > MAX_CURVES or max_nodes <= 0:
        return best_order, best_obj, None, False
    z = float(model.h.getInfo().objective_function_value)
    if not np.isfinite(z) or best_obj - z <= OPTIMAL_ABS_TOL:
        return best_order, best_obj, None, False
    rc = np.maximum(reduced_cost_matrix(model), 0.0)
    partner, enter = node_tables(model)
    path, obj, bound, done = _search(np.ascontiguousarray(model.A), np.ascontiguousarray(rc),
                                     model.node_curve.astype(np.int64), partner,
                                     model.group.n_curves, z, float(best_obj), OPTIMAL_ABS_TOL,
                                     int(max_nodes))
    order = best_order
    if obj < best_obj - 1e-9:
        order = enter[path]
        # the search prices the path by the group's own link costs, as ``path_cost`` does
        obj = float(model.group.path_cost(order))
        if obj >= best_obj - 1e-9:          # (never: the same numbers summed otherwise)
            order, obj = best_order, best_obj
    if not done:
        return order, obj, None, False
    bound = min(bound, obj)
    return order, obj, bound, obj - bound <= OPTIMAL_ABS_TOL


@numba.njit(cache=True)
def _search(A, rc, node_curve, partner, n_curves, z, best, tol, max_nodes):
    """Depth-first search of the module docstring. ``A``: arc costs (inf: no arc); ``rc``:
    reduced costs >= 0; node 0 = S, 1 = E. Returns (entry node per position of the best path
    found, or empty; its cost (``best`` if none beat it); the least bound of the dropped partial
    paths (inf: none dropped); whether the search ended within ``max_nodes``).

    Two partial paths through the same curves that end at the same node have the same
    completions: the dearer one is dropped (``seen``, a hash table of (curves entered, exit
    node) -> least cost, up to 63 curves), so the search is the subset DP restricted to the
    states the bounds leave open."""
    N = A.shape[0]
    gap = best - z + tol
    # successors of each node into other curves' nodes, by reduced cost, within the gap
    count = np.zeros(N + 1, np.int64)
    for u in range(N):
        if u == 1:
            continue
        for v in range(2, N):
            if np.isfinite(A[u, v]) and rc[u, v] <= gap and node_curve[v] != node_curve[u]:
                count[u + 1] += 1
    start = np.cumsum(count)
    succ = np.empty(start[N], np.int64)
    fill = start[:N].copy()
    for u in range(N):
        if u == 1:
            continue
        for v in range(2, N):
            if np.isfinite(A[u, v]) and rc[u, v] <= gap and node_curve[v] != node_curve[u]:
                succ[fill[u]] = v
                fill[u] += 1
        seg = succ[start[u]:start[u + 1]]
        keys = np.empty(len(seg))
        for i in range(len(seg)):
            keys[i] = rc[u, seg[i]]
        succ[start[u]:start[u + 1]] = seg[np.argsort(keys, kind="mergesort")]
    # the cheapest way into each curve and into E, in reduced cost and in cost
    in_rc = np.full(n_curves, np.inf)
    in_a = np.full(n_curves, np.inf)
    e_rc, e_a = np.inf, np.inf
    for u in range(N):
        if u == 1:
            continue
        for v in range(N):
            if not np.isfinite(A[u, v]) or node_curve[v] == node_curve[u]:
                continue
            if v == 1:
                if u != 0:
                    e_rc = min(e_rc, rc[u, v])
                    e_a = min(e_a, A[u, v])
            elif v >= 2:
                c = node_curve[v]
                in_rc[c] = min(in_rc[c], rc[u, v])
                in_a[c] = min(in_a[c], A[u, v])
    rem_rc0 = e_rc
    rem_a0 = e_a
    for c in range(n_curves):
        rem_rc0 += in_rc[c]
        rem_a0 += in_a[c]
    best_path = np.empty(0, np.int64)
    least = np.inf
    if not (np.isfinite(rem_rc0) and np.isfinite(rem_a0)):
        return best_path, best, least, False
    if max(z + rem_rc0, rem_a0) >= best - tol:
        return best_path, best, max(z + rem_rc0, rem_a0), True
    # dominance: open addressing over (mask, node), at most half full
    dominance = n_curves <= 63
    size = 1
    while size < 2 * max_nodes + 2:
        size *= 2
    if not dominance:
        size = 1
    seen_key = np.full(size, -1, np.int64)
    seen_cost = np.empty(size)
    stored = 0
    # the stack: per depth d (curves entered), the exit node, the next successor to try, the
    # path's cost, reduced cost, the two completion bounds and the curves entered (a bit mask);
    # ``entered[d]`` the entry node of the d-th curve
    cur = np.empty(n_curves + 1, np.int64)
    ptr = np.empty(n_curves + 1, np.int64)
    cost = np.empty(n_curves + 1)
    rcs = np.empty(n_curves + 1)
    rem_rc = np.empty(n_curves + 1)
    rem_a = np.empty(n_curves + 1)
    mask = np.zeros(n_curves + 1, np.int64)
    entered = np.empty(n_curves, np.int64)
    visited = np.zeros(n_curves, np.bool_)
    d = 0
    cur[0], ptr[0], cost[0], rcs[0], rem_rc[0], rem_a[0] = 0, start[0], 0.0, 0.0, rem_rc0, rem_a0
    nodes = 0
    while d >= 0:
        u = cur[d]
        if d == n_curves:
            t = cost[d] + A[u, 1]
            if t < best - 1e-9:
                best = t
                best_path = entered.copy()
            d -= 1
            if d >= 0:
                visited[node_curve[entered[d]]] = False
            continue
        if ptr[d] >= start[u + 1]:
            d -= 1
            if d >= 0:
                visited[node_curve[entered[d]]] = False
            continue
        v = succ[ptr[d]]
        ptr[d] += 1
        c = node_curve[v]
        if visited[c]:
            continue
        r = rcs[d] + rc[u, v]
        rr = rem_rc[d] - in_rc[c]
        a = cost[d] + A[u, v]
        ra = rem_a[d] - in_a[c]
        w = partner[v]
        b = max(z + r + rr, a + ra)
        if d + 1 == n_curves and np.isfinite(A[w, 1]):
            # the last curve: its way out to E is known
            b = max(z + r + rc[w, 1], a + A[w, 1])
        if b >= best - tol:
            least = min(least, b)
            continue
        m = mask[d] | (np.int64(1) << np.int64(c)) if dominance else 0
        if dominance and d + 1 < n_curves:
            key = m * N + w
            h = (key * 0x9E3779B1) & (size - 1)
            while seen_key[h] != -1 and seen_key[h] != key:
                h = (h + 1) & (size - 1)
            if seen_key[h] == key:
                if seen_cost[h] <= a:
                    continue            # reached as cheaply before: its completions are known
                seen_cost[h] = a
            elif stored < size // 2:
                seen_key[h] = key
                seen_cost[h] = a
                stored += 1
        nodes += 1
        if nodes > max_nodes:
            return best_path, best, least, False
        entered[d] = v
        visited[c] = True
        d += 1
        cur[d], ptr[d], cost[d], rcs[d], rem_rc[d], rem_a[d] = w, start[w], a, r, rr, ra
        mask[d] = m
    return best_path, best, least, True


def load_kernel() -> None:
    """Compile (or load from numba's cache) ``_search`` on a made-up graph (S, E, two open
    curves), so that the first group it runs on does not pay for it (``symmetric.load_kernels``:
    compiled inside a group's limit, it had held one two-process run 13 s past its budget)."""
    A = np.full((6, 6), np.inf)
    A[0, 2:] = A[2:, 1] = 1.0
    A[2:4, 4:] = A[4:, 2:4] = 2.0
    node_curve = np.array([-1, -2, 0, 0, 1, 1], np.int64)
    _search(A, np.where(np.isfinite(A), 0.5, np.inf), node_curve,
            np.array([0, 1, 3, 2, 5, 4], np.int64), 2, 0.0, 10.0, OPTIMAL_ABS_TOL, 100)
