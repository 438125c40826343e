"""Gating solvers: brute force == dp == milp == cpsat on tiny problems, exact <= greedy, every claimed
energy re-scored with the one energy function, feasibility checked without trusting the library,
rotation candidates contain the optimum. Problems are built with ``from_moves`` (no G-code) except
one test over a real slicer file (skipped when ../shared/instances is absent)."""
from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatesopt.energy import step_energy_j
from gatesopt.errors import GatesoptError, InfeasibleError
from gatesopt.gating import GatingOptions, build, from_moves, score, solve
from gatesopt.gating import GatingOptionsError, check_feasible, steps_motor_at

INSTANCES = Path(__file__).resolve().parents[2] / "shared" / "instances"
EXACT = ("dp", "milp", "cpsat")


# ------------------------------------------------------------------------------------------------
# helpers
def path_moves(points, durations, e_steps=None):
    """Moves along a polyline of (x, y) points; ``e_steps`` adds E-only moves (retract/unretract)
    after the given move indices: {index: (dE, duration)}."""
    starts, ends, durs = [], [], []
    e = 0.0
    for i in range(len(points) - 1):
        (x0, y0), (x1, y1) = points[i], points[i + 1]
        starts.append((x0, y0, 0.2, e))
        e += 0.05
        ends.append((x1, y1, 0.2, e))
        durs.append(durations[i])
        if e_steps and i in e_steps:
            de, dd = e_steps[i]
            starts.append((x1, y1, 0.2, e))
            e += de
            ends.append((x1, y1, 0.2, e))
            durs.append(dd)
    return np.array(starts), np.array(ends), np.array(durs)


def with_xy_off(coeffs, value_w):
    """The coefficients with a non-additive both-XY-off correction of ``value_w`` in every class."""
    return dataclasses.replace(coeffs, xy_off_w_by_cls=np.full(len(coeffs.base_w_by_cls), float(value_w)))


def brute_force(problem):
    """Lexicographic (energy, lines) optimum over every subset of every angle's idle intervals, scored by
    ``score`` (the one energy function over the pieces), budgets enforced."""
    best = None
    for k in range(problem.n_angles):
        g = problem.idle_intervals_of(k)
        assert len(g) <= 12, "instance too big for brute force"
        for r in range(len(g) + 1):
            for sub in itertools.combinations(g, r):
                sub = np.array(sub, np.int64)
                sc = score(problem, problem.idle_motor[sub], problem.idle_start_s[sub], problem.idle_end_s[sub])
                if sc.added_time_s > problem.max_added_time_s + 1e-9 or sc.lines_added > problem.max_added_lines:
                    continue
                key = (sc.energy_j, sc.lines_added)
                if best is None or key[0] < best[0] - 1e-7 or (abs(key[0] - best[0]) <= 1e-7 and key[1] < best[1]):
                    best = key
    return best


def rescore(sol):
    """Energy of a solution recomputed here from its pieces with step_energy_j (not via the library's sum)."""
    p = sol.problem
    row, dur, en, stall = sol.enable_pieces()
    e = step_energy_j(dur[~stall], p.coeffs.take(row[~stall]), en[~stall]).sum()
    e += step_energy_j(dur[stall], p.stall_coeffs.take(row[stall]), en[stall]).sum()
    assert np.isclose(dur[~stall].sum(), p.total_s)                  # pieces tile the timeline
    assert np.isclose(dur[stall].sum(), sol.added_time_s)
    return float(e)


def independent_violations(sol):
    """Off time within start-ahead / end-late of a step of that motor, checked step by step."""
    p, o = sol.problem, sol.problem.options
    steps, _ = steps_motor_at(p, sol.angle_index)
    sa = o.start_ahead_s if o.on_line else 0.0
    bad = []
    for m, a, b in zip(sol.off_motor, sol.off_start_s, sol.off_end_s):
        assert b > a
        for i in np.flatnonzero(steps[:, m]):
            lo, hi = p.start_s[i] - sa, p.start_s[i + 1] + o.end_late_s
            if a < hi - 1e-9 and b > lo + 1e-9:
                bad.append((int(m), float(a), float(b), int(i)))
    return bad


