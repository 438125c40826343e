"""The CLI says when a run's time went to compiling numba kernels (gatesopt/_jit.py), counting only
what that command compiled, on stderr."""
from __future__ import annotations

import numba
import numpy as np

from gatesopt import _jit
from gatesopt.cli import main


def test_compile_time_is_counted_and_noted_only_for_what_a_command_compiled(monkeypatch, tmp_path, capsys):
    before = _jit.compile_s()
    seed = int(np.random.default_rng().integers(1 << 30))

    @numba.njit
    def made_up(x):                 # a new function: compiled here, whatever any cache holds
        return x * 2 + seed
    assert made_up(3) == 6 + seed
    assert _jit.compile_s() > before
    assert _jit.compile_note(since_s=_jit.compile_s()) is None     # nothing compiled since
    gcode = tmp_path / "a.gcode"
    gcode.write_text("G28\nG1 X10 Y10 F3000\nG1 X20 E1 F1200\n")
    assert main(["profile", str(gcode)]) == 0       # may compile the parser (a cold cache)
    capsys.readouterr()
    assert main(["profile", str(gcode)]) == 0       # all loaded by now: nothing to say
    out = capsys.readouterr()
    assert "numba" not in out.err and "numba" not in out.out
    monkeypatch.setattr(_jit, "NOTE_MIN_S", -1.0)   # every command passes the threshold
    assert main(["profile", str(gcode)]) == 0
    out = capsys.readouterr()
    assert "gatesopt: note:" in out.err and "compiling numba kernels" in out.err
    assert "numba" not in out.out                    # stdout stays the report
