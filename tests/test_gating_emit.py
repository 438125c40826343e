"""Emission of gated G-code (gatesopt.gating.emit) and the firmware models (gatesopt.firmware)."""
from __future__ import annotations

import math
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

import gatesopt
from gatesopt import firmware
from gatesopt.gating.emit import EmitError, Switch, render, render_switches
from gatesopt.program import Kind
from gatesopt.verify import verify

SHARED = Path(__file__).resolve().parents[2] / "shared" / "instances"

ABS_E = """G21
G90
M82
G92 E0
G1 F1200
G1 X10 Y0 E1.0 ; first side
G1 X10 Y10 E2.0
M106 S255
G1 X0 Y10 E3.0 F600
G1 X0 Y0 E4.0
M107
"""


def _starts(p):
    return np.cumsum(p.duration_s) - p.duration_s


def _cut(p, row, f, motor=1, on=False):
    """A switch at fraction f of step ``row``."""
    return Switch(float(_starts(p)[row] + f * p.duration_s[row]), motor, on)


def _collinear(prog, rows):
    """Max distance of the pieces' joints from the line through the first start and last end."""
    a = prog.start_mm[rows[0], :3]
    b = prog.end_mm[rows[-1], :3]
    d = (b - a) / np.linalg.norm(b - a)
    worst = 0.0
    for r in rows[:-1]:
        v = prog.end_mm[r, :3] - a
        worst = max(worst, np.linalg.norm(v - np.dot(v, d) * d))
    return worst


def _motion(p):
    return np.flatnonzero(np.isin(p.kind, gatesopt.program.MOTION_KINDS))


# ------------------------------------------------------------------------------------------------
def test_no_gating_no_rotation_is_byte_identical():
    p = gatesopt.parse(ABS_E)
    assert render_switches(p, []).text == ABS_E
    crlf = ABS_E.replace("\n", "\r\n")
    p2 = gatesopt.parse(crlf)
    assert render_switches(p2, []).text == crlf


@pytest.mark.skipif(not (SHARED / "real_slic3r131_stars.gcode").exists(), reason="../shared/instances absent")
def test_real_file_round_trip_byte_identical():
    path = SHARED / "real_slic3r131_stars.gcode"
    p = gatesopt.parse(path)
    assert render(p, []).text.encode("utf-8", "surrogateescape") == path.read_bytes()


def test_split_absolute_e_is_collinear_and_proportional():
    p = gatesopt.parse(ABS_E)
    r = render_switches(p, [_cut(p, 0, 0.3)])
    q = gatesopt.parse(r.text)
    lines = r.text.splitlines()
    assert lines[5] == "G1 X3 Y0 E0.3 ; first side"        # comment and words kept on piece 1
    assert lines[6] == "S0 Y"
    assert lines[7] == "G1 X10 Y0 E1.0"                     # piece 2: original end text
    m = _motion(q)
    assert q.end_mm[m[0], 3] == pytest.approx(0.3)
    assert _collinear(q, m[:2]) < 1e-9
    assert r.splits == 1 and r.instruction_lines == 1 and r.lines_added == 2


def test_split_relative_e_sums_exactly_in_decimal():
    text = "G21\nG90\nM83\nG1 F1800\nG1 X10.123 Y3.3 E0.12345 ; wall\nG1 X20 Y3.3 E.33333\n"
    p = gatesopt.parse(text)
    r = render_switches(p, [_cut(p, 0, 1 / 3), _cut(p, 0, 0.77, on=True), _cut(p, 1, 0.5, motor=0)])
    lines = [l for l in r.text.splitlines() if l.startswith("G1 X")]
    e = [Decimal(l.split("E")[1].split()[0]) for l in lines]
    assert sum(e[:3]) == Decimal("0.12345")                 # three pieces of the first move
    assert sum(e[3:]) == Decimal(".33333")
    q = gatesopt.parse(r.text)
    m = _motion(q)
    assert _collinear(q, m[:3]) < 1e-5
    dE = q.end_mm[m[:3], 3] - q.start_mm[m[:3], 3]
    L = q.length_mm[m[:3]]
    np.testing.assert_allclose(dE / L, 0.12345 / L.sum(), rtol=1e-4)