def check_solution(sol):
    assert sol.status in ("optimal", "feasible", "fallback", "infeasible")
    assert "!=" not in sol.message, sol.message          # milp's model agrees with the scoring
    assert math.isclose(rescore(sol), sol.energy_j, rel_tol=1e-9, abs_tol=1e-9)
    assert independent_violations(sol) == []
    assert check_feasible(sol.problem, sol.angle_index, sol.off_motor, sol.off_start_s, sol.off_end_s) == []


# ------------------------------------------------------------------------------------------------
# hand-made instances
def small_problem(**opts):
    # X move, Y move, diagonal, retract, X travel, short Y jog, long retract, X move
    pts = [(0, 0), (10, 0), (10, 10), (0, 0), (5, 0), (5, 0.3), (9, 0.3)]
    s, e, d = path_moves(pts, [1.0, 1.0, 1.4, 0.5, 0.05, 0.4], e_steps={2: (-1.0, 0.1), 4: (-0.5, 0.8)})
    return from_moves(s, e, d, GatingOptions(**{"rotate": "none", **opts}))


def test_idle_intervals_respect_start_ahead_end_late():
    p = small_problem()
    steps, _ = steps_motor_at(p, 0)
    for g in range(p.n_idle_intervals):
        m = p.idle_motor[g]
        rows = np.flatnonzero(steps[:, m])
        before = rows[p.start_s[rows + 1] <= p.idle_start_s[g] + 1e-12]
        after = rows[p.start_s[rows] >= p.idle_end_s[g] - 1e-12]
        assert len(before) + len(after) == len(rows)                  # no step inside an idle interval
        if len(before):
            assert math.isclose(p.idle_start_s[g], p.start_s[before[-1] + 1] + 1e-3)
        if len(after):
            assert math.isclose(p.idle_end_s[g], p.start_s[after[0]] - 1.8e-3)


@pytest.mark.parametrize("opts", [{}, {"stall_off_s": 0.2, "stall_on_s": 0.1}, {"on_line": False, "stall_off_s": 0.2},
                                  {"rotate": "auto"}])
def test_idle_interval_table_agrees_with_scoring_each_alone(opts):
    p = small_problem(**opts)
    assert p.n_idle_intervals > 0
    for g in range(p.n_idle_intervals):
        sc = score(p, p.idle_motor[[g]], p.idle_start_s[[g]], p.idle_end_s[[g]])
        assert math.isclose(p.energy_before_j - sc.energy_j, p.idle_net_j[g], abs_tol=1e-9)
        assert sc.lines_added == p.idle_lines[g]
        assert math.isclose(sc.added_time_s, p.idle_stall_s[g])


def test_paper_firmware_switches_off_in_every_idle_interval():
    # 3dgates: no stall, so every idle interval with a saving is off in the optimum (issue #3)
    p = small_problem()
    sol = solve(p, "dp")
    assert sol.status == "optimal"
    saving = p.idle_saving_j > 0
    assert len(sol.off_motor) == int(saving.sum())
    check_solution(sol)


@pytest.mark.parametrize("opts", [
    {},
    {"stall_off_s": 0.3, "on_line": False, "merge_lines": False},          # Klipper-like
    {"stall_off_s": 0.05, "merge_lines": True},                              # Marlin-like, shared stalls
    {"max_added_lines_pct": 60.0},
    {"stall_off_s": 0.05, "max_added_time_pct": 2.0, "max_added_lines_pct": 80.0},
    {"rotate": "auto", "max_angles": 2},
    {"motors": ("X", "Y", "E"), "stall_off_s": 0.02, "max_added_lines_pct": 80.0},
])
def test_exact_formulations_match_brute_force(opts):
    p = small_problem(**opts)
    best = brute_force(p)
    for f in EXACT:
        sol = solve(p, f, time_limit_s=30)
        check_solution(sol)
        if f == "dp" and not p.separable:
            assert sol.energy_j >= best[0] - 1e-7                           # heuristic there
            continue
        assert sol.status == "optimal", (f, sol.message)
        assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6), (f, sol.energy_j, best)
        assert sol.lines_added == best[1], (f, sol.lines_added, best)
        if not math.isnan(sol.bound_j):
            assert sol.bound_j <= sol.energy_j + 1e-6


