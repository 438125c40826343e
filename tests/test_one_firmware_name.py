"""One firmware detection, one name, in every command (realsweep P8), and `verify`'s two time
models each named, its print time the one `solve` reports (realsweep P10).

Before: on a Bambu Lab file `solve` said "firmware none" (nothing gated), `profile` "3dgates"
(``figures.file_firmware``'s pricing dialect shown as the name) and `verify` "marlin" (the
dialect of the file's own ``M17`` lines, ``firmware.detect``); and `verify`'s one "time" line was
the paper's T = L/F, which rose where `solve`'s print time fell (bambustudio020301_cube20mm:
1685.81 -> 1706.77 s beside `solve`'s 1,851.7 -> 1,845.3 s)."""
from __future__ import annotations

import json
import re

from gatesopt.cli import main
from gatesopt.parse import parse
from gatesopt.rewrite.printer import choose

from conftest import PROJECT_INSTANCES

SRC = PROJECT_INSTANCES / "square_grid_m82.gcode"


def _bambu(tmp_path):
    """The square with a Bambu Lab printer model and Bambu's own motor-current ``M17`` line."""
    p = tmp_path / "bambu.gcode"
    p.write_text("; printer_model = Bambu Lab X1 Carbon\nM17 X1.2 Y1.2 Z0.75\n" + SRC.read_text())
    return p


def _firmware_words(text: str, prefix: str) -> list[str]:
    return [ln.split()[1].rstrip(":") for ln in text.splitlines() if ln.startswith(prefix)]


def test_profile_solve_and_verify_name_one_firmware(tmp_path, capsys):
    src, out = _bambu(tmp_path), tmp_path / "out.gcode"
    assert choose(parse(str(src))).firmware is None           # nothing gated on Bambu's firmware
    assert main(["solve", str(src), "-o", str(out), "--no-order", "--json", str(tmp_path / "s.json")]) == 0
    solve = capsys.readouterr().out
    assert _firmware_words(solve, "firmware ") == ["none"]
    assert json.loads((tmp_path / "s.json").read_text())["firmware"] == "none"
    assert main(["profile", str(src)]) == 0
    assert _firmware_words(capsys.readouterr().out, "firmware ") == ["none"]
    assert main(["profile", str(src), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["firmware"] == "none"
    assert main(["verify", str(src), str(out)]) == 0
    assert "(firmware: none)" in capsys.readouterr().out
    from gatesopt.rewrite.printer import file_firmware
    assert file_firmware(parse(str(src))) == ("none", "3dgates")
    # a solve report given as the claim names it so too, and is read as no dialect
    assert main(["verify", str(src), str(out), "--claimed", str(tmp_path / "s.json")]) == 0
    assert "(firmware: none)" in capsys.readouterr().out


def test_a_gated_file_is_named_alike_too(tmp_path, capsys):
    out = tmp_path / "out.gcode"
    assert main(["solve", str(SRC), "-o", str(out), "--no-order"]) == 0
    assert _firmware_words(capsys.readouterr().out, "firmware ") == ["marlin"]
    assert main(["profile", str(SRC)]) == 0
    assert _firmware_words(capsys.readouterr().out, "firmware ") == ["marlin"]
    assert main(["verify", str(SRC), str(out)]) == 0
    assert "(firmware: marlin)" in capsys.readouterr().out


def test_verify_gives_solves_print_time_and_names_the_paper_time(tmp_path, capsys):
    out, sj = tmp_path / "out.gcode", tmp_path / "s.json"
    assert main(["solve", str(SRC), "-o", str(out), "--no-order", "--json", str(sj)]) == 0
    s = json.loads(sj.read_text())
    solve_line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("print time"))
    assert main(["verify", str(SRC), str(out)]) == 0
    text = capsys.readouterr().out
    line = next(ln for ln in text.splitlines() if ln.startswith("print time"))
    assert line.split("(")[0] == solve_line.split("(")[0]      # the same numbers as solve's
    assert f"{s['print_time_before_s']:,.1f} s -> {s['print_time_after_s']:,.1f} s" in line
    assert "planner model" in line
    paper = next(ln for ln in text.splitlines() if ln.startswith("paper time"))
    assert "T = L/F" in paper and "not the print time" in paper
    assert f"{s['paper_time_before_s']:,.2f} s -> {s['paper_time_after_s']:,.2f} s" in paper
    assert not re.search(r"^time ", text, re.M)                 # no unnamed time line
    assert main(["verify", str(SRC), str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["print_time_model"] == "planner"
    assert abs(d["print_time_after_s"] - s["print_time_after_s"]) < 1e-6
