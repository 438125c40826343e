"""A file's *own* motor lines (a start G-code ``M17``, an ``M84`` before the print, a closing
``M18 X``) under every firmware preset: the solver's claimed energy and time must be what the
verifier recomputes from the text, because both take a motor line's stall from the one function,
``gatesopt.firmware.stall_durations``.

What the firmware really does with such a line decides its stall: Klipper has no ``M17``
(klippy/gcode.py ``cmd_default``: 'Unknown command:"M17"', skipped) but dwells on its own ``M18`` /
``M84`` (klippy/extras/stepper_enable.py) and on ``SET_STEPPER_ENABLE``; Marlin and RepRapFirmware
drain the queue on ``M18`` / ``M84`` and know no ``SET_STEPPER_ENABLE``; the 3DGates patch never
stalls. Regression: ``gatesopt solve --firmware klipper`` on a file with ``M17`` after ``G28`` failed
its own verification (the verifier charged 0.22 s of Klipper stall for the M17, the solver nothing).
"""
from __future__ import annotations

import pytest

from gatesopt import Kind, parse
from gatesopt import firmware as fwmod
from gatesopt.cli import main
from gatesopt.rewrite import run
from gatesopt.gating import GatingOptions, build
from gatesopt.verify import energy_of, verify

PRESETS = tuple(fwmod.PRESETS)          # 3dgates, marlin, klipper, reprap
MADE = ("3dgates", "marlin", "klipper")  # what `gatesopt solve --firmware` writes


def make_gcode(start=(), end=("M84",), layers=4) -> str:
    """A small print: home, ``start`` lines, a purge line, ``layers`` layers of a 20 mm square and
    a few infill lines (single-axis travels between them: something to gate on every preset), a
    2 s pause per layer (worth a Klipper stall), then the end G-code with ``end`` last."""
    out = ["; test print", "G21", "G90", "M82", "M104 S215", "M140 S60", "G28", *start,
           "G92 E0", "G1 Z0.3 F720", "G1 X5 Y5 F9000", "G1 X5 Y100 E5 F1200", "G92 E0"]
    e = 0.0
    for k in range(layers):
        out += [f";LAYER:{k}", f"G1 Z{0.2 * (k + 1):.2f} F720", "G1 X100 Y100 F9000"]
        for x, y in ((120, 100), (120, 120), (100, 120), (100, 100)):
            e += 0.8
            out.append(f"G1 X{x} Y{y} E{e:.5f} F1800")
        out += [f"G1 E{e - 0.8:.5f} F2100", "G1 X102 Y102 F9000", f"G1 E{e:.5f} F2100"]
        for i in range(4):
            y = 102 + 5 * i
            e += 0.7
            out += [f"G1 X118 Y{y} E{e:.5f} F3000", f"G1 X118 Y{y + 2.5} F9000"]
            e += 0.7
            out += [f"G1 X102 Y{y + 2.5} E{e:.5f} F3000", f"G1 X102 Y{y + 5} F9000"]
        out.append("G4 P2000")
    out += [f"G1 E{e - 1:.5f} F2100", "G1 Z20 F720", "G1 X0 Y200 F3000", "M104 S0", "M140 S0", *end]
    return "\n".join(out) + "\n"


def _options(fw: str, **kw) -> GatingOptions:
    # RepRapFirmware may gate E only (its M18 X unhomes X)
    motors = ("E",) if fw == "reprap" else ("X", "Y")
    return GatingOptions.for_firmware(fw, motors=motors, **kw)


def _solve_and_check(text: str, fw: str, **kw):
    """Solve ``text`` for ``fw`` through the library; the claim must be the verifier's numbers."""
    res = run(parse(text, source="own-lines"), _options(fw, **kw), order=False)
    sol, rep = res.solution, res.report
    assert sol.lines_added > 0, "nothing gated: the test would prove nothing"
    # split points are written to 0.01 um (emit DECIMALS_SPLIT_MM): a split move runs ~1e-8 s off the
    # model, within the verifier's CLAIM_REL_TOL (1e-6)
    assert sol.energy_j == pytest.approx(rep.energy_j, rel=1e-8, abs=0), (fw, [str(f) for f in rep.findings])
    assert sol.time_after_s == pytest.approx(rep.time_s, rel=1e-9, abs=0), fw
    assert rep.ok, (fw, [str(f) for f in rep.findings])
    # and the independent verifier, run again from the two texts alone
    again = verify(parse(text), parse(res.text), firmware=fw, claimed=(sol.energy_j, sol.time_after_s))
    assert again.ok, (fw, [str(f) for f in again.findings])
    return res


