"""Ordering problems without G-code: plain polylines (pen plotters, laser cutters)."""
from __future__ import annotations

import dataclasses

import numpy as np

from .problem import CLOSED_TOL_MM, OrderingOptions, OrderingProblem


def from_polylines(layers, *, origin_xy=(0.0, 0.0), options: OrderingOptions | None = None,
                   fixed_layers=()) -> OrderingProblem:
    """One group per layer; each polyline is an (k >= 1, 2) array of XY vertices in mm. The
    objective is travel distance (there is no printer whose time to model).

    A polyline whose last vertex equals its first (within CLOSED_TOL_MM) is a closed loop and keeps
    its start vertex as seam (unless ``options.move_seams``). ``fixed_layers``: layer indices
    whose order must be kept.
    """
    options = options or OrderingOptions(mode="free")
    # no printer to time: the links cost their length (Fleming Eq. 1)
    options = dataclasses.replace(options, objective="travel")
    starts, ends, closed, layer_of, pts, pstart = [], [], [], [], [], [0]
    gstart, glayer, gfixed, glabel = [0], [], [], []
    for li, layer in enumerate(layers):
        for poly in layer:
            p = np.asarray(poly, float).reshape(-1, 2)
            if len(p) == 0:
                raise ValueError(f"layer {li}: empty polyline")
            starts.append(p[0]); ends.append(p[-1])
            closed.append(len(p) > 2 and bool(np.hypot(*(p[-1] - p[0])) <= CLOSED_TOL_MM))
            layer_of.append(li)
            pts.append(p)
            pstart.append(pstart[-1] + len(p))
        gstart.append(len(starts)); glayer.append(li); gfixed.append(li in fixed_layers)
        glabel.append(f"L{li}")
    n = len(starts)
    return OrderingProblem(
        curve_start_xy=np.asarray(starts, float).reshape(n, 2),
        curve_end_xy=np.asarray(ends, float).reshape(n, 2),
        curve_closed=np.asarray(closed, bool), curve_layer=np.asarray(layer_of, np.int64),
        points_xy=np.concatenate(pts) if pts else np.zeros((0, 2)),
        curve_point_start=np.asarray(pstart, np.int64),
        group_curve_start=np.asarray(gstart, np.int64), group_layer=np.asarray(glayer, np.int64),
        group_fixed=np.asarray(gfixed, bool), group_label=tuple(glabel),
        origin_xy=np.asarray(origin_xy, float), options=options,
        curve_step_start=np.full(n, -1, np.int64), curve_step_stop=np.full(n, -1, np.int64))
