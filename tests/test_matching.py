"""The minimum-cost perfect matching (gatesopt/ordering/matching.py) and what the ordering takes
from it: a lower bound, odd-set cuts valid for every path, and a patched path."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from gatesopt.ordering import auto, dp, symmetric, symmetric_graph
from gatesopt.ordering.matching import min_cost_perfect_matching

from tests.test_ordering import random_problem


def _brute_force(c, ok):
    """Cheapest perfect matching by recursion over the lowest unmatched vertex (V <= 12)."""
    V = len(c)

    @functools.lru_cache(maxsize=None)
    def best(mask):
        if mask == (1 << V) - 1:
            return 0
        i = next(k for k in range(V) if not mask >> k & 1)
        out = np.inf
        for j in range(i + 1, V):
            if not mask >> j & 1 and ok[i, j]:
                out = min(out, c[i, j] + best(mask | 1 << i | 1 << j))
        return out
    return best(0)


def _instance(rng, V, ties=False):
    if ties:        # few distinct costs: many ties, many blossoms
        c = rng.integers(0, 4, (V, V))
    else:
        pts = rng.random((V, 2)) * 100
        c = np.floor(np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1)) * 1e3)
    c = np.minimum(c, c.T).astype(np.int64)
    ok = ~np.eye(V, dtype=bool)
    for i in range(0, V, 2):                    # like the two ends of one curve
        ok[i, i + 1] = ok[i + 1, i] = False
    return c, ok


@pytest.mark.parametrize("seed", range(40))
def test_matching_is_the_cheapest_perfect_matching(seed):
    rng = np.random.default_rng(seed)
    V = 2 * int(rng.integers(2, 7))
    c, ok = _instance(rng, V, ties=seed % 2 == 0)
    bound, mate, sets = min_cost_perfect_matching(c, ok)
    opt = _brute_force(c, ok)
    assert bound == pytest.approx(opt)
    # the matching itself: perfect, on allowed edges, of the optimal cost
    assert np.array_equal(mate[mate], np.arange(V)) and np.all(mate != np.arange(V))
    assert ok[np.arange(V), mate].all()
    assert c[np.arange(V), mate].sum() / 2 == pytest.approx(opt)
    # odd sets: the optimum crosses each at least once
    for H in sets:
        assert len(H) % 2 == 1
        inside = np.zeros(V, bool)
        inside[H] = True
        assert np.count_nonzero(inside != inside[mate]) >= 1


@pytest.mark.parametrize("seed", range(12))
def test_a_sparse_search_graph_still_gives_a_valid_bound(seed):
    """Run on each vertex's nearest edges only (and one known perfect matching), the bound comes
    from a dual repaired on the edges left out: never above the optimum of the whole graph, and
    equal to it with pricing rounds enough."""
    rng = np.random.default_rng(100 + seed)
    V = 2 * int(rng.integers(4, 7))
    c, ok = _instance(rng, V)
    opt = _brute_force(c, ok)
    k = 1 + seed % 3
    near = np.argsort(np.where(ok, c, 1 << 40), axis=1)[:, :k]
    search = np.zeros((V, V), bool)
    search[np.repeat(np.arange(V), k), near.ravel()] = True
    perm = rng.permutation(V // 2)              # pairs (2i, 2j+1) for a permutation: perfect
    for i, j in enumerate(perm):
        a, b = 2 * i, 2 * j + 1
        if ok[a, b]:
            search[a, b] = search[b, a] = True
        else:                                   # i == j: use the next pair's end instead
            b2 = 2 * ((j + 1) % (V // 2)) + 1
            search[a, b2] = search[b2, a] = True
    bound, _, _ = min_cost_perfect_matching(c, ok, search)
    if bound is not None:
        assert bound <= opt + 1e-9
    full, _, _ = min_cost_perfect_matching(c, ok)
    assert full == pytest.approx(opt)


@pytest.mark.parametrize("seed", range(6))
def test_the_dual_is_repaired_where_pricing_stopped(seed, monkeypatch):
    """No pricing round: the matching runs once on each vertex's nearest edge and a path's
    pairs, far from the optimum; the violated edges then found are only repaired in the dual
    (``_certify``), and the bound is still never above the whole graph's optimum."""
    from gatesopt.ordering import matching
    monkeypatch.setattr(matching, "MAX_PRICING_ROUNDS", 0)
    rng = np.random.default_rng(300 + seed)
    V = 40
    pts = rng.random((V, 2)) * 100
    c = np.floor(np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1)) * 100).astype(np.int64)
    ok = ~np.eye(V, dtype=bool)
    search = np.zeros((V, V), bool)
    search[np.arange(V), np.argsort(np.where(ok, c, 1 << 40), axis=1)[:, 0]] = True
    search[np.arange(0, V, 2), np.arange(1, V, 2)] = True
    full, _, _ = min_cost_perfect_matching(c, ok)
    sparse_opt, _, _ = min_cost_perfect_matching(np.where(search | search.T, c, 0),
                                                 search | search.T)
    bound, _, _ = min_cost_perfect_matching(c, ok, search)
    assert sparse_opt > full + 1       # the search graph alone is far from the optimum
    assert bound <= full + 1e-9