def test_split_g91_relative_xyz():
    text = "G21\nM83\nG1 F600\nG1 X5 Y5 E0.1\nG91\nG1 X10 Y-2 Z0.2 E0.5\nG90\nG1 X0 Y0\n"
    p = gatesopt.parse(text)
    r = render_switches(p, [_cut(p, 1, 0.25)])
    q = gatesopt.parse(r.text)
    np.testing.assert_allclose(q.end_mm[-1], p.end_mm[-1])
    g91 = [l for l in r.text.splitlines() if l.startswith("G1 X") and "Z" in l]
    xs = [Decimal(l.split("X")[1].split()[0]) for l in g91]
    assert len(g91) == 2 and sum(xs) == Decimal(10)
    m = _motion(q)
    assert _collinear(q, m[1:3]) < 1e-5


def test_split_inches_and_g92_offset():
    text = "G20\nG90\nM82\nG92 X1 Y1 E0\nG1 F30\nG1 X2 Y1 E0.1\n"
    p = gatesopt.parse(text)
    r = render_switches(p, [_cut(p, 0, 0.5)])
    q = gatesopt.parse(r.text)
    m = _motion(q)
    # half way in machine mm: the original start plus half the move (1 inch = 25.4 mm)
    np.testing.assert_allclose(q.end_mm[m[0], :2], p.start_mm[0, :2] + [12.7, 0.0], atol=1e-4)
    assert "G1 X1.5 Y1 E0.05" in r.text
    np.testing.assert_allclose(q.end_mm[m[-1]], p.end_mm[0])


def test_split_arc_stays_on_the_circle():
    text = "G21\nG90\nM83\nG1 F600\nG1 X10 Y0\nG3 X0 Y10 I-10 J0 E1.5\n"
    p = gatesopt.parse(text)
    arc = int(np.flatnonzero(p.kind == Kind.ARC)[0])
    r = render_switches(p, [_cut(p, arc, 0.4, motor=0)])
    q = gatesopt.parse(r.text)
    arcs = np.flatnonzero(q.kind == Kind.ARC)
    assert len(arcs) == 2
    for a in arcs:
        for pt in (q.start_mm[a, :2], q.end_mm[a, :2]):
            assert math.hypot(*pt) == pytest.approx(10.0, abs=1e-4)
        np.testing.assert_allclose(q.arc_center_mm[a], [0, 0], atol=1e-4)
    assert q.length_mm[arcs].sum() == pytest.approx(p.length_mm[arc], rel=1e-5)
    e = q.end_mm[arcs, 3] - q.start_mm[arcs, 3]
    assert e.sum() == pytest.approx(1.5, abs=1e-9)
    assert e[0] / e.sum() == pytest.approx(0.4, abs=1e-5)


def test_switch_on_a_step_boundary_does_not_split():
    p = gatesopt.parse(ABS_E)
    t1 = float(np.cumsum(p.duration_s)[0])
    r = render_switches(p, [Switch(t1, 0, False), Switch(t1, 1, False)])
    assert r.splits == 0
    lines = r.text.splitlines()
    assert lines[6] == "S0 X Y"                  # one merged line, right before the next step
    assert lines[7] == "G1 X10 Y10 E2.0"


def test_rotation_header_and_coordinates():
    p = gatesopt.parse(ABS_E)
    r = render(p, [], rotation_deg=90, center_mm=(5, 5))
    assert r.text.splitlines()[0] == "; gatesopt: rotate_deg=90 center_x=5 center_y=5"
    q = gatesopt.parse(r.text)
    m = _motion(q)
    np.testing.assert_allclose(q.end_mm[m[0], :2], [10, 10], atol=1e-9)   # (10,0) -> (10,10)
    for line in ("M106 S255", "M107", "G92 E0"):
        assert line in r.text.splitlines()


def test_rotation_single_axis_moves_have_equal_text():
    # a square rotated by 30 degrees, then rotated back by -30: its sides are single-axis again
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    pts = [(0, 0), (10, 0), (10, 10), (0, 10), (0, 0)]
    rot = [(50 + c * x - s * y, 50 + s * x + c * y) for x, y in pts]
    text = "G21\nG90\nM82\nG1 F1200\n" + f"G1 X{rot[0][0]:.3f} Y{rot[0][1]:.3f}\n" + "".join(
        f"G1 X{x:.3f} Y{y:.3f} E{k + 1}\n" for k, (x, y) in enumerate(rot[1:]))
    p = gatesopt.parse(text)
    r = render(p, [], rotation_deg=-30, center_mm=(50, 50))
    q = gatesopt.parse(r.text)
    d = np.abs(q.end_mm[1:, :2] - q.start_mm[1:, :2])
    assert np.all(d.min(axis=1) == 0.0)          # every side is exactly single-axis in the text
    assert 0 < r.max_snap_mm <= 1e-3


