"""The independent verifier catches broken outputs (gatesopt.verify)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import gatesopt
from gatesopt.gating.emit import Switch, render_switches
from gatesopt.verify import Finding, energy_of, read_rotation, verify

SHARED = Path(__file__).resolve().parents[2] / "shared" / "instances"

SQUARE = """; square
G21
G90
M82
M104 S200
G92 E0
G1 F1200
G1 X0 Y0
G1 X20 Y0 E1.0
G1 X20 Y20 E2.0
M106 S255
G1 X0 Y20 E3.0
G1 X0 Y0 E4.0
G1 Z0.4 F600
G1 X20 Y0 E5.0 F1200
M107
"""


def _good():
    """A valid gated output: Y off during the first X move (with end-late/start-ahead kept)."""
    p = gatesopt.parse(SQUARE)
    t = np.cumsum(p.duration_s)
    st = t - p.duration_s
    x1 = 1  # G1 X20 Y0 E1.0: X only; Y last stepped... never before, first Y step is row 2
    sw = [Switch(st[x1] + 0.1, 1, False), Switch(t[x1] - 0.01, 1, True)]
    return p, render_switches(p, sw).text


def _checks(rep):
    return {f.check for f in rep.findings}


def test_valid_output_passes_and_energy_is_recomputed():
    p, text = _good()
    q = gatesopt.parse(text)
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]
    assert rep.energy_j < rep.energy_before_j            # Y was off for a while
    assert rep.time_s == pytest.approx(rep.time_before_s)
    e, t, _ = energy_of(q)
    assert verify(p, q, claimed=(e, t)).ok
    assert not verify(p, q, claimed=(e * 1.001, t)).ok


def test_deleted_line_is_caught():
    p, text = _good()
    broken = text.replace("M106 S255\n", "")
    rep = verify(p, gatesopt.parse(broken))
    assert not rep.ok and "commands" in _checks(rep)
    assert any("M106" in f.message for f in rep.findings)


def test_deleted_comment_is_caught():
    p, text = _good()
    rep = verify(p, gatesopt.parse(text.replace("; square\n", "")))
    assert not rep.ok and "commands" in _checks(rep)


def test_motor_stepping_while_off_is_caught():
    p, text = _good()
    broken = text.replace("S1 Y\n", "")
    rep = verify(p, gatesopt.parse(broken))
    assert not rep.ok and "timing" in _checks(rep)
    assert any("steps while off" in f.message for f in rep.findings)
    # on Klipper too: its own re-enable at the first move comes after the first steps of an input
    # shaper (docs/RESULTS.md), so its dialect writes an explicit enable and one missing is a finding
    assert "steps while off" in " ".join(f.message for f in verify(p, gatesopt.parse(broken),
                                                                  firmware="klipper").findings)


def test_late_switch_on_is_caught():
    p = gatesopt.parse(SQUARE)
    t = np.cumsum(p.duration_s)
    st = t - p.duration_s
    sw = [Switch(st[1] + 0.1, 1, False), Switch(t[1] - 0.001, 1, True)]   # 1 ms < 1.8 ms start-ahead
    rep = verify(p, gatesopt.parse(render_switches(p, sw).text))
    assert not rep.ok
    f = [f for f in rep.findings if f.check == "timing"]
    assert f and "start-ahead" in f[0].message and f[0].line is not None


def test_early_switch_off_is_caught():
    p = gatesopt.parse(SQUARE)
    st = np.cumsum(p.duration_s) - p.duration_s
    sw = [Switch(st[2] + 0.0005, 0, False), Switch(st[3] - 0.01, 0, True)]  # X stepped until st[2]
    rep = verify(p, gatesopt.parse(render_switches(p, sw).text))
    assert any(f.check == "timing" and "end-late" in f.message for f in rep.findings)


def test_moved_geometry_is_caught():
    p, text = _good()
    broken = text.replace("G1 X20 Y20 E2.0", "G1 X20 Y20.01 E2.0")
    rep = verify(p, gatesopt.parse(broken))
    assert not rep.ok and "geometry" in _checks(rep)
    g = [f for f in rep.findings if f.check == "geometry"]
    assert any(f.line is not None for f in g)


def test_changed_e_is_caught():
    p, text = _good()
    broken = text.replace("G1 X0 Y20 E3.0", "G1 X0 Y20 E3.2").replace("G1 X0 Y0 E4.0", "G1 X0 Y0 E4.2")
    rep = verify(p, gatesopt.parse(broken))
    assert not rep.ok and "extrusion" in _checks(rep)


def test_wrong_rotation_header_is_caught():
    p, text = _good()
    rep = verify(p, gatesopt.parse("; gatesopt: rotate_deg=10 center_x=0 center_y=0\n" + text))
    assert not rep.ok and "geometry" in _checks(rep)


def test_rotated_output_verifies():
    from gatesopt.gating.emit import render
    p = gatesopt.parse(SQUARE)
    q = gatesopt.parse(render(p, [], rotation_deg=33, center_mm=(10, 10)).text)
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]
    assert rep.rotate_deg == 33


def _rotated_square(deg: float, shift_mm: float) -> str:
    """SQUARE rotated by ``deg`` about (10, 10), as gatesopt writes it (4 decimals), with the corner
    (20, 20) moved by ``shift_mm`` on both of the output's axes: what two single-axis snaps of a
    move of a micrometre or two do to a point."""
    import math
    import re
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    out = [f"; gatesopt: rotate_deg={deg:g} center_x=10 center_y=10"]
    for ln in SQUARE.splitlines():
        m = re.match(r"G1 X(\S+) Y(\S+)(.*)", ln)
        if m:
            x, y = float(m.group(1)), float(m.group(2))
            rx, ry = 10 + c * (x - 10) - s * (y - 10), 10 + s * (x - 10) + c * (y - 10)
            if (x, y) == (20.0, 20.0):
                rx, ry = rx + shift_mm, ry + shift_mm
            ln = f"G1 X{rx:.4f} Y{ry:.4f}{m.group(3)}"
        out.append(ln)
    return "\n".join(out) + "\n"


def test_geometry_tolerance_is_per_axis_of_the_rotated_output():
    """The snap tolerance holds on each axis of the output's own frame; the verifier compares in
    the original's, where that box turned by 30 deg reaches 1.37x as far on an axis. A Cura file
    rotated by 30 deg with a 1 um travel between two extrusions (both axes snapped) was refused."""
    p = gatesopt.parse(SQUARE)
    rep = verify(p, gatesopt.parse(_rotated_square(30, 1.0e-3)))
    assert rep.ok, [str(f) for f in rep.findings]
    rep = verify(p, gatesopt.parse(_rotated_square(30, 1.5e-3)))      # more than any snap
    assert not rep.ok and "geometry" in _checks(rep)


# reduced from PrusaSlicer 2.5 output (marlin2, complete_objects, a cylinder): gated at 45 deg, the
# first piece of a split move ends, as written, within the tolerance of an unrelated original
# vertex (100.029, 102.71); the verifier took that piece for an unrotated row and refused a
# correct output
ROTATED_SPLIT = """G21
G90
M82
G28
G92 E0
G1 Z0.2 F7800
G1 X96.619 Y101.637 F7800
G1 X96.225 Y100 E4.00183
G1 X100 Y96.225 E4.28625
G1 X103.775 Y100 E4.57066
G1 X100 Y103.775 E4.85508
G1 X102.588 Y101.246 F7800
G1 E2 F2400
G1 F1200
G1 X101.912 Y101.923 E2.04622
G1 X100.029 Y102.71 E2.46494
"""


def test_a_rotated_piece_ending_on_an_unrelated_vertex_still_verifies():
    from gatesopt.rewrite import run
    from gatesopt.gating import GatingOptions
    from gatesopt.verify.geometry import _near
    p = gatesopt.parse(ROTATED_SPLIT)
    res = run(p, GatingOptions(rotate=45.0, bed_size_mm=(300, 300)), formulation="dp", order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]
    # the coincidence the test is about: a row of the output ends on an original vertex as written
    out = res.output
    ext = np.flatnonzero(out.extruding & (out.layer >= 0))
    verts = np.concatenate([p.start_mm[:, :3], p.end_mm[:, :3]])
    assert _near(verts, out.end_mm[ext, :3], 1.1e-3).any()
    # and that piece moved off the line by 0.1 mm is still caught
    piece = "G1 X100.0282 Y102.711 "
    assert res.text.count(piece) == 1
    assert not verify(p, gatesopt.parse(res.text.replace(piece, "G1 X100.0282 Y102.811 "))).ok


def test_a_rotated_reordered_output_without_gating_lines_verifies(tmp_path):
    # re-ordered, rotated, and no motor line worth inserting (Marlin firmware on a tiny print):
    # the ordering checks, which compare moves in the original's frame, ran on the rotated text
    # and refused a correct output
    from gatesopt.cli import main
    src = tmp_path / "two.gcode"
    src.write_text("""G21