@pytest.mark.parametrize("opts", [
    {},
    {"stall_off_s": 0.05, "merge_lines": False},
    {"stall_off_s": 0.05, "max_added_lines_pct": 60.0},
])
def test_shared_enable_pin_matches_brute_force(opts):
    p = small_problem(shared_enable=(("X", "Y"),), **opts)
    assert set(p.idle_motor.tolist()) == {0}            # the group's idle intervals belong to its first motor
    best = brute_force(p)
    for f in EXACT:
        sol = solve(p, f)
        check_solution(sol)
        if f == "dp" and not p.separable:
            continue
        assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6) and sol.lines_added == best[1], f
        x = sol.off_motor == 0
        y = sol.off_motor == 1
        assert np.array_equal(sol.off_start_s[x], sol.off_start_s[y])   # both motors, same moments
        assert np.array_equal(sol.off_end_s[x], sol.off_end_s[y])
    # one shared pin can only switch off when neither motor steps: never better than two pins
    assert solve(p, "milp").energy_j >= solve(small_problem(**opts), "milp").energy_j - 1e-9


def test_budgets_with_rotation_match_brute_force():
    # milp prunes rotations by a knapsack bound under budgets: the optimum must survive
    p = small_problem(rotate="auto", max_angles=2, stall_off_s=0.02, max_added_lines_pct=50.0,
                      max_added_time_pct=1.0, check_bed=False)
    assert p.n_angles > 1
    best = brute_force(p)
    for f in ("milp", "cpsat"):
        sol = solve(p, f)
        check_solution(sol)
        assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6) and sol.lines_added == best[1], f


def test_non_additive_xy_power_matches_brute_force():
    # both XY off saves 3 W less than the sum of the two (a measured both_xy_gated value)
    p0 = small_problem()
    c = p0.coeffs
    coeffs = with_xy_off(c, 3.0)
    p = from_moves(p0.start_mm, p0.end_mm, p0.duration_s, p0.options, coeffs=coeffs)
    assert not p.separable and np.allclose(p.xy_inter_w, 3.0)
    best = brute_force(p)
    for f in ("milp", "cpsat"):
        sol = solve(p, f)
        check_solution(sol)
        assert sol.status == "optimal"
        assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6) and sol.lines_added == best[1]


def test_budget_zero_keeps_everything_on():
    p = small_problem(max_added_lines_pct=0.0)
    for f in ("dp", "milp", "cpsat"):
        sol = solve(p, f)
        assert sol.lines_added == 0 and sol.energy_j == pytest.approx(p.energy_before_j)
    g = solve(p, "greedy")
    assert g.status == "infeasible" and "budget" in g.message


def test_exact_beats_or_ties_greedy_and_greedy_is_feasible():
    for opts in ({}, {"stall_off_s": 0.22, "on_line": False, "merge_lines": False}):
        p = small_problem(**opts)
        g = solve(p, "greedy")
        check_solution(g)
        for f in EXACT:
            assert solve(p, f).energy_j <= g.energy_j + 1e-9


def test_greedy_keeps_short_excursions_on():
    # the 0.3 mm Y jog between two X moves is below neigh_t = 0.5 mm: the paper keeps X on across
    # it ... and X is not stepped by the jog, so dp switches X off there and saves more
    p = small_problem()
    g, d = solve(p, "greedy"), solve(p, "dp")
    assert len(g.off_motor) < len(d.off_motor)
    assert d.energy_j < g.energy_j


def test_rotated_square_candidates_contain_the_optimum():
    # a square turned by 17 degrees about its centre, printed with retractions at the corners
    th = math.radians(17.0)
    c, s_ = math.cos(th), math.sin(th)
    corners = [(-10, -10), (10, -10), (10, 10), (-10, 10), (-10, -10)]
    pts = [(100 + c * x - s_ * y, 100 + s_ * x + c * y) for x, y in corners]
    s, e, d = path_moves(pts, [1.0, 1.0, 1.0, 1.0], e_steps={0: (-0.5, 0.2), 1: (-0.5, 0.2), 2: (-0.5, 0.2)})
    auto = from_moves(s, e, d, GatingOptions(rotate="auto", bed_size_mm=(200, 200)))
    assert np.any(np.isclose(auto.angles_deg % 90.0, 73.0, atol=1e-6))
    best = solve(auto, "dp")
    assert math.isclose(best.rotation_deg % 90.0, 73.0, abs_tol=1e-6)
    assert best.max_snap_mm <= 1e-3
    # no fixed angle of a fine sweep does better
    for deg in np.arange(0.0, 90.0, 2.5):
        fixed = solve(from_moves(s, e, d, GatingOptions(rotate=float(deg)), bed_size_mm=(200, 200)), "dp")
        assert best.energy_j <= fixed.energy_j + 1e-9
    # the unrotated square has no single-axis move: only the retractions can be gated
    none = solve(from_moves(s, e, d, GatingOptions(rotate="none")), "dp")
    assert best.energy_j < none.energy_j - 1.0
    # the greedy's 30-degree sweep cannot reach 73 degrees
    assert solve(auto, "greedy").energy_j > best.energy_j


