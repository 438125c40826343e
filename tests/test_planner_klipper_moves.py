"""Planner timing of Z moves, extrude-only moves and retractions on Klipper (issue 34).

Every expected number is computed by hand from Klipper's rules (Klipper 84104bb):

* klippy/kinematics/cartesian.py ``CartKinematics.check_move``: a move with Z is limited to
  ``max_z_velocity * z_ratio`` and ``max_z_accel * z_ratio``, ``z_ratio = move_d / |dz|``;
* klippy/kinematics/extruder.py ``PrinterExtruder.check_move``: a move without X and Y (extrude
  only, or Z with E) and a retraction (E < 0) are limited to ``max_extrude_only_velocity /
  |axis_r|`` and ``max_extrude_only_accel / |axis_r|``, ``axis_r = dE / move_d``; their defaults
  are max_velocity and max_accel times ``4 nozzle^2 / (pi (filament / 2)^2)``;
* klippy/toolhead.py ``Move.__init__``: an extrude-only move keeps its requested speed (no
  max_velocity) and starts from an acceleration of 99999999.9 (so only the extruder's applies);
  ``Move.calc_junction``: the junction deviation is the toolhead's, ``scv^2 (sqrt 2 - 1) /
  max_accel``, times each move's own acceleration; ``Move.mcr_delta_v2``: the smoothed look-ahead
  accelerates at ``max_accel (1 - minimum_cruise_ratio)`` but never faster than the move itself.

The same numbers came out of klippy itself (a copy of Klipper's toolhead.py that logged each
move's accel_t + cruise_t + decel_t, on a printer.cfg with these limits).
"""
from __future__ import annotations

import math

import numpy as np

import pytest

from gatesopt import planner
from gatesopt.parse import parse
from gatesopt.printer_config import read_printer_config

RATIO = 4 * 0.4 ** 2 / (math.pi * (1.75 / 2) ** 2)     # Klipper's def_max_extrude_ratio, 0.26606
E_ACCEL = 3000 * RATIO                                  # 798.243 mm/s^2
E_VELOCITY = 300 * RATIO                                # 79.824 mm/s

GCODE = """G28
G90
M83
G1 X10 Y10 Z1 F3000
SET_VELOCITY_LIMIT VELOCITY=300 ACCEL=3000 SQUARE_CORNER_VELOCITY=5 MINIMUM_CRUISE_RATIO=0.5
G4 P100
G1 X13 Z5 F6000
G4 P100
G1 E-0.8 F2100
G4 P100
G1 E50 F6000
G4 P100
SET_VELOCITY_LIMIT VELOCITY=50
G1 E10 F4200
G4 P100
SET_VELOCITY_LIMIT VELOCITY=300
G1 X23 E-5 F3000
G4 P100
G1 X33 E5 F3000
G4 P100
G1 Z5.2 F720
G1 X43 F3000
"""


def rest_to_rest_s(length_mm, v_mm_s, a_mm_s2):
    """A move from rest to rest: a trapezoid, or a triangle with peak sqrt(a L)."""
    if v_mm_s * v_mm_s / a_mm_s2 >= length_mm:
        return 2 * math.sqrt(a_mm_s2 * length_mm) / a_mm_s2
    return 2 * v_mm_s / a_mm_s2 + (length_mm - v_mm_s * v_mm_s / a_mm_s2) / v_mm_s


@pytest.fixture(scope="module")
def moves():
    prog = parse(GCODE, source="klipper_moves.gcode")
    pl = planner.plan(prog)
    assert pl.firmware == "klipper"
    lines = prog.line[pl.move_step] + 1
    return {int(ln): int(s) for ln, s in zip(lines, pl.move_step)}, pl


def test_z_move_scaled_by_z_ratio(moves):
    # G1 X13 Z5 from (10, 10, 1): move_d 5, dz 4, z_ratio 1.25: v = 15 * 1.25 = 18.75 mm/s (the
    # stock max_z_velocity 15), a = 100 * 1.25 = 125 mm/s^2; rest to rest: 2 v / a + (5 - v^2 / a) / v
    idx, pl = moves
    k = idx[7]
    assert pl.nominal_mm_s[k] == pytest.approx(18.75) and pl.accel_mm_s2[k] == pytest.approx(125.0)
    assert pl.duration_s[k] == pytest.approx(0.3 + (5 - 2.8125) / 18.75, rel=1e-12)    # 0.416667 s
    assert pl.duration_s[k] == pytest.approx(0.416666667, abs=1e-9)


