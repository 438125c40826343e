"""The parser: lossless round trip, modal state, layers, and a clear error for each bad input."""
from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from gatesopt import GcodeError, Kind, parse
from gatesopt.program import E, X, Y

from conftest import manifest, read_bytes, shared_params


# ------------------------------------------------------------------------------------------------
# lossless, on every real slicer output we have

#: the corpus manifest counts layers by distinct extrusion Z; where its start G-code purges at a Z
#: of its own outside the print (IceSL: two lines at Y 1 and Z 0.3, the print at 50-70 mm from
#: Z 0.12), the parser puts that purge before the first layer (``parse._purge_layer``)
START_PURGE_LAYERS = {"real_icesl.gcode.gz": 1}

@pytest.mark.parametrize("path", shared_params())
def test_round_trip_and_layers_on_real_slicer_output(path):
    data = read_bytes(path)
    prog = parse(data, source=path.name)
    assert prog.to_bytes() == data
    assert prog.to_gcode().encode("utf-8", "surrogateescape") == data
    row = manifest()[path.name]
    if "spiral" in row["notes"] and "no layer markers" in row["notes"]:
        # a marker-less continuous spiral: one layer, never one per distinct Z (no invented layers)
        assert prog.n_layers == 1
    else:
        assert prog.n_layers == int(row["layers"]) - START_PURGE_LAYERS.get(path.name, 0)
    # every step is a row with a source line, and positions chain: end of one = start of next
    assert np.all(np.diff(prog.line) > 0)
    assert np.allclose(prog.end_mm[:-1], prog.start_mm[1:])
    assert np.all(prog.duration_s >= 0) and np.all(np.isfinite(prog.duration_s))


def test_parse_reads_gzip_path(tmp_path):
    text = "G90\nG1 X1 Y2 F600\n"
    p = tmp_path / "a.gcode.gz"
    p.write_bytes(gzip.compress(text.encode()))
    prog = parse(p)
    assert prog.to_gcode() == text and prog.n_steps == 1


def test_crlf_and_missing_final_newline_round_trip():
    text = "G90\r\nG1 X1 Y2 F600 ; move\r\nG1 X3"
    prog = parse(text)
    assert prog.to_gcode() == text
    assert prog.line_ending == "\r\n"
    assert prog.n_steps == 2 and prog.end_mm[-1, X] == 3


# ------------------------------------------------------------------------------------------------
# modal state, resolved once in the parser
def test_absolute_and_relative_positioning_g90_g91():
    p = parse("G1 X10 Y10 F600\nG91\nG1 X5 Y-2\nG90\nG1 X1 Y1\n")
    assert p.end_mm[:, :2].tolist() == [[10, 10], [15, 8], [1, 1]]
    assert p.relative_xyz.tolist() == [False, True, False]


def test_g91_makes_e_relative_like_marlin_and_g90_resets_it():
    # Marlin gcode.h: set_relative_mode() sets/clears the E bits too
    p = parse("M83\nG1 X1 E1 F600\nG90\nG1 X2 E5\nG91\nG1 X1 E1\n")
    assert p.end_mm[:, E].tolist() == [1, 5, 6]


def test_klipper_flavor_g90_keeps_m83():
    # Klipper gcode_move.py: G90 sets absolute_coord only; M83 stays in force
    p = parse("; gcode_flavor = klipper\nM83\nG1 X1 E1 F600\nG90\nG1 X2 E5\n")
    assert p.end_mm[:, E].tolist() == [1, 6]


def test_m82_m83_extrusion_modes():
    p = parse("M82\nG1 X1 E2 F600\nG1 X2 E3\nM83\nG1 X3 E0.5\nG1 X4 E0.5\n")
    assert p.end_mm[:, E].tolist() == [2, 3, 3.5, 4]
    assert p.relative_e.tolist() == [False, False, True, True]


