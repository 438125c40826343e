"""Exact gating for the coupled problem with OR-Tools CP-SAT (formulations/gating.md "cpsat").

The same model as ``gatesopt.gating.milp`` (``coupled.CoupledModel``: x, y, z, w, a), all Boolean, with
integer coefficients: energy in units of ``unit_j`` (1 µJ, or 1e-9 of the objective's magnitude
if finer, coarser only if the objective would not fit in 2^53), stall time in microseconds, and the lexicographic objective written exactly as
``energy_units * (lines_ub + 1) + lines``. Hinted with the dp (or given) solution, fixed seed,
``options.num_workers`` workers.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..solvers import Status, Stopped, relative_gap, run_native, stop_requested
from .coupled import LINE_TIEBREAK_S, LINE_TIEBREAK_SHARE, CoupledModel, build_model, hint_vector
from .dp import warm_start
from .problem import GatingProblem
from .solution import GatingSolution, solution_from_idle

UNIT_J = 1e-6           # energy unit of the integer objective
UNIT_REL = 1e-9         # ... or this share of the objective's magnitude, if finer
TIME_UNIT_S = 1e-6      # time unit of the stall budget


#: items (variables, constraints) written between two checks for a stop or the deadline while the
#: model is built in Python (``_polled``): a 217k-line file's model took ~2 s to build, and a
#: Ctrl-C during it waited for all of it (bench/ctrl_c.py)
POLL_ITEMS = 2048


class _BuildStopped(Exception):
    """A stop request or the deadline arrived while the CP-SAT model was being built."""


def _polled(items, should_stop):
    """``items``, checking ``should_stop()`` every ``POLL_ITEMS`` of them (raises
    ``_BuildStopped``)."""
    for i, item in enumerate(items):
        if i % POLL_ITEMS == 0 and should_stop():
            raise _BuildStopped
        yield item


def _status_map():
    from ortools.sat.python import cp_model as cp
    return {cp.OPTIMAL: Status.OPTIMAL, cp.FEASIBLE: Status.FEASIBLE, cp.INFEASIBLE: Status.INFEASIBLE,
            cp.MODEL_INVALID: Status.INFEASIBLE, cp.UNKNOWN: Status.FALLBACK}


def _add_share_cuts(m, model, x) -> None:
    """Redundant budget rows over x alone: a shared line, split or stall charged 1/|sharers| to each
    sharer never exceeds what is paid (the argument of ``coupled.build_model``'s share bound). They give CP-SAT's
    LP relaxation a plain knapsack row to work with. Scaled by 12 = lcm(1..4) (sharers <= 4 when
    X, Y, Z, E share one moment; larger groups round the shares down, which keeps the row valid)."""
    S = 12
    lines = model.x_lines * S
    tau = model.x_stall_s * S
    for i, mem in enumerate(model.z_members):
        lines[mem] += S / len(mem)
        tau[mem] += model.z_stall_s[i] * S / len(mem)
    for mem in model.w_members:
        lines[mem] += S / len(mem)
    if math.isfinite(model.max_lines):
        cl = np.floor(lines + 1e-9).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(cl, x) if c) <= int(model.max_lines) * S)
    if math.isfinite(model.max_time_s):
        ct = np.floor(tau / TIME_UNIT_S + 1e-6).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(ct, x) if c) <= int(math.floor(model.max_time_s * S / TIME_UNIT_S + 1e-6)))


@dataclass
class _CpModel:
    """The CP-SAT model of a ``CoupledModel`` and its variables (``_cp_model``)."""

    m: object                   # cp_model.CpModel
    x: list                     # x[g]: idle interval g off
    y: list                     # y[k]: rotation k chosen
    z: list                     # z[e]: shared instruction line e
    w: list                     # w[t]: shared split at moment t
    a: list                     # a[p]: X and Y intervals of pair p both off
    unit_j: float               # energy unit of the integer objective
    W: int                      # weight of one energy unit (lines_ub + 1): lines break ties
    e0: int                     # the constant energy_before_j, in objective units

    def q(self, v) -> np.ndarray:
        """Energies (J) in integer units of ``unit_j``."""
        return np.round(np.asarray(v, float) / self.unit_j).astype(np.int64)


def _cp_model(cp, model: CoupledModel, should_stop=lambda: False) -> _CpModel:
    """Variables, constraints and the lexicographic objective (energy units * W + lines). Raises
    ``_BuildStopped`` once ``should_stop()`` (checked every ``POLL_ITEMS`` items)."""
    nx, nz, nw, na = model.nx, len(model.z_members), len(model.w_members), len(model.a_pairs)
    ny = len(model.angles)
    lines_ub = int(round(model.x_lines.sum())) + nz + nw
    W = lines_ub + 1
    # energy unit: 1 µJ unless sum |c| * W would leave the exactly representable integers; finer
    # for a tiny print (under 1 kJ: 1e-9 of it), so that the rounding's slack in the reported
    # bound (``_energy_bound_j``) stays far within the gap tolerance it is judged by
    mag = (abs(model.energy_before_j) + np.abs(model.x_energy_j).sum() + np.abs(model.z_energy_j).sum()
           + np.abs(model.a_energy_j).sum())
    unit = max(min(UNIT_J, mag * UNIT_REL), mag * W / 2.0 ** 53)
    m = cp.CpModel()
    x = [m.NewBoolVar(f"x_{g}") for g in _polled(model.x_idle, should_stop)]   # x[g]: idle interval g off
    y = [m.NewBoolVar(f"y_{k}") for k in model.angles]          # y[k]: rotation k chosen
    z = [m.NewBoolVar(f"z_{i}") for i in range(nz)]             # z[e]: shared instruction line e
    w = [m.NewBoolVar(f"w_{i}") for i in range(nw)]             # w[t]: shared split at moment t
    a = [m.NewBoolVar(f"a_{i}") for i in range(na)]             # a[p]: X and Y intervals of pair p both off
    m.AddExactlyOne(y)
    if ny > 1:
        for i, k in _polled(enumerate(model.x_angle.tolist()), should_stop):
            m.AddImplication(x[i], y[k])
    for mem in _polled(model.c_members, should_stop):             # rule B of a firmware schedule
        m.AddAtMostOne([x[j] for j in mem.tolist()])
    for i, mem in _polled(enumerate(model.z_members), should_stop):
        for j in mem.tolist():
            m.AddImplication(x[j], z[i])
    for i, mem in _polled(enumerate(model.w_members), should_stop):
        for j in mem.tolist():
            m.AddImplication(x[j], w[i])
    for i, (g, h) in _polled(enumerate(model.a_pairs.tolist()), should_stop):
        if model.a_energy_j[i] > 0:
            m.AddBoolOr([x[g].Not(), x[h].Not(), a[i]])
        else:
            m.AddImplication(a[i], x[g])
            m.AddImplication(a[i], x[h])
    if math.isfinite(model.max_time_s):
        ts = np.round(model.x_stall_s / TIME_UNIT_S).astype(np.int64).tolist()
        tz = np.round(model.z_stall_s / TIME_UNIT_S).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(ts, x) if c) + sum(c * v for c, v in zip(tz, z) if c)
              <= int(math.floor(model.max_time_s / TIME_UNIT_S + 1e-6)))
    if math.isfinite(model.max_lines):
        xl = np.round(model.x_lines).astype(np.int64).tolist()
        m.Add(sum(c * v for c, v in zip(xl, x) if c) + sum(z) + sum(w) <= int(model.max_lines))
    if should_stop():
        raise _BuildStopped
    _add_share_cuts(m, model, x)
    if should_stop():
        raise _BuildStopped
    # the constant energy_before_j is in the objective so that CP-SAT's relative gap is relative
    # to the print's energy, as HiGHS's is (its offset_)
    c = _CpModel(m, x, y, z, w, a, unit, W, int(round(model.energy_before_j / unit)) * W)
    cx = c.q(model.x_energy_j) * W + np.round(model.x_lines).astype(np.int64)
    cz = c.q(model.z_energy_j) * W + 1
    cw = np.ones(nw, np.int64)
    ca = c.q(model.a_energy_j) * W
    terms = [(int(k), v) for k, v in _polled(zip(cx.tolist(), x), should_stop) if k]
    terms += [(int(k), v) for k, v in zip(cz.tolist(), z) if k]
    terms += [(int(k), v) for k, v in zip(cw.tolist(), w) if k]
    terms += [(int(k), v) for k, v in zip(ca.tolist(), a) if k]
    m.Minimize(cp.LinearExpr.WeightedSum([v for _, v in terms], [k for k, _ in terms]) + c.e0)
    return c


def _add_hints(c: _CpModel, model: CoupledModel, hv, should_stop=lambda: False) -> None:
    """The start ``hv`` = (x, y) as CP-SAT hints, with the z, w, a values it implies (raises
    ``_BuildStopped`` once ``should_stop()``)."""
    hx, hy = hv
    for v, b in _polled(zip(c.x, hx.tolist()), should_stop):
        c.m.AddHint(v, int(b))
    for v, b in zip(c.y, hy.tolist()):
        c.m.AddHint(v, int(b))
    for i, mem in _polled(enumerate(model.z_members), should_stop):
        c.m.AddHint(c.z[i], int(hx[mem].max()))
    for i, mem in enumerate(model.w_members):
        c.m.AddHint(c.w[i], int(hx[mem].max()))
    for i, (g, h) in enumerate(model.a_pairs.tolist()):
        c.m.AddHint(c.a[i], int(hx[g] * hx[h]))


def _set_parameters(solver, problem: GatingProblem) -> int:
    """Workers, subsolvers, seed and gap limit of the first stage; returns the number of workers."""
    nw = max(1, int(problem.options.num_workers))
    solver.parameters.num_workers = nw
    # The LP relaxation is what proves a budgeted instance (a knapsack row). With 2 workers the
    # default portfolio has no worker at the full linearization and stalled at a 1-2 % gap on
    # 9k-interval files for 60 s; "max_lp" (linearization level 2) proves them in well under a second.
    # CP-SAT's presolve spent the whole 60 s on the largest instance (clique merging and symmetry
    # detection over the x -> z implications) before searching; without it that instance is
    # proven in ~12 s. Our model is already reduced (coupled.build_model).
    solver.parameters.cp_model_presolve = False
    if nw == 1:
        solver.parameters.linearization_level = 2
    elif nw == 2:
        solver.parameters.subsolvers.extend(["max_lp", "default_lp"])
    else:
        solver.parameters.extra_subsolvers.append("max_lp")
    solver.parameters.random_seed = int(problem.options.seed)
    solver.parameters.relative_gap_limit = float(problem.options.mip_rel_gap)
    # Ctrl-C is ours (``solvers.run_native`` stops the search and keeps its best answer): CP-SAT's
    # own SIGINT handler would take the signal from Python, which then never learns of it
    solver.parameters.catch_sigint_signal = False
    return nw


def _fewest_lines(cp, c: _CpModel, model: CoupledModel, solver, problem: GatingProblem, nw: int,
                  t0: float, time_limit_s: float | None):
    """Second stage: energy held at what the first stage found, fewest lines (the lexicographic
    order of formulations/gating.md section 4, exactly). Returns (xs, ys, note) or None."""
    x, z, w, a = c.x, c.z, c.w, c.a
    energy = [(int(k), v) for k, v in zip(c.q(model.x_energy_j).tolist(), x) if k]
    energy += [(int(k), v) for k, v in zip(c.q(model.z_energy_j).tolist(), z) if k]
    energy += [(int(k), v) for k, v in zip(c.q(model.a_energy_j).tolist(), a) if k]
    found = sum(k * solver.BooleanValue(v) for k, v in energy)
    if energy:
        c.m.Add(cp.LinearExpr.WeightedSum([v for _, v in energy], [k for k, _ in energy]) <= found)
    xl = np.round(model.x_lines).astype(np.int64).tolist()
    lines = [(k, v) for k, v in zip(xl, x) if k] + [(1, v) for v in z + w]
    c.m.Minimize(cp.LinearExpr.WeightedSum([v for _, v in lines], [k for k, _ in lines]))
    c.m.ClearHints()
    for v in x + c.y + z + w + a:
        c.m.AddHint(v, int(solver.BooleanValue(v)))
    used = time.perf_counter() - t0
    second = cp.CpSolver()
    second.parameters.num_workers = nw
    second.parameters.cp_model_presolve = False
    second.parameters.random_seed = int(problem.options.seed)
    # at most as long again as the first stage took, within what is left of the limit (none
    # left: no second stage, rather than a fresh 50 ms past the limit)
    left = used if time_limit_s is None else min(used, float(time_limit_s) - used)
    if left <= 0.0 or stop_requested():
        return None
    second.parameters.max_time_in_seconds = left
    second.parameters.catch_sigint_signal = False
    st2, _ = run_native(lambda: second.solve(c.m), second.stop_search)
    if st2 not in (cp.OPTIMAL, cp.FEASIBLE):
        return None
    return (np.array([second.BooleanValue(v) for v in x], bool),
            np.array([second.BooleanValue(v) for v in c.y], bool),
            f"; fewest lines at that energy: {second.StatusName(st2)}")


def _energy_bound_j(c: _CpModel, model: CoupledModel, nx: int, nz: int, na: int, bound_obj: float) -> float:
    """CP-SAT's objective bound as a bound on the energy (J): obj = energy_units * W + lines with
    0 <= lines <= lines_ub, so energy_units >= floor(bound / W); each rounded coefficient is off
    by <= unit / 2; and never below the share bound."""
    bound_units = math.floor((bound_obj - c.e0) / c.W)
    slack = c.unit_j / 2.0 * (nx + nz + na + 1)            # +1: the rounded constant
    return max(model.energy_before_j + bound_units * c.unit_j - slack, model.bound_j)


def _gap_stop(cp, c: _CpModel, model: CoupledModel, nx: int, nz: int, na: int, rel_gap: float, t0: float):
    """The stopping rule as CP-SAT callbacks: once the gap this formulation will report (the
    energy against ``_energy_bound_j``) is at most ``rel_gap``, the search goes on for the line
    tie-break only a little longer (``milp.LINE_TIEBREAK_S``, as HiGHS does): ``state["stop_at"]``,
    the deadline ``solvers.run_native`` watches. An incumbent's energy is taken from its
    objective, rounded up by the coefficients' rounding (its exact energy is re-scored at the
    end, ``solution_from_idle``). Returns (solution callback, bound callback, state)."""
    slack = c.unit_j / 2.0 * (nx + nz + na + 1)
    state = {"energy": math.inf, "bound": -math.inf, "stop_at": None}

    def check():
        b = _energy_bound_j(c, model, nx, nz, na, state["bound"])
        if (state["stop_at"] is None and math.isfinite(state["energy"])
                and relative_gap(state["energy"], b) <= rel_gap):
            now = time.perf_counter()
            state["stop_at"] = now + max(LINE_TIEBREAK_S, LINE_TIEBREAK_SHARE * (now - t0))

    class OnSolution(cp.CpSolverSolutionCallback):
        def on_solution_callback(self):
            units = math.floor((self.ObjectiveValue() - c.e0) / c.W)
            state["energy"] = min(state["energy"], model.energy_before_j + units * c.unit_j + slack)
            state["bound"] = max(state["bound"], self.BestObjectiveBound())
            check()

    def on_bound(bound):
        state["bound"] = max(state["bound"], float(bound))
        check()
    return OnSolution(), on_bound, state


def solve(problem: GatingProblem, *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    """The coupled model solved by CP-SAT within ``time_limit_s`` for the whole call, stopped as
    soon as the gap it reports is at most ``options.mip_rel_gap`` (``_gap_stop``), or on a stop
    request (Ctrl-C, ``solvers.run_native``) with its best answer."""
    from ortools.sat.python import cp_model as cp

    t0 = time.perf_counter()
    start = warm_start(problem, hint)
    model = build_model(problem, start.energy_j)
    if model.nx == 0:
        return solution_from_idle(problem, "cpsat", Status.OPTIMAL, int(model.angles[0]),
                                  np.zeros(0, np.int64), solve_s=time.perf_counter() - t0,
                                  bound_j=problem.energy_before_j)
    nx, ny, nz, na = model.nx, len(model.angles), len(model.z_members), len(model.a_pairs)
    if stop_requested():
        return _start_answer(problem, start, model, Status.FEASIBLE, time.perf_counter() - t0,
                             "not searched: stop requested", Stopped.INTERRUPTED)
    # the limit is for the whole call: the dp start and building the model count against it
    deadline = None if time_limit_s is None else t0 + float(time_limit_s)

    def should_stop() -> bool:
        return stop_requested() or (deadline is not None and time.perf_counter() >= deadline)
    try:
        c = _cp_model(cp, model, should_stop)
        hv = hint_vector(problem, model, start)
        if hv is not None:
            _add_hints(c, model, hv, should_stop)
    except _BuildStopped:
        stopped = Stopped.INTERRUPTED if stop_requested() else Stopped.TIME_LIMIT
        return _start_answer(problem, start, model, Status.FEASIBLE, time.perf_counter() - t0,
                             f"not searched: {stopped} while building the model", stopped)
    solver = cp.CpSolver()
    nw = _set_parameters(solver, problem)
    if deadline is not None:
        left = deadline - time.perf_counter()
        if left <= 0.0:     # the limit went to the start and the build: no fresh 10 ms for CP-SAT
            return _start_answer(problem, start, model, Status.FEASIBLE, time.perf_counter() - t0,
                                 "not searched: time limit reached while building the model",
                                 Stopped.TIME_LIMIT)
        solver.parameters.max_time_in_seconds = left
    on_solution, on_bound, rule = _gap_stop(cp, c, model, nx, nz, na, problem.options.mip_rel_gap, t0)
    solver.best_bound_callback = on_bound
    st, stopped = run_native(lambda: solver.solve(c.m, on_solution), solver.stop_search,
                             lambda: rule["stop_at"])
    by_rule = stopped == Stopped.TIME_LIMIT     # run_native's deadline is the rule's
    if by_rule:
        stopped = Stopped.NO
    mapped = _status_map().get(st, Status.FALLBACK)
    if not stopped and st != cp.OPTIMAL and not by_rule:
        stopped = Stopped.TIME_LIMIT
    if st not in (cp.OPTIMAL, cp.FEASIBLE):
        status = Status.INFEASIBLE if mapped == Status.INFEASIBLE else Status.FALLBACK
        return _start_answer(problem, start, model, status, time.perf_counter() - t0,
                             f"CP-SAT {solver.StatusName(st)}", stopped)
    xs = np.array([solver.BooleanValue(v) for v in c.x], bool)
    ys = np.array([solver.BooleanValue(v) for v in c.y], bool)
    lines_note = ""
    if not stopped and solver.ObjectiveValue() - solver.BestObjectiveBound() >= 1.0:
        # the gap rule stopped the search with room for a line less at the same energy (a gap
        # of 1 unit is one line, see W): the second stage
        second = _fewest_lines(cp, c, model, solver, problem, nw, t0, time_limit_s)
        if second is not None:
            xs, ys, lines_note = second
    k = int(model.angles[int(np.argmax(ys))])
    bound = _energy_bound_j(c, model, nx, nz, na, solver.BestObjectiveBound())
    sol = solution_from_idle(problem, "cpsat", Status.FEASIBLE, k, model.x_idle[xs],
                             solve_s=time.perf_counter() - t0, bound_j=bound,
                             message=f"CP-SAT {solver.StatusName(st)}; {nx} gap variables, {ny} angle(s), "
                                     f"{len(model.pruned)} pruned by bound; energy unit {c.unit_j:.3g} J"
                                     + lines_note)
    proven = sol.gap <= problem.options.mip_rel_gap
    return replace(sol, status=Status.OPTIMAL if proven else Status.FEASIBLE,
                   stopped=Stopped.NO if proven else stopped)


def _start_answer(problem: GatingProblem, start: GatingSolution, model: CoupledModel, status: Status,
                  solve_s: float, why: str, stopped: Stopped) -> GatingSolution:
    """The warm start as cpsat's answer, bounded by the share bound."""
    gap = relative_gap(start.energy_j, model.bound_j)
    if status == Status.FEASIBLE and gap <= problem.options.mip_rel_gap:
        status = Status.OPTIMAL
    return replace(start, formulation="cpsat", status=status, solve_s=solve_s, bound_j=model.bound_j,
                   gap=gap, stopped=Stopped.NO if status == Status.OPTIMAL else stopped,
                   message=f"{why}; returned the dp/hint start")
