"""Re-emit G-code with the curves in the solved order and direction (``emit``).

Rules (formulations/ordering.md, "Emit"; ``layout`` explains the line classes):

- A curve printed as the slicer printed it keeps its lines byte for byte, except the E word in
  absolute-E (M82) files, re-numbered from the cumulative E of the new order. A reversed curve,
  or a loop that starts at another vertex, is written move by move (``G1 X Y E F``; arcs with G2
  and G3 swapped and I/J re-computed from the new start point).
- A gap whose two neighbours are still neighbours (same curves, same ends) is copied as it was:
  the slicer's own retraction, wipe, z-hop, combing path. Under the time objective, a link that
  runs the other way round between the same two ends (curve c + 1 left where the gap before it
  ended, curve c entered where it began) writes that gap backwards where it is pure travel
  (``gaps.reversed_gap``, ``gaps.ReversibleGaps``), at the price ``cost`` gives it.
- Any other gap is rebuilt the way the slicer builds its travels (``gaps.rebuilt_gap``), with
  parameters read from the file (``travel.TravelStyle``): retract (if the travel is at least the
  shortest travel the slicer retracted for), z-hop, one straight travel, lower, unretract. If the slicer combs (it made
  long travels without retracting), a rebuilt travel that crosses no wall of its layer and is
  no longer than the slicer's own dry travels (and ``travel.COMB_TESTED_MAX_MM``) skips the
  retraction, as the slicer would (``travel.TravelRule``, the rule the time objective prices). Its non-motion lines are kept:
  a boundary gap's lines (layer change, barriers) stay at the boundary in their order; a gap
  inside a group travels with the curve that followed it (minus ``;TYPE:``/wipe comments, which
  are re-derived).
- State every extrusion sees (fan, acceleration, jerk, flow, pressure advance, feature label,
  feedrate) is tracked through the output; before each curve, every value that differs from what
  that curve saw in the original is re-issued with the original line (``writer.Writer``).
- An E-only G92 travels with the next curve (E after it continues from it: E is numbered from the
  output's own running total and the offset each copied G92 sets); a G92 with X/Y/Z is a barrier.
- Object labels (``layout.LINE_LABEL``): a *run* is the curves between two gaps that hold labels.
  A run's opening labels lie in the gap before its first curve and are written where that gap is
  consumed (entering the run); its closing labels (``; stop printing object``, ``M486 S-1``,
  ``EXCLUDE_OBJECT_END``) are written where the output leaves the run: in place when the gap that
  holds them is the one consumed, else right after the run's last curve, and dropped from any
  other gap (safe mode moves whole runs: ``blocks.py``). So each run's moves stay inside its own
  labels, whichever runs are printed before and after it.
"""
from __future__ import annotations

import bisect

import numpy as np

from ..headers import ORDER_HEADER
from ..program import Program
from .gaps import rebuilt_gap, reversed_gap
from .layout import LIMIT_STATE_HEADS, LINE_LABEL, Layout, layout, link_travel_steps
from ..slicers import LABEL_CLOSE
from .problem import OrderingProblem, OrderingSolution
from .travel import TravelRule
from .wipes import SlicerWipes, side_of
from .writer import (F_WORD, CurveMoves, PerLine, Writer, gcode_number, required_state,
                     states_at)


