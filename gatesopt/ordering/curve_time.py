"""What a curve's own moves take, printed forwards and backwards, under the planner's rules
(issue 36; formulations/ordering.md, "Cost model"): the time objective's per-candidate term.

The planner's time of a move sequence is not the same run backwards: Marlin's classic jerk takes
the entered move's safe speed where both safe speeds beat the shared junction speed
(``_planner_kernel.junction_speed``, planner.cpp "separate safe exit / entry velocities"), and an
arc's speed cap is taken at its start tangent (``_planner_kernel.prepare_moves``). Measured on
the corpus: PrusaSlicer bunny curves of 11-190 moves at one feed 4-25 ms apart (0.1 %), ArcWelder
perimeters printed backwards 67-125 ms slower (480.9 vs 606.3 ms: the arc's cap 29.2 vs 23.0
mm/s). A link into a reversed candidate carries that difference (``reversed_extra_ms``), so the
ordering pays for a reversal what the planner will charge for it; the term belongs to the
candidate, so adding it to every link into it keeps the costs an ATSP.

Each curve is planned alone: from rest (its safe speed) to rest, the limits in force at each of
its moves (``limits.MachineLimits.regimes``), arcs with their tangents. What the junctions with
the travels around it add is the link's (``cost``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _planner_kernel as pk
from . import gap_plan as gp
from ..limits import MachineLimits
from ..planner import arc_tangents, move_geometry
from ..program import MOTION_KINDS, Program
from .layout import link_travel_steps


#: a curve's change of time printed backwards below this (ms) is not priced (``CurveEnds.of``)
NODE_MIN_MS = 0.1


@dataclass(frozen=True, eq=False)
class _Alone:
    """Each curve planned alone, one orientation: per move (curves' moves in print order) its
    curve, step, prepared values and planned speeds and time."""

    owner: np.ndarray
    steps: np.ndarray
    L: np.ndarray
    vnom: np.ndarray
    acc: np.ndarray
    safe: np.ndarray
    entry: np.ndarray
    exit: np.ndarray
    peak: np.ndarray
    t: np.ndarray
    u_start: np.ndarray     # (m, 4) unit vector at the move's start (an arc's tangent)
    u_end: np.ndarray       # (m, 4) and at its end


def _alone(program: Program, lim: MachineLimits, s0: np.ndarray, s1: np.ndarray,
           backwards: bool) -> _Alone | None:
    """Each curve's steps ``s0[i]:s1[i]`` planned alone (from and to rest), forwards or
    backwards, as ``planner.plan`` plans a file (None where it would refuse the limits)."""
    n = len(s0)
    lengths = s1 - s0
    steps = np.concatenate([np.arange(a, b) for a, b in zip(s0.tolist(), s1.tolist())]
                           + [np.zeros(0, np.int64)]).astype(np.int64)
    owner = np.repeat(np.arange(n), lengths)
    kind = program.kind[steps]
    klipper = lim.firmware == "klipper"
    length, is_arc = move_geometry(program, klipper)     # as planner.plan moves each step
    keep = np.isin(kind, np.asarray(MOTION_KINDS, kind.dtype)) & (length[steps] > 0)
    steps, owner = steps[keep], owner[keep]
    if backwards:
        # each curve's moves in reverse order (owner ascending, position descending)
        pos = np.arange(len(steps))
        order = np.lexsort((-pos, owner))
        steps, owner = steps[order], owner[order]
    m = len(steps)
    d = (program.end_mm[steps] - program.start_mm[steps]).astype(float)
    if backwards:
        d[:, :3] = -d[:, :3]
    L = length[steps].astype(float)
    arc = is_arc[steps]
    arc_row = np.full(m, -1, np.int64)
    ai = np.flatnonzero(arc)
    arc_row[ai] = np.arange(len(ai))
    # the planner's own arc model (Klipper's chords under Klipper's rules), printed backwards or not
    arc_us, arc_ue, arc_phi, arc_seg, arc_path = arc_tangents(program, steps[ai], L[ai], klipper, backwards)
    if klipper and len(ai):
        L[ai] = arc_path
    stop_before = np.ones(m, np.bool_)
    stop_before[1:] = owner[1:] != owner[:-1]
    table, regime = lim.regimes_at(program.line[steps])
    code = pk.JUNCTION_CODE[lim.junction]
    vnom, acc, safe, vj, _ = pk.prepare_moves(
        code, d, L, program.feed_mm_s[steps].astype(float), arc_row, arc_us, arc_ue, arc_phi,
        arc_seg, stop_before, regime, np.ascontiguousarray(table))
    if m and not (np.all(np.isfinite(acc) & (acc > 0)) and np.all(np.isfinite(vnom) & (vnom > 0))):
        return None         # the planner refuses such a file; nothing to price here
    # each curve ends at rest: the passes stop before every curve's first move, and a move
    # before a stop ends at its safe speed
    entry, exit_, peak, t_acc, t_cruise, t_dec = pk.plan_moves(L, acc, vnom, vj, safe, stop_before)
    u = d / np.maximum(L, 1e-300)[:, None]
    us, ue = u.copy(), u.copy()
    us[ai], ue[ai] = arc_us, arc_ue
    return _Alone(owner, steps, L, vnom, acc, safe, np.minimum(entry, vnom),
                  np.minimum(exit_, vnom), peak, t_acc + t_cruise + t_dec, us, ue)


@dataclass(frozen=True, eq=False)
class CurveEnds:
    """Per curve c and orientation o (0: as the slicer printed it, 1: backwards), the moves
    that meet the travels around it, as ``gap_plan.plan_ends_s`` joins them to a link's moves
    (formulations/ordering.md, "Cost model"): ``head[c, o]`` its first move and ``tail[c, o]``
    its last, as prepared work rows (``gap_plan.work_array`` columns: an arc's row carries its
    tangent where it meets the travel); ``head_exit_mm_s`` / ``tail_entry_mm_s`` the speed the
    curve planned alone has where the head ends / the tail starts (a link's plan keeps them as
    caps), ``head_ms`` / ``tail_ms`` their time planned alone. A curve of one move is split at
    its middle: the head is its first half, the tail its second, both at its peak speed there.
    ``node_ms[c]``: what printing c backwards adds to its moves' time planned alone (0 for
    loops). ``ok[c]``: c has moves and the limits plan (else a link prices without them)."""

    head: np.ndarray            # (n, 2, W_COLS)
    tail: np.ndarray            # (n, 2, W_COLS)
    head_exit_mm_s: np.ndarray  # (n, 2)
    tail_entry_mm_s: np.ndarray
    head_ms: np.ndarray
    tail_ms: np.ndarray
    node_ms: np.ndarray         # (n,)
    ok: np.ndarray              # (n,) bool
    #: per curve, its first / last move's step (-1: none) and whether it is one move
    first_step: np.ndarray
    last_step: np.ndarray
    single: np.ndarray

    @staticmethod
    def empty(n: int) -> "CurveEnds":
        z2 = np.zeros((n, 2))
        return CurveEnds(np.zeros((n, 2, gp.W_COLS)), np.zeros((n, 2, gp.W_COLS)), z2, z2.copy(),
                         z2.copy(), z2.copy(), np.zeros(n), np.zeros(n, bool),
                         np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, bool))

    @staticmethod
    def of(program: Program, lim: MachineLimits, s0, s1, closed) -> "CurveEnds":
        s0, s1 = np.asarray(s0, np.int64), np.asarray(s1, np.int64)
        n = len(s0)
        out = CurveEnds.empty(n)
        if not n or junction_code(lim) < 0:
            return out
        plans = [_alone(program, lim, s0, s1, bw) for bw in (False, True)]
        if plans[0] is None or plans[1] is None or not len(plans[0].owner):
            return out
        totals = []
        for o, a in enumerate(plans):
            totals.append(np.bincount(a.owner, weights=a.t, minlength=n))
            m = len(a.owner)
            first = np.ones(m, bool)
            first[1:] = a.owner[1:] != a.owner[:-1]
            last = np.ones(m, bool)
            last[:-1] = a.owner[1:] != a.owner[:-1]
            fi, li = np.flatnonzero(first), np.flatnonzero(last)
            cf, cl = a.owner[fi], a.owner[li]
            single = np.zeros(n, bool)
            single[cf] = fi == li
            for rows, idx, cs, u in ((out.head, fi, cf, a.u_start), (out.tail, li, cl, a.u_end)):
                r = rows[cs, o]
                r[:, gp.W_U:gp.W_U + 4] = u[idx]
                r[:, gp.W_L] = np.where(single[cs], 0.5, 1.0) * a.L[idx]
                r[:, gp.W_V], r[:, gp.W_A], r[:, gp.W_SAFE] = a.vnom[idx], a.acc[idx], a.safe[idx]
                r[:, gp.W_READY] = 1.0
                rows[cs, o] = r
            half = np.where(single[cf], 0.5, 1.0)
            out.head_exit_mm_s[cf, o] = np.where(single[cf], a.peak[fi], a.exit[fi])
            out.head_ms[cf, o] = half * a.t[fi] * 1000.0
            half = np.where(single[cl], 0.5, 1.0)
            out.tail_entry_mm_s[cl, o] = np.where(single[cl], a.peak[li], a.entry[li])
            out.tail_ms[cl, o] = half * a.t[li] * 1000.0
            if o == 0:
                out.ok[cf] = True
                out.first_step[cf] = a.steps[fi]
                out.last_step[cl] = a.steps[li]
                out.single[:] = single
        out.node_ms[:] = (totals[1] - totals[0]) * 1000.0
        out.node_ms[np.asarray(closed, bool)] = 0.0
        # below NODE_MIN_MS a curve's two directions are one price: under Klipper the rest is
        # an arc chorded from its other end (real_orca230_arcs: 95 % of its curves under
        # 0.01 ms, none above 0.13 ms), under the model's own error per layer (0.3-1.4 ms
        # measured), and a direction term on a candidate keeps the symmetric model from
        # proving any group holding it (it prices an edge at the cheaper direction)
        out.node_ms[np.abs(out.node_ms) < NODE_MIN_MS] = 0.0
        return out

    def reversal_ok(self, rtol: float = 1e-9) -> np.ndarray:
        """Per curve: its boundary moves printed backwards (orientation 1) are those printed as
        the slicer printed them (orientation 0) run backwards -- the same length, nominal speed,
        acceleration and safe speed, the XYZ direction reversed, the speed caps and times planned
        alone the same -- so that a link joined to it backwards is its mirror's run backwards
        (``cost._mirrorable``). Not so where a boundary move is an arc Klipper chords from its
        own start (the chords of the two orientations differ), nor under a rule whose alone
        plans differ by direction."""
        ok = self.ok.copy()
        scal = (gp.W_L, gp.W_V, gp.W_A, gp.W_SAFE)
        for a, b in ((self.tail[:, 0], self.head[:, 1]), (self.head[:, 0], self.tail[:, 1])):
            for col in scal:
                ok &= np.isclose(a[:, col], b[:, col], rtol=rtol, atol=1e-12)
            ok &= np.isclose(a[:, gp.W_U:gp.W_U + 3], -b[:, gp.W_U:gp.W_U + 3], rtol=0,
                             atol=1e-12).all(axis=1)
            ok &= np.isclose(a[:, gp.W_U + 3], b[:, gp.W_U + 3], rtol=0, atol=1e-12)
        for a, b in ((self.tail_entry_mm_s[:, 0], self.head_exit_mm_s[:, 1]),
                     (self.head_exit_mm_s[:, 0], self.tail_entry_mm_s[:, 1]),
                     (self.tail_ms[:, 0], self.head_ms[:, 1]),
                     (self.head_ms[:, 0], self.tail_ms[:, 1])):
            ok &= np.isclose(a, b, rtol=rtol, atol=1e-12)
        return ok

    def context_ms(self, pl) -> tuple[np.ndarray, np.ndarray]:
        """(head, tail): per curve, what its head / tail move (half a one-move curve) takes in
        the slicer's file as planned (``pl``: ``planner.Plan`` of the program) less what it
        takes planned alone: the part of the curve's time a copied gap's junctions decide."""
        n = len(self.ok)
        head, tail = np.zeros(n), np.zeros(n)
        c = np.flatnonzero(self.ok)
        if not len(c):
            return head, tail
        f, la, one = self.first_step[c], self.last_step[c], self.single[c]
        t_first = pl.duration_s[f]
        t_last = pl.duration_s[la]
        half = np.asarray(pl.time_at_fraction(f[one], 0.5), float)
        h = t_first.copy()
        h[one] = half
        tl = t_last.copy()
        tl[one] = t_last[one] - half
        head[c] = h * 1000.0 - self.head_ms[c, 0]
        tail[c] = tl * 1000.0 - self.tail_ms[c, 0]
        return head, tail


def gap_rows(program: Program, lay, lim: MachineLimits) -> tuple[np.ndarray, np.ndarray]:
    """(table, row): the limits regimes of ``lim`` (``MachineLimits.regimes``) and per curve c
    of ``lay`` the regime in force at the slicer's last travel in the gap before c (its last
    motion step without one, c's first step in a gap without motion): what a link into c runs
    under (``layout.link_travel_steps``: the emitter re-issues those limits before its travel)."""
    table, regime = lim.regimes_at(program.line[link_travel_steps(program, lay)])
    return np.ascontiguousarray(table, float), regime


def junction_code(lim: MachineLimits) -> int:
    """The planner's junction rule of ``lim`` (``_planner_kernel.JUNCTION_CODE``), -1 unknown."""
    return pk.JUNCTION_CODE.get(lim.junction, -1)
