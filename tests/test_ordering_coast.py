"""The slicer's coasting stays with its curve, and loops keep their direction in free mode.

The regression sweep of 2026-11-27 (sweep 7) found: re-ordering dropped Cura's coasting (a wall's
last stretch run without extrusion before the retraction: 5,188 coast moves -> 16 in free mode,
-> 2,486 in safe mode with time to order) and Cura's infill wipe (a line's tail run on into the
wall), because they lay in the gap the ordering rebuilds; and free mode reversed PrusaSlicer's
perimeters (clipped 0.06 mm short of their seam, so not closed: 246 of 282 external perimeters of
a cube printed clockwise)."""
from __future__ import annotations

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build
from gatesopt.ordering.layout import LINE_CURVE, layout
from gatesopt.program import Kind
from gatesopt.rewrite.order import order_program

from conftest import SHARED_INSTANCES


def coasted_file() -> str:
    """Cura-like layers: a square wall loop whose last 1 mm is coasted (G0 at 90 % of its feed)
    before the retraction; infill lines each with a 0.3 mm tail at their own feed, then a travel
    at 150 mm/s; one line followed by a 6 mm run at its feed (too long for a coast: travel)."""
    out = [";FLAVOR:Marlin", ";Generated with Cura_SteamEngine 4.13.1", "G21", "G90", "M82",
           "G28", "G92 E0", "G1 Z0.2 F720"]
    e = 0.0
    for layer in range(3):
        z = 0.2 * (layer + 1)
        out += [f";LAYER:{layer}", f"G0 F9000 X20 Y20 Z{z:.1f}", ";TYPE:WALL-OUTER"]
        for x, y in ((40, 20), (40, 40), (20, 40), (20, 21)):
            e += 0.8
            out.append(f"G1 F1800 X{x} Y{y} E{e:.5f}")
        out += ["G0 F1620 X20 Y20.2", "G0 X20 Y20", f"G1 F2700 E{e - 5:.5f}",
                "G0 F9000 X60 Y20", f"G1 F2700 E{e:.5f}", ";TYPE:FILL"]
        for k in range(6):
            y = 20 + 4 * k
            x0, x1 = (60, 80) if k % 2 == 0 else (90, 110)
            e += 0.6
            out += [f"G0 F9000 X{x0} Y{y}", f"G1 F3600 X{x1} Y{y} E{e:.5f}",
                    f"G1 X{x1 + 0.3} Y{y}"]
        e += 0.6
        out += ["G0 F9000 X60 Y50", f"G1 F3600 X80 Y50 E{e:.5f}", "G1 X86 Y50",
                "G0 F9000 X60 Y60"]
    out += ["M104 S0", "M84"]
    return "\n".join(out) + "\n"


def test_coasting_and_infill_tails_belong_to_their_curves():
    program = gatesopt.parse(coasted_file(), source="coasted.gcode")
    lay = layout(program)
    coast = lay.curve_coast
    assert len(coast) == len(lay.curve_s0)
    for c in range(len(coast)):
        last = program.end_mm[lay.curve_s1[c] - 1, :2]
        tail = program.kind[lay.curve_s1[c] - 1] == Kind.TRAVEL
        assert tail == coast[c]
        if coast[c]:
            # every line of the curve, its tail's too, is a curve line
            assert (lay.line_class[lay.curve_l1[c]] == LINE_CURVE)
    per_layer = int(np.count_nonzero(program.layer[lay.curve_s0] == 1))
    # per layer: the wall (coasted) and six lines with tails; the seventh line's 6 mm run is a
    # travel
    assert coast[program.layer[lay.curve_s0] == 1].tolist() == [True] * 7 + [False]
    assert per_layer == 8
    problem = build(program, OrderingOptions(mode="free"))
    walls = np.flatnonzero(np.hypot(*(problem.curve_end_xy - problem.curve_start_xy).T) < 0.5)
    assert len(walls) == 3 and problem.curve_one_way[walls].all()
    assert not problem.curve_closed[walls].any()        # no loop: its seam may not move
    lines = np.setdiff1d(np.arange(problem.n_curves), walls)
    assert not problem.curve_one_way[lines].any()       # lines with a tail may still turn round


