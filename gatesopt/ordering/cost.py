"""Travel priced as printed (issue 36; formulations/ordering.md, "Cost model"): the time the travel
between two curves takes as ``emitter.emit`` writes it.

A link from curve u (left at its exit) to curve v (entered at its entry) is emitted one of two ways:

- *copied*: v is the curve the slicer printed after u and both are printed as the slicer printed
  them, so the slicer's own gap is copied (its wipe, retraction, z-hop, combing path): the link
  costs that gap's time, ``TimePricer.copy_ms[v]``;
- *reversed* (``gaps.reversed_gap``): u is the curve the slicer printed after v, left where the
  gap between them ended and v entered where it began, and that gap is pure travel
  (``gaps.ReversibleGaps``): it is written backwards and costs its own time, ``copy_ms[u]``, as
  the copied link the other way round does (plus the E move of a net E v's entry consumes);
- *rebuilt* (``gaps.rebuilt_gap``): retract (if ``travel.TravelRule.retracts`` says so), lift,
  one straight travel, lower, unretract, plus the net E of the slicer's gaps it consumes (a prime
  the slicer added). Its time is the sum of those moves' times.

Every move is priced by ``MoveTimes``: a trapezoidal velocity profile (the planner model's move,
``planner.py``: accelerate at a, cruise, decelerate) between two junction speeds, with the
acceleration, speed caps and junction speed of its kind (XY travel, extruder-only, Z-only, a
wipe) from the file's machine limits (``limits.machine_limits``). A link's cost is therefore a
sum of move times, the same function that prices the moves of an emitted gap
(``MoveTimes.steps_s``), so the cost the solver optimises is what the emitted travels cost under
that model (tests/test_ordering_cost.py checks it on emitted files). The costs are in ms.

The cost is asymmetric where a copied gap cannot be reversed (a wipe, a state line, firmware
retraction in it: priced one way only), and a rebuilt link's E moves depend on the gaps of the
curve it enters; by default a link is also joined to the curves around it, a reversed candidate
carries its curve's change of time and a reversed gap is planned backwards (``TimePricer``,
formulations/ordering.md "Joined to the curves"): direction dependent under classic jerk and for
arcs. It breaks the triangle inequality where a long link retracts and two short ones do not.
formulations/ordering.md says which bounds rely on what.
"""
from __future__ import annotations

import weakref
from functools import partial

import numba
import numpy as np

from ..limits import MachineLimits, machine_limits
from ..program import Program
from .gap_plan import (JOINED_MAX_MOVES, MOVE_EPS_MM, W_COLS, W_J, W_JREADY, e_row, end_side,
                       junction, regime_rows, reversed_gap_times_ms, same_z_s)
from .candidates import one_way
from .curve_time import CurveEnds, gap_rows
from .file_end import FileEnd
from .gaps import GapFacts, ReversibleGaps
from .layout import Layout
from .move_times import MT_CODE, MoveTimes, trapezoid_one_s
from .._planner_kernel import JERK, SCV
from .problem import DENSE_MAX_CANDS, FILE_END, Anchor, Group, LinkCosts, OrderingProblem
from .link_cost import link_one, reversed_link, reversed_ms
from .travel import TravelRule, cross_one
from .wipes import SlicerWipes

MS_PER_S = 1000.0


def gap_times_ms(program: Program, move: MoveTimes, lay: Layout | None = None) -> np.ndarray:
    """(n_curves - 1,) the time (ms) of each gap between two consecutive curves of ``program``
    (``layout.layout``'s curves) under ``move``: what a re-ordered file's travels cost under the
    time objective's model, measured on the file itself (tests/test_ordering_cost.py compares it
    with the solver's cost of the order it emitted)."""
    from .layout import layout
    lay = lay or layout(program)
    n = len(lay.curve_s0)
    if n < 2:
        return np.zeros(0)
    return move.gaps_s(program, lay.curve_s1[:-1], lay.curve_s0[1:]) * MS_PER_S


def reversal_symmetric(code: int) -> bool:
    """Whether the planner's junction rule ``code`` (``_planner_kernel.JUNCTION_CODE``) gives a
    move sequence run backwards (order and directions reversed) the same time: Klipper's
    (``toolhead.py`` ``Move.calc_junction``: the junction's limits are symmetric in the two
    moves, accelerations are symmetric trapezoids, the smoothed look-ahead accelerates and
    decelerates at one ``accel_to_decel``); not Marlin's classic jerk (``planner.cpp``: the
    exit speeds scaled to the smaller nominal speed, the entered block's safe speed) nor its
    junction deviation (the entered block's acceleration, the entered move's length in
    ``JD_HANDLE_SMALL_SEGMENTS``)."""
    return code == SCV


