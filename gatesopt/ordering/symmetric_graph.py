"""The symmetric model's graph (formulations/ordering.md, "milp, symmetric model"): when every
curve is an open curve with its two directions or a loop with one seam, the orientation choice
disappears into an undirected graph: nodes S (the start), E (the end), both end points of each
open curve (joined by the curve itself: a *fixed* edge) and the seam of each loop. The path
S -> ... -> E plus the fixed edge E-S is a tour. A one-way curve (``candidates.one_way``: one
candidate, entered at one end, left at the other) is an open curve whose travel edges exist one
way only (into its entry, out of its exit): the undirected graph relaxes it, the directed model
(``symmetric.DirectedModel``) is exact for it.

Here: the graph (``travel_graph``), whether a group has one (``applies``), the cheapest perfect
matching of its end points as a bound with its odd sets (``odd_sets``), the path patched from that
matching (``matching_path``, Karp's patching), and the compiled graph kernels the LP model
(``symmetric.SymmetricModel``) shares: components, greedy edge matching. No HiGHS here.
"""
from __future__ import annotations

import numba
import numpy as np

from . import matching
from .problem import OPTIMAL_ABS_TOL, Group

#: edges per vertex the matching's blossom algorithm starts from (``odd_sets``)
MATCHING_NEIGHBOURS = 10
#: refine with ``symmetric.DirectedModel`` when the group's arcs differ from their reverse by more
#: than this somewhere (ms or mm; a symmetric group never needs it)
ASYMMETRY_TOL = OPTIMAL_ABS_TOL


def components(n_nodes: int, r, c):
    """Connected components (count, label per node; labels numbered in order of each component's
    lowest node) of the undirected graph with edges (r, c). Union-find compiled: called a few
    times per LP round, where scipy's csgraph spent ~0.5 ms per call building its sparse matrix."""
    return _components(int(n_nodes), np.asarray(r, np.int64), np.asarray(c, np.int64))


@numba.njit(cache=True)
def _components(n, r, c):
    parent = np.arange(n)
    for i in range(len(r)):
        a, b = _find(parent, r[i]), _find(parent, c[i])
        if a != b:
            parent[max(a, b)] = min(a, b)
    lab = np.empty(n, np.int64)
    root_lab = np.full(n, -1)
    k = 0
    for v in range(n):
        root = _find(parent, v)
        if root_lab[root] < 0:
            root_lab[root] = k
            k += 1
        lab[v] = root_lab[root]
    return k, lab


def asymmetric(arcs: np.ndarray) -> bool:
    """Whether a travel edge of ``arcs`` (``arc_costs``; S's and E's edges aside)
    costs otherwise one way than the other, or exists one way only (at one-way curves' ends)."""
    A = arcs[2:, 2:]
    fin, both = np.isfinite(A), np.isfinite(A) & np.isfinite(A.T)
    return bool(np.any(fin != fin.T) or np.any(np.abs(A[both] - A.T[both]) > ASYMMETRY_TOL))


def applies(group: Group) -> bool:
    """Every curve: one candidate (a loop's seam, entered and left at one point, or a one-way
    curve, entered at one end and left at the other), or exactly two candidates that are each
    other's reverse."""
    cc = group.cand_curve
    counts = np.bincount(cc, minlength=group.n_curves)
    if counts.max(initial=0) > 2:
        return False
    two = np.nonzero(counts[cc] == 2)[0]
    f = group.cand_flip[two]
    return bool(np.all(f != two) and np.allclose(group.cand_entry_xy[two], group.cand_exit_xy[f]))


def travel_graph(group: Group):
    """See ``graph_and_arcs``: the symmetric graph (positions, curve per node, degree per node,
    cost matrix, nodes per curve, each curve's first candidate)."""
    return graph_and_arcs(group)[:6]


def arc_costs(group: Group) -> np.ndarray:
    """The travel graph's arcs (``graph_and_arcs``): cost of u -> v, leaving u's curve at u
    and entering v's curve at v, the group's link cost; inf where no arc exists (into S, out
    of E, within a curve). ``travel_graph``'s matrix is its minimum with its transpose."""
    return graph_and_arcs(group)[6]


