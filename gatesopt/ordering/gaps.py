"""The travel between two curves that are no longer neighbours, rebuilt the way the slicer builds
its travels (formulations/ordering.md, "Emit"): retract (if the travel is at least the shortest
travel the slicer retracted for), z-hop, one straight travel, lower, unretract, with the
parameters read from the file (``travel.TravelStyle``). A combing slicer's travel that crosses no
wall of its layer skips the retraction (``travel.TravelRule``, ``travel.WallCrossing``). The gaps' non-motion lines are
kept around it.

A link between the two ends of a slicer's gap the other way round (from curve c + 1 back into
curve c) writes that gap backwards where it is pure travel (``ReversibleGaps``, ``reversed_gap``;
formulations/ordering.md, "Reversed gaps"): the time objective prices it at the gap's own time,
which makes its link costs symmetric.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..program import Kind, Program
from .layout import (LINE_BARRIER, LINE_CURVE, LINE_FW_RETRACT, LINE_FW_UNRETRACT, LINE_MOTION,
                     LINE_NEUTRAL, LINE_STATE, Layout)
from .travel import TravelRule
from .wipes import WIPE_E_EPS_MM
from .writer import Writer

#: a gap's E-only steps (plain ints: an enum lookup per step is slow)
E_MOVE_KINDS = (int(Kind.RETRACT), int(Kind.UNRETRACT))
#: the gap lines a curve moved elsewhere leaves behind: feature labels and wipe markers are
#: re-derived where it lands
TYPE_OR_WIPE = re.compile(r"^\s*;\s*(TYPE:|FEATURE:|feature |WIPE_START|WIPE_END)", re.I)
#: a reversed gap's net E and its ends' height difference may be this far from 0 (float noise of
#: absolute E / Z read from the file)
REVERSE_EPS = 1e-9
#: step kinds a reversible gap may hold: travels without E, E-only moves, Z-only moves
REVERSIBLE_KINDS = (int(Kind.TRAVEL), int(Kind.RETRACT), int(Kind.UNRETRACT), int(Kind.Z_ONLY))


@dataclass(frozen=True, eq=False)
class ReversibleGaps:
    """Per curve c, about the slicer's gap before it (between curve c - 1 and c; formulations/
    ordering.md, "Reversed gaps"):

    ``plain[c]``: its lines are moves, neutral lines and state lines only (no firmware
    retraction, E reset, barrier): a link into c that writes another gap's moves reversed can
    take its lines along (``reversed_gap``);
    ``ok[c]``: also, it can be written reversed -- from the start of c back to the end of c - 1,
    each move run backwards at its own feed: no state line (its moves ran under the state curve
    c - 1 saw, which curve c sees too), travels without E, E-only and Z-only moves (no wipe, no
    arc), net E 0 and both ends at one height. Its reverse is then the same moves in reverse
    order (a retraction at its start, the unretraction at its end), and the planner's time of a
    move sequence run backwards is the same (trapezoids with equal acceleration and deceleration;
    a junction's speed limit depends on the angle between its moves, the same either way round):
    the link from c back into c - 1 costs the gap's own time (``cost.TimePricer``).
    ``start_xy[c]`` / ``end_xy[c]``: where curve c starts and ends (the gap before c ends at
    ``start_xy[c]`` and starts at ``end_xy[c - 1]``)."""

    ok: np.ndarray          # (n,) bool
    plain: np.ndarray       # (n,) bool
    start_xy: np.ndarray    # (n, 2)
    end_xy: np.ndarray      # (n, 2)

    @staticmethod
    def of(program: Program, lay: Layout) -> "ReversibleGaps":
        n = len(lay.curve_s0)
        s0, s1 = lay.curve_s0, lay.curve_s1
        start_xy = program.start_mm[s0, :2].astype(float) if n else np.zeros((0, 2))
        end_xy = program.end_mm[s1 - 1, :2].astype(float) if n else np.zeros((0, 2))
        ok = np.zeros(n, bool)
        plain = np.zeros(n, bool)
        if n < 2:
            return ReversibleGaps(ok, plain, start_xy, end_xy)
        cls = lay.line_class
        g0, g1 = lay.curve_l1[:-1] + 1, lay.curve_l0[1:]        # gap before c = 1..n-1: lines [g0, g1)

        def span(flags, a, b):
            c = np.concatenate(([0], np.cumsum(flags)))
            return c[b] - c[a]
        plain_cls = (cls == LINE_MOTION) | (cls == LINE_NEUTRAL) | (cls == LINE_STATE)
        plain[1:] = (span(~plain_cls, g0, g1) == 0) & ~lay.gap_boundary[1:]
        a, b = s1[:-1], s0[1:]                                     # its steps [a, b)
        d = program.end_mm - program.start_mm
        moves_xy = np.hypot(d[:, 0], d[:, 1]) > REVERSE_EPS
        bad = ~np.isin(program.kind, np.asarray(REVERSIBLE_KINDS, program.kind.dtype)) | (
            moves_xy & (np.abs(d[:, 3]) > 0.0))
        net_e = span(d[:, 3], a, b)
        dz = program.start_mm[b, 2] - program.end_mm[s1[:-1] - 1, 2]
        ok[1:] = (plain[1:] & (span(cls == LINE_STATE, g0, g1) == 0) & (span(bad, a, b) == 0)
                  & (np.abs(net_e) <= REVERSE_EPS) & (np.abs(dz) <= REVERSE_EPS))
        return ReversibleGaps(ok, plain, start_xy, end_xy)

    def applies(self, group_first, p: int, c: int, head_xy, entry_xy) -> bool:
        """Whether the link from curve p (the head at ``head_xy``) into curve c (entered at
        ``entry_xy``) is the gap before p written reversed: p follows c in the file, in one group,
        the gap between them reversible, the head where that gap ended and c entered where it
        began; a gap that c's entry consumes (c not its group's first) plain. The pricer's
        kernels (``link_cost.reversed_link``) test the same."""
        if p != c + 1 or c < 0 or not self.ok[p] or group_first[p] != group_first[c]:
            return False
        if c != group_first[c] and not self.plain[c]:
            return False
        return (abs(head_xy[0] - self.start_xy[p, 0]) <= REVERSE_EPS
                and abs(head_xy[1] - self.start_xy[p, 1]) <= REVERSE_EPS
                and abs(entry_xy[0] - self.end_xy[c, 0]) <= REVERSE_EPS
                and abs(entry_xy[1] - self.end_xy[c, 1]) <= REVERSE_EPS)


@dataclass(frozen=True, eq=False)
class GapFacts:
    """What the slicer's gaps before each curve hold, as ``rebuilt_gap`` sums it: per curve
    c the gap between curve c - 1 and c (``own_*``) and the boundary gap of c's group (the gap
    before the group's first curve, ``bnd_*``, indexed by curve too)."""

    net_e: np.ndarray           # (n,) net E of the gap's moves (mm of filament)
    retract_mm: np.ndarray      # (n,) filament its moves pull back
    fw_net: np.ndarray          # (n,) firmware unretractions minus retractions (G11 - G10)
    fw_retracted: np.ndarray    # (n,) bool: a G10 in the gap

    @staticmethod
    def of(program: Program, lay: Layout) -> "GapFacts":
        n = len(lay.curve_s0)
        l1 = lay.curve_l1
        g0 = np.concatenate(([0], l1[:-1] + 1)) if n else np.zeros(0, np.int64)    # gap lines [g0, g1)
        g1 = lay.curve_l0
        step = lay.step_of_line
        has = step >= 0
        s = np.where(has, step, 0)
        de = np.where(has & (lay.line_class == LINE_MOTION), program.end_mm[s, 3] - program.start_mm[s, 3], 0.0)

        def span(v):
            c = np.concatenate(([0.0], np.cumsum(v)))
            return c[g1] - c[g0]
        return GapFacts(span(de), span(np.where(de < 0, -de, 0.0)),
                        np.rint(span(lay.line_class == LINE_FW_UNRETRACT)
                                - span(lay.line_class == LINE_FW_RETRACT)).astype(np.int64),
                        span(lay.line_class == LINE_FW_RETRACT) > 0)


