"""Program -> OrderingProblem: the curves of a ``layout.Layout`` cut into groups (formulations/
ordering.md, "Build").

Groups never span a boundary (a barrier line or a layer change). ``--order-mode safe`` further
splits at every change of feature (``;TYPE:``) and keeps walls, ironing, skirt/brim, fills the
slicer orders on purpose (monotonic, concentric) and (without feature comments) closed loops, or
loops whose end stops short of their start by at most ``LOOP_GAP_MM`` (the seam gap slicers clip),
in the slicer's order and direction; ``free`` puts each layer's curves in one group, as the paper
does, but for a pass over what the layer printed before it (ironing: ``slicers.PASS_OVER_FEATURE``),
which keeps its place, the curves before and after it in groups of their own. Layers the layout
keeps (the first, fatal lines, ...) are fixed in both modes.
"""
from __future__ import annotations

import dataclasses
import re

import numpy as np

from ..program import Kind, Program
from ..planner import plan
from ..slicers import FIXED_FEATURE, PASS_OVER_FEATURE
from .cost import TimePricer
from .move_times import MoveTimes
from .layout import Layout, layout
from .blocks import CurveGroups, order_blocks
from .problem import CLOSED_TOL_MM, COST_UNIT, OrderingOptions, OrderingProblem, group_starts
from .travel import TravelRule

#: a curve without a feature comment whose end lies this close to its start is a clipped loop
#: (a wall) in safe mode
LOOP_GAP_MM = 0.5


def _fixed_features(program: Program) -> np.ndarray:
    """(n_features,) bool: features whose order and direction the slicer fixed."""
    fixed = np.array([bool(FIXED_FEATURE.search(nm)) for nm in program.feature_names], bool)
    # solid fills printed monotonic or concentric keep their order too
    return fixed


_MONOTONIC_CFG = re.compile(rb"\n; *(top_fill_pattern|bottom_fill_pattern|solid_fill_pattern|fill_pattern|"
                            rb"top_surface_pattern|bottom_surface_pattern|infill_pattern|"
                            rb"top_bottom_pattern)\s*=\s*(\w+)")
_ORDERED_PATTERNS = (b"monotonic", b"monotonicline", b"concentric")
_SOLID_FEATURE = re.compile(r"solid|top|bottom|skin|surface", re.I)
_SPARSE_FEATURE = re.compile(r"internal infill|^fill$|sparse", re.I)


def _pattern_fixed(program: Program) -> np.ndarray:
    """Features whose fill pattern the slicer orders on purpose (monotonic, concentric)."""
    tail = program.data[-200_000:]
    cfg = {m.group(1).lower(): m.group(2).lower() for m in _MONOTONIC_CFG.finditer(b"\n" + tail)}
    solid_ordered = any(cfg.get(k, b"") in _ORDERED_PATTERNS for k in (
        b"top_fill_pattern", b"bottom_fill_pattern", b"solid_fill_pattern", b"top_surface_pattern",
        b"bottom_surface_pattern", b"top_bottom_pattern"))
    sparse_ordered = any(cfg.get(k, b"") in _ORDERED_PATTERNS for k in (b"fill_pattern", b"infill_pattern"))
    out = np.zeros(len(program.feature_names), bool)
    for i, nm in enumerate(program.feature_names):
        if solid_ordered and _SOLID_FEATURE.search(nm):
            out[i] = True
        if sparse_ordered and _SPARSE_FEATURE.search(nm):
            out[i] = True
    return out