def graph_and_arcs(group: Group):
    """The symmetric model's graph: node 0 = S, 1 = E, then the end points of each open curve
    (joined by the curve: a fixed edge; a one-way curve's arcs go into its entry and out of its
    exit only) and each loop's seam. Returns (positions, curve per node
    (-1 S, -2 E), degree per node (travel edges: 1, a seam 2), cost matrix (inf where no travel
    edge exists: same curve, S-E, the diagonal; 0 into E when the path may end anywhere), nodes
    per curve, each curve's first candidate).

    An edge x-y is a link either way: leaving x's curve at x into y's curve at y, or the reverse.
    Its cost is the cheaper of the two (the group's link costs: travel distance, the same both
    ways; the time objective's costs differ where one way is the slicer's own gap, copied). The
    model then relaxes the group's problem: its bound is valid, and a path it finds is priced by
    the group (``Group.path_cost``); it proves a path only where that price meets the bound.
    Edges at S and E have one direction (S starts the path, E ends it): exact. Last in the
    tuple, the arcs' own costs (``arc_costs``), which the directed refinement
    (``symmetric.DirectedModel``) prices exactly."""
    n = group.n_curves
    cc = group.cand_curve
    counts = np.bincount(cc, minlength=n)
    by_curve = np.argsort(cc, kind="stable")
    first_cand = by_curve[np.searchsorted(cc[by_curve], np.arange(n))]
    one = counts == 1
    # a loop: one node (its seam), degree 2; a one-way curve (one candidate, entered at one end
    # and left at the other: ``candidates.one_way``) has two nodes like an open curve, with arcs
    # into its entry and out of its exit only
    loop = one.copy()
    loop[one] = np.all(np.isclose(group.cand_entry_xy[first_cand[one]],
                                  group.cand_exit_xy[first_cand[one]]), axis=1)
    one_way = one & ~loop
    per_curve = np.where(loop, 1, 2)            # open: entry of its first candidate, then exit
    first_node = 2 + np.cumsum(per_curve) - per_curve
    N = 2 + int(per_curve.sum())
    pos = np.zeros((N, 2))
    pos[0] = group.start_xy
    if group.end_xy is not None:
        pos[1] = group.end_xy
    pos[first_node] = group.cand_entry_xy[first_cand]
    opened = first_node[~loop]
    pos[opened + 1] = group.cand_exit_xy[first_cand[~loop]]
    node_curve = np.concatenate([[-1, -2], np.repeat(np.arange(n), per_curve)])
    deg = np.ones(N)
    deg[first_node[loop]] = 2.0
    curve_nodes = [(f,) if lp else (f, f + 1) for f, lp in zip(first_node.tolist(), loop.tolist())]
    # per node: the candidate that enters its curve there and the one that leaves it there (an
    # open curve's first candidate enters at its first node and leaves at its second; the flip
    # the other way round; a loop's one candidate does both at its seam)
    enter = np.full(N, -1, np.int64)
    leave = np.full(N, -1, np.int64)
    enter[first_node] = first_cand
    leave[first_node] = np.where(loop, first_cand, group.cand_flip[first_cand])
    enter[opened + 1] = group.cand_flip[first_cand[~loop]]
    leave[opened + 1] = first_cand[~loop]
    # a one-way curve is never left at its entry nor entered at its exit: no such arcs
    single = first_node[one_way]
    leave[single] = -1
    enter[single + 1] = -1
    inner = np.arange(2, N)
    D = group.arc_cost()
    A = np.full((N, N), np.inf)                 # arcs u -> v
    lv, en = leave[inner], enter[inner]
    A[2:, 2:] = D[lv[:, None], en[None, :]]
    A[0, 2:] = group.start_cost()[en]
    A[2:, 1] = group.end_cost()[lv]             # 0: the path just ends
    A[2:][lv < 0] = np.inf
    A[:, 2:][:, en < 0] = np.inf
    np.fill_diagonal(A, np.inf)                 # no travel edge within a curve, nor S-E
    A[opened, opened + 1] = A[opened + 1, opened] = np.inf
    C = np.minimum(A, A.T)
    return pos, node_curve, deg, C, curve_nodes, first_cand, A