def test_line_numbers_are_refused():
    text = "N1 G21*0\nN2 G1 X10 F600*0\nN3 G1 X20*0\n"
    p = gatesopt.parse(text)
    with pytest.raises(EmitError, match="line numbers"):
        render_switches(p, [_cut(p, 0, 0.5)])
    assert render_switches(p, []).text == text     # nothing to change: output is the input


# ------------------------------------------------------------------------------------------------
def test_firmware_texts():
    assert firmware.get("3dgates").off_lines("YX") == ["S0 X Y"]
    assert firmware.get("3dgates").on_lines(["X"]) == ["S1 X"]
    assert firmware.get("marlin").off_lines("XY") == ["M18 X Y"]
    assert firmware.get("marlin").on_lines("XY") == ["M17 X Y"]
    k = firmware.get("klipper")
    assert k.off_lines("XY") == ["SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0",
                                 "SET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=0"]
    # an explicit enable, start-ahead before the next move: Klipper's own re-enable at the move's
    # start comes after the first shaped steps (docs/RESULTS.md)
    assert k.on_lines("XY") == ["SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=1",
                                "SET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=1"]
    assert not any("M18" in l or "M84" in l for l in k.off_lines("XYZE"))
    with pytest.raises(firmware.FirmwareError, match="homed"):
        firmware.get("reprap").check_motors(["X"])
    firmware.get("reprap").check_motors(["E"])
    with pytest.raises(firmware.FirmwareError):
        firmware.get("grbl")


def test_parse_motor_line():
    assert firmware.parse_motor_line("S0 X Y ; off") == (False, ("X", "Y"))
    assert firmware.parse_motor_line("M84") == (False, ("X", "Y", "Z", "E"))
    assert firmware.parse_motor_line("M84 S600") is None        # idle timeout, not a disable
    assert firmware.parse_motor_line("SET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=0") == (False, ("Y",))
    assert firmware.parse_motor_line("G1 X1") is None


def test_gating_costs_and_stalls():
    c = firmware.gating_costs("klipper")
    assert c.stall_off_s == pytest.approx(0.22) and c.on_lines_per_gate == 1 and not c.off_lines_merged
    # ENABLE=1: a look-ahead flush (a stop) and 2 x SDS_CHECK_TIME, no dwell (17-19 ms measured)
    assert 0.017 <= c.stall_on_s <= 0.019
    assert firmware.gating_costs("3dgates").stall_off_s == 0.0
    text = ("G21\nG1 X10 F600\nSET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=0\nG1 X20\n"
            "M18 X\nM17 X\nG1 X30\nM84\n")
    p = gatesopt.parse(text)
    k = firmware.stall_durations(p, "klipper")
    motor = np.flatnonzero(p.kind == Kind.MOTOR)
    assert len(motor) == 4
    # the closing M84 comes after the last move: no stall (the print is over); Klipper has no M17
    # (an unknown command, skipped: no dwell), Marlin no SET_STEPPER_ENABLE
    np.testing.assert_allclose(k[motor], [0.22, 0.22, 0.0, 0.0])
    m = firmware.stall_durations(p, "marlin")
    np.testing.assert_allclose(m[motor], [0.0, firmware.get("marlin").stall_off_s, 0.0, 0.0])
    assert firmware.stall_durations(p, "3dgates").sum() == 0.0
    # a disable that is a full stop takes the caller's price where it has a planner: Marlin's per
    # move (``disable_is_stop``), RepRapFirmware's per line (``stall_is_stop``)
    assert firmware.stall_durations(p, "marlin", enable_price=lambda prog, rows: [0.5] * len(rows))[motor[1]] == 0.5
    assert firmware.stall_durations(p, "reprap", planner=lambda prog, r: 0.5)[motor[1]] == 0.5


def test_unsplittable_step_moves_switch_to_safe_side():
    text = "G21\nG1 X10 F600\nG4 P1000\nG1 X20\n"
    p = gatesopt.parse(text)
    dwell = int(np.flatnonzero(p.kind == Kind.DWELL)[0])
    r = render_switches(p, [_cut(p, dwell, 0.5, motor=0, on=False)])
    assert r.moved == 1
    assert r.text.splitlines()[3] == "S0 X"        # after the dwell
    r2 = render_switches(p, [_cut(p, dwell, 0.5, motor=0, on=True)])
    assert r2.text.splitlines()[2] == "S1 X"       # before it


