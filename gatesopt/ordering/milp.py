"""Exact curve ordering as a MILP solved by HiGHS (formulations/ordering.md, "milp").

Assignment-style model over {depot} + candidates with in/out degree equal to the visit variable
``y[k]`` and exactly one visited candidate per curve. Subtours are cut in a
solve–separate–re-solve loop (HiGHS has no lazy-constraint callback): every cycle that misses the
depot, over curves K, gets the cut "the path leaves S", S = every candidate of the curves in K.
Each MILP of the loop is a relaxation of the ordering problem, so its dual bound is a valid lower
bound even when the loop stops at the time limit. The warm start (the hint, or ``ils.warm_start``)
is passed to HiGHS as the incumbent of every solve; it satisfies every cut.
"""
from __future__ import annotations

import time

import highspy
import numpy as np

from .._native import native_stdout_to_stderr

from .bounds import lower_bound_mm
from .ils import warm_start
from .problem import OPTIMAL_ABS_TOL_MM, Group, GroupSolution

_OPT = highspy.HighsModelStatus.kOptimal
STATUS = {
    highspy.HighsModelStatus.kOptimal: "optimal",
    highspy.HighsModelStatus.kTimeLimit: "feasible",
    highspy.HighsModelStatus.kInfeasible: "infeasible",
}


