"""``verify --firmware X`` checks that the motor lines the rewrite added are X's own (gatesopt.verify
``check_firmware``): a Marlin-gated file is no Klipper file (Klipper's M18 turns every stepper off
and clears homing), nor a RepRapFirmware one (its ``M18 X`` unhomes X), S0/S1 are no stock
firmware's, SET_STEPPER_ENABLE is no Marlin's. The original's own motor lines are never checked."""
from __future__ import annotations

import dataclasses

import pytest

import gatesopt
from gatesopt import firmware as fwmod
from gatesopt.cli import main
from gatesopt.verify import check_firmware, detect_firmware, firmware_problem, verify

SRC = __import__("conftest").PROJECT_INSTANCES / "square_grid_m82.gcode"
MADE = ("3dgates", "marlin", "klipper")          # what `gatesopt solve --firmware` writes
CHECKED = tuple(fwmod.PRESETS)                   # what `gatesopt verify --firmware` takes


def _solve(src, out, fw) -> None:
    # (--motors X,Y: the test printer is cartesian; of unknown kinematics stock Klipper gates no X/Y)
    assert main(["solve", str(src), "-o", str(out), "--firmware", fw, "--rotate", "none",
                 "--no-order", "--force", "--motors", "X,Y"]) == 0


def _added(original_text: str, output_text: str) -> set[int]:
    """1-based output lines that are motor lines the original does not have."""
    own = set(original_text.splitlines())
    return {i + 1 for i, t in enumerate(output_text.splitlines())
            if t not in own and fwmod.parse_motor_line(t) is not None}


@pytest.fixture(scope="module")
def gated(tmp_path_factory):
    d = tmp_path_factory.mktemp("dialects")
    out = {}
    for fw in MADE:
        path = d / f"{fw}.gcode"
        _solve(SRC, path, fw)
        out[fw] = path
    return out


@pytest.fixture(scope="module")
def end_gcode_m18(tmp_path_factory):
    """The instance with end G-code that disables motors the Marlin way (``M18 X Y E``, ``M84``),
    gated for Klipper."""
    d = tmp_path_factory.mktemp("own")
    src = d / "own.gcode"
    src.write_text(SRC.read_text().replace("M84 X Y E ; disable motors\n",
                                           "M18 X Y E ; disable motors\nM84\n"))
    out = d / "own.klipper.gcode"
    _solve(src, out, "klipper")
    return src, out


def test_every_dialect_gates_something(gated):
    for fw, path in gated.items():
        added = _added(SRC.read_text(), path.read_text())
        assert added, fw
        words = {fwmod.parse_motor_line(path.read_text().splitlines()[i - 1]) for i in added}
        # some X or Y is gated: RepRapFirmware may gate E only
        assert any(set(m) & {"X", "Y"} for _, m in words), fw


@pytest.mark.parametrize("made", MADE)
def test_verified_for_its_own_firmware_there_is_no_finding(gated, made, capsys):
    p, q = gatesopt.parse(SRC), gatesopt.parse(gated[made])
    rep = verify(p, q, firmware=made)
    assert rep.ok, [str(f) for f in rep.findings]
    assert "firmware" in rep.checks
    assert check_firmware(q, firmware=made, original=p) == []
    capsys.readouterr()
    assert main(["verify", str(SRC), str(gated[made]), "--firmware", made]) == 0
    # --firmware auto finds the dialect as before
    assert detect_firmware(p, q) == fwmod.detect(q) == made
    assert main(["verify", str(SRC), str(gated[made])]) == 0
    assert f"(firmware: {made})" in capsys.readouterr().out


@pytest.mark.parametrize("made,checked", [(m, c) for m in MADE for c in CHECKED if c != m])
def test_verified_for_another_firmware_is_a_finding(gated, made, checked, capsys):
    p, q = gatesopt.parse(SRC), gatesopt.parse(gated[made])
    rep = verify(p, q, firmware=checked)
    assert not rep.ok
    found = [f for f in rep.findings if f.check == "firmware"]
    assert found
    text = gated[made].read_text().splitlines()
    added = _added(SRC.read_text(), gated[made].read_text())
    for f in found:
        assert not f.in_original and f.line in added          # an added line, in the output
        line = text[f.line - 1].strip()
        assert f.message.startswith(line) and checked in f.message and "\n" not in f.message
    capsys.readouterr()
    assert main(["verify", str(SRC), str(gated[made]), "--firmware", checked]) == 1
    printed = capsys.readouterr().out
    assert "FAILED" in printed and f"[firmware] line {found[0].line}: " in printed


