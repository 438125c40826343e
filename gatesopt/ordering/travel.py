"""How the slicer travels between curves, read from its own gaps (formulations/ordering.md,
"Emit"): retraction, z-hop, speeds, whether it combs (``TravelStyle``, ``travel_style``), and the
combing test for a rebuilt travel: does it cross a wall of its layer (``WallCrossing``)? And the
rule for when a rebuilt travel retracts (``TravelRule``), which the emitter follows and the time
objective prices (``cost.TimePricer``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..program import Kind, Program
from ..slicers import WALL_FEATURE
from .layout import LINE_FW_RETRACT, Layout, feed_travels
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


#: wall segments are binned into square cells of this size (mm) for the crossing test; a layer
#: spans at most GRID_MAX_CELLS cells a side (larger cells beyond)
GRID_CELL_MM = 2.0
GRID_MAX_CELLS = 256
#: the combing exemption is tested only for travels up to this long (mm): a longer rebuilt travel
#: retracts (the slicer's own combed travels are kept wherever its neighbours are, copied). The
#: time objective tests every link of a group in range against its layer's walls
#: (formulations/ordering.md, "Cost model": the cap keeps that within a budget's share)
COMB_TESTED_MAX_MM = 20.0


class WallCrossing:
    """Does a straight travel cross a wall of its layer? (A combing slicer's reason to retract.)

    Walls: the layer's closed curves and curves whose feature names a wall or perimeter. A travel
    that crosses none of them stays inside one region bounded by walls -- over infill, where the
    slicer itself travels without retracting -- so it may skip the retraction. The travel is
    trimmed by ``COMB_TRIM_MM`` at each end (its ends are curve ends, which touch walls). Per
    layer the wall segments are binned in a grid (``GRID_CELL_MM``) and a compiled kernel walks
    the cells each travel passes (``crosses_many``; tests/test_ordering_cost.py checks it
    against shapely).
    """

    def __init__(self, program: Program, problem: OrderingProblem, lay: Layout):
        names = program.feature_names
        feat = program.feature[lay.curve_s0]
        is_wall = np.array([f >= 0 and bool(WALL_FEATURE.search(names[f])) for f in feat], bool)
        self.wall = is_wall | problem.curve_closed
        self.problem = problem
        self.cache: dict = {}
        self.grids: dict = {}

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

    def _grid(self, layer: int):
        grid = self.grids.get(layer)
        if grid is None:
            a, b = self._segments(layer)
            if not len(a):
                grid = None
            else:
                lo = np.minimum(a, b).min(axis=0)
                hi = np.maximum(a, b).max(axis=0)
                h = max(GRID_CELL_MM, float((hi - lo).max()) / GRID_MAX_CELLS)
                nx, ny = (np.floor((hi - lo) / h).astype(np.int64) + 1).tolist()
                start, items = _bin_segments(np.ascontiguousarray(a), np.ascontiguousarray(b),
                                             float(lo[0]), float(lo[1]), h, nx, ny)
                grid = (np.ascontiguousarray(a), np.ascontiguousarray(b), float(lo[0]),
                        float(lo[1]), h, nx, ny, start, items)
            self.grids[layer] = grid
        return grid

    def crosses_many(self, layer: int, p, q) -> np.ndarray:
        """(k,) bool: whether the travel p[i] -> q[i] crosses a wall of ``layer``."""
        p = np.ascontiguousarray(np.asarray(p, float).reshape(-1, 2)[:, :2])
        q = np.ascontiguousarray(np.asarray(q, float).reshape(-1, 2)[:, :2])
        grid = self._grid(layer)
        if grid is None:
            return np.zeros(len(p), bool)
        return _crosses(p, q, COMB_TRIM_MM, *grid)

    def grid(self, layer: int):
        """The layer's wall grid for ``cross_one`` (after the trim): (trim, a, b, x0, y0, h, nx,
        ny, start, items), or None without walls."""
        g = self._grid(layer)
        return None if g is None else (COMB_TRIM_MM,) + g

    def crosses(self, layer: int, p, q) -> bool:
        return bool(self.crosses_many(layer, np.asarray(p, float)[:2], np.asarray(q, float)[:2])[0])


@numba.njit(cache=True)
def _bin_segments(a, b, x0, y0, h, nx, ny):
    """CSR of the segments a -> b whose bounding box touches each grid cell (ix * ny + iy)."""
    k = len(a)
    lo = np.empty((k, 4), np.int64)
    count = np.zeros(nx * ny + 1, np.int64)
    for s in range(k):
        ix0 = min(max(int(np.floor((min(a[s, 0], b[s, 0]) - x0) / h)), 0), nx - 1)
        ix1 = min(max(int(np.floor((max(a[s, 0], b[s, 0]) - x0) / h)), 0), nx - 1)
        iy0 = min(max(int(np.floor((min(a[s, 1], b[s, 1]) - y0) / h)), 0), ny - 1)
        iy1 = min(max(int(np.floor((max(a[s, 1], b[s, 1]) - y0) / h)), 0), ny - 1)
        lo[s, 0], lo[s, 1], lo[s, 2], lo[s, 3] = ix0, ix1, iy0, iy1
        for ix in range(ix0, ix1 + 1):
            for iy in range(iy0, iy1 + 1):
                count[ix * ny + iy + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for s in range(k):
        for ix in range(lo[s, 0], lo[s, 1] + 1):
            for iy in range(lo[s, 2], lo[s, 3] + 1):
                c = ix * ny + iy
                items[fill[c]] = s
                fill[c] += 1
    return start, items


@numba.njit(cache=True, inline="always")
def _orient(ox, oy, vx, vy, wx, wy):
    """z of (v - o) x (w - o): which side of the line o -> v the point w lies on."""
    return (vx - ox) * (wy - oy) - (vy - oy) * (wx - ox)


@numba.njit(cache=True)
def _crosses(p, q, trim, a, b, x0, y0, h, nx, ny, start, items):
    """Per travel p[i] -> q[i] (trimmed by ``trim`` at each end): does it cross a segment
    a[s] -> b[s]? (``cross_one``)"""
    n = len(p)
    out = np.zeros(n, np.bool_)
    stamp = np.full(len(a), -1, np.int64)
    for i in range(n):
        out[i] = cross_one(p[i, 0], p[i, 1], q[i, 0], q[i, 1], i, stamp, trim, a, b, x0, y0, h,
                           nx, ny, start, items)
    return out


@numba.njit(cache=True)
def cross_one(px, py, qx, qy, tag, stamp, trim, a, b, x0, y0, h, nx, ny, start, items):
    """Does the travel (px, py) -> (qx, qy), trimmed by ``trim`` at each end, cross a segment
    a[s] -> b[s] of the grid (``_bin_segments``)? The cells it passes are visited column by column
    (the y range of the travel within each column of cells, widened by a hair); ``stamp[s] ==
    tag`` marks a segment tested already for this travel (``tag``: a number unique per call)."""
    dx, dy = qx - px, qy - py
    L = np.sqrt(dx * dx + dy * dy)
    if L <= 2 * trim:
        return False
    ux, uy = dx / L, dy / L
    px, py = px + trim * ux, py + trim * uy
    qx, qy = qx - trim * ux, qy - trim * uy
    xl, xh = min(px, qx), max(px, qx)
    ix0 = int(np.floor((xl - x0) / h))
    ix1 = int(np.floor((xh - x0) / h))
    if ix1 < 0 or ix0 >= nx:
        return False
    ix0, ix1 = max(ix0, 0), min(ix1, nx - 1)
    for ix in range(ix0, ix1 + 1):
        cx0 = max(xl, x0 + ix * h)
        cx1 = min(xh, x0 + (ix + 1) * h)
        if qx != px:
            ya = py + (cx0 - px) * (qy - py) / (qx - px)
            yb = py + (cx1 - px) * (qy - py) / (qx - px)
            yl, yh = min(ya, yb), max(ya, yb)
        else:
            yl, yh = min(py, qy), max(py, qy)
        iy0 = max(int(np.floor((yl - y0) / h - 1e-9)), 0)
        iy1 = min(int(np.floor((yh - y0) / h + 1e-9)), ny - 1)
        for iy in range(iy0, iy1 + 1):
            c = ix * ny + iy
            for t in range(start[c], start[c + 1]):
                s = items[t]
                if stamp[s] == tag:
                    continue
                stamp[s] = tag
                ax, ay, bx, by = a[s, 0], a[s, 1], b[s, 0], b[s, 1]
                o1 = _orient(px, py, qx, qy, ax, ay)
                o2 = _orient(px, py, qx, qy, bx, by)
                o3 = _orient(ax, ay, bx, by, px, py)
                o4 = _orient(ax, ay, bx, by, qx, qy)
                if o1 * o2 <= 0 and o3 * o4 <= 0 and (o1 != 0 or o2 != 0):
                    return True
    return False


@dataclass(frozen=True, eq=False)
class TravelRule:
    """When a rebuilt travel retracts (``gaps.rebuilt_gap``; ``cost.TimePricer`` prices the same
    rule): if it is at least as long as the shortest travel the slicer retracted for, or if the
    boundary gap it replaces retracted (a layer change, a barrier); a combing slicer's travel
    (``TravelStyle.comb_max_mm``) up to ``comb_cap_mm`` long at one height that crosses no wall
    of its layer (``walls``) goes dry."""

    style: TravelStyle
    walls: WallCrossing | None

    @property
    def comb_cap_mm(self) -> float:
        """Longest travel the combing exemption applies to (0: none)."""
        if self.walls is None or self.style.comb_max_mm <= 0:
            return 0.0
        return min(self.style.comb_max_mm, COMB_TESTED_MAX_MM)

    def vector(self) -> np.ndarray:
        """(retract mm, shortest retracted travel, firmware retraction 0/1, comb cap) for the
        compiled pricing kernel."""
        st = self.style
        return np.array([st.retract_mm, st.min_travel_mm, float(st.firmware_retract),
                         self.comb_cap_mm], float)

    @staticmethod
    def of(program: Program, problem: OrderingProblem, lay: Layout,
           style: "TravelStyle | None" = None) -> "TravelRule":
        style = style or travel_style(program, lay)
        walls = WallCrossing(program, problem, lay) if style.comb_max_mm > 0 else None
        return TravelRule(style, walls)


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
    tr = feed_travels(program)
    if tr.any():
        style["travel_feed_mm_s"] = float(np.median(program.feed_mm_s[tr]))
        lines = program.line[np.flatnonzero(tr)[:5000]]
        g0_share = np.mean(program.line_number[lines] == 0)
        style["travel_cmd"] = "G0" if g0_share > 0.5 else "G1"
    zr = kind == Kind.Z_ONLY
    if zr.any():
        style["z_feed_mm_s"] = float(np.median(program.feed_mm_s[zr]))
    return TravelStyle(**style)
