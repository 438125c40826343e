"""The travel between two curves that are no longer neighbours, rebuilt the way the slicer builds
its travels (formulations/ordering.md, "Emit"): retract (if the travel is at least the shortest
travel the slicer retracted for), z-hop, one straight travel, lower, unretract, with the
parameters read from the file (``travel.TravelStyle``). A combing slicer's travel that crosses no
wall of its layer skips the retraction (``travel.TravelRule``, ``travel.WallCrossing``). The gaps' non-motion lines are
kept around it.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..program import Program
from .layout import (LINE_CURVE, LINE_FW_RETRACT, LINE_FW_UNRETRACT, LINE_MOTION, LINE_NEUTRAL,
                     Layout)
from .travel import TravelRule
from .writer import Writer

#: the gap lines a curve moved elsewhere leaves behind: feature labels and wipe markers are
#: re-derived where it lands
TYPE_OR_WIPE = re.compile(r"^\s*;\s*(TYPE:|FEATURE:|feature |WIPE_START|WIPE_END)", re.I)


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
    ``rebuilt_gap``); its moves summed."""
    pre, mid, post, late = [], [], [], []
    boundary_retracted = early_push = False
    fw_lines, fw_net, fw_boundary, fw_retracted = set(), 0, False, False
    r_boundary = r_internal = 0.0
    net = 0.0
    cls_of, de_of, travel_of = w.line_cls, w.line_de, w.line_travel
    gap: list[int] = []
    for lines, boundary in line_sets:
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
            if not boundary and cls[j] == LINE_NEUTRAL and TYPE_OR_WIPE.match(p.line_text(i)):
                continue
            (pre if j < split_r else mid if j < split_t else post if j < split_u else late).append(i)
    return _GapLines(pre, mid, post, late, gap, net, r_boundary, r_internal, boundary_retracted,
                     early_push, fw_lines, fw_net, fw_boundary, fw_retracted)


def rebuilt_gap(w: Writer, p: Program, lay: Layout, rule: TravelRule, line_sets, c: int,
                target, layer: int = -1) -> None:
    """One rebuilt travel into curve c, with the non-motion lines of the given original gaps.

    Each gap's lines split where the slicer retracted, travelled and unretracted: lines before
    its first retraction come before ours, lines after its last travel after our travel, lines
    after its unretraction after ours. The filament
    the consumed gaps pulled back and pushed forward is kept: the retraction length is the
    slicer's own for this gap (else the file's median), and the net E of the consumed gaps is
    unchanged, so E per layer (and across a layer change) stays what it was. Whether it
    retracts is ``rule``'s (``travel.TravelRule``), which ``cost.TimePricer`` prices: the
    retraction length is the boundary gap's, else the file's median.
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
        w.copy_line(i)

    for i in pre:
        copy(i)
    (tx, ty, tz), (x0, y0, z0) = target.tolist(), w.xyz.tolist()
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
        move_e(-r, style.retract_feed_mm_s)
    for i in mid:
        copy(i)
    if moving:
        x_now, y_now, z_now = w.xyz.tolist()
        z_to = tz
        if retract and style.hop_mm > 0:
            z_up = max(z_now, z_to) + style.hop_mm
        else:
            z_up = max(z_now, z_to)
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