# ------------------------------------------------------------------------------------------------
def _e2e(path, formulation, fw="3dgates", rotate="none"):
    from gatesopt.gating import GatingOptions
    from gatesopt.rewrite import run
    from gatesopt.gating.solve import is_installed
    try:
        import importlib
        importlib.import_module(f"gatesopt.gating.{formulation}")
    except ModuleNotFoundError:
        pytest.skip(f"formulation {formulation} not written yet")
    if not is_installed(formulation):
        pytest.skip(f"{formulation} backend missing")
    p = gatesopt.parse(path)
    res = run(p, GatingOptions.for_firmware(fw, rotate=rotate), formulation=formulation, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]
    assert res.report.energy_j == pytest.approx(res.solution.energy_j, rel=1e-6)
    # independent re-check straight from the text
    rep = verify(p, gatesopt.parse(res.text), firmware=fw, claimed=res.solution.energy_j and
                 (res.solution.energy_j, res.solution.time_after_s))
    assert rep.ok
    return res


E2E_FILES = ["real_slic3r131_stars.gcode", "real_prusa274_screw_arcs.gcode.gz",
             "slic3r13_torus_3dhoney20_acp.gcode"]


def test_the_library_refuses_x_y_gating_on_a_corexy_file():
    # real_prusa240 names a Voron (corexy): GatingOptions built by hand gating X, Y is refused
    # up front (its X/Y motors each step for every X or Y move); the extruder is gated
    from gatesopt.firmware import FirmwareError
    from gatesopt.gating import GatingOptions
    from gatesopt.rewrite import run
    path = SHARED / "real_prusa240_m486_arcwelder.gcode"
    if not path.exists():
        pytest.skip(f"{path} absent (../shared/instances not beside the repo)")
    p = gatesopt.parse(path)
    with pytest.raises(FirmwareError, match=r"corexy kinematics .*X,Y cannot be gated"):
        run(p, GatingOptions.for_firmware("3dgates"), order=False)
    res = run(p, GatingOptions.for_firmware("3dgates", motors=("E",)), order=False)
    assert res.report.ok and "S0 E" in res.text


@pytest.mark.parametrize("name", E2E_FILES)
@pytest.mark.parametrize("formulation", ["dp", "greedy"])
def test_end_to_end_real_files(name, formulation):
    path = SHARED / name
    if not path.exists():
        pytest.skip(f"{path} absent (../shared/instances not beside the repo)")
    res = _e2e(path, formulation)
    assert res.solution.saving_pct > 0


@pytest.mark.parametrize("fw,rotate", [("klipper", "none"), ("marlin", "none"), ("3dgates", "45")])
def test_end_to_end_firmware_and_rotation(fw, rotate):
    path = SHARED / "real_slic3r131_stars.gcode"
    if not path.exists():
        pytest.skip("../shared/instances absent")
    res = _e2e(path, "dp", fw, rotate)
    if fw == "klipper":
        assert "M18" not in res.text.replace(gatesopt.parse(path).to_gcode(), "")
        assert "SET_STEPPER_ENABLE" in res.text
    if rotate != "none":
        assert res.text.startswith("; gatesopt: rotate_deg=45 ")


def test_klipper_lines_at_one_moment_share_one_split():
    p = gatesopt.parse(ABS_E)
    t = float(_starts(p)[2] + 0.5 * p.duration_s[2])
    r = render_switches(p, [Switch(t, 0, False), Switch(t, 1, False)], firmware="klipper")
    lines = r.text.splitlines()
    i = lines.index("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0")
    assert lines[i + 1] == "SET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=0"
    assert r.splits == 1 and r.lines_added == 3          # two instruction lines + one extra piece


