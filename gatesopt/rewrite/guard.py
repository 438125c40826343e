"""The time guard (formulations/ordering.md, "Time guard"): per layer, which order the emitted
file prints -- the slicer's, the solver's, or the greedy one -- decided on what the planner model
says the emitted file takes.

A layer's re-ordering changes more than its own steps: where it ends moves the travel into the
next layer (the layer change), and where it starts moves the travel from the layer before. The
planner's time of the file is split at extrusions (``layer_parts_s``): per layer, ``inner`` (its
first extruding step to its last) and ``after`` (the steps from there to the next layer's first
extrusion: the layer change, which belongs to both layers). One stage of the guard has one state
per layer, s = 1 the candidate's order, s = 0 the base's (the slicer's, or an earlier stage's
answer):

    T = prefix + sum_k inner_k(s_k) + sum_k after_k(s_k, s_k+1)

and picks the states that minimise T (a shortest path over the layers, ``_best_states``) from
measured terms: the base's file gives every (0, 0) term, the candidate's file every (1, 1) term,
and two more emits (``_alternate``: changed layers alternately the base's) the (1, 0) and (0, 1)
terms of adjacent changed layers. Only the layers around those the candidate's file printed
slower are weighed (``open_layers``); every other re-ordered layer keeps the candidate's order
in each file measured, so those emits write again only the layers around the open ones.
Comparing layer by layer instead put back a layer whose new exit made the layer change shorter
-- a gain the next layer's time shows (measured: prusa25_star_rect15_m82 safe, 46 layers 44 ms
slower each, the next 71 ms faster).

The states are then emitted and measured; of every file measured (the base's, the candidate's,
the alternating ones, the chosen) the shortest print is the stage's answer: the planner's
look-ahead joins the terms with a hair of difference, and the answer is never slower than any
measured one, the base's included.

With a greedy solution beside the solver's (``emit_guarded(greedy=...)``, issue 36: never slower
than greedy), two stages run: the slicer's order against the greedy one (in the layers where the
greedy order may be taken), then that answer against the solver's. So the file returned is never
slower (planner model, up to ``GUARD_TOL_S`` per layer the look-ahead joins) than the slicer's,
than the greedy file as its own guard would return it, nor than the solver's.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..ordering import dp
from ..ordering.bounds import lower_bound
from ..ordering.chain import (BACKWARDS, KEPT, LOOKAHEAD_TO, anchor_at, anchor_before, end_of,
                              entry_positions, path_curves, quick_dp, reprove)
from ..ordering.emitter import emit
from ..ordering.layers import model_travel_mm
from ..ordering.problem import OPTIMAL_ABS_TOL, GroupSolution, OrderingProblem, OrderingSolution
from ..ordering.repair import REPAIRED
from ..limits import same_settings
from ..parse import parse
from ..planner import planned_durations_s
from ..program import Program
from ..solvers import Status

#: a layer counts as slower re-ordered only by more than this (s): the planner's look-ahead runs
#: across layers, so a layer whose own text did not change can differ by a hair where a moved
#: neighbour meets it
GUARD_TOL_S = 1e-3
#: where more than this share of the re-ordered layers is open (``open_layers``), the guard
#: weighs them all: prusa25_bunny_triangles15_lh01 free, the exact stage against greedy's file,
#: 142 of 165 layers open printed 0.53 s slower than all 165 weighed (bench/after_solve.py
#: --may-differ), while the emits spared are the few that were not open
OPEN_ALL_SHARE = 0.5
#: where each layer's order comes from in the guard's answer (``Guarded.source``)
FROM_SLICER, FROM_SOLVER, FROM_GREEDY = 0, 1, 2
#: the formulation a group printed in the greedy order is reported with (its status: at best
#: feasible, ``emit_guarded``)
GREEDY_TAKEN = "greedy (time guard)"


@dataclasses.dataclass(frozen=True, eq=False)
class Guarded:
    """What ``emit_guarded`` returns: the solution emitted (per layer the order the guard chose,
    each group with the answer printed), its text and parsed file, the layers the solver changed
    that keep the slicer's order because re-ordered they printed slower (``kept``), and per layer
    where its order comes from (``source``: ``FROM_SLICER``, ``FROM_SOLVER``, ``FROM_GREEDY``)."""

    solution: OrderingSolution
    text: str
    output: Program
    kept: np.ndarray
    source: np.ndarray
    #: per step, the planner's durations (``step_times_s``) of the input and of ``output``, where
    #: the guard planned them (the report's print times reuse them: ``figures.figures``), else None
    planned_s: tuple = (None, None)
    #: layers whose groups the repair pass solved again (``emit_guarded(repair=...)``): the
    #: solver's order was put back there although a group in it was proven optimal
    repaired: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    #: groups proven optimal on the model's costs whose layer prints the slicer's order (the
    #: planner found it faster, after any repair): reported with the path printed
    #: (``put_back_answer``), not as proven
    proofs_put_back: int = 0

    def __iter__(self):     # (solution, text, output, kept), as the guard returned it before
        return iter((self.solution, self.text, self.output, self.kept))

    @property
    def greedy_layers(self) -> int:
        """Layers printed in the greedy order (another order than the solver's)."""
        return int(np.count_nonzero(self.source == FROM_GREEDY))


def step_times_s(program: Program, options=None) -> np.ndarray:
    """Per step, its time under the planner model (``planner.plan``: acceleration, junction
    speeds, the file's machine limits, or those of ``options``, an ``OrderingOptions``: the
    family and printer the print is planned by): what the time guard and the report's print time
    use."""
    return planned_durations_s(program, options.limits_of(program) if options is not None else None)


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


def mix_layers(problem: OrderingProblem, base: OrderingSolution | None, solution: OrderingSolution,
               states, with_cost: bool = True) -> OrderingSolution:
    """Per layer, ``solution``'s order where ``states`` is 1, else ``base``'s (None: the slicer's
    order and direction); each group's answer from the solution its layer is taken from (from
    ``solution`` where ``base`` is None). A layer's curves are one contiguous block of the print
    order in every solution, at the same positions (curve numbers grow with the layer), so the
    blocks are taken whole."""
    pp = problem.program_problem
    n = pp.n_curves
    states = np.asarray(states, np.int64)
    take = states[pp.curve_layer] == 1          # per position (the slicer's: position = curve)
    for s in (base, solution):
        if s is not None and not np.array_equal(pp.curve_layer[s.curve_order], pp.curve_layer):
            raise ValueError("a solution whose layers are not contiguous blocks in layer order")
    if base is None:
        order, rev, seam = np.arange(n), np.zeros(n, bool), np.zeros(n, np.int64)
        groups = solution.groups
    else:
        order, rev, seam = base.curve_order, base.curve_reversed, base.curve_seam
        g_take = states[np.asarray(problem.group_layer, np.int64)] == 1
        groups = tuple(b if t else a for a, b, t in zip(base.groups, solution.groups, g_take))
    order = np.where(take, solution.curve_order, order)
    rev = np.where(take, solution.curve_reversed, rev)          # per curve: take is per layer too
    seam = np.where(take, solution.curve_seam, seam)
    mixed = dataclasses.replace(solution, curve_order=order, curve_reversed=rev, curve_seam=seam,
                                groups=groups)
    return with_model_cost(problem, mixed) if with_cost else mixed


def with_model_cost(problem: OrderingProblem, solution: OrderingSolution) -> OrderingSolution:
    """``solution`` with its model travel and cost (``travel_after_mm``, ``cost_after``) figured
    for its own order (``mix_layers`` without them: the guard's measured files need neither)."""
    pp = problem.program_problem
    order, rev, seam = solution.curve_order, solution.curve_reversed, solution.curve_seam
    return dataclasses.replace(solution, travel_after_mm=model_travel_mm(pp, order, rev, seam),
                               cost_after=pp.order_cost(order, rev, seam))


def keep_layers(problem: OrderingProblem, solution: OrderingSolution, layers) -> OrderingSolution:
    """``solution`` with the curves of ``layers`` back in the slicer's order and direction."""
    pp = problem.program_problem
    n_layers = int(pp.curve_layer.max()) + 1 if pp.n_curves else 0
    states = np.ones(n_layers, np.int64)
    states[np.asarray(layers, np.int64)] = 0
    return mix_layers(problem, None, solution, states)


def differing_layers(problem: OrderingProblem, a: OrderingSolution | None,
                     b: OrderingSolution | None, n_layers: int | None = None) -> np.ndarray:
    """(n_layers,) bool: layers whose curves ``a`` and ``b`` print in another order, direction or
    from another seam (None: the slicer's order)."""
    pp = problem.program_problem
    n = pp.n_curves
    L = max(n_layers or 0, int(pp.curve_layer.max()) + 1 if n else 0)

    def arrays(s):
        if s is None:
            return np.arange(n), np.zeros(n, bool), np.zeros(n, np.int64)
        return (np.asarray(s.curve_order, np.int64), np.asarray(s.curve_reversed, bool),
                np.asarray(s.curve_seam, np.int64))
    (oa, ra, sa), (ob, rb, sb) = arrays(a), arrays(b)
    out = np.zeros(L, bool)
    # positions hold the same layer in both (``mix_layers``), and a curve's layer is its own
    out[np.unique(pp.curve_layer[(oa != ob) | (ra != rb) | (sa != sb)])] = True
    return out


def changed_layers(problem: OrderingProblem, solution: OrderingSolution) -> np.ndarray:
    """(n_layers,) bool: layers whose curves ``solution`` prints in another order, direction or
    from another seam than the slicer."""
    return differing_layers(problem, None, solution)


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


def _best_states(terms: _Terms, has: np.ndarray, changed: np.ndarray,
                 on: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The states (1: re-ordered) of the extruding layers that minimise T over the measured terms
    (a layer that did not change is 0, a layer of ``on`` is 1; an unmeasured combination is not
    chosen), and that T. Ties go to the re-ordered state."""
    inner, after, prefix = terms.arrays()
    ids = np.flatnonzero(has)
    inner = np.where(np.isnan(inner), np.inf, inner)
    after = np.where(np.isnan(after), np.inf, after)
    allowed = np.ones((len(ids), 2), bool)
    allowed[:, 1] = changed[ids]
    if on is not None:
        allowed[:, 0] = ~on[ids]
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


@dataclasses.dataclass(frozen=True, eq=False)
class _Measured:
    """An emitted file: the solution, its text, the parsed file and its step times (planner)."""

    solution: OrderingSolution | None
    text: str
    output: Program
    durations_s: np.ndarray

    @property
    def total_s(self) -> float:
        return float(self.durations_s.sum())


def _stage(program: Program, problem: OrderingProblem, base: _Measured, solution: OrderingSolution,
           changed: np.ndarray, emitted) -> tuple[_Measured, np.ndarray]:
    """One stage (module docstring): per layer ``base``'s order (0) or ``solution``'s (1), where
    ``changed`` (the layers in which they differ). Returns the fastest file measured, never slower
    than ``base``'s beyond ``GUARD_TOL_S``, and its states."""
    L = program.n_layers
    changed = np.concatenate((changed[:L], np.zeros(max(0, L - len(changed)), bool)))
    zero = np.zeros(L, np.int64)
    if not changed.any():
        return base, zero

    def measured(states) -> _Measured:
        sol = mix_layers(problem, base.solution, solution, states, with_cost=False)
        text, out = emitted(sol)
        return _Measured(sol, text, out, step_times_s(out, problem.options))
    states1 = changed.astype(np.int64)
    first = measured(states1)
    if first.output.n_layers != L:
        return first, states1           # (the layers no longer line up: no guard)
    slower = (layer_times_s(first.output, first.durations_s)
              > layer_times_s(base.output, base.durations_s) + GUARD_TOL_S)
    if not slower.any():
        return first, states1
    p0 = layer_parts_s(base.output, base.durations_s)
    p1 = layer_parts_s(first.output, first.durations_s)
    tried = [(first.total_s, 1, first, states1)]
    if p0 is not None and p1 is not None:
        has = (p0[0] > 0) | (p0[1] > 0) | changed
        open_ = open_layers(changed, has, slower)
        kept_on = changed & ~open_          # re-ordered in every file this stage measures
        terms = _Terms(L)
        terms.add(p0, zero, has)
        terms.add(p1, states1, has)
        for states in _alternate(open_, has, on=kept_on):
            m = measured(states)
            tried.append((m.total_s, 2, m, states))
            parts = layer_parts_s(m.output, m.durations_s) if m.output.n_layers == L else None
            if parts is not None:
                terms.add(parts, states, has)
        states, _ = _best_states(terms, has, changed, on=kept_on)
        if not np.array_equal(states, states1):
            m = measured(states)
            tried.append((m.total_s, 0, m, states))
    best = min(tried, key=lambda x: (x[0], x[1]))
    if best[0] <= base.total_s + GUARD_TOL_S:
        return best[2], best[3]
    return base, zero       # every state measured prints slower than the base: its order throughout


def _repair_stage(program: Program, problem: OrderingProblem, base: _Measured,
                  solution: OrderingSolution, changed: np.ndarray, emitted) -> _Measured:
    """The repair pass's stage: ``solution`` (``base``'s order but in ``changed``) measured in at
    most two emits, where ``_stage`` takes up to five. Its file is taken if no layer of it prints
    slower than in ``base``'s (beyond ``GUARD_TOL_S``) and the whole no slower; else the file
    with only the changed layers that printed no slower, with the layer after them no slower
    either (the layer change belongs to both), taken on the same terms; else ``base``'s."""
    L = program.n_layers
    changed = np.concatenate((changed[:L], np.zeros(max(0, L - len(changed)), bool)))
    if not changed.any():
        return base
    t0 = layer_times_s(base.output, base.durations_s)

    def measured(states):
        sol = mix_layers(problem, base.solution, solution, states, with_cost=False)
        text, out = emitted(sol)
        m = _Measured(sol, text, out, step_times_s(out, problem.options))
        if out.n_layers != L:
            return m, None
        return m, layer_times_s(out, m.durations_s)

    def taken(m, t1):
        return (t1 is not None and np.all(t1 <= t0 + GUARD_TOL_S)
                and m.total_s <= base.total_s + GUARD_TOL_S)
    first, t1 = measured(changed.astype(np.int64))
    if taken(first, t1):
        return first
    if t1 is None:
        return base
    ok = changed & (t1 <= t0 + GUARD_TOL_S)
    ok[:-1] &= t1[1:] <= t0[1:] + GUARD_TOL_S
    if not ok.any() or np.array_equal(ok, changed):
        return base
    second, t2 = measured(ok.astype(np.int64))
    return second if taken(second, t2) else base


def greedy_taken(gs: GroupSolution) -> GroupSolution:
    """A greedy answer printed by the guard in a group entered otherwise than greedy's chain
    entered it, its status as ``printed_answer`` made it: formulation ``GREEDY_TAKEN``."""
    form = gs.formulation if gs.formulation.startswith("kept") else GREEDY_TAKEN
    return GroupSolution.make(gs.order, gs.objective, gs.bound, gs.status, gs.solve_s, form)


def printed_answer(problem: OrderingProblem, final: OrderingSolution, g: int, gs: GroupSolution,
                   entered_alike: bool, first: np.ndarray,
                   exited_alike: bool = True) -> GroupSolution:
    """Group g's answer ``gs`` as ``final`` prints it: as it was where the group is entered as the
    chain that proved it entered it (``same_entry_groups``) and the next group is entered there
    as in that chain (``same_next_entries``: a path proven for the next group's entry as its end
    -- ``ordering.settle`` -- holds only there), or where it is not proven, or where its proof
    is split with its neighbour (``+back``) or made on the printed file's entry (``+joined``);
    else proven again from where ``final`` enters it (``chain.reprove``: the subset DP where it
    is quick, else at best feasible), for its own end (free, a fixed group's entry, the file's
    end) or, failing that, for the next group's entry as printed. A group entered alike whose
    next group is entered otherwise keeps a proof the subset DP cannot check quickly unless it
    was made for the next group's entry (the slicer's order taken for it, a look-ahead path).
    ``first``: ``chain.entry_positions`` of ``final``."""
    if (gs.status != Status.OPTIMAL or gs.formulation.endswith((BACKWARDS, REPAIRED))
            or (entered_alike and exited_alike)):
        return gs
    start = anchor_before(problem, final, int(first[g]))
    end = end_of(problem, g)
    if entered_alike and not quick_dp(problem.group(g, start, end)) and not any(s in gs.formulation for s in (KEPT, LOOKAHEAD_TO)):
        return gs           # (proven for its own end: the next group's entry does not matter)
    got = reprove(problem, g, start, end, gs)
    n = len(final.curve_order)
    if (got.status != Status.OPTIMAL and end is None and g + 1 < problem.n_groups
            and first[g + 1] < n):
        to_next = reprove(problem, g, start, anchor_at(problem, final, int(first[g + 1])), gs)
        if to_next.status == Status.OPTIMAL:
            return to_next
    return got


def printed_path(problem: OrderingProblem, final: OrderingSolution, g: int, grp,
                 first: np.ndarray) -> np.ndarray | None:
    """Group g's path as ``final`` prints it, in ``grp``'s candidates (``problem.group(g, ...)``):
    its curves from position ``first[g]`` on, each with the candidate of its direction and seam;
    None where ``final`` does not print the group's curves there as one run."""
    n = grp.n_curves
    at = int(first[g])
    curves = path_curves(problem, g, grp, np.arange(len(grp.cand_curve)))
    cand = {(int(c), bool(r), int(s)): k for k, (c, r, s) in
            enumerate(zip(curves, np.asarray(grp.cand_reversed, bool), np.asarray(grp.cand_seam)))}
    order = np.asarray(final.curve_order, np.int64)[at:at + n]
    if len(order) != n:
        return None
    rev = np.asarray(final.curve_reversed, bool)[order]
    seam = np.asarray(final.curve_seam, np.int64)[order]
    path = [cand.get((int(c), bool(r), int(s))) for c, r, s in zip(order, rev, seam)]
    return None if any(k is None for k in path) else np.asarray(path, np.int64)


def put_back_answer(problem: OrderingProblem, final: OrderingSolution, g: int, gs: GroupSolution,
                    first: np.ndarray) -> GroupSolution:
    """Group g's answer where ``final`` prints its layer in the slicer's order although ``gs``
    (a proven path) is another one: the printed path, priced from where ``final`` enters it to
    its own end (``end_of``), optimal only where the subset DP finds it an optimum there
    (``chain.quick_dp``), else feasible with the DP's optimum or the cheap bound
    (``bounds.lower_bound``) as its bound; formulation ``gs``'s + ``KEPT``. ``gs`` itself where
    ``final`` prints ``gs``'s path."""
    grp = problem.group(g, anchor_before(problem, final, int(first[g])), end_of(problem, g))
    path = printed_path(problem, final, g, grp, first)
    if path is None or np.array_equal(path, gs.order):
        return gs
    cost = grp.path_cost(path)
    bound = dp.solve(grp).objective if quick_dp(grp) else lower_bound(grp)
    status = Status.OPTIMAL if cost - bound <= OPTIMAL_ABS_TOL else Status.FEASIBLE
    form = gs.formulation if gs.formulation.endswith(KEPT) else gs.formulation + KEPT
    return GroupSolution.make(path, cost, min(bound, cost), status, gs.solve_s, form)


def same_next_entries(problem: OrderingProblem, a: OrderingSolution,
                      b: OrderingSolution) -> np.ndarray:
    """(n_groups,) bool: groups after which ``a`` and ``b`` enter the next group alike -- its
    first curve printed is the same curve, in the same direction, from the same seam (True for
    the last group, and where the next group prints nothing in either)."""
    (ca, ra, sa), (cb, rb, sb) = _first_curves(problem, a), _first_curves(problem, b)
    same = (ca == cb) & (ra == rb) & (sa == sb)
    return np.append(same[1:], True) if len(same) else same


def _first_curves(problem: OrderingProblem, s: OrderingSolution):
    """Per group the curve ``s`` prints first (-1: none), whether reversed, its seam."""
    n = problem.program_problem.n_curves
    order = np.asarray(s.curve_order, np.int64)
    p = entry_positions(problem, s)
    c = np.where(p < n, order[np.minimum(p, max(n - 1, 0))], -1) if n else np.full(len(p), -1)
    cc = np.maximum(c, 0)
    rev = np.where(c >= 0, np.asarray(s.curve_reversed, bool)[cc], False) if n else c >= 0
    seam = np.where(c >= 0, np.asarray(s.curve_seam, np.int64)[cc], 0) if n else c * 0
    return c, rev, seam


def same_entry_groups(problem: OrderingProblem, a: OrderingSolution,
                      b: OrderingSolution) -> np.ndarray:
    """(n_groups,) bool: groups that ``a`` and ``b`` enter alike -- the curve printed before the
    group's first one is the same curve, printed in the same direction from the same seam (or
    none: the file's first curve). Such a group starts where it starts in the other: where it
    prints ``b``'s path and ``b``'s solver proved that path for this start (and for the end it
    had: the next fixed group's entry, the file's end, or free -- the same in every solution for
    a chain solved forward), the proof stands. Inside a layer printed whole from one solution
    only a layer's first group can be entered otherwise (``mix_layers``)."""
    n = problem.program_problem.n_curves

    def entry(s):
        order = np.asarray(s.curve_order, np.int64)
        p = entry_positions(problem, s) - 1
        p = np.where(p < n - 1, p, -1)          # (an empty group: no entry)
        c = np.where(p >= 0, order[np.maximum(p, 0)], -1) if n else np.full(len(p), -1)
        cc = np.maximum(c, 0)
        rev = np.where(c >= 0, np.asarray(s.curve_reversed, bool)[cc], False) if n else c >= 0
        seam = np.where(c >= 0, np.asarray(s.curve_seam, np.int64)[cc], 0) if n else c * 0
        return c, rev, seam
    (ca, ra, sa), (cb, rb, sb) = entry(a), entry(b)
    return (ca == cb) & (ra == rb) & (sa == sb)


def layers_of_groups(problem: OrderingProblem, groups, n_layers: int) -> np.ndarray:
    """(n_layers,) bool: layers holding one of ``groups`` (group indices)."""
    out = np.zeros(n_layers, bool)
    lay = np.asarray(problem.group_layer, np.int64)[np.asarray(groups, np.int64)]
    out[lay[lay < n_layers]] = True
    return out


def proven_layers(problem: OrderingProblem, solution: OrderingSolution, n_layers: int) -> np.ndarray:
    """(n_layers,) bool: layers holding a re-orderable group ``solution`` proved optimal."""
    return layers_of_groups(problem, [g for g, gs in enumerate(solution.groups)
                                      if problem.group_reorderable[g] and gs.status == Status.OPTIMAL],
                            n_layers)


def emit_guarded(program: Program, problem: OrderingProblem, solution: OrderingSolution,
                 time_guard: bool = True, greedy: OrderingSolution | None = None,
                 greedy_layers=None, repair=None) -> Guarded:
    """Emit and re-parse ``solution``; with ``time_guard``, per layer the order the planner model
    says prints fastest (module docstring): the slicer's where the re-ordered layer does not pay
    for itself, and, with ``greedy`` (a greedy solution of the same problem), the greedy order in
    the layers of ``greedy_layers`` ((n_layers,) bool; None: every layer) where it prints faster.
    A group printed in the greedy order is reported with its greedy answer: proven where greedy
    proved it and it is entered as in greedy's chain (``same_entry_groups``), else at best
    "feasible" (``GREEDY_TAKEN``).

    ``repair`` (the repair pass, formulations/ordering.md "Time guard"): called as
    ``repair(printed, layers)`` with the solution printed so far and the layers where the
    solver's order was not printed although a group in it was proven optimal (the model and the
    planner disagree there); it returns ``printed`` with those layers' groups solved again on
    costs that agree with the planner (``ordering.repair.resolve_layers``), or None. One more
    stage then measures that answer against the printed file (never slower than it), and in
    those layers the solver's answer is the repaired one (its groups' status on those costs),
    printed or not."""
    memo: dict = {}                     # layers that did not change are not emitted again
    L = program.n_layers

    def emitted(sol):
        text = emit(program, problem, sol, memo)
        out = parse(text, source=f"{program.source} (re-ordered)")
        same_settings(out, program)         # its printer's facts and settings: the input's
        return text, out
    if not time_guard:
        text, out = emitted(solution)
        return Guarded(solution, text, out, np.zeros(0, np.int64), np.full(L, FROM_SOLVER))
    # a safety net: the time objective prices each travel as emitted (cost.py), but not every
    # junction of the planner (formulations/ordering.md, "Time guard")
    own = problem.pricer.planned_steps_s(program) if problem.pricer is not None else None
    slicer = _Measured(None, "", program,
                       own if own is not None else step_times_s(program, problem.options))
    base = slicer
    if greedy is not None:
        may = np.ones(L, bool) if greedy_layers is None else np.asarray(greedy_layers, bool)[:L]
        base, _ = _stage(program, problem, slicer, greedy, changed_layers(problem, greedy)[:L] & may,
                         emitted)
    best, _ = _stage(program, problem, base, solution,
                     differing_layers(problem, base.solution, solution, L), emitted)
    repaired = np.zeros(0, np.int64)
    proved = solution       # the chain the solver's proofs were made in (before any repair)
    if repair is not None:
        lost = (differing_layers(problem, best.solution, solution, L)[:L]
                & changed_layers(problem, solution)[:L] & proven_layers(problem, solution, L))
        if lost.any():
            printed = (best.solution if best.solution is not None else
                       mix_layers(problem, None, solution, np.zeros(L, np.int64), with_cost=False))
            cand = repair(printed, np.flatnonzero(lost))
            if cand is not None:
                # the layers solved again: those whose groups got new answers (a layer the
                # repair had no time for keeps ``printed``'s, the same objects)
                new = [g for g, (a, b) in enumerate(zip(printed.groups, cand.groups)) if a is not b]
                done = layers_of_groups(problem, new, L) & lost
                best = _repair_stage(program, problem, best, cand,
                                     differing_layers(problem, best.solution, cand, L) & done,
                                     emitted)
                # in those layers the solver's answer is the repaired one, printed or not
                solution = dataclasses.replace(
                    mix_layers(problem, solution, cand, done.astype(np.int64), with_cost=False),
                    cost_after=solution.cost_after, travel_after_mm=solution.travel_after_mm)
                repaired = np.flatnonzero(done)
    planned = (slicer.durations_s, best.durations_s)
    if best.solution is None:
        # the slicer's file throughout: emitted as the solution with every layer put back
        sol = keep_layers(problem, solution, np.arange(L))
        best = _Measured(sol, *emitted(sol), slicer.durations_s)
        planned = (slicer.durations_s, None)     # (that text was not planned: its own plan)
    # per layer where its order comes from, by what it prints: the solver's answer wherever the
    # layer prints it (also where that is the slicer's or the greedy order)
    final = best.solution
    same = ~differing_layers(problem, final, solution, L)[:L]
    source = np.where(same, FROM_SOLVER, FROM_SLICER)
    glay = np.asarray(problem.group_layer, np.int64)
    # the solver's proofs stand in the groups it prints entered as its chain entered them (a
    # layer after one put back or printed in greedy's order may start from another curve), and
    # left for the next group's entry as its chain left them (a proof made for that entry); not
    # checked: a path solved backwards (its start free) and a repaired one (solved from
    # ``printed``'s entry). A layer put back: its answers are what it prints (``put_back_answer``)
    put_back = source[glay] != FROM_SOLVER
    # (entries compared with the chain the proofs were made in: a layer repaired before a group
    # moves its start even where the file prints the repaired layer; the repaired groups
    # themselves are proven on the printed entry, ``+joined``)
    entered = same_entry_groups(problem, final, proved) | put_back
    exited = same_next_entries(problem, final, proved) | put_back
    first = entry_positions(problem, final)
    groups = tuple(printed_answer(problem, final, g, gs, a, first, x)
                   for g, (gs, a, x) in enumerate(zip(solution.groups, entered, exited)))
    if greedy is not None:
        source[~same & ~differing_layers(problem, final, greedy, L)[:L]] = FROM_GREEDY
        at = source[glay] == FROM_GREEDY
        # greedy's proofs stand in the groups entered as in greedy's chain
        alike = same_entry_groups(problem, final, greedy)
        left_alike = same_next_entries(problem, final, greedy)
        decided = problem.group_reorderable
        # (entered alike but the next group otherwise: greedy's answer, proven again where a
        # proof for the next group's entry could no longer hold, under greedy's own name)
        def greedys(g, gg, a, x):
            if a and x:
                return gg
            got = printed_answer(problem, final, g, gg, a, first, x)
            return got if a else greedy_taken(got)
        groups = tuple((greedys(g, gg, a, x) if d else gg) if t else gs
                       for g, (gs, gg, t, d, a, x) in enumerate(zip(groups, greedy.groups, at,
                                                                    decided, alike, left_alike)))
    # a proof in a layer printed in the slicer's order (the planner found it faster, after the
    # repair pass) is the model's, not the print's: the slicer's path stands in its place, proven
    # only where it is an optimum itself (issue 36: no "proven optimal" group reverted)
    slicers = source[glay] == FROM_SLICER
    printed = tuple(put_back_answer(problem, final, g, gs, first)
                    if s and problem.group_reorderable[g] and gs.status == Status.OPTIMAL else gs
                    for g, (gs, s) in enumerate(zip(groups, slicers)))
    n_put_back = sum(a is not b for a, b in zip(printed, groups))
    groups = printed
    sol = dataclasses.replace(with_model_cost(problem, final), groups=groups,
                              formulation=solution.formulation, solve_s=solution.solve_s)
    kept = np.flatnonzero(changed_layers(problem, solution)[:L] & (source == FROM_SLICER))
    return Guarded(sol, best.text, best.output, kept, source, planned, repaired, n_put_back)


def open_layers(changed: np.ndarray, has: np.ndarray, slower: np.ndarray) -> np.ndarray:
    """The re-ordered layers whose state the guard weighs (``_stage``): those the candidate's
    file printed slower than the base's (beyond ``GUARD_TOL_S``) and the re-ordered extruding
    layers next to a slower layer, re-ordered or not: its entry is the layer before's exit, its
    exit the next one's entry (the layer change belongs to both). The other re-ordered layers
    keep the candidate's order in every file the stage measures, so that each emit after the
    first writes again only the layers around the open ones (the emitter's memo has the rest).
    Every re-ordered layer where none is open (a slower layer without a re-ordered neighbour:
    the look-ahead's hair past ``GUARD_TOL_S``) or where more than ``OPEN_ALL_SHARE`` of them
    are: the emits then save little, and the shortest path has every state to choose from."""
    ids = np.flatnonzero(has)
    if not len(ids):
        return changed.copy()
    # a slower layer without extrusion belongs to the extruding layers on either side of it
    at = np.minimum(np.searchsorted(ids, np.flatnonzero(slower)), len(ids) - 1)
    near = np.zeros(len(ids), bool)
    for d in (-1, 0, 1):
        near[np.clip(at + d, 0, len(ids) - 1)] = True
    open_ = np.zeros(len(changed), bool)
    open_[ids[near]] = True
    open_ &= changed
    n_open = int(np.count_nonzero(open_))
    return open_ if 0 < n_open <= OPEN_ALL_SHARE * np.count_nonzero(changed) else changed.copy()


def _alternate(changed: np.ndarray, has: np.ndarray, on: np.ndarray | None = None):
    """The states that measure the (1, 0) and (0, 1) terms of adjacent re-ordered layers: every
    other one of ``changed`` put back, then the others; the layers of ``on`` re-ordered in both.
    Nothing where no layer of ``changed`` lies next to a re-ordered extruding layer (those terms
    are then in the slicer's file and the re-ordered one)."""
    ids = np.flatnonzero(has)
    on = np.zeros(len(changed), bool) if on is None else on
    c = changed[ids]
    moved = c | on[ids]
    pair = moved[:-1] & moved[1:] & (c[:-1] | c[1:])
    if not pair.any():
        return []
    out = []
    for parity in (0, 1):
        states = on.astype(np.int64)
        sel = ids[c & (np.arange(len(ids)) % 2 == parity)]
        states[sel] = 1
        out.append(states)
    return out
