"""The slicer-knowledge table (``gatesopt.slicers``) as the parser reads it: every layer marker row
finds its layers from its own example line, a table with more slicers than the old 3-bit kind field
held works end to end, and the extended motor commands are a table too."""
from __future__ import annotations

import importlib
import re

import numpy as np
import pytest

from gatesopt import _scan, _scan_tables, slicers
from gatesopt import parse as parse_fn
from gatesopt.firmware import EXTENDED_MOTOR_COMMANDS, ExtendedMotorCommand
from gatesopt.program import AXES, Kind

from conftest import shared_params

parse_module = importlib.import_module("gatesopt.parse")   # ``gatesopt.parse`` is also the function


def _two_layers(example: str, trailing: bool) -> str:
    """A two-layer print with ``example`` where each layer starts."""
    if trailing:        # the example is the layer change move itself
        return f"G1 X0 Y0 F600\n{example}\nG1 X10 E1\n{example.replace('Z0.350', 'Z0.550')}\nG1 X0 E2\n"
    return f"G1 X0 Y0 F600\n{example}\nG1 Z0.2\nG1 X10 E1\n{example}\nG1 Z0.4\nG1 X0 E2\n"


@pytest.mark.parametrize("marker", slicers.LAYER_MARKERS, ids=lambda m: f"{m.slicer}-{m.where}")
def test_each_layer_marker_row_finds_the_layers_of_its_example(marker):
    prog = parse_fn(_two_layers(marker.example, marker.where == slicers.TRAILING))
    assert prog.layer_method == f"marker:{marker.slicer}"
    assert prog.n_layers == 2
    ext = np.flatnonzero(prog.extruding)
    assert prog.layer[ext].tolist() == [0, 1]
    if marker.z_after:      # the layer's Z is the one the comment gives, not the extrusion's
        z = float(re.search(re.escape(marker.z_after.decode()) + r"\s*([-\d.]+)", marker.example).group(1))
        assert prog.layer_z_mm[0] == pytest.approx(z)


def test_an_earlier_row_wins_over_a_later_one_in_the_same_file():
    # PrusaSlicer custom G-code may carry a generic '; layer 3' comment: the slicer's own marker wins
    text = ";LAYER_CHANGE\n; layer 1\nG1 Z0.2 F600\nG1 X1 E1\n;LAYER_CHANGE\nG1 Z0.4\nG1 X2 E2\n"
    prog = parse_fn(text)
    assert prog.layer_method == "marker:prusaslicer" and prog.n_layers == 2


def test_layer_kinds_are_the_table_slicers_in_row_order():
    assert slicers.LAYER_KINDS == ("prusaslicer", "bambu", "cura", "simplify3d", "slic3r", "kisslicer",
                                   "comment")


def test_a_bad_row_is_refused_when_the_table_is_written():
    with pytest.raises(ValueError, match="follow"):
        slicers.LayerMarker("x", b";X", ";X", follow="number")
    with pytest.raises(ValueError, match="upper case"):
        slicers.LayerMarker("x", b"layer", "; layer 1", fold_case=True)


def test_more_slicers_than_a_three_bit_field_held(monkeypatch):
    """Twelve slicers, each with its own marker: the tenth one's layers are found as its own."""
    markers = tuple(slicers.LayerMarker(f"s{k}", f";S{k}_LAYER".encode(), f";S{k}_LAYER") for k in range(12))
    kinds = tuple(m.slicer for m in markers)
    tables = (*_scan_tables.pack_comment_markers(markers, kinds, slicers.Z_MARKERS, slicers.FEATURE_MARKERS),
              *_scan_tables.pack_motor_commands(EXTENDED_MOTOR_COMMANDS, AXES))
    monkeypatch.setattr(parse_module, "SCAN_TABLES", tables)
    monkeypatch.setattr(slicers, "LAYER_KINDS", kinds)
    prog = parse_fn(_two_layers(";S10_LAYER", False))
    assert prog.layer_method == "marker:s10" and prog.n_layers == 2
    # and the kernel's own output: kind 11 (1-based) on both marker lines
    data = _two_layers(";S10_LAYER", False).encode()
    buf = np.frombuffer(data, np.uint8)
    out = _scan.scan(buf, _scan.line_starts(buf), False, 1.0, 1.0, 25.0, 1.0, 25.0,
                     _scan.initial_state(25.0, 25.0), tables)
    mk_line, mk_kind = out[5][0], out[5][1]
    assert mk_line.tolist() == [1, 4] and mk_kind.tolist() == [11, 11]