def test_extrude_only_moves_use_the_extruder_limits(moves):
    idx, pl = moves
    # a retraction of 0.8 mm at 35 mm/s: a = max_extrude_only_accel 798.24 (not ACCEL 3000), a
    # triangle with peak sqrt(798.24 * 0.8) = 25.27 mm/s: 0.063315 s (0.034 s at 3000 mm/s^2)
    k = idx[9]
    assert pl.accel_mm_s2[k] == pytest.approx(E_ACCEL)
    assert pl.duration_s[k] == pytest.approx(2 * math.sqrt(E_ACCEL * 0.8) / E_ACCEL, rel=1e-12)
    assert pl.duration_s[k] == pytest.approx(0.063315110, abs=1e-9)
    # 50 mm at 100 mm/s: capped at max_extrude_only_velocity 79.82 mm/s
    k = idx[11]
    assert pl.nominal_mm_s[k] == pytest.approx(E_VELOCITY)
    assert pl.duration_s[k] == pytest.approx(rest_to_rest_s(50, E_VELOCITY, E_ACCEL), rel=1e-12)
    assert pl.duration_s[k] == pytest.approx(0.726375488, abs=1e-9)
    # under SET_VELOCITY_LIMIT VELOCITY=50 an extrude-only move still runs at its 70 mm/s
    k = idx[14]
    assert pl.nominal_mm_s[k] == pytest.approx(70.0)
    assert pl.duration_s[k] == pytest.approx(rest_to_rest_s(10, 70, E_ACCEL), rel=1e-12)
    assert pl.duration_s[k] == pytest.approx(0.230549711, abs=1e-9)


def test_retraction_with_xy_is_capped_but_extrusion_is_not(moves):
    idx, pl = moves
    # G1 X23 E-5: axis_r = -0.5, a = min(3000, 798.24 / 0.5) = 1596.49 mm/s^2, v = 50 mm/s
    k = idx[17]
    assert pl.accel_mm_s2[k] == pytest.approx(2 * E_ACCEL)
    assert pl.duration_s[k] == pytest.approx(rest_to_rest_s(10, 50, 2 * E_ACCEL), rel=1e-12)
    assert pl.duration_s[k] == pytest.approx(0.231318774, abs=1e-9)
    # G1 X33 E5: the same ratio extruding: no extruder cap, a = 3000
    k = idx[19]
    assert pl.accel_mm_s2[k] == pytest.approx(3000.0)
    assert pl.duration_s[k] == pytest.approx(rest_to_rest_s(10, 50, 3000), rel=1e-12)


def test_junction_from_z_to_xy_uses_the_toolhead_deviation(moves):
    # G1 Z5.2 then G1 X43, a 90 degree corner: R_jd = sin 45 / (1 - sin 45) = 2.41421, JD =
    # 25 (sqrt 2 - 1) / 3000 (the toolhead's max_accel), v^2 = R_jd JD min(100, 3000) = 0.8333
    idx, pl = moves
    kz, kx = idx[21], idx[22]
    r_jd = math.sin(math.pi / 4) / (1 - math.sin(math.pi / 4))
    v = math.sqrt(r_jd * 25 * (math.sqrt(2) - 1) / 3000 * 100)
    assert v == pytest.approx(0.912871, abs=1e-6)
    assert pl.exit_mm_s[kz] == pytest.approx(v) and pl.entry_mm_s[kx] == pytest.approx(v)
    # the Z move is not smoothed below its own 100 mm/s^2 (mcr_delta_v2 <= delta_v2): from rest,
    # v_peak^2 = (0 + (v^2 + 2 L a)) / 2, then down to v
    peak = math.sqrt((v * v + 2 * 0.2 * 100) / 2)
    assert pl.cruise_mm_s[kz] == pytest.approx(peak)
    assert pl.duration_s[kz] == pytest.approx(peak / 100 + (peak - v) / 100, rel=1e-12)
    assert pl.duration_s[kz] == pytest.approx(0.081240902, abs=1e-9)


def test_printer_config_extruder_limits(tmp_path):
    cfg = tmp_path / "printer.cfg"
    base = ("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n\n"
            "[extruder]\nnozzle_diameter: 0.4\nfilament_diameter: 1.75\n")
    cfg.write_text(base)
    pc = read_printer_config(cfg)
    assert pc.max_extrude_only_velocity_mm_s == pytest.approx(E_VELOCITY)
    assert pc.max_extrude_only_accel_mm_s2 == pytest.approx(E_ACCEL)
    lv = pc.limit_values()
    assert lv["max_feed_e"] == pytest.approx(E_VELOCITY) and lv["max_accel_e"] == pytest.approx(E_ACCEL)
    cfg.write_text(base + "max_extrude_only_velocity: 120\nmax_extrude_only_accel: 1500\n")
    pc = read_printer_config(cfg)
    assert (pc.max_extrude_only_velocity_mm_s, pc.max_extrude_only_accel_mm_s2) == (120.0, 1500.0)
    # a 1 mm retraction at 40 mm/s on that printer: a = 1500, peak sqrt(1500) = 38.7 < 40
    from gatesopt.limits import machine_limits
    prog = parse("G90\nM83\nG1 E-1 F2400\n", source="r.gcode")
    pl = planner.plan(prog, machine_limits(prog, printer=pc))
    k = pl.move_step[0]
    assert pl.duration_s[k] == pytest.approx(2 * math.sqrt(1500.0) / 1500.0, rel=1e-12)