def rotated_square_gcode(deg=17.0, n_layers=3):
    """G-code of a 20 mm square turned by ``deg`` about (100, 100), retracting at every corner, with a
    purge line before the print and a park move after it."""
    th = math.radians(deg)
    c, s_ = math.cos(th), math.sin(th)
    pts = [(100 + c * x - s_ * y, 100 + s_ * x + c * y) for x, y in [(-10, -10), (10, -10), (10, 10), (-10, 10)]]
    out = ["G28", "G90", "M82", "G92 E0", "G1 Z0.3 F600", "G1 X5 Y5 F6000", "G1 X5 Y100 E5 F1200"]
    e = 5.0
    for layer in range(n_layers):
        out += [";LAYER_CHANGE", f"G1 Z{0.3 + 0.2 * layer:.1f} F600", f"G1 X{pts[0][0]:.3f} Y{pts[0][1]:.3f} F6000"]
        for k in range(1, 5):
            x, y = pts[k % 4]
            e += 0.8
            out += [f"G1 X{x:.3f} Y{y:.3f} E{e:.5f} F1200", f"G1 E{e - 0.8:.5f} F2400", f"G1 E{e:.5f} F2400"]
    out += ["G1 X0 Y200 F6000", "M84"]
    return "\n".join(out) + "\n"


def test_rotation_found_on_parsed_gcode():
    from gatesopt.parse import parse
    prog = parse(rotated_square_gcode())
    p = build(prog, GatingOptions(bed_size_mm=(220, 220)))
    # the purge line and the park move stay put: rotation starts at the travel to the square
    assert prog.extruding[p.rotate_lo + 1] and not prog.extruding[p.rotate_lo]
    assert np.allclose(p.center_mm, (100, 100), atol=1e-3)
    sol = solve(p, "dp")
    check_solution(sol)
    assert math.isclose(sol.rotation_deg % 90.0, 73.0, abs_tol=0.01)   # coordinates have 3 decimals
    assert sol.max_snap_mm <= 1e-3
    none = solve(build(prog, GatingOptions(rotate="none")), "dp")
    assert sol.energy_j < none.energy_j
    # a planner's own durations plug in: twice as slow doubles every step's energy, and saves more
    # than twice as much (start-ahead and end-late stay 1.8 ms and 1 ms)
    slow = build(prog, GatingOptions(rotate="none"), duration_s=2 * prog.duration_s)
    assert math.isclose(slow.energy_before_j, 2 * none.energy_before_j, rel_tol=1e-9)
    slow_sol = solve(slow, "dp")
    check_solution(slow_sol)
    assert slow_sol.saving_j > 2 * none.saving_j


def test_rotation_that_leaves_the_bed_is_refused():
    s, e, d = path_moves([(1, 1), (199, 1), (199, 199), (1, 199)], [1, 1, 1])
    with pytest.raises(InfeasibleError, match="does not fit"):
        from_moves(s, e, d, GatingOptions(rotate=45.0), bed_size_mm=(200, 200))
    p = from_moves(s, e, d, GatingOptions(rotate="auto"), bed_size_mm=(200, 200))
    assert set(np.round(p.angles_deg, 6)) <= {0.0, 90.0, 180.0, 270.0}


def test_bad_options_are_clear_errors():
    with pytest.raises(GatingOptionsError, match="motors"):
        GatingOptions(motors=("Q",))
    with pytest.raises(GatingOptionsError, match="rotate"):
        GatingOptions(rotate="sideways")
    with pytest.raises(GatingOptionsError, match="enable pin"):
        GatingOptions(motors=("X", "Y"), shared_enable=(("X", "Z"),))
    with pytest.raises(GatesoptError, match="formulation"):
        solve(small_problem(), "simplex")


def test_milp_time_limit_returns_a_feasible_answer():
    p = small_problem(stall_off_s=0.05, max_added_time_pct=2.0)
    sol = solve(p, "milp", time_limit_s=1e-3)
    assert sol.status in ("optimal", "feasible", "fallback")
    assert sol.added_time_s <= p.max_added_time_s + 1e-9
    check_solution(sol)


