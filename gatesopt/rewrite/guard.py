"""The time guard (formulations/ordering.md, "Time guard"): which re-ordered layers keep the
slicer's order, decided on what the planner model says the emitted file takes.

A layer's re-ordering changes more than its own steps: where it ends moves the travel into the
next layer (the layer change), and where it starts moves the travel from the layer before. The
planner's time of the file is split at extrusions (``layer_parts_s``): per layer, ``inner`` (its
first extruding step to its last) and ``after`` (the steps from there to the next layer's first
extrusion: the layer change, which belongs to both layers). With one state per layer, s = 1
re-ordered, s = 0 put back,

    T = prefix + sum_k inner_k(s_k) + sum_k after_k(s_k, s_k+1)

and the guard picks the states that minimise T (a shortest path over the layers, ``_best_states``)
from measured terms: the slicer's file gives every (0, 0) term, the re-ordered file every (1, 1)
term, and two more emits (``_alternate``: re-ordered layers alternately put back) the (1, 0) and
(0, 1) terms of adjacent re-ordered layers. Comparing layer by layer instead put back a layer
whose new exit made the layer change shorter -- a gain the next layer's time shows (measured:
prusa25_star_rect15_m82 safe, 46 layers 44 ms slower each, the next 71 ms faster).

The states are then emitted and measured; of every file measured (the slicer's, the re-ordered,
the alternating ones, the chosen) the shortest print is returned: the planner's look-ahead joins
the terms with a hair of difference, and the answer is never slower than any measured one.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..ordering.emitter import emit
from ..ordering.layers import model_travel_mm
from ..ordering.problem import OrderingProblem, OrderingSolution
from ..parse import parse
from ..planner import plan
from ..program import Program

#: a layer counts as slower re-ordered only by more than this (s): the planner's look-ahead runs
#: across layers, so a layer whose own text did not change can differ by a hair where a moved
#: neighbour meets it
GUARD_TOL_S = 1e-3


def step_times_s(program: Program) -> np.ndarray:
    """Per step, its time under the planner model (``planner.plan``: acceleration, junction
    speeds, the file's machine limits): what the time guard and the report's print time use."""
    return plan(program).duration_s


def layer_times_s(program: Program, durations_s: np.ndarray | None = None) -> np.ndarray:
    """Per layer (0..n_layers-1), the time of every step in it (planner model, or the
    ``durations_s`` given)."""
    d = step_times_s(program) if durations_s is None else durations_s
    m = program.layer >= 0
    return np.bincount(program.layer[m], weights=d[m], minlength=program.n_layers)


def layer_parts_s(program: Program, durations_s: np.ndarray | None = None):
    """(inner, after, total): per layer, the time from its first extruding step to its last
    (``inner``) and from there to the next extruding layer's first extruding step (``after``; the
    last such layer: to the file's end), and the file's whole time. A layer without extrusion has
    0 in both (its steps are in the ``after`` of the layer before). None where extruding layers
    are not in increasing order (the guard then compares whole files)."""
    d = step_times_s(program) if durations_s is None else np.asarray(durations_s, float)
    L = program.n_layers
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    inner, after = np.zeros(L), np.zeros(L)
    if not len(ext):
        return inner, after, float(d.sum())
    lay = program.layer[ext].astype(np.int64)
    if np.any(np.diff(lay) < 0):
        return None
    cut = np.flatnonzero(np.diff(lay)) + 1
    first = ext[np.concatenate(([0], cut))]
    last = ext[np.concatenate((cut - 1, [len(ext) - 1]))]
    c = np.concatenate(([0.0], np.cumsum(d)))
    ids = lay[np.concatenate(([0], cut))]
    inner[ids] = c[last + 1] - c[first]
    nxt = np.concatenate((first[1:], [len(d)]))
    after[ids] = c[nxt] - c[last + 1]
    return inner, after, float(c[-1])


def keep_layers(problem: OrderingProblem, solution: OrderingSolution, layers) -> OrderingSolution:
    """``solution`` with the curves of ``layers`` back in the slicer's order and direction.
    A layer's curves are one contiguous block of the print order, and curve numbers grow with
    the layer, so sorting the positions they hold restores each block."""
    problem = problem.program_problem
    order = solution.curve_order.copy()
    at = np.isin(problem.curve_layer[order], np.asarray(layers, np.int64))
    order[at] = np.sort(order[at])
    rev, seam = solution.curve_reversed.copy(), solution.curve_seam.copy()
    rev[order[at]] = False
    seam[order[at]] = 0
    return dataclasses.replace(solution, curve_order=order, curve_reversed=rev, curve_seam=seam,
                               travel_after_mm=model_travel_mm(problem, order, rev, seam),
                               cost_after=problem.order_cost(order, rev, seam))


def changed_layers(problem: OrderingProblem, solution: OrderingSolution) -> np.ndarray:
    """(n_layers,) bool: layers whose curves ``solution`` prints in another order, direction or
    from another seam than the slicer."""
    problem = problem.program_problem
    n = problem.n_curves
    order = np.asarray(solution.curve_order, np.int64)
    moved = np.zeros(n, bool)
    moved[order] = order != np.arange(n)
    turned = np.asarray(solution.curve_reversed, bool) | (np.asarray(solution.curve_seam) != 0)
    out = np.zeros(max(problem.n_layers, int(problem.curve_layer.max()) + 1 if n else 0), bool)
    out[np.unique(problem.curve_layer[moved | turned])] = True
    return out


class _Terms:
    """The measured terms of T (module docstring): ``inner[l, s]`` and ``after[l, s, t]`` (t: the
    state of the next extruding layer), NaN where not measured, each the mean of what was seen."""

    def __init__(self, n_layers: int):
        self.sum_i = np.zeros((n_layers, 2))
        self.n_i = np.zeros((n_layers, 2))
        self.sum_a = np.zeros((n_layers, 2, 2))
        self.n_a = np.zeros((n_layers, 2, 2))
        self.prefix = []

    def add(self, parts, states: np.ndarray, has: np.ndarray) -> None:
        inner, after, total = parts
        ids = np.flatnonzero(has)
        s = states[ids].astype(np.int64)
        t = np.concatenate((s[1:], [0]))
        np.add.at(self.sum_i, (ids, s), inner[ids])
        np.add.at(self.n_i, (ids, s), 1.0)
        np.add.at(self.sum_a, (ids, s, t), after[ids])
        np.add.at(self.n_a, (ids, s, t), 1.0)
        self.prefix.append(total - inner.sum() - after.sum())

    def arrays(self):
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sum_i / self.n_i, self.sum_a / self.n_a, float(np.mean(self.prefix))


def _best_states(terms: _Terms, has: np.ndarray, changed: np.ndarray) -> tuple[np.ndarray, float]:
    """The states (1: re-ordered) of the extruding layers that minimise T over the measured terms
    (a layer that did not change is 0; an unmeasured combination is not chosen), and that T.
    Ties go to the re-ordered state."""
    inner, after, prefix = terms.arrays()
    ids = np.flatnonzero(has)
    inner = np.where(np.isnan(inner), np.inf, inner)
    after = np.where(np.isnan(after), np.inf, after)
    allowed = np.ones((len(ids), 2), bool)
    allowed[:, 1] = changed[ids]
    # cost[k, s]: the least T of layers ids[k:] given layer ids[k] in state s (backwards)
    cost = np.full((len(ids), 2), np.inf)
    pick = np.zeros((len(ids), 2), np.int64)
    for k in range(len(ids) - 1, -1, -1):
        lk = ids[k]
        for s in (1, 0):
            if not allowed[k, s]:
                continue
            if k == len(ids) - 1:
                cost[k, s] = inner[lk, s] + after[lk, s, 0]
                continue
            opts = [after[lk, s, t] + cost[k + 1, t] if allowed[k + 1, t] else np.inf for t in (1, 0)]
            j = int(np.argmin(opts))
            pick[k, s] = 1 - j
            cost[k, s] = inner[lk, s] + opts[j]
    states = np.zeros(len(has), np.int64)
    if not len(ids):
        return states, prefix
    s = 1 if allowed[0, 1] and cost[0, 1] <= cost[0, 0] else 0
    total = prefix + cost[0, s]
    for k in range(len(ids)):
        states[ids[k]] = s
        s = pick[k, s]
    return states, total


def emit_guarded(program: Program, problem: OrderingProblem, solution: OrderingSolution,
                 time_guard: bool = True):
    """Emit and re-parse; with ``time_guard``, the re-ordered layers that do not pay for
    themselves keep the slicer's order (module docstring). Returns (solution, text, output, the
    layers put back)."""
    memo: dict = {}                     # layers that did not change are not emitted again

    def emitted(sol):
        text = emit(program, problem, sol, memo)
        return text, parse(text, source=f"{program.source} (re-ordered)")
    text, out = emitted(solution)
    none = np.zeros(0, np.int64)
    if not time_guard or out.n_layers != program.n_layers:
        return solution, text, out, none
    # a safety net: the time objective prices each travel as emitted (cost.py), but not every
    # junction of the planner (formulations/ordering.md, "Time guard")
    before = step_times_s(program)
    after = step_times_s(out)
    if np.all(layer_times_s(out, after) <= layer_times_s(program, before) + GUARD_TOL_S):
        return solution, text, out, none
    changed = changed_layers(problem, solution)[:program.n_layers]
    changed = np.concatenate((changed, np.zeros(program.n_layers - len(changed), bool)))
    p0, p1 = layer_parts_s(program, before), layer_parts_s(out, after)
    t0 = float(before.sum())
    tried = [(float(after.sum()), 1, (solution, text, out, none))]

    def put_back(states):
        kept = np.flatnonzero(changed & (states == 0))
        sol = keep_layers(problem, solution, kept) if len(kept) else solution
        return (sol, *emitted(sol), kept)
    if p0 is not None and p1 is not None:
        has = (p0[0] > 0) | (p0[1] > 0) | changed
        terms = _Terms(program.n_layers)
        terms.add(p0, np.zeros(program.n_layers, np.int64), has)
        terms.add(p1, changed.astype(np.int64), has)
        for states in _alternate(changed, has):
            state = put_back(states)
            d = step_times_s(state[2])
            tried.append((float(d.sum()), 2, state))
            parts = layer_parts_s(state[2], d) if state[2].n_layers == program.n_layers else None
            if parts is not None:
                terms.add(parts, states, has)
        states, _ = _best_states(terms, has, changed)
        if not np.array_equal(states, changed.astype(np.int64)):
            state = put_back(states)
            tried.append((float(step_times_s(state[2]).sum()), 0, state))
    best = min(tried, key=lambda x: (x[0], x[1]))
    if best[0] <= t0 + GUARD_TOL_S:
        return best[2]
    # every state measured prints slower than the slicer's: its order throughout
    kept = np.flatnonzero(changed)
    sol = keep_layers(problem, solution, np.arange(program.n_layers))
    return (sol, *emitted(sol), kept)


def _alternate(changed: np.ndarray, has: np.ndarray):
    """The states that measure the (1, 0) and (0, 1) terms of adjacent re-ordered layers: every
    other one of them put back, then the others. Nothing where no two extruding layers in a row
    both changed (those terms are then in the slicer's file and the re-ordered one)."""
    ids = np.flatnonzero(has)
    c = changed[ids]
    pair = c[:-1] & c[1:]
    if not pair.any():
        return []
    out = []
    for parity in (0, 1):
        states = np.zeros(len(changed), np.int64)
        sel = ids[c & (np.arange(len(ids)) % 2 == parity)]
        states[sel] = 1
        out.append(states)
    return out