def test_g92_e0_keeps_cumulative_e_and_records_offset():
    p = parse("M82\nG1 X1 E5 F600\nG92 E0\nG1 X2 E1\n")
    assert p.end_mm[:, E].tolist() == [5, 6]
    assert p.offset_mm[-1, E] == 5


def test_g92_on_xyz_shifts_coordinates():
    p = parse("G1 X10 Y10 F600\nG92 X0 Y0\nG1 X5 Y5\n")
    assert p.end_mm[-1, :2].tolist() == [15, 15]
    assert p.offset_mm[-1, :2].tolist() == [10, 10]


def test_g20_inches():
    p = parse("G20\nG1 X1 Y0 F10\nG21\nG1 X1 Y0\n")
    assert p.end_mm[0, X] == pytest.approx(25.4)
    assert p.feed_mm_s[0] == pytest.approx(25.4 * 10 / 60)
    assert p.end_mm[1, X] == 1.0 and p.inch.tolist() == [True, False]


def test_modal_feedrate_and_paper_time_model():
    p = parse("G1 F1200\nG1 X10\nG1 X30\nG0 X30 Y40 F6000\n")
    assert p.feed_mm_s.tolist() == [20, 20, 100]
    # T = L / F (3DGates Eq. 2)
    assert p.duration_s.tolist() == pytest.approx([0.5, 1.0, 0.4])


def test_kinds_of_steps():
    p = parse("M83\nG1 X1 F600\nG1 X2 E1\nG1 E-1\nG1 E1\nG1 Z1\nG1 X3 Y3 E-0.2\n")
    assert [Kind(k).name for k in p.kind] == ["TRAVEL", "EXTRUDE", "RETRACT", "UNRETRACT", "Z_ONLY", "RETRACT"]
    # an E-only move's length is |dE|
    assert p.length_mm[2] == 1.0


def test_g28_homes_and_g4_dwells():
    p = parse("G1 X5 Y5 F600\nG28 X\nG4 P500\nG4 S2\n")
    assert Kind(p.kind[1]) == Kind.HOME and p.end_mm[1, X] == 0 and p.end_mm[1, Y] == 5
    assert [Kind(k) for k in p.kind[2:]] == [Kind.DWELL, Kind.DWELL]
    assert p.duration_s[2:].tolist() == [0.5, 2.0]


def test_arc_ij_quarter_circle_has_true_length_and_steps_both_motors():
    p = parse("G1 X10 Y0 F600\nG3 X0 Y10 I-10 J0 E1\n")
    assert Kind(p.kind[1]) == Kind.ARC and p.arc_ccw[1]
    assert p.length_mm[1] == pytest.approx(math.pi * 10 / 2)
    assert p.arc_center_mm[1].tolist() == [0, 0]
    assert p.steps_motor()[1, :2].all()
    assert p.extruding[1]


def test_arc_r_form_and_full_circle():
    p = parse("G1 X10 Y0 F600\nG2 X0 Y-10 R10\nG2 X0 Y-10 I0 J10\n")
    # clockwise from (10,0) to (0,-10) with R>0: the short way, a quarter circle around (0,0)
    assert p.arc_center_mm[1] == pytest.approx([0, 0])
    assert p.length_mm[1] == pytest.approx(math.pi * 10 / 2)
    # same start and end with I/J: a full circle
    assert p.length_mm[2] == pytest.approx(2 * math.pi * 10)


def test_line_numbers_checksums_and_comments():
    p = parse("N10 G1 X1 Y2 F600*45\nN11 G1 (inline comment) X3 ; trailing\n; only comment\n")
    assert p.end_mm[:, :2].tolist() == [[1, 2], [3, 2]]


def test_unknown_and_klipper_extended_commands_pass_through():
    text = ("SET_VELOCITY_LIMIT ACCEL=3000\nEXCLUDE_OBJECT_START NAME=part_1\nM117 Layer 1/10 ok!\n"
            "M486 S0 A\"my part\"\nM999\nG1 X1 F600\nT1\n")
    p = parse(text)
    assert p.to_gcode() == text and p.n_steps == 1
    assert p.line_letter[0] == ord("@") and p.is_command("M", 117)[2] and p.is_command("T", 1)[6]


