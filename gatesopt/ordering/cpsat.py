"""Exact curve ordering with OR-Tools CP-SAT (formulations/ordering.md, "cpsat").

``AddCircuit`` over the nodes {depot 0} + {one node per candidate}: the circuit leaves the depot
into the first candidate (cost = travel from the group's start point), runs candidate to
candidate (cost = exit-to-entry travel), and returns to the depot at cost 0 (the path is open:
it ends wherever its last curve ends). A candidate the path skips takes its self-loop literal
``skip[k]``; exactly one candidate per curve is visited (generalised TSP with clusters, the
OR-Tools idiom for optional nodes). Costs are integers: travel in units of 1/SCALE mm.

The model (~m^2 arcs) is written straight into the CpModelProto from index arrays, and its
building counts against the group's limit: a group whose model would not be built and solved in
the time left keeps the warm start (status "fallback"), as ``auto`` keeps its heuristic path.
"""
from __future__ import annotations

import time

import numpy as np
from ortools.sat.python import cp_model

from .. import _jit
from ..solvers import Status, run_native
from .bounds import lower_bound
from .ils import warm_start
from .problem import OPTIMAL_ABS_TOL, Group, GroupSolution, trivial_solution

#: integer cost scale: 1 unit = 0.1 µm of travel (rounding error <= n * 0.05 µm per path)
SCALE = 10_000
#: building the model (``_Model.build`` and its hint), per arc of the circuit (``n_arcs``),
#: measured; written straight into the proto because CpModel's Python API was ~5x slower and
#: overran a budget's small limits (docs/BENCHMARKS.md, "Curve-ordering constants")
BUILD_S_PER_ARC = 2.5e-6
#: what CP-SAT takes beyond ``max_time_in_seconds`` (copying and loading the model before its
#: first time check, handing the solution back) and reading the solution, per arc (measured)
SOLVER_S_PER_ARC = 4e-6
#: CP-SAT is not started (the model not built) with less than MIN_SOLVE_S + MIN_SOLVE_S_PER_ARC *
#: arcs left for it: the warm start is kept. Given a complete, feasible hint it still returns
#: nothing (UNKNOWN) until its presolve is done, which takes about this long (docs/BENCHMARKS.md)
MIN_SOLVE_S = 0.01
MIN_SOLVE_S_PER_ARC = 3e-5
#: variables written per step of ``_Model.build`` (the deadline is checked between steps)
BUILD_CHUNK = 8192

#: CP-SAT's answer in the solver vocabulary (gatesopt.solvers.Status)
STATUS = {
    cp_model.OPTIMAL: Status.OPTIMAL,
    cp_model.FEASIBLE: Status.FEASIBLE,
    cp_model.INFEASIBLE: Status.INFEASIBLE,
    cp_model.MODEL_INVALID: Status.INFEASIBLE,
    cp_model.UNKNOWN: Status.FALLBACK,
}


def solve(group: Group, *, time_limit_s: float = 10.0, hint=None, num_workers: int = 2,
          seed: int = 0) -> GroupSolution:
    """Within about ``time_limit_s`` from the call: the warm start, building the model and CP-SAT
    all count against it (CP-SAT gets what is left). A group whose model would not be built in
    time, or would leave CP-SAT too little (``MIN_SOLVE_S``, ``MIN_SOLVE_S_PER_ARC``), keeps the
    warm start (status "fallback" unless the cheap bound proves it)."""
    t0 = time.perf_counter()
    triv = trivial_solution(group, t0, "cpsat")
    if triv is not None:
        return triv
    hint = warm_start(group, hint, t0, time_limit_s)
    return _solve_circuit(group, t0, time_limit_s, hint, num_workers, seed, closed=False)


def closed_tour(group: Group, *, time_limit_s: float = 10.0, num_workers: int = 2, seed: int = 0):
    """Shortest *closed* tour through every curve (start point ignored): the Concorde step of
    Fleming et al. Algorithm 1. Returns (candidate order, proven optimal?) or None (no tour found,
    or the model would not be built and solved within the limit)."""
    t0 = time.perf_counter()
    if group.n_curves < 2:
        return None
    sol = _solve_circuit(group, t0, time_limit_s, None, num_workers, seed, closed=True)
    return sol


def n_arcs(group: Group, closed: bool = False) -> int:
    """Arcs (one 0-1 variable each) of the circuit model of ``group``: x[u, v] between
    candidates of different curves, first[k] and last[k] (open path) or the depot's self-loop
    (closed tour), skip[k] for candidates of curves with several."""
    m = group.n_cands
    counts = np.bincount(group.cand_curve, minlength=group.n_curves)
    x = m * m - int((counts.astype(np.int64) ** 2).sum())
    return x + (1 if closed else 2 * m) + int(counts[counts > 1].sum())