class _Model:
    """Column layout: first[k] (m) | last[k] (m) | x[u,v] (A) | y[k] (m)."""

    def __init__(self, group: Group):
        m, n = group.n_cands, group.n_curves
        arc = group.arc_cost_mm()
        self.us, self.vs = np.nonzero(np.isfinite(arc))
        A = len(self.us)
        self.m, self.n, self.A = m, n, A
        self.o_first, self.o_last, self.o_x, self.o_y = 0, m, 2 * m, 2 * m + A
        ncol = 3 * m + A
        cost = np.concatenate([group.start_cost_mm(), group.end_cost_mm(), arc[self.us, self.vs], np.zeros(m)])
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("mip_rel_gap", 1e-9)
        h.setOptionValue("mip_abs_gap", 1e-5)
        h.setOptionValue("random_seed", 0)
        h.addCols(ncol, cost, np.zeros(ncol), np.ones(ncol), 0, np.zeros(0, np.int32),
                  np.zeros(0, np.int32), np.zeros(0))
        ints = np.arange(2 * m + A, dtype=np.int32)
        h.changeColsIntegrality(len(ints), ints, np.full(len(ints), 1, np.uint8))  # kInteger
        rows = []   # (lower, upper, cols, vals)
        k = np.arange(m)
        # in-degree of candidate k equals y[k]; out-degree equals y[k] (built grouped by k)
        for ends, o_end in ((self.vs, self.o_first), (self.us, self.o_last)):
            srt = np.argsort(ends, kind="stable")
            bounds_ = np.searchsorted(ends[srt], np.arange(m + 1))
            for kk in range(m):
                arcs_k = srt[bounds_[kk]:bounds_[kk + 1]]
                rows.append((0.0, 0.0, np.concatenate([[o_end + kk], self.o_x + arcs_k, [self.o_y + kk]]),
                             np.concatenate([[1.0], np.ones(len(arcs_k)), [-1.0]])))
        # the depot: one first and one last candidate
        rows.append((1.0, 1.0, self.o_first + k, np.ones(m)))
        rows.append((1.0, 1.0, self.o_last + k, np.ones(m)))
        # one visited candidate per curve
        for c in range(n):
            ks = np.nonzero(group.cand_curve == c)[0]
            rows.append((1.0, 1.0, self.o_y + ks, np.ones(len(ks))))
        self.h = h
        self.add_rows(rows)
        self.group = group

    def add_rows(self, rows):
        lo = np.array([r[0] for r in rows], float)
        hi = np.array([r[1] for r in rows], float)
        starts = np.cumsum([0] + [len(r[2]) for r in rows[:-1]]).astype(np.int32)
        idx = np.concatenate([np.asarray(r[2]) for r in rows]).astype(np.int32)
        val = np.concatenate([np.asarray(r[3], float) for r in rows])
        self.h.addRows(len(rows), lo, hi, len(idx), starts, idx, val)

    def columns_of(self, order: np.ndarray) -> np.ndarray:
        col = np.zeros(3 * self.m + self.A)
        col[self.o_first + order[0]] = 1
        col[self.o_last + order[-1]] = 1
        col[self.o_y + order] = 1
        pos = {(int(u), int(v)): i for i, (u, v) in enumerate(zip(self.us, self.vs))}
        for u, v in zip(order[:-1], order[1:]):
            col[self.o_x + pos[int(u), int(v)]] = 1
        return col

    def decode(self, col: np.ndarray):
        """(path from the depot, list of cycles that miss the depot), as candidate lists."""
        m = self.m
        xs = np.nonzero(col[self.o_x:self.o_x + self.A] > 0.5)[0]
        succ = dict(zip(self.us[xs].tolist(), self.vs[xs].tolist()))
        firsts = np.nonzero(col[self.o_first:self.o_first + m] > 0.5)[0]
        path, seen = [], set()
        cur = int(firsts[0]) if len(firsts) else None
        while cur is not None and cur not in seen:
            path.append(cur)
            seen.add(cur)
            cur = succ.get(cur)
        cycles = []
        for s in list(succ):
            if s in seen:
                continue
            cyc, cur = [], s
            while cur is not None and cur not in seen:
                cyc.append(cur)
                seen.add(cur)
                cur = succ.get(cur)
            if cyc:
                cycles.append(cyc)
        return np.asarray(path, np.int64), cycles

    @property
    def n_int(self) -> int:
        return 2 * self.m + self.A

    def lp_cuts(self, col: np.ndarray) -> list:
        m = self.m
        on = col[self.o_x:self.o_x + self.A] > 1e-6
        fi = np.nonzero(col[self.o_first:self.o_first + m] > 1e-6)[0]
        la = np.nonzero(col[self.o_last:self.o_last + m] > 1e-6)[0]
        r = np.concatenate([self.us[on], fi, la])
        c = np.concatenate([self.vs[on], np.full(len(fi), m), np.full(len(la), m)])
        ncomp, lab = _components(m + 1, r, c)
        used = col[self.o_y:self.o_y + m] > 1e-6
        cuts = []
        for comp in range(ncomp):
            if comp == lab[m]:
                continue
            nodes = np.nonzero((lab[:m] == comp) & used)[0]
            if len(nodes):
                cuts.append(self.cut(nodes))
        return cuts

    def cut(self, cycle) -> tuple:
        """x(δ+(S)) + last(S) >= 1, S = all candidates of the cycle's curves."""
        g = self.group
        curves = np.unique(g.cand_curve[cycle])
        in_s = np.isin(g.cand_curve, curves)
        leave = np.nonzero(in_s[self.us] & ~in_s[self.vs])[0]
        s_idx = np.nonzero(in_s)[0]
        cols = np.concatenate([self.o_x + leave, self.o_last + s_idx])
        return (1.0, highspy.kHighsInf, cols, np.ones(len(cols)))


