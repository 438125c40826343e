"""Rotation that is explicit and safe (issue 37): no rotation without a known bed that the rotated
print fits with the margin; said in one line either way; the slicer's bounds lines follow the
rotation; the exact angles the geometry suggests are candidates; a rotated solution is written by
``rewrite.run`` only (``gating.emit`` refuses one)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import gatesopt
from gatesopt import gating, slicers
from gatesopt.cli import main
from gatesopt.errors import InfeasibleError
from gatesopt.gating import GatingOptions
from gatesopt.gating.emit import EmitError
from gatesopt.gating.rotation import BED_MARGIN_MM, PrintOutline, clearance_mm
from gatesopt.rewrite import run
from gatesopt.verify import verify

CURA_BOX = ";FLAVOR:Marlin\n;MINX:70\n;MINY:70\n;MINZ:0.2\n;MAXX:130\n;MAXY:130\n;MAXZ:0.6\n"
OUTLINE = "EXCLUDE_OBJECT_DEFINE NAME=part CENTER=100,100 POLYGON=[[70,70],[130,70],[130,130],[70,130]]\n"


def diagonal_part(header: str = CURA_BOX, layers: int = 3) -> str:
    """A 60 mm square (70..130) filled with 45-degree lines written with 3 decimals, as slicers
    write them: the lines' directions scatter by up to ~1e-3 deg around 45."""
    out = [header.rstrip("\n"), "G21", "G90", "M82", "G28", "G92 E0"]
    e = 0.0
    for k in range(layers):
        out += [f";LAYER:{k}", f"G1 Z{0.2 * (k + 1):.1f} F600", "G1 X70 Y70 F6000"]
        for x, y in ((130, 70), (130, 130), (70, 130), (70, 70)):
            e += 2.0
            out.append(f"G1 X{x} Y{y} E{e:.5f} F1800")
        for i, c in enumerate(np.arange(-55.0, 56.0, 3.7)):
            # the line x - y = c inside the square, endpoints rounded to 3 decimals
            x0, y0 = max(70.0, 70.0 + c), max(70.0, 70.0 - c)
            x1, y1 = min(130.0, 130.0 + c), min(130.0, 130.0 - c)
            (ax, ay), (bx, by) = ((x0, y0), (x1, y1)) if i % 2 == 0 else ((x1, y1), (x0, y0))
            # a few tenths of a micrometre off, inwards (the box stays 70..130)
            ax, by = ax + _inward(ax) * (i % 3), by + _inward(by) * (i % 2)
            out.append(f"G1 X{ax:.4f} Y{ay:.3f} F6000")
            e += 0.03 * math.hypot(bx - ax, by - ay)
            out.append(f"G1 X{bx:.3f} Y{by:.4f} E{e:.5f} F1800")
    out += ["G1 X0 Y200 F6000", "M84 X Y E"]
    return "\n".join(out) + "\n"


def _inward(v: float) -> float:
    return 0.0004 if v < 100 else -0.0004


def paper(**kw) -> GatingOptions:
    return GatingOptions.for_firmware("3dgates", **kw)


def test_without_a_bed_the_print_stays_and_the_line_says_how_to_allow_it():
    prog = gatesopt.parse(diagonal_part())
    res = run(prog, paper(), order=False)
    s = res.summary()
    assert res.report.ok and s["rotation_deg"] == 0.0
    assert s["rotation_line"] == "none (bed size unknown: --bed WxD to allow it)"
    with pytest.raises(InfeasibleError, match=r"--rotate 45: the bed size is unknown.*--bed WxD"):
        run(prog, paper(rotate=45.0), order=False)


