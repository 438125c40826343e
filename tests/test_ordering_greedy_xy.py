"""The XY local search (``ordering.greedy_xy``) that groups above ``problem.DENSE_MAX_CANDS``
candidates use: no test reached it while it named a constant that no longer existed (numba fails
at the first call). On random open paths it returns each curve once, in either direction, never
longer than it started, and no shorter than the brute-force optimum."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from gatesopt.ordering.greedy_xy import local_search_xy, path_cost_xy


def _instance(rng, n):
    a = rng.uniform(0, 100, (n, 2))
    b = a + rng.uniform(-20, 20, (n, 2))
    ent = np.empty((2 * n, 2))
    ext = np.empty((2 * n, 2))
    ent[0::2], ext[0::2] = a, b           # candidate 2c: curve c forward
    ent[1::2], ext[1::2] = b, a           # candidate 2c+1: curve c reversed
    flip = np.arange(2 * n) ^ 1
    return ent, ext, flip


def _brute(ent, ext, n, sx, sy):
    best = np.inf
    for perm in itertools.permutations(range(n)):
        for dirs in itertools.product((0, 1), repeat=n):
            seq = np.array([2 * c + d for c, d in zip(perm, dirs)], np.int64)
            best = min(best, path_cost_xy(seq, ent, ext, sx, sy, False))
    return best


@pytest.mark.parametrize("seed", range(6))
def test_local_search_xy_shortens_and_keeps_every_curve_once(seed):
    rng = np.random.default_rng(seed)
    n = 6
    ent, ext, flip = _instance(rng, n)
    seq = np.array(rng.permutation(n) * 2, np.int64)
    before = path_cost_xy(seq, ent, ext, 0.0, 0.0, False)
    out = local_search_xy(seq, ent, ext, flip, 0.0, 0.0, False, 50)
    after = path_cost_xy(out, ent, ext, 0.0, 0.0, False)
    assert sorted(out // 2) == list(range(n))
    assert after <= before + 1e-9
    assert after >= _brute(ent, ext, n, 0.0, 0.0) - 1e-9
