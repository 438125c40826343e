"""A link and its mirror (issue 36, proofs under the joined link costs): the mirror of u -> v is
flip(v) -> flip(u), the same two points the other way round. Where the firmware's junction rule
is the same run backwards (Klipper), a link joined to two open curves and its mirror are one
sequence of moves run both ways, so one price: checked on real layers with every link priced
itself, and the matrix that prices such pairs once is that reference. Under Marlin's classic jerk
the default prices each link its own moves (``OrderingOptions.joined_links``): every pair one
price, so the symmetric model's edge is exact there."""
from __future__ import annotations

import numpy as np
import pytest

import gatesopt
from gatesopt.limits import machine_limits
from gatesopt.ordering import OrderingOptions, build
from gatesopt.ordering import gap_plan as gp
from gatesopt.ordering.move_times import MoveTimes
from gatesopt.ordering.problem import OrderingOptionsError
from gatesopt.ordering.wipes import SlicerWipes

from conftest import SHARED_INSTANCES, needs_shared
from test_ordering_cost_build import _groups
from test_ordering_cost_planner import mk3_layers


def _pairs(grp):
    """(u, v, flip(v), flip(u)) of every link between two curves of ``grp`` that may both be
    reversed (a loop or a one-way curve, ``candidates``, has no mirror: its flip is itself)."""
    m = grp.n_cands
    u, v = np.divmod(np.arange(m * m), m)
    two_way = grp.cand_flip != np.arange(m)
    ok = (grp.cand_curve[u] != grp.cand_curve[v]) & two_way[u] & two_way[v]
    u, v = u[ok], v[ok]
    return u, v, grp.cand_flip[v], grp.cand_flip[u]