def test_motor_enable_state_from_s_series_marlin_and_klipper():
    p = parse("G1 X1 Y1 F600\nS0 Y\nG1 X2\nM18 X\nG4 P1\nSET_STEPPER_ENABLE STEPPER=stepper_z ENABLE=0\n"
              "G4 P1\nG1 X3\nM84\nG4 P1\n")
    en = p.enabled
    kinds = [Kind(k) for k in p.kind]
    assert kinds.count(Kind.MOTOR) == 4
    assert en[2].tolist() == [True, False, True, True]       # S0 Y
    assert en[4].tolist() == [False, False, True, True]      # M18 X, during the dwell
    assert en[6].tolist() == [False, False, False, True]     # Klipper disables Z
    assert en[7].tolist() == [True, False, False, True]      # X steps: on again
    assert en[9].tolist() == [False] * 4                     # M84: all off


def test_m84_with_timeout_only_is_not_a_disable():
    p = parse("G1 X1 F600\nM84 S600\nG1 X2\n")
    assert Kind.MOTOR not in [Kind(k) for k in p.kind]


def test_fan_and_temperatures_are_modal():
    p = parse("M104 S200\nM140 S60\nG1 X1 F600\nM106 S127.5\nG1 X2\nM106 P1 S255\nM107\nG1 X3\n")
    assert p.hotend_c.tolist() == [200, 200, 200] and p.bed_c.tolist() == [60, 60, 60]
    assert p.fan.tolist() == pytest.approx([0, 0.5, 0])


def test_parser_records_the_lines_that_set_the_part_fan():
    """The lines the parser applied to ``fan`` (no P, P0 in any spelling, M107) are recorded once,
    for re-ordering (state) and verify; a fan with another index, or a bare P, is not one."""
    text = ("G1 X1 F600\nM106 S100\nM106 P0 S50\nM106 P0.0 S60\nM107\nM106 P2 S30\n"
            "M107 P1\nM106 P1.5 S9\n; M106 S1\nG1 X2\n")
    p = parse(text)
    assert p.part_fan_lines.tolist() == [1, 2, 3, 4]
    assert p.fan.tolist() == pytest.approx([0, 0])       # M107 last: the P2 and P1 lines change nothing


def test_heat_wait_duration_is_the_named_assumption():
    p = parse("M109 S205\nG1 X1 F600\n")
    assert Kind(p.kind[0]) == Kind.WAIT
    # from 25 C ambient at 2 C/s (paper.toml [time])
    assert p.duration_s[0] == pytest.approx((205 - 25) / 2.0)


# ------------------------------------------------------------------------------------------------
# layers
def test_layers_from_prusaslicer_markers_and_features():
    text = (";LAYER_CHANGE\n;Z:0.2\n;TYPE:Perimeter\nG1 Z0.2 F600\nG1 X1 E1\n;TYPE:Internal infill\nG1 X2 E2\n"
            ";LAYER_CHANGE\n;Z:0.4\nG1 Z0.4\nG1 X1 E3\n")
    p = parse(text)
    assert p.n_layers == 2 and p.layer_method == "marker:prusaslicer"
    assert p.layer.tolist() == [0, 0, 0, 1, 1]
    assert p.layer_z_mm.tolist() == [0.2, 0.4]
    assert [p.feature_names[f] for f in p.feature] == ["Perimeter", "Perimeter", "Internal infill",
                                                       "Internal infill", "Internal infill"]


def test_cura_layer_markers():
    p = parse(";LAYER:0\nG1 Z0.3 F600\nG1 X1 E1\n;LAYER:1\nG1 Z0.5\nG1 X2 E2\n")
    assert p.layer_method == "marker:cura" and p.layer.tolist() == [0, 0, 1, 1]