@dataclass
class _GapLines:
    """The lines of the consumed gaps by where they go around our travel (``_sort_lines``), and
    what their moves did to the filament."""

    pre: list           # before our retraction
    mid: list           # between it and our travel
    post: list          # after our travel, before our unretraction
    late: list          # after our unretraction
    gap: list           # every line of the consumed gaps, in order
    net: float          # net E of their moves (mm of filament)
    r_boundary: float   # filament the boundary gap retracted
    r_internal: float   # filament the gaps inside the group retracted
    boundary_retracted: bool
    early_push: bool    # the slicer unretracted before its last travel
    fw_lines: set       # firmware retraction lines (bare G10 / G11)
    fw_net: int         # G11s minus G10s
    fw_boundary: bool   # a G10 in the boundary gap
    fw_retracted: bool  # any G10


def _sort_lines(w: Writer, p: Program, line_sets) -> _GapLines:
    """Each gap's lines split where the slicer retracted, travelled and unretracted (see
    ``rebuilt_gap``); its moves summed. A barrier or a neutral command (``Writer.command_set``:
    progress, messages) of a later gap never goes before one of an earlier gap: it goes at least
    where that one went (a Bambu Studio layer change holds ``M73 L2`` and the aux fan's barrier
    ``M106 P2``; the next layer's first curve's own gap an ``M73 P38`` inside its wipe, which,
    written before our retraction, went ahead of the barrier: verify reads the control commands
    out of order)."""
    pre, mid, post, late = [], [], [], []
    parts = (pre, mid, post, late)
    floor = 0           # where the last barrier or command of an earlier gap went (index in parts)
    boundary_retracted = early_push = False
    fw_lines, fw_net, fw_boundary, fw_retracted = set(), 0, False, False
    r_boundary = r_internal = 0.0
    net = 0.0
    cls_of, de_of, travel_of = w.line_cls, w.line_de, w.line_travel
    marked = w.marker_moves
    commands = w.command_set
    gap: list[int] = []
    for lines, boundary in line_sets:
        set_floor = floor
        lines = list(lines)
        gap += lines
        cls = [cls_of[i] for i in lines]
        travel_pos = [j for j, i in enumerate(lines) if travel_of[i]]
        retract_pos = [j for j, i in enumerate(lines)
                       if (cls[j] == LINE_MOTION and de_of[i] < 0) or cls[j] == LINE_FW_RETRACT]
        split_t = travel_pos[-1] if travel_pos else len(lines)
        split_r = min(retract_pos[0], split_t) if retract_pos else split_t
        push_pos = [j for j, i in enumerate(lines)
                    if (cls[j] == LINE_MOTION and de_of[i] > 0) or cls[j] == LINE_FW_UNRETRACT]
        split_u = push_pos[-1] if push_pos else len(lines)
        if boundary and push_pos and push_pos[-1] < split_t:
            early_push = True
        for j, i in enumerate(lines):
            if cls[j] == LINE_MOTION:
                d_e = de_of[i]
                net += d_e
                if d_e < 0:
                    if boundary:
                        boundary_retracted = True
                        r_boundary -= d_e
                    else:
                        r_internal -= d_e
                if i in marked:
                    # the layer's marker after this move's G-code (Slic3r's ``G1 Z1 F7800 ; move
                    # to next layer (4)``): our travel replaces the move, its marker stays where
                    # it was (``Writer.copy_gap_line``); dropped, the layers after it merged
                    (pre if j < split_r else mid if j < split_t else post if j < split_u else late).append(i)
                continue
            if cls[j] == LINE_CURVE:
                continue
            if cls[j] == LINE_FW_RETRACT or cls[j] == LINE_FW_UNRETRACT:
                fw_lines.add(i)
                if cls[j] == LINE_FW_RETRACT:
                    fw_net -= 1
                    fw_retracted = True
                    fw_boundary = fw_boundary or boundary
                else:
                    fw_net += 1
            if not boundary and cls[j] == LINE_NEUTRAL and TYPE_OR_WIPE.match(w.texts[i]):
                continue
            at = 0 if j < split_r else 1 if j < split_t else 2 if j < split_u else 3
            if cls[j] == LINE_BARRIER or i in commands:
                at = max(at, set_floor)
                floor = max(floor, at)
            parts[at].append(i)
    return _GapLines(pre, mid, post, late, gap, net, r_boundary, r_internal, boundary_retracted,
                     early_push, fw_lines, fw_net, fw_boundary, fw_retracted)