# ------------------------------------------------------------------------------------------------
# generated instances
@st.composite
def tiny_problems(draw):
    n = draw(st.integers(2, 6))
    x, y, e = 50.0, 50.0, 0.0
    starts, ends, durs = [], [], []
    for _ in range(n):
        kind = draw(st.sampled_from(["x", "y", "xy", "retract", "dwell"]))
        dx = draw(st.floats(0.2, 8.0)) * draw(st.sampled_from([-1, 1]))
        dy = draw(st.floats(0.2, 8.0)) * draw(st.sampled_from([-1, 1]))
        de = draw(st.sampled_from([0.0, 0.1]))
        nx, ny, ne = x, y, e
        if kind == "x":
            nx += dx
        elif kind == "y":
            ny += dy
        elif kind == "xy":
            nx, ny = nx + dx, ny + dy
        elif kind == "retract":
            ne -= 0.5
        starts.append((x, y, 0.2, e))
        ne += de if kind in ("x", "y", "xy") else 0.0
        ends.append((nx, ny, 0.2, ne))
        durs.append(draw(st.sampled_from([0.0005, 0.002, 0.05, 0.3, 1.0])))
        x, y, e = nx, ny, ne
    opts = dict(
        rotate="none",
        start_ahead_s=draw(st.sampled_from([0.0, 1.8e-3, 0.01])),
        end_late_s=draw(st.sampled_from([0.0, 1.0e-3, 0.02])),
        stall_off_s=draw(st.sampled_from([0.0, 0.01, 0.22])),
        stall_on_s=draw(st.sampled_from([0.0, 0.01])),
        on_line=draw(st.booleans()),
        merge_lines=draw(st.booleans()),
        max_added_lines_pct=draw(st.sampled_from([None, None, 50.0, 100.0])),
        max_added_time_pct=draw(st.sampled_from([None, None, 1.0, 10.0])),
        shared_enable=draw(st.sampled_from([(), (), (("X", "Y"),)])),
    )
    inter = draw(st.sampled_from([0.0, 0.0, 2.0, -2.0]))
    p = from_moves(np.array(starts), np.array(ends), np.array(durs), GatingOptions(**opts))
    if inter:
        c = p.coeffs
        coeffs = with_xy_off(c, inter)
        p = from_moves(p.start_mm, p.end_mm, p.duration_s, p.options, coeffs=coeffs)
    return p


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tiny_problems())
def test_generated_exact_vs_brute_force(p):
    best = brute_force(p)
    sols = {f: solve(p, f, time_limit_s=20) for f in ("greedy",) + EXACT}
    for f, sol in sols.items():
        if f != "greedy" or sol.status != "infeasible":
            check_solution(sol)
        assert sol.energy_j >= best[0] - 1e-6 or (f == "greedy" and sol.status == "infeasible")
    for f in ("milp", "cpsat") + (("dp",) if p.separable else ()):
        sol = sols[f]
        assert sol.status == "optimal", (f, sol.message)
        assert math.isclose(sol.energy_j, best[0], abs_tol=1e-6), (f, sol.energy_j, best)
        assert sol.lines_added == best[1], (f, sol.lines_added, best)
        assert sol.added_time_s <= p.max_added_time_s + 1e-9 and sol.lines_added <= p.max_added_lines
    if sols["greedy"].status != "infeasible":
        assert sols["milp"].energy_j <= sols["greedy"].energy_j + 1e-6


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tiny_problems())
def test_share_bound_never_exceeds_the_optimum(p):
    """``build_model``'s bound (each shared line's stall charged 1/|sharers| to each sharer, negative
    XY corrections all taken, budgets as fractional knapsacks) prunes angles and is reported when a
    solver stops early: it must hold on every problem, budgets, shared pins and XY power included."""
    from gatesopt.gating import coupled, dp, milp
    best = brute_force(p)[0]
    for incumbent_j in (math.inf, dp.solve(p).energy_j):
        model = coupled.build_model(p, incumbent_j)
        assert model.bound_j <= best + 1e-6, (incumbent_j, model.bound_j, best)
    # dp reports it too where it is a heuristic (not separable), and calls its answer optimal only
    # within the exact solvers' relative gap of it
    d = dp.solve(p)
    assert d.bound_j <= best + 1e-6 and d.bound_j <= d.energy_j + 1e-9
    assert (d.status == "optimal") == (p.separable or d.gap <= p.options.mip_rel_gap), (d.status, d.gap)


