"""The gating problem as a cvxpy model: for planners that add constraints of their own and pick any
mixed-integer solver cvxpy knows (HiGHS through highspy, SCIP, Gurobi, ...).

``to_cvxpy(problem)`` writes ``coupled.build_model``'s model (formulations/gating.md §3) with the
objective and constraints ``milp`` passes HiGHS, budgets included; ``CvxpyGating.solution()``
turns the values a solver found back into a ``GatingSolution`` (re-scored with the one energy
function, like every formulation's answer). cvxpy is imported here only, on first use::

    from gatesopt.gating import build, cvxpy_model
    m = cvxpy_model.to_cvxpy(build(program, options))
    mine = cp.Problem(m.problem.objective, m.problem.constraints + [cp.sum(m.off) <= 100])
    mine.solve(solver="HIGHS")          # or any MIP solver of cp.installed_solvers()
    sol = m.solution(mine)

Variables (index ``i`` of ``off`` is the idle interval ``model.x_idle[i]`` of the problem, at
angle ``model.angles[model.x_angle[i]]``):

    off[i]          boolean   x: the idle interval is off (its motor switched off over all of it)
    angle[k]        boolean   y: rotation ``model.angles[k]`` chosen (exactly one)
    line[e]         [0, 1]    z: instruction line e shared by several intervals is written
    split[t]        [0, 1]    w: split moment t shared by several intervals is written
    xy_both_off[p]  [0, 1]    a: the X and Y intervals of pair ``model.a_pairs[p]`` are both off

An idle interval that can never lower the energy gets no variable (it stays on; ``build_model``'s
reductions). Angles are not pruned by an incumbent here (``incumbent_j`` = inf): constraints a
planner adds could make any angle the best.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..solvers import Status
from .coupled import CoupledModel, build_model
from .milp import LINE_WEIGHT_J, highs_options
from .problem import GatingProblem
from .solution import GatingSolution, solution_from_idle


@dataclass(frozen=True, eq=False)
class CvxpyGating:
    """A gating problem written as a ``cvxpy.Problem`` and the variables to read back."""

    gating: GatingProblem
    model: CoupledModel
    problem: object             # cvxpy.Problem: minimise energy (J) + LINE_WEIGHT_J x lines
    off: object | None          # cvxpy.Variable (nx,) boolean, None when no interval can save
    angle: object               # cvxpy.Variable (ny,) boolean
    line: object | None         # cvxpy.Variable (nz,) in [0, 1], None when nz = 0
    split: object | None        # (nw,)
    xy_both_off: object | None  # (na,)

    def solution(self, problem=None, status: str | None = None) -> GatingSolution:
        """The answer in the variables' values (after ``problem.solve()``; ``problem`` when the
        planner solved a problem of its own built from these variables), re-scored. Status:
        ``status`` if given, else "optimal" when cvxpy says so, else "feasible"."""
        import cvxpy as cp

        solved = self.problem if problem is None else problem
        if self.angle.value is None or (self.off is not None and self.off.value is None):
            raise ValueError(f"no values to read: the cvxpy problem's status is {solved.status!r}")
        if status is None:
            status = Status.OPTIMAL if solved.status == cp.OPTIMAL else Status.FEASIBLE
        off = np.zeros(0, bool) if self.off is None else np.asarray(self.off.value) > 0.5
        chosen = self.model.x_idle[off]
        k = int(self.model.angles[int(np.argmax(self.angle.value))])
        return solution_from_idle(self.gating, "cvxpy", status, k, chosen,
                                  message=f"cvxpy {solved.status}; {self.model.nx} interval variables")


def to_cvxpy(problem: GatingProblem, *, incumbent_j: float = math.inf) -> CvxpyGating:
    """``problem``'s coupled model as a cvxpy problem (module docstring). ``incumbent_j``: the
    energy of a known solution, to leave out angles that cannot beat it (exact, as ``milp`` does;
    only valid while nobody adds constraints)."""
    import cvxpy as cp
    import scipy.sparse as sp

    model = build_model(problem, incumbent_j)
    nx, ny = model.nx, len(model.angles)
    nz, nw, na = len(model.z_members), len(model.w_members), len(model.a_pairs)
    if nx == 0:     # nothing can save energy: every motor stays on, at any angle
        y = cp.Variable(ny, boolean=True, name="angle")
        objective = model.energy_before_j + 0 * cp.sum(y)
        return CvxpyGating(problem, model, cp.Problem(cp.Minimize(objective), [cp.sum(y) == 1]),
                           None, y, None, None, None)
    x = cp.Variable(nx, boolean=True, name="off")
    y = cp.Variable(ny, boolean=True, name="angle")
    z = cp.Variable(nz, name="line") if nz else None
    w = cp.Variable(nw, name="split") if nw else None
    a = cp.Variable(na, name="xy_both_off") if na else None
    cons = [cp.sum(y) == 1]
    if ny > 1:                                  # an interval of the chosen angle only
        pick = sp.csr_matrix((np.ones(nx), (np.arange(nx), model.x_angle)), shape=(nx, ny))
        cons.append(x <= pick @ y)
    if model.c_members:                         # rule B of a firmware schedule: cliques
        cons.append(_cliques(model.c_members, nx) @ x <= 1)
    for var, members in ((z, model.z_members), (w, model.w_members)):
        if var is not None:                     # a shared line/split is written if any member is off
            cons += [var >= 0, var <= 1, _members(members, nx) @ x <= _owners(members) @ var]
    objective = model.energy_before_j + (model.x_energy_j + LINE_WEIGHT_J * model.x_lines) @ x
    if z is not None:
        objective = objective + (model.z_energy_j + LINE_WEIGHT_J) @ z
    if w is not None:
        objective = objective + LINE_WEIGHT_J * cp.sum(w)
    if a is not None:
        cons += _and_constraints(model, x, a)
        objective = objective + model.a_energy_j @ a
    cons += _budgets(model, x, z, w)
    return CvxpyGating(problem, model, cp.Problem(cp.Minimize(objective), cons), x, y, z, w, a)


def _cliques(cliques: list, nx: int):
    """(number of cliques, nx) sparse: row c sums the x of clique c."""
    import scipy.sparse as sp

    lens = np.array([len(c) for c in cliques])
    return sp.csr_matrix((np.ones(int(lens.sum())), (np.repeat(np.arange(len(cliques)), lens),
                                                     np.concatenate(cliques))), shape=(len(cliques), nx))


def _members(members: list, nx: int):
    """(sum of member counts, nx) sparse: row r picks the r-th (shared thing, member) pair's x."""
    import scipy.sparse as sp

    cols = np.concatenate(members)
    return sp.csr_matrix((np.ones(len(cols)), (np.arange(len(cols)), cols)), shape=(len(cols), nx))


