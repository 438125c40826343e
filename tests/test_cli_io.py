"""Slicer-facing I/O of `gatesopt solve`: --in-place, pipes, never overwriting, never partial files."""
from __future__ import annotations

import gzip
import os
import stat
import subprocess
import sys

from gatesopt import parse
from gatesopt.cli import main
from gatesopt.verify import verify

from conftest import PROJECT_INSTANCES

SRC = PROJECT_INSTANCES / "square_lines.gcode"


def _copy(tmp_path, name="print.gcode", mode=0o640, gz=False):
    p = tmp_path / name
    data = SRC.read_bytes()
    p.write_bytes(gzip.compress(data) if gz else data)
    p.chmod(mode)
    return p


def test_in_place_replaces_verified_and_keeps_permissions(tmp_path):
    p = _copy(tmp_path)
    assert main(["solve", "--in-place", "--rotate", "none", "--no-order", str(p)]) == 0
    assert stat.S_IMODE(p.stat().st_mode) == 0o640
    out = parse(p)
    assert "M18" in out.to_gcode()          # the file's flavor (marlin2): Marlin's lines
    assert verify(parse(SRC), out, firmware="marlin").ok
    assert sorted(x.name for x in tmp_path.iterdir()) == ["print.gcode"]     # no temp file left


def test_in_place_keeps_gzip(tmp_path):
    p = _copy(tmp_path, "print.gcode.gz", gz=True)
    assert main(["solve", "--in-place", "--rotate", "none", "--no-order", str(p)]) == 0
    assert p.read_bytes()[:2] == b"\x1f\x8b"
    assert verify(parse(SRC), parse(p), firmware="marlin").ok


def test_in_place_failure_leaves_the_original_untouched(tmp_path, capsys):
    p = tmp_path / "bad.gcode"
    p.write_text("G1 X0 F600\nG1 X1.2.3\n")
    before = p.read_bytes()
    assert main(["solve", "--in-place", str(p)]) == 2
    assert p.read_bytes() == before
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.gcode:2" in err[0]
    assert sorted(x.name for x in tmp_path.iterdir()) == ["bad.gcode"]


def test_in_place_failed_verification_leaves_the_original(tmp_path, monkeypatch, capsys):
    import dataclasses
    from gatesopt.rewrite import pipeline
    real = pipeline.run

    def broken(*a, **k):
        r = real(*a, **k)
        return dataclasses.replace(r, report=dataclasses.replace(r.report, ok=False, findings=("line 9: made up",)))
    monkeypatch.setattr(pipeline, "run", broken)
    p = _copy(tmp_path)
    before = p.read_bytes()
    assert main(["solve", "--in-place", "--rotate", "none", str(p)]) == 2
    assert p.read_bytes() == before
    assert "failed verification (line 9: made up); the input is unchanged" in capsys.readouterr().err


def test_option_combinations_are_refused(tmp_path, capsys):
    p = _copy(tmp_path)
    assert main(["solve", str(p)]) == 2                       # no -o, no --in-place
    assert main(["solve", str(p), "-o", str(p)]) == 2          # -o is the input
    assert main(["solve", "--in-place", "-", ]) == 2           # in place needs a file
    other = tmp_path / "exists.gcode"
    other.write_text("keep me")
    assert main(["solve", str(p), "-o", str(other)]) == 2      # never overwrite without --force
    assert other.read_text() == "keep me"
    assert main(["solve", str(p), "-o", str(tmp_path / "r.gcode"), "--no-gating", "--rotate", "45"]) == 2
    assert not (tmp_path / "r.gcode").exists()
    msgs = capsys.readouterr().err
    assert "--in-place" in msgs and "must not be the input" in msgs and "--force" in msgs
    assert "--rotate 45" in msgs and "--no-gating" in msgs
    assert main(["solve", str(p), "-o", str(tmp_path / "r.gcode"), "--budget", "0"]) == 2
    assert "--budget" in capsys.readouterr().err