def test_klipper_rules_on_a_profile_without_square_corner_velocity():
    # a Cura file (fdmprinter defaults: no square corner velocity) planned by Klipper's rules gets
    # Klipper's default 5 mm/s: a 90 degree corner at exactly 5 mm/s, not an undefined junction
    from gatesopt.limits import machine_limits
    prog = parse(";FLAVOR:Marlin\nG90\nG1 X50 F3000\nG1 X50 Y50 F3000\n", source="c.gcode")
    lim = machine_limits(prog, family="klipper")
    assert lim.profile == "cura_fdmprinter" and lim.square_corner_velocity_mm_s == 5.0
    pl = planner.plan(prog, lim)
    ms = pl.move_step
    assert pl.exit_mm_s[ms[0]] == pytest.approx(5.0) and np.isfinite(pl._vj_free).all()


def test_klipper_m204_needs_s_or_both_p_and_t():
    # klippy/toolhead.py cmd_M204: S, else min(P, T) when both are given; "M204 P800" alone is
    # refused ('Invalid M204 command') and the acceleration stays (PrusaSlicer writes it per feature)
    from gatesopt.limits import machine_limits
    prog = parse("SET_VELOCITY_LIMIT ACCEL=3000\nM204 P1250 R1250 T1400\nG90\nG1 X10 F3000\nM204 P800\n"
                 "G1 X20 F3000\nM204 S900\nG1 X30 F3000\n", source="m204.gcode")
    pl = planner.plan(prog, machine_limits(prog))
    assert pl.firmware == "klipper"
    assert [float(pl.accel_mm_s2[k]) for k in pl.move_step] == [1250.0, 1250.0, 900.0]


# Orca's spiral lift: G3 with Z only, target = start. Klipper (gcode_arcs.py planArc) turns it
# a full circle only if its float angle is exactly 0: I-1.2166 J0 gives exactly 0 (r_Q = 0),
# I-.427 J1.139 at (100, 100) a hair off it: one segment straight up (a 0.4 mm Z move)
SPIRALS = ("SET_VELOCITY_LIMIT VELOCITY=300 ACCEL=3000 SQUARE_CORNER_VELOCITY=5\nG90\nM83\n"
           "G1 X100 Y100 Z1 F6000\nG4 P100\nG3 Z1.4 I-.427 J1.139 F30000\nG4 P100\n"
           "G3 Z1.8 I-1.2166 J0 F30000\nG4 P100\n")


def test_a_spiral_lift_klipper_does_not_turn_is_a_z_move():
    from gatesopt.firmware.klipper import arc_turn, null_arcs
    from gatesopt.program import Kind
    prog = parse(SPIRALS, source="spirals.gcode")
    arcs = np.flatnonzero(prog.kind == Kind.ARC)
    assert len(arcs) == 2
    assert abs(arc_turn((100.0, 100.0), (100.0, 100.0), (-0.427, 1.139), False)) < 1e-12
    assert arc_turn((100.0, 100.0), (100.0, 100.0), (-1.2166, 0.0), False) == 2 * math.pi
    assert null_arcs(prog, arcs).tolist() == [True, False]
    pl = planner.plan(prog)
    # 0.4 mm at max_z_velocity 5 (the kinematics' default here is 15: capped by the Z ratio 1),
    # max_z_accel 100, from rest to rest
    z = pl.limits.max_feed_mm_s[2]
    assert pl.length_mm[arcs[0]] == pytest.approx(0.4)
    assert pl.duration_s[arcs[0]] == pytest.approx(rest_to_rest_s(0.4, z, pl.limits.max_accel_mm_s2[2]), rel=1e-12)
    # the full circle: 7 chords (floor of the 7.65 mm helix), as long as their sum
    R, n = 1.2166, 7
    chord = math.hypot(2 * R * math.sin(math.pi / n), 0.4 / n)
    assert pl.length_mm[arcs[1]] == pytest.approx(n * chord, rel=1e-12)


