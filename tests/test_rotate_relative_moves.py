"""Rotation of relative (G91) moves: the XY delta turns with the model, the head does not jump.

Cura's stock end G-code wipes with "G91 / G1 X5 Y5 ;Wipe out": 5 mm from where the print ended.
After a rotation the print ends elsewhere; the wipe must be the rotated 5 mm from *there*, not a
travel to where the unrotated print would have ended (which drags the nozzle over the print and
passed every check of the verifier but the new ``positions`` one). Every test compares positions
as the parser resolves them in the original and the output.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import gatesopt
from gatesopt.gating.emit import render
from gatesopt.rewrite import run
from gatesopt.gating import GatingOptions, build
from gatesopt.program import MOTION_KINDS
from gatesopt import verify as verify_mod
from gatesopt.verify import verify

ROT_ON, ROT_OFF = ";>rotated", ";<rotated"     # the lines in between are the rotated print
BED = (400.0, 400.0)        # a rotation needs a bed the rotated print fits (issue 37)

# Cura-like: a G91 block in the start G-code (before the print: stays where the slicer put it),
# two layers with an arc, and Cura's end G-code (G91 wipe, an X-only move and a relative arc).
CURA_LIKE = f"""\
;FLAVOR:Marlin
G21
G90
M82
G28
G91
G1 Z2 F600
G1 X5 Y5 F3000
G1 X5
G2 X5 Y5 I5 J0
G90
G92 E0
G1 X10 Y10 F3000
G1 X30 Y10 E2 F1000
;LAYER:0
{ROT_ON}
G0 F3000 X50 Y50 Z0.2
G1 F1200 X70 Y50 E3
G1 X70 Y70 E4
G1 X50 Y70 E5
G1 X50 Y50 E6
;LAYER:1
G0 X50 Y50 Z0.4
G1 X70 Y50 E7
G1 X70 Y70 E8
G2 X50 Y70 I-10 J0 E9
G1 X50 Y50 E10
G91 ;Relative positioning
G1 E-2 F2700 ;Retract a bit
G1 E-2 Z0.2 F2400 ;Retract and raise Z
G1 X5 Y5 F3000 ;Wipe out
G1 X5 ;X only
G2 X5 Y5 I5 J0 ;relative arc
G1 Z10 ;Raise Z more
G90 ;Absolute positioning
{ROT_OFF}
G1 X0 Y200
M84
"""


def _g91_print(n_steps: int = 60) -> str:
    """A print written in G91 throughout (relative extrusion too): X-only and Y-only moves, a
    relative arc, and staircases of 1 mm steps whose rotated deltas all round the same way (at 30
    degrees (1, 0) turns to (0.8660254, 0.5), written 0.866: 25 nm short each time)."""
    up = "G1 X1 E0.01\nG1 Y1 E0.01\n" * n_steps
    down = "G1 X-1 E0.01\nG1 Y-1 E0.01\n" * n_steps
    return f"""\
G21
G90
M83
G1 X10 Y10 F3000
G91
;LAYER:0
{ROT_ON}
G1 X40 Y40 Z0.2 F3000
G1 X20 E1 F1200
G1 Y20 E1
G2 X-20 Y0 I-10 J0 E1.5
{up};LAYER:1
G1 Z0.2
{down}G1 E-1 F2700
G1 X5 Y5 F3000 ;Wipe out
G1 X5
G1 Z10
G90
{ROT_OFF}
G1 X0 Y200
"""


def _rot(xy, deg, center):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    if deg % 90 == 0:
        c, s = round(c), round(s)
    xy = np.asarray(xy, float)
    x, y = xy[..., 0] - center[0], xy[..., 1] - center[1]
    return np.stack([center[0] + c * x - s * y, center[1] + s * x + c * y], axis=-1)


def _motion(p):
    return np.flatnonzero(np.isin(p.kind, MOTION_KINDS))


def _rotated_rows(p, text):
    """Per motion row of ``p``: between the ROT_ON / ROT_OFF lines (None: every row)."""
    rows = _motion(p)
    if text is None:
        return np.ones(len(rows), bool)
    lines = text.splitlines()
    on, off = lines.index(ROT_ON), lines.index(ROT_OFF)
    return (p.line[rows] > on) & (p.line[rows] < off)


def _expected_ends(p, deg, center, rotated):
    """The original's end points (X Y Z E), XY rotated where ``rotated``."""
    e = p.end_mm[_motion(p)].astype(float).copy()
    e[rotated, :2] = _rot(e[rotated, :2], deg, center)
    return e


def _rotate_only(p, deg):
    """Rotation alone, with the pipeline's rotated rows and centre: one output move per move."""
    prob = build(p, GatingOptions(rotate=deg, bed_size_mm=BED))
    assert float(prob.angles_deg[0]) == pytest.approx(deg % 360)
    center = tuple(float(v) for v in prob.center_mm)
    r = render(p, [], rotation_deg=deg, center_mm=center, rotate_rows=(prob.rotate_lo, prob.rotate_hi))
    return r, gatesopt.parse(r.text), center