def emit(program: Program, problem: OrderingProblem, solution: OrderingSolution,
         memo: dict | None = None) -> str:
    """G-code text with the curves of ``problem`` in the order of ``solution``.

    ``memo``: a dict kept between calls on the same program and problem (the time guard emits
    again after putting a few layers back, ``rewrite.guard.emit_guarded``). A layer whose curves, in
    the same order and directions, are entered from the same state (previous curve, position,
    feedrate, state lines, feature, E up to ``MEMO_E_TOL_MM``) gets the text it got before; E
    words differ from a fresh emit by at most that tolerance, where rounding tips a last digit."""
    program.check_rewritable()
    problem = problem.program_problem       # (a solution is in the program's curve numbering)
    lay = problem.layout if problem.layout is not None else layout(program)
    p = program
    n = len(lay.curve_s0)
    if n == 0:
        return program.to_gcode()
    order = np.asarray(solution.curve_order, np.int64)
    rev = np.asarray(solution.curve_reversed, bool)
    seam = np.asarray(solution.curve_seam, np.int64)
    if len(order) != n or not np.array_equal(np.sort(order), np.arange(n)):
        raise ValueError("solution does not order every curve of the program exactly once")
    # what depends on the program and problem only (travel style, walls and their per-layer
    # segments, per-line and per-curve lists) is made once per memo, not once per guard pass
    fixed = memo.get(_FIXED) if memo is not None else None
    if fixed is None:
        # the time objective's pricer holds the rule it priced (its walls' grids built already)
        rule = problem.pricer.rule if problem.pricer is not None else TravelRule.of(program, problem, lay)
        # the gaps a link may write reversed: the time objective's pricer says which (and prices
        # them so); the travel objective rebuilds every link that is not the slicer's own
        rgaps = problem.pricer.reversible if problem.pricer is not None else None
        lists = Writer.per_line(program, lay)
        # the slicer's wipes a rebuilt travel writes again (the pricer's, which priced them)
        wipes = (problem.pricer.wipes if problem.pricer is not None
                 else SlicerWipes.of(program, lay, problem.curve_closed))
        fixed = (rule, lists, _Plan.per_curve(p, problem, lay, lists), rgaps, wipes)
        if memo is not None:
            memo[_FIXED] = fixed
    rule, lists, per_curve, rgaps, wipes = fixed
    w = Writer(program, lay, lists)
    plan = _Plan(p, lay, rule, order, rev, seam, per_curve, rgaps, wipes)

    # prefix + first gap: verbatim (the first layer keeps its order, so curve 0 stays first)
    prev = -1
    w.copy_lines(0, plan.l0[0])
    # one block of the order per layer (a layer's curves are contiguous in any solution)
    lay_of = problem.curve_layer[order]
    cuts = np.flatnonzero(np.diff(lay_of)) + 1
    starts, ends = np.concatenate(([0], cuts)), np.concatenate((cuts, [n]))
    for k0, k1 in zip(starts.tolist(), ends.tolist()):
        key = None
        if memo is not None:
            blk = order[k0:k1]
            key = (int(lay_of[k0]), prev, bool(plan.changed[prev]) if prev >= 0 else False,
                   blk.tobytes(), rev[blk].tobytes(), seam[blk].tobytes(), w.entry_key())
            hit = memo.get(key[:-1])
            if hit is not None and same_entry(hit[0], key[-1]):
                w.extend_from(hit[0], hit[1], hit[2])
                prev = int(order[k1 - 1])
                continue
            start = len(w.out)
        plan.layer_moves(k0, k1)
        k = k0
        while k < k1:
            k = _emit_curves(plan, w, k, k1, prev)
            prev = plan.order[k]
            k += 1
        if key is not None:
            memo[key[:-1]] = (key[-1], w.out[start:], w.snapshot())
    # state the remainder of the file expects, then the remainder verbatim (the last run's
    # closing labels where the output left another run last: see _closing)
    last = plan.l1[n - 1]
    w.reissue(states_at(plan.req, [last + 1]), 0)
    skip = frozenset()
    if plan.run[prev] != plan.run[n - 1]:
        for i in plan.closes[plan.run[prev]]:
            w.copy_line(i)
        skip = plan.close_set
    a = last + 1
    for i in sorted(i for i in skip if i >= a):
        w.copy_lines(a, i)
        a = i + 1
    w.copy_lines(a, p.n_lines)
    text = "".join(w.out)
    if p.n_lines and not p.data.endswith(b"\n") and text.endswith(w.nl):
        # the file ends without a line ending (FullControl's closing "M84 ; disable steppers"):
        # so does the output. ``copy_line`` ends every line, for the lines a re-ordering moves;
        # the added one made the original's last line differ from its copy byte for byte
        text = text[:-len(w.nl)]
    if text != p.to_gcode():
        # says what this file is to ``gatesopt verify ORIG OUT``: a re-ordering, checked curve
        # by curve, even where no curve visibly moved (kept order, rebuilt travels)
        text = ORDER_HEADER + w.nl + text
    return text