def build(program: Program, options: OrderingOptions | None = None, lay: Layout | None = None) -> OrderingProblem:
    """Curves and groups of ``program`` (see module docstring)."""
    options = options or OrderingOptions()
    lay = lay or layout(program)
    s0, s1 = lay.curve_s0, lay.curve_s1
    n = len(s0)
    start_xy = program.start_mm[s0, :2] if n else np.zeros((0, 2))
    end_xy = program.end_mm[s1 - 1, :2] if n else np.zeros((0, 2))
    closed = np.hypot(*(end_xy - start_xy).T) <= CLOSED_TOL_MM if n else np.zeros(0, bool)
    # a curve that ends in the slicer's coasting is never a loop, even where the coast reaches
    # its start (Cura coasts along the wall's last stretch): a loop started elsewhere would coast
    # mid-way
    coast = np.asarray(lay.curve_coast, bool) if len(lay.curve_coast) == n else np.zeros(n, bool)
    closed = closed & ~coast
    # polyline vertices: the start of each step and the end of the last
    counts = (s1 - s0) + 1
    pstart = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    if n:
        idx = np.concatenate([np.arange(a, b) for a, b in zip(s0, s1)])
        owner = np.repeat(np.arange(n), s1 - s0)
        pts = np.empty((pstart[-1], 2))
        pos_in = pstart[owner] + (idx - s0[owner])
        pts[pos_in] = program.start_mm[idx, :2]
        pts[pstart[1:] - 1] = end_xy
        # arcs cannot start a rotated loop (their centre would move with the seam): no seam there
        has_arc = np.zeros(n, bool)
        np.logical_or.at(has_arc, owner, program.kind[idx] == Kind.ARC)
        closed = closed & ~(has_arc & options.move_seams)
    else:
        pts = np.zeros((0, 2))
    # a wall where no feature comment says what a curve is: a closed loop, or one whose end stops
    # just short of its start (Slic3r and PrusaSlicer clip 15 % of the nozzle off a loop's end
    # against a seam bulge: 0.06-0.1 mm); safe mode keeps such curves' order and direction
    gap_mm = np.hypot(*(end_xy - start_xy).T) if n else np.zeros(0)
    wall_like = closed | ((gap_mm <= LOOP_GAP_MM) & (s1 - s0 >= 3))
    # printed in their own direction only (``candidates``), in free mode too: the clipped loops
    # (a wall's direction is the slicer's choice) and the coasted curves, which printed
    # backwards would coast into their start
    one_way = (wall_like & ~closed) | coast
    layer = program.layer[s0].astype(np.int64)
    feature = program.feature[s0].astype(np.int64)
    fixed_feat = _fixed_features(program) | _pattern_fixed(program)
    has_features = len(program.feature_names) > 0
    pass_over = np.array([bool(PASS_OVER_FEATURE.search(nm)) for nm in program.feature_names], bool)
    # ---- groups: per curve whether it keeps the slicer's order, and the key a group shares
    fixed = np.zeros(n, bool)
    key = np.zeros(n, np.int64)
    labels = []
    for c in range(n):
        lay_c = int(layer[c])
        keep = bool(lay.layer_keep[lay_c]) if lay_c < len(lay.layer_keep) else True
        if options.mode == "safe":
            if keep:
                fx = True
            elif has_features and feature[c] >= 0:
                fx = bool(fixed_feat[feature[c]])
            else:
                fx = bool(wall_like[c])
            key[c] = 2 * (feature[c] + 1) + fx
        else:
            # one group per layer, but a pass over what was printed before it (ironing) keeps
            # its place: the curves before it and those after it are groups of their own
            fx = keep or bool(has_features and feature[c] >= 0 and pass_over[feature[c]])
            key[c] = fx
        fixed[c] = fx
        fname = program.feature_names[feature[c]] if feature[c] >= 0 else ("loops" if wall_like[c] else "curves")
        labels.append(f"L{lay_c} {fname if options.mode == 'safe' else 'all'}")
    boundary = np.ones(n, bool)
    if n > 1:
        boundary[1:] = lay.gap_boundary[1:] | (layer[1:] != layer[:-1])
    gstart = group_starts(boundary, key)
    glayer = layer[gstart[:-1]]
    gfixed = fixed[gstart[:-1]]
    glabel = [labels[c] for c in gstart[:-1].tolist()]
    origin = program.start_mm[s0[0], :2] if n else np.zeros(2)
    notes = list(lay.notes)
    for i, w in enumerate(lay.layer_why):
        if w and i > 0:
            notes.append(f"layer {i}: {w}")
    problem = OrderingProblem(
        curve_start_xy=start_xy, curve_end_xy=end_xy, curve_closed=np.asarray(closed, bool),
        curve_layer=layer, points_xy=pts, curve_point_start=pstart,
        group_curve_start=gstart, group_layer=np.asarray(glayer, np.int64),
        group_fixed=np.asarray(gfixed, bool), group_label=tuple(glabel), origin_xy=origin,
        options=options, cost_unit=COST_UNIT[options.objective],
        curve_step_start=s0, curve_step_stop=s1, notes=tuple(notes), layout=lay,
        curve_one_way=one_way)
    step_plan = None
    if options.objective == "time":
        # the limits read once (~0.13 s on a 170k-line Klipper file): the plan, both pricers
        lim = options.limits_of(program)
        step_plan = plan(program, lim) if options.copied_gaps == "planner" else None
        problem = with_pricer(program, problem, step_plan, limits=lim)
        first_pricer = problem.pricer
    if options.mode == "safe" and options.blocks:
        # islands and labelled objects. Not in free mode: its groups choose their own entry, which
        # a block order fixed on the slicer's first and last curves does not see (moving the
        # objects measured worse there: plate__cura_mk3 free -4.16 % -> -3.75 %, docs/RESULTS.md)
        problem = order_blocks(program, problem, CurveGroups(boundary, key, fixed, tuple(labels),
                                                             wall_like))
        if problem.base is not None and options.objective == "time":
            # priced again on the groups the islands' new order made (blocks.permuted)
            # (the curves' own end moves and times do not depend on the groups: made once)
            base = with_pricer(program, problem.base, step_plan, first_pricer.ends,
                               first_pricer.limits)
            problem = dataclasses.replace(problem, base=base, pricer=base.pricer)
    return problem


def with_pricer(program: Program, problem: OrderingProblem, step_plan=None,
                ends=None, limits=None) -> OrderingProblem:
    """``problem`` with the time objective's link costs (``cost.TimePricer``): the rule the
    emitter follows (``travel.TravelRule``, read from the file's own travels) and the planner's
    limits for each move (``move_times.MoveTimes``, ``limits.machine_limits``). ``step_plan``: the
    program's ``planner.Plan`` where it was made already (copied gaps are priced from it);
    ``ends``: its ``curve_time.CurveEnds`` where made already; ``limits``: the program's under
    the problem's options (``OrderingOptions.limits_of``) where read already."""
    lay = problem.layout
    rule = TravelRule.of(program, problem, lay)
    lim = limits if limits is not None else problem.options.limits_of(program)
    move = MoveTimes.from_limits(lim)
    if step_plan is None and problem.options.copied_gaps == "planner":
        step_plan = plan(program, lim)
    step_s = None if step_plan is None else step_plan.duration_s
    return dataclasses.replace(problem, cost_unit=COST_UNIT["time"],
                               pricer=TimePricer(program, lay, problem, rule, move, step_s, lim,
                                                 step_plan, ends))