def _motor_stalls(text: str, fw: str) -> dict[str, float]:
    p = parse(text)
    stall = fwmod.stall_durations(p, fw)
    rows = [int(r) for r in (p.kind == Kind.MOTOR).nonzero()[0]]
    return {p.line_text(int(p.line[r])).strip(): float(stall[r]) for r in rows}


# ------------------------------------------------------------------------------------------------
def test_each_firmware_stalls_only_on_motor_lines_it_carries_out():
    text = make_gcode(start=("M17", "SET_STEPPER_ENABLE STEPPER=stepper_z ENABLE=0",
                             "SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=1", "M84 X", "S1 X Y"),
                      end=("M84",))
    k = fwmod.get("klipper").stall_off_s
    k_on = fwmod.get("klipper").stall_on_s
    m = fwmod.get("marlin").stall_off_s
    want = {
        # Klipper: M17 is an unknown command (no dwell); SET_STEPPER_ENABLE ENABLE=0 and M18/M84
        # (stepper_enable.py motor_off) dwell, ENABLE=1 flushes the look-ahead; S-series unknown
        "klipper": [0.0, k, k_on, k, 0.0],
        # Marlin / RepRapFirmware: M17 enables at once, M18/M84 drain the queue; the other
        # dialects' lines are unknown commands
        "marlin": [0.0, 0.0, 0.0, m, 0.0],
        "reprap": [0.0, 0.0, 0.0, m, 0.0],
        "3dgates": [0.0, 0.0, 0.0, 0.0, 0.0],
    }
    for fw, expect in want.items():
        got = _motor_stalls(text, fw)
        assert [got[t] for t in ("M17", "SET_STEPPER_ENABLE STEPPER=stepper_z ENABLE=0",
                                 "SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=1", "M84 X", "S1 X Y")] \
            == pytest.approx(expect), fw
        assert got["M84"] == 0.0, fw          # after the last move: the print is over


def test_klipper_m17_adds_no_stall_to_the_print():
    plain = energy_of(parse(make_gcode()), firmware="klipper")
    with_m17 = energy_of(parse(make_gcode(start=("M17",))), firmware="klipper")
    assert with_m17[2] == 0.0 and with_m17[1] == pytest.approx(plain[1], rel=1e-12)


@pytest.mark.parametrize("fw", PRESETS)
def test_original_m17_and_closing_m84_claim_is_what_verify_recomputes(fw):
    _solve_and_check(make_gcode(start=("M17",), end=("M84",)), fw)


@pytest.mark.parametrize("fw", PRESETS)
@pytest.mark.parametrize("line", ["M84", "M18", "M18 X", "M17 X Y"])
def test_original_motor_line_in_start_gcode_is_priced_alike(fw, line):
    """A start G-code line that stalls the firmware (Marlin's M18 drains the queue, Klipper's M84
    dwells): the solver's own numbers, before and after, include that stall as the verifier does."""
    text = make_gcode(start=(line,), end=("M104 S0", "M84"))
    res = _solve_and_check(text, fw, rotate="none")
    # without a rotation the solver gates the original itself: its "before" is the verifier's
    assert res.solution.energy_before_j == pytest.approx(res.report.energy_before_j, rel=1e-12, abs=0)
    assert res.solution.problem.time_before_s == pytest.approx(res.report.time_before_s, rel=1e-12, abs=0)


@pytest.mark.parametrize("fw", PRESETS)
def test_rotated_solve_with_original_m17_and_m84_verifies(fw):
    _solve_and_check(make_gcode(start=("M17", "M84"), end=("M84",)), fw, rotate=30.0, bed_size_mm=(220, 220))


@pytest.mark.parametrize("fw", PRESETS)
@pytest.mark.parametrize("enable", ["0", "1"])
def test_original_set_stepper_enable_on_every_firmware(fw, enable):
    line = f"SET_STEPPER_ENABLE STEPPER=stepper_z ENABLE={enable}"
    _solve_and_check(make_gcode(start=(line,), end=("M84",)), fw)


