"""How the slicer travels between curves, read from its own gaps (formulations/ordering.md,
"Emit"): retraction, z-hop, speeds, whether it combs (``TravelStyle``, ``travel_style``), and the
combing test for a rebuilt travel: does it cross a wall of its layer (``WallCrossing``)?
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..program import Kind, Program
from ..slicers import WALL_FEATURE
from .layout import LINE_FW_RETRACT, Layout
from .problem import OrderingProblem


@dataclass(frozen=True)
class TravelStyle:
    """How the slicer travels, read from its own gaps."""

    retract_mm: float = 0.0         # filament pulled back before a travel
    retract_feed_mm_s: float = 35.0
    unretract_feed_mm_s: float = 35.0
    min_travel_mm: float = np.inf   # shortest travel the slicer retracted for
    hop_mm: float = 0.0             # z-hop height (0: none)
    travel_feed_mm_s: float = 150.0
    z_feed_mm_s: float = 10.0
    travel_cmd: str = "G1"
    #: longest same-layer travel the slicer made without retracting (combing: Cura, ideaMaker,
    #: Creality Print, PrusaSlicer's "only retract when crossing perimeters"); 0: it does not comb
    comb_max_mm: float = 0.0
    #: the slicer retracts with bare G10 / G11 (the firmware's retraction, not E moves)
    firmware_retract: bool = False


#: travels shorter than this say nothing about combing (every slicer skips retracting for them)
COMB_MIN_TRAVEL_MM = 2.0
#: share of long same-layer travels without retraction that marks a combing slicer
COMB_SHARE = 0.2
#: a rebuilt travel is trimmed by this much at each end before the wall-crossing test (its ends
#: are curve ends, which touch walls)
COMB_TRIM_MM = 0.3


def _cross_z(o, v, w):
    """z of (v - o) x (w - o): which side of the line o -> v the point w lies on."""
    return (v[..., 0] - o[..., 0]) * (w[..., 1] - o[..., 1]) - (v[..., 1] - o[..., 1]) * (w[..., 0] - o[..., 0])


class WallCrossing:
    """Does a straight travel cross a wall of its layer? (A combing slicer's reason to retract.)

    Walls: the layer's closed curves and curves whose feature names a wall or perimeter. A travel
    that crosses none of them stays inside one region bounded by walls — over infill, where the
    slicer itself travels without retracting — so it may skip the retraction.
    """

    def __init__(self, program: Program, problem: OrderingProblem, lay: Layout):
        names = program.feature_names
        feat = program.feature[lay.curve_s0]
        is_wall = np.array([f >= 0 and bool(WALL_FEATURE.search(names[f])) for f in feat], bool)
        self.wall = is_wall | problem.curve_closed
        self.problem = problem
        self.cache: dict = {}

    def _segments(self, layer: int):
        seg = self.cache.get(layer)
        if seg is None:
            pr = self.problem
            cs = np.flatnonzero((pr.curve_layer == layer) & self.wall)
            parts = [pr.points_xy[pr.curve_point_start[c]:pr.curve_point_start[c + 1]] for c in cs]
            a = np.concatenate([q[:-1] for q in parts]) if parts else np.zeros((0, 2))
            b = np.concatenate([q[1:] for q in parts]) if parts else np.zeros((0, 2))
            seg = self.cache[layer] = (a, b)
        return seg

    def crosses(self, layer: int, p, q) -> bool:
        p, q = np.asarray(p[:2], float), np.asarray(q[:2], float)
        d = q - p
        length = float(np.hypot(*d))
        if length <= 2 * COMB_TRIM_MM:
            return False
        u = d / length
        p, q = p + COMB_TRIM_MM * u, q - COMB_TRIM_MM * u
        a, b = self._segments(layer)
        if not len(a):
            return False
        lo, hi = np.minimum(p, q), np.maximum(p, q)
        near = ((np.maximum(a, b) >= lo) & (np.minimum(a, b) <= hi)).all(axis=1)
        a, b = a[near], b[near]
        o1, o2 = _cross_z(p, q, a), _cross_z(p, q, b)
        o3, o4 = _cross_z(a, b, p), _cross_z(a, b, q)
        return bool(np.any((o1 * o2 <= 0) & (o3 * o4 <= 0) & ((o1 != 0) | (o2 != 0))))


def travel_style(program: Program, lay: Layout) -> TravelStyle:
    """Median retraction, z-hop and speeds over the file's gaps between curves."""
    kind, d = program.kind, program.delta_mm
    n = len(lay.curve_s0)
    if n < 2:
        return TravelStyle()
    g0 = lay.curve_s1[:-1]          # gap steps [g0, g1)
    g1 = lay.curve_s0[1:]
    retr = np.zeros(len(g0))
    hop = np.zeros(len(g0))
    xy_len = np.hypot(*(program.start_mm[g1, :2] - program.end_mm[g0 - 1, :2]).T)
    retract_rows = (d[:, 3] < 0)
    cum_r = np.concatenate(([0.0], np.cumsum(np.where(retract_rows, -d[:, 3], 0.0))))
    retr = cum_r[g1] - cum_r[g0]
    # gaps with a firmware retraction (bare G10 between the two curves' lines)
    cum_fw = np.concatenate(([0], np.cumsum(lay.line_class == LINE_FW_RETRACT)))
    fw = (cum_fw[lay.curve_l0[1:]] - cum_fw[lay.curve_l1[:-1] + 1]) > 0
    z_end = program.end_mm[:, 2]
    # z-hop: highest Z inside the gap above the next curve's Z (gaps within one layer only)
    same_layer = program.layer[g0 - 1] == program.layer[g1]
    has_e = retr > 1e-6
    has_r = has_e | fw
    for i in np.flatnonzero(has_r & same_layer)[:2000]:
        if g1[i] > g0[i]:
            hop[i] = z_end[g0[i]:g1[i]].max() - program.start_mm[g1[i], 2]
    style = {}
    if has_r.any():
        if has_e.any():
            style["retract_mm"] = float(np.median(retr[has_e]))
        style["firmware_retract"] = bool(fw.sum() > has_e.sum())
        internal = has_r & same_layer
        style["min_travel_mm"] = float(xy_len[internal].min()) if internal.any() else 1.0
        hops = hop[has_r & same_layer]
        if len(hops) and np.mean(hops > 1e-3) >= 0.5:
            style["hop_mm"] = float(np.median(hops[hops > 1e-3]))
        # combing: a fair share of the travels at least as long as a retracted one went without
        long_ = same_layer & (xy_len >= max(style["min_travel_mm"], COMB_MIN_TRAVEL_MM))
        combed = long_ & ~has_r
        if long_.sum() >= 10 and combed.sum() >= COMB_SHARE * long_.sum():
            style["comb_max_mm"] = float(np.percentile(xy_len[combed], 95))
    rr = (kind == Kind.RETRACT) & (np.hypot(d[:, 0], d[:, 1]) == 0)
    if rr.any():
        style["retract_feed_mm_s"] = float(np.median(program.feed_mm_s[rr]))
    ur = kind == Kind.UNRETRACT
    if ur.any():
        style["unretract_feed_mm_s"] = float(np.median(program.feed_mm_s[ur]))
    tr = (kind == Kind.TRAVEL) & (program.length_mm > 1.0)
    if tr.any():
        style["travel_feed_mm_s"] = float(np.median(program.feed_mm_s[tr]))
        lines = program.line[np.flatnonzero(tr)[:5000]]
        g0_share = np.mean(program.line_number[lines] == 0)
        style["travel_cmd"] = "G0" if g0_share > 0.5 else "G1"
    zr = kind == Kind.Z_ONLY
    if zr.any():
        style["z_feed_mm_s"] = float(np.median(program.feed_mm_s[zr]))
    return TravelStyle(**style)
