"""Iterated local search (gatesopt/ordering/ils.py): valid paths, never worse than its start,
deterministic, at the DP optimum on small groups, and past the greedy trap on a real layer."""
from __future__ import annotations

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, auto, build, dp, greedy, ils, milp
from gatesopt.ordering.ils import _apply_move, _apply_reverse
from gatesopt.ordering.problem import GroupSolution

from conftest import SHARED_INSTANCES, needs_shared
from test_ordering import random_problem


def test_in_place_moves_match_a_list_reference():
    """The two kernels the descent edits the path with, against plain list surgery."""
    rng = np.random.default_rng(0)
    n = 12
    cc = np.repeat(np.arange(n), 2)                     # candidate 2c, 2c+1: curve c, both ways
    flip = np.arange(2 * n) ^ 1
    for _ in range(300):
        seq = np.array([2 * c + rng.integers(0, 2) for c in rng.permutation(n)], np.int64)
        posof = np.empty(n, np.int64)
        posof[cc[seq]] = np.arange(n)
        ref = seq.tolist()
        if rng.random() < 0.5:
            i, j = sorted(rng.choice(n, 2, replace=False))
            ref[i:j + 1] = [int(flip[v]) for v in reversed(ref[i:j + 1])]
            _apply_reverse(seq, posof, cc, flip, i, j)
        else:
            L = int(rng.integers(1, 4))
            i = int(rng.integers(0, n - L + 1))
            k = i + L - 1
            a = int(rng.choice([a for a in range(-1, n) if not (i - 1 <= a <= k)]))
            rev = bool(rng.integers(0, 2))
            seg = ref[i:k + 1]
            if rev:
                seg = [int(flip[v]) for v in reversed(seg)]
            rest = ref[:i] + ref[k + 1:]
            at = a + 1 if a < i else a + 1 - L
            ref = rest[:at] + seg + rest[at:]
            _apply_move(seq, posof, cc, flip, i, k, a, rev)
        assert seq.tolist() == ref
        assert np.array_equal(posof[cc[seq]], np.arange(n))


@pytest.mark.parametrize("seed", range(6))
def test_ils_is_valid_never_worse_and_deterministic(seed):
    prob = random_problem(300 + seed, 60, closed_share=0.2, clustered=seed % 2 == 0)
    grp = prob.group(0, prob.origin_xy)
    start = greedy.nearest_neighbour(grp)
    local = grp.path_cost(greedy.improve(grp, start))
    a = ils.improve_ils(grp, start, kicks=400, seed=seed)
    grp.check_order(a)
    assert grp.path_cost(a) <= local + 1e-9
    b = ils.improve_ils(grp, start, kicks=400, seed=seed)
    assert np.array_equal(a, b)


def test_ils_stops_at_its_target():
    """``target`` (a lower bound from the caller): a search that starts at or below it does
    not kick at all, so the path comes back as it went in; without a target, kicks that tie or
    improve are taken and the same path does change."""
    for seed in range(4):
        prob = random_problem(700 + seed, 40, closed_share=0.2)
        grp = prob.group(0, prob.origin_xy)
        local = greedy.improve(grp, greedy.nearest_neighbour(grp))
        cost = grp.path_cost(local)
        kept = ils.improve_ils(grp, local, kicks=300, local_optimum=True, target=cost + 1e-6)
        assert np.array_equal(kept, local)
        moved = ils.improve_ils(grp, local, kicks=300, local_optimum=True)
        assert not np.array_equal(moved, local)
        # a target it reaches on the way: it stops there, at or below the target
        half = cost - 0.5 * (cost - grp.path_cost(moved))
        stopped = ils.improve_ils(grp, local, kicks=300, local_optimum=True, target=half)
        assert grp.path_cost(moved) <= grp.path_cost(stopped) <= half


def test_ils_reaches_the_dp_optimum_on_small_groups():
    """Groups of 12 open and closed curves: the exact DP says what optimal is."""
    hits, total, greedy_hits = 0, 0, 0
    for seed in range(12):
        prob = random_problem(500 + seed, 12, closed_share=0.3)
        grp = prob.group(0, prob.origin_xy)
        opt = dp.solve(grp).objective
        found = grp.path_cost(ils.improve_ils(grp, greedy.nearest_neighbour(grp)))
        assert found >= opt - 1e-6                      # nothing below the optimum
        hits += found <= opt + 1e-6
        greedy_hits += greedy.solve(grp).objective <= opt + 1e-6
        total += 1
    assert hits >= total - 1
    assert hits > greedy_hits                           # it does something the greedy does not


