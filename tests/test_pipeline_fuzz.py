"""Whole-pipeline fuzzing: random valid programs through every formulation, every output verified;
mutated real files give a clear error or a verified output, never a traceback or a partial file."""
from __future__ import annotations

import math
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatesopt import parse
from gatesopt.cli import main
from gatesopt.rewrite import run
from gatesopt.gating import GatingOptions

from conftest import PROJECT_INSTANCES


@st.composite
def programs(draw):
    """A small but complete print: start code, layers of curves and travels, end code, written
    with the modal switches real files use."""
    absolute_e = draw(st.booleans())
    lines = ["G21", "G90", "M82" if absolute_e else "M83", "M104 S200", "M109 S200", "G28", "G92 E0"]
    e = 0.0
    x, y = 100.0, 100.0
    zhop = draw(st.sampled_from([0.0, 0.4]))
    n_layers = draw(st.integers(1, 3))

    def ext(dx_e):
        nonlocal e
        e += dx_e
        return f"E{e:.5f}" if absolute_e else f"E{dx_e:.5f}"

    for layer in range(n_layers):
        z = 0.2 * (layer + 1)
        lines += [";LAYER_CHANGE", f";Z:{z:.1f}", f"G1 Z{z:.3f} F600"]
        if layer == 1:
            lines.append("M106 S255")
        if draw(st.booleans()) and not absolute_e:
            lines.append("G92 E0")
        for _ in range(draw(st.integers(1, 4))):
            # travel (retract, optional hop, move, unretract)
            tx, ty = draw(st.floats(80, 120)), draw(st.floats(80, 120))
            lines.append(f"G1 {ext(-0.8)} F2100")
            if zhop:
                lines.append(f"G1 Z{z + zhop:.3f} F600")
            lines.append(f"G1 X{tx:.3f} Y{ty:.3f} F9000")
            if zhop:
                lines.append(f"G1 Z{z:.3f} F600")
            lines.append(f"G1 {ext(0.8)} F2100")
            x, y = tx, ty
            lines.append("G1 F1800")
            kind = draw(st.sampled_from(["axis", "diagonal", "arc", "relative"]))
            for _ in range(draw(st.integers(1, 5))):
                if kind == "axis":              # single-axis moves: what gating feeds on
                    if draw(st.booleans()):
                        nx, ny = draw(st.floats(80, 120)), y
                    else:
                        nx, ny = x, draw(st.floats(80, 120))
                    d = math.hypot(nx - x, ny - y)
                    lines.append(f"G1 X{nx:.3f} Y{ny:.3f} {ext(0.033 * d)}")
                elif kind == "diagonal":
                    nx, ny = draw(st.floats(80, 120)), draw(st.floats(80, 120))
                    d = math.hypot(nx - x, ny - y)
                    lines.append(f"G1 X{nx:.3f} Y{ny:.3f} {ext(0.033 * d)}")
                elif kind == "arc":             # a half circle around a centre to the right
                    r = draw(st.floats(1, 8))
                    nx, ny = x + 2 * r, y
                    lines.append(f"G2 X{nx:.3f} Y{ny:.3f} I{r:.3f} J0 {ext(0.033 * math.pi * r)}")
                else:                           # relative XY moves inside G91
                    dx = draw(st.floats(-10, 10))
                    lines.append("G91")
                    if absolute_e:
                        lines.append("M82")
                    # in G91 Marlin makes E relative too unless M82 follows; write what applies
                    de = 0.033 * abs(dx)
                    if absolute_e:
                        e += de
                        lines.append(f"G1 X{dx:.3f} E{e:.5f}")
                    else:
                        lines.append(f"G1 X{dx:.3f} E{de:.5f}")
                    lines.append("G90")
                    if not absolute_e:
                        lines.append("M83")
                    else:
                        lines.append("M82")
                    nx, ny = float(f"{x + dx:.3f}"), y
                x, y = nx, ny
    lines += [f"G1 {ext(-0.8)} F2100", "G1 Z10 F600", "M104 S0", "M107", "M84"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("formulation", ["greedy", "dp", "milp", "cpsat"])
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(text=programs(), firmware=st.sampled_from(["3dgates", "marlin", "klipper"]),
       rotate=st.sampled_from(["none", "auto"]), order=st.booleans())
def test_every_formulation_gives_a_verified_output(formulation, text, firmware, rotate, order):
    program = parse(text)
    budget = {"max_added_time_pct": 5.0} if firmware != "3dgates" and formulation in ("milp", "cpsat") else {}
    opts = GatingOptions.for_firmware(firmware, rotate=rotate, num_workers=1, bed_size_mm=(250, 250), **budget)
    res = run(program, opts, formulation=formulation, time_limit_s=10.0, order=order)
    assert res.report.ok, [str(f) for f in res.report.findings[:3]]
    assert res.report.energy_j <= res.report.energy_before_j + 1e-6 or firmware != "3dgates"


# ------------------------------------------------------------------------------------------------
def _mutations(data: bytes, rng: random.Random) -> list[tuple[str, bytes]]:
    lines = data.splitlines(keepends=True)
    k = rng.randrange(len(lines))
    out = [
        ("truncated mid-line", data[:rng.randrange(len(data) // 4, len(data))]),
        ("garbage bytes", data[:k * 10] + bytes(rng.randrange(256) for _ in range(40)) + data[k * 10:]),
        ("duplicated lines", b"".join(lines[:k] + lines[k:k + 20] * 2 + lines[k + 20:])),
        ("deleted lines", b"".join(lines[:k] + lines[k + 15:])),
        ("huge number", data.replace(b"X1", b"X1999999", 1)),
        ("NUL byte", data[:k] + b"\x00" + data[k:]),
        ("binary G-code", b"GCDE" + data[4:]),
    ]
    return out


@pytest.mark.parametrize("seed", range(3))
def test_mutated_real_files_give_a_clear_error_or_a_verified_output(tmp_path, capsys, seed):
    from gatesopt.verify import verify
    data = (PROJECT_INSTANCES / "star_triangles.gcode").read_bytes()
    rng = random.Random(seed)
    for name, mutated in _mutations(data, rng):
        src = tmp_path / "in.gcode"
        out = tmp_path / "out.gcode"
        src.write_bytes(mutated)
        if out.exists():
            out.unlink()
        code = main(["solve", str(src), "-o", str(out), "--rotate", "none", "--time-limit", "10"])
        err = capsys.readouterr().err.strip()
        if code == 0:
            assert verify(parse(src), parse(out), firmware="marlin").ok, name     # the file's flavor
        else:
            assert code in (1, 2), name
            assert err.splitlines()[0].startswith("gatesopt: error:"), (name, err)
            assert not out.exists(), f"{name}: a partial output was left"
        leftovers = [p.name for p in tmp_path.iterdir() if p.name not in ("in.gcode", "out.gcode")]
        assert not leftovers, (name, leftovers)


def test_ctrl_c_during_an_exact_solve_still_gives_a_verified_answer(monkeypatch):
    from gatesopt.rewrite import pipeline
    real = pipeline.solve

    def interrupted(problem, formulation, **kw):
        if formulation != "dp":
            raise KeyboardInterrupt
        return real(problem, formulation, **kw)
    monkeypatch.setattr(pipeline, "solve", interrupted)
    program = parse(PROJECT_INSTANCES / "square_lines.gcode")
    opts = GatingOptions.for_firmware("marlin", max_added_time_pct=1.0, rotate="none")
    res = run(program, opts, formulation="milp", order=False)
    assert res.report.ok
    assert res.solution.status == "fallback"
    assert any("interrupted" in n for n in res.notes)
    assert res.report.energy_j < res.report.energy_before_j


def test_ctrl_c_during_ordering_keeps_the_slicer_order(monkeypatch):
    from gatesopt.rewrite import order as ordering_pipeline

    def interrupted(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(ordering_pipeline, "solve", interrupted)
    program = parse(PROJECT_INSTANCES / "square_lines.gcode")
    res = run(program, GatingOptions(rotate="none"), formulation="dp", order=True)
    assert res.report.ok and not res.ordered
    assert any("slicer's order kept" in n for n in res.notes)
