"""Reversed gaps (issue 36, formulations/ordering.md "Reversed gaps"): a slicer's gap that is pure
travel is written backwards where the link runs the other way round, at its own time, so the time
objective's link costs are symmetric there and the undirected model is exact: the gap's moves come
out reversed and verify, the cost the solver saw is the emitted travels' time, and the symmetric
model proves small groups at the brute-force optimum of the true costs."""
from __future__ import annotations

import time

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, emit, greedy, symmetric, symmetric_graph
from gatesopt.ordering.cost import gap_times_ms
from gatesopt.ordering.layout import layout
from gatesopt.ordering.problem import OrderingSolution
from gatesopt.verify.ordering import check
from test_ordering_cost import _brute, _small_groups, slicer_gcode


def cura_like_gcode(n_layers: int = 3, n_lines: int = 5) -> str:
    """Infill lines the way CuraEngine writes them (absolute E, ``;TYPE:FILL``): after each line
    a non-extruding move along it (the infill wipe), then a retraction, a z-hop, a travel of
    two moves (a combed path), lowering and the unretraction."""
    out = ["G21", "G90", "M82", "M104 S200", "G28", "G92 E0", "G1 Z0.2 F600"]
    e = 0.0
    for layer in range(n_layers):
        z = 0.2 * (layer + 1)
        out += [f";LAYER:{layer}", f"G0 F9000 X10 Y10 Z{z:.2f}", ";TYPE:FILL"]
        for k in range(n_lines):
            y = 10.0 + 4.0 * k
            a, b = (10.0, 30.0) if k % 2 == 0 else (30.0, 10.0)
            if k:
                out.append(f"G0 F9000 X{a:.3f} Y{y:.3f}")
            e += 0.8
            out.append(f"G1 F1800 X{b:.3f} Y{y:.3f} E{e:.5f}")
            if k + 1 < n_lines:
                wipe = b + (0.4 if b > a else -0.4)
                e -= 5.0
                out += [f"G1 X{wipe:.3f} Y{y:.3f}", f"G1 F2700 E{e:.5f}", f"G1 F300 Z{z + 0.4:.2f}",
                        f"G0 F9000 X{(a + b) / 2:.3f} Y{y + 2.5:.3f}"]
                nxt_a = 10.0 if (k + 1) % 2 == 0 else 30.0
                out += [f"G0 X{nxt_a:.3f} Y{y + 4.0:.3f}", f"G1 F300 Z{z:.2f}"]
                e += 5.0
                out.append(f"G1 F2700 E{e:.5f}")
    out.append("M104 S0")
    return "\n".join(out) + "\n"


def _gap_steps(prog, lay, k):
    """Steps of the gap before curve k."""
    return np.arange(lay.curve_s1[k - 1], lay.curve_s0[k])


def _swap_reversed(prob, c):
    """The slicer's order with curves c and c + 1 swapped and both reversed."""
    n = prob.n_curves
    order = np.arange(n)
    order[[c, c + 1]] = [c + 1, c]
    rev = np.zeros(n, bool)
    rev[[c, c + 1]] = True
    return OrderingSolution(order, rev, np.zeros(n, np.int64), (), 0.0, 0.0, 0.0, "test")


@pytest.mark.parametrize("mode", ["safe", "free"])
def test_reversed_gap_is_the_gap_backwards_and_verifies(mode):
    prog = gatesopt.parse(cura_like_gcode())
    prob = build(prog, OrderingOptions(mode=mode, copied_gaps="moves"))
    rg = prob.pricer.reversible
    lay = prob.layout
    # every gap between two infill lines of a re-orderable layer is reversible
    gcs = prob.group_curve_start
    inner = [c for g in np.flatnonzero(prob.group_reorderable) for c in range(gcs[g] + 1, gcs[g + 1])]
    assert len(inner) >= 8 and rg.ok[inner].all()
    c = inner[2] - 1                            # curves c, c + 1 of one re-orderable group
    sol = _swap_reversed(prob, c)
    out = gatesopt.parse(emit(prog, prob, sol))
    assert check(prog, out) == []
    lay_out = layout(out)
    src, dst = _gap_steps(prog, lay, c + 1), _gap_steps(out, lay_out, c + 1)
    moving = lambda p, s: s[np.abs(p.end_mm[s] - p.start_mm[s]).max(axis=1) > 1e-9]
    src, dst = moving(prog, src)[::-1], moving(out, dst)
    assert len(src) == len(dst) == 7             # wipe, retract, lift, two travels, lower, unretract
    np.testing.assert_allclose(out.start_mm[dst, :3], prog.end_mm[src, :3], atol=1e-5)
    np.testing.assert_allclose(out.end_mm[dst, :3], prog.start_mm[src, :3], atol=1e-5)
    np.testing.assert_allclose(out.end_mm[dst, 3] - out.start_mm[dst, 3],
                               -(prog.end_mm[src, 3] - prog.start_mm[src, 3]), atol=1e-5)
    np.testing.assert_allclose(out.feed_mm_s[dst], prog.feed_mm_s[src])
    # the unretraction reversed retracts first, the retraction reversed unretracts last but one
    Kind = gatesopt.program.Kind
    assert out.kind[dst[0]] == Kind.RETRACT and out.kind[dst[-2]] == Kind.UNRETRACT
    # the link costs the gap's own time, and that is what the emitted travels take
    move = prob.pricer.move
    link = prob.pricer.links_ms(c + 1, True, prob.curve_start_xy[c + 1], c, True,
                                prob.curve_end_xy[c])
    assert float(link) == pytest.approx(prob.pricer.copy_ms[c + 1], abs=1e-9)
    cost = prob.order_cost(sol.curve_order, sol.curve_reversed, sol.curve_seam)
    assert cost == pytest.approx(gap_times_ms(out, move).sum(), rel=1e-9, abs=1e-6)