def joins(policy: str, code: int) -> bool:
    """Whether links are joined to the curves' moves (``OrderingOptions.joined_links``) under
    the junction rule ``code``: "symmetric" under every rule but Marlin's classic jerk (where a
    joined link and its mirror differ by its junction rule, not by the print: measured on
    cura413_star_triangles20 89 % of the mirrored pairs, 1.6 ms apart on average, up to 10 ms,
    and the symmetric model, which relaxes each edge to the cheaper direction, proved 0 of its
    99 groups against 95 unjoined)."""
    return policy == "all" or (policy == "symmetric" and code != JERK)


class TimePricer:
    """The time objective's link costs for one Program-built problem (module docstring).

    Arrays per problem curve: ``group_first`` (first curve of its group: a link into a curve of
    another group consumes that group's boundary gap, as ``emitter`` does), ``z_entry`` /
    ``z_exit``, ``layer``; the slicer's gaps (``GapFacts``) and ``copy_ms`` (each gap's time,
    copied). ``rule``: when a rebuilt travel retracts (shared with the emitter)."""

    def __init__(self, program: Program, lay: Layout, problem: OrderingProblem, rule: TravelRule,
                 move: MoveTimes, step_s: np.ndarray | None = None,
                 limits: MachineLimits | None = None, step_plan=None, ends=None):
        """``step_s``: per step of ``program``, the time a copied gap's steps take (the
        planner's, ``OrderingOptions.copied_gaps``); None: each move priced by ``move``.
        ``limits``: the file's (None: read here where needed). ``step_plan``: the
        ``planner.Plan`` ``step_s`` came from: the links are then joined to the curves
        (``ends``: ``curve_time.CurveEnds`` of these curves, None: made here)."""
        self.rule, self.move = rule, move
        style = rule.style
        self.style_vec = np.array([style.retract_feed_mm_s, style.unretract_feed_mm_s,
                                   style.travel_feed_mm_s, style.z_feed_mm_s, style.hop_mm], float)
        self.move_vec = move.vector()
        n = problem.n_curves
        gidx = np.repeat(np.arange(problem.n_groups), np.diff(problem.group_curve_start))
        self.group_first = problem.group_curve_start[gidx].astype(np.int64)
        self.layer = problem.curve_layer.astype(np.int64)
        self.z_entry = program.start_mm[lay.curve_s0, 2].astype(float) if n else np.zeros(0)
        self.z_exit = program.end_mm[lay.curve_s1 - 1, 2].astype(float) if n else np.zeros(0)
        facts = GapFacts.of(program, lay)
        self.own = facts
        gf = self.group_first
        self.bnd = GapFacts(facts.net_e[gf], facts.retract_mm[gf], facts.fw_net[gf],
                            facts.fw_retracted[gf])
        # each gap's time as the slicer wrote it (copied when both neighbours stay as they were)
        copy = np.zeros(n)
        if n > 1:
            a, b = lay.curve_s1[:-1], lay.curve_s0[1:]
            if step_s is None:
                copy[1:] = move.gaps_s(program, a, b)
            else:
                steps = np.concatenate([np.arange(x, y) for x, y in zip(a.tolist(), b.tolist())])
                owner = np.repeat(np.arange(1, n), b - a)
                copy = np.bincount(owner, weights=np.asarray(step_s)[steps], minlength=n)
        self.copy_ms = copy * MS_PER_S
        #: gaps a link may write reversed, at their own time (``gaps.ReversibleGaps``)
        self.reversible = ReversibleGaps.of(program, lay)
        #: per curve, what printing it backwards adds to its own moves' time (ms; 0 for loops,
        #: whose candidates move the seam): every link into a reversed candidate carries it
        #: (``curve_time.reversed_extra_ms``)
        #: and the moves of each curve a link joins its own to (``curve_time.CurveEnds``): a
        #: rebuilt link is planned with the last move of the curve it leaves and the first of
        #: the curve it enters, less what they take in their curves planned alone; a copied
        #: gap costs, besides its steps, what the slicer's file spends on those two moves beyond
        #: that (``CurveEnds.context_ms``), so both price the same quantity
        #: -- with the copied gaps at the planner's time (``step_plan``); priced move by move
        #: (``copied_gaps="moves"``) every link is its moves alone, from and to rest
        self.closed = np.asarray(problem.curve_closed, np.bool_)
        #: -- which links are joined: ``OrderingOptions.joined_links`` (``joins``)
        code = move.junction_code
        planned = bool(n) and code >= 0 and step_plan is not None
        joined = planned and joins(problem.options.joined_links, code)
        lim = limits if limits is not None or not planned else machine_limits(program)
        if not planned:
            ends = CurveEnds.empty(n)
        elif ends is None:
            ends = CurveEnds.of(program, lim, lay.curve_s0, lay.curve_s1, problem.curve_closed)
        #: the curves' boundary moves and times (``CurveEnds``), made wherever the moves are
        #: planned: a reversed curve's ``node_ms`` is priced joined or not (ArcWelder arcs under
        #: classic jerk: up to 140 ms, real_prusa240); the links join them where ``joined``
        self.ends, self.joined = ends, bool(joined)
        self.step_plan, self.limits = step_plan, lim     # (for ``repair.planner_priced``)
        # the program planned (``planned_steps_s``); not sent to a helper process (__getstate__)
        self._planned = weakref.ref(program) if step_plan is not None else None
        self.node_ms = ends.node_ms
        #: the limits a rebuilt link's moves run under: those in force at the slicer's last
        #: travel in the gap before the curve it enters (``layout.link_travel_steps``; the
        #: emitter re-issues them before the travel, wherever they were stated: PrusaSlicer's
        #: ``M204 S`` for travels, Orca's per-feature ``SET_VELOCITY_LIMIT``, written after a
        #: wall in the gap after it), row ``gap_row[c]`` of ``row_table``, joined or not; with
        #: the copied gaps priced move by move, the file's first (``MoveTimes.limits_row``)
        self.row_table = np.asarray(move.limits_row, float).reshape(1, -1)
        self.gap_row = np.zeros(n, np.int64)
        if planned:
            table, row = gap_rows(program, lay, lim)
            # one row per distinct set of limits (a file that restates them per feature, as
            # Orca's SET_VELOCITY_LIMIT, has thousands of regimes and a handful of values): the
            # same prices, and ``_dense`` mirrors and prepares per distinct row
            key = np.nan_to_num(table, nan=-1.0, posinf=-2.0, neginf=-3.0)
            _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
            self.row_table = np.ascontiguousarray(table[first])
            self.gap_row = np.asarray(inv, np.int64).ravel()[row]
        #: the junction rule is the same run backwards (``reversal_symmetric``): a joined link
        #: between open curves and its mirror are one price (``_dense`` prices them once)
        self.mirror_joined = joined and reversal_symmetric(code)
        #: per curve: its boundary moves printed backwards are its boundary moves run backwards
        #: (``CurveEnds.reversal_ok``; not so where one is an arc Klipper chords from its own
        #: start, the chords then differ); never a curve printed one way only (a loop, a
        #: one-way curve: ``candidates``), which has no reversal to mirror
        self.mirror_ok = (ends.reversal_ok() & ~self.closed & ~one_way(problem)
                          if self.mirror_joined else np.zeros(n, bool))
        #: each curve's wipe, written first by a rebuilt travel that leaves it retracting
        self.wipes = SlicerWipes.of(program, lay, problem.curve_closed)
        self.gap_ms = self.copy_ms.copy()
        #: a reversed gap's link: ``gap_ms`` where the curves are not joined, else its moves
        #: backwards planned with the curves' (``gap_plan.reversed_gaps_ms``)
        self.rev_ms = self.gap_ms
        if n > 1 and joined and ends.ok.any():
            head, tail = ends.context_ms(step_plan)
            self.copy_ms[1:] += tail[:-1] + head[1:]
            self.rev_ms = reversed_gap_times_ms(program, lay, self.reversible.ok, self.ends_args(),
                                                move.junction_code, move.limits_row)
            if self.mirror_joined:
                # a gap between two open curves written backwards, left from the one reversed
                # into the other reversed, is the copied link's moves run backwards: under a
                # rule the same both ways its time is the copied gap's in the file (the
                # planner's, look-ahead beyond the two boundary moves included), the price of
                # its mirror, the copied link (``reversed_gaps_ms`` would plan it with the two
                # boundary moves only: up to ~0.5 ms apart on the Klipper corpus files)
                both_open = np.zeros(n, bool)
                both_open[1:] = ~self.closed[1:] & ~self.closed[:-1] & ends.ok[1:] & ends.ok[:-1]
                self.rev_ms = np.where(both_open & self.reversible.ok, self.copy_ms, self.rev_ms)
        self.file_end = FileEnd.of(program, lay, move)     # the file's last group's end
        # the kernels' constant arguments, made once (per call costs: most of passing a group)
        r = self.reversible
        self._rev = (r.ok, r.plain, np.ascontiguousarray(r.start_xy), np.ascontiguousarray(r.end_xy))
        self._rule_vec = rule.vector()
        self._ends = self.ends_args()

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_planned"] = None        # a weak reference does not pickle; nor need it
        return state

    def planned_steps_s(self, program: Program) -> np.ndarray | None:
        """Per step of ``program``, its planner time, if ``program`` is the one this pricer
        planned (``step_plan``, under ``limits``): the time guard's measure of the input, which it
        would otherwise plan again (~0.23 s on a 170k-line Klipper file, limits read included);
        None for any other program."""
        if self._planned is None or self._planned() is not program:
            return None
        return self.step_plan.duration_s

    def ends_args(self) -> tuple:
        """``ends`` for the kernels (``gap_plan.end_side``)."""
        e = self.ends
        ok = e.ok if self.joined else np.zeros_like(e.ok)   # unjoined: no end is joined
        wp = self.wipes
        return (e.head, e.tail, e.head_exit_mm_s, e.tail_entry_mm_s, e.head_ms, e.tail_ms, ok,
                self.closed, self.rev_ms, self.row_table, self.gap_row,
                wp.n_moves, wp.moves, wp.e_mm, wp.shift_xy)


    def links_ms(self, prev, prev_changed, from_xy, nxt, nxt_changed, to_xy) -> np.ndarray:
        """Cost (ms) of each link prev[i] -> nxt[i] (problem curves; prev -1: the head comes from
        no known curve) leaving at ``from_xy`` and entering at ``to_xy``."""
        prev = np.asarray(prev, np.int64)
        nxt = np.asarray(nxt, np.int64)
        k = np.broadcast_shapes(prev.shape, nxt.shape)
        prev, nxt = np.broadcast_to(prev, k).ravel(), np.broadcast_to(nxt, k).ravel()
        prev_changed = np.broadcast_to(np.asarray(prev_changed, bool), k).ravel()
        nxt_changed = np.broadcast_to(np.asarray(nxt_changed, bool), k).ravel()
        from_xy = np.broadcast_to(np.asarray(from_xy, float), k + (2,)).reshape(-1, 2)
        to_xy = np.broadcast_to(np.asarray(to_xy, float), k + (2,)).reshape(-1, 2)
        return self._links_flat(prev, prev_changed, np.ascontiguousarray(from_xy), nxt,
                                nxt_changed, np.ascontiguousarray(to_xy)).reshape(k)

    def _links_flat(self, prev, prev_changed, from_xy, nxt, nxt_changed, to_xy) -> np.ndarray:
        """``links_ms`` of links given as flat arrays of one length (int64, bool, contiguous
        (n, 2) floats): no broadcasting (``group_costs``' one call per group)."""
        z0 = np.where(prev >= 0, self.z_exit[np.maximum(prev, 0)], self.z_entry[nxt])
        z1 = self.z_entry[nxt]
        out = np.empty(len(nxt))
        need = np.zeros(len(nxt), bool)
        no_retract = np.empty(len(nxt))
        _links(prev, prev_changed, nxt, nxt_changed, from_xy, to_xy, z0, z1, self.group_first,
               self.own.net_e, self.own.retract_mm, self.own.fw_net, self.own.fw_retracted,
               self.bnd.net_e, self.bnd.retract_mm, self.bnd.fw_net, self.bnd.fw_retracted,
               self.copy_ms, *self._rev, self._rule_vec, self.style_vec, self.move_vec, out,
               need, no_retract, self.node_ms, self._ends)
        if need.any():
            self._exempt(out, need, no_retract, nxt, from_xy, to_xy)
        return out

    def _exempt(self, out, need, no_retract, nxt, from_xy, to_xy) -> None:
        """Links that retract only because no combing test was made: those that cross no wall of
        their layer go dry (``TravelRule``), at the cost ``no_retract``."""
        idx = np.flatnonzero(need)
        if not len(idx):
            return
        layers = self.layer[nxt[idx]]
        for lay_i in np.unique(layers).tolist():
            sel = idx[layers == lay_i]
            dry = ~self.rule.walls.crosses_many(lay_i, from_xy[sel], to_xy[sel])
            out[sel[dry]] = no_retract[sel[dry]]

    def anchor_link(self, a: Anchor, b: Anchor) -> float:
        """Cost (ms) of the travel from anchor ``a`` into anchor ``b`` (program curves)."""
        xy = np.array([np.asarray(a.xy, float)[:2], np.asarray(b.xy, float)[:2]])
        return float(self._links_flat(np.array([a.curve]), np.array([a.changed]), xy[:1],
                                      np.array([b.curve]), np.array([b.changed]), xy[1:])[0])

    def order_cost(self, order, changed, entry_xy, exit_xy) -> float:
        """Cost (ms) of the travels between consecutive curves of ``order`` (the file's prefix,
        before its first curve, and its end, after the last, are copied whatever the order)."""
        if len(order) < 2:
            return 0.0
        return float(self.links_ms(order[:-1], changed[:-1], exit_xy[:-1], order[1:], changed[1:],
                                   entry_xy[1:]).sum())

    # -- a group's costs --------------------------------------------------------------------------
    def group_costs(self, curves, grp: Group, start: Anchor, end: Anchor | None) -> LinkCosts:
        """The link costs of ``grp`` whose local curves are program curves ``curves`` (start and
        end anchors in program curves too)."""
        gc = np.asarray(curves, np.int64)[grp.cand_curve]
        changed = np.asarray(grp.cand_reversed, bool) | (np.asarray(grp.cand_seam) != 0)
        m = grp.n_cands
        file_end = end is not None and end.curve == FILE_END
        if end is None or file_end:
            sxy = np.asarray(start.xy, float).reshape(1, 2)
            s = self._links_flat(np.full(m, start.curve, np.int64), np.full(m, start.changed),
                                 np.repeat(sxy, m, axis=0), gc, changed,
                                 np.ascontiguousarray(grp.cand_entry_xy, float))
            e = np.zeros(m)
            direct = 0.0
            if file_end and self.file_end is not None:
                # the file's end after the last curve (``file_end.FileEnd``): no link, no group
                e = self.file_end.ms(grp.cand_exit_xy)
                direct = float(self.file_end.ms(sxy)[0])
        else:
            # start, direct (into a curve only) and end links in one call: the same numbers
            k = int(end.curve >= 0)
            prev = np.concatenate([np.full(m + k, start.curve, np.int64), gc])
            prev_ch = np.concatenate([np.full(m + k, start.changed), changed])
            nxt = np.concatenate([gc, np.full(k + m, end.curve, np.int64)])
            nxt_ch = np.concatenate([changed, np.full(k + m, end.changed)])
            sxy = np.asarray(start.xy, float).reshape(1, 2)
            exy = np.asarray(end.xy, float).reshape(1, 2)
            from_xy = np.concatenate([np.repeat(sxy, m + k, axis=0), grp.cand_exit_xy])
            to_xy = np.concatenate([grp.cand_entry_xy, np.repeat(exy, k + m, axis=0)])
            both = self._links_flat(prev, prev_ch, from_xy, nxt, nxt_ch, to_xy)
            s, e = both[:m], both[m + k:]
            direct = float(both[m]) if k else 0.0
        link = _GroupLinks(self, gc, changed, grp.cand_exit_xy, grp.cand_entry_xy)
        # made on first use (``LinkCosts.matrix``): a fixed or unsearched group makes none
        make = partial(self.dense, grp, gc, changed) if grp.n_cands <= DENSE_MAX_CANDS else None
        return LinkCosts(None, s, e, link, direct, make)

    def dense(self, grp: Group, gc, changed, mirror: bool = True) -> np.ndarray:
        """The group's (m, m) link matrix (``_dense``; ``mirror=False``: each link priced itself,
        the same matrix bit for bit, the tests' reference)."""
        m = grp.n_cands
        ent = np.ascontiguousarray(grp.cand_entry_xy, float)
        ext = np.ascontiguousarray(grp.cand_exit_xy, float)
        _, pid = np.unique(np.concatenate([ent, ext]), axis=0, return_inverse=True)
        pid = pid.ravel().astype(np.int64)
        grid = self.rule.walls.grid(int(self.layer[gc[0]])) if (
            self.rule.comb_cap_mm > 0 and m) else None
        if grid is None:
            z2, zi = np.zeros((0, 2)), np.zeros(1, np.int64)
            grid = (0.0, z2, z2, 0.0, 0.0, 1.0, 1, 1, np.zeros(2, np.int64), zi)
        # a loop's two-way "exit" is its seam, as is its entry; a reversed curve's z comes from
        # its other end (z is constant along a curve outside spiral-vase layers, which are kept)
        return _dense(gc, np.asarray(changed, np.bool_), ent, ext,
                      np.asarray(grp.cand_curve, np.int64), np.asarray(grp.cand_flip, np.int64),
                      pid[:m], pid[m:], int(pid.max()) + 1 if m else 0,
                      self.z_entry[gc], self.z_exit[gc], self.group_first, self.own.net_e,
                      self.own.retract_mm, self.own.fw_net, self.own.fw_retracted, self.bnd.net_e,
                      self.bnd.retract_mm, self.bnd.fw_net, self.bnd.fw_retracted, self.copy_ms,
                      *self._rev, self._rule_vec, self.style_vec, self.move_vec,
                      self.node_ms, self._ends, self.rule.comb_cap_mm > 0 and len(grid[1]) > 0,
                      *grid, mirror, self.mirror_ok)