_FIXED = "fixed"                # the memo's entry for what every emit of the program shares

#: a memoized layer is reused when its entry's logical E (absolute-E files) differs by at most
#: this: re-ordered layers sum the same E in another order, so E at the next layer's start drifts
#: by ~1e-12 mm; the output writes E with 6 decimals
MEMO_E_TOL_MM = 1e-7


def same_entry(memo_entry: tuple, entry: tuple) -> bool:
    """Whether a memoized layer's entry state is this one (E within MEMO_E_TOL_MM)."""
    return memo_entry[:5] == entry[:5] and abs(memo_entry[5] - entry[5]) <= MEMO_E_TOL_MM


class _Plan:
    """What ``emit`` knows about the file and the solution, per curve as Python lists (numpy
    scalar indexing curve by curve was a fifth of the emit)."""

    def __init__(self, p: Program, lay: Layout, rule: TravelRule, order, rev, seam,
                 per_curve: tuple, rgaps=None, wipes: SlicerWipes | None = None):
        self.p, self.lay, self.rule, self.rgaps = p, lay, rule, rgaps
        self.order, self.rev, self.seam = order.tolist(), rev.tolist(), seam.tolist()
        self.order_arr = order
        self.changed_arr = rev | (seam != 0)
        self.changed = self.changed_arr.tolist()
        (self.group_first, self.layer, self.l0, self.l1, self.feature, self.req,
         self.curve_state, self.run, self.closes, self.close_set, self.s0,
         self.feed0, self.has_f, quiet, self.travel_state, self.n_keys) = per_curve
        # per position k of the order: curve order[k] follows order[k - 1] as in the file, both
        # unchanged, and nothing is written between them but the original's lines (``quiet``):
        # ``_emit_curves`` copies such a run of curves as one run of lines
        nxt = np.zeros(len(order), bool)
        if len(order) > 1:
            a, b = order[:-1], order[1:]
            nxt[1:] = (b == a + 1) & ~self.changed_arr[a] & ~self.changed_arr[b] & quiet[b]
        self.follows = nxt.tolist()
        self.rev_arr, self.seam_arr = rev, seam
        self.moves = None       # the layer's curves written move by move (``layer_moves``)
        self.wipes = wipes      # the slicer's wipes a rebuilt travel writes (``wipes.SlicerWipes``)

    def layer_moves(self, k0: int, k1: int) -> None:
        """``moves``: the moves of the curves at positions k0..k1-1 written move by move (made
        where a layer is written, not for the layers the memo gives)."""
        blk = self.order_arr[k0:k1]
        moved = blk[self.changed_arr[blk]]
        self.moves = CurveMoves.of(self.p, self.lay, moved.tolist(), self.rev_arr[moved].tolist(),
                                   self.seam_arr[moved].tolist())

    @staticmethod
    def per_curve(p: Program, problem: OrderingProblem, lay: Layout, lines: PerLine) -> tuple:
        """What does not depend on the order: each curve's group's original first curve, layer,
        first and last line, feature, the state lines in force at any line and, per state key,
        the text in force at each curve's first line (``states_at``)."""
        gidx = np.repeat(np.arange(problem.n_groups), np.diff(problem.group_curve_start))
        req = required_state(p, lay)
        curve_state = states_at(req, lay.curve_l0)
        run, closes, close_set = _runs(p, lay)
        # per curve, the motion limits in force at the slicer's travel into it: a rebuilt (or
        # reversed) travel runs under them, as ``cost.TimePricer`` prices it. Left alone, it ran
        # under the limits of the curve the output leaves: Orca states a wall's acceleration
        # before the wall and its travel acceleration (SET_VELOCITY_LIMIT ACCEL=10000) after
        # it, in the gap after the wall, which a link from the wall into another curve does not
        # consume: real_orca230_arcs layer 168, links from a wall into gap infill planned at the
        # wall's 5,000 mm/s^2, 23.7 ms over the price each
        limit_req = {k: v for k, v in req.items() if k[0] in LIMIT_STATE_HEADS}
        travel_state = states_at(limit_req, p.line[link_travel_steps(p, lay)])
        # per curve, how many state keys are in force at its first line (a key is, from its
        # first line on): where the output has no others, ``Writer.reissue`` leaves each
        # command's keys in the original's order, so a curve that follows as in the file needs
        # no state line before it (``_emit_curves``)
        firsts = np.sort(np.asarray([arr[0] for arr, _ in req.values()], np.int64))
        n_keys = np.searchsorted(firsts, lay.curve_l0, side="left").tolist()
        has_f = sets_feed(p, lay.curve_s0).tolist()
        return (problem.group_curve_start[gidx].tolist(), problem.curve_layer.tolist(),
                lay.curve_l0.tolist(), lay.curve_l1.tolist(), p.feature[lay.curve_s0].tolist(),
                req, curve_state, run, closes, close_set, lay.curve_s0.tolist(),
                p.feed_mm_s[lay.curve_s0].tolist(), has_f, _quiet(p, lay, lines, has_f),
                travel_state, n_keys)

    def gap_lines(self, c: int) -> range:
        """The original lines between curve c - 1 and curve c."""
        return range(self.l1[c - 1] + 1 if c > 0 else 0, self.l0[c])