#: a slicer's travel that climbs more than this above both its ends and the file's hop is a
#: clearance lift, which a rebuilt travel keeps (``rebuilt_gap``)
CLEARANCE_EPS_MM = 1e-3


def gap_top_z(p: Program, lay: Layout, lines) -> float:
    """The highest Z (machine mm) the slicer's moves among ``lines`` reach (-inf: no move)."""
    if not len(lines):
        return -math.inf
    steps = lay.step_of_line[np.asarray(lines, np.int64)]
    steps = steps[steps >= 0]
    return float(p.end_mm[steps, 2].max()) if len(steps) else -math.inf


def rebuilt_gap(w: Writer, p: Program, lay: Layout, rule: TravelRule, line_sets, c: int,
                target, layer: int = -1, limits=None, wipe=None) -> None:
    """One rebuilt travel into curve c, with the non-motion lines of the given original gaps.

    Each gap's lines split where the slicer retracted, travelled and unretracted: lines before
    its first retraction come before ours, lines after its last travel after our travel, lines
    after its unretraction after ours. The filament
    the consumed gaps pulled back and pushed forward is kept: the retraction length is the
    slicer's own for this gap (else the file's median), and the net E of the consumed gaps is
    unchanged, so E per layer (and across a layer change) stays what it was. Whether it
    retracts is ``rule``'s (``travel.TravelRule``), which ``cost.TimePricer`` prices: the
    retraction length is the boundary gap's, else the file's median. ``limits``: (states, k) of
    ``writer.states_at`` -- the motion limits the travel runs under, re-issued (``Writer.reissue``)
    after the lines that come before it (``emitter``: those in force at the slicer's travel).
    ``wipe``: the wipe the slicer made after the curve the head leaves, printed as the slicer
    printed it (``(moves, e_mm)``, ``emitter._wipe_of``): where the travel retracts (by E, and
    no more than the wipe pulls back), its moves come first, then the rest of the retraction in
    place, and the travel starts where the wipe ended (``wipes``; ``link_cost.rebuilt_s`` prices
    the same).
    """
    style = rule.style
    g = _sort_lines(w, p, line_sets)
    pre, mid, post, late, gap, net = g.pre, g.mid, g.post, g.late, g.gap, g.net
    r_boundary, boundary_retracted = g.r_boundary, g.boundary_retracted
    fw_lines, fw_boundary = g.fw_lines, g.fw_boundary
    cls_of, de_of = w.line_cls, w.line_de
    # firmware retraction (bare G10 / G11): rebuilt as one G10 before our travel and one G11
    # after it, unless the consumed gaps do not end as retracted as they began (then copied)
    use_fw = g.fw_net == 0 and (g.fw_retracted or (
        style.firmware_retract and r_boundary <= 0 and g.r_internal <= 0))
    if use_fw and fw_lines:
        pre, mid, post, late = ([i for i in b if i not in fw_lines] for b in (pre, mid, post, late))
    s = int(lay.curve_s0[c])
    off = p.offset_mm[s]
    relative_e = bool(p.relative_e[s])
    # E per layer must not change: where a layer's first line lies inside these gaps, what this
    # gap has emitted when that line is copied must equal what the slicer's gap lines before it
    # moved (net_before)
    net_before = {}
    markers = [i for i in gap if i in w.layer_lines]
    if markers:
        mot = [i for i in gap if cls_of[i] == LINE_MOTION]
        de = np.asarray([de_of[i] for i in mot], float)
        mot = np.asarray(mot, np.int64)
        net_before = {m: float(de[mot < m].sum()) for m in markers}
    emitted = 0.0

    def move_e(d_e: float, feed_mm_s: float = style.unretract_feed_mm_s) -> None:
        nonlocal emitted
        w.move_e(d_e, feed_mm_s, relative_e)
        emitted += d_e

    def copy(i: int) -> None:
        if i in net_before and abs(net_before[i] - emitted) > 1e-9:
            move_e(net_before[i] - emitted)
        w.copy_gap_line(i)

    for i in pre:
        copy(i)
    if limits is not None:
        w.reissue(*limits)
    (tx, ty, tz), (x0, y0, z0) = target.tolist(), (float(v) for v in w.xyz)
    dist = math.hypot(tx - x0, ty - y0)
    moving = dist > 1e-9 or abs(tz - z0) > 1e-9
    # the boundary gap's own retraction length where it retracted (a layer change may retract
    # more), else the file's median: a link inside a group costs the same whichever curve it
    # enters, which keeps the time objective's costs symmetric there (cost.py)
    r = r_boundary if r_boundary > 0 else style.retract_mm
    if use_fw:
        retract = moving and (fw_boundary or (style.firmware_retract and dist >= style.min_travel_mm))
    else:
        retract = moving and r > 0 and (boundary_retracted
                                        or (style.retract_mm > 0 and dist >= style.min_travel_mm))
    cap = rule.comb_cap_mm
    if (retract and cap > 0 and dist <= cap and abs(tz - z0) <= 1e-9
            and not rule.walls.crosses(layer, (x0, y0), (tx, ty))):
        retract = False     # the slicer combs: a travel over infill that crosses no wall goes dry
    if retract and use_fw:
        w.write("G10")
    elif retract:
        if wipe is not None and wipe[1] <= r + WIPE_E_EPS_MM:
            x, y, z = (float(v) for v in w.xyz)
            for d_x, d_y, d_e, feed in wipe[0]:
                if abs(d_x) <= 1e-9 and abs(d_y) <= 1e-9:
                    move_e(d_e, feed)           # its E-only retraction
                    continue
                x, y = x + d_x, y + d_y
                w.move_xy_e(x, y, d_e, feed, relative_e, off)
                emitted += d_e
            if r - wipe[1] > 1e-9:
                move_e(-(r - wipe[1]), style.retract_feed_mm_s)
        else:
            move_e(-r, style.retract_feed_mm_s)
    for i in mid:
        copy(i)
    if moving:
        x_now, y_now, z_now = (float(v) for v in w.xyz)
        z_to = tz
        if retract and style.hop_mm > 0:
            z_up = max(z_now, z_to) + style.hop_mm
        else:
            z_up = max(z_now, z_to)
        top_z = gap_top_z(p, lay, gap)
        if top_z > max(z_now, z_to) + style.hop_mm + CLEARANCE_EPS_MM:
            # the slicer's travel climbed higher than a hop: a lift over what is printed (a
            # one-at-a-time print leaving an object, Cura's "G0 X.. Y.. Z10"): ours flies no
            # lower (dropped, the head crossed the object's top at its own height)
            z_up = max(z_up, top_z)
        if z_up > z_now + 1e-9:
            w.move_xyz([x_now, y_now, z_up], style.z_feed_mm_s, "G1", off)
        z_now = float(w.xyz[2])
        w.move_xyz([tx, ty, z_now], style.travel_feed_mm_s, style.travel_cmd, off)
        if abs(z_now - z_to) > 1e-9:
            w.move_xyz([tx, ty, z_to], style.z_feed_mm_s, "G1", off)
    # unretract, plus any prime the slicer's gaps added: whatever brings the gap to its net E
    if (g.early_push or not boundary_retracted) and abs(net - emitted) > 1e-9:
        # a retraction the slicer did not make here: undo it at once, on this side of any marker
        move_e(net - emitted)
    for i in post:                      # e.g. the next layer's marker: before the unretract, as the slicer
        copy(i)
    if retract and use_fw:
        w.write("G11")
    if abs(net - emitted) > 1e-9:
        move_e(net - emitted)
    for i in late:
        copy(i)


