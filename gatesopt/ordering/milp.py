"""Exact curve ordering as a MILP solved by HiGHS (formulations/ordering.md, "milp").

Assignment-style model over {depot} + candidates with in/out degree equal to the visit variable
``y[k]`` and exactly one visited candidate per curve. Subtours are cut in a
solve–separate–re-solve loop (HiGHS has no lazy-constraint callback): every cycle that misses the
depot, over curves K, gets the cut "the path leaves S", S = every candidate of the curves in K.
Each MILP of the loop is a relaxation of the ordering problem, so its dual bound is a valid lower
bound even when the loop stops at the time limit. The warm start (the hint, or ``ils.warm_start``)
is passed to HiGHS as the incumbent of every solve; it satisfies every cut.

Groups of open curves and fixed-seam loops (``symmetric_graph.applies``) go to the undirected
model of ``symmetric.py`` instead (formulations/ordering.md, "milp, symmetric model"); this
directed model serves the rest (several seam candidates per loop).
"""
from __future__ import annotations

import time

import highspy
import numpy as np

from .. import _jit
from .._native import run_highs
from ..solvers import Status
from . import symmetric, symmetric_graph
from .bounds import lower_bound
from .ils import warm_start
from .problem import OPTIMAL_ABS_TOL, Group, GroupSolution, trivial_solution

_OPT = highspy.HighsModelStatus.kOptimal

#: largest group (candidates) the directed model takes on after the symmetric model stopped
#: without a proof. Small groups close at once (square_grid's 20-candidate groups: 1 -> 9 of 9
#: proven); on real_kirimoto30's groups of up to 288 candidates the directed loop ran past the
#: group's time limit (12.2 s of HiGHS for 3 groups with 2 s each, cProfile of `gatesopt order
#: --budget 8`): HiGHS overshoots its time limit there, so large groups keep the symmetric answer.
DIRECTED_AFTER_SYMMETRIC_MAX_CANDS = 60


class _Model:
    """Column layout: first[k] (m) | last[k] (m) | x[u,v] (A) | y[k] (m)."""

    def __init__(self, group: Group):
        m, n = group.n_cands, group.n_curves
        arc = group.arc_cost()
        self.us, self.vs = np.nonzero(np.isfinite(arc))
        A = len(self.us)
        self.m, self.n, self.A = m, n, A
        self.o_first, self.o_last, self.o_x, self.o_y = 0, m, 2 * m, 2 * m + A
        ncol = 3 * m + A
        cost = np.concatenate([group.start_cost(), group.end_cost(), arc[self.us, self.vs], np.zeros(m)])
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
        ncomp, lab = symmetric_graph.components(m + 1, r, c)
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


def _lp_rounds(model, deadline: float, max_rounds: int = 60) -> float:
    """Cutting planes on the LP relaxation first (cheap): cut every connected component of the
    fractional solution's support that misses the depot. Returns the last LP bound (valid)."""
    h = model.h
    model.deadline = deadline
    n_int = model.n_int
    idx = np.arange(n_int, dtype=np.int32)
    h.changeColsIntegrality(n_int, idx, np.zeros(n_int, np.uint8))       # continuous
    bound = 0.0
    for _ in range(max_rounds):
        if not run_highs(h, deadline):
            break
        if h.getModelStatus() != _OPT:
            break
        bound = max(bound, float(h.getInfo().objective_function_value))
        cuts = model.lp_cuts(np.asarray(h.getSolution().col_value))
        if not cuts:
            break
        model.add_rows(cuts)
    h.changeColsIntegrality(n_int, idx, np.ones(n_int, np.uint8))        # back to integer
    return bound


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None,
          give_up_gap: float | None = None, known_bound: float | None = None) -> GroupSolution:
    """``give_up_gap``: stop after the LP rounds if their bound leaves a larger relative gap (the
    branch-and-cut loop rarely closes such gaps within seconds; ``auto`` uses 0.15).
    ``known_bound``: a lower bound already proven for this group (else the cheap bound of
    ``bounds.py`` is computed)."""
    t0 = time.perf_counter()
    triv = trivial_solution(group, t0, "milp")
    if triv is not None:
        return triv
    hint = warm_start(group, hint, t0, time_limit_s)
    # the limit runs from the call, numba's first compile of a kernel on the way not counted (a
    # fresh install's first solve under load otherwise spends it compiling, and answers unproven)
    deadline = t0 + time_limit_s + _jit.compile_s_since(t0)
    best = np.asarray(getattr(hint, "order", hint), np.int64)
    best_obj = group.path_cost(best)
    # auto passes the bound it has (the cheap one or the matching's: ~0.7 ms to recompute the
    # cheap one on a 100-curve group)
    bound = lower_bound(group) if known_bound is None else float(known_bound)
    if symmetric_graph.applies(group):
        order, obj, lp_bound, proven = symmetric.solve(group, best, deadline)
        group.check_order(order)
        bound = max(bound, lp_bound)
        if (proven or obj - bound <= OPTIMAL_ABS_TOL or time.perf_counter() >= deadline
                or group.n_cands > DIRECTED_AFTER_SYMMETRIC_MAX_CANDS):
            status = Status.OPTIMAL if proven or obj - bound <= OPTIMAL_ABS_TOL else Status.FEASIBLE
            return GroupSolution.make(order, obj, bound, status, time.perf_counter() - t0, "milp")
        # Not proven: on the time objective the copied slicer gaps make the costs asymmetric and
        # the undirected model prices each edge the cheaper way round, a relaxation whose bound
        # can stay below the best path. The directed model below is exact for asymmetric costs:
        # it gets the time left, the relaxation's path as its incumbent and its bound.
        best, best_obj = np.asarray(order, np.int64), float(obj)
    model = _Model(group)
    h = model.h
    status = Status.FALLBACK
    bound = max(bound, _lp_rounds(model, deadline))
    if best_obj - bound <= OPTIMAL_ABS_TOL:       # the LP bound alone proves the warm start
        return GroupSolution.make(best, best_obj, bound, Status.OPTIMAL, time.perf_counter() - t0, "milp")
    if give_up_gap is not None and best_obj > 0 and (best_obj - bound) / best_obj > give_up_gap:
        return GroupSolution.make(best, best_obj, bound, Status.FEASIBLE, time.perf_counter() - t0, "milp")
    while True:
        if not run_highs(h, deadline, start=model.columns_of(best)):
            break
        ms = h.getModelStatus()
        info = h.getInfo()
        if np.isfinite(info.mip_dual_bound):
            bound = max(bound, float(info.mip_dual_bound))
        if info.primal_solution_status == 0:     # no solution at all
            break
        col = np.asarray(h.getSolution().col_value)
        path, cycles = model.decode(col)
        if not cycles and len(path) == group.n_curves:
            obj = group.path_cost(path)
            if obj < best_obj:
                best, best_obj = path, obj
            if ms == _OPT:
                status = Status.OPTIMAL
                break
            status = Status.FEASIBLE
            break
        if ms != _OPT:
            status = Status.FEASIBLE
            break
        model.add_rows([model.cut(c) for c in cycles])
    group.check_order(best)
    if best_obj - bound <= OPTIMAL_ABS_TOL:
        status = Status.OPTIMAL
    return GroupSolution.make(best, best_obj, bound, status, time.perf_counter() - t0, "milp")