# ------------------------------------------------------------------------------------------------
# The compiled writer of split moves (gating/_emit_kernel.py) against the reference
# (_Emitter.rewrite): byte for byte, on every spelling the kernel accepts and on those it leaves.
KERNEL_CASES = {
    "absolute E": ABS_E,
    "relative E, comments, F": "G21\nG90\nM83\nG1 X10 Y0 E1.00000 F1200 ; a\nG1 X10 Y10 E.5\n"
                                "G1 X0 Y10 E+0.33333\nG1 X0 Y0 E1.\n",
    "G91, inches, G92": "G20\nG91\nM83\nG92 X1 Y2\nG1 X0.5 Y0 E0.02\nG1 X0 Y0.5 E0.02\nG90\n"
                        "G1 X1.25 Y2.75 Z0.1 E0.3\n",
    "CRLF, trailing blanks": "G90\r\nM82\r\nG1 X10 Y0 E1.0  \r\nG1 X10 Y10 E2.0\t; c\r\nG1 X0 Y10 E3.0",
    "left to the reference": "G90\nM83\ng1 x10 y0 e1\nG1  X10 Y10 E1\nG1X0Y10E1\nG01 X0 Y0 E1 X0\n"
                             "G1 X5 Y5 E1*12\nG2 X10 Y5 I2.5 J0 E1\n",
}


def _kernel_and_reference(p, switches, fw="3dgates"):
    from gatesopt.gating.emit import PlacedArrays, place_switches
    from gatesopt.gating.emit_plain import render_plain
    arrays = PlacedArrays.from_placed(place_switches(p, switches))
    fwm = firmware.get(fw)
    return (render_plain(p, fwm, arrays, 0.0, (0, 0)),
            render_plain(p, fwm, arrays, 0.0, (0, 0), split_in_kernel=False))


@pytest.mark.parametrize("case", sorted(KERNEL_CASES))
@pytest.mark.parametrize("fw", ["3dgates", "klipper"])
def test_kernel_splits_equal_the_reference(case, fw):
    p = gatesopt.parse(KERNEL_CASES[case])
    rng = np.random.default_rng(7)
    motion = _motion(p)
    for _ in range(20):
        sw = [_cut(p, int(r), float(rng.uniform(0.001, 0.999)), motor=int(rng.integers(0, 2)),
                   on=bool(rng.integers(0, 2))) for r in rng.choice(motion, size=6)]
        fast, ref = _kernel_and_reference(p, sw, fw)
        assert fast == ref
        assert fast.splits > 0


def test_kernel_leaves_a_rounding_tie_to_the_reference():
    # the split point X = 12.015625 is exactly halfway between two 5-decimal texts: Python's
    # format rounds it half to even, which a product in floating point cannot decide
    p = gatesopt.parse("G90\nM82\nG1 X0 Y5 E0\nG1 X24.03125 Y5 E1\n")
    fast, ref = _kernel_and_reference(p, [_cut(p, 1, 0.5, motor=1)])
    assert fast == ref
    assert "G1 X12.01562 Y5 E0.5\n" in fast.text


@pytest.mark.parametrize("name", ["real_prusa240_m486_arcwelder.gcode", "real_slic3r131_stars.gcode"])
def test_kernel_equals_the_reference_on_real_files(name):
    from gatesopt.gating.emit import solution_arrays
    from gatesopt.gating.emit_plain import render_plain
    from gatesopt.gating import GatingOptions, build
    from gatesopt.gating.solve import solve
    path = SHARED / name
    if not path.exists():
        pytest.skip("../shared/instances absent")
    p = gatesopt.parse(path)
    for fw in ("3dgates", "marlin"):
        sol = solve(build(p, GatingOptions.for_firmware(fw, motors=("X", "Y", "Z", "E"), rotate="none")), "dp")
        arrays, fwm = solution_arrays(sol), firmware.get(fw)
        fast = render_plain(p, fwm, arrays, 0.0, (0, 0))
        assert fast.splits > 100
        assert fast == render_plain(p, fwm, arrays, 0.0, (0, 0), split_in_kernel=False)


def test_the_stream_refuses_x_y_gating_on_a_corexy_file(tmp_path):
    # gate_stream reads the printer model from the file's head and tail (PrusaSlicer writes it at
    # the end), with the file's own line number
    from gatesopt.firmware import FirmwareError
    from gatesopt.stream import gate_stream
    path = SHARED / "real_prusa240_m486_arcwelder.gcode"
    if not path.exists():
        pytest.skip(f"{path} absent (../shared/instances not beside the repo)")
    line = next(i for i, ln in enumerate(path.read_bytes().splitlines(), 1)
                if ln.startswith(b"; printer_model ="))
    with pytest.raises(FirmwareError, match=rf"corexy kinematics .*\(line {line}\)"):
        gate_stream(path, tmp_path / "out.gcode")
    assert not (tmp_path / "out.gcode").exists()