@pytest.mark.parametrize("fw, end", [("marlin", "M18 X"), ("marlin", "M18 Y"), ("reprap", "M18 E"),
                                     ("marlin", "M18 X Y E"), ("klipper", "M18 X Y E")])
def test_original_line_with_the_very_text_gating_writes(fw, end):
    """Marlin gating writes ``M18 X``; an ``M18 X`` of the file's own is still told apart from the
    copies gating added (by where it stands, not by its text)."""
    _solve_and_check(make_gcode(end=(end, "M84")), fw)


@pytest.mark.parametrize("fw", ["marlin", "reprap"])
def test_no_interval_spans_the_files_own_m17(fw):
    """E, idle from the file's start to its first extrusion, may be switched off at the start
    (where Marlin's stop costs nothing: no move before it) -- but the start G-code's own ``M17``
    enables every motor on the way, so an off line before it switches nothing off for the rest of
    the interval. Regression: ``--motors E`` on Marlin put ``M18 E`` before ``G28`` / ``M17`` and
    claimed E off until its ``M17 E``; the verifier counted E on from the ``M17``, the solve failed
    its own verification (claim 1280.796 J, recomputed 1280.844 J). Each interval now ends before a
    line where the firmware switches its motor itself (``gating.problem._barrier_cum``)."""
    text = make_gcode(start=("M17",), end=("M84",))
    prog = parse(text)
    opts = GatingOptions.for_firmware(fw, motors=("E",))
    prob = build(prog, opts)
    own_m17 = [r for r in (prog.kind == Kind.MOTOR).nonzero()[0]
               if prog.line_text(int(prog.line[r])).strip() == "M17"]
    assert len(own_m17) == 1
    r17 = int(own_m17[0])
    spans = (prob.idle_prev_row < r17) & (prob.idle_next_row > r17)
    assert not spans.any(), "an idle interval across the file's own M17"
    res = run(prog, opts, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]
    assert res.solution.energy_j == pytest.approx(res.report.energy_j, rel=1e-8, abs=0)


@pytest.mark.parametrize("formulation", ["greedy", "dp", "milp", "cpsat"])
def test_every_formulation_claims_the_verified_energy_with_klipper_m17(formulation):
    text = make_gcode(start=("M17", "M84"), end=("M84",))
    opts = _options("klipper", rotate="none", num_workers=1, max_added_time_pct=5.0)
    res = run(parse(text), opts, formulation=formulation, time_limit_s=10.0, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]
    assert res.solution.energy_j == pytest.approx(res.report.energy_j, rel=1e-8, abs=0)   # split points
    assert "!=" not in res.solution.message        # milp: its model's energy is the scored one


@pytest.mark.parametrize("fw", MADE)
def test_cli_solve_with_start_m17_verifies(tmp_path, capsys, fw):
    """The reported case, through the command line: ``gatesopt solve --firmware klipper`` on a
    file whose start G-code has ``M17`` after ``G28``."""
    src, out = tmp_path / "m17.gcode", tmp_path / f"out.{fw}.gcode"
    src.write_text(make_gcode(start=("M17",), end=("M84 ; disable motors",)))
    assert main(["solve", str(src), "-o", str(out), "--firmware", fw, "--force"]) == 0
    assert out.exists()
    assert main(["verify", str(src), str(out), "--firmware", fw]) == 0
    capsys.readouterr()


def test_closing_disable_is_not_inside_the_print():
    """Cura's closing 'M84 X Y E' after the last move switches nothing off that steps again: the
    file is not 'already gated' and may be rotated; an 'M18 X' between moves is."""
    from gatesopt.gating.rotation import own_xy_disable
    head = "G90\nM82\nG92 E0\n;LAYER:0\nG1 Z0.2 F600\nG0 X10 Y10 F6000\nG1 X20 Y10 E1 F1200\n"
    closing = parse(head + "G1 X20 Y20 E2\nG91\nG1 Z5\nG90\nM84 X Y E\n")
    assert own_xy_disable(closing, 0, closing.n_steps) is None
    inside = parse(head + "M18 X\nG1 X20 Y20 E2\nG1 X30 Y20 E3\nM84 X Y E\n")
    row = own_xy_disable(inside, 0, inside.n_steps)
    assert row is not None and inside.line_text(int(inside.line[row])).startswith("M18 X")
