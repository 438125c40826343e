"""The paper's re-compiler, 3DGates (Chen et al., ASPLOS'17) Section 4.3, Algorithm 1: the baseline.

As published, in our terms (formulations/gating.md "greedy"):

1. *Instruction grouping*: per layer and motor m, the moves that step m form clusters; two
   clusters are one when the XY path between them is shorter than the neighbourhood threshold
   ``neigh_t`` = 0.5 mm (``options.neighbour_mm``, Algorithm 1 line 2) — a short excursion does not
   earn an off/on pair ("minimum quantity of S-series instructions"). Clusters do not span layers.
2. *Rotation*: the model is turned in 30° steps; the orientation with the most straight X plus
   straight Y moves (a count of moves, not of time or energy) is taken (lines 6-8).
3. *Insertion*: each cluster is sandwiched between S-on and S-off (lines 19-22), S-on Start-Ahead
   before its first step and S-off End-Late after its last, splitting the neighbouring move where
   that moment falls inside it (lines 11-16).

Weaknesses kept on purpose: it counts moves instead of weighing energy (a long retraction or a
slow short move between clusters stays on, an idle interval whose firmware stall costs more than it
saves is still switched off), knows no budget, and only tries 30° steps. Its off intervals are
exactly the problem's idle intervals between clusters, so it is feasible by construction and scored
with the same energy function as every other formulation.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..solvers import Status
from .problem import GatingProblem
from .rotation import greedy_angle
from .solution import GatingSolution, solution_from_idle


def choose_angle(problem: GatingProblem) -> int:
    """Among the candidates that are 30° steps (0 always is), the one with most straight moves."""
    return greedy_angle(problem.angles_deg, problem.angle_straight_moves)


def choose_idle_intervals(problem: GatingProblem, k: int) -> np.ndarray:
    """Idle intervals of angle k that separate clusters (Algorithm 1 grouping with neigh_t)."""
    g = problem.idle_intervals_of(k)
    n = problem.n_steps
    xy = np.hypot(*(problem.end_mm[:, :2] - problem.start_mm[:, :2]).T)
    cum = np.concatenate(([0.0], np.cumsum(xy)))
    prev = problem.idle_prev_row[g]
    nxt = problem.idle_next_row[g]
    # XY path travelled between the two clusters (the moves strictly between their steps)
    path = cum[np.clip(nxt, 0, n)] - cum[np.clip(prev + 1, 0, n)]
    edge = (prev < 0) | (nxt >= n)
    layer_change = np.zeros(len(g), bool)
    inner = ~edge
    layer_change[inner] = problem.layer[prev[inner]] != problem.layer[nxt[inner]]
    apart = path >= problem.options.neighbour_mm
    return g[edge | layer_change | apart]


def keep_spacing(problem: GatingProblem, chosen: np.ndarray) -> np.ndarray:
    """``chosen`` (sorted) without the intervals that would break rule B of a firmware schedule:
    per motor, in time order, an interval stays only at the spacing from the last one kept (the
    paper's algorithm knows no such rule; this is the least change that makes its answer one the
    firmware carries out)."""
    if not problem.has_spacing or not len(chosen):
        return chosen
    keep = np.ones(len(chosen), bool)
    for m in np.unique(problem.idle_motor[chosen]):
        last = None
        for i in np.flatnonzero(problem.idle_motor[chosen] == m):
            g = chosen[i]
            if last is None or problem.spacing_ok(int(m), problem.idle_lb_off_s[last], problem.idle_lb_on_s[last],
                                                  problem.idle_lb_off_s[g], problem.idle_lb_on_s[g]):
                last = g
            else:
                keep[i] = False
    return chosen[keep]


def solve(problem: GatingProblem, *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    t0 = time.perf_counter()
    k = choose_angle(problem)
    chosen = keep_spacing(problem, choose_idle_intervals(problem, k))
    sol = solution_from_idle(problem, "greedy", Status.FEASIBLE, k, chosen, solve_s=time.perf_counter() - t0)
    over = None
    if sol.added_time_s > problem.max_added_time_s + 1e-9:
        over = (f"added time {sol.added_time_s:.3f} s > budget {problem.max_added_time_s:.3f} s "
                f"({TIME_MODEL})")
    return judged(sol, over)


#: the time model greedy's own solve judges its stalls in (the gating problem's)
TIME_MODEL = "the gating model's time: T = L/F plus the firmware's stalls"


def judged(sol: GatingSolution, time_over: str | None) -> GatingSolution:
    """``sol`` with the status its budgets give it (the paper's re-compiler knows none: its answer
    is what it is, and only labelled): infeasible where ``time_over`` says how it breaks the time
    budget (None: it keeps it; the caller says in which time model, ``rewrite.budget.on_print``:
    the planner's print time a run's budget is on) or it adds more lines than allowed."""
    over = [time_over] if time_over else []
    if sol.lines_added > sol.problem.max_added_lines:
        over.append(f"added lines {sol.lines_added} > budget {sol.problem.max_added_lines:.0f}")
    if over:
        return replace(sol, status=Status.INFEASIBLE,
                       message="the paper's re-compiler knows no budget: " + "; ".join(over))
    return replace(sol, status=Status.FEASIBLE, message="")