def test_free_mode_keeps_every_coast_and_tail():
    program = gatesopt.parse(coasted_file(), source="coasted.gcode")
    res = order_program(program, OrderingOptions(mode="free"))
    assert res.ok
    out = res.output
    # the coasted walls: each still ends in its two coast moves at F1620 (the retraction after
    # them is the travel's: none where free mode printed the wall last and the next layer starts
    # where it ended)
    coast_in = np.flatnonzero((program.kind == Kind.TRAVEL) & np.isclose(program.feed_mm_s, 27.0))
    coast_out = np.flatnonzero((out.kind == Kind.TRAVEL) & np.isclose(out.feed_mm_s, 27.0))
    assert len(coast_out) == len(coast_in) == 6
    first = coast_out[0::2]
    assert out.extruding[first - 1].all() and (coast_out[1::2] == first + 1).all()
    assert np.allclose(out.end_mm[first - 1, :2], [20, 21])
    # each line's tail: after it (forward) or, reversed, leading into it (the tail run backwards)
    def tails(p):
        t = (p.kind == Kind.TRAVEL) & np.isclose(p.length_mm, 0.3)
        after = np.flatnonzero(t[1:] & p.extruding[:-1])
        before = np.flatnonzero(t[:-1] & p.extruding[1:])
        return len(after), len(before)
    a_in, b_in = tails(program)
    a_out, b_out = tails(out)
    assert (a_in, b_in) == (18, 0)
    assert a_out + b_out == 18
    assert res.summary["travel_after_mm"] < res.summary["travel_before_mm"]


def _perimeter_turns(program, feature: str) -> list[float]:
    """Signed area of each extruding run of ``feature`` with >= 4 moves that ends within 0.2 mm of
    its start, a loop (> 0: counter-clockwise). (Open perimeters, benchy's split walls, are open
    curves: free mode may print them either way.)"""
    names = program.feature_names
    rows = np.flatnonzero(program.extruding & (program.layer >= 0))
    out, run = [], []
    for r in rows.tolist() + [-1]:
        if r >= 0 and run and r == run[-1] + 1 and program.feature[r] == program.feature[run[-1]]:
            run.append(r)
            continue
        if len(run) >= 4 and names[program.feature[run[0]]] == feature:
            p = np.vstack([program.start_mm[run, :2], program.end_mm[run[-1], :2]])
            if np.hypot(*(p[-1] - p[0])) < 0.2:
                out.append(float(np.sum(p[:-1, 0] * p[1:, 1] - p[1:, 0] * p[:-1, 1])))
        run = [r] if r >= 0 else []
    return out


def test_free_mode_keeps_prusaslicer_perimeters_turning_their_way():
    path = SHARED_INSTANCES / "real_prusa261_benchy.gcode.gz"
    if not path.exists():
        pytest.skip(f"{path} not found")
    program = gatesopt.parse(path)
    problem = build(program, OrderingOptions(mode="free"))
    # PrusaSlicer clips its loops 0.06 mm short of their seam: one-way curves, not loops
    gap = np.hypot(*(problem.curve_end_xy - problem.curve_start_xy).T)
    clipped = (gap > 1e-3) & (gap < 0.2) & (problem.curve_step_stop - problem.curve_step_start >= 3)
    assert clipped.sum() > 100 and problem.curve_one_way[clipped].all()
    res = order_program(program, OrderingOptions(mode="free"), formulation="greedy")
    assert res.ok
    before = np.sign(_perimeter_turns(program, "External perimeter"))
    after = np.sign(_perimeter_turns(res.output, "External perimeter"))
    assert len(before) > 100 and sorted(before) == sorted(after)
