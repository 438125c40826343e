"""A group's candidates (formulations/ordering.md, "Candidates"; ``problem`` module docstring):
per curve in order, the ways it may be printed, each with its entry and exit point.

- a curve of a fixed-order group: one candidate, as printed;
- a closed loop: one candidate entered and left at its seam (with ``move_seams``, one per seam
  vertex tried, ``OrderingProblem.seam_vertices``), in its own direction;
- a one-way curve (``OrderingProblem.curve_one_way``): one candidate, forward. A loop the slicer
  clipped short of its seam (PrusaSlicer and Slic3r stop 15 % of the nozzle short, 0.06 mm:
  not closed, yet a wall whose direction the slicer chose) and a curve that ends in the slicer's
  coasting (Cura's ``coasting_enable``: its last moves without extrusion, ``layout`` keeps them
  with the curve), which printed backwards would coast at its start;
- any other open curve: two, forward then reversed.

``candidates`` makes them with arrays (passing a file's ~2,000 groups of ~30 curves cost ~0.4 s
in a loop); ``candidates_with_seams`` one curve at a time, with ``move_seams``' several seams
per loop. Both return ``(cand_curve, entry_xy, exit_xy, flip, reversed, seam)``.
"""
from __future__ import annotations

import numpy as np


def one_way(problem, curves=None) -> np.ndarray:
    """Per curve of ``curves`` (None: every curve of ``problem``), whether it is one-way."""
    if curves is None:
        curves = np.arange(problem.n_curves)
    if problem.curve_one_way is None:
        return np.zeros(len(curves), bool)
    return np.asarray(problem.curve_one_way[curves], bool)


def candidates(problem, curves, fixed: bool) -> tuple:
    """The candidates of a group of ``curves`` where each loop keeps its seam (module
    docstring)."""
    n = len(curves)
    closed = np.asarray(problem.curve_closed[curves], bool)
    two = np.zeros(n, bool) if fixed else ~closed & ~one_way(problem, curves)
    cnt = 1 + two.astype(np.int64)
    first = np.cumsum(cnt) - cnt
    m = int(cnt.sum())
    cc = np.repeat(np.arange(n, dtype=np.int64), cnt)
    rev = np.zeros(m, bool)
    rev[first[two] + 1] = True
    a, b = problem.curve_start_xy[curves], problem.curve_end_xy[curves]
    ent, ext = a[cc], b[cc]
    ent[rev], ext[rev] = b[cc[rev]], a[cc[rev]]
    loop = np.flatnonzero(closed) if not fixed else np.zeros(0, np.int64)
    if len(loop):
        # a loop is entered and left at its seam: its first vertex
        p = problem.points_xy[problem.curve_point_start[curves[loop]]]
        ent[first[loop]] = p
        ext[first[loop]] = p
    flip = np.arange(m, dtype=np.int64)
    flip[first[two]], flip[first[two] + 1] = first[two] + 1, first[two]
    return (cc, np.asarray(ent, float).reshape(m, 2), np.asarray(ext, float).reshape(m, 2),
            flip, rev, np.zeros(m, np.int64))


def candidates_with_seams(problem, curves, fixed: bool) -> tuple:
    """``candidates`` one curve at a time, with ``move_seams``' several seams per loop."""
    cc, ent, ext, flip, rev, seam = [], [], [], [], [], []
    single = one_way(problem, curves)
    for local, c in enumerate(curves):
        a, b = problem.curve_start_xy[c], problem.curve_end_xy[c]
        k0 = len(cc)
        if fixed or single[local]:
            cc.append(local); ent.append(a); ext.append(b); flip.append(k0)
            rev.append(False); seam.append(0)
        elif problem.curve_closed[c]:
            for v in problem.seam_vertices(c):
                p = problem.points_xy[problem.curve_point_start[c] + v]
                flip.append(len(cc)); cc.append(local); ent.append(p); ext.append(p)
                rev.append(False); seam.append(int(v))
        else:
            cc += [local, local]; ent += [a, b]; ext += [b, a]; flip += [k0 + 1, k0]
            rev += [False, True]; seam += [0, 0]
    m = len(cc)
    return (np.asarray(cc, np.int64), np.asarray(ent, float).reshape(m, 2),
            np.asarray(ext, float).reshape(m, 2), np.asarray(flip, np.int64),
            np.asarray(rev, bool), np.asarray(seam, np.int64))
