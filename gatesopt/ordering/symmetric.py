"""Exact ordering as a symmetric TSP with fixed edges (formulations/ordering.md, "milp, symmetric
model"): an LP over a sparse set of travel edges with subtour and blossom cuts, column pricing,
reduced-cost fixing, then our own branch-and-cut on what is left (HiGHS solves the LPs).

When every curve is an open curve with its two directions or a loop with one seam, the
orientation choice disappears into an undirected graph: nodes S (the start), E (the end), both
end points of each open curve (joined by the curve itself: a *fixed* edge) and the seam of each
loop. The path S -> ... -> E plus the fixed edge E-S is a tour. The LP relaxation with subtour
cuts (Held–Karp) is far tighter than the directed model's; blossoms (2-matching combs) close most
of what is left on infill, where long fixed edges make odd cycles of half-edges cheap.

Only the few shortest travel edges of each node are columns at first: real layers have hundreds
of end points and a dense model has ~N^2/2 columns, most of which no good path uses. Missing edges
enter when their reduced cost is negative (column generation); at the end every missing edge's
reduced cost ``rc_e`` proves that no path cheaper than the incumbent uses it when
``rc_e > UB - LB`` (reduced-cost fixing), so the branch-and-cut runs on the sparse graph and its
optimum is the optimum of the whole problem.
"""
from __future__ import annotations

import time

import highspy
import numba
import numpy as np
from scipy.spatial.distance import cdist

from .._native import run_highs
from . import matching
from .problem import OPTIMAL_ABS_TOL_MM, Group

_OPT = highspy.HighsModelStatus.kOptimal
_INFEASIBLE = highspy.HighsModelStatus.kInfeasible
_EPS = 1e-6

#: travel edges per node in the first LP (nearest other-curve end points)
K_NEIGHBOURS = 8
#: no branching when reduced-cost fixing leaves more columns than this per node: the root gap
#: is then too wide to close within seconds (measured with HiGHS's MIP, before our own
#: branch-and-cut: 166 k columns for a 312-curve group with an 11 % root gap, nothing closed in
#: 20 s)
MAX_BRANCH_COLUMNS_PER_NODE = 40
#: edges per vertex the matching's blossom algorithm starts from (``odd_sets``)
MATCHING_NEIGHBOURS = 10
#: ILS kicks per curve spent on the path built from the root LP point (it starts close to the
#: optimum; the warm start's search already spent its share)
POLISH_KICKS_PER_CURVE = 1
#: at most this many priced-in columns per pricing round, per node of the graph
PRICE_PER_NODE = 1
#: share of a group's time (from the root's start) in which the root may separate blossoms
#: exactly (``_blossoms_exact``) once the fast separators find nothing
EXACT_BLOSSOM_SHARE = 0.25
EXACT_BLOSSOM_MAX_CUTS = 10
EXACT_BLOSSOM_MIN_VIOLATION = 0.1
#: at most this many subtour cuts per separation round (``_min_cuts``)
MAX_SUBTOUR_CUTS = 40
#: separation rounds per branch-and-cut node (then it is branched on its last LP point)
MAX_NODE_CUT_ROUNDS = 50


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


def applies(group: Group) -> bool:
    """Every curve: one candidate entering and leaving at one point (a loop's seam), or exactly
    two candidates that are each other's reverse."""
    cc = group.cand_curve
    counts = np.bincount(cc, minlength=group.n_curves)
    if counts.max(initial=0) > 2:
        return False
    one = counts[cc] == 1
    if not np.allclose(group.cand_entry_xy[one], group.cand_exit_xy[one]):
        return False
    two = np.nonzero(counts[cc] == 2)[0]
    f = group.cand_flip[two]
    return bool(np.all(f != two) and np.allclose(group.cand_entry_xy[two], group.cand_exit_xy[f]))


def travel_graph(group: Group):
    """The symmetric model's graph: node 0 = S, 1 = E, then the end points of each open curve
    (joined by the curve: a fixed edge) and each loop's seam. Returns (positions, curve per node
    (-1 S, -2 E), degree per node (travel edges: 1, a seam 2), cost matrix (inf where no travel
    edge exists: same curve, S-E, the diagonal; 0 into E when the path may end anywhere), nodes
    per curve, each curve's first candidate)."""
    n = group.n_curves
    cc = group.cand_curve
    counts = np.bincount(cc, minlength=n)
    by_curve = np.argsort(cc, kind="stable")
    first_cand = by_curve[np.searchsorted(cc[by_curve], np.arange(n))]
    loop = counts == 1                          # a loop: one node (its seam), degree 2
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
    C = cdist(pos, pos)
    if group.end_xy is None:
        C[1, :] = C[:, 1] = 0.0                            # the path just ends
    np.fill_diagonal(C, np.inf)                 # no travel edge within a curve, nor S-E
    C[opened, opened + 1] = C[opened + 1, opened] = np.inf
    C[0, 1] = C[1, 0] = np.inf
    return pos, node_curve, deg, C, curve_nodes, first_cand


