"""The independent verifier catches broken outputs (gatesopt.verify)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import gatesopt
from gatesopt.gating.emit import Switch, render_switches
from gatesopt.verify import Finding, energy_of, verify

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
    # on Klipper the first step re-enables the motor by itself: not a finding
    assert "steps while off" not in " ".join(f.message for f in verify(p, gatesopt.parse(broken),
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
    q = gatesopt.parse(render(p, [], rotate_deg=33, center_mm=(10, 10)).text)
    rep = verify(p, q)
    assert rep.ok, [str(f) for f in rep.findings]
    assert rep.rotate_deg == 33


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
                     "--rotate", "none", "--no-order"]) == 0
        capsys.readouterr()
        assert main(["verify", str(src), str(out)]) == 0
        assert f"(firmware: {fw})" in capsys.readouterr().out