def test_solve_gives_the_ordering_a_budget(tmp_path, monkeypatch):
    # `solve` re-orders before gating; on a large file 2 s per group without a cap took minutes
    from gatesopt.rewrite import order as ordering_pipeline
    seen = []
    real = ordering_pipeline.solve

    def spy(problem, formulation="auto", **kw):
        if formulation != "greedy":     # (the greedy solve before the exact one: its own share)
            seen.append(kw.get("budget_s"))
        return real(problem, formulation, **kw)

    monkeypatch.setattr(ordering_pipeline, "solve", spy)
    p = _copy(tmp_path)
    assert main(["solve", str(p), "-o", str(tmp_path / "a.gcode")]) == 0
    assert main(["solve", str(p), "-o", str(tmp_path / "b.gcode"), "--budget", "3"]) == 0
    # the budget covers the ordering's build and emit too: the solve gets less
    from gatesopt.rewrite.order import FINISH_FIXED_S, FINISH_S_PER_LINE
    est = FINISH_FIXED_S + FINISH_S_PER_LINE * parse(str(p)).n_lines
    assert len(seen) == 2 and seen[0] <= 10.0 - est and seen[1] <= 3.0 - est and seen[1] > 0


def test_pipes_stdin_to_stdout_messages_on_stderr():
    text = SRC.read_text()
    r = subprocess.run([sys.executable, "-m", "gatesopt", "solve", "-", "-o", "-", "--rotate", "none",
                        "--no-order"], input=text, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(text.splitlines()[0])          # G-code on stdout, nothing else
    assert "verified      yes" in r.stderr
    assert verify(parse(text), parse(r.stdout), firmware="marlin").ok


def test_determinism_same_input_same_bytes(tmp_path):
    outs = []
    for k in range(2):
        o = tmp_path / f"o{k}.gcode"
        assert main(["solve", str(SRC), "-o", str(o), "--formulation", "cpsat", "--max-added-lines-pct", "30",
                     "--time-limit", "20", "--threads", "1"]) == 0
        outs.append(o.read_bytes())
    assert outs[0] == outs[1]


def test_a_new_output_gets_the_usual_permissions(tmp_path):
    out = tmp_path / "new.gcode"
    old = os.umask(0o022)
    try:
        assert main(["solve", str(SRC), "-o", str(out), "--rotate", "none", "--no-order"]) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o644


MACH3 = """G21
G90
G28
G92 A0
G1 Z0.3 F7800
G1 X90 Y90 F7800
G1 F1800
G1 X110 Y90 A1.0
G1 X110 Y110 A2.0
G1 X90 Y110 A3.0
G1 X90 Y90 A4.0
"""


def test_a_file_with_the_extruder_on_axis_a_is_never_rewritten(tmp_path, capsys):
    # PrusaSlicer's mach3 / machinekit flavours write the extruder as A; splitting such a move for
    # gating put all its filament on the first piece (found on real slicer output): the file is
    # profiled with a warning, and every rewrite refuses it with file:line, writing nothing
    import pytest

    from gatesopt.errors import GcodeError
    from gatesopt.rewrite import run
    from gatesopt.stream import gate_stream

    src = tmp_path / "mach3.gcode"
    src.write_text(MACH3)
    prog = parse(str(src))
    assert prog.foreign_axis_lines.tolist() == [7, 8, 9, 10]
    assert any("mach3.gcode:8:" in w and "axis" in w for w in prog.warnings)
    for cmd in (["solve", str(src), "-o", str(tmp_path / "s.gcode")],
                ["solve", str(src), "-o", str(tmp_path / "s.gcode"), "--no-gating"],
                ["order", str(src), "-o", str(tmp_path / "s.gcode"), "--workers", "1"]):
        assert main(cmd) == 2
        err = capsys.readouterr().err
        assert "mach3.gcode:8: G1 X110 Y90 A1.0:" in err and "axis" in err, err
        assert not (tmp_path / "s.gcode").exists()
    with pytest.raises(GcodeError):
        run(prog, formulation="greedy", order=False)
    with pytest.raises(GcodeError, match=":8:"):
        gate_stream(src, tmp_path / "s.gcode")
    assert not (tmp_path / "s.gcode").exists()
    assert main(["profile", str(src)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mach3.gcode"]     # no temp file left