def test_marlin_file_for_klipper_and_reprap_says_why(gated):
    p, q = gatesopt.parse(SRC), gatesopt.parse(gated["marlin"])
    kl = check_firmware(q, firmware="klipper", original=p)
    assert "not klipper's" in kl[0].message and "SET_STEPPER_ENABLE" in kl[0].message
    rr = check_firmware(q, firmware="reprap", original=p)
    assert rr and all(fwmod.PRESETS["reprap"].refused_note in f.message for f in rr)
    assert all(f.message.split()[0] == "M18" for f in rr)     # M17 (on) is not reported twice


def test_the_originals_own_motor_lines_are_not_checked(end_gcode_m18):
    src, out = end_gcode_m18
    p, q = gatesopt.parse(src), gatesopt.parse(out)
    assert verify(p, q, firmware="klipper").ok
    assert main(["verify", str(src), str(out)]) == 0
    # for Marlin, only the added SET_STEPPER_ENABLE lines are wrong, not the end G-code's M18/M84
    found = check_firmware(q, firmware="marlin", original=p)
    text = out.read_text().splitlines()
    assert found and all(text[f.line - 1].startswith("SET_STEPPER_ENABLE") for f in found)
    assert {f.line for f in found} == _added(src.read_text(), out.read_text())


def test_an_added_copy_of_an_original_line_is_checked(end_gcode_m18):
    """The original ends with ``M84``; a second ``M84`` put in mid-print is the rewrite's (and on
    Klipper turns every stepper off), though its text is the original's."""
    src, out = end_gcode_m18
    lines = out.read_text().splitlines(keepends=True)
    k = next(i for i, t in enumerate(lines) if t.startswith("SET_STEPPER_ENABLE"))
    mutated = "".join(lines[:k] + ["M84\n"] + lines[k:])
    p, q = gatesopt.parse(src), gatesopt.parse(mutated, source="mutated")
    found = check_firmware(q, firmware="klipper", original=p)
    assert [f.line for f in found] == [k + 1]
    assert not verify(p, q, firmware="klipper").ok


def test_auto_is_not_misled_by_the_originals_own_m17(tmp_path, capsys):
    """Start G-code with ``M17``: ``firmware.detect`` reads the whole output and says Marlin; the
    added lines are S-series, so ``--firmware auto`` checks for 3dgates, as the output was made."""
    src = tmp_path / "m17.gcode"
    src.write_text(SRC.read_text().replace("G28", "M17 ; enable all steppers\nG28", 1))
    out = tmp_path / "m17.3dgates.gcode"
    _solve(src, out, "3dgates")
    p, q = gatesopt.parse(src), gatesopt.parse(out)
    assert fwmod.detect(q) == "marlin"
    assert detect_firmware(p, q) == "3dgates"
    capsys.readouterr()
    assert main(["verify", str(src), str(out)]) == 0
    assert "(firmware: 3dgates)" in capsys.readouterr().out
    assert main(["verify", str(src), str(out), "--firmware", "marlin"]) == 1


def test_each_presets_own_lines_pass_and_the_others_do_not():
    for name, fw in fwmod.PRESETS.items():
        motors = sorted(fw.allowed_motors, key=fwmod.AXES.index)
        for line in fw.off_lines(motors) + fw.on_lines(motors):
            assert firmware_problem(line, name) is None, (name, line)
        for other, ofw in fwmod.PRESETS.items():
            if {ofw.off_word, ofw.on_word} == {fw.off_word, fw.on_word}:
                continue                                      # marlin and reprap share M17/M18
            for line in ofw.off_lines(["E"]) + ofw.on_lines(["E"]):
                assert firmware_problem(line, name), (name, line)


def test_firmware_problem_reads_gatesopt_firmware(monkeypatch):
    assert firmware_problem("M18 E", "reprap") is None
    assert "may not gate" in firmware_problem("M18 X E ; gate", "reprap")
    assert firmware_problem("M84 X", "marlin") is None            # M84 is M18 on Marlin
    assert "not klipper's" in firmware_problem("M84 X", "klipper")
    assert firmware_problem("M18 S30", "klipper") is None          # idle timeout, no motor line
    assert firmware_problem("G1 X10", "klipper") is None
    # the rules are the presets': a Marlin that unhomed on M18 would refuse X, keep E
    monkeypatch.setitem(fwmod.PRESETS, "marlin",
                        dataclasses.replace(fwmod.PRESETS["marlin"], homing_kept=False))
    assert "homed" in firmware_problem("M18 X", "marlin")
    assert firmware_problem("M18 E", "marlin") is None