def _assert_positions(p, q, deg, center, rotated, atol=1.1e-3):
    a, b = _motion(p), _motion(q)
    assert len(a) == len(b)                       # rotation alone splits nothing
    want = _expected_ends(p, deg, center, rotated)
    got = q.end_mm[b].astype(float)
    bad = np.flatnonzero(np.abs(got - want).max(axis=1) > atol)
    assert not len(bad), [(p.line_text(int(p.line[a[i]])).strip(), got[i].round(4).tolist(),
                           want[i].round(4).tolist()) for i in bad[:5]]


def _line_of(q, needle):
    lines = q.to_gcode().splitlines()
    hits = [ln for ln in lines if needle in ln]
    assert len(hits) == 1, (needle, hits)
    return hits[0]


# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("deg", [30, 90])
def test_cura_end_gcode_relative_moves_are_rotated(deg):
    p = gatesopt.parse(CURA_LIKE)
    r, q, center = _rotate_only(p, deg)
    _assert_positions(p, q, deg, center, _rotated_rows(p, CURA_LIKE))
    # the wipe is the rotated (5, 5) from where the rotated print ended: ~7 mm, not a travel
    rows = _motion(q)
    wipe = rows[np.flatnonzero(q.line[rows] == q.to_gcode().splitlines().index(_line_of(q, "Wipe out")))[0]]
    d = q.end_mm[wipe, :2] - q.start_mm[wipe, :2]
    np.testing.assert_allclose(d, _rot([5.0, 5.0], deg, (0.0, 0.0)), atol=1e-4)
    # an X-only relative move is an X and Y delta after the rotation (at 90: X0 Y5)
    x_only = _line_of(q, ";X only")
    assert " Y" in x_only.split(";")[0] and " X" in x_only.split(";")[0]
    # the relative arc: its end and its centre (I/J from its start) turn with it
    arc = rows[np.flatnonzero(q.line[rows] == q.to_gcode().splitlines().index(_line_of(q, "relative arc")))[0]]
    pa = _motion(p)[np.flatnonzero(p.kind[_motion(p)] == gatesopt.program.Kind.ARC)[-1]]
    np.testing.assert_allclose(q.arc_center_mm[arc], _rot(p.arc_center_mm[pa], deg, center), atol=1e-3)
    np.testing.assert_allclose(q.end_mm[arc, :2], _rot(p.end_mm[pa, :2], deg, center), atol=1e-3)
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]
    assert "positions" in rep.checks


@pytest.mark.parametrize("deg", [30, 90])
def test_start_gcode_g91_block_stays_where_the_slicer_put_it(deg):
    # before the print nothing is rotated (absolute or relative): the G91 block is kept as written
    p = gatesopt.parse(CURA_LIKE)
    r, q, center = _rotate_only(p, deg)
    out = r.text.splitlines()
    for ln in ("G1 X5 Y5 F3000", "G1 X5", "G2 X5 Y5 I5 J0"):
        assert ln in out[:12]
    _assert_positions(p, q, deg, center, _rotated_rows(p, CURA_LIKE))


@pytest.mark.parametrize("deg", [30, 90])
def test_whole_file_rotation_with_g91_at_the_start(deg):
    # ``render`` without rotate_rows rotates every row: a relative first move goes from where the
    # head is (the parser's origin, unrotated) to the rotated end point
    text = "G21\nM82\nG91\nG1 X15 Y5 F3000\nG1 X5\nG2 X5 Y5 I5 J0\nG90\nG1 X40 Y10 E1 F1200\nG1 X40 Y30 E2\n"
    p = gatesopt.parse(text)
    center = (25.0, 20.0)
    r = render(p, [], rotation_deg=deg, center_mm=center)
    q = gatesopt.parse(r.text)
    _assert_positions(p, q, deg, center, _rotated_rows(p, None))
    assert verify(p, q).ok


@pytest.mark.parametrize("deg", [30, 90])
def test_print_in_g91_keeps_its_rotated_geometry(deg):
    # every move relative, 2 x 120 equal small ones: each rotated delta is written from where the
    # text before left the head, so 4-decimal rounding does not add up along the print
    text = _g91_print()
    p = gatesopt.parse(text)
    r, q, center = _rotate_only(p, deg)
    _assert_positions(p, q, deg, center, _rotated_rows(p, text), atol=1e-4)
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]


@pytest.mark.parametrize("deg", [30, 90])
@pytest.mark.parametrize("name", ["cura", "g91"])
def test_pipeline_output_verifies_positions(deg, name):
    text = CURA_LIKE if name == "cura" else _g91_print(20)
    p = gatesopt.parse(text)
    res = run(p, GatingOptions(rotate=deg, bed_size_mm=BED), order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]
    assert "positions" in res.report.checks
    assert res.text.startswith(f"; gatesopt: rotate_deg={deg} ")
    assert not verify_mod.check_positions(p, res.output)