def _owners(members: list):
    """(sum of member counts, n shared) sparse: row r picks the shared thing of pair r."""
    import scipy.sparse as sp

    lens = np.array([len(m) for m in members])
    rows = np.arange(int(lens.sum()))
    return sp.csr_matrix((np.ones(len(rows)), (rows, np.repeat(np.arange(len(members)), lens))),
                         shape=(len(rows), len(members)))


def _and_constraints(model: CoupledModel, x, a) -> list:
    """a[p] = x[g] AND x[h], linearised on the side the objective does not push: a >= x_g + x_h - 1
    where the correction is positive (the objective pushes a down), a <= x_g, a <= x_h where it is
    negative (pushed up)."""
    g, h = model.a_pairs[:, 0], model.a_pairs[:, 1]
    pos = model.a_energy_j > 0
    cons = [a >= 0, a <= 1]
    ip, ineg = np.flatnonzero(pos), np.flatnonzero(~pos)
    if len(ip):
        cons.append(a[ip] >= x[g[ip]] + x[h[ip]] - 1)
    if len(ineg):
        cons += [a[ineg] <= x[g[ineg]], a[ineg] <= x[h[ineg]]]
    return cons


def _budgets(model: CoupledModel, x, z, w) -> list:
    """The added-time budget (stall seconds) and the added-lines budget, as ``milp`` writes them."""
    import cvxpy as cp

    cons = []
    if math.isfinite(model.max_time_s):
        t = model.x_stall_s @ x
        if z is not None:
            t = t + model.z_stall_s @ z
        cons.append(t <= model.max_time_s + 1e-9)
    if math.isfinite(model.max_lines):
        n = model.x_lines @ x
        for var in (z, w):
            if var is not None:
                n = n + cp.sum(var)
        cons.append(n <= float(model.max_lines))
    return cons


def solve(problem: GatingProblem, *, solver: str = "HIGHS", time_limit_s: float | None = None,
          hint: GatingSolution | None = None, **solver_options) -> GatingSolution:
    """Export and solve with cvxpy's ``solver`` (the ``solve(problem, ...)`` signature of the
    formulations; ``hint`` is not passed on: cvxpy has no portable warm start for a MIP). HiGHS
    gets ``milp``'s options unless given others: with HiGHS's defaults (presolve on, restarts)
    the 259k-line PrusaSlicer bunny under a Marlin 1 % budget took 374-497 s in HiGHS instead of
    6-9 s (docs/BENCHMARKS.md)."""
    m = to_cvxpy(problem)
    if solver == "HIGHS":
        solver_options = {**highs_options(problem, time_limit_s), **solver_options}
        if time_limit_s is not None:
            solver_options.setdefault("time_limit", float(time_limit_s))
    m.problem.solve(solver=solver, **solver_options)
    return m.solution()