def test_with_a_bed_auto_takes_the_exact_angle_and_says_how_it_chose():
    prog = gatesopt.parse(diagonal_part())
    res = run(prog, paper(bed_size_mm=(235, 235)), order=False)
    s = res.summary()
    assert res.report.ok, [str(f) for f in res.report.findings]
    assert s["rotation_deg"] == 45.0            # exactly: not one of the scattered directions
    line = s["rotation_line"]
    assert line.startswith("45 deg about (100.000, 100.000), the best of ")
    assert "candidate angles (0, 30, 45, 60 deg and" in line and "by dp's energy" in line
    assert f"fits the 235 x 235 mm bed (--bed) with {BED_MARGIN_MM:g} mm margin" in line
    # no candidate near 45 does better than exactly 45, and auto is as good as asking for 45
    fixed = run(prog, paper(bed_size_mm=(235, 235), rotate=45.0), order=False)
    assert res.report.energy_j <= fixed.report.energy_j + 1e-6
    for off in (-6e-4, 6e-4):
        near = run(prog, paper(bed_size_mm=(235, 235), rotate=45.0 + off), order=False)
        assert res.report.energy_j < near.report.energy_j


def test_the_exact_angle_is_a_candidate_where_directions_scatter_around_it():
    prog = gatesopt.parse(diagonal_part())
    p = gating.build(prog, paper(bed_size_mm=(235, 235)))
    assert 45.0 in [float(a) for a in p.angles_deg]
    sol = gating.solve(p, "dp")
    assert sol.rotation_deg == 45.0 and sol.status == "optimal"


def test_a_rotation_must_fit_the_bed_with_the_margin():
    prog = gatesopt.parse(diagonal_part())
    # rotated by 45 deg the 60 mm square reaches 100 + 42.4 = 142.4 mm
    assert run(prog, paper(bed_size_mm=(150, 150)), order=False).summary()["rotation_deg"] == 45.0
    for bed in ((146, 146), (140, 140)):        # 3.6 mm < the 5 mm margin; off the bed
        res = run(prog, paper(bed_size_mm=bed), order=False)
        assert res.report.ok and res.summary()["rotation_deg"] == 0.0
        with pytest.raises(InfeasibleError, match="does not fit the .* bed .* with 5 mm margin"):
            run(prog, paper(bed_size_mm=bed, rotate=45.0), order=False)
    # a margin of one's own
    assert run(prog, paper(bed_size_mm=(146, 146), bed_margin_mm=3.0), order=False).summary()["rotation_deg"] == 45.0


def test_the_margin_is_no_more_than_the_slicer_kept():
    # the square 2 mm from the bed's edge, as the slicer placed it: 2 mm is enough after rotating
    part = diagonal_part().replace("G1 X0 Y200 F6000", "G1 X100 Y100 F6000")
    prog = gatesopt.parse(part)
    p = gating.build(prog, paper(bed_size_mm=(132, 250)))
    assert p.rotation_plan.slicer_clearance_mm == pytest.approx(2.0)
    assert p.rotation_plan.margin_mm == pytest.approx(2.0)


def test_the_file_s_bed_with_its_origin_is_the_one_checked():
    bed = slicers.read_bed(b"; bed_shape = 5x0,215x0,215x220,5x220\n")
    outline = PrintOutline(np.array([[8.0, 10.0], [50.0, 10.0], [50.0, 60.0], [8.0, 60.0]]),
                           *(np.zeros((0, 2)),) * 3, np.zeros(0, bool))
    assert clearance_mm(outline, bed, (29.0, 35.0), 0.0) == pytest.approx(3.0)      # x 8 - 5
    # turned a quarter about (29, 35): x = 64 - y runs 4..54, 1 mm past the bed's edge at x = 5
    assert clearance_mm(outline, bed, (29.0, 35.0), 90.0) == pytest.approx(-1.0)