def _runs(p: Program, lay: Layout) -> tuple[list, list, frozenset]:
    """Per curve its run (the curves between two gaps that hold object labels), per run its
    closing label lines (in the gap after its last curve, or after the last curve of the file),
    and all closing label lines."""
    n = len(lay.curve_l0)
    lab = np.zeros(p.n_lines + 1, np.int64)
    close = sorted(i for i, (_, kind, _) in lay.labels.items() if kind == LABEL_CLOSE)
    lab[1:] = np.cumsum(lay.line_class == LINE_LABEL)
    l0, l1 = lay.curve_l0, lay.curve_l1
    starts = np.ones(n, bool)
    if n > 1:
        starts[1:] = lab[l0[1:]] - lab[l1[:-1] + 1] > 0
    run = (np.cumsum(starts) - 1).tolist()
    ends = np.concatenate((np.flatnonzero(starts)[1:] - 1, [n - 1])).astype(np.int64)
    gap_end = np.where(ends + 1 < n, l0[np.minimum(ends + 1, n - 1)], p.n_lines)
    arr = np.asarray(close, np.int64)
    a = np.searchsorted(arr, l1[ends] + 1)
    b = np.searchsorted(arr, gap_end)
    closes = [arr[x:y].tolist() for x, y in zip(a.tolist(), b.tolist())]
    return run, closes, frozenset(close)


def _closing(plan: _Plan, w: Writer, prev: int, c: int, lines: list) -> list:
    """The gaps ``lines`` (``(lines, boundary)`` pairs) the rebuilt travel from ``prev`` into
    ``c`` consumes, without closing labels other than those of ``prev``'s run where the output
    leaves it here; those are written first unless a consumed gap holds them (module docstring)."""
    if not plan.close_set:
        return lines
    r = plan.run[prev]
    mine = frozenset(plan.closes[r]) if plan.run[c] != r else frozenset()
    if mine and not any(i in mine for rng, _ in lines for i in rng):
        for i in plan.closes[r]:
            w.copy_line(i)
        mine = frozenset()
    close = plan.close_set
    return [([i for i in rng if i not in close or i in mine], b) for rng, b in lines]