def tree_cuts_below(n: int, u, v, w, limit: float, max_cuts: int, seconds: float,
                    keep_out: int = 0) -> list[np.ndarray]:
    """The distinct cuts of the Gomory–Hu tree of the graph on nodes 0..n-1 (edges u-v of
    capacity w) whose capacity is below ``limit``, the smallest first, at most ``max_cuts``, each
    as the boolean side without node ``keep_out``. Every pair of nodes has a minimum cut among the
    tree's n - 1, so this finds nested cuts together (``SymmetricModel._min_cuts``)."""
    u, v = np.asarray(u, np.int64), np.asarray(v, np.int64)
    w = np.asarray(w, float)
    sides = _gomory_hu_sides(n, *_residual_arcs(n, u, v, w), float(seconds))
    if len(sides) == 0:
        return []
    value = (sides[:, u] != sides[:, v]) @ w
    below = np.flatnonzero(value < limit)
    out, seen = [], set()
    for i in below[np.argsort(value[below], kind="stable")]:
        side = sides[i] ^ sides[i, keep_out]            # one orientation: one key per cut
        k = side.tobytes()
        if k not in seen:
            seen.add(k)
            out.append(side)
            if len(out) >= max_cuts:
                break
    return out


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
    return bound / matching.UNITS_PER_MM, masks, (idx[a], idx[mate[a]])


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
                    edges[1].astype(np.int64), C)
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
        else:                                   # open: traverse to the other end point
            k = k0 if cur == nodes[0] else int(group.cand_flip[k0])
            out = nodes[1] if cur == nodes[0] else nodes[0]
            nxt = adj[out][0]
        order.append(k)
        came, cur = out, nxt
    return np.asarray(order, np.int64)