def _slicer_chain_group(name: str, mode: str, layer: int, n_curves: int):
    """The group of ``n_curves`` curves in ``layer`` of a corpus file (found by what it is, not by
    its index, which shifts whenever the build splits a layer differently), starting where the
    slicer's own order left the previous group (as bench/ordering_peers.py builds its instances)."""
    prob = build(gatesopt.parse(SHARED_INSTANCES / name), OrderingOptions(mode=mode, objective="travel"))
    pos = np.asarray(prob.origin_xy, float)
    for g in range(prob.n_groups):
        curves = prob.group_curves(g)
        if prob.group_layer[g] == layer and len(curves) == n_curves:
            end = None
            if g + 1 < prob.n_groups and prob.group_fixed[g + 1]:
                end = prob.curve_start_xy[prob.group_curve_start[g + 1]]
            return prob.group(g, pos, end)
        if len(curves):
            pos = prob.curve_end_xy[curves[-1]]
    raise AssertionError("no such group")


@needs_shared
def test_ils_escapes_the_greedy_trap_on_a_real_layer():
    """ideaMaker 5.1.4, safe mode, the 60-curve group of layer 7 (group 82 in docs/RESULTS.md,
    peers): 2-opt/Or-opt stop at 59.69 mm; LKH-3 found 42.79 mm. auto must get there and never
    claim a bound above."""
    grp = _slicer_chain_group("real_ideamaker514.gcode.gz", "safe", 7, 60)
    g = greedy.solve(grp)
    assert g.objective > 59.0
    a = auto.solve(grp, time_limit_s=1.0)
    grp.check_order(a.order)
    assert a.objective <= 42.790 + 1e-3
    assert a.bound <= a.objective + 1e-6
    m = milp.solve(grp, time_limit_s=1.0)               # its default incumbent is the ILS path
    assert m.objective <= 42.790 + 1e-3


@pytest.mark.parametrize("m", [1, 2, 5, 11, 60])
def test_near_lists_equal_a_full_row_sort(m):
    """``_near_lists``: per candidate the k cheapest links of other curves as a stable sort of its
    row (out) and column (in) gives (ties in index order: integer points make many), with its own
    curve's candidates (at infinity) last when too few others exist; asymmetric costs too."""
    from gatesopt.ordering.ils import _near_lists
    rng = np.random.default_rng(m)
    ent = rng.integers(0, 4, (m, 2)).astype(float)
    ext = rng.integers(0, 4, (m, 2)).astype(float)
    cc = np.sort(rng.integers(0, max(m // 2, 1), m))     # curves of one or more candidates
    D = np.hypot(ext[:, None, 0] - ent[None, :, 0], ext[:, None, 1] - ent[None, :, 1])
    D = D + rng.integers(0, 2, (m, m))                    # asymmetric, with ties
    far = np.where(cc[:, None] == cc[None, :], np.inf, D)
    for k in range(0, min(10, m - 1) + 1):
        near_out, near_in = _near_lists(np.ascontiguousarray(far), cc.astype(np.int64), k)
        np.testing.assert_array_equal(near_out, np.argsort(far, axis=1, kind="stable")[:, :k])
        np.testing.assert_array_equal(near_in, np.argsort(far.T, axis=1, kind="stable")[:, :k])


def test_auto_spends_the_limit_the_exact_step_left_on_the_path(monkeypatch):
    """The exact step stopping early without a proof (a root gap too wide to branch on) leaves
    the rest of the group's limit to ILS: the path gets shorter, never longer, and stays
    "feasible" with the bound it had; an exact step that used its whole limit is returned as is."""
    auto.warm_up()
    prob = random_problem(12, 40, closed_share=0.0)     # ILS shortens its matching path
    grp = prob.group(0, prob.origin_xy)
    poor = np.arange(grp.n_curves, dtype=np.int64) * 2          # the curves in input order
    calls = []

    def gave_up(group, *, time_limit_s, hint=None, **kw):
        calls.append(time_limit_s)
        return GroupSolution.make(poor, group.path_cost(poor), 0.0, "feasible", 0.0, "milp")

    monkeypatch.setattr(milp, "solve", gave_up)
    a = auto.solve(grp, time_limit_s=2.0)
    assert calls, "the group never reached the exact step"
    assert a.formulation == "auto:milp+ils" and a.status == "feasible"
    # auto never keeps an exact step's path worse than its own warm start: ILS went on from that
    assert a.objective < greedy.solve(grp).objective - 1e-6
    assert a.objective == pytest.approx(grp.path_cost(a.order))
    assert a.bound <= a.objective

    def used_it_all(group, *, time_limit_s, hint=None, **kw):
        import time
        time.sleep(time_limit_s)
        return GroupSolution.make(poor, group.path_cost(poor), 0.0, "feasible", 0.0, "milp")

    monkeypatch.setattr(milp, "solve", used_it_all)
    b = auto.solve(grp, time_limit_s=0.3)
    assert b.formulation == "auto:milp" and b.objective > a.objective