@pytest.mark.parametrize("seed", range(8))
def test_matching_bound_and_path_on_ordering_groups(seed):
    """On layer groups of open lines and loops: the matching's bound is at most the proven
    optimum (the subset DP), every odd set is crossed by the optimal path's travel edges, and the
    patched path is a valid order."""
    prob = random_problem(900 + seed, 12, closed_share=0.3 if seed % 2 else 0.0,
                          clustered=seed % 3 == 0)
    grp = prob.group(0, prob.origin_xy, None if seed % 4 else np.array([5.0, 5.0]))
    assert symmetric_graph.applies(grp) and dp.fits(grp)
    opt = dp.solve(grp)
    order, bound = symmetric_graph.matching_path(grp)
    grp.check_order(order)
    assert bound <= opt.objective + 1e-6
    assert grp.path_cost(order) >= opt.objective - 1e-6
    model = symmetric.SymmetricModel(grp, opt.order)
    _, masks, _ = symmetric_graph.odd_sets(model.C, model.deg, grp.end_xy is None)
    travel = model.tour_edges(opt.order)
    for inside in masks:
        assert np.count_nonzero(inside[travel[:, 0]] != inside[travel[:, 1]]) >= 1


def test_auto_takes_the_matching_bound_and_stays_exact():
    """A group given no time for an exact step: the fallback reports the matching's bound (well
    above the cheap bound), never above the optimum; with time, the seeded exact step proves
    the same optimum as the DP."""
    prob = random_problem(77, 14, closed_share=0.0, clustered=True)
    grp = prob.group(0, prob.origin_xy)
    opt = dp.solve(grp).objective
    quick = auto.solve(grp, time_limit_s=1e-4)
    assert quick.bound <= opt + 1e-6 and quick.objective >= opt - 1e-6
    _, mbound = symmetric_graph.matching_path(grp)
    assert quick.bound >= mbound - 1e-9
    full = auto.solve(grp, time_limit_s=5.0)
    assert full.status == "optimal" and full.objective == pytest.approx(opt, abs=1e-6)


def test_the_kept_workspace_gives_what_a_fresh_one_gives():
    """The blossom algorithm keeps its large arrays from call to call (``matching._workspace``)
    and must leave them clean: a run of instances of changing size (with ties: many blossoms)
    gives the same bound and matching as each run alone on new arrays, and the arrays it reads
    as 'no edge' are zero after every call."""
    from gatesopt.ordering import matching
    rng = np.random.default_rng(7)
    instances = [_instance(rng, V, ties=k % 2 == 0) for k, V in enumerate([40, 12, 60, 8, 30, 60])]
    kept = []
    for c, ok in instances:
        kept.append(min_cost_perfect_matching(c, ok))
        gu, gv, gw, flower, flower_from = matching._WORK.arrays
        assert not gw.any() and not flower_from.any()
    for (c, ok), (bound, mate, _) in zip(instances, kept):
        matching._WORK.arrays = None
        fresh_bound, fresh_mate, _ = min_cost_perfect_matching(c, ok)
        assert bound == fresh_bound and np.array_equal(mate, fresh_mate)
        assert bound == pytest.approx(c[np.arange(len(c)), mate].sum() / 2)


def test_threads_get_their_own_workspace(monkeypatch):
    """Two threads matching at once (a planner calling the library from threads) get the bounds
    and odd sets each gets alone: the kept arrays are per thread. A pause between the blossom
    algorithm and the reading of its blossoms hands the other thread the interpreter right there."""
    import threading
    import time
    from gatesopt.ordering import matching
    tree = matching._blossom_tree

    def paused_tree(*a):
        time.sleep(0.002)
        return tree(*a)
    rng = np.random.default_rng(3)
    instances = [_instance(rng, 2 * int(rng.integers(10, 40)), ties=k % 2 == 0) for k in range(16)]
    alone = [min_cost_perfect_matching(c, ok) for c, ok in instances]
    monkeypatch.setattr(matching, "_blossom_tree", paused_tree)
    got = [None] * len(instances)

    def work(k0):
        for k in range(k0, len(instances), 2):
            for _ in range(3):
                got[k] = min_cost_perfect_matching(*instances[k])
    threads = [threading.Thread(target=work, args=(k0,)) for k0 in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for (b0, m0, s0), (b1, m1, s1) in zip(alone, got):
        assert b0 == b1 and np.array_equal(m0, m1)
        assert [h.tolist() for h in s0] == [h.tolist() for h in s1]


@pytest.mark.parametrize("seed", range(12))
def test_travel_matching_equals_the_dense_matching(seed):
    """``travel_matching`` (one compiled pass from the node cost matrix) gives the bound of
    ``min_cost_perfect_matching`` on the same graph written out: vertices per node (a seam
    twice), no edge inside a node or where the cost is infinite, costs in whole units."""
    from gatesopt.ordering import matching
    rng = np.random.default_rng(seed)
    N = int(rng.integers(4, 30))
    pts = rng.random((N, 2)) * 50
    C = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
    C[rng.random((N, N)) < 0.1] = np.inf
    C = np.minimum(C, C.T)
    np.fill_diagonal(C, np.inf)
    rep = rng.integers(1, 3, N)
    if rep.sum() % 2:
        rep[0] = 3 - rep[0]
    idx = np.repeat(np.arange(N), rep)
    C2 = C[np.ix_(idx, idx)]
    ok = np.isfinite(C2) & (idx[:, None] != idx[None, :])
    units = np.floor(np.where(ok, C2, 0.0) * matching.UNITS_PER_COST).astype(np.int64)
    dense, _, _ = min_cost_perfect_matching(units, ok)
    got, mate, _ = matching.travel_matching(C, idx, 3, 0)
    assert (dense is None) == (got is None)
    if dense is not None:
        assert got == dense
        assert ok[np.arange(len(idx)), mate].all()