class SymmetricModel:
    """Nodes 0 = S, 1 = E, then the end points of the curves; HiGHS rows 0..N-1 are the degree
    equations ``x(δ(v)) = deg_v`` (1 beside a fixed edge, 2 for a loop's seam), the rest cuts."""

    def __init__(self, group: Group, incumbent: np.ndarray):
        self.group = group
        (self.pos, self.node_curve, self.deg, self.C, self.curve_nodes,
         self.first_cand) = travel_graph(group)
        N = self.N = len(self.pos)
        C = self.C
        self.fixed_u, self.fixed_v = fixed_edges(self.curve_nodes)
        # columns (u < v) and cuts (node mask "inside", row index N + i)
        self.eu = np.zeros(0, np.int64)
        self.ev = np.zeros(0, np.int64)
        self.present = np.zeros((N, N), bool)
        self.cut_inside: list[np.ndarray] = []
        h = self.h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("random_seed", 0)
        h.addRows(N, self.deg, self.deg, 0, np.zeros(N, np.int32), np.zeros(0, np.int32), np.zeros(0))
        # first columns: each node's nearest neighbours, every edge at E, the incumbent's edges
        k = min(K_NEIGHBOURS, N - 1)
        # a partial selection: the full row sort took ~1 ms of the model's ~1.6 ms build on a
        # 100-curve group (which k of equal distances enter matters not: pricing adds the rest)
        near = np.argpartition(C, k - 1, axis=1)[:, :k] if k > 0 else np.zeros((N, 0), np.int64)
        r = np.repeat(np.arange(N), k)
        c = near.ravel()
        inc = self.tour_edges(incumbent)
        r = np.concatenate([r, np.full(N, 1), inc[:, 0]])
        c = np.concatenate([c, np.arange(N), inc[:, 1]])
        self.add_columns(r, c)

    # -- columns and rows -------------------------------------------------------------------

    def add_columns(self, r, c) -> int:
        r, c = np.asarray(r, np.int64), np.asarray(c, np.int64)
        u, v = np.minimum(r, c), np.maximum(r, c)
        ok = np.isfinite(self.C[u, v]) & ~self.present[u, v]
        key = np.unique(u[ok] * self.N + v[ok])
        u, v = key // self.N, key % self.N
        if len(u) == 0:
            return 0
        self.present[u, v] = self.present[v, u] = True
        # entries: the two degree rows, and every cut row the edge crosses (coefficient 1: a new
        # column is never a blossom's tooth)
        K = len(u)
        rows_all, cols_all = [u, v], [np.arange(K), np.arange(K)]
        if self.cut_inside:
            ins = np.asarray(self.cut_inside)                   # (cuts, N)
            j, r = np.nonzero((ins[:, u] != ins[:, v]).T)
            rows_all.append(self.N + r)
            cols_all.append(j)
        rows_all, cols_all = np.concatenate(rows_all), np.concatenate(cols_all)
        o = np.argsort(cols_all, kind="stable")
        idx = rows_all[o].astype(np.int32)
        starts = np.searchsorted(cols_all[o], np.arange(K)).astype(np.int32)
        self.h.addCols(K, self.C[u, v], np.zeros(K), np.ones(K), len(idx), starts, idx,
                       np.ones(len(idx)))
        self.eu = np.concatenate([self.eu, u])
        self.ev = np.concatenate([self.ev, v])
        return len(u)

    def add_cuts(self, cuts) -> int:
        """Cuts given as (inside, teeth or None): for ``teeth`` None the subtour cut
        ``x(δ(U)) >= 2``, else (edges of δ(H) at 1: travel columns, fixed-edge mask) the blossom
        ``x(δ(H) \\ T) - x(T) >= 1 - |T|``; fixed edges are constants moved to the right. All in
        one HiGHS call (a separation round finds up to ~40; one call each cost ~35 us apiece).
        Returns how many."""
        if not cuts:
            return 0
        K = len(cuts)
        ins = np.array([inside for inside, _ in cuts], bool)               # (cuts, nodes)
        cross = ins[:, self.eu] != ins[:, self.ev]
        coef = np.ones(cross.shape)
        fixed_cross = ins[:, self.fixed_u] != ins[:, self.fixed_v]
        rhs = np.empty(K)
        for i, (_, teeth) in enumerate(cuts):
            if teeth is None:
                rhs[i] = 2.0 - fixed_cross[i].sum()
            else:
                tooth_col, tooth_fixed = teeth
                coef[i, tooth_col] = -1.0
                n_t = len(tooth_col) + int(tooth_fixed.sum())
                rhs[i] = (1.0 - n_t - int((fixed_cross[i] & ~tooth_fixed).sum())
                          + int(tooth_fixed.sum()))
        r, c = np.nonzero(cross)
        starts = np.searchsorted(r, np.arange(K)).astype(np.int32)
        self.h.addRows(K, rhs, np.full(K, highspy.kHighsInf), len(c), starts,
                       c.astype(np.int32), coef[r, c])
        self.cut_inside.extend(ins)
        return K

    def seed_odd_sets(self) -> float:
        """Start the LP with the odd-set cuts ``x(δ(H)) >= 1`` of the cheapest perfect matching's
        dual (``odd_sets``): the blossoms the separators would otherwise find a few per round.
        Returns the matching's bound (0 if it failed)."""
        last = _last_odd_sets           # one read: another thread may replace it meanwhile
        if last is not None and last[0] is self.group:
            _, bound, masks = last                  # auto took its path from the same matching
        else:
            bound, masks, _ = odd_sets(self.C, self.deg, self.group.end_xy is None)
        none = np.zeros(0, np.int64)
        self.add_cuts([(inside, (none, inside[self.fixed_u] != inside[self.fixed_v]))
                       for inside in masks])
        return 0.0 if bound is None else bound

    def tour_edges(self, order: np.ndarray) -> np.ndarray:
        """The travel edges of a candidate order, as (u, v) node pairs."""
        g = self.group
        out, prev = [], 0
        for k in order:
            c = int(g.cand_curve[k])
            nodes = self.curve_nodes[c]
            if len(nodes) == 1:
                a = b = nodes[0]
            else:
                a, b = (nodes[0], nodes[1]) if k == self.first_cand[c] else (nodes[1], nodes[0])
            out.append((prev, a))
            prev = b
        out.append((prev, 1))
        return np.asarray(out, np.int64)

    def columns_of(self, order: np.ndarray) -> np.ndarray:
        e = self.tour_edges(order)
        u, v = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
        index = {(a, b): j for j, (a, b) in enumerate(zip(self.eu.tolist(), self.ev.tolist()))}
        col = np.zeros(len(self.eu))
        for a, b in zip(u.tolist(), v.tolist()):
            col[index[a, b]] = 1.0
        return col

    # -- separation ---------------------------------------------------------------------------

    def _support_components(self, on: np.ndarray):
        return components(self.N, np.concatenate([self.eu[on], self.fixed_u]),
                          np.concatenate([self.ev[on], self.fixed_v]))

    def separate(self, x: np.ndarray, deadline: float, integer: bool = False,
                 exact_blossoms_until: float = -np.inf) -> int:
        """Add violated cuts for the point ``x``; returns how many. Components of the support
        first; a connected support gets exact subtour separation by minimum cuts and the
        odd-component blossom heuristic; if these find nothing before ``exact_blossoms_until``
        (a ``time.perf_counter()`` value), exact blossom separation."""
        ncomp, lab = self._support_components(x > _EPS)
        if ncomp > 1:
            return self.add_cuts([(lab == comp, None) for comp in range(ncomp)])
        if integer:
            return 0
        n = self._min_cuts(x, deadline)
        n += self._blossoms(x)
        if n == 0 and time.perf_counter() < exact_blossoms_until:
            n = self._blossoms_exact(x, min(deadline, exact_blossoms_until))
        return n

    def _min_cuts(self, x: np.ndarray, deadline: float, max_cuts: int = MAX_SUBTOUR_CUTS) -> int:
        """A cut below 2 (capacities x, fixed edges 1) is a violated subtour cut
        ``x(δ(U)) >= 2 - fixed(δ(U))``. Edges at 1 (fixed ones included) are shrunk first
        (Padberg–Rinaldi: with x_uv = 1 moving v to u's side never increases a cut, as
        x(δ(v)) = 2), then the Gomory–Hu tree of what is left gives a minimum cut for every pair
        of nodes: its cuts below 2, the most violated first, are added all at once. Nested
        violated cuts are common (a far cluster of curves behind a chain of near ones); a search
        from S that stops at the first cut per sink found one of them per LP round (measured on 60
        Cura bunny groups: 1204 LP solves and 4.1 s in all, with the tree 923 and 3.1-3.4 s; one
        47-curve group took 17 LP rounds and 83 ms, with the tree 6 and 19 ms)."""
        on = x > 1e-9
        n_sh, lab = self._support_components(x >= 1 - 1e-9)
        if n_sh <= 2:
            return 0
        u, v = lab[self.eu[on]], lab[self.ev[on]]
        keep = u != v
        # parallel edges between two shrunk nodes: one arc with the summed capacity
        key, inv = np.unique(np.minimum(u, v)[keep] * n_sh + np.maximum(u, v)[keep], return_inverse=True)
        w = np.bincount(inv, weights=x[on][keep], minlength=len(key))
        cuts = tree_cuts_below(n_sh, key // n_sh, key % n_sh, w, 2.0 - 1e-6, max_cuts,
                               float(deadline - time.perf_counter()), keep_out=int(lab[0]))
        return self.add_cuts([(side[lab], None) for side in cuts])

    def _edges_at_one(self, x: np.ndarray):
        """The edges at 1 in ``x``, the blossoms' possible teeth: travel columns and every fixed
        edge, as (u, v, column or -1)."""
        ones = np.nonzero(x >= 1 - _EPS)[0]
        return (np.concatenate([self.eu[ones], self.fixed_u]),
                np.concatenate([self.ev[ones], self.fixed_v]),
                np.concatenate([ones, np.full(len(self.fixed_u), -1)]))

    def _blossoms(self, x: np.ndarray) -> int:
        """Odd-component heuristic (Padberg–Hong): a handle H = a connected component of the
        fractional edges; its teeth are the edges at 1 (fixed edges included) leaving H. With an
        odd number of disjoint teeth the blossom ``x(δ(H) \\ T) - x(T) >= 1 - |T|`` is violated
        by 1 - x(δ(H) \\ T). Teeth meeting outside H pull their common end point into H."""
        frac = (x > _EPS) & (x < 1 - _EPS)
        if not frac.any():
            return 0
        one_u, one_v, one_col = self._edges_at_one(x)
        ncomp, lab = components(self.N, self.eu[frac], self.ev[frac])
        touched = np.zeros(self.N, bool)
        touched[self.eu[frac]] = touched[self.ev[frac]] = True
        found = []
        for comp in np.unique(lab[touched]):
            inside = lab == comp
            if inside.sum() < 3:
                continue
            for _ in range(self.N):
                cross = inside[one_u] != inside[one_v]
                outer = np.where(inside[one_u[cross]], one_v[cross], one_u[cross])
                vals, cnt = np.unique(outer, return_counts=True)
                if (cnt > 1).any():
                    inside[vals[cnt > 1]] = True
                    continue
                break
            if cross.sum() < 3 or cross.sum() % 2 == 0:
                continue
            col = one_col[cross]
            tooth_col = col[col >= 0]
            tooth_fixed = inside[self.fixed_u] != inside[self.fixed_v]     # all at 1
            others = (inside[self.eu] != inside[self.ev]) & (x > _EPS)
            others[tooth_col] = False
            if x[others].sum() >= 1 - 1e-4:
                continue
            found.append((inside, (tooth_col, tooth_fixed)))
        return self.add_cuts(found)

    def _blossoms_exact(self, x: np.ndarray, deadline: float) -> int:
        """Blossoms the odd-component heuristic misses (Letchford, Reinelt and Theis, "Odd
        minimum cut sets and b-matchings revisited", 2008). For a handle H the best odd T of
        δ(H) takes the edges with x > 1/2, and if their number is even the edge with the least
        |1 - 2x| changes side, so ``x(δ(H) \\ T) + Σ_T (1 - x) = Σ_δ(H) min(x, 1 - x)`` plus that
        parity term; the blossom is violated when this is below 1. The candidate handles are the
        minimum cuts of a Gomory–Hu tree (Gusfield's n - 1 maximum flows) under the weights
        min(x, 1 - x), within each component of the fractional edges (edges at 1 weigh 0). LRT
        show that a most violated blossom is among such cuts; here teeth need not be disjoint (the
        inequality is valid for any odd T, by the parity of x(δ(H)) on a tour). The
        ``EXACT_BLOSSOM_MAX_CUTS`` most violated, by at least ``EXACT_BLOSSOM_MIN_VIOLATION``,
        enter."""
        frac = (x > _EPS) & (x < 1 - _EPS)
        if not frac.any():
            return 0
        N = self.N
        one_u, one_v, one_col = self._edges_at_one(x)
        fcol = np.nonzero(frac)[0]
        fu, fv, fx = self.eu[fcol], self.ev[fcol], x[fcol]
        _, lab = components(N, fu, fv)
        touched = np.zeros(N, bool)
        touched[fu] = touched[fv] = True
        found, seen = [], set()
        for comp in np.unique(lab[touched]).tolist():
            nodes = np.flatnonzero(lab == comp)
            n = len(nodes)
            if n < 3:
                continue
            local = np.full(N, -1)
            local[nodes] = np.arange(n)
            mine = lab[fu] == comp
            w = np.minimum(fx[mine], 1.0 - fx[mine])
            indptr, head, cap, rev = _residual_arcs(n, local[fu[mine]], local[fv[mine]], w)
            sides = _gomory_hu_sides(n, indptr, head, cap, rev,
                                     float(deadline - time.perf_counter()))
            for side in sides:
                inside = np.zeros(N, bool)
                inside[nodes[side]] = True
                key = inside.tobytes()
                if key in seen:
                    continue
                seen.add(key)
                cross_f = inside[fu] != inside[fv]
                xs = fx[cross_f]
                cross_1 = inside[one_u] != inside[one_v]
                tooth = xs > 0.5
                value = float(np.minimum(xs, 1.0 - xs).sum())
                if (int(tooth.sum()) + int(cross_1.sum())) % 2 == 0:
                    # parity: the fractional edge with the least |1 - 2x| changes side (an edge at
                    # 1 leaving T would cost 1: no violation)
                    if len(xs) == 0:
                        continue
                    j = int(np.argmin(np.abs(1.0 - 2.0 * xs)))
                    value += abs(1.0 - 2.0 * xs[j])
                    tooth[j] = not tooth[j]
                if value < 1.0 - EXACT_BLOSSOM_MIN_VIOLATION:
                    cols = one_col[cross_1]
                    found.append((value, inside,
                                  np.concatenate([fcol[cross_f][tooth], cols[cols >= 0]])))
            if time.perf_counter() > deadline:
                break
        found.sort(key=lambda f: f[0])
        return self.add_cuts([(inside, (tooth_col.astype(np.int64),
                                        inside[self.fixed_u] != inside[self.fixed_v]))
                              for _, inside, tooth_col in found[:EXACT_BLOSSOM_MAX_CUTS]])

    # -- duals ------------------------------------------------------------------------------

    def reduced_costs(self) -> np.ndarray:
        """Reduced cost of every edge under the current LP duals (HiGHS: rc = c - A^T y); inf
        where no edge exists. Cut rows cross an edge iff exactly one of its ends is inside; a
        missing edge is never a tooth (teeth are columns at 1)."""
        y = np.asarray(self.h.getSolution().row_dual)
        yd, yc = y[:self.N], y[self.N:]
        rc = self.C - yd[:, None] - yd[None, :]
        if len(yc):
            act = np.abs(yc) > 1e-12
            if act.any():
                _subtract_cut_duals(rc, np.asarray(self.cut_inside)[act], yc[act])
        return rc

    def lp_bound(self, obj: float, rc: np.ndarray) -> float:
        """Valid lower bound from the restricted LP: obj + sum of the negative reduced costs of
        missing edges (each x_e <= 1), halved for the symmetric duplicates."""
        miss = ~self.present & np.isfinite(rc)
        neg = np.minimum(rc[miss], 0.0)
        return float(obj + 0.5 * neg.sum())

    def price(self, rc: np.ndarray) -> int:
        miss = ~self.present & np.isfinite(rc)
        iu, iv = np.nonzero(np.triu(miss & (rc < -1e-7), 1))
        if len(iu) == 0:
            return 0
        keep = np.argsort(rc[iu, iv])[:max(PRICE_PER_NODE * self.N, 20)]
        return self.add_columns(iu[keep], iv[keep])

    # -- decoding -----------------------------------------------------------------------------

    def decode(self, x: np.ndarray) -> np.ndarray | None:
        """Candidate order from an integer point, or None if it has subtours."""
        on = x > 0.5
        ncomp, _ = self._support_components(on)
        if ncomp > 1:
            return None
        return self.decode_edges(self.eu[on], self.ev[on])

    def decode_edges(self, eu, ev) -> np.ndarray:
        """Candidate order of the tour whose travel edges are (eu, ev)."""
        return decode_edges(self.group, self.node_curve, self.curve_nodes, self.first_cand, eu, ev)

    def tour_from(self, x: np.ndarray) -> np.ndarray:
        """A path built from an LP or subtour point: greedy edge matching (Kruskal-like: an edge
        enters if both ends still need a travel edge and it closes no cycle) over the columns by
        ``x`` descending, then cost; what is left is joined by the cheapest edges of the whole
        graph. Gives the exact step an incumbent near the LP optimum (ILS polishes it)."""
        key = np.lexsort((self.C[self.eu, self.ev], -np.round(x, 6)))
        cols = key[x[key] > _EPS]
        u, v = _match(self.N, self.deg.astype(np.int64), self.fixed_u, self.fixed_v,
                      self.eu[cols], self.ev[cols], self.C)
        return self.decode_edges(u, v)

    # -- the solve ----------------------------------------------------------------------------

    def root(self, deadline: float, max_rounds: int = 500, cuts: bool = True,
             exact_blossoms_s: float = 0.0) -> float:
        """Cutting planes and pricing on the LP until neither finds anything (or time is up).
        Returns a valid lower bound (0 if no LP was solved); ``self.complete`` tells whether the
        LP of the whole graph was solved to optimality. ``cuts=False``: pricing only, the bound
        of the degree equations alone (a fractional matching; bench/ordering_gaps.py compares).
        For the first ``exact_blossoms_s`` seconds, rounds where the other separators find
        nothing also try ``_blossoms_exact`` (branch-and-cut nodes use the fast separators only)."""
        exact_until = time.perf_counter() + exact_blossoms_s
        self.complete = False
        bound = 0.0
        t_round = 0.0                           # the longest round so far
        for _ in range(max_rounds):
            t = time.perf_counter()
            if not run_highs(self.h, deadline) or self.h.getModelStatus() != _OPT:
                break
            x = np.asarray(self.h.getSolution().col_value)
            obj = float(self.h.getInfo().objective_function_value)
            # the reduced costs of the whole graph (a dense N x N pass with every cut row) serve
            # pricing and the bound: they wait until separation finds nothing, unless the next
            # round might not finish in time (then this round's bound is the one kept). On 173
            # Cura bunny groups: 309 passes instead of 3007
            last_chance = time.perf_counter() + 2 * t_round > deadline
            if last_chance:
                bound = max(bound, self.lp_bound(obj, self.reduced_costs()))
            found = self.separate(x, deadline, exact_blossoms_until=exact_until) if cuts else 0
            t_round = max(t_round, time.perf_counter() - t)
            if found:
                continue
            rc = self.reduced_costs()
            bound = max(bound, self.lp_bound(obj, rc))
            if self.price(rc):
                continue
            self.complete = True
            self.rc = rc
            break
        return bound

    def branch(self, best: np.ndarray, best_obj: float, bound: float, deadline: float,
               max_nodes: int = 100_000):
        """Branch-and-cut on the sparse graph after reduced-cost fixing. Needs ``root`` to have
        completed: an edge whose reduced cost exceeds ``best_obj - bound`` is in no path cheaper
        than ``best`` (any path using it costs at least ``bound + rc_e``), so missing edges below
        that enter as columns, present ones above it are fixed at 0 (again whenever the
        incumbent improves), and the optimum of what is left is the optimum of the whole
        problem. Best-bound node selection; each node's LP is hot-started from the last one (only
        column bounds change); subtour and blossom separation at every node (valid for every
        path, so the cuts stay for all nodes); branching on the edge closest to 1/2; a path built
        from each fractional point (``tour_from``) may improve the incumbent. Returns (order,
        objective, bound, proven)."""
        import heapq
        h = self.h
        rc = self.rc
        col_rc = np.asarray(h.getSolution().col_dual, float)
        n_old = len(col_rc)
        gap = best_obj - bound + 1e-6
        iu, iv = np.nonzero(np.triu(~self.present & np.isfinite(rc) & (rc <= gap), 1))
        if n_old + len(iu) > MAX_BRANCH_COLUMNS_PER_NODE * self.N:
            return best, best_obj, bound, False
        self.add_columns(iu, iv)
        col_rc = np.concatenate([col_rc, rc[self.eu[n_old:], self.ev[n_old:]]])
        root_bound = bound
        ncol = len(self.eu)
        upper = np.ones(ncol)                   # global upper bounds (0: fixed by reduced cost)
        applied: dict[int, float] = {}          # node bounds currently set in HiGHS: col -> value

        def fix_by_reduced_cost():
            """Fix at 0 what the incumbent's gap excludes; a column the current node fixes keeps
            its node bound until the node is left (then it is restored to ``upper``)."""
            drop = np.nonzero((col_rc > best_obj - root_bound + 1e-6) & (upper > 0))[0]
            upper[drop] = 0.0
            drop = np.asarray([c for c in drop.tolist() if c not in applied], np.int32)
            if len(drop):
                h.changeColsBounds(len(drop), drop, np.zeros(len(drop)), np.zeros(len(drop)))

        fix_by_reduced_cost()
        heap = [(bound, 0, ())]                 # (parent's LP bound, tiebreak, fixings)
        count = 1
        nodes = 0
        while heap:
            if time.perf_counter() > deadline or nodes >= max_nodes:
                break
            node_bound, _, fixings = heapq.heappop(heap)
            if node_bound >= best_obj - OPTIMAL_ABS_TOL_MM:
                continue
            nodes += 1
            # this node's fixings; the previous node's that it lacks go back to the global bounds
            # (only what changed is sent)
            want = dict(fixings)
            cols = [c for c in applied if c not in want] + [c for c in want if applied.get(c) != want[c]]
            if cols:
                cols_a = np.asarray(cols, np.int32)
                lo = np.array([want.get(c, 0.0) for c in cols])
                hi = np.array([want[c] if c in want else upper[c] for c in cols])
                h.changeColsBounds(len(cols_a), cols_a, lo, hi)
            applied.clear()
            applied.update(want)
            lp_obj, x, outcome = None, None, "branch"
            for _ in range(MAX_NODE_CUT_ROUNDS):
                if not run_highs(h, deadline):
                    outcome = "stopped"
                    break
                ms = h.getModelStatus()
                if ms == _INFEASIBLE:
                    outcome = "pruned"
                    break
                if ms != _OPT:                  # time limit or anything else: not settled
                    outcome = "stopped"
                    break
                lp_obj = float(h.getInfo().objective_function_value)
                x = np.asarray(h.getSolution().col_value)
                if lp_obj >= best_obj - OPTIMAL_ABS_TOL_MM:
                    outcome = "pruned"
                    break
                if not self.separate(x, deadline):
                    break
            # (cut rounds used up: the last LP point and its value, a valid bound, are branched on)
            if outcome == "stopped":            # only an LP that proves something discards a node
                heapq.heappush(heap, (node_bound, count, fixings))
                break
            if outcome == "pruned":
                continue
            frac = np.nonzero((x > _EPS) & (x < 1 - _EPS))[0]
            if len(frac) == 0:                  # integral, connected (separation found nothing)
                order = self.decode(x)
                if order is not None:
                    obj = self.group.path_cost_mm(order)
                    if obj < best_obj - 1e-9:
                        best, best_obj = order, obj
                        fix_by_reduced_cost()
                continue
            order = self.tour_from(x)
            if order is not None and len(order) == self.group.n_curves:
                obj = self.group.path_cost_mm(order)
                if obj < best_obj - 1e-9:
                    best, best_obj = order, obj
                    fix_by_reduced_cost()
            # branch on the edge closest to 1/2, the longer one on ties
            e = frac[np.lexsort((-self.C[self.eu[frac], self.ev[frac]], np.abs(x[frac] - 0.5)))[0]]
            for val in (1.0, 0.0):
                heapq.heappush(heap, (lp_obj, count, fixings + ((int(e), val),)))
                count += 1
        open_bound = min((b for b, _, _ in heap), default=best_obj)
        bound = max(bound, min(open_bound, best_obj))
        proven = best_obj - bound <= OPTIMAL_ABS_TOL_MM
        return best, best_obj, bound, proven

    def _polish(self, order, best, best_obj, bound, deadline):
        """ILS from ``order``, stopped once it reaches ``bound`` (then proven optimal); the
        better of it and ``best``."""
        from .ils import improve_ils
        if order is None or len(order) != self.group.n_curves:
            return best, best_obj
        order = improve_ils(self.group, order, kicks=POLISH_KICKS_PER_CURVE * self.group.n_curves,
                            deadline=deadline, target_mm=bound + OPTIMAL_ABS_TOL_MM)
        obj = self.group.path_cost_mm(order)
        return (order, obj) if obj < best_obj - 1e-9 else (best, best_obj)


