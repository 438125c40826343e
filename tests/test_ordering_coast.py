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
    before the retraction; six infill lines, the even ones coasted 0.3 mm (at 90 % of their feed)
    before a retraction, the odd ones with Cura's infill wipe (0.3 mm at their own feed: the
    gap's, as before); a last line followed by a 6 mm run at 90 % (too long for a coast)."""
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
            out += [f"G0 F9000 X{x0} Y{y}", f"G1 F3600 X{x1} Y{y} E{e:.5f}"]
            if k % 2 == 0:
                out += [f"G0 F3240 X{x1 + 0.3} Y{y}", f"G1 F2700 E{e - 5:.5f}",
                        f"G0 F9000 X{x1 + 0.3} Y{y + 1}", f"G1 F2700 E{e:.5f}"]
            else:
                out.append(f"G1 X{x1 + 0.3} Y{y}")
        e += 0.6
        out += ["G0 F9000 X60 Y50", f"G1 F3600 X80 Y50 E{e:.5f}", "G0 F3240 X86 Y50",
                f"G1 F2700 E{e - 5:.5f}", "G0 F9000 X60 Y60", f"G1 F2700 E{e:.5f}"]
    out += ["M104 S0", "M84"]
    return "\n".join(out) + "\n"


def test_coasting_belongs_to_its_curve():
    program = gatesopt.parse(coasted_file(), source="coasted.gcode")
    lay = layout(program)
    coast = lay.curve_coast
    assert len(coast) == len(lay.curve_s0)
    for c in range(len(coast)):
        tail = program.kind[lay.curve_s1[c] - 1] == Kind.TRAVEL
        assert tail == coast[c]
        if coast[c]:
            assert lay.line_class[lay.curve_l1[c]] == LINE_CURVE
    # per layer: the wall and the even lines coasted; the odd lines' infill wipe (at their own
    # feed) and the last line's 6 mm run are the gaps'
    assert coast[program.layer[lay.curve_s0] == 1].tolist() == [True, True, False, True, False,
                                                                True, False, False]
    problem = build(program, OrderingOptions(mode="free"))
    walls = np.flatnonzero(np.hypot(*(problem.curve_end_xy - problem.curve_start_xy).T) < 0.5)
    assert len(walls) == 3 and problem.curve_one_way[walls].all()
    assert not problem.curve_closed[walls].any()        # no loop: its seam may not move
    # coasted curves keep their direction (backwards they would coast into their start); the
    # others may turn round
    assert problem.curve_one_way.tolist() == coast.tolist()


def test_free_mode_keeps_every_coast():
    program = gatesopt.parse(coasted_file(), source="coasted.gcode")
    res = order_program(program, OrderingOptions(mode="free"))
    assert res.ok
    out = res.output
    for feed_mm_s, n in ((27.0, 6), (54.0, 9)):
        coast_in = np.flatnonzero((program.kind == Kind.TRAVEL)
                                  & np.isclose(program.feed_mm_s, feed_mm_s))
        coast_out = np.flatnonzero((out.kind == Kind.TRAVEL) & np.isclose(out.feed_mm_s, feed_mm_s))
        # (the 6 mm run at 54 mm/s is the gap's: rebuilt where the last line moved)
        assert len(coast_in) == n + (3 if feed_mm_s == 54.0 else 0)
        kept = [r for r in coast_out if out.length_mm[r] < 1.0]
        assert len(kept) == n
        # each right after its curve's last extrusion, or after the coast move before it
        assert all(out.extruding[r - 1] or out.kind[r - 1] == Kind.TRAVEL for r in kept)
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