def test_z_fallback_ignores_z_hops():
    # travel with z-hop: up 0.4, across, down again; extrusion continues on the same layer
    text = ("M83\nG1 Z0.2 F600\nG1 X1 E1\nG1 Z0.6\nG1 X5\nG1 Z0.2\nG1 X6 E1\n"
            "G1 Z0.4\nG1 X7 E1\n")
    p = parse(text)
    assert p.layer_method == "z-change" and p.n_layers == 2
    assert p.layer_z_mm.tolist() == [0.2, 0.4]


def test_z_fallback_does_not_cut_a_spiral_into_layers():
    pts = "".join(f"G1 X{10 * math.cos(a):.3f} Y{10 * math.sin(a):.3f} Z{0.2 + a / 100:.4f} E0.1\n"
                  for a in np.linspace(0, 20, 200))
    p = parse("M83\nG1 X10 Y0 Z0.2 F600\n" + pts)
    assert p.n_layers == 1


# ------------------------------------------------------------------------------------------------
# bad input: one line naming file and line, never a traceback
@pytest.mark.parametrize("text, message", [
    ("G1 X1.2.3\n", "<text>:1: G1 X1.2.3: bad number for X"),
    ("G1 X0\nG1 Xnan Y1\n", "<text>:2: G1 Xnan Y1: X has no number"),
    ("G1 Yinf\n", "<text>:1: G1 Yinf: Y has no number"),
    ("G1 X1 Y-\n", "<text>:1: G1 X1 Y-: bad number for Y"),
    ("G1 X2000000\n", "<text>:1: G1 X2000000: absurd coordinate for X"),
    ("G1 X1 F0\n", "<text>:1: G1 X1 F0: feedrate F must be positive"),
    ("G1 X1 F600\nG2 X2 Y2\n", "<text>:2: G2 X2 Y2: arc needs I/J or an R"),
    ("M104 S200\n; no moves here\n", "<text>: no moves"),
    ("", "<text>: empty file"),
    ("  \n\n", "<text>: empty file"),
])
def test_bad_input_gives_one_clear_line(text, message):
    with pytest.raises(GcodeError) as err:
        parse(text)
    assert str(err.value).startswith(message)
    assert "\n" not in str(err.value)


def test_binary_gcode_is_refused_with_the_setting_to_change():
    with pytest.raises(GcodeError, match="binary G-code.*Supports binary G-code"):
        parse(b"GCDE\x01\x00\x00\x00rest")


def test_nul_bytes_are_refused_with_line():
    with pytest.raises(GcodeError, match=r"<bytes>:2: binary data"):
        parse(b"G1 X1\nG1 \x00X2\n")


def test_non_utf8_is_a_warning_and_round_trips():
    data = b"; caf\xe9 latin-1 comment\nG1 X1 F600\n"
    p = parse(data)
    assert p.to_bytes() == data
    assert p.to_gcode().encode("utf-8", "surrogateescape") == data
    assert any("not UTF-8" in w and ":1:" in w for w in p.warnings)


def test_unexpanded_placeholder_is_a_warning_and_ignored_like_marlin():
    p = parse("G1 X1 Y1 F600\nG1 X0 Y{machine_depth} ;Present print\n")
    assert p.end_mm[-1, :2].tolist() == [0, 1]
    assert any(":2:" in w and "placeholder" in w for w in p.warnings)


def test_missing_file_and_directory_and_corrupt_gzip(tmp_path):
    with pytest.raises(GcodeError, match="no such file"):
        parse(tmp_path / "missing.gcode")
    with pytest.raises(GcodeError, match="directory"):
        parse(tmp_path)
    bad = tmp_path / "x.gcode.gz"
    bad.write_bytes(b"\x1f\x8b\x08\x00garbage")
    with pytest.raises(GcodeError, match="corrupt gzip"):
        parse(bad)


def test_no_extrusion_is_a_warning():
    p = parse("G1 X1 F600\nG1 X2\n")
    assert any("no extrusion" in w for w in p.warnings)