class _Model:
    """The circuit model written straight into the CpModelProto from index arrays.

    Variable layout: first[k] (m) | last[k] (m) | x[u, v] (A) | skip[k] (S), or for a closed tour
    x (A) | skip (S) | depot_out (1; the depot sits out of the circuit, its self-loop fixed true).
    """

    def __init__(self, group: Group, closed: bool):
        m, n = group.n_cands, group.n_curves
        self.group, self.closed, self.m, self.n = group, closed, m, n
        arc = group.arc_cost()
        self.us, self.vs = np.nonzero(np.isfinite(arc))     # x[u, v]: v follows u (other curves)
        self.arc_c = np.rint(arc[self.us, self.vs] * SCALE).astype(np.int64)
        counts = np.bincount(group.cand_curve, minlength=n)
        self.sk = np.flatnonzero(counts[group.cand_curve] > 1)     # candidates that may be skipped
        A, S = len(self.us), len(self.sk)
        if closed:
            self.o_first = self.o_last = -1
            self.o_x, self.o_skip, self.o_depot = 0, A, A + S
            self.n_vars = A + S + 1
        else:
            self.o_first, self.o_last, self.o_x, self.o_skip = 0, m, 2 * m, 2 * m + A
            self.n_vars = 2 * m + A + S
        self.model = cp_model.CpModel()

    def build(self, deadline: float | None) -> bool:
        """Writes the model; False (model unusable) if ``deadline`` passed while writing it."""
        g, m, p = self.group, self.m, self.model.proto
        A, S = len(self.us), len(self.sk)
        n_bool = self.n_vars - (1 if self.closed else 0)
        for a in range(0, n_bool, BUILD_CHUNK):                 # the bulk of the time
            p.merge_text_format("variables { domain: [0, 1] }\n" * min(BUILD_CHUNK, n_bool - a))
            if deadline is not None and time.perf_counter() > deadline:
                return False
        k1 = np.arange(1, m + 1)
        x = self.o_x + np.arange(A)
        skip = self.o_skip + np.arange(S)
        tails, heads, lits = [self.us + 1, self.sk + 1], [self.vs + 1, self.sk + 1], [x, skip]
        if self.closed:
            p.merge_text_format("variables { domain: [1, 1] }\n")
            tails.append([0])
            heads.append([0])
            lits.append([self.o_depot])
        else:
            # first[k]: the path starts with candidate k (0 -> k); last[k]: it ends with k
            # (k -> 0, the return arc)
            tails += [np.zeros(m, np.int64), k1]
            heads += [k1, np.zeros(m, np.int64)]
            lits += [self.o_first + np.arange(m), self.o_last + np.arange(m)]
        circ = p.constraints.add().circuit
        circ.tails.extend(np.concatenate(tails).tolist())
        circ.heads.extend(np.concatenate(heads).tolist())
        circ.literals.extend(np.concatenate(lits).tolist())
        # exactly one candidate per curve is visited: sum of its skip[k] = |K_i| - 1
        cc = g.cand_curve[self.sk]
        srt = np.argsort(cc, kind="stable")
        cuts = np.flatnonzero(np.diff(cc[srt])) + 1
        for ks in np.split(skip[srt], cuts) if S else []:
            lin = p.constraints.add().linear
            lin.vars.extend(ks.tolist())
            lin.coeffs.extend([1] * len(ks))
            lin.domain.extend([len(ks) - 1, len(ks) - 1])
        if self.closed:
            ovars, ocost = [x], [self.arc_c]
        else:
            start_c = np.rint(g.start_cost() * SCALE).astype(np.int64)
            end_c = np.rint(g.end_cost() * SCALE).astype(np.int64)
            ovars = [self.o_first + np.arange(m), self.o_last + np.arange(m), x]
            ocost = [start_c, end_c, self.arc_c]
        ovars, ocost = np.concatenate(ovars), np.concatenate(ocost)
        nz = ocost != 0
        obj = p.objective
        obj.vars.extend(ovars[nz].tolist())
        obj.coeffs.extend(ocost[nz].tolist())
        obj.scaling_factor = 1.0
        return True

    def hint(self, order: np.ndarray) -> None:
        """Every literal of the path ``order``."""
        m, p = self.m, self.model.proto
        follows = np.zeros((m, m), bool)
        follows[order[:-1], order[1:]] = True
        visited = np.zeros(m, bool)
        visited[order] = True
        val = np.zeros(self.n_vars, np.int64)
        val[self.o_first + order[0]] = 1
        val[self.o_last + order[-1]] = 1
        val[self.o_x:self.o_x + len(self.us)] = follows[self.us, self.vs]
        val[self.o_skip:self.o_skip + len(self.sk)] = ~visited[self.sk]
        p.solution_hint.vars.extend(range(self.n_vars))
        p.solution_hint.values.extend(val.tolist())

    def decode(self, solver) -> np.ndarray:
        """The path (open) or the tour (closed) of CP-SAT's solution, as candidates."""
        sol = np.asarray(solver.response_proto.solution, np.int64)
        on = np.flatnonzero(sol[self.o_x:self.o_x + len(self.us)])
        succ = dict(zip(self.us[on].tolist(), self.vs[on].tolist()))
        if self.closed:
            cur = next(iter(succ))
            order = [cur]
            while succ[cur] != order[0]:
                cur = succ[cur]
                order.append(cur)
            return np.asarray(order, np.int64)
        order = []
        cur = int(np.argmax(sol[self.o_first:self.o_first + self.m]))
        while cur is not None and len(order) <= self.n:
            order.append(cur)
            cur = succ.get(cur)
        return np.asarray(order, np.int64)