def solve(group: Group, incumbent: np.ndarray, deadline: float):
    """Root LP (cuts and pricing); a path built from the LP point and polished by ILS may improve
    the incumbent; then branch-and-cut if a gap is left. Returns (order, objective, bound,
    proven optimal)."""
    best = np.asarray(incumbent, np.int64)
    best_obj = group.path_cost_mm(best)
    model = SymmetricModel(group, best)
    bound = model.seed_odd_sets()
    if best_obj - bound <= OPTIMAL_ABS_TOL_MM:
        return best, best_obj, bound, True
    bound = max(bound, model.root(
        deadline, exact_blossoms_s=EXACT_BLOSSOM_SHARE * (deadline - time.perf_counter())))
    if best_obj - bound > OPTIMAL_ABS_TOL_MM and model.complete:
        x = np.asarray(model.h.getSolution().col_value)
        best, best_obj = model._polish(model.tour_from(x), best, best_obj, bound, deadline)
    if best_obj - bound <= OPTIMAL_ABS_TOL_MM:
        return best, best_obj, bound, True
    if not model.complete:
        return best, best_obj, bound, False
    return model.branch(best, best_obj, bound, deadline)


@numba.njit(cache=True)
def _subtract_cut_duals(rc, inside, w):
    """``rc[u, v] -= sum_r w_r [cut r crosses uv]``, crossing = ``[u in r] + [v in r] - 2 [u in r]
    [v in r]``, summed over each cut's smaller side (a side and its complement cross the same
    edges). A loop rather than numpy's matrix product: OpenBLAS's threads spin after each
    product, on the core the other process of a two-process solve needs (measured on 60 Cura
    bunny groups in one process: 8.8 s of CPU for 6.6 s, 6.3 s for 6.3 s with this loop)."""
    n_cuts, n = inside.shape
    a = np.zeros(n)
    q = np.zeros((n, n))
    side = np.empty(n, np.int64)
    for r in range(n_cuts):
        flip = 2 * inside[r].sum() > n
        k = 0
        for u in range(n):
            if inside[r, u] != flip:
                side[k] = u
                k += 1
        wr = w[r]
        for i in range(k):
            u = side[i]
            a[u] += wr
            for j in range(k):
                q[u, side[j]] += wr
    for u in range(n):
        for v in range(n):
            rc[u, v] -= a[u] + a[v] - 2.0 * q[u, v]


