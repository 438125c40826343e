"""The time objective (issue 36, ``gatesopt.ordering.cost``): the cost the solver optimises is what
the emitted travels cost under the same model, on random small layers written the way slicers
write them (retractions, z-hops, wipes, combing, firmware retraction); the exact formulations agree
with brute force on the asymmetric costs; the wall test agrees with shapely; a move's time agrees
with the planner model for a move from and to rest."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, emit, solve
from gatesopt.ordering import auto, cpsat, dp, milp
from gatesopt.ordering.cost import MoveTimes, gap_times_ms
from gatesopt.ordering.move_times import trapezoid_s
from gatesopt.ordering.problem import Anchor
from gatesopt.verify.ordering import check


def slicer_gcode(seed: int, *, n_layers: int = 4, comb: bool = False, hop: bool = True,
                 wipe: bool = False, firmware: bool = False, islands: int = 1) -> str:
    """A few layers the way a slicer writes them: per island a wall loop (``;TYPE:Perimeter``),
    then infill lines inside it (``;TYPE:Internal infill``), in a shuffled order; a travel of
    at least 2 mm retracts (and hops) unless ``comb`` lets some stay dry; ``wipe``: a wipe move
    retracts part of the filament after each curve; ``firmware``: G10 / G11."""
    rng = np.random.default_rng(seed)
    out = ["G21", "G90", "M83", "M104 S200", "G28", "M204 P1000 T1500", "M205 X8 Y8 E4.5",
           "G1 Z0.2 F600"]
    pos = np.zeros(2)
    z = 0.2
    centres = [np.array([20.0 + 35 * k, 20.0 + 10 * (k % 2)]) for k in range(islands)]

    def travel(to, long_ok_dry=False):
        nonlocal pos
        d = float(np.hypot(*(to - pos)))
        retract = d >= 2.0 and not (comb and long_ok_dry and rng.random() < 0.6)
        if retract and wipe:
            back = pos + rng.uniform(-1, 1, 2)
            out.append(f"G1 X{back[0]:.3f} Y{back[1]:.3f} E-0.3 F3000")
            pos = back
        if retract:
            out.append("G10" if firmware else f"G1 E-{0.5 if wipe else 0.8} F2100")
            if hop:
                out.append(f"G1 Z{z + 0.4:.2f} F720")
        out.append(f"G1 X{to[0]:.3f} Y{to[1]:.3f} F9000")
        if retract:
            if hop:
                out.append(f"G1 Z{z:.2f} F720")
            out.append("G11" if firmware else "G1 E0.8 F2100")
        pos = np.asarray(to, float)

    for layer in range(n_layers):
        z = 0.2 * (layer + 1)
        out.append(";LAYER_CHANGE")
        out.append(f"G1 Z{z:.2f} F720")
        for c in centres:
            # the wall: a square loop around the island
            corners = c + np.array([[-10, -10], [10, -10], [10, 10], [-10, 10], [-10, -10]], float)
            start = int(rng.integers(0, 4))
            ring = np.vstack([corners[start:4], corners[:start + 1]])
            travel(ring[0])
            out.append(";TYPE:Perimeter")
            for p in ring[1:]:
                out.append(f"G1 X{p[0]:.3f} Y{p[1]:.3f} E0.8 F1800")
            pos = ring[-1]
            # infill: lines across the island, in a shuffled order and direction
            ys = rng.permutation(np.linspace(-8, 8, int(rng.integers(4, 8))))
            for y in ys:
                a, b = c + [-9.5, y], c + [9.5, y]
                if rng.random() < 0.5:
                    a, b = b, a
                travel(a, long_ok_dry=True)
                out.append(";TYPE:Internal infill")
                out.append(f"G1 X{b[0]:.3f} Y{b[1]:.3f} E0.9 F3000")
                pos = b
    out.append("M104 S0")
    return "\n".join(out) + "\n"


VARIANTS = [dict(), dict(comb=True, hop=False), dict(wipe=True), dict(firmware=True),
            dict(islands=3), dict(comb=True, islands=2, hop=False)]


@pytest.mark.parametrize("variant", range(len(VARIANTS)))
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("mode", ["safe", "free"])
def test_model_cost_is_the_emitted_travels_time(variant, seed, mode):
    """For random small layers: the solver's cost of the order it chose (and of the slicer's
    order) equals the time of the emitted file's travels between curves under the same model,
    and the output verifies."""
    prog = gatesopt.parse(slicer_gcode(seed, **VARIANTS[variant]))
    # copied gaps priced move by move, as gap_times_ms measures every gap (the default prices them
    # at the planner's time: test_copied_gaps_cost_the_planners_time)
    prob = build(prog, OrderingOptions(mode=mode, copied_gaps="moves"))
    assert prob.cost_unit == "ms" and prob.pricer is not None
    move = prob.pricer.move
    assert prob.pricer.copy_ms[1:].sum() == pytest.approx(gap_times_ms(prog, move).sum(), rel=1e-9)
    sol = solve(prob, "auto", time_limit_s=1.0)
    assert sol.cost_before == pytest.approx(gap_times_ms(prog, move).sum(), rel=1e-9, abs=1e-6)
    out = gatesopt.parse(emit(prog, prob, sol))
    measured = gap_times_ms(out, move)
    assert len(measured) == prob.n_curves - 1
    assert sol.cost_after == pytest.approx(measured.sum(), rel=1e-6, abs=1e-3)
    assert sol.cost_after <= sol.cost_before + 1e-6
    assert check(prog, out) == []


@pytest.mark.parametrize("variant", [0, 1, 4])
def test_copied_gaps_cost_the_planners_time(variant):
    """By default the slicer's own gaps cost what the planner says they take in the input
    (``gap_ms``), plus what the input spends on the curves' moves they meet beyond those moves'
    time in their curves planned alone (``copy_ms``: the junctions' share, which a rebuilt link
    prices too, ``curve_time.CurveEnds``); the slicer's whole order costs the sum of that;
    priced as a rebuilt travel is (``copied_gaps="moves"``: each gap's moves planned together
    from and to rest, ``MoveTimes.gaps_s``) the gaps cost the same within 1 % (their ends meet
    curves)."""
    from gatesopt.planner import plan
    prog = gatesopt.parse(slicer_gcode(1, **VARIANTS[variant]))
    prob = build(prog, OrderingOptions(mode="free"))
    moves = build(prog, OrderingOptions(mode="free", copied_gaps="moves"))
    lay = prob.layout
    d = plan(prog).duration_s
    gaps = sum(d[a:b].sum() for a, b in zip(lay.curve_s1[:-1].tolist(), lay.curve_s0[1:].tolist()))
    assert prob.pricer.gap_ms[1:].sum() == pytest.approx(1000.0 * gaps, rel=1e-9)
    assert prob.pricer.gap_ms.sum() == pytest.approx(moves.pricer.copy_ms.sum(), rel=0.01)
    head, tail = prob.pricer.ends.context_ms(plan(prog))
    share = tail[:-1].sum() + head[1:].sum()
    assert abs(share) > 1.0                     # the junctions with the curves do cost something
    assert prob.pricer.copy_ms[1:].sum() == pytest.approx(1000.0 * gaps + share, rel=1e-9)
    n = prob.n_curves
    ident, no = np.arange(n), np.zeros(n, bool)
    assert prob.order_cost(ident, no, np.zeros(n, np.int64)) == pytest.approx(
        prob.pricer.copy_ms[1:].sum(), rel=1e-9)


def test_combing_file_is_read_as_combing():
    prog = gatesopt.parse(slicer_gcode(0, comb=True, hop=False, n_layers=6))
    prob = build(prog, OrderingOptions(mode="free"))
    assert prob.pricer.rule.comb_cap_mm > 0


def _brute(grp):
    cand = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    best = np.inf
    for perm in itertools.permutations(range(grp.n_curves)):
        for pick in itertools.product(*[cand[c] for c in perm]):
            best = min(best, grp.path_cost(np.array(pick)))
    return best


def _small_groups(max_curves=6):
    """Groups of real time-priced problems (random slicer layers) small enough for brute force,
    each from the slicer's previous curve (an asymmetric start: the copied gap) and with an end
    where the next group is fixed."""
    out = []
    for seed, variant in ((0, dict()), (1, dict(comb=True, hop=False)), (2, dict(wipe=True)),
                          (3, dict(islands=2))):
        prog = gatesopt.parse(slicer_gcode(seed, n_layers=3, **variant))
        prob = build(prog, OrderingOptions(mode="safe"))
        for g in np.flatnonzero(prob.group_reorderable):
            n = prob.group_curve_start[g + 1] - prob.group_curve_start[g]
            if n > max_curves:
                continue
            c0 = int(prob.group_curve_start[g])
            start = Anchor(prob.curve_end_xy[c0 - 1].copy(), c0 - 1, False)
            end = None
            if g + 1 < prob.n_groups and prob.group_fixed[g + 1]:
                c1 = int(prob.group_curve_start[g + 1])
                end = Anchor(prob.curve_start_xy[c1].copy(), c1, False)
            out.append(prob.group(g, start, end))
    return out


def test_costs_are_asymmetric_and_break_the_triangle_inequality():
    """What the bounds must not assume (formulations/ordering.md, "Cost model")."""
    asym = tri = False
    for grp in _small_groups(max_curves=8):
        D = grp.arc_cost()
        f = grp.cand_flip
        ok = np.isfinite(D)
        asym |= bool(np.any(np.abs(D[ok] - D[f][:, f].T[ok]) > 1e-6))
        m = grp.n_cands
        for u, v, w in itertools.permutations(range(m), 3):
            if np.isfinite(D[u, w]) and np.isfinite(D[u, v]) and np.isfinite(D[f[v], w]):
                # u -> w directly against u -> v, through v's curve (its flip leaves at v's entry)
                if D[u, w] > D[u, v] + D[f[v], w] + 1e-6 and np.allclose(grp.cand_entry_xy[v], grp.cand_exit_xy[f[v]]):
                    tri = True
                    break
    assert asym and tri


@pytest.mark.parametrize("which", ["dp", "milp", "cpsat", "auto"])
def test_exact_formulations_match_brute_force_on_time_costs(which):
    groups = _small_groups()
    assert len(groups) >= 5
    fn = {"dp": dp.solve, "milp": milp.solve, "cpsat": cpsat.solve, "auto": auto.solve}[which]
    for grp in groups:
        best = _brute(grp)
        gs = fn(grp, time_limit_s=5.0)
        grp.check_order(gs.order)
        assert gs.objective == pytest.approx(grp.path_cost(gs.order), abs=1e-6)
        assert gs.bound <= best + 1e-6                 # the bound is valid
        assert gs.objective >= best - 1e-6
        # every exact formulation proves these small groups: the milp's undirected model alone
        # could not on asymmetric (time) costs, its directed model must take over
        assert gs.status == "optimal", (which, grp.n_curves, gs.objective, gs.bound)
        assert gs.objective == pytest.approx(best, abs=1e-3)


def test_symmetric_model_bound_is_valid_and_proofs_are_real():
    """The symmetric model prices each edge the cheaper way round: its bound stays valid, and
    a path it calls optimal is optimal under the true (asymmetric) costs."""
    from gatesopt.ordering import greedy, symmetric, symmetric_graph
    n_proven = 0
    for grp in _small_groups(max_curves=7):
        if not symmetric_graph.applies(grp):
            continue
        best = _brute(grp)
        order, obj, bound, proven = symmetric.solve(grp, greedy.nearest_neighbour(grp),
                                                    deadline=__import__("time").perf_counter() + 5)
        assert bound <= best + 1e-6
        assert obj == pytest.approx(grp.path_cost(order), abs=1e-9)
        if proven:
            n_proven += 1
            assert obj == pytest.approx(best, abs=1e-3)
    assert n_proven >= 1


def test_backwards_group_costs_the_path_without_its_first_link():
    for grp in _small_groups(max_curves=5):
        if grp.end_xy is None:
            continue
        back = grp.backwards()
        rng = np.random.default_rng(0)
        for _ in range(5):
            curves = rng.permutation(grp.n_curves)
            order = np.array([np.flatnonzero(grp.cand_curve == c)[0] for c in curves])
            fwd_cost = grp.path_cost(order) - grp.start_cost()[order[0]]
            assert back.path_cost(order[::-1]) == pytest.approx(fwd_cost, abs=1e-9)


@pytest.mark.parametrize("jerk", [False, True])
def test_trapezoid_against_the_planner_from_rest_to_rest(jerk):
    """A move between two dwells (the head at rest before and after) takes the planner model's
    time: accelerate from the rest speed (Marlin 2's minimum planner speed; under classic jerk the
    axis jerk), cruise, decelerate; XY travel, extruder-only and Z-only moves."""
    from gatesopt.limits import machine_limits
    from gatesopt.planner import plan
    lines = ["G21", "G90", "M83", "M201 X1000 Y1000 Z200 E5000", "M203 X300 Y300 Z10 E60",
             "M204 P800 R1200 T1500", "M205 X8 Y8 Z0.4 E4.5", "G1 X0 Y0 F9000", "G4 P0",
             "G1 X40 Y0 F9000", "G4 P0", "G1 X41 Y0 F9000", "G4 P0", "G1 E-0.8 F2100",
             "G4 P0", "G1 Z2 F720", "G4 P0"]
    if jerk:        # PrusaSlicer's config block: classic jerk (limits.machine_limits)
        lines += ["; machine_max_jerk_x = 8", "; machine_max_jerk_y = 8", "; machine_max_jerk_z = 0.4",
                  "; machine_max_jerk_e = 4.5", "; gcode_flavor = marlin"]
    prog = gatesopt.parse("\n".join(lines) + "\n")
    lim = machine_limits(prog)
    assert (lim.junction == "jerk") == jerk
    move = MoveTimes.from_limits(lim)
    pl = plan(prog)
    moves = [s for s in range(prog.n_steps) if prog.length_mm[s] > 0]
    assert len(moves) == 4
    ours = move.steps_s(prog, moves)
    np.testing.assert_allclose(ours, pl.duration_s[moves], rtol=1e-6)
    assert move.xy_s(40.0, 150.0) == pytest.approx(ours[0])
    assert trapezoid_s(40.0, 150.0, 1000.0, move.xy_junction_mm_s) == pytest.approx(ours[0])


@pytest.mark.parametrize("seed", range(4))
def test_wall_crossing_kernel_agrees_with_shapely(seed):
    """The grid kernel (``travel.WallCrossing.crosses_many``) against shapely on random travels
    over a real layer's walls (each travel trimmed by COMB_TRIM_MM at both ends)."""
    shapely = pytest.importorskip("shapely")
    from shapely.geometry import LineString, MultiLineString
    from gatesopt.ordering.travel import COMB_TRIM_MM, WallCrossing
    prog = gatesopt.parse(slicer_gcode(seed, islands=3, n_layers=2))
    prob = build(prog, OrderingOptions(mode="free", objective="travel"))
    walls = WallCrossing(prog, prob, prob.layout)
    layer = int(prob.curve_layer[-1])
    a, b = walls._segments(layer)
    assert len(a) > 0
    geom = MultiLineString([[tuple(x), tuple(y)] for x, y in zip(a, b)])
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 110, (400, 2))
    q = p + rng.normal(0, 15, (400, 2))
    got = walls.crosses_many(layer, p, q)
    want = []
    for x, y in zip(p, q):
        d = y - x
        L = float(np.hypot(*d))
        if L <= 2 * COMB_TRIM_MM:
            want.append(False)
            continue
        u = d / L
        want.append(LineString([tuple(x + COMB_TRIM_MM * u), tuple(y - COMB_TRIM_MM * u)]).intersects(geom))
    np.testing.assert_array_equal(got, np.asarray(want))
    assert 0 < got.sum() < len(got)
