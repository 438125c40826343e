"""`gatesopt profile` end to end through the CLI entry point."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gatesopt.cli import main

from conftest import PROJECT_INSTANCES

FIVE_LINES = "G21\nG90\nM83\nG1 F1200 X10 Y0 E0.5\nG0 F3000 X10 Y30\n"


@pytest.fixture
def five(tmp_path):
    p = tmp_path / "five.gcode"
    p.write_text(FIVE_LINES)
    return p


def test_profile_text_report(five, capsys):
    assert main(["profile", str(five)]) == 0
    out = capsys.readouterr().out
    assert "energy      33 J" in out and "time        1.1 s" in out
    for sector in ("X motor", "Y motor", "heater", "fans", "idle"):
        assert sector in out


def test_profile_json_and_per_layer(five, capsys):
    assert main(["profile", str(five), "--json", "--per-layer"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["energy_j"] == pytest.approx(32.78)
    assert d["time_s"] == pytest.approx(1.1)
    assert d["lines"] == 5 and d["moves"] == 2
    assert sum(d["sectors_j"].values()) == pytest.approx(d["energy_j"])
    assert "per_layer" in d


def test_profile_component_profile(five, capsys):
    assert main(["profile", str(five), "--json", "--profile", "component_example"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["profile"] == "component_example" and d["energy_j"] > 0


def test_profile_errors_are_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.gcode"
    bad.write_text("G1 X1 F600\nG1 X1.2.3\n")
    assert main(["profile", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"gatesopt: error: {bad}:2: G1 X1.2.3: bad number for X"
    assert main(["profile", str(tmp_path / "missing.gcode")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["profile", str(bad), "--profile", "nope"]) == 2


def test_profile_reads_stdin_in_a_real_process(five):
    out = subprocess.run([sys.executable, "-m", "gatesopt", "profile", "-", "--json"], input=FIVE_LINES,
                         capture_output=True, text=True, check=True).stdout
    assert json.loads(out)["energy_j"] == pytest.approx(32.78)


def test_profile_on_bundled_instances(capsys):
    files = sorted(PROJECT_INSTANCES.glob("*.gcode"))
    if not files:
        pytest.skip("instances/ not generated yet")
    for f in files:
        assert main(["profile", str(f), "--json"]) == 0
        d = json.loads(capsys.readouterr().out)
        assert d["layers"] >= 1 and d["energy_j"] > 0
