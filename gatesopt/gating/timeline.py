"""The problem's timeline: step ``i`` runs from ``start_s[i]`` to ``start_s[i + 1]`` (the original
print, no stalls; formulations/gating.md §1). Where a moment falls among the steps, and integrals of
a per-step rate over time, for the scoring (``gating.scoring``) and the coupled model
(``gating.coupled``); ``gating._kernels`` does the same inside its loops with ``TIME_EPS_S``.
"""
from __future__ import annotations

import numpy as np

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