class _SymModel:
    """Undirected model when every curve is an open curve with its two directions or a loop with
    one seam (formulations/ordering.md, "milp, symmetric"): nodes S, E, each open curve's two end
    points (joined by the curve itself, a fixed edge) and each loop's seam. The path S -> ... -> E
    plus the fixed edge E-S is a tour: a symmetric TSP with fixed edges, whose LP relaxation with
    subtour cuts (Held–Karp) is far tighter than the directed model's, where a curve may be half
    forwards and half backwards."""

    def __init__(self, group: Group):
        self.group = group
        n = group.n_curves
        cc = group.cand_curve
        counts = np.bincount(cc, minlength=n)
        first_cand = np.full(n, -1)
        for k in range(group.n_cands - 1, -1, -1):
            first_cand[cc[k]] = k
        pos = [group.start_xy, group.end_xy if group.end_xy is not None else np.zeros(2)]
        node_curve = [-1, -2]
        self.curve_nodes = []
        for c in range(n):
            k = first_cand[c]
            if counts[c] == 1:                                  # loop: one node, degree 2
                self.curve_nodes.append((len(pos),))
                pos.append(group.cand_entry_xy[k]); node_curve.append(c)
            else:                                               # open: entry of k, exit of k
                self.curve_nodes.append((len(pos), len(pos) + 1))
                pos += [group.cand_entry_xy[k], group.cand_exit_xy[k]]; node_curve += [c, c]
        self.pos = np.asarray(pos, float)
        self.node_curve = np.asarray(node_curve)
        self.first_cand = first_cand
        N = len(pos)
        self.N = N
        iu, ju = np.triu_indices(N, 1)
        keep = (self.node_curve[iu] != self.node_curve[ju]) & ~((iu == 0) & (ju == 1))
        self.eu, self.ev = iu[keep], ju[keep]
        cost = np.hypot(*(self.pos[self.eu] - self.pos[self.ev]).T)
        if group.end_xy is None:
            cost[(self.eu == 1) | (self.ev == 1)] = 0.0         # the path just ends
        self.A = len(cost)
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("mip_rel_gap", 1e-9)
        h.setOptionValue("mip_abs_gap", 1e-5)
        h.setOptionValue("random_seed", 0)
        h.addCols(self.A, cost, np.zeros(self.A), np.ones(self.A), 0, np.zeros(0, np.int32),
                  np.zeros(0, np.int32), np.zeros(0))
        ints = np.arange(self.A, dtype=np.int32)
        h.changeColsIntegrality(self.A, ints, np.ones(self.A, np.uint8))
        self.h = h
        deg = np.ones(N)
        for nodes in self.curve_nodes:
            if len(nodes) == 1:
                deg[nodes[0]] = 2.0
        ends = np.concatenate([self.eu, self.ev])
        edge = np.concatenate([np.arange(self.A), np.arange(self.A)])
        srt = np.argsort(ends, kind="stable")
        b = np.searchsorted(ends[srt], np.arange(N + 1))
        rows = [(deg[v], deg[v], edge[srt[b[v]:b[v + 1]]], np.ones(b[v + 1] - b[v])) for v in range(N)]
        self.add_rows(rows)
        self.fixed_r = [nodes[0] for nodes in self.curve_nodes if len(nodes) == 2] + [0]
        self.fixed_c = [nodes[1] for nodes in self.curve_nodes if len(nodes) == 2] + [1]

    add_rows = _Model.add_rows

    @property
    def n_int(self) -> int:
        return self.A

    def _edge_index(self):
        if not hasattr(self, "_eidx"):
            self._eidx = {(int(u), int(v)): i for i, (u, v) in enumerate(zip(self.eu, self.ev))}
        return self._eidx

    def columns_of(self, order: np.ndarray) -> np.ndarray:
        g = self.group
        col = np.zeros(self.A)
        eidx = self._edge_index()
        prev = 0
        for k in order:
            c = int(g.cand_curve[k])
            nodes = self.curve_nodes[c]
            if len(nodes) == 1:
                a = b = nodes[0]
            else:
                fwd = k == self.first_cand[c]
                a, b = (nodes[0], nodes[1]) if fwd else (nodes[1], nodes[0])
            col[eidx[min(prev, a), max(prev, a)]] = 1
            prev = b
        col[eidx[min(prev, 1), max(prev, 1)]] = 1
        return col

    def _cuts_from(self, on: np.ndarray) -> list:
        r = np.concatenate([self.eu[on], self.fixed_r])
        c = np.concatenate([self.ev[on], self.fixed_c])
        ncomp, lab = _components(self.N, r, c)
        if ncomp == 1:
            return []
        cuts = []
        for comp in range(ncomp):
            inside = lab == comp
            cross = np.nonzero(inside[self.eu] != inside[self.ev])[0]
            cuts.append((2.0, highspy.kHighsInf, cross, np.ones(len(cross))))
        return cuts

    def lp_cuts(self, col: np.ndarray) -> list:
        cuts = self._cuts_from(col > 1e-6)
        return cuts if cuts else self._min_cuts(col)

    def _min_cuts(self, col: np.ndarray, max_cuts: int = 40) -> list:
        """Exact separation for a fractional point with connected support: a minimum S-v cut
        (max flow, capacities x scaled to integers; fixed edges count 1) below 2 is a violated
        subtour cut x(δ(U)) >= 2 - fixed(δ(U))."""
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import maximum_flow
        scale = 10 ** 6
        on = col > 1e-9
        r = np.concatenate([self.eu[on], self.ev[on], self.fixed_r, self.fixed_c])
        c = np.concatenate([self.ev[on], self.eu[on], self.fixed_c, self.fixed_r])
        w = np.concatenate([col[on], col[on], np.ones(2 * len(self.fixed_r))])
        cap = csr_matrix((np.rint(w * scale).astype(np.int32), (r, c)), shape=(self.N, self.N))
        cap.sum_duplicates()
        fixed_u = np.asarray(self.fixed_r)
        fixed_v = np.asarray(self.fixed_c)
        cuts, seen = [], set()
        deadline = getattr(self, "deadline", np.inf)
        for t in range(2, self.N):
            if time.perf_counter() > deadline:
                break
            res = maximum_flow(cap, 0, t)
            if res.flow_value >= 2 * scale - 1000:
                continue
            # the sink side: nodes that cannot be reached from S in the residual graph
            flow = res.flow.tocsr() if hasattr(res, "flow") else res.residual
            resid = cap - flow
            resid.data[resid.data < 1] = 0
            resid.eliminate_zeros()
            from scipy.sparse.csgraph import breadth_first_order
            reach = np.zeros(self.N, bool)
            reach[breadth_first_order(resid, 0, directed=True, return_predecessors=False)] = True
            key = reach.tobytes()
            if key in seen:
                continue
            seen.add(key)
            cross = np.nonzero(reach[self.eu] != reach[self.ev])[0]
            n_fixed = int((reach[fixed_u] != reach[fixed_v]).sum())
            cuts.append((2.0 - n_fixed, highspy.kHighsInf, cross, np.ones(len(cross))))
            if len(cuts) >= max_cuts:
                break
        return cuts

    def decode(self, col: np.ndarray):
        """(candidate path from S, [] or [subtour marker]) from an integer solution."""
        on = col > 0.5
        cuts = self._cuts_from(on)
        if cuts:
            return np.zeros(0, np.int64), cuts
        adj = {}
        for u, v in zip(self.eu[on].tolist(), self.ev[on].tolist()):
            adj.setdefault(u, []).append(v)
            adj.setdefault(v, []).append(u)
        g = self.group
        order, came, cur = [], 0, adj[0][0]
        while cur != 1 and len(order) <= g.n_curves:
            c = int(self.node_curve[cur])
            nodes = self.curve_nodes[c]
            k0 = int(self.first_cand[c])
            if len(nodes) == 1:                     # loop: leave by its other travel edge
                k, out = k0, cur
                nxt = [v for v in adj[cur] if v != came][0]
            else:                                   # open: traverse to the other end point
                k = k0 if cur == nodes[0] else int(g.cand_flip[k0])
                out = nodes[1] if cur == nodes[0] else nodes[0]
                nxt = adj[out][0]
            order.append(k)
            came, cur = out, nxt
        return np.asarray(order, np.int64), []

    def cut(self, row) -> tuple:
        return row


