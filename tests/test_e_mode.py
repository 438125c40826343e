"""A file that extrudes before any M82/M83 (Kiri:Moto leaves the mode to the printer's start
macro) is read in the E mode its words make sense in, and said so: read as absolute, a relative
file's extrusions look like travels, and a re-ordered output printed half the part (found on
real_kirimoto30: 101.6 of 224.9 mm of filament)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gatesopt import parse_text
from gatesopt.energy import profile
from gatesopt.stream import profile_stream


def _zigzag(n: int, relative: bool, declare: str = "") -> str:
    """A layer of ``n`` 10 mm extrusions with a 2 mm retraction around a travel every 10 moves."""
    lines = ["print_start", declare, "G1 Z0.2 F600"] if declare else ["print_start", "G1 Z0.2 F600"]
    e = 0.0
    for i in range(n):
        if i % 10 == 0:
            lines += [f"G1 E{-2.0 if relative else e - 2.0:.4f} F2400",
                      f"G1 X{i * 2.0:.1f} Y0 F6000", f"G1 E{2.0 if relative else e:.4f} F2400"]
        de = 0.33 + 0.01 * (i % 3)
        e += de
        lines.append(f"G1 X{i * 2.0:.1f} Y{10.0 if i % 2 == 0 else 0.0} E{de if relative else e:.4f} F1800")
    return "\n".join(lines) + "\n"


def _extruded_mm(prog) -> float:
    de = prog.end_mm[:, 3] - prog.start_mm[:, 3]
    xy = np.hypot(*(prog.end_mm[:, :2] - prog.start_mm[:, :2]).T)
    return float(de[(de > 0) & (xy > 0)].sum())


def test_undeclared_relative_file_is_read_relative_and_said():
    prog = parse_text(_zigzag(60, relative=True), source="kiri.gcode")
    assert prog.relative_e.all()
    assert math.isclose(_extruded_mm(prog), sum(0.33 + 0.01 * (i % 3) for i in range(60)), rel_tol=1e-9)
    said = [w for w in prog.warnings if "M82/M83" in w]
    assert len(said) == 1 and said[0].startswith("kiri.gcode:") and "relative E (M83)" in said[0]


@pytest.mark.parametrize("declare", ["", "M82"])
def test_absolute_file_stays_absolute_without_a_word(declare):
    prog = parse_text(_zigzag(60, relative=False, declare=declare), source="abs.gcode")
    assert not prog.relative_e.any()
    assert not [w for w in prog.warnings if "M82/M83" in w]


def test_a_declared_mode_is_never_second_guessed():
    """M82 said before the first extrusion wins, whatever the words look like (the firmware does
    what the file says)."""
    prog = parse_text(_zigzag(60, relative=True, declare="M82"), source="x.gcode")
    assert not prog.relative_e.any()
    assert not [w for w in prog.warnings if "M82/M83" in w]


def test_the_stream_reads_the_same_mode(tmp_path):
    path = tmp_path / "kiri.gcode"
    path.write_text(_zigzag(60, relative=True))
    whole = profile(parse_text(path.read_text(), source=str(path)))
    as_absolute = profile(parse_text("M82\n" + path.read_text(), source=str(path)))
    report = profile_stream(path, chunk_bytes=1 << 10)
    assert any("M82/M83" in w for w in report.warnings)
    assert math.isclose(report.energy_j, whole.energy_j, rel_tol=1e-6)
    assert not math.isclose(report.energy_j, as_absolute.energy_j, rel_tol=1e-3)