def joinable_costs(C: np.ndarray, node_curve: np.ndarray) -> np.ndarray:
    """``C`` for building tours (``_patch``, ``match_edges``): every two nodes of different
    curves joinable. Where one-way curves leave no travel edge between two of their end points
    (both entries, both exits), such an edge costs more than any real one: a tour that takes it
    anyway traverses a one-way curve against its way, and ``decode_edges`` prints that curve its
    own way (the path priced as printed, ``Group.path_cost``). ``C`` itself where nothing is
    missing."""
    other = node_curve[:, None] != node_curve[None, :]
    other[0, 1] = other[1, 0] = False           # S-E is the fixed edge
    miss = other & ~np.isfinite(C)
    if not miss.any():
        return C
    fin = C[np.isfinite(C)]
    H = C.copy()
    H[miss] = 2.0 * float(fin.max(initial=0.0)) + 1.0
    return H


def fixed_edges(curve_nodes):
    """The fixed edges of ``travel_graph``: each open curve between its end points, and E-S."""
    two = [nd for nd in curve_nodes if len(nd) == 2]
    return (np.array([nd[0] for nd in two] + [0], np.int64),
            np.array([nd[1] for nd in two] + [1], np.int64))


def odd_sets(C: np.ndarray, deg: np.ndarray, free_end: bool):
    """The cheapest perfect matching of the travel graph (``matching.py``; a seam counted as two
    vertices): every path's travel edges are one, so its cost is a lower bound (mm, rounded
    down), and the odd sets H of its dual hold ``x(δ(H)) >= 1`` for every path. Returns (bound,
    node masks of the odd sets, the matching's edges as node pairs (u, v); None, [], None if the
    matching failed)."""
    N = len(C)
    rep = np.where(deg == 2, 2, 1)
    idx = np.repeat(np.arange(N), rep)
    # the blossom algorithm runs on each vertex's nearest edges (and E's), adding the others
    # whose reduced cost turns negative (``matching.travel_matching``)
    k = min(MATCHING_NEIGHBOURS, len(idx) - 1)
    hub = int(np.flatnonzero(idx == 1)[0]) if free_end else None
    bound, mate, sets = matching.travel_matching(C, idx, k, 1, hub=hub)
    if bound is None:
        return None, [], None
    masks = []
    for H in sets:
        cnt = np.bincount(idx[H], minlength=N)
        if ((cnt > 0) & (cnt < rep)).any():     # a seam split between H and the rest
            continue
        inside = cnt > 0
        if int(deg[inside].sum()) % 2 == 1:
            masks.append(inside)
    a = np.flatnonzero(mate > np.arange(len(mate)))
    return bound / matching.UNITS_PER_COST, masks, (idx[a], idx[mate[a]])


#: (group, bound, odd sets) of the last ``matching_path``: its exact step reuses them
_last_odd_sets = None


def matching_path(group: Group):
    """A path from the cheapest perfect matching (``odd_sets``) and its bound: with the fixed
    edges the matching is a set of cycles, one through S and E; ``_patch`` joins them into one
    (Karp's patching). Polished by local search, it is the fallback path where it beats the
    greedy one (formulations/ordering.md, "Bounds").
    Returns (candidate order, bound mm), or (None, 0.0) if the matching failed."""
    global _last_odd_sets
    pos, node_curve, deg, C, curve_nodes, first_cand = travel_graph(group)
    bound, masks, edges = odd_sets(C, deg, group.end_xy is None)
    _last_odd_sets = (group, bound, masks)
    if bound is None:
        return None, 0.0
    fixed_u, fixed_v = fixed_edges(curve_nodes)
    eu, ev = _patch(len(pos), fixed_u, fixed_v, edges[0].astype(np.int64),
                    edges[1].astype(np.int64), joinable_costs(C, node_curve))
    return decode_edges(group, node_curve, curve_nodes, first_cand, eu, ev), bound


def decode_edges(group: Group, node_curve, curve_nodes, first_cand, eu, ev) -> np.ndarray:
    """Candidate order of the tour (of ``travel_graph``'s nodes) whose travel edges are (eu, ev)."""
    adj: dict[int, list[int]] = {}
    for u, v in zip(np.asarray(eu).tolist(), np.asarray(ev).tolist()):
        adj.setdefault(u, []).append(v)
        adj.setdefault(v, []).append(u)
    order, came, cur = [], 0, adj[0][0]
    while cur != 1 and len(order) <= group.n_curves:
        c = int(node_curve[cur])
        nodes = curve_nodes[c]
        k0 = int(first_cand[c])
        if len(nodes) == 1:                     # loop: leave by its other travel edge
            k, out = k0, cur
            nxt = [v for v in adj[cur] if v != came][0]
        else:                                   # open: traverse to the other end point (a
            # one-way curve entered at its exit, flip == itself, is printed its own way)
            k = k0 if cur == nodes[0] else int(group.cand_flip[k0])
            out = nodes[1] if cur == nodes[0] else nodes[0]
            nxt = adj[out][0]
        order.append(k)
        came, cur = out, nxt
    return np.asarray(order, np.int64)