def test_an_arc_bulging_past_its_end_points_counts():
    bed = slicers.rectangle_bed(0, 0, 100, 100, "--bed")
    # a half circle from (40, 10) to (60, 10) around (50, 10), counter-clockwise: it dips to y = 0
    arc = PrintOutline(np.array([[40.0, 10.0], [60.0, 10.0], [50.0, 50.0]]), np.array([[40.0, 10.0]]),
                       np.array([[60.0, 10.0]]), np.array([[50.0, 10.0]]), np.array([True]))
    assert clearance_mm(arc, bed, (50.0, 30.0), 0.0) == pytest.approx(0.0, abs=1e-9)
    cw = PrintOutline(arc.hull_mm, arc.arc_start_mm, arc.arc_end_mm, arc.arc_center_mm, np.array([False]))
    assert clearance_mm(cw, bed, (50.0, 30.0), 0.0) == pytest.approx(10.0)          # bulges up: inside


def test_the_slicer_s_bounds_lines_follow_the_rotation():
    prog = gatesopt.parse(diagonal_part(CURA_BOX + OUTLINE))
    res = run(prog, paper(bed_size_mm=(235, 235)), order=False)
    assert res.report.ok and "bounds" in res.report.checks, [str(f) for f in res.report.findings]
    lines = res.text.splitlines()
    head = {ln.split(":")[0]: float(ln.split(":")[1]) for ln in lines[:12] if ln.startswith((";MIN", ";MAX"))}
    half = 30 * math.sqrt(2)
    assert head[";MINX"] == pytest.approx(100 - half, abs=2e-3) and head[";MAXY"] == pytest.approx(100 + half, abs=2e-3)
    assert head[";MINZ"] == 0.2 and head[";MAXZ"] == 0.6                  # Z is not rotated
    outline = next(ln for ln in lines if ln.startswith("EXCLUDE_OBJECT_DEFINE"))
    assert outline.startswith("EXCLUDE_OBJECT_DEFINE NAME=part CENTER=100,100 POLYGON=[[100,57.574]")
    # the verifier recomputes them: a stale box is a finding
    stale = res.text.replace(f";MINX:{head[';MINX']:g}", ";MINX:70", 1)
    bad = verify(prog, gatesopt.parse(stale), firmware="3dgates")
    assert any(f.check == "bounds" and ";MINX:70" in f.message for f in bad.findings)
    # unrotated, the lines are the slicer's
    flat = run(prog, paper(rotate="none"), order=False)
    assert flat.text.splitlines()[:9] == diagonal_part(CURA_BOX + OUTLINE).splitlines()[:9]


def test_ideamaker_bounding_box_is_rewritten():
    box = ";Bounding Box: 70.000 130.000 70.000 130.000 0.000 0.600\n"
    prog = gatesopt.parse(diagonal_part(";Dimension: 235.000 235.000 250.000 0.400\n" + box))
    res = run(prog, paper(), order=False)                  # the bed is the file's ';Dimension:'
    assert res.report.ok and res.summary()["rotation_deg"] == 45.0
    new = next(ln for ln in res.text.splitlines() if ln.startswith(";Bounding Box:"))
    assert new.split()[2:4] == ["57.574", "142.426"] and new.split()[-2:] == ["0.000", "0.600"]


def test_emit_refuses_a_rotated_solution_and_names_the_whole_job():
    prog = gatesopt.parse(diagonal_part())
    sol = gating.solve(gating.build(prog, paper(bed_size_mm=(235, 235))), "dp")
    assert sol.rotation_deg == 45.0
    with pytest.raises(EmitError, match=r"rewrite\.run"):
        gating.emit(prog, sol)
    # unrotated, the step-by-step path writes a file that verifies
    flat = gating.solve(gating.build(prog, paper(rotate="none")), "dp")
    assert verify(prog, gatesopt.parse(gating.emit(prog, flat)), firmware="3dgates").ok