# ------------------------------------------------------------------------------------------------
# a real slicer file
@pytest.fixture(scope="module")
def stars():
    path = INSTANCES / "real_slic3r131_stars.gcode"
    if not path.exists():
        pytest.skip(f"{path} absent (real slicer instances live in ../shared/instances)")
    from gatesopt.parse import parse
    return parse(path)


def test_real_file_dp_equals_milp_and_beats_greedy(stars):
    p = build(stars, GatingOptions())
    d, m, g = solve(p, "dp"), solve(p, "milp", time_limit_s=60), solve(p, "greedy")
    for s in (d, m, g):
        check_solution(s)
    assert d.status == "optimal" and m.status == "optimal"
    assert math.isclose(d.energy_j, m.energy_j, rel_tol=1e-9) and d.lines_added == m.lines_added
    assert d.energy_j <= g.energy_j
    assert d.energy_j < p.energy_before_j


def test_real_file_budget(stars):
    p = build(stars, GatingOptions.for_firmware("marlin", rotate="none", max_added_time_pct=1.0,
                                                max_added_lines_pct=5.0))
    d, m, c = solve(p, "dp"), solve(p, "milp", time_limit_s=60), solve(p, "cpsat", time_limit_s=60)
    for s in (d, m, c):
        check_solution(s)
        assert s.added_time_s <= p.max_added_time_s + 1e-9 and s.lines_added <= p.max_added_lines
    assert m.status == "optimal" and m.energy_j <= d.energy_j + 1e-9
    assert m.bound_j <= m.energy_j
    # both exact methods prove the same optimum (within their 1e-6 relative gap)
    assert c.status == "optimal" and math.isclose(c.energy_j, m.energy_j, rel_tol=2e-6)
    assert c.bound_j <= m.energy_j + 1e-6 and m.bound_j <= c.energy_j + 1e-6


def sequential_squares_gcode(deg=17.0, n_layers=8) -> str:
    """Two turned squares printed one after the other (PrusaSlicer "complete_objects", Cura "one at
    a time"): the second starts again at the bed once the first is finished."""
    one = rotated_square_gcode(deg, n_layers).splitlines()
    body = one[one.index(";LAYER_CHANGE"):one.index("G1 X0 Y200 F6000")]
    e_last = float(body[-1].split("E")[1].split()[0])
    second = []
    for line in body:                       # the same square 40 mm further in X, E continuing
        if line.startswith("G1 X"):
            parts = line.split()
            parts[1] = f"X{float(parts[1][1:]) + 40:.3f}"
            line = " ".join(parts)
        if " E" in line:
            head, tail = line.split(" E")
            val, *rest = tail.split()
            line = " ".join([head, f"E{float(val) + e_last:.5f}", *rest])
        second.append(line)
    return "\n".join(one[:one.index("G1 X0 Y200 F6000")] + ["G1 Z10 F600"] + second
                     + ["G1 X0 Y200 F6000", "M84"]) + "\n"


def test_sequential_print_is_not_rotated():
    """The slicer checked the print head's clearance for the objects where they stand: rotated,
    the head (an asymmetric shape) could hit an object printed before. ``auto`` keeps 0 deg and
    says why; an explicit angle is refused with the file and line where the print goes back down."""
    from gatesopt.parse import parse
    prog = parse(sequential_squares_gcode(), source="seq.gcode")
    p = build(prog, GatingOptions(bed_size_mm=(220, 220)))
    assert list(p.angles_deg) == [0.0]
    assert any("one at a time" in n and "rotation kept at 0 deg" in n for n in p.notes)
    # the first extrusion of the second square: lift, layer change, Z, travel, then this line
    line = next(i for i, t in enumerate(prog.lines()) if t.startswith("G1 Z10")) + 1 + 4
    with pytest.raises(InfeasibleError, match=rf"seq\.gcode:{line}: objects are printed one at a time"):
        build(prog, GatingOptions(rotate=73.0, bed_size_mm=(220, 220)))
    # the same squares layer by layer (no return to the bed) are rotated as before
    together = parse(rotated_square_gcode(n_layers=8))
    q = build(together, GatingOptions(bed_size_mm=(220, 220)))
    assert not q.notes and math.isclose(solve(q, "dp").rotation_deg % 90.0, 73.0, abs_tol=0.01)


