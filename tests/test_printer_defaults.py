"""Defaults that fit the file's printer (issue 37): the firmware is read from the file (slicer
flavor settings, printer models, Klipper commands; ``gatesopt.slicers``) and said in one line; the
paper's S0/S1 only by name; stock firmware gets a time budget; M18 is never written for a Klipper
file unless forced by name."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

import gatesopt
from gatesopt import firmware, kinematics, slicers
from gatesopt.cli import main
from gatesopt.rewrite import printer

from conftest import SHARED_INSTANCES, read_bytes, shared_params

FRESH = SHARED_INSTANCES.parent.parent / "fresh"


def square(header: str = "", start: str = "", layers: int = 3) -> str:
    """A 40 mm square with lines across it, ``header`` on top and ``start`` as start G-code."""
    out = [header, "G21", "G90", "M82", "M104 S200", "G28", start, "G92 E0"]
    e = 0.0
    for k in range(layers):
        out += [";LAYER:%d" % k, f"G1 Z{0.2 * (k + 1):.1f} F600", "G1 X80 Y80 F6000"]
        for i in range(8):
            y = 80 + 5 * i
            e += 1.3
            out += [f"G1 X120 Y{y} E{e:.4f} F1800", f"G1 X120 Y{y + 2.5} F6000"]
            e += 1.3
            out += [f"G1 X80 Y{y + 2.5} E{e:.4f} F1800", f"G1 X80 Y{y + 5} F6000"]
    out += ["M104 S0", "M84 X Y E"]
    return "\n".join(line for line in out if line) + "\n"


# -- the table ------------------------------------------------------------------------------------
EXPECTED_FAMILY = {";FLAVOR:Marlin": "marlin", "; gcode_flavor = marlin2": "marlin",
                   ";Firmware: RepRapFirmware": "reprapfirmware",
                   ";   firmwareTypeOverride,RepRap (Marlin/Repetier/Sprinter)": "marlin",
                   "; firmware_type = 1": ""}


@pytest.mark.parametrize("row", slicers.FLAVOR_SETTINGS, ids=lambda r: r.slicer)
def test_every_flavor_setting_row_reads_its_example(row):
    ev = slicers.flavor_evidence(("; something\n" + row.example + "\n").encode())
    assert ev is not None and ev.line == 2 and ev.text == row.example.strip()
    assert ev.family == EXPECTED_FAMILY[row.example]


@pytest.mark.parametrize("value, family", [("Marlin", "marlin"), ("Marlin(Volumetric)", "marlin"),
                                           ("RepRap", "reprapfirmware"), ("Griffin", "other"),
                                           ("UltiGCode", "other")])
def test_cura_flavours(value, family):
    assert slicers.flavor_evidence(f";FLAVOR:{value}\n".encode()).family == family


@pytest.mark.parametrize("value, family", [("marlin", "marlin"), ("marlin2", "marlin"), ("klipper", "klipper"),
                                           ("reprapfirmware", "reprapfirmware"), ("reprap", "marlin"),
                                           ("smoothie", "other"), ("repetier", "other")])
def test_prusaslicer_flavours(value, family):
    # 'reprap' is Slic3r's "RepRap (Marlin/Sprinter)"; RepRapFirmware is 'reprapfirmware'
    assert slicers.flavor_evidence(f"; gcode_flavor = {value}\n".encode()).family == family


def test_a_klipper_command_wins_over_a_marlin_flavor_and_says_its_line():
    text = square(";FLAVOR:Marlin", start="START_PRINT EXTRUDER_TEMP=200 BED_TEMP=60")
    facts = slicers.read_printer(text.encode())
    assert facts.firmware.family == "klipper" and facts.firmware.kind == "Klipper command"
    assert facts.firmware.line == text.splitlines().index("START_PRINT EXTRUDER_TEMP=200 BED_TEMP=60") + 1
    assert facts.flavor == "Marlin"
    # a Klipper command only as a comment, or a word without an underscore, is no evidence
    for start in ("; START_PRINT", "PAUSE", "M486 S1", "G1X10Y10"):
        assert slicers.read_printer(square(";FLAVOR:Marlin", start=start).encode()).firmware.family == "marlin"


def test_a_printer_model_that_runs_klipper():
    data = b"; gcode_flavor = marlin\n; printer_model = Voron_v2_250\n"
    assert slicers.read_printer(data).firmware.family == "klipper"
    assert slicers.read_printer(b"; printer_model = Bambu Lab X1 Carbon\n").firmware.family == "bambu"
    assert slicers.read_printer(b";TARGET_MACHINE.NAME:Creality K1 Max\n").firmware.family == "klipper"


#: where the file says more than the manifest's flavor column: ideaMaker's printer setting
#: ';Firmware: RepRapFirmware' (line 18), which the column (filled from PrusaSlicer/Cura headers) left out
MANIFEST_MISSES = {"real_ideamaker514.gcode.gz": "RepRapFirmware"}


def _manifest_flavor(row: dict) -> str:
    f = MANIFEST_MISSES.get(row["file"], row["flavor"])
    return f.split("_fw")[1] if f.startswith("kisslicer_fw") else f   # KISSlicer: firmware_type = 1


@pytest.mark.parametrize("path", shared_params())
def test_every_corpus_file_flavor_is_the_manifest_s(path):
    from conftest import manifest
    row = manifest()[path.name]
    facts = slicers.read_printer(read_bytes(path))
    assert facts.flavor == _manifest_flavor(row)
    choice = printer.choose(read_bytes(path))
    # the paper's S0/S1 never by default; a Klipper file never gets M18
    assert choice.firmware != "3dgates"
    if facts.firmware and facts.firmware.family == "klipper":
        assert choice.firmware == "klipper"
    if row["flavor"] in ("klipper",):
        assert facts.firmware.family == "klipper"


#: what each fresh slice's printer runs: the job's printer profile (bench/fresh_slices.py)
FRESH_DIALECT = {"cura_ender3": "marlin", "cura_mk3": "marlin", "prusa_mk3s": "marlin", "slic3r": "marlin",
                 "prusa_klipper": "klipper"}


def _fresh_rows():
    if not (FRESH / "manifest.tsv").exists():
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"no fresh slices at {FRESH}"))]
    with open(FRESH / "manifest.tsv", newline="") as f:
        return [pytest.param(r, id=r["file"]) for r in csv.DictReader(f, delimiter="\t")]


@pytest.mark.parametrize("row", _fresh_rows())
def test_every_fresh_file_gets_its_printer_s_dialect(row):
    data = (FRESH / row["file"]).read_bytes()
    facts = slicers.read_printer(data)
    settings = row["settings"]
    if "machine_gcode_flavor=RepRap (Marlin/Sprinter)" in settings:
        assert facts.flavor == "Marlin"                       # CuraEngine's name for it
    elif m := re.search(r"flavor (\w+)", settings):
        assert facts.flavor == m.group(1)
    else:
        assert facts.flavor == "reprap"                       # Slic3r's default, RepRap (Marlin/Sprinter)
    job = next(j for j in FRESH_DIALECT if row["file"].endswith(f"__{j}.gcode") or f"__{j}_" in row["file"])
    choice = printer.choose(data)
    assert choice.firmware == FRESH_DIALECT[job]
    assert f"(line {facts.firmware.line})" in choice.line
    if job == "prusa_klipper":
        # PrusaSlicer's Voron 2.4 profile: corexy, so X and Y are not gated and nothing is
        assert kinematics.model_kinematics(data).name == "corexy"
        assert choice.options is None and choice.motors == () and "nothing is gated" in choice.line
        return
    assert choice.max_added_time_pct == printer.STOCK_BUDGET_PCT and choice.budget_is_default


# -- the choice -----------------------------------------------------------------------------------
def test_a_marlin_flavor_gets_marlin_lines_and_a_budget_said_in_one_line():
    c = printer.choose(gatesopt.parse(square(";FLAVOR:Marlin")))
    assert c.firmware == "marlin" and c.max_added_time_pct == 1.0 and c.options.max_added_time_pct == 1.0
    assert "\n" not in c.line
    assert c.line.startswith("marlin: read flavor setting ';FLAVOR:Marlin' (line 1)")
    assert "the print takes at most 1 % longer than as sliced" in c.line


def test_nothing_known_says_what_was_assumed_and_how_to_choose():
    c = printer.choose(gatesopt.parse(square()))
    assert c.firmware == "marlin"
    assert c.line.startswith("marlin assumed: the file names no firmware") and "--firmware" in c.line


def test_the_paper_s_lines_only_by_name():
    c = printer.choose(gatesopt.parse(square(";FLAVOR:Marlin")), "3dgates")
    assert c.firmware == "3dgates" and c.max_added_time_pct is None       # no stall: no budget
    assert "only by the paper's patched firmware" in c.line


def test_m18_for_a_klipper_file_is_refused_unless_forced_by_name():
    prog = gatesopt.parse(square(";FLAVOR:Marlin", start="START_PRINT"))
    assert printer.choose(prog).firmware == "klipper"
    with pytest.raises(firmware.FirmwareError, match=r"<text>:\d+: the file is for klipper .*stops the print"):
        printer.choose(prog, "marlin")
    assert printer.choose(prog, "marlin", force=True).firmware == "marlin"


def test_reprapfirmware_gates_e_only_and_unknown_firmware_is_not_gated():
    c = printer.choose(gatesopt.parse(square(";FLAVOR:RepRap")))
    assert c.firmware == "reprap" and c.motors == ("E",) and "gates E only" in c.line
    bambu = printer.choose(gatesopt.parse(square("; printer_model = Bambu Lab P1S")))
    assert bambu.firmware is None and bambu.options is None and "nothing is gated" in bambu.line


def test_an_explicit_budget_or_none_replaces_the_default():
    prog = gatesopt.parse(square(";FLAVOR:Marlin"))
    assert printer.choose(prog, max_added_time_pct=None).options.max_added_time_pct is None
    assert printer.choose(prog, max_added_time_pct=3.0).max_added_time_pct == 3.0


# -- the command line -----------------------------------------------------------------------------
def test_solve_of_a_marlin_file_writes_m18_and_says_so(tmp_path, capsys):
    src = tmp_path / "part.gcode"
    src.write_text(square(";FLAVOR:Marlin"))
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--json", str(tmp_path / "r.json")]) == 0
    text = out.read_text()
    assert "M18 " in text and not re.search(r"(?m)^S[01] ", text)
    printed = capsys.readouterr().out
    assert "firmware      marlin: read flavor setting ';FLAVOR:Marlin' (line 1)" in printed
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["firmware"] == "marlin" and d["firmware_choice"]["max_added_time_pct"] == 1.0
    assert d["added_time_pct"] <= 1.0 + 1e-6
    assert main(["verify", str(src), str(out)]) == 0


def test_verify_checks_a_reprapfirmware_output_as_reprapfirmware_s(tmp_path, capsys):
    # RepRapFirmware's M18 E / M17 E read as Marlin's too: verify takes the dialect the file
    # names, as solve did, and so reports solve's saving (a RepRap-flavour Cura file: verify said
    # marlin, 0.33 %, against solve's reprap, 0.32 %)
    src = tmp_path / "part.gcode"
    # (slow travels between the layers: an idle extruder worth switching off)
    src.write_text(square(";FLAVOR:RepRap").replace("G1 X80 Y80 F6000", "G1 X5 Y5 F600\nG1 X80 Y80 F600"))
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--json", str(tmp_path / "r.json")]) == 0
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["firmware"] == "reprap" and "M18 E" in out.read_text()
    capsys.readouterr()
    assert main(["verify", str(src), str(out)]) == 0
    printed = capsys.readouterr().out
    assert "(firmware: reprap)" in printed
    from gatesopt.verify import detect_firmware
    assert detect_firmware(gatesopt.parse(str(src)), gatesopt.parse(str(out))) == "reprap"
    # and a Marlin file's output stays Marlin's
    src.write_text(square(";FLAVOR:Marlin").replace("G1 X80 Y80 F6000", "G1 X5 Y5 F600\nG1 X80 Y80 F600"))
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--force"]) == 0
    assert "M18 " in out.read_text()
    assert detect_firmware(gatesopt.parse(str(src)), gatesopt.parse(str(out))) == "marlin"


def test_klipper_without_a_budget_gets_one(tmp_path, capsys):
    src = tmp_path / "part.gcode"
    src.write_text(square(";FLAVOR:Marlin", layers=6))
    out = tmp_path / "out.gcode"
    # (--motors X,Y: a cartesian printer; of unknown kinematics stock Klipper gates no X/Y)
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--firmware", "klipper",
                 "--motors", "X,Y", "--json", str(tmp_path / "r.json")]) == 0
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["added_time_pct"] <= 1.0 + 1e-6 and d["firmware_choice"]["budget_is_default"]
    assert "the file says marlin" in capsys.readouterr().out
    # lifted by name: more stalls, more saving
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--firmware", "klipper", "--force",
                 "--motors", "X,Y", "--max-added-time-pct", "none", "--json", str(tmp_path / "r2.json"),
                 "--force"]) == 0
    d2 = json.loads((tmp_path / "r2.json").read_text())
    assert d2["added_time_pct"] > 1.0 and d2["saving_pct"] >= d["saving_pct"]


def test_solve_refuses_marlin_lines_for_a_klipper_file_in_one_line(tmp_path, capsys):
    src = tmp_path / "part.gcode"
    src.write_text(square("; gcode_flavor = klipper"))
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--firmware", "marlin"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stops the print" in err[0] and "--force-firmware marlin" in err[0]
    assert not out.exists()
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--force-firmware", "marlin"]) == 0
    assert "M18 " in out.read_text()
    # (auto: Klipper's own lines; --motors X,Y: a cartesian printer, as no model is named)
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--force", "--motors", "X,Y"]) == 0
    assert "SET_STEPPER_ENABLE" in out.read_text() and "M18 X" not in out.read_text()


def test_batch_and_compare_read_each_file_s_firmware(tmp_path, capsys):
    a, b = tmp_path / "a.gcode", tmp_path / "b.gcode"
    a.write_text(square(";FLAVOR:Marlin"))
    # (a cartesian model named: of unknown kinematics stock Klipper gates no X/Y)
    b.write_text(square("; gcode_flavor = klipper\n; printer_model = ENDER3V2"))
    assert main(["batch", str(a), str(b), "--out", str(tmp_path / "r.json"), "--no-order", "--quiet"]) == 0
    rows = json.loads((tmp_path / "r.json").read_text())
    rows = rows["rows"] if isinstance(rows, dict) else rows
    assert sorted((r["file"].rsplit("/", 1)[1], r["firmware"]) for r in rows) == [("a.gcode", "marlin"),
                                                                                   ("b.gcode", "klipper")]
    assert all("at most 1 % longer than as sliced" in r["firmware_line"] for r in rows)
    capsys.readouterr()
    assert main(["compare", str(a), "--formulations", "dp"]) == 0
    assert "firmware marlin: read flavor setting" in capsys.readouterr().out
    # a printer nothing is gated on: a row that says so, not an empty table
    c = tmp_path / "c.gcode"
    c.write_text(square(";FLAVOR:Griffin"))
    assert main(["compare", str(c), "--json", str(tmp_path / "c.json")]) == 0
    printed = capsys.readouterr().out
    assert "not gated" in printed and "no motor line for this printer; try --ordering" in printed
    rows = json.loads((tmp_path / "c.json").read_text())
    rows = rows["rows"] if isinstance(rows, dict) else rows
    assert [(r["formulation"], r["status"]) for r in rows] == [("-", "not gated")]


# -- the printer's kinematics and its printer.cfg --------------------------------------------------
BENCH_CFG = Path(__file__).resolve().parents[1] / "bench" / "klipper" / "printer.cfg"


def _cfg(tmp_path, kinematics="cartesian", gating=False):
    text = BENCH_CFG.read_text().replace("kinematics: cartesian", f"kinematics: {kinematics}")
    assert f"kinematics: {kinematics}" in text
    p = tmp_path / f"{kinematics}{'_g' if gating else ''}.cfg"
    p.write_text(text + ("\n[gatesopt_gating]\n" if gating else ""))
    from gatesopt.printer_config import read_printer_config
    return read_printer_config(str(p))


@pytest.mark.parametrize("model, expected", [("Voron_v2_250", "corexy"), ("CR-K1 Max", "corexy"),
                                               ("Voron Switchwire", "corexz"), ("COREONE", "corexy"),
                                               ("MK3S", "cartesian"), ("ENDER3V2", "cartesian"),
                                               ("Ender-3 V3", None), ("Ender-3 V3 SE", "cartesian"),
                                               ("Bambu Lab A1", None), ("Anycubic Kobra S1", None)])
def test_printer_models_name_their_kinematics(model, expected):
    k = kinematics.model_kinematics(f"; printer_model = {model}\n".encode())
    assert (k.name if k else None) == expected


def test_a_corexy_printer_gets_no_x_y_gating_and_says_why():
    prog = gatesopt.parse(square("; printer_model = Voron_v2_250", start="PRINT_START"))
    c = printer.choose(prog)
    assert c.firmware == "klipper" and c.options is None and c.motors == ()
    assert "corexy kinematics" in c.line and "X,Y are not gated" in c.line and "--motors E" in c.line
    with pytest.raises(firmware.FirmwareError, match=r"corexy kinematics .* X cannot be gated"):
        printer.choose(prog, motors=("X", "E"))
    e = printer.choose(prog, motors=("E",))
    assert e.options is not None and e.motors == ("E",)
    # corexz (Voron Switchwire): X and Z are coupled, Y is one motor: Y is gated
    sw = printer.choose(gatesopt.parse(square("; printer_model = Voron Switchwire", start="PRINT_START")))
    assert sw.motors == ("Y",) and "X are not gated" in sw.line


def test_stock_klipper_of_unknown_kinematics_gets_no_x_y_gating_and_says_how_to_get_it(tmp_path):
    # a Klipper file (PRINT_START) naming no printer: on a corexy machine, gated X/Y would be
    # stepped by the other axis's moves before Klipper re-enables them (a layer shift, measured
    # in Klipper's host on Cura's own Voron 2 profile), so nothing is gated by default; the line
    # says what gates them (the printer.cfg's kinematics, or --motors X,Y on a cartesian printer)
    prog = gatesopt.parse(square(";FLAVOR:RepRap", start="PRINT_START"))
    c = printer.choose(prog)
    assert c.firmware == "klipper" and c.options is None and c.motors == ()
    assert "kinematics unknown" in c.line and "--motors X,Y" in c.line and "--printer-config" in c.line
    asked = printer.choose(prog, motors=("X", "Y"))
    assert asked.motors == ("X", "Y") and asked.options is not None
    assert printer.choose(prog, motors=("E",)).motors == ("E",)
    assert printer.choose(prog, printer=_cfg(tmp_path)).motors == ("X", "Y")
    assert printer.choose(prog, "klipper").motors == ()
    # a cartesian model the slicer names: gated, and said
    ender = printer.choose(gatesopt.parse(square("; printer_model = ENDER3V2", start="PRINT_START")))
    assert ender.motors == ("X", "Y") and "cartesian kinematics (printer model" in ender.line
    # Marlin enables the motors a move needs before it steps: unknown kinematics stays gated
    assert printer.choose(gatesopt.parse(square(";FLAVOR:Marlin"))).motors == ("X", "Y")


def test_solve_on_a_corexy_file_writes_no_motor_line(tmp_path, capsys):
    src = tmp_path / "voron.gcode"
    src.write_text(square("; printer_model = Voron_v2_250", start="PRINT_START"))
    out = tmp_path / "out.gcode"
    assert main(["solve", str(src), "-o", str(out), "--no-order"]) == 0
    text = out.read_text()
    assert "SET_STEPPER_ENABLE" not in text and "M18" not in text.replace("M84 X Y E", "")
    assert "nothing is gated" in capsys.readouterr().out


def test_a_printer_config_says_the_printer_runs_klipper(tmp_path):
    # a plain Cura file (Marlin flavour, as Klipper's docs tell Cura users to set) for a Klipper
    # printer: without the printer.cfg it gets Marlin's M18, which would stop a Klipper print
    prog = gatesopt.parse(square(";FLAVOR:Marlin"))
    assert printer.choose(prog).firmware == "marlin"
    cfg = _cfg(tmp_path)
    c = printer.choose(prog, printer=cfg)
    assert c.firmware == "klipper" and c.motors == ("X", "Y")
    assert c.line.startswith(f"klipper: read --printer-config {cfg.source}") and "the file says marlin" in c.line
    with pytest.raises(firmware.FirmwareError, match=r"is a Klipper config.*stops the print"):
        printer.choose(prog, "marlin", printer=cfg)
    # the module's section in it: the module is installed, so its stall-free dialect
    assert printer.choose(prog, printer=_cfg(tmp_path, gating=True)).firmware == "klipper-gating"
    # a corexy printer.cfg wins over a model the file does not name, and a cartesian one over
    # the corexy model the file names (the printer.cfg is the user's own machine)
    assert printer.choose(prog, printer=_cfg(tmp_path, "corexy")).options is None
    voron = gatesopt.parse(square("; printer_model = Voron_v2_250", start="PRINT_START"))
    assert printer.choose(voron, printer=cfg).motors == ("X", "Y")
    # with [gatesopt_gating] on a corexy printer: the stock dialect (klipper-gating refuses it),
    # and X, Y not gated
    g = printer.choose(prog, printer=_cfg(tmp_path, "corexy", gating=True))
    assert g.firmware == "klipper" and g.options is None and "klipper-gating models cartesian" in g.line


def test_batch_reads_the_printer_config(tmp_path):
    src = tmp_path / "cura.gcode"
    src.write_text(square(";FLAVOR:Marlin"))
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(BENCH_CFG.read_text())
    out = tmp_path / "rows.csv"
    assert main(["batch", str(src), "--printer-config", str(cfg), "--out", str(out), "--no-order",
                 "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert rows[0]["firmware"] == "klipper" and rows[0]["verified"] == "True"


def test_the_verifier_reports_a_gated_motor_a_corexy_printer_couples(tmp_path):
    # an output gating X on a Voron (made before gatesopt read the kinematics, or by another
    # tool): the verifier says which line and why, from the printer model or the printer.cfg
    from gatesopt.verify import verify
    text = square("; printer_model = Voron_v2_250", start="PRINT_START")
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("G1 X120 Y80 "))
    gated = lines[:k + 1] + ["SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0", lines[k + 1],
                             "SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=1"] + lines[k + 2:]
    orig, out = gatesopt.parse(text), gatesopt.parse("\n".join(gated) + "\n")
    rep = verify(orig, out, firmware="klipper")
    hits = [f for f in rep.findings if "corexy printer" in f.message]
    assert len(hits) == 1 and hits[0].line == k + 2 and "stepper_x" in hits[0].message
    # the user's printer.cfg says cartesian: no such finding
    rep = verify(orig, out, firmware="klipper", printer=_cfg(tmp_path))
    assert not [f for f in rep.findings if "corexy" in f.message]


def test_a_marlin_flavour_alone_says_how_a_klipper_printer_gets_safe_lines(tmp_path):
    # nothing in a Marlin-flavoured Cura file tells a Klipper printer from a Marlin one: the
    # firmware line says what to do if it is Klipper; not where something says which it is
    hint = "if the printer runs Klipper, pass its printer.cfg (--printer-config)"
    assert hint in printer.choose(gatesopt.parse(square(";FLAVOR:Marlin"))).line
    assert hint in printer.choose(gatesopt.parse(square())).line            # nothing read: assumed
    assert hint not in printer.choose(gatesopt.parse(square(";FLAVOR:Marlin")), "marlin").line
    assert hint not in printer.choose(gatesopt.parse(square(";FLAVOR:Marlin")), printer=_cfg(tmp_path)).line


def test_a_run_that_gates_nothing_says_firmware_none_in_its_json(tmp_path, capsys):
    # a Bambu Lab printer: no motor line gatesopt knows to be safe, nothing gated; the JSON said
    # "firmware": "3dgates" (the rules the output was checked by) beside the line saying none
    src = tmp_path / "part.gcode"
    src.write_text(square("; printer_model = Bambu Lab X1 Carbon"))
    out, rj = tmp_path / "out.gcode", tmp_path / "r.json"
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--json", str(rj)]) == 0
    assert "firmware      none: Bambu Lab firmware" in capsys.readouterr().out
    d = json.loads(rj.read_text())
    assert d["firmware"] == "none" and d["firmware_choice"]["firmware"] is None
    assert d["status"] == "skipped" and d["verified"]