def test_long_prints_may_extrude_more_than_100_m_but_not_absurd_amounts():
    # cumulative E past 100 m is a long print, not corrupt input (a 1 kg spool is ~330 m)
    p = parse("M83\n" + "G1 X1 E40000 F600\nG1 X0 E40000\n" * 3)
    assert p.end_mm[-1, E] == 240000
    with pytest.raises(GcodeError, match="absurd coordinate for E"):
        parse("G1 X1 E200000000 F600\n")


def test_z_fallback_ignores_lines_between_extrusions_that_do_not_move_z():
    # a gated spiral: motor instructions and a dwell between extrusions make no new layer
    pts = "".join(f"G1 X{10 * math.cos(a):.3f} Y{10 * math.sin(a):.3f} Z{0.2 + a / 100:.4f} E0.1\n"
                  + ("S0 Y\nS1 Y\n" if i % 3 == 0 else "") + ("G4 P1\n" if i % 7 == 0 else "")
                  for i, a in enumerate(np.linspace(0, 20, 200)))
    p = parse("M83\nG1 X10 Y0 Z0.2 F600\n" + pts)
    assert p.n_layers == 1


def test_stray_characters_inside_a_g_command_are_an_error_but_text_commands_are_not():
    with pytest.raises(GcodeError, match=r"<text>:2: .*unexpected character in a G command"):
        parse("G1 X0 F600\nG1 X1 \x82\xfd Y10 E1\n")
    with pytest.raises(GcodeError, match="unexpected character"):
        parse("G1 X0 F600\nG1 X1 # Y2\n")
    p = parse("M117 Printing 1/10 #%&\nG1 X1 F600\nM118 E1 ok: 50%\n")
    assert p.n_steps == 1


def test_extrusion_by_m101_m103_is_warned_about():
    # Cura's BFB flavour: the extruder is switched on (M101) and off (M103), moves carry no E;
    # the start G-code's prime used to keep every warning quiet
    text = "G28\nG1 F200 E3\nG92 E0\nG1 Z0.3 F900\nM108 S8.5\nM101\nG1 X10 Y10 F900\nG1 X20 Y10\nM103\n"
    prog = parse(text)
    assert any(":6: M101: the extruder is switched on and off" in w for w in prog.warnings)
    assert not any("M101" in w for w in parse(text.replace("M101\n", "")).warnings)


# ------------------------------------------------------------------------------------------------
# the start G-code's purge line in a file without layer markers (Slic3r 1.x, IceSL)
_PURGE_START = "G90\nM82\nG28\nG1 X5 Y5 Z0.3 F3000\nG92 E0\nG1 X100 E12 F1000 ; purge line\nG92 E0\n"


def _square_layers(z0: float, n: int, e0: float = 0.0) -> str:
    out, e = [], e0
    for k in range(n):
        z = z0 + 0.2 * k
        out.append(f"G1 Z{z:.2f} F600\nG1 X90 Y90 F6000")
        for x, y in ((110, 90), (110, 110), (90, 110), (90, 90)):
            e += 1.0
            out.append(f"G1 X{x} Y{y} E{e:.3f} F1200")
    return "\n".join(out) + "\n"


def test_purge_line_at_its_own_z_outside_the_print_is_not_a_layer():
    prog = parse(_PURGE_START + _square_layers(0.35, 3))
    assert prog.n_layers == 3
    purge = np.flatnonzero(prog.extruding & (prog.end_mm[:, 1] == 5.0))
    assert len(purge) == 1 and prog.layer[purge[0]] == -1
    assert (prog.layer[prog.extruding & (prog.end_mm[:, 1] > 50)] >= 0).all()