G90
M82
G28
G92 E0
G1 Z0.2 F7800
G1 X90 Y90 F7800
G1 X110 Y90 E1 F1800
G1 X110 Y110 E2
G1 X90 Y110 E3
G1 X90 Y90 E4
G1 X95 Y95 F7800
G1 X105 Y95 E4.5
G1 X100 Y105 F7800
G1 X100 Y100 E4.8
""")
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--firmware", "marlin", "--rotate", "45",
                 "--bed", "200x200", "--max-added-time-pct", "none"]) == 0
    q = gatesopt.parse(str(out))
    assert read_rotation(q)[0] == 45.0
    assert not (q.kind == gatesopt.Kind.MOTOR).any()
    rep = verify(gatesopt.parse(str(src)), q, firmware="marlin")
    assert rep.ok, [str(f) for f in rep.findings]


def test_finding_text():
    f = Finding("timing", 12, "motor X steps while off")
    assert str(f) == "[timing] line 12: motor X steps while off"
    assert str(Finding("commands", 3, "gone", in_original=True)).startswith("[commands] original line 3")


def test_reordered_output_keeps_control_order_only():
    # swap the two perimeter halves (a re-ordering): gating-only checks would fail, the
    # re-ordered checks hold (same segments, same E per layer, same heater/fan order)
    a = SQUARE
    b = a.replace("G1 X20 Y0 E1.0\nG1 X20 Y20 E2.0\n", "G1 X20 Y0 E1.0\nG1 X20 Y20 E2.0\n")
    p = gatesopt.parse(a)
    rep = verify(p, gatesopt.parse(b), reordered=True)
    assert rep.ok and rep.reordered


@pytest.mark.skipif(not (SHARED / "slic3r13_torus_3dhoney20_acp.gcode").exists(),
                    reason="../shared/instances absent")
def test_real_file_identity_verifies():
    p = gatesopt.parse(SHARED / "slic3r13_torus_3dhoney20_acp.gcode")
    rep = verify(p, p)
    assert rep.ok and rep.energy_j == pytest.approx(rep.energy_before_j)


def test_verify_cli_detects_the_output_dialect(tmp_path, capsys):
    from gatesopt.cli import main
    src = __import__("conftest").PROJECT_INSTANCES / "square_lines.gcode"
    for fw in ("klipper", "marlin", "3dgates"):
        out = tmp_path / f"{fw}.gcode"
        assert main(["solve", str(src), "-o", str(out), "--firmware", fw, "--max-added-time-pct", "1",
                     "--rotate", "none", "--no-order", "--motors", "X,Y"]) == 0
        capsys.readouterr()
        assert main(["verify", str(src), str(out)]) == 0
        assert f"(firmware: {fw})" in capsys.readouterr().out


# ------------------------------------------------------------------------------------------------
# The verifier's bulk paths (equal lines walked in a kernel, motor lines read once per distinct
# text, a split move joined back in one query when the whole run is an original move) must still
# reject what the line-by-line reading rejected.
def test_distinct_lines_groups_exactly_equal_texts():
    from gatesopt._text import distinct_lines
    rng = np.random.default_rng(3)
    words = ["S0 X", "S0 X ", "S0 Y", "S1 X", "s0 x", "M107", "S0 X\r", ";", ""]
    text = "".join(str(rng.choice(words)) + "\n" for _ in range(2000))
    p = gatesopt.parse("G1 X1\n" + text, require_moves=False)
    lines = np.arange(1, p.n_lines)
    inverse, texts = distinct_lines(p, lines)
    assert len(texts) == len(set(texts))
    assert [texts[k] for k in inverse] == [p.line_text(int(i)) for i in lines]


@pytest.fixture(scope="module")
def gated_stars():
    from gatesopt.rewrite import run
    from gatesopt.gating import GatingOptions
    path = SHARED / "real_slic3r131_stars.gcode"
    if not path.exists():
        pytest.skip("../shared/instances absent")
    p = gatesopt.parse(path)
    res = run(p, GatingOptions.for_firmware("3dgates", rotate="none"), order=False)
    assert res.report.ok and res.emitted.splits > 100 and p.line_ending == "\r\n"
    return p, res.text


def _mutated_checks(p, text):
    rep = verify(p, gatesopt.parse(text, source="mutated"))
    assert not rep.ok
    return _checks(rep)


def test_a_control_line_replaced_by_a_motor_line_is_caught(gated_stars):
    p, text = gated_stars
    assert "commands" in _mutated_checks(p, text.replace("M106 S255\r\n", "S0 X\r\n", 1))


def test_a_line_changed_in_one_byte_is_caught(gated_stars):
    p, text = gated_stars
    assert "commands" in _mutated_checks(p, text.replace("M106 S224.4\r\n", "M106 S224.5\r\n", 1))


def test_an_inserted_command_is_caught(gated_stars):
    p, text = gated_stars
    lines = text.splitlines(keepends=True)
    k = next(i for i in range(len(lines) // 2, len(lines)) if lines[i].startswith("S1 "))
    assert "commands" in _mutated_checks(p, "".join(lines[:k] + ["M104 S0\r\n"] + lines[k:]))


def test_a_dropped_switch_on_in_a_real_output_is_caught(gated_stars):
    p, text = gated_stars
    lines = text.splitlines(keepends=True)
    k = next(i for i in range(len(lines) // 2, len(lines)) if lines[i].startswith("S1 "))
    assert "timing" in _mutated_checks(p, "".join(lines[:k] + lines[k + 1:]))


def test_a_bent_split_move_is_caught(gated_stars):
    # the first piece of a split move ends 0.05 mm off the move: the pieces are no longer one
    # straight move, so they are not joined back, and neither matches the original
    p, text = gated_stars
    lines = text.splitlines(keepends=True)
    k = next(i for i in range(len(lines) // 2, len(lines)) if lines[i].startswith("S0 ")
             and lines[i - 1].startswith("G1 X") and lines[i + 1].startswith("G1 X"))
    q = gatesopt.parse("".join(lines[:k]))
    x, y = q.end_mm[-1, :2]
    words = lines[k - 1].split()
    lines[k - 1] = " ".join([words[0], f"X{x + 0.05:.3f}", f"Y{y + 0.05:.3f}"] + words[3:]) + "\r\n"
    assert "geometry" in _mutated_checks(p, "".join(lines))


def test_two_collinear_moves_rewritten_as_one_split_elsewhere_are_caught():
    # original: two collinear moves meeting at X10; output: one move split at X7. The run of
    # pieces (0 -> 20) is no move of the original, so nothing is joined and both sides differ
    p = gatesopt.parse("G90\nM83\nG1 X0 Y0\nG1 X10 Y0 E1\nG1 X20 Y0 E1\nG1 X20 Y10 E1\n")
    ok = gatesopt.parse("G90\nM83\nG1 X0 Y0\nG1 X5 Y0 E0.5\nS0 Y\nG1 X10 Y0 E0.5\nG1 X20 Y0 E1\nS1 Y\n"
                        "G1 X20 Y10 E1\n")
    assert "geometry" not in _checks(verify(p, ok, start_ahead_s=0, end_late_s=0))
    bad = gatesopt.parse("G90\nM83\nG1 X0 Y0\nG1 X7 Y0 E0.7\nS0 Y\nG1 X20 Y0 E1.3\nS1 Y\nG1 X20 Y10 E1\n")
    assert "geometry" in _checks(verify(p, bad, start_ahead_s=0, end_late_s=0))


def test_a_reordered_output_reports_each_fault_once():
    # verify() runs the extrusion and commands checks on every output; the re-ordering's own
    # checks (gatesopt.verify.ordering) ran them a second time: one fault, two findings
    p = gatesopt.parse(SQUARE)
    q = gatesopt.parse(SQUARE.replace("M104 S200\n", "").replace("G1 X20 Y0 E5.0", "G1 X20 Y0 E5.5"))
    rep = verify(p, q, reordered=True)
    assert "ordering" in rep.checks
    texts = [str(f) for f in rep.findings]
    assert len(texts) == len(set(texts)), texts
    assert sum("control command missing: M104 S200" in t for t in texts) == 1
    assert sum(f.check == "extrusion" for f in rep.findings) == 1


def test_whole_print_extrusion_is_not_called_layer_minus_one():
    # the layer finders disagree (a marker only in the output): net E is compared over the whole
    # print, and the finding says so instead of naming "layer -1"
    p = gatesopt.parse(SQUARE)
    q = gatesopt.parse(SQUARE.replace("G1 Z0.4 F600\n", "G1 Z0.4 F600\n;LAYER:1\n")
                       .replace("G1 X20 Y0 E5.0", "G1 X20 Y0 E5.5"))
    assert p.n_layers != q.n_layers
    found = [f for f in verify(p, q, reordered=True).findings if f.check == "extrusion"]
    assert len(found) == 1
    assert "layer -1" not in found[0].message and "whole print" in found[0].message
    assert "net E 5.50000 mm, original 5.00000 mm" in found[0].message


@pytest.mark.parametrize("dim", [3, 6])
def test_near_equals_brute_force_and_its_index_lives_with_the_array(dim):
    # ``geometry._near``: exact copies by hashing, the rest by a k-d tree (unbalanced), both made
    # once per points array and kept for as long as that array lives
    import gc
    from gatesopt.verify import geometry
    rng = np.random.default_rng(dim)
    tol = 1.1e-3
    pts = np.round(rng.uniform(0, 5, (400, dim)), 3)
    pts[::7, 0] = -0.0                                   # -0.0 equals 0.0
    q = np.concatenate([pts[::3] * 1.0,                  # exact copies
                        pts[1::3] + rng.uniform(-0.9, 0.9, (len(pts[1::3]), dim)) * tol,   # within
                        pts[2::3] + rng.choice([-1, 1], (len(pts[2::3]), dim)) * 1.2 * tol,  # beyond
                        rng.uniform(0, 5, (50, dim))])
    q[0, 0] = 0.0
    brute = (np.abs(q[:, None, :] - pts[None, :, :]).max(axis=2) < tol).any(axis=1)
    assert geometry._near(pts, q, tol).tolist() == brute.tolist()
    assert brute.sum() >= len(pts[::3]) + len(pts[1::3])   # the cases are what they say
    assert geometry._near(pts, q, tol).tolist() == brute.tolist()       # from the kept index
    assert id(pts) in geometry._INDEXES
    key = id(pts)
    del pts
    gc.collect()
    assert key not in geometry._INDEXES