def _sample(prob, n=14, max_cands=300):
    groups = list(_groups(prob, max_cands=max_cands))
    return groups[::max(1, len(groups) // n)]


@needs_shared
@pytest.mark.parametrize("name", ["real_crealityprint514.gcode.gz",
                                  "real_superslicer2356_arcwelder.gcode",
                                  "real_orca230_arcs.gcode.gz"])
def test_a_joined_link_is_its_mirrors_price_under_klipper(name):
    prob = build(gatesopt.parse(SHARED_INSTANCES / name), OrderingOptions(mode="free"))
    pr = prob.pricer
    # the physics below is of links without a wipe (a link out of a curve the slicer wipes
    # after writes the wipe first, its mirror does not: ``wipes``; ``_dense`` prices it itself)
    assert (pr.wipes.n_moves > 0).any() == (name != "real_superslicer2356_arcwelder.gcode")
    pr.wipes = SlicerWipes.none(prob.n_curves)
    pr._ends = pr.ends_args()
    assert pr.joined and pr.mirror_joined and pr.ends.ok.any()
    joined_pairs = 0
    for g, grp in _sample(prob):
        gc = prob.source_curves(prob.group_curves(g))[grp.cand_curve]
        changed = np.asarray(grp.cand_reversed) | (np.asarray(grp.cand_seam) != 0)
        ref = pr.dense(grp, gc, changed, mirror=False)      # every link priced itself
        fast = pr.dense(grp, gc, changed)                   # such pairs priced once
        fin = np.isfinite(ref)
        assert np.array_equal(fin, np.isfinite(fast))
        np.testing.assert_allclose(fast[fin], ref[fin], rtol=0, atol=1e-9)
        # the physics: a rebuilt link at one height joined at both ends to open curves whose
        # boundary moves backwards are their reversal, under one limits regime, without a lone
        # prime, neither it nor its mirror a gap of the slicer's (copied or reversed)
        u, v, fv, fu = _pairs(grp)
        p, c = gc[u], gc[v]
        net = np.where(gc != pr.group_first[gc], pr.own.net_e[gc], 0.0)
        sel = (pr.mirror_ok[p] & pr.mirror_ok[c] & (np.abs(p - c) > 1)
               & (pr.gap_row[c] == pr.gap_row[gc[fu]]) & (np.abs(net[v]) <= 1e-9)
               & (np.abs(net[fu]) <= 1e-9)
               & (np.abs(pr.z_exit[p] - pr.z_entry[c]) <= 1e-9)
               & (pr.z_entry == pr.z_exit)[p] & (pr.z_entry == pr.z_exit)[c]
               & (pr.group_first[p] == pr.group_first[c]))
        node = np.where(changed, pr.node_ms[gc], 0.0)
        a = ref[u[sel], v[sel]] - node[v[sel]]
        b = ref[fv[sel], fu[sel]] - node[fu[sel]]
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
        joined_pairs += int(sel.sum())
    # (>= 200 before the slicers' clipped loops became one-way curves, which have no mirror)
    assert joined_pairs >= 150, joined_pairs


def test_klipper_window_takes_the_same_time_backwards():
    # gap_plan.plan_ends_s with Klipper's smoothed look-ahead (``klipper_smoothing``, capped both
    # ways): random windows of short and long moves at random angles, and the same moves run
    # backwards with the two end speeds swapped
    prog = gatesopt.parse(mk3_layers().replace(";FLAVOR:Marlin", ";FLAVOR:Klipper").replace(
        "M205 X8 Y8 Z0.4 E2.5", "SET_VELOCITY_LIMIT SQUARE_CORNER_VELOCITY=5"))
    mt = MoveTimes.from_limits(machine_limits(prog))
    if mt.junction_code != 2:
        pytest.skip("this file does not select Klipper's rule")
    row = np.asarray(mt.limits_row, float)
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(300):
        n = int(rng.integers(2, gp.JOINED_MAX_MOVES + 1))
        L = np.where(rng.random(n) < 0.4, rng.uniform(0.02, 0.5, n), rng.uniform(1.0, 40.0, n))
        ang = np.cumsum(rng.normal(0.0, 0.8, n))
        feed = rng.choice([30.0, 60.0, 150.0, 300.0], n)
        fwd = gp.work_array(n)
        fwd[:, 0], fwd[:, 1] = L * np.cos(ang), L * np.sin(ang)
        fwd[:, gp.W_L], fwd[:, gp.W_F] = L, feed
        bwd = fwd[::-1].copy()
        bwd[:, :4] = -bwd[:, :4]
        v0, v1 = rng.uniform(0.0, 40.0, 2)
        t_f = gp.plan_ends_s(fwd, n, 2, row, v0, v1)
        t_b = gp.plan_ends_s(bwd, n, 2, row, v1, v0)
        assert abs(t_f - t_b) <= 1e-12 * max(1.0, t_f), (n, t_f, t_b)
        checked += 1
    assert checked == 300


@needs_shared
@pytest.mark.parametrize("mode", ["safe", "free"])
def test_classic_jerk_links_are_one_price_both_ways_by_default(mode):
    prog = gatesopt.parse(SHARED_INSTANCES / "cura413_star_triangles20.gcode.gz")
    prob = build(prog, OrderingOptions(mode=mode))
    pr = prob.pricer
    assert pr.move.junction_code == 0 and not pr.joined and not pr.mirror_joined
    # the travels keep the limits in force at each gap (not joined, still planned)
    assert len(pr.row_table) >= 1
    pairs = 0
    for g, grp in _sample(prob):
        D = grp.arc_cost()
        u, v, fv, fu = _pairs(grp)
        # Cura's gaps are pure travel (reversible at their own time): every pair one price
        np.testing.assert_allclose(D[u, v], D[fv, fu], rtol=0, atol=1e-9)
        pairs += len(u)
    assert pairs >= 1000
    # joined (``"all"``, the previous default): most pairs differ by the jerk rule's junctions
    alljoined = build(prog, OrderingOptions(mode=mode, joined_links="all"))
    g, grp = _sample(alljoined, n=3)[0]
    D = grp.arc_cost()
    u, v, fv, fu = _pairs(grp)
    assert np.count_nonzero(np.abs(D[u, v] - D[fv, fu]) > 1e-6) > len(u) // 4


def test_joined_links_is_checked():
    with pytest.raises(OrderingOptionsError, match="joined_links"):
        OrderingOptions(joined_links="sometimes")
