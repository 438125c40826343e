"""The compiled pass that writes a rotated file (``gating.emit_rotated``, ``_emit_kernel.
render_rotated``) writes exactly the bytes of the per-line reference (``emit_line.LineRewriter``
through ``emit._write_lines``), and ends with the same snap counts: on the bundled instances, on
every corpus file, at several angles, and on lines made to leave the plain form."""
from __future__ import annotations

import pytest

import gatesopt
from gatesopt.gating.emit import _default_snap, _rows_to_rewrite, _write_lines, header_bounds
from gatesopt.gating.emit_line import LineRewriter
from gatesopt.gating.emit_rotated import write_rotated
from gatesopt.gating.rotation import rotated_rows, rotation_center

from conftest import PROJECT_INSTANCES, needs_shared, shared_files

ANGLES = (45.0, 90.0, 17.3, 313.25)


def both(program, deg):
    """(compiled text, reference text, compiled rewriter, reference rewriter)."""
    lo, hi = rotated_rows(program)
    center = tuple(float(v) for v in rotation_center(program, lo, hi))
    out = []
    for writer in (write_rotated, _write_lines):
        em = LineRewriter(program, deg, center, (lo, hi), None)
        em.snap = _default_snap(em, program)
        rewrite = _rows_to_rewrite(program, em, {})
        header = ["; gatesopt: rotate_deg=x"]
        bounds = header_bounds(program, deg, center)    # the slicer's bounds lines, turned too
        if writer is write_rotated:
            pieces, added, splits = writer(program, em, rewrite, header, bounds)
        else:
            pieces, added, splits = writer(program, em, {}, {}, rewrite, header, bounds)
        out.append(("".join(pieces), added, splits, em))
    return out


def assert_same(program, deg):
    (a, added_a, split_a, em_a), (b, added_b, split_b, em_b) = both(program, deg)
    if a != b:
        la, lb = a.splitlines(), b.splitlines()
        i = next(i for i, (x, y) in enumerate(zip(la, lb)) if x != y)
        pytest.fail(f"{program.source} at {deg} deg, line {i + 1}: {la[i]!r} != reference {lb[i]!r}")
    assert (added_a, split_a) == (added_b, split_b)
    assert (em_a.max_snap, em_a.snap_refused, em_a.snap_missed) == (em_b.max_snap, em_b.snap_refused,
                                                                    em_b.snap_missed)


@pytest.mark.parametrize("path", sorted(PROJECT_INSTANCES.glob("*.gcode")), ids=lambda p: p.name)
def test_bundled_instances(path):
    program = gatesopt.parse(path)
    for deg in ANGLES:
        assert_same(program, deg)


#: corpus files of every kind of line the pass meets or hands on (arcs, relative E and XYZ, Cura's
#: G91 wipe, KISSlicer, ideaMaker, IceSL, Kiri:Moto, Creality Print, CRLF), small enough for the
#: reference (~30 us a line)
CORPUS = ("real_superslicer2356_arcwelder.gcode", "real_prusa240_m486_arcwelder.gcode",
          "real_bambu0110_arcs.gcode.gz", "slic3r13_cyl_concentric30_rel.gcode.gz",
          "cura413_star_triangles20.gcode.gz", "real_kisslicer206.gcode.gz", "real_ideamaker420.gcode",
          "real_icesl.gcode.gz", "real_kirimoto30.gcode.gz", "real_crealityprint514.gcode.gz",
          "real_slic3r131_stars.gcode", "real_cura410_cubic.gcode.gz")


@needs_shared
@pytest.mark.parametrize("path", [p for p in shared_files() if p.name in CORPUS], ids=lambda p: p.name)
def test_corpus(path):
    assert_same(gatesopt.parse(path), 45.0)


ODD = """; start
G28 ; home
G90
M82
G1 X10 Y10 Z0.2 F3000
G1 X20 Y10 E1.0 F1200
G1 X20.00001 Y30 E2.0
G1 X20 Y30.0004 E2.5 ; snapped twice
g1 x25 y35 e3
G1X30Y35E3.5
G1 X31  Y36 E3.6
G1 Y40 E4
G1 X35 E4.5\t; tab before the comment
G2 X40 Y40 I2.5 J0 E5
G91
G1 X1 Y1 E0.1
G90
G20
G1 X1.6 Y1.6 E5.5
G21
M83
G1 X50 Y50 E.05000
G1 X52 Y50 E-.5
G1 X52 Y{machine_depth} E0.1
G1 X60 Y60 E+1.0 F600
G1 X61 Y61 E0.00000000000000000001
G1 X60 Y60
; end
G1 X0 Y200 F6000
M84
"""


@pytest.mark.parametrize("ending", ["\n", "\r\n"])
def test_lines_out_of_the_plain_form_go_to_the_reference(ending):
    program = gatesopt.parse(ODD.replace("\n", ending), source="odd.gcode")
    for deg in ANGLES + (0.0001, 89.9999):
        assert_same(program, deg)