def symmetric_ok(group: Group) -> bool:
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


def _lp_rounds(model, t0: float, time_limit_s: float, max_rounds: int = 60) -> float:
    """Cutting planes on the LP relaxation first (cheap): cut every connected component of the
    fractional solution's support that misses the depot. Returns the last LP bound (valid)."""
    h = model.h
    model.deadline = t0 + time_limit_s
    n_int = model.n_int
    idx = np.arange(n_int, dtype=np.int32)
    h.changeColsIntegrality(n_int, idx, np.zeros(n_int, np.uint8))       # continuous
    bound = 0.0
    for _ in range(max_rounds):
        left = time_limit_s - (time.perf_counter() - t0)
        if left <= 0:
            break
        h.setOptionValue("time_limit", float(left))
        with native_stdout_to_stderr():     # HiGHS may printf; stdout can carry G-code
            h.run()
        if h.getModelStatus() != _OPT:
            break
        bound = max(bound, float(h.getInfo().objective_function_value))
        cuts = model.lp_cuts(np.asarray(h.getSolution().col_value))
        if not cuts:
            break
        model.add_rows(cuts)
    h.changeColsIntegrality(n_int, idx, np.ones(n_int, np.uint8))        # back to integer
    return bound


def _components(n_nodes, r, c):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    g = coo_matrix((np.ones(len(r)), (r, c)), shape=(n_nodes, n_nodes))
    return connected_components(g, directed=False)


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          give_up_gap: float | None = None) -> GroupSolution:
    """``give_up_gap``: stop after the LP rounds if their bound leaves a larger relative gap (the
    branch-and-cut loop rarely closes such gaps within seconds; ``auto`` uses 0.15)."""
    t0 = time.perf_counter()
    from .cpsat import _trivial
    triv = _trivial(group, t0)
    if triv is not None:
        return GroupSolution.make(triv.order, triv.objective_mm, triv.bound_mm, triv.status,
                                  triv.solve_s, "milp")
    hint = warm_start(group, hint, t0, time_limit_s)
    best = np.asarray(getattr(hint, "order", hint), np.int64)
    best_obj = group.path_cost_mm(best)
    bound = lower_bound_mm(group)
    model = _SymModel(group) if symmetric_ok(group) else _Model(group)
    h = model.h
    status = "fallback"
    bound = max(bound, _lp_rounds(model, t0, time_limit_s))
    if best_obj - bound <= OPTIMAL_ABS_TOL_MM:       # the LP bound alone proves the warm start
        return GroupSolution.make(best, best_obj, bound, "optimal", time.perf_counter() - t0, "milp")
    if give_up_gap is not None and best_obj > 0 and (best_obj - bound) / best_obj > give_up_gap:
        return GroupSolution.make(best, best_obj, bound, "feasible", time.perf_counter() - t0, "milp")
    while True:
        left = time_limit_s - (time.perf_counter() - t0)
        if left <= 0:
            break
        h.setOptionValue("time_limit", float(left))
        sol = highspy.HighsSolution()
        sol.col_value = model.columns_of(best).tolist()
        sol.value_valid = True
        h.setSolution(sol)
        with native_stdout_to_stderr():     # HiGHS may printf; stdout can carry G-code
            h.run()
        ms = h.getModelStatus()
        info = h.getInfo()
        if np.isfinite(info.mip_dual_bound):
            bound = max(bound, float(info.mip_dual_bound))
        if info.primal_solution_status == 0:     # no solution at all
            break
        col = np.asarray(h.getSolution().col_value)
        path, cycles = model.decode(col)
        if not cycles and len(path) == group.n_curves:
            obj = group.path_cost_mm(path)
            if obj < best_obj:
                best, best_obj = path, obj
            if ms == _OPT:
                status = "optimal"
                break
            status = "feasible"
            break
        if ms != _OPT:
            status = "feasible"
            break
        model.add_rows([model.cut(c) for c in cycles])
    group.check_order(best)
    if best_obj - bound <= OPTIMAL_ABS_TOL_MM:
        status = "optimal"
    return GroupSolution.make(best, best_obj, bound, status, time.perf_counter() - t0, "milp")