def test_solve_says_the_rotation_and_what_its_status_covers(tmp_path, capsys):
    src = tmp_path / "part.gcode"
    src.write_text(diagonal_part())
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--firmware", "3dgates"]) == 0
    printed = capsys.readouterr().out
    assert "rotation      none (bed size unknown: --bed WxD to allow it)" in printed
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--firmware", "3dgates", "--force",
                 "--bed", "235x235"]) == 0
    printed = capsys.readouterr().out
    assert "status optimal at the 45 deg rotation chosen" in printed
    assert "rotation      45 deg about (100.000, 100.000), the best of" in printed
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--rotate", "45", "--force"]) == 2
    assert "--bed WxD" in capsys.readouterr().err


def test_the_rotation_line_cites_the_bed_line_of_the_user_s_file():
    """The curve ordering writes a re-ordered copy (a ``; gatesopt: order`` line first, moves
    re-written): the bed read from that copy is one or many lines off (the check of issue 37 cited
    line 100391 for the bed_shape at line 101553 of holes__prusa_mk3s). The line said is the file's."""
    from conftest import PROJECT_INSTANCES
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    bed = slicers.read_bed(program.data)
    res = run(program, order_budget_s=5.0)
    assert res.ordered and slicers.read_bed(res.base.data).line != bed.line
    assert f"(bed_shape, line {bed.line})" in res.summary()["rotation_line"]
    assert res.summary()["rotation"]["bed"] == bed.describe()


def test_a_rotation_that_saves_too_little_once_rotated_is_not_taken():
    """The angle is chosen on the unrotated moves (and dp picks it before repairing a time budget:
    holes__prusa_mk3s with the stock 1 % budget was turned 45 deg for 3.88 % where 0 deg saves
    4.91 %); the rotated print is solved again and kept only if it saves min_rotation_gain_pct more
    than 0 deg does, said in the rotation line."""
    program = gatesopt.parse(diagonal_part(), source="part.gcode")
    turned = run(program, paper(bed_size_mm=(235, 235)), order=False)
    assert turned.summary()["rotation_deg"] == 45.0 and turned.report.ok
    gain = turned.rotation["gain_pct"]
    assert gain > 0.5
    kept = run(program, paper(bed_size_mm=(235, 235), min_rotation_gain_pct=gain + 1.0), order=False)
    s = kept.summary()
    assert s["rotation_deg"] == 0.0 and kept.report.ok
    assert s["rotation_line"].startswith("none: 45 deg, the best of")
    assert f"saves {gain:.2f} % more than 0 deg once rotated, below the {gain + 1.0:g} %" in s["rotation_line"]
    assert "(--rotate 45 to take it)" in s["rotation_line"]
    unrotated = run(program, paper(rotate="none"), order=False)
    assert s["energy_after_j"] == pytest.approx(unrotated.summary()["energy_after_j"])
    assert gain == pytest.approx(100 * (1 - turned.summary()["energy_after_j"] / s["energy_after_j"]), rel=1e-6)


def test_the_stock_budget_holds_against_the_print_as_sliced_when_rotated():
    """The rotated text of this PrusaSlicer file takes 0.15 s longer itself (1175.21 s against
    1175.06 s); with the budget on the rotated print the output took +1.013 % where the firmware
    line says "at most 1 %". The budget is on the print as sliced: its print time as the reports
    give it (planner model), which the rotated text alone makes longer by more (issue 37)."""
    from conftest import SHARED_INSTANCES
    src = SHARED_INSTANCES / "prusa25_star_rect15_m82.gcode.gz"
    if not src.exists():
        pytest.skip("development corpus not found")
    program = gatesopt.parse(src)
    res = run(program, order=False)         # marlin read from the file, the stock 1 % budget
    s = res.summary()
    assert s["firmware"] == "marlin" and s["rotation_deg"] == 45.0 and res.report.ok
    from gatesopt.rewrite.figures import print_time_s
    turned_s = print_time_s(res.base, "marlin")     # the rotated text, no gating line
    assert turned_s > s["print_time_before_s"]
    assert 0.0 < s["added_time_pct"] <= 1.0 + 1e-9
    assert s["print_time_after_s"] <= 1.01 * s["print_time_before_s"] * (1 + 1e-12)