def test_gap_not_reversed_where_the_link_does_not_meet_its_ends():
    """Curves c + 1 -> c with c printed forwards (entered at its start, not where the gap began):
    a rebuilt travel, not the reversed gap."""
    prog = gatesopt.parse(cura_like_gcode())
    prob = build(prog, OrderingOptions(mode="free", copied_gaps="moves"))
    c = int(prob.group_curve_start[1]) + 1
    sol = _swap_reversed(prob, c)
    rev = sol.curve_reversed.copy()
    rev[c] = False
    sol = OrderingSolution(sol.curve_order, rev, sol.curve_seam, (), 0.0, 0.0, 0.0, "test")
    link = prob.pricer.links_ms(c + 1, True, prob.curve_start_xy[c + 1], c, False,
                                prob.curve_start_xy[c])
    assert float(link) != pytest.approx(prob.pricer.copy_ms[c + 1], abs=1e-6)
    out = gatesopt.parse(emit(prog, prob, sol))
    assert check(prog, out) == []
    cost = prob.order_cost(sol.curve_order, sol.curve_reversed, sol.curve_seam)
    assert cost == pytest.approx(gap_times_ms(out, prob.pricer.move).sum(), rel=1e-9, abs=1e-6)


def test_wipes_stay_one_way():
    """A gap whose retraction moves the head (a wipe) is not reversed: it would extrude."""
    prog = gatesopt.parse(slicer_gcode(0, wipe=True, n_layers=3))
    prob = build(prog, OrderingOptions(mode="free"))
    rg = prob.pricer.reversible
    lay = prob.layout
    wiped = [c for c in range(1, prob.n_curves)
             if np.any(prog.kind[_gap_steps(prog, lay, c)] == gatesopt.program.Kind.RETRACT)]
    assert wiped and not rg.ok[wiped].any()


def _symmetric_costs(grp) -> bool:
    D = grp.arc_cost()
    f = grp.cand_flip
    R = D[f][:, f].T
    ok = np.isfinite(D)
    return bool(np.array_equal(ok, np.isfinite(R)) and np.allclose(D[ok], R[ok], rtol=0, atol=1e-9))


def test_reversible_gaps_make_costs_symmetric():
    """Groups whose copied gaps are all reversible have symmetric link costs; groups with wipes
    keep asymmetric ones."""
    groups = _small_groups(max_curves=8)
    sym = [_symmetric_costs(g) for g in groups]
    assert sum(sym) >= 5 and not all(sym)


def test_symmetric_model_proves_symmetric_groups_at_the_brute_force_optimum():
    """On groups with symmetric costs the undirected model is exact: it proves each one, at the
    optimum brute force finds under the true (directed) costs."""
    n = 0
    for grp in _small_groups(max_curves=7):
        if not symmetric_graph.applies(grp) or not _symmetric_costs(grp):
            continue
        best = _brute(grp)
        order, obj, bound, proven = symmetric.solve(grp, greedy.nearest_neighbour(grp),
                                                    time.perf_counter() + 10)
        assert proven, (grp.n_curves, obj, bound)
        assert obj == pytest.approx(grp.path_cost(order), abs=1e-9)
        assert obj == pytest.approx(best, abs=1e-3) and bound <= best + 1e-6
        n += 1
    assert n >= 5