def test_extended_motor_commands_are_a_table(monkeypatch):
    """A dialect's own motor command is one more row; Klipper's keeps working beside it."""
    gate = ExtendedMotorCommand("GATESOPT_TEST", "MOTOR", (("X", "X"), ("Y", "Y")), "ON")
    tables = parse_module.SCAN_TABLES[:2] + _scan_tables.pack_motor_commands(EXTENDED_MOTOR_COMMANDS + (gate,), AXES)
    text = ("G1 X1 Y1 F600\nGATESOPT_TEST MOTOR=Y ON=0\nSET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0\n"
            "gatesopt_test motor=y on=1\nGATESOPT_TEST MOTOR=Q ON=0\nG1 X2\n")
    before = parse_fn(text)
    assert before.kind.tolist() == [Kind.TRAVEL, Kind.MOTOR, Kind.TRAVEL]     # unknown to today's table
    monkeypatch.setattr(parse_module, "SCAN_TABLES", tables)
    prog = parse_fn(text)
    assert prog.kind.tolist() == [Kind.TRAVEL, Kind.MOTOR, Kind.MOTOR, Kind.MOTOR, Kind.TRAVEL]
    # enables X Y Z E after each row: Y off, then X off too, then Y on again; MOTOR=Q is no motor line
    assert prog.enabled[1:4, :2].tolist() == [[True, False], [False, False], [False, True]]


# -- the printer a file was sliced for: beds and bounds lines (issue 37) --------------------------
@pytest.mark.parametrize("text, box", slicers.BED_EXAMPLES, ids=lambda v: str(v)[:30])
def test_each_bed_reader_reads_its_example(text, box):
    bed = slicers.read_bed(("; generated by a slicer\n" + text + "\n").encode())
    assert bed is not None and bed.line >= 2
    xs, ys = zip(*bed.polygon_mm)
    assert (min(xs), min(ys), max(xs), max(ys)) == pytest.approx(box)


def test_a_round_bed_is_the_polygon_inside_its_circle():
    bed = slicers.read_bed(b";Dimension: 200.000 200.000 200.000 0.400\n;Plate Shape: 1\n;Origin Center: 1\n")
    r = np.hypot(*np.array(bed.polygon_mm).T)
    assert len(bed.polygon_mm) == 64 and np.allclose(r, 100.0)


@pytest.mark.parametrize("fmt", slicers.BOUNDS_FORMATS, ids=lambda f: f"{f.slicer}-{f.kind}")
def test_each_bounds_line_is_found_and_turned(fmt):
    data = (f"; header\n{fmt.example}\nG1 X1 Y1\n").encode()
    starts = np.array([0] + [i + 1 for i, b in enumerate(data) if b == 10], np.int64)
    found = slicers.bounds_lines(data, starts)
    assert [(line, f) for line, f, *_ in found] == [(1, fmt)]
    quarter = lambda p: np.column_stack((-np.asarray(p)[:, 1], np.asarray(p)[:, 0]))   # 90 deg about 0
    new = slicers.rotated_bounds(data, starts, quarter, np.array([[90.0, 96.5], [140.0, 120.0]]))
    assert set(new) == {1} and new[1].endswith("\n") and new[1] != fmt.example + "\n"
    if fmt.kind == "outline":
        assert "[-95,115]" in new[1].replace(".0", "") or "[-95.0,115.0]" in new[1]


@pytest.mark.parametrize("path", shared_params())
def test_every_corpus_file_bed_is_the_parser_s_bed_shape(path):
    from conftest import read_bytes
    data = read_bytes(path)
    bed = slicers.read_bed(data)
    header = parse_module._read_header(data)
    if "bed_size_mm" in header:
        assert bed is not None and bed.size_mm == pytest.approx(header["bed_size_mm"])
