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
    assert main(["profile", str(five), "--json", "--per-layer", "--time-model", "paper"]) == 0
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


def test_profile_reports_the_planner_time_and_says_what_the_energy_is_over(five, capsys):
    """The default time is the planner model's (acceleration: longer than T = L/F, and within a
    few % of the slicers' own estimates, where T = L/F is 20-27 % under PrusaSlicer's); the paper
    model is one option away, and the energy stays the one `solve` and `verify` report: the
    3DGates tables over the paper's T = L/F durations, said so."""
    assert main(["profile", str(five), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["time_model"] == "planner" and d["energy_time_model"] == "paper"
    assert d["time_s"] > d["paper_time_s"] == pytest.approx(1.1)
    assert d["energy_j"] == pytest.approx(32.78)            # the paper durations' energy
    assert d["mean_power_w"] == pytest.approx(32.78 / 1.1)   # over the times it was integrated
    assert main(["profile", str(five)]) == 0
    out = capsys.readouterr().out
    assert "planner model" in out and "--time-model paper" in out
    assert "T = L/F durations" in out and "--energy-time-model planner" in out
    # the energy over the planner's durations, one option away
    assert main(["profile", str(five), "--json", "--energy-time-model", "planner"]) == 0
    assert json.loads(capsys.readouterr().out)["energy_j"] > 32.78 + 0.1


def test_profile_energy_matches_solve(capsys, tmp_path):
    """The energy `profile` gives is the `energy before` `solve` reports, by default."""
    src = PROJECT_INSTANCES / "star_lines_m82.gcode"
    assert main(["profile", str(src), "--json"]) == 0
    prof = json.loads(capsys.readouterr().out)
    rj = tmp_path / "r.json"
    assert main(["solve", str(src), "-o", str(tmp_path / "o.gcode"), "--no-order", "--rotate", "none",
                 "--json", str(rj)]) == 0
    solved = json.loads(rj.read_text())
    assert prof["energy_j"] == pytest.approx(solved["energy_before_j"], rel=1e-9)