def _emit_curves(plan: _Plan, w: Writer, k: int, k_end: int, prev: int) -> int:
    """The k-th curve of the new order with the gap before it, and the curves after it (before
    position ``k_end``) that follow it as in the file (``_Plan.follows``); returns the position of
    the last curve written."""
    p, lay = plan.p, plan.lay
    c = plan.order[k]
    if k > 0:
        if prev == c - 1 and not plan.changed[prev] and not plan.changed[c]:
            w.copy_lines(plan.l1[prev] + 1, plan.l0[c])
        else:
            lines = []
            first = plan.group_first[c]
            if first != plan.group_first[prev]:             # crossing into c's group
                lines.append((plan.gap_lines(first), True))
                if c != first:
                    lines.append((plan.gap_lines(c), False))
            elif c != first:
                lines.append((plan.gap_lines(c), False))
            lines = _closing(plan, w, prev, c, lines)
            entry = _entry_mm(p, lay, c, plan.rev[c], plan.seam[c])
            if plan.rgaps is not None and plan.rgaps.applies(plan.group_first, prev, c, w.xyz, entry):
                # the gap before c + 1 backwards, under the limits of its own travel
                w.reissue(plan.travel_state, c + 1)
                reversed_gap(w, p, lay, plan.rule, lines, c)
            else:
                rebuilt_gap(w, p, lay, plan.rule, lines, c, entry, plan.layer[c],
                            limits=(plan.travel_state, c),
                            wipe=_wipe_of(plan, prev))
    w.reissue(plan.curve_state, c)      # state the curve saw in the original
    fi = plan.feature[c]
    if fi >= 0 and w.feature != p.feature_names[fi]:
        w.write(f"{lay.feature_prefix}{p.feature_names[fi]}")
        w.feature = p.feature_names[fi]
    reverse, seam = plan.rev[c], plan.seam[c]
    if not reverse and seam == 0:
        # (the per-curve lists: numpy scalar indexing was a fifth of this path)
        feed = plan.feed0[c]
        if w.feed is None or abs(w.feed - feed) > 1e-9:
            # the first move may rely on a modal F set before it: set it explicitly
            if not plan.has_f[c]:
                w.write(f"G1 F{gcode_number(feed * 60.0, 3)}")
                w.feed = feed
        # this curve and those that follow it as in the file: one run of the original's lines
        # (where the output has only the state keys the original had at c: else ``reissue``
        # may write a command's lines again before the next curve)
        follows = plan.follows
        last = k
        if len(w.state) == plan.n_keys[c]:
            while last + 1 < k_end and follows[last + 1]:
                last += 1
        w.copy_lines(plan.l0[c], plan.l1[plan.order[last]] + 1)
        return last
    _curve(plan, w, p, lay, c, reverse)
    return k


def _wipe_of(plan: _Plan, prev: int):
    """The wipe out of curve ``prev`` (``wipes.SlicerWipes``) on the side the output leaves it
    by: ``(moves, e_mm)``, the moves as (dX, dY, dE, feed mm/s) rows; else None.
    ``gaps.rebuilt_gap`` writes it where its travel retracts."""
    wp = plan.wipes
    side = side_of(plan.changed[prev])
    k = int(wp.n_moves[prev, side]) if wp is not None else 0
    if not k:
        return None
    return wp.moves[prev, side, :k].tolist(), float(wp.e_mm[prev, side])


def sets_feed(p: Program, steps: np.ndarray) -> np.ndarray:
    """Per step of ``steps``: whether its line sets F itself (an F word before any ';', as
    ``F_WORD`` finds it), else the move relies on the modal F set before it."""
    lines = p.line[steps]
    if not p.data.isascii():
        return np.asarray([bool(F_WORD.search(p.line_text(int(i)).split(";")[0]))
                           for i in lines.tolist()], bool)
    # F_WORD on every F of the file at once (the file's characters are its bytes): not after a
    # letter or '_', then [-+]? and a digit or '.' and a digit; before its line's first ';'
    data = np.frombuffer(p.data, np.uint8)
    pad = np.concatenate((data, np.zeros(3, np.uint8)))
    at = np.flatnonzero((data == ord("F")) | (data == ord("f")))
    before = np.where(at > 0, pad[at - 1], ord("\n"))
    lower = before | 0x20                                   # a letter's lower case
    after = at + 1 + ((pad[at + 1] == ord("+")) | (pad[at + 1] == ord("-")))

    def digit(i):
        return (pad[i] >= ord("0")) & (pad[i] <= ord("9"))
    word = (~((lower >= ord("a")) & (lower <= ord("z"))) & (before != ord("_"))
            & (digit(after) | ((pad[after] == ord(".")) & digit(after + 1))))
    line_start = p.line_start
    line_of = np.searchsorted(line_start, at, side="right") - 1
    semis = np.append(np.flatnonzero(data == ord(";")), len(data))     # (a file without any)
    first_semi = semis[np.searchsorted(semis, line_start[line_of])]
    has = np.zeros(p.n_lines, bool)
    has[line_of[word & (at < first_semi)]] = True
    return has[lines]