class _GroupLinks:
    """Links between candidates u -> v of one group (a group without a dense matrix prices the
    links of its path with it)."""

    def __init__(self, pricer: TimePricer, gc, changed, exit_xy, entry_xy):
        self.pricer, self.gc, self.changed = pricer, gc, changed
        self.exit_xy, self.entry_xy = exit_xy, entry_xy

    def copied_only(self, u, v) -> np.ndarray | None:
        """``copy_ms`` (as ``_dense`` and ``link_one`` give) if every link u[i] -> v[i] is the
        slicer's own gap, copied (v's curve right after u's, both as printed); else None."""
        gu, gv = self.gc[u], self.gc[v]
        if ((gv == gu + 1) & ~self.changed[u] & ~self.changed[v]).all():
            return self.pricer.copy_ms[gv]
        return None

    def __call__(self, u, v):
        u, v = np.asarray(u, np.int64), np.asarray(v, np.int64)
        return self.pricer.links_ms(self.gc[u], self.changed[u], self.exit_xy[u], self.gc[v],
                                    self.changed[v], self.entry_xy[v])


@numba.njit(cache=True)
def _links(prev, prev_changed, nxt, nxt_changed, from_xy, to_xy, z0, z1, group_first,
           own_net, own_r, own_fw_net, own_fw, bnd_net, bnd_r, bnd_fw_net, bnd_fw, copy_ms,
           rev_ok, rev_plain, rev_start, rev_end, rule, style, mt, out, need, no_retract, node,
           ends):
    """``link_one`` per link, plus what a reversed curve entered adds to its own moves
    (``node``: ``TimePricer.node_ms``); the wall test is the caller's (``need``,
    ``no_retract``)."""
    w = np.zeros((JOINED_MAX_MOVES, W_COLS))
    for i in range(len(nxt)):
        out[i], need[i], no_retract[i] = link_one(
            prev[i], prev_changed[i], nxt[i], nxt_changed[i], from_xy[i, 0], from_xy[i, 1],
            to_xy[i, 0], to_xy[i, 1], z0[i], z1[i], group_first, own_net, own_r, own_fw_net,
            own_fw, bnd_net, bnd_r, bnd_fw_net, bnd_fw, copy_ms, rev_ok, rev_plain, rev_start,
            rev_end, rule, style, mt, w, ends)
        if nxt_changed[i]:
            out[i] += node[nxt[i]]
            no_retract[i] += node[nxt[i]]


