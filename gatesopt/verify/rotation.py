"""The rotation a gating rewrite declares (``; gatesopt: rotate_deg=`` header,
``gatesopt.headers``), read back and undone: what ``geometry`` and ``positions`` compare in."""
from __future__ import annotations

import math

import numpy as np

from ..errors import GatesoptError
from ..headers import HEADER_LINES, PREFIX, ROTATE_PREFIX
from ..program import Program


def _rotation_headers(program: Program) -> list[tuple[float, float, float]]:
    """Every ``; gatesopt: rotate_deg=`` line in the first ``HEADER_LINES`` lines, as (deg,
    center_x, center_y), in file order: the newest first (each rotating rewrite puts its line on
    top of the text it read, which may hold the lines of an earlier one)."""
    out = []
    for i in range(min(program.n_lines, HEADER_LINES)):
        t = program.line_text(i).strip()
        if t.startswith(ROTATE_PREFIX):
            try:
                kv = dict(w.split("=", 1) for w in t[len(PREFIX):].split() if "=" in w)
                out.append((float(kv["rotate_deg"]), float(kv.get("center_x", 0)),
                            float(kv.get("center_y", 0))))
            except (KeyError, ValueError):
                raise GatesoptError(f"{program.source}:{i + 1}: unreadable rotation header: {t[:80]}") from None
    return out


def read_rotation(program: Program, original: Program | None = None) -> tuple[float, float, float]:
    """(deg, center_x, center_y): the rotation ``program`` declares against ``original``.

    The rotation lines ``original`` has itself (a gatesopt output solved again) came along with its
    text and are not this rewrite's; the others, if there are several (an output rewritten twice,
    compared with the slicer's file), compose into one rotation: about a centre c, p -> c +
    e^{i deg}(p - c), so two of them make p -> w p + t with w = e^{i(a + b)}, whose centre is
    t / (1 - w). Rotations that add up to a whole turn with a shift left over cannot be undone
    as a rotation: an error."""
    heads = _rotation_headers(program)
    if original is not None and heads:
        own = _rotation_headers(original)
        if own and heads[len(heads) - len(own):] == own:
            heads = heads[:len(heads) - len(own)]
    if not heads:
        return 0.0, 0.0, 0.0
    if len(heads) == 1:
        return heads[0]
    w, t, deg = 1 + 0j, 0j, 0.0
    for d, cx, cy in reversed(heads):           # the oldest was applied first
        r = complex(math.cos(math.radians(d)), math.sin(math.radians(d)))
        w, t, deg = r * w, r * t + (1 - r) * complex(cx, cy), deg + d
    if abs(1 - w) < 1e-12:
        if abs(t) > 1e-9:
            raise GatesoptError(f"{program.source}: its {len(heads)} rotation headers add up to a "
                                "whole turn and a shift, which verify cannot undo")
        return 0.0, 0.0, 0.0
    c = t / (1 - w)
    return math.remainder(deg, 360.0), c.real, c.imag


def rotate_xy(xy: np.ndarray, deg: float, center) -> np.ndarray:
    """Points ``xy`` (..., 2) turned by ``deg`` about ``center`` (x, y), counter-clockwise."""
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    x = xy[..., 0] - center[0]
    y = xy[..., 1] - center[1]
    return np.stack([center[0] + c * x - s * y, center[1] + s * x + c * y], axis=-1)


def undone_tol(tol_mm: float, deg: float) -> float:
    """``tol_mm`` per axis of a rotated output's own frame, seen in the original's frame where the
    geometry is compared: the box |dx|, |dy| <= tol turned by ``deg`` reaches tol * (|cos| + |sin|)
    on each axis (1.37x at 30 deg, 1.41x at 45). A rotated output's single-axis snap moves a point
    by up to ``SNAP_MM`` on each of the output's axes (both, for a move of a micrometre or two):
    a Cura file rotated by 30 deg failed here on a 1 um travel between two extrusions."""
    t = math.radians(deg % 360.0)
    return tol_mm * (abs(math.cos(t)) + abs(math.sin(t)))