def _quiet(p: Program, lay: Layout, lines: PerLine, has_f: list) -> np.ndarray:
    """(n,) bool: curve c printed unchanged right after curve c - 1 (unchanged), with the
    original's lines between them, needs nothing written before it (``_emit_curves`` copies such
    runs of curves as runs of lines). Its state lines: what c - 1 saw (``Writer.reissue`` made it
    so, each command's keys in the original's order where the output holds no other key, which
    ``_emit_curves`` checks) with the lines between applied, which are c's by ``states_at``. Its feature label: the
    last label between them, else c - 1's where it has one. Its feed: the last the lines between
    set (``Writer.copy_line``: every step does) within 1e-9 of c's, or c's first move sets F."""
    n = len(lay.curve_l0)
    quiet = np.zeros(n, bool)
    if n < 2:
        return quiet
    n_lines = p.n_lines
    l0 = lay.curve_l0
    a, b = l0[:-1], l0[1:]              # the lines between: [a, b), curve c - 1 and its gap
    idx = np.arange(n_lines)
    # feed: the last line before b that sets it (c - 1 has a step, so it lies in [a, b))
    fset = np.full(n_lines, np.nan)
    steps = lay.step_of_line >= 0
    fset[steps] = p.feed_mm_s[lay.step_of_line[steps]]
    for i, eff in lines.effects.items():
        if eff.feed_mm_s is not None:
            fset[i] = eff.feed_mm_s
    last_f = np.maximum.accumulate(np.where(np.isnan(fset), -1, idx))
    fed = fset[last_f[b - 1]]
    feed_ok = np.abs(fed - p.feed_mm_s[lay.curve_s0[1:]]) <= 1e-9
    # feature: the last label line in [a, b), else c - 1's own
    # (names compared, as ``_emit_curves`` does: each as the first index of its name)
    names: dict = {}
    for j, name in enumerate(p.feature_names):
        names.setdefault(name, j)
    canon = np.asarray([names[name] for name in p.feature_names] + [-1], np.int64)
    label = np.full(n_lines, -2, np.int64)  # -2: no label; a name not a feature's: -3
    for i, eff in lines.effects.items():
        if eff.feature is not None:
            label[i] = names.get(eff.feature, -3)
    last_l = np.maximum.accumulate(np.where(label != -2, idx, -1))
    at = last_l[b - 1]
    fi = p.feature[lay.curve_s0]
    fi = np.where(fi >= 0, canon[fi], -1)
    seen = np.where(at >= a, label[np.maximum(at, 0)], fi[:-1])
    feature_ok = (fi[1:] < 0) | ((seen >= 0) & (seen == fi[1:]))
    # where the feed differs, c's first move may set F itself
    quiet[1:] = feature_ok & (feed_ok | np.asarray(has_f[1:], bool))
    return quiet


def _curve(plan: _Plan, w: Writer, p: Program, lay: Layout, c: int, reverse: bool) -> None:
    """Curve c printed backwards (``reverse``) or from vertex ``seam``, move by move (in its
    own order and direction ``_emit_curves`` copies it)."""
    a, b = int(lay.curve_s0[c]), int(lay.curve_s1[c])
    # neutral commands inside the curve (progress M73, messages M117) are not moves: written
    # move by move the curve would lose them, so they go first, in their order
    cmd = w.command_lines
    for k in range(bisect.bisect_right(cmd, int(lay.curve_l0[c])),
                   bisect.bisect_left(cmd, int(lay.curve_l1[c]))):
        w.copy_line(cmd[k])
    j0 = plan.moves.first[c]
    w.steps(plan.moves, j0, j0 + b - a, reverse)


def _entry_mm(p: Program, lay: Layout, c: int, reverse: bool, seam: int) -> np.ndarray:
    """XYZ where curve c starts when printed ``reverse``d / from vertex ``seam``."""
    if reverse:
        return p.end_mm[int(lay.curve_s1[c]) - 1, :3]
    return p.start_mm[int(lay.curve_s0[c]) + seam, :3]