def test_an_arc_runs_at_its_chords_average_speed():
    # a 5 mm radius circle at 100 mm/s: 31 chords of 11.6 degrees; Klipper's junction between two
    # of them (toolhead.py calc_junction, scv 5, 3000 mm/s^2) is ~44.9 mm/s, and each chord
    # accelerates from it and back (its own trapezoid, LookAheadQueue.flush): peak
    # sqrt(va^2 + a c), the arc's cruise the chord's length over its time
    prog = parse("SET_VELOCITY_LIMIT VELOCITY=300 ACCEL=3000 SQUARE_CORNER_VELOCITY=5\nG90\n"
                 "G1 X100 Y100 F6000\nG4 P100\nG2 X100 Y100 I5 J0 F6000\nG4 P100\n", source="circle.gcode")
    pl = planner.plan(prog)
    k = pl.move_step[1]
    n, R, a = 31, 5.0, 3000.0
    theta = 2 * math.pi / n
    c = 2 * R * math.sin(theta / 2)
    jd = 25 * (math.sqrt(2) - 1) / a
    cos_t = -math.cos(theta)
    sin_d2, cos_d2 = math.sqrt(0.5 * (1 - cos_t)), math.sqrt(0.5 * (1 + cos_t))
    va = math.sqrt(min(sin_d2 / (1 - sin_d2) * jd * a, 0.5 * c * sin_d2 / cos_d2 * a))
    vp = math.sqrt(va * va + a * c)
    assert vp < 100
    v_eff = c / (2 * (vp - va) / a)
    assert pl.nominal_mm_s[k] == pytest.approx(v_eff, rel=1e-9)
    assert pl.duration_s[k] == pytest.approx(rest_to_rest_s(n * c, v_eff, a), rel=1e-9)


def test_a_junction_across_an_acceleration_change_keeps_each_moves_own_deviation():
    # toolhead.py Move.__init__ keeps the toolhead's junction_deviation (scv^2 (sqrt 2 - 1) /
    # max_accel) as it was when the move was made; calc_junction multiplies each side's by its
    # own acceleration: at 90 degrees both give scv^2 (sqrt 2 - 1) R_jd = scv^2, whatever the accels
    prog = parse("SET_VELOCITY_LIMIT VELOCITY=300 ACCEL=2000 SQUARE_CORNER_VELOCITY=5\nG90\n"
                 "G1 X100 F12000\nSET_VELOCITY_LIMIT ACCEL=10000\nG1 X100 Y100 F12000\n", source="acc.gcode")
    pl = planner.plan(prog)
    a, b = pl.move_step
    assert pl.accel_mm_s2[a] == 2000 and pl.accel_mm_s2[b] == 10000
    assert pl.exit_mm_s[a] == pytest.approx(5.0, rel=1e-9)


CUT_GCODE = """G28
G90
M83
SET_VELOCITY_LIMIT VELOCITY=300 ACCEL=4000 SQUARE_CORNER_VELOCITY=5
G1 X10 Y10 F6000
G1 E1 F1800
G1 X10.00013 Y10 E0.000004 F1359
G1 X30 Y10 E0.6
G1 X30 Y30 F6000
"""


def test_a_move_cut_in_line_keeps_its_speed_through_the_cut_on_klipper():
    # toolhead.py Move.calc_junction: for moves straight in line junction_cos_theta is -1,
    # cos_theta_d2 is 0 and the junction-deviation / centripetal rule is skipped, so the cut
    # costs nothing however short the first piece (0.00013 mm here, as a gating line placed
    # 5.7 us into a move cuts it). A clamp at -0.999999 (Marlin's) capped the junction at
    # sqrt(0.5 * 0.00013 * 4000 * tan) = 19.2 mm/s; the same move uncut is the reference.
    cut = planner.plan(parse(CUT_GCODE, source="cut.gcode"))
    whole = planner.plan(parse(CUT_GCODE.replace("G1 X10.00013 Y10 E0.000004 F1359\n", "")
                               .replace("G1 X30 Y10 E0.6", "G1 X30 Y10 E0.600004 F1359"),
                               source="whole.gcode"))
    assert cut.firmware == "klipper"
    k = int(np.flatnonzero(cut.move_step == cut.move_step[-2])[0])     # the long piece
    assert cut._vj_free[k] == pytest.approx(1359 / 60, rel=1e-12)
    assert cut.duration_s.sum() == pytest.approx(whole.duration_s.sum(), abs=1e-9)
    # the stop a gating line at the cut costs is the one inside the uncut move
    row = int(cut.move_step[k])
    inside = int(whole.move_step[-2])
    assert planner.stop_restart_s(cut, [row])[0] == pytest.approx(
        planner.stop_restart_s(whole, [inside], True)[0], rel=1e-12)
