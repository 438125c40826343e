"""The problem's timeline: step ``i`` runs from ``start_s[i]`` to ``start_s[i + 1]`` (the original
print, no stalls; formulations/gating.md §1). Where a moment falls among the steps, and integrals of
a per-step rate over time, for the scoring (``gating.scoring``) and the coupled model
(``gating.coupled``); ``gating._kernels`` does the same inside its loops with ``TIME_EPS_S``.
"""
from __future__ import annotations

import numpy as np

from ..program import MOTION_KINDS, Kind

TIME_EPS_S = 1e-12          # a boundary closer than this to a step boundary is on it (no split)


def row_at(start_s, t, side):
    """Row whose time span holds t. side='off': the last row starting at t; 'on': the first."""
    n = len(start_s) - 1
    if side == "on":
        r = np.searchsorted(start_s, t - TIME_EPS_S, "left")
        exact = (r <= n) & (np.abs(start_s[np.minimum(r, n)] - t) <= TIME_EPS_S)
        r = np.where(exact, r, r - 1)
    else:
        r = np.searchsorted(start_s, t + TIME_EPS_S, "right") - 1
    return np.clip(r, 0, n)


def is_split(start_s, row, t):
    """True where moment ``t`` falls strictly inside step ``row`` (an instruction there splits it)."""
    n = len(start_s) - 1
    r = np.minimum(row, n - 1) if n else row
    inside = (start_s[r] + TIME_EPS_S < t) & (t < start_s[np.minimum(r + 1, n)] - TIME_EPS_S)
    return inside & (row < n)


def whole_steps(steps_motor, kind, split_moves: str = "all") -> np.ndarray:
    """(n,) bool: steps no instruction may split, so that a moment inside one is placed at its
    safe side (an off at its end, an on at its start: the motor only stays on longer, which
    start-ahead and end-late always allow) by the model and the emitter alike:

    - a step that is not a move (a dwell, a heat-up wait, homing): its G-code cannot be cut;
    - with ``split_moves`` "kinematic", an extrude-only move (E steps, X Y Z do not): Klipper plans
      each on its own, from rest to rest (klippy/toolhead.py ``Move.calc_junction``: no junction
      speed to or from a move that is not kinematic), so a retraction cut in two costs a stop more
      (+12.5 ms measured, docs/RESULTS.md); on Marlin an ``M18`` between its halves drains the
      queue inside the retraction;
    - with "none", every move: a Klipper ``SET_STEPPER_ENABLE`` flushes the look-ahead, a full
      stop at the line; between two moves the head is often at rest already (next to a
      retraction) or slow (a corner), inside one it stops from cruising speed.

    A dialect says which (``firmware.Firmware.split_moves``)."""
    sm = np.asarray(steps_motor, bool)
    kind = np.asarray(kind)
    out = ~np.isin(kind, MOTION_KINDS)
    if split_moves == "none":
        out[:] = True
    elif split_moves == "kinematic":
        out |= sm[:, 3] & ~sm[:, :3].any(axis=1) & (kind != Kind.ARC)
    return out


def integral(cum, start_s, rate, t, row):
    """Integral of ``rate`` over [0, t] with ``row`` the row holding t (prefix sum + partial row)."""
    n = len(start_s) - 1
    r = np.minimum(row, n - 1)
    part = np.where(row < n, rate[r] * (t - start_s[r]), 0.0)
    return cum[row] + part


def nearest_boundary(start_s, t):
    """Index of the step boundary (``start_s`` entry) nearest to each moment ``t``: where a line
    written between two steps stands (``firmware.Schedule``: the off line goes at the end of the
    motor's last step, its off comes a known delay later)."""
    n = len(start_s) - 1
    r = np.clip(np.searchsorted(start_s, t), 0, n)
    lower = np.maximum(r - 1, 0)
    closer = np.abs(start_s[lower] - t) < np.abs(start_s[r] - t)
    return np.where(closer, lower, r)