def _kept(group: Group, hint, t0: float) -> GroupSolution:
    """The hint (the warm start) with the cheap bound: what a group keeps without CP-SAT's
    solution ("optimal" if the bound proves it)."""
    order = np.asarray(getattr(hint, "order", hint), np.int64)
    group.check_order(order)
    obj = group.path_cost(order)
    bound = lower_bound(group)
    status = Status.OPTIMAL if obj - bound <= OPTIMAL_ABS_TOL else Status.FALLBACK
    return GroupSolution.make(order, obj, bound, status, time.perf_counter() - t0, "cpsat")


def _solve_circuit(group: Group, t0, time_limit_s, hint, num_workers, seed, closed):
    n = group.n_curves
    # the limit runs from the call (t0): the warm start, building and CP-SAT all count, numba's
    # first compile of a kernel on the way does not (a fresh install's first solve under load)
    deadline = t0 + float(time_limit_s) + _jit.compile_s_since(t0)
    arcs = n_arcs(group, closed)
    build_s, after_s = BUILD_S_PER_ARC * arcs, SOLVER_S_PER_ARC * arcs
    min_solve_s = MIN_SOLVE_S + MIN_SOLVE_S_PER_ARC * arcs

    def give_up():
        # CP-SAT not run: a closed tour has no answer, an open path keeps its warm start
        return None if closed else _kept(group, hint, t0)

    if deadline - time.perf_counter() < build_s + after_s + min_solve_s:
        return give_up()        # too large to be built and solved in the time left (or none left)
    mod = _Model(group, closed)
    # building is abandoned where it leaves CP-SAT too little (a slower machine, a busy core)
    if not mod.build(deadline - after_s - min_solve_s):
        return give_up()
    deadline = t0 + float(time_limit_s) + _jit.compile_s_since(t0)
    if hint is not None:
        mod.hint(np.asarray(getattr(hint, "order", hint), np.int64))
    left = deadline - time.perf_counter() - after_s
    if left < min_solve_s:
        return give_up()
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = left
    solver.parameters.num_workers = int(num_workers)
    solver.parameters.random_seed = int(seed)
    # Ctrl-C: ``solvers.run_native`` stops the search (CP-SAT's own handler would hide it)
    solver.parameters.catch_sigint_signal = False
    code, _ = run_native(lambda: solver.solve(mod.model), solver.stop_search)
    status = STATUS.get(code, Status.FALLBACK)
    if closed:
        if status not in (Status.OPTIMAL, Status.FEASIBLE):
            return None
        return mod.decode(solver), status == Status.OPTIMAL
    if status not in (Status.OPTIMAL, Status.FEASIBLE):
        # no solution within the limit: keep the hint (solve always passes one), cheap bound
        return _kept(group, hint, t0)
    order = mod.decode(solver)
    # integer rounding: each of the n links is off by at most 0.5 unit
    bound = max(solver.BestObjectiveBound() / SCALE - (n + 1) * 0.5 / SCALE, lower_bound(group))
    group.check_order(order)
    obj = group.path_cost(order)
    # integer costs: the model's optimum may be a hair longer than the hint in float travel
    h_order = np.asarray(getattr(hint, "order", hint), np.int64)
    h_obj = group.path_cost(h_order)
    if h_obj < obj - 1e-9:
        order, obj = h_order, h_obj
    if status == Status.OPTIMAL or obj - bound <= OPTIMAL_ABS_TOL:
        status = Status.OPTIMAL
    return GroupSolution.make(order, obj, bound, status, time.perf_counter() - t0, "cpsat")