def load_kernels() -> None:
    """Compile (or load from numba's cache) the kernels of the exact blossom separation, of
    the reduced costs and of the matching on made-up graphs, so that the first group that needs
    them does not pay for it."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 0.0]])
    odd_sets(np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1)) + np.diag(np.full(4, np.inf)),
             np.ones(4), True)
    arcs = _residual_arcs(3, np.array([0, 1, 2]), np.array([1, 2, 0]), np.full(3, 0.5))
    _gomory_hu_sides(3, *arcs, 1.0)
    _subtract_cut_duals(np.zeros((3, 3)), np.array([[True, False, False]]), np.ones(1))


def _residual_arcs(n: int, u, v, w):
    """An undirected graph (edges u-v of capacity w) as residual arcs for the max flows below:
    u->v and v->u, each with capacity w, grouped by tail (``indptr``) and paired by ``rev``."""
    tail = np.concatenate([u, v])
    head = np.concatenate([v, u])
    m = len(u)
    rev = np.concatenate([np.arange(m, 2 * m), np.arange(m)])
    srt = np.argsort(tail, kind="stable")
    inv = np.empty_like(srt)
    inv[srt] = np.arange(len(srt))
    indptr = np.searchsorted(tail[srt], np.arange(n + 1)).astype(np.int64)
    return (indptr, head[srt].astype(np.int64), np.concatenate([w, w])[srt].astype(np.float64),
            inv[rev[srt]].astype(np.int64))


@numba.njit(cache=True)
def _max_flow(indptr, head, cap, rev, s, t, limit, queue, parent):
    """Edmonds–Karp maximum flow from s to t (residual arcs of ``_residual_arcs``), stopped once
    it reaches ``limit``. Returns (flow, side); below the limit, ``side`` is the source side of a
    minimum cut: the nodes the last search reached in the residual graph (it ran to the end)."""
    r = cap.copy()
    flow = 0.0
    while flow < limit - 1e-6:
        parent[:] = -2
        parent[s] = -1
        qh, qt = 0, 1
        queue[0] = s
        while qh < qt and parent[t] == -2:
            a = queue[qh]
            qh += 1
            for e in range(indptr[a], indptr[a + 1]):
                b = head[e]
                if parent[b] == -2 and r[e] > 1e-9:
                    parent[b] = e
                    queue[qt] = b
                    qt += 1
        if parent[t] == -2:
            break
        # bottleneck along the path, then push
        f = limit - flow
        b = t
        while b != s:
            e = parent[b]
            f = min(f, r[e])
            b = head[rev[e]]
        b = t
        while b != s:
            e = parent[b]
            r[e] -= f
            r[rev[e]] += f
            b = head[rev[e]]
        flow += f
    return flow, parent != -2


@numba.njit(cache=True)
def _gomory_hu_sides(n, indptr, head, cap, rev, seconds):
    """Gusfield's Gomory–Hu cut tree: for s = 1 .. n-1 a minimum cut between s and its current
    tree neighbour t, whose s side re-hangs the later nodes of t that it holds. Returns the s side
    of each of these n - 1 cuts (fewer if ``seconds`` run out)."""
    tree = np.zeros(n, np.int64)
    sides = np.zeros((n - 1, n), np.bool_)
    queue = np.empty(n, np.int64)
    parent = np.empty(n, np.int64)
    with numba.objmode(t0="f8"):
        t0 = time.perf_counter()
    k = 0
    for s in range(1, n):
        if s % 16 == 0:
            with numba.objmode(now="f8"):
                now = time.perf_counter()
            if now - t0 > seconds:
                break
        t = tree[s]
        _, side = _max_flow(indptr, head, cap, rev, s, t, np.inf, queue, parent)
        sides[k] = side
        k += 1
        for i in range(s + 1, n):
            if side[i] and tree[i] == t:
                tree[i] = s
    return sides[:k]


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
def _match(n, deg, fixed_u, fixed_v, pref_u, pref_v, C):
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
