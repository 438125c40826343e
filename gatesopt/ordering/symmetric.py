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

The graph, the matching's odd sets and the compiled graph kernels are in ``symmetric_graph``; the
separation of subtour and blossom cuts in ``separation``; this module holds the LP model
(``SymmetricModel``: columns, rows, duals, pricing, root, branch-and-cut) and ``solve``.

Where the group's links cost otherwise one way than the other (the time objective's copied slicer
gaps), the symmetric model prices each edge the cheaper way round and relaxes the group: a tour
it finds priced above its LP value is cut off alone (``SymmetricModel.add_no_good``), and a gap
left by its root goes on in ``DirectedModel``, a column per direction and an "entered once" row
per curve, exact for such costs (formulations/ordering.md, "Direction-dependent costs").
"""
from __future__ import annotations

import heapq
import time

import highspy
import numba
import numpy as np

from .._native import run_lp
from . import rc_search, separation
from . import ils
from .problem import OPTIMAL_ABS_TOL, Group
from .separation import COLUMN_EPS, gomory_hu_sides, residual_arcs
from .symmetric_graph import (asymmetric, components, decode_edges, fixed_edges, graph_and_arcs,
                              joinable_costs, match_edges, matching_of, odd_sets)

_OPT = highspy.HighsModelStatus.kOptimal
_INFEASIBLE = highspy.HighsModelStatus.kInfeasible

#: travel edges per node in the first LP (nearest other-curve end points)
K_NEIGHBOURS = 8
#: no branching when reduced-cost fixing leaves more columns than this per node: the root gap
#: is then too wide to close within seconds (docs/BENCHMARKS.md, "Curve-ordering constants")
MAX_BRANCH_COLUMNS_PER_NODE = 40
#: ILS kicks per curve spent on the path built from the root LP point (it starts close to the
#: optimum; the warm start's search already spent its share)
POLISH_KICKS_PER_CURVE = 1
#: at most this many priced-in columns per pricing round, per node of the graph
PRICE_PER_NODE = 1
#: share of a group's time (from the root's start) in which the root may separate blossoms
#: exactly (``_blossoms_exact``) once the fast separators find nothing
EXACT_BLOSSOM_SHARE = 0.25
#: separation rounds per branch-and-cut node (then it is branched on its last LP point)
MAX_NODE_CUT_ROUNDS = 50
#: whether a group with direction-dependent costs left open by the symmetric root goes on in
#: ``DirectedModel`` (else: the symmetric branch-and-cut with no-good cuts). Free mode, 0.3 s
#: per group: prusa25_ymotor_grid30_zhop 1 -> 49 of 60 sampled groups proven (docs/RESULTS.md,
#: "Proofs on direction-dependent costs")
DIRECTED = True
#: whether such a group starts in ``DirectedModel`` (else the symmetric root first). At 0.3 s
#: per group: zaxis_lightning10 51 (on) vs 54 (off) of 57 proven, yrod_solid100 33 vs 38 of 49
DIRECTED_FIRST = False


class SymmetricModel:
    """Nodes 0 = S, 1 = E, then the end points of the curves; HiGHS rows 0..N-1 are the degree
    equations ``x(δ(v)) = deg_v`` (1 beside a fixed edge, 2 for a loop's seam), the rest cuts."""

    #: lp_bound: each missing edge's reduced cost is counted once per orientation in the matrix
    PAIRS_FACTOR = 0.5

    def __init__(self, group: Group, incumbent: np.ndarray, graph=None):
        self.group = group
        (self.pos, self.node_curve, self.deg, self.C, self.curve_nodes,
         self.first_cand, self.A) = graph_and_arcs(group) if graph is None else graph
        N = self.N = len(self.pos)
        self.C_join = joinable_costs(self.C, self.node_curve)      # the costs tours are built by
        self.fixed_u, self.fixed_v = fixed_edges(self.curve_nodes)
        # edges (u < v), the HiGHS columns over them (here one per edge; ``DirectedModel``: one
        # per direction), cuts (node mask "inside", row index cut_row0 + i, teeth as node pairs)
        self.eu = np.zeros(0, np.int64)
        self.ev = np.zeros(0, np.int64)
        self.col_edge = np.zeros(0, np.int64)
        self.col_tail = np.zeros(0, np.int64)
        self.col_head = np.zeros(0, np.int64)
        self.present = np.zeros((N, N), bool)
        self.cut_inside: list[np.ndarray] = []
        self.cut_teeth: list = []           # per cut: None, or (tooth edges (u, v), fixed mask)
        self.no_goods = 0                   # of them, cuts of one tour (``add_no_good``)
        h = self.h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("random_seed", 0)
        h.addRows(N, self.deg, self.deg, 0, np.zeros(N, np.int32), np.zeros(0, np.int32), np.zeros(0))
        self.cut_row0 = N
        self.extra_rows()
        # first columns: each node's nearest neighbours, every edge at E, the incumbent's edges
        k = min(K_NEIGHBOURS, N - 1)
        # a partial selection: the full row sort took ~1 ms of the model's ~1.6 ms build on a
        # 100-curve group (which k of equal distances enter matters not: pricing adds the rest)
        near = np.argpartition(self.C, k - 1, axis=1)[:, :k] if k > 0 else np.zeros((N, 0), np.int64)
        r = np.repeat(np.arange(N), k)
        c = near.ravel()
        inc = self.tour_edges(incumbent)
        r = np.concatenate([r, np.full(N, 1), inc[:, 0]])
        c = np.concatenate([c, np.arange(N), inc[:, 1]])
        self.add_columns(r, c)

    # -- columns and rows -------------------------------------------------------------------

    def extra_rows(self) -> None:
        """Rows between the degree equations and the cuts (``DirectedModel``: none here)."""

    def arcs_of(self, u, v, e0: int):
        """The columns of new edges (u, v), edge indices from e0: (tail, head, edge, cost)."""
        return u, v, np.arange(e0, e0 + len(u)), self.C[u, v]

    def extra_entries(self, head):
        """(rows, column positions) a new column has besides degree and cut rows."""
        return np.zeros(0, np.int64), np.zeros(0, np.int64)

    def add_columns(self, r, c) -> int:
        r, c = np.asarray(r, np.int64), np.asarray(c, np.int64)
        u, v = np.minimum(r, c), np.maximum(r, c)
        ok = np.isfinite(self.C[u, v]) & ~self.present[u, v]
        key = np.unique(u[ok] * self.N + v[ok])
        u, v = key // self.N, key % self.N
        if len(u) == 0:
            return 0
        self.present[u, v] = self.present[v, u] = True
        tail, head, edge, cost = self.arcs_of(u, v, len(self.eu))
        # entries: the two degree rows, and every cut row the edge crosses (coefficient 1: a new
        # column is never a blossom's tooth)
        K = len(tail)
        rows_all, cols_all = [tail, head], [np.arange(K), np.arange(K)]
        er, ec = self.extra_entries(head)
        rows_all.append(er)
        cols_all.append(ec)
        if self.cut_inside:
            ins = np.asarray(self.cut_inside)                   # (cuts, N)
            j, r = np.nonzero((ins[:, tail] != ins[:, head]).T)
            rows_all.append(self.cut_row0 + r)
            cols_all.append(j)
        rows_all, cols_all = np.concatenate(rows_all), np.concatenate(cols_all)
        o = np.argsort(cols_all, kind="stable")
        idx = rows_all[o].astype(np.int32)
        starts = np.searchsorted(cols_all[o], np.arange(K)).astype(np.int32)
        self.h.addCols(K, cost, np.zeros(K), np.ones(K), len(idx), starts, idx,
                       np.ones(len(idx)))
        self.eu = np.concatenate([self.eu, u])
        self.ev = np.concatenate([self.ev, v])
        self.col_edge = np.concatenate([self.col_edge, edge])
        self.col_tail = np.concatenate([self.col_tail, tail])
        self.col_head = np.concatenate([self.col_head, head])
        return len(u)

    def edge_x(self, x: np.ndarray) -> np.ndarray:
        return x                            # an LP point per edge (the sum of its columns)

    def edge_rc(self, rc: np.ndarray) -> np.ndarray:
        return rc                           # per edge: a missing edge may enter if below 0

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
        cross = ins[:, self.eu] != ins[:, self.ev]                          # (cuts, edges)
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
        cross, coef = cross[:, self.col_edge], coef[:, self.col_edge]     # per column
        r, c = np.nonzero(cross)
        starts = np.searchsorted(r, np.arange(K)).astype(np.int32)
        self.h.addRows(K, rhs, np.full(K, highspy.kHighsInf), len(c), starts,
                       c.astype(np.int32), coef[r, c])
        self.cut_inside.extend(ins)
        self.cut_teeth.extend(None if t is None else
                              (self.eu[t[0]], self.ev[t[0]], t[1]) for _, t in cuts)
        return K

    def add_no_good(self, on: np.ndarray) -> None:
        """The cut ``x(T) <= |T| - 1`` over the travel columns ``on`` of one tour T: every other
        tour keeps it, T alone breaks it. Where the group prices T above the model (an edge
        taken the dearer way round: ``travel_graph``), T is already an incumbent: the node's
        LP bound then rises past T instead of stopping at it (formulations/ordering.md, "milp,
        symmetric model", "direction-dependent costs"). Its row is registered with an empty
        node mask: it crosses no cut, so a column priced in later gets no entry in it (it is
        not in T) and the reduced costs of missing edges are untouched by its dual."""
        cols = np.flatnonzero(on).astype(np.int32)
        self.h.addRows(1, np.array([-highspy.kHighsInf]), np.array([len(cols) - 1.0]), len(cols),
                       np.zeros(1, np.int32), cols, np.ones(len(cols)))
        self.cut_inside.append(np.zeros(self.N, bool))
        self.cut_teeth.append(False)        # not passed on (``DirectedModel.take_cuts``)
        self.no_goods += 1

    def priced_above(self, x: np.ndarray, lp_obj: float):
        """(order, cost) of the path of an integral, connected LP point ``x`` if the group
        prices it above the LP's value (by more than ``OPTIMAL_ABS_TOL``), else None."""
        if np.any((x > COLUMN_EPS) & (x < 1 - COLUMN_EPS)):
            return None
        order = self.decode(x)
        if order is None or len(order) != self.group.n_curves:
            return None
        obj = self.group.path_cost(order)
        return (order, obj) if obj > lp_obj + OPTIMAL_ABS_TOL else None

    def seed_odd_sets(self) -> float:
        """Start the LP with the odd-set cuts ``x(δ(H)) >= 1`` of the cheapest perfect matching's
        dual (``odd_sets``): the blossoms the separators would otherwise find a few per round.
        Returns the matching's bound (0 if it failed)."""
        last = matching_of(self.group)
        if last is not None:
            bound, masks = last                     # auto took its path from the same matching
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
        """The LP point of a candidate order (its travel edges' columns at 1)."""
        e = self.tour_edges(order)
        if self.PAIRS_FACTOR == 0.5:            # one column per edge (u < v)
            e = np.sort(e, axis=1)
        index = {(a, b): j for j, (a, b) in enumerate(zip(self.col_tail.tolist(),
                                                          self.col_head.tolist()))}
        col = np.zeros(len(self.col_edge))
        for a, b in e.tolist():
            col[index[a, b]] = 1.0
        return col

    # -- separation ---------------------------------------------------------------------------

    def support_components(self, on: np.ndarray):
        """Connected components of the columns ``on`` plus the fixed edges (count, label per
        node)."""
        return components(self.N, np.concatenate([self.eu[on], self.fixed_u]),
                          np.concatenate([self.ev[on], self.fixed_v]))

    def separate(self, x: np.ndarray, deadline: float, integer: bool = False,
                 exact_blossoms_until: float = -np.inf) -> int:
        """Add violated cuts for the point ``x`` (``separation``); returns how many. Components of
        the support first; a connected support gets exact subtour separation by minimum cuts and
        the odd-component blossom heuristic; if these find nothing before
        ``exact_blossoms_until`` (a ``time.perf_counter()`` value), exact blossom separation."""
        x = self.edge_x(x)
        ncomp, lab = self.support_components(x > COLUMN_EPS)
        if ncomp > 1:
            return self.add_cuts([(lab == comp, None) for comp in range(ncomp)])
        if integer:
            return 0
        n = self._min_cuts(x, deadline)
        n += self._blossoms(x)
        if n == 0 and time.perf_counter() < exact_blossoms_until:
            n = self._blossoms_exact(x, min(deadline, exact_blossoms_until))
        return n

    def _min_cuts(self, x: np.ndarray, deadline: float) -> int:
        return self.add_cuts(separation.subtour_cuts(self, x, deadline))

    def _blossoms(self, x: np.ndarray) -> int:
        return self.add_cuts(separation.odd_component_blossoms(self, x))

    def _blossoms_exact(self, x: np.ndarray, deadline: float) -> int:
        return self.add_cuts(separation.exact_blossoms(self, x, deadline))

    # -- duals ------------------------------------------------------------------------------

    def reduced_costs(self) -> np.ndarray:
        """Reduced cost of every edge under the current LP duals (HiGHS: rc = c - A^T y); inf
        where no edge exists. Cut rows cross an edge iff exactly one of its ends is inside; a
        missing edge is never a tooth (teeth are columns at 1)."""
        y = np.asarray(self.h.getSolution().row_dual)
        yd, yc = y[:self.N], y[self.cut_row0:]
        rc = self.rc_of_rows(y) - yd[:, None] - yd[None, :]
        if len(yc):
            act = np.abs(yc) > 1e-12
            if act.any():
                _subtract_cut_duals(rc, np.asarray(self.cut_inside)[act], yc[act])
        return rc

    def rc_of_rows(self, y: np.ndarray) -> np.ndarray:
        return self.C                       # the costs less the duals of ``extra_rows``

    def lp_bound(self, obj: float, rc: np.ndarray) -> float:
        """Valid lower bound from the restricted LP: obj + sum of the negative reduced costs of
        missing edges (each x_e <= 1), halved for the symmetric duplicates."""
        miss = ~self.present & np.isfinite(rc)
        neg = np.minimum(rc[miss], 0.0)
        return float(obj + self.PAIRS_FACTOR * neg.sum())

    def price(self, rc: np.ndarray) -> int:
        rc = self.edge_rc(rc)
        miss = ~self.present & np.isfinite(rc)
        iu, iv = np.nonzero(np.triu(miss & (rc < -1e-7), 1))
        if len(iu) == 0:
            return 0
        keep = np.argsort(rc[iu, iv])[:max(PRICE_PER_NODE * self.N, 20)]
        return self.add_columns(iu[keep], iv[keep])

    # -- decoding -----------------------------------------------------------------------------

    def decode(self, x: np.ndarray) -> np.ndarray | None:
        """Candidate order from an integer point, or None if it has subtours."""
        on = self.edge_x(x) > 0.5
        ncomp, _ = self.support_components(on)
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
        x = self.edge_x(x)
        key = np.lexsort((self.C[self.eu, self.ev], -np.round(x, 6)))
        cols = key[x[key] > COLUMN_EPS]
        u, v = match_edges(self.N, self.deg.astype(np.int64), self.fixed_u, self.fixed_v,
                           self.eu[cols], self.ev[cols], self.C_join)
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
            if not run_lp(self.h, deadline) or self.h.getModelStatus() != _OPT:
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
        h = self.h
        rc = self.rc
        col_rc = np.asarray(h.getSolution().col_dual, float)
        n_old = len(col_rc)
        open_gap = best_obj - bound + 1e-6      # UB - LB: an edge costing more is in no better path
        erc = self.edge_rc(rc)
        iu, iv = np.nonzero(np.triu(~self.present & np.isfinite(erc) & (erc <= open_gap), 1))
        if len(self.eu) + len(iu) > MAX_BRANCH_COLUMNS_PER_NODE * self.N:
            return best, best_obj, bound, False
        self.add_columns(iu, iv)
        col_rc = np.concatenate([col_rc, rc[self.col_tail[n_old:], self.col_head[n_old:]]])
        root_bound = bound
        ncol = len(self.col_edge)
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
        unsettled = np.inf                      # least bound of integral nodes priced higher
        count = 1
        nodes = 0
        while heap:
            if time.perf_counter() > deadline or nodes >= max_nodes:
                break
            node_bound, _, fixings = heapq.heappop(heap)
            if node_bound >= best_obj - OPTIMAL_ABS_TOL:
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
                if not run_lp(h, deadline):
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
                if lp_obj >= best_obj - OPTIMAL_ABS_TOL:
                    outcome = "pruned"
                    break
                if self.separate(x, deadline):
                    continue
                tour = self.priced_above(x, lp_obj)
                if tour is None:
                    break
                # an integral path the group prices above the model (a travel edge taken the
                # dearer way round): it is the incumbent if cheaper, and a cut excludes it alone
                # from the node, whose other paths may cost less (``add_no_good``)
                order, obj = tour
                if obj < best_obj - 1e-9:
                    best, best_obj = order, obj
                    fix_by_reduced_cost()
                self.add_no_good(x > 0.5)
            # (cut rounds used up: the last LP point and its value, a valid bound, are branched on)
            if outcome == "stopped":            # only an LP that proves something discards a node
                heapq.heappush(heap, (node_bound, count, fixings))
                break
            if outcome == "pruned":
                continue
            frac = np.nonzero((x > COLUMN_EPS) & (x < 1 - COLUMN_EPS))[0]
            if len(frac) == 0:                  # integral, connected (separation found nothing)
                order = self.decode(x)
                if order is not None:
                    obj = self.group.path_cost(order)
                    if obj < best_obj - 1e-9:
                        best, best_obj = order, obj
                        fix_by_reduced_cost()
                    if obj > lp_obj + OPTIMAL_ABS_TOL:
                        # the path costs more than the model's edges say (an edge priced the
                        # cheaper way round: ``travel_graph``): another path of this node may
                        # cost less than it, so the node's bound stays in the final bound
                        unsettled = min(unsettled, lp_obj)
                continue
            order = self.tour_from(x)
            if order is not None and len(order) == self.group.n_curves:
                obj = self.group.path_cost(order)
                if obj < best_obj - 1e-9:
                    best, best_obj = order, obj
                    fix_by_reduced_cost()
            # branch on the edge closest to 1/2, the longer one on ties
            e = frac[np.lexsort((-self.C[self.col_tail[frac], self.col_head[frac]],
                                 np.abs(x[frac] - 0.5)))[0]]
            for val in (1.0, 0.0):
                heapq.heappush(heap, (lp_obj, count, fixings + ((int(e), val),)))
                count += 1
        open_bound = min((b for b, _, _ in heap), default=best_obj)
        bound = max(bound, min(open_bound, unsettled, best_obj))
        proven = best_obj - bound <= OPTIMAL_ABS_TOL
        return best, best_obj, bound, proven

    def _polish(self, order, best, best_obj, bound, deadline):
        """ILS from ``order``, stopped once it reaches ``bound`` (then proven optimal); the
        better of it and ``best``."""
        if order is None or len(order) != self.group.n_curves:
            return best, best_obj
        order = ils.improve_ils(self.group, order,
                                kicks=POLISH_KICKS_PER_CURVE * self.group.n_curves,
                                deadline=deadline, target=bound + OPTIMAL_ABS_TOL)
        obj = self.group.path_cost(order)
        return (order, obj) if obj < best_obj - 1e-9 else (best, best_obj)


class DirectedModel(SymmetricModel):
    """The symmetric model's graph with a column per direction of each travel edge, priced by
    the group's own link costs (``symmetric_graph.arc_costs``): exact where the time objective's
    links cost otherwise one way than the other (formulations/ordering.md, "milp, symmetric
    model", "direction-dependent costs"). Besides the degree equations, one row per curve: it is
    entered once, ``z(δ^in(nodes of c)) = 1`` (an open curve at either end point, a loop at its
    seam; nothing enters S, E is entered by its degree). On a tour S -> ... -> E these make every
    travel edge's direction the path's: S's edge leaves S, so the curve it enters is entered
    there and must leave by its other edge, and so on. Cuts (subtours, blossoms) hold for the
    edges' sums ``x_e = z_uv + z_vu`` and are separated on them (``edge_x``); both columns of an
    edge get its coefficient. A relaxation of nothing: its bound is a bound of the group's true
    costs, its integral points are paths priced as the group prices them."""

    PAIRS_FACTOR = 1.0

    def extra_rows(self) -> None:
        n = self.group.n_curves
        self.h.addRows(n, np.ones(n), np.ones(n), 0, np.zeros(n, np.int32),
                       np.zeros(0, np.int32), np.zeros(0))
        self.cut_row0 = self.N + n

    def arcs_of(self, u, v, e0: int):
        edge = np.arange(e0, e0 + len(u))
        fwd, bwd = np.isfinite(self.A[u, v]), np.isfinite(self.A[v, u])
        tail = np.concatenate([u[fwd], v[bwd]])
        head = np.concatenate([v[fwd], u[bwd]])
        return tail, head, np.concatenate([edge[fwd], edge[bwd]]), self.A[tail, head]

    def extra_entries(self, head):
        j = np.flatnonzero(head >= 2)
        return self.N + self.node_curve[head[j]], j

    def edge_x(self, x: np.ndarray) -> np.ndarray:
        return np.bincount(self.col_edge, weights=x, minlength=len(self.eu))

    def edge_rc(self, rc: np.ndarray) -> np.ndarray:
        return np.minimum(rc, rc.T)

    def rc_of_rows(self, y: np.ndarray) -> np.ndarray:
        y_in = np.zeros(self.N)
        y_in[2:] = y[self.N:self.cut_row0][self.node_curve[2:]]
        return self.A - y_in[None, :]

    def take_cuts(self, model: SymmetricModel) -> None:
        """The edges and the cuts of a symmetric model of the same group (its no-good cuts
        excepted: a tour priced above the symmetric model may be the optimum here)."""
        self.add_columns(model.eu, model.ev)
        index = {(a, b): j for j, (a, b) in enumerate(zip(self.eu.tolist(), self.ev.tolist()))}
        cuts = []
        for inside, teeth in zip(model.cut_inside, model.cut_teeth):
            if teeth is False:
                continue
            if teeth is not None:
                tu, tv, tf = teeth
                teeth = (np.array([index[a, b] for a, b in zip(tu.tolist(), tv.tolist())],
                                  np.int64), tf)
            cuts.append((inside, teeth))
        self.add_cuts(cuts)


def solve(group: Group, incumbent: np.ndarray, deadline: float):
    """Root LP (cuts and pricing); a path built from the LP point and polished by ILS may improve
    the incumbent; then branch-and-cut if a gap is left. Returns (order, objective, bound,
    proven optimal)."""
    best = np.asarray(incumbent, np.int64)
    best_obj = group.path_cost(best)
    graph = graph_and_arcs(group)
    directed = DIRECTED and asymmetric(graph[6])
    model = (DirectedModel if directed and DIRECTED_FIRST else SymmetricModel)(group, best, graph)
    bound = model.seed_odd_sets()
    if best_obj - bound <= OPTIMAL_ABS_TOL:
        return best, best_obj, bound, True
    bound = max(bound, model.root(
        deadline, exact_blossoms_s=EXACT_BLOSSOM_SHARE * (deadline - time.perf_counter())))
    if best_obj - bound > OPTIMAL_ABS_TOL and model.complete:
        x = np.asarray(model.h.getSolution().col_value)
        best, best_obj = model._polish(model.tour_from(x), best, best_obj, bound, deadline)
    if best_obj - bound <= OPTIMAL_ABS_TOL:
        return best, best_obj, bound, True
    if not model.complete:
        return best, best_obj, bound, False
    best, best_obj, proof = rc_search.after_root(model, best, best_obj, bound, deadline)
    if proof is not None:       # (a group the search proved needs no branching)
        return proof
    if directed and not isinstance(model, DirectedModel):
        return _directed(model, best, best_obj, bound, deadline)
    return model.branch(best, best_obj, bound, deadline)


def _directed(sym: SymmetricModel, best, best_obj: float, bound: float, deadline: float):
    """The symmetric root left a gap on a group whose links cost otherwise one way than the
    other: the same root again in ``DirectedModel`` (the symmetric model's edges and cuts to
    start from), then its branch-and-cut. Returns as ``solve``."""
    graph = (sym.pos, sym.node_curve, sym.deg, sym.C, sym.curve_nodes, sym.first_cand, sym.A)
    model = DirectedModel(sym.group, best, graph=graph)
    model.take_cuts(sym)
    bound = max(bound, model.root(
        deadline, exact_blossoms_s=EXACT_BLOSSOM_SHARE * (deadline - time.perf_counter())))
    if best_obj - bound > OPTIMAL_ABS_TOL and model.complete:
        x = np.asarray(model.h.getSolution().col_value)
        best, best_obj = model._polish(model.tour_from(x), best, best_obj, bound, deadline)
    if best_obj - bound <= OPTIMAL_ABS_TOL:
        return best, best_obj, bound, True
    if not model.complete:
        return best, best_obj, bound, False
    best, best_obj, proof = rc_search.after_root(model, best, best_obj, bound, deadline)
    if proof is not None:       # (a group the search proved needs no branching)
        return proof
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
    the reduced costs, of the matching and of the reduced-cost search on made-up graphs, so that
    the first group that needs them does not pay for it."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 0.0]])
    odd_sets(np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1)) + np.diag(np.full(4, np.inf)),
             np.ones(4), True)
    arcs = residual_arcs(3, np.array([0, 1, 2]), np.array([1, 2, 0]), np.full(3, 0.5))
    gomory_hu_sides(3, *arcs, 1.0)
    _subtract_cut_duals(np.zeros((3, 3)), np.array([[True, False, False]]), np.ones(1))
    rc_search.load_kernel()