def reversed_gap(w: Writer, p: Program, lay: Layout, rule: TravelRule, line_sets, c: int) -> None:
    """The link from curve c + 1 back into curve c: the slicer's gap between them
    (``ReversibleGaps.ok``) written backwards, each of its moves from its end to its start at its
    own feed, an E move's E negated (the unretraction becomes the retraction at the start, the
    retraction the unretraction at the end); then the lines and net E of the gaps this entry
    into c consumes (``line_sets``, as ``rebuilt_gap`` takes them: c's own gap unless c begins
    its group), which travel with c (a net E there: one E move at the unretraction feed, as
    ``rebuilt_gap`` writes it and ``cost`` prices it)."""
    g = _sort_lines(w, p, line_sets)
    a, b = int(lay.curve_s1[c]), int(lay.curve_s0[c + 1])
    emitted = 0.0
    # (the steps' rows as floats, read once: numpy scalars per step were most of this)
    start, end = p.start_mm[a:b].tolist(), p.end_mm[a:b].tolist()
    offset, kind = p.offset_mm[a:b].tolist(), p.kind[a:b].tolist()
    g0 = (p.line_number[p.line[a:b]] == 0).tolist()
    feeds, relative = w.lines.step_feed, w.lines.step_relative_e
    for j in range(b - a - 1, -1, -1):
        s = a + j
        d_e = end[j][3] - start[j][3]
        if kind[j] in E_MOVE_KINDS:
            w.move_e(-d_e, feeds[s], relative[s])
            emitted -= d_e
        else:
            w.move_xyz(start[j][:3], feeds[s], "G0" if g0[j] else "G1", offset[j])
    if abs(g.net - emitted) > REVERSE_EPS:
        w.move_e(g.net - emitted, rule.style.unretract_feed_mm_s,
                 bool(p.relative_e[int(lay.curve_s0[c])]))
    for i in g.pre + g.mid + g.post + g.late:
        w.copy_gap_line(i)