@numba.njit(cache=True)
def _dense(gc, changed, ent, ext, local, flip, pid_ent, pid_ext, n_points, z_ent, z_ext, group_first,
           own_net, own_r, own_fw_net, own_fw, bnd_net, bnd_r, bnd_fw_net, bnd_fw, copy_ms,
           rev_ok, rev_plain, rev_start, rev_end, rule, style, mt, node, ends, has_walls, trim, a, b,
           x0, y0, h, nx, ny, start, items, mirror, mirror_ok):
    """A group's (m, m) link matrix (inf within one curve). Every link stays inside the group
    (no boundary gap), so what a rebuilt link's E and Z moves cost depends on the curve it enters
    only: made once per candidate, and per link only the XY travel and the retraction rule
    (``link_one`` where the two ends lie at different heights, or the link leaves a curve the
    slicer wiped after, as it printed it: ``wipes``). The wall test is made here, before a link
    is planned (``_crosses``: once per pair of points, memoized), so each link's moves are
    planned once, as they will be written. A link into a
    reversed candidate carries what reversing adds to its curve's own moves (``node``).

    ``mirror``: a rebuilt link at one height and its mirror flip(v) -> flip(u) (the same two
    points the other way round, ``_mirror_of``) are priced once where neither is joined to a
    curve's moves (``end_side`` -1 at all four ends: the curves' ends unknown, as under
    ``copied_gaps="moves"`` or without the file's limits, or loops entered at a moved seam) and
    both run under one limits regime (``gap_plan.regime_rows``): the price then depends on the
    direction through |dx|, |dy| only (per-axis caps, jerk and safe speeds take |u_axis|; the
    junctions with E-only and Z-only moves are right angles), the same number bit for bit.
    ``mirror_ok`` (``TimePricer.mirror_ok``: the rule is the same run backwards, Klipper's, and
    the curve's boundary moves backwards are its own reversed) extends it to links joined to open
    curves (``_mirrorable``) that carry no lone prime: the mirror's planned sequence is
    then the link's run backwards (the curve's last move backwards is its first move reversed,
    the retraction and lift before the travel as the unretraction and lowering after it), the
    same time up to rounding (tests/test_ordering_cost_mirror.py), priced once. A link joined to a
    loop is not its mirror's price (the loop is left along its last move and entered along its
    first), nor is any joined link under Marlin's rules (``reversal_symmetric``). (``node`` is
    added per link, not mirrored.)"""
    m = len(gc)
    out = np.empty((m, m))
    done = np.zeros((m, m), np.bool_)     # priced as the mirror of a link before it
    w = np.zeros((JOINED_MAX_MOVES, W_COLS))
    side = np.empty(m, np.int64)        # each candidate's rows in ``ends`` (``end_side``)
    # a candidate whose curve the slicer wiped after (``wipes``): a link out of it that
    # retracts writes a wipe first (``link_one`` prices it; no mirror)
    wiper = np.zeros(m, np.bool_)
    for k in range(m):
        side[k] = end_side(gc[k], changed[k], ends)
        wiper[k] = ends[11][gc[k], 1 if changed[k] else 0] > 0
    memo = np.full((n_points, n_points), -1, np.int8)
    stamp = np.full(max(len(a), 1), -1, np.int64)
    tag = 0
    retract_mm, min_travel, fw_style, comb_cap = rule[0], rule[1], rule[2] > 0.5, rule[3]
    v_r, v_u, v_xy, v_z, hop = style[0], style[1], style[2], style[3], style[4]
    # per entered candidate: (use_fw, E time retracting, E time dry), as rebuilt_s sums them
    use_fw = np.zeros(m, np.bool_)
    e_wet = np.zeros(m)
    e_dry = np.zeros(m)
    net_v = np.zeros(m)
    planned = mt[MT_CODE] >= 0.0       # the moves planned together (``rebuilt_s``), per link
    for v in range(m):
        c = gc[v]
        net, r_i, fw_net, fw_ret = 0.0, 0.0, 0, False
        if c != group_first[c]:
            net, r_i, fw_net, fw_ret = own_net[c], own_r[c], own_fw_net[c], own_fw[c]
        net_v[v] = net
        use_fw[v] = fw_net == 0 and (fw_ret or (fw_style and r_i <= 0.0))
        e_dry[v] = trapezoid_one_s(abs(net), min(v_u, mt[5]), mt[4], mt[6]) if abs(net) > MOVE_EPS_MM else 0.0
        e_wet[v] = e_dry[v] if use_fw[v] else (trapezoid_one_s(retract_mm, min(v_r, mt[5]), mt[4], mt[6])
                                               + trapezoid_one_s(abs(net + retract_mm), min(v_u, mt[5]), mt[4], mt[6]))
    t_hop = 2.0 * trapezoid_one_s(hop, min(v_z, mt[8]), mt[7], mt[9]) if hop > 0.0 else 0.0
    v_xy_cap = min(v_xy, mt[1])
    # planned: the moves that do not depend on the link, prepared once (``same_z_s``) per
    # candidate v and per limits regime of the group (``gap_plan.regime_rows``)
    code, hop_on = int(mt[MT_CODE]), hop > MOVE_EPS_MM
    vreg, rows_loc, pres = regime_rows(gc, ends, code, planned, retract_mm, v_r, hop, v_z)
    u_rows, has_u = np.zeros((2, m, W_COLS)), np.zeros((2, m), np.bool_)
    if planned:
        for v in range(m):
            pre = pres[vreg[v]]
            lim_row = rows_loc[vreg[v]]
            wet = net_v[v] if use_fw[v] else net_v[v] + retract_mm
            for j, e in ((0, wet), (1, net_v[v])):
                has_u[j, v] = abs(e) > MOVE_EPS_MM
                if has_u[j, v]:
                    e_row(u_rows[j], v, e, v_u, code, lim_row)
            if hop_on and has_u[0, v]:
                w[0, :] = pre[2]
                w[1, :] = u_rows[0, v]
                u_rows[0, v, W_J] = junction(w, 1, code, lim_row)
                u_rows[0, v, W_JREADY] = 1.0
    grid_args = (trim, a, b, x0, y0, h, nx, ny, start, items)
    for u in range(m):
        for v in range(m):
            if done[u, v]:
                continue
            if local[u] == local[v]:
                out[u, v] = np.inf
                continue
            p, c = gc[u], gc[v]
            if p == c - 1 and not changed[u] and not changed[v]:
                out[u, v] = copy_ms[c]
                continue
            if reversed_link(p, changed[u], c, ext[u, 0], ext[u, 1], ent[v, 0], ent[v, 1],
                              group_first, rev_ok, rev_plain, rev_start, rev_end):
                out[u, v] = (reversed_ms(p, c, group_first, own_net, ends[8], style, mt)
                             + (node[c] if changed[v] else 0.0))
                continue
            need, dry = False, 0.0      # (set by ``link_one``: its wall test is made below)
            if (abs(z_ext[u] - z_ent[v]) > MOVE_EPS_MM or group_first[p] != group_first[c]
                    or wiper[u]):
                t, need, dry = link_one(p, changed[u], c, changed[v], ext[u, 0], ext[u, 1],
                                         ent[v, 0], ent[v, 1], z_ext[u], z_ent[v], group_first,
                                         own_net, own_r, own_fw_net, own_fw, bnd_net, bnd_r,
                                         bnd_fw_net, bnd_fw, copy_ms, rev_ok, rev_plain,
                                         rev_start, rev_end, rule, style, mt, w, ends)
            else:
                dx = ent[v, 0] - ext[u, 0]
                dy = ent[v, 1] - ext[u, 1]
                dist = np.sqrt(dx * dx + dy * dy)
                moving = dist > MOVE_EPS_MM
                if use_fw[v]:
                    retract = moving and fw_style and dist >= min_travel
                else:
                    retract = moving and retract_mm > 0.0 and dist >= min_travel
                if retract and comb_cap > 0.0 and dist <= comb_cap:
                    # a travel the slicer would have combed retracts only where it crosses a
                    # wall: the test comes first, so each link is planned once, as it goes
                    retract = has_walls and _crosses(u, v, pid_ext, pid_ent, memo, ext, ent, tag,
                                                     stamp, grid_args)
                if planned:
                    t = same_z_s(dx, dy, dist, retract, not use_fw[v] and retract_mm > MOVE_EPS_MM,
                                 hop_on, pres[vreg[v]], u_rows, v, has_u[0 if retract else 1, v],
                                 w, code, rows_loc[vreg[v]], v_xy, p, side[u], c, side[v],
                                 ends) * 1000.0
                else:
                    t_xy = trapezoid_one_s(dist, v_xy_cap, mt[0], mt[2]) if moving else 0.0
                    t = ((t_xy + e_wet[v] + t_hop) if retract else (t_xy + e_dry[v])) * 1000.0
            if need and not (has_walls and _crosses(u, v, pid_ext, pid_ent, memo, ext, ent, tag,
                                                    stamp, grid_args)):
                t = dry
            tag += 1        # (one wall test at most per link: the two above exclude each other)
            out[u, v] = t + (node[c] if changed[v] else 0.0)
            if (mirror and not wiper[u] and not wiper[flip[v]]
                    and _mirrorable(u, side, flip, gc, mirror_ok)
                    and _mirrorable(v, side, flip, gc, mirror_ok)
                    and abs(z_ext[u] - z_ent[v]) <= MOVE_EPS_MM and group_first[p] == group_first[c]):
                fu, fv = flip[u], flip[v]
                # unjoined both ways, or joined to open curves under a rule the same backwards,
                # under one limits regime: what makes the two prices equal
                # (joined: no lone prime, whose one E-only move -- a stop under Klipper -- sits
                # before the curve entered both ways, so the mirror is not the link backwards)
                if (vreg[fu] == vreg[v] and (abs(net_v[v]) <= MOVE_EPS_MM
                                             or (side[u] < 0 and side[v] < 0))
                        and _mirror_of(u, v, fu, fv, gc, changed, ent, ext, z_ent, z_ext, net_v,
                                       use_fw, group_first, rev_ok, rev_plain, rev_start, rev_end)):
                    out[fv, fu] = t + (node[gc[fu]] if changed[fu] else 0.0)
                    done[fv, fu] = True
    return out