def test_skirt_at_the_first_layer_z_and_a_first_layer_inside_the_print_stay_layers():
    # the same line at the first layer's Z (a skirt or purge printed with it): one layer with it
    prog = parse(_PURGE_START.replace("Z0.3", "Z0.35") + _square_layers(0.35, 3))
    assert prog.n_layers == 3 and (prog.layer[prog.extruding] >= 0).all()
    # a first layer at its own Z inside the later layers' footprint is part of the print (a raft)
    inside = _PURGE_START.replace("X5 Y5", "X95 Y95").replace("X100 E12", "X105 E12")
    prog = parse(inside + _square_layers(0.35, 3))
    assert prog.n_layers == 4 and (prog.layer[prog.extruding] >= 0).all()


def test_slic3r_verbose_layer_comment_on_the_layer_change_move_is_a_marker():
    text = _PURGE_START + "".join(
        _square_layers(0.3 + 0.2 * k, 1, 4.0 * k).replace(
            f"G1 Z{0.3 + 0.2 * k:.2f} F600", f"G1 Z{0.3 + 0.2 * k:.3f} F7800.000 ; move to next layer ({k})")
        for k in range(3))
    prog = parse(text)
    assert prog.layer_method == "marker:slic3r"
    assert prog.n_layers == 3
    # the purge, at the first layer's Z, is before the first marker: not part of the print
    purge = np.flatnonzero(prog.extruding & (prog.end_mm[:, 1] == 5.0))
    assert prog.layer[purge[0]] == -1


def test_line_numbered_instructions_read_as_without_numbers():
    """A host-numbered line (``N7 M106 S255``) is the same instruction as ``M106 S255`` for every
    module that reads a line's instruction word (``_text.code_words``): the ordering's state
    lines, the planner's queue drains."""
    from gatesopt._text import code_words
    from gatesopt.ordering.layout import state_key_of
    from gatesopt.planner import drains_queue
    assert code_words("N7 m106 s255 ; fan") == ["M106", "S255"]
    assert code_words(b"N7 M106 S255") == [b"M106", b"S255"]
    text = "G28\nG1 X10 Y10 F3000\nN7 M106 S255\nM106 S128\nN8 M17\nM17\nN9 M18 X\nG4 P0\n"
    prog = parse(text)
    assert state_key_of(prog, 2) == state_key_of(prog, 3) == ("fan",)
    drains = drains_queue(prog)
    motor = [int(prog.line[r]) for r in np.flatnonzero(prog.kind == Kind.MOTOR)]
    by_line = {int(prog.line[r]): bool(drains[r]) for r in range(prog.n_steps)}
    assert motor == [4, 5, 6]
    assert [by_line[i] for i in motor] == [False, False, True]     # M17 does not drain, M18 does


def test_a_command_number_after_blanks_reads_as_the_firmware_reads_it():
    """``G 28 W`` (a Prusa start G-code in a real Simplify3D 3.1 file, refused before as "unexpected
    character in a G command"): Marlin skips blanks between a command's letter and its number
    (GCodeParser::parse) and Klipper joins them, so it is G28; a spaced motion command moves."""
    from gatesopt._text import code_words
    p = parse("G 28 W ; home\nG 1 X10 Y5 F1200\nM 104 S200\nG1 X20 Y5\n")
    assert p.line_letter[0] == ord("G") and p.line_number[0] == 28
    assert p.line_letter[2] == ord("M") and p.line_number[2] == 104
    assert Kind.HOME in p.kind.tolist()
    moves = np.flatnonzero(p.kind == Kind.TRAVEL)
    assert np.allclose(p.end_mm[moves[-2], :2], [10.0, 5.0])
    assert np.allclose(p.end_mm[moves[-1], :2], [20.0, 5.0])
    assert p.to_gcode() == "G 28 W ; home\nG 1 X10 Y5 F1200\nM 104 S200\nG1 X20 Y5\n"
    assert code_words("G 28 W ; home") == ["G28", "W"]
    assert code_words(b"N12 M 117 hi") == [b"M117", b"HI"]
    # a lone letter is not joined to a word that is not its number
    assert code_words("G W") == ["G", "W"]