def test_a_whole_run_refuses_the_angle_at_the_inputs_line_before_ordering(monkeypatch):
    # ``rewrite.pipeline.run`` checks an explicit angle on the file as given: the line named is
    # the user's (after the ordering it was a line of the re-ordered text, under the input's
    # name: a CuraEngine one-at-a-time slice said :1826 for its drop at 1883) and no ordering
    # runs first
    from gatesopt.parse import parse
    from gatesopt.rewrite import pipeline
    prog = parse(sequential_squares_gcode(), source="seq.gcode")
    line = next(i for i, t in enumerate(prog.lines()) if t.startswith("G1 Z10")) + 1 + 4
    monkeypatch.setattr(pipeline, "_order_curves", lambda *a, **k: pytest.fail("ordered first"))
    with pytest.raises(InfeasibleError, match=rf"seq\.gcode:{line}: objects are printed one at a time"):
        pipeline.run(prog, GatingOptions(rotate=73.0, bed_size_mm=(220, 220)))


def test_rotation_sweep_refuses_a_sequential_print(tmp_path):
    """``gatesopt report --sweep`` (the paper's Fig. 14) on a print of objects one at a time: one
    angle is no sweep, and the user is told why instead of getting a figure with a single point."""
    from gatesopt.errors import GatesoptError
    from gatesopt.report import rotation_sweep
    seq = tmp_path / "seq.gcode"
    seq.write_text(sequential_squares_gcode())
    with pytest.raises(GatesoptError, match=r"no rotation sweep: --rotate auto tries only 0 deg.*one at a time"):
        rotation_sweep(seq)
    flat = tmp_path / "flat.gcode"
    flat.write_text(rotated_square_gcode(n_layers=8))
    sweep = rotation_sweep(flat)
    # the file names no bed: the command would not turn it; the sweep is the model's what-if at
    # the angles --rotate auto tries on a bed, and says so
    assert not sweep.bed_checked and 0.0 in sweep.angles_deg and 30.0 in sweep.angles_deg
    energy = dict(zip(sweep.angles_deg, sweep.energy_j))
    # the square is turned by 17 deg: at 73 deg its sides run along the axes and one motor can be
    # gated on each; at 0 and 30 deg both motors move on every side (the same energy)
    at73 = min(energy, key=lambda a: abs(a % 90.0 - 73.0))
    assert abs(at73 % 90.0 - 73.0) < 0.01 and math.isclose(sweep.chosen_deg % 90.0, 73.0, abs_tol=0.01)
    assert energy[at73] < energy[0.0] == energy[30.0]
    # with a bed the print fits, the angles are those the command tries, checked against it
    bedded = rotation_sweep(flat, options=GatingOptions(bed_size_mm=(220, 220)))
    assert bedded.bed_checked and math.isclose(bedded.chosen_deg % 90.0, 73.0, abs_tol=0.01)


def test_a_stopped_solver_still_reports_the_share_bound(stars, monkeypatch):
    """HiGHS stopped before it has anything (here: never run) returns the dp start as a fallback,
    with the share bound and its gap, not an unknown gap. On a 217k-line Cura file under Marlin
    HiGHS had not finished its root LP in 10 s and reported a 75 % gap where this bound gives 8e-6."""
    from gatesopt.gating import coupled, dp, milp
    p = build(stars, GatingOptions.for_firmware("marlin"))
    exact = solve(p, "milp", time_limit_s=60)
    assert exact.status == "optimal"
    from gatesopt._native import HighsRun
    monkeypatch.setattr(milp, "run_highs", lambda h, start=None, **kw: HighsRun(False))
    sol = solve(p, "milp", time_limit_s=60)
    start = dp.solve(p)
    assert sol.status == "fallback" and sol.energy_j == pytest.approx(start.energy_j, rel=1e-12)
    model = coupled.build_model(p, start.energy_j)
    assert sol.bound_j == pytest.approx(model.bound_j, rel=1e-12)
    assert sol.bound_j <= exact.energy_j + 1e-6
    # the bound is tight on real output: far inside the gap HiGHS's unfinished root gave
    assert 0.0 <= sol.gap < 0.01
    # and it prunes: under Marlin's shared stalls most of the 18 angles cannot beat the dp start
    assert len(model.angles) < p.n_angles