@numba.njit(cache=True, inline="always")
def _crosses(u, v, pid_ext, pid_ent, memo, ext, ent, tag, stamp, grid):
    """Whether ``_dense``'s link u -> v crosses a wall of its layer (``travel.cross_one`` on the
    layer's ``grid``; ``tag`` a number unique to this test), memoized per pair of points
    (``memo``: -1 not tested; a travel and its reverse cross the same walls)."""
    i, j = pid_ext[u], pid_ent[v]
    if memo[i, j] < 0:
        trim, a, b, x0, y0, h, nx, ny, start, items = grid
        hit = cross_one(ext[u, 0], ext[u, 1], ent[v, 0], ent[v, 1], tag, stamp, trim, a, b, x0,
                        y0, h, nx, ny, start, items)
        memo[i, j] = 1 if hit else 0
        memo[j, i] = memo[i, j]
    return memo[i, j] != 0


@numba.njit(cache=True, inline="always")
def _mirrorable(k, side, flip, gc, mirror_ok):
    """Whether candidate k's end of a link allows ``_dense``'s mirror: neither k nor its flip is
    joined to its curve's moves, or both are, to an open curve whose boundary moves printed
    backwards are its own run backwards (``mirror_ok``: ``TimePricer.mirror_ok``, only under a
    rule the same both ways)."""
    if side[k] < 0 and side[flip[k]] < 0:
        return True
    return side[k] >= 0 and side[flip[k]] >= 0 and mirror_ok[gc[k]]