def matching_of(group: Group):
    """(bound, odd sets) of the last ``matching_path`` if it was ``group``'s, else None: the
    exact step (``SymmetricModel.seed_odd_sets``) reuses them."""
    last = _last_odd_sets           # one read: another thread may replace it meanwhile
    if last is not None and last[0] is group:
        return last[1], last[2]
    return None


@numba.njit(cache=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(cache=True)
def _patch(n, fixed_u, fixed_v, eu, ev, C):
    """Karp's patching: the travel edges (eu, ev) and the fixed edges form cycles; while there
    is more than one, the cheapest exchange of a travel edge (a, b) of the cycle through S for a
    travel edge (c, d) of another cycle, (a, b) + (c, d) -> (a, c) + (b, d) or (a, d) + (b, c),
    joins the two. Returns the travel edges of the one cycle."""
    m = len(eu)
    eu = eu.copy()
    ev = ev.copy()
    while True:
        _, lab = _components(n, np.concatenate((fixed_u, eu)), np.concatenate((fixed_v, ev)))
        root = lab[0]
        best, bi, bj, cross = np.inf, -1, -1, False
        for j in range(m):
            if lab[eu[j]] == root:
                continue
            c, d = eu[j], ev[j]
            for i in range(m):
                a, b = eu[i], ev[i]
                if lab[a] != root:
                    continue
                base = C[a, b] + C[c, d]
                v1 = C[a, c] + C[b, d] - base
                if v1 < best:
                    best, bi, bj, cross = v1, i, j, False
                v2 = C[a, d] + C[b, c] - base
                if v2 < best:
                    best, bi, bj, cross = v2, i, j, True
        if bi < 0:
            return eu, ev
        a, b, c, d = eu[bi], ev[bi], eu[bj], ev[bj]
        if cross:
            c, d = d, c
        eu[bi], ev[bi], eu[bj], ev[bj] = a, c, b, d


@numba.njit(cache=True)
def match_edges(n, deg, fixed_u, fixed_v, pref_u, pref_v, C):
    """Greedy edge matching to one Hamiltonian cycle through the fixed edges: first the preferred
    edges in their order, then the cheapest remaining edges between fragment ends. Returns the
    travel edges (u, v)."""
    parent = np.arange(n)
    need = deg.copy()
    for i in range(len(fixed_u)):
        parent[_find(parent, fixed_u[i])] = _find(parent, fixed_v[i])
    out_u = np.empty(n, np.int64)
    out_v = np.empty(n, np.int64)
    k = 0
    n_edges = 0
    for i in range(n):
        n_edges += deg[i]
    n_edges //= 2                       # travel edges of the tour
    for i in range(len(pref_u)):
        a, b = pref_u[i], pref_v[i]
        if need[a] == 0 or need[b] == 0:
            continue
        ra, rb = _find(parent, a), _find(parent, b)
        if ra == rb and k + 1 < n_edges:
            continue
        parent[ra] = rb
        need[a] -= 1
        need[b] -= 1
        out_u[k] = a
        out_v[k] = b
        k += 1
    while k < n_edges:                  # join fragments: cheapest edge between free ends
        best, ba, bb = np.inf, -1, -1
        for a in range(n):
            if need[a] == 0:
                continue
            ra = _find(parent, a)
            for b in range(a + 1, n):
                if need[b] == 0 or not np.isfinite(C[a, b]):
                    continue
                if _find(parent, b) == ra and k + 1 < n_edges:
                    continue
                if C[a, b] < best:
                    best, ba, bb = C[a, b], a, b
        if ba < 0:
            break
        parent[_find(parent, ba)] = _find(parent, bb)
        need[ba] -= 1
        need[bb] -= 1
        out_u[k] = ba
        out_v[k] = bb
        k += 1
    return out_u[:k], out_v[:k]