@pytest.mark.parametrize("deg", [30, 90])
def test_relative_move_after_homing_is_not_rotated(deg):
    # homing ends the rotated run: a relative move after "G28 X0 Y0" goes from the machine's home
    text = CURA_LIKE.replace(f"G1 Z10 ;Raise Z more\nG90 ;Absolute positioning\n{ROT_OFF}\nG1 X0 Y200\n",
                             f"G1 Z10 ;Raise Z more\n{ROT_OFF}\nG28 X0 Y0\nG1 X10 Y10 ;from home\nG90\n")
    assert "from home" in text
    p = gatesopt.parse(text)
    r, q, center = _rotate_only(p, deg)
    _assert_positions(p, q, deg, center, _rotated_rows(p, text))
    assert "G1 X10 Y10 ;from home" in r.text.splitlines()
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]


def _broken(q_text, needle, replacement):
    """The output with the line containing ``needle`` replaced (what the emitter used to write)."""
    lines = q_text.splitlines(keepends=True)
    k = [i for i, ln in enumerate(lines) if needle in ln]
    assert len(k) == 1
    lines[k[0]] = replacement + "\n"
    return "".join(lines)


@pytest.mark.parametrize("deg", [30, 90])
@pytest.mark.parametrize("which", ["wipe", "x_only", "arc"])
def test_verify_refuses_unrotated_relative_moves(deg, which):
    p = gatesopt.parse(CURA_LIKE)
    r, q, center = _rotate_only(p, deg)
    assert verify(p, q).ok
    if which == "wipe":
        # the old output: the wipe as a travel from the rotated print to the unrotated wipe point
        rows = _motion(p)
        w = rows[np.flatnonzero(p.line[rows] == CURA_LIKE.splitlines().index("G1 X5 Y5 F3000 ;Wipe out"))[0]]
        d = p.end_mm[w, :2] - _rot(p.start_mm[w, :2], deg, center)
        bad = _broken(r.text, "Wipe out", f"G1 X{d[0]:.4f} Y{d[1]:.4f} F3000 ;Wipe out")
    elif which == "x_only":
        bad = _broken(r.text, ";X only", "G1 X5 ;X only")          # the delta not rotated
    else:
        bad = _broken(r.text, ";relative arc", "G2 X5 Y5 I5 J0 ;relative arc")
    rep = verify(p, gatesopt.parse(bad))
    assert not rep.ok
    assert any(f.check == "positions" for f in rep.findings), [str(f) for f in rep.findings]


def test_a_twice_rotated_output_verifies_against_either_input():
    """An output rotated again (its input a rotated gatesopt output, gated with no lines added)
    carries two rotation headers. Against the slicer's file they compose into one rotation (30 +
    45 deg about another centre); against its own input, only the new one counts: the input's
    header came along with its text."""
    p = gatesopt.parse(CURA_LIKE)
    def rows(q):
        b = build(q, GatingOptions(rotate="none"))
        return b.rotate_lo, b.rotate_hi
    once = gatesopt.parse(render(p, [], rotation_deg=30, center_mm=(60.0, 60.0), rotate_rows=rows(p)).text)
    twice = gatesopt.parse(render(once, [], rotation_deg=45, center_mm=(10.0, -5.0),
                                  rotate_rows=rows(once)).text)
    assert verify_mod.read_rotation(twice, once) == (45.0, 10.0, -5.0)
    deg, cx, cy = verify_mod.read_rotation(twice, p)
    assert deg == pytest.approx(75.0)
    # the composed centre is the fixed point of both rotations applied in turn
    a, b = math.radians(30), math.radians(45)
    c = complex(cx, cy)
    first = 60 + 60j + complex(math.cos(a), math.sin(a)) * (c - (60 + 60j))
    assert abs((10 - 5j) + complex(math.cos(b), math.sin(b)) * (first - (10 - 5j)) - c) < 1e-9
    for original in (p, once):
        rep = verify(original, twice)
        assert rep.ok, [str(f) for f in rep.findings]
        assert "positions" in rep.checks
    # the slicer's file itself declares no rotation against anything
    assert verify_mod.read_rotation(p, p) == (0.0, 0.0, 0.0)


def test_a_gated_file_is_not_rotated_again():
    """Gating lines in the input (gatesopt's own earlier output) were placed for its X and Y
    moves: rotated, they would hold a motor off while it steps. ``auto`` keeps 0 deg and says
    why; a fixed angle is refused with the file and line of the first such line."""
    from gatesopt.errors import GatesoptError
    p = gatesopt.parse(CURA_LIKE)
    gated = run(p, GatingOptions(rotate=30, bed_size_mm=BED), order=False)
    assert gated.report.ok and gated.solution.instructions().time_s.size
    again = run(gated.output, GatingOptions(rotate="auto", bed_size_mm=BED), order=False)
    assert again.report.ok and again.report.rotate_deg == 0.0
    assert any("rotation kept at 0 deg" in n and "already gated" in n for n in again.notes)
    with pytest.raises(GatesoptError, match=r"\(output\):\d+: the file switches an X/Y motor off"):
        run(gated.output, GatingOptions(rotate=90, bed_size_mm=BED), order=False)