@numba.njit(cache=True, inline="always")
def _mirror_of(u, v, fu, fv, gc, changed, ent, ext, z_ent, z_ext, net_v, use_fw, group_first,
               rev_ok, rev_plain, rev_start, rev_end):
    """Whether the link flip(v) -> flip(u) of ``_dense`` is priced as the rebuilt link u -> v
    at one height (both in its generic branch): the same two points the other way round, neither
    the slicer's gap copied nor a gap reversed, both ends at one height, and the entered curves'
    own gaps alike (net E and firmware retraction: what the unretraction into each costs)."""
    p2, c2 = gc[fv], gc[fu]
    if (ext[fv, 0] != ent[v, 0] or ext[fv, 1] != ent[v, 1] or ent[fu, 0] != ext[u, 0]
            or ent[fu, 1] != ext[u, 1] or net_v[fu] != net_v[v] or use_fw[fu] != use_fw[v]
            or (p2 == c2 - 1 and not changed[fv] and not changed[fu])
            or abs(z_ext[fv] - z_ent[fu]) > MOVE_EPS_MM):
        return False
    return not reversed_link(p2, changed[fv], c2, ext[fv, 0], ext[fv, 1], ent[fu, 0], ent[fu, 1],
                              group_first, rev_ok, rev_plain, rev_start, rev_end)
